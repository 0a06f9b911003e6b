//! The GPU backend for yarnify: SPEC §4 as WGSL compute passes on wgpu.
//!
//! Two ways to accumulate forces ([`Mode`]):
//! - [`Mode::Gather`] (the default): each node sums its own segments,
//!   joints and contacts through a precomputed adjacency, in a fixed order,
//!   recomputing the elements it shares with its neighbours. No atomics, no
//!   quantum, deterministic. With friction, a fabric of fewer than
//!   [`FUSE_BELOW`] nodes also recomputes each node's contact partners' v*,
//!   so a whole substep is one dispatch (`fused.wgsl`); a larger one runs
//!   the forces (`gather.wgsl`) and then friction and the move
//!   (`friction.wgsl`). Without friction it is `gather.wgsl` alone.
//! - [`Mode::FixedPointAtomic`]: the paper's scheme. Every element adds
//!   round(f·S), S = 4096, into three i32 accumulators per node with
//!   atomicAdd (`fixed.wgsl`), then friction and the move (`friction.wgsl`).
//!   An overflow is detected and reported, and the state put back as it was
//!   before the failing call; nothing wraps silently.
//!
//! Pins take one more dispatch when there are any (`pins.wgsl`), and
//! re-seated contacts one more while any is closing (`reseat.wgsl`).
//! [`Backend::advance`] records all `n` substeps into one submission and
//! reads nothing back; state is copied back only when asked. It waits for
//! the GPU to finish, so errors and timings belong to the call that caused
//! them.
//!
//! The shaders round every product, square root and quotient as the CPU
//! does (`mul`, `sqrt_rounded`, `div_rounded` in `common.wgsl`), so gather
//! mode reproduces `Serial<f32>` bit for bit where the GPU's `fma` is exact.
//!
//! Only WebGPU's core features are used, so the same shaders run in a
//! browser. The crate owns how the GPU executes the model, never what the
//! model is: the shaders are the formulas of `yarn_model::terms`, operation
//! for operation.
//!
//! ```no_run
//! use yarn_backend_wgpu::{Mode, Wgpu};
//! use yarn_model::{Backend, Params};
//! use yarn_topology::{Chart, Fabric, Geometry};
//!
//! let fabric = Fabric::from_chart(&Chart::stockinette(16, 16)?, &Geometry::default())?;
//! let mut gpu = Wgpu::new(Mode::Gather)?;
//! gpu.load(&fabric, &Params::default())?;
//! gpu.advance(1500)?;
//! println!("{}: max speed {:.3}", gpu.name(), gpu.state()?.max_speed());
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

#![forbid(unsafe_code)]

mod gpu;
mod layout;
pub mod shaders;

use std::sync::Arc;

use bytemuck::Pod;
pub use gpu::{Gpu, GpuError, read_mapped};
use layout::{DIVERGED, FRICTION_ON, FUSED_FMA, GpuContact, GpuParams, GpuPin, GpuReseat, OVERFLOWED};
pub use wgpu;
use wgpu::util::DeviceExt;
use yarn_model::terms::MIN_SIN_THETA;
use yarn_model::{Backend, BackendError, Model, Params, State, V3};
use yarn_topology::{Fabric, Pin};

/// Threads per workgroup in every pass (`WORKGROUP` in the shaders).
pub(crate) const WORKGROUP: u32 = 128;

/// The fixed-point scale S of [`Mode::FixedPointAtomic`] (the paper's).
pub const FIXED_POINT_SCALE: f32 = 4096.0;

/// How forces are accumulated on the GPU.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Mode {
    /// Atomics-free per-node gather in a fixed order: deterministic, no
    /// quantum, and it measured faster (see the README). The default.
    #[default]
    Gather,
    /// The paper's i32 atomicAdd of round(f·S), S = [`FIXED_POINT_SCALE`]:
    /// forces are quantised to 1/S, and the order of additions varies.
    FixedPointAtomic,
}

impl Mode {
    /// Short name for reports: `"gather"` or `"fixed"`.
    pub fn name(self) -> &'static str {
        match self {
            Mode::Gather => "gather",
            Mode::FixedPointAtomic => "fixed",
        }
    }
}

/// The GPU backend, in `f32`.
#[derive(Debug)]
pub struct Wgpu {
    gpu: Arc<Gpu>,
    mode: Mode,
    fuse_below: usize,
    checkpoint_every: u64,
    loaded: Option<Loaded>,
}

/// A state the CPU side holds, and the substep it belongs to: what is left
/// to read when the device is lost ([`Wgpu::last_good_state`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Checkpoint {
    /// Substeps since load.
    pub substeps: u64,
    /// Positions and velocities then.
    pub state: State<f32>,
}

