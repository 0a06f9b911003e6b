//! The `yarn-gate` command-line tool: parse, hand the arguments to their
//! command (each lives beside its library code), print what it returns,
//! and turn that into the exit code.

use std::process::ExitCode;

use clap::{Parser, Subcommand};
use yarn_gate::NO_ADAPTER_EXIT;
use yarn_gate::bench::BenchArgs;
use yarn_gate::check::CheckArgs;
use yarn_gate::drape::DrapeArgs;
use yarn_gate::gpucheck::GpucheckArgs;
use yarn_gate::pareto::ParetoArgs;
use yarn_gate::plotdata::PlotdataArgs;
use yarn_gate::render::RenderArgs;
use yarn_gate::stress::StressArgs;

/// yarnify's behavioural gate: does the simulated yarn behave like knit?
#[derive(Debug, Parser)]
#[command(version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Relax a free patch (stockinette, or --pattern's) and check
    /// dissipation, edge curl and course/wale anisotropy (exit code 0 only
    /// if all pass).
    Check(CheckArgs),
    /// Measure the cost per node, and per stitch, per substep of each
    /// backend over square patches or a chart file (median of repeated
    /// runs after a warm-up).
    Bench(BenchArgs),
    /// Check the GPU backend against the serial f32 one on this machine's
    /// adapter, in both accumulation modes (exit code 0 only if both pass).
    Gpucheck(GpucheckArgs),
    /// Relax a patch, then draw its yarn as tubes into a PNG (and
    /// optionally a Wavefront OBJ mesh).
    Render(RenderArgs),
    /// Drop a patch, flat or folded, onto a floor under gravity with
    /// self-contact on, report how close yarn came to yarn and to the
    /// floor, and draw it (exit code 0 only if nothing passed through).
    Drape(DrapeArgs),
    /// Measure the data behind the paper's figures 2-4 and write a CSV and
    /// a PNG plot for each.
    Plotdata(PlotdataArgs),
    /// Run time against error: every configuration (backend x substep) on
    /// four reference problems against a Serial f64 reference at h/16 (h
    /// the paper's 1/1500 s), with each problem's Pareto front and a
    /// recommended configuration (writes pareto.csv and pareto.png).
    Pareto(ParetoArgs),
    /// Stress the step: the largest stable substep per backend against k_s,
    /// k_c, k_b and the mass, next to the analytic bound 2/ω_max (writes
    /// stability.png); or, with --soak N, N substeps of random grabs,
    /// releases, unravelling and parameter changes.
    Stress(StressArgs),
}

/// Run the command; exit 0 when it passes, 1 when it runs and fails, 2
/// when it cannot run, and 3 ([`NO_ADAPTER_EXIT`]) when it cannot run for
/// want of a GPU adapter.
fn main() -> ExitCode {
    let outcome = match Cli::parse().command {
        Command::Check(args) => args.run(),
        Command::Bench(args) => args.run(),
        Command::Gpucheck(args) => args.run(),
        Command::Render(args) => args.run(),
        Command::Drape(args) => args.run(),
        Command::Plotdata(args) => args.run(),
        Command::Pareto(args) => args.run(),
        Command::Stress(args) => args.run(),
    };
    match outcome {
        Ok(outcome) => {
            print!("{}", outcome.stdout);
            if outcome.pass { ExitCode::SUCCESS } else { ExitCode::FAILURE }
        }
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(if e.is_no_adapter() { NO_ADAPTER_EXIT } else { 2 })
        }
    }
}
