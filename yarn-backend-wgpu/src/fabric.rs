//! A fabric loaded on the GPU: its host model, buffers and bind groups,
//! which pair of state buffers is current, and the newest state the CPU
//! side holds. It owns every operation on a loaded fabric, so the backend
//! in `lib.rs` only forwards to it.
//!
//! This module owns the uploads, the read-backs, the batch submission and
//! its rollback; what a substep dispatches is in `record.rs`, the buffers
//! in `bindings.rs`, and the stage counters in `timing.rs`.

use std::sync::Arc;

use yarn_model::self_contact::grid::{GridShape, MAX_LONG};
use yarn_model::{BackendError, Model, Rollback, State, V3, advance_with_rollback};

use crate::bindings::{
    Buffers, Groups, Parity, chain, forces_kernel, gpu_contacts, grid, incidence, lists, lists_bytes, pinned,
    reseat_group, rows, rule, storage, vec4s,
};
use crate::gpu::{Gpu, read_mapped};
use crate::layout::{
    CADENCE, CROWDED, DIVERGED, FRICTION_IN_TENSION, FRICTION_ON, FUSED_FMA, GpuChain, GpuParams, GpuPin, GpuSurface,
    LATE_REBUILD, LOOKAHEAD, MAX_COLLIDERS, OVERFLOWED, SELF_CONTACT, STRETCHED,
};
use crate::record::Dispatch;
use crate::timing::Timestamps;
use crate::{Checkpoint, FIXED_POINT_SCALE, Mode, Raised, WORKGROUP};

/// A fabric on the GPU.
#[derive(Debug)]
pub(crate) struct GpuFabric {
    pub(crate) gpu: Arc<Gpu>,
    pub(crate) mode: Mode,
    /// Gather mode with friction fuses its substep below this many nodes.
    pub(crate) fuse_below: usize,
    pub(crate) model: Model<f32>,
    pub(crate) buffers: Buffers,
    pub(crate) groups: Groups,
    /// Which buffer of each pair is current.
    pub(crate) parity: Parity,
    /// Substeps since load.
    pub(crate) substeps: u64,
    /// The newest state copied to the CPU.
    pub(crate) checkpoint: Checkpoint,
    /// Where the batch in flight started, for [`Rollback::restore`].
    saved: (Parity, u64),
    /// Set by the stage counters while a timed batch runs.
    pub(crate) timestamps: Option<Timestamps>,
    /// Slots in each segment's self-contact candidate list.
    pub(crate) slots: u32,
    /// How many candidates the most crowded segment had, when a batch
    /// found more than the slots hold: the lists grow and the batch runs
    /// again.
    crowded: Option<u32>,
    /// Whether a batch's pushes ran on lists some node had moved half the
    /// skin from: it is put back and runs again with a rebuild check every
    /// substep.
    late: bool,
    /// Batches that start before this substep check for a rebuild every
    /// substep, since one not long before was late; and how long the next
    /// late batch makes them do so.
    pub(crate) every_substep_until: u64,
    late_backoff: u64,
    /// How many batches were late.
    pub(crate) late_batches: u64,
    /// Whether the status stays on the GPU across batches until
    /// [`crate::Wgpu::read_raised`] takes it, instead of being waited for
    /// at the end of each: in the browser, where nothing may wait.
    pub(crate) deferred_status: bool,
    /// Substeps since load when the deferred status was last taken.
    raised_since: u64,
}

/// Substeps a late batch ([`GpuFabric::late`]) has the batches after it
/// check for a rebuild every substep, doubled by each late batch in a row.
const FIRST_LATE_BACKOFF: u64 = 1_000;

/// Slots per segment's candidate list at load: at rest a segment of the
/// default fabric has at most 7 candidates, so this leaves room for a fold
/// or a crush; more grow the lists ([`GpuFabric::advance`]).
pub(crate) const FIRST_SLOTS: u32 = 16;

