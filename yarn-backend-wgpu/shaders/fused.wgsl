// Gather mode with friction, the whole substep in one pass (SPEC §4 steps
// 1–4). A node's friction needs v* of its contact partners, which the
// two-pass form gets from a second dispatch; here each node recomputes its
// partners' v* itself. That costs half a node's force again on average and
// saves one dispatch and one round trip through memory per substep. It
// reads one pair of state buffers and writes the other.

@group(0) @binding(0) var<uniform> p: Params;
@group(0) @binding(1) var<storage, read> x: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> v: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read_write> x_next: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read_write> v_next: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read> chain: array<Chain>;
@group(0) @binding(6) var<storage, read> start: array<u32>;
@group(0) @binding(7) var<storage, read> incident: array<Contact>;

// v* of node j (step 2).
fn velocity_star(j: u32) -> vec3<f32> {
    return damped_velocity(v[j].xyz, node_force(j));
}

@compute @workgroup_size(WORKGROUP)
fn main(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_id) local: vec3<u32>,
        @builtin(num_workgroups) groups: vec3<u32>) {
    let i = thread_index(group, local, groups);
    if i >= p.nodes {
        return;
    }
    let own = velocity_star(i);
    // As `node_friction`, with each partner's v* recomputed.
    var dv = vec3<f32>(0.0);
    for (var e = start[i]; e < start[i + 1u]; e++) {
        let c = incident[e];
        if c.alive != 0u {
            let is_b = c.b == i;
            let other = velocity_star(select(c.b, c.a, is_b));
            let w = select(other - own, own - other, is_b);
            let dw = friction_change(x[c.b].xyz - x[c.a].xyz, w, c.rest);
            dv -= dw * select(0.5, -0.5, is_b);
        }
    }
    let velocity = own + dv;
    v_next[i] = vec4<f32>(velocity, 0.0);
    x_next[i] = vec4<f32>(x[i].xyz + mul3(velocity, p.h), 0.0);
}
