//! The `yarn-gate` command-line tool.

use std::process::ExitCode;

use clap::{Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use yarn_backend_cpu::{Rayon, Reference, Serial};
use yarn_backend_wgpu::{Gpu, Mode, Wgpu};
use yarn_gate::GateError;
use yarn_gate::bench::{BenchConfig, bench, table};
use yarn_gate::check::{CheckConfig, CheckReport, run_check, run_static_check};
use yarn_gate::gpucheck::run_gpucheck;
use yarn_gate::pareto;
use yarn_gate::plotdata as plot;
use yarn_model::statics::StaticOptions;
use yarn_model::{Backend, Params, widen};
use yarn_render::{Renderer, View, tube_obj};
use yarn_topology::{Chart, Fabric, Geometry};

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
    /// Measure the cost per node per substep of each backend over square
    /// patches (median of repeated runs after a warm-up).
    Bench(BenchArgs),
    /// Check the GPU backend against the serial f32 one on this machine's
    /// adapter, in both accumulation modes (exit code 0 only if both pass).
    Gpucheck(GpucheckArgs),
    /// Relax a patch, then draw its yarn as tubes into a PNG (and
    /// optionally a Wavefront OBJ mesh).
    Render(RenderArgs),
    /// Measure the data behind the paper's figures 2-4 and write a CSV and
    /// a PNG plot for each.
    Plotdata(PlotdataArgs),
    /// Run time against error: every configuration (backend x substep) on
    /// four reference problems against a Serial f64 reference at h/8, with
    /// each problem's Pareto front and a recommended configuration (writes
    /// pareto.csv and pareto.png).
    Pareto(ParetoArgs),
    /// Stress the step: the largest stable substep per backend against k_s,
    /// k_c, k_b and the mass, next to the analytic bound 2/ω_max (writes
    /// stability.png); or, with --soak N, N substeps of random grabs,
    /// releases, unravelling and parameter changes.
    Stress(StressArgs),
}

#[derive(Debug, clap::Args)]
struct StressArgs {
    /// Backends, comma-separated; GPU ones are left out, with a warning,
    /// when there is no adapter.
    #[arg(long, value_delimiter = ',', default_value = "serial-f32,serial-f64,wgpu")]
    backend: Vec<String>,
    /// Patch size for the stability map, WIDTHxHEIGHT.
    #[arg(long, default_value = "8x8", value_parser = parse_size)]
    size: (usize, usize),
    /// Simulated seconds each stability trial runs.
    #[arg(long, default_value_t = 0.5)]
    duration: f64,
    /// Bisection steps on the substep.
    #[arg(long, default_value_t = 8)]
    bisections: u32,
    /// Run a soak of this many substeps on a 16x16 patch instead of the map.
    #[arg(long)]
    soak: Option<u64>,
    /// Folder for stability.png (created if missing).
    #[arg(long, default_value = "stress")]
    out: std::path::PathBuf,
    /// Print JSON instead of the table.
    #[arg(long)]
    json: bool,
}

#[derive(Debug, clap::Args)]
struct ParetoArgs {
    /// Backends, comma-separated; GPU ones are left out, with a warning,
    /// when there is no adapter.
    #[arg(long, value_delimiter = ',', default_value = "serial-f64,serial-f32,rayon,wgpu,wgpu-fixed")]
    backend: Vec<String>,
    /// Patch size in stitches, WIDTHxHEIGHT.
    #[arg(long, default_value = "16x16", value_parser = parse_size)]
    size: (usize, usize),
    /// Simulated seconds per problem.
    #[arg(long, default_value_t = 1.0)]
    duration: f64,
    /// Substeps per 1/150 s control tick to try, comma-separated: h =
    /// 1/(150 N) s, so 10 is the paper's 1/1500.
    #[arg(long, value_delimiter = ',', default_value = "2,3,5,10,20,40")]
    substeps: Vec<u32>,
    /// Timed runs per configuration; the median wall time is reported.
    #[arg(long, default_value_t = 3)]
    repeats: usize,
    /// Folder for pareto.csv and pareto.png (created if missing).
    #[arg(long, default_value = "pareto")]
    out: std::path::PathBuf,
    /// Print one JSON object (rows, recommended, reference_self_error)
    /// instead of the table.
    #[arg(long)]
    json: bool,
}