impl Wgpu {
    /// A backend on its own GPU context.
    ///
    /// # Errors
    /// As [`Gpu::new`]: no adapter (with what to install) or no device.
    pub fn new(mode: Mode) -> Result<Self, GpuError> {
        Ok(Self::with_gpu(Gpu::new()?, mode))
    }

    /// A backend on a shared GPU context: building one compiles every
    /// pipeline, so share it between backends.
    pub fn with_gpu(gpu: Arc<Gpu>, mode: Mode) -> Self {
        Self { gpu, mode, fuse_below: FUSE_BELOW, checkpoint_every: 0, loaded: None }
    }

    /// Also copy the state back to the CPU at the end of an
    /// [`Backend::advance`] once `substeps` have passed since the last copy
    /// (0, the default, never does: the state is then copied only when
    /// loaded, written or read). Each copy is a read-back, so the cost is
    /// one round trip per `substeps`.
    pub fn set_checkpoint_every(&mut self, substeps: u64) {
        self.checkpoint_every = substeps;
    }

    /// The newest state the CPU side holds: the one loaded, written or read
    /// last, or copied by [`Wgpu::set_checkpoint_every`]. It stays readable
    /// when the device is lost and the GPU's copy with it. `None` before
    /// load.
    pub fn last_good_state(&self) -> Option<&Checkpoint> {
        self.loaded.as_ref().map(|l| &l.checkpoint)
    }

    /// Fuse gather mode's substep with friction into one dispatch only
    /// below `nodes` nodes (default [`FUSE_BELOW`]; 0 never fuses). The
    /// results are the same either way; only the speed differs.
    pub fn set_fuse_below(&mut self, nodes: usize) {
        self.fuse_below = nodes;
    }

    /// The GPU context.
    pub fn gpu(&self) -> &Arc<Gpu> {
        &self.gpu
    }

    /// The accumulation mode.
    pub fn mode(&self) -> Mode {
        self.mode
    }

    /// The buffer holding the current positions on the GPU, one
    /// `vec4<f32>` per node (xyz, w unused), for drawing without a copy to
    /// the CPU (`yarn_render::Renderer::render_gpu`). `None` before load.
    /// Valid until the next call that changes the state.
    pub fn positions(&self) -> Option<&wgpu::Buffer> {
        self.loaded.as_ref().map(|l| &l.buffers.x[l.px])
    }

    fn loaded(&mut self) -> Result<&mut Loaded, BackendError> {
        self.loaded.as_mut().ok_or(BackendError::NotLoaded)
    }

    /// Wait for the GPU, then report any error it raised.
    fn finish(&self) -> Result<(), BackendError> {
        self.gpu
            .device
            .poll(wgpu::PollType::Wait { submission_index: None, timeout: None })
            .map_err(|e| BackendError::Device(e.to_string()))?;
        self.gpu.take_error().map_err(BackendError::Device)
    }

    /// Copy `bytes` of `buffer` back to the CPU, waiting for the device.
    /// In the browser nothing may wait: use [`Wgpu::read_positions`].
    fn read(&self, buffer: &wgpu::Buffer, bytes: u64) -> Result<Vec<u8>, BackendError> {
        if cfg!(target_arch = "wasm32") {
            return Err(BackendError::Device(
                "a blocking read-back is not possible in the browser; await `Wgpu::read_positions` instead".into(),
            ));
        }
        pollster::block_on(self.read_async(buffer, bytes))
    }

    /// Submit a copy of `bytes` of `buffer` to a staging buffer; the
    /// future owns what it needs, so no borrow of `self` is held while it
    /// waits.
    fn read_async(
        &self,
        buffer: &wgpu::Buffer,
        bytes: u64,
    ) -> impl std::future::Future<Output = Result<Vec<u8>, BackendError>> + 'static {
        let device = &self.gpu.device;
        let staging = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size: bytes,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("readback") });
        encoder.copy_buffer_to_buffer(buffer, 0, &staging, 0, bytes);
        self.gpu.queue.submit([encoder.finish()]);
        let gpu = Arc::clone(&self.gpu);
        async move {
            let bytes = read_mapped(&gpu.device, &staging).await.map_err(BackendError::Device)?;
            gpu.take_error().map_err(BackendError::Device)?;
            Ok(bytes)
        }
    }

    /// The current positions, copied back without blocking: the read-back
    /// for the browser, where [`Backend::read_state`] cannot wait. The copy
    /// is submitted now, so the result is the state as of this call; the
    /// future borrows nothing, and natively it is ready at once.
    ///
    /// # Errors
    /// [`BackendError::NotLoaded`] before load; [`BackendError::Device`]
    /// when the device fails.
    pub fn read_positions(
        &self,
    ) -> Result<impl std::future::Future<Output = Result<Vec<V3<f32>>, BackendError>> + 'static, BackendError> {
        let loaded = self.loaded.as_ref().ok_or(BackendError::NotLoaded)?;
        let n = loaded.model.node_count();
        let bytes = self.read_async(&loaded.buffers.x[loaded.px], (n * 16) as u64);
        Ok(async move { Ok(vectors(&bytes.await?)) })
    }

    /// Read a node buffer of `vec4<f32>` as vectors.
    fn read_vectors(&self, buffer: &wgpu::Buffer, nodes: usize, out: &mut Vec<V3<f32>>) -> Result<(), BackendError> {
        let bytes = self.read(buffer, (nodes * 16) as u64)?;
        *out = vectors(&bytes);
        Ok(())
    }
}

