//! Bad input, fuzzed: random charts and sizes (0 and huge included), user
//! parts with bad indices, NaN and infinite coordinates, duplicate nodes and
//! self-contacts, and parameters that are negative, zero, NaN, infinite or
//! extreme, pushed through the public API of the topology, the model and
//! the CPU and GPU backends. Every call must return a value or a typed
//! error; a panic fails the test.
//!
//! Each property counts how many of its inputs reach each layer (a fabric
//! built, parameters the model accepts, a load and an advance on each
//! backend), prints the counts and holds them to floors, so a generator
//! that stops reaching a layer fails instead of fuzzing nothing.

use std::cell::{Cell, RefCell};
use std::sync::Arc;

use proptest::prelude::*;
use proptest::test_runner::{Config, TestRunner};
use yarn_backend_cpu::{Rayon, Reference, Serial};
use yarn_backend_wgpu::{Gpu, Mode, Wgpu};
use yarn_gate::conformance::strategy;
use yarn_model::{Backend, Model, Params, State, V3};
use yarn_topology::{Boundary, Chart, Fabric, FabricParts, Geometry, Pin, Vec3, YarnSpan};

/// A number from the awkward corners and the ordinary middle.
fn awkward() -> impl Strategy<Value = f64> {
    prop_oneof![
        Just(0.0),
        Just(-0.0),
        Just(f64::NAN),
        Just(f64::INFINITY),
        Just(f64::NEG_INFINITY),
        Just(f64::MAX),
        Just(f64::MIN_POSITIVE),
        Just(1e300),
        Just(-1e-300),
        -1e3..1e3f64,
    ]
}

fn params() -> impl Strategy<Value = Params> {
    (prop::array::uniform14(prop_oneof![12 => Just(None), 1 => awkward().prop_map(Some)]), any::<bool>()).prop_map(
        |(v, friction_in_tension)| {
            let d = Params::default();
            let pick = |k: usize, default: f64| v[k].unwrap_or(default);
            Params {
                stretch_stiffness: pick(0, d.stretch_stiffness),
                bend_stiffness: pick(1, d.bend_stiffness),
                rest_curl: pick(2, d.rest_curl),
                contact_stiffness: pick(3, d.contact_stiffness),
                friction: pick(4, d.friction),
                friction_in_tension,
                damping: pick(5, d.damping),
                mass: pick(6, d.mass),
                substep: pick(7, d.substep),
                gravity: pick(8, d.gravity),
                substep_limit: pick(9, d.substep_limit),
                sleep_speed: pick(10, d.sleep_speed),
                self_contact_stiffness: pick(11, d.self_contact_stiffness),
                self_contact_skin: pick(12, d.self_contact_skin),
                collider_stiffness: pick(13, d.collider_stiffness),
            }
        },
    )
}

fn point() -> impl Strategy<Value = Vec3> {
    prop_oneof![
        8 => point_ordinary(),
        1 => (awkward(), awkward(), awkward()).prop_map(|(x, y, z)| Vec3::new(x, y, z)),
    ]
}

fn point_ordinary() -> impl Strategy<Value = Vec3> {
    (-20.0..20.0f64, -20.0..20.0f64, -2.0..2.0f64).prop_map(|(x, y, z)| Vec3::new(x, y, z))
}

/// One way to spoil valid user parts, aimed at one error of
/// [`Fabric::from_parts`] (an awkward value may turn out valid).
#[derive(Debug, Clone)]
enum Flaw {
    /// No nodes at all.
    NoNodes,
    /// Node k repeats the one before it: a zero-length segment.
    Repeat(usize),
    /// Node k at an awkward point.
    Position(usize, Vec3),
    /// A contact naming a node past the end (or far out) at one end.
    ContactPastEnd(u32),
    /// A contact from node k to itself.
    SelfContact(usize),
    /// Contact k repeated, its nodes swapped.
    DuplicateContact(usize),
    /// A pin on a node past the end (or far out).
    PinPastEnd(u32),
    /// A pin toward an awkward target.
    PinTarget(Vec3),
    /// A boundary list of another length.
    Boundary(usize),
    /// An awkward yarn radius.
    Radius(f64),
    /// An awkward course direction.
    Course(Vec3),
    /// Yarn spans spoilt at yarn k: shifted by `shift` nodes (a gap or an
    /// overlap, or past the end), or closed (too short when under 3).
    Yarns(usize, i64),
}

