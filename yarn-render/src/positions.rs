//! The positions as callers hand them over, one `[f32; 3]` a node: the check
//! that they can be drawn, their widening to `f64` vectors for the maths,
//! and their padding to `vec4<f32>` for GPU storage buffers. This room must
//! not know about wgpu, the camera or the mesh.

use nalgebra::Vector3;
use yarn_topology::{Link, YarnSpan, validate_yarns};

use crate::RenderError;

/// At least two nodes, all finite, and `yarns` covering them as a fabric's
/// do.
pub(crate) fn check(positions: &[[f32; 3]], yarns: &[YarnSpan]) -> Result<(), RenderError> {
    if positions.len() < 2 {
        return Err(RenderError::TooFewNodes(positions.len()));
    }
    if let Some((index, &value)) =
        positions.iter().enumerate().find(|(_, position)| position.iter().any(|coordinate| !coordinate.is_finite()))
    {
        return Err(RenderError::NotFinite { index, value });
    }
    // None named is one open yarn over every node, which always fits.
    if !yarns.is_empty() {
        validate_yarns(yarns, positions.len())?;
    }
    Ok(())
}

/// The yarns to draw `nodes` nodes as: `yarns`, or one open yarn over all
/// of them when it is empty (as [`yarn_topology::FabricParts::yarns`]).
pub(crate) fn spans(yarns: &[YarnSpan], nodes: usize) -> Vec<YarnSpan> {
    if yarns.is_empty() { vec![YarnSpan::open(0..nodes as u32)] } else { yarns.to_vec() }
}

/// Each node's neighbours along its yarn, `[prev, next]` with
/// [`Link::NONE`] for a missing one: the layout of the shader's `links`.
pub(crate) fn links(yarns: &[YarnSpan]) -> Vec<[u32; 2]> {
    yarns
        .iter()
        .flat_map(|yarn| yarn.nodes().map(|i| Link::new(yarn.prev(i as u32), yarn.next(i as u32)).raw()))
        .collect()
}

/// Each point padded to a `vec4<f32>` (w = 0), the layout of the shader's
/// storage buffers.
pub(crate) fn vec4s(points: &[[f32; 3]]) -> Vec<[f32; 4]> {
    points.iter().map(|point| [point[0], point[1], point[2], 0.0]).collect()
}

/// A point widened to `f64`.
pub(crate) fn vector(point: &[f32; 3]) -> Vector3<f64> {
    Vector3::new(f64::from(point[0]), f64::from(point[1]), f64::from(point[2]))
}