/// `vec4<f32>` bytes as vectors (w dropped).
fn vectors(bytes: &[u8]) -> Vec<V3<f32>> {
    bytemuck::pod_collect_to_vec::<u8, [f32; 4]>(bytes).iter().map(|v| V3::new(v[0], v[1], v[2])).collect()
}

/// A fabric on the GPU: its buffers, the bind groups of every pass, and the
/// host copy of the model (for validation and counts).
#[derive(Debug)]
struct Loaded {
    model: Model<f32>,
    buffers: Buffers,
    groups: Groups,
    /// Positions and velocities are double-buffered: `x[px]` and `v[pv]`
    /// are current.
    px: usize,
    pv: usize,
    substeps: u64,
    /// The newest state copied to the CPU.
    checkpoint: Checkpoint,
}

#[derive(Debug)]
struct Buffers {
    params: wgpu::Buffer,
    x: [wgpu::Buffer; 2],
    v: [wgpu::Buffer; 2],
    forces: wgpu::Buffer,
    /// Per node i: the rest length of segment i and κθ0 of joint i.
    chain: wgpu::Buffer,
    contacts: wgpu::Buffer,
    /// Each node's contacts, copied in contact order:
    /// `incident[start[i]..start[i + 1]]`.
    start: wgpu::Buffer,
    incident: wgpu::Buffer,
    pins: wgpu::Buffer,
    pin_count: u32,
    /// The re-seated contacts closing, with their slots in `incident`.
    reseats: wgpu::Buffer,
    reseat_count: u32,
    /// Fixed-point accumulators (three i32 per node).
    acc: wgpu::Buffer,
    /// `status[0]`: the OVERFLOWED and DIVERGED bits a batch raised, and
    /// the mappable copy each submission ends with, so reading it costs no
    /// second round trip.
    status: wgpu::Buffer,
    status_readback: wgpu::Buffer,
    /// The positions and velocities a batch started from, put back if it
    /// overflows or diverges.
    snapshot: [wgpu::Buffer; 2],
}

/// Bind groups by `[px][pv]`: the forces pass writing the next positions,
/// the same pass writing `forces`, friction, pins, and the divergence check.
#[derive(Debug)]
struct Groups {
    step: [[wgpu::BindGroup; 2]; 2],
    probe: [[wgpu::BindGroup; 2]; 2],
    friction: [[wgpu::BindGroup; 2]; 2],
    pins: [[wgpu::BindGroup; 2]; 2],
    fused: [[wgpu::BindGroup; 2]; 2],
    check: [[wgpu::BindGroup; 2]; 2],
    reseat: wgpu::BindGroup,
}

impl Loaded {
    fn gpu_params(&self, fused_fma: bool) -> GpuParams {
        let c = self.model.coeffs;
        GpuParams {
            nodes: self.model.node_count() as u32,
            contacts: self.model.contacts.len() as u32,
            pins: self.buffers.pin_count,
            flags: if c.friction > 0.0 { FRICTION_ON } else { 0 } | if fused_fma { FUSED_FMA } else { 0 },
            stretch: c.stretch,
            bend: c.bend,
            contact: c.contact,
            friction: c.friction,
            h: c.h,
            h_over_m: c.h_over_m,
            damping_factor: c.damping_factor,
            friction_impulse: c.friction_impulse,
            gravity_y: -c.mass * c.gravity,
            min_sin: MIN_SIN_THETA as f32,
            scale: FIXED_POINT_SCALE,
            max_force: max_force() as f32,
            max_speed: self.model.divergence_speed() as f32,
            one: 1.0,
            reseat_step: self.model.reseat_step(),
            reseats: self.buffers.reseat_count,
        }
    }
}

