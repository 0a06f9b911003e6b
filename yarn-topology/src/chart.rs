//! The stitch chart: a W×H grid of stitch kinds, row 0 at the bottom
//! (cast-on), column 0 at the left, and its plain-text form. The
//! conventions are on [`Chart`], where rustdoc shows them.

use std::path::Path;

use crate::TopologyError;
use crate::arch::SEG;
use crate::fabric::MAX_NODES;

/// The kind of one stitch cell, as seen from the technical face (+z); see
/// [what a chart records](Chart#what-a-chart-records).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
#[non_exhaustive]
pub enum StitchKind {
    /// A knit stitch: the loop is drawn through the loop below from back to
    /// front, so its legs lie toward +z (the face), in front of the head of
    /// the loop below.
    #[default]
    Knit,
    /// A purl stitch: the loop is drawn through the loop below from front to
    /// back, so its legs lie behind the head of the loop below and its
    /// head-and-sinker bumps show on the face.
    Purl,
}

impl StitchKind {
    /// The side of the face the stitch's legs lie toward, along z: `+1.0`
    /// for knit (in front of the loop below), `-1.0` for purl (behind it).
    pub const fn sign(self) -> f64 {
        match self {
            Self::Knit => 1.0,
            Self::Purl => -1.0,
        }
    }

    /// The letter that stands for the stitch in a text chart: `'k'` or `'p'`.
    pub const fn letter(self) -> char {
        match self {
            Self::Knit => 'k',
            Self::Purl => 'p',
        }
    }

    /// The stitch a text-chart letter stands for, in either case: `k`/`K`
    /// is knit, `p`/`P` is purl, anything else `None`.
    pub const fn from_letter(letter: char) -> Option<Self> {
        match letter {
            'k' | 'K' => Some(Self::Knit),
            'p' | 'P' => Some(Self::Purl),
            _ => None,
        }
    }
}

/// A W×H grid of stitch kinds, stored row by row from the bottom: row 0 is
/// the cast-on, column 0 the left column.
///
/// ## What a chart records
///
/// A chart is the fabric as seen from its technical face, the +z side. The
/// fabric is knitted row by row along one serpentine yarn: row 0, the
/// cast-on at the bottom, is laid left to right, row 1 right to left, and so
/// on. Column 0 is the left column as the face shows it, whichever way the
/// yarn runs along that row.
///
/// Each cell says how its loop passes through the loop below it:
///
/// - [`StitchKind::Knit`]: drawn through from back to front, so its legs lie
///   toward +z, in front of the head of the loop below. The face shows the
///   stitch's V.
/// - [`StitchKind::Purl`]: drawn through from front to back, so its legs lie
///   behind the head of the loop below, and the head-and-sinker bumps show
///   on the face.
///
/// A purl seen from the face is a knit worked from the back. The chart
/// records what the face shows, not what the knitter's needle did: a knitter
/// working flat turns the work on the wrong-side rows (odd rows here) and
/// would *knit* those rows of stockinette, yet every cell of stockinette is
/// [`StitchKind::Knit`] in the chart.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Chart {
    width: usize,
    height: usize,
    stitches: Vec<StitchKind>,
}

impl Chart {
    /// A chart from an explicit row-major list (row 0 first).
    ///
    /// # Errors
    /// [`TopologyError::EmptyChart`] if a side is zero,
    /// [`TopologyError::TooLarge`] if the fabric would exceed the node limit,
    /// [`TopologyError::ChartShape`] if the list length is not `width * height`.
    pub fn new(width: usize, height: usize, stitches: Vec<StitchKind>) -> Result<Self, TopologyError> {
        check_size(width, height)?;
        let expected = width * height;
        if stitches.len() != expected {
            return Err(TopologyError::ChartShape { width, height, expected, got: stitches.len() });
        }
        Ok(Self { width, height, stitches })
    }

    /// An all-knit chart: plain stockinette, the same chart as
    /// [`Pattern::Stockinette`](crate::Pattern::Stockinette) gives.
    ///
    /// # Errors
    /// As for [`Chart::new`].
    pub fn stockinette(width: usize, height: usize) -> Result<Self, TopologyError> {
        Self::from_fn(width, height, |_, _| StitchKind::Knit)
    }

    /// A chart whose stitch at (column, row) is `stitch(column, row)`. The
    /// size is checked before anything is allocated.
    pub(crate) fn from_fn(
        width: usize,
        height: usize,
        mut stitch: impl FnMut(usize, usize) -> StitchKind,
    ) -> Result<Self, TopologyError> {
        check_size(width, height)?;
        let stitches = (0..height).flat_map(|row| (0..width).map(move |column| (column, row)));
        let stitches = stitches.map(|(column, row)| stitch(column, row)).collect();
        Ok(Self { width, height, stitches })
    }

