//! The mechanics of yarnify: what the yarn *does*.
//!
//! This crate owns the model parameters ([`Params`]), the energy and exact
//! force of each term (SPEC §3, [`terms`]), the substep every backend follows
//! (SPEC §4, [`step`]), the [`Backend`] contract, and [`Simulation`], the
//! small driver for users who just want to run a fabric.
//!
//! It knows fabrics only through `yarn-topology`, and it must not know how a
//! backend computes: CPU, rayon and GPU implementations live in their own
//! crates and are held to [`step::substep`] by the conformance suite.
//!
//! ```
//! use yarn_model::{Model, Params, State, step};
//! use yarn_topology::{Chart, Fabric, Geometry};
//!
//! let fabric = Fabric::from_chart(&Chart::stockinette(4, 4)?, &Geometry::default())?;
//! let model = Model::<f64>::new(&fabric, &Params::default())?;
//! let mut state = State::at_rest(&fabric);
//! let before = step::energy(&model, &state).total();
//! let mut scratch = step::Scratch::default();
//! for _ in 0..200 {
//!     step::substep(&model, &mut state, &mut scratch);
//! }
//! assert!(step::energy(&model, &state).total() < before);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

#![forbid(unsafe_code)]

mod backend;
pub mod collider;
mod model;
mod params;
mod real;
mod rollback;
pub mod self_contact;
mod simulation;
pub mod stages;
#[cfg(not(target_arch = "wasm32"))]
pub mod statics;
pub mod step;
pub mod terms;

pub use backend::{Backend, BackendError};
pub use collider::{Collider, ColliderError, Plane};
pub use model::{Coefficients, ContactRest, DIVERGENCE_REACH, Model, RESEAT_SPEED, Reseat, State};
pub use params::{ParamError, Params, SLEEP_AFTER, STABLE_FRACTION};
pub use real::{Real, V3, widen};
pub use rollback::{Rollback, advance_with_rollback};
pub use simulation::Simulation;
pub use stages::{Stage, StageTimes};
pub use step::Energy;
