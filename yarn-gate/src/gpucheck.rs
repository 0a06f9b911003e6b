//! `gpucheck`: the GPU backend against `Serial<f32>` on the chosen adapter,
//! for each accumulation mode: the force field after one accumulation and
//! a 120-substep trajectory, on the gate's stockinette patch and on a
//! random mix of knit and purl stitches of the same size; and the renderer,
//! drawing the stockinette gather trajectory's end.
//!
//! This module owns the bounds, the report and the command
//! ([`GpucheckArgs`]). It opens the one adapter itself rather than going
//! through the command line's backend names: both modes must share it.

use std::sync::Arc;

use serde::Serialize;
use yarn_backend_cpu::Serial;
use yarn_backend_wgpu::{FIXED_POINT_SCALE, Gpu, Mode, Wgpu};
use yarn_model::{Backend, Params, V3, widen};
use yarn_render::{Renderer, View};
use yarn_topology::{Chart, Fabric, Geometry, StitchKind};

use crate::GateError;
use crate::cli::{Outcome, parse_size};
use crate::conformance::TRAJECTORY_STEPS;
use crate::conformance::strategy::mixed_chart;

/// `yarn-gate gpucheck`: check this machine's adapter.
#[derive(Debug, clap::Args)]
pub struct GpucheckArgs {
    /// Patch size in stitches, WIDTHxHEIGHT.
    #[arg(long, default_value = "16x16", value_parser = parse_size)]
    size: (usize, usize),
    /// Seed of the random knit and purl chart checked beside stockinette.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Print one JSON object instead of the table.
    #[arg(long)]
    json: bool,
}

impl GpucheckArgs {
    /// Run the check; the outcome passes only if both modes and the drawing
    /// do.
    ///
    /// # Errors
    /// No adapter, or as [`run_gpucheck`].
    pub fn run(&self) -> Result<Outcome, GateError> {
        let report = run_gpucheck(&Gpu::new()?, self.size, self.seed)?;
        Ok(Outcome::json_or(&report, self.json, || report.table()).verdict(report.pass))
    }
}

/// Gather's force error bound, relative to the largest force: the same
/// sums in the same order as `Serial`, so only the GPU's own `sqrt` and
/// division rounding remain.
pub const GATHER_FORCE: f64 = 1e-5;
/// Gather's trajectory bound after [`TRAJECTORY_STEPS`], in yarn radii.
pub const GATHER_TRAJECTORY: f64 = 1e-4;
/// Fixed point's force error bound, absolute: half a quantum 1/S for each
/// of up to 16 contributions to a node, plus [`GATHER_FORCE`] of the
/// largest force for f32 rounding.
pub const FIXED_POINT_QUANTA: f64 = 16.0 * 0.5 / FIXED_POINT_SCALE as f64;
/// Fixed point's trajectory bound, in yarn radii: quantisation noise of
/// about 1e-3 per force, integrated over 120 substeps.
pub const FIXED_POINT_TRAJECTORY: f64 = 1e-2;

/// One mode's agreement with `Serial<f32>`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ModeReport {
    /// `"gather"` or `"fixed"`.
    pub mode: &'static str,
    /// Largest per-node force difference.
    pub force_max_err: f64,
    /// The same over the largest reference force.
    pub force_rel_err: f64,
    /// The force error against `Serial<f64>` instead, relative to its
    /// largest force: how accurate the mode is, beside how close it is to
    /// the CPU's own f32 rounding.
    pub force_rel_err_vs_f64: f64,
    /// Largest position difference after the trajectory, in yarn radii.
    pub trajectory_max_err: f64,
    /// The bounds this mode was held to: force (relative), trajectory (r).
    pub force_bound: f64,
    /// See `force_bound`.
    pub trajectory_bound: f64,
    /// Both within bounds.
    pub pass: bool,
}

