//! CPU backends for yarnify.
//!
//! - [`Serial`]: SPEC §4 on one thread, in `f32` (the fast CPU backend,
//!   which `Rayon` and the GPU's gather mode reproduce bit for bit) or
//!   `f64` (the ground truth for accuracy figures). Its passes run over the
//!   state stored by component, in blocks whose loops the compiler
//!   vectorises.
//! - [`Rayon`]: the same passes with each pass's blocks spread over a rayon
//!   thread pool, in `f32`.
//! - [`Reference`]: [`yarn_model::step::substep`] as written, element by
//!   element: the plainest statement of the model, against which the
//!   conformance suite holds the fast backends.
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

/// The [`Backend`] methods that [`Serial`] and [`Rayon`] hand straight to
/// their loaded fabric, for a backend with a `loaded()` accessor, a
/// `loaded` field and `Real = $real`.
macro_rules! forward_to_loaded {
    ($real:ty) => {
        fn set_params(&mut self, params: &yarn_model::Params) -> Result<(), yarn_model::BackendError> {
            self.loaded()?.set_params(params)
        }

        fn set_pins(&mut self, pins: &[yarn_topology::Pin]) -> Result<(), yarn_model::BackendError> {
            self.loaded()?.set_pins(pins)
        }

        fn set_contacts_alive(&mut self, alive: &[bool]) -> Result<(), yarn_model::BackendError> {
            self.loaded()?.set_contacts_alive(alive)
        }

        fn set_colliders(&mut self, colliders: &[yarn_model::Collider]) -> Result<(), yarn_model::BackendError> {
            self.loaded()?.set_colliders(colliders)
        }

        fn self_contact_builds(&self) -> Option<u64> {
            self.loaded.as_ref().map(crate::fabric::CpuFabric::self_contact_builds)
        }

        fn write_state(&mut self, state: &yarn_model::State<$real>) -> Result<(), yarn_model::BackendError> {
            self.loaded()?.write_state(state)
        }

        fn read_state(&mut self, state: &mut yarn_model::State<$real>) -> Result<(), yarn_model::BackendError> {
            self.loaded()?.read_state(state);
            Ok(())
        }

        fn model(&self) -> Result<&yarn_model::Model<$real>, yarn_model::BackendError> {
            self.loaded.as_ref().map(crate::fabric::CpuFabric::model).ok_or(yarn_model::BackendError::NotLoaded)
        }
    };
}

mod fabric;
mod rayon_backend;

pub use rayon_backend::Rayon;

use fabric::{CpuFabric, Exec};
use yarn_model::stages::StageTimes;
use yarn_model::{Backend, BackendError, Model, Params, Real, Rollback, State, V3, advance_with_rollback, step};
use yarn_topology::{Fabric, Pin};

/// The single-threaded backend, in precision `T` (`f32` or `f64`).
#[derive(Debug, Default)]
pub struct Serial<T: Real> {
    loaded: Option<CpuFabric<T>>,
}

impl<T: Real> Serial<T> {
    /// An empty backend; call [`Backend::load`] before use.
    pub fn new() -> Self {
        Self { loaded: None }
    }

    /// Blocks of 512 nodes asleep now (see [`Params::sleep_speed`]); 0
    /// before load.
    pub fn sleeping_blocks(&self) -> usize {
        self.loaded.as_ref().map_or(0, CpuFabric::sleeping_blocks)
    }

    fn loaded(&mut self) -> Result<&mut CpuFabric<T>, BackendError> {
        self.loaded.as_mut().ok_or(BackendError::NotLoaded)
    }
}

impl<T: Real> Backend for Serial<T> {
    type Real = T;

    fn name(&self) -> String {
        format!("serial-{}", T::NAME)
    }

    fn load(&mut self, fabric: &Fabric, params: &Params) -> Result<(), BackendError> {
        self.loaded = Some(CpuFabric::new(fabric, params, Exec::Sequential, 1)?);
        Ok(())
    }

    forward_to_loaded!(T);

    fn compute_forces(&mut self, forces: &mut Vec<V3<T>>) -> Result<(), BackendError> {
        self.loaded()?.compute_forces(forces);
        Ok(())
    }

    fn advance(&mut self, substeps: u64) -> Result<(), BackendError> {
        self.loaded()?.advance(substeps)
    }

    fn advance_timed(&mut self, substeps: u64) -> Result<StageTimes, BackendError> {
        self.loaded()?.advance_timed(substeps)
    }
}

/// [`yarn_model::step::substep`] as a backend, in precision `T`: every
/// element in order, one node vector at a time. Slow and plain; it is what
/// the other backends are checked against.
#[derive(Debug, Clone, Default)]
pub struct Reference<T: Real> {
    loaded: Option<Loaded<T>>,
}

#[derive(Debug, Clone)]
struct Loaded<T: Real> {
    model: Model<T>,
    state: State<T>,
    scratch: step::Scratch<T>,
    /// Substeps completed since load.
    substeps: u64,
    /// The state at the start of the current advance, to put back if it
    /// diverges.
    saved: State<T>,
}

impl<T: Real> Rollback for Loaded<T> {
    type Real = T;

    fn model_mut(&mut self) -> &mut Model<T> {
        &mut self.model
    }

    fn save(&mut self) {
        self.saved.clone_from(&self.state);
    }

    fn run(&mut self, substeps: u64) -> Result<(), BackendError> {
        let limit = self.model.divergence_speed();
        for k in 1..=substeps {
            step::substep(&self.model, &mut self.state, &mut self.scratch);
            self.model.close_reseats(1, |_, _| ());
            if let Some((node, speed)) = self.state.first_diverged(limit) {
                return Err(BackendError::Diverged { substep: self.substeps + k, node, speed, limit });
            }
        }
        self.substeps += substeps;
        Ok(())
    }

    fn restore(&mut self) -> Result<(), BackendError> {
        self.state.clone_from(&self.saved);
        Ok(())
    }
}

impl<T: Real> Reference<T> {
    /// An empty backend; call [`Backend::load`] before use.
    pub fn new() -> Self {
        Self { loaded: None }
    }

    fn loaded(&mut self) -> Result<&mut Loaded<T>, BackendError> {
        self.loaded.as_mut().ok_or(BackendError::NotLoaded)
    }
}

impl<T: Real> Backend for Reference<T> {
    type Real = T;

    fn name(&self) -> String {
        format!("reference-{}", T::NAME)
    }

