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
//! re-seated contacts one more while any is closing (`reseat.wgsl`);
//! `record.rs` lists a substep's dispatches in one place.
//! [`Backend::advance`] records all `n` substeps into one submission and
//! reads nothing back; state is copied back only when asked. It waits for
//! the GPU to finish, so errors and timings belong to the call that caused
//! them.
//!
//! The shaders round every product, square root and quotient as the CPU
//! does (`mul`, `sqrt_rounded`, `div_rounded` in `common.wgsl`), so gather
//! mode reproduces `Serial<f32>` bit for bit where the GPU's `fma` is exact.
//!
//! Only WebGPU's core features are used by a substep, so the same shaders
//! run in a browser; the stage counters
//! ([`Backend::advance_timed`]) use timestamp queries where the adapter
//! has them (`timing.rs`).
//!
//! The rooms: `gpu.rs` (the device and its pipelines), `bindings.rs` (a
//! fabric's buffers and bind groups), `fabric.rs` (a loaded fabric and
//! every operation on it, with the rollback), `record.rs` (what a substep
//! dispatches), `timing.rs` (the stage counters), `layout.rs` (the Rust
//! mirrors of the WGSL structs) and `shaders.rs` (the WGSL sources). This
//! file is the [`Backend`] and forwards to the loaded fabric. The crate owns how the GPU executes the model, never what the
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

mod bindings;
mod fabric;
mod gpu;
mod layout;
mod record;
pub mod shaders;
#[cfg(not(target_arch = "wasm32"))]
pub mod testing;
mod timing;
#[cfg(test)]
mod touch_tests;

use std::sync::Arc;

use fabric::{GpuFabric, check_fits, finish, vectors};
pub use gpu::{Gpu, GpuError, read_mapped};
pub use layout::MAX_COLLIDERS;
pub use wgpu;
use yarn_model::{Backend, BackendError, Model, Params, StageTimes, State, V3};
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

/// Gather mode with friction fuses the substep into one dispatch below this
/// many nodes, and runs the forces and the friction as two passes from it
/// up. Fusing saves a dispatch but recomputes each contact partner's v*,
/// with scattered reads; measured on an H200 (`yarn-gate bench --backend
/// wgpu`), one dispatch won at 2,048 nodes (9.9 against 11.5 µs a
/// substep), tied at 32,768, and lost from 1M nodes up (0.10 against 0.07
/// ns a node-substep at 1M, 0.09 against 0.06 at 4.2M).
pub const FUSE_BELOW: usize = 65_536;

/// The GPU backend, in `f32`.
#[derive(Debug)]
pub struct Wgpu {
    gpu: Arc<Gpu>,
    mode: Mode,
    fuse_below: usize,
    checkpoint_every: u64,
    /// Time stages with timestamp queries where the device has them.
    timestamps: bool,
    loaded: Option<GpuFabric>,
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

/// What the GPU raised over the substeps `first..end`, read by
/// [`Wgpu::read_raised`] in the browser, where [`Backend::advance`] cannot
/// wait for the GPU to say. Natively each is an error of the call that
/// raised it, with the state put back; here the substeps have run.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Raised {
    /// Substeps since load at the read before.
    pub first: u64,
    /// Substeps since load at this read.
    pub end: u64,
    /// A fixed-point force overflowed ([`BackendError::Overflow`]).
    pub overflowed: bool,
    /// A velocity passed the divergence speed ([`BackendError::Diverged`]).
    pub diverged: bool,
    /// Yarn stretched past what the self-contact search covers
    /// ([`BackendError::Overstretched`]).
    pub overstretched: bool,
    /// More self-contact candidates lay near one segment than its list
    /// holds: the most there were. Those substeps ran without the ones
    /// left over; [`Wgpu::grow_lists`] makes room.
    pub crowded: Option<u32>,
}