/// The smallest fraction of the frame the drawn patch must cover: three
/// quarters of the 46.5 % that `gpucheck` measures on lavapipe (and the
/// gate's default render, 46-47 %), so a patch drawn half or framed half
/// off the picture fails. Re-measure with `yarn-gate gpucheck`, which
/// prints the coverage beside this bound.
pub const MIN_RENDER_COVERAGE: f64 = 0.35;

/// Both modes on one chart.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ChartReport {
    /// The chart: `"stockinette"`, or `"mixed, seed S"` for the random
    /// knit and purl chart.
    pub chart: String,
    /// Its purl stitches.
    pub purls: usize,
    /// Nodes in the patch.
    pub nodes: usize,
    /// `Serial<f32>`'s own force error against `Serial<f64>`, relative to
    /// the largest force: the f32 rounding any f32 backend is bound by.
    pub serial_f32_force_rel_err_vs_f64: f64,
    /// One report per mode.
    pub modes: Vec<ModeReport>,
}

/// The whole check.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct GpuCheckReport {
    /// The adapter's name and API.
    pub adapter: String,
    /// Whether the adapter's `fma` is fused (the shaders then correct their
    /// square roots and quotients).
    pub fused_fma: bool,
    /// Patch size in stitches.
    pub size: String,
    /// Stockinette, then the random knit and purl chart.
    pub charts: Vec<ChartReport>,
    /// The fraction of a 640x480 frame of the stockinette patch that is yarn.
    pub render_coverage: f64,
    /// Every mode passes on every chart, and the drawing covers enough.
    pub pass: bool,
}

fn max_diff(a: &[V3<f32>], b: &[V3<f32>]) -> f64 {
    a.iter().zip(b).map(|(p, q)| (widen(p) - widen(q)).norm()).fold(0.0, f64::max)
}

fn max_diff_f64(a: &[V3<f32>], b: &[V3<f64>]) -> f64 {
    a.iter().zip(b).map(|(p, q)| (widen(p) - q).norm()).fold(0.0, f64::max)
}

/// Run the check on `gpu` under the gate's parameters with a patch of
/// `size` stitches: stockinette, then [`mixed_chart`]`(size, seed)`.
///
/// # Errors
/// When a patch cannot be built or a backend fails.
pub fn run_gpucheck(gpu: &Arc<Gpu>, (width, height): (usize, usize), seed: u64) -> Result<GpuCheckReport, GateError> {
    let geometry = Geometry::default();
    let stockinette_fabric = Fabric::from_chart(&Chart::stockinette(width, height)?, &geometry)?;
    let (stockinette, drawn) = check_chart(gpu, "stockinette".into(), 0, &stockinette_fabric)?;
    let mixed = mixed_chart(width, height, seed)?;
    let purls = mixed.count(StitchKind::Purl);
    let (mixed, _) = check_chart(gpu, format!("mixed, seed {seed}"), purls, &Fabric::from_chart(&mixed, &geometry)?)?;
    let view = View { width: 640, height: 480, ..View::default() };
    let r = geometry.yarn_radius as f32;
    let render_coverage = Renderer::new(gpu)
        .render(&drawn, stockinette_fabric.yarns(), r, &view)
        .map_err(|e| GateError::Render(e.to_string()))?
        .coverage();
    let charts = vec![stockinette, mixed];
    let pass = charts.iter().flat_map(|c| &c.modes).all(|m| m.pass) && render_coverage > MIN_RENDER_COVERAGE;
    Ok(GpuCheckReport {
        adapter: gpu.adapter(),
        fused_fma: gpu.fused_fma(),
        size: format!("{width}x{height}"),
        charts,
        render_coverage,
        pass,
    })
}