/// Check that `model` fits the device: its buffers one binding each, its
/// passes one dispatch each.
///
/// # Errors
/// [`BackendError::TooLarge`] naming the limit.
pub(crate) fn check_fits(gpu: &Gpu, model: &Model<f32>) -> Result<(), BackendError> {
    let (nodes, contacts) = (model.node_count(), model.contacts().len());
    fits_binding(gpu, "the node buffer (bytes)", nodes as u64 * 16)?;
    fits_binding(gpu, "the per-node chain records (bytes)", (nodes * size_of::<GpuChain>()) as u64)?;
    fits_binding(gpu, "the per-node contact records (bytes)", contacts as u64 * 32)?;
    if model.self_contact() {
        fits_binding(gpu, "the self-contact candidate lists (bytes)", lists_bytes(nodes, FIRST_SLOTS))?;
        fits_binding(gpu, "the self-contact grid (bytes)", 4 * grid_len(model) as u64)?;
    }
    fits_dispatch(gpu, nodes.max(contacts))
}

/// Refuse self-contact in fixed-point mode, whose scatter has no pair term.
///
/// # Errors
/// [`BackendError::Unsupported`] naming the mode and the way out.
pub(crate) fn refuse_self_contact(mode: Mode, params: &yarn_model::Params) -> Result<(), BackendError> {
    if mode == Mode::FixedPointAtomic && params.self_contact_stiffness > 0.0 {
        return Err(BackendError::Unsupported {
            backend: "wgpu-fixed",
            feature: "self-contact",
            remedy: "use `Mode::Gather` (the default), or set `self_contact_stiffness` to 0",
        });
    }
    Ok(())
}

/// Entries of the self-contact grid of `model` (`grid.wgsl`).
pub(crate) fn grid_len(model: &Model<f32>) -> usize {
    4 + 2 * GridShape::new(model).buckets() + model.node_count() + MAX_LONG as usize
}

/// Check that a buffer of `bytes` fits one binding.
fn fits_binding(gpu: &Gpu, what: &'static str, bytes: u64) -> Result<(), BackendError> {
    let limits = &gpu.limits;
    let (limit, limit_name) = if limits.max_storage_buffer_binding_size < limits.max_buffer_size {
        (limits.max_storage_buffer_binding_size, "max_storage_buffer_binding_size")
    } else {
        (limits.max_buffer_size, "max_buffer_size")
    };
    if bytes > limit { Err(BackendError::TooLarge { what, needed: bytes, limit, limit_name }) } else { Ok(()) }
}

/// Check that `threads` fit one dispatch.
fn fits_dispatch(gpu: &Gpu, threads: usize) -> Result<(), BackendError> {
    if u32::try_from(threads).ok().and_then(|t| gpu.groups(t)).is_some() {
        return Ok(());
    }
    let max = u64::from(gpu.limits.max_compute_workgroups_per_dimension);
    Err(BackendError::TooLarge {
        what: "the dispatch (threads)",
        needed: threads as u64,
        limit: max * max * u64::from(WORKGROUP),
        limit_name: "max_compute_workgroups_per_dimension",
    })
}

/// The largest force component one fixed-point addition takes: half the
/// i32 range, so a node's sum of a few such terms is checked for wrapping.
pub(crate) fn max_force() -> f64 {
    f64::from(i32::MAX) / f64::from(FIXED_POINT_SCALE) / 2.0
}

/// Wait for the GPU, then report any error it raised.
pub(crate) fn finish(gpu: &Gpu) -> Result<(), BackendError> {
    gpu.device
        .poll(wgpu::PollType::Wait { submission_index: None, timeout: None })
        .map_err(|e| BackendError::Device(e.to_string()))?;
    gpu.take_error().map_err(BackendError::Device)
}

/// `vec4<f32>` bytes as vectors (w dropped).
pub(crate) fn vectors(bytes: &[u8]) -> Vec<V3<f32>> {
    bytemuck::pod_collect_to_vec::<u8, [f32; 4]>(bytes).iter().map(|v| V3::new(v[0], v[1], v[2])).collect()
}

