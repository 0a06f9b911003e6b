//! The contract every compute backend fulfils.

use yarn_topology::{Fabric, Pin, TopologyError};

use crate::stages::{Stage, StagePart, StageTimes, TimingMethod};
use crate::{Energy, Model, ParamError, Params, Real, State, V3, step};

/// Why a backend could not do what was asked. Each variant says what to fix.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum BackendError {
    /// The parameters did not validate.
    #[error(transparent)]
    Params(#[from] ParamError),
    /// A pin or fabric part was invalid.
    #[error(transparent)]
    Topology(#[from] TopologyError),
    /// A collider was invalid.
    #[error(transparent)]
    Collider(#[from] crate::ColliderError),
    /// An array has the wrong length for the loaded fabric.
    #[error("{what}: expected {expected} entries for the loaded fabric, got {got}")]
    LengthMismatch {
        /// Which array.
        what: &'static str,
        /// Length the loaded fabric needs.
        expected: usize,
        /// Length supplied.
        got: usize,
    },
    /// An operation that needs a fabric was called before [`Backend::load`].
    #[error("no fabric is loaded; call `load` first")]
    NotLoaded,
    /// The fabric needs more of a device resource than the device allows.
    #[error(
        "{what} needs {needed} but the device allows {limit} ({limit_name}); use a smaller fabric or a CPU backend"
    )]
    TooLarge {
        /// What does not fit, e.g. "node buffer (bytes)".
        what: &'static str,
        /// How much the fabric needs.
        needed: u64,
        /// The device's limit.
        limit: u64,
        /// The limit's name in the device API, to look up.
        limit_name: &'static str,
    },
    /// Fixed-point force accumulation overflowed: some force was too large
    /// to quantise. The state was restored to before the failing call.
    #[error(
        "fixed-point force overflow during substeps {first}..{end} (a force beyond ±{max_force:e}); \
         the state is as before this call: lower the stiffnesses or the substep, or use the gather mode"
    )]
    Overflow {
        /// First substep of the failing call (counted since load).
        first: u64,
        /// One past its last substep.
        end: u64,
        /// The largest force the fixed-point scale can hold.
        max_force: f64,
    },
    /// The simulation blew up: a node's position or velocity turned
    /// non-finite, or its speed passed [`crate::Model::divergence_speed`].
    /// The state is as it was before the failing call.
    #[error(
        "the simulation diverged at substep {substep}: node {node} reached speed {speed:e} (the limit is {limit:e}); \
         the state is as before this call: lower the substep, the stiffnesses or the applied pull"
    )]
    Diverged {
        /// The substep (counted since load) whose result was bad; a GPU
        /// names the last substep of the failing call.
        substep: u64,
        /// The first bad node.
        node: usize,
        /// Its speed (NaN if its state was not finite).
        speed: f64,
        /// The speed limit it passed.
        limit: f64,
    },
    /// Yarn stretched further than the self-contact search covers (the
    /// GPU's candidate grid, [`crate::self_contact::grid`]): past any
    /// physical state. The state is as it was before the failing call.
    #[error(
        "yarn stretched past what the self-contact search covers during substeps {first}..{end} (more than {} \
         segments at once past 1.5 times the longest rest segment, or one spanning more than {} grid cells); \
         the state is as before this call: lower the substep, the stiffnesses or the applied pull",
        crate::self_contact::grid::MAX_LONG,
        crate::self_contact::grid::MAX_BOX
    )]
    Overstretched {
        /// First substep of the failing call (counted since load).
        first: u64,
        /// One past its last substep.
        end: u64,
    },
    /// With self-contact on, the positions given have yarn already deep in
    /// yarn: two segments that may touch closer than
    /// [`crate::self_contact::MIN_START_RADII`] yarn radii.
    /// Self-contact would fling them apart, so the state is refused and the
    /// one before kept.
    #[error(
        "segments {a} and {b} are {distance:.2} r apart, closer than {} r: the yarn given already passes through \
         itself, and self-contact would fling it apart; separate them first, or turn self-contact off \
         (`self_contact_stiffness` 0)",
        crate::self_contact::MIN_START_RADII
    )]
    Interpenetrating {
        /// The segments, by their first nodes.
        a: u32,
        /// See `a`.
        b: u32,
        /// Their closest distance, in yarn radii.
        distance: f64,
    },
    /// The compute device reported an error or was lost.
    #[error("compute device error: {0}")]
    Device(String),
    /// The scene turns on a part of the model this backend does not run
    /// yet.
    #[error("the {backend} backend does not run {feature} yet; {remedy}, or use a CPU backend")]
    Unsupported {
        /// The backend.
        backend: &'static str,
        /// The part of the model.
        feature: &'static str,
        /// What turns it off, e.g. "set `self_contact_stiffness` to 0".
        remedy: &'static str,
    },
}

