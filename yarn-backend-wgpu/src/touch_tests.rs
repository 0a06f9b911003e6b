//! The self-contact list passes against their CPU twins
//! (`yarn_model::self_contact::grid`), and the lists' growth.

use std::sync::Arc;

use yarn_backend_cpu::Serial;
use yarn_model::self_contact::grid;
use yarn_model::{Backend, BackendError, Params, State, V3};
use yarn_topology::{Chart, Fabric, FabricParts, Geometry, Vec3, YarnSpan};

use crate::bindings::rows;
use crate::fabric::FIRST_SLOTS;
use crate::{Gpu, Mode, Raised, Wgpu, testing};

/// A 3x3 stockinette with each node moved up to `amount` along each axis
/// and then every position scaled by `squeeze` about the origin.
fn crumpled(amount: f32, squeeze: f32) -> (Fabric, State<f32>) {
    let fabric = Fabric::from_chart(&Chart::stockinette(3, 3).unwrap(), &Geometry::default()).unwrap();
    let mut state = State::<f32>::at_rest(&fabric);
    let mut seed = 0x2545_f491_4f6c_dd1du64;
    for p in &mut state.positions {
        for k in 0..3 {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            p[k] = (p[k] + ((seed >> 40) as f32 / (1u64 << 24) as f32 - 0.5) * 2.0 * amount) * squeeze;
        }
    }
    (fabric, state)
}

/// The GPU's lists at the positions loaded: per node, the segment's
/// candidates and the anchor.
fn gpu_lists(backend: &Wgpu) -> (Vec<Vec<u32>>, Vec<V3<f32>>) {
    let loaded = backend.loaded.as_ref().unwrap();
    let n = loaded.model.node_count();
    let bytes = loaded.read(&loaded.buffers.lists, crate::bindings::lists_bytes(n, loaded.slots)).unwrap();
    let words: Vec<u32> = bytemuck::pod_collect_to_vec(&bytes);
    let field = |i: usize, row: usize| words[rows::at(n, i, row)];
    let lists =
        (0..n).map(|i| (0..field(i, rows::COUNT) as usize).map(|k| field(i, rows::SLOTS + k)).collect()).collect();
    let anchor = |i: usize, c: usize| f32::from_bits(field(i, rows::ANCHOR + c));
    let anchors = (0..n).map(|i| V3::new(anchor(i, 0), anchor(i, 1), anchor(i, 2))).collect();
    (lists, anchors)
}

fn gpu() -> Option<Arc<Gpu>> {
    testing::shared_gpu()
}

/// Load `fabric` into `backend` at `state` under `params`. A crumpled state
/// has yarn through yarn, which a backend with self-contact on refuses to
/// be given (`Interpenetrating`), so it is written with self-contact off
/// and then turned on.
fn place(backend: &mut dyn Backend<Real = f32>, fabric: &Fabric, params: &Params, state: &State<f32>) {
    backend.load(fabric, &Params { self_contact_stiffness: 0.0, ..*params }).unwrap();
    backend.write_state(state).unwrap();
    backend.set_params(params).unwrap();
}

/// `grid_insert.wgsl` and `grid_find.wgsl` build the twins' lists entry for
/// entry, at rest, crumpled, and with yarn pulled out long across the patch
/// (the long list), whatever order their atomics ran in, and anchor every
/// node where it is.
#[test]
fn the_gpu_lists_are_the_twins() {
    let Some(gpu) = gpu() else { return };
    let params = Params { self_contact_stiffness: 800.0, ..Params::default() };
    for (amount, pulled) in [(0.0, false), (1.8, false), (0.5, true)] {
        let (fabric, mut state) = crumpled(amount, 1.0);
        if pulled {
            for (node, by) in [(30, 8.0), (31, -6.0), (100, 12.0)] {
                state.positions[node] += V3::new(by, 0.0, 0.5 * by);
            }
        }
        let mut backend = Wgpu::with_gpu(Arc::clone(&gpu), Mode::Gather);
        place(&mut backend, &fabric, &params, &state);
        backend.forces().unwrap();
        let (lists, anchors) = gpu_lists(&backend);
        let twins = grid::lists(backend.model().unwrap(), &state.positions).unwrap();
        assert_eq!(lists, twins, "amount {amount}");
        assert_eq!(anchors, state.positions);
        assert!(amount == 0.0 || twins.iter().map(Vec::len).sum::<usize>() > 200);
    }
}

