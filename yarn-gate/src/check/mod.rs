//! `yarn-gate check`: the behavioural gate, in two forms.
//!
//! - [`rest`], the default: relax until rest is certified
//!   ([`crate::certificate`]), hold each stiffness probe to a certified
//!   rest too, double the work and show nothing moved, and report the
//!   resting curl, size and stiffness by direction.
//! - [`paper`], the `paper` preset: the paper's fixed 12,000-substep
//!   window and its criteria, reproducing today's figures bit for bit.
//!
//! This module owns the command ([`CheckArgs`]) and what both forms share:
//! the criterion and its table.

pub mod paper;
pub mod rest;

use serde::Serialize;
use yarn_model::Backend;
use yarn_model::statics::StaticOptions;
use yarn_topology::{Fabric, Geometry};

pub use paper::{
    CheckConfig, CheckReport, ENERGY_RISE_TOLERANCE, MIN_ANISOTROPY, MIN_CURL, PULL_STRAIN, SETTLED_SPEED_FRACTION,
    STATIC_FORCE_DROP, Solver, run_check, run_static_check,
};

use crate::GateError;
use crate::backends::{BackendWork, with_backend};
use crate::cli::{Outcome, PATTERN_HELP, PatternArg, SUBSTEPS, parse_pattern, parse_size, phases, with_bar};
use crate::preset::Preset;

/// `yarn-gate check`: run the gate once and judge it.
#[derive(Debug, clap::Args)]
pub struct CheckArgs {
    /// The model and gate: `default` (the gate at a certified rest) or
    /// `paper` (the paper's model and its fixed 12,000-substep gate, on
    /// its 8-node arch, which knits no purl).
    #[arg(long, value_enum, default_value_t = Preset::Default)]
    preset: Preset,
    #[arg(long, default_value = "stockinette", value_parser = parse_pattern, help = PATTERN_HELP)]
    pattern: PatternArg,
    /// Patch size in stitches, WIDTHxHEIGHT (unused with a chart file
    /// --pattern).
    #[arg(long, default_value = "16x16", value_parser = parse_size)]
    size: (usize, usize),
    /// With `--preset paper`: substeps of free relaxation, and each
    /// stiffness probe holds as long (default 12,000). Otherwise: the
    /// budget of each relaxation and hold, in substeps for the dynamics
    /// (default 1,000,000) or force evaluations for the solve (default
    /// 20,000); a run that spends it is reported uncertified.
    #[arg(long)]
    steps: Option<u64>,
    /// Backend for the dynamics: serial (f64, the ground truth),
    /// serial-f32, rayon, wgpu (gather), wgpu-fixed (f32), or
    /// reference-f32 / reference-f64 (the element-by-element substep).
    /// Default: serial. Naming one chooses the dynamic path.
    #[arg(long)]
    backend: Option<String>,
    /// Rest-curl fraction κ; 1 gives a patch that should read flat.
    #[arg(long)]
    rest_curl: Option<f64>,
    /// Self-contact stiffness k_sc: yarn kept one diameter from yarn
    /// (docs/self-contact.md); 0 turns it off [default: the preset's, off
    /// in both]. 1,600 is the drape's.
    #[arg(long)]
    self_contact: Option<f64>,
    /// Friction coefficient μ of the dynamic path, persistent contacts and
    /// self-contact alike; 0 turns friction off [default: the preset's,
    /// 0.3]. The static solve is frictionless whatever it is.
    #[arg(long)]
    friction: Option<f64>,
    /// Give stretched contacts friction too, by how far they are stretched
    /// (`Params::friction_in_tension`; the dynamic path only).
    #[arg(long)]
    friction_in_tension: bool,
    /// Nodes a loop of the default preset's interlooped geometry: even, at
    /// least 10 (default 24, `Geometry::nodes_per_loop`).
    #[arg(long)]
    nodes_per_loop: Option<usize>,
    /// The path to rest: `static` (a frictionless quasi-static solve in
    /// f64; --backend is not used) or `dynamic` (the damped dynamics with
    /// friction on --backend, from the assembled state). Default: static,
    /// or dynamic with `--preset paper` or a --backend.
    #[arg(long, value_parser = ["dynamic", "static"])]
    solver: Option<String>,
    /// Print one JSON object instead of the table.
    #[arg(long)]
    json: bool,
}

/// The default budget of each dynamic relaxation or hold, in substeps.
pub const DYNAMIC_BUDGET: u64 = 1_000_000;
/// The default budget of each static relaxation or hold, in force
/// evaluations.
pub const STATIC_BUDGET: u64 = 20_000;