#[derive(Debug, clap::Args)]
struct PlotdataArgs {
    /// Folder to write the CSV and PNG files into (created if missing).
    #[arg(long, default_value = "figures")]
    out: std::path::PathBuf,
    /// Backend for figures 2 and 3 (see `check --help`).
    #[arg(long, default_value = "rayon")]
    backend: String,
    /// Patch size for figures 2 and 3, WIDTHxHEIGHT.
    #[arg(long, default_value = "16x16", value_parser = parse_size)]
    size: (usize, usize),
    /// Substeps of free relaxation (figure 2).
    #[arg(long, default_value_t = 12_000)]
    steps: u64,
    /// Substeps each stiffness probe holds (figure 3).
    #[arg(long, default_value_t = 6_000)]
    pull_steps: u64,
    /// Backends for figure 4, comma-separated; a GPU one is left out, with
    /// a warning, when there is no adapter.
    #[arg(long, value_delimiter = ',', default_value = "serial-f32,rayon,wgpu")]
    scaling: Vec<String>,
}

#[derive(Debug, clap::Args)]
struct RenderArgs {
    /// Patch size in stitches, WIDTHxHEIGHT.
    #[arg(long, default_value = "16x16", value_parser = parse_size)]
    size: (usize, usize),
    /// Substeps of free relaxation before drawing.
    #[arg(long, default_value_t = 3_000)]
    steps: u64,
    /// Backend for the relaxation (see `check --help`).
    #[arg(long, default_value = "rayon")]
    backend: String,
    /// The PNG to write.
    #[arg(long, default_value = "fabric.png")]
    out: std::path::PathBuf,
    /// Also write the tube surface as a Wavefront OBJ mesh here.
    #[arg(long)]
    obj: Option<std::path::PathBuf>,
    /// Image size in pixels, WIDTHxHEIGHT.
    #[arg(long, default_value = "1280x960", value_parser = parse_size)]
    image: (usize, usize),
    /// Camera rotation about the vertical axis, in degrees.
    #[arg(long, default_value_t = 0.0)]
    orbit: f32,
    /// Camera angle above the fabric's plane, in degrees.
    #[arg(long, default_value_t = 20.0)]
    elevation: f32,
}

#[derive(Debug, clap::Args)]
struct GpucheckArgs {
    /// Patch size in stitches, WIDTHxHEIGHT.
    #[arg(long, default_value = "16x16", value_parser = parse_size)]
    size: (usize, usize),
    /// Print one JSON object instead of the table.
    #[arg(long)]
    json: bool,
}

#[derive(Debug, clap::Args)]
struct BenchArgs {
    /// Backends to measure, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "serial-f32,serial-f64,rayon")]
    backend: Vec<String>,
    /// Patch sides in stitches, comma-separated (8 = 8x8 = 512 nodes).
    #[arg(long, value_delimiter = ',', default_value = "8,16,32,64")]
    sizes: Vec<usize>,
    /// Threads for the rayon backend; 0 uses one per core.
    #[arg(long, default_value_t = 0)]
    threads: usize,
    /// Timed runs per row; the median is reported.
    #[arg(long, default_value_t = 7)]
    repeats: usize,
    /// Friction coefficient μ of the scene; 0 turns the friction pass off
    /// [default: the model's default].
    #[arg(long)]
    friction: Option<f64>,
    /// Gravity of the scene (model units per s²).
    #[arg(long, default_value_t = 0.0)]
    gravity: f64,
    /// Hold each patch's top row in place, as a drape does.
    #[arg(long)]
    pin_top: bool,
    /// Fraction of the contacts to release first, the top rows' (as after
    /// unravelling).
    #[arg(long, default_value_t = 0.0)]
    dead: f64,
    /// Let blocks of nodes slower than this sleep (CPU backends; 0: never).
    #[arg(long, default_value_t = 0.0)]
    sleep: f64,
    /// Substeps to run before timing, so the fabric settles.
    #[arg(long, default_value_t = 0)]
    settle: u64,
    /// Print a JSON array of rows instead of the table.
    #[arg(long)]
    json: bool,
}