/// A pin whose target lies far from where its node was is watched where
/// the pin puts the node, not only where the move took it, so the GPU's
/// lists see the pairs the pin brought into reach, as `Serial<f32>`'s do.
/// Regression: `pins.wgsl` did not watch its nodes, so the substep after a
/// target was set ran on lists built before the pin moved its node, and a
/// pair that pushed on the CPU added nothing here. The pin moves its node
/// at the end of the batch's first substep, which may rebuild, and the
/// next may not: so the batch was late to rebuild, and ran again with a
/// rebuild check every substep.
#[test]
fn a_node_pinned_far_away_is_watched_where_the_pin_puts_it() {
    let Some(gpu) = gpu() else { return };
    let params = Params { self_contact_stiffness: 800.0, sleep_speed: 0.0, substep: 1.0 / 6000.0, ..Params::default() };
    let (fabric, state) = crumpled(0.0, 1.0);
    let model = yarn_model::Model::<f32>::new(&fabric, &params).unwrap();
    let r = model.contact_rule().radius();
    let pairs_at = |x: &[V3<f32>], skin: f64| {
        let mut pairs = Vec::new();
        yarn_model::self_contact::find_pairs(&model, x, skin, &mut pairs);
        pairs
    };
    let candidates = pairs_at(&state.positions, params.self_contact_skin * r);
    // The first node and axis whose move by 0.8 r brings into touch a pair
    // that was beyond the lists' reach, without yarn through yarn.
    let axes = [V3::x(), -V3::x(), V3::y(), -V3::y(), V3::z(), -V3::z()];
    let (node, target) = (0..fabric.node_count())
        .flat_map(|n| axes.iter().map(move |&axis| (n, axis)))
        .find_map(|(n, axis)| {
            let mut x = state.positions.clone();
            x[n] += axis * (0.8 * r) as f32;
            let reached = pairs_at(&x, 0.0).iter().any(|pair| !candidates.contains(pair));
            (reached && model.check_apart(&x).is_ok()).then_some((n, x[n]))
        })
        .expect("some node's move brings a far pair into touch");
    let pin = yarn_topology::Pin {
        node: node as u32,
        target: yarn_topology::Vec3::new(target.x.into(), target.y.into(), target.z.into()),
    };
    let mut backend = Wgpu::with_gpu(gpu, Mode::Gather);
    let mut serial = Serial::<f32>::new();
    for b in [&mut backend as &mut dyn Backend<Real = f32>, &mut serial] {
        place(b, &fabric, &params, &state);
        b.advance(2).unwrap();
        b.set_pins(&[pin]).unwrap();
        b.advance(30).unwrap();
    }
    assert_eq!(backend.state().unwrap(), serial.state().unwrap());
    assert!(backend.loaded.as_ref().unwrap().every_substep_until > 2, "the batch was not late");
}