/// A compute backend: something that can hold a fabric and advance it by the
/// substep of SPEC §4.
///
/// ```
/// use yarn_model::{Backend, Params};
/// use yarn_topology::{Chart, Fabric, Geometry};
///
/// fn relax<B: Backend>(backend: &mut B) -> Result<f64, Box<dyn std::error::Error>> {
///     let fabric = Fabric::from_chart(&Chart::stockinette(4, 4)?, &Geometry::default())?;
///     backend.load(&fabric, &Params::default())?;
///     backend.advance(100)?;
///     Ok(backend.state()?.max_speed())
/// }
/// ```
///
/// ## Design
///
/// The trait is a handful of required primitives (load, parameters, pins,
/// colliders, contact liveness, state in and out, one force accumulation, and
/// `advance(n)`) because those are exactly what differ between a serial
/// loop, a thread pool and a GPU queue. Everything else (energy, metrics,
/// probes) is computed once, above the backend, from the state it returns.
///
/// The backend is the one owner of the host [`Model`]: it keeps it exact
/// (parameters, pins, liveness, the re-seated contacts closing as the
/// substeps run) and lends it out through [`Backend::model`], so a caller
/// never keeps a copy of its own that could drift. [`Backend::measure`]
/// evaluates energy from it in `f64`.
///
/// `advance` takes a substep count rather than being called per substep so
/// that a GPU backend can record n substeps into one submission with no
/// readback; reading state is a separate, explicit call for the same reason.
/// `compute_forces` exists for conformance: the force field after one
/// accumulation is the sharpest cross-backend check (SPEC §6).
///
/// Each backend computes in one precision, [`Backend::Real`]; the state
/// crosses the boundary in that precision so that comparisons see exactly
/// what the backend holds.
pub trait Backend {
    /// The scalar this backend computes in.
    type Real: Real;

    /// A short name for reports, e.g. `"serial-f32"`.
    fn name(&self) -> String;

    /// CPU threads the backend computes on, for reports.
    fn threads(&self) -> usize {
        1
    }

    /// Load a fabric: state at its assembled positions with zero velocity,
    /// its own pins, every contact alive.
    ///
    /// # Errors
    /// [`BackendError::Params`] if `params` do not validate.
    fn load(&mut self, fabric: &Fabric, params: &Params) -> Result<(), BackendError>;

    /// Replace the parameters.
    ///
    /// # Errors
    /// [`BackendError::Params`] if they do not validate, or
    /// [`BackendError::NotLoaded`].
    fn set_params(&mut self, params: &Params) -> Result<(), BackendError>;

    /// Replace the pins.
    ///
    /// # Errors
    /// [`BackendError::Topology`] for a bad pin, or [`BackendError::NotLoaded`].
    fn set_pins(&mut self, pins: &[Pin]) -> Result<(), BackendError>;

    /// Replace the colliders the fabric meets ([`crate::collider`]); a
    /// fabric loads with none.
    ///
    /// # Errors
    /// [`BackendError::Collider`] for a bad collider (the colliders are
    /// unchanged), or [`BackendError::NotLoaded`].
    fn set_colliders(&mut self, colliders: &[crate::Collider]) -> Result<(), BackendError>;

    /// Set the liveness of every contact, one flag per contact. A contact
    /// that comes alive away from its rest separation is re-seated at its
    /// length and moves back after every substep ([`crate::Reseat`],
    /// [`crate::Model::set_contacts_alive`]), so reviving adds no energy.
    ///
    /// # Errors
    /// [`BackendError::LengthMismatch`] or [`BackendError::NotLoaded`].
    fn set_contacts_alive(&mut self, alive: &[bool]) -> Result<(), BackendError>;