#[derive(Debug, clap::Args)]
struct CheckArgs {
    /// Patch size in stitches, WIDTHxHEIGHT.
    #[arg(long, default_value = "16x16", value_parser = parse_size)]
    size: (usize, usize),
    /// Substeps of free relaxation; each stiffness probe holds as long.
    #[arg(long, default_value_t = 12_000)]
    steps: u64,
    /// Backend: serial (f64, the ground truth), serial-f32, rayon, wgpu
    /// (gather), wgpu-fixed (f32), or reference-f32 / reference-f64 (the
    /// element-by-element substep).
    #[arg(long, default_value = "serial")]
    backend: String,
    /// Rest-curl fraction κ; 1 gives a patch that should read flat.
    #[arg(long)]
    rest_curl: Option<f64>,
    /// How to bring the patch to rest: `dynamic` (the damped dynamics for
    /// --steps substeps on --backend), or `static` (an energy minimum by a
    /// quasi-static solve in f64, no friction; --steps and --backend are
    /// not used).
    #[arg(long, default_value = "dynamic", value_parser = ["dynamic", "static"])]
    solver: String,
    /// Print one JSON object instead of the table.
    #[arg(long)]
    json: bool,
}

fn parse_size(text: &str) -> Result<(usize, usize), String> {
    let err = || format!("`{text}` is not a size; write WIDTHxHEIGHT, e.g. 16x16");
    let (w, h) = text.split_once(['x', 'X']).ok_or_else(err)?;
    Ok((w.trim().parse().map_err(|_| err())?, h.trim().parse().map_err(|_| err())?))
}

const BACKENDS: &str =
    "serial, serial-f64, serial-f32, rayon, wgpu (= wgpu-gather), wgpu-fixed, reference-f32, reference-f64";

/// Run `$body` with `$backend` bound to the backend named `$name`.
macro_rules! with_backend {
    ($name:expr, $threads:expr, $backend:ident => $body:expr) => {
        match $name {
            "serial" | "serial-f64" => {
                let $backend = Serial::<f64>::new();
                $body
            }
            "serial-f32" => {
                let $backend = Serial::<f32>::new();
                $body
            }
            "rayon" => {
                let $backend = rayon($threads)?;
                $body
            }
            "wgpu" | "wgpu-gather" => {
                let $backend = Wgpu::new(Mode::Gather)?;
                $body
            }
            "wgpu-fixed" => {
                let $backend = Wgpu::new(Mode::FixedPointAtomic)?;
                $body
            }
            "reference-f32" => {
                let $backend = Reference::<f32>::new();
                $body
            }
            "reference-f64" => {
                let $backend = Reference::<f64>::new();
                $body
            }
            other => Err(GateError::UnknownBackend { name: other.into(), known: BACKENDS.into() }),
        }
    };
}

fn rayon(threads: usize) -> Result<Rayon, GateError> {
    if threads == 0 {
        return Ok(Rayon::new());
    }
    Rayon::with_threads(threads).map_err(|e| GateError::ThreadPool { threads, reason: e.to_string() })
}

fn progress_bar(len: u64, template: &str) -> ProgressBar {
    let bar = ProgressBar::new(len);
    bar.set_style(ProgressStyle::with_template(template).expect("static template").progress_chars("=> "));
    bar
}

fn check(args: &CheckArgs) -> Result<CheckReport, GateError> {
    let params = Params { rest_curl: args.rest_curl.unwrap_or(Params::gate().rest_curl), ..Params::gate() };
    let config =
        CheckConfig { width: args.size.0, height: args.size.1, steps: args.steps, pull_steps: args.steps, params };
    let bar = progress_bar(args.steps, "{msg:>12} [{bar:40}] {pos}/{len} substeps ({eta})");
    let mut progress = |phase: &'static str, done: u64, total: u64| {
        bar.set_message(phase);
        bar.set_length(total);
        bar.set_position(done);
    };
    let report = if args.solver == "static" {
        run_static_check(&config, &StaticOptions::default(), &mut progress)
    } else {
        with_backend!(args.backend.as_str(), 0, backend => run_check(backend, &config, &mut progress))
    };
    bar.finish_and_clear();
    report
}