    fn load(&mut self, fabric: &Fabric, params: &Params) -> Result<(), BackendError> {
        let model = Model::new(fabric, params)?;
        let state = State::at_rest(fabric);
        model.check_apart(&state.positions)?;
        self.loaded =
            Some(Loaded { model, saved: state.clone(), state, scratch: step::Scratch::default(), substeps: 0 });
        Ok(())
    }

    fn set_params(&mut self, params: &Params) -> Result<(), BackendError> {
        self.loaded()?.model.set_params(params)
    }

    fn set_pins(&mut self, pins: &[Pin]) -> Result<(), BackendError> {
        self.loaded()?.model.set_pins(pins)
    }

    fn set_contacts_alive(&mut self, alive: &[bool]) -> Result<(), BackendError> {
        let Loaded { model, state, .. } = self.loaded()?;
        model.set_contacts_alive(alive, &state.positions)
    }

    fn set_colliders(&mut self, colliders: &[yarn_model::Collider]) -> Result<(), BackendError> {
        self.loaded()?.model.set_colliders(colliders)
    }

    fn self_contact_builds(&self) -> Option<u64> {
        self.loaded.as_ref().map(|loaded| loaded.scratch.candidates.builds())
    }

    fn write_state(&mut self, state: &State<T>) -> Result<(), BackendError> {
        let loaded = self.loaded()?;
        state.check_len(loaded.model.node_count())?;
        loaded.model.check_apart(&state.positions)?;
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
        advance_with_rollback(self.loaded()?, substeps)
    }