/// Both modes against `Serial<f32>` on `fabric`, and the gather
/// trajectory's end positions for drawing.
fn check_chart(
    gpu: &Arc<Gpu>,
    chart: String,
    purls: usize,
    fabric: &Fabric,
) -> Result<(ChartReport, Vec<[f32; 3]>), GateError> {
    let params = Params::paper();
    let mut reference = Serial::<f32>::new();
    reference.load(fabric, &params)?;
    let want_forces = reference.forces()?;
    reference.advance(TRAJECTORY_STEPS)?;
    let want = reference.state()?;
    let largest = want_forces.iter().map(|f| widen(f).norm()).fold(0.0, f64::max).max(1.0);
    let mut truth = Serial::<f64>::new();
    truth.load(fabric, &params)?;
    let true_forces = truth.forces()?;
    let true_largest = true_forces.iter().map(|f| f.norm()).fold(0.0, f64::max).max(1.0);
    let r = fabric.yarn_radius();
    let mut modes = Vec::new();
    let mut drawn = Vec::new();
    for mode in [Mode::Gather, Mode::FixedPointAtomic] {
        let mut backend = Wgpu::with_gpu(Arc::clone(gpu), mode);
        backend.load(fabric, &params)?;
        let forces = backend.forces()?;
        let force_max_err = max_diff(&forces, &want_forces);
        let force_rel_err_vs_f64 = max_diff_f64(&forces, &true_forces) / true_largest;
        backend.advance(TRAJECTORY_STEPS)?;
        let end = backend.state()?.positions;
        let trajectory_max_err = max_diff(&end, &want.positions) / r;
        if mode == Mode::Gather {
            drawn = end.iter().map(|p| [p.x, p.y, p.z]).collect();
        }
        let (force_bound, trajectory_bound) = match mode {
            Mode::Gather => (GATHER_FORCE, GATHER_TRAJECTORY),
            Mode::FixedPointAtomic => (GATHER_FORCE + FIXED_POINT_QUANTA / largest, FIXED_POINT_TRAJECTORY),
        };
        let force_rel_err = force_max_err / largest;
        modes.push(ModeReport {
            mode: mode.name(),
            force_max_err,
            force_rel_err,
            force_rel_err_vs_f64,
            trajectory_max_err,
            force_bound,
            trajectory_bound,
            pass: force_rel_err <= force_bound && trajectory_max_err <= trajectory_bound,
        });
    }
    let report = ChartReport {
        chart,
        purls,
        nodes: fabric.node_count(),
        serial_f32_force_rel_err_vs_f64: max_diff_f64(&want_forces, &true_forces) / true_largest,
        modes,
    };
    Ok((report, drawn))
}

impl GpuCheckReport {
    /// A plain-text table of the report.
    pub fn table(&self) -> String {
        let mut out = format!(
            "adapter: {} (fused fma: {})\npatch: {}\n",
            self.adapter,
            if self.fused_fma { "yes" } else { "no" },
            self.size
        );
        for chart in &self.charts {
            out += &format!(
                "\n{} ({} purls, {} nodes); Serial f32 force rel err vs f64: {:.3e}\n",
                chart.chart, chart.purls, chart.nodes, chart.serial_f32_force_rel_err_vs_f64
            );
            out += &format!(
                "{:<8} {:>14} {:>14} {:>12} {:>12} {:>18} {:>12}  verdict\n",
                "mode", "force max err", "force rel err", "(bound)", "vs f64", "trajectory err r", "(bound)"
            );
            for m in &chart.modes {
                out += &format!(
                    "{:<8} {:>14.3e} {:>14.3e} {:>12.1e} {:>12.3e} {:>18.3e} {:>12.1e}  {}\n",
                    m.mode,
                    m.force_max_err,
                    m.force_rel_err,
                    m.force_bound,
                    m.force_rel_err_vs_f64,
                    m.trajectory_max_err,
                    m.trajectory_bound,
                    if m.pass { "PASS" } else { "FAIL" }
                );
            }
        }
        out += &format!(
            "render   {:.1} % of a 640x480 frame is yarn (pass above {:.0} %)\n",
            100.0 * self.render_coverage,
            100.0 * MIN_RENDER_COVERAGE
        );
        out += if self.pass { "\nPASS: the GPU matches Serial f32 and draws the patch\n" } else { "\nFAIL\n" };
        out
    }
}
