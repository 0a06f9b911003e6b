//! A yarn made ready to draw: [`Yarn`] holds what stays fixed from frame to
//! frame (its tube frames on the GPU, its framing, its camera's uniform
//! buffer) and answers picking questions through its framing. This room
//! prepares data; it must not record passes or read anything back.

use wgpu::util::DeviceExt;
use yarn_topology::YarnSpan;

use crate::camera::{Framing, View};
use crate::positions::{check, links, spans, vec4s};
use crate::shader::Camera;
use crate::transport::transport_normals;
use crate::{RenderError, Renderer};

/// A fabric's yarns ready to draw from a position buffer: their tube
/// frames and each node's neighbours along its yarn on the GPU, the bounds
/// that frame them, and the camera's uniform buffer. Made once per fabric
/// by [`Renderer::yarn`], then drawn every frame.
#[derive(Debug)]
pub struct Yarn {
    /// One `vec4<f32>` frame normal a node, from the reference shape.
    pub(crate) normals: wgpu::Buffer,
    /// One `vec2<u32>` a node: the nodes before and after it along its
    /// yarn, `Link::NONE` for none.
    pub(crate) links: wgpu::Buffer,
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
    /// Prepare the yarns of `reference` for drawing from a position buffer
    /// of the same node count, each of `yarns` as its own tube (empty: one
    /// open yarn over every node; a closed yarn's tube closes):
    /// `reference` (its rest shape, say) sets the tube frames (re-squared
    /// to the current tangents in the shader) and the framing.
    ///
    /// # Errors
    /// Fewer than two positions, a non-finite one, or yarns that do not
    /// cover them ([`RenderError::Yarns`]).
    pub fn yarn(&self, reference: &[[f32; 3]], yarns: &[YarnSpan], radius: f32) -> Result<Yarn, RenderError> {
        check(reference, yarns)?;
        let yarns = spans(yarns, reference.len());
        let framing = Framing::of(reference, radius);
        let camera = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("camera"),
            size: std::mem::size_of::<Camera>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let normals = self.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("normals"),
            contents: bytemuck::cast_slice(&vec4s(&transport_normals(reference, &yarns))),
            usage: wgpu::BufferUsages::STORAGE,
        });
        let links = self.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("links"),
            contents: bytemuck::cast_slice(&links(&yarns)),
            usage: wgpu::BufferUsages::STORAGE,
        });
        Ok(Yarn { normals, links, camera, framing, nodes: reference.len() })
    }
}
