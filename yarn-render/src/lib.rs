//! The swept-tube renderer for yarnify (paper §9): the yarn polyline drawn
//! as a tube of radius r, offscreen on wgpu, to an RGBA image or PNG; and
//! the same tube as a Wavefront OBJ mesh.
//!
//! The tube is generated in the vertex shader (`shaders/yarn.wgsl`, the
//! file the browser demo uses too): one instance per segment, [`SIDES`]
//! ring vertices at each end, around each node's parallel-transport frame
//! ([`transport_normals`]), so rings do not twist along the yarn. No tube
//! geometry is stored. Shading is Lambert under a key light with an
//! ambient floor and a rim term, in two tones that alternate along the
//! yarn; the frame is multisampled with a depth buffer, and the camera
//! frames the fabric's bounds.
//!
//! This crate owns drawing; it knows nothing of the model beyond positions.
//!
//! ```no_run
//! use yarn_backend_wgpu::Gpu;
//! use yarn_render::{Renderer, View};
//! use yarn_topology::{Chart, Fabric, Geometry};
//!
//! let fabric = Fabric::from_chart(&Chart::stockinette(8, 8)?, &Geometry::default())?;
//! let positions: Vec<[f32; 3]> =
//!     fabric.positions().iter().map(|p| [p.x as f32, p.y as f32, p.z as f32]).collect();
//! let renderer = Renderer::new(&*Gpu::new()?);
//! let frame = renderer.render(&positions, fabric.yarn_radius() as f32, &View::default())?;
//! frame.save_png("fabric.png")?;
//! println!("{:.0} % of the frame is yarn", 100.0 * frame.coverage());
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

#![forbid(unsafe_code)]

use std::fmt::Write as _;
use std::path::Path;
use std::sync::{Mutex, PoisonError};

use bytemuck::{Pod, Zeroable};
use nalgebra::{Matrix4, Perspective3, Point3, Vector3};
use wgpu::util::DeviceExt;
use yarn_backend_wgpu::{Gpu, read_mapped};

/// The tube shader, shared with the browser demo.
pub const SHADER: &str = include_str!("../shaders/yarn.wgsl");

/// Ring vertices per tube section (`SIDES` in the shader).
pub const SIDES: u32 = 7;

/// The background colour, RGBA; [`Frame::coverage`] counts every other
/// pixel as yarn.
pub const BACKGROUND: [u8; 4] = [242, 244, 248, 255];

/// Multisampling.
const SAMPLES: u32 = 4;
const FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8UnormSrgb;
const DEPTH: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

/// Why a frame could not be drawn or saved.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// Fewer than two nodes: there is no segment to draw.
    #[error("a yarn of {0} nodes has no segment to draw; give at least 2 positions")]
    TooFewNodes(usize),
    /// A position is NaN or infinite.
    #[error("position {index} is not finite ({value:?}); the simulation diverged or the input is bad")]
    NotFinite {
        /// Which node.
        index: usize,
        /// Its position.
        value: [f32; 3],
    },
    /// The image size is zero or beyond the device's texture limit.
    #[error("an image of {width}x{height} is outside 1..={limit} pixels a side")]
    BadSize {
        /// Requested width.
        width: u32,
        /// Requested height.
        height: u32,
        /// The device's largest 2-D texture side.
        limit: u32,
    },
    /// The GPU failed.
    #[error("GPU error while rendering: {0}")]
    Device(String),
    /// The PNG could not be written.
    #[error("could not write the image: {0}")]
    Image(#[from] image::ImageError),
}

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

/// A rendered RGBA image.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Frame {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Row-major RGBA, 8 bits a channel.
    pub rgba: Vec<u8>,
}

impl Frame {
    /// The fraction of pixels that are not background: how much of the frame
    /// the yarn covers.
    pub fn coverage(&self) -> f64 {
        let pixels = self.rgba.chunks_exact(4);
        let total = pixels.len().max(1);
        let yarn = pixels.filter(|p| p.iter().zip(BACKGROUND).any(|(&a, b)| a.abs_diff(b) > 8)).count();
        yarn as f64 / total as f64
    }

