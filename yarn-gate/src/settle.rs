//! The two paths the gate takes to a certified rest ([`Certificate`]):
//!
//! - [`Statics`]: a frictionless quasi-static solve in f64
//!   ([`yarn_model::statics`]), its force tolerance tightened a
//!   hundredfold at a time until the rest certifies.
//! - [`Dynamics`]: the damped dynamics with friction on a backend, from
//!   wherever the state was put, checked at geometrically spaced substeps
//!   until the rest certifies.
//!
//! Friction makes rest depend on the path: a frictionless equilibrium is
//! also at rest with friction (no force is left for friction to hold), but
//! the dynamics may stop, held by friction, elsewhere, or not at all
//! within its budget. Both stop at their budget uncertified rather than
//! measure a transient as if it were a rest.

use std::time::Instant;

use serde::Serialize;
use yarn_model::statics::{self, StaticOptions};
use yarn_model::{Backend, BackendError, Model, Params, State, V3};
use yarn_topology::{Fabric, Pin};

use crate::GateError;
use crate::certificate::{Certificate, REST_COAST, Window};

/// A state some path brought toward rest, with its certificate.
#[derive(Debug, Clone, PartialEq)]
pub struct Rest {
    /// The state reached.
    pub state: State<f64>,
    /// The pins it was held by.
    pub pins: Vec<Pin>,
    /// How close to rest it is.
    pub certificate: Certificate,
    /// The work it took: substeps, or force evaluations.
    pub work: u64,
    /// Wall time it took, in seconds.
    pub seconds: f64,
}

/// What the report says of one [`Rest`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Settled {
    /// How close to rest the state is.
    pub certificate: Certificate,
    /// Substeps (dynamics) or force evaluations (statics) it took.
    pub work: u64,
    /// Wall time, seconds.
    pub seconds: f64,
}

impl Rest {
    /// What the report keeps of it.
    pub fn settled(&self) -> Settled {
        Settled { certificate: self.certificate, work: self.work, seconds: self.seconds }
    }
}

/// A path to rest.
pub trait Settle {
    /// The backend or solver, by name.
    fn name(&self) -> String;

    /// What [`Rest::work`] counts, in words ("substeps", "force evaluations").
    fn unit(&self) -> &'static str;

    /// Bring `start`, held by `pins`, to a certified rest, or stop after
    /// `budget` units of work. `progress` gets the work done so far.
    ///
    /// # Errors
    /// A backend's failure, or pins it refuses.
    fn settle(
        &mut self,
        start: &State<f64>,
        pins: &[Pin],
        budget: u64,
        progress: &mut dyn FnMut(u64),
    ) -> Result<Rest, GateError>;

    /// Go on from `rest` for `work` more units, whether or not it stays
    /// certified: the doubling test.
    ///
    /// # Errors
    /// As [`Settle::settle`].
    fn run_on(&mut self, rest: &Rest, work: u64, progress: &mut dyn FnMut(u64)) -> Result<Rest, GateError>;
}

/// The frictionless quasi-static solve in f64.
#[derive(Debug)]
pub struct Statics {
    model: Model<f64>,
    options: StaticOptions,
    radius: f64,
}

/// Each round of [`Statics::settle`] asks for forces this much smaller
/// than the last, until the rest certifies.
const TOLERANCE_STEP: f64 = 1e-2;

impl Statics {
    /// The solve of `fabric` under `params` (friction plays no part),
    /// starting at `options`' force tolerance.
    ///
    /// # Errors
    /// Parameters that do not validate.
    pub fn new(fabric: &Fabric, params: &Params, options: StaticOptions) -> Result<Self, GateError> {
        Ok(Self { model: Model::new(fabric, params)?, options, radius: fabric.yarn_radius() })
    }

    fn solve(&mut self, state: &mut State<f64>, tolerance: f64, evaluations: u64) -> statics::StaticReport {
        let options =
            StaticOptions { force_tolerance: tolerance, max_evaluations: evaluations as usize, ..self.options };
        statics::solve(&self.model, state, &options)
    }
}

