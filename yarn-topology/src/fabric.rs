//! The `Fabric`: yarns of nodes with their element tables and rest values
//! (SPEC §2). A fabric holds one or more yarns ([`YarnSpan`]), each a
//! contiguous run of nodes in node order, open or closed; springs and
//! bending joints follow each yarn and never join two. A fabric is valid by
//! construction: both constructors check every index and coordinate, so
//! downstream crates index freely.

use std::ops::Range;

use crate::{TopologyError, Vec3};

/// The most nodes one fabric may hold. Backends index nodes with `u32`, and a
/// GPU binding of 2^27 nodes already needs gigabytes; beyond it a fabric is
/// refused rather than half-allocated.
pub(crate) const MAX_NODES: usize = 1 << 27;

/// A stretch spring along one segment of a yarn, from node `a` to the next
/// node of its yarn, `b`: `a + 1`, or for a closed yarn's closing segment
/// the yarn's first node. A segment is named by its first node `a`, since
/// every node starts at most one.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Spring {
    /// First node.
    pub a: u32,
    /// Second node: the node after `a` along its yarn.
    pub b: u32,
    /// Rest length ℓ0: the assembled segment length.
    pub rest_length: f64,
}

/// A bending triple `(a, b, c)` of one yarn, centred on node `b`: `a` is
/// the node before `b` along its yarn and `c` the node after it, which wrap
/// around at the ends of a closed yarn (`(last, first, first + 1)` and
/// `(last − 1, last, first)`). A joint is named by its centre `b`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Triple {
    /// The node before the centre.
    pub a: u32,
    /// Centre node.
    pub b: u32,
    /// The node after the centre.
    pub c: u32,
    /// Rest turning angle θ0 in radians: the assembled angle between the two
    /// segments (0 for a straight joint).
    pub rest_angle: f64,
}

/// One yarn of a fabric: the contiguous run of nodes `start..end`, in node
/// order, open (two free ends) or closed (a loop: its last node joins its
/// first with a spring, and its joints wrap around).
///
/// ```
/// use yarn_topology::YarnSpan;
///
/// let ring = YarnSpan::closed(4..8);
/// assert_eq!((ring.next(7), ring.prev(4), ring.segments()), (Some(4), Some(7), 4));
/// let strand = YarnSpan::open(0..4);
/// assert_eq!((strand.next(3), strand.prev(0), strand.segments()), (None, None, 3));
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct YarnSpan {
    /// The yarn's first node.
    pub start: u32,
    /// One past its last node.
    pub end: u32,
    /// Whether the yarn is a closed loop.
    pub closed: bool,
}

impl YarnSpan {
    /// An open yarn over `nodes`.
    pub fn open(nodes: Range<u32>) -> Self {
        Self { start: nodes.start, end: nodes.end, closed: false }
    }

    /// A closed yarn over `nodes`: its last node joins its first.
    pub fn closed(nodes: Range<u32>) -> Self {
        Self { start: nodes.start, end: nodes.end, closed: true }
    }

    /// The yarn's nodes.
    pub fn nodes(&self) -> Range<usize> {
        self.start as usize..self.end as usize
    }

    /// Number of nodes (zero for a span that ends before it starts).
    pub fn len(&self) -> usize {
        self.end.saturating_sub(self.start) as usize
    }

    /// Whether the span holds no node (never so in a [`Fabric`]).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The fewest nodes a yarn may have: 1 open, 3 closed (a closed yarn
    /// of two nodes would have two springs on one pair and no joint angle).
    pub fn min_len(closed: bool) -> usize {
        if closed { 3 } else { 1 }
    }

    /// Whether `node` is one of the yarn's nodes.
    pub fn contains(&self, node: u32) -> bool {
        (self.start..self.end).contains(&node)
    }

    /// Its segments (springs): one fewer than its nodes when open, as many
    /// when closed.
    pub fn segments(&self) -> usize {
        if self.closed { self.len() } else { self.len().saturating_sub(1) }
    }

    /// The node after `node` along the yarn: `node + 1`, the first node
    /// after the last of a closed yarn, or `None` at an open yarn's end
    /// (and for a node not in the yarn).
    pub fn next(&self, node: u32) -> Option<u32> {
        if !self.contains(node) {
            None
        } else if node + 1 < self.end {
            Some(node + 1)
        } else {
            self.closed.then_some(self.start)
        }
    }

    /// The node before `node` along the yarn: `node − 1`, the last node
    /// before the first of a closed yarn, or `None` at an open yarn's start
    /// (and for a node not in the yarn).
    pub fn prev(&self, node: u32) -> Option<u32> {
        if !self.contains(node) {
            None
        } else if node > self.start {
            Some(node - 1)
        } else {
            self.closed.then(|| self.end - 1)
        }
    }
}

/// A node's neighbours along its yarn: the node before it and the node
/// after it, either missing at an open yarn's ends. Held as two `u32` with
/// [`Link::NONE`] for a missing one, the layout backends upload.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Link {
    prev: u32,
    next: u32,
}