    fn model(&self) -> Result<&Model<T>, BackendError> {
        self.loaded.as_ref().map(|loaded| &loaded.model).ok_or(BackendError::NotLoaded)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use yarn_model::Stage;
    use yarn_topology::{Chart, Geometry};

    /// The paper's 3x3 arch: 72 nodes, as the counts below expect.
    fn patch() -> Fabric {
        Fabric::from_chart(&Chart::stockinette(3, 3).unwrap(), &Geometry::paper()).unwrap()
    }

    /// How far apart the farthest pair of matching vectors of `a` and `b` is.
    fn farthest(a: &[V3<f64>], b: &[V3<f64>]) -> f64 {
        a.iter().zip(b).map(|(p, q)| (p - q).norm()).fold(0.0, f64::max)
    }

    /// A patch dropped on a floor with self-contact on: `Serial<f64>`
    /// takes a substep as the reference does to rounding and follows it
    /// closely over the drop, `Serial<f32>` and `Rayon` agree
    /// bit for bit, the list is rebuilt far less often than every substep,
    /// and nothing ends inside the floor.
    #[test]
    fn self_contact_and_a_floor_run_on_every_cpu_backend() {
        let fabric = Fabric::from_chart(&Chart::stockinette(6, 6).unwrap(), &Geometry::default()).unwrap();
        let floor_y = fabric.positions().iter().map(|p| p.y).fold(f64::INFINITY, f64::min) - 1.5;
        let colliders = [yarn_model::Collider::Plane(yarn_model::Plane::floor(floor_y))];
        let params = Params { self_contact_stiffness: 800.0, gravity: 100.0, ..Params::default() };
        let substeps = 400;
        fn drop_on<B: Backend>(
            mut backend: B,
            fabric: &Fabric,
            params: &Params,
            colliders: &[yarn_model::Collider],
            substeps: u64,
        ) -> (State<f64>, u64) {
            backend.load(fabric, params).unwrap();
            backend.set_pins(&[]).unwrap();
            backend.set_colliders(colliders).unwrap();
            backend.advance(substeps).unwrap();
            (backend.state().unwrap().cast(), backend.self_contact_builds().unwrap())
        }
        let (reference, reference_builds) = drop_on(Reference::<f64>::new(), &fabric, &params, &colliders, substeps);
        let (serial, serial_builds) = drop_on(Serial::<f64>::new(), &fabric, &params, &colliders, substeps);
        let (single, _) = drop_on(Serial::<f32>::new(), &fabric, &params, &colliders, substeps);
        let (parallel, _) = drop_on(Rayon::with_threads(2).unwrap(), &fabric, &params, &colliders, substeps);
        // Each substep agrees to rounding (below), but friction at a pair
        // that barely slips turns along its slip, whose direction rounding
        // decides, so the two part by about 6e-9 over the 400 substeps.
        let worst = farthest(&reference.positions, &serial.positions);
        assert!(worst < 2e-8, "serial f64 strays {worst} from the reference");
        let (midway, _) = drop_on(Reference::<f64>::new(), &fabric, &params, &colliders, substeps / 5);
        fn one_substep<B: Backend<Real = f64>>(
            mut backend: B,
            fabric: &Fabric,
            params: &Params,
            colliders: &[yarn_model::Collider],
            from: &State<f64>,
        ) -> State<f64> {
            backend.load(fabric, params).unwrap();
            backend.set_colliders(colliders).unwrap();
            backend.write_state(from).unwrap();
            backend.advance(1).unwrap();
            backend.state().unwrap()
        }
        let (a, b) = (
            one_substep(Reference::<f64>::new(), &fabric, &params, &colliders, &midway),
            one_substep(Serial::<f64>::new(), &fabric, &params, &colliders, &midway),
        );
        let worst = farthest(&a.velocities, &b.velocities);
        assert!(worst < 1e-13, "one substep from the same state: serial f64 strays {worst} from the reference");
        assert_eq!(single, parallel, "serial f32 and rayon must agree bit for bit");
        let radius = fabric.yarn_radius();
        let lowest = serial.positions.iter().map(|p| p.y).fold(f64::INFINITY, f64::min);
        assert!(lowest > floor_y + 0.5 * radius, "a node sank to {lowest}, the floor is at {floor_y}");
        assert!(lowest < floor_y + 2.0 * radius, "the patch never reached the floor: lowest node at {lowest}");
        for builds in [reference_builds, serial_builds] {
            assert!((1..substeps / 4).contains(&builds), "{builds} list builds in {substeps} substeps");
        }
    }

    /// What a substep computes does not depend on when the candidate list
    /// was built or its near list refreshed: a skin of 0.1 r rebuilds and
    /// refreshes at other substeps than one of 2 r, and a patch dropped on
    /// itself follows the same trajectory, bit for bit, on `Serial` and
    /// `Rayon`.
    #[test]
    fn cpu_trajectories_do_not_depend_on_the_skin() {
        let fabric = Fabric::from_chart(&Chart::stockinette(4, 4).unwrap(), &Geometry::default()).unwrap();
        fn drop_with<B: Backend>(mut backend: B, fabric: &Fabric, skin: f64) -> (State<f64>, u64) {
            let params =
                Params { self_contact_stiffness: 800.0, self_contact_skin: skin, gravity: 200.0, ..Params::default() };
            backend.load(fabric, &params).unwrap();
            backend.set_pins(&[]).unwrap();
            let mut state = backend.state().unwrap();
            for v in state.velocities.iter_mut().step_by(5) {
                *v = V3::new(B::Real::of(0.0), B::Real::of(0.0), B::Real::of(30.0));
            }
            backend.write_state(&state).unwrap();
            backend.advance(300).unwrap();
            (backend.state().unwrap().cast(), backend.self_contact_builds().unwrap())
        }
        let (thin, thin_builds) = drop_with(Serial::<f32>::new(), &fabric, 0.1);
        let (thick, thick_builds) = drop_with(Serial::<f32>::new(), &fabric, 2.0);
        assert!(thin_builds > thick_builds && thick_builds >= 1, "builds: {thin_builds} and {thick_builds}");
        let apart = |a: &State<f64>, b: &State<f64>| farthest(&a.positions, &b.positions);
        assert!(thin == thick, "serial f32, skins 0.1 r and 2 r: {} apart", apart(&thin, &thick));
        let (parallel, _) = drop_with(Rayon::with_threads(2).unwrap(), &fabric, 0.1);
        assert!(thin == parallel, "serial f32 and rayon, skin 0.1 r: {} apart", apart(&thin, &parallel));
        let (thin, _) = drop_with(Serial::<f64>::new(), &fabric, 0.1);
        let (thick, _) = drop_with(Serial::<f64>::new(), &fabric, 2.0);
        assert!(thin == thick, "serial f64, skins 0.1 r and 2 r: {} apart", apart(&thin, &thick));
    }

    /// Self-contact where the block and move passes take a node's sums on
    /// their own: a ring's closure (its last segment, from node 11 back to
    /// node 0) pressed across an open yarn, and sliding along it. The
    /// forces of `Serial<f64>` are the reference's to rounding and its
    /// trajectory follows it, and the closure's nodes feel the push.
    #[test]
    fn self_contact_reaches_a_rings_closure() {
        use yarn_topology::{FabricParts, Vec3, YarnSpan};
        let mut positions: Vec<Vec3> = (0..16).map(|i| Vec3::new(1.2 * i as f64, 0.0, 0.0)).collect();
        // The ring's closure crosses the yarn 1.6 above it, inside 2r = 1.8.
        positions.extend((0..12).map(|k| {
            let angle = -std::f64::consts::FRAC_PI_2 + (k as f64 + 0.5) * std::f64::consts::TAU / 12.0;
            Vec3::new(8.0, 3.0 * angle.cos(), 4.5 + 3.0 * angle.sin())
        }));
        let yarns = vec![YarnSpan { start: 0, end: 16, closed: false }, YarnSpan { start: 16, end: 28, closed: true }];
        let fabric = Fabric::from_parts(FabricParts { positions, yarns, ..FabricParts::default() }).unwrap();
        let params = Params { self_contact_stiffness: 800.0, ..Params::default() };
        let mut sliding = State::<f64>::at_rest(&fabric);
        for v in &mut sliding.velocities[16..] {
            *v = V3::new(0.0, 20.0, 0.0);
        }
        let (mut fast, mut plain) = (Serial::<f64>::new(), Reference::<f64>::new());
        for backend in [&mut fast as &mut dyn Backend<Real = f64>, &mut plain] {
            backend.load(&fabric, &params).unwrap();
            backend.set_pins(&[]).unwrap();
            backend.write_state(&sliding).unwrap();
        }
        let (f, g) = (fast.forces().unwrap(), plain.forces().unwrap());
        let scale = g.iter().map(|v| v.norm()).fold(0.0, f64::max);
        let worst = farthest(&f, &g);
        assert!(worst < 1e-12 * scale, "forces differ by {worst:e} of {scale}");
        let mut off = Reference::<f64>::new();
        off.load(&fabric, &Params { self_contact_stiffness: 0.0, ..params }).unwrap();
        off.write_state(&sliding).unwrap();
        let without = off.forces().unwrap();
        for node in [16, 27] {
            let push = (g[node] - without[node]).norm();
            assert!(push > 1.0, "ring node {node} feels {push} of self-contact");
        }
        fast.advance(60).unwrap();
        plain.advance(60).unwrap();
        let (a, b) = (fast.state().unwrap(), plain.state().unwrap());
        let worst = farthest(&a.positions, &b.positions);
        assert!(worst < 1e-9, "trajectories differ by {worst:e}");
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

    /// A node flung far from its neighbours makes the next substep blow up:
    /// every CPU backend stops with `Diverged`, naming the substep, and
    /// leaves the state as it was before the call; a sane state then runs on.
    #[test]
    fn divergence_is_reported_and_rolled_back() {
        fn check<B: Backend>(mut backend: B) {
            let fabric = patch();
            backend.load(&fabric, &Params { friction: 0.0, ..Params::default() }).unwrap();
            backend.advance(5).unwrap();
            let mut flung = backend.state().unwrap();
            let good = flung.clone();
            flung.positions[7].x += <B::Real as Real>::of(1e4);
            backend.write_state(&flung).unwrap();
            match backend.advance(20) {
                Err(BackendError::Diverged { substep: 6, node, speed, limit }) => {
                    assert!(speed > limit && [6, 7, 8].contains(&node), "{}: node {node} at {speed}", backend.name());
                }
                other => panic!("{}: expected a divergence at substep 6, got {other:?}", backend.name()),
            }
            assert_eq!(backend.state().unwrap(), flung, "{}: the state was not rolled back", backend.name());
            let mut nan = good.clone();
            nan.velocities[3].y = <B::Real as Real>::of(f64::NAN);
            backend.write_state(&nan).unwrap();
            assert!(matches!(backend.advance(1), Err(BackendError::Diverged { substep: 6, .. })), "{}", backend.name());
            backend.write_state(&good).unwrap();
            backend.advance(20).expect("a sane state runs on");
        }
        check(Serial::<f32>::new());
        check(Serial::<f64>::new());
        check(Reference::<f64>::new());
        check(Rayon::with_threads(2).unwrap());
    }

    /// A divergence is judged on the state the substep ends with, as the
    /// reference judges it: a pinned node flung at 100 times the limit, with
    /// friction on, is stopped by its pin, and every CPU backend runs on
    /// where the reference does, to its state within rounding.
    #[test]
    fn a_node_its_pin_stops_has_not_diverged() {
        fn flung<B: Backend>(mut backend: B) -> State<f64> {
            let fabric = patch();
            backend.load(&fabric, &Params::default()).unwrap();
            backend.set_pins(&[Pin { node: 10, target: fabric.positions()[10] }]).unwrap();
            backend.advance(5).unwrap();
            let mut state = backend.state().unwrap();
            let limit = backend.model().unwrap().divergence_speed();
            state.velocities[10].y = <B::Real as Real>::of(100.0 * limit);
            backend.write_state(&state).unwrap();
            let name = backend.name();
            backend.advance(3).unwrap_or_else(|e| panic!("{name}: {e}"));
            backend.state().unwrap().cast()
        }
        let reference = flung(Reference::<f64>::new());
        assert_eq!(reference.velocities[10], V3::zeros(), "the pin stops its node");
        let reference_f32 = flung(Reference::<f32>::new());
        assert!(farthest(&flung(Serial::<f64>::new()).positions, &reference.positions) < 1e-12);
        let serial_f32 = flung(Serial::<f32>::new());
        assert!(farthest(&serial_f32.positions, &reference_f32.positions) < 1e-5);
        assert_eq!(flung(Rayon::with_threads(2).unwrap()), serial_f32);
    }

    /// A settled fabric falls asleep, a grab wakes what it moves, and the
    /// result stays within 0.15 r of the same run without sleeping (the
    /// grab draws its node 10 units, 11 r, out of the fabric).
    #[test]
    fn sleeping_skips_a_settled_fabric_and_wakes_for_a_grab() {
        // The paper's arch: 4,096 nodes, eight blocks of 512.
        let fabric = Fabric::from_chart(&Chart::stockinette(64, 8).unwrap(), &Geometry::paper()).unwrap();
        let node = fabric.head_node(32, 4).unwrap();
        // A flat, strongly damped patch settles within a few hundred substeps.
        let params = Params { damping: 40.0, rest_curl: 1.0, ..Params::default() };
        let run = |sleep_speed: f64| {
            let mut backend = Rayon::with_threads(2).unwrap();
            backend.load(&fabric, &Params { sleep_speed, ..params }).unwrap();
            backend.advance(1000).unwrap();
            let settled = backend.sleeping_blocks();
            let start = backend.state().unwrap().positions[node];
            for k in 1..=10 {
                let target = start + V3::new(0.0, 0.0, 1.0) * (k as f32);
                backend.set_pins(&[Pin { node: node as u32, target: target.cast() }]).unwrap();
                backend.advance(100).unwrap();
            }
            let grabbed = backend.sleeping_blocks();
            (settled, grabbed, backend.state().unwrap())
        };
        let (awake, _, reference) = run(0.0);
        let (settled, grabbed, slept) = run(0.02);
        assert_eq!(awake, 0);
        assert_eq!(settled, 8, "every block of the settled patch should sleep");
        assert!(grabbed < 8, "the grab woke nothing");
        let r = fabric.yarn_radius();
        let worst = reference
            .positions
            .iter()
            .zip(&slept.positions)
            .map(|(a, b)| f64::from((a - b).norm()) / r)
            .fold(0.0, f64::max);
        assert!(worst < 0.15, "sleeping moved a node {worst} r from the awake run");
    }

    /// A straight yarn three blocks long (1,536 nodes, 0.5 apart along x,
    /// which `f32` holds exactly) with `contacts`. At rest every force is
    /// zero, so with any sleep speed it falls asleep at the first look
    /// after [`yarn_model::SLEEP_AFTER`] substeps.
    fn straight_yarn(contacts: Vec<[u32; 2]>) -> Fabric {
        let positions = (0..3 * 512u32).map(|i| yarn_topology::Vec3::new(0.5 * f64::from(i), 0.0, 0.0)).collect();
        Fabric::from_parts(yarn_topology::FabricParts { positions, contacts, ..Default::default() }).unwrap()
    }

    /// A CPU backend and how it reports its sleeping blocks.
    type Sleeper<B> = (B, fn(&B) -> usize);

    /// Every call that changes the scene wakes every block: new
    /// parameters, a written state, a change of contact liveness and new
    /// pins. After each the yarn falls asleep again within
    /// [`yarn_model::SLEEP_AFTER`] substeps, except the block holding a
    /// pin, which stays awake.
    #[test]
    fn every_scene_change_wakes_a_sleeping_fabric() {
        fn check<B: Backend>((mut backend, sleeping): Sleeper<B>) {
            let fabric = straight_yarn(vec![[100, 900]]);
            let params = Params { sleep_speed: 0.01, ..Params::default() };
            backend.load(&fabric, &params).unwrap();
            let name = backend.name();
            let settle = |backend: &mut B| {
                backend.advance(u64::from(yarn_model::SLEEP_AFTER)).unwrap();
                sleeping(backend)
            };
            assert_eq!(sleeping(&backend), 0, "{name}: asleep at load");
            assert_eq!(settle(&mut backend), 3, "{name}: the yarn at rest did not fall asleep");

            backend.set_params(&Params { damping: 5.0, ..params }).unwrap();
            assert_eq!(sleeping(&backend), 0, "{name}: set_params left blocks asleep");
            assert_eq!(settle(&mut backend), 3, "{name}: not asleep again after set_params");

            let state = backend.state().unwrap();
            backend.write_state(&state).unwrap();
            assert_eq!(sleeping(&backend), 0, "{name}: write_state left blocks asleep");
            assert_eq!(settle(&mut backend), 3, "{name}: not asleep again after write_state");

            backend.set_contacts_alive(&[false]).unwrap();
            assert_eq!(sleeping(&backend), 0, "{name}: set_contacts_alive left blocks asleep");
            assert_eq!(settle(&mut backend), 3, "{name}: not asleep again after set_contacts_alive");

            backend.set_pins(&[Pin { node: 700, target: fabric.positions()[700] }]).unwrap();
            assert_eq!(sleeping(&backend), 0, "{name}: set_pins left blocks asleep");
            assert_eq!(settle(&mut backend), 2, "{name}: the pinned block (1 of 3) fell asleep, or another stayed up");
        }
        check::<Serial<f32>>((Serial::new(), Serial::sleeping_blocks));
        check::<Serial<f64>>((Serial::new(), Serial::sleeping_blocks));
        check::<Rayon>((Rayon::with_threads(2).unwrap(), Rayon::sleeping_blocks));
    }

    /// Kick the start of `fabric` (its first 10 nodes at 1 along x) on
    /// `backend`, undamped at sleep speed 0.01 (and `self_contact_stiffness`),
    /// and check that after [`yarn_model::SLEEP_AFTER`] substeps exactly one
    /// block sleeps, nodes 1,024 on, and that it wakes at the look where
    /// nodes 512..1,024 first move faster than twice the sleep speed, not
    /// before and not after, by substep 4,000.
    fn wakes_when_the_middle_moves_fast<B: Backend>(
        (mut backend, sleeping): Sleeper<B>,
        fabric: &Fabric,
        self_contact_stiffness: f64,
    ) {
        let sleep_speed = 0.01;
        let params = Params { sleep_speed, damping: 0.0, self_contact_stiffness, ..Params::default() };
        backend.load(fabric, &params).unwrap();
        let name = backend.name();
        let mut state = backend.state().unwrap();
        for v in &mut state.velocities[..10] {
            v.x = B::Real::of(1.0);
        }
        backend.write_state(&state).unwrap();
        let mut substeps = u64::from(yarn_model::SLEEP_AFTER);
        backend.advance(substeps).unwrap();
        let state = backend.state().unwrap();
        assert_eq!(sleeping(&backend), 1, "{name}: only the last block should sleep");
        assert!(state.velocities[1024..].iter().all(|v| *v == V3::zeros()), "{name}: the last block is awake");
        // The fastest speed squared in the middle block, as the sleep look
        // computes it.
        let middle = |state: &State<B::Real>| {
            state.velocities[512..1024].iter().map(|v| v.norm_squared().to_f64()).fold(0.0, f64::max)
        };
        let wake2 = 4.0 * sleep_speed * sleep_speed;
        loop {
            let before = middle(&backend.state().unwrap());
            backend.advance(10).unwrap();
            substeps += 10;
            let after = middle(&backend.state().unwrap());
            if sleeping(&backend) == 0 {
                assert!(before <= wake2 && after > wake2, "{name}: woke at middle speed² {after}, limit {wake2}");
                eprintln!("{name}: the last block woke at substep {substeps} (middle speed² {after} > {wake2})");
                return;
            }
            assert!(after <= wake2, "{name}: middle speed² {after} past {wake2}, the last block still asleep");
            assert!(substeps < 4000, "{name}: the kick never reached the middle block");
        }
    }

    /// A sleeping block wakes when a neighbour moves at more than twice
    /// the sleep speed, with no call to the backend. A kick at the start of
    /// an undamped straight yarn keeps the first block fast, which holds
    /// the second awake while the third falls asleep. The kick travels
    /// along the yarn at about 0.27 nodes per substep (ωh at the default
    /// k_s, m and h); the third block wakes at the look where the second
    /// first moves faster than twice the sleep speed, not before and not
    /// after. It woke at substep 1,870 on every backend here (printed);
    /// the test gives the kick until substep 4,000.
    #[test]
    fn a_sleeping_block_wakes_when_its_neighbour_moves_fast() {
        let fabric = straight_yarn(Vec::new());
        wakes_when_the_middle_moves_fast((Serial::<f32>::new(), Serial::sleeping_blocks), &fabric, 0.0);
        wakes_when_the_middle_moves_fast((Serial::<f64>::new(), Serial::sleeping_blocks), &fabric, 0.0);
        wakes_when_the_middle_moves_fast((Rayon::with_threads(2).unwrap(), Rayon::sleeping_blocks), &fabric, 0.0);
    }

    /// A sleeping block wakes when a block it touches only through
    /// self-contact moves fast. The kicked straight yarn of the test above
    /// (two blocks here) has a second yarn, a third block, lying beside its
    /// second block 2.0 apart: within reach plus the skin (1.8 + 0.45), so
    /// they make candidate pairs, but out of reach, so nothing pushes and
    /// the second yarn stays at rest. It starts 4 units past the second
    /// block's first node, out of the skin of the segment that joins the
    /// first two blocks (which would make it touch the first). It shares
    /// no segment and no contact with the first yarn, so only the pairs
    /// can wake it: it falls asleep while the kick runs along the first
    /// block, and wakes at the look where the second block first moves
    /// faster than twice the sleep speed, not before and not after.
    #[test]
    fn a_sleeping_block_wakes_when_a_block_it_touches_moves_fast() {
        use yarn_topology::{FabricParts, Vec3, YarnSpan};
        let kicked = (0..1024u32).map(|i| Vec3::new(0.5 * f64::from(i), 0.0, 0.0));
        let beside = (0..512u32).map(|i| Vec3::new(260.0 + 0.5 * f64::from(i), 2.0, 0.0));
        let yarns = vec![YarnSpan::open(0..1024), YarnSpan::open(1024..1536)];
        let fabric =
            Fabric::from_parts(FabricParts { positions: kicked.chain(beside).collect(), yarns, ..Default::default() })
                .unwrap();
        wakes_when_the_middle_moves_fast((Serial::<f32>::new(), Serial::sleeping_blocks), &fabric, 1600.0);
        wakes_when_the_middle_moves_fast((Serial::<f64>::new(), Serial::sleeping_blocks), &fabric, 1600.0);
        wakes_when_the_middle_moves_fast((Rayon::with_threads(2).unwrap(), Rayon::sleeping_blocks), &fabric, 1600.0);
    }

    /// A block that is slow but speeding up is not settling, so it does not
    /// sleep: the straight yarn falls from rest under gravity, undamped, at
    /// g t, which stays under the sleep speed for 600 substeps (0.4 of it)
    /// while rising at every look. A rule on speed alone froze it in mid-air
    /// after [`yarn_model::SLEEP_AFTER`] substeps. Once gravity is off it
    /// drifts at a steady speed, still under the sleep speed, and sleeps.
    #[test]
    fn a_block_speeding_up_from_rest_stays_awake() {
        fn check<B: Backend>((mut backend, sleeping): Sleeper<B>) {
            let params = Params { sleep_speed: 1.0, gravity: -1.0, damping: 0.0, ..Params::default() };
            backend.load(&straight_yarn(Vec::new()), &params).unwrap();
            let name = backend.name();
            for _ in 0..60 {
                backend.advance(10).unwrap();
                assert_eq!(sleeping(&backend), 0, "{name}: a block falling from rest fell asleep");
            }
            let fastest = backend.state().unwrap().velocities.iter().map(|v| v.norm().to_f64()).fold(0.0, f64::max);
            assert!(fastest < params.sleep_speed, "{name}: fell at {fastest}, past the sleep speed");
            backend.set_params(&Params { gravity: 0.0, ..params }).unwrap();
            backend.advance(u64::from(yarn_model::SLEEP_AFTER)).unwrap();
            assert_eq!(sleeping(&backend), 3, "{name}: the steady drift did not fall asleep");
        }
        check::<Serial<f32>>((Serial::new(), Serial::sleeping_blocks));
        check::<Serial<f64>>((Serial::new(), Serial::sleeping_blocks));
        check::<Rayon>((Rayon::with_threads(2).unwrap(), Rayon::sleeping_blocks));
    }

    /// Equal bit for bit (so -0 differs from 0, and a NaN equals itself):
    /// `assert_eq!` on the bits, naming the first node that differs rather
    /// than printing thousands.
    fn assert_same(got: &[V3<f32>], want: &[V3<f32>], what: &str) {
        let bits = |v: &V3<f32>| v.map(f32::to_bits);
        assert_eq!(got.len(), want.len(), "{what}: lengths");
        let differ = got.iter().zip(want).filter(|(a, b)| bits(a) != bits(b)).count();
        let first = got.iter().zip(want).position(|(a, b)| bits(a) != bits(b)).map(|i| (i, got[i], want[i]));
        assert_eq!(first, None, "{what}: {differ} of {} nodes differ; (first node, rayon, serial)", got.len());
    }

    /// `Rayon` is `Serial<f32>` spread over threads: the same forces and
    /// the same trajectory, bit for bit, on 1, 2 and 3 threads. The 48x48
    /// patch (18,432 nodes in 36 blocks, 4,512 contacts in up to 9
    /// contact blocks) splits every pass into several tasks. The run is kicked,
    /// pinned (the top row, and a grabbed head drawn out), has every fifth
    /// contact dead, and revives them at substep 60 away from their rest,
    /// so re-seated contacts close during the second half; with friction
    /// (four passes) and without (the move fused into the block pass). So
    /// that equality means something, the run must move nodes more than 1
    /// unit and re-seat more than a tenth of the contacts (measured, and
    /// printed: 7.6 units and 903 of 4,512 contacts, at both μ).
    #[test]
    fn rayon_matches_serial_f32_bit_for_bit_on_1_2_and_3_threads() {
        let fabric = Fabric::from_chart(&Chart::stockinette(48, 48).unwrap(), &Geometry::default()).unwrap();
        let contacts = fabric.contacts().len();
        let grabbed = fabric.stitch_node(24, 24, 4).unwrap() as u32;
        let mut pins: Vec<Pin> = fabric
            .side_nodes(yarn_topology::Side::Top)
            .into_iter()
            .map(|node| Pin { node, target: fabric.positions()[node as usize] })
            .collect();
        pins.push(Pin { node: grabbed, target: fabric.positions()[grabbed as usize] + yarn_topology::Vec3::z() * 3.0 });
        let some_dead: Vec<bool> = (0..contacts).map(|k| k % 5 != 0).collect();
        let run = |backend: &mut dyn Backend<Real = f32>, friction: f64| {
            backend.load(&fabric, &Params { friction, gravity: 9.81, ..Params::default() }).unwrap();
            backend.set_pins(&pins).unwrap();
            backend.set_contacts_alive(&some_dead).unwrap();
            let mut state = backend.state().unwrap();
            for (i, v) in state.velocities.iter_mut().enumerate() {
                let t = i as f32;
                *v = V3::new((0.37 * t).sin(), (0.61 * t).cos(), (0.23 * t).sin()) * 5.0;
            }
            backend.write_state(&state).unwrap();
            let forces = backend.forces().unwrap();
            backend.advance(60).unwrap();
            let half = backend.state().unwrap();
            backend.set_contacts_alive(&vec![true; contacts]).unwrap();
            let reseating = backend.model().unwrap().reseating().len();
            backend.advance(60).unwrap();
            (forces, half, reseating, backend.state().unwrap(), backend.forces().unwrap())
        };
        for friction in [0.3, 0.0] {
            let serial = run(&mut Serial::<f32>::new(), friction);
            let (_, half, reseating, end, _) = &serial;
            let moved = end
                .positions
                .iter()
                .zip(fabric.positions())
                .map(|(p, q)| (p.cast::<f64>() - q).norm())
                .fold(0.0, f64::max);
            eprintln!("μ = {friction}: moved up to {moved:.2}, {reseating} of {contacts} contacts re-seated");
            assert!(moved > 1.0 && reseating * 10 > contacts, "moved {moved}, {reseating} of {contacts} re-seated");
            assert_ne!(half, end, "the second half did not move");
            for threads in 1..=3 {
                let rayon = run(&mut Rayon::with_threads(threads).unwrap(), friction);
                let what = format!("μ = {friction}, {threads} threads");
                assert_same(&rayon.0, &serial.0, &format!("{what}: forces at the start"));
                assert_same(&rayon.1.positions, &serial.1.positions, &format!("{what}: positions at substep 60"));
                assert_same(&rayon.1.velocities, &serial.1.velocities, &format!("{what}: velocities at substep 60"));
                assert_eq!(rayon.2, serial.2, "{what}: re-seated contacts");
                assert_same(&rayon.3.positions, &serial.3.positions, &format!("{what}: positions at substep 120"));
                assert_same(&rayon.3.velocities, &serial.3.velocities, &format!("{what}: velocities at substep 120"));
                assert_same(&rayon.4, &serial.4, &format!("{what}: forces at the end"));
            }
        }
    }

    /// Yarns that cross the CPU's blocks of 512 and break inside and at
    /// their edges: an open yarn of 300 nodes, a ring of 700 (wrapping
    /// from block 1 back to block 0), a lone node, two nodes, a ring of 3,
    /// an open yarn ending exactly at node 1,536 (a block edge) and one of
    /// 400 after it; laid as waves, with contacts across yarns.
    fn many_yarns() -> Fabric {
        use yarn_topology::{FabricParts, Vec3, YarnSpan};
        let lengths = [(300, false), (700, true), (1, false), (2, false), (3, true), (530, false), (400, false)];
        let (mut positions, mut yarns) = (Vec::new(), Vec::new());
        for (k, &(len, closed)) in lengths.iter().enumerate() {
            let start = positions.len() as u32;
            let y = 4.0 * k as f64;
            for i in 0..len {
                let t = i as f64;
                positions.push(if closed {
                    let angle = std::f64::consts::TAU * t / len as f64;
                    let r = 0.1 * len as f64;
                    Vec3::new(r * angle.cos(), y + r * angle.sin(), 0.4 * (3.0 * angle).sin())
                } else {
                    Vec3::new(0.5 * t, y + 0.3 * (0.2 * t).sin(), 0.2 * (0.13 * t).cos())
                });
            }
            yarns.push(YarnSpan { start, end: start + len, closed });
        }
        assert_eq!(yarns[5].end, 1536, "a yarn must end at a block edge");
        let contacts = vec![[299, 300], [999, 1000], [1001, 1003], [10, 1200], [1535, 1536], [700, 1800]];
        Fabric::from_parts(FabricParts { positions, yarns, contacts, ..FabricParts::default() }).unwrap()
    }

    /// On [`many_yarns`], the f64 kernel gives `Reference<f64>`'s forces
    /// and trajectory, as on one yarn (`serial_f64_matches_reference_f64`),
    /// and every CPU backend the reference's forces to f32 rounding.
    #[test]
    fn cpu_backends_match_the_reference_on_many_yarns() {
        let fabric = many_yarns();
        let params = Params { gravity: 3.0, ..Params::default() };
        // Drawn off the rest shape, so every element pulls.
        let mut drawn = State::<f64>::at_rest(&fabric);
        for (i, p) in drawn.positions.iter_mut().enumerate() {
            let t = i as f64;
            *p += V3::new(0.1 * (0.7 * t).sin(), 0.1 * (1.3 * t).cos(), 0.1 * (0.9 * t).sin());
        }
        let (mut fast, mut plain) = (Serial::<f64>::new(), Reference::<f64>::new());
        fast.load(&fabric, &params).unwrap();
        plain.load(&fabric, &params).unwrap();
        fast.write_state(&drawn).unwrap();
        plain.write_state(&drawn).unwrap();
        let (f, g) = (fast.forces().unwrap(), plain.forces().unwrap());
        let scale = g.iter().map(|v| v.norm()).fold(0.0, f64::max);
        let worst = farthest(&f, &g);
        assert!(scale > 1.0 && worst < 1e-12 * scale, "forces differ by {worst:e} of {scale}");
        fast.advance(300).unwrap();
        plain.advance(300).unwrap();
        let (a, b) = (fast.state().unwrap(), plain.state().unwrap());
        let moved = farthest(&b.positions, fabric.positions());
        let worst = farthest(&a.positions, &b.positions);
        assert!(moved > 1e-2 && worst < 1e-9, "moved {moved}, differ by {worst:e}");
        let drawn = drawn.cast::<f32>();
        let mut reference = Reference::<f32>::new();
        reference.load(&fabric, &params).unwrap();
        reference.write_state(&drawn).unwrap();
        let want = reference.forces().unwrap();
        let scale = want.iter().map(|v| f64::from(v.norm())).fold(0.0, f64::max);
        let backends: [Box<dyn Backend<Real = f32>>; 3] = [
            Box::new(Serial::<f32>::new()),
            Box::new(Rayon::with_threads(2).unwrap()),
            Box::new(Rayon::with_threads(3).unwrap()),
        ];
        for mut backend in backends {
            backend.load(&fabric, &params).unwrap();
            backend.write_state(&drawn).unwrap();
            let got = backend.forces().unwrap();
            let worst = got.iter().zip(&want).map(|(a, b)| f64::from((a - b).norm())).fold(0.0, f64::max);
            assert!(worst <= 1e-5 * scale, "{}: forces differ by {worst:e} of {scale}", backend.name());
        }
    }

    /// Two open yarns of 600 and 700 nodes, the second starting where the
    /// first ends (inside block 1): a spring or joint across the break
    /// would pull the ends together. On every CPU backend each yarn's nodes
    /// feel exactly, bit for bit, the forces of the yarn alone, which the
    /// block pass computes without a break; a closed ring of 700 nodes
    /// across two blocks, at its rest shape with κ = 1, feels none.
    #[test]
    fn an_isolated_yarn_end_feels_only_its_own_yarn_and_a_ring_at_rest_nothing() {
        use yarn_topology::{FabricParts, Vec3, YarnSpan};
        let wave = |from: f64, n: usize| -> Vec<Vec3> {
            (0..n)
                .map(|i| Vec3::new(from + 0.5 * i as f64, (0.3 * i as f64).sin(), 0.1 * (0.2 * i as f64).cos()))
                .collect()
        };
        let (a, b) = (wave(0.0, 600), wave(299.8, 700));
        let fabric = |positions: Vec<Vec3>, yarns| {
            Fabric::from_parts(FabricParts { positions, yarns, ..FabricParts::default() }).unwrap()
        };
        let two =
            fabric(a.iter().chain(&b).copied().collect(), vec![YarnSpan::open(0..600), YarnSpan::open(600..1300)]);
        let (alone_a, alone_b) = (fabric(a, Vec::new()), fabric(b, Vec::new()));
        let params = Params { gravity: 9.81, ..Params::default() };
        fn forces<B: Backend>(backend: &mut B, fabric: &Fabric, params: &Params) -> Vec<V3<B::Real>> {
            backend.load(fabric, params).unwrap();
            let mut state = backend.state().unwrap();
            // By where a node is, not its index, which differs between fabrics.
            for p in &mut state.positions {
                let t = 3.0 * p.x.to_f64();
                *p += V3::new(0.05 * t.cos(), 0.07, -0.03 * t.sin()).map(<B::Real as Real>::of);
            }
            backend.write_state(&state).unwrap();
            backend.forces().unwrap()
        }
        fn check<B: Backend>(make: impl Fn() -> B, two: &Fabric, a: &Fabric, b: &Fabric, params: &Params) {
            let name = make().name();
            let f = forces(&mut make(), two, params);
            assert_eq!(&f[..600], forces(&mut make(), a, params).as_slice(), "{name}: the first yarn");
            assert_eq!(&f[600..], forces(&mut make(), b, params).as_slice(), "{name}: the second yarn");
            assert!(f[599].norm().to_f64() > 1.0 && f[600].norm().to_f64() > 1.0, "{name}: the ends are not loaded");
        }
        check(Serial::<f32>::new, &two, &alone_a, &alone_b, &params);
        check(Serial::<f64>::new, &two, &alone_a, &alone_b, &params);
        check(Reference::<f32>::new, &two, &alone_a, &alone_b, &params);
        check(|| Rayon::with_threads(2).unwrap(), &two, &alone_a, &alone_b, &params);

        let n = 700;
        let ring: Vec<Vec3> = (0..n)
            .map(|i| std::f64::consts::TAU * i as f64 / n as f64)
            .map(|t| Vec3::new(40.0 * t.cos(), 40.0 * t.sin(), 2.0 * (5.0 * t).sin()))
            .collect();
        let ring = fabric(ring, vec![YarnSpan::closed(0..n as u32)]);
        let flat = Params { rest_curl: 1.0, ..Params::default() };
        let mut backend = Serial::<f64>::new();
        backend.load(&ring, &flat).unwrap();
        let largest = backend.forces().unwrap().iter().map(|f| f.norm()).fold(0.0, f64::max);
        assert!(largest < 1e-9, "the ring at rest feels {largest}");
        backend.load(&ring, &Params::default()).unwrap();
        let f = backend.forces().unwrap();
        assert!(
            f[0].norm() > 1e3 * largest && f[n - 1].norm() > 1e3 * largest,
            "the pre-stressed ring's wrap feels only {} and {}",
            f[0].norm(),
            f[n - 1].norm()
        );
    }

    /// `Rayon` is `Serial<f32>` bit for bit on [`many_yarns`] too, kicked,
    /// with friction and without, on 1, 2 and 3 threads.
    #[test]
    fn rayon_matches_serial_f32_bit_for_bit_on_many_yarns() {
        let fabric = many_yarns();
        let run = |backend: &mut dyn Backend<Real = f32>, friction: f64| {
            backend.load(&fabric, &Params { friction, gravity: 9.81, ..Params::default() }).unwrap();
            let mut state = backend.state().unwrap();
            for (i, v) in state.velocities.iter_mut().enumerate() {
                let t = i as f32;
                *v = V3::new((0.37 * t).sin(), (0.61 * t).cos(), (0.23 * t).sin()) * 5.0;
            }
            backend.write_state(&state).unwrap();
            let forces = backend.forces().unwrap();
            backend.advance(100).unwrap();
            (forces, backend.state().unwrap())
        };
        for friction in [0.3, 0.0] {
            let serial = run(&mut Serial::<f32>::new(), friction);
            for threads in 1..=3 {
                let rayon = run(&mut Rayon::with_threads(threads).unwrap(), friction);
                let what = format!("μ = {friction}, {threads} threads");
                assert_same(&rayon.0, &serial.0, &format!("{what}: forces"));
                assert_same(&rayon.1.positions, &serial.1.positions, &format!("{what}: positions"));
                assert_same(&rayon.1.velocities, &serial.1.velocities, &format!("{what}: velocities"));
            }
        }
    }

    /// The conformance suite holds every f32 backend to `Reference<f32>`;
    /// this holds the f64 kernel, the ground truth of accuracy figures, to
    /// `Reference<f64>`, across block edges (1,152 nodes) and with friction.
    #[test]
    fn serial_f64_matches_reference_f64() {
        let fabric = Fabric::from_chart(&Chart::stockinette(12, 12).unwrap(), &Geometry::default()).unwrap();
        let params = Params { gravity: 3.0, ..Params::default() };
        let (mut fast, mut plain) = (Serial::<f64>::new(), Reference::<f64>::new());
        fast.load(&fabric, &params).unwrap();
        plain.load(&fabric, &params).unwrap();
        let alive: Vec<bool> = (0..fabric.contacts().len()).map(|k| k % 7 != 0).collect();
        fast.set_contacts_alive(&alive).unwrap();
        plain.set_contacts_alive(&alive).unwrap();
        let (f, g) = (fast.forces().unwrap(), plain.forces().unwrap());
        let scale = g.iter().map(|v| v.norm()).fold(0.0, f64::max);
        let worst = farthest(&f, &g);
        assert!(scale > 1.0 && worst < 1e-12 * scale, "forces differ by {worst:e} of {scale}");
        fast.advance(300).unwrap();
        plain.advance(300).unwrap();
        let (a, b) = (fast.state().unwrap(), plain.state().unwrap());
        let moved = farthest(&b.positions, fabric.positions());
        let worst = farthest(&a.positions, &b.positions);
        assert!(moved > 1e-2 && worst < 1e-9, "moved {moved}, differ by {worst:e}");
    }

    /// The stage counters time every pass and change nothing: a timed
    /// advance ends bit for bit where an untimed one does, with friction
    /// (four passes) and without (the move fused into the block pass).
    #[test]
    fn timed_advance_matches_advance_and_names_every_pass() {
        fn check<B: Backend>(make: impl Fn() -> B, friction: f64) {
            let fabric = Fabric::from_chart(&Chart::stockinette(4, 4).unwrap(), &Geometry::default()).unwrap();
            let params = Params { friction, gravity: 9.81, ..Params::default() };
            let pins = [Pin { node: 0, target: fabric.positions()[0] }];
            let run = |timed: bool| {
                let mut backend = make();
                backend.load(&fabric, &params).unwrap();
                backend.set_pins(&pins).unwrap();
                let times = if timed {
                    Some(backend.advance_timed(40).unwrap())
                } else {
                    backend.advance(40).map(|()| None).unwrap()
                };
                (backend.state().unwrap(), times)
            };
            let (plain, _) = run(false);
            let (timed, times) = run(true);
            let name = make().name();
            assert_eq!(plain, timed, "{name}: timing changed the result");
            let times = times.expect("timed");
            let passes: Vec<&str> = times.parts.iter().map(|p| p.pass).collect();
            let expected: &[&str] = if friction > 0.0 {
                &["contact forces", "block forces", "friction", "move", "pins", "reseat", "sleep"]
            } else {
                &["contact forces", "block forces", "pins", "reseat", "sleep"]
            };
            assert_eq!(passes, expected, "{name} at μ = {friction}");
            let block = &times.parts[1];
            assert_eq!(block.stages.contains(&Stage::Move), friction == 0.0, "{name}: {block:?}");
            assert_eq!(times.substeps, 40);
            assert!(times.total_seconds() > 0.0 && times.total_seconds() <= times.wall_seconds, "{times:?}");
        }
        for friction in [0.3, 0.0] {
            check(Serial::<f32>::new, friction);
            check(Serial::<f64>::new, friction);
            check(|| Rayon::with_threads(2).unwrap(), friction);
        }
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
        let worst = farthest(&a.positions, &b.positions);
        let moved = farthest(&b.positions, fabric.positions());
        assert!(moved > 1e-2, "the patch must move for the comparison to mean anything (moved {moved})");
        assert!(worst < 1e-3 * moved.max(1.0), "f32 drifted {worst} from f64");
    }
}