impl Settle for Statics {
    fn name(&self) -> String {
        "statics-f64".into()
    }

    fn unit(&self) -> &'static str {
        "force evaluations"
    }

    fn settle(
        &mut self,
        start: &State<f64>,
        pins: &[Pin],
        budget: u64,
        progress: &mut dyn FnMut(u64),
    ) -> Result<Rest, GateError> {
        let clock = Instant::now();
        self.model.set_pins(pins)?;
        let mut state = start.clone();
        let (mut tolerance, mut work) = (self.options.force_tolerance, 0);
        loop {
            let report = self.solve(&mut state, tolerance, budget - work);
            work += report.evaluations as u64;
            progress(work);
            let certificate = Certificate::of(&self.model, &state, self.radius);
            // A solve that stopped short of its tolerance has stalled, and
            // a tighter one would stall too.
            if certificate.certified || work >= budget || !report.converged {
                let seconds = clock.elapsed().as_secs_f64();
                return Ok(Rest { state, pins: pins.to_vec(), certificate, work, seconds });
            }
            tolerance *= TOLERANCE_STEP;
        }
    }

    fn run_on(&mut self, rest: &Rest, work: u64, progress: &mut dyn FnMut(u64)) -> Result<Rest, GateError> {
        let clock = Instant::now();
        self.model.set_pins(&rest.pins)?;
        let mut state = rest.state.clone();
        let report = self.solve(&mut state, 0.0, work);
        progress(report.evaluations as u64);
        let certificate = Certificate::of(&self.model, &state, self.radius);
        let seconds = rest.seconds + clock.elapsed().as_secs_f64();
        Ok(Rest { state, pins: rest.pins.clone(), certificate, work: rest.work + report.evaluations as u64, seconds })
    }
}

/// The damped dynamics, with friction, on a backend.
#[derive(Debug)]
pub struct Dynamics<'f, B> {
    backend: B,
    fabric: &'f Fabric,
    damping: f64,
}

/// Substeps between looks at the speed (and, with self-contact, at whether
/// yarn passed through yarn); a certificate is computed only when the
/// speed allows rest, and then after at least a tenth more work.
pub const CHUNK: u64 = 2_000;
/// A certificate is computed again only after this fraction more work
/// than was done when the last one was.
const CHECK_GROWTH: f64 = 0.1;

impl<'f, B: Backend> Dynamics<'f, B> {
    /// `backend` loaded with `fabric` under `params`.
    ///
    /// # Errors
    /// Whatever the backend's load fails with.
    pub fn new(mut backend: B, fabric: &'f Fabric, params: &Params) -> Result<Self, GateError> {
        backend.load(fabric, params)?;
        Ok(Self { backend, fabric, damping: params.damping })
    }

    /// Advance up to `budget` substeps from the backend's state, after
    /// `before` substeps already run toward this rest, stopping early at a
    /// certified rest when `stop_at_rest`. A certificate's window
    /// ([`Window`]) runs from the last look at a rest that did not
    /// certify, or without stopping from a tenth of `budget` before its end.
    fn advance(
        &mut self,
        before: u64,
        budget: u64,
        stop_at_rest: bool,
        progress: &mut dyn FnMut(u64),
    ) -> Result<(State<f64>, Certificate, u64), GateError> {
        let model = self.backend.model()?.in_f64(self.fabric)?;
        let radius = self.fabric.yarn_radius();
        let (mut done, mut next_check) = (0, 0);
        let last_window = ((budget as f64 * CHECK_GROWTH) as u64).max(CHUNK);
        let mut looked: Option<(Vec<V3<f64>>, u64)> = None;
        loop {
            let state = self.backend.state()?.cast::<f64>();
            // The start was checked when it was written.
            if done > 0
                && let Err(BackendError::Interpenetrating { a, b, distance }) = model.check_apart(&state.positions)
            {
                return Err(GateError::PassedThrough { phase: String::new(), work: done, a, b, distance });
            }
            let coasting = state.max_speed() / self.damping.max(f64::MIN_POSITIVE) / radius;
            let last = done >= budget;
            if last || (stop_at_rest && coasting < REST_COAST && done >= next_check) {
                let window = looked.as_ref().map(|(since, at)| Window { since, work: done - at, total: before + done });
                let certificate = Certificate::over(&model, &state, radius, window);
                if last || certificate.certified {
                    return Ok((state, certificate, done));
                }
                next_check = done + ((done as f64 * CHECK_GROWTH) as u64).max(CHUNK);
                looked = Some((state.positions, done));
            } else if !stop_at_rest && looked.is_none() && done + last_window >= budget {
                looked = Some((state.positions, done));
            }
            let chunk = CHUNK.min(budget - done);
            self.backend.advance(chunk)?;
            done += chunk;
            progress(done);
        }
    }
}

