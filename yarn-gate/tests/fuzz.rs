//! Bad input, fuzzed: random charts and sizes (0 and huge included), user
//! parts with bad indices, NaN and infinite coordinates, duplicate nodes and
//! self-contacts, and parameters that are negative, zero, NaN, infinite or
//! extreme, pushed through the public API of the topology, the model and
//! the CPU and GPU backends. Every call must return a value or a typed
//! error; a panic fails the test. The counts of inputs tried are printed.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use proptest::prelude::*;
use yarn_backend_cpu::{Reference, Serial};
use yarn_backend_wgpu::{Gpu, Mode, Wgpu};
use yarn_model::{Backend, Params, State, V3};
use yarn_topology::{Boundary, Chart, Fabric, FabricParts, Geometry, Pin, Vec3};

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
    (prop::array::uniform11(prop_oneof![12 => Just(None), 1 => awkward().prop_map(Some)])).prop_map(|v| {
        let d = Params::default();
        let pick = |k: usize, default: f64| v[k].unwrap_or(default);
        Params {
            stretch_stiffness: pick(0, d.stretch_stiffness),
            bend_stiffness: pick(1, d.bend_stiffness),
            rest_curl: pick(2, d.rest_curl),
            contact_stiffness: pick(3, d.contact_stiffness),
            friction: pick(4, d.friction),
            damping: pick(5, d.damping),
            mass: pick(6, d.mass),
            substep: pick(7, d.substep),
            gravity: pick(8, d.gravity),
            substep_limit: pick(9, d.substep_limit),
            sleep_speed: pick(10, d.sleep_speed),
        }
    })
}

fn point() -> impl Strategy<Value = Vec3> {
    prop_oneof![
        8 => point_ordinary(),
        1 => (awkward(), awkward(), awkward()).prop_map(|(x, y, z)| Vec3::new(x, y, z)),
    ]
}

/// User parts: a few nodes (none included), some repeated, contacts and
/// pins whose indices are mostly in range but may be past the end or equal,
/// boundary lists of any length, and odd radii and directions.
fn parts() -> impl Strategy<Value = FabricParts> {
    (0usize..14)
        .prop_flat_map(|n| {
            // Mostly valid indices, sometimes one past the end or far out.
            let index = move || prop_oneof![10 => 0..(n.max(1) as u32), 1 => Just(n as u32), 1 => Just(u32::MAX)];
            (
                prop::collection::vec(
                    (prop_oneof![20 => point_ordinary(), 1 => point()], prop::bool::weighted(0.05)),
                    n,
                ),
                prop::collection::vec((index(), index()), 0..10),
                prop::collection::vec((index(), point()), 0..4),
                prop_oneof![6 => Just(None), 1 => (0usize..16).prop_map(Some)],
                prop_oneof![6 => Just(None), 1 => awkward().prop_map(Some), 2 => (0.1..1.0f64).prop_map(Some)],
                prop_oneof![6 => Just(None), 1 => point().prop_map(Some)],
            )
        })
        .prop_map(|(nodes, contacts, pins, boundary, yarn_radius, course)| {
            let mut positions: Vec<Vec3> = Vec::new();
            for (p, repeat) in nodes {
                // A repeated node makes a zero-length segment.
                positions.push(if repeat { positions.last().copied().unwrap_or(p) } else { p });
            }
            FabricParts {
                positions,
                contacts: contacts.into_iter().map(|(a, b)| [a, b]).collect(),
                pins: pins.into_iter().map(|(node, target)| Pin { node, target }).collect(),
                boundary: boundary.map(|n| vec![Boundary::INTERIOR; n]).unwrap_or_default(),
                yarn_radius,
                course,
                wale: None,
            }
        })
}

fn point_ordinary() -> impl Strategy<Value = Vec3> {
    (-20.0..20.0f64, -20.0..20.0f64, -2.0..2.0f64).prop_map(|(x, y, z)| Vec3::new(x, y, z))
}

/// Inputs per property.
const CASES: u32 = 1000;

static CHARTS: AtomicU64 = AtomicU64::new(0);
static PARTS: AtomicU64 = AtomicU64::new(0);
static RUNS: AtomicU64 = AtomicU64::new(0);

fn gpu() -> Option<Arc<Gpu>> {
    yarn_backend_wgpu::testing::shared_gpu()
}

/// Everything a user can do to a loaded backend, with the fuzzed inputs;
/// each result is either fine or an error, never a panic.
fn exercise<B: Backend>(mut backend: B, fabric: &Fabric, params: &Params, pins: &[Pin], alive: &[bool], flung: f64) {
    if backend.load(fabric, params).is_err() {
        return;
    }
    let _ = backend.set_params(params);
    let _ = backend.set_pins(pins);
    let _ = backend.set_contacts_alive(alive);
    let _ = backend.advance(5);
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
    RUNS.fetch_add(1, Ordering::Relaxed);
}

proptest! {
    #![proptest_config(ProptestConfig { cases: CASES, ..ProptestConfig::default() })]

    #[test]
    fn charts_of_any_size_build_or_say_why(
        width in prop_oneof![0usize..6, Just(1 << 40), Just(usize::MAX)],
        height in prop_oneof![0usize..6, Just(1 << 40), Just(usize::MAX)],
        geometry in prop::array::uniform4(prop_oneof![3 => Just(None), 1 => awkward().prop_map(Some)]),
    ) {
        let d = Geometry::default();
        let g = Geometry {
            stitch_width: geometry[0].unwrap_or(d.stitch_width),
            stitch_height: geometry[1].unwrap_or(d.stitch_height),
            yarn_radius: geometry[2].unwrap_or(d.yarn_radius),
            ..d
        };
        CHARTS.fetch_add(1, Ordering::Relaxed);
        if let Ok(chart) = Chart::stockinette(width, height)
            && let Ok(fabric) = Fabric::from_chart(&chart, &g)
        {
            prop_assert!(fabric.node_count() > 0);
            prop_assert!(fabric.positions().iter().all(|p| p.iter().all(|c| c.is_finite())));
        }
    }

    #[test]
    fn user_parts_and_parameters_never_panic(
        parts in parts(),
        params in params(),
        pins in prop::collection::vec((0u32..16, point()), 0..3),
        alive in prop::collection::vec(any::<bool>(), 0..12),
        flung in awkward(),
    ) {
        if PARTS.fetch_add(1, Ordering::Relaxed) + 1 == u64::from(CASES) {
            eprintln!(
                "fuzz: {} chart inputs and {CASES} user-part inputs so far; {} backend runs on the parts that built",
                CHARTS.load(Ordering::Relaxed),
                RUNS.load(Ordering::Relaxed)
            );
        }
        let pins: Vec<Pin> = pins.into_iter().map(|(node, target)| Pin { node, target }).collect();
        let _ = params.validate();
        if let Ok(fabric) = Fabric::from_parts(parts) {
            exercise(Serial::<f32>::new(), &fabric, &params, &pins, &alive, flung);
            exercise(Serial::<f64>::new(), &fabric, &params, &pins, &alive, flung);
            exercise(Reference::<f64>::new(), &fabric, &params, &pins, &alive, flung);
            if let Some(gpu) = gpu() {
                exercise(Wgpu::with_gpu(Arc::clone(&gpu), Mode::Gather), &fabric, &params, &pins, &alive, flung);
                exercise(Wgpu::with_gpu(gpu, Mode::FixedPointAtomic), &fabric, &params, &pins, &alive, flung);
            }
        }
    }
}
