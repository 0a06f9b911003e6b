//! The interlooped generator: every loop drawn through the loop below it.
//!
//! Each stitch is one period of Crane's plain-knit curve (Crane 2023, see
//! `Geometry`), t in [−π, π): the head at t = 0, the legs around ±π/2,
//! the neck where they come closest, and the sinkers at ±π, shared with the
//! neighbouring stitches. In the face projection (x, y) every stitch is the
//! same; the stitch kinds set only z, crossing by crossing:
//!
//! - A stitch crosses the loop below four times. Its legs pass over (knit)
//!   or under (purl) the lower head at the lower loop's t = ±T1, and its
//!   sinkers pass under (knit) or over (purl) the lower legs at the lower
//!   loop's t = ±T2. T1 and T2 are solved from the curve
//!   ([`Crossings::solve`]); by the curve's point symmetry the upper loop's
//!   parameters are ±(π − T2) and ±(π − T1).
//! - So a loop's head region (|t| ≤ T2) lies as the stitch *above* it
//!   demands, and its legs below the neck and its sinkers (|t| ≥ π − T2)
//!   as its own kind demands. In between, and between two sinker halves of
//!   different kinds, z blends with a smoothstep, passing through the
//!   mid-plane where a knit meets a purl.
//!
//! Every crossing is a node of both strands by construction, and each pair
//! is a persistent contact (the choice the issue offered: nodes at the
//! crossings, so a contact stays a node pair and no backend changes). Rows
//! are laid serpentine and joined at the edges by a turn that bulges one
//! yarn radius outward.

use std::f64::consts::PI;

use crate::fabric::{Boundary, FabricParts, Side};
use crate::{Chart, Geometry, TopologyError, Vec3};

/// The fewest nodes a loop can have: the eight crossing parameters, the
/// head and the sinker.
pub(crate) const MIN_NODES_PER_LOOP: usize = 10;

/// The crossing parameters of one loop with the loop above, on the lower
/// loop: `t1` on its head and `t2` on its legs (0 < t1 < t2 < π/2). The
/// same crossings seen from the upper loop lie at π − t2 and π − t1.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Crossings {
    pub(crate) t1: f64,
    pub(crate) t2: f64,
}

impl Crossings {
    /// Solve lower(t1) = upper(π − t2) in the face projection by Newton's
    /// method from Crane's shape (t1 ≈ 0.27, t2 ≈ 1.28).
    ///
    /// # Errors
    /// [`TopologyError::NoCrossings`] when the loops of adjacent rows do not
    /// cross as a stitch must (a loop too short to reach the row above, or
    /// a shape whose head does not overhang its neck).
    pub(crate) fn solve(g: &Geometry) -> Result<Self, TopologyError> {
        let shape = Shape::of(g);
        // Unknowns (u, v): lower loop at t = u, upper loop at t = v; the
        // upper loop is the lower one moved up a stitch height.
        let residual = |u: f64, v: f64| {
            let (a, b) = (shape.xy(u), shape.xy(v));
            [a[0] - b[0], a[1] - (b[1] + g.stitch_height)]
        };
        let (mut u, mut v) = (0.27, PI - 1.28);
        for _ in 0..60 {
            let r = residual(u, v);
            if r[0].abs().max(r[1].abs()) < 1e-13 * g.stitch_width {
                break;
            }
            let h = 1e-7;
            let du = residual(u + h, v).map2(residual(u - h, v), |p, m| (p - m) / (2.0 * h));
            let dv = residual(u, v + h).map2(residual(u, v - h), |p, m| (p - m) / (2.0 * h));
            let det = du[0] * dv[1] - dv[0] * du[1];
            if det.abs() < f64::MIN_POSITIVE || !det.is_finite() {
                break;
            }
            u -= (r[0] * dv[1] - dv[0] * r[1]) / det;
            v -= (du[0] * r[1] - r[0] * du[1]) / det;
        }
        let r = residual(u, v);
        let (t1, t2) = (u, PI - v);
        let converged = r[0].abs().max(r[1].abs()) < 1e-9 * g.stitch_width;
        if converged && 0.0 < t1 && t1 < t2 && t2 < PI / 2.0 {
            Ok(Self { t1, t2 })
        } else {
            Err(TopologyError::NoCrossings)
        }
    }
}

