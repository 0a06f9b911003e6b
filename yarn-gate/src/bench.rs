//! `yarn-gate bench`: cost per node per substep, and per stitch per substep,
//! of each backend over square patches (or one chart file), as the median
//! of repeated timed runs after a warm-up; and, with `--stages`, where a
//! substep's time goes, pass by pass.
//!
//! This module owns the command ([`BenchArgs`]), the timing and its tables.
//! It knows backends only through [`Backend`]: how a backend splits its
//! substep into passes, and how it times them, is the backend's
//! ([`Backend::advance_timed`]).

use std::fmt::Write as _;
use std::time::Instant;

use serde::Serialize;
use yarn_backend_wgpu::Gpu;
use yarn_model::stages::StageTimes;
use yarn_model::{Backend, Params};
use yarn_topology::{Chart, Fabric, Geometry, Pattern, Pin, Side};

use crate::GateError;
use crate::backends::{BackendWork, with_backend};
use crate::cli::{
    Outcome, PATTERN_HELP, PatternArg, TIMED_RUNS, counts, parse_fraction, parse_pattern, parse_repeats, parse_threads,
    with_bar,
};
use crate::preset::Preset;

/// `yarn-gate bench`: time each backend at each size.
#[derive(Debug, clap::Args)]
pub struct BenchArgs {
    /// Backends to measure, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "serial-f32,serial-f64,rayon")]
    backend: Vec<String>,
    /// The model: `default` (the default parameters on interlooped loops,
    /// 24 nodes a stitch) or `paper` (the paper's parameters on its 8-node
    /// arch, which knits no purl); compare the two by ns/stitch-step.
    #[arg(long, value_enum, default_value_t = Preset::Default)]
    preset: Preset,
    #[arg(long, default_value = "stockinette", value_parser = parse_pattern, help = PATTERN_HELP)]
    pattern: PatternArg,
    /// Patch sides in stitches, comma-separated (8 = 8x8 stitches); unused
    /// with a chart file --pattern, which is benched at its own size.
    #[arg(long, value_delimiter = ',', default_value = "8,16,32,64")]
    sizes: Vec<usize>,
    /// Threads for the rayon backend; 0 uses one per core.
    #[arg(long, default_value_t = 0, value_parser = parse_threads)]
    threads: usize,
    /// Timed runs per row; the median is reported.
    #[arg(long, default_value_t = 7, value_parser = parse_repeats)]
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
    #[arg(long, default_value_t = 0.0, value_parser = parse_fraction, allow_negative_numbers = true)]
    dead: f64,
    /// Let blocks of nodes slower than this sleep (CPU backends; 0: never).
    #[arg(long, default_value_t = 0.0)]
    sleep: f64,
    /// Self-contact stiffness k_sc of the scene, 0 for off, or several,
    /// comma-separated: each backend is then timed at each in turn, and a
    /// row with self-contact on is priced against the row without it, of
    /// the same backend and size, in its scene column (`cost=`) and its
    /// `self_contact_cost` [default: the model's default].
    #[arg(long, value_delimiter = ',')]
    self_contact: Vec<f64>,
    /// The self-contact lists' skin, in yarn radii: a wider one rebuilds
    /// them less often and holds more far pairs [default: the model's
    /// default].
    #[arg(long)]
    skin: Option<f64>,
    /// Substeps to run before timing, so the fabric settles.
    #[arg(long, default_value_t = 0)]
    settle: u64,
    /// Also time each pass of the substep: after a backend's timed runs at
    /// a size, run as many substeps again --repeats times with the
    /// backend's stage counters on (CPU timers, GPU timestamps, or per-pass
    /// runs where the GPU has none), and report per pass the stages it
    /// covers, its median µs per substep and its share of the passes'
    /// total, in a table after the main one (with --json, under `stages`
    /// in each row).
    #[arg(long)]
    stages: bool,
    /// Print a JSON array of rows instead of the table.
    #[arg(long)]
    json: bool,
}