fn run_bench(args: &BenchArgs) -> Result<Vec<yarn_gate::bench::BenchRow>, GateError> {
    let defaults = Params::default();
    let params = Params {
        friction: args.friction.unwrap_or(defaults.friction),
        gravity: args.gravity,
        sleep_speed: args.sleep,
        ..defaults
    };
    let config = BenchConfig {
        sides: args.sizes.clone(),
        repeats: args.repeats.max(1),
        params,
        pin_top: args.pin_top,
        dead: args.dead,
        settle: args.settle,
        ..BenchConfig::default()
    };
    let mut rows = Vec::new();
    for name in &args.backend {
        let bar = progress_bar(0, "{msg:>12} [{bar:40}] {pos}/{len} timed runs");
        bar.set_message(name.clone());
        let mut progress = |done, total| {
            bar.set_length(total);
            bar.set_position(done);
        };
        let measured = with_backend!(name.as_str(), args.threads, backend => {
            let mut backend = backend;
            bench(&mut backend, &config, &mut progress)
        });
        bar.finish_and_clear();
        rows.extend(measured?);
    }
    Ok(rows)
}

/// Print what bounds the GPU rows below: a copy pass's bandwidth over a
/// 1 GiB buffer, an empty dispatch's cost, and a copy of one node buffer
/// (16 bytes a node) at each size benched, which is the least a pass over
/// that fabric's state can take.
fn print_gpu_floors(rows: &[yarn_gate::bench::BenchRow]) -> Result<(), String> {
    let gpu = Gpu::new().map_err(|e| e.to_string())?;
    let (bytes, rate) = gpu.copy_bandwidth(1 << 30, 9)?;
    let dispatch = gpu.dispatch_overhead(9)?;
    eprintln!(
        "{}: a copy pass moves {:.0} GB/s (read + write, {} MiB buffer); an empty dispatch costs {:.2} µs",
        gpu.adapter(),
        rate / 1e9,
        bytes >> 20,
        dispatch * 1e6
    );
    let sizes: std::collections::BTreeSet<usize> =
        rows.iter().filter(|r| r.backend.starts_with("wgpu")).map(|r| r.nodes).collect();
    for nodes in sizes {
        let (bytes, rate) = gpu.copy_bandwidth(nodes as u64 * 16, 9)?;
        eprintln!(
            "  copying one node buffer of {nodes} nodes ({} KiB): {:.2} µs a pass, {:.0} GB/s",
            bytes >> 10,
            2.0 * bytes as f64 / rate * 1e6,
            rate / 1e9
        );
    }
    Ok(())
}

/// Run `stress`; returns what to print.
fn stress(args: &StressArgs) -> Result<String, GateError> {
    use yarn_gate::stress;
    if let Some(substeps) = args.soak {
        let mut reports = Vec::new();
        for name in &args.backend {
            let bar = progress_bar(substeps, "{msg:>12} [{bar:40}] {pos}/{len} substeps ({eta})");
            bar.set_message(name.clone());
            let report = with_backend!(name.as_str(), 0, backend => {
                let mut backend = backend;
                stress::soak(&mut backend, substeps, 1, &mut |done| bar.set_position(done))
            });
            bar.finish_and_clear();
            match report {
                Ok(report) => reports.push(report),
                Err(GateError::Gpu(e)) => eprintln!("warning: {name} left out: {e}"),
                Err(e) => return Err(e),
            }
        }
        if args.json {
            return Ok(serde_json::to_string_pretty(&reports).expect("reports serialise"));
        }
        let mut out = format!(
            "{:<14} {:>10} {:>8} {:>12} {:>16} {:>7}\n",
            "backend", "substeps", "actions", "max energy", "final max speed", "finite"
        );
        for r in &reports {
            out += &format!(
                "{:<14} {:>10} {:>8} {:>12.1} {:>16.3} {:>7}\n",
                r.backend, r.substeps, r.actions, r.max_energy, r.final_max_speed, r.finite
            );
        }
        return Ok(out);
    }
    let config = stress::StressConfig {
        size: args.size,
        duration: args.duration,
        bisections: args.bisections,
        ..stress::StressConfig::default()
    };
    let mut rows = Vec::new();
    for name in &args.backend {
        let bar = progress_bar(0, "{msg:>12} [{bar:40}] {pos}/{len} cells");
        bar.set_message(name.clone());
        let measured = with_backend!(name.as_str(), 0, backend => {
            let mut backend = backend;
            stress::map(&mut backend, &config, &mut |done, total| {
                bar.set_length(total);
                bar.set_position(done);
            })
        });
        bar.finish_and_clear();
        match measured {
            Ok(measured) => rows.extend(measured),
            Err(GateError::Gpu(e)) => eprintln!("warning: {name} left out: {e}"),
            Err(e) => return Err(e),
        }
    }
    std::fs::create_dir_all(&args.out)
        .map_err(|e| GateError::Io { path: args.out.display().to_string(), reason: e.to_string() })?;
    let png = args.out.join("stability.png");
    stress::plot(&png, &rows)?;
    if args.json {
        return Ok(serde_json::to_string_pretty(&rows).expect("rows serialise"));
    }
    let lowest = rows.iter().map(|r| r.ratio).fold(f64::INFINITY, f64::min);
    Ok(format!("{}lowest stable fraction of 2/ω_max: {lowest:.3}\nwrote {}", stress::table(&rows), png.display()))
}