/// Small helper so the Newton step reads as two 2-vectors.
trait Map2 {
    fn map2(self, other: Self, f: impl Fn(f64, f64) -> f64) -> Self;
}

impl Map2 for [f64; 2] {
    fn map2(self, other: Self, f: impl Fn(f64, f64) -> f64) -> Self {
        [f(self[0], other[0]), f(self[1], other[1])]
    }
}

/// Crane's curve in model units, centred on a stitch: x and y of loop
/// parameter t, and the out-of-plane profile before its sign.
#[derive(Debug, Clone, Copy)]
struct Shape {
    /// Model units of x per unit of t.
    scale_x: f64,
    roundness: f64,
    half_height: f64,
    depth: f64,
}

impl Shape {
    fn of(g: &Geometry) -> Self {
        Self {
            scale_x: g.stitch_width / (2.0 * PI),
            roundness: g.roundness,
            half_height: g.loop_height / 2.0,
            depth: g.depth,
        }
    }

    fn xy(&self, t: f64) -> [f64; 2] {
        [self.scale_x * (t + self.roundness * (2.0 * t).sin()), self.half_height * t.cos()]
    }

    /// z for side σ in [−1, 1]: +1 puts the legs toward the face (knit).
    fn z(&self, t: f64, sigma: f64) -> f64 {
        -self.depth * (2.0 * t).cos() * sigma
    }

    /// Arc length from 0 to t, by the midpoint rule on 256 pieces.
    fn arc(&self, t: f64) -> f64 {
        let pieces = 256;
        let dt = t / pieces as f64;
        (0..pieces)
            .map(|i| {
                let s = (i as f64 + 0.5) * dt;
                let dx = self.scale_x * (1.0 + 2.0 * self.roundness * (2.0 * s).cos());
                let dy = -self.half_height * s.sin();
                let dz = 2.0 * self.depth * (2.0 * s).sin();
                (dx * dx + dy * dy + dz * dz).sqrt() * dt
            })
            .sum()
    }