impl Link {
    /// The stored value of a missing neighbour: no node has this index
    /// (a fabric holds fewer than 2^27 nodes).
    pub const NONE: u32 = u32::MAX;

    /// A link to `prev` and `next`.
    pub fn new(prev: Option<u32>, next: Option<u32>) -> Self {
        Self { prev: prev.unwrap_or(Self::NONE), next: next.unwrap_or(Self::NONE) }
    }

    /// The node before, along the yarn.
    pub fn prev(self) -> Option<u32> {
        (self.prev != Self::NONE).then_some(self.prev)
    }

    /// The node after, along the yarn.
    pub fn next(self) -> Option<u32> {
        (self.next != Self::NONE).then_some(self.next)
    }

    /// `[prev, next]` as stored, [`Link::NONE`] for a missing one.
    pub fn raw(self) -> [u32; 2] {
        [self.prev, self.next]
    }
}

/// A persistent contact between two nodes of different yarn passes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Contact {
    /// First node.
    pub a: u32,
    /// Second node.
    pub b: u32,
    /// Rest separation d_c: the assembled distance, floored at 2r.
    pub rest: f64,
    /// Which strand lies toward the technical face in the assembled fabric:
    /// the node further along course × wale. `None` when the two lie level
    /// (within 1e-9 of their separation).
    pub front: Option<Front>,
}

/// One node of a [`Contact`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Front {
    /// The contact's node `a`.
    A,
    /// The contact's node `b`.
    B,
}

/// A node held at a target position.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pin {
    /// The pinned node.
    pub node: u32,
    /// Where the node is held.
    pub target: Vec3,
}

/// One side of a rectangular fabric.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Side {
    /// Row 0, the cast-on: a course edge.
    Bottom,
    /// The last row, the bind-off: a course edge.
    Top,
    /// Column 0: a wale edge.
    Left,
    /// The last column: a wale edge.
    Right,
}

impl Side {
    /// All four sides.
    pub const ALL: [Side; 4] = [Side::Bottom, Side::Top, Side::Left, Side::Right];

    fn bit(self) -> u8 {
        match self {
            Side::Bottom => 1,
            Side::Top => 2,
            Side::Left => 4,
            Side::Right => 8,
        }
    }

    /// True for the top and bottom rows (course edges), false for the wale
    /// edges.
    pub fn is_course(self) -> bool {
        matches!(self, Side::Bottom | Side::Top)
    }
}

/// The set of sides a node lies on (empty for interior nodes). Corner
/// stitches lie on two sides.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct Boundary(u8);

impl Boundary {
    /// No side: an interior node.
    pub const INTERIOR: Boundary = Boundary(0);

    /// This set plus `side`.
    #[must_use]
    pub fn with(self, side: Side) -> Boundary {
        Boundary(self.0 | side.bit())
    }

    /// The sides of the stitch at (`column`, `row`) in a `width` × `height`
    /// chart.
    pub(crate) fn of_stitch(column: usize, row: usize, width: usize, height: usize) -> Boundary {
        [
            (row == 0, Side::Bottom),
            (row + 1 == height, Side::Top),
            (column == 0, Side::Left),
            (column + 1 == width, Side::Right),
        ]
        .into_iter()
        .filter(|&(on, _)| on)
        .fold(Boundary::INTERIOR, |sides, (_, side)| sides.with(side))
    }

    /// Whether the node lies on `side`.
    pub fn on(self, side: Side) -> bool {
        self.0 & side.bit() != 0
    }

    /// Whether the node lies on no side.
    pub fn is_interior(self) -> bool {
        self.0 == 0
    }

    /// Whether the node lies on a course edge (top or bottom row).
    pub fn on_course_edge(self) -> bool {
        self.on(Side::Bottom) || self.on(Side::Top)
    }

    /// Whether the node lies on a wale edge (left or right column).
    pub fn on_wale_edge(self) -> bool {
        self.on(Side::Left) || self.on(Side::Right)
    }
}

/// The parts a user supplies to build a fabric without a chart.
///
/// Springs and bending triples follow from the node order along each yarn
/// ([`FabricParts::yarns`]; by default one open yarn over every node), and
/// rest values from the given positions, exactly as for a generated fabric.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct FabricParts {
    /// Node positions, yarn after yarn, each yarn's in order along it.
    pub positions: Vec<Vec3>,
    /// The yarns, in node order, covering every node without gaps or
    /// overlaps; empty means one open yarn over all the nodes.
    pub yarns: Vec<YarnSpan>,
    /// Contact node pairs. Rest separations are the given distances,
    /// floored at twice `yarn_radius`.
    pub contacts: Vec<[u32; 2]>,
    /// Pinned nodes and their targets.
    pub pins: Vec<Pin>,
    /// Per-node boundary sides; empty means every node is interior.
    pub boundary: Vec<Boundary>,
    /// Yarn radius r in model units; `None` uses 0.9 (SPEC §1).
    pub yarn_radius: Option<f64>,
    /// Course direction; `None` uses +x.
    pub course: Option<Vec3>,
    /// Wale direction; `None` uses +y.
    pub wale: Option<Vec3>,
}

