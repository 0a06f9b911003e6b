//! The `Fabric`: one open yarn polyline with its element tables and rest
//! values (SPEC §2). A fabric is valid by construction: both constructors
//! check every index and coordinate, so downstream crates index freely.

use crate::{TopologyError, Vec3};

/// The most nodes one fabric may hold. Backends index nodes with `u32`, and a
/// GPU binding of 2^27 nodes already needs gigabytes; beyond it a fabric is
/// refused rather than half-allocated.
pub(crate) const MAX_NODES: usize = 1 << 27;

/// A stretch spring between consecutive nodes `a` and `a + 1`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Spring {
    /// First node; the second is `a + 1`.
    pub a: u32,
    /// Rest length ℓ0: the assembled segment length.
    pub rest_length: f64,
}

/// A bending triple `(b - 1, b, b + 1)` centred on node `b`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Triple {
    /// Centre node; the neighbours are `b - 1` and `b + 1`.
    pub b: u32,
    /// Rest turning angle θ0 in radians: the assembled angle between the two
    /// segments (0 for a straight joint).
    pub rest_angle: f64,
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
/// Springs and bending triples follow from the node order (one open
/// polyline), and rest values from the given positions, exactly as for a
/// generated fabric.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct FabricParts {
    /// Node positions along the yarn.
    pub positions: Vec<Vec3>,
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

/// One open yarn polyline with its springs, bending triples, persistent
/// contacts, pins, boundary sides and fabric directions.
#[derive(Debug, Clone, PartialEq)]
pub struct Fabric {
    positions: Vec<Vec3>,
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
    /// use yarn_topology::{Fabric, FabricParts, Vec3, TopologyError};
    ///
    /// let parts = FabricParts {
    ///     positions: vec![Vec3::new(0.0, 0.0, 0.0), Vec3::new(1.0, 0.0, 0.0), Vec3::new(1.0, 1.0, 0.0)],
    ///     contacts: vec![[0, 2]],
    ///     ..FabricParts::default()
    /// };
    /// let fabric = Fabric::from_parts(parts.clone())?;
    /// assert_eq!(fabric.springs().len(), 2);
    ///
    /// let bad = FabricParts { contacts: vec![[1, 1]], ..parts };
    /// assert_eq!(Fabric::from_parts(bad), Err(TopologyError::SelfContact { contact: 0, node: 1 }));
    /// # Ok::<(), TopologyError>(())
    /// ```
    pub fn from_parts(parts: FabricParts) -> Result<Self, TopologyError> {
        let FabricParts { positions, contacts, pins, boundary, yarn_radius, course, wale } = parts;
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

        let springs = (0..n.saturating_sub(1))
            .map(|i| {
                let rest_length = (positions[i + 1] - positions[i]).norm();
                // Catches exact duplicates and lengths that would overflow 1/ℓ.
                if rest_length > f64::MIN_POSITIVE && rest_length.is_finite() {
                    Ok(Spring { a: i as u32, rest_length })
                } else {
                    Err(TopologyError::ZeroLengthSegment { segment: i })
                }
            })
            .collect::<Result<Vec<_>, _>>()?;
        let triples = (1..n.saturating_sub(1))
            .map(|b| Triple {
                b: b as u32,
                rest_angle: turning_angle(positions[b - 1], positions[b], positions[b + 1]),
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

        Ok(Self { positions, springs, triples, contacts, pins, boundary, yarn_radius, course, wale, grid: None })
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

    /// The N − 1 stretch springs, one per segment.
    pub fn springs(&self) -> &[Spring] {
        &self.springs
    }

    /// The N − 2 bending triples, one per interior node.
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
        assert_eq!(Fabric::from_parts(p), Err(TopologyError::ZeroLengthSegment { segment: 2 }));
        let p = FabricParts { contacts: vec![[0, 2], [1, 9]], ..parts(4) };
        assert_eq!(Fabric::from_parts(p), Err(TopologyError::ContactOutOfRange { contact: 1, node: 9, nodes: 4 }));
        let p = FabricParts { contacts: vec![[2, 2]], ..parts(4) };
        assert_eq!(Fabric::from_parts(p), Err(TopologyError::SelfContact { contact: 0, node: 2 }));
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

    #[test]
    fn errors_say_what_to_fix() {
        let message = TopologyError::ContactOutOfRange { contact: 3, node: 12, nodes: 10 }.to_string();
        assert!(message.contains("contact 3") && message.contains("node 12") && message.contains("0..10"), "{message}");
    }
}
