//! A fabric loaded on the CPU, behind [`Serial`](crate::Serial) and
//! [`Rayon`](crate::Rayon): the host model, the state by component, and
//! what the passes reuse, so stepping allocates nothing.
//!
//! Its rooms: `field.rs` (the storage layout), `contacts.rs` (the live
//! contact lists), `sleep.rs` (which blocks sleep), `passes.rs` (the
//! substep's passes and their arithmetic), `chain.rs` (where yarns end or
//! wrap, and the force there), `touching.rs` (self-contact and colliders)
//! and `rollback.rs` (putting a failed advance back). This file ties them together and owns the order
//! of a substep's bookkeeping around the passes.

/// Run one pass: the same `body` over a sequential or a parallel iterator.
macro_rules! run_pass {
    ($exec:expr, $sequential:expr, $parallel:expr, $min_len:expr, $body:expr) => {
        match $exec {
            crate::fabric::Exec::Sequential => $sequential.for_each($body),
            crate::fabric::Exec::Parallel => {
                use rayon::prelude::*;
                $parallel.with_min_len($min_len).for_each($body)
            }
        }
    };
}

mod chain;
mod contacts;
mod field;
mod passes;
mod rollback;
mod sleep;
mod touching;

use std::sync::Mutex;
use std::sync::atomic::AtomicBool;
use std::time::Instant;

use yarn_model::stages::{self, Stage, StageClock, StageTimes};
use yarn_model::{BackendError, Model, Params, Real, State, advance_with_rollback};
use yarn_topology::{Fabric, Pin};

use contacts::LiveContacts;
use field::Field;
pub(crate) use passes::Exec;
use passes::Scratch;
use sleep::{SLEEP_CHECK, Sleep};
use touching::SelfContacts;

const RESEAT: &[Stage] = &[Stage::Reseat];
const SLEEP: &[Stage] = &[Stage::Sleep];

/// A loaded fabric on the CPU.
#[derive(Debug)]
pub(crate) struct CpuFabric<T: Real> {
    model: Model<T>,
    positions: Field<T>,
    velocities: Field<T>,
    /// Without friction, the forces and the move share a pass, which writes
    /// the new positions here while other blocks still read the old ones.
    next_positions: Field<T>,
    /// κθ0 of the joint centred on each node (zero where none), refreshed
    /// with the parameters.
    target: Vec<T>,
    /// The nodes the block pass computes from their links
    /// ([`chain::breaks`]), ascending.
    breaks: Vec<u32>,
    contacts: LiveContacts<T>,
    /// The self-contact candidate list and its per-pair buffers.
    touching: SelfContacts<T>,
    sleep: Sleep,
    /// One scratch per thread that may run blocks, by rayon thread index;
    /// each is locked only by its own thread.
    scratch: Vec<Mutex<Scratch<T>>>,
    exec: Exec,
    /// Substeps completed since load.
    substeps: u64,
    /// Set by a block whose velocity, after friction, passed the divergence
    /// speed (or is not finite) in the last substep.
    diverged: AtomicBool,
    /// The state at the start of the current `advance`, to put back if it
    /// diverges.
    saved: [Field<T>; 2],
    /// The stage counters, on only inside [`CpuFabric::advance_timed`].
    clock: Option<StageClock>,
}

impl<T: Real> CpuFabric<T> {
    /// Load `fabric` at rest, to run with `threads` threads as `exec` says.
    pub(crate) fn new(fabric: &Fabric, params: &Params, exec: Exec, threads: usize) -> Result<Self, BackendError> {
        let model = Model::<T>::new(fabric, params)?;
        let n = model.node_count();
        let state = State::<T>::at_rest(fabric);
        model.check_apart(&state.positions)?;
        let mut loaded = Self {
            positions: Field::from_vectors(&state.positions),
            velocities: Field::from_vectors(&state.velocities),
            next_positions: Field::zeros(n),
            target: Vec::new(),
            breaks: chain::breaks(&model),
            contacts: LiveContacts::default(),
            touching: SelfContacts::default(),
            sleep: Sleep::new(&model),
            scratch: (0..threads.max(1)).map(|_| Mutex::new(Scratch::new())).collect(),
            exec,
            substeps: 0,
            diverged: AtomicBool::new(false),
            saved: [Field::zeros(n), Field::zeros(n)],
            clock: None,
            model,
        };
        loaded.refresh_targets();
        loaded.refresh_contacts();
        Ok(loaded)
    }

