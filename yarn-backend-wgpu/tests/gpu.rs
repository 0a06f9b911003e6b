//! The GPU backend's own behaviour on a real adapter: refusals, the
//! fixed-point overflow and divergence reports and restores. Agreement with the CPU is the
//! conformance suite's job (`yarn-gate/tests/conformance.rs`).

use std::sync::Arc;

use yarn_backend_wgpu::{Gpu, Mode, Wgpu, testing, wgpu};
use yarn_model::stages::TimingMethod;
use yarn_model::{Backend, BackendError, Params, State, V3};
use yarn_topology::{Chart, Fabric, Geometry};

/// The shared GPU, or `None` with the skip counted when this machine has
/// no adapter ([`yarn_backend_wgpu::testing`]).
fn gpu() -> Option<Arc<Gpu>> {
    testing::shared_gpu()
}

/// The paper's 3x3 arch: 72 nodes, as the byte counts below expect.
fn patch() -> Fabric {
    Fabric::from_chart(&Chart::stockinette(3, 3).expect("valid size"), &Geometry::paper()).expect("valid chart")
}

#[test]
fn fixed_point_overflow_is_reported_and_the_state_kept() {
    let Some(gpu) = gpu() else { return };
    let fabric = patch();
    let mut backend = Wgpu::with_gpu(gpu, Mode::FixedPointAtomic);
    backend.load(&fabric, &Params::default()).unwrap();
    backend.advance(5).unwrap();
    // One node thrown 10^4 radii away: its springs pull with about 8e6,
    // far past what i32 quanta of 1/4096 hold.
    let mut wild = backend.state().unwrap();
    wild.positions[10] += V3::new(1e4, 0.0, 0.0);
    backend.write_state(&wild).unwrap();
    match backend.advance(10) {
        Err(BackendError::Overflow { first, end, max_force }) => {
            assert_eq!((first, end), (5, 15));
            assert!(max_force > 1e5 && max_force < 1e6, "{max_force}");
        }
        other => panic!("expected an overflow, got {other:?}"),
    }
    assert_eq!(backend.state().unwrap(), wild, "the failing call must leave the state it started from");
    // Back to a sane state, stepping works again.
    backend.write_state(&State::at_rest(&fabric)).unwrap();
    backend.advance(10).unwrap();
}

#[test]
fn gather_has_no_quantum_to_overflow() {
    let Some(gpu) = gpu() else { return };
    let fabric = patch();
    let mut backend = Wgpu::with_gpu(gpu, Mode::Gather);
    backend.load(&fabric, &Params::default()).unwrap();
    let mut wild = State::at_rest(&fabric);
    wild.positions[10] += V3::new(1e4, 0.0, 0.0);
    backend.write_state(&wild).unwrap();
    let forces = backend.forces().unwrap();
    assert!(forces[10].norm() > 1e6, "the spring pulls back hard: {}", forces[10].norm());
    // No overflow: the absurd pull is caught as the divergence it is.
    assert!(matches!(backend.advance(1), Err(BackendError::Diverged { substep: 1, .. })));
    assert_eq!(backend.state().unwrap(), wild);
}

#[test]
fn refusals_name_the_problem_and_keep_the_state() {
    let Some(gpu) = gpu() else { return };
    let mut backend = Wgpu::with_gpu(gpu, Mode::Gather);
    assert_eq!(backend.advance(1), Err(BackendError::NotLoaded));
    let fabric = patch();
    backend.load(&fabric, &Params::default()).unwrap();
    backend.advance(3).unwrap();
    let before = backend.state().unwrap();
    let short = State { positions: vec![V3::zeros(); 2], velocities: vec![V3::zeros(); 2] };
    assert!(matches!(backend.write_state(&short), Err(BackendError::LengthMismatch { what: "positions", .. })));
    assert!(backend.set_contacts_alive(&[true]).is_err());
    assert!(backend.set_params(&Params { substep: 1.0, ..Params::default() }).is_err());
    let bad_pin = yarn_topology::Pin { node: 10_000, target: yarn_topology::Vec3::zeros() };
    assert!(backend.set_pins(&[bad_pin]).is_err());
    assert_eq!(backend.state().unwrap(), before);
    // Pins that are valid hold.
    let target = yarn_topology::Vec3::new(1.0, 2.0, 3.0);
    backend.set_pins(&[yarn_topology::Pin { node: 4, target }]).unwrap();
    backend.advance(20).unwrap();
    let state = backend.state().unwrap();
    assert_eq!(state.positions[4], V3::new(1.0, 2.0, 3.0));
    assert_eq!(state.velocities[4], V3::zeros());
}

