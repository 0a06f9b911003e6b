//! `plotdata`: the data behind the paper's figures 2–4 (§11–12), measured
//! here and written as a CSV and a PNG plot each.
//!
//! - Figure 2: total and bending energy over the free relaxation (log y).
//! - Figure 3: course and wale stiffness: the force on the far grip against
//!   the strain applied, for both axes.
//! - Figure 4: cost per substep against node count, log-log, one line per
//!   backend, with an ideal-linear reference.
//!
//! This module owns the command too ([`PlotdataArgs`]); how a figure is
//! drawn is the `plot` module's, and how figure 4's rows are timed is
//! [`mod@crate::bench`]'s.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use plotters::prelude::*;
use yarn_model::{Backend, Params};
use yarn_topology::{Chart, Fabric, Geometry};

use crate::GateError;
use crate::backends::{BackendWork, for_each_backend, with_backend};
use crate::bench::{BenchConfig, BenchRow, Benchmark};
use crate::cli::{Outcome, SUBSTEPS, parse_size, phases, with_bar};
use crate::metrics::{self, Axis, Relaxation, Stiffness};
use crate::plot::{FONT, canvas, plot_error};

/// Strains of the figure 3 probes.
pub const STRAINS: [f64; 4] = [0.025, 0.05, 0.075, 0.1];

/// `yarn-gate plotdata`: measure the figures' data and write them.
#[derive(Debug, clap::Args)]
pub struct PlotdataArgs {
    /// Folder to write the CSV and PNG files into (created if missing).
    #[arg(long, default_value = "figures")]
    out: PathBuf,
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

impl PlotdataArgs {
    /// Measure and write the three figures; the outcome names the files
    /// written.
    ///
    /// # Errors
    /// When a backend fails or a file cannot be written.
    pub fn run(&self) -> Result<Outcome, GateError> {
        std::fs::create_dir_all(&self.out).map_err(|e| GateError::io(&self.out, e))?;
        let (relaxation, probes) = with_bar(0, SUBSTEPS, "", |bar| {
            with_backend(&self.backend, 0, &mut Measure { args: self, progress: &mut phases(bar) })
        })?;
        let mut written = Vec::new();
        written.extend(figure2(&self.out, &relaxation, Params::paper().substep)?);
        written.extend(figure3(&self.out, &probes)?);
        let config = BenchConfig { repeats: 3, work_per_run: 2_000_000, ..BenchConfig::default() };
        let rows = for_each_backend(&self.scaling, 0, &mut Benchmark { config: &config })?.concat();
        written.extend(figure4(&self.out, &rows)?);
        Ok(Outcome::text(written.iter().map(|path| format!("wrote {}\n", path.display())).collect()))
    }
}

/// Figures 2 and 3's measurement ([`measure`]) on one backend.
struct Measure<'a, 'p> {
    args: &'a PlotdataArgs,
    progress: &'p mut dyn FnMut(&'static str, u64, u64),
}

impl BackendWork for Measure<'_, '_> {
    type Output = (Relaxation, Vec<Stiffness>);

    fn run<B: Backend>(&mut self, _name: &str, mut backend: B) -> Result<Self::Output, GateError> {
        measure(&mut backend, self.args.size, self.args.steps, self.args.pull_steps, self.progress)
    }
}