/// A pinned node flung at 100 times the divergence speed, with
/// self-contact and friction on, is stopped by its pin in the same
/// substep and has not diverged: the GPU runs on, to `Serial<f32>`'s state
/// bit for bit, as the CPU does. Regression: the per-substep watch flagged
/// the node before its pin stopped it, and the batch failed with "node 0
/// reached speed NaN".
#[test]
fn a_node_its_pin_stops_has_not_diverged() {
    let Some(gpu) = gpu() else { return };
    let params = Params { self_contact_stiffness: 800.0, ..Params::default() };
    let (fabric, state) = crumpled(0.0, 1.0);
    let pin = yarn_topology::Pin { node: 10, target: fabric.positions()[10] };
    let mut backend = Wgpu::with_gpu(gpu, Mode::Gather);
    let mut serial = Serial::<f32>::new();
    for b in [&mut backend as &mut dyn Backend<Real = f32>, &mut serial] {
        place(b, &fabric, &params, &state);
        b.set_pins(&[pin]).unwrap();
        b.advance(5).unwrap();
        let mut flung = b.state().unwrap();
        flung.velocities[10].y = 100.0 * b.model().unwrap().divergence_speed() as f32;
        b.write_state(&flung).unwrap();
        let name = b.name();
        b.advance(3).unwrap_or_else(|e| panic!("{name}: {e}"));
    }
    assert_eq!(backend.state().unwrap().velocities[10], V3::zeros(), "the pin stops its node");
    assert_eq!(backend.state().unwrap(), serial.state().unwrap());
}

/// A closed yarn's first node takes the sums of the segment that closes
/// the yarn, which no thread beside it has (`gather.wgsl` and
/// `friction.wgsl` sum it again there): rings of 8 nodes lie along an open
/// yarn of 300, each ring's closing segment parallel to it 1.5 r above and
/// sliding along it, so that segment pushes and rubs. Forces and a
/// trajectory are `Serial<f32>`'s bit for bit.
#[test]
fn a_closed_yarns_first_node_takes_the_segment_that_closes_it() {
    let Some(gpu) = gpu() else { return };
    let r = 0.5;
    let mut positions: Vec<Vec3> = (0..300).map(|i| Vec3::new(f64::from(i), 0.0, 0.0)).collect();
    let mut yarns = vec![YarnSpan { start: 0, end: 300, closed: false }];
    let (ring, step) = (2.0, std::f64::consts::TAU / 8.0);
    let centre_height = 1.5 * r + ring * (step / 2.0).cos();
    for centre in [20.0, 95.0, 130.0, 250.0] {
        let start = positions.len() as u32;
        // Node 0 just right of the bottom, node 7 just left: 7 to 0 closes it.
        positions.extend((0..8).map(|k| {
            let angle = -std::f64::consts::FRAC_PI_2 + step / 2.0 + step * f64::from(k);
            Vec3::new(centre + ring * angle.cos(), centre_height + ring * angle.sin(), 0.0)
        }));
        yarns.push(YarnSpan { start, end: start + 8, closed: true });
    }
    let parts = FabricParts { positions, yarns, yarn_radius: Some(r), ..FabricParts::default() };
    let fabric = Fabric::from_parts(parts).unwrap();
    let params = Params { self_contact_stiffness: 800.0, friction: 0.5, sleep_speed: 0.0, ..Params::default() };
    let mut state = State::<f32>::at_rest(&fabric);
    for v in &mut state.velocities[300..] {
        *v = V3::new(0.5, -0.2, 0.0);
    }
    let mut backend = Wgpu::with_gpu(Arc::clone(&gpu), Mode::Gather);
    let mut serial = Serial::<f32>::new();
    for b in [&mut backend as &mut dyn Backend<Real = f32>, &mut serial] {
        place(b, &fabric, &params, &state);
    }
    let forces = serial.forces().unwrap();
    assert!(forces[300].norm() > 0.0, "the closing segment pushes the ring's first node");
    assert_eq!(backend.forces().unwrap(), forces);
    backend.advance(20).unwrap();
    serial.advance(20).unwrap();
    assert_eq!(backend.state().unwrap(), serial.state().unwrap());
}

