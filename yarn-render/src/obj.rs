//! The tube as a Wavefront OBJ mesh: [`tube_obj`] writes, for each yarn,
//! rings of [`SIDES`] vertices around the transported frames, quads
//! between them and caps at an open yarn's ends. This room knows text and
//! geometry only; it must not know about the GPU or the camera.

use std::fmt::Write as _;

use nalgebra::Vector3;
use yarn_topology::YarnSpan;

use crate::positions::{check, spans, vector};
use crate::transport::transport_normals;
use crate::{RenderError, SIDES};

/// The tubes through `positions` as a Wavefront OBJ mesh, one object per
/// yarn of `yarns` (empty: one open yarn over every node; a lone yarn's
/// object is `yarn`, several are `yarn0`, `yarn1`, …): [`SIDES`] vertices a
/// node around its transported frame, quads (as triangle pairs) between
/// neighbouring rings of a yarn, closing back to the first ring on a
/// closed yarn, and flat caps at an open yarn's two ends. No face joins
/// two yarns. Blender and most tools open it as is.
///
/// # Errors
/// As [`crate::Renderer::render`]: fewer than two positions, a non-finite
/// one, or yarns that do not cover them.
pub fn tube_obj(positions: &[[f32; 3]], yarns: &[YarnSpan], radius: f32) -> Result<String, RenderError> {
    check(positions, yarns)?;
    let yarns = spans(yarns, positions.len());
    let normals = transport_normals(positions, &yarns);
    let mut obj = String::from("# yarnify tube mesh\n");
    let sides = SIDES as usize;
    // The 1-based OBJ index of a ring's vertex; `side` wraps around.
    let ring = |node: usize, side: usize| node * sides + side % sides + 1;
    for (k, yarn) in yarns.iter().enumerate() {
        // Writing to a String cannot fail.
        let _ = if yarns.len() == 1 { writeln!(obj, "o yarn") } else { writeln!(obj, "o yarn{k}") };
        let at = |node: Option<u32>, or: usize| positions[node.map_or(or, |n| n as usize)];
        for node in yarn.nodes() {
            let before = vector(&at(yarn.prev(node as u32), node));
            let after = vector(&at(yarn.next(node as u32), node));
            let tangent = (after - before).try_normalize(1e-12).unwrap_or_else(Vector3::x);
            let transported = vector(&normals[node]);
            let normal =
                (transported - tangent * transported.dot(&tangent)).try_normalize(1e-12).unwrap_or(transported);
            let binormal = tangent.cross(&normal);
            for side in 0..sides {
                let angle = std::f64::consts::TAU * side as f64 / sides as f64;
                let vertex =
                    vector(&positions[node]) + (normal * angle.cos() + binormal * angle.sin()) * f64::from(radius);
                let _ = writeln!(obj, "v {:.5} {:.5} {:.5}", vertex.x, vertex.y, vertex.z);
            }
        }
        for node in yarn.nodes() {
            let Some(next) = yarn.next(node as u32).map(|n| n as usize) else { continue };
            for side in 0..sides {
                // The quad's corners, counter-clockwise: two on this ring, two on the next.
                let (a, b, c, d) = (ring(node, side), ring(node, side + 1), ring(next, side + 1), ring(next, side));
                let _ = writeln!(obj, "f {a} {b} {c}\nf {a} {c} {d}");
            }
        }
        if !yarn.closed {
            for node in [yarn.start as usize, yarn.end as usize - 1] {
                let cap: Vec<String> = (0..sides).map(|side| ring(node, side).to_string()).collect();
                let _ = writeln!(obj, "f {}", cap.join(" "));
            }
        }
    }
    Ok(obj)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn obj_has_a_ring_per_node_and_two_triangles_per_side_per_segment() {
        let positions: Vec<[f32; 3]> = (0..5).map(|i| [i as f32, (i as f32).sin(), 0.0]).collect();
        let obj = tube_obj(&positions, &[], 0.5).unwrap();
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

    /// Faces as lists of the nodes their vertices belong to.
    fn face_nodes(obj: &str) -> Vec<Vec<usize>> {
        let sides = SIDES as usize;
        obj.lines()
            .filter(|l| l.starts_with("f "))
            .map(|l| l[2..].split(' ').map(|i| (i.parse::<usize>().expect("index") - 1) / sides).collect())
            .collect()
    }

    /// Two open yarns and a closed ring: one object each, no face joins two
    /// yarns, the ring's tube closes (a quad from its last ring to its
    /// first) and has no caps, and each open yarn has its two.
    #[test]
    fn obj_has_one_tube_per_yarn_and_a_ring_closes() {
        let positions: Vec<[f32; 3]> = (0..4)
            .map(|i| [i as f32, 0.0, 0.0])
            .chain((0..3).map(|i| [i as f32, 3.0, 0.0]))
            .chain(
                (0..6).map(|i| (i as f32) * std::f32::consts::TAU / 6.0).map(|t| [2.0 * t.cos(), 2.0 * t.sin(), 6.0]),
            )
            .collect();
        let yarns = [YarnSpan::open(0..4), YarnSpan::open(4..7), YarnSpan::closed(7..13)];
        let obj = tube_obj(&positions, &yarns, 0.25).unwrap();
        let objects: Vec<&str> = obj.lines().filter(|l| l.starts_with("o ")).collect();
        assert_eq!(objects, ["o yarn0", "o yarn1", "o yarn2"]);
        assert_eq!(obj.lines().filter(|l| l.starts_with("v ")).count(), 13 * SIDES as usize);
        let yarn_of = |node: usize| yarns.iter().position(|y| y.contains(node as u32)).unwrap();
        let faces = face_nodes(&obj);
        for face in &faces {
            assert!(face.iter().all(|&n| yarn_of(n) == yarn_of(face[0])), "a face joins two yarns: {face:?}");
        }
        let quads_between =
            |a: usize, b: usize| faces.iter().filter(|f| f.len() == 3 && f.contains(&a) && f.contains(&b)).count();
        assert_eq!(quads_between(12, 7), 2 * SIDES as usize, "the ring's tube does not close");
        assert_eq!(quads_between(3, 4), 0);
        assert_eq!(quads_between(6, 7), 0);
        let caps: Vec<usize> = faces.iter().filter(|f| f.len() == SIDES as usize).map(|f| f[0]).collect();
        assert_eq!(caps, [0, 3, 4, 6], "caps at the open yarns' ends only");
        // 3 + 2 open segments, 6 closed, two triangles a side each, and 4 caps.
        assert_eq!(faces.len(), (3 + 2 + 6) * 2 * SIDES as usize + 4);
        assert!(matches!(
            tube_obj(&positions, &[YarnSpan::open(0..4)], 0.25),
            Err(RenderError::Yarns(yarn_topology::TopologyError::YarnsEndEarly { end: 4, nodes: 13 }))
        ));
    }
}