impl BenchArgs {
    /// Time every backend named at every size. A GPU backend without an
    /// adapter is an error here, not left out: a bench asked for it.
    ///
    /// # Errors
    /// A bad size, a chart file that cannot be read or parsed, a purl
    /// stitch with `--preset paper`, an unknown backend, or a backend
    /// failure.
    pub fn run(&self) -> Result<Outcome, GateError> {
        let defaults = self.preset.params();
        let params = Params {
            friction: self.friction.unwrap_or(defaults.friction),
            gravity: self.gravity,
            sleep_speed: self.sleep,
            self_contact_skin: self.skin.unwrap_or(defaults.self_contact_skin),
            ..defaults
        };
        let stiffnesses = if self.self_contact.is_empty() {
            vec![defaults.self_contact_stiffness]
        } else {
            self.self_contact.clone()
        };
        let charts = match &self.pattern {
            PatternArg::File(path) => vec![Chart::from_file(path)?],
            PatternArg::Named(pattern) => {
                self.sizes.iter().map(|&side| pattern.chart(side, side)).collect::<Result<_, _>>()?
            }
        };
        let geometry = self.preset.geometry();
        // A chart the geometry cannot knit fails here, before any backend.
        for chart in &charts {
            Fabric::from_chart(chart, &geometry)?;
        }
        let config = BenchConfig {
            charts,
            geometry,
            repeats: self.repeats,
            params,
            pin_top: self.pin_top,
            dead: self.dead,
            settle: self.settle,
            stages: self.stages,
            ..BenchConfig::default()
        };
        let mut rows = Vec::new();
        for name in &self.backend {
            for &self_contact_stiffness in &stiffnesses {
                let config = BenchConfig { params: Params { self_contact_stiffness, ..params }, ..config.clone() };
                rows.extend(with_backend(name, self.threads, &mut Benchmark { config: &config })?);
            }
        }
        price_self_contact(&mut rows);
        if self.backend.iter().any(|b| b.starts_with("wgpu")) {
            // The memory-bound ceiling, measured in the same run.
            if let Err(e) = print_gpu_floors(&rows) {
                eprintln!("copy bandwidth not measured: {e}");
            }
        }
        Ok(Outcome::json_or(&rows, self.json, || table(&rows) + &stages_table(&rows)))
    }
}

/// [`bench`] on one backend, with a progress bar of its timed runs.
#[derive(Debug)]
pub(crate) struct Benchmark<'a> {
    /// What to time.
    pub(crate) config: &'a BenchConfig,
}

impl BackendWork for Benchmark<'_> {
    type Output = Vec<BenchRow>;

    fn run<B: Backend>(&mut self, name: &str, mut backend: B) -> Result<Vec<BenchRow>, GateError> {
        with_bar(0, TIMED_RUNS, name, |bar| bench(&mut backend, self.config, &mut counts(bar)))
    }
}

