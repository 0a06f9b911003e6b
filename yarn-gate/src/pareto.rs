//! `yarn-gate pareto`: run time against error. Four reference problems are
//! each solved by `Serial<f64>` at a small substep (the reference) and by
//! every configuration (backend × precision × substep h × accumulation
//! mode); each configuration's wall time per simulated second is set
//! against its position and energy error from the reference at matched
//! simulated times, and the Pareto front of the two is marked.
//!
//! Every problem is driven on a fixed control clock ([`CONTROL`]): pins
//! move, and states are compared, only at control ticks, so every substep
//! h = CONTROL / n meets them exactly.
//!
//! This module owns the problems, the sweep over configurations, the front,
//! the recommendation, their table, CSV and plot, and the command
//! ([`ParetoArgs`]). How the plot is drawn is the `plot` module's, and it
//! knows a backend only through [`Backend`].

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use indicatif::ProgressBar;
use nalgebra::Vector3;
use plotters::prelude::*;
use serde::Serialize;
use yarn_backend_cpu::Serial;
use yarn_backend_wgpu::GpuError;
use yarn_model::{Backend, Params};
use yarn_topology::{Chart, Fabric, Geometry, Pin, Side};

use crate::GateError;
use crate::backends::{BackendWork, for_each_backend, left_out_warning};
use crate::bench::median;
use crate::cli::{
    Outcome, PATTERN_HELP, PatternArg, parse_pattern, parse_repeats, parse_seconds, parse_size, parse_substeps,
    with_bar,
};
use crate::plot::{PanelAxes, canvas, distinct, log_log_panel, panel_legend, plot_error};
use crate::preset::Preset;

/// `yarn-gate pareto`: every configuration on every problem, against the
/// reference.
#[derive(Debug, clap::Args)]
pub struct ParetoArgs {
    /// Backends, comma-separated; GPU ones are left out, with a warning,
    /// when there is no adapter.
    #[arg(long, value_delimiter = ',', default_value = "serial-f64,serial-f32,rayon,wgpu,wgpu-fixed")]
    backend: Vec<String>,
    /// The model every problem starts from (each sets its own substep and
    /// gravity): `default` (the default parameters on interlooped loops)
    /// or `paper` (the paper's parameters on its 8-node arch, which knits
    /// no purl).
    #[arg(long, value_enum, default_value_t = Preset::Default)]
    preset: Preset,
    #[arg(long, default_value = "stockinette", value_parser = parse_pattern, help = PATTERN_HELP)]
    pattern: PatternArg,
    /// Patch size in stitches, WIDTHxHEIGHT (unused with a chart file
    /// --pattern).
    #[arg(long, default_value = "16x16", value_parser = parse_size)]
    size: (usize, usize),
    /// Simulated seconds per problem.
    #[arg(long, default_value_t = 1.0, value_parser = parse_seconds, allow_negative_numbers = true)]
    duration: f64,
    /// Substeps per 1/150 s control tick to try, comma-separated: h =
    /// 1/(150 N) s, so 10 is the paper's 1/1500.
    #[arg(long, value_delimiter = ',', default_value = "2,3,5,10,20,40", value_parser = parse_substeps)]
    substeps: Vec<u32>,
    /// Timed runs per configuration; the median wall time is reported.
    #[arg(long, default_value_t = 3, value_parser = parse_repeats)]
    repeats: usize,
    /// Self-contact stiffness k_sc of the model [default: the preset's].
    /// With it on, the reference runs with it, and every configuration
    /// also runs without it (its backend named `… no self-contact`), so
    /// the table sets what self-contact costs against the error its
    /// absence makes.
    #[arg(long)]
    self_contact: Option<f64>,
    /// Friction coefficient μ of the model, persistent contacts and
    /// self-contact alike; 0 turns friction off [default: the preset's,
    /// 0.3].
    #[arg(long)]
    friction: Option<f64>,
    /// Folder for pareto.csv and pareto.png (created if missing).
    #[arg(long, default_value = "pareto")]
    out: PathBuf,
    /// Print one JSON object (rows, recommended, reference_self_error)
    /// instead of the table.
    #[arg(long)]
    json: bool,
}

/// Checkpoints a run is compared at, evenly spaced over its ticks.
const CHECKPOINTS: u32 = 4;

impl ParetoArgs {
    /// Solve the references, sweep every configuration, mark each
    /// problem's front and the recommendation, and write the CSV and plot.
    ///
    /// # Errors
    /// A bad size, a chart file that cannot be read or parsed, a purl
    /// stitch with `--preset paper`, an unknown backend, a backend failure
    /// other than a refused substep, or a file that cannot be written.
    pub fn run(&self) -> Result<Outcome, GateError> {
        let patch =
            Patch { chart: self.pattern.chart(self.size)?, geometry: self.preset.geometry(), params: self.params() };
        // A chart the geometry cannot knit fails here, before any run.
        Fabric::from_chart(&patch.chart, &patch.geometry)?;
        let patch = &patch;
        let ticks = (self.duration / CONTROL).round().max(1.0) as u32;
        let runs = Problem::ALL.len() * REFERENCE_SUBSTEPS.len() + self.backend.len() * self.runs_per_backend();
        let (reference_self_error, mut rows) =
            with_bar(runs as u64, "{msg:>24} [{bar:40}] {pos}/{len} runs ({eta})", "", |bar| {
                let (references, reference_self_error) = self.references(patch, ticks, bar)?;
                let mut sweep = Sweep { args: self, patch, references: &references, ticks, bar };
                let rows = for_each_backend(&self.backend, 0, &mut sweep)?.concat();
                Ok::<_, GateError>((reference_self_error, rows))
            })?;
        mark_front(&mut rows);
        let recommended = recommend(&mut rows);
        let written = write(&self.out, &rows)?.iter().map(|p| p.display().to_string()).collect();
        let report = ParetoReport { rows, recommended, reference_self_error, written };
        Ok(Outcome::json_or(&report, self.json, || report.text()))
    }