impl GpuFabric {
    /// Upload `model` (checked by [`check_fits`]) at `state`.
    pub(crate) fn new(gpu: Arc<Gpu>, mode: Mode, fuse_below: usize, model: Model<f32>, state: State<f32>) -> Self {
        let buffers = Buffers::new(&gpu.device, &model, &state.positions, &state.velocities, FIRST_SLOTS);
        let groups = Groups::new(&gpu, mode, &buffers);
        let checkpoint = Checkpoint { substeps: 0, state };
        let mut fabric = Self {
            gpu,
            mode,
            fuse_below,
            model,
            buffers,
            groups,
            parity: Parity::default(),
            substeps: 0,
            checkpoint,
            saved: (Parity::default(), 0),
            timestamps: None,
            slots: FIRST_SLOTS,
            crowded: None,
            late: false,
            every_substep_until: 0,
            late_backoff: FIRST_LATE_BACKOFF,
            late_batches: 0,
            deferred_status: cfg!(target_arch = "wasm32"),
            raised_since: 0,
        };
        fabric.upload_pins();
        fabric
    }

    /// The buffer holding the current positions.
    pub(crate) fn positions(&self) -> &wgpu::Buffer {
        &self.buffers.x[self.parity.x]
    }

    pub(crate) fn gpu_params(&self) -> GpuParams {
        let c = self.model.coeffs();
        let model = &self.model;
        let surfaces = model.surfaces();
        let shape = GridShape::new(model);
        let radius = model.contact_rule().radius();
        let (rebuild_x, rebuild_y) = self.gpu.groups(model.node_count() as u32).unwrap_or((1, 1));
        let mut gpu_surfaces = [GpuSurface::default(); MAX_COLLIDERS];
        for (gpu, s) in gpu_surfaces.iter_mut().zip(surfaces) {
            *gpu = GpuSurface {
                normal: s.normal.into(),
                offset: s.offset,
                thickness: s.thickness,
                friction: s.friction,
                _pad: [0.0; 2],
            };
        }
        GpuParams {
            nodes: self.model.node_count() as u32,
            contacts: self.model.contacts().len() as u32,
            pins: self.buffers.pin_count,
            flags: if self.friction_on() { FRICTION_ON } else { 0 }
                | if self.gpu.fused_fma { FUSED_FMA } else { 0 }
                | if model.self_contact() { SELF_CONTACT } else { 0 }
                | if model.params().friction_in_tension { FRICTION_IN_TENSION } else { 0 },
            stretch: c.stretch,
            bend: c.bend,
            contact: c.contact,
            friction: c.friction,
            h: c.h,
            h_over_m: c.h_over_m,
            damping_factor: c.damping_factor,
            friction_impulse: c.friction_impulse,
            gravity_y: -c.mass * c.gravity,
            min_sin: yarn_model::terms::MIN_SIN_THETA as f32,
            scale: FIXED_POINT_SCALE,
            max_force: max_force() as f32,
            max_speed: self.model.divergence_speed() as f32,
            one: 1.0,
            reseat_step: self.model.reseat_step(),
            reseats: self.buffers.reseat_count,
            self_contact: c.self_contact,
            self_impulse: c.self_contact_impulse,
            reach: (2.0 * radius) as f32,
            radius: radius as f32,
            collider: c.collider,
            collider_impulse: c.collider_impulse,
            cell: shape.cell,
            search_reach: shape.reach,
            half_skin: (0.5 * model.params().self_contact_skin * radius) as f32,
            mask: shape.mask,
            slots: self.slots,
            colliders: surfaces.len() as u32,
            rebuild_x,
            rebuild_y,
            short: shape.short,
            // The browser cannot run a late batch again, so it checks for a
            // rebuild every substep, as soon as a node has moved half the skin.
            lookahead: if self.deferred_status { 0.0 } else { LOOKAHEAD * CADENCE as f32 * c.h },
            surfaces: gpu_surfaces,
        }
    }