/// A crush that puts more candidates near a segment than the lists hold
/// grows them and runs the batch again, to `Serial<f32>`'s forces and
/// trajectory bit for bit; on a device whose bindings cannot hold lists
/// that long it is refused by name, with the state kept.
#[test]
fn a_crush_grows_the_lists_or_is_refused_by_name() {
    let Some(gpu) = gpu() else { return };
    let params = Params { self_contact_stiffness: 200.0, sleep_speed: 0.0, substep: 1.0 / 6000.0, ..Params::default() };
    let (fabric, state) = crumpled(0.5, 0.35);
    let twins = grid::lists(&yarn_model::Model::<f32>::new(&fabric, &params).unwrap(), &state.positions).unwrap();
    let most = twins.iter().map(Vec::len).max().unwrap();
    assert!(most > FIRST_SLOTS as usize, "the crush puts {most} candidates near one segment");
    let mut backend = Wgpu::with_gpu(Arc::clone(&gpu), Mode::Gather);
    let mut serial = Serial::<f32>::new();
    for b in [&mut backend as &mut dyn Backend<Real = f32>, &mut serial] {
        place(b, &fabric, &params, &state);
    }
    assert_eq!(backend.forces().unwrap(), serial.forces().unwrap());
    let slots = backend.loaded.as_ref().unwrap().slots;
    assert!(slots as usize >= most && slots > FIRST_SLOTS, "{slots} slots for {most} candidates");
    backend.advance(20).unwrap();
    serial.advance(20).unwrap();
    assert_eq!(backend.state().unwrap(), serial.state().unwrap());

    // Lists of 16 slots fit a binding of this size; 32 do not.
    let bytes = crate::bindings::lists_bytes(fabric.node_count(), FIRST_SLOTS);
    let mut limits = gpu.device().limits();
    limits.max_storage_buffer_binding_size = bytes.next_multiple_of(256);
    let narrow = Gpu::with_limits(limits).expect("lower limits than the adapter's open");
    let mut backend = Wgpu::with_gpu(narrow, Mode::Gather);
    place(&mut backend, &fabric, &params, &state);
    match backend.advance(5) {
        Err(BackendError::TooLarge { what, needed, limit, limit_name }) => {
            assert_eq!(
                (what, limit_name),
                ("the self-contact candidate lists (bytes)", "max_storage_buffer_binding_size")
            );
            assert!(needed > limit, "{needed} bytes in {limit}");
        }
        other => panic!("expected TooLarge, got {other:?}"),
    }
    assert_eq!(backend.state().unwrap(), state, "the refused batch is put back");
}

/// Where the batches leave their status on the GPU (the browser, where
/// nothing may wait), a crush does not fail the advance: the batch runs
/// without the candidates its lists had no room for, and
/// [`Wgpu::read_raised`] then says how many the most crowded segment had,
/// once. [`Wgpu::grow_lists`] makes room, after which the forces and a
/// trajectory are `Serial<f32>`'s bit for bit and nothing more is raised.
#[test]
fn where_nothing_may_wait_a_crush_is_raised_and_the_lists_grow() {
    let Some(gpu) = gpu() else { return };
    let params = Params { self_contact_stiffness: 200.0, sleep_speed: 0.0, substep: 1.0 / 6000.0, ..Params::default() };
    let (fabric, state) = crumpled(0.5, 0.35);
    let twins = grid::lists(&yarn_model::Model::<f32>::new(&fabric, &params).unwrap(), &state.positions).unwrap();
    let most = twins.iter().map(Vec::len).max().unwrap() as u32;
    let mut backend = Wgpu::with_gpu(Arc::clone(&gpu), Mode::Gather);
    place(&mut backend, &fabric, &params, &state);
    backend.loaded.as_mut().unwrap().deferred_status = true;
    backend.advance(1).unwrap();
    assert_eq!(backend.list_slots(), Some(FIRST_SLOTS), "the lists grew without being asked");
    let raised = pollster::block_on(backend.read_raised().unwrap()).unwrap();
    assert_eq!(raised, Raised { first: 0, end: 1, crowded: Some(most), ..Raised::default() });
    let again = pollster::block_on(backend.read_raised().unwrap()).unwrap();
    assert_eq!(again, Raised { first: 1, end: 1, ..Raised::default() }, "a read did not clear the status");

    let slots = backend.grow_lists(most).unwrap();
    assert!(slots >= most && backend.list_slots() == Some(slots), "{slots} slots for {most} candidates");
    let crowded = backend.state().unwrap();
    let mut serial = Serial::<f32>::new();
    place(&mut serial, &fabric, &params, &crowded);
    assert_eq!(backend.forces().unwrap(), serial.forces().unwrap());
    backend.advance(20).unwrap();
    serial.advance(20).unwrap();
    assert_eq!(backend.state().unwrap(), serial.state().unwrap());
    let raised = pollster::block_on(backend.read_raised().unwrap()).unwrap();
    assert!(raised.is_clear() && (raised.first, raised.end) == (1, 21), "{raised:?}");
}