/// The largest force component one fixed-point addition takes: half the
/// i32 range, so a node's sum of a few such terms is checked for wrapping.
fn max_force() -> f64 {
    f64::from(i32::MAX) / f64::from(FIXED_POINT_SCALE) / 2.0
}

/// A storage buffer holding `data` (padded to one 16-byte element when
/// empty: a binding may not be).
fn storage(device: &wgpu::Device, label: &str, data: &[impl Pod]) -> wgpu::Buffer {
    let bytes: &[u8] = bytemuck::cast_slice(data);
    let contents = if bytes.is_empty() { &[0u8; 16][..] } else { bytes };
    device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some(label),
        contents,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
    })
}

fn vec4s(v: &[V3<f32>]) -> Vec<[f32; 4]> {
    v.iter().map(|p| [p.x, p.y, p.z, 0.0]).collect()
}

/// Per node i: the rest length of segment i and κθ0 of joint i, zero past
/// the yarn's ends.
fn chain(model: &Model<f32>) -> Vec<[f32; 2]> {
    let kappa = model.coeffs.rest_curl;
    (0..model.node_count())
        .map(|i| {
            [
                model.spring_rest.get(i).copied().unwrap_or(0.0),
                model.rest_angle.get(i).map_or(0.0, |&theta0| kappa * theta0),
            ]
        })
        .collect()
}

fn gpu_contacts(model: &Model<f32>) -> Vec<GpuContact> {
    model
        .contacts
        .iter()
        .zip(&model.alive)
        .map(|(c, &alive)| GpuContact { a: c.a, b: c.b, rest: c.rest, alive: u32::from(alive) })
        .collect()
}

/// Gather mode with friction fuses the substep into one dispatch below this
/// many nodes, and runs the forces and the friction as two passes from it
/// up. Fusing saves a dispatch but recomputes each contact partner's v*,
/// with scattered reads; measured on an H200 (`yarn-gate bench --backend
/// wgpu`), one dispatch won at 2,048 nodes (9.9 against 11.5 µs a
/// substep), tied at 32,768, and lost from 1M nodes up (0.10 against 0.07
/// ns a node-substep at 1M, 0.09 against 0.06 at 4.2M).
pub const FUSE_BELOW: usize = 65_536;

/// Each node's alive contacts in contact order, as `start` offsets into
/// `incident`, which holds a copy of each contact record per node; and the
/// re-seated contacts with the slots of their two copies.
fn incidence(model: &Model<f32>) -> (Vec<u32>, Vec<GpuContact>, Vec<GpuReseat>) {
    let contacts = gpu_contacts(model);
    let (start, entries) = model.incidence();
    let mut slots = vec![[0u32; 2]; contacts.len()];
    for (e, &(node, k)) in entries.iter().enumerate() {
        slots[k as usize][usize::from(contacts[k as usize].b == node)] = e as u32;
    }
    let reseats = model
        .reseating()
        .iter()
        .map(|r| {
            let [slot_a, slot_b] = slots[r.contact as usize];
            GpuReseat { contact: r.contact, slot_a, slot_b, knit: r.knit }
        })
        .collect();
    (start, entries.into_iter().map(|(_, k)| contacts[k as usize]).collect(), reseats)
}

impl Wgpu {
    /// Check that a buffer of `bytes` fits one binding.
    fn check_fits(&self, what: &'static str, bytes: u64) -> Result<(), BackendError> {
        let limits = &self.gpu.limits;
        let (limit, limit_name) = if limits.max_storage_buffer_binding_size < limits.max_buffer_size {
            (limits.max_storage_buffer_binding_size, "max_storage_buffer_binding_size")
        } else {
            (limits.max_buffer_size, "max_buffer_size")
        };
        if bytes > limit { Err(BackendError::TooLarge { what, needed: bytes, limit, limit_name }) } else { Ok(()) }
    }

    /// Check that `threads` fit one dispatch.
    fn check_dispatch(&self, threads: usize) -> Result<(), BackendError> {
        if u32::try_from(threads).ok().and_then(|t| self.gpu.groups(t)).is_some() {
            return Ok(());
        }
        let max = u64::from(self.gpu.limits.max_compute_workgroups_per_dimension);
        Err(BackendError::TooLarge {
            what: "the dispatch (threads)",
            needed: threads as u64,
            limit: max * max * u64::from(WORKGROUP),
            limit_name: "max_compute_workgroups_per_dimension",
        })
    }

