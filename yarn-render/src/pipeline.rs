//! Drawing on the GPU: [`Renderer`] builds the tube pipeline once, keeps
//! the multisampled targets of the last size drawn, and [`Renderer::draw`]
//! records one pass of a [`Yarn`] into a caller's texture. This room
//! records and never submits or reads back; it must not know about images
//! on the CPU or files.

use std::sync::{Mutex, PoisonError};

use nalgebra::Vector3;
use yarn_backend_wgpu::Gpu;

use crate::camera::View;
use crate::shader::Camera;
use crate::{BACKGROUND, RenderError, SHADER, SIDES, Yarn};

/// Multisampling.
const SAMPLES: u32 = 4;
/// The colour format of offscreen images ([`Renderer::new`]).
const FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8UnormSrgb;
/// The depth buffer's format.
const DEPTH: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;
/// Bytes a node takes in a position buffer: one `vec4<f32>`.
const NODE_BYTES: u64 = 16;

/// Draws yarn on a GPU.
#[derive(Debug)]
pub struct Renderer {
    pub(crate) device: wgpu::Device,
    pub(crate) queue: wgpu::Queue,
    pipeline: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
    /// The colour format of the textures drawn into.
    pub(crate) format: wgpu::TextureFormat,
    /// The multisampled colour and depth targets of the last size drawn.
    targets: Mutex<Option<Targets>>,
}

/// Multisampled colour and depth textures of one size.
#[derive(Debug)]
struct Targets {
    size: (u32, u32),
    colour: wgpu::TextureView,
    depth: wgpu::TextureView,
}

impl Renderer {
    /// A renderer on `gpu`'s device, drawing offscreen images.
    pub fn new(gpu: &Gpu) -> Self {
        Self::for_format(gpu, FORMAT)
    }