    /// The host model.
    pub(crate) fn model(&self) -> &Model<T> {
        &self.model
    }

    /// Rebuild the live contact lists: the alive contacts with a node in an
    /// awake block.
    fn refresh_contacts(&mut self) {
        self.contacts.refresh(&self.model, self.sleep.asleep());
    }

    fn refresh_targets(&mut self) {
        let kappa = self.model.coeffs().rest_curl;
        self.target = self.model.joint_rest().iter().map(|&theta0| kappa * theta0).collect();
    }

    pub(crate) fn set_params(&mut self, params: &Params) -> Result<(), BackendError> {
        self.model.set_params(params)?;
        self.refresh_targets();
        self.wake_all();
        Ok(())
    }

    pub(crate) fn set_pins(&mut self, pins: &[Pin]) -> Result<(), BackendError> {
        self.model.set_pins(pins)?;
        self.wake_all();
        Ok(())
    }

    pub(crate) fn set_colliders(&mut self, colliders: &[yarn_model::Collider]) -> Result<(), BackendError> {
        self.model.set_colliders(colliders)?;
        self.wake_all();
        Ok(())
    }

    /// How many times the self-contact candidate list has been built.
    pub(crate) fn self_contact_builds(&self) -> u64 {
        self.touching.builds()
    }

    pub(crate) fn set_contacts_alive(&mut self, alive: &[bool]) -> Result<(), BackendError> {
        let mut positions = Vec::new();
        if self.model.revives(alive) {
            self.positions.to_vectors(&mut positions);
        }
        self.model.set_contacts_alive(alive, &positions)?;
        self.sleep.wake_all();
        self.refresh_contacts();
        Ok(())
    }

    pub(crate) fn write_state(&mut self, state: &State<T>) -> Result<(), BackendError> {
        state.check_len(self.model.node_count())?;
        self.model.check_apart(&state.positions)?;
        self.positions = Field::from_vectors(&state.positions);
        self.velocities = Field::from_vectors(&state.velocities);
        self.wake_all();
        Ok(())
    }

    pub(crate) fn read_state(&self, state: &mut State<T>) {
        self.positions.to_vectors(&mut state.positions);
        self.velocities.to_vectors(&mut state.velocities);
    }

    /// Wake every sleeping block.
    fn wake_all(&mut self) {
        if self.sleep.wake_all() {
            self.refresh_contacts();
        }
    }

    /// Blocks asleep now, for tests and reports.
    pub(crate) fn sleeping_blocks(&self) -> usize {
        self.sleep.sleeping_blocks()
    }

    /// Advance `substeps` substeps. A substep whose damped velocities pass
    /// the model's divergence speed, or turn non-finite, ends the call with
    /// [`BackendError::Diverged`], the state put back as it was before it.
    pub(crate) fn advance(&mut self, substeps: u64) -> Result<(), BackendError> {
        advance_with_rollback(self, substeps)
    }

    /// [`CpuFabric::advance`] with the stage counters on.
    pub(crate) fn advance_timed(&mut self, substeps: u64) -> Result<StageTimes, BackendError> {
        self.clock = Some(StageClock::default());
        let started = Instant::now();
        let result = self.advance(substeps);
        let wall_seconds = started.elapsed().as_secs_f64();
        let clock = self.clock.take().unwrap_or_default();
        result.map(|()| clock.report(substeps, wall_seconds))
    }

    /// The bookkeeping after each substep's passes: close the re-seated
    /// contacts and, every [`SLEEP_CHECK`] substeps, update which blocks
    /// sleep. `done` counts the substeps of this advance.
    fn after_substep(&mut self, done: u64) {
        let started = stages::start(&self.clock);
        let contacts = &mut self.contacts;
        self.model.close_reseats(1, |contact, rest| contacts.set_rest(contact, rest));
        stages::stop(&mut self.clock, "reseat", RESEAT, started);
        if (self.substeps + done).is_multiple_of(SLEEP_CHECK) {
            let started = stages::start(&self.clock);
            let limit = self.model.params().sleep_speed;
            if self.sleep.update(
                limit,
                self.model.pins(),
                &self.positions,
                &mut self.velocities,
                &mut self.next_positions,
            ) {
                self.refresh_contacts();
            }
            stages::stop(&mut self.clock, "sleep", SLEEP, started);
        }
    }
}