/// Relax a `width`×`height` patch on `backend` for `steps` substeps, then
/// pull it along each axis at every strain of [`STRAINS`], holding each for
/// `pull_steps`. Returns the relaxation and the probes, course first.
///
/// # Errors
/// When the patch cannot be built or the backend fails.
pub fn measure<B: Backend>(
    backend: &mut B,
    (width, height): (usize, usize),
    steps: u64,
    pull_steps: u64,
    progress: &mut dyn FnMut(&'static str, u64, u64),
) -> Result<(Relaxation, Vec<Stiffness>), GateError> {
    let fabric = Fabric::from_chart(&Chart::stockinette(width, height)?, &Geometry::default())?;
    let params = Params::paper();
    backend.load(&fabric, &params)?;
    let relaxation = metrics::relax(backend, &fabric, steps, 200, |done| progress("relax", done, steps))?;
    let relaxed = backend.state()?.cast::<f64>();
    let mut probes = Vec::new();
    let total = pull_steps * (2 * STRAINS.len()) as u64;
    for axis in [Axis::Course, Axis::Wale] {
        for strain in STRAINS {
            let offset = probes.len() as u64 * pull_steps;
            let probe = metrics::stiffness(backend, &fabric, &relaxed, axis, strain, pull_steps, |done| {
                progress("pull", offset + done / 2, total);
            })?;
            probes.push(probe);
        }
    }
    Ok((relaxation, probes))
}

/// Figure 2: `fig2_energy.csv` and `.png` in `dir`, for a relaxation run
/// at substep `h` seconds.
///
/// # Errors
/// When a file cannot be written.
pub fn figure2(dir: &Path, relaxation: &Relaxation, h: f64) -> Result<[PathBuf; 2], GateError> {
    let mut csv = String::from("substep,time_s,total_energy,bending_energy\n");
    for s in &relaxation.trace {
        let _ = writeln!(csv, "{},{:.6},{:.6},{:.6}", s.substep, s.substep as f64 * h, s.total, s.bend);
    }
    let (csv_path, png_path) = (dir.join("fig2_energy.csv"), dir.join("fig2_energy.png"));
    std::fs::write(&csv_path, csv).map_err(|e| GateError::io(&csv_path, e))?;
    let steps = relaxation.last().substep.max(1) as f64;
    let values = relaxation.trace.iter().flat_map(|s| [s.total, s.bend]).filter(|v| *v > 0.0);
    let (low, high) = values.fold((f64::INFINITY, 0.0f64), |(lo, hi), v| (lo.min(v), hi.max(v)));
    line_plot(
        &png_path,
        Plot {
            title: "Figure 2: energy over the free relaxation",
            labels: (&format!("substep (h = {h:.3e} s)"), "energy, model units (log scale)"),
            ranges: (0.0..steps, (low * 0.8).max(1e-9)..high * 1.25),
            log: (false, true),
            legend: SeriesLabelPosition::UpperRight,
            series: &[
                ("total", relaxation.trace.iter().map(|s| (s.substep as f64, s.total)).collect(), RED),
                ("bending", relaxation.trace.iter().map(|s| (s.substep as f64, s.bend)).collect(), BLUE),
            ],
            reference: None,
        },
    )?;
    Ok([csv_path, png_path])
}

/// Figure 3: `fig3_stiffness.csv` and `.png` in `dir`.
///
/// # Errors
/// When a file cannot be written.
pub fn figure3(dir: &Path, probes: &[Stiffness]) -> Result<[PathBuf; 2], GateError> {
    let mut csv = String::from("axis,strain,force,baseline,stiffness,residual_speed\n");
    for p in probes {
        let axis = match p.axis {
            Axis::Course => "course",
            Axis::Wale => "wale",
        };
        let _ = writeln!(
            csv,
            "{axis},{},{:.6},{:.6},{:.6},{:.6}",
            p.strain, p.force, p.baseline, p.stiffness, p.residual_speed
        );
    }
    let (csv_path, png_path) = (dir.join("fig3_stiffness.csv"), dir.join("fig3_stiffness.png"));
    std::fs::write(&csv_path, csv).map_err(|e| GateError::io(&csv_path, e))?;
    let series = |axis| -> Vec<(f64, f64)> {
        std::iter::once((0.0, 0.0))
            .chain(probes.iter().filter(|p| p.axis == axis).map(|p| (100.0 * p.strain, p.force)))
            .collect()
    };
    let top = probes.iter().map(|p| p.force).fold(0.0, f64::max).max(1e-9);
    let strain_max = 100.0 * STRAINS[STRAINS.len() - 1];
    line_plot(
        &png_path,
        Plot {
            title: "Figure 3: course and wale stiffness",
            labels: ("strain (%)", "force change on the far grip, model units"),
            ranges: (0.0..strain_max * 1.05, 0.0..top * 1.15),
            log: (false, false),
            legend: SeriesLabelPosition::UpperLeft,
            series: &[
                ("course (along rows)", series(Axis::Course), RED),
                ("wale (along columns)", series(Axis::Wale), BLUE),
            ],
            reference: None,
        },
    )?;
    Ok([csv_path, png_path])
}

/// Figure 4: `fig4_scaling.csv` and `.png` in `dir`, from `rows` of
/// `yarn-gate bench`.
///
/// # Errors
/// When a file cannot be written.
pub fn figure4(dir: &Path, rows: &[BenchRow]) -> Result<[PathBuf; 2], GateError> {
    let mut csv = String::from("backend,threads,nodes,contacts,us_per_substep,ns_per_node_substep\n");
    for r in rows {
        let _ = writeln!(
            csv,
            "{},{},{},{},{:.4},{:.4}",
            r.backend,
            r.threads,
            r.nodes,
            r.contacts,
            1e6 / r.substeps_per_s,
            r.ns_per_node_substep
        );
    }
    let (csv_path, png_path) = (dir.join("fig4_scaling.csv"), dir.join("fig4_scaling.png"));
    std::fs::write(&csv_path, csv).map_err(|e| GateError::io(&csv_path, e))?;
    let mut names: Vec<&str> = rows.iter().map(|r| r.backend.as_str()).collect();
    names.dedup();
    let palette = [RED, BLUE, GREEN, MAGENTA, CYAN, BLACK];
    let series: Vec<Series<'_>> = names
        .iter()
        .zip(palette.iter().cycle())
        .map(|(name, colour)| {
            let points = rows.iter().filter(|r| r.backend == *name).map(|r| (r.nodes as f64, 1e6 / r.substeps_per_s));
            (*name, points.collect(), *colour)
        })
        .collect();
    let xs = rows.iter().map(|r| r.nodes as f64);
    let (x_low, x_high) = xs.fold((f64::INFINITY, 0.0f64), |(lo, hi), x| (lo.min(x), hi.max(x)));
    let ys = rows.iter().map(|r| 1e6 / r.substeps_per_s);
    let (y_low, y_high) = ys.fold((f64::INFINITY, 0.0f64), |(lo, hi), y| (lo.min(y), hi.max(y)));
    // Ideal linear cost through the first backend's largest patch.
    let reference = series.first().and_then(|(_, points, _)| points.last().copied()).map(|(x, y)| {
        let slope = y / x;
        vec![(x_low, slope * x_low), (x_high, slope * x_high)]
    });
    line_plot(
        &png_path,
        Plot {
            title: "Figure 4: cost per substep against fabric size",
            labels: ("nodes (log scale)", "µs per substep (log scale)"),
            ranges: (x_low * 0.8..x_high * 1.25, (y_low * 0.5).max(1e-6)..y_high * 2.0),
            log: (true, true),
            legend: SeriesLabelPosition::UpperLeft,
            series: &series,
            reference: reference.map(|points| ("ideal linear", points)),
        },
    )?;
    Ok([csv_path, png_path])
}

/// A named line of points in a colour.
type Series<'a> = (&'a str, Vec<(f64, f64)>, RGBColor);