/// Yarns of nodes with their springs, bending triples, persistent
/// contacts, pins, boundary sides and fabric directions.
#[derive(Debug, Clone, PartialEq)]
pub struct Fabric {
    positions: Vec<Vec3>,
    yarns: Vec<YarnSpan>,
    springs: Vec<Spring>,
    triples: Vec<Triple>,
    contacts: Vec<Contact>,
    pins: Vec<Pin>,
    boundary: Vec<Boundary>,
    yarn_radius: f64,
    course: Vec3,
    wale: Vec3,
    grid: Option<Grid>,
}

/// How a generated fabric's nodes map to its stitches.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Grid {
    /// The paper's arch: `SEG` nodes per stitch.
    Arch { width: usize, height: usize },
    /// Interlooped loops with their turns between rows.
    Loops(crate::loops::Layout),
}

impl Fabric {
    /// Build a fabric from user parts, validating them (SPEC §2).
    ///
    /// # Errors
    /// One [`TopologyError`] variant per kind of bad input, naming the first
    /// offending node, segment, contact or pin.
    ///
    /// ```
    /// use yarn_topology::{Fabric, FabricParts, Vec3, TopologyError, YarnSpan};
    ///
    /// let parts = FabricParts {
    ///     positions: vec![Vec3::new(0.0, 0.0, 0.0), Vec3::new(1.0, 0.0, 0.0), Vec3::new(1.0, 1.0, 0.0)],
    ///     contacts: vec![[0, 2]],
    ///     ..FabricParts::default()
    /// };
    /// let fabric = Fabric::from_parts(parts.clone())?;
    /// assert_eq!(fabric.springs().len(), 2);
    ///
    /// let bad = FabricParts { contacts: vec![[1, 1]], ..parts.clone() };
    /// assert_eq!(Fabric::from_parts(bad), Err(TopologyError::SelfContact { contact: 0, node: 1 }));
    ///
    /// // The same three nodes as a closed ring: a third spring joins node 2
    /// // back to node 0, and every node is a joint.
    /// let ring = Fabric::from_parts(FabricParts { yarns: vec![YarnSpan::closed(0..3)], ..parts })?;
    /// assert_eq!((ring.springs().len(), ring.triples().len()), (3, 3));
    /// # Ok::<(), TopologyError>(())
    /// ```
    pub fn from_parts(parts: FabricParts) -> Result<Self, TopologyError> {
        let FabricParts { positions, yarns, contacts, pins, boundary, yarn_radius, course, wale } = parts;
        let n = positions.len();
        if n == 0 {
            return Err(TopologyError::NoNodes);
        }
        if n > MAX_NODES {
            return Err(TopologyError::TooManyNodes { nodes: n, max_nodes: MAX_NODES });
        }
        for (node, p) in positions.iter().enumerate() {
            if let Some(axis) = (0..3).find(|&k| !p[k].is_finite()) {
                return Err(TopologyError::NonFinitePosition { node, axis, value: p[axis] });
            }
        }
        let yarn_radius = yarn_radius.unwrap_or(DEFAULT_RADIUS);
        if !(yarn_radius.is_finite() && yarn_radius > 0.0) {
            return Err(TopologyError::BadGeometry { name: "yarn_radius", value: yarn_radius });
        }
        let mut first_between = std::collections::HashMap::with_capacity(contacts.len());
        let checked_contacts = contacts
            .iter()
            .enumerate()
            .map(|(contact, &[a, b])| {
                for node in [a, b] {
                    if node as usize >= n {
                        return Err(TopologyError::ContactOutOfRange { contact, node: node as usize, nodes: n });
                    }
                }
                if a == b {
                    return Err(TopologyError::SelfContact { contact, node: a as usize });
                }
                if let Some(first) = first_between.insert((a.min(b), a.max(b)), contact) {
                    return Err(TopologyError::DuplicateContact { contact, first, a: a as usize, b: b as usize });
                }
                Ok((a, b))
            })
            .collect::<Result<Vec<_>, _>>()?;
        validate_pins(&pins, n)?;
        let boundary = if boundary.is_empty() {
            vec![Boundary::INTERIOR; n]
        } else if boundary.len() == n {
            boundary
        } else {
            return Err(TopologyError::BoundaryLength { got: boundary.len(), nodes: n });
        };
        let course = direction("course", course.unwrap_or(Vec3::x()))?;
        let wale = direction("wale", wale.unwrap_or(Vec3::y()))?;
        let yarns = if yarns.is_empty() {
            vec![YarnSpan::open(0..n as u32)]
        } else {
            validate_yarns(&yarns, n)?;
            yarns
        };

        // In node order, so spring and joint tables are sorted by first node
        // and by centre: for one open yarn, spring i is (i, i + 1) and
        // triple i is centred on i + 1.
        let springs = yarns
            .iter()
            .flat_map(|yarn| yarn.nodes().filter_map(|a| yarn.next(a as u32).map(|b| (a as u32, b))))
            .map(|(a, b)| {
                let rest_length = (positions[b as usize] - positions[a as usize]).norm();
                // Catches exact duplicates and lengths that would overflow 1/ℓ.
                if rest_length > f64::MIN_POSITIVE && rest_length.is_finite() {
                    Ok(Spring { a, b, rest_length })
                } else {
                    Err(TopologyError::ZeroLengthSegment { segment: a as usize, next: b as usize })
                }
            })
            .collect::<Result<Vec<_>, _>>()?;
        let triples = yarns
            .iter()
            .flat_map(|yarn| {
                yarn.nodes().filter_map(|b| {
                    let b = b as u32;
                    Some((yarn.prev(b)?, b, yarn.next(b)?))
                })
            })
            .map(|(a, b, c)| Triple {
                a,
                b,
                c,
                rest_angle: turning_angle(positions[a as usize], positions[b as usize], positions[c as usize]),
            })
            .collect();
        let floor = 2.0 * yarn_radius;
        let normal = course.cross(&wale);
        let contacts = checked_contacts
            .into_iter()
            .map(|(a, b)| {
                let apart = positions[b as usize] - positions[a as usize];
                let ahead = apart.dot(&normal);
                let front = if ahead.abs() <= 1e-9 * apart.norm() {
                    None
                } else if ahead > 0.0 {
                    Some(Front::B)
                } else {
                    Some(Front::A)
                };
                Contact { a, b, rest: apart.norm().max(floor), front }
            })
            .collect();

        Ok(Self { positions, yarns, springs, triples, contacts, pins, boundary, yarn_radius, course, wale, grid: None })
    }

