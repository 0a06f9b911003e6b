//! The persistent GPU context: adapter, device, queue and the compiled
//! pipelines, built once and shared by every backend on it (STYLE 5). It
//! also collects the device's asynchronous errors and its loss, so a
//! failing dispatch surfaces as an error instead of a hang.

use std::sync::{Arc, Mutex, PoisonError};

use wgpu::util::DeviceExt;

use crate::shaders::{self, Pass};

/// Why no GPU context could be made.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum GpuError {
    /// No adapter was found.
    #[error(
        "no GPU adapter found ({reason}). On Linux without a GPU, install lavapipe \
         (`apt-get install mesa-vulkan-drivers`), or use a CPU backend (`serial`, `rayon`)"
    )]
    NoAdapter {
        /// What wgpu said.
        reason: String,
    },
    /// The adapter refused to open a device.
    #[error("the GPU adapter `{adapter}` could not open a device: {reason}")]
    Device {
        /// The adapter's name.
        adapter: String,
        /// What wgpu said.
        reason: String,
    },
}

/// A pass's pipelines, one per entry point, and the bind group layout they
/// share.
#[derive(Debug)]
pub(crate) struct PassPipelines<const N: usize> {
    pub(crate) layout: wgpu::BindGroupLayout,
    pub(crate) entries: [wgpu::ComputePipeline; N],
}

/// How a pass binds each of its buffers, in binding order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Slot {
    Uniform,
    Read,
    ReadWrite,
}

/// The compiled passes.
#[derive(Debug)]
pub(crate) struct Pipelines {
    /// Entry points `step`, `forces`, and with self-contact
    /// `step_touching`, `forces_touching`.
    pub(crate) gather: PassPipelines<4>,
    /// Entry points `scatter`, `step`, `forces`.
    pub(crate) fixed: PassPipelines<3>,
    /// Entry points `main`, and with self-contact and friction
    /// `main_touching`.
    pub(crate) friction: PassPipelines<2>,
    pub(crate) pins: PassPipelines<1>,
    pub(crate) fused: PassPipelines<1>,
    pub(crate) reseat: PassPipelines<1>,
    pub(crate) check: PassPipelines<1>,
    /// Self-contact's list passes: whether to rebuild, then the rebuild.
    pub(crate) plan: PassPipelines<1>,
    pub(crate) grid_insert: PassPipelines<1>,
    pub(crate) grid_find: PassPipelines<1>,
}

/// A GPU device with yarnify's pipelines, shareable between backends.
#[derive(Debug)]
pub struct Gpu {
    instance: wgpu::Instance,
    adapter: wgpu::Adapter,
    pub(crate) device: wgpu::Device,
    pub(crate) queue: wgpu::Queue,
    pub(crate) limits: wgpu::Limits,
    /// The device's `fma` rounds once (tested on creation).
    pub(crate) fused_fma: bool,
    /// The device has timestamp queries (WebGPU's optional
    /// `timestamp-query`), for the stage counters.
    pub(crate) timestamps: bool,
    info: wgpu::AdapterInfo,
    errors: Arc<Mutex<Vec<String>>>,
    pub(crate) pipelines: Pipelines,
}

impl Gpu {
    /// Open the default adapter (high performance first) and build the
    /// pipelines, blocking until done.
    ///
    /// # Errors
    /// [`GpuError::NoAdapter`] when there is no adapter, with what to
    /// install; [`GpuError::Device`] when it cannot open a device.
    pub fn new() -> Result<Arc<Self>, GpuError> {
        pollster::block_on(Self::new_async())
    }

    /// [`Gpu::new`] with a device opened at `limits` instead of every limit
    /// the adapter offers: to see how a fabric fares on a smaller device, or
    /// to keep a context within a budget. Each limit must be one the
    /// adapter supports.
    ///
    /// # Errors
    /// As [`Gpu::new`]; [`GpuError::Device`] when the adapter cannot meet
    /// `limits`.
    pub fn with_limits(limits: wgpu::Limits) -> Result<Arc<Self>, GpuError> {
        pollster::block_on(Self::open(Some(limits)))
    }