    /// How many times the GPU has built the self-contact lists since
    /// self-contact was turned on (`plan.wgsl`'s generation), read back;
    /// `None` with it off, or in the browser, where nothing may wait.
    pub(crate) fn self_contact_builds(&self) -> Option<u64> {
        if !self.model.self_contact() || cfg!(target_arch = "wasm32") {
            return None;
        }
        let bytes = self.read(&self.buffers.grid, 8).ok()?;
        Some(u64::from(bytemuck::pod_read_unaligned::<u32>(&bytes[4..8])))
    }

    /// Have the next substep rebuild the self-contact lists: the positions,
    /// parameters or pins changed other than by a substep.
    pub(crate) fn mark_stale(&self) {
        if self.model.self_contact() {
            self.gpu.queue.write_buffer(&self.buffers.lists, 0, bytemuck::bytes_of(&1u32));
        }
    }

    /// Remake the self-contact buffers for the model as it is now, with
    /// self-contact just turned on or off, and rebind; the lists start
    /// stale.
    fn remake_touch(&mut self) {
        let device = &self.gpu.device;
        self.buffers.lists = storage(device, "lists", &lists(&self.model, self.slots));
        self.buffers.rule = storage(device, "rule", &rule(&self.model));
        self.buffers.grid = storage(device, "grid", &grid(&self.model));
        self.groups = Groups::new(&self.gpu, self.mode, &self.buffers);
        self.write_params();
    }

    pub(crate) fn write_params(&self) {
        self.gpu.queue.write_buffer(&self.buffers.params, 0, bytemuck::bytes_of(&self.gpu_params()));
    }

    /// Upload the model's pins and parameters, and rebind.
    fn upload_pins(&mut self) {
        let pins: Vec<GpuPin> = self
            .model
            .pins()
            .iter()
            .map(|&(node, target)| GpuPin { goal: [target.x, target.y, target.z], node })
            .collect();
        self.buffers.pin_count = pins.len() as u32;
        self.buffers.pins = storage(&self.gpu.device, "pins", &pins);
        if self.model.self_contact() {
            let row = 4 * rows::at(self.model.node_count(), 0, rows::PINNED) as u64;
            self.gpu.queue.write_buffer(&self.buffers.lists, row, bytemuck::cast_slice(&pinned(&self.model)));
        }
        self.groups = Groups::new(&self.gpu, self.mode, &self.buffers);
        self.write_params();
    }

    /// Upload the model's contact records, per-node lists and re-seated
    /// contacts, and rebind the reseat pass to its new buffer.
    pub(crate) fn upload_contacts(&mut self) {
        let queue = &self.gpu.queue;
        queue.write_buffer(&self.buffers.contacts, 0, bytemuck::cast_slice(&gpu_contacts(&self.model)));
        // Only alive contacts are listed per node, so a released contact
        // costs the gather nothing.
        let (start, incident, reseats) = incidence(&self.model);
        queue.write_buffer(&self.buffers.start, 0, bytemuck::cast_slice(&start));
        if !incident.is_empty() {
            queue.write_buffer(&self.buffers.incident, 0, bytemuck::cast_slice(&incident));
        }
        self.buffers.reseat_count = reseats.len() as u32;
        self.buffers.reseats = storage(&self.gpu.device, "reseats", &reseats);
        self.groups.reseat = reseat_group(&self.gpu, &self.buffers);
        self.write_params();
    }

    pub(crate) fn set_params(&mut self, params: &yarn_model::Params) -> Result<(), BackendError> {
        refuse_self_contact(self.mode, params)?;
        let touching = self.model.self_contact();
        let mut model = self.model.clone();
        model.set_params(params)?;
        if model.self_contact() && !touching {
            check_fits(&self.gpu, &model)?;
        }
        self.model = model;
        if self.model.self_contact() == touching {
            self.write_params();
            self.mark_stale();
        } else {
            self.slots = FIRST_SLOTS;
            self.remake_touch();
        }
        self.gpu.queue.write_buffer(&self.buffers.chain, 0, bytemuck::cast_slice(&chain(&self.model)));
        Ok(())
    }

