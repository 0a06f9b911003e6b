//! `Fabric::from_chart`, and the paper's arch generator (SPEC §2): one loop
//! of `SEG` nodes per stitch, rows laid serpentine, and two contacts where
//! each head is clasped by the feet of the loop above. It is the `paper`
//! preset's geometry ([`crate::LoopShape::Arch`]); it knits stockinette only.
//!
//! The arch profile is a function of a loop phase p in [0, SEG): p = 0 is the
//! low point between loops, p = SEG/2 the head. Rows laid right to left use
//! p = SEG − s for the s-th node, which is the serpentine offset φ_ρ of the
//! paper's eq. (3): the yarn turns at the row end without a zero-length
//! segment, and every head stays centred in its column.

use std::f64::consts::PI;

use crate::fabric::{Boundary, FabricParts, Grid, MAX_NODES};
use crate::{
    Chart, Contact, Fabric, Geometry, LoopShape, Spring, StitchKind, TopologyError, Triple, Vec3, available_memory,
    check_memory, loops,
};

/// What building a fabric holds per node at most: positions and boundary
/// flags in the parts and again in the fabric, a spring, a triple and (at
/// a quarter contact per node) room for a contact.
const FABRIC_BYTES_PER_NODE: u64 = (2 * (size_of::<Vec3>() + size_of::<Boundary>())
    + size_of::<Spring>()
    + size_of::<Triple>()
    + size_of::<Contact>()) as u64;

/// Nodes per loop.
pub const SEG: usize = 8;

/// Phase of the head node within a loop.
const HEAD: usize = SEG / 2;
/// Phases of the two feet, one node in from each end of the loop: the
/// lowest nodes that belong to this loop in both row directions.
const FEET: [usize; 2] = [1, SEG - 1];

impl Geometry {
    /// Position of loop phase `p` in the cell whose lower-left corner is at
    /// (x0, y0): the arch rises as sin² to the head, and the out-of-plane
    /// profile is a raised cosine, forward at the head and back at the feet.
    fn node(&self, x0: f64, y0: f64, p: usize) -> Vec3 {
        let phase = PI * p as f64 / SEG as f64;
        let rise = phase.sin().powi(2);
        Vec3::new(
            x0 + self.stitch_width * p as f64 / SEG as f64,
            y0 + self.loop_height * rise,
            -self.depth * (2.0 * phase).cos(),
        )
    }
}

impl Fabric {
    /// Generate the fabric of a stitch chart with the given loop geometry:
    /// interlooped loops (the default) or the paper's arch
    /// ([`LoopShape`]).
    ///
    /// Rows are laid serpentine, row 0 left to right, row 1 right to left,
    /// and so on; [`Fabric::stitch_node`] finds a stitch's nodes.
    ///
    /// # Errors
    /// [`TopologyError::BadGeometry`] or [`TopologyError::BadNodesPerLoop`]
    /// for a geometry that does not validate, [`TopologyError::TooLarge`]
    /// when the fabric would exceed the node limit,
    /// [`TopologyError::OutOfMemory`] when it would not fit in memory, and
    /// [`TopologyError::NoCrossings`] for an interlooped shape whose loops
    /// do not reach through the row below.
    pub fn from_chart(chart: &Chart, geometry: &Geometry) -> Result<Self, TopologyError> {
        geometry.validate()?;
        let (w, h) = (chart.width(), chart.height());
        let nodes = match geometry.shape {
            LoopShape::Arch => w.checked_mul(h).and_then(|s| s.checked_mul(SEG)),
            LoopShape::Interlooped => Some(loops::layout(chart, geometry).node_count()),
        };
        let nodes = match nodes {
            Some(n) if n <= MAX_NODES => n,
            _ => return Err(TopologyError::TooLarge { width: w, height: h, max_nodes: MAX_NODES }),
        };
        check_memory("the fabric (bytes)", nodes as u64 * FABRIC_BYTES_PER_NODE, available_memory())?;
        match geometry.shape {
            LoopShape::Arch => Fabric::assembled(arch(chart, geometry)?, Grid::Arch { width: w, height: h }),
            LoopShape::Interlooped => {
                let (parts, layout) = loops::build(chart, geometry)?;
                Fabric::assembled(parts, Grid::Loops(layout))
            }
        }
    }
}