fn flaw() -> impl Strategy<Value = Flaw> {
    let far = || prop_oneof![Just(0u32), Just(u32::MAX)];
    prop_oneof![
        Just(Flaw::NoNodes),
        any::<usize>().prop_map(Flaw::Repeat),
        (any::<usize>(), point()).prop_map(|(k, p)| Flaw::Position(k, p)),
        far().prop_map(Flaw::ContactPastEnd),
        any::<usize>().prop_map(Flaw::SelfContact),
        any::<usize>().prop_map(Flaw::DuplicateContact),
        far().prop_map(Flaw::PinPastEnd),
        point().prop_map(Flaw::PinTarget),
        (0usize..16).prop_map(Flaw::Boundary),
        awkward().prop_map(Flaw::Radius),
        point().prop_map(Flaw::Course),
        (any::<usize>(), prop_oneof![Just(0i64), Just(-1), Just(1), Just(i64::from(u32::MAX))])
            .prop_map(|(k, shift)| Flaw::Yarns(k, shift)),
    ]
}

/// Yarn spans over `n` nodes from `cuts` (each a length and whether the
/// yarn is closed, closed only from 3 nodes), the last yarn taking what is
/// left; none for no cuts, which is one open yarn.
fn yarns_from(n: usize, cuts: &[(usize, bool)]) -> Vec<YarnSpan> {
    let mut yarns = Vec::new();
    let mut start = 0;
    for (k, &(len, closed)) in cuts.iter().enumerate() {
        let len = if k + 1 == cuts.len() { n - start } else { len.min(n - start) };
        if len == 0 {
            break;
        }
        yarns.push(YarnSpan { start: start as u32, end: (start + len) as u32, closed: closed && len >= 3 });
        start += len;
    }
    if start < n {
        yarns.push(YarnSpan::open(start as u32..n as u32));
    }
    if cuts.is_empty() { Vec::new() } else { yarns }
}

/// Valid user parts: 1 to 13 nodes at ordinary points, in one open yarn or
/// several open and closed ones, contacts between distinct nodes (each pair once), pins on
/// nodes with ordinary targets, a boundary list of the right length or
/// none, and an ordinary radius and direction or the defaults.
fn valid_parts() -> impl Strategy<Value = FabricParts> {
    (1usize..14).prop_flat_map(|n| {
        let node = move || 0..n as u32;
        (
            prop::collection::vec(point_ordinary(), n),
            prop::collection::vec((node(), 1..n.max(2) as u32), if n > 1 { 0..10 } else { 0..1 }),
            prop::collection::vec((node(), point_ordinary()), 0..4),
            any::<bool>(),
            prop_oneof![Just(None), (0.1..1.0f64).prop_map(Some)],
            prop_oneof![Just(None), point_ordinary().prop_map(Some)],
            prop::collection::vec((1usize..6, any::<bool>()), 0..4),
        )
            .prop_map(move |(positions, contacts, pins, boundary, yarn_radius, course, cuts)| FabricParts {
                yarns: yarns_from(n, &cuts),
                contacts: strategy::distinct_contacts(contacts.into_iter().map(|(a, step)| [a, (a + step) % n as u32])),
                pins: pins.into_iter().map(|(node, target)| Pin { node, target }).collect(),
                boundary: if boundary { vec![Boundary::INTERIOR; n] } else { Vec::new() },
                positions,
                yarn_radius,
                course,
                wale: None,
            })
    })
}

/// User parts: valid about half the time, otherwise with one [`Flaw`].
fn parts() -> impl Strategy<Value = FabricParts> {
    (valid_parts(), prop_oneof![10 => Just(None), 10 => flaw().prop_map(Some)]).prop_map(|(mut parts, flaw)| {
        let n = parts.positions.len();
        match flaw {
            None => {}
            Some(Flaw::NoNodes) => parts.positions.clear(),
            Some(Flaw::Repeat(k)) if n > 1 => parts.positions[1 + k % (n - 1)] = parts.positions[k % (n - 1)],
            Some(Flaw::Repeat(_)) => parts.positions.push(parts.positions[0]),
            Some(Flaw::Position(k, p)) => parts.positions[k % n] = p,
            Some(Flaw::ContactPastEnd(far)) => parts.contacts.push([0, if far == 0 { n as u32 } else { far }]),
            Some(Flaw::SelfContact(k)) => parts.contacts.push([(k % n) as u32; 2]),
            Some(Flaw::DuplicateContact(k)) => {
                if let Some(&[a, b]) = parts.contacts.get(k % parts.contacts.len().max(1)) {
                    parts.contacts.push([b, a]);
                }
            }
            Some(Flaw::PinPastEnd(far)) => {
                parts.pins.push(Pin { node: if far == 0 { n as u32 } else { far }, target: Vec3::zeros() });
            }
            Some(Flaw::PinTarget(target)) => parts.pins.push(Pin { node: 0, target }),
            Some(Flaw::Boundary(len)) => parts.boundary = vec![Boundary::INTERIOR; len],
            Some(Flaw::Radius(r)) => parts.yarn_radius = Some(r),
            Some(Flaw::Course(c)) => parts.course = Some(c),
            Some(Flaw::Yarns(k, shift)) => {
                if parts.yarns.is_empty() {
                    parts.yarns.push(YarnSpan::open(0..n as u32));
                }
                let count = parts.yarns.len();
                let yarn = &mut parts.yarns[k % count];
                if shift == 0 {
                    yarn.closed = true;
                } else {
                    yarn.end = (i64::from(yarn.end) + shift).clamp(0, i64::from(u32::MAX)) as u32;
                }
            }
        }
        parts
    })
}

