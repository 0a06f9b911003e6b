//! The tube's twist-free frames: [`transport_normals`] carries a normal
//! along the yarn by parallel transport. Pure geometry on positions; this
//! room must not know about the GPU, the camera or the mesh format.

use nalgebra::{Rotation3, Unit, Vector3};
use yarn_topology::YarnSpan;

use crate::positions::{spans, vector};

/// Each node's frame normal, carried along its yarn by parallel transport
/// (each step rotates it by the turn from one segment to the next), so the
/// tube's rings do not twist. Degenerate segments keep the previous frame.
/// Each of `yarns` (empty: one open yarn over every node) is transported
/// on its own. Around a closed yarn the transport comes back to its first
/// node turned by the loop's holonomy; that turn is spread evenly over its
/// segments, so the closing one twists no more than the rest.
///
/// The yarns are not checked here; spans that do not cover the positions
/// (see [`yarn_topology::validate_yarns`]) give normals for the nodes they
/// do cover.
pub fn transport_normals(positions: &[[f32; 3]], yarns: &[YarnSpan]) -> Vec<[f32; 3]> {
    let mut normals = Vec::with_capacity(positions.len());
    for yarn in spans(yarns, positions.len()) {
        let Some(nodes) = positions.get(yarn.nodes()) else { continue };
        normals.extend(transport(nodes, yarn.closed));
    }
    normals.into_iter().map(|normal| [normal.x as f32, normal.y as f32, normal.z as f32]).collect()
}

/// The unit direction from `a` to `b`, or +x where they coincide.
fn direction(a: &[f32; 3], b: &[f32; 3]) -> Vector3<f64> {
    (vector(b) - vector(a)).try_normalize(1e-12).unwrap_or_else(Vector3::x)
}

/// The rotation that turns `incoming` onto `outgoing` about their common
/// normal, or `None` when they are parallel.
fn turn(incoming: Vector3<f64>, outgoing: Vector3<f64>) -> Option<Rotation3<f64>> {
    let axis = incoming.cross(&outgoing);
    let sin = axis.norm();
    (sin > 1e-12).then(|| Rotation3::from_axis_angle(&Unit::new_normalize(axis), sin.atan2(incoming.dot(&outgoing))))
}