    /// Save as PNG.
    ///
    /// # Errors
    /// When the file cannot be written.
    pub fn save_png(&self, path: impl AsRef<Path>) -> Result<(), RenderError> {
        image::save_buffer(path, &self.rgba, self.width, self.height, image::ExtendedColorType::Rgba8)?;
        Ok(())
    }
}

/// Mirrors `Camera` in the shader.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct Camera {
    view_proj: [[f32; 4]; 4],
    eye: [f32; 3],
    radius: f32,
    light: [f32; 3],
    segments: u32,
}

/// Draws yarn on a GPU.
#[derive(Debug)]
pub struct Renderer {
    device: wgpu::Device,
    queue: wgpu::Queue,
    pipeline: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
    format: wgpu::TextureFormat,
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

/// A yarn ready to draw from a position buffer: its tube frames on the GPU,
/// the bounds that frame it, and its camera's uniform buffer. Made once per
/// fabric by [`Renderer::yarn`], then drawn every frame.
#[derive(Debug)]
pub struct Yarn {
    normals: wgpu::Buffer,
    camera: wgpu::Buffer,
    low: Vector3<f64>,
    high: Vector3<f64>,
    radius: f32,
    nodes: usize,
}

impl Yarn {
    /// Where `point` lands in the image of `view`: pixel x (from the left),
    /// pixel y (from the top) and depth in 0..1, or `None` behind the
    /// camera. For picking a node under the cursor.
    pub fn project(&self, view: &View, point: [f32; 3]) -> Option<[f32; 3]> {
        let clip = self.view_proj(view) * vector(&point).push(1.0);
        (clip.w > 0.0).then(|| {
            let ndc = clip.xyz() / clip.w;
            let x = (ndc.x + 1.0) / 2.0 * f64::from(view.width);
            let y = (1.0 - ndc.y) / 2.0 * f64::from(view.height);
            [x as f32, y as f32, ndc.z as f32]
        })
    }

    /// The point at pixel (`x`, `y`) and `depth` of `view`'s image: the
    /// inverse of [`Yarn::project`], for dragging a node with the cursor.
    pub fn unproject(&self, view: &View, x: f32, y: f32, depth: f32) -> [f32; 3] {
        let ndc = nalgebra::Vector4::new(
            2.0 * f64::from(x) / f64::from(view.width) - 1.0,
            1.0 - 2.0 * f64::from(y) / f64::from(view.height),
            f64::from(depth),
            1.0,
        );
        let inverse = self.view_proj(view).try_inverse().unwrap_or_else(Matrix4::identity);
        let world = inverse * ndc;
        let p = world.xyz() / world.w;
        [p.x as f32, p.y as f32, p.z as f32]
    }

    fn view_proj(&self, view: &View) -> Matrix4<f64> {
        camera(self.low, self.high, self.radius, view).0
    }
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
            entries: &[entry(0, wgpu::BufferBindingType::Uniform), entry(1, storage), entry(2, storage)],
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

