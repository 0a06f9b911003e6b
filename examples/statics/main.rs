//! A rested state two ways: the damped dynamics run until it stops, and
//! `yarn_model::statics::solve`, which minimises the energy directly. It
//! prints, for a 4x4 patch hung from its top row and for the gate's free
//! 16x16 patch (both frictionless), each method's energy, residual force,
//! cost in force evaluations and wall time, and how far apart the two
//! resting shapes are, in yarn radii; then the smallest budget (doubling
//! from 25 evaluations) at which a solve gets as low as the dynamics did.
//!
//! Run: `cargo run --release --example statics`

use std::time::Instant;

use yarn_backend_cpu::Serial;
use yarn_model::statics::{StaticOptions, solve};
use yarn_model::{Backend, Model, Params, State, step};
use yarn_topology::{Chart, Fabric, Geometry, Pin, Side};

fn main() -> std::process::ExitCode {
    yarnify_examples::main_with(run)
}

fn run() -> Result<(), Box<dyn std::error::Error>> {
    println!(
        "{:<22} {:<22} {:>12} {:>12} {:>10} {:>8}  apart",
        "problem", "method", "evaluations", "energy", "max force", "wall s"
    );
    for (name, size, hung, substeps) in
        [("4x4 hung, g = 9.81", 4, true, 200_000), ("16x16 free (the gate)", 16, false, 200_000)]
    {
        let fabric = Fabric::from_chart(&Chart::stockinette(size, size)?, &Geometry::default())?;
        let params = Params { friction: 0.0, gravity: if hung { 9.81 } else { 0.0 }, ..Params::paper() };
        let rest = fabric.positions();
        let pins: Vec<Pin> = if hung {
            fabric.side_nodes(Side::Top).into_iter().map(|node| Pin { node, target: rest[node as usize] }).collect()
        } else {
            Vec::new()
        };
        let mut model = Model::<f64>::new(&fabric, &params)?;
        model.set_pins(&pins)?;
        let radius = fabric.yarn_radius();
        let max_force = |state: &State<f64>| {
            let mut forces = Vec::new();
            step::accumulate_forces(&model, &state.positions, &mut forces);
            let pinned = |i: usize| pins.iter().any(|p| p.node as usize == i);
            forces.iter().enumerate().filter(|(i, _)| !pinned(*i)).map(|(_, f)| f.norm()).fold(0.0, f64::max)
        };

        let mut dynamic = Serial::<f64>::new();
        dynamic.load(&fabric, &params)?;
        dynamic.set_pins(&pins)?;
        let substeps = yarnify_examples::substeps(substeps);
        let clock = Instant::now();
        dynamic.advance(substeps)?;
        let settled = dynamic.state()?;
        let wall = clock.elapsed().as_secs_f64();
        let energy = step::energy(&model, &settled).potential();
        println!(
            "{name:<22} {:<22} {substeps:>12} {energy:>12.4} {:>10.2e} {wall:>8.2}",
            "dynamics",
            max_force(&settled)
        );

        let solve_within = |budget: usize| {
            let mut state = State::at_rest(&fabric);
            let clock = Instant::now();
            let report =
                solve(&model, &mut state, &StaticOptions { max_evaluations: budget, ..StaticOptions::default() });
            (state, report, clock.elapsed().as_secs_f64())
        };
        for budget in [1_200, 5_000] {
            let (state, report, wall) = solve_within(yarnify_examples::substeps(budget) as usize);
            let apart = state.positions.iter().zip(&settled.positions).map(|(a, b)| (a - b).norm()).fold(0.0, f64::max)
                / radius;
            println!(
                "{name:<22} {:<22} {:>12} {:>12.4} {:>10.2e} {wall:>8.2}  {apart:.2} r",
                format!("statics, {budget} evals"),
                report.evaluations,
                report.energy,
                report.max_force
            );
        }
        let mut budget = 25;
        let (report, wall) = loop {
            let (_, report, wall) = solve_within(budget);
            if report.energy <= energy || report.converged || budget >= 5_000 {
                break (report, wall);
            }
            budget *= 2;
        };
        println!(
            "{name:<22} {:<22} {:>12} {:>12.4} {:>10.2e} {wall:>8.2}",
            "statics, to that energy", report.evaluations, report.energy, report.max_force
        );
    }
    Ok(())
}