/// Contact liveness flags: the fabric's count or a random one.
fn alive() -> impl Strategy<Value = (bool, Vec<bool>)> {
    (any::<bool>(), prop::collection::vec(any::<bool>(), 0..12))
}

fn alive_for(fabric: &Fabric, (fit, bits): &(bool, Vec<bool>)) -> Vec<bool> {
    if *fit && !bits.is_empty() {
        (0..fabric.contacts().len()).map(|k| bits[k % bits.len()]).collect()
    } else {
        bits.clone()
    }
}

/// Inputs per property.
const CASES: u32 = 1000;

fn gpu() -> Option<Arc<Gpu>> {
    yarn_backend_wgpu::testing::shared_gpu()
}

/// How many of one property's inputs reached each layer.
#[derive(Debug, Default)]
struct Reach {
    tried: Cell<u64>,
    /// A fabric was built.
    topology: Cell<u64>,
    /// [`Model::new`] accepted the fabric and the parameters.
    model: Cell<u64>,
    /// Per backend: loads that succeeded, each followed by an advance.
    backends: RefCell<Vec<(String, u64)>>,
}

/// The least a property's inputs must reach, out of [`CASES`].
#[derive(Debug)]
struct Floors {
    topology: u64,
    model: u64,
    /// For every backend, GPU ones included where there is a GPU.
    backend: u64,
}

impl Reach {
    fn bump(counter: &Cell<u64>) {
        counter.set(counter.get() + 1);
    }

    fn ran(&self, name: String) {
        let mut backends = self.backends.borrow_mut();
        match backends.iter_mut().find(|(known, _)| *known == name) {
            Some((_, count)) => *count += 1,
            None => backends.push((name, 1)),
        }
    }

    /// Print the counts beside `floors` and hold them to it; every
    /// backend of `expected` must have run.
    fn check(&self, property: &str, floors: &Floors, expected: &[String]) {
        let tried = self.tried.get();
        eprintln!("fuzz {property}: {tried} inputs");
        let mut layers = vec![("topology".to_string(), self.topology.get(), floors.topology)];
        layers.push(("model".to_string(), self.model.get(), floors.model));
        for name in expected {
            let count = self.backends.borrow().iter().find(|(known, _)| known == name).map_or(0, |(_, c)| *c);
            layers.push((name.clone(), count, floors.backend));
        }
        for (layer, count, floor) in &layers {
            eprintln!("  {layer:>16}: {count:>4} reached (floor {floor})");
        }
        for (layer, count, floor) in layers {
            assert!(count >= floor, "{property}: only {count} of {tried} inputs reached {layer}, floor {floor}");
        }
    }
}

/// The backends every built fabric goes through, by name; the GPU ones
/// only where there is a GPU.
fn backend_names() -> Vec<String> {
    let mut names = vec![Serial::<f32>::new().name(), Serial::<f64>::new().name(), Reference::<f64>::new().name()];
    names.push(Rayon::new().name());
    if let Some(gpu) = gpu() {
        names.push(Wgpu::with_gpu(Arc::clone(&gpu), Mode::Gather).name());
        names.push(Wgpu::with_gpu(gpu, Mode::FixedPointAtomic).name());
    }
    names
}

/// Everything a user can do to a loaded backend, with the fuzzed inputs;
/// each result is either fine or an error, never a panic. A load that
/// succeeds counts toward `reach`.
fn exercise<B: Backend>(
    reach: &Reach,
    mut backend: B,
    fabric: &Fabric,
    params: &Params,
    pins: &[Pin],
    alive: &[bool],
    flung: f64,
) {
    if backend.load(fabric, params).is_err() {
        return;
    }
    let _ = backend.set_params(params);
    let _ = backend.set_pins(pins);
    let _ = backend.set_contacts_alive(alive);
    let _ = backend.advance(5);
    reach.ran(backend.name());
    if let Ok(mut state) = backend.state() {
        if let Some(v) = state.velocities.first_mut() {
            v.x = <B::Real as yarn_model::Real>::of(flung);
        }
        let _ = backend.write_state(&state);
        let _ = backend.advance(3);
        let _ = backend.forces();
    }
    let short = State::<B::Real> { positions: vec![V3::zeros(); 1], velocities: Vec::new() };
    assert!(backend.write_state(&short).is_err() || fabric.node_count() == 1);
    let _ = backend.state();
}

