// Gather mode's forces (SPEC §4 step 1): each node's own
// (`node_force.wgsl`: no atomics, a fixed order) and, with self-contact,
// its pairs' (`touch.wgsl`), for the update of `update.wgsl`: the whole
// substep without friction, and `Backend::compute_forces`. With friction,
// `fused.wgsl` takes the substep of a small fabric without self-contact or
// colliders.

@group(0) @binding(0) var<uniform> p: Params;
@group(0) @binding(1) var<storage, read> x: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read_write> v: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read_write> out: array<vec4<f32>>;
// Per node: its segment's rest length, its joint's κθ0 and its neighbours.
@group(0) @binding(4) var<storage, read> chain: array<Chain>;
@group(0) @binding(5) var<storage, read> start: array<u32>;
@group(0) @binding(6) var<storage, read> incident: array<Contact>;
@group(0) @binding(7) var<storage, read_write> lists: array<u32>;

// The node's force, gathered (`node_force.wgsl`), then its self-contacts'.
fn total_force(i: u32) -> vec3<f32> {
    return with_self_contact(node_force(i), i);
}

fn v_star(j: u32) -> vec3<f32> {
    return v[j].xyz;
}
