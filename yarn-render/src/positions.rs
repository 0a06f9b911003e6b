//! The positions as callers hand them over, one `[f32; 3]` a node: the check
//! that they can be drawn, their widening to `f64` vectors for the maths,
//! and their padding to `vec4<f32>` for GPU storage buffers. This room must
//! not know about wgpu, the camera or the mesh.

use nalgebra::Vector3;

use crate::RenderError;

/// At least two nodes, all finite.
pub(crate) fn check(positions: &[[f32; 3]]) -> Result<(), RenderError> {
    if positions.len() < 2 {
        return Err(RenderError::TooFewNodes(positions.len()));
    }
    match positions.iter().enumerate().find(|(_, position)| position.iter().any(|coordinate| !coordinate.is_finite())) {
        Some((index, &value)) => Err(RenderError::NotFinite { index, value }),
        None => Ok(()),
    }
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
