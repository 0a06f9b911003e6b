//! `Simulation`: a backend, the fabric it runs and the parameters, for users
//! who just want to run. Energy is evaluated here, in `f64`, from the state
//! the backend reports, so every backend is measured by the same ruler.

use yarn_topology::{Fabric, Pin};

use crate::{Backend, BackendError, Energy, Model, Params, State, step};

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
    /// The scene in f64 (parameters, pins, liveness), kept in step with the
    /// backend so energy can be measured outside it.
    scene: Model<f64>,
    substeps: u64,
}

impl<B: Backend> Simulation<B> {
    /// Load `fabric` into `backend` under `params`.
    ///
    /// # Errors
    /// [`BackendError::Params`] if `params` do not validate.
    pub fn new(mut backend: B, fabric: Fabric, params: Params) -> Result<Self, BackendError> {
        let scene = Model::new(&fabric, &params)?;
        backend.load(&fabric, &params)?;
        Ok(Self { backend, fabric, scene, substeps: 0 })
    }

    /// Advance by `substeps` substeps.
    ///
    /// # Errors
    /// Whatever the backend reports.
    pub fn advance(&mut self, substeps: u64) -> Result<(), BackendError> {
        self.backend.advance(substeps)?;
        self.scene.close_reseats(substeps, |_, _| ());
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

    /// Energy of the current state by term, evaluated in `f64`.
    ///
    /// # Errors
    /// Whatever the backend reports when reading the state.
    pub fn energy(&mut self) -> Result<Energy, BackendError> {
        let state = self.backend.state()?.cast::<f64>();
        Ok(step::energy(&self.scene, &state))
    }

    /// Replace the parameters.
    ///
    /// # Errors
    /// [`BackendError::Params`]; nothing changes then.
    pub fn set_params(&mut self, params: Params) -> Result<(), BackendError> {
        self.scene.set_params(&params)?;
        self.backend.set_params(&params)
    }

    /// Replace the pins.
    ///
    /// # Errors
    /// [`BackendError::Topology`] for a bad pin; nothing changes then.
    pub fn set_pins(&mut self, pins: &[Pin]) -> Result<(), BackendError> {
        self.scene.set_pins(pins)?;
        self.backend.set_pins(pins)
    }

    /// Set the liveness of every contact. A contact revived away from its
    /// rest separation is re-seated and moves back ([`crate::Reseat`]).
    ///
    /// # Errors
    /// [`BackendError::LengthMismatch`]; nothing changes then. Whatever the
    /// backend reports when reading the state.
    pub fn set_contacts_alive(&mut self, alive: &[bool]) -> Result<(), BackendError> {
        let positions =
            if self.scene.revives(alive) { self.backend.state()?.cast::<f64>().positions } else { Vec::new() };
        let mut scene = self.scene.clone();
        scene.set_contacts_alive(alive, &positions)?;
        self.backend.set_contacts_alive(alive)?;
        self.scene = scene;
        Ok(())
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

    /// The parameters in force.
    pub fn params(&self) -> &Params {
        self.scene.params()
    }

    /// The backend, for calls the simulation does not wrap.
    pub fn backend_mut(&mut self) -> &mut B {
        &mut self.backend
    }
}