/// What `pareto` reports.
#[derive(Debug, serde::Serialize)]
struct ParetoReport {
    rows: Vec<pareto::ParetoRow>,
    recommended: Option<String>,
    /// Per problem, the largest position difference, in yarn radii,
    /// between the reference and the same run at half its substep.
    reference_self_error: std::collections::BTreeMap<&'static str, f64>,
    written: Vec<String>,
}

fn pareto(args: &ParetoArgs) -> Result<ParetoReport, GateError> {
    use pareto::{Problem, REFERENCE_SUBSTEPS, run};
    const CHECKPOINTS: u32 = 4;
    let ticks = (args.duration / pareto::CONTROL).round().max(1.0) as u32;
    let radius = Geometry::default().yarn_radius;
    let repeats = args.repeats.max(1);
    let total = (Problem::ALL.len() * (2 + args.backend.len() * args.substeps.len() * repeats)) as u64;
    let bar = progress_bar(total, "{msg:>24} [{bar:40}] {pos}/{len} runs ({eta})");
    let mut references = Vec::new();
    let mut reference_self_error = std::collections::BTreeMap::new();
    for problem in Problem::ALL {
        bar.set_message(format!("reference {}", problem.name()));
        let [coarse, fine] =
            REFERENCE_SUBSTEPS.map(|n| run(&mut Serial::<f64>::new(), problem, args.size, ticks, n, CHECKPOINTS));
        let (coarse, fine) = (coarse?, fine?);
        bar.inc(2);
        reference_self_error.insert(problem.name(), pareto::errors(&coarse, &fine, radius).0);
        references.push(coarse);
    }
    let mut rows = Vec::new();
    for name in &args.backend {
        let measured = with_backend!(name.as_str(), 0, backend => {
            let mut backend = backend;
            let mut rows = Vec::new();
            for &n in &args.substeps {
                let h = pareto::CONTROL / f64::from(n.max(1));
                for (problem, reference) in Problem::ALL.into_iter().zip(&references) {
                    bar.set_message(format!("{name} {}", problem.name()));
                    let mut walls = Vec::new();
                    let mut last = None;
                    for _ in 0..repeats {
                        let outcome = match run(&mut backend, problem, args.size, ticks, n.max(1), CHECKPOINTS) {
                            Ok(r) => r,
                            // An h the parameters refuse: a failed configuration.
                            Err(GateError::Backend(e)) => pareto::Run {
                                checkpoints: Vec::new(), energies: Vec::new(), wall_s: f64::INFINITY,
                                failure: Some(e.to_string()),
                            },
                            Err(e) => return Err(e),
                        };
                        walls.push(outcome.wall_s);
                        last = Some(outcome);
                        bar.inc(1);
                    }
                    walls.sort_by(f64::total_cmp);
                    let outcome = last.expect("at least one repeat");
                    let (pos_err_max, pos_err_rms, energy_err) = pareto::errors(&outcome, reference, radius);
                    let failure = outcome.failure.or_else(|| {
                        (!pos_err_max.is_finite()).then(|| format!("diverged: beyond {} r", pareto::DIVERGED))
                    });
                    rows.push(pareto::ParetoRow {
                        problem,
                        config: pareto::config_name(name, h),
                        backend: name.clone(),
                        h,
                        wall_s_per_sim_s: walls[walls.len() / 2] / (pareto::CONTROL * f64::from(ticks)),
                        pos_err_max,
                        pos_err_rms,
                        energy_err,
                        on_front: false,
                        recommended: false,
                        failure,
                    });
                }
            }
            Ok::<_, GateError>(rows)
        });
        match measured {
            Ok(measured) => rows.extend(measured),
            Err(GateError::Gpu(e)) => {
                bar.suspend(|| eprintln!("warning: {name} left out: {e}"));
                bar.inc((Problem::ALL.len() * args.substeps.len() * repeats) as u64);
            }
            Err(e) => return Err(e),
        }
    }
    bar.finish_and_clear();
    pareto::mark_front(&mut rows);
    let recommended = pareto::recommend(&mut rows);
    let written = pareto::write(&args.out, &rows)?.iter().map(|p| p.display().to_string()).collect();
    Ok(ParetoReport { rows, recommended, reference_self_error, written })
}