    /// Assemble a fabric from already-checked generator output.
    pub(crate) fn assembled(parts: FabricParts, grid: Grid) -> Result<Self, TopologyError> {
        let mut fabric = Self::from_parts(parts)?;
        fabric.grid = Some(grid);
        Ok(fabric)
    }

    /// Number of yarn nodes N.
    pub fn node_count(&self) -> usize {
        self.positions.len()
    }

    /// Assembled node positions, in yarn order.
    pub fn positions(&self) -> &[Vec3] {
        &self.positions
    }

    /// The yarns, in node order, covering every node: one open yarn over
    /// all of them unless the parts said otherwise.
    pub fn yarns(&self) -> &[YarnSpan] {
        &self.yarns
    }

    /// Each node's neighbours along its yarn, in node order.
    pub fn links(&self) -> Vec<Link> {
        let mut links = Vec::with_capacity(self.positions.len());
        for yarn in &self.yarns {
            links.extend(yarn.nodes().map(|i| Link::new(yarn.prev(i as u32), yarn.next(i as u32))));
        }
        links
    }

    /// The stretch springs, one per segment, sorted by first node: N − 1
    /// for one open yarn; N less the number of open yarns in general.
    pub fn springs(&self) -> &[Spring] {
        &self.springs
    }

    /// The bending triples, one per node with a neighbour on both sides,
    /// sorted by centre: N − 2 for one open yarn; N less twice the number
    /// of open yarns of two or more nodes, less those of one, in general.
    pub fn triples(&self) -> &[Triple] {
        &self.triples
    }

    /// The persistent contacts.
    pub fn contacts(&self) -> &[Contact] {
        &self.contacts
    }

    /// The pins the fabric was built with (none for a generated fabric).
    pub fn pins(&self) -> &[Pin] {
        &self.pins
    }

    /// Per-node boundary sides.
    pub fn boundary(&self) -> &[Boundary] {
        &self.boundary
    }

    /// Nodes lying on `side`, in yarn order.
    pub fn side_nodes(&self, side: Side) -> Vec<u32> {
        (0..self.positions.len() as u32).filter(|&i| self.boundary[i as usize].on(side)).collect()
    }

    /// Yarn radius r.
    pub fn yarn_radius(&self) -> f64 {
        self.yarn_radius
    }

    /// Unit vector along a row (the course direction).
    pub fn course(&self) -> Vec3 {
        self.course
    }

    /// Unit vector up a column (the wale direction).
    pub fn wale(&self) -> Vec3 {
        self.wale
    }