    /// The model every problem starts from: the preset's, with
    /// `--self-contact` and `--friction` where given.
    fn params(&self) -> Params {
        let preset = self.preset.params();
        Params {
            self_contact_stiffness: self.self_contact.unwrap_or(preset.self_contact_stiffness),
            friction: self.friction.unwrap_or(preset.friction),
            ..preset
        }
    }

    /// Timed runs per backend: each substep on each problem, `repeats`
    /// times.
    fn runs_per_backend(&self) -> usize {
        let variants = if self.self_contact.is_some_and(|k| k > 0.0) { 2 } else { 1 };
        Problem::ALL.len() * self.substeps.len() * self.repeats * variants
    }

    /// Each problem's reference run, and how far the reference is from
    /// itself at half its substep.
    fn references(
        &self,
        patch: &Patch,
        ticks: u32,
        bar: &ProgressBar,
    ) -> Result<(Vec<Run>, BTreeMap<&'static str, f64>), GateError> {
        let radius = patch.geometry.yarn_radius;
        let mut references = Vec::new();
        let mut self_error = BTreeMap::new();
        for problem in Problem::ALL {
            bar.set_message(format!("reference {}", problem.name()));
            let [coarse, fine] =
                REFERENCE_SUBSTEPS.map(|n| run(&mut Serial::<f64>::new(), problem, patch, ticks, n, CHECKPOINTS));
            let (coarse, fine) = (coarse?, fine?);
            bar.inc(REFERENCE_SUBSTEPS.len() as u64);
            self_error.insert(problem.name(), errors(&coarse, &fine, radius).0);
            references.push(coarse);
        }
        Ok((references, self_error))
    }
}

/// What `pareto` reports (its JSON).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ParetoReport {
    /// Every configuration on every problem, front and recommendation
    /// marked.
    pub rows: Vec<ParetoRow>,
    /// The recommended configuration ([`recommend`]), if any is accurate
    /// everywhere.
    pub recommended: Option<String>,
    /// Per problem, the largest position difference, in yarn radii,
    /// between the reference and the same run at half its substep.
    pub reference_self_error: BTreeMap<&'static str, f64>,
    /// The files written.
    pub written: Vec<String>,
}

impl ParetoReport {
    /// The table, the reference's self-consistency, the recommendation and
    /// the files written.
    pub fn text(&self) -> String {
        let mut out = table(&self.rows);
        let self_error: Vec<String> =
            self.reference_self_error.iter().map(|(problem, error)| format!("{problem} {error:.1e}")).collect();
        let _ = writeln!(
            out,
            "reference: serial-f64 at h=1/{:.0}; against h=1/{:.0} it differs by at most (r): {}",
            150.0 * f64::from(REFERENCE_SUBSTEPS[0]),
            150.0 * f64::from(REFERENCE_SUBSTEPS[1]),
            self_error.join(", ")
        );
        let _ = match &self.recommended {
            Some(config) => writeln!(out, "recommended (fastest within {ACCURACY} r everywhere): {config}"),
            None => writeln!(out, "no configuration is within {ACCURACY} r on every problem"),
        };
        for path in &self.written {
            let _ = writeln!(out, "wrote {path}");
        }
        out
    }
}

/// Every configuration of one backend on every problem.
struct Sweep<'a> {
    args: &'a ParetoArgs,
    patch: &'a Patch,
    /// Each problem's reference, in [`Problem::ALL`] order.
    references: &'a [Run],
    ticks: u32,
    /// The whole command's bar, across backends.
    bar: &'a ProgressBar,
}

impl BackendWork for Sweep<'_> {
    type Output = Vec<ParetoRow>;

    fn run<B: Backend>(&mut self, name: &str, mut backend: B) -> Result<Vec<ParetoRow>, GateError> {
        let sim_seconds = CONTROL * f64::from(self.ticks);
        let mut rows = Vec::new();
        // With self-contact on, each configuration also runs without it.
        let without =
            Patch { params: Params { self_contact_stiffness: 0.0, ..self.patch.params }, ..self.patch.clone() };
        let off_name = format!("{name} no self-contact");
        let mut variants = vec![(self.patch, name)];
        if self.patch.params.self_contact_stiffness > 0.0 {
            variants.push((&without, off_name.as_str()));
        }
        for (patch, name) in variants {
            rows.extend(self.sweep(&mut backend, patch, name, sim_seconds)?);
        }
        Ok(rows)
    }

    fn left_out(&mut self, name: &str, reason: &GpuError) {
        self.bar.suspend(|| eprintln!("{}", left_out_warning(name, reason)));
        self.bar.inc(self.args.runs_per_backend() as u64);
    }
}