/// Measure and write the three figures; returns the files written.
fn plotdata(args: &PlotdataArgs) -> Result<Vec<std::path::PathBuf>, GateError> {
    std::fs::create_dir_all(&args.out)
        .map_err(|e| GateError::Io { path: args.out.display().to_string(), reason: e.to_string() })?;
    let bar = progress_bar(0, "{msg:>12} [{bar:40}] {pos}/{len} substeps ({eta})");
    let mut progress = |phase: &'static str, done: u64, total: u64| {
        bar.set_message(phase);
        bar.set_length(total);
        bar.set_position(done);
    };
    let (relaxation, probes) = with_backend!(args.backend.as_str(), 0, backend => {
        let mut backend = backend;
        plot::measure(&mut backend, args.size, args.steps, args.pull_steps, &mut progress)
    })?;
    bar.finish_and_clear();
    let mut written = Vec::new();
    written.extend(plot::figure2(&args.out, &relaxation, Params::gate().substep)?);
    written.extend(plot::figure3(&args.out, &probes)?);
    let config = BenchConfig { repeats: 3, work_per_run: 2_000_000, ..BenchConfig::default() };
    let mut rows = Vec::new();
    for name in &args.scaling {
        let bar = progress_bar(0, "{msg:>12} [{bar:40}] {pos}/{len} timed runs");
        bar.set_message(name.clone());
        let mut progress = |done, total| {
            bar.set_length(total);
            bar.set_position(done);
        };
        let measured = with_backend!(name.as_str(), 0, backend => {
            let mut backend = backend;
            bench(&mut backend, &config, &mut progress)
        });
        bar.finish_and_clear();
        match measured {
            Ok(measured) => rows.extend(measured),
            Err(GateError::Gpu(e)) => eprintln!("figure 4 leaves out {name}: {e}"),
            Err(e) => return Err(e),
        }
    }
    written.extend(plot::figure4(&args.out, &rows)?);
    Ok(written)
}

/// Relax, draw, save; returns the coverage.
fn render(args: &RenderArgs) -> Result<f64, GateError> {
    let fabric = Fabric::from_chart(&Chart::stockinette(args.size.0, args.size.1)?, &Geometry::default())?;
    let bar = progress_bar(args.steps, "{msg:>12} [{bar:40}] {pos}/{len} substeps ({eta})");
    bar.set_message("relaxing");
    let positions = with_backend!(args.backend.as_str(), 0, backend => {
        let mut backend = backend;
        relax(&mut backend, &fabric, args.steps, &bar)
    })?;
    bar.finish_and_clear();
    let radius = fabric.yarn_radius() as f32;
    let view = View {
        width: args.image.0 as u32,
        height: args.image.1 as u32,
        orbit: args.orbit.to_radians(),
        elevation: args.elevation.to_radians(),
        zoom: 1.0,
    };
    let frame = Renderer::new(&*Gpu::new()?)
        .render(&positions, radius, &view)
        .and_then(|frame| frame.save_png(&args.out).map(|()| frame))
        .map_err(|e| GateError::Render(e.to_string()))?;
    if let Some(path) = &args.obj {
        std::fs::write(path, tube_obj(&positions, radius))
            .map_err(|e| GateError::Io { path: path.display().to_string(), reason: e.to_string() })?;
    }
    Ok(frame.coverage())
}