    /// Draw the yarn through `positions` as a tube of `radius`, framed by
    /// `view`.
    ///
    /// # Errors
    /// Fewer than two positions, a non-finite one, a bad image size, or a
    /// GPU failure.
    pub fn render(&self, positions: &[[f32; 3]], radius: f32, view: &View) -> Result<Frame, RenderError> {
        check(positions)?;
        let position_buffer = self.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("positions"),
            contents: bytemuck::cast_slice(&vec4s(positions)),
            usage: wgpu::BufferUsages::STORAGE,
        });
        self.image(&position_buffer, positions, radius, view)
    }

    /// Draw the yarn whose positions are already on this renderer's GPU, in
    /// `positions` (one `vec4<f32>` per node, xyz used: the layout of
    /// `yarn_backend_wgpu::Wgpu::positions`), so nothing comes back to the
    /// CPU. `reference` is the same yarn in a shape known here, such as its
    /// rest shape: it sets the tube frames (re-squared to the current
    /// tangents in the shader) and the framing.
    ///
    /// # Errors
    /// As [`Renderer::render`], for `reference`; and a buffer too small for
    /// it.
    pub fn render_gpu(
        &self,
        positions: &wgpu::Buffer,
        reference: &[[f32; 3]],
        radius: f32,
        view: &View,
    ) -> Result<Frame, RenderError> {
        self.image(positions, reference, radius, view)
    }

    /// Prepare the yarn of `reference` for drawing from a position buffer
    /// of the same node count: `reference` (its rest shape, say) sets the
    /// tube frames (re-squared to the current tangents in the shader) and
    /// the framing.
    ///
    /// # Errors
    /// Fewer than two positions or a non-finite one.
    pub fn yarn(&self, reference: &[[f32; 3]], radius: f32) -> Result<Yarn, RenderError> {
        check(reference)?;
        let (low, high) = reference
            .iter()
            .map(vector)
            .fold((Vector3::repeat(f64::INFINITY), Vector3::repeat(f64::NEG_INFINITY)), |(low, high), p| {
                (low.inf(&p), high.sup(&p))
            });
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
        Ok(Yarn { normals, camera, low, high, radius, nodes: reference.len() })
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
        let limit = self.device.limits().max_texture_dimension_2d;
        if !(1..=limit).contains(&view.width) || !(1..=limit).contains(&view.height) {
            return Err(RenderError::BadSize { width: view.width, height: view.height, limit });
        }
        if positions.size() < yarn.nodes as u64 * 16 {
            return Err(RenderError::Device(format!(
                "the position buffer holds {} bytes, too few for {} nodes",
                positions.size(),
                yarn.nodes
            )));
        }
        let (view_proj, eye, direction) = camera(yarn.low, yarn.high, yarn.radius, view);
        let light = Vector3::new(-0.4, 0.7, 0.6) + direction * 0.5;
        let uniform = Camera {
            view_proj: view_proj.cast::<f32>().into(),
            eye: [eye.x as f32, eye.y as f32, eye.z as f32],
            radius: yarn.radius,
            light: [light.x as f32, light.y as f32, light.z as f32],
            segments: (yarn.nodes - 1) as u32,
        };
        self.queue.write_buffer(&yarn.camera, 0, bytemuck::bytes_of(&uniform));
        let group = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("yarn"),
            layout: &self.layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: yarn.camera.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: positions.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 2, resource: yarn.normals.as_entire_binding() },
            ],
        });
        let mut targets = self.targets.lock().unwrap_or_else(PoisonError::into_inner);
        let targets = match targets.take() {
            Some(t) if t.size == (view.width, view.height) => targets.insert(t),
            _ => targets.insert(self.targets(view.width, view.height)),
        };
        let [r, g, b, _] = BACKGROUND.map(|c| srgb_to_linear(f64::from(c) / 255.0));
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
        pass.draw(0..SIDES * 6, 0..(yarn.nodes - 1) as u32);
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

    /// Draw `positions` with frames and framing from `shape` into an image.
    fn image(
        &self,
        positions: &wgpu::Buffer,
        shape: &[[f32; 3]],
        radius: f32,
        view: &View,
    ) -> Result<Frame, RenderError> {
        let yarn = self.yarn(shape, radius)?;
        let device = &self.device;
        let limit = device.limits().max_texture_dimension_2d;
        if !(1..=limit).contains(&view.width) || !(1..=limit).contains(&view.height) {
            return Err(RenderError::BadSize { width: view.width, height: view.height, limit });
        }
        let size = wgpu::Extent3d { width: view.width, height: view.height, depth_or_array_layers: 1 };
        let resolved = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("resolved"),
            size,
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: self.format,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let row = (view.width * 4).div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT) * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
        let readback = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("frame"),
            size: u64::from(row) * u64::from(view.height),
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            mapped_at_creation: false,
        });
        let mut encoder = device.create_command_encoder(&Default::default());
        self.draw(&mut encoder, &resolved.create_view(&Default::default()), positions, &yarn, view)?;
        encoder.copy_texture_to_buffer(
            resolved.as_image_copy(),
            wgpu::TexelCopyBufferInfo {
                buffer: &readback,
                layout: wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(row), rows_per_image: None },
            },
            size,
        );
        self.queue.submit([encoder.finish()]);
        let mapped = pollster::block_on(read_mapped(device, &readback)).map_err(RenderError::Device)?;
        let mut rgba = Vec::with_capacity((view.width * view.height * 4) as usize);
        for line in mapped.chunks(row as usize).take(view.height as usize) {
            rgba.extend_from_slice(&line[..(view.width * 4) as usize]);
        }
        Ok(Frame { width: view.width, height: view.height, rgba })
    }
}