    pub(crate) fn set_colliders(&mut self, colliders: &[yarn_model::Collider]) -> Result<(), BackendError> {
        if colliders.len() > MAX_COLLIDERS {
            return Err(BackendError::Unsupported {
                backend: "wgpu",
                feature: "more than 8 colliders",
                remedy: "set at most 8",
            });
        }
        self.model.set_colliders(colliders)?;
        self.write_params();
        Ok(())
    }

    pub(crate) fn set_pins(&mut self, pins: &[yarn_topology::Pin]) -> Result<(), BackendError> {
        self.model.set_pins(pins)?;
        self.upload_pins();
        self.mark_stale();
        Ok(())
    }

    /// As the trait says. Reviving a contact reads the positions back,
    /// which the browser cannot do while waiting: there it is an error.
    pub(crate) fn set_contacts_alive(&mut self, alive: &[bool]) -> Result<(), BackendError> {
        let mut positions = Vec::new();
        if self.model.revives(alive) && alive.len() == self.model.contacts().len() {
            self.read_vectors(self.positions(), self.model.node_count(), &mut positions)?;
        }
        self.model.set_contacts_alive(alive, &positions)?;
        self.upload_contacts();
        Ok(())
    }

    pub(crate) fn write_state(&mut self, state: &State<f32>) -> Result<(), BackendError> {
        state.check_len(self.model.node_count())?;
        self.model.check_apart(&state.positions)?;
        let queue = &self.gpu.queue;
        queue.write_buffer(&self.buffers.x[self.parity.x], 0, bytemuck::cast_slice(&vec4s(&state.positions)));
        queue.write_buffer(&self.buffers.v[self.parity.v], 0, bytemuck::cast_slice(&vec4s(&state.velocities)));
        self.checkpoint = Checkpoint { substeps: self.substeps, state: state.clone() };
        self.mark_stale();
        Ok(())
    }

    /// As the trait says; the state read is also kept as the
    /// [`crate::Wgpu::last_good_state`].
    pub(crate) fn read_state(&mut self, state: &mut State<f32>) -> Result<(), BackendError> {
        let n = self.model.node_count();
        self.read_vectors(&self.buffers.x[self.parity.x], n, &mut state.positions)?;
        self.read_vectors(&self.buffers.v[self.parity.v], n, &mut state.velocities)?;
        self.checkpoint = Checkpoint { substeps: self.substeps, state: state.clone() };
        Ok(())
    }

    pub(crate) fn compute_forces(&mut self, forces: &mut Vec<V3<f32>>) -> Result<(), BackendError> {
        self.run_again_when_put_back(|fabric| fabric.forces_once(forces))
    }

    /// [`Self::compute_forces`] with the lists as they are: rebuilt first,
    /// since the positions may have been written since the last substep.
    fn forces_once(&mut self, forces: &mut Vec<V3<f32>>) -> Result<(), BackendError> {
        let n = self.model.node_count();
        self.mark_stale();
        let kernel = forces_kernel(self.mode, self.model.self_contact(), &self.gpu.pipelines, &self.buffers);
        let group = self.groups.forces_only.at(self.parity);
        let workgroups = |threads: usize| self.gpu.groups(threads as u32).unwrap_or((1, 1));
        let mut encoder = self.gpu.device.create_command_encoder(&Default::default());
        {
            let mut pass = encoder.begin_compute_pass(&Default::default());
            self.list_plan(self.parity, true, &mut |d| d.record(&mut pass));
            let dispatch = |pipeline, threads| Dispatch {
                pass: "",
                stages: &[],
                pipeline,
                group,
                workgroups: workgroups(threads),
                indirect: None,
            };
            if let Some(scatter) = kernel.scatter {
                dispatch(scatter, n.max(self.model.contacts().len())).record(&mut pass);
            }
            Dispatch { workgroups: self.forces_workgroups(), ..dispatch(kernel.forces, n) }.record(&mut pass);
        }
        self.record_status(&mut encoder);
        self.gpu.queue.submit([encoder.finish()]);
        self.check_status(self.substeps, self.substeps)?;
        self.read_vectors(&self.buffers.forces, n, forces)
    }