/// Run `kernel` (a WGSL entry point `main` over `cases` threads that reads
/// `input` and writes `output`, `outputs` vec4s a case) after the prelude,
/// the lists' arithmetic and `touch.wgsl`, with `backend`'s parameters.
fn run_kernel(backend: &Wgpu, kernel: &str, input: &[[f32; 4]], cases: usize, outputs: usize) -> Vec<[f32; 4]> {
    use wgpu::util::DeviceExt;
    let loaded = backend.loaded.as_ref().unwrap();
    let device = &loaded.gpu.device;
    let source = [crate::shaders::COMMON, crate::shaders::LISTS, crate::shaders::TOUCH, kernel].join("\n");
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("pair kernel"),
        source: wgpu::ShaderSource::Wgsl(source.into()),
    });
    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: None,
        layout: None,
        module: &module,
        entry_point: Some("main"),
        compilation_options: Default::default(),
        cache: None,
    });
    let params = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: None,
        contents: bytemuck::bytes_of(&loaded.gpu_params()),
        usage: wgpu::BufferUsages::UNIFORM,
    });
    let input = crate::bindings::storage(device, "input", input);
    let bytes = (cases * outputs * 16) as u64;
    let output = device.create_buffer(&wgpu::BufferDescriptor {
        label: None,
        size: bytes,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: None,
        layout: &pipeline.get_bind_group_layout(0),
        entries: &[
            wgpu::BindGroupEntry { binding: 0, resource: params.as_entire_binding() },
            wgpu::BindGroupEntry { binding: 1, resource: input.as_entire_binding() },
            wgpu::BindGroupEntry { binding: 2, resource: output.as_entire_binding() },
        ],
    });
    let mut encoder = device.create_command_encoder(&Default::default());
    {
        let mut pass = encoder.begin_compute_pass(&Default::default());
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &group, &[]);
        pass.dispatch_workgroups(cases.div_ceil(64) as u32, 1, 1);
    }
    loaded.gpu.queue.submit([encoder.finish()]);
    bytemuck::pod_collect_to_vec(&loaded.read(&output, bytes).unwrap())
}