    fn bind(&self, layout: &wgpu::BindGroupLayout, label: &str, buffers: &[&wgpu::Buffer]) -> wgpu::BindGroup {
        let entries: Vec<_> = buffers
            .iter()
            .enumerate()
            .map(|(i, b)| wgpu::BindGroupEntry { binding: i as u32, resource: b.as_entire_binding() })
            .collect();
        self.gpu.device.create_bind_group(&wgpu::BindGroupDescriptor { label: Some(label), layout, entries: &entries })
    }

    /// The bind groups of every pass for every parity.
    fn bind_all(&self, b: &Buffers) -> Groups {
        let k = &self.gpu.kernels;
        let (x, v) = (&b.x, &b.v);
        let table = |f: &dyn Fn(usize, usize) -> wgpu::BindGroup| [[f(0, 0), f(0, 1)], [f(1, 0), f(1, 1)]];
        // The forces pass with `out` = the next positions (`step`) or the
        // force buffer (`probe`).
        let forces_pass = |label, px: usize, pv: usize, out: &wgpu::Buffer| match self.mode {
            Mode::Gather => {
                self.bind(&k.gather.layout, label, &[&b.params, &x[px], &v[pv], out, &b.chain, &b.start, &b.incident])
            }
            Mode::FixedPointAtomic => self.bind(
                &k.fixed.layout,
                label,
                &[&b.params, &x[px], &v[pv], out, &b.chain, &b.contacts, &b.acc, &b.status],
            ),
        };
        Groups {
            step: table(&|px, pv| forces_pass("step", px, pv, &x[1 - px])),
            probe: table(&|px, pv| forces_pass("forces", px, pv, &b.forces)),
            friction: table(&|px, pv| {
                let buffers = [&b.params, &x[px], &v[pv], &x[1 - px], &v[1 - pv], &b.start, &b.incident];
                self.bind(&k.friction.layout, "friction", &buffers)
            }),
            pins: table(&|px, pv| self.bind(&k.pins.layout, "pins", &[&b.params, &x[px], &v[pv], &b.pins])),
            check: table(&|px, pv| self.bind(&k.check.layout, "check", &[&b.params, &x[px], &v[pv], &b.status])),
            reseat: self.bind_reseat(b),
            fused: table(&|px, pv| {
                let buffers = [&b.params, &x[px], &v[pv], &x[1 - px], &v[1 - pv], &b.chain, &b.start, &b.incident];
                self.bind(&k.fused.layout, "fused", &buffers)
            }),
        }
    }

    /// Upload the model's pins and parameters, and rebind.
    fn upload_pins(&self, l: &mut Loaded) {
        let pins: Vec<GpuPin> =
            l.model.pins.iter().map(|&(node, target)| GpuPin { goal: [target.x, target.y, target.z], node }).collect();
        l.buffers.pin_count = pins.len() as u32;
        l.buffers.pins = storage(&self.gpu.device, "pins", &pins);
        l.groups = self.bind_all(&l.buffers);
        self.write_params(l);
    }

    fn bind_reseat(&self, b: &Buffers) -> wgpu::BindGroup {
        self.bind(&self.gpu.kernels.reseat.layout, "reseat", &[&b.params, &b.contacts, &b.incident, &b.reseats])
    }

    /// Upload the model's contact records, per-node lists and re-seated
    /// contacts, and rebind the reseat pass to its new buffer.
    fn upload_contacts(&self, l: &mut Loaded) {
        let queue = &self.gpu.queue;
        queue.write_buffer(&l.buffers.contacts, 0, bytemuck::cast_slice(&gpu_contacts(&l.model)));
        // Only alive contacts are listed per node, so a released contact
        // costs the gather nothing.
        let (start, incident, reseats) = incidence(&l.model);
        queue.write_buffer(&l.buffers.start, 0, bytemuck::cast_slice(&start));
        if !incident.is_empty() {
            queue.write_buffer(&l.buffers.incident, 0, bytemuck::cast_slice(&incident));
        }
        l.buffers.reseat_count = reseats.len() as u32;
        l.buffers.reseats = storage(&self.gpu.device, "reseats", &reseats);
        l.groups.reseat = self.bind_reseat(&l.buffers);
        self.write_params(l);
    }

    fn write_params(&self, l: &Loaded) {
        self.gpu.queue.write_buffer(&l.buffers.params, 0, bytemuck::bytes_of(&l.gpu_params(self.gpu.fused_fma)));
    }

