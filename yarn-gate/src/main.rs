//! The `yarn-gate` command-line tool.

use std::process::ExitCode;

use clap::{Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use yarn_backend_cpu::Serial;
use yarn_gate::GateError;
use yarn_gate::check::{CheckConfig, CheckReport, run_check};
use yarn_model::Params;

/// yarnify's behavioural gate: does the simulated yarn behave like knit?
#[derive(Debug, Parser)]
#[command(version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Relax a free stockinette patch and check dissipation, edge curl and
    /// course/wale anisotropy (exit code 0 only if all pass).
    Check(CheckArgs),
}

#[derive(Debug, clap::Args)]
struct CheckArgs {
    /// Patch size in stitches, WIDTHxHEIGHT.
    #[arg(long, default_value = "16x16", value_parser = parse_size)]
    size: (usize, usize),
    /// Substeps of free relaxation; each stiffness probe holds as long.
    #[arg(long, default_value_t = 12_000)]
    steps: u64,
    /// Backend: serial (f64, the ground truth) or serial-f32.
    #[arg(long, default_value = "serial")]
    backend: String,
    /// Rest-curl fraction κ; 1 gives a patch that should read flat.
    #[arg(long)]
    rest_curl: Option<f64>,
    /// Print one JSON object instead of the table.
    #[arg(long)]
    json: bool,
}

fn parse_size(text: &str) -> Result<(usize, usize), String> {
    let err = || format!("`{text}` is not a size; write WIDTHxHEIGHT, e.g. 16x16");
    let (w, h) = text.split_once(['x', 'X']).ok_or_else(err)?;
    Ok((w.trim().parse().map_err(|_| err())?, h.trim().parse().map_err(|_| err())?))
}

const BACKENDS: &str = "serial, serial-f64, serial-f32";

fn check(args: &CheckArgs) -> Result<CheckReport, GateError> {
    let params = Params { rest_curl: args.rest_curl.unwrap_or(Params::gate().rest_curl), ..Params::gate() };
    let config =
        CheckConfig { width: args.size.0, height: args.size.1, steps: args.steps, pull_steps: args.steps, params };
    let bar = ProgressBar::new(args.steps);
    bar.set_style(
        ProgressStyle::with_template("{msg:>12} [{bar:40}] {pos}/{len} substeps ({eta})")
            .expect("static template")
            .progress_chars("=> "),
    );
    let mut progress = |phase: &'static str, done: u64, total: u64| {
        bar.set_message(phase);
        bar.set_length(total);
        bar.set_position(done);
    };
    let report = match args.backend.as_str() {
        "serial" | "serial-f64" => run_check(Serial::<f64>::new(), &config, &mut progress),
        "serial-f32" => run_check(Serial::<f32>::new(), &config, &mut progress),
        other => Err(GateError::UnknownBackend { name: other.into(), known: BACKENDS.into() }),
    };
    bar.finish_and_clear();
    report
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match cli.command {
        Command::Check(args) => match check(&args) {
            Ok(report) => {
                if args.json {
                    println!("{}", serde_json::to_string_pretty(&report).expect("report serialises"));
                } else {
                    print!("{}", report.table());
                }
                if report.pass { ExitCode::SUCCESS } else { ExitCode::FAILURE }
            }
            Err(e) => {
                eprintln!("error: {e}");
                ExitCode::from(2)
            }
        },
    }
}