    pub(crate) fn advance(&mut self, substeps: u64) -> Result<(), BackendError> {
        self.run_again_when_put_back(|fabric| advance_with_rollback(fabric, substeps))
    }

    /// Run `work`; when it fails (the state already put back) because a
    /// segment had more self-contact candidates than its list holds,
    /// double the slots until they hold them, remake the lists and run it
    /// again; when it fails because it was late to rebuild the lists, run
    /// it again with a rebuild check every substep.
    ///
    /// # Errors
    /// `work`'s, or [`BackendError::TooLarge`] naming the binding limit
    /// when lists that large do not fit the device.
    fn run_again_when_put_back<R>(
        &mut self,
        mut work: impl FnMut(&mut Self) -> Result<R, BackendError>,
    ) -> Result<R, BackendError> {
        loop {
            let result = work(self);
            if let Some(needed) = self.crowded.take() {
                self.grow_lists(needed)?;
            } else if std::mem::take(&mut self.late) {
                self.late_batches += 1;
                self.every_substep_until = self.substeps + self.late_backoff;
                self.late_backoff *= 2;
            } else {
                return result;
            }
        }
    }

    /// How many substeps of the batch starting now may rebuild the
    /// self-contact lists: one in every [`CADENCE`], or every one in the
    /// browser (which cannot run a late batch again) and after a late one.
    fn cadence(&self) -> u64 {
        if self.deferred_status || self.substeps < self.every_substep_until { 1 } else { CADENCE }
    }

    /// Make the candidate lists hold at least `needed` candidates a
    /// segment: double the slots, or more, and remake the lists stale;
    /// nothing when they already hold that many.
    ///
    /// # Errors
    /// [`BackendError::TooLarge`] naming the binding limit when lists that
    /// large do not fit the device; the lists are then kept.
    pub(crate) fn grow_lists(&mut self, needed: u32) -> Result<(), BackendError> {
        if needed <= self.slots {
            return Ok(());
        }
        let slots = needed.next_power_of_two().max(2 * self.slots);
        fits_binding(
            &self.gpu,
            "the self-contact candidate lists (bytes)",
            lists_bytes(self.model.node_count(), slots),
        )?;
        self.slots = slots;
        // New lists start stale; the grid and its rebuild count stay.
        self.buffers.lists = storage(&self.gpu.device, "lists", &lists(&self.model, slots));
        self.groups = Groups::new(&self.gpu, self.mode, &self.buffers);
        self.write_params();
        Ok(())
    }

    /// Copy `bytes` of `buffer` back to the CPU, waiting for the device.
    /// In the browser nothing may wait: use [`crate::Wgpu::read_positions`].
    pub(crate) fn read(&self, buffer: &wgpu::Buffer, bytes: u64) -> Result<Vec<u8>, BackendError> {
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
    pub(crate) fn read_async(
        &self,
        buffer: &wgpu::Buffer,
        bytes: u64,
    ) -> impl std::future::Future<Output = Result<Vec<u8>, BackendError>> + 'static {
        self.read_async_then(buffer, bytes, |_| ())
    }

    /// [`Self::read_async`], with `then` recorded after the copy in the
    /// same submission.
    fn read_async_then(
        &self,
        buffer: &wgpu::Buffer,
        bytes: u64,
        then: impl FnOnce(&mut wgpu::CommandEncoder),
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
        then(&mut encoder);
        self.gpu.queue.submit([encoder.finish()]);
        let gpu = Arc::clone(&self.gpu);
        async move {
            let bytes = read_mapped(&gpu.device, &staging).await.map_err(BackendError::Device)?;
            gpu.take_error().map_err(BackendError::Device)?;
            Ok(bytes)
        }
    }

