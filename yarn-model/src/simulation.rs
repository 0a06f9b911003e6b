//! `Simulation`: a backend and the fabric it runs, for users who just want
//! to run. The backend owns the model (parameters, pins, liveness); energy
//! is evaluated in `f64` from it and the state it reports
//! ([`Backend::measure`]), so every backend is measured by the same ruler.

use yarn_topology::{Fabric, Pin};

use crate::{Backend, BackendError, Energy, Params, State};

/// A fabric running on a backend.
///
/// ```
/// use yarn_model::{Params, Simulation};
/// use yarn_topology::{Chart, Fabric, Geometry};
/// # fn run<B: yarn_model::Backend>(backend: B) -> Result<(), Box<dyn std::error::Error>> {
/// let fabric = Fabric::from_chart(&Chart::stockinette(8, 8)?, &Geometry::default())?;
/// let mut sim = Simulation::new(backend, fabric, Params::default())?;
/// let before = sim.energy()?.total();
/// sim.advance(500)?;
/// assert!(sim.energy()?.total() < before);
/// # Ok(()) }
/// ```
#[derive(Debug)]
pub struct Simulation<B: Backend> {
    backend: B,
    fabric: Fabric,
    substeps: u64,
}

impl<B: Backend> Simulation<B> {
    /// Load `fabric` into `backend` under `params`.
    ///
    /// # Errors
    /// [`BackendError::Params`] if `params` do not validate.
    pub fn new(mut backend: B, fabric: Fabric, params: Params) -> Result<Self, BackendError> {
        backend.load(&fabric, &params)?;
        Ok(Self { backend, fabric, substeps: 0 })
    }

    /// Advance by `substeps` substeps.
    ///
    /// # Errors
    /// Whatever the backend reports.
    pub fn advance(&mut self, substeps: u64) -> Result<(), BackendError> {
        self.backend.advance(substeps)?;
        self.substeps += substeps;
        Ok(())
    }

    /// The current state, in the backend's precision.
    ///
    /// # Errors
    /// Whatever the backend reports.
    pub fn state(&mut self) -> Result<State<B::Real>, BackendError> {
        self.backend.state()
    }

    /// Energy of the current state by term, evaluated in `f64`
    /// ([`Backend::measure`]).
    ///
    /// # Errors
    /// Whatever the backend reports when reading the state.
    pub fn energy(&mut self) -> Result<Energy, BackendError> {
        Ok(self.backend.measure(&self.fabric)?.0)
    }

    /// Replace the parameters.
    ///
    /// # Errors
    /// [`BackendError::Params`]; nothing changes then.
    pub fn set_params(&mut self, params: Params) -> Result<(), BackendError> {
        self.backend.set_params(&params)
    }

    /// Replace the pins.
    ///
    /// # Errors
    /// [`BackendError::Topology`] for a bad pin; nothing changes then.
    pub fn set_pins(&mut self, pins: &[Pin]) -> Result<(), BackendError> {
        self.backend.set_pins(pins)
    }

    /// Set the liveness of every contact. A contact revived away from its
    /// rest separation is re-seated and moves back ([`crate::Reseat`]).
    ///
    /// # Errors
    /// [`BackendError::LengthMismatch`]; nothing changes then. Whatever the
    /// backend reports when reading the state.
    pub fn set_contacts_alive(&mut self, alive: &[bool]) -> Result<(), BackendError> {
        self.backend.set_contacts_alive(alive)
    }

    /// Overwrite positions and velocities.
    ///
    /// # Errors
    /// [`BackendError::LengthMismatch`].
    pub fn write_state(&mut self, state: &State<B::Real>) -> Result<(), BackendError> {
        self.backend.write_state(state)
    }

    /// Substeps taken since construction.
    pub fn substeps(&self) -> u64 {
        self.substeps
    }

    /// The fabric being simulated.
    pub fn fabric(&self) -> &Fabric {
        &self.fabric
    }

    /// The parameters in force: the backend's, which it changes only when
    /// it accepts new ones.
    ///
    /// # Errors
    /// [`BackendError::NotLoaded`] if the backend lost its fabric (a failed
    /// `load` through [`Simulation::backend_mut`]).
    pub fn params(&self) -> Result<&Params, BackendError> {
        Ok(self.backend.model()?.params())
    }

    /// The backend, for calls the simulation does not wrap.
    pub fn backend_mut(&mut self) -> &mut B {
        &mut self.backend
    }
}
