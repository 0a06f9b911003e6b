// Gather mode, pass 1 (SPEC §4 steps 1–2): each node sums the forces of its
// own segments, joints and contacts, recomputing the elements it shares
// with its neighbours, so no atomics and no second pass are needed; the sum
// is in the same order as the CPU kernel's. Then the damped velocity update
// v* in place, and, without friction, the move into `x_next`.

@group(0) @binding(0) var<uniform> p: Params;
@group(0) @binding(1) var<storage, read> x: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read_write> v: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read_write> out: array<vec4<f32>>;
// Per node i: the rest length of segment i and κθ0 of joint i (zero past
// the ends).
@group(0) @binding(4) var<storage, read> chain: array<vec2<f32>>;
@group(0) @binding(5) var<storage, read> contacts: array<Contact>;
@group(0) @binding(6) var<storage, read> start: array<u32>;
@group(0) @binding(7) var<storage, read> incident: array<u32>;

struct Stretched {
    segment: Segment,
    force: vec3<f32>,
}

// Segment s (nodes s, s+1), zero when it does not exist.
fn segment(s: i32) -> Stretched {
    if s < 0 || s >= i32(p.nodes) - 1 {
        return Stretched(Segment(vec3<f32>(0.0), 0.0), vec3<f32>(0.0));
    }
    let d = x[s + 1].xyz - x[s].xyz;
    return Stretched(segment_of(d), spring_force(d, chain[s].x, p.stretch));
}

// Joint j (nodes j, j+1, j+2) from its segments, zero when it does not exist.
fn joint(j: i32, s0: Segment, s1: Segment) -> JointForces {
    if j < 0 || j >= i32(p.nodes) - 2 {
        return JointForces(vec3<f32>(0.0), vec3<f32>(0.0));
    }
    return joint_forces(s0, s1, chain[j].y, p.bend, p.min_sin);
}

fn node_force(node: u32) -> vec3<f32> {
    let i = i32(node);
    let s0 = segment(i - 2);
    let s1 = segment(i - 1);
    let s2 = segment(i);
    let s3 = segment(i + 1);
    let j0 = joint(i - 2, s0.segment, s1.segment);
    let j1 = joint(i - 1, s1.segment, s2.segment);
    let j2 = joint(i, s2.segment, s3.segment);
    var f = vec3<f32>(0.0, p.gravity_y, 0.0) + s2.force - s1.force + j2.first - (j1.first + j1.last) + j0.last;
    for (var e = start[node]; e < start[node + 1u]; e++) {
        let entry = incident[e];
        let c = contacts[entry & ~IS_B];
        if c.alive != 0u {
            let force = spring_force(x[c.b].xyz - x[c.a].xyz, c.rest, p.contact);
            f += select(force, -force, (entry & IS_B) != 0u);
        }
    }
    return f;
}

@compute @workgroup_size(WORKGROUP)
fn step(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_id) local: vec3<u32>,
        @builtin(num_workgroups) groups: vec3<u32>) {
    let i = thread_index(group, local, groups);
    if i >= p.nodes {
        return;
    }
    let velocity = (v[i].xyz + node_force(i) * p.h_over_m) * p.damping_factor;
    v[i] = vec4<f32>(velocity, 0.0);
    if (p.flags & FRICTION_ON) == 0u {
        out[i] = vec4<f32>(x[i].xyz + velocity * p.h, 0.0);
    }
}

// F = −∇U for `Backend::compute_forces`, into `out`.
@compute @workgroup_size(WORKGROUP)
fn forces(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_id) local: vec3<u32>,
          @builtin(num_workgroups) groups: vec3<u32>) {
    let i = thread_index(group, local, groups);
    if i >= p.nodes {
        return;
    }
    out[i] = vec4<f32>(node_force(i), 0.0);
}
