//! Where the camera stands: [`View`] (the caller's angles, zoom and image
//! size), and [`Framing`], the bounds a camera frames, with the maths from
//! them to a view-projection matrix and between points and pixels. Pure
//! `f64` maths; this room must not know about wgpu, buffers or the shader's
//! layout.

use nalgebra::{Matrix4, Perspective3, Point3, Vector3, Vector4};

use crate::positions::vector;

/// Where the camera stands and the image size.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct View {
    /// Image width in pixels (default: 1280).
    pub width: u32,
    /// Image height in pixels (default: 960).
    pub height: u32,
    /// Rotation about the fabric's vertical (wale) axis, in radians
    /// (default: 0, facing the fabric).
    pub orbit: f32,
    /// Angle above the fabric's plane, in radians (default: 0.35).
    pub elevation: f32,
    /// Magnification: 1 frames the whole fabric, 2 comes twice as close
    /// (default: 1).
    pub zoom: f32,
}

impl Default for View {
    fn default() -> Self {
        Self { width: 1280, height: 960, orbit: 0.0, elevation: 0.35, zoom: 1.0 }
    }
}

/// What a camera frames: the bounds `low`..`high` of a yarn's nodes, padded
/// by its tube `radius`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Framing {
    low: Vector3<f64>,
    high: Vector3<f64>,
    radius: f32,
}

impl Framing {
    /// The framing of the tube of `radius` through `positions`.
    pub(crate) fn of(positions: &[[f32; 3]], radius: f32) -> Self {
        let (low, high) = positions
            .iter()
            .map(vector)
            .fold((Vector3::repeat(f64::INFINITY), Vector3::repeat(f64::NEG_INFINITY)), |(low, high), point| {
                (low.inf(&point), high.sup(&point))
            });
        Self { low, high, radius }
    }

    /// The tube radius the bounds are padded by.
    pub(crate) fn radius(&self) -> f32 {
        self.radius
    }

    /// The camera that frames the bounds from `view`'s angles: its
    /// view-projection matrix (to wgpu's depth range), the eye, and the
    /// direction from the centre to the eye.
    pub(crate) fn camera(&self, view: &View) -> (Matrix4<f64>, Vector3<f64>, Vector3<f64>) {
        let (low, high) = (self.low, self.high);
        let centre = (low + high) / 2.0;
        let fovy = 35f64.to_radians();
        let aspect = f64::from(view.width) / f64::from(view.height);
        let (orbit, elevation) = (f64::from(view.orbit), f64::from(view.elevation));
        let direction = Vector3::new(elevation.cos() * orbit.sin(), elevation.sin(), elevation.cos() * orbit.cos());
        let right = Vector3::y().cross(&direction).try_normalize(1e-12).unwrap_or_else(Vector3::x);
        let up = direction.cross(&right);
        // The bounding box's half extents across and up the image, and in depth.
        let pad = f64::from(self.radius);
        let corners = (0..8).map(|corner| {
            Vector3::new(
                if corner & 1 == 0 { low.x } else { high.x },
                if corner & 2 == 0 { low.y } else { high.y },
                if corner & 4 == 0 { low.z } else { high.z },
            ) - centre
        });
        let extent =
            |axis: &Vector3<f64>| corners.clone().map(|corner| corner.dot(axis).abs()).fold(0.0, f64::max) + pad;
        let (across, upward, reach) = (extent(&right), extent(&up), extent(&direction));
        // Far enough that the box fits both fields of view, with a margin, then
        // closer by the zoom; the depth range keeps room for a fabric pulled
        // well outside its rest bounds.
        let tan_y = (fovy / 2.0).tan();
        let zoom = if view.zoom.is_finite() && view.zoom > 0.0 { f64::from(view.zoom) } else { 1.0 };
        let distance = reach + 1.08 * (upward / tan_y).max(across / (aspect * tan_y)) / zoom;
        let eye = centre + direction * distance;
        let look = Matrix4::look_at_rh(&Point3::from(eye), &Point3::from(centre), &Vector3::y());
        let depth_reach = (high - low).norm() + pad;
        let projection =
            Perspective3::new(aspect, fovy, (distance - depth_reach).max(1e-2 * distance), distance + depth_reach);
        // OpenGL's depth range [−1, 1] to wgpu's [0, 1].
        let depth = Matrix4::new(1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.5, 0.5, 0.0, 0.0, 0.0, 1.0);
        (depth * projection.as_matrix() * look, eye, direction)
    }

    /// Where `point` lands in the image of `view`: pixel x (from the left),
    /// pixel y (from the top) and depth in 0..1, or `None` behind the
    /// camera.
    pub(crate) fn project(&self, view: &View, point: [f32; 3]) -> Option<[f32; 3]> {
        let clip = self.view_proj(view) * vector(&point).push(1.0);
        (clip.w > 0.0).then(|| {
            let ndc = clip.xyz() / clip.w;
            let x = (ndc.x + 1.0) / 2.0 * f64::from(view.width);
            let y = (1.0 - ndc.y) / 2.0 * f64::from(view.height);
            [x as f32, y as f32, ndc.z as f32]
        })
    }

    /// The point at pixel (`x`, `y`) and `depth` of `view`'s image: the
    /// inverse of [`Framing::project`].
    pub(crate) fn unproject(&self, view: &View, x: f32, y: f32, depth: f32) -> [f32; 3] {
        let ndc = Vector4::new(
            2.0 * f64::from(x) / f64::from(view.width) - 1.0,
            1.0 - 2.0 * f64::from(y) / f64::from(view.height),
            f64::from(depth),
            1.0,
        );
        let inverse = self.view_proj(view).try_inverse().unwrap_or_else(Matrix4::identity);
        let world = inverse * ndc;
        let point = world.xyz() / world.w;
        [point.x as f32, point.y as f32, point.z as f32]
    }

    fn view_proj(&self, view: &View) -> Matrix4<f64> {
        self.camera(view).0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bad_zoom_frames_like_no_zoom_and_pixels_map_back_to_points() {
        let framing = Framing::of(&[[0.0, 0.0, 0.0], [4.0, 2.0, 1.0], [-1.0, 3.0, 0.5]], 0.2);
        let view = View { width: 320, height: 240, ..View::default() };
        for zoom in [0.0, -1.0, f32::NAN, f32::INFINITY] {
            assert_eq!(framing.camera(&View { zoom, ..view }), framing.camera(&view), "zoom {zoom}");
        }
        let point = [1.5, 1.0, 0.25];
        let [x, y, depth] = framing.project(&view, point).expect("in front of the camera");
        assert!((0.0..320.0).contains(&x) && (0.0..240.0).contains(&y) && (0.0..=1.0).contains(&depth));
        let back = framing.unproject(&view, x, y, depth);
        assert!((0..3).all(|axis| (back[axis] - point[axis]).abs() < 1e-3), "{point:?} came back as {back:?}");
    }
}
