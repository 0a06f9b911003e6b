//! CPU backends for yarnify.
//!
//! [`Serial`] is the reference implementation of SPEC §4: it runs
//! [`yarn_model::step::substep`] as written, in `f32` (the reference for the
//! other `f32` backends) or `f64` (the ground truth for accuracy figures).
//!
//! [`Rayon`] computes the same function in parallel passes with a
//! deterministic per-node gather (see its module for the pass layout).
//!
//! This crate owns how the CPU executes the model, never what the model is:
//! formulas stay in `yarn-model`.
//!
//! ```
//! use yarn_backend_cpu::Serial;
//! use yarn_model::{Params, Simulation};
//! use yarn_topology::{Chart, Fabric, Geometry};
//!
//! let fabric = Fabric::from_chart(&Chart::stockinette(4, 4)?, &Geometry::default())?;
//! let mut sim = Simulation::new(Serial::<f64>::new(), fabric, Params::default())?;
//! sim.advance(100)?;
//! println!("energy {:.1}", sim.energy()?.total());
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

#![forbid(unsafe_code)]

mod rayon_backend;

pub use rayon_backend::Rayon;

use yarn_model::{Backend, BackendError, Model, Params, Real, State, V3, step};
use yarn_topology::{Fabric, Pin};

/// The serial reference backend, in precision `T` (`f32` or `f64`).
#[derive(Debug, Clone, Default)]
pub struct Serial<T: Real> {
    loaded: Option<Loaded<T>>,
}

#[derive(Debug, Clone)]
struct Loaded<T: Real> {
    model: Model<T>,
    state: State<T>,
    scratch: step::Scratch<T>,
}

impl<T: Real> Serial<T> {
    /// An empty backend; call [`Backend::load`] before use.
    pub fn new() -> Self {
        Self { loaded: None }
    }

    fn loaded(&mut self) -> Result<&mut Loaded<T>, BackendError> {
        self.loaded.as_mut().ok_or(BackendError::NotLoaded)
    }
}

impl<T: Real> Backend for Serial<T> {
    type Real = T;

    fn name(&self) -> String {
        format!("serial-{}", T::NAME)
    }

    fn load(&mut self, fabric: &Fabric, params: &Params) -> Result<(), BackendError> {
        let model = Model::new(fabric, params)?;
        self.loaded = Some(Loaded { model, state: State::at_rest(fabric), scratch: step::Scratch::default() });
        Ok(())
    }

    fn set_params(&mut self, params: &Params) -> Result<(), BackendError> {
        self.loaded()?.model.set_params(params)
    }

    fn set_pins(&mut self, pins: &[Pin]) -> Result<(), BackendError> {
        self.loaded()?.model.set_pins(pins)
    }

    fn set_contacts_alive(&mut self, alive: &[bool]) -> Result<(), BackendError> {
        self.loaded()?.model.set_contacts_alive(alive)
    }

    fn write_state(&mut self, state: &State<T>) -> Result<(), BackendError> {
        let loaded = self.loaded()?;
        state.check_len(loaded.model.node_count())?;
        loaded.state.clone_from(state);
        Ok(())
    }

    fn read_state(&mut self, state: &mut State<T>) -> Result<(), BackendError> {
        state.clone_from(&self.loaded()?.state);
        Ok(())
    }

    fn compute_forces(&mut self, forces: &mut Vec<V3<T>>) -> Result<(), BackendError> {
        let loaded = self.loaded()?;
        step::accumulate_forces(&loaded.model, &loaded.state.positions, forces);
        Ok(())
    }

    fn advance(&mut self, substeps: u64) -> Result<(), BackendError> {
        let Loaded { model, state, scratch } = self.loaded()?;
        for _ in 0..substeps {
            step::substep(model, state, scratch);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use yarn_topology::{Chart, Geometry};

    fn patch() -> Fabric {
        Fabric::from_chart(&Chart::stockinette(3, 3).unwrap(), &Geometry::default()).unwrap()
    }

    #[test]
    fn calls_before_load_say_so() {
        let mut serial = Serial::<f32>::new();
        assert_eq!(serial.advance(1), Err(BackendError::NotLoaded));
        assert_eq!(serial.state(), Err(BackendError::NotLoaded));
    }

    #[test]
    fn bad_input_is_refused_and_state_kept() {
        let fabric = patch();
        let mut serial = Serial::<f64>::new();
        serial.load(&fabric, &Params::default()).unwrap();
        serial.advance(10).unwrap();
        let before = serial.state().unwrap();
        let short = State { positions: vec![V3::zeros(); 3], velocities: vec![V3::zeros(); 3] };
        assert!(matches!(
            serial.write_state(&short),
            Err(BackendError::LengthMismatch { what: "positions", expected: 72, got: 3 })
        ));
        assert!(matches!(
            serial.set_contacts_alive(&[true]),
            Err(BackendError::LengthMismatch { expected: 12, got: 1, .. })
        ));
        assert!(serial.set_params(&Params { damping: -1.0, ..Params::default() }).is_err());
        assert_eq!(serial.state().unwrap(), before, "refused input changed the state");
    }

    #[test]
    fn f32_tracks_f64_over_a_short_run() {
        let fabric = patch();
        let (mut single, mut double) = (Serial::<f32>::new(), Serial::<f64>::new());
        single.load(&fabric, &Params::default()).unwrap();
        double.load(&fabric, &Params::default()).unwrap();
        single.advance(300).unwrap();
        double.advance(300).unwrap();
        let (a, b) = (single.state().unwrap().cast::<f64>(), double.state().unwrap());
        let worst = a.positions.iter().zip(&b.positions).map(|(p, q)| (p - q).norm()).fold(0.0, f64::max);
        let moved = b.positions.iter().zip(fabric.positions()).map(|(p, q)| (p - q).norm()).fold(0.0, f64::max);
        assert!(moved > 1e-2, "the patch must move for the comparison to mean anything (moved {moved})");
        assert!(worst < 1e-3 * moved.max(1.0), "f32 drifted {worst} from f64");
    }
}