/// Print what bounds the GPU rows: a copy pass's bandwidth over a 1 GiB
/// buffer, an empty dispatch's cost, and a copy of one node buffer (16
/// bytes a node) at each size benched, which is the least a pass over that
/// fabric's state can take.
fn print_gpu_floors(rows: &[BenchRow]) -> Result<(), String> {
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

/// How the benchmark runs.
#[derive(Debug, Clone, PartialEq)]
pub struct BenchConfig {
    /// The patches, one row of the table each.
    pub charts: Vec<Chart>,
    /// The stitch geometry the charts are knitted in.
    pub geometry: Geometry,
    /// Timed runs per row; the median is reported.
    pub repeats: usize,
    /// Node-substeps per timed run; the substep count follows from the
    /// patch size, so every run does about the same work.
    pub work_per_run: u64,
    /// The model and solver parameters of the scene (friction and gravity
    /// among them).
    pub params: Params,
    /// Hold the top row in place, as a drape does.
    pub pin_top: bool,
    /// The fraction of contacts released, the last in yarn order first (the
    /// top rows, as after unravelling).
    pub dead: f64,
    /// Substeps run before timing, to let the fabric settle (the warm-up
    /// is a quarter of a run otherwise).
    pub settle: u64,
    /// After the timed runs at each size, time the passes of as many
    /// substeps again, `repeats` times, with [`Backend::advance_timed`]
    /// ([`BenchRow::stages`]).
    pub stages: bool,
}

impl Default for BenchConfig {
    /// Stockinette of 8×8 to 64×64 stitches in the default geometry, 7 runs
    /// of about 20 million node-substeps each.
    fn default() -> Self {
        Self {
            charts: [8, 16, 32, 64]
                .into_iter()
                .map(|side| Pattern::Stockinette.chart(side, side).expect("64x64 stitches are within the node limit"))
                .collect(),
            geometry: Geometry::default(),
            repeats: 7,
            work_per_run: 20_000_000,
            params: Params::default(),
            pin_top: false,
            dead: 0.0,
            settle: 0,
            stages: false,
        }
    }
}

/// One measured row.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BenchRow {
    /// Backend name.
    pub backend: String,
    /// Threads the backend ran on.
    pub threads: usize,
    /// Patch size, `WxH` stitches.
    pub size: String,
    /// Stitch count, W × H.
    pub stitches: usize,
    /// Node count.
    pub nodes: usize,
    /// Contact count.
    pub contacts: usize,
    /// Substeps per timed run.
    pub substeps: u64,
    /// Friction coefficient μ of the scene.
    pub friction: f64,
    /// Gravity of the scene.
    pub gravity: f64,
    /// Pinned nodes.
    pub pins: usize,
    /// Released contacts.
    pub dead_contacts: usize,
    /// The sleep speed (0: sleeping off).
    pub sleep_speed: f64,
    /// Median nanoseconds per node per substep.
    pub ns_per_node_substep: f64,
    /// Median nanoseconds per stitch per substep: `ns_per_node_substep` ×
    /// `nodes` / `stitches`, the cost of the same fabric whatever its
    /// geometry's nodes per stitch.
    pub ns_per_stitch_substep: f64,
    /// Fastest and slowest run, same unit: the spread of the repeats.
    pub ns_min: f64,
    /// See `ns_min`.
    pub ns_max: f64,
    /// Median substeps per second.
    pub substeps_per_s: f64,
    /// The self-contact stiffness of the scene (0: off).
    pub self_contact: f64,
    /// Self-contact list builds per 1,000 substeps over the timed runs,
    /// where self-contact is on and the backend counts them.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub builds_per_1000: Option<f64>,
    /// Batches run again over the timed runs because they were late to
    /// rebuild the self-contact lists ([`Backend::late_list_reruns`]),
    /// where the backend may be.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub late_reruns: Option<u64>,
    /// With self-contact on, this row's time over that of the row without
    /// it of the same backend, threads and patch, where the same run timed
    /// one (`bench --self-contact 0,K`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub self_contact_cost: Option<f64>,
    /// Where the substeps' time went, pass by pass, when
    /// [`BenchConfig::stages`] asked.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub stages: Option<StageReport>,
}

/// Where a row's substeps spent their time, pass by pass: the median of
/// repeated [`Backend::advance_timed`] calls.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StageReport {
    /// How the backend took the times
    /// ([`yarn_model::stages::TimingMethod::name`]).
    pub method: &'static str,
    /// Wall microseconds per substep of a timed call, timing included
    /// (median over the calls).
    pub wall_us_per_substep: f64,
    /// Set when the passes timed are not those `advance` runs (a GPU
    /// substep fused into one dispatch, timed as its unfused passes).
    pub note: Option<String>,
    /// Every pass, in the order a substep runs them.
    pub parts: Vec<PassShare>,
}

/// One pass of a [`StageReport`].
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PassShare {
    /// The pass, e.g. `"block forces"` or `"friction.wgsl"`.
    pub pass: &'static str,
    /// The stages it covers ([`yarn_model::Stage::name`]).
    pub stages: Vec<&'static str>,
    /// Median microseconds per substep.
    pub us_per_substep: f64,
    /// Its fraction of the passes' total (the shares sum to 1).
    pub share: f64,
}