    /// The positions laid flat, face up, their lowest point `drop` above
    /// the floor y = 0: the chart's plane (x along the course, y along the
    /// wale) turned so that its normal, z, points up. With `fold`, the half
    /// past the middle of the course is first bent up and over the other
    /// half round a half-cylinder whose inner face keeps its length, so the
    /// yarn starts stretched at the bend, never pressed into itself, and
    /// the two layers start well apart. This is what `yarn-gate drape` and
    /// the browser demo drop onto a floor.
    ///
    /// ```
    /// use yarn_topology::{Chart, Fabric, Geometry};
    ///
    /// let fabric = Fabric::from_chart(&Chart::stockinette(4, 4)?, &Geometry::default())?;
    /// let laid = fabric.laid_flat(false, 2.0);
    /// let lowest = laid.iter().map(|p| p.y).fold(f64::INFINITY, f64::min);
    /// assert!((lowest - 2.0).abs() < 1e-9);
    /// # Ok::<(), yarn_topology::TopologyError>(())
    /// ```
    pub fn laid_flat(&self, fold: bool, drop: f64) -> Vec<Vec3> {
        let r = self.yarn_radius;
        let (lo, hi) = self
            .positions
            .iter()
            .fold((Vec3::repeat(f64::INFINITY), Vec3::repeat(f64::NEG_INFINITY)), |(lo, hi), p| (lo.inf(p), hi.sup(p)));
        let middle = 0.5 * (lo.x + hi.x);
        let (mid, thickness) = (0.5 * (lo.z + hi.z), hi.z - lo.z);
        // The inner face of the fold keeps its length, so the bend only
        // stretches yarn (compressed, it would start pressed into itself);
        // an inner radius of twice the thickness stretches the outer face
        // by half.
        let inner = 2.0 * thickness + 2.0 * r;
        let bend = inner + 0.5 * thickness;
        let folded = |p: &Vec3| -> Vec3 {
            let along = p.x - middle;
            if !fold || along <= 0.0 {
                return *p;
            }
            // Round a half-cylinder about the line x = middle,
            // z = mid + bend, then flat back over the first half.
            let angle = (along / inner).min(std::f64::consts::PI);
            let past = (along - inner * std::f64::consts::PI).max(0.0);
            let radius = bend - (p.z - mid);
            Vec3::new(middle + radius * angle.sin() - past, p.y, mid + bend - radius * angle.cos())
        };
        // (x, y, z) → (x, z, −y): the chart's normal becomes up.
        let laid: Vec<Vec3> = self.positions.iter().map(folded).map(|p| Vec3::new(p.x, p.z, -p.y)).collect();
        let lowest = laid.iter().map(|p| p.y).fold(f64::INFINITY, f64::min);
        let lift = Vec3::new(0.0, drop - lowest, 0.0);
        laid.into_iter().map(|p| p + lift).collect()
    }

    /// `(width, height)` in stitches for a fabric generated from a chart.
    pub fn grid(&self) -> Option<(usize, usize)> {
        match self.grid.as_ref()? {
            Grid::Arch { width, height } => Some((*width, *height)),
            Grid::Loops(layout) => Some((layout.width, layout.height)),
        }
    }

    /// Nodes per loop for a fabric generated from a chart
    /// ([`crate::Geometry::nodes_per_loop`]).
    pub fn nodes_per_loop(&self) -> Option<usize> {
        match self.grid.as_ref()? {
            Grid::Arch { .. } => Some(crate::SEG),
            Grid::Loops(layout) => Some(layout.nodes_per_loop),
        }
    }

    /// Index of the node at loop phase `p` of the stitch at (`column`,
    /// `row`) in a generated fabric, or `None` outside the grid or for
    /// `p >= nodes_per_loop`.
    ///
    /// Phases run along the loop in the course direction, whichever way the
    /// row is laid, and the head is phase `nodes_per_loop / 2`. Phase 0 is
    /// the low point at the stitch's left end: for the arch, a node of the
    /// stitch on rows laid left to right and of its left neighbour on rows
    /// laid right to left; for interlooped loops, the sinker it shares with
    /// its left neighbour. Phases `1..nodes_per_loop` belong to this stitch
    /// alone in both shapes.
    pub fn stitch_node(&self, column: usize, row: usize, p: usize) -> Option<usize> {
        let (w, h) = self.grid()?;
        let n = self.nodes_per_loop()?;
        if column >= w || row >= h || p >= n {
            return None;
        }
        Some(match self.grid.as_ref()? {
            Grid::Arch { width, .. } => crate::arch::node_index(*width, row, column, p),
            Grid::Loops(layout) => layout.index(column, row, p),
        })
    }

    /// The head node of the stitch at (`column`, `row`): phase
    /// `nodes_per_loop / 2`.
    pub fn head_node(&self, column: usize, row: usize) -> Option<usize> {
        self.stitch_node(column, row, self.nodes_per_loop()? / 2)
    }

    /// Replace the fabric's pins, validating them as [`Fabric::from_parts`]
    /// does.
    ///
    /// # Errors
    /// [`TopologyError::PinOutOfRange`] or [`TopologyError::NonFinitePin`].
    pub fn set_pins(&mut self, pins: Vec<Pin>) -> Result<(), TopologyError> {
        validate_pins(&pins, self.positions.len())?;
        self.pins = pins;
        Ok(())
    }
}

