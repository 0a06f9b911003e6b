//! The stitch chart: a W×H grid of stitch kinds, row 0 at the bottom
//! (cast-on), column 0 at the left. Generators read fabrics from charts so
//! that knit/purl patterns can arrive later without a new API.

use crate::TopologyError;
use crate::fabric::MAX_NODES;
use crate::stockinette::SEG;

/// The kind of one stitch cell.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
#[non_exhaustive]
pub enum StitchKind {
    /// A knit stitch: the loop is pulled through the loop below from back to
    /// front, with its head toward the technical face.
    #[default]
    Knit,
}

/// A W×H grid of stitch kinds, stored row by row from the bottom.
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

    /// An all-knit chart: plain stockinette.
    ///
    /// # Errors
    /// As for [`Chart::new`].
    pub fn stockinette(width: usize, height: usize) -> Result<Self, TopologyError> {
        check_size(width, height)?;
        Ok(Self { width, height, stitches: vec![StitchKind::Knit; width * height] })
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