impl CheckArgs {
    /// Run the gate; the outcome passes only if every criterion does.
    ///
    /// # Errors
    /// As [`run_check`], [`run_static_check`], [`rest::run_static`] and
    /// [`rest::run_dynamic`]; a chart file that cannot be read or parsed;
    /// with `--preset paper`, a chart with a purl stitch
    /// ([`yarn_topology::TopologyError::ArchPurl`]); and an unknown backend.
    pub fn run(&self) -> Result<Outcome, GateError> {
        let mut params = self.preset.params();
        params.rest_curl = self.rest_curl.unwrap_or(params.rest_curl);
        params.self_contact_stiffness = self.self_contact.unwrap_or(params.self_contact_stiffness);
        params.friction = self.friction.unwrap_or(params.friction);
        params.friction_in_tension |= self.friction_in_tension;
        let chart = self.pattern.chart(self.size)?;
        let solver = self.solver.as_deref();
        let backend = self.backend.as_deref().unwrap_or("serial");
        if self.preset == Preset::Paper {
            // The paper's gate knits stockinette of the chart's size, which
            // is this chart when it is all knit, and so stays bit for bit
            // what it was; a purl stitch the arch refuses before anything
            // runs.
            Fabric::from_chart(&chart, &Geometry::paper())?;
            let steps = self.steps.unwrap_or(12_000);
            let (width, height) = (chart.width(), chart.height());
            let config = CheckConfig { width, height, steps, pull_steps: steps, params };
            let report = with_bar(steps, SUBSTEPS, "", |bar| {
                let progress = &mut phases(bar);
                if solver == Some("static") {
                    run_static_check(&config, &StaticOptions::default(), progress)
                } else {
                    with_backend(backend, 0, &mut Paper { config: &config, progress })
                }
            })?;
            return Ok(Outcome::json_or(&report, self.json, || report.table()).verdict(report.pass));
        }
        let dynamic = solver == Some("dynamic") || (solver.is_none() && self.backend.is_some());
        let budget = self.steps.unwrap_or(if dynamic { DYNAMIC_BUDGET } else { STATIC_BUDGET });
        let mut geometry = self.preset.geometry();
        geometry.nodes_per_loop = self.nodes_per_loop.unwrap_or(geometry.nodes_per_loop);
        let config = rest::RestConfig { chart, budget, params, geometry };
        let report = with_bar(budget, rest::PROGRESS, "", |bar| {
            let progress = &mut phases(bar);
            if dynamic {
                with_backend(backend, 0, &mut AtRest { config: &config, progress })
            } else {
                rest::run_static(&config, progress)
            }
        })?;
        Ok(Outcome::json_or(&report, self.json, || report.table()).verdict(report.pass))
    }
}

/// [`run_check`] on one backend.
struct Paper<'a, 'p> {
    config: &'a CheckConfig,
    progress: &'p mut dyn FnMut(&'static str, u64, u64),
}

impl BackendWork for Paper<'_, '_> {
    type Output = CheckReport;

    fn run<B: Backend>(&mut self, _name: &str, backend: B) -> Result<CheckReport, GateError> {
        run_check(backend, self.config, self.progress)
    }
}

/// [`rest::run_dynamic`] on one backend.
struct AtRest<'a, 'p> {
    config: &'a rest::RestConfig,
    progress: &'p mut dyn FnMut(&'static str, u64, u64),
}

impl BackendWork for AtRest<'_, '_> {
    type Output = rest::RestReport;

    fn run<B: Backend>(&mut self, _name: &str, backend: B) -> Result<rest::RestReport, GateError> {
        rest::run_dynamic(backend, self.config, self.progress)
    }
}

/// One pass/fail criterion.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Criterion {
    /// What is checked.
    pub name: &'static str,
    /// What we measured, in words.
    pub measured: String,
    /// What passes, in words.
    pub threshold: String,
    /// The paper's figure for the same quantity.
    pub paper: &'static str,
    /// Whether it passed.
    pub pass: bool,
}

/// The criteria as a table, with the verdict under it.
fn criteria_table(criteria: &[Criterion], pass: bool) -> String {
    let widths = [24, 44, 30, 42];
    let row = |cells: [&str; 5]| {
        format!(
            "{:<w0$} {:<w1$} {:<w2$} {:<w3$} {}\n",
            cells[0],
            cells[1],
            cells[2],
            cells[3],
            cells[4],
            w0 = widths[0],
            w1 = widths[1],
            w2 = widths[2],
            w3 = widths[3]
        )
    };
    let mut out = row(["criterion", "measured", "pass when", "paper", "verdict"]);
    for c in criteria {
        out += &row([c.name, &c.measured, &c.threshold, c.paper, if c.pass { "PASS" } else { "FAIL" }]);
    }
    out + &format!("\n{}\n", if pass { "PASS: every criterion holds" } else { "FAIL: see the criteria above" })
}
