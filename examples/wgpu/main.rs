//! Relax a patch on the GPU, in both force-accumulation modes, and compare
//! where they end.
//!
//! Run: `cargo run --release --example wgpu` (on a machine without a GPU,
//! `apt-get install mesa-vulkan-drivers` gives a software one).

use yarn_backend_wgpu::{Gpu, Mode, Wgpu};
use yarn_model::{Backend, Params};
use yarn_topology::{Chart, Fabric, Geometry};

fn main() -> std::process::ExitCode {
    yarnify_examples::main_with(run)
}

fn run() -> Result<(), Box<dyn std::error::Error>> {
    // One device context, shared: building it compiles every pipeline.
    let gpu = Gpu::new()?;
    println!("adapter: {}", gpu.adapter());
    let fabric = Fabric::from_chart(&Chart::stockinette(32, 32)?, &Geometry::default())?;

    let mut ends = Vec::new();
    for mode in [Mode::Gather, Mode::FixedPointAtomic] {
        let mut backend = Wgpu::with_gpu(gpu.clone(), mode);
        backend.load(&fabric, &Params::default())?;
        // All substeps go into one submission; nothing is read back until
        // `state()` asks.
        backend.advance(yarnify_examples::substeps(1500))?;
        let state = backend.state()?;
        println!("{:>14}: max speed {:.4}", backend.name(), state.max_speed());
        ends.push(state);
    }
    // The fixed-point mode rounds every force to 1/4096: close, not equal.
    let gap = ends[0].positions.iter().zip(&ends[1].positions).map(|(a, b)| (a - b).norm()).fold(0.0, f32::max);
    println!("largest gap between the modes: {gap:.2e} (yarn radius {})", fabric.yarn_radius());
    Ok(())
}