    /// Record one substep into `pass`, flipping the parities.
    fn record_substep(&self, l: &mut Loaded, pass: &mut wgpu::ComputePass<'_>) {
        let k = &self.gpu.kernels;
        let groups = |threads: usize| self.gpu.groups(threads as u32).unwrap_or((1, 1));
        let nodes = groups(l.model.node_count());
        let friction = l.model.coeffs.friction > 0.0;
        let step = match self.mode {
            Mode::Gather if friction && l.model.node_count() < self.fuse_below => {
                pass.set_pipeline(&k.fused.entries[0]);
                pass.set_bind_group(0, &l.groups.fused[l.px][l.pv], &[]);
                pass.dispatch_workgroups(nodes.0, nodes.1, 1);
                (l.px, l.pv) = (1 - l.px, 1 - l.pv);
                return self.record_pins(l, pass);
            }
            Mode::Gather => &k.gather.entries[0],
            Mode::FixedPointAtomic => {
                let (gx, gy) = groups(l.model.node_count().max(l.model.contacts.len()));
                pass.set_pipeline(&k.fixed.entries[0]);
                pass.set_bind_group(0, &l.groups.step[l.px][l.pv], &[]);
                pass.dispatch_workgroups(gx, gy, 1);
                &k.fixed.entries[1]
            }
        };
        pass.set_pipeline(step);
        pass.set_bind_group(0, &l.groups.step[l.px][l.pv], &[]);
        pass.dispatch_workgroups(nodes.0, nodes.1, 1);
        if friction {
            pass.set_pipeline(&k.friction.entries[0]);
            pass.set_bind_group(0, &l.groups.friction[l.px][l.pv], &[]);
            pass.dispatch_workgroups(nodes.0, nodes.1, 1);
            l.pv = 1 - l.pv;
        }
        l.px = 1 - l.px;
        self.record_pins(l, pass);
    }

    /// Record the pins pass, when there are pins.
    fn record_pins(&self, l: &Loaded, pass: &mut wgpu::ComputePass<'_>) {
        if let Some((gx, gy)) = (l.buffers.pin_count > 0).then(|| self.gpu.groups(l.buffers.pin_count)).flatten() {
            pass.set_pipeline(&self.gpu.kernels.pins.entries[0]);
            pass.set_bind_group(0, &l.groups.pins[l.px][l.pv], &[]);
            pass.dispatch_workgroups(gx, gy, 1);
        }
    }

    fn advance_loaded(&self, l: &mut Loaded, substeps: u64) -> Result<(), BackendError> {
        let (px, pv, first) = (l.px, l.pv, l.substeps);
        // The host's model closes the re-seated contacts as the GPU will,
        // which says for how many substeps the reseat pass is needed.
        let reseats = l.model.save_reseats();
        let closing = l.model.close_reseats(substeps, |_, _| ());
        let reseat_groups = self.gpu.groups(l.buffers.reseat_count).unwrap_or((1, 1));
        let device = &self.gpu.device;
        let mut encoder = device.create_command_encoder(&Default::default());
        // A batch can fail part way: keep the state it started from.
        let [saved_x, saved_v] = &l.buffers.snapshot;
        encoder.copy_buffer_to_buffer(&l.buffers.x[px], 0, saved_x, 0, saved_x.size());
        encoder.copy_buffer_to_buffer(&l.buffers.v[pv], 0, saved_v, 0, saved_v.size());
        {
            let mut pass = encoder.begin_compute_pass(&Default::default());
            for s in 0..substeps {
                self.record_substep(l, &mut pass);
                if s < closing {
                    pass.set_pipeline(&self.gpu.kernels.reseat.entries[0]);
                    pass.set_bind_group(0, &l.groups.reseat, &[]);
                    pass.dispatch_workgroups(reseat_groups.0, reseat_groups.1, 1);
                }
            }
            let (gx, gy) = self.gpu.groups(l.model.node_count() as u32).unwrap_or((1, 1));
            pass.set_pipeline(&self.gpu.kernels.check.entries[0]);
            pass.set_bind_group(0, &l.groups.check[l.px][l.pv], &[]);
            pass.dispatch_workgroups(gx, gy, 1);
        }
        Self::record_status(&mut encoder, l);
        self.gpu.queue.submit([encoder.finish()]);
        l.substeps += substeps;
        let result = self.check_status(l, first, l.substeps);
        if result.is_err() {
            let [saved_x, saved_v] = &l.buffers.snapshot;
            let mut encoder = device.create_command_encoder(&Default::default());
            encoder.copy_buffer_to_buffer(saved_x, 0, &l.buffers.x[px], 0, saved_x.size());
            encoder.copy_buffer_to_buffer(saved_v, 0, &l.buffers.v[pv], 0, saved_v.size());
            self.gpu.queue.submit([encoder.finish()]);
            (l.px, l.pv, l.substeps) = (px, pv, first);
            if closing > 0 {
                l.model.restore_reseats(&reseats);
                self.upload_contacts(l);
            }
            self.finish()?;
        }
        result
    }