impl Sweep<'_> {
    /// Every substep on every problem of `patch` on `backend`, its rows
    /// named `name`.
    fn sweep<B: Backend>(
        &self,
        backend: &mut B,
        patch: &Patch,
        name: &str,
        sim_seconds: f64,
    ) -> Result<Vec<ParetoRow>, GateError> {
        let mut rows = Vec::new();
        for &per_tick in &self.args.substeps {
            let h = CONTROL / f64::from(per_tick);
            for (problem, reference) in Problem::ALL.into_iter().zip(self.references) {
                self.bar.set_message(format!("{name} {}", problem.name()));
                let mut runs = Vec::new();
                for _ in 0..self.args.repeats {
                    runs.push(match run(backend, problem, patch, self.ticks, per_tick, CHECKPOINTS) {
                        Ok(measured) => measured,
                        // An h the parameters refuse: a failed configuration.
                        Err(GateError::Backend(e)) => Run::failed(e.to_string()),
                        Err(e) => return Err(e),
                    });
                    self.bar.inc(1);
                }
                let wall_s_per_sim_s = median(runs.iter().map(|repeat| repeat.wall_s)) / sim_seconds;
                if let Some(last) = runs.pop() {
                    let radius = patch.geometry.yarn_radius;
                    rows.push(ParetoRow::new(problem, name, h, wall_s_per_sim_s, last, reference, radius));
                }
            }
        }
        Ok(rows)
    }
}

/// The control interval in simulated seconds: pins move and states are
/// compared on this clock. The paper's h = 1/1500 s is 10 substeps a tick.
pub const CONTROL: f64 = 1.0 / 150.0;

/// Substeps per control tick of the configurations measured: h = 1/300 s
/// to 1/6000 s.
pub const SUBSTEPS_PER_TICK: [u32; 6] = [2, 3, 5, 10, 20, 40];

/// Substeps per tick of the reference (h = 1/24000 s, the paper's h / 16),
/// and of the run at half its substep that it is checked against.
pub const REFERENCE_SUBSTEPS: [u32; 2] = [160, 320];

/// A position error above this many yarn radii counts as inaccurate when
/// choosing the recommended configuration.
pub const ACCURACY: f64 = 0.1;

/// A run this many yarn radii or more from the reference has diverged: it
/// counts as failed.
pub const DIVERGED: f64 = 1e3;

/// The patch every problem is posed on.
#[derive(Debug, Clone, PartialEq)]
pub struct Patch {
    /// Its stitches.
    pub chart: Chart,
    /// The geometry they are knitted in.
    pub geometry: Geometry,
    /// The model each problem starts from; the problem sets the substep
    /// and gravity ([`Problem::params`]).
    pub params: Params,
}

/// The reference problems.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Problem {
    /// The patch released from its assembled shape, free.
    Relax,
    /// The left and right columns gripped and pulled 10 % apart along the
    /// course over the first half, then held.
    Pull,
    /// The head of the centre stitch grabbed and drawn out of the fabric by
    /// 3 stitch widths over the first half, then held.
    Snag,
    /// The top row held and the patch left to hang under gravity.
    Drape,
}

impl Problem {
    /// Every problem, in report order.
    pub const ALL: [Problem; 4] = [Problem::Relax, Problem::Pull, Problem::Snag, Problem::Drape];

    /// Its name in tables and file names.
    pub fn name(self) -> &'static str {
        match self {
            Problem::Relax => "relax",
            Problem::Pull => "pull",
            Problem::Snag => "snag",
            Problem::Drape => "drape",
        }
    }

    /// Its parameters at substep `h`: `model`'s, with gravity only when
    /// draping.
    pub fn params(self, model: &Params, h: f64) -> Params {
        let gravity = if self == Problem::Drape { 9.81 } else { 0.0 };
        Params { substep: h, gravity, ..*model }
    }

    /// The pins at simulated time `t` of a run lasting `duration`, on
    /// `fabric` knitted in `geometry`.
    fn pins(self, fabric: &Fabric, geometry: &Geometry, t: f64, duration: f64) -> Vec<Pin> {
        let rest = fabric.positions();
        let ramp = (2.0 * t / duration).min(1.0);
        let held = |side| fabric.side_nodes(side).into_iter();
        match self {
            Problem::Relax => Vec::new(),
            Problem::Pull => {
                let (left, right) = (held(Side::Left), held(Side::Right));
                let course = fabric.course();
                let width = right.clone().map(|i| rest[i as usize].dot(&course)).fold(f64::MIN, f64::max)
                    - left.clone().map(|i| rest[i as usize].dot(&course)).fold(f64::MAX, f64::min);
                let pull = course * (0.1 * width * ramp);
                left.map(|node| Pin { node, target: rest[node as usize] })
                    .chain(right.map(|node| Pin { node, target: rest[node as usize] + pull }))
                    .collect()
            }
            Problem::Snag => {
                let Some((w, h)) = fabric.grid() else { return Vec::new() };
                let Some(node) = fabric.head_node(w / 2, h / 2) else { return Vec::new() };
                let out = fabric.course().cross(&fabric.wale());
                let reach = 3.0 * geometry.stitch_width * ramp;
                vec![Pin { node: node as u32, target: rest[node] + out * reach }]
            }
            Problem::Drape => held(Side::Top).map(|node| Pin { node, target: rest[node as usize] }).collect(),
        }
    }
}

