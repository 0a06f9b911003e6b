//! Relax a larger patch on every core with the rayon backend, and time it.
//!
//! Run: `cargo run --release --example rayon`

use std::time::Instant;

use yarn_backend_cpu::Rayon;
use yarn_model::{Backend, Params, Simulation};
use yarn_topology::{Chart, Fabric, Geometry};

fn main() -> std::process::ExitCode {
    yarnify_examples::main_with(run)
}

fn run() -> Result<(), Box<dyn std::error::Error>> {
    // 64x64 stitches: 32,768 nodes, where a second core pays off.
    let fabric = Fabric::from_chart(&Chart::stockinette(64, 64)?, &Geometry::default())?;
    let nodes = fabric.node_count();
    // `Rayon::new()` uses rayon's global pool, one thread per core;
    // `Rayon::with_threads(n)` builds its own.
    let mut sim = Simulation::new(Rayon::new(), fabric, Params::default())?;
    let threads = sim.backend_mut().threads();

    let steps = yarnify_examples::substeps(3000);
    let start = Instant::now();
    sim.advance(steps)?;
    let seconds = start.elapsed().as_secs_f64();
    println!(
        "{steps} substeps of {nodes} nodes on {threads} threads: {:.1} ns per node-substep, energy {:.1}",
        seconds * 1e9 / (steps as f64 * nodes as f64),
        sim.energy()?.total()
    );
    Ok(())
}
