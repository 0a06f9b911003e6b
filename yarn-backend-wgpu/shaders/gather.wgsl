// Gather mode, pass 1 (SPEC §4 steps 1–2): each node's force
// (`node_force.wgsl`: no atomics, a fixed order), then the damped velocity
// update v* in place, and, without friction, the move into `x_next`.

@group(0) @binding(0) var<uniform> p: Params;
@group(0) @binding(1) var<storage, read> x: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read_write> v: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read_write> out: array<vec4<f32>>;
// Per node i: the rest length of segment i and κθ0 of joint i (zero past
// the ends).
@group(0) @binding(4) var<storage, read> chain: array<vec2<f32>>;
@group(0) @binding(5) var<storage, read> start: array<u32>;
@group(0) @binding(6) var<storage, read> incident: array<Contact>;

@compute @workgroup_size(WORKGROUP)
fn step(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_id) local: vec3<u32>,
        @builtin(num_workgroups) groups: vec3<u32>) {
    let i = thread_index(group, local, groups);
    if i >= p.nodes {
        return;
    }
    let velocity = mul3(v[i].xyz + mul3(node_force(i), p.h_over_m), p.damping_factor);
    v[i] = vec4<f32>(velocity, 0.0);
    if (p.flags & FRICTION_ON) == 0u {
        out[i] = vec4<f32>(x[i].xyz + mul3(velocity, p.h), 0.0);
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