/// A device opened at `full`'s limits with `lower` applied.
fn lowered(full: &Gpu, lower: impl FnOnce(&mut wgpu::Limits)) -> Arc<Gpu> {
    let mut limits = full.device().limits();
    lower(&mut limits);
    Gpu::with_limits(limits).expect("lower limits than the adapter's open")
}

/// A fabric over the device's binding or dispatch limit is refused with
/// `TooLarge` naming the limit and both figures, on devices opened with
/// lowered limits, and the fabric loaded before stays loaded.
#[test]
fn a_fabric_over_the_device_limits_is_refused_by_name() {
    let Some(full) = gpu() else { return };
    let (small, large) =
        (patch(), Fabric::from_chart(&Chart::stockinette(10, 10).unwrap(), &Geometry::paper()).unwrap());
    // 72 nodes of 16 bytes, 1,152 bytes, in a binding of at most 1,024.
    let narrow = lowered(&full, |l| l.max_storage_buffer_binding_size = 1024);
    let mut backend = Wgpu::with_gpu(narrow, Mode::Gather);
    match backend.load(&small, &Params::default()) {
        Err(BackendError::TooLarge { what, needed, limit, limit_name }) => {
            assert_eq!((what, needed, limit), ("the node buffer (bytes)", 1152, 1024));
            assert_eq!(limit_name, "max_storage_buffer_binding_size");
        }
        other => panic!("expected TooLarge, got {other:?}"),
    }
    assert_eq!(backend.state(), Err(BackendError::NotLoaded));
    // 800 nodes in a grid of at most 2x2 workgroups of 128 threads.
    let short = lowered(&full, |l| l.max_compute_workgroups_per_dimension = 2);
    let mut backend = Wgpu::with_gpu(short, Mode::FixedPointAtomic);
    backend.load(&small, &Params::default()).unwrap();
    backend.advance(5).unwrap();
    let before = backend.state().unwrap();
    match backend.load(&large, &Params::default()) {
        Err(BackendError::TooLarge { what, needed, limit, limit_name }) => {
            assert_eq!(
                (what, limit, limit_name),
                ("the dispatch (threads)", 512, "max_compute_workgroups_per_dimension")
            );
            assert!(needed >= 800, "{needed} threads");
        }
        other => panic!("expected TooLarge, got {other:?}"),
    }
    assert_eq!(backend.state().unwrap(), before, "the refused load lost the fabric before it");
    backend.advance(5).expect("the fabric before runs on");
}

/// A node flung at an absurd speed, or given a NaN velocity, ends the
/// call with `Diverged` in both modes, naming the node, and the state is
/// as before the call; a sane state then runs on. (One substep: left to
/// run, the flung node would go on to overflow fixed point's forces too,
/// and an overflow is what a batch with both reports.)
#[test]
fn divergence_is_reported_and_the_state_kept() {
    let Some(gpu) = gpu() else { return };
    let fabric = patch();
    for mode in [Mode::Gather, Mode::FixedPointAtomic] {
        for friction in [0.0, 0.3] {
            let mut backend = Wgpu::with_gpu(Arc::clone(&gpu), mode);
            backend.load(&fabric, &Params { friction, ..Params::default() }).unwrap();
            backend.advance(5).unwrap();
            let good = backend.state().unwrap();
            let mut flung = good.clone();
            flung.velocities[10] = V3::new(0.0, 1e7, 0.0);
            backend.write_state(&flung).unwrap();
            match backend.advance(1) {
                Err(BackendError::Diverged { substep: 6, node, speed, limit }) => {
                    assert!(speed > limit, "{mode:?} μ={friction}: node {node} at {speed} under {limit}");
                }
                other => panic!("{mode:?} μ={friction}: expected a divergence, got {other:?}"),
            }
            assert_eq!(backend.state().unwrap(), flung, "{mode:?} μ={friction}: not rolled back");
            let mut nan = good.clone();
            nan.velocities[4].x = f32::NAN;
            backend.write_state(&nan).unwrap();
            match backend.advance(1) {
                Err(BackendError::Diverged { substep: 6, node: 4, speed, .. }) => assert!(speed.is_nan()),
                other => panic!("{mode:?} μ={friction}: expected a divergence, got {other:?}"),
            }
            backend.write_state(&good).unwrap();
            backend.advance(50).expect("a sane state runs on");
        }
    }
}