/// What was measured of one run of one problem: the states and energies at
/// each checkpoint, and the wall time spent advancing.
#[derive(Debug, Clone)]
pub struct Run {
    /// Positions at each checkpoint, in f64.
    pub checkpoints: Vec<Vec<Vector3<f64>>>,
    /// Total energy at each checkpoint.
    pub energies: Vec<f64>,
    /// Wall seconds spent in `advance` and in setting pins.
    pub wall_s: f64,
    /// The run stopped early: a non-finite state or a backend error.
    pub failure: Option<String>,
}

impl Run {
    /// A run that could not start, for `reason`: infinitely slow and
    /// infinitely wrong.
    pub fn failed(reason: String) -> Self {
        Self { checkpoints: Vec::new(), energies: Vec::new(), wall_s: f64::INFINITY, failure: Some(reason) }
    }
}

/// Run `problem` on `patch` for `ticks` control ticks at `per_tick`
/// substeps a tick, reading the state at `checkpoints` evenly spaced ticks.
///
/// # Errors
/// The patch cannot be built or the parameters are refused (an h above the
/// stability bound).
pub fn run<B: Backend>(
    backend: &mut B,
    problem: Problem,
    patch: &Patch,
    ticks: u32,
    per_tick: u32,
    checkpoints: u32,
) -> Result<Run, GateError> {
    let fabric = Fabric::from_chart(&patch.chart, &patch.geometry)?;
    let params = problem.params(&patch.params, CONTROL / f64::from(per_tick));
    backend.load(&fabric, &params)?;
    let duration = CONTROL * f64::from(ticks);
    let mut out = Run { checkpoints: Vec::new(), energies: Vec::new(), wall_s: 0.0, failure: None };
    let every = (ticks / checkpoints.max(1)).max(1);
    for tick in 0..ticks {
        let start = Instant::now();
        let advanced = backend
            .set_pins(&problem.pins(&fabric, &patch.geometry, CONTROL * f64::from(tick), duration))
            .and_then(|()| backend.advance(u64::from(per_tick)));
        out.wall_s += start.elapsed().as_secs_f64();
        if let Err(e) = advanced {
            out.failure = Some(e.to_string());
            break;
        }
        if (tick + 1) % every == 0 {
            let (energy, state) = backend.measure(&fabric)?;
            if state.positions.iter().chain(&state.velocities).any(|p| !p.iter().all(|c| c.is_finite())) {
                out.failure = Some(format!("the state is not finite at tick {}", tick + 1));
                break;
            }
            out.energies.push(energy.total());
            out.checkpoints.push(state.positions);
        }
    }
    Ok(out)
}

/// How far `run` is from `reference`, in yarn radii, over their common
/// checkpoints: the largest and the root-mean-square node distance, and
/// the largest energy difference relative to the reference's energy at
/// that checkpoint. All infinite for a run that failed or diverged
/// ([`DIVERGED`]).
pub fn errors(run: &Run, reference: &Run, radius: f64) -> (f64, f64, f64) {
    if run.failure.is_some() || run.checkpoints.len() < reference.checkpoints.len() {
        return (f64::INFINITY, f64::INFINITY, f64::INFINITY);
    }
    let (mut max, mut sum, mut count, mut energy) = (0.0f64, 0.0, 0usize, 0.0f64);
    for (k, (mine, theirs)) in run.checkpoints.iter().zip(&reference.checkpoints).enumerate() {
        for (p, q) in mine.iter().zip(theirs) {
            let d = (p - q).norm() / radius;
            max = max.max(d);
            sum += d * d;
            count += 1;
        }
        energy = energy.max((run.energies[k] - reference.energies[k]).abs() / reference.energies[k].abs().max(1e-300));
    }
    if max >= DIVERGED {
        return (f64::INFINITY, f64::INFINITY, f64::INFINITY);
    }
    (max, (sum / count.max(1) as f64).sqrt(), energy)
}

/// One configuration's result on one problem.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ParetoRow {
    /// The problem.
    pub problem: Problem,
    /// `backend h=1/N`, e.g. `serial-f32 h=1/1500`.
    pub config: String,
    /// The backend (precision and accumulation mode are in its name).
    pub backend: String,
    /// The substep h in seconds.
    pub h: f64,
    /// Wall seconds per simulated second (median over the repeats).
    pub wall_s_per_sim_s: f64,
    /// Largest node distance from the reference over the checkpoints, in
    /// yarn radii.
    pub pos_err_max: f64,
    /// Root-mean-square node distance from the reference, in yarn radii.
    pub pos_err_rms: f64,
    /// Largest relative energy difference from the reference.
    pub energy_err: f64,
    /// No configuration is both faster and more accurate (by
    /// `pos_err_max`).
    pub on_front: bool,
    /// The recommended configuration ([`recommend`]).
    pub recommended: bool,
    /// Why the run stopped early, if it did.
    pub failure: Option<String>,
}