    /// Read a chart from its plain-text form, as printed knitting charts are
    /// read: the **last** row of letters is row 0, the cast-on, and each row
    /// above it is the next one knitted.
    ///
    /// ## Format
    ///
    /// - Each row is a line of `k` (knit) and `p` (purl) as seen from the
    ///   face, column 0 first (at the left). Upper case `K` and `P` are
    ///   accepted too.
    /// - Whitespace anywhere on a line (leading, trailing, or between the
    ///   letters) is ignored, so `k p k p` is the row `kpkp`.
    /// - `#` starts a comment that runs to the end of its line. Lines that
    ///   are empty once comments and whitespace are removed are skipped,
    ///   wherever they stand; a trailing newline is fine, and so are `\r\n`
    ///   line ends and a leading byte-order mark.
    /// - Every row must be as wide as the bottom row.
    ///
    /// Errors count rows as knitters do, from 1 at the bottom (chart row
    /// `r` is the chart's row index `r - 1`), lines from 1 at the top of the
    /// text, and columns from 1 at the left, counting stitches rather than
    /// characters (whitespace is not a column). Rows are checked from the
    /// bottom up, so the error reported is the lowest one.
    ///
    /// ```
    /// use yarn_topology::{Chart, StitchKind};
    ///
    /// let chart = Chart::parse(
    ///     "# a 4-wide band of purl over two rows of 1x1 rib
    ///      p p p p
    ///      K P K P
    ///      k p k p   # row 0, the cast-on
    ///     ",
    /// )?;
    /// assert_eq!((chart.width(), chart.height()), (4, 3));
    /// assert_eq!(chart.get(1, 0), Some(StitchKind::Purl));
    /// assert_eq!(chart.get(0, 2), Some(StitchKind::Purl));
    /// assert_eq!(chart.to_text(), "pppp\nkpkp\nkpkp\n");
    /// # Ok::<(), yarn_topology::TopologyError>(())
    /// ```
    ///
    /// # Errors
    /// [`TopologyError::BadStitch`] for a character that is not a stitch
    /// letter, whitespace or a comment;
    /// [`TopologyError::RaggedRow`] for a row wider or narrower than the
    /// bottom row; [`TopologyError::EmptyChartText`] if there are no rows at
    /// all; [`TopologyError::TooLarge`] as for [`Chart::new`].
    pub fn parse(text: &str) -> Result<Self, TopologyError> {
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        // (line number, the line without its comment) for each row, top first.
        let rows: Vec<(usize, &str)> = text
            .lines()
            .enumerate()
            .map(|(i, line)| (i + 1, line.split_once('#').map_or(line, |(stitches, _comment)| stitches)))
            .filter(|(_, line)| !line.trim().is_empty())
            .collect();
        let height = rows.len();
        if height == 0 {
            return Err(TopologyError::EmptyChartText);
        }
        let mut stitches = Vec::with_capacity(text.len());
        let mut width = 0;
        // The bottom row is row 0 and sets the width, so read upward from it.
        for (index, &(line, content)) in rows.iter().rev().enumerate() {
            let row = index + 1;
            let start = stitches.len();
            for found in content.chars().filter(|c| !c.is_whitespace()) {
                let column = stitches.len() - start + 1;
                let stitch =
                    StitchKind::from_letter(found).ok_or(TopologyError::BadStitch { row, line, column, found })?;
                stitches.push(stitch);
            }
            let row_width = stitches.len() - start;
            if row == 1 {
                width = row_width;
            } else if row_width != width {
                return Err(TopologyError::RaggedRow { row, line, width: row_width, expected: width });
            }
        }
        Self::new(width, height, stitches)
    }

    /// Read a chart from a text file in the format of [`Chart::parse`].
    ///
    /// # Errors
    /// [`TopologyError::ReadChart`] if the file cannot be read (or is not
    /// UTF-8), and otherwise as for [`Chart::parse`].
    pub fn from_file(path: &Path) -> Result<Self, TopologyError> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| TopologyError::ReadChart { path: path.to_path_buf(), message: e.to_string() })?;
        Self::parse(&text)
    }

    /// The chart in the text form [`Chart::parse`] reads: one line of
    /// lower-case `k` and `p` per row, the top row first and row 0 last,
    /// each line ending in `\n`, with no spaces or comments.
    pub fn to_text(&self) -> String {
        let mut text = String::with_capacity((self.width + 1) * self.height);
        for row in self.stitches.chunks_exact(self.width).rev() {
            text.extend(row.iter().map(|stitch| stitch.letter()));
            text.push('\n');
        }
        text
    }

    /// Width in stitches (the number of columns, or wales).
    pub fn width(&self) -> usize {
        self.width
    }

    /// Height in stitches (the number of rows, or courses).
    pub fn height(&self) -> usize {
        self.height
    }

    /// The stitch at `column`, `row`, or `None` outside the chart.
    pub fn get(&self, column: usize, row: usize) -> Option<StitchKind> {
        (column < self.width && row < self.height).then(|| self.stitches[row * self.width + column])
    }

    /// How many of its stitches are `kind`.
    ///
    /// ```
    /// use yarn_topology::{Pattern, StitchKind};
    ///
    /// let rib = Pattern::Rib2x2.chart(8, 3)?;
    /// assert_eq!((rib.count(StitchKind::Knit), rib.count(StitchKind::Purl)), (12, 12));
    /// # Ok::<(), yarn_topology::TopologyError>(())
    /// ```
    pub fn count(&self, kind: StitchKind) -> usize {
        self.stitches.iter().filter(|&&k| k == kind).count()
    }
}

fn check_size(width: usize, height: usize) -> Result<(), TopologyError> {
    if width == 0 || height == 0 {
        return Err(TopologyError::EmptyChart { width, height });
    }
    let nodes = width.checked_mul(height).and_then(|s| s.checked_mul(SEG));
    match nodes {
        Some(n) if n <= MAX_NODES => Ok(()),
        _ => Err(TopologyError::TooLarge { width, height, max_nodes: MAX_NODES }),
    }
}
