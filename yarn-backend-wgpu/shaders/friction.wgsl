// Friction and move (SPEC §4 steps 3–4), both modes: each node sums the
// Jacobi friction changes of its contacts, all from x and v* (node a gets
// −Δw/2, b +Δw/2), then its self-contacts' (capped, `touch.wgsl`), then
// its colliders' (from v*), and moves. It writes the other pair of state
// buffers, since its neighbours still read this one.

@group(0) @binding(0) var<uniform> p: Params;
@group(0) @binding(1) var<storage, read> x: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> v: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read_write> x_next: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read_write> v_next: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read> start: array<u32>;
@group(0) @binding(6) var<storage, read> incident: array<Contact>;
@group(0) @binding(7) var<storage, read_write> lists: array<u32>;

fn v_star(j: u32) -> vec3<f32> {
    return v[j].xyz;
}

@compute @workgroup_size(WORKGROUP)
fn main(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_id) local: vec3<u32>,
        @builtin(num_workgroups) groups: vec3<u32>) {
    let i = thread_index(group, local, groups);
    if i >= p.nodes {
        return;
    }
    let w = v[i].xyz;
    var velocity = w + node_friction(i);
    velocity += self_contact_friction(i);
    velocity += collider_friction(x[i].xyz, w);
    watch_speed(i, velocity);
    let at = x[i].xyz + mul3(velocity, p.h);
    v_next[i] = vec4<f32>(velocity, 0.0);
    x_next[i] = vec4<f32>(at, 0.0);
    watch_move(i, at, velocity);
}