impl ParetoRow {
    /// `backend`'s row at substep `h` on `problem`: `run` (its last repeat)
    /// measured against `reference` by [`errors`] in yarn radii of
    /// `radius`, beside its median wall seconds per simulated second. A
    /// run beyond [`DIVERGED`] is a failure. Neither on the front nor
    /// recommended until [`mark_front`] and [`recommend`] say so.
    pub fn new(
        problem: Problem,
        backend: &str,
        h: f64,
        wall_s_per_sim_s: f64,
        run: Run,
        reference: &Run,
        radius: f64,
    ) -> Self {
        let (pos_err_max, pos_err_rms, energy_err) = errors(&run, reference, radius);
        let failure =
            run.failure.or_else(|| (!pos_err_max.is_finite()).then(|| format!("diverged: beyond {DIVERGED} r")));
        Self {
            problem,
            config: config_name(backend, h),
            backend: backend.to_owned(),
            h,
            wall_s_per_sim_s,
            pos_err_max,
            pos_err_rms,
            energy_err,
            on_front: false,
            recommended: false,
            failure,
        }
    }
}

/// The configuration label of `backend` at `h`.
pub fn config_name(backend: &str, h: f64) -> String {
    format!("{backend} h=1/{:.0}", 1.0 / h)
}

/// How much faster a configuration must be (as a fraction of wall time)
/// to beat another of no worse accuracy: differences smaller than this are
/// within the run-to-run noise of a shared machine and count as ties.
pub const WALL_MARGIN: f64 = 0.10;

/// How much more accurate (as a fraction of `pos_err_max`) a configuration
/// must be to beat another that is no slower, beyond the wall margin.
pub const ERROR_MARGIN: f64 = 0.05;

/// Whether `o` beats `r`: clearly faster and no less accurate (within the
/// error margin), or clearly more accurate and no slower (within the wall
/// margin). Ties within both margins beat neither.
fn beats(o: &ParetoRow, r: &ParetoRow) -> bool {
    let faster = o.wall_s_per_sim_s <= r.wall_s_per_sim_s * (1.0 - WALL_MARGIN);
    let no_slower = o.wall_s_per_sim_s <= r.wall_s_per_sim_s * (1.0 + WALL_MARGIN);
    let more_accurate = o.pos_err_max <= r.pos_err_max * (1.0 - ERROR_MARGIN);
    let no_less_accurate = o.pos_err_max <= r.pos_err_max * (1.0 + ERROR_MARGIN);
    o.pos_err_max.is_finite() && ((faster && no_less_accurate) || (more_accurate && no_slower))
}

/// Mark each row that no other row of the same problem beats: none is
/// faster by [`WALL_MARGIN`] at no worse accuracy, or more accurate by
/// [`ERROR_MARGIN`] at no greater cost. Failed runs are never on the front.
pub fn mark_front(rows: &mut [ParetoRow]) {
    let beaten: Vec<bool> = rows
        .iter()
        .map(|r| !r.pos_err_max.is_finite() || rows.iter().any(|o| o.problem == r.problem && beats(o, r)))
        .collect();
    for (row, beaten) in rows.iter_mut().zip(beaten) {
        row.on_front = !beaten;
    }
}

/// The recommended configuration: of those within [`ACCURACY`] on every
/// problem, the one with the least total wall time. Marks its rows and
/// returns its name, or `None` if no configuration is accurate everywhere.
/// Being the fastest accurate one on each problem's sum, it is on every
/// problem's front unless another configuration is both faster and more
/// accurate there, which the report then shows.
pub fn recommend(rows: &mut [ParetoRow]) -> Option<String> {
    let mut configs: Vec<&str> = rows.iter().map(|r| r.config.as_str()).collect();
    configs.sort_unstable();
    configs.dedup();
    let best = configs
        .into_iter()
        .filter(|c| rows.iter().filter(|r| r.config == *c).all(|r| r.pos_err_max <= ACCURACY))
        .map(|c| (c, rows.iter().filter(|r| r.config == c).map(|r| r.wall_s_per_sim_s).sum::<f64>()))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(c, _)| c.to_owned())?;
    for row in rows.iter_mut() {
        row.recommended = row.config == best;
    }
    Some(best)
}