impl<B: Backend> Settle for Dynamics<'_, B> {
    fn name(&self) -> String {
        self.backend.name()
    }

    fn unit(&self) -> &'static str {
        "substeps"
    }

    fn settle(
        &mut self,
        start: &State<f64>,
        pins: &[Pin],
        budget: u64,
        progress: &mut dyn FnMut(u64),
    ) -> Result<Rest, GateError> {
        let clock = Instant::now();
        self.backend.set_pins(pins)?;
        self.backend.write_state(&start.cast())?;
        let (state, certificate, work) = self.advance(0, budget, true, progress)?;
        Ok(Rest { state, pins: pins.to_vec(), certificate, work, seconds: clock.elapsed().as_secs_f64() })
    }

    fn run_on(&mut self, rest: &Rest, work: u64, progress: &mut dyn FnMut(u64)) -> Result<Rest, GateError> {
        let clock = Instant::now();
        self.backend.set_pins(&rest.pins)?;
        self.backend.write_state(&rest.state.cast())?;
        let (state, certificate, done) = self.advance(rest.work, work, false, progress)?;
        let seconds = rest.seconds + clock.elapsed().as_secs_f64();
        Ok(Rest { state, pins: rest.pins.clone(), certificate, work: rest.work + done, seconds })
    }
}

#[cfg(test)]
mod tests {
    use yarn_backend_cpu::Serial;
    use yarn_topology::{FabricParts, Vec3, YarnSpan};

    use super::*;

    /// A yarn dropped across a held one under a load its push holds only
    /// deep inside it sinks in past 1 r, and the dynamics stops there by
    /// name, with the substeps it ran and, once the gate says where, its
    /// phase; the same drop onto a stiff enough push comes to rest on top.
    #[test]
    fn yarn_pushed_through_yarn_stops_the_dynamics_where_it_happened() {
        let positions: Vec<Vec3> = (0..7)
            .map(|i| Vec3::new(f64::from(i) - 3.0, 0.0, 0.0))
            .chain((0..7).map(|i| Vec3::new(0.0, 2.5, f64::from(i) - 3.0)))
            .collect();
        let fabric = Fabric::from_parts(FabricParts {
            positions,
            yarns: vec![YarnSpan::open(0..7), YarnSpan::open(7..14)],
            yarn_radius: Some(0.9),
            ..FabricParts::default()
        })
        .unwrap();
        let held: Vec<Pin> = (0..7).map(|i| Pin { node: i, target: fabric.positions()[i as usize] }).collect();
        let drop = |self_contact_stiffness: f64| {
            let params = Params { gravity: 200.0, self_contact_stiffness, ..Params::default() };
            let mut dynamics = Dynamics::new(Serial::<f64>::new(), &fabric, &params).unwrap();
            dynamics.settle(&State::at_rest(&fabric), &held, 20_000, &mut |_| {})
        };
        let error = drop(1.0).unwrap_err();
        let GateError::PassedThrough { work, distance, .. } = &error else { panic!("{error}") };
        assert!(*work > 0 && *work < 20_000 && *distance < 1.0, "{error}");
        let named = error.during("drop").to_string();
        assert!(named.starts_with("yarn passed through yarn in `drop` after "), "{named}");
        let rest = drop(1_600.0).unwrap();
        assert!(rest.state.positions[10].y > 0.9 * 2.0 * 0.9, "{:?}", rest.state.positions[10]);
    }
}