    /// The parameter at arc length `s` from 0 (inverse of `arc`, by
    /// bisection on [0, π]).
    fn at_arc(&self, s: f64) -> f64 {
        let (mut lo, mut hi) = (0.0, PI);
        for _ in 0..60 {
            let mid = 0.5 * (lo + hi);
            if self.arc(mid) < s {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        0.5 * (lo + hi)
    }
}

/// The loop parameters of a loop's nodes, sorted, in [−π, π): the head,
/// the sinker at −π and the eight crossings, with the other nodes spread
/// so that the pieces between them are as even in arc length as the fixed
/// nodes allow. Symmetric: `params[n − p] = −params[p]`.
pub(crate) fn loop_params(g: &Geometry, crossings: Crossings) -> Vec<f64> {
    let shape = Shape::of(g);
    let Crossings { t1, t2 } = crossings;
    let keys = [0.0, t1, t2, PI - t2, PI - t1, PI];
    let arcs: Vec<f64> = keys.iter().map(|&t| shape.arc(t)).collect();
    let lengths: Vec<f64> = arcs.windows(2).map(|w| w[1] - w[0]).collect();
    // One half-loop holds (n − 10) / 2 free nodes; each goes to the piece
    // whose sub-pieces are longest.
    let mut extra = vec![0usize; lengths.len()];
    for _ in 0..(g.nodes_per_loop - MIN_NODES_PER_LOOP) / 2 {
        let longest = (0..lengths.len())
            .max_by(|&i, &j| (lengths[i] / (extra[i] + 1) as f64).total_cmp(&(lengths[j] / (extra[j] + 1) as f64)))
            .unwrap_or(0);
        extra[longest] += 1;
    }
    let mut half = Vec::with_capacity(g.nodes_per_loop / 2 + 1);
    for (piece, &k) in extra.iter().enumerate() {
        half.push(keys[piece]);
        for j in 1..=k {
            half.push(shape.at_arc(arcs[piece] + lengths[piece] * j as f64 / (k + 1) as f64));
        }
    }
    // half = [0, …, π) with n/2 entries; mirror it to [−π, π).
    let mut params: Vec<f64> = std::iter::once(-PI).chain(half.iter().skip(1).rev().map(|t| -t)).collect();
    params.extend(&half);
    params
}

/// The phase (index into `loop_params`) of parameter `t`, which must be
/// one of them.
pub(crate) fn phase_of(params: &[f64], t: f64) -> usize {
    params.iter().position(|&p| (p - t).abs() < 1e-12).unwrap_or(0)
}

/// The side of the face a loop region lies toward, blended as the module
/// doc says: `own` is this stitch's sign, `above` the sign of the stitch
/// drawn through it, `next` the sign of the neighbour in the row on the
/// side of t.
fn side(t: f64, crossings: Crossings, own: f64, above: f64, next: f64) -> f64 {
    let Crossings { t1, t2 } = crossings;
    let at = t.abs();
    if at <= PI - t1 {
        above + (own - above) * smoothstep((at - t2) / (PI - 2.0 * t2))
    } else {
        own + (0.5 * (own + next) - own) * smoothstep((at - (PI - t1)) / t1)
    }
}

fn smoothstep(x: f64) -> f64 {
    let x = x.clamp(0.0, 1.0);
    x * x * (3.0 - 2.0 * x)
}

/// The node layout of an interlooped fabric: row r's loops, then (below
/// the top row) the turn up to row r + 1.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Layout {
    pub(crate) width: usize,
    pub(crate) height: usize,
    pub(crate) nodes_per_loop: usize,
    /// Nodes inside each turn between rows (excluding both row ends).
    pub(crate) turn_nodes: usize,
}

impl Layout {
    /// Nodes in one row: its loops and the sinker node at its far end.
    fn row_nodes(&self) -> usize {
        self.width * self.nodes_per_loop + 1
    }

    /// Every node of the fabric.
    pub(crate) fn node_count(&self) -> usize {
        self.height * self.row_nodes() + self.height.saturating_sub(1) * self.turn_nodes
    }