impl StageReport {
    /// The per-pass medians of `calls`, timed calls of the same substeps on
    /// one backend; a pass missing from a call counts 0 s in it (a re-seat
    /// pass runs only while contacts close). `None` without calls.
    pub fn median_of(calls: &[StageTimes]) -> Option<Self> {
        let first = calls.first()?;
        let mut passes = Vec::new();
        for part in calls.iter().flat_map(|call| &call.parts) {
            if !passes.contains(&(part.pass, &part.stages)) {
                passes.push((part.pass, &part.stages));
            }
        }
        let seconds: Vec<f64> = passes
            .iter()
            .map(|&(pass, stages)| {
                median(calls.iter().map(|call| {
                    call.parts.iter().filter(|p| p.pass == pass && p.stages == *stages).map(|p| p.seconds).sum()
                }))
            })
            .collect();
        let total: f64 = seconds.iter().sum();
        let micros = |seconds: f64| 1e6 * seconds / first.substeps.max(1) as f64;
        let parts = passes
            .iter()
            .zip(&seconds)
            .map(|(&(pass, stages), &seconds)| PassShare {
                pass,
                stages: stages.iter().map(|stage| stage.name()).collect(),
                us_per_substep: micros(seconds),
                // All zero (a clock too coarse for the passes): even shares.
                share: if total > 0.0 { seconds / total } else { 1.0 / passes.len() as f64 },
            })
            .collect();
        Some(Self {
            method: first.method.name(),
            wall_us_per_substep: micros(median(calls.iter().map(|call| call.wall_seconds))),
            note: first.note.clone(),
            parts,
        })
    }
}

/// The median of `values` (the upper one of an even count; 0 for none).
pub(crate) fn median(values: impl Iterator<Item = f64>) -> f64 {
    let mut values: Vec<f64> = values.collect();
    values.sort_by(f64::total_cmp);
    values.get(values.len() / 2).copied().unwrap_or(0.0)
}