/// One yarn's normals, one per node: node i's belongs to the segment
/// leaving it (the last node of an open yarn keeps its predecessor's).
fn transport(nodes: &[[f32; 3]], closed: bool) -> Vec<Vector3<f64>> {
    let mut tangents: Vec<Vector3<f64>> = nodes.windows(2).map(|segment| direction(&segment[0], &segment[1])).collect();
    if let (true, Some(first), Some(last)) = (closed, nodes.first(), nodes.last()) {
        tangents.push(direction(last, first));
    }
    let first = tangents.first().copied().unwrap_or_else(Vector3::x);
    // Any unit vector perpendicular to the first tangent.
    let helper = if first.x.abs() < 0.9 { Vector3::x() } else { Vector3::y() };
    let mut normal = (helper - first * helper.dot(&first)).normalize();
    let mut normals = Vec::with_capacity(nodes.len());
    normals.push(normal);
    for pair in tangents.windows(2) {
        if let Some(rotation) = turn(pair[0], pair[1]) {
            normal = rotation * normal;
        }
        normals.push(normal);
    }
    if closed {
        // Once more across the closing joint, onto the first segment: the
        // angle it ends at from the first normal, about the first tangent,
        // is the holonomy, undone a share per segment.
        let back = turn(tangents[tangents.len() - 1], first).map_or(normal, |rotation| rotation * normal);
        let holonomy = first.dot(&normals[0].cross(&back)).atan2(normals[0].dot(&back));
        let count = nodes.len() as f64;
        for (k, (normal, tangent)) in normals.iter_mut().zip(&tangents).enumerate() {
            let undo = Rotation3::from_axis_angle(&Unit::new_normalize(*tangent), -holonomy * k as f64 / count);
            *normal = undo * *normal;
        }
    } else {
        normals.push(normal);
    }
    normals.truncate(nodes.len());
    normals
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn transported_normals_stay_unit_and_perpendicular_and_a_line_keeps_its_normal() {
        // Along a helix the transported normal stays unit and perpendicular
        // to the yarn; how it turns is the next test's.
        let positions: Vec<[f32; 3]> =
            (0..200).map(|i| i as f32 * 0.1).map(|t| [t.cos() * 3.0, t.sin() * 3.0, t * 0.5]).collect();
        let normals = transport_normals(&positions, &[]);
        for (i, n) in normals.iter().enumerate().take(positions.len() - 1) {
            let n = vector(n);
            let t = (vector(&positions[i + 1]) - vector(&positions[i])).normalize();
            assert!((n.norm() - 1.0).abs() < 1e-5, "node {i}: |n| = {}", n.norm());
            // Perpendicular to the incoming or outgoing segment (the frame
            // is transported per segment).
            assert!(n.dot(&t).abs() < 1e-4 || i == 0, "node {i}: n·t = {}", n.dot(&t));
        }
        // A straight line keeps its normal exactly.
        let line: Vec<[f32; 3]> = (0..10).map(|i| [i as f32, 0.0, 0.0]).collect();
        let normals = transport_normals(&line, &[]);
        assert!(normals.windows(2).all(|w| w[0] == w[1]));
    }

    /// The twist left on each segment of a closed loop of `positions`
    /// between node k's normal carried across the joint at k + 1 and that
    /// node's own, about its outgoing tangent; the last is the closing
    /// segment's, carried onto the first node.
    fn loop_twists(positions: &[[f32; 3]], normals: &[Vector3<f64>]) -> Vec<f64> {
        let n = positions.len();
        let tangent = |k: usize| direction(&positions[k % n], &positions[(k + 1) % n]);
        (0..n)
            .map(|k| {
                let carried = turn(tangent(k), tangent(k + 1)).map_or(normals[k], |r| r * normals[k]);
                let own = normals[(k + 1) % n];
                tangent(k + 1).dot(&carried.cross(&own)).atan2(carried.dot(&own))
            })
            .collect()
    }

    /// Around a closed loop that is not flat (a lopsided saddle, whose
    /// transport comes back turned by 1.27 rad), the normals stay unit and
    /// perpendicular to each node's outgoing segment, the closing one's
    /// included, and the twist left on each segment is the same on every
    /// one, the closing one too; a flat ring has none. Each yarn is
    /// transported on its own: an open yarn after the loop starts afresh.
    #[test]
    fn a_closed_loop_spreads_its_holonomy_evenly() {
        let n = 40;
        let mut positions: Vec<[f32; 3]> = (0..n)
            .map(|i| std::f32::consts::TAU * i as f32 / n as f32)
            .map(|t| [3.0 * t.cos() + (2.0 * t).cos(), 3.0 * t.sin(), 1.5 * (2.0 * t).sin()])
            .collect();
        positions.extend((0..5).map(|i| [i as f32, 10.0, 0.0]));
        let yarns = [YarnSpan::closed(0..n as u32), YarnSpan::open(n as u32..n as u32 + 5)];
        let normals: Vec<Vector3<f64>> = transport_normals(&positions, &yarns).iter().map(vector).collect();
        assert_eq!(normals.len(), n + 5);
        for k in 0..n {
            let tangent = direction(&positions[k], &positions[(k + 1) % n]);
            assert!((normals[k].norm() - 1.0).abs() < 1e-6, "node {k}");
            assert!(normals[k].dot(&tangent).abs() < 1e-6, "node {k}: n·t = {}", normals[k].dot(&tangent));
        }
        let twists = loop_twists(&positions[..n], &normals[..n]);
        let spread = twists.iter().fold(0.0f64, |m, t| m.max((t - twists[0]).abs()));
        println!("twist per segment {:.3e} rad, spread {spread:.1e}", twists[0]);
        assert!((twists[0] * n as f64).abs() > 1.0, "the saddle should carry its holonomy: {}", twists[0]);
        assert!(spread < 1e-5, "the closing segment twists {} against {} elsewhere", twists[n - 1], twists[0]);
        // The open yarn after it is a line: its normals are all one.
        assert!(normals[n..].windows(2).all(|w| (w[0] - w[1]).norm() < 1e-7));
        let flat: Vec<[f32; 3]> = positions[..n].iter().map(|p| [p[0], p[1], 0.0]).collect();
        let normals: Vec<Vector3<f64>> =
            transport_normals(&flat, &[YarnSpan::closed(0..n as u32)]).iter().map(vector).collect();
        let most = loop_twists(&flat, &normals).into_iter().fold(0.0f64, |m, t| m.max(t.abs()));
        assert!(most < 1e-6, "a flat ring twists {most} rad on a segment");
    }

    /// How far the measured twist along the helix may stray from the
    /// analytic transport, as a fraction of it. The polyline is a discrete
    /// helix in `f32`, whose chords turn a little differently from the
    /// curve (an O(h²) gap at h = 0.05), plus rounding. Measured: the total
    /// twist 0.030 % off, the worst segment's rate 0.031 % (re-measure with
    /// `cargo test --release -p yarn-render --lib twist -- --nocapture`).
    /// A frame that ignores the torsion, as a Frenet frame does, is 100 %
    /// off.
    const TWIST_TOLERANCE: f64 = 0.01;

    #[test]
    fn transported_normals_twist_against_frenet_at_the_helix_torsion() {
        use std::f64::consts::{PI, TAU};
        // The helix (a cos t, a sin t, c t) has torsion τ = c / (a² + c²)
        // and arc length √(a² + c²) per unit t. Written as n = cos θ N +
        // sin θ B in the Frenet frame (N, B), a normal with no twist of its
        // own obeys dθ/ds = −τ: it turns against the Frenet frame at the
        // torsion's rate. A Frenet frame, or any frame squared against a
        // fixed axis, keeps θ constant here.
        let (a, c, h) = (3.0f64, 0.5f64, 0.05f64);
        let torsion = c / (a * a + c * c);
        let ts: Vec<f64> = (0..400).map(|i| f64::from(i) * h).collect();
        let positions: Vec<[f32; 3]> =
            ts.iter().map(|&t| [(a * t.cos()) as f32, (a * t.sin()) as f32, (c * t) as f32]).collect();
        let normals = transport_normals(&positions, &[]);
        // Node i's normal belongs to its outgoing segment: measure it in the
        // Frenet frame at that segment's middle, where the chord's tangent
        // has the principal normal −(cos t, sin t, 0) exactly.
        let angles: Vec<f64> = (0..positions.len() - 1)
            .map(|i| {
                let tangent = (vector(&positions[i + 1]) - vector(&positions[i])).normalize();
                let middle = ts[i] + h / 2.0;
                let principal = Vector3::new(-middle.cos(), -middle.sin(), 0.0);
                let binormal = tangent.cross(&principal);
                let n = vector(&normals[i]);
                n.dot(&binormal).atan2(n.dot(&principal))
            })
            .collect();
        // The turn from one angle to the next, in (−π, π].
        let turn = |from: f64, to: f64| (to - from + PI).rem_euclid(TAU) - PI;
        let length_per_segment = (a * a + c * c).sqrt() * h;
        let rates: Vec<f64> = angles.windows(2).map(|pair| turn(pair[0], pair[1]) / length_per_segment).collect();
        let twist = rates.iter().sum::<f64>() * length_per_segment;
        let length = length_per_segment * rates.len() as f64;
        let error = (twist + torsion * length).abs() / (torsion * length);
        let off = |rate: f64| (rate + torsion).abs() / torsion;
        let (worst, worst_rate) =
            rates.iter().copied().enumerate().max_by(|a, b| off(a.1).total_cmp(&off(b.1))).expect("rates");
        println!(
            "twist over {length:.2}: {twist:.5} rad against −τL = {:.5} rad ({:.3} % off); worst segment {worst}: {:.3} % off",
            -torsion * length,
            100.0 * error,
            100.0 * off(worst_rate)
        );
        assert!(
            error < TWIST_TOLERANCE,
            "total twist {twist} rad over {length}, the torsion says {} rad",
            -torsion * length
        );
        assert!(
            off(worst_rate) < TWIST_TOLERANCE,
            "segment {worst}: dθ/ds = {worst_rate}, the torsion says {}",
            -torsion
        );
    }
}
