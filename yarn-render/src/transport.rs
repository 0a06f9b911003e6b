//! The tube's twist-free frames: [`transport_normals`] carries a normal
//! along the yarn by parallel transport. Pure geometry on positions; this
//! room must not know about the GPU, the camera or the mesh format.

use nalgebra::Vector3;

use crate::positions::vector;

/// Each node's frame normal, carried along the yarn by parallel transport
/// (each step rotates it by the turn from one segment to the next), so the
/// tube's rings do not twist. Degenerate segments keep the previous frame.
pub fn transport_normals(positions: &[[f32; 3]]) -> Vec<[f32; 3]> {
    let tangents: Vec<Vector3<f64>> = positions
        .windows(2)
        .map(|segment| (vector(&segment[1]) - vector(&segment[0])).try_normalize(1e-12).unwrap_or_else(Vector3::x))
        .collect();
    let first = tangents.first().copied().unwrap_or_else(Vector3::x);
    // Any unit vector perpendicular to the first tangent.
    let helper = if first.x.abs() < 0.9 { Vector3::x() } else { Vector3::y() };
    let mut normal = (helper - first * helper.dot(&first)).normalize();
    let mut normals = Vec::with_capacity(positions.len());
    normals.push(normal);
    for turn in tangents.windows(2) {
        let (incoming, outgoing) = (turn[0], turn[1]);
        let axis = incoming.cross(&outgoing);
        let sin = axis.norm();
        if sin > 1e-12 {
            let rotation = nalgebra::Rotation3::from_axis_angle(
                &nalgebra::Unit::new_normalize(axis),
                sin.atan2(incoming.dot(&outgoing)),
            );
            normal = rotation * normal;
        }
        normals.push(normal);
    }
    normals.push(normal);
    normals.into_iter().map(|normal| [normal.x as f32, normal.y as f32, normal.z as f32]).collect()
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
        let normals = transport_normals(&positions);
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
        let normals = transport_normals(&line);
        assert!(normals.windows(2).all(|w| w[0] == w[1]));
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
        let normals = transport_normals(&positions);
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
