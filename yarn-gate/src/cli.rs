//! What every `yarn-gate` command shares: patch sizes and patterns as the
//! command line writes them, progress bars, and the [`Outcome`] a command
//! hands back to be printed.
//!
//! This module knows nothing of any one command, nor of exit codes: the
//! binary alone turns an outcome or an error into one.

use std::path::{Path, PathBuf};

use indicatif::{ProgressBar, ProgressStyle};
use serde::Serialize;
use yarn_topology::{Chart, Pattern, TopologyError};

use crate::GateError;

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

/// Parse a number that must be finite and satisfy `within`, which `what`
/// names in words ("a finite number above 0").
fn parse_number(text: &str, within: impl Fn(f64) -> bool, what: &str) -> Result<f64, String> {
    match text.trim().parse::<f64>() {
        Ok(value) if value.is_finite() && within(value) => Ok(value),
        _ => Err(format!("`{text}` is not {what}")),
    }
}

/// Parse an angle in degrees: any finite number.
///
/// # Errors
/// A message naming the text, for NaN, an infinity or no number.
pub(crate) fn parse_degrees(text: &str) -> Result<f32, String> {
    parse_number(text, |_| true, "a finite number of degrees").map(|degrees| degrees as f32)
}

/// Parse a length of time, a count of seconds above zero.
///
/// # Errors
/// A message naming the text, for zero, a negative number, NaN, an
/// infinity or no number.
pub(crate) fn parse_seconds(text: &str) -> Result<f64, String> {
    parse_number(text, |seconds| seconds > 0.0, "a finite number of seconds above 0")
}

/// Parse a fraction, from 0 to 1 inclusive.
///
/// # Errors
/// A message naming the text, for a number outside 0..=1, NaN or no
/// number.
pub(crate) fn parse_fraction(text: &str) -> Result<f64, String> {
    parse_number(text, |fraction| (0.0..=1.0).contains(&fraction), "a fraction from 0 to 1")
}

/// The most threads `--threads` takes: far past the cores of any machine
/// it measures, and each thread holds working memory of its own, so a
/// slip of the keyboard (100,000) is refused rather than spent building a
/// pool for minutes.
pub(crate) const MAX_THREADS: usize = 1024;

/// Parse a thread count, 0 (one per core) to [`MAX_THREADS`].
///
/// # Errors
/// A message naming the text and the range, for anything else.
pub(crate) fn parse_threads(text: &str) -> Result<usize, String> {
    match text.trim().parse::<usize>() {
        Ok(threads) if threads <= MAX_THREADS => Ok(threads),
        _ => Err(format!("`{text}` is not a thread count from 0 (one per core) to {MAX_THREADS}")),
    }
}

/// Parse a count of timed runs, 1 or more.
///
/// # Errors
/// A message naming the text, for 0 or anything but a whole number.
pub(crate) fn parse_repeats(text: &str) -> Result<usize, String> {
    parse_count(text, "a count of runs, 1 or more")
}

/// Parse a count of substeps per control tick, 1 or more.
///
/// # Errors
/// A message naming the text, for 0 or anything but a whole number.
pub(crate) fn parse_substeps(text: &str) -> Result<u32, String> {
    parse_count(text, "a count of substeps per tick, 1 or more")
}

/// A whole number, 1 or more; otherwise a message that the text is not
/// `what`.
fn parse_count<N: std::str::FromStr + From<u8> + PartialOrd>(text: &str, what: &str) -> Result<N, String> {
    match text.trim().parse::<N>() {
        Ok(count) if count >= N::from(1) => Ok(count),
        _ => Err(format!("`{text}` is not {what}")),
    }
}

/// Parse a distance, finite and not negative.
///
/// # Errors
/// A message naming the text, for a negative number, NaN, an infinity or
/// no number.
pub(crate) fn parse_distance(text: &str) -> Result<f64, String> {
    parse_number(text, |distance| distance >= 0.0, "a finite distance, 0 or more")
}

/// Parse an image size, `WIDTHxHEIGHT` in pixels ([`parse_size`]); how
/// large the device draws is the renderer's to say.
///
/// # Errors
/// As [`parse_size`], and a side past `u32`.
pub(crate) fn parse_image(text: &str) -> Result<(u32, u32), String> {
    let (width, height) = parse_size(text)?;
    let side = |side: usize| u32::try_from(side).map_err(|_| format!("`{text}` has a side past {} pixels", u32::MAX));
    Ok((side(width)?, side(height)?))
}

/// Refuse a file to be written into a folder that does not exist, before
/// the run that would write it rather than after.
///
/// # Errors
/// [`GateError::Io`] naming the file and its missing folder.
pub(crate) fn check_folder(path: &Path) -> Result<(), GateError> {
    let folder = path.parent().filter(|folder| !folder.as_os_str().is_empty()).unwrap_or(Path::new("."));
    if folder.is_dir() {
        return Ok(());
    }
    Err(GateError::io(path, format!("its folder {} does not exist", folder.display())))
}

/// The help of every command's `--pattern`. Each pattern name is spelled
/// out here, as clap needs a constant; a test holds it to [`Pattern::ALL`].
pub(crate) const PATTERN_HELP: &str = "The stitches: a pattern name (stockinette, reverse-stockinette, garter, \
     rib-1x1, rib-2x2, seed), knitted at --size (bench: each of --sizes); or else the path of a plain-text chart \
     file (one row of k and p per line as the face shows them, the bottom row last, # starts a comment), which \
     sets its own size and leaves --size/--sizes unused";

/// A patch's stitches as `--pattern` gives them.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) enum PatternArg {
    /// A named pattern, sized by the command's size flag.
    Named(Pattern),
    /// A plain-text chart file ([`Chart::parse`]'s format), which sets its
    /// own size. It is read when the command runs, so its errors are the
    /// command's ([`crate::GateError::Topology`]).
    File(PathBuf),
}

