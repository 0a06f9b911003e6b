//! The one error type of this crate: every bad chart, chart text, pattern
//! name or user part names the offending index or value and what would be
//! valid.

/// Why a chart, a chart text or file, a pattern name or a set of user parts
/// could not become a [`crate::Chart`] or [`crate::Fabric`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum TopologyError {
    /// A chart needs at least one stitch in each direction.
    #[error("chart is {width}x{height}: both sides must be at least 1 stitch")]
    EmptyChart {
        /// Requested width in stitches.
        width: usize,
        /// Requested height in stitches.
        height: usize,
    },
    /// The chart's node count would not fit the index type used by backends.
    #[error(
        "chart {width}x{height} needs more than {max_nodes} nodes; use a smaller chart (at most {max_nodes} / 8 stitches)"
    )]
    TooLarge {
        /// Requested width in stitches.
        width: usize,
        /// Requested height in stitches.
        height: usize,
        /// The most nodes a fabric may hold.
        max_nodes: usize,
    },
    /// The stitch list given to [`crate::Chart::new`] has the wrong length.
    #[error("chart {width}x{height} needs {expected} stitches, got {got}")]
    ChartShape {
        /// Chart width.
        width: usize,
        /// Chart height.
        height: usize,
        /// `width * height`.
        expected: usize,
        /// Length of the list supplied.
        got: usize,
    },
    /// A text chart with no rows of stitches.
    #[error(
        "the chart text has no rows (only blank lines or # comments); write at least one row of k and p, the bottom row last"
    )]
    EmptyChartText,
    /// A text chart holds a character that is not a stitch letter.
    #[error(
        "chart row {row} (line {line}), column {column}: {found:?} is not a stitch; write k for knit or p for purl (# starts a comment)"
    )]
    BadStitch {
        /// Chart row, counting from 1 at the bottom (the cast-on) as knitters do.
        row: usize,
        /// Text line, counting from 1 at the top.
        line: usize,
        /// Stitch column, counting from 1 at the left; whitespace is not a column.
        column: usize,
        /// The character found.
        found: char,
    },
    /// A row of a text chart is not as wide as the bottom row.
    #[error(
        "chart row {row} (line {line}) is {width} stitches wide but row 1, the bottom row, is {expected}; give every row the same number of stitches"
    )]
    RaggedRow {
        /// Chart row, counting from 1 at the bottom (the cast-on) as knitters do.
        row: usize,
        /// Text line, counting from 1 at the top.
        line: usize,
        /// Stitches in this row.
        width: usize,
        /// Stitches in row 1, the bottom row.
        expected: usize,
    },
    /// A chart file could not be read.
    #[error("cannot read the chart file `{}`: {message}", path.display())]
    ReadChart {
        /// The file asked for.
        path: std::path::PathBuf,
        /// What the system said (the I/O error's message).
        message: String,
    },
    /// A pattern name that is not one of [`crate::Pattern::ALL`].
    #[error("unknown pattern `{name}`; use one of: {}", crate::pattern::names())]
    UnknownPattern {
        /// The name given.
        name: String,
    },
    /// A geometry parameter is not finite or not positive.
    #[error("geometry field `{name}` is {value}; it must be finite and positive")]
    BadGeometry {
        /// Field name in [`crate::Geometry`].
        name: &'static str,
        /// The rejected value.
        value: f64,
    },
    /// The nodes per loop do not suit the loop shape.
    #[error(
        "geometry has {got} nodes per loop; the {shape:?} shape needs exactly 8 (Arch) or an even number of at least 10 (Interlooped)"
    )]
    BadNodesPerLoop {
        /// The shape asked for.
        shape: crate::LoopShape,
        /// The nodes per loop asked for.
        got: usize,
    },
    /// An interlooped shape whose loops do not pass through the row below.
    #[error(
        "the loops of adjacent rows do not cross: make loop_height larger than stitch_height and roundness at least 1 (the defaults are 9.33, 5.83 and 1.5)"
    )]
    NoCrossings,
    /// A chart asks for a stitch the loop shape cannot knit.
    #[error(
        "the paper's arch knits only knit stitches, and stitch ({column}, {row}) is a purl; use the interlooped geometry (Geometry::default) for purl"
    )]
    ArchPurl {
        /// Column of the first purl stitch.
        column: usize,
        /// Row of the first purl stitch.
        row: usize,
    },
    /// User parts with no nodes at all.
    #[error("a fabric needs at least one node")]
    NoNodes,
    /// More memory than the system has free.
    #[error(
        "{what} needs {needed} bytes but only {available} are available (MemAvailable in /proc/meminfo, or the cap of `limit_memory`); use a smaller fabric or free memory"
    )]
    OutOfMemory {
        /// What would not fit.
        what: &'static str,
        /// Bytes it needs.
        needed: u64,
        /// Bytes the system can give.
        available: u64,
    },
    /// More nodes than backends can index.
    #[error("{nodes} nodes given; a fabric holds at most {max_nodes}")]
    TooManyNodes {
        /// Nodes supplied.
        nodes: usize,
        /// The most nodes a fabric may hold.
        max_nodes: usize,
    },
    /// A node coordinate is NaN or infinite.
    #[error("node {node} has non-finite coordinate {value} on axis {axis}")]
    NonFinitePosition {
        /// Offending node.
        node: usize,
        /// 0, 1 or 2 for x, y, z.
        axis: usize,
        /// The value found.
        value: f64,
    },
    /// Two consecutive nodes of a yarn coincide, so the segment between
    /// them has no direction. A closed yarn's closing segment runs from its
    /// last node back to its first.
    #[error("segment {segment} (nodes {segment} and {next}) has zero length; move one of them")]
    ZeroLengthSegment {
        /// The segment, named by its first node.
        segment: usize,
        /// Its second node: `segment + 1`, or a closed yarn's first node.
        next: usize,
    },
    /// A yarn starts after the node where the yarn before it ended (or,
    /// for the first yarn, after node 0): the nodes between belong to none.
    #[error(
        "yarn {yarn} starts at node {start}, but node {expected} is the first not in an earlier yarn; \
         yarns must cover the nodes in order without gaps"
    )]
    YarnGap {
        /// The offending yarn.
        yarn: usize,
        /// Its first node.
        start: usize,
        /// Where it should start: where the yarn before it ends (0 for the first).
        expected: usize,
    },
    /// A yarn starts before the yarn before it has ended: their nodes overlap.
    #[error(
        "yarn {yarn} starts at node {start}, inside the yarn before it, which ends at node {expected}; \
         yarns must not overlap"
    )]
    YarnOverlap {
        /// The offending yarn.
        yarn: usize,
        /// Its first node.
        start: usize,
        /// Where it should start: one past the last node of the yarn before.
        expected: usize,
    },
    /// A yarn with too few nodes: an open yarn needs one, a closed one three.
    #[error(
        "yarn {yarn} has {nodes} nodes; a{} yarn needs at least {min}",
        if *closed { " closed" } else { "n open" }
    )]
    ShortYarn {
        /// The offending yarn.
        yarn: usize,
        /// Its nodes (zero when it ends before it starts).
        nodes: usize,
        /// Whether it is closed.
        closed: bool,
        /// The fewest it may have.
        min: usize,
    },
    /// A yarn ends past the last node.
    #[error("yarn {yarn} ends at node {end}, but only nodes 0..{nodes} exist")]
    YarnPastEnd {
        /// The offending yarn.
        yarn: usize,
        /// One past its last node.
        end: usize,
        /// Number of nodes.
        nodes: usize,
    },
    /// The yarns end before the last node: the nodes after belong to none.
    #[error("the yarns end at node {end}, but the fabric has {nodes} nodes; the last yarn must end at {nodes}")]
    YarnsEndEarly {
        /// One past the last yarn's last node.
        end: usize,
        /// Number of nodes.
        nodes: usize,
    },
    /// A contact refers to a node that does not exist.
    #[error("contact {contact} refers to node {node}, but only nodes 0..{nodes} exist")]
    ContactOutOfRange {
        /// Offending contact.
        contact: usize,
        /// The out-of-range node index.
        node: usize,
        /// Number of nodes.
        nodes: usize,
    },
    /// A contact joins a node to itself.
    #[error("contact {contact} joins node {node} to itself; a contact needs two different nodes")]
    SelfContact {
        /// Offending contact.
        contact: usize,
        /// The node named twice.
        node: usize,
    },
    /// A contact joins the same two nodes as an earlier one, in either
    /// order. A crossing is one contact: a repeat doubles its spring, and
    /// under the persistent contacts' friction, which each contact applies
    /// in full from the same slip (SPEC §4 step 3), k repeats turn a
    /// sticking slip s into (1 − k)s every substep, which grows from k = 3.
    #[error(
        "contact {contact} joins nodes {a} and {b}, as contact {first} does; give each crossing one contact (a repeat doubles its spring and its friction)"
    )]
    DuplicateContact {
        /// Offending contact.
        contact: usize,
        /// The earlier contact between the same nodes.
        first: usize,
        /// The offending contact's first node.
        a: usize,
        /// Its second node.
        b: usize,
    },
    /// A pin refers to a node that does not exist.
    #[error("pin {pin} refers to node {node}, but only nodes 0..{nodes} exist")]
    PinOutOfRange {
        /// Offending pin.
        pin: usize,
        /// The out-of-range node index.
        node: usize,
        /// Number of nodes.
        nodes: usize,
    },
    /// A pin target is NaN or infinite.
    #[error("pin {pin} has non-finite target coordinate {value} on axis {axis}")]
    NonFinitePin {
        /// Offending pin.
        pin: usize,
        /// 0, 1 or 2 for x, y, z.
        axis: usize,
        /// The value found.
        value: f64,
    },
    /// The boundary list does not have one entry per node.
    #[error("boundary list has {got} entries for {nodes} nodes")]
    BoundaryLength {
        /// Entries supplied.
        got: usize,
        /// Number of nodes.
        nodes: usize,
    },
    /// A course or wale direction is zero or non-finite.
    #[error("the {name} direction {value:?} is not a finite non-zero vector")]
    BadDirection {
        /// `"course"` or `"wale"`.
        name: &'static str,
        /// The rejected vector.
        value: [f64; 3],
    },
}