/// Check that every pin names an existing node and a finite target.
///
/// # Errors
/// [`TopologyError::PinOutOfRange`] or [`TopologyError::NonFinitePin`].
pub fn validate_pins(pins: &[Pin], nodes: usize) -> Result<(), TopologyError> {
    for (pin, p) in pins.iter().enumerate() {
        if p.node as usize >= nodes {
            return Err(TopologyError::PinOutOfRange { pin, node: p.node as usize, nodes });
        }
        if let Some(axis) = (0..3).find(|&k| !p.target[k].is_finite()) {
            return Err(TopologyError::NonFinitePin { pin, axis, value: p.target[axis] });
        }
    }
    Ok(())
}

/// Check that `yarns` cover nodes `0..nodes` in order, each long enough
/// ([`YarnSpan::min_len`]), without gaps or overlaps.
///
/// # Errors
/// [`TopologyError::YarnGap`], [`TopologyError::YarnOverlap`],
/// [`TopologyError::ShortYarn`], [`TopologyError::YarnPastEnd`] or
/// [`TopologyError::YarnsEndEarly`], naming the first offending yarn.
pub fn validate_yarns(yarns: &[YarnSpan], nodes: usize) -> Result<(), TopologyError> {
    let mut expected = 0usize;
    for (yarn, span) in yarns.iter().enumerate() {
        let start = span.start as usize;
        if start > expected {
            return Err(TopologyError::YarnGap { yarn, start, expected });
        }
        if start < expected {
            return Err(TopologyError::YarnOverlap { yarn, start, expected });
        }
        let min = YarnSpan::min_len(span.closed);
        if span.len() < min {
            return Err(TopologyError::ShortYarn { yarn, nodes: span.len(), closed: span.closed, min });
        }
        if span.end as usize > nodes {
            return Err(TopologyError::YarnPastEnd { yarn, end: span.end as usize, nodes });
        }
        expected = span.end as usize;
    }
    if expected < nodes {
        return Err(TopologyError::YarnsEndEarly { end: expected, nodes });
    }
    Ok(())
}

const DEFAULT_RADIUS: f64 = 0.9;

fn direction(name: &'static str, v: Vec3) -> Result<Vec3, TopologyError> {
    let norm = v.norm();
    if norm.is_finite() && norm > 0.0 {
        Ok(v / norm)
    } else {
        Err(TopologyError::BadDirection { name, value: [v.x, v.y, v.z] })
    }
}

