//! Offscreen images: [`Renderer::render`] and [`Renderer::render_gpu`]
//! draw into a texture of their own, submit, and copy the pixels back into
//! a [`Frame`]. This room owns submission and the row-aligned copy; it must
//! not know how the pass is recorded or where the camera stands.

use wgpu::util::DeviceExt;
use yarn_backend_wgpu::read_mapped;
use yarn_topology::YarnSpan;

use crate::camera::View;
use crate::positions::{check, vec4s};
use crate::{Frame, RenderError, Renderer};

impl Renderer {
    /// Draw the yarns through `positions` as tubes of `radius`, framed by
    /// `view`: each of `yarns` its own tube (empty: one open yarn over
    /// every node), a closed yarn's closing on itself.
    ///
    /// # Errors
    /// Fewer than two positions, a non-finite one, yarns that do not cover
    /// them, a bad image size, or a GPU failure.
    pub fn render(
        &self,
        positions: &[[f32; 3]],
        yarns: &[YarnSpan],
        radius: f32,
        view: &View,
    ) -> Result<Frame, RenderError> {
        check(positions, yarns)?;
        let position_buffer = self.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("positions"),
            contents: bytemuck::cast_slice(&vec4s(positions)),
            usage: wgpu::BufferUsages::STORAGE,
        });
        self.image(&position_buffer, positions, yarns, radius, view)
    }

    /// Draw the yarn whose positions are already on this renderer's GPU, in
    /// `positions` (one `vec4<f32>` per node, xyz used: the layout of
    /// `yarn_backend_wgpu::Wgpu::positions`), so nothing comes back to the
    /// CPU. `reference` is the same yarn in a shape known here, such as its
    /// rest shape: it sets the tube frames (re-squared to the current
    /// tangents in the shader) and the framing; `yarns` as for
    /// [`Renderer::render`].
    ///
    /// # Errors
    /// As [`Renderer::render`], for `reference`; and a buffer too small for
    /// it.
    pub fn render_gpu(
        &self,
        positions: &wgpu::Buffer,
        reference: &[[f32; 3]],
        yarns: &[YarnSpan],
        radius: f32,
        view: &View,
    ) -> Result<Frame, RenderError> {
        self.image(positions, reference, yarns, radius, view)
    }

    /// Draw `positions` with frames and framing from `shape` into an image.
    fn image(
        &self,
        positions: &wgpu::Buffer,
        shape: &[[f32; 3]],
        yarns: &[YarnSpan],
        radius: f32,
        view: &View,
    ) -> Result<Frame, RenderError> {
        let yarn = self.yarn(shape, yarns, radius)?;
        self.check_size(view)?;
        let device = &self.device;
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
        // Copies from a texture take rows padded to the copy alignment.
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