    /// Take the deferred status without waiting: copy it back and clear it
    /// in one submission. The future borrows nothing.
    pub(crate) fn read_raised(&mut self) -> impl std::future::Future<Output = Result<Raised, BackendError>> + 'static {
        let (first, end) = (self.raised_since, self.substeps);
        self.raised_since = end;
        let status = &self.buffers.status;
        let bytes = self.read_async_then(status, 16, |encoder| encoder.clear_buffer(status, 0, None));
        async move { Ok(Raised::from_status(&bytes.await?, first, end)) }
    }

    /// Read a node buffer of `vec4<f32>` as vectors.
    fn read_vectors(&self, buffer: &wgpu::Buffer, nodes: usize, out: &mut Vec<V3<f32>>) -> Result<(), BackendError> {
        let bytes = self.read(buffer, (nodes * 16) as u64)?;
        *out = vectors(&bytes);
        Ok(())
    }

    /// End a submission by copying the status to its mappable twin and
    /// clearing it for the next; a deferred status stays where it is.
    pub(crate) fn record_status(&self, encoder: &mut wgpu::CommandEncoder) {
        if self.deferred_status {
            return;
        }
        encoder.copy_buffer_to_buffer(&self.buffers.status, 0, &self.buffers.status_readback, 0, 16);
        encoder.clear_buffer(&self.buffers.status, 0, None);
    }

    /// Wait for the GPU, then read the status the batch of substeps
    /// `first..end` raised (copied by [`Self::record_status`], so this is
    /// the only wait): a fixed-point overflow, or a diverged state, which
    /// the read-back state then names. A deferred status, which nothing
    /// waits for, reports only device errors here and the rest through
    /// [`crate::Wgpu::read_raised`].
    fn check_status(&mut self, first: u64, end: u64) -> Result<(), BackendError> {
        if self.deferred_status {
            return finish(&self.gpu);
        }
        let status = pollster::block_on(read_mapped(&self.gpu.device, &self.buffers.status_readback))
            .map_err(BackendError::Device)?;
        self.gpu.take_error().map_err(BackendError::Device)?;
        let raised = Raised::from_status(&status, first, end);
        let late = bytemuck::pod_read_unaligned::<u32>(&status[..4]) & LATE_REBUILD != 0;
        if raised.is_clear() && !late {
            return Ok(());
        }
        // Whatever else a late batch raised may have come of its lists.
        if late {
            self.late = true;
            return Err(BackendError::Device(format!(
                "substeps {first}..{end} used self-contact lists a node had moved half the skin from; \
                 they run again with a rebuild check every substep"
            )));
        }
        if raised.overflowed {
            return Err(BackendError::Overflow { first, end, max_force: max_force() });
        }
        if raised.overstretched {
            return Err(BackendError::Overstretched { first, end });
        }
        if let Some(crowd) = raised.crowded {
            self.crowded = Some(crowd);
            return Err(BackendError::TooLarge {
                what: "self-contact candidates near one segment",
                needed: u64::from(crowd),
                limit: u64::from(self.slots),
                limit_name: "the slots per candidate list",
            });
        }
        let limit = self.model.divergence_speed();
        let n = self.model.node_count();
        let mut state = State { positions: Vec::new(), velocities: Vec::new() };
        self.read_vectors(&self.buffers.x[self.parity.x], n, &mut state.positions)?;
        self.read_vectors(&self.buffers.v[self.parity.v], n, &mut state.velocities)?;
        let (node, speed) = state.first_diverged(f64::from(limit as f32)).unwrap_or((0, f64::NAN));
        Err(BackendError::Diverged { substep: end, node, speed, limit })
    }
}

