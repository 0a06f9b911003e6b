//! The drawing every figure shares: a canvas with the embedded font, a
//! log-log panel of a multi-panel figure with its legend, and the colour
//! order of backends.
//!
//! This module owns how the figures look; it knows nothing of what they
//! show, which `plotdata`, `pareto` and `stress` measure and lay out.
//! Plots use `plotters` with the DejaVu font embedded in the binary, so no
//! system fonts are needed.

use std::path::Path;
use std::sync::Once;

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::GateError;

/// The font family name the plots use.
pub(crate) const FONT: &str = "yarnify-sans";

/// Register the embedded DejaVu font as [`FONT`], once per process.
fn register_font() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        // The embedded font is a valid TrueType file; if it were not, the
        // plots would fail with a clear error when drawing text.
        let _ = plotters::style::register_font(FONT, FontStyle::Normal, dejavu::sans::regular());
    });
}

/// The error of a plot at `path` that could not be drawn.
pub(crate) fn plot_error(path: &Path, e: impl std::fmt::Display) -> GateError {
    GateError::Render(format!("could not draw {}: {e}", path.display()))
}

/// A white PNG canvas of `size` pixels at `path`, the font registered.
pub(crate) fn canvas(path: &Path, size: (u32, u32)) -> Result<DrawingArea<BitMapBackend<'_>, Shift>, GateError> {
    register_font();
    let root = BitMapBackend::new(path, size).into_drawing_area();
    root.fill(&WHITE).map_err(|e| plot_error(path, e))?;
    Ok(root)
}

/// Each backend name once, sorted: the order of a figure's colours.
pub(crate) fn distinct<'a>(names: impl Iterator<Item = &'a str>) -> Vec<&'a str> {
    let mut names: Vec<&str> = names.collect();
    names.sort_unstable();
    names.dedup();
    names
}

/// A log-log chart in one panel of a multi-panel figure.
pub(crate) type LogLog<'a, 'b> = ChartContext<'a, BitMapBackend<'b>, Cartesian2d<LogCoord<f64>, LogCoord<f64>>>;

/// How a log-log panel is labelled.
pub(crate) struct PanelAxes<'s> {
    /// The panel's title.
    pub(crate) caption: String,
    /// The axis descriptions, x then y.
    pub(crate) labels: (&'s str, &'s str),
    /// Tick labels on each axis.
    pub(crate) ticks: usize,
    /// How x tick values are printed (y ticks print as powers of ten).
    pub(crate) x_format: fn(&f64) -> String,
}

/// A log-log chart over `x` and `y` on `panel`, with its mesh drawn, for
/// figures written to `path`.
pub(crate) fn log_log_panel<'a, 'b>(
    panel: &'a DrawingArea<BitMapBackend<'b>, Shift>,
    path: &Path,
    axes: &PanelAxes<'_>,
    x: std::ops::Range<f64>,
    y: std::ops::Range<f64>,
) -> Result<LogLog<'a, 'b>, GateError> {
    let fail = |e: &dyn std::fmt::Display| plot_error(path, e);
    let mut chart = ChartBuilder::on(panel)
        .caption(&axes.caption, (FONT, 22))
        .margin(12)
        .x_label_area_size(44)
        .y_label_area_size(72)
        .build_cartesian_2d(x.log_scale(), y.log_scale())
        .map_err(|e| fail(&e))?;
    chart
        .configure_mesh()
        .x_labels(axes.ticks)
        .y_labels(axes.ticks)
        .x_label_formatter(&axes.x_format)
        .y_label_formatter(&|v| format!("{v:.0e}"))
        .x_desc(axes.labels.0)
        .y_desc(axes.labels.1)
        .label_style((FONT, 13))
        .axis_desc_style((FONT, 15))
        .draw()
        .map_err(|e| fail(&e))?;
    Ok(chart)
}

/// A panel's legend, in its lower left corner (empty in these figures).
pub(crate) fn panel_legend<'a, 'b: 'a>(chart: &mut LogLog<'a, 'b>, path: &Path) -> Result<(), GateError> {
    chart
        .configure_series_labels()
        .label_font((FONT, 13))
        .background_style(WHITE.mix(0.9))
        .border_style(BLACK)
        .position(SeriesLabelPosition::LowerLeft)
        .draw()
        .map_err(|e| plot_error(path, e))
}
