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
    fn transported_normals_stay_perpendicular_and_do_not_twist_on_a_helix() {
        // A helix: constant curvature and torsion, so a twist-free frame
        // rotates at a steady rate and stays unit and perpendicular.
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
}