/// The pair arithmetic of `touch.wgsl` (closest points, the push, the
/// friction changes) and the colliders' of `common.wgsl` give the CPU's
/// numbers bit for bit on random pairs of segments in and out of reach, as
/// the conformance suite needs of whole substeps; a mismatch is counted per
/// quantity, so a compiler that rounds one step its own way shows where.
#[test]
fn the_pair_arithmetic_is_the_cpus_bit_for_bit() {
    use yarn_model::step::{collider_friction, self_contact_friction};
    use yarn_model::terms::{closest_gap, self_contact_forces};
    use yarn_model::{Collider, Plane};
    let Some(gpu) = gpu() else { return };
    let params = Params { self_contact_stiffness: 800.0, friction: 0.3, ..Params::default() };
    let (fabric, _) = crumpled(0.0, 1.0);
    let mut backend = Wgpu::with_gpu(gpu, Mode::Gather);
    backend.load(&fabric, &params).unwrap();
    let floor = Plane { normal: yarn_topology::Vec3::new(0.2, 1.0, -0.1), ..Plane::floor(0.3) };
    backend.set_colliders(&[Collider::Plane(floor)]).unwrap();
    let model = backend.model().unwrap().clone();
    let cases = 4096;
    let mut seed = 0x9e37_79b9_7f4a_7c15u64;
    let mut next = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0
    };
    // Per case: p0, p1, q0, q1, then their velocities.
    let base = [[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.6, -1.0], [0.0, 1.6, 1.0]];
    let mut input = Vec::with_capacity(8 * cases);
    for _ in 0..cases {
        input.extend(base.map(|b| [b[0] + 0.4 * next(), b[1] + 0.4 * next(), b[2] + 0.4 * next(), 0.0]));
        input.extend((0..4).map(|_| [5.0 * next(), 5.0 * next(), 5.0 * next(), 0.0]));
    }
    let kernel = "
