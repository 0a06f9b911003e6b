//! A yarn made ready to draw: [`Yarn`] holds what stays fixed from frame to
//! frame (its tube frames on the GPU, its framing, its camera's uniform
//! buffer) and answers picking questions through its framing. This room
//! prepares data; it must not record passes or read anything back.

use wgpu::util::DeviceExt;

use crate::camera::{Framing, View};
use crate::positions::{check, vec4s};
use crate::shader::Camera;
use crate::transport::transport_normals;
use crate::{RenderError, Renderer};

/// A yarn ready to draw from a position buffer: its tube frames on the GPU,
/// the bounds that frame it, and its camera's uniform buffer. Made once per
/// fabric by [`Renderer::yarn`], then drawn every frame.
#[derive(Debug)]
pub struct Yarn {
    /// One `vec4<f32>` frame normal a node, from the reference shape.
    pub(crate) normals: wgpu::Buffer,
    /// The uniform buffer [`Renderer::draw`] writes a [`Camera`] into.
    pub(crate) camera: wgpu::Buffer,
    /// The reference shape's bounds and the tube radius.
    pub(crate) framing: Framing,
    /// The node count; a position buffer needs 16 bytes for each.
    pub(crate) nodes: usize,
}

impl Yarn {
    /// Where `point` lands in the image of `view`: pixel x (from the left),
    /// pixel y (from the top) and depth in 0..1, or `None` behind the
    /// camera. For picking a node under the cursor.
    pub fn project(&self, view: &View, point: [f32; 3]) -> Option<[f32; 3]> {
        self.framing.project(view, point)
    }

    /// The point at pixel (`x`, `y`) and `depth` of `view`'s image: the
    /// inverse of [`Yarn::project`], for dragging a node with the cursor.
    pub fn unproject(&self, view: &View, x: f32, y: f32, depth: f32) -> [f32; 3] {
        self.framing.unproject(view, x, y, depth)
    }
}

impl Renderer {
    /// Prepare the yarn of `reference` for drawing from a position buffer
    /// of the same node count: `reference` (its rest shape, say) sets the
    /// tube frames (re-squared to the current tangents in the shader) and
    /// the framing.
    ///
    /// # Errors
    /// Fewer than two positions or a non-finite one.
    pub fn yarn(&self, reference: &[[f32; 3]], radius: f32) -> Result<Yarn, RenderError> {
        check(reference)?;
        let framing = Framing::of(reference, radius);
        let camera = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("camera"),
            size: std::mem::size_of::<Camera>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let normals = self.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("normals"),
            contents: bytemuck::cast_slice(&vec4s(&transport_normals(reference))),
            usage: wgpu::BufferUsages::STORAGE,
        });
        Ok(Yarn { normals, camera, framing, nodes: reference.len() })
    }
}
