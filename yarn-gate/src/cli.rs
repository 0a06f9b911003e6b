//! What every `yarn-gate` command shares: patch sizes as the command line
//! writes them, progress bars, and the [`Outcome`] a command hands back to
//! be printed.
//!
//! This module knows nothing of any one command, nor of exit codes: the
//! binary alone turns an outcome or an error into one.

use indicatif::{ProgressBar, ProgressStyle};
use serde::Serialize;

/// A progress bar's line when it counts substeps.
pub(crate) const SUBSTEPS: &str = "{msg:>12} [{bar:40}] {pos}/{len} substeps ({eta})";

/// A progress bar's line when it counts timed runs.
pub(crate) const TIMED_RUNS: &str = "{msg:>12} [{bar:40}] {pos}/{len} timed runs";

/// What a command hands back: what to print on stdout, and its verdict.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Outcome {
    /// Printed as it is: it ends in its own newline.
    pub stdout: String,
    /// Whether the command passed; one without a verdict always does.
    pub pass: bool,
}

impl Outcome {
    /// `stdout`, with no verdict.
    pub(crate) fn text(stdout: String) -> Self {
        Self { stdout, pass: true }
    }

    /// `report` as pretty JSON when `json`, otherwise `table()`.
    pub(crate) fn json_or(report: &impl Serialize, json: bool, table: impl FnOnce() -> String) -> Self {
        if json {
            Self::text(serde_json::to_string_pretty(report).expect("reports serialise") + "\n")
        } else {
            Self::text(table())
        }
    }

    /// The same output with the command's verdict.
    pub(crate) fn verdict(self, pass: bool) -> Self {
        Self { pass, ..self }
    }
}

/// Parse `WIDTHxHEIGHT`, e.g. `16x16`.
///
/// # Errors
/// A message naming the text and the form it should take.
pub(crate) fn parse_size(text: &str) -> Result<(usize, usize), String> {
    let err = || format!("`{text}` is not a size; write WIDTHxHEIGHT, e.g. 16x16");
    let (width, height) = text.split_once(['x', 'X']).ok_or_else(err)?;
    Ok((width.trim().parse().map_err(|_| err())?, height.trim().parse().map_err(|_| err())?))
}

/// Run `work` with a bar of `len` steps, drawn as `template` and labelled
/// `label`, and clear the bar afterwards, whether `work` failed or not.
pub(crate) fn with_bar<T>(len: u64, template: &str, label: &str, work: impl FnOnce(&ProgressBar) -> T) -> T {
    let bar = ProgressBar::new(len);
    bar.set_style(ProgressStyle::with_template(template).expect("static template").progress_chars("=> "));
    bar.set_message(label.to_owned());
    let result = work(&bar);
    bar.finish_and_clear();
    result
}

/// A `progress(done, total)` callback that moves `bar`.
pub(crate) fn counts(bar: &ProgressBar) -> impl FnMut(u64, u64) + '_ {
    |done, total| {
        bar.set_length(total);
        bar.set_position(done);
    }
}

/// A `progress(phase, done, total)` callback that moves `bar` and shows
/// the phase as its label.
pub(crate) fn phases(bar: &ProgressBar) -> impl FnMut(&'static str, u64, u64) + '_ {
    |phase, done, total| {
        bar.set_message(phase);
        bar.set_length(total);
        bar.set_position(done);
    }
}