/// A device lost in the middle of a run comes back as an error from the
/// next call, not a hang or a panic, and the last state copied to the CPU
/// (here by a checkpoint every 20 substeps) is still readable.
#[test]
fn a_lost_device_is_an_error_and_the_last_good_state_stays() {
    // A context of its own: the loss must not touch the shared one.
    let Some(_) = gpu() else { return };
    let gpu = Gpu::new().expect("a second context");
    let mut backend = Wgpu::with_gpu(Arc::clone(&gpu), Mode::Gather);
    let fabric = patch();
    backend.load(&fabric, &Params::default()).unwrap();
    assert_eq!(backend.last_good_state().unwrap().state, State::at_rest(&fabric), "load is the first checkpoint");
    backend.set_checkpoint_every(20);
    backend.advance(10).unwrap();
    assert_eq!(backend.last_good_state().unwrap().substeps, 0, "checkpointed before 20 substeps");
    backend.advance(15).unwrap();
    let checkpoint = backend.last_good_state().unwrap().clone();
    assert_eq!(checkpoint.substeps, 25);
    assert_eq!(checkpoint.state, backend.state().unwrap(), "the checkpoint is not the GPU's state");
    backend.advance(5).unwrap();
    gpu.device().destroy();
    match backend.advance(10) {
        Err(BackendError::Device(message)) => assert!(!message.is_empty()),
        other => panic!("expected a device error, got {other:?}"),
    }
    assert!(matches!(backend.state(), Err(BackendError::Device(_))));
    assert_eq!(backend.last_good_state(), Some(&checkpoint), "the last good state was lost with the device");
}

/// The stage counters time the passes without changing the result: in
/// both modes, by timestamps (where the adapter has them) and by per-pass
/// runs, a timed advance ends bit for bit where an untimed one does, every
/// pass of the substep is named, and a fused substep says it was timed as
/// its unfused passes. Contacts revived half way keep the reseat pass
/// running, which the per-pass runs must put back.
#[test]
fn timed_advance_matches_advance_and_names_every_pass() {
    let Some(gpu) = gpu() else { return };
    let fabric = patch();
    let contacts = fabric.contacts().len();
    let pins = [yarn_topology::Pin { node: 0, target: fabric.positions()[0] }];
    let params = Params { gravity: 9.81, ..Params::default() };
    let run = |mode: Mode, timed: Option<bool>| {
        let mut backend = Wgpu::with_gpu(Arc::clone(&gpu), mode);
        backend.load(&fabric, &params).unwrap();
        backend.set_pins(&pins).unwrap();
        backend.set_contacts_alive(&vec![false; contacts]).unwrap();
        backend.advance(30).unwrap();
        backend.set_contacts_alive(&vec![true; contacts]).unwrap();
        let times = match timed {
            Some(timestamps) => {
                backend.set_timestamps(timestamps);
                Some(backend.advance_timed(20).unwrap())
            }
            None => {
                backend.advance(20).unwrap();
                None
            }
        };
        backend.advance(10).unwrap();
        (backend.state().unwrap(), times)
    };
    for mode in [Mode::Gather, Mode::FixedPointAtomic] {
        let (plain, _) = run(mode, None);
        for timestamps in [true, false] {
            let (timed, times) = run(mode, Some(timestamps));
            let times = times.expect("timed");
            assert_eq!(plain, timed, "{mode:?} (timestamps {timestamps}): timing changed the result");
            let method =
                if timestamps && gpu.timestamps() { TimingMethod::GpuTimestamps } else { TimingMethod::GpuPassRuns };
            assert_eq!(times.method, method);
            let passes: Vec<&str> = times.parts.iter().map(|p| p.pass).collect();
            let expected: &[&str] = match mode {
                Mode::Gather => &["gather.wgsl step", "friction.wgsl", "pins.wgsl", "reseat.wgsl", "check.wgsl"],
                Mode::FixedPointAtomic => &[
                    "fixed.wgsl scatter",
                    "fixed.wgsl step",
                    "friction.wgsl",
                    "pins.wgsl",
                    "reseat.wgsl",
                    "check.wgsl",
                ],
            };
            assert_eq!(passes, expected, "{mode:?} (timestamps {timestamps})");
            assert!(times.parts.iter().all(|p| p.seconds >= 0.0 && p.seconds.is_finite()), "{times:?}");
            assert!(times.total_seconds() > 0.0, "{times:?}");
            assert_eq!(times.note.is_some(), mode == Mode::Gather, "only gather fuses at 72 nodes: {:?}", times.note);
        }
    }
}