/// At least two nodes, all finite.
fn check(positions: &[[f32; 3]]) -> Result<(), RenderError> {
    if positions.len() < 2 {
        return Err(RenderError::TooFewNodes(positions.len()));
    }
    match positions.iter().enumerate().find(|(_, p)| p.iter().any(|c| !c.is_finite())) {
        Some((index, &value)) => Err(RenderError::NotFinite { index, value }),
        None => Ok(()),
    }
}

fn vec4s(v: &[[f32; 3]]) -> Vec<[f32; 4]> {
    v.iter().map(|p| [p[0], p[1], p[2], 0.0]).collect()
}

fn srgb_to_linear(c: f64) -> f64 {
    if c <= 0.04045 { c / 12.92 } else { ((c + 0.055) / 1.055).powf(2.4) }
}

fn vector(p: &[f32; 3]) -> Vector3<f64> {
    Vector3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]))
}

/// Each node's frame normal, carried along the yarn by parallel transport
/// (each step rotates it by the turn from one segment to the next), so the
/// tube's rings do not twist. Degenerate segments keep the previous frame.
pub fn transport_normals(positions: &[[f32; 3]]) -> Vec<[f32; 3]> {
    let tangents: Vec<Vector3<f64>> = positions
        .windows(2)
        .map(|w| (vector(&w[1]) - vector(&w[0])).try_normalize(1e-12).unwrap_or_else(Vector3::x))
        .collect();
    let first = tangents.first().copied().unwrap_or_else(Vector3::x);
    // Any unit vector perpendicular to the first tangent.
    let helper = if first.x.abs() < 0.9 { Vector3::x() } else { Vector3::y() };
    let mut normal = (helper - first * helper.dot(&first)).normalize();
    let mut normals = Vec::with_capacity(positions.len());
    normals.push(normal);
    for w in tangents.windows(2) {
        let axis = w[0].cross(&w[1]);
        let sin = axis.norm();
        if sin > 1e-12 {
            let rotation =
                nalgebra::Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(axis), sin.atan2(w[0].dot(&w[1])));
            normal = rotation * normal;
        }
        normals.push(normal);
    }
    normals.push(normal);
    normals.into_iter().map(|n| [n.x as f32, n.y as f32, n.z as f32]).collect()
}