/// The rows as a table, one block per problem, fastest first.
pub fn table(rows: &[ParetoRow]) -> String {
    let mut out = String::new();
    for problem in Problem::ALL {
        let mut mine: Vec<&ParetoRow> = rows.iter().filter(|r| r.problem == problem).collect();
        if mine.is_empty() {
            continue;
        }
        mine.sort_by(|a, b| a.wall_s_per_sim_s.total_cmp(&b.wall_s_per_sim_s));
        let _ = writeln!(
            out,
            "{:<6} {:<44} {:>12} {:>12} {:>12} {:>11}  front",
            problem.name(),
            "config",
            "wall s/sim s",
            "pos err max",
            "pos err rms",
            "energy err"
        );
        for r in mine {
            let mark = match (r.on_front, r.recommended) {
                (true, true) => "yes  <- recommended",
                (false, true) => "no   <- recommended",
                (true, false) => "yes",
                (false, false) => "",
            };
            let _ = writeln!(
                out,
                "{:<6} {:<44} {:>12.4} {:>12.3e} {:>12.3e} {:>11.2e}  {mark}{}",
                "",
                r.config,
                r.wall_s_per_sim_s,
                r.pos_err_max,
                r.pos_err_rms,
                r.energy_err,
                r.failure.as_deref().map(|f| format!(" (failed: {f})")).unwrap_or_default()
            );
        }
        out.push('\n');
    }
    out
}

/// Write `pareto.csv` and `pareto.png` (one panel per problem: wall time
/// against position error, log-log, each backend in its own colour, the
/// front joined, the recommended configuration ringed) into `dir`.
///
/// # Errors
/// When a file cannot be written or the plot cannot be drawn.
pub fn write(dir: &Path, rows: &[ParetoRow]) -> Result<[PathBuf; 2], GateError> {
    std::fs::create_dir_all(dir).map_err(|e| GateError::io(dir, e))?;
    let csv_path = dir.join("pareto.csv");
    std::fs::write(&csv_path, csv(rows)).map_err(|e| GateError::io(&csv_path, e))?;
    let png_path = dir.join("pareto.png");
    plot(&png_path, rows)?;
    Ok([csv_path, png_path])
}

/// The rows as `pareto.csv`: one line per row after the header.
pub fn csv(rows: &[ParetoRow]) -> String {
    let mut csv = String::from(
        "problem,config,backend,h,wall_s_per_sim_s,pos_err_max,pos_err_rms,energy_err,on_front,recommended\n",
    );
    for r in rows {
        let _ = writeln!(
            csv,
            "{},{},{},{},{},{},{},{},{},{}",
            r.problem.name(),
            r.config,
            r.backend,
            r.h,
            r.wall_s_per_sim_s,
            r.pos_err_max,
            r.pos_err_rms,
            r.energy_err,
            r.on_front,
            r.recommended
        );
    }
    csv
}