    /// Index of phase `p` (0 ≤ p ≤ nodes_per_loop; p = nodes_per_loop is
    /// the sinker node at t = π, phase 0 of the next column) of the stitch
    /// at (`column`, `row`).
    pub(crate) fn index(&self, column: usize, row: usize, p: usize) -> usize {
        let start = row * (self.row_nodes() + self.turn_nodes);
        let along = column * self.nodes_per_loop + p;
        if row.is_multiple_of(2) { start + along } else { start + self.row_nodes() - 1 - along }
    }
}

/// The turn between rows needs this many interior nodes for pieces about
/// as long as the loop's.
fn turn_nodes(g: &Geometry) -> usize {
    let loop_length = 2.0 * Shape::of(g).arc(PI);
    let piece = loop_length / g.nodes_per_loop as f64;
    ((g.stitch_height / piece).round() as usize).max(2) - 1
}

/// The layout of `chart` under `g`, for sizing before building.
pub(crate) fn layout(chart: &Chart, g: &Geometry) -> Layout {
    Layout { width: chart.width(), height: chart.height(), nodes_per_loop: g.nodes_per_loop, turn_nodes: turn_nodes(g) }
}

/// Build the interlooped fabric of `chart`.
pub(crate) fn build(chart: &Chart, g: &Geometry) -> Result<(FabricParts, Layout), TopologyError> {
    let crossings = Crossings::solve(g)?;
    let params = loop_params(g, crossings);
    let shape = Shape::of(g);
    let layout = layout(chart, g);
    let (w, h, n) = (layout.width, layout.height, layout.nodes_per_loop);
    let sign = |column: usize, row: usize| chart.get(column, row).map_or(1.0, |k| k.sign());
    let mut positions = vec![Vec3::zeros(); layout.node_count()];
    let mut boundary = vec![Boundary::INTERIOR; layout.node_count()];
    for row in 0..h {
        for column in 0..w {
            let own = sign(column, row);
            let above = if row + 1 < h { sign(column, row + 1) } else { own };
            let sides = Boundary::of_stitch(column, row, w, h);
            let last = column + 1 == w;
            let far_sinker = last.then_some(PI);
            for (p, t) in params.iter().copied().chain(far_sinker).enumerate() {
                let next = match (t < 0.0, column) {
                    (true, 0) => own,
                    (true, c) => sign(c - 1, row),
                    (false, c) if c + 1 < w => sign(c + 1, row),
                    (false, _) => own,
                };
                let [x, y] = shape.xy(t);
                let i = layout.index(column, row, p);
                positions[i] = Vec3::new(
                    column as f64 * g.stitch_width + x,
                    row as f64 * g.stitch_height + y,
                    shape.z(t, side(t, crossings, own, above, next)),
                );
                boundary[i] = sides;
            }
        }
    }
    for row in 0..h.saturating_sub(1) {
        // The turn: from this row's far end to the next row's start,
        // bulging one yarn radius outward from the edge.
        let (from, to) = if row.is_multiple_of(2) {
            (layout.index(w - 1, row, n), layout.index(w - 1, row + 1, n))
        } else {
            (layout.index(0, row, 0), layout.index(0, row + 1, 0))
        };
        let outward = if row.is_multiple_of(2) { 1.0 } else { -1.0 };
        let (a, b) = (positions[from], positions[to]);
        let edge = if row.is_multiple_of(2) { Side::Right } else { Side::Left };
        let sides = Boundary::INTERIOR.with(edge);
        for k in 1..=layout.turn_nodes {
            let s = k as f64 / (layout.turn_nodes + 1) as f64;
            let bulge = outward * g.yarn_radius * (PI * s).sin();
            positions[from + k] = a + (b - a) * s + Vec3::new(bulge, 0.0, 0.0);
            boundary[from + k] = sides;
        }
    }
    let mut contacts = Vec::with_capacity(4 * w * h.saturating_sub(1));
    let Crossings { t1, t2 } = crossings;
    for row in 0..h.saturating_sub(1) {
        for column in 0..w {
            for (lower, upper) in [(t1, PI - t2), (t2, PI - t1), (-t1, t2 - PI), (-t2, t1 - PI)] {
                let a = layout.index(column, row, phase_of(&params, lower));
                let b = layout.index(column, row + 1, phase_of(&params, upper));
                contacts.push([a as u32, b as u32]);
            }
        }
    }
    let parts =
        FabricParts { positions, contacts, boundary, yarn_radius: Some(g.yarn_radius), ..FabricParts::default() };
    Ok((parts, layout))
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::{Fabric, Front, StitchKind};

    /// Closest distance between segments p0p1 and q0q1 (Eberly's clamped
    /// parameters, exact for segments).
    pub(crate) fn segment_distance(p0: Vec3, p1: Vec3, q0: Vec3, q1: Vec3) -> f64 {
        let (u, v, w0) = (p1 - p0, q1 - q0, p0 - q0);
        let (a, b, c, d, e) = (u.dot(&u), u.dot(&v), v.dot(&v), u.dot(&w0), v.dot(&w0));
        let den = a * c - b * b;
        let mut s = if den > 1e-14 * a * c { ((b * e - c * d) / den).clamp(0.0, 1.0) } else { 0.0 };
        let mut t = (b * s + e) / c;
        if t < 0.0 {
            t = 0.0;
            s = (-d / a).clamp(0.0, 1.0);
        } else if t > 1.0 {
            t = 1.0;
            s = ((b - d) / a).clamp(0.0, 1.0);
        }
        (w0 + u * s - v * t).norm()
    }

    /// The smallest distance between two segments that lie more than
    /// `apart` of arc length from each other along the yarn, and where.
    pub(crate) fn clearance(x: &[Vec3], apart: f64) -> (f64, usize, usize) {
        let mut arc = vec![0.0];
        for w in x.windows(2) {
            arc.push(arc[arc.len() - 1] + (w[1] - w[0]).norm());
        }
        let mut best = (f64::INFINITY, 0, 0);
        for i in 0..x.len() - 1 {
            for j in i + 1..x.len() - 1 {
                if arc[j] - arc[i + 1] < apart {
                    continue;
                }
                let d = segment_distance(x[i], x[i + 1], x[j], x[j + 1]);
                if d < best.0 {
                    best = (d, i, j);
                }
            }
        }
        best
    }

    pub(crate) fn fabric(w: usize, h: usize, kind: impl Fn(usize, usize) -> StitchKind) -> Fabric {
        let stitches = (0..h).flat_map(|r| (0..w).map(move |c| (c, r))).map(|(c, r)| kind(c, r)).collect();
        Fabric::from_chart(&Chart::new(w, h, stitches).unwrap(), &Geometry::default()).unwrap()
    }

    /// The closed curve of one loop: its nodes from sinker to sinker,
    /// closed across its feet by the chord between the two sinkers.
    pub(crate) fn closed_loop(f: &Fabric, column: usize, row: usize) -> Vec<Vec3> {
        let n = f.nodes_per_loop().unwrap();
        let mut nodes: Vec<usize> = (0..n).map(|p| f.stitch_node(column, row, p).unwrap()).collect();
        let last = nodes[n - 1];
        let toward_far_end = if row.is_multiple_of(2) { last + 1 } else { last - 1 };
        nodes.push(toward_far_end);
        nodes.iter().map(|&i| f.positions()[i]).collect()
    }

    fn stockinette(w: usize, h: usize) -> Fabric {
        fabric(w, h, |_, _| StitchKind::Knit)
    }

    #[test]
    fn counts_follow_the_layout() {
        let g = Geometry::default();
        let turn = turn_nodes(&g);
        assert!(turn >= 1, "a turn has interior nodes");
        for (w, h) in [(1, 1), (1, 4), (5, 1), (3, 4), (16, 16)] {
            let f = stockinette(w, h);
            let n = h * (24 * w + 1) + (h - 1) * turn;
            assert_eq!(f.node_count(), n, "{w}x{h}");
            assert_eq!(f.springs().len(), n - 1, "{w}x{h}");
            assert_eq!(f.contacts().len(), 4 * w * (h - 1), "{w}x{h}: four crossings per stitch above row 0");
            assert_eq!(f.grid(), Some((w, h)));
        }
    }

    #[test]
    fn every_node_is_laid_once_in_yarn_order() {
        let (w, h) = (4, 3);
        let f = stockinette(w, h);
        let mut seen = vec![false; f.node_count()];
        for r in 0..h {
            for c in 0..w {
                for p in 0..24 {
                    let i = f.stitch_node(c, r, p).unwrap();
                    assert!(!seen[i], "node {i} is two stitches' node");
                    seen[i] = true;
                }
            }
        }
        let loop_nodes = seen.iter().filter(|&&s| s).count();
        assert_eq!(loop_nodes, w * h * 24);
        // Consecutive nodes are near neighbours along the whole yarn.
        let longest = f.springs().iter().map(|s| s.rest_length).fold(0.0, f64::max);
        let shortest = f.springs().iter().map(|s| s.rest_length).fold(f64::INFINITY, f64::min);
        assert!(longest < 3.0 && shortest > 0.3, "segments from {shortest} to {longest}");
        assert_eq!(f.head_node(1, 1), f.stitch_node(1, 1, 12));
        let head = f.positions()[f.head_node(1, 1).unwrap()];
        assert!((head.x - 7.32).abs() < 1e-9 && (head.y - (5.83 + 9.33 / 2.0)).abs() < 1e-9, "head {head:?}");
    }

    #[test]
    fn crossings_are_nodes_of_both_strands() {
        let c = Crossings::solve(&Geometry::default()).unwrap();
        assert!((c.t1 - 0.2693).abs() < 1e-3 && (c.t2 - 1.2807).abs() < 1e-3, "{c:?}");
        let f = stockinette(4, 3);
        let x = f.positions();
        for contact in f.contacts() {
            let (a, b) = (x[contact.a as usize], x[contact.b as usize]);
            assert!(
                (a.xy() - b.xy()).norm() < 1e-9,
                "contact {contact:?}: strands at {a:?} and {b:?} do not cross there"
            );
            assert!(contact.front.is_some(), "contact {contact:?} has no order");
        }
    }

    fn pattern(p: crate::Pattern, w: usize, h: usize) -> Fabric {
        fabric(w, h, |c, r| p.stitch(c, r))
    }

    #[test]
    fn each_crossing_lies_as_its_stitch_kind_demands() {
        let (w, h) = (6, 5);
        for p in crate::Pattern::ALL {
            let f = pattern(p, w, h);
            for r in 1..h {
                for c in 0..w {
                    let kind = p.stitch(c, r);
                    let crossings = &f.contacts()[4 * ((r - 1) * w + c)..][..4];
                    for (k, contact) in crossings.iter().enumerate() {
                        // Pairs 0 and 2: the upper loop's leg over the lower
                        // head; 1 and 3: the lower leg over the upper sinker
                        // (for knit; purl reverses both).
                        let upper_in_front = (k % 2 == 0) == (kind == StitchKind::Knit);
                        let expected = if upper_in_front { Front::B } else { Front::A };
                        assert_eq!(contact.front, Some(expected), "{p}: stitch ({c},{r}) crossing {k} ({kind:?})");
                    }
                }
            }
        }
    }

    /// Where two segments' face projections cross, if they do.
    fn projected_crossing(p0: Vec3, p1: Vec3, q0: Vec3, q1: Vec3) -> Option<[f64; 2]> {
        let (r, s, qp) = (p1 - p0, q1 - q0, q0 - p0);
        let den = r.x * s.y - r.y * s.x;
        if den.abs() < 1e-14 {
            return None;
        }
        let u = (qp.x * s.y - qp.y * s.x) / den;
        let v = (qp.x * r.y - qp.y * r.x) / den;
        let inside = |t: f64| (-1e-9..=1.0 + 1e-9).contains(&t);
        (inside(u) && inside(v)).then(|| [p0.x + u * r.x, p0.y + u * r.y])
    }

    #[test]
    fn every_crossing_in_the_face_view_is_a_contact() {
        for p in [crate::Pattern::Stockinette, crate::Pattern::Seed] {
            let f = pattern(p, 4, 4);
            let x = f.positions();
            let mut found: Vec<[f64; 2]> = Vec::new();
            for i in 0..x.len() - 1 {
                for j in i + 2..x.len() - 1 {
                    if let Some(point) = projected_crossing(x[i], x[i + 1], x[j], x[j + 1])
                        && !found.iter().any(|q| (q[0] - point[0]).hypot(q[1] - point[1]) < 1e-6)
                    {
                        found.push(point);
                    }
                }
            }
            for point in &found {
                let at_contact = f.contacts().iter().any(|c| {
                    let a = x[c.a as usize];
                    (a.x - point[0]).hypot(a.y - point[1]) < 1e-6
                });
                assert!(at_contact, "{p}: strands cross at {point:?} where there is no contact");
            }
            assert_eq!(found.len(), f.contacts().len(), "{p}: one contact per crossing");
        }
    }

    /// Where segment p0p1 passes through triangle abc, as the sign of its
    /// travel along the fabric normal (+1 toward the face), if it does.
    fn piercing(p0: Vec3, p1: Vec3, [a, b, c]: [Vec3; 3]) -> Option<f64> {
        let normal = (b - a).cross(&(c - a));
        let (d0, d1) = ((p0 - a).dot(&normal), (p1 - a).dot(&normal));
        if d0.signum() == d1.signum() {
            return None;
        }
        let hit = p0 + (p1 - p0) * (d0 / (d0 - d1));
        let inside = [(a, b), (b, c), (c, a)].iter().all(|(u, v)| (v - u).cross(&(hit - u)).dot(&normal) >= 0.0);
        inside.then(|| (p1.z - p0.z).signum())
    }

    /// Each half of loop (c, r), head to sinker, passes once through the
    /// spanning fan of loop (c, r − 1) closed across its neck.
    fn piercings(f: &Fabric, params: &[f64], column: usize, row: usize) -> [Vec<f64>; 2] {
        let n = f.nodes_per_loop().unwrap();
        let x = f.positions();
        // The lower loop from neck to neck: the nodes nearest the narrowest
        // point of the legs, then the chord across it.
        let neck = (0..n)
            .filter(|&p| params[p] > 0.0)
            .min_by(|&p, &q| {
                x[f.stitch_node(column, row - 1, p).unwrap()]
                    .x
                    .total_cmp(&x[f.stitch_node(column, row - 1, q).unwrap()].x)
                    .then(q.cmp(&p))
            })
            .unwrap();
        let lower: Vec<Vec3> = (n - neck..=neck).map(|p| x[f.stitch_node(column, row - 1, p).unwrap()]).collect();
        let centre = lower.iter().sum::<Vec3>() / lower.len() as f64;
        let fan: Vec<[Vec3; 3]> = (0..lower.len()).map(|i| [centre, lower[i], lower[(i + 1) % lower.len()]]).collect();
        let upper = closed_loop(f, column, row);
        let (upper, fan) = (&upper, &fan);
        let half = |range: std::ops::Range<usize>| -> Vec<f64> {
            range.flat_map(|i| fan.iter().filter_map(move |tri| piercing(upper[i], upper[i + 1], *tri))).collect()
        };
        [half(0..n / 2), half(n / 2..n)]
    }

    #[test]
    fn every_loop_is_drawn_through_the_loop_below_as_its_kind_demands() {
        let params = loop_params(&Geometry::default(), Crossings::solve(&Geometry::default()).unwrap());
        let (w, h) = (5, 4);
        for p in crate::Pattern::ALL {
            let f = pattern(p, w, h);
            for r in 1..h {
                for c in 0..w {
                    let side = p.stitch(c, r).sign();
                    let [rising, falling] = piercings(&f, &params, c, r);
                    // Knit: the rising half comes through from the back to
                    // the face, the falling half goes back; purl reverses.
                    assert_eq!(rising, vec![side], "{p}: stitch ({c},{r}), rising half");
                    assert_eq!(falling, vec![-side], "{p}: stitch ({c},{r}), falling half");
                    if c + 1 < w {
                        let [a, b] = piercings(&f, &params, c + 1, r);
                        assert_eq!((a.len(), b.len()), (1, 1), "{p}: ({},{r}) ", c + 1);
                    }
                }
            }
        }
    }

    #[test]
    fn the_assembled_yarn_does_not_interpenetrate() {
        let r = Geometry::default().yarn_radius;
        for p in crate::Pattern::ALL {
            let f = pattern(p, 5, 4);
            let (d, i, j) = clearance(f.positions(), PI * r);
            eprintln!("{p}: clearance {d:.4} = {:.4} of 2r at segments {i}, {j}", d / (2.0 * r));
            assert!(d > 2.0 * r * (1.0 - CLEARANCE_TOLERANCE), "{p}: segments {i} and {j} are {d} apart");
        }
    }

    /// How far below 2r the assembled polyline may come, as a fraction of
    /// 2r: the chords cut inside the curve they sample. Measured at the
    /// default 24 nodes a loop: 0.959 of 2r for stockinette, reverse
    /// stockinette and garter, 0.933 for the ribs and seed (a sinker
    /// passing between a knit and a purl column); see the test's output.
    const CLEARANCE_TOLERANCE: f64 = 0.1;

    /// The sampling table behind the default nodes per loop
    /// (`docs/patterns.md`): for each n, the smallest clearance of the
    /// assembled stockinette over 2r, the loop's polyline length against
    /// the curve's, and the largest gap between a chord and the curve at
    /// the chord's middle parameter, in yarn radii. Run with
    /// `cargo test -p yarn-topology --release sampling -- --nocapture`.
    #[test]
    fn sampling_error_falls_as_nodes_per_loop_grow() {
        let mut rows = Vec::new();
        for n in [10, 12, 16, 20, 24, 32, 48] {
            let g = Geometry { nodes_per_loop: n, ..Geometry::default() };
            let crossings = Crossings::solve(&g).unwrap();
            let shape = Shape::of(&g);
            let params = loop_params(&g, crossings);
            let point = |t: f64| {
                let [x, y] = shape.xy(t);
                Vec3::new(x, y, shape.z(t, 1.0))
            };
            let ends: Vec<f64> = params.iter().copied().chain([PI]).collect();
            let polyline: f64 = ends.windows(2).map(|w| (point(w[1]) - point(w[0])).norm()).sum();
            let deviation = ends
                .windows(2)
                .map(|w| (point(0.5 * (w[0] + w[1])) - 0.5 * (point(w[0]) + point(w[1]))).norm())
                .fold(0.0, f64::max);
            let f = Fabric::from_chart(&Chart::stockinette(5, 4).unwrap(), &g).unwrap();
            let (clear, _, _) = clearance(f.positions(), PI * g.yarn_radius);
            let length = 2.0 * shape.arc(PI);
            rows.push((n, clear / (2.0 * g.yarn_radius), polyline / length - 1.0, deviation / g.yarn_radius));
        }
        eprintln!("nodes/loop  clearance/2r  length error  chord gap/r");
        for (n, c, l, d) in &rows {
            eprintln!("{n:>10}  {c:>12.4}  {l:>12.2e}  {d:>11.4}");
        }
        for pair in rows.windows(2) {
            let ((n0, _, l0, d0), (n1, _, l1, d1)) = (pair[0], pair[1]);
            assert!(l1.abs() < l0.abs() && d1 <= d0, "{n1} nodes sample the loop no better than {n0}");
        }
    }

    #[test]
    fn the_default_shape_has_the_documented_gauge() {
        let g = Geometry::default();
        let shape = Shape::of(&g);
        let loop_length = 2.0 * shape.arc(PI);
        let diameter = 2.0 * g.yarn_radius;
        let close =
            |got: f64, want: f64, what: &str| assert!((got - want).abs() < 0.01, "{what}: {got}, documented {want}");
        close(loop_length, 31.05, "loop length");
        close(loop_length / diameter, 17.25, "loop length over yarn diameter");
        close(loop_length / g.stitch_width, 4.24, "k_w");
        close(loop_length / g.stitch_height, 5.33, "k_c");
        // The neck, where a loop's legs pass closest, is one diameter wide.
        let neck = (0..2000)
            .map(|i| PI / 2.0 + PI / 2.0 * i as f64 / 2000.0)
            .map(|t| shape.xy(t)[0])
            .fold(f64::INFINITY, f64::min);
        close(2.0 * neck / diameter, 1.0, "neck over yarn diameter");
    }
}