/// The paper's arch fabric (SPEC §2): node `SEG * k + s` is the s-th node
/// of the k-th loop along the yarn; row ρ holds loops `ρW .. (ρ+1)W`, left
/// to right for even ρ and right to left for odd ρ.
fn arch(chart: &Chart, geometry: &Geometry) -> Result<FabricParts, TopologyError> {
    let (w, h) = (chart.width(), chart.height());
    for row in 0..h {
        if let Some(column) = (0..w).find(|&c| chart.get(c, row) == Some(StitchKind::Purl)) {
            return Err(TopologyError::ArchPurl { column, row });
        }
    }
    let mut positions = Vec::with_capacity(w * h * SEG);
    let mut boundary = Vec::with_capacity(w * h * SEG);
    for row in 0..h {
        for k in 0..w {
            let column = column_of(row, k, w);
            let x0 = column as f64 * geometry.stitch_width;
            let y0 = row as f64 * geometry.stitch_height;
            for s in 0..SEG {
                positions.push(geometry.node(x0, y0, phase_of(row, s)));
            }
            boundary.extend([Boundary::of_stitch(column, row, w, h); SEG]);
        }
    }
    let mut contacts = Vec::with_capacity(2 * w * h.saturating_sub(1));
    for row in 0..h.saturating_sub(1) {
        for column in 0..w {
            let head = node_index(w, row, column, HEAD);
            for foot in FEET {
                contacts.push([head as u32, node_index(w, row + 1, column, foot) as u32]);
            }
        }
    }
    Ok(FabricParts { positions, contacts, boundary, yarn_radius: Some(geometry.yarn_radius), ..FabricParts::default() })
}

/// Column of the k-th loop laid in `row`.
fn column_of(row: usize, k: usize, width: usize) -> usize {
    if row.is_multiple_of(2) { k } else { width - 1 - k }
}

/// Loop phase of the s-th node laid in `row`.
fn phase_of(row: usize, s: usize) -> usize {
    if row.is_multiple_of(2) { s } else { SEG - s }
}