impl Default for PatternArg {
    fn default() -> Self {
        Self::Named(Pattern::Stockinette)
    }
}

impl PatternArg {
    /// The chart: the named pattern at `width` × `height`, or the file's
    /// chart at its own size.
    ///
    /// # Errors
    /// A size the chart cannot take, or a file that cannot be read or is
    /// not a chart (the error names its row, line and column).
    pub(crate) fn chart(&self, (width, height): (usize, usize)) -> Result<Chart, TopologyError> {
        match self {
            Self::Named(pattern) => pattern.chart(width, height),
            Self::File(path) => Chart::from_file(path),
        }
    }
}

/// Parse `--pattern`: a pattern name first, so a file named like one is
/// shadowed by it; otherwise the path of an existing file.
///
/// # Errors
/// A message listing every pattern name and saying a chart file is also
/// accepted, when `text` is neither a name nor an existing path.
pub(crate) fn parse_pattern(text: &str) -> Result<PatternArg, String> {
    if let Ok(pattern) = text.parse::<Pattern>() {
        return Ok(PatternArg::Named(pattern));
    }
    let path = Path::new(text);
    if path.exists() {
        return Ok(PatternArg::File(path.to_path_buf()));
    }
    let names = Pattern::ALL.map(Pattern::name).join(", ");
    Err(format!(
        "`{text}` is neither a pattern nor an existing file; name one of: {names}; or give the path of a \
         plain-text chart file (rows of k and p, the bottom row last)"
    ))
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pattern_is_a_name_first_then_an_existing_file() {
        assert_eq!(parse_pattern("seed"), Ok(PatternArg::Named(Pattern::Seed)));
        assert_eq!(parse_pattern("rib-2x2"), Ok(PatternArg::Named(Pattern::Rib2x2)));
        assert_eq!(PatternArg::default(), PatternArg::Named(Pattern::Stockinette));
        let path = std::env::temp_dir().join(format!("yarnify-pattern-{}.txt", std::process::id()));
        std::fs::write(&path, "kp\npk\n").unwrap();
        let text = path.to_str().unwrap();
        let arg = parse_pattern(text).unwrap();
        assert_eq!(arg, PatternArg::File(path.clone()));
        let chart = arg.chart((40, 40)).unwrap();
        assert_eq!((chart.width(), chart.height(), chart.to_text()), (2, 2, "kp\npk\n".to_owned()), "its own size");
        std::fs::remove_file(&path).unwrap();
        assert_eq!(PatternArg::Named(Pattern::Garter).chart((3, 2)).unwrap().to_text(), "ppp\nkkk\n");
    }

    #[test]
    fn an_image_side_past_u32_is_refused_and_a_missing_folder_named() {
        assert_eq!(parse_image("640x480"), Ok((640, 480)));
        assert!(parse_image("4294967297x1").is_err_and(|message| message.contains("past")));
        assert!(check_folder(Path::new("frame.png")).is_ok(), "the working folder");
        assert!(check_folder(&std::env::temp_dir().join("frame.png")).is_ok());
        let missing = std::env::temp_dir().join("yarnify-no-such-folder").join("frame.png");
        let message = check_folder(&missing).unwrap_err().to_string();
        assert!(message.contains("yarnify-no-such-folder") && message.contains("does not exist"), "{message}");
    }

    #[test]
    fn a_number_out_of_its_range_is_refused_by_name() {
        for bad in ["nan", "NaN", "inf", "-inf", "1e999", "", "two"] {
            let quoted = format!("`{bad}` is not ");
            for parse in [parse_seconds, parse_fraction, parse_distance] {
                assert!(parse(bad).is_err_and(|message| message.starts_with(&quoted)), "{bad}");
            }
            assert!(parse_degrees(bad).is_err_and(|message| message.starts_with(&quoted)), "{bad}");
        }
        assert_eq!(parse_degrees("-30"), Ok(-30.0));
        assert_eq!(parse_seconds(" 0.25 "), Ok(0.25));
        assert!(parse_seconds("0").is_err() && parse_seconds("-1").is_err());
        assert_eq!((parse_fraction("0"), parse_fraction("1")), (Ok(0.0), Ok(1.0)));
        assert!(parse_fraction("1.01").is_err() && parse_fraction("-0.01").is_err());
        assert_eq!((parse_threads("0"), parse_threads("1024")), (Ok(0), Ok(MAX_THREADS)));
        assert!(parse_threads("1025").is_err() && parse_threads("-1").is_err() && parse_threads("2.5").is_err());
        assert_eq!((parse_repeats("1"), parse_repeats("7")), (Ok(1), Ok(7)));
        assert!(parse_repeats("0").is_err() && parse_repeats("-1").is_err());
        assert_eq!(parse_substeps("10"), Ok(10));
        assert!(parse_substeps("0").is_err() && parse_substeps("1.5").is_err());
        assert_eq!(parse_distance("0"), Ok(0.0));
        assert!(parse_distance("-0.5").is_err());
    }

    #[test]
    fn an_unknown_pattern_lists_every_name_and_the_chart_file() {
        let message = parse_pattern("moss-stitch-nowhere").unwrap_err();
        for pattern in Pattern::ALL {
            assert!(message.contains(pattern.name()), "{message} lacks {pattern}");
        }
        assert!(message.contains("`moss-stitch-nowhere`") && message.contains("chart file"), "{message}");
    }

    #[test]
    fn the_pattern_help_names_every_pattern() {
        for pattern in Pattern::ALL {
            assert!(PATTERN_HELP.contains(&format!("{pattern},")) || PATTERN_HELP.contains(&format!("{pattern})")));
        }
    }
}