    /// Overwrite positions and velocities.
    ///
    /// # Errors
    /// [`BackendError::LengthMismatch`] or [`BackendError::NotLoaded`].
    fn write_state(&mut self, state: &State<Self::Real>) -> Result<(), BackendError>;

    /// Copy positions and velocities into `state`, resizing it.
    ///
    /// # Errors
    /// [`BackendError::NotLoaded`].
    fn read_state(&mut self, state: &mut State<Self::Real>) -> Result<(), BackendError>;

    /// F = −∇U at the current positions (SPEC §4 step 1), into `forces`,
    /// resized to the node count. The state does not change.
    ///
    /// # Errors
    /// [`BackendError::NotLoaded`].
    fn compute_forces(&mut self, forces: &mut Vec<V3<Self::Real>>) -> Result<(), BackendError>;

    /// Advance by `substeps` substeps of SPEC §4.
    ///
    /// # Errors
    /// [`BackendError::NotLoaded`].
    fn advance(&mut self, substeps: u64) -> Result<(), BackendError>;

    /// The host model of the loaded fabric: parameters, pins, liveness and
    /// rest values as this backend runs them.
    ///
    /// # Errors
    /// [`BackendError::NotLoaded`].
    fn model(&self) -> Result<&Model<Self::Real>, BackendError>;

    /// [`Backend::advance`], reporting where the substeps' time went, pass
    /// by pass ([`StageTimes`]). The state ends where `advance` would leave
    /// it. Timing costs only here: `advance` never reads a clock. This
    /// default times the whole call as one part; the backends in this
    /// workspace time each pass.
    ///
    /// # Errors
    /// As [`Backend::advance`].
    fn advance_timed(&mut self, substeps: u64) -> Result<StageTimes, BackendError> {
        let started = std::time::Instant::now();
        self.advance(substeps)?;
        let seconds = started.elapsed().as_secs_f64();
        Ok(StageTimes {
            substeps,
            method: TimingMethod::WallClock,
            parts: vec![StagePart {
                pass: "advance",
                stages: vec![Stage::Forces, Stage::Friction, Stage::Move, Stage::Pins, Stage::Reseat, Stage::Check],
                seconds,
            }],
            wall_seconds: seconds,
            note: None,
        })
    }

    /// The current state in `f64` and its energy by term, evaluated in
    /// `f64` against `fabric` (the fabric loaded) and this backend's model
    /// ([`Model::in_f64`]), so every backend is measured by the same ruler.
    ///
    /// # Errors
    /// [`BackendError::NotLoaded`], [`BackendError::LengthMismatch`] when
    /// `fabric` is not the one loaded, or a failure reading the state.
    fn measure(&mut self, fabric: &Fabric) -> Result<(Energy, State<f64>), BackendError> {
        let state = self.state()?.cast::<f64>();
        let ruler = self.model()?.in_f64(fabric)?;
        Ok((step::energy(&ruler, &state), state))
    }

    /// How many times the self-contact candidate lists have been built
    /// since load ([`crate::self_contact`]), for reports; `None` where the
    /// backend does not count them.
    fn self_contact_builds(&self) -> Option<u64> {
        None
    }

    /// How many batches of substeps were put back and run again since load
    /// because they used self-contact lists that some node had moved half
    /// the skin from (a backend that checks whether to rebuild the lists
    /// only every few substeps), for reports; `None` where the backend
    /// checks every substep.
    fn late_list_reruns(&self) -> Option<u64> {
        None
    }

    /// The current state, freshly allocated.
    ///
    /// # Errors
    /// As [`Backend::read_state`].
    fn state(&mut self) -> Result<State<Self::Real>, BackendError> {
        let mut state = State::default();
        self.read_state(&mut state)?;
        Ok(state)
    }

    /// The force field at the current positions, freshly allocated.
    ///
    /// # Errors
    /// As [`Backend::compute_forces`].
    fn forces(&mut self) -> Result<Vec<V3<Self::Real>>, BackendError> {
        let mut forces = Vec::new();
        self.compute_forces(&mut forces)?;
        Ok(forces)
    }
}
