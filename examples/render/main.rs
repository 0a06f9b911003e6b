//! Relax a patch and draw it as shaded tubes into `fabric.png`.
//!
//! Run: `cargo run --release --example render [-- OUT.png]`

use yarn_backend_cpu::Rayon;
use yarn_backend_wgpu::Gpu;
use yarn_model::{Params, Simulation};
use yarn_render::{Renderer, View};
use yarn_topology::{Chart, Fabric, Geometry};

fn main() -> std::process::ExitCode {
    yarnify_examples::main_with(run)
}

fn run() -> Result<(), Box<dyn std::error::Error>> {
    let out = std::env::args().nth(1).unwrap_or_else(|| "fabric.png".into());
    let fabric = Fabric::from_chart(&Chart::stockinette(12, 10)?, &Geometry::default())?;
    let radius = fabric.yarn_radius() as f32;
    let yarns = fabric.yarns().to_vec();
    let mut sim = Simulation::new(Rayon::new(), fabric, Params::default())?;
    sim.advance(yarnify_examples::substeps(3000))?;
    let positions = yarnify_examples::positions_f32(&sim.state()?.positions);

    // Seen from 25 degrees round and 30 up, so the loops' depth shows.
    let view = View { orbit: 25f32.to_radians(), elevation: 30f32.to_radians(), ..View::default() };
    let frame = Renderer::new(&*Gpu::new()?).render(&positions, &yarns, radius, &view)?;
    frame.save_png(&out)?;
    println!("wrote {out}: {:.0} % of the frame is yarn", 100.0 * frame.coverage());
    Ok(())
}