/// Benchmark one backend over every size in `config`. `progress(done,
/// total)` counts timed runs, the stage-timed ones among them.
///
/// # Errors
/// [`GateError`] for a bad size or a backend failure, and
/// [`GateError::NoTimedRuns`] for `repeats` 0.
pub fn bench<B: Backend>(
    backend: &mut B,
    config: &BenchConfig,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<Vec<BenchRow>, GateError> {
    if config.repeats == 0 {
        return Err(GateError::NoTimedRuns);
    }
    let stage_calls = if config.stages { config.repeats } else { 0 };
    let total = (config.charts.len() * (config.repeats + stage_calls)) as u64;
    let mut done = 0;
    let mut count_one = || {
        done += 1;
        progress(done, total);
    };
    let mut rows = Vec::with_capacity(config.charts.len());
    for chart in &config.charts {
        let fabric = Fabric::from_chart(chart, &config.geometry)?;
        let nodes = fabric.node_count();
        let stitches = chart.width() * chart.height();
        backend.load(&fabric, &config.params)?;
        let pins: Vec<Pin> = if config.pin_top {
            let rest = fabric.positions();
            fabric.side_nodes(Side::Top).into_iter().map(|node| Pin { node, target: rest[node as usize] }).collect()
        } else {
            Vec::new()
        };
        backend.set_pins(&pins)?;
        let contacts = fabric.contacts().len();
        let alive_contacts = contacts - (config.dead.clamp(0.0, 1.0) * contacts as f64).round() as usize;
        backend.set_contacts_alive(&(0..contacts).map(|k| k < alive_contacts).collect::<Vec<_>>())?;
        // At least 50 substeps, so a huge fabric's run is not a handful of
        // substeps timed against the device waking up (on an H200, 4- and
        // 10-substep runs of 4M and 8M nodes varied 2-3x run to run).
        let substeps = (config.work_per_run / nodes as u64).max(50);
        // Warm-up: caches, the thread pool, and the release transient.
        backend.advance(config.settle.max(substeps / 4 + 1))?;
        let builds_before = backend.self_contact_builds();
        let reruns_before = backend.late_list_reruns();
        let mut times = Vec::with_capacity(config.repeats);
        for _ in 0..config.repeats {
            let start = Instant::now();
            backend.advance(substeps)?;
            times.push(start.elapsed().as_secs_f64());
            count_one();
        }
        let builds_per_1000 = builds_before.zip(backend.self_contact_builds()).map(|(before, after)| {
            1000.0 * after.saturating_sub(before) as f64 / (config.repeats as u64 * substeps) as f64
        });
        let late_reruns = reruns_before.zip(backend.late_list_reruns()).map(|(before, after)| after - before);
        let mut calls = Vec::with_capacity(stage_calls);
        for _ in 0..stage_calls {
            calls.push(backend.advance_timed(substeps)?);
            count_one();
        }
        times.sort_by(f64::total_cmp);
        let median_time = times[times.len() / 2];
        let per = |t: f64| t * 1e9 / (substeps as f64 * nodes as f64);
        let ns_per_node_substep = per(median_time);
        rows.push(BenchRow {
            backend: backend.name(),
            threads: backend.threads(),
            size: format!("{}x{}", chart.width(), chart.height()),
            stitches,
            nodes,
            contacts: fabric.contacts().len(),
            substeps,
            friction: config.params.friction,
            gravity: config.params.gravity,
            pins: pins.len(),
            dead_contacts: contacts - alive_contacts,
            sleep_speed: config.params.sleep_speed,
            ns_per_node_substep,
            ns_per_stitch_substep: ns_per_node_substep * nodes as f64 / stitches as f64,
            ns_min: per(times[0]),
            ns_max: per(times[times.len() - 1]),
            substeps_per_s: substeps as f64 / median_time,
            self_contact: config.params.self_contact_stiffness,
            builds_per_1000,
            late_reruns,
            self_contact_cost: None,
            stages: StageReport::median_of(&calls),
        });
    }
    Ok(rows)
}

/// The rows as a table, each row's scene (friction, gravity, pins) in its
/// last column.
pub fn table(rows: &[BenchRow]) -> String {
    let mut out = format!(
        "{:<16} {:>7} {:>7} {:>8} {:>7} {:>8} {:>14} {:>16} {:>15} {:>14}  scene\n",
        "backend",
        "threads",
        "size",
        "stitches",
        "nodes",
        "contacts",
        "ns/node-step",
        "(min..max)",
        "ns/stitch-step",
        "substeps/s"
    );
    for r in rows {
        out += &format!(
            "{:<16} {:>7} {:>7} {:>8} {:>7} {:>8} {:>14.2} {:>16} {:>15.2} {:>14.0}  μ={} g={} pins={} dead={} sleep={}\n",
            r.backend,
            r.threads,
            r.size,
            r.stitches,
            r.nodes,
            r.contacts,
            r.ns_per_node_substep,
            format!("({:.2}..{:.2})", r.ns_min, r.ns_max),
            r.ns_per_stitch_substep,
            r.substeps_per_s,
            r.friction,
            r.gravity,
            r.pins,
            r.dead_contacts,
            r.sleep_speed
        );
        if r.self_contact > 0.0 {
            out.pop();
            out += &format!(" k_sc={}", r.self_contact);
            if let Some(builds) = r.builds_per_1000 {
                out += &format!(" builds/1000={builds:.1}");
            }
            if let Some(reruns) = r.late_reruns {
                out += &format!(" late={reruns}");
            }
            if let Some(cost) = r.self_contact_cost {
                out += &format!(" cost={cost:.2}x");
            }
            out.push('\n');
        }
    }
    out
}

/// Set [`BenchRow::self_contact_cost`] of each row with self-contact on,
/// against the row without it of the same backend, threads and patch.
fn price_self_contact(rows: &mut [BenchRow]) {
    let same_patch = |a: &BenchRow, b: &BenchRow| (&a.backend, a.threads, &a.size) == (&b.backend, b.threads, &b.size);
    let off: Vec<BenchRow> = rows.iter().filter(|r| r.self_contact == 0.0).cloned().collect();
    for row in rows.iter_mut().filter(|r| r.self_contact > 0.0) {
        row.self_contact_cost =
            off.iter().find(|o| same_patch(o, row)).map(|o| row.ns_per_node_substep / o.ns_per_node_substep);
    }
}

/// The rows' stage reports as tables, one block per backend and size
/// (empty when no row has one).
pub fn stages_table(rows: &[BenchRow]) -> String {
    let mut out = String::new();
    for row in rows {
        let Some(stages) = &row.stages else { continue };
        let _ = writeln!(
            out,
            "\nstages of {} at {} ({} nodes), by {}; the timed call took {:.3} µs a substep",
            row.backend, row.size, row.nodes, stages.method, stages.wall_us_per_substep
        );
        let _ = writeln!(out, "  {:<18} {:<40} {:>12} {:>7}", "pass", "stages", "µs/substep", "share");
        for part in &stages.parts {
            let _ = writeln!(
                out,
                "  {:<18} {:<40} {:>12.3} {:>6.1}%",
                part.pass,
                part.stages.join("+"),
                part.us_per_substep,
                100.0 * part.share
            );
        }
        if let Some(note) = &stages.note {
            let _ = writeln!(out, "  note: {note}");
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use yarn_model::Stage;
    use yarn_model::stages::{StagePart, TimingMethod};

    /// A call of 100 substeps that took `wall` s, with a forces pass of
    /// `forces` s, a fused pass, and a pins pass of `pins` s if it ran.
    fn call(forces: f64, pins: Option<f64>, wall: f64) -> StageTimes {
        let part = |pass, stages: &[Stage], seconds| StagePart { pass, stages: stages.to_vec(), seconds };
        let mut parts = vec![
            part("block forces", &[Stage::Forces], forces),
            part("block forces", &[Stage::Forces, Stage::Move], 1e-3),
        ];
        parts.extend(pins.map(|seconds| part("pins", &[Stage::Pins], seconds)));
        StageTimes { substeps: 100, method: TimingMethod::CpuTimers, parts, wall_seconds: wall, note: Some("n".into()) }
    }

    #[test]
    fn stage_medians_are_taken_per_pass_and_their_shares_sum_to_one() {
        assert_eq!(StageReport::median_of(&[]), None);
        let calls = [call(1e-3, Some(1e-4), 5e-3), call(3e-3, None, 4e-3), call(2e-3, Some(3e-4), 6e-3)];
        let report = StageReport::median_of(&calls).expect("three calls");
        assert_eq!(report.method, "cpu timers");
        assert_eq!(report.note.as_deref(), Some("n"));
        assert!((report.wall_us_per_substep - 50.0).abs() < 1e-9, "{report:?}");
        let passes: Vec<(&str, String)> = report.parts.iter().map(|p| (p.pass, p.stages.join("+"))).collect();
        assert_eq!(
            passes,
            [("block forces", "forces".into()), ("block forces", "forces+move".into()), ("pins", "pins".into())],
            "a pass under two stage sets is two parts"
        );
        // Medians of (1, 3, 2) ms, (1, 1, 1) ms, and (0.1, 0, 0.3) ms: a
        // pass missing from a call took no time in it.
        let micros: Vec<f64> = report.parts.iter().map(|p| p.us_per_substep).collect();
        for (got, want) in micros.iter().zip([20.0, 10.0, 1.0]) {
            assert!((got - want).abs() < 1e-9, "{micros:?}");
        }
        let shares: f64 = report.parts.iter().map(|p| p.share).sum();
        assert!((shares - 1.0).abs() < 1e-12 && (report.parts[0].share - 20.0 / 31.0).abs() < 1e-12);
    }

    /// A row's per-stitch cost is its per-node cost times the nodes a
    /// stitch has, in either geometry, and the table shows both.
    #[test]
    fn rows_count_stitches_and_their_cost_follows_from_the_nodes() {
        let chart = Pattern::Rib1x1.chart(4, 3).unwrap();
        for (geometry, chart) in
            [(Geometry::default(), chart), (Geometry::paper(), Pattern::Stockinette.chart(3, 2).unwrap())]
        {
            let config = BenchConfig {
                charts: vec![chart.clone()],
                geometry,
                repeats: 1,
                work_per_run: 2_000,
                ..BenchConfig::default()
            };
            let no_runs = BenchConfig { repeats: 0, ..config.clone() };
            let refused = bench(&mut yarn_backend_cpu::Serial::<f32>::new(), &no_runs, &mut |_, _| {});
            assert_eq!(refused, Err(GateError::NoTimedRuns));
            let rows = bench(&mut yarn_backend_cpu::Serial::<f32>::new(), &config, &mut |_, _| {}).unwrap();
            let [row] = rows.as_slice() else { panic!("one chart, one row: {rows:?}") };
            assert_eq!(row.stitches, chart.width() * chart.height());
            assert_eq!(row.size, format!("{}x{}", chart.width(), chart.height()));
            let expected = row.ns_per_node_substep * row.nodes as f64 / row.stitches as f64;
            assert!(row.ns_per_stitch_substep > 0.0, "{row:?}");
            assert!((row.ns_per_stitch_substep - expected).abs() <= 1e-12 * expected, "{row:?}");
            let text = table(&rows);
            assert!(text.contains("stitches") && text.contains("ns/stitch-step"), "{text}");
            let json = serde_json::to_value(row).unwrap();
            assert_eq!(json["stitches"], row.stitches);
            assert!(json.get("ns_per_stitch_substep").is_some() && json.get("ns_per_node_substep").is_some());
        }
    }

    /// A 3x3 row of `backend`, 1 ns a node-substep unless set otherwise.
    fn row(backend: &str, stages: Option<StageReport>) -> BenchRow {
        BenchRow {
            backend: backend.into(),
            threads: 1,
            size: "3x3".into(),
            stitches: 9,
            nodes: 72,
            contacts: 12,
            substeps: 100,
            friction: 0.3,
            gravity: 0.0,
            pins: 0,
            dead_contacts: 0,
            sleep_speed: 0.0,
            ns_per_node_substep: 1.0,
            ns_per_stitch_substep: 8.0,
            ns_min: 1.0,
            ns_max: 1.0,
            substeps_per_s: 1.0,
            self_contact: 0.0,
            builds_per_1000: None,
            late_reruns: None,
            self_contact_cost: None,
            stages,
        }
    }

    #[test]
    fn the_stage_table_has_a_block_per_row_that_has_stages() {
        let row = |stages| row("serial-f32", stages);
        assert_eq!(stages_table(&[row(None)]), "");
        let text = stages_table(&[row(StageReport::median_of(&[call(1e-3, Some(1e-4), 5e-3)])), row(None)]);
        assert_eq!(text.matches("stages of serial-f32 at 3x3 (72 nodes), by cpu timers").count(), 1, "{text}");
        assert!(text.contains("forces+move") && text.contains("  note: n\n"), "{text}");
        let without = serde_json::to_value(row(None)).expect("serialises");
        assert!(without.get("stages").is_none(), "{without}");
    }

    /// A row with self-contact is priced against the row without it of
    /// the same backend and patch, and only where the run timed one.
    #[test]
    fn self_contact_is_priced_against_the_same_patch_without_it() {
        let timed = |backend: &str, size: &str, self_contact: f64, ns: f64| BenchRow {
            size: size.into(),
            self_contact,
            ns_per_node_substep: ns,
            ..row(backend, None)
        };
        let mut rows = vec![
            timed("rayon", "3x3", 0.0, 2.0),
            timed("rayon", "3x3", 1600.0, 5.0),
            timed("rayon", "4x4", 0.0, 4.0),
            timed("rayon", "4x4", 800.0, 6.0),
            timed("serial-f32", "3x3", 1600.0, 9.0),
        ];
        price_self_contact(&mut rows);
        let costs: Vec<Option<f64>> = rows.iter().map(|r| r.self_contact_cost).collect();
        assert_eq!(costs, [None, Some(2.5), None, Some(1.5), None], "no serial-f32 row without self-contact");
        let text = table(&rows);
        assert_eq!(text.matches(" cost=").count(), 2, "{text}");
        assert!(text.contains("k_sc=1600 cost=2.50x") && text.contains("k_sc=800 cost=1.50x"), "{text}");
        let json = serde_json::to_value(&rows).expect("serialises");
        assert_eq!(json[1]["self_contact_cost"], 2.5);
        assert!(json[0].get("self_contact_cost").is_none(), "{}", json[0]);
    }
}