/// The camera that frames the bounds `low`..`high` from `view`'s angles:
/// its view-projection matrix (to wgpu's depth range), the eye, and the
/// direction from the centre to the eye.
fn camera(
    low: Vector3<f64>,
    high: Vector3<f64>,
    radius: f32,
    view: &View,
) -> (Matrix4<f64>, Vector3<f64>, Vector3<f64>) {
    let centre = (low + high) / 2.0;
    let fovy = 35f64.to_radians();
    let aspect = f64::from(view.width) / f64::from(view.height);
    let (orbit, elevation) = (f64::from(view.orbit), f64::from(view.elevation));
    let direction = Vector3::new(elevation.cos() * orbit.sin(), elevation.sin(), elevation.cos() * orbit.cos());
    let right = Vector3::y().cross(&direction).try_normalize(1e-12).unwrap_or_else(Vector3::x);
    let up = direction.cross(&right);
    // The bounding box's half extents across and up the image, and in depth.
    let pad = f64::from(radius);
    let corners = (0..8).map(|k| {
        Vector3::new(
            if k & 1 == 0 { low.x } else { high.x },
            if k & 2 == 0 { low.y } else { high.y },
            if k & 4 == 0 { low.z } else { high.z },
        ) - centre
    });
    let extent = |axis: &Vector3<f64>| corners.clone().map(|c| c.dot(axis).abs()).fold(0.0, f64::max) + pad;
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

/// The tube through `positions` as a Wavefront OBJ mesh: [`SIDES`] vertices
/// a node around its transported frame, quads (as triangle pairs) between
/// neighbouring rings, and flat caps at the two ends. Blender and most
/// tools open it as is.
pub fn tube_obj(positions: &[[f32; 3]], radius: f32) -> String {
    let normals = transport_normals(positions);
    let mut obj = String::from("# yarnify tube mesh\no yarn\n");
    let sides = SIDES as usize;
    for (i, (p, n)) in positions.iter().zip(&normals).enumerate() {
        let before = vector(&positions[i.saturating_sub(1)]);
        let after = vector(&positions[(i + 1).min(positions.len() - 1)]);
        let t = (after - before).try_normalize(1e-12).unwrap_or_else(Vector3::x);
        let n = vector(n);
        let n = (n - t * n.dot(&t)).try_normalize(1e-12).unwrap_or(n);
        let b = t.cross(&n);
        for k in 0..sides {
            let angle = std::f64::consts::TAU * k as f64 / sides as f64;
            let v = vector(p) + (n * angle.cos() + b * angle.sin()) * f64::from(radius);
            // Writing to a String cannot fail.
            let _ = writeln!(obj, "v {:.5} {:.5} {:.5}", v.x, v.y, v.z);
        }
    }
    let ring = |i: usize, k: usize| i * sides + k % sides + 1;
    for i in 0..positions.len().saturating_sub(1) {
        for k in 0..sides {
            let (a, b, c, d) = (ring(i, k), ring(i, k + 1), ring(i + 1, k + 1), ring(i + 1, k));
            let _ = writeln!(obj, "f {a} {b} {c}\nf {a} {c} {d}");
        }
    }
    for i in [0, positions.len() - 1] {
        let cap: Vec<String> = (0..sides).map(|k| ring(i, k).to_string()).collect();
        let _ = writeln!(obj, "f {}", cap.join(" "));
    }
    obj
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shader_validates_and_its_camera_matches() {
        let module = naga::front::wgsl::parse_str(SHADER).expect("parses");
        naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::empty())
            .validate(&module)
            .expect("validates");
        let mut layouter = naga::proc::Layouter::default();
        layouter.update(module.to_ctx()).expect("layout");
        let (handle, ty) = module.types.iter().find(|(_, t)| t.name.as_deref() == Some("Camera")).expect("Camera");
        assert_eq!(layouter[handle].size as usize, std::mem::size_of::<Camera>());
        let naga::TypeInner::Struct { members, .. } = &ty.inner else { panic!("Camera is a struct") };
        let offsets: Vec<u32> = members.iter().map(|m| m.offset).collect();
        assert_eq!(offsets, [0, 64, 76, 80, 92]);
        assert_eq!(
            [
                std::mem::offset_of!(Camera, view_proj),
                std::mem::offset_of!(Camera, eye),
                std::mem::offset_of!(Camera, radius),
                std::mem::offset_of!(Camera, light),
                std::mem::offset_of!(Camera, segments),
            ]
            .map(|o| o as u32),
            offsets.as_slice()
        );
        assert!(SHADER.contains(&format!("const SIDES: u32 = {SIDES}u;")));
    }

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

    #[test]
    fn coverage_counts_non_background_pixels() {
        let mut frame = Frame { width: 2, height: 2, rgba: BACKGROUND.repeat(4) };
        assert_eq!(frame.coverage(), 0.0);
        frame.rgba[4..8].copy_from_slice(&[200, 80, 60, 255]);
        assert_eq!(frame.coverage(), 0.25);
    }
}