impl Raised {
    /// The status words the batches of substeps `first..end` left
    /// (`status[0]`'s bits, `status[1]` the crowd), as flags.
    fn from_status(status: &[u8], first: u64, end: u64) -> Self {
        let [bits, crowd]: [u32; 2] = bytemuck::pod_read_unaligned(&status[..8]);
        Self {
            first,
            end,
            overflowed: bits & OVERFLOWED != 0,
            diverged: bits & DIVERGED != 0,
            overstretched: bits & STRETCHED != 0,
            crowded: (bits & CROWDED != 0).then_some(crowd),
        }
    }
}

/// A batch is one submission: the snapshot copies, every substep's
/// dispatches, the divergence check and the status copy, then one wait.
impl Rollback for GpuFabric {
    type Real = f32;

    fn model_mut(&mut self) -> &mut Model<f32> {
        &mut self.model
    }

    /// The GPU copies the state into its snapshot buffers at the start of
    /// the batch's own submission ([`Rollback::run`]), so saving costs no
    /// submission of its own; here only the parity and count are kept.
    fn save(&mut self) {
        self.saved = (self.parity, self.substeps);
    }

    fn run(&mut self, substeps: u64) -> Result<(), BackendError> {
        let first = self.substeps;
        // The host's model closes the re-seated contacts as the GPU will,
        // which says for how many substeps the reseat pass is needed.
        let closing = self.model.close_reseats(substeps, |_, _| ());
        let fuse = self.fuses() && self.timestamps.is_none();
        let cadence = self.cadence();
        let mut encoder = self.gpu.device.create_command_encoder(&Default::default());
        // A batch can fail part way: keep the state it started from.
        let [saved_x, saved_v] = &self.buffers.snapshot;
        encoder.copy_buffer_to_buffer(&self.buffers.x[self.parity.x], 0, saved_x, 0, saved_x.size());
        encoder.copy_buffer_to_buffer(&self.buffers.v[self.parity.v], 0, saved_v, 0, saved_v.size());
        let mut parity = self.parity;
        match self.timestamps.take() {
            None => {
                let mut pass = encoder.begin_compute_pass(&Default::default());
                for s in 0..substeps {
                    parity =
                        self.substep_plan(parity, fuse, s < closing, s % cadence == 0, &mut |d| d.record(&mut pass));
                }
                self.check_dispatch(parity).record(&mut pass);
            }
            Some(mut timestamps) => {
                for s in 0..substeps {
                    parity = self.substep_plan(parity, false, s < closing, s % cadence == 0, &mut |d| {
                        timestamps.record(&self.gpu, &mut encoder, d)
                    });
                }
                timestamps.record(&self.gpu, &mut encoder, &self.check_dispatch(parity));
                timestamps.resolve(&self.gpu.device, &mut encoder);
                self.timestamps = Some(timestamps);
            }
        }
        self.record_status(&mut encoder);
        self.gpu.queue.submit([encoder.finish()]);
        self.parity = parity;
        self.substeps += substeps;
        self.check_status(first, self.substeps)?;
        if cadence > 1 {
            self.late_backoff = FIRST_LATE_BACKOFF;
        }
        Ok(())
    }

    fn restore(&mut self) -> Result<(), BackendError> {
        let (parity, substeps) = self.saved;
        let [saved_x, saved_v] = &self.buffers.snapshot;
        let mut encoder = self.gpu.device.create_command_encoder(&Default::default());
        encoder.copy_buffer_to_buffer(saved_x, 0, &self.buffers.x[parity.x], 0, saved_x.size());
        encoder.copy_buffer_to_buffer(saved_v, 0, &self.buffers.v[parity.v], 0, saved_v.size());
        self.gpu.queue.submit([encoder.finish()]);
        (self.parity, self.substeps) = (parity, substeps);
        // The GPU's copies of re-seated rests moved on with the batch, and
        // its lists were built for states put back.
        if !self.model.reseating().is_empty() {
            self.upload_contacts();
        }
        self.mark_stale();
        finish(&self.gpu)
    }
}
