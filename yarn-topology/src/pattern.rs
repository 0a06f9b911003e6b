//! Named knit-purl patterns: the stitch rule of each, by the CLI name, and
//! the chart it fills.

use std::fmt;
use std::str::FromStr;

use crate::{Chart, StitchKind, TopologyError};

/// A named knit-purl pattern. Each is defined as seen from the technical
/// face, row 0 at the bottom and column 0 at the left, with the conventions
/// of [`Chart`] (the chart records what the face shows).
///
/// ```
/// use yarn_topology::{Pattern, StitchKind};
///
/// let pattern: Pattern = "rib-1x1".parse()?;
/// assert_eq!(pattern, Pattern::Rib1x1);
/// let chart = pattern.chart(5, 2)?;
/// assert_eq!(chart.to_text(), "kpkpk\nkpkpk\n");
/// assert_eq!(chart.get(1, 0), Some(StitchKind::Purl));
/// assert_eq!(Pattern::Seed.to_string(), "seed");
/// # Ok::<(), yarn_topology::TopologyError>(())
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Pattern {
    /// Every stitch knit (`stockinette`).
    Stockinette,
    /// Every stitch purl: the back of stockinette (`reverse-stockinette`).
    ReverseStockinette,
    /// Rows alternate knit (row 0) and purl (row 1) (`garter`). Knitted flat
    /// by knitting every row, the face shows alternate knit and purl courses.
    Garter,
    /// Columns alternate knit and purl, knit at column 0, the same in every
    /// row (`rib-1x1`).
    Rib1x1,
    /// Columns go knit, knit, purl, purl, from knit at column 0, the same in
    /// every row (`rib-2x2`).
    Rib2x2,
    /// A checkerboard: knit where row + column is even, so knit at (0, 0)
    /// (`seed`).
    Seed,
}

impl Pattern {
    /// Every pattern, in the order of this enum.
    pub const ALL: [Self; 6] =
        [Self::Stockinette, Self::ReverseStockinette, Self::Garter, Self::Rib1x1, Self::Rib2x2, Self::Seed];

    /// The pattern's name on the command line, which [`FromStr`] reads and
    /// [`Display`](fmt::Display) writes.
    pub const fn name(self) -> &'static str {
        match self {
            Self::Stockinette => "stockinette",
            Self::ReverseStockinette => "reverse-stockinette",
            Self::Garter => "garter",
            Self::Rib1x1 => "rib-1x1",
            Self::Rib2x2 => "rib-2x2",
            Self::Seed => "seed",
        }
    }

    /// The stitch at `column`, `row` of this pattern, seen from the face.
    /// Every pattern repeats without end, so any cell has a stitch.
    pub const fn stitch(self, column: usize, row: usize) -> StitchKind {
        let knit = match self {
            Self::Stockinette => true,
            Self::ReverseStockinette => false,
            Self::Garter => row.is_multiple_of(2),
            Self::Rib1x1 => column.is_multiple_of(2),
            Self::Rib2x2 => column % 4 < 2,
            // Both even or both odd, as (row + column) even says, without overflow.
            Self::Seed => row.is_multiple_of(2) == column.is_multiple_of(2),
        };
        if knit { StitchKind::Knit } else { StitchKind::Purl }
    }

    /// A `width` × `height` chart of this pattern.
    ///
    /// # Errors
    /// [`TopologyError::EmptyChart`] if a side is zero,
    /// [`TopologyError::TooLarge`] if the fabric would exceed the node limit.
    pub fn chart(self, width: usize, height: usize) -> Result<Chart, TopologyError> {
        Chart::from_fn(width, height, |column, row| self.stitch(column, row))
    }
}

impl fmt::Display for Pattern {
    /// Writes [`Pattern::name`].
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Pattern {
    type Err = TopologyError;

    /// The pattern whose [`Pattern::name`] is exactly `name`.
    ///
    /// # Errors
    /// [`TopologyError::UnknownPattern`], listing every valid name, if no
    /// pattern has that name.
    fn from_str(name: &str) -> Result<Self, Self::Err> {
        Self::ALL
            .into_iter()
            .find(|pattern| pattern.name() == name)
            .ok_or_else(|| TopologyError::UnknownPattern { name: name.to_owned() })
    }
}

/// Every pattern name, comma separated, for error messages.
pub(crate) fn names() -> String {
    Pattern::ALL.map(Pattern::name).join(", ")
}