    /// [`Gpu::new`] without blocking, for the browser.
    ///
    /// # Errors
    /// As [`Gpu::new`].
    pub async fn new_async() -> Result<Arc<Self>, GpuError> {
        Self::open(None).await
    }

    /// Open the default adapter with a device at `limits`, or at every
    /// limit the adapter offers.
    // In the browser wgpu's handles are neither `Send` nor `Sync`, and
    // nothing is shared across threads there.
    #[cfg_attr(target_arch = "wasm32", allow(clippy::arc_with_non_send_sync))]
    async fn open(limits: Option<wgpu::Limits>) -> Result<Arc<Self>, GpuError> {
        // Vulkan, Metal, DX12 or the browser's WebGPU (WGPU_BACKEND overrides):
        // compute needs no GL fallback, and probing for one only adds noise.
        let mut descriptor = wgpu::InstanceDescriptor::new_without_display_handle();
        // wgpu checks an indirect dispatch's workgroup counts with a compute
        // pass of its own before it: about 7 µs each on the H200, twice a
        // substep with self-contact, whether the lists are rebuilt or not.
        // The only indirect dispatches here are the rebuild's, whose counts
        // `plan.wgsl` writes as zero or from `Gpu::groups`, within
        // `max_compute_workgroups_per_dimension`. WGPU_VALIDATION_INDIRECT_CALL=1
        // turns the check back on.
        descriptor.flags.remove(wgpu::InstanceFlags::VALIDATION_INDIRECT_CALL);
        let mut descriptor = descriptor.with_env();
        descriptor.backends = wgpu::Backends::from_env().unwrap_or(wgpu::Backends::PRIMARY);
        let instance = wgpu::Instance::new(descriptor);
        let adapter = instance
            .request_adapter(&wgpu::RequestAdapterOptions {
                power_preference: wgpu::PowerPreference::HighPerformance,
                ..Default::default()
            })
            .await
            .map_err(|e| GpuError::NoAdapter { reason: e.to_string() })?;
        let info = adapter.get_info();
        // Unless told otherwise, ask for every limit the adapter offers, so
        // large fabrics fit where the hardware allows. No feature beyond WebGPU's core is used by a
        // substep; timestamp queries, where the adapter has them, serve only
        // the stage counters.
        let features = adapter.features() & wgpu::Features::TIMESTAMP_QUERY;
        let (device, queue) = adapter
            .request_device(&wgpu::DeviceDescriptor {
                label: Some("yarnify"),
                required_limits: limits.unwrap_or_else(|| adapter.limits()),
                required_features: features,
                ..Default::default()
            })
            .await
            .map_err(|e| GpuError::Device { adapter: info.name.clone(), reason: e.to_string() })?;
        let errors = Arc::new(Mutex::new(Vec::new()));
        let sink = Arc::clone(&errors);
        device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
            sink.lock().unwrap_or_else(PoisonError::into_inner).push(e.to_string());
        }));
        let sink = Arc::clone(&errors);
        device.set_device_lost_callback(move |reason, message| {
            sink.lock().unwrap_or_else(PoisonError::into_inner).push(format!("device lost ({reason:?}): {message}"));
        });
        use Slot::{Read, ReadWrite, Uniform};
        let pipelines = Pipelines {
            gather: build(
                &device,
                &shaders::GATHER,
                &[Uniform, Read, ReadWrite, ReadWrite, Read, Read, Read, ReadWrite],
                ["step", "forces", "step_touching", "forces_touching"],
            ),
            fixed: build(
                &device,
                &shaders::FIXED,
                &[Uniform, Read, ReadWrite, ReadWrite, Read, Read, ReadWrite, ReadWrite],
                ["scatter", "step", "forces"],
            ),
            friction: build(
                &device,
                &shaders::FRICTION,
                &[Uniform, Read, Read, ReadWrite, ReadWrite, Read, Read, ReadWrite, Read],
                ["main", "main_touching"],
            ),
            pins: build(&device, &shaders::PINS, &[Uniform, ReadWrite, ReadWrite, Read, ReadWrite], ["main"]),
            fused: build(
                &device,
                &shaders::FUSED,
                &[Uniform, Read, Read, ReadWrite, ReadWrite, Read, Read, Read],
                ["main"],
            ),
            reseat: build(&device, &shaders::RESEAT, &[Uniform, ReadWrite, ReadWrite, Read], ["main"]),
            check: build(&device, &shaders::CHECK, &[Uniform, Read, Read, ReadWrite, ReadWrite], ["main"]),
            plan: build(&device, &shaders::PLAN, &[Uniform, ReadWrite, ReadWrite, ReadWrite], ["main"]),
            grid_insert: build(&device, &shaders::GRID_INSERT, &[Uniform, Read, Read, ReadWrite], ["main"]),
            grid_find: build(
                &device,
                &shaders::GRID_FIND,
                &[Uniform, Read, ReadWrite, ReadWrite, Read, ReadWrite],
                ["main"],
            ),
        };
        let limits = device.limits();
        let timestamps = features.contains(wgpu::Features::TIMESTAMP_QUERY);
        let mut gpu =
            Self { instance, adapter, device, queue, limits, fused_fma: false, timestamps, info, errors, pipelines };
        gpu.fused_fma =
            gpu.test_fma().await.map_err(|reason| GpuError::Device { adapter: gpu.info.name.clone(), reason })?;
        gpu.take_error().map_err(|reason| GpuError::Device { adapter: gpu.info.name.clone(), reason })?;
        Ok(Arc::new(gpu))
    }

    /// Whether `fma` rounds once on this device (`fma_test.wgsl`).
    async fn test_fma(&self) -> Result<bool, String> {
        let device = &self.device;
        let one_ulp = 1.0 + f32::EPSILON;
        let input = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("fma test"),
            contents: bytemuck::cast_slice(&[one_ulp, one_ulp, -(1.0 + 2.0 * f32::EPSILON), 0.0]),
            usage: wgpu::BufferUsages::STORAGE,
        });
        let output = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("fma test result"),
            size: 16,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let staging = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("fma test readback"),
            size: 16,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let test = build(device, &shaders::FMA_TEST, &[Slot::Read, Slot::ReadWrite], ["main"]);
        let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("fma test"),
            layout: &test.layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: input.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: output.as_entire_binding() },
            ],
        });
        let mut encoder = device.create_command_encoder(&Default::default());
        {
            let mut pass = encoder.begin_compute_pass(&Default::default());
            pass.set_pipeline(&test.entries[0]);
            pass.set_bind_group(0, &group, &[]);
            pass.dispatch_workgroups(1, 1, 1);
        }
        encoder.copy_buffer_to_buffer(&output, 0, &staging, 0, 16);
        self.queue.submit([encoder.finish()]);
        let bytes = read_mapped(device, &staging).await?;
        let result = bytemuck::pod_read_unaligned::<f32>(&bytes[..4]);
        Ok(result != 0.0)
    }

    /// The instance the device came from, e.g. to make a canvas surface in
    /// the browser.
    pub fn instance(&self) -> &wgpu::Instance {
        &self.instance
    }

    /// The adapter the device came from, e.g. for a surface's
    /// capabilities.
    pub fn wgpu_adapter(&self) -> &wgpu::Adapter {
        &self.adapter
    }

    /// The device, for other GPU work on the same context (the renderer).
    pub fn device(&self) -> &wgpu::Device {
        &self.device
    }

    /// The device's queue.
    pub fn queue(&self) -> &wgpu::Queue {
        &self.queue
    }

    /// Whether this device's `fma` rounds once, so the shaders can correct
    /// their square roots and quotients to the CPU's rounding.
    pub fn fused_fma(&self) -> bool {
        self.fused_fma
    }

    /// Whether this device has timestamp queries, which the stage counters
    /// use ([`yarn_model::Backend::advance_timed`]); without them they time
    /// each pass by dispatching it alone.
    pub fn timestamps(&self) -> bool {
        self.timestamps
    }

    /// The adapter's name and backend, e.g. `"llvmpipe (LLVM 15.0.6, 256 bits) (Vulkan)"`.
    /// Browsers may withhold the name; then the driver stands in, or
    /// "unnamed adapter".
    pub fn adapter(&self) -> String {
        let info = &self.info;
        let name = [&info.name, &info.driver, &info.driver_info].into_iter().find(|s| !s.is_empty());
        format!("{} ({:?})", name.map_or("unnamed adapter", String::as_str), info.backend)
    }

    /// The memory bandwidth a pass reaches on this device, in bytes per
    /// second counting each byte read and written: a compute pass
    /// (`copy.wgsl`) copying a `bytes`-sized buffer (capped by the binding
    /// limit), the median of `repeats` timed submissions of 8 to 256 copies
    /// (more for smaller buffers, so the submission's own latency is shared
    /// out). The ceiling for the memory-bound passes. Returns the buffer
    /// size used and the rate.
    ///
    /// # Errors
    /// When the device fails.
    pub fn copy_bandwidth(&self, bytes: u64, repeats: usize) -> Result<(u64, f64), String> {
        let limit = self.limits.max_storage_buffer_binding_size.min(self.limits.max_buffer_size);
        let elements = (bytes.min(limit) / 16).min(u64::from(u32::MAX)) as u32;
        let bytes = u64::from(elements) * 16;
        let copies = ((1u64 << 32) / bytes.max(1)).clamp(8, 256) as u32;
        let seconds = self.time_copies(elements, copies, repeats)?;
        Ok((bytes, 2.0 * bytes as f64 / seconds))
    }

    /// The cost of one dispatch that does almost nothing, in seconds: the
    /// floor under every substep, since each takes at least one dispatch.
    /// The median of `repeats` submissions of 256 copies of one 16-byte
    /// element.
    ///
    /// # Errors
    /// When the device fails.
    pub fn dispatch_overhead(&self, repeats: usize) -> Result<f64, String> {
        self.time_copies(1, 256, repeats)
    }

    /// Seconds per dispatch of `copy.wgsl` over `elements` 16-byte
    /// elements: the median of `repeats` timed submissions of `copies`
    /// dispatches each (one untimed first), so the submission's own
    /// latency is shared out.
    fn time_copies(&self, elements: u32, copies: u32, repeats: usize) -> Result<f64, String> {
        let buffer = |label| {
            self.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: u64::from(elements.max(1)) * 16,
                usage: wgpu::BufferUsages::STORAGE,
                mapped_at_creation: false,
            })
        };
        let (source, target) = (buffer("copy source"), buffer("copy target"));
        let copy = build(&self.device, &shaders::COPY, &[Slot::Read, Slot::ReadWrite], ["main"]);
        let group = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("copy"),
            layout: &copy.layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: source.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: target.as_entire_binding() },
            ],
        });
        let (gx, gy) = self.groups(elements).ok_or("the copy buffer is too large to dispatch")?;
        let mut times = Vec::with_capacity(repeats);
        for run in 0..=repeats {
            let mut encoder = self.device.create_command_encoder(&Default::default());
            {
                let mut pass = encoder.begin_compute_pass(&Default::default());
                pass.set_pipeline(&copy.entries[0]);
                pass.set_bind_group(0, &group, &[]);
                for _ in 0..copies {
                    pass.dispatch_workgroups(gx, gy, 1);
                }
            }
            let start = std::time::Instant::now();
            self.queue.submit([encoder.finish()]);
            self.device
                .poll(wgpu::PollType::Wait { submission_index: None, timeout: None })
                .map_err(|e| e.to_string())?;
            self.take_error()?;
            if run > 0 {
                times.push(start.elapsed().as_secs_f64() / f64::from(copies));
            }
        }
        times.sort_by(f64::total_cmp);
        Ok(times[times.len() / 2])
    }

    /// The first error the device reported since the last call, if any.
    pub(crate) fn take_error(&self) -> Result<(), String> {
        let mut errors = self.errors.lock().unwrap_or_else(PoisonError::into_inner);
        match errors.first() {
            Some(first) => {
                let first = first.clone();
                errors.clear();
                Err(first)
            }
            None => Ok(()),
        }
    }

    /// Workgroups for `threads` threads: (x, y) within the per-dimension
    /// limit, or `None` if even a square grid cannot hold them.
    pub(crate) fn groups(&self, threads: u32) -> Option<(u32, u32)> {
        let groups = threads.div_ceil(crate::WORKGROUP).max(1);
        let max = self.limits.max_compute_workgroups_per_dimension;
        let rows = groups.div_ceil(max);
        // Rows of equal length, so few workgroups start only to exit (a
        // grid of 65,535 + 1 workgroups as two full rows ran 3x slower).
        (rows <= max).then_some((groups.div_ceil(rows), rows))
    }
}