/// One line chart: its axes, its lines, and an optional reference line.
struct Plot<'a> {
    title: &'a str,
    labels: (&'a str, &'a str),
    ranges: (std::ops::Range<f64>, std::ops::Range<f64>),
    /// Log scale on (x, y).
    log: (bool, bool),
    legend: SeriesLabelPosition,
    series: &'a [Series<'a>],
    /// Drawn dashed grey.
    reference: Option<(&'a str, Vec<(f64, f64)>)>,
}

/// Draw `plot` into a 960x640 PNG at `path`.
fn line_plot(path: &Path, plot: Plot<'_>) -> Result<(), GateError> {
    let Plot { title, labels: (x_label, y_label), ranges: (x_range, y_range), log, legend, series, reference } = plot;
    let fail = |e: &dyn std::fmt::Display| plot_error(path, e);
    let root = canvas(path, (960, 640))?;
    let mut builder = ChartBuilder::on(&root);
    builder.caption(title, (FONT, 26)).margin(16).x_label_area_size(48).y_label_area_size(80);
    // plotters types linear and log axes differently, so each combination
    // builds its own chart; the drawing below is the same for all.
    macro_rules! draw {
        ($x:expr, $y:expr) => {{
            let mut chart = builder.build_cartesian_2d($x, $y).map_err(|e| fail(&e))?;
            chart
                .configure_mesh()
                .x_desc(x_label)
                .y_desc(y_label)
                .label_style((FONT, 16))
                .axis_desc_style((FONT, 18))
                .draw()
                .map_err(|e| fail(&e))?;
            for (name, points, colour) in series {
                let colour = *colour;
                chart
                    .draw_series(LineSeries::new(points.iter().copied(), colour.stroke_width(3)))
                    .map_err(|e| fail(&e))?
                    .label(*name)
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], colour.stroke_width(3)));
                chart.draw_series(points.iter().map(|&p| Circle::new(p, 4, colour.filled()))).map_err(|e| fail(&e))?;
            }
            if let Some((name, points)) = &reference {
                let grey = RGBColor(140, 140, 140);
                chart
                    .draw_series(DashedLineSeries::new(points.iter().copied(), 8, 6, grey.stroke_width(2)))
                    .map_err(|e| fail(&e))?
                    .label(*name)
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], grey.stroke_width(2)));
            }
            chart
                .configure_series_labels()
                .label_font((FONT, 16))
                .background_style(WHITE.mix(0.9))
                .border_style(BLACK)
                .position(legend.clone())
                .draw()
                .map_err(|e| fail(&e))?;
        }};
    }
    match log {
        (false, false) => draw!(x_range, y_range),
        (false, true) => draw!(x_range, y_range.log_scale()),
        (true, false) => draw!(x_range.log_scale(), y_range),
        (true, true) => draw!(x_range.log_scale(), y_range.log_scale()),
    }
    root.present().map_err(|e| fail(&e))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::metrics::Sample;

    fn temp_dir(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("yarnify-plot-{name}-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    /// The PNG's width and height from its header.
    fn png_size(path: &Path) -> (u32, u32) {
        let bytes = std::fs::read(path).unwrap();
        assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
        let word = |at: usize| u32::from_be_bytes(bytes[at..at + 4].try_into().unwrap());
        (word(16), word(20))
    }

    #[test]
    fn figure2_writes_every_sample_and_a_plot() {
        let dir = temp_dir("fig2");
        let trace = (0..=10)
            .map(|k| Sample {
                substep: k * 100,
                total: 1000.0 / (1.0 + k as f64),
                bend: 50.0 + k as f64,
                max_speed: 1.0,
            })
            .collect();
        let relaxation = Relaxation { trace, peak_speed: 2.0 };
        let [csv, png] = figure2(&dir, &relaxation, 1.0 / 1500.0).unwrap();
        let text = std::fs::read_to_string(csv).unwrap();
        assert_eq!(text.lines().count(), 12);
        assert!(text.lines().nth(11).unwrap().starts_with("1000,0.666667,90.909091,60.000000"));
        assert_eq!(png_size(&png), (960, 640));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn figure4_has_a_row_per_measurement() {
        let dir = temp_dir("fig4");
        let row = |backend: &str, nodes: usize, per_s: f64| BenchRow {
            backend: backend.into(),
            threads: 1,
            size: "x".into(),
            stitches: nodes / 16,
            nodes,
            contacts: nodes / 4,
            substeps: 10,
            friction: 0.3,
            gravity: 0.0,
            pins: 0,
            dead_contacts: 0,
            sleep_speed: 0.0,
            ns_per_node_substep: 1e9 / per_s / nodes as f64,
            ns_per_stitch_substep: 16e9 / per_s / nodes as f64,
            ns_min: 0.0,
            ns_max: 0.0,
            substeps_per_s: per_s,
            self_contact: 0.0,
            builds_per_1000: None,
            late_reruns: None,
            self_contact_cost: None,
            stages: None,
        };
        let rows = [row("a", 512, 1e5), row("a", 2048, 2.5e4), row("b", 512, 2e5), row("b", 2048, 1e5)];
        let [csv, png] = figure4(&dir, &rows).unwrap();
        let text = std::fs::read_to_string(csv).unwrap();
        assert_eq!(text.lines().count(), 5);
        // 2.5e4 substeps/s is 40 µs per substep.
        assert!(text.contains("a,1,2048,512,40.0000,"), "{text}");
        assert_eq!(png_size(&png), (960, 640));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