impl Raised {
    /// Nothing was raised.
    pub fn is_clear(&self) -> bool {
        !self.overflowed && !self.diverged && !self.overstretched && self.crowded.is_none()
    }
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
        Self { gpu, mode, fuse_below: FUSE_BELOW, checkpoint_every: 0, timestamps: true, loaded: None }
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
        self.loaded.as_ref().map(|loaded| &loaded.checkpoint)
    }

    /// Fuse gather mode's substep with friction into one dispatch only
    /// below `nodes` nodes (default [`FUSE_BELOW`]; 0 never fuses). The
    /// results are the same either way; only the speed differs.
    pub fn set_fuse_below(&mut self, nodes: usize) {
        self.fuse_below = nodes;
        if let Some(loaded) = &mut self.loaded {
            loaded.fuse_below = nodes;
        }
    }

    /// Time the stages of [`Backend::advance_timed`] with timestamp queries
    /// where the device has them (`true`, the default), or always by
    /// dispatching each pass alone and timing it by the wall clock
    /// (`false`), as on a device without them.
    pub fn set_timestamps(&mut self, use_them: bool) {
        self.timestamps = use_them;
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
        self.loaded.as_ref().map(GpuFabric::positions)
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
        let bytes = loaded.read_async(loaded.positions(), (loaded.model.node_count() * 16) as u64);
        Ok(async move { Ok(vectors(&bytes.await?)) })
    }

    /// What the GPU raised since the last read ([`Raised`]), taken without
    /// blocking: the copy back and the clear are submitted now, and the
    /// future borrows nothing. In the browser the batches leave their
    /// status on the GPU for this; natively [`Backend::advance`] waits for
    /// it and turns it into errors, so this reads clear.
    ///
    /// # Errors
    /// [`BackendError::NotLoaded`] before load; [`BackendError::Device`]
    /// when the device fails.
    pub fn read_raised(
        &mut self,
    ) -> Result<impl std::future::Future<Output = Result<Raised, BackendError>> + 'static, BackendError> {
        Ok(self.loaded()?.read_raised())
    }

    /// Make the self-contact candidate lists hold at least `needed`
    /// candidates a segment (nothing when they already do), as
    /// [`Backend::advance`] does on its own natively when a batch finds
    /// them crowded; for the browser, after [`Raised::crowded`]. Returns
    /// the slots each list now has.
    ///
    /// # Errors
    /// [`BackendError::NotLoaded`] before load; [`BackendError::TooLarge`]
    /// naming the binding limit when lists that long do not fit the
    /// device, with the lists kept.
    pub fn grow_lists(&mut self, needed: u32) -> Result<u32, BackendError> {
        let loaded = self.loaded()?;
        loaded.grow_lists(needed)?;
        Ok(loaded.slots)
    }

    /// Slots in each segment's self-contact candidate list; `None` before
    /// load.
    pub fn list_slots(&self) -> Option<u32> {
        self.loaded.as_ref().map(|loaded| loaded.slots)
    }

    fn loaded(&mut self) -> Result<&mut GpuFabric, BackendError> {
        self.loaded.as_mut().ok_or(BackendError::NotLoaded)
    }

    /// After an advance: copy the state back when a checkpoint is due.
    fn checkpoint_if_due(&mut self) -> Result<(), BackendError> {
        let every = self.checkpoint_every;
        let loaded = self.loaded()?;
        let due = every > 0 && loaded.substeps.saturating_sub(loaded.checkpoint.substeps) >= every;
        if due {
            self.state()?;
        }
        Ok(())
    }
}

impl Backend for Wgpu {
    type Real = f32;

    fn name(&self) -> String {
        format!("wgpu-{}", self.mode.name())
    }

    fn load(&mut self, fabric: &Fabric, params: &Params) -> Result<(), BackendError> {
        fabric::refuse_self_contact(self.mode, params)?;
        let model = Model::<f32>::new(fabric, params)?;
        check_fits(&self.gpu, &model)?;
        let state = State::at_rest(fabric);
        model.check_apart(&state.positions)?;
        // The fabric is accepted: free the previous one's buffers before
        // making the new ones, so the two never hold memory together.
        self.loaded = None;
        finish(&self.gpu)?;
        let loaded = GpuFabric::new(Arc::clone(&self.gpu), self.mode, self.fuse_below, model, state);
        self.loaded = Some(loaded);
        finish(&self.gpu)
    }

    fn set_params(&mut self, params: &Params) -> Result<(), BackendError> {
        self.loaded()?.set_params(params)
    }

    fn set_pins(&mut self, pins: &[Pin]) -> Result<(), BackendError> {
        self.loaded()?.set_pins(pins)
    }

    /// As the trait says. Reviving a contact reads the positions back,
    /// which the browser cannot do while waiting: there it is an error.
    fn set_contacts_alive(&mut self, alive: &[bool]) -> Result<(), BackendError> {
        self.loaded()?.set_contacts_alive(alive)
    }

    /// As the trait says; the GPU holds at most
    /// [`MAX_COLLIDERS`] (8), and more are
    /// [`BackendError::Unsupported`].
    fn set_colliders(&mut self, colliders: &[yarn_model::Collider]) -> Result<(), BackendError> {
        self.loaded()?.set_colliders(colliders)
    }

    fn write_state(&mut self, state: &State<f32>) -> Result<(), BackendError> {
        self.loaded()?.write_state(state)
    }

    /// As the trait says; the state read is also kept as the
    /// [`Wgpu::last_good_state`].
    fn read_state(&mut self, state: &mut State<f32>) -> Result<(), BackendError> {
        self.loaded()?.read_state(state)
    }

    fn compute_forces(&mut self, forces: &mut Vec<V3<f32>>) -> Result<(), BackendError> {
        self.loaded()?.compute_forces(forces)
    }

    fn advance(&mut self, substeps: u64) -> Result<(), BackendError> {
        self.loaded()?.advance(substeps)?;
        self.checkpoint_if_due()
    }

    /// As the trait says, counted by the GPU and read back; `None` in the
    /// browser.
    fn self_contact_builds(&self) -> Option<u64> {
        self.loaded.as_ref()?.self_contact_builds()
    }

    /// As the trait says: natively, only one substep in
    /// `CADENCE` (8) may rebuild the lists, and a batch that was late
    /// runs again checking every substep; `None` in the browser, which
    /// checks every substep.
    fn late_list_reruns(&self) -> Option<u64> {
        let loaded = self.loaded.as_ref()?;
        (loaded.model.self_contact() && !loaded.deferred_status).then_some(loaded.late_batches)
    }

    fn model(&self) -> Result<&Model<f32>, BackendError> {
        self.loaded.as_ref().map(|loaded| &loaded.model).ok_or(BackendError::NotLoaded)
    }

    /// As the trait says, by timestamp queries where the device has them
    /// ([`Wgpu::set_timestamps`]) or by per-pass timing runs; a substep
    /// that runs fused is timed as its unfused passes, and the report's
    /// note says so.
    fn advance_timed(&mut self, substeps: u64) -> Result<StageTimes, BackendError> {
        let timestamps = self.timestamps;
        let times = self.loaded()?.advance_timed(substeps, timestamps)?;
        self.checkpoint_if_due()?;
        Ok(times)
    }
}