/// A built fabric through the model and every backend.
fn simulate(reach: &Reach, fabric: &Fabric, params: &Params, pins: &[Pin], alive: &[bool], flung: f64) {
    Reach::bump(&reach.topology);
    if Model::<f64>::new(fabric, params).is_ok() {
        Reach::bump(&reach.model);
    }
    exercise(reach, Serial::<f32>::new(), fabric, params, pins, alive, flung);
    exercise(reach, Serial::<f64>::new(), fabric, params, pins, alive, flung);
    exercise(reach, Reference::<f64>::new(), fabric, params, pins, alive, flung);
    exercise(reach, Rayon::new(), fabric, params, pins, alive, flung);
    if let Some(gpu) = gpu() {
        exercise(reach, Wgpu::with_gpu(Arc::clone(&gpu), Mode::Gather), fabric, params, pins, alive, flung);
        exercise(reach, Wgpu::with_gpu(gpu, Mode::FixedPointAtomic), fabric, params, pins, alive, flung);
    }
}

fn runner() -> TestRunner {
    // An integration test has no lib.rs for proptest to file regressions
    // beside; a failure prints its minimal input instead.
    TestRunner::new(Config { cases: CASES, failure_persistence: None, ..Config::default() })
}

fn pins() -> impl Strategy<Value = Vec<Pin>> {
    prop::collection::vec((0u32..16, point()).prop_map(|(node, target)| Pin { node, target }), 0..3)
}

/// Half of the fewest that four runs of the 1,000 charts reached: 314–319
/// built, 166–190 accepted by the model, and as many on every backend
/// (lavapipe for the GPU ones).
const CHART_FLOORS: Floors = Floors { topology: 157, model: 83, backend: 83 };

/// Half of the fewest that four runs of the 1,000 user parts reached:
/// 657–671 built, 375–398 accepted by the model, and as many on every
/// backend (lavapipe for the GPU ones).
const PART_FLOORS: Floors = Floors { topology: 328, model: 187, backend: 187 };

#[test]
fn charts_of_any_size_build_or_say_why() {
    let size = || prop_oneof![8 => 1usize..6, 1 => Just(0usize), 1 => Just(1 << 40), 1 => Just(usize::MAX)];
    let inputs = (
        size(),
        size(),
        prop::array::uniform4(prop_oneof![6 => Just(None), 1 => awkward().prop_map(Some)]),
        params(),
        pins(),
        alive(),
        awkward(),
    );
    let reach = Reach::default();
    runner()
        .run(&inputs, |(width, height, geometry, params, pins, alive, flung)| {
            Reach::bump(&reach.tried);
            let d = Geometry::default();
            let g = Geometry {
                stitch_width: geometry[0].unwrap_or(d.stitch_width),
                stitch_height: geometry[1].unwrap_or(d.stitch_height),
                yarn_radius: geometry[2].unwrap_or(d.yarn_radius),
                loop_height: geometry[3].unwrap_or(d.loop_height),
                ..d
            };
            if let Ok(chart) = Chart::stockinette(width, height)
                && let Ok(fabric) = Fabric::from_chart(&chart, &g)
            {
                prop_assert!(fabric.node_count() > 0);
                prop_assert!(fabric.positions().iter().all(|p| p.iter().all(|c| c.is_finite())));
                simulate(&reach, &fabric, &params, &pins, &alive_for(&fabric, &alive), flung);
            }
            Ok(())
        })
        .unwrap();
    reach.check("charts", &CHART_FLOORS, &backend_names());
}

#[test]
fn user_parts_and_parameters_never_panic() {
    let inputs = (parts(), params(), pins(), alive(), awkward());
    let reach = Reach::default();
    runner()
        .run(&inputs, |(parts, params, pins, alive, flung)| {
            Reach::bump(&reach.tried);
            let _ = params.validate();
            if let Ok(fabric) = Fabric::from_parts(parts) {
                simulate(&reach, &fabric, &params, &pins, &alive_for(&fabric, &alive), flung);
            }
            Ok(())
        })
        .unwrap();
    reach.check("user parts", &PART_FLOORS, &backend_names());
}