    /// A renderer on `gpu`'s device that draws into textures of `format`,
    /// such as a browser canvas's preferred format ([`Renderer::draw`]).
    pub fn for_format(gpu: &Gpu, format: wgpu::TextureFormat) -> Self {
        let device = gpu.device().clone();
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("yarn.wgsl"),
            source: wgpu::ShaderSource::Wgsl(SHADER.into()),
        });
        let entry = |binding, ty| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::VERTEX | wgpu::ShaderStages::FRAGMENT,
            ty: wgpu::BindingType::Buffer { ty, has_dynamic_offset: false, min_binding_size: None },
            count: None,
        };
        let storage = wgpu::BufferBindingType::Storage { read_only: true };
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("yarn"),
            entries: &[
                entry(0, wgpu::BufferBindingType::Uniform),
                entry(1, storage),
                entry(2, storage),
                entry(3, storage),
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("yarn"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("yarn"),
            layout: Some(&pipeline_layout),
            vertex: wgpu::VertexState {
                module: &module,
                entry_point: Some("vs"),
                compilation_options: Default::default(),
                buffers: &[],
            },
            primitive: wgpu::PrimitiveState::default(),
            depth_stencil: Some(wgpu::DepthStencilState {
                format: DEPTH,
                depth_write_enabled: Some(true),
                depth_compare: Some(wgpu::CompareFunction::Less),
                stencil: Default::default(),
                bias: Default::default(),
            }),
            multisample: wgpu::MultisampleState { count: SAMPLES, ..Default::default() },
            fragment: Some(wgpu::FragmentState {
                module: &module,
                entry_point: Some("fs"),
                compilation_options: Default::default(),
                targets: &[Some(format.into())],
            }),
            multiview_mask: None,
            cache: None,
        });
        Self { device, queue: gpu.queue().clone(), pipeline, layout, format, targets: Mutex::new(None) }
    }

    /// Record a drawing of `yarn` at `positions` (one `vec4<f32>` per node)
    /// into `target`, a `view.width` x `view.height` texture of this
    /// renderer's format, cleared to [`BACKGROUND`] first. Nothing is
    /// submitted or read back: the caller submits `encoder`, e.g. once a
    /// frame into a canvas.
    ///
    /// # Errors
    /// A bad image size, or a position buffer too small for the yarn.
    pub fn draw(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        target: &wgpu::TextureView,
        positions: &wgpu::Buffer,
        yarn: &Yarn,
        view: &View,
    ) -> Result<(), RenderError> {
        self.check_size(view)?;
        let needed = yarn.nodes as u64 * NODE_BYTES;
        if positions.size() < needed {
            return Err(RenderError::PositionBufferTooSmall { bytes: positions.size(), needed, nodes: yarn.nodes });
        }
        let (view_proj, eye, direction) = yarn.framing.camera(view);
        let light = Vector3::new(-0.4, 0.7, 0.6) + direction * 0.5;
        let uniform = Camera {
            view_proj: view_proj.cast::<f32>().into(),
            eye: [eye.x as f32, eye.y as f32, eye.z as f32],
            radius: yarn.framing.radius(),
            light: [light.x as f32, light.y as f32, light.z as f32],
            nodes: yarn.nodes as u32,
        };
        self.queue.write_buffer(&yarn.camera, 0, bytemuck::bytes_of(&uniform));
        let group = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("yarn"),
            layout: &self.layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: yarn.camera.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: positions.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 2, resource: yarn.normals.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 3, resource: yarn.links.as_entire_binding() },
            ],
        });
        let mut targets = self.targets.lock().unwrap_or_else(PoisonError::into_inner);
        let targets = match targets.take() {
            Some(kept) if kept.size == (view.width, view.height) => targets.insert(kept),
            _ => targets.insert(self.targets(view.width, view.height)),
        };
        let [r, g, b, _] = BACKGROUND.map(|channel| srgb_to_linear(f64::from(channel) / 255.0));
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("yarn"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: &targets.colour,
                depth_slice: None,
                resolve_target: Some(target),
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Clear(wgpu::Color { r, g, b, a: 1.0 }),
                    store: wgpu::StoreOp::Discard,
                },
            })],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: &targets.depth,
                depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Clear(1.0), store: wgpu::StoreOp::Discard }),
                stencil_ops: None,
            }),
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &group, &[]);
        // One instance per node, for the segment leaving it (none at an open
        // yarn's end, which draws nothing).
        pass.draw(0..SIDES * 6, 0..yarn.nodes as u32);
        Ok(())
    }

    /// Whether this device can draw `view`'s image size: 1 to its largest
    /// texture side, a side. Drawing checks it too; a caller about to run
    /// long before it draws can check first.
    ///
    /// # Errors
    /// [`RenderError::BadSize`], naming the device's limit.
    pub fn check_size(&self, view: &View) -> Result<(), RenderError> {
        let limit = self.device.limits().max_texture_dimension_2d;
        if !(1..=limit).contains(&view.width) || !(1..=limit).contains(&view.height) {
            return Err(RenderError::BadSize { width: view.width, height: view.height, limit });
        }
        Ok(())
    }

    fn targets(&self, width: u32, height: u32) -> Targets {
        let texture = |label, format| {
            self.device
                .create_texture(&wgpu::TextureDescriptor {
                    label: Some(label),
                    size: wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
                    mip_level_count: 1,
                    sample_count: SAMPLES,
                    dimension: wgpu::TextureDimension::D2,
                    format,
                    usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
                    view_formats: &[],
                })
                .create_view(&Default::default())
        };
        Targets { size: (width, height), colour: texture("colour", self.format), depth: texture("depth", DEPTH) }
    }
}

/// An sRGB-encoded channel in 0..=1 to linear light, the terms the pass's
/// clear colour is given in.
fn srgb_to_linear(encoded: f64) -> f64 {
    if encoded <= 0.04045 { encoded / 12.92 } else { ((encoded + 0.055) / 1.055).powf(2.4) }
}
