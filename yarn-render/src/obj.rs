//! The tube as a Wavefront OBJ mesh: [`tube_obj`] writes rings of [`SIDES`]
//! vertices around the transported frames, quads between them and caps at
//! the ends. This room knows text and geometry only; it must not know about
//! the GPU or the camera.

use std::fmt::Write as _;

use nalgebra::Vector3;

use crate::SIDES;
use crate::positions::vector;
use crate::transport::transport_normals;

/// The tube through `positions` as a Wavefront OBJ mesh: [`SIDES`] vertices
/// a node around its transported frame, quads (as triangle pairs) between
/// neighbouring rings, and flat caps at the two ends. Blender and most
/// tools open it as is.
pub fn tube_obj(positions: &[[f32; 3]], radius: f32) -> String {
    let normals = transport_normals(positions);
    let mut obj = String::from("# yarnify tube mesh\no yarn\n");
    let sides = SIDES as usize;
    for (node, (position, transported)) in positions.iter().zip(&normals).enumerate() {
        let before = vector(&positions[node.saturating_sub(1)]);
        let after = vector(&positions[(node + 1).min(positions.len() - 1)]);
        let tangent = (after - before).try_normalize(1e-12).unwrap_or_else(Vector3::x);
        let transported = vector(transported);
        let normal = (transported - tangent * transported.dot(&tangent)).try_normalize(1e-12).unwrap_or(transported);
        let binormal = tangent.cross(&normal);
        for side in 0..sides {
            let angle = std::f64::consts::TAU * side as f64 / sides as f64;
            let vertex = vector(position) + (normal * angle.cos() + binormal * angle.sin()) * f64::from(radius);
            // Writing to a String cannot fail.
            let _ = writeln!(obj, "v {:.5} {:.5} {:.5}", vertex.x, vertex.y, vertex.z);
        }
    }
    // The 1-based OBJ index of a ring's vertex; `side` wraps around.
    let ring = |node: usize, side: usize| node * sides + side % sides + 1;
    for node in 0..positions.len().saturating_sub(1) {
        for side in 0..sides {
            // The quad's corners, counter-clockwise: two on this ring, two on the next.
            let (a, b, c, d) = (ring(node, side), ring(node, side + 1), ring(node + 1, side + 1), ring(node + 1, side));
            let _ = writeln!(obj, "f {a} {b} {c}\nf {a} {c} {d}");
        }
    }
    for node in [0, positions.len() - 1] {
        let cap: Vec<String> = (0..sides).map(|side| ring(node, side).to_string()).collect();
        let _ = writeln!(obj, "f {}", cap.join(" "));
    }
    obj
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn obj_has_a_ring_per_node_and_two_triangles_per_side_per_segment() {
        let positions: Vec<[f32; 3]> = (0..5).map(|i| [i as f32, (i as f32).sin(), 0.0]).collect();
        let obj = tube_obj(&positions, 0.5);
        let count = |prefix: &str| obj.lines().filter(|l| l.starts_with(prefix)).count();
        assert_eq!(count("v "), 5 * SIDES as usize);
        assert_eq!(count("f "), 4 * SIDES as usize * 2 + 2);
        // Every face index points at a vertex.
        let max = obj
            .lines()
            .filter(|l| l.starts_with("f "))
            .flat_map(|l| l[2..].split(' ').map(|i| i.parse::<usize>().expect("index")))
            .max()
            .expect("faces");
        assert_eq!(max, 5 * SIDES as usize);
    }
}