@group(0) @binding(0) var<uniform> p: Params;
@group(0) @binding(1) var<storage, read> x: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read_write> v: array<vec4<f32>>;
var<private> lists: array<u32, 4>;
fn v_star(j: u32) -> vec3<f32> { return vec3<f32>(0.0); }
@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let b = 8u * id.x;
    let at = Quad(x[b].xyz, x[b + 1u].xyz, x[b + 2u].xyz, x[b + 3u].xyz);
    let w = Quad(x[b + 4u].xyz, x[b + 5u].xyz, x[b + 6u].xyz, x[b + 7u].xyz);
    let c = closest_gap(at.p0, at.p1, at.q0, at.q1);
    let f = pair_forces(at.p0, at.p1, at.q0, at.q1);
    let dv = pair_friction(at, w, sharing_of(id.x));
    let o = 15u * id.x;
    v[o] = vec4<f32>(c.gap, c.s);
    v[o + 1u] = vec4<f32>(c.t, 0.0, 0.0, 0.0);
    v[o + 2u] = vec4<f32>(f.p0, 0.0);
    v[o + 3u] = vec4<f32>(f.p1, 0.0);
    v[o + 4u] = vec4<f32>(f.q0, 0.0);
    v[o + 5u] = vec4<f32>(f.q1, 0.0);
    v[o + 6u] = vec4<f32>(dv.p0, 0.0);
    v[o + 7u] = vec4<f32>(dv.p1, 0.0);
    v[o + 8u] = vec4<f32>(dv.q0, 0.0);
    v[o + 9u] = vec4<f32>(dv.q1, 0.0);
    v[o + 10u] = vec4<f32>(with_colliders(vec3<f32>(0.0), at.p0), 0.0);
    v[o + 11u] = vec4<f32>(collider_friction(at.p0, w.p0), 0.0);
    let s = p.surfaces[0];
    let slip = w.p0 - mul3(s.normal, dot3(s.normal, w.p0));
    v[o + 12u] = vec4<f32>(slip, dot3(s.normal, at.p0) - s.offset);
    // A segment's sums over three partners, as a node gathers them: this
    // case's pair and the next two cases'.
    var push = vec3<f32>(0.0);
    var drag = vec3<f32>(0.0);
    for (var k = 0u; k < 3u; k++) {
        let m = (id.x + k) % (arrayLength(&x) / 8u);
        let e = 8u * m;
        let pair = Quad(x[e].xyz, x[e + 1u].xyz, x[e + 2u].xyz, x[e + 3u].xyz);
        let speed = Quad(x[e + 4u].xyz, x[e + 5u].xyz, x[e + 6u].xyz, x[e + 7u].xyz);
        push += last_share(pair_forces(pair.p0, pair.p1, pair.q0, pair.q1), false);
        drag += first_share(pair_friction(pair, speed, sharing_of(m)), true);
    }
    v[o + 13u] = vec4<f32>(push, 0.0);
    v[o + 14u] = vec4<f32>(drag, 0.0);
}
// Shared with 1 to 7 pairs.
fn sharing_of(m: u32) -> f32 { return f32(1u + m % 7u); }";
    let out = run_kernel(&backend, kernel, &input, cases, 15);
    let c = model.coeffs();
    let (r, reach) = (model.contact_rule().radius() as f32, (2.0 * model.contact_rule().radius()) as f32);
    // As the kernel's `sharing_of`.
    let sharing_of = |m: usize| (1 + m % 7) as f32;
    let mut wrong = std::collections::BTreeMap::<&str, usize>::new();
    let mut touching = 0;
    for k in 0..cases {
        let v3 = |i: usize| V3::new(input[8 * k + i][0], input[8 * k + i][1], input[8 * k + i][2]);
        let o = |i: usize| V3::new(out[15 * k + i][0], out[15 * k + i][1], out[15 * k + i][2]);
        let (x, w) = ([v3(0), v3(1), v3(2), v3(3)], [v3(4), v3(5), v3(6), v3(7)]);
        let (gap, s, t) = closest_gap(&x[0], &x[1], &x[2], &x[3]);
        let forces = self_contact_forces(&x[0], &x[1], &x[2], &x[3], reach, c.self_contact);
        touching += usize::from(forces.is_some());
        let forces = forces.unwrap_or([V3::zeros(); 4]);
        let dv =
            self_contact_friction([&x[0], &x[1], &x[2], &x[3]], [&w[0], &w[1], &w[2], &w[3]], reach, sharing_of(k), c)
                .unwrap_or([V3::zeros(); 4]);
        let surfaces = model.surfaces();
        let push = surfaces[0].force(&x[0], r, c.collider).unwrap_or_default();
        let drag = collider_friction(surfaces, &x[0], &w[0], r, c.collider_impulse);
        let n = surfaces[0].normal;
        let slip = w[0] - n * n.dot(&w[0]);
        let height = n.dot(&x[0]) - surfaces[0].offset;
        let mut count = |what, same: bool| *wrong.entry(what).or_default() += usize::from(!same);
        count("closest gap", o(0) == gap && out[15 * k][3] == s && out[15 * k + 1][0] == t);
        count("push", (0..4).all(|m| o(2 + m) == forces[m]));
        count("friction", (0..4).all(|m| o(6 + m) == dv[m]));
        count("collider push", o(10) == push);
        count("collider friction", o(11) == drag);
        count("collider slip", o(12) == slip);
        count("collider height", out[15 * k + 12][3] == height);
        // The sums over this case's pair and the next two cases'.
        let partners: Vec<usize> = (0..3).map(|m| (k + m) % cases).collect();
        let pair_of = |m: usize| {
            let v3 = |i: usize| V3::new(input[8 * m + i][0], input[8 * m + i][1], input[8 * m + i][2]);
            ([v3(0), v3(1), v3(2), v3(3)], [v3(4), v3(5), v3(6), v3(7)])
        };
        let push_sum = partners.iter().fold(V3::zeros(), |sum, &m| {
            let (x, _) = pair_of(m);
            sum + self_contact_forces(&x[0], &x[1], &x[2], &x[3], reach, c.self_contact).map_or(V3::zeros(), |f| f[1])
        });
        let drag_sum = partners.iter().fold(V3::zeros(), |sum, &m| {
            let (x, w) = pair_of(m);
            sum + self_contact_friction(
                [&x[0], &x[1], &x[2], &x[3]],
                [&w[0], &w[1], &w[2], &w[3]],
                reach,
                sharing_of(m),
                c,
            )
            .map_or(V3::zeros(), |dv| dv[2])
        });
        count("pushes summed", o(13) == push_sum);
        count("friction summed", o(14) == drag_sum);
    }
    println!("{touching} of {cases} pairs in reach; mismatches: {wrong:?}");
    assert!(touching > cases / 4 && touching < cases, "{touching} of {cases} in reach");
    assert!(wrong.values().all(|&n| n == 0), "mismatches: {wrong:?}");
}