    /// End a submission by copying the status to its mappable twin and
    /// clearing it for the next.
    fn record_status(encoder: &mut wgpu::CommandEncoder, l: &Loaded) {
        encoder.copy_buffer_to_buffer(&l.buffers.status, 0, &l.buffers.status_readback, 0, 16);
        encoder.clear_buffer(&l.buffers.status, 0, None);
    }

    /// Wait for the GPU, then read the status the batch of substeps
    /// `first..end` raised (copied by [`Self::record_status`], so this is
    /// the only wait): a fixed-point overflow, or a diverged state, which
    /// the read-back state then names. In the browser, where nothing may
    /// wait, only device errors are reported.
    fn check_status(&self, l: &Loaded, first: u64, end: u64) -> Result<(), BackendError> {
        if cfg!(target_arch = "wasm32") {
            return self.finish();
        }
        let status = pollster::block_on(read_mapped(&self.gpu.device, &l.buffers.status_readback))
            .map_err(BackendError::Device)?;
        self.gpu.take_error().map_err(BackendError::Device)?;
        let status = bytemuck::pod_read_unaligned::<u32>(&status[..4]);
        if status & (OVERFLOWED | DIVERGED) == 0 {
            return Ok(());
        }
        if status & OVERFLOWED != 0 {
            return Err(BackendError::Overflow { first, end, max_force: max_force() });
        }
        let limit = l.model.divergence_speed();
        let n = l.model.node_count();
        let mut state = State { positions: Vec::new(), velocities: Vec::new() };
        self.read_vectors(&l.buffers.x[l.px], n, &mut state.positions)?;
        self.read_vectors(&l.buffers.v[l.pv], n, &mut state.velocities)?;
        let (node, speed) = state.first_diverged(f64::from(limit as f32)).unwrap_or((0, f64::NAN));
        Err(BackendError::Diverged { substep: end, node, speed, limit })
    }
}

impl Backend for Wgpu {
    type Real = f32;

    fn name(&self) -> String {
        format!("wgpu-{}", self.mode.name())
    }