/// The chain record's links, in both modes: a ring of 300 nodes (its wrap
/// from node 299 back to node 0 crossing workgroups of 128) then two open
/// yarns end to end, the second starting 0.5 from the first's end. Gather
/// gives `Serial<f32>`'s forces bit for bit, fixed point within its
/// quanta, and in both each yarn's nodes feel exactly what the yarn alone
/// gives them: no segment or joint reaches across a break.
#[test]
fn segments_and_joints_follow_the_yarns_on_the_gpu() {
    use yarn_topology::{FabricParts, Vec3, YarnSpan};
    let Some(gpu) = gpu() else { return };
    let ring: Vec<Vec3> = (0..300)
        .map(|i| std::f64::consts::TAU * f64::from(i) / 300.0)
        .map(|t| Vec3::new(30.0 * t.cos(), 30.0 * t.sin(), 1.5 * (7.0 * t).sin()))
        .collect();
    let wave = |from: f64, n: usize| -> Vec<Vec3> {
        (0..n).map(|i| Vec3::new(from + i as f64, 40.0 + (0.3 * i as f64).sin(), 0.1 * i as f64)).collect()
    };
    let yarns = [(ring, true), (wave(0.0, 40), false), (wave(39.5, 50), false)];
    let fabric = |parts: &[(Vec<Vec3>, bool)]| {
        let (mut positions, mut spans) = (Vec::new(), Vec::new());
        for (nodes, closed) in parts {
            let start = positions.len() as u32;
            positions.extend(nodes);
            spans.push(YarnSpan { start, end: positions.len() as u32, closed: *closed });
        }
        Fabric::from_parts(FabricParts { positions, yarns: spans, ..FabricParts::default() }).expect("valid yarns")
    };
    let all = fabric(&yarns);
    let params = Params { gravity: 9.81, ..Params::default() };
    let forces = |backend: &mut dyn Backend<Real = f32>, fabric: &Fabric| {
        backend.load(fabric, &params).expect("load");
        let mut state = backend.state().expect("state");
        // Off the rest shape by where each node is, the same on its own.
        for p in &mut state.positions {
            *p += V3::new(0.05 * (3.0 * p.x).cos(), 0.07, -0.03 * (2.0 * p.y).sin());
        }
        backend.write_state(&state).expect("write");
        backend.forces().expect("forces")
    };
    let serial = forces(&mut yarn_backend_cpu::Serial::<f32>::new(), &all);
    for mode in [Mode::Gather, Mode::FixedPointAtomic] {
        let mut backend = Wgpu::with_gpu(Arc::clone(&gpu), mode);
        let got = forces(&mut backend, &all);
        if mode == Mode::Gather {
            assert_eq!(got, serial, "gather against serial-f32");
        } else {
            let worst = got.iter().zip(&serial).map(|(a, b)| (a - b).norm()).fold(0.0, f32::max);
            assert!(worst <= 16.0 * 0.5 / 4096.0 + 1e-4, "fixed point off serial-f32 by {worst}");
        }
        for (k, (yarn, part)) in all.yarns().iter().zip(&yarns).enumerate() {
            let alone = forces(&mut backend, &fabric(std::slice::from_ref(part)));
            assert_eq!(&got[yarn.nodes()], alone.as_slice(), "{mode:?}: yarn {k} feels more than itself");
        }
    }
}