fn plot(path: &Path, rows: &[ParetoRow]) -> Result<(), GateError> {
    let fail = |e: &dyn std::fmt::Display| plot_error(path, e);
    let root = canvas(path, (1280, 960))?;
    let backends = distinct(rows.iter().map(|r| r.backend.as_str()));
    let colour = |backend: &str| Palette99::pick(backends.iter().position(|b| *b == backend).unwrap_or(0)).to_rgba();
    for (panel, problem) in root.split_evenly((2, 2)).iter().zip(Problem::ALL) {
        let mine: Vec<&ParetoRow> =
            rows.iter().filter(|r| r.problem == problem && r.pos_err_max.is_finite() && r.pos_err_max > 0.0).collect();
        if mine.is_empty() {
            continue;
        }
        let span = |f: &dyn Fn(&ParetoRow) -> f64| {
            let (lo, hi) = mine.iter().map(|r| f(r)).fold((f64::MAX, f64::MIN), |(l, h), v| (l.min(v), h.max(v)));
            (lo / 1.5)..(hi * 1.5)
        };
        let axes = PanelAxes {
            caption: format!("{}: wall time against error", problem.name()),
            labels: ("wall s per simulated s", "max position error (r)"),
            ticks: 8,
            x_format: |v| format!("{v:.2e}"),
        };
        let mut chart = log_log_panel(panel, path, &axes, span(&|r| r.wall_s_per_sim_s), span(&|r| r.pos_err_max))?;
        let mut front: Vec<(f64, f64)> =
            mine.iter().filter(|r| r.on_front).map(|r| (r.wall_s_per_sim_s, r.pos_err_max)).collect();
        front.sort_by(|a, b| a.0.total_cmp(&b.0));
        chart.draw_series(LineSeries::new(front, BLACK.mix(0.5).stroke_width(2))).map_err(|e| fail(&e))?;
        for backend in &backends {
            let c = colour(backend);
            chart
                .draw_series(
                    mine.iter()
                        .filter(|r| r.backend == *backend)
                        .map(|r| Circle::new((r.wall_s_per_sim_s, r.pos_err_max), 5, c.filled())),
                )
                .map_err(|e| fail(&e))?
                .label(*backend)
                .legend(move |(x, y)| Circle::new((x + 10, y), 5, c.filled()));
        }
        chart
            .draw_series(
                mine.iter()
                    .filter(|r| r.recommended)
                    .map(|r| Circle::new((r.wall_s_per_sim_s, r.pos_err_max), 11, BLACK.stroke_width(2))),
            )
            .map_err(|e| fail(&e))?
            .label("recommended")
            .legend(|(x, y)| Circle::new((x + 10, y), 7, BLACK.stroke_width(2)));
        panel_legend(&mut chart, path)?;
    }
    root.present().map_err(|e| fail(&e))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    /// `pareto`'s arguments alone, as the binary parses them.
    #[derive(Debug, Parser)]
    struct Pareto {
        #[command(flatten)]
        args: ParetoArgs,
    }

    fn params(args: &[&str]) -> Params {
        Pareto::try_parse_from(std::iter::once("pareto").chain(args.iter().copied())).unwrap().args.params()
    }

    #[test]
    fn the_model_is_the_presets_with_the_self_contact_and_friction_given() {
        let default = Params::default();
        assert_eq!(params(&[]), default);
        let changed = params(&["--self-contact", "1600", "--friction", "0"]);
        assert_eq!(
            (changed.self_contact_stiffness, changed.friction, changed.stretch_stiffness),
            (1600.0, 0.0, default.stretch_stiffness)
        );
        assert_eq!(params(&["--preset", "paper", "--friction", "1"]), Params { friction: 1.0, ..Params::paper() });
    }

    fn row(problem: Problem, config: &str, wall: f64, err: f64) -> ParetoRow {
        ParetoRow {
            problem,
            config: config.into(),
            backend: config.split(' ').next().unwrap_or_default().into(),
            h: 1.0 / 1500.0,
            wall_s_per_sim_s: wall,
            pos_err_max: err,
            pos_err_rms: err / 2.0,
            energy_err: 0.0,
            on_front: false,
            recommended: false,
            failure: None,
        }
    }

    #[test]
    fn the_front_keeps_only_the_unbeaten_and_the_recommendation_is_the_fastest_accurate() {
        let mut rows = vec![
            row(Problem::Relax, "a h=1", 1.0, 0.5),
            row(Problem::Relax, "b h=1", 2.0, 0.05),
            row(Problem::Relax, "c h=1", 3.0, 0.06),
            row(Problem::Relax, "d h=1", 4.0, 0.001),
            row(Problem::Relax, "e h=1", 0.5, f64::INFINITY),
            // A tie with b within the margins: both stay.
            row(Problem::Relax, "f h=1", 2.1, 0.049),
            // Barely more accurate than d, but slower: d stays, g goes.
            row(Problem::Relax, "g h=1", 5.0, 0.00099),
            row(Problem::Pull, "a h=1", 1.0, 0.01),
            row(Problem::Pull, "b h=1", 2.0, 0.02),
            row(Problem::Pull, "c h=1", 3.0, 0.02),
            row(Problem::Pull, "d h=1", 4.0, 0.01),
            row(Problem::Pull, "e h=1", 0.5, f64::INFINITY),
            row(Problem::Pull, "f h=1", 2.1, 0.049),
            row(Problem::Pull, "g h=1", 5.0, 0.00099),
        ];
        mark_front(&mut rows);
        let front: Vec<(&str, &str)> =
            rows.iter().filter(|r| r.on_front).map(|r| (r.problem.name(), r.config.as_str())).collect();
        assert_eq!(
            front,
            [
                ("relax", "a h=1"),
                ("relax", "b h=1"),
                ("relax", "d h=1"),
                ("relax", "f h=1"),
                ("pull", "a h=1"),
                ("pull", "g h=1")
            ]
        );
        // a is inaccurate on relax, e failed: b is the fastest accurate
        // everywhere (f, as accurate, is slower in total).
        assert_eq!(recommend(&mut rows).as_deref(), Some("b h=1"));
        assert!(rows.iter().filter(|r| r.recommended).all(|r| r.config == "b h=1"));
        assert_eq!(rows.iter().filter(|r| r.recommended).count(), 2);
        assert!(table(&rows).contains("<- recommended"));
    }

    /// The front and the recommendation on given timings: the wall times
    /// are set here and the errors come from [`errors`] of given runs, so
    /// no clock of a loaded machine decides the front.
    #[test]
    fn the_recommended_configuration_is_on_every_front_when_none_is_both_faster_and_more_accurate() {
        let radius = Geometry::default().yarn_radius;
        // One node at `error` radii from the reference's, at one checkpoint.
        let at = |error: f64| Run {
            checkpoints: vec![vec![Vector3::new(error * radius, 0.0, 0.0)]],
            energies: vec![1.0],
            wall_s: 0.0,
            failure: None,
        };
        let reference = at(0.0);
        // Backend, substeps a tick, wall s per simulated s, and the run.
        let configurations = [
            ("serial-f64", 40, 8.0, at(0.001)),
            ("serial-f32", 10, 2.0, at(0.05)),
            // Slower and less accurate than serial-f32: beaten.
            ("wgpu-fixed", 10, 3.0, at(0.08)),
            // The fastest, but beyond ACCURACY: on the front, not recommended.
            ("rayon", 2, 0.5, at(0.5)),
            ("wgpu", 3, 0.2, Run::failed("refused".into())),
            ("reference-f32", 5, 1.0, at(DIVERGED)),
        ];
        let mut rows = Vec::new();
        for (k, problem) in Problem::ALL.into_iter().enumerate() {
            // Each problem costs and errs a little differently.
            let (wall_scale, error_scale) = (1.0 + 0.5 * k as f64, 1.0 + 0.1 * k as f64);
            for (backend, per_tick, wall, run) in &configurations {
                let h = CONTROL / f64::from(*per_tick);
                let mut run = run.clone();
                run.checkpoints.iter_mut().flatten().for_each(|p| *p *= error_scale);
                rows.push(ParetoRow::new(problem, backend, h, wall * wall_scale, run, &reference, radius));
            }
        }
        let error = |config: &str| rows.iter().find(|r| r.config == config).map(|r| r.pos_err_max);
        assert!((error("serial-f32 h=1/1500").unwrap() - 0.05).abs() < 1e-12, "errors() in radii");
        assert_eq!(error("wgpu h=1/450"), Some(f64::INFINITY));
        let failures: Vec<&str> = rows.iter().filter_map(|r| r.failure.as_deref()).collect();
        assert_eq!(failures.len(), 8, "{failures:?}");
        assert!(failures.iter().filter(|f| f.starts_with("diverged")).count() == 4, "{failures:?}");

        mark_front(&mut rows);
        assert_eq!(recommend(&mut rows).as_deref(), Some("serial-f32 h=1/1500"));
        for problem in Problem::ALL {
            let mine: Vec<&ParetoRow> = rows.iter().filter(|r| r.problem == problem).collect();
            let Some(best) = mine.iter().find(|r| r.recommended) else { panic!("{problem:?} has no recommended row") };
            // The premise: nothing here is both faster and more accurate.
            assert!(
                !mine.iter().any(|r| r.wall_s_per_sim_s < best.wall_s_per_sim_s && r.pos_err_max < best.pos_err_max),
                "{problem:?}"
            );
            assert!(best.on_front, "{problem:?}: the recommended configuration is off the front");
            let front: Vec<&str> = mine.iter().filter(|r| r.on_front).map(|r| r.backend.as_str()).collect();
            assert_eq!(front, ["serial-f64", "serial-f32", "rayon"], "{problem:?}");
        }
        let table = table(&rows);
        assert_eq!(table.matches("yes  <- recommended").count(), 4, "{table}");
        assert!(!table.contains("no   <- recommended"), "{table}");
        let csv = csv(&rows);
        let marked: Vec<&str> = csv.lines().filter(|l| l.ends_with(",true,true")).collect();
        assert_eq!(marked.len(), 4, "{csv}");
        assert!(marked.iter().all(|l| l.contains(",serial-f32 h=1/1500,")), "{csv}");
        assert_eq!(csv.lines().count(), 1 + rows.len());
    }

    #[test]
    fn errors_are_measured_in_radii_and_a_failed_run_is_infinitely_wrong() {
        let at = |x: f64| Run {
            checkpoints: vec![vec![Vector3::new(x, 0.0, 0.0), Vector3::zeros()]],
            energies: vec![2.0 + x],
            wall_s: 1.0,
            failure: None,
        };
        let (max, rms, energy) = errors(&at(0.5), &at(0.0), 0.5);
        assert_eq!((max, rms), (1.0, (0.5f64).sqrt()));
        assert!((energy - 0.25).abs() < 1e-12);
        let failed = Run { failure: Some("diverged".into()), ..at(0.0) };
        assert_eq!(errors(&failed, &at(0.0), 0.5).0, f64::INFINITY);
        assert_eq!(errors(&at(DIVERGED), &at(0.0), 1.0).0, f64::INFINITY, "diverged");
    }

    #[test]
    fn each_problem_drives_its_pins_on_the_control_clock() {
        let geometry = Geometry::default();
        let fabric = Fabric::from_chart(&Chart::stockinette(6, 6).expect("size"), &geometry).expect("fabric");
        let pins = |problem: Problem, t| problem.pins(&fabric, &geometry, t, 1.0);
        assert!(pins(Problem::Relax, 0.5).is_empty());
        let start = pins(Problem::Pull, 0.0);
        let half = pins(Problem::Pull, 0.5);
        let end = pins(Problem::Pull, 1.0);
        // Interlooped rows end in different turns at the two sides, so the
        // columns need not hold as many nodes each.
        assert_eq!(start.len(), fabric.side_nodes(Side::Left).len() + fabric.side_nodes(Side::Right).len());
        let moved =
            |pins: &[Pin]| pins.iter().map(|p| (p.target - fabric.positions()[p.node as usize]).norm()).sum::<f64>();
        assert_eq!(moved(&start), 0.0);
        assert!(moved(&half) > 0.0 && (moved(&half) - moved(&end)).abs() < 1e-12, "the pull ramps, then holds");
        let snag = pins(Problem::Snag, 1.0);
        assert_eq!(snag.len(), 1);
        assert!((moved(&snag) - 3.0 * geometry.stitch_width).abs() < 1e-9);
        assert_eq!(pins(Problem::Drape, 0.3).len(), fabric.side_nodes(Side::Top).len());
        let model = Params { friction: 0.125, ..Params::paper() };
        let (drape, relax) = (Problem::Drape.params(&model, 1e-3), Problem::Relax.params(&model, 1e-3));
        assert!(drape.gravity > 0.0 && relax.gravity == 0.0);
        assert_eq!((drape.substep, drape.friction, relax.friction), (1e-3, 0.125, 0.125), "the model's, but h");
    }
}