/// The bytes of `staging`, a `MAP_READ` buffer that submitted work copies
/// into, once the device has finished that work. Natively this waits on the
/// device and is ready at once; in the browser, where nothing may block, the
/// future resolves when the browser maps the buffer. The buffer is unmapped
/// again afterwards.
///
/// # Errors
/// When the device fails or the mapping is refused.
pub async fn read_mapped(device: &wgpu::Device, staging: &wgpu::Buffer) -> Result<Vec<u8>, String> {
    let (sender, receiver) = futures_channel::oneshot::channel();
    staging.map_async(wgpu::MapMode::Read, .., move |result| {
        // The receiver waits below; if it is gone there is nobody to tell.
        let _ = sender.send(result);
    });
    // A no-op in the browser, which maps on its own.
    device.poll(wgpu::PollType::Wait { submission_index: None, timeout: None }).map_err(|e| e.to_string())?;
    receiver.await.map_err(|e| e.to_string())?.map_err(|e| e.to_string())?;
    let bytes = staging.get_mapped_range(..).map_err(|e| e.to_string())?.to_vec();
    staging.unmap();
    Ok(bytes)
}

/// Compile `pass` with one bind group layout of `slots`, for each entry
/// point.
fn build<const N: usize>(device: &wgpu::Device, pass: &Pass, slots: &[Slot], entries: [&str; N]) -> PassPipelines<N> {
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(pass.name),
        source: wgpu::ShaderSource::Wgsl(pass.source().into()),
    });
    let layout_entries: Vec<_> = slots
        .iter()
        .enumerate()
        .map(|(binding, slot)| wgpu::BindGroupLayoutEntry {
            binding: binding as u32,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Buffer {
                ty: match slot {
                    Slot::Uniform => wgpu::BufferBindingType::Uniform,
                    Slot::Read => wgpu::BufferBindingType::Storage { read_only: true },
                    Slot::ReadWrite => wgpu::BufferBindingType::Storage { read_only: false },
                },
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        })
        .collect();
    let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some(pass.name),
        entries: &layout_entries,
    });
    let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some(pass.name),
        bind_group_layouts: &[Some(&layout)],
        immediate_size: 0,
    });
    let entries = entries.map(|entry| {
        device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some(entry),
            layout: Some(&pipeline_layout),
            module: &module,
            entry_point: Some(entry),
            compilation_options: Default::default(),
            cache: None,
        })
    });
    PassPipelines { layout, entries }
}