/// Cache lines of positions (16 bytes a node, 128-byte lines) a warp of 32
/// segments loads in the forces pass for its partners, with nodes in yarn
/// order (as the GPU keeps them) and in the Morton order of their
/// positions (cells of one yarn radius), and the share of a warp's lanes
/// busy while its longest list is walked. No GPU is needed:
/// `cargo test --release -p yarn-backend-wgpu -- --ignored --nocapture measure_the_lines_a_warp_loads`.
#[test]
#[ignore = "a measurement, printed"]
fn measure_the_lines_a_warp_loads() {
    use std::collections::HashSet;
    const WARP: usize = 32;
    const NODES_A_LINE: usize = 8;
    let params = Params { self_contact_stiffness: 1600.0, ..Params::default() };
    for size in [16, 64, 208] {
        let fabric = Fabric::from_chart(&Chart::stockinette(size, size).unwrap(), &Geometry::default()).unwrap();
        let model = yarn_model::Model::<f32>::new(&fabric, &params).unwrap();
        let x = State::<f32>::at_rest(&fabric).positions;
        let lists = grid::lists(&model, &x).unwrap();
        let end = |a: usize| yarn_model::step::segment_end(&model, a);
        let low = x.iter().fold(V3::repeat(f32::MAX), |m, p| m.inf(p));
        let morton = |p: &V3<f32>| {
            let cell = (p - low) / fabric.yarn_radius() as f32;
            (0..21).fold(0u64, |m, bit| {
                (0..3).fold(m, |m, axis| m | ((((cell[axis] as u64) >> bit) & 1) << (3 * bit + axis)))
            })
        };
        let mut by_space: Vec<usize> = (0..x.len()).collect();
        by_space.sort_by_key(|&i| morton(&x[i]));
        let slots: usize = lists.iter().map(Vec::len).sum();
        println!("{size}x{size}: {} nodes, {:.2} candidates a segment", x.len(), slots as f64 / x.len() as f64);
        for (name, order) in [("yarn", (0..x.len()).collect::<Vec<_>>()), ("Morton", by_space)] {
            let mut place = vec![0; x.len()];
            for (k, &i) in order.iter().enumerate() {
                place[i] = k;
            }
            let line = |i: usize| place[i] / NODES_A_LINE;
            let (mut own, mut partners, mut by_slot, mut steps, mut busy) = (0, 0, 0, 0, 0);
            for warp in order.chunks(WARP) {
                own += warp.iter().flat_map(|&s| [line(s), line(end(s))]).collect::<HashSet<_>>().len();
                let longest = warp.iter().map(|&s| lists[s].len()).max().unwrap_or(0);
                let mut all = HashSet::new();
                for k in 0..longest {
                    let lines: HashSet<usize> = warp
                        .iter()
                        .filter_map(|&s| lists[s].get(k))
                        .flat_map(|&j| [line(j as usize), line(end(j as usize))])
                        .collect();
                    by_slot += lines.len();
                    all.extend(lines);
                }
                partners += all.len();
                steps += longest;
                busy += warp.iter().map(|&s| lists[s].len()).sum::<usize>();
            }
            let warps = x.len().div_ceil(WARP) as f64;
            println!(
                "  {name:>6} order, a warp: {:.1} lines of its own, {:.1} of its partners' ({:.1} a slot), {:.0} % of lanes busy",
                own as f64 / warps,
                partners as f64 / warps,
                by_slot as f64 / steps as f64,
                100.0 * busy as f64 / (steps * WARP) as f64
            );
        }
    }
}