    fn load(&mut self, fabric: &Fabric, params: &Params) -> Result<(), BackendError> {
        let model = Model::<f32>::new(fabric, params)?;
        let n = model.node_count();
        let contacts = model.contacts.len();
        self.check_fits("the node buffer (bytes)", n as u64 * 16)?;
        self.check_fits("the per-node contact records (bytes)", contacts as u64 * 32)?;
        self.check_dispatch(n.max(contacts))?;
        // The fabric is accepted: free the previous one's buffers before
        // making the new ones, so the two never hold memory together.
        self.loaded = None;
        self.finish()?;
        let (start, incident, _) = incidence(&model);
        let device = &self.gpu.device;
        let state = State::<f32>::at_rest(fabric);
        let (x, v) = (vec4s(&state.positions), vec4s(&state.velocities));
        let buffers = Buffers {
            params: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("params"),
                size: std::mem::size_of::<GpuParams>() as u64,
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
            x: [storage(device, "x0", &x), storage(device, "x1", &x)],
            v: [storage(device, "v0", &v), storage(device, "v1", &v)],
            forces: storage(device, "forces", &v),
            chain: storage(device, "chain", &chain(&model)),
            contacts: storage(device, "contacts", &gpu_contacts(&model)),
            start: storage(device, "start", &start),
            incident: storage(device, "incident", &incident),
            pins: storage(device, "pins", &[0u32; 4]),
            pin_count: 0,
            reseats: storage(device, "reseats", &[0u32; 4]),
            reseat_count: 0,
            acc: storage(device, "accumulators", &vec![0i32; 3 * n]),
            status: storage(device, "status", &[0u32; 4]),
            status_readback: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("status readback"),
                size: 16,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
            snapshot: [x.len(), v.len()].map(|elements| {
                device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("snapshot"),
                    size: (elements.max(1) * 16) as u64,
                    usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
                    mapped_at_creation: false,
                })
            }),
        };
        let groups = self.bind_all(&buffers);
        let checkpoint = Checkpoint { substeps: 0, state };
        let mut loaded = Loaded { model, buffers, groups, px: 0, pv: 0, substeps: 0, checkpoint };
        self.upload_pins(&mut loaded);
        self.loaded = Some(loaded);
        self.finish()
    }

    fn set_params(&mut self, params: &Params) -> Result<(), BackendError> {
        self.loaded()?.model.set_params(params)?;
        let loaded = self.loaded.as_ref().ok_or(BackendError::NotLoaded)?;
        self.write_params(loaded);
        self.gpu.queue.write_buffer(&loaded.buffers.chain, 0, bytemuck::cast_slice(&chain(&loaded.model)));
        Ok(())
    }

    fn set_pins(&mut self, pins: &[Pin]) -> Result<(), BackendError> {
        let mut loaded = self.loaded.take().ok_or(BackendError::NotLoaded)?;
        let result = loaded.model.set_pins(pins);
        if result.is_ok() {
            self.upload_pins(&mut loaded);
        }
        self.loaded = Some(loaded);
        result
    }

    /// As the trait says. Reviving a contact reads the positions back,
    /// which the browser cannot do while waiting: there it is an error.
    fn set_contacts_alive(&mut self, alive: &[bool]) -> Result<(), BackendError> {
        let mut loaded = self.loaded.take().ok_or(BackendError::NotLoaded)?;
        let mut positions = Vec::new();
        let mut result = Ok(());
        if loaded.model.revives(alive) && alive.len() == loaded.model.contacts.len() {
            result = self.read_vectors(&loaded.buffers.x[loaded.px], loaded.model.node_count(), &mut positions);
        }
        result = result.and_then(|()| loaded.model.set_contacts_alive(alive, &positions));
        if result.is_ok() {
            self.upload_contacts(&mut loaded);
        }
        self.loaded = Some(loaded);
        result
    }

    fn write_state(&mut self, state: &State<f32>) -> Result<(), BackendError> {
        let loaded = self.loaded.as_ref().ok_or(BackendError::NotLoaded)?;
        state.check_len(loaded.model.node_count())?;
        let queue = &self.gpu.queue;
        queue.write_buffer(&loaded.buffers.x[loaded.px], 0, bytemuck::cast_slice(&vec4s(&state.positions)));
        queue.write_buffer(&loaded.buffers.v[loaded.pv], 0, bytemuck::cast_slice(&vec4s(&state.velocities)));
        let substeps = loaded.substeps;
        self.loaded()?.checkpoint = Checkpoint { substeps, state: state.clone() };
        Ok(())
    }

    /// As the trait says; the state read is also kept as the
    /// [`Wgpu::last_good_state`].
    fn read_state(&mut self, state: &mut State<f32>) -> Result<(), BackendError> {
        let loaded = self.loaded.as_ref().ok_or(BackendError::NotLoaded)?;
        let n = loaded.model.node_count();
        self.read_vectors(&loaded.buffers.x[loaded.px], n, &mut state.positions)?;
        self.read_vectors(&loaded.buffers.v[loaded.pv], n, &mut state.velocities)?;
        let substeps = loaded.substeps;
        self.loaded()?.checkpoint = Checkpoint { substeps, state: state.clone() };
        Ok(())
    }

    fn compute_forces(&mut self, forces: &mut Vec<V3<f32>>) -> Result<(), BackendError> {
        let loaded = self.loaded.as_ref().ok_or(BackendError::NotLoaded)?;
        let k = &self.gpu.kernels;
        let n = loaded.model.node_count();
        let groups = |threads: usize| self.gpu.groups(threads as u32).unwrap_or((1, 1));
        let bind = &loaded.groups.probe[loaded.px][loaded.pv];
        let mut encoder = self.gpu.device.create_command_encoder(&Default::default());
        {
            let mut pass = encoder.begin_compute_pass(&Default::default());
            let probe = match self.mode {
                Mode::Gather => &k.gather.entries[1],
                Mode::FixedPointAtomic => {
                    let (gx, gy) = groups(n.max(loaded.model.contacts.len()));
                    pass.set_pipeline(&k.fixed.entries[0]);
                    pass.set_bind_group(0, bind, &[]);
                    pass.dispatch_workgroups(gx, gy, 1);
                    &k.fixed.entries[2]
                }
            };
            let (gx, gy) = groups(n);
            pass.set_pipeline(probe);
            pass.set_bind_group(0, bind, &[]);
            pass.dispatch_workgroups(gx, gy, 1);
        }
        Self::record_status(&mut encoder, loaded);
        self.gpu.queue.submit([encoder.finish()]);
        self.check_status(loaded, loaded.substeps, loaded.substeps)?;
        self.read_vectors(&loaded.buffers.forces, n, forces)
    }

    fn advance(&mut self, substeps: u64) -> Result<(), BackendError> {
        let mut loaded = self.loaded.take().ok_or(BackendError::NotLoaded)?;
        let result = self.advance_loaded(&mut loaded, substeps);
        let due = self.checkpoint_every > 0
            && loaded.substeps.saturating_sub(loaded.checkpoint.substeps) >= self.checkpoint_every;
        self.loaded = Some(loaded);
        result?;
        if due {
            self.state()?;
        }
        Ok(())
    }
}
