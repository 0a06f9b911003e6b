//! Relax a stockinette patch on the single-threaded CPU backend and print
//! its energy as it falls.
//!
//! Run: `cargo run --release --example serial`

use yarn_backend_cpu::Serial;
use yarn_model::{Params, Simulation};
use yarn_topology::{Chart, Fabric, Geometry};

fn main() -> std::process::ExitCode {
    yarnify_examples::main_with(run)
}

fn run() -> Result<(), Box<dyn std::error::Error>> {
    // A 16x16 stitch chart of plain knit becomes one serpentine yarn of
    // 2048 nodes with 480 persistent contacts.
    let chart = Chart::stockinette(16, 16)?;
    let fabric = Fabric::from_chart(&chart, &Geometry::default())?;
    println!("{} nodes, {} contacts", fabric.node_count(), fabric.contacts().len());

    // The paper's parameters, gravity off. The serial backend in f32 is the
    // reference every other f32 backend is held to.
    let mut sim = Simulation::new(Serial::<f32>::new(), fabric, Params::default())?;

    // Let the pre-stressed yarn go: its bending energy drains through the
    // damping while the contacts hold the loops together.
    for _ in 0..=6 {
        let energy = sim.energy()?;
        println!(
            "substep {:>5}  total {:>8.2}  bend {:>8.2}  contact {:>6.2}  max speed {:.3}",
            sim.substeps(),
            energy.total(),
            energy.bend,
            energy.contact,
            sim.state()?.max_speed()
        );
        sim.advance(yarnify_examples::substeps(2000))?;
    }
    Ok(())
}
