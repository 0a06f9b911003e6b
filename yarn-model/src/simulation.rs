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

#[cfg(test)]
mod tests {
    use yarn_topology::{Chart, Geometry};

    use super::*;
    use crate::{Model, V3, step};

    /// A backend stricter than [`Params::validate`]: it refuses friction
    /// above 1, as a device might refuse what the model allows.
    #[derive(Debug, Default)]
    struct Picky {
        loaded: Option<(Model<f64>, State<f64>)>,
    }

    impl Picky {
        fn loaded(&mut self) -> Result<&mut (Model<f64>, State<f64>), BackendError> {
            self.loaded.as_mut().ok_or(BackendError::NotLoaded)
        }
    }

    impl Backend for Picky {
        type Real = f64;

        fn name(&self) -> String {
            "picky".into()
        }

        fn load(&mut self, fabric: &Fabric, params: &Params) -> Result<(), BackendError> {
            self.loaded = Some((Model::new(fabric, params)?, State::at_rest(fabric)));
            Ok(())
        }

        fn set_params(&mut self, params: &Params) -> Result<(), BackendError> {
            if params.friction > 1.0 {
                return Err(BackendError::Device("this device allows friction up to 1".into()));
            }
            self.loaded()?.0.set_params(params)
        }

        fn set_pins(&mut self, pins: &[Pin]) -> Result<(), BackendError> {
            self.loaded()?.0.set_pins(pins)
        }

        fn set_contacts_alive(&mut self, alive: &[bool]) -> Result<(), BackendError> {
            let (model, state) = self.loaded()?;
            model.set_contacts_alive(alive, &state.positions)
        }

        fn set_colliders(&mut self, colliders: &[crate::Collider]) -> Result<(), BackendError> {
            self.loaded()?.0.set_colliders(colliders)
        }

        fn write_state(&mut self, state: &State<f64>) -> Result<(), BackendError> {
            self.loaded()?.1.clone_from(state);
            Ok(())
        }

        fn read_state(&mut self, state: &mut State<f64>) -> Result<(), BackendError> {
            state.clone_from(&self.loaded()?.1);
            Ok(())
        }

        fn compute_forces(&mut self, forces: &mut Vec<V3<f64>>) -> Result<(), BackendError> {
            let (model, state) = self.loaded()?;
            step::accumulate_forces(model, &state.positions, forces);
            Ok(())
        }

        fn advance(&mut self, substeps: u64) -> Result<(), BackendError> {
            let (model, state) = self.loaded()?;
            let mut scratch = step::Scratch::default();
            for _ in 0..substeps {
                step::substep(model, state, &mut scratch);
                model.close_reseats(1, |_, _| ());
            }
            Ok(())
        }

        fn model(&self) -> Result<&Model<f64>, BackendError> {
            self.loaded.as_ref().map(|(model, _)| model).ok_or(BackendError::NotLoaded)
        }
    }

    /// Regression: the simulation kept a copy of the parameters and updated
    /// it before the backend accepted them, so a refused change was still
    /// reported (and measured) as in force.
    #[test]
    fn parameters_a_backend_refuses_are_not_reported_in_force() {
        let fabric = Fabric::from_chart(&Chart::stockinette(3, 3).unwrap(), &Geometry::default()).unwrap();
        let mut sim = Simulation::new(Picky::default(), fabric, Params::default()).unwrap();
        let refused = Params { friction: 1.5, ..Params::default() };
        refused.validate().expect("the model itself allows it");
        assert!(sim.set_params(refused).is_err());
        assert_eq!(sim.params().unwrap().friction, Params::default().friction);
        sim.set_params(Params { friction: 0.5, ..Params::default() }).unwrap();
        assert_eq!(sim.params().unwrap().friction, 0.5);
    }

    /// Energy is measured against the backend's own model: a contact it
    /// released stops counting, and reviving it (re-seated at its length)
    /// adds nothing.
    #[test]
    fn energy_follows_the_backends_liveness_and_reseats() {
        let fabric = Fabric::from_chart(&Chart::stockinette(3, 3).unwrap(), &Geometry::default()).unwrap();
        let contacts = fabric.contacts().len();
        let mut sim = Simulation::new(Picky::default(), fabric, Params::default()).unwrap();
        sim.set_contacts_alive(&vec![false; contacts]).unwrap();
        sim.advance(200).unwrap();
        let released = sim.energy().unwrap();
        assert_eq!(released.contact, 0.0, "released contacts still counted: {released:?}");
        sim.set_contacts_alive(&vec![true; contacts]).unwrap();
        let revived = sim.energy().unwrap();
        assert!(revived.contact.abs() < 1e-12, "revival added {} of contact energy", revived.contact);
        assert!(!sim.backend_mut().model().unwrap().reseating().is_empty(), "nothing drifted to re-seat");
    }
}