/// The turning angle at `b` between segments a→b and b→c, in [0, π].
fn turning_angle(a: Vec3, b: Vec3, c: Vec3) -> f64 {
    let u = (b - a).normalize();
    let v = (c - b).normalize();
    u.dot(&v).clamp(-1.0, 1.0).acos()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn line(n: usize) -> Vec<Vec3> {
        (0..n).map(|i| Vec3::new(i as f64, (i % 2) as f64, 0.0)).collect()
    }

    fn parts(n: usize) -> FabricParts {
        FabricParts { positions: line(n), ..FabricParts::default() }
    }

    #[test]
    fn rest_values_come_from_the_given_geometry() {
        let f = Fabric::from_parts(FabricParts { contacts: vec![[0, 3], [0, 1]], ..parts(4) }).unwrap();
        assert_eq!(f.springs().len(), 3);
        assert!((f.springs()[0].rest_length - 2f64.sqrt()).abs() < 1e-12);
        // (0,0)->(1,1)->(2,0): a right-angle turn.
        assert!((f.triples()[0].rest_angle - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        assert!((f.contacts()[0].rest - 10f64.sqrt()).abs() < 1e-12, "assembled distance kept");
        assert_eq!(f.contacts()[1].rest, 1.8, "floored at 2r");
    }

    #[test]
    fn each_violation_has_its_own_error() {
        assert_eq!(Fabric::from_parts(FabricParts::default()), Err(TopologyError::NoNodes));
        let mut p = parts(4);
        p.positions[2].y = f64::NAN;
        assert!(matches!(Fabric::from_parts(p), Err(TopologyError::NonFinitePosition { node: 2, axis: 1, .. })));
        let mut p = parts(4);
        p.positions[3] = p.positions[2];
        assert_eq!(Fabric::from_parts(p), Err(TopologyError::ZeroLengthSegment { segment: 2, next: 3 }));
        let p = FabricParts { contacts: vec![[0, 2], [1, 9]], ..parts(4) };
        assert_eq!(Fabric::from_parts(p), Err(TopologyError::ContactOutOfRange { contact: 1, node: 9, nodes: 4 }));
        let p = FabricParts { contacts: vec![[2, 2]], ..parts(4) };
        assert_eq!(Fabric::from_parts(p), Err(TopologyError::SelfContact { contact: 0, node: 2 }));
        let p = FabricParts { contacts: vec![[0, 2], [1, 3], [2, 0]], ..parts(4) };
        assert_eq!(Fabric::from_parts(p), Err(TopologyError::DuplicateContact { contact: 2, first: 0, a: 2, b: 0 }));
        let p = FabricParts { pins: vec![Pin { node: 4, target: Vec3::zeros() }], ..parts(4) };
        assert_eq!(Fabric::from_parts(p), Err(TopologyError::PinOutOfRange { pin: 0, node: 4, nodes: 4 }));
        let p = FabricParts { pins: vec![Pin { node: 1, target: Vec3::new(0.0, 0.0, f64::INFINITY) }], ..parts(4) };
        assert!(matches!(Fabric::from_parts(p), Err(TopologyError::NonFinitePin { pin: 0, axis: 2, .. })));
        let p = FabricParts { boundary: vec![Boundary::INTERIOR; 3], ..parts(4) };
        assert_eq!(Fabric::from_parts(p), Err(TopologyError::BoundaryLength { got: 3, nodes: 4 }));
        let p = FabricParts { course: Some(Vec3::zeros()), ..parts(4) };
        assert!(matches!(Fabric::from_parts(p), Err(TopologyError::BadDirection { name: "course", .. })));
        let p = FabricParts { yarn_radius: Some(-1.0), ..parts(4) };
        assert!(matches!(Fabric::from_parts(p), Err(TopologyError::BadGeometry { name: "yarn_radius", .. })));
    }

    /// An open yarn 0..4, a closed ring 4..9 and a lone node 9: springs and
    /// joints follow each yarn, the ring's wrap around, and nothing joins
    /// two yarns.
    #[test]
    fn several_yarns_never_share_a_spring_or_joint() {
        let yarns = vec![YarnSpan::open(0..4), YarnSpan::closed(4..9), YarnSpan::open(9..10)];
        let f = Fabric::from_parts(FabricParts { yarns: yarns.clone(), contacts: vec![[3, 4], [8, 9]], ..parts(10) })
            .unwrap();
        assert_eq!(f.yarns(), yarns.as_slice());
        let springs: Vec<(u32, u32)> = f.springs().iter().map(|s| (s.a, s.b)).collect();
        assert_eq!(springs, [(0, 1), (1, 2), (2, 3), (4, 5), (5, 6), (6, 7), (7, 8), (8, 4)]);
        let closing = f.springs()[7];
        assert!((closing.rest_length - (f.positions()[4] - f.positions()[8]).norm()).abs() < 1e-12);
        let triples: Vec<(u32, u32, u32)> = f.triples().iter().map(|t| (t.a, t.b, t.c)).collect();
        assert_eq!(triples, [(0, 1, 2), (1, 2, 3), (8, 4, 5), (4, 5, 6), (5, 6, 7), (6, 7, 8), (7, 8, 4)]);
        let wrapped = f.triples()[2];
        let x = f.positions();
        assert!((wrapped.rest_angle - turning_angle(x[8], x[4], x[5])).abs() < 1e-15);
        let links = f.links();
        assert_eq!((links[0].prev(), links[3].next()), (None, None), "the open yarn's ends");
        assert_eq!((links[4].prev(), links[8].next()), (Some(8), Some(4)), "the ring wraps");
        assert_eq!((links[9].prev(), links[9].next()), (None, None), "a lone node has no neighbour");
        assert_eq!(f.contacts().len(), 2, "contacts may join any nodes");
    }

    /// Parts that name no yarns are one open yarn over every node, the
    /// same fabric as naming it.
    #[test]
    fn no_yarns_means_one_open_yarn() {
        let default = Fabric::from_parts(parts(5)).unwrap();
        assert_eq!(default.yarns(), [YarnSpan::open(0..5)]);
        let named = Fabric::from_parts(FabricParts { yarns: vec![YarnSpan::open(0..5)], ..parts(5) }).unwrap();
        assert_eq!(named, default);
        assert!(default.springs().iter().enumerate().all(|(i, s)| s.a as usize == i && s.b as usize == i + 1));
        assert!(default.triples().iter().enumerate().all(|(i, t)| t.b as usize == i + 1 && t.a + 2 == t.c));
    }

    #[test]
    fn each_bad_yarn_list_has_its_own_error() {
        let with = |yarns: Vec<YarnSpan>| Fabric::from_parts(FabricParts { yarns, ..parts(6) });
        assert_eq!(with(vec![YarnSpan::open(1..6)]), Err(TopologyError::YarnGap { yarn: 0, start: 1, expected: 0 }));
        assert_eq!(
            with(vec![YarnSpan::open(0..3), YarnSpan::open(4..6)]),
            Err(TopologyError::YarnGap { yarn: 1, start: 4, expected: 3 })
        );
        assert_eq!(
            with(vec![YarnSpan::open(0..3), YarnSpan::open(2..6)]),
            Err(TopologyError::YarnOverlap { yarn: 1, start: 2, expected: 3 })
        );
        assert_eq!(
            with(vec![YarnSpan::open(0..3), YarnSpan::open(3..3), YarnSpan::open(3..6)]),
            Err(TopologyError::ShortYarn { yarn: 1, nodes: 0, closed: false, min: 1 })
        );
        assert_eq!(
            with(vec![YarnSpan::open(0..4), YarnSpan::closed(4..6)]),
            Err(TopologyError::ShortYarn { yarn: 1, nodes: 2, closed: true, min: 3 })
        );
        assert_eq!(
            with(vec![YarnSpan { start: 0, end: 0, closed: false }, YarnSpan::open(0..6)]),
            Err(TopologyError::ShortYarn { yarn: 0, nodes: 0, closed: false, min: 1 })
        );
        assert_eq!(
            with(vec![YarnSpan { start: 3, end: 1, closed: true }]),
            Err(TopologyError::YarnGap { yarn: 0, start: 3, expected: 0 })
        );
        assert_eq!(
            with(vec![YarnSpan::open(0..2), YarnSpan { start: 2, end: 1, closed: false }]),
            Err(TopologyError::ShortYarn { yarn: 1, nodes: 0, closed: false, min: 1 })
        );
        assert_eq!(with(vec![YarnSpan::open(0..7)]), Err(TopologyError::YarnPastEnd { yarn: 0, end: 7, nodes: 6 }));
        assert_eq!(
            with(vec![YarnSpan::open(0..2), YarnSpan::closed(2..5)]),
            Err(TopologyError::YarnsEndEarly { end: 5, nodes: 6 })
        );
        // The closing segment of a ring whose last node sits on its first.
        let mut p = FabricParts { yarns: vec![YarnSpan::open(0..2), YarnSpan::closed(2..6)], ..parts(6) };
        p.positions[5] = p.positions[2];
        assert_eq!(Fabric::from_parts(p.clone()), Err(TopologyError::ZeroLengthSegment { segment: 5, next: 2 }));
        let message = TopologyError::ZeroLengthSegment { segment: 5, next: 2 }.to_string();
        assert!(message.contains("nodes 5 and 2"), "{message}");
        // Between two yarns nodes may coincide: no segment joins them.
        p.positions[5] = Vec3::new(9.0, 9.0, 9.0);
        p.positions[2] = p.positions[1];
        assert!(Fabric::from_parts(p).is_ok(), "a yarn may start where the last one ended");
        let message = TopologyError::ShortYarn { yarn: 2, nodes: 2, closed: true, min: 3 }.to_string();
        assert!(message.contains("yarn 2") && message.contains("closed") && message.contains('3'), "{message}");
    }

    proptest::proptest! {
        /// Any partition of the nodes into yarns, open or closed, builds a
        /// fabric whose counts follow the yarns, whose springs and joints
        /// each lie within one yarn along it, and whose links agree with
        /// them.
        #[test]
        fn springs_and_joints_follow_any_yarns(
            lengths in proptest::collection::vec((1usize..7, proptest::bool::ANY), 1..6),
        ) {
            let mut yarns = Vec::new();
            for (len, closed) in lengths {
                let start = yarns.last().map_or(0, |y: &YarnSpan| y.end);
                let closed = closed && len >= 3;
                yarns.push(YarnSpan { start, end: start + len as u32, closed });
            }
            let n = yarns.last().map_or(0, |y| y.end as usize);
            // A helix: no two nodes coincide, so no segment is zero.
            let positions = (0..n).map(|i| Vec3::new((i as f64).cos(), (i as f64).sin(), 0.3 * i as f64)).collect();
            let f = Fabric::from_parts(FabricParts { positions, yarns: yarns.clone(), ..FabricParts::default() }).unwrap();
            let springs: usize = yarns.iter().map(YarnSpan::segments).sum();
            let joints: usize = yarns.iter().map(|y| if y.closed { y.len() } else { y.len().saturating_sub(2) }).sum();
            proptest::prop_assert_eq!(f.springs().len(), springs);
            proptest::prop_assert_eq!(f.triples().len(), joints);
            let yarn_of = |node: u32| yarns.iter().position(|y| y.contains(node));
            let links = f.links();
            for s in f.springs() {
                proptest::prop_assert_eq!(yarn_of(s.a), yarn_of(s.b));
                proptest::prop_assert_eq!(links[s.a as usize].next(), Some(s.b));
                proptest::prop_assert_eq!(links[s.b as usize].prev(), Some(s.a));
            }
            for t in f.triples() {
                proptest::prop_assert!(yarn_of(t.a) == yarn_of(t.b) && yarn_of(t.b) == yarn_of(t.c));
                proptest::prop_assert_eq!(links[t.b as usize].raw(), [t.a, t.c]);
            }
            proptest::prop_assert!(f.springs().windows(2).all(|w| w[0].a < w[1].a));
            proptest::prop_assert!(f.triples().windows(2).all(|w| w[0].b < w[1].b));
        }
    }

    #[test]
    fn errors_say_what_to_fix() {
        let message = TopologyError::ContactOutOfRange { contact: 3, node: 12, nodes: 10 }.to_string();
        assert!(message.contains("contact 3") && message.contains("node 12") && message.contains("0..10"), "{message}");
    }
}
