//! Use yarnify as another tool would: build a fabric from a chart, pin its
//! top row, let it drape under gravity, and export the yarn as an OBJ mesh
//! (`drape.obj`) that Blender opens.
//!
//! Run: `cargo run --release --example drape [-- OUT.obj]`

use yarn_backend_cpu::Rayon;
use yarn_model::{Params, Simulation};
use yarn_render::tube_obj;
use yarn_topology::{Chart, Fabric, Geometry, Pin, Side};

fn main() -> std::process::ExitCode {
    yarnify_examples::main_with(run)
}

fn run() -> Result<(), Box<dyn std::error::Error>> {
    let out = std::env::args().nth(1).unwrap_or_else(|| "drape.obj".into());
    let fabric = Fabric::from_chart(&Chart::stockinette(20, 16)?, &Geometry::default())?;

    // Hold the bind-off row where it was knitted.
    let pins: Vec<Pin> = fabric
        .side_nodes(Side::Top)
        .into_iter()
        .map(|node| Pin { node, target: fabric.positions()[node as usize] })
        .collect();
    println!("pinned {} nodes of {}", pins.len(), fabric.node_count());
    let radius = fabric.yarn_radius() as f32;
    let yarns = fabric.yarns().to_vec();

    // Gravity on (it is off by default); everything else as the paper's.
    let params = Params { gravity: 9.81, ..Params::default() };
    let mut sim = Simulation::new(Rayon::new(), fabric, params)?;
    sim.set_pins(&pins)?;
    let start = sim.state()?;
    sim.advance(yarnify_examples::substeps(6000))?;
    let end = sim.state()?;

    // How far the free bottom edge fell.
    let drop = start.positions.iter().zip(&end.positions).map(|(a, b)| a.y - b.y).fold(0.0, f32::max);
    println!("the fabric hangs {drop:.2} lower at its most");
    std::fs::write(&out, tube_obj(&yarnify_examples::positions_f32(&end.positions), &yarns, radius)?)?;
    println!("wrote {out}");
    Ok(())
}