/// Node index of phase `p` (1..SEG-1 on odd rows, 0..SEG-1 on even rows; the
/// phases FEET and HEAD exist on both) in the stitch at (`column`, `row`).
pub(crate) fn node_index(width: usize, row: usize, column: usize, p: usize) -> usize {
    let k = column_of(row, column, width);
    let s = phase_of(row, p) % SEG;
    (row * width + k) * SEG + s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Side;

    fn patch(w: usize, h: usize) -> Fabric {
        Fabric::from_chart(&Chart::stockinette(w, h).unwrap(), &Geometry::paper()).unwrap()
    }

    #[test]
    fn counts_match_spec_for_16x16() {
        let f = patch(16, 16);
        assert_eq!(f.node_count(), 2048);
        assert_eq!(f.springs().len(), 2047);
        assert_eq!(f.triples().len(), 2046);
        assert_eq!(f.contacts().len(), 480);
    }

    #[test]
    fn counts_follow_formulas_for_thin_and_tiny_charts() {
        for (w, h) in [(1, 1), (1, 5), (7, 1), (3, 4), (5, 2)] {
            let f = patch(w, h);
            let n = 8 * w * h;
            assert_eq!(f.node_count(), n, "{w}x{h}");
            assert_eq!(f.springs().len(), n - 1, "{w}x{h}");
            assert_eq!(f.triples().len(), n - 2, "{w}x{h}");
            assert_eq!(f.contacts().len(), 2 * w * (h - 1), "{w}x{h}");
        }
    }

    #[test]
    fn each_head_reaches_into_the_row_above_between_its_feet() {
        let f = patch(6, 5);
        let x = f.positions();
        for row in 0..4 {
            let next_row_low = (0..6).map(|c| x[f.stitch_node(c, row + 1, 1).unwrap()].y).fold(f64::INFINITY, f64::min);
            for c in 0..6 {
                let head = x[f.stitch_node(c, row, HEAD).unwrap()];
                let feet = FEET.map(|p| x[f.stitch_node(c, row + 1, p).unwrap()]);
                assert!(head.y > (row + 1) as f64 * 4.2, "head of ({c},{row}) stays below the row above");
                assert!(head.y > next_row_low - 0.5, "head of ({c},{row}) does not reach the feet above");
                assert!(feet[0].x < head.x && head.x < feet[1].x, "head of ({c},{row}) not between its clasping feet");
                assert!(head.z > 0.0 && feet.iter().all(|f| f.z < 0.0), "head must be in front, feet behind");
            }
        }
        // Contacts pair exactly these nodes.
        for contact in f.contacts() {
            let (a, b) = (x[contact.a as usize], x[contact.b as usize]);
            assert!(b.y > a.y - 1.0 && (b - a).norm() < 4.0, "contact {contact:?} spans too far");
        }
    }

    #[test]
    fn no_segment_has_zero_length() {
        for (w, h) in [(1, 1), (2, 3), (16, 16)] {
            let f = patch(w, h);
            let shortest = f.springs().iter().map(|s| s.rest_length).fold(f64::INFINITY, f64::min);
            assert!(shortest > 0.5, "{w}x{h}: shortest segment {shortest}");
        }
    }

    #[test]
    fn serpentine_order_is_one_strand() {
        let (w, h) = (5, 4);
        let f = patch(w, h);
        let x = f.positions();
        // Consecutive nodes are near neighbours everywhere, including row turns.
        for s in f.springs() {
            assert!(s.rest_length < 4.0, "segment {} jumps {}", s.a, s.rest_length);
        }
        // Rows alternate direction, and the yarn turns at alternate sides.
        for row in 0..h {
            let first = x[row * w * SEG];
            let last = x[(row + 1) * w * SEG - 1];
            if row % 2 == 0 {
                assert!(last.x > first.x + 4.0 * (w as f64 - 1.0), "row {row} not left to right");
            } else {
                assert!(last.x < first.x - 4.0 * (w as f64 - 1.0), "row {row} not right to left");
            }
        }
    }

    #[test]
    fn boundary_families_cover_the_edges() {
        let f = patch(4, 3);
        let count = |side| f.side_nodes(side).len();
        assert_eq!(count(Side::Bottom), 4 * SEG);
        assert_eq!(count(Side::Top), 4 * SEG);
        assert_eq!(count(Side::Left), 3 * SEG);
        assert_eq!(count(Side::Right), 3 * SEG);
        let interior = f.boundary().iter().filter(|b| b.is_interior()).count();
        assert_eq!(interior, 2 * SEG);
        assert_eq!(f.course(), Vec3::x());
        assert_eq!(f.wale(), Vec3::y());
    }

    #[test]
    fn bad_charts_and_geometry_are_typed_errors() {
        assert_eq!(Chart::stockinette(0, 3), Err(TopologyError::EmptyChart { width: 0, height: 3 }));
        assert!(matches!(Chart::stockinette(usize::MAX, 2), Err(TopologyError::TooLarge { .. })));
        assert!(matches!(Chart::new(2, 2, vec![StitchKind::Knit; 3]), Err(TopologyError::ChartShape { got: 3, .. })));
        let geometry = Geometry { loop_height: f64::NAN, ..Geometry::paper() };
        let err = Fabric::from_chart(&Chart::stockinette(2, 2).unwrap(), &geometry).unwrap_err();
        assert!(matches!(err, TopologyError::BadGeometry { name: "loop_height", .. }));
    }
}