/// Advance `backend` from rest by `steps` substeps, with progress; return
/// the positions in f32.
fn relax<B: Backend>(
    backend: &mut B,
    fabric: &Fabric,
    steps: u64,
    bar: &ProgressBar,
) -> Result<Vec<[f32; 3]>, GateError> {
    backend.load(fabric, &Params::gate())?;
    let chunk = (steps / 100).max(1);
    let mut done = 0;
    while done < steps {
        let n = chunk.min(steps - done);
        backend.advance(n)?;
        done += n;
        bar.set_position(done);
    }
    let state = backend.state()?;
    Ok(state.positions.iter().map(widen).map(|p| [p.x as f32, p.y as f32, p.z as f32]).collect())
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match cli.command {
        Command::Stress(args) => match stress(&args) {
            Ok(out) => {
                println!("{out}");
                ExitCode::SUCCESS
            }
            Err(e) => {
                eprintln!("error: {e}");
                ExitCode::from(2)
            }
        },
        Command::Pareto(args) => match pareto(&args) {
            Ok(report) => {
                if args.json {
                    println!("{}", serde_json::to_string_pretty(&report).expect("the report serialises"));
                } else {
                    print!("{}", pareto::table(&report.rows));
                    let self_error: Vec<String> =
                        report.reference_self_error.iter().map(|(p, e)| format!("{p} {e:.1e}")).collect();
                    println!(
                        "reference: serial-f64 at h=1/{:.0}; against h=1/{:.0} it differs by at most (r): {}",
                        150.0 * f64::from(pareto::REFERENCE_SUBSTEPS[0]),
                        150.0 * f64::from(pareto::REFERENCE_SUBSTEPS[1]),
                        self_error.join(", ")
                    );
                    match &report.recommended {
                        Some(c) => println!("recommended (fastest within {} r everywhere): {c}", pareto::ACCURACY),
                        None => println!("no configuration is within {} r on every problem", pareto::ACCURACY),
                    }
                    for path in &report.written {
                        println!("wrote {path}");
                    }
                }
                ExitCode::SUCCESS
            }
            Err(e) => {
                eprintln!("error: {e}");
                ExitCode::from(2)
            }
        },
        Command::Plotdata(args) => match plotdata(&args) {
            Ok(written) => {
                for path in written {
                    println!("wrote {}", path.display());
                }
                ExitCode::SUCCESS
            }
            Err(e) => {
                eprintln!("error: {e}");
                ExitCode::from(2)
            }
        },
        Command::Render(args) => match render(&args) {
            Ok(coverage) => {
                println!("wrote {} ({:.1} % of the frame is yarn)", args.out.display(), 100.0 * coverage);
                if let Some(obj) = &args.obj {
                    println!("wrote {}", obj.display());
                }
                ExitCode::SUCCESS
            }
            Err(e) => {
                eprintln!("error: {e}");
                ExitCode::from(2)
            }
        },
        Command::Gpucheck(args) => {
            let report =
                Gpu::new().map_err(GateError::from).and_then(|gpu| run_gpucheck(&gpu, args.size.0, args.size.1));
            finish(report, args.json, |r| (r.table(), r.pass))
        }
        Command::Bench(args) => match run_bench(&args) {
            Ok(rows) => {
                if args.backend.iter().any(|b| b.starts_with("wgpu")) {
                    // The memory-bound ceiling, measured in the same run.
                    if let Err(e) = print_gpu_floors(&rows) {
                        eprintln!("copy bandwidth not measured: {e}");
                    }
                }
                if args.json {
                    println!("{}", serde_json::to_string_pretty(&rows).expect("rows serialise"));
                } else {
                    print!("{}", table(&rows));
                }
                ExitCode::SUCCESS
            }
            Err(e) => {
                eprintln!("error: {e}");
                ExitCode::from(2)
            }
        },
        Command::Check(args) => finish(check(&args), args.json, |r| (r.table(), r.pass)),
    }
}

/// Print a pass/fail report as JSON or as its table, and turn it into the
/// exit code: 0 on pass, 1 on fail, 2 when it could not run.
fn finish<R: serde::Serialize>(
    report: Result<R, GateError>,
    json: bool,
    table_and_pass: impl Fn(&R) -> (String, bool),
) -> ExitCode {
    match report {
        Ok(report) => {
            let (table, pass) = table_and_pass(&report);
            if json {
                println!("{}", serde_json::to_string_pretty(&report).expect("report serialises"));
            } else {
                print!("{table}");
            }
            if pass { ExitCode::SUCCESS } else { ExitCode::FAILURE }
        }
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(2)
        }
    }
}
