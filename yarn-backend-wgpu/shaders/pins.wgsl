// Pins (SPEC §4 step 5): each pinned node is put at its target, at rest.
// Dispatched only when the scene has pins. With self-contact a pinned node
// is watched where it is put (`watch_move`), not only where the move took
// it: a target set since the last build may lie far from both.

@group(0) @binding(0) var<uniform> p: Params;
@group(0) @binding(1) var<storage, read_write> x: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read_write> v: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> pins: array<Pin>;
@group(0) @binding(4) var<storage, read_write> lists: array<u32>;

@compute @workgroup_size(WORKGROUP)
fn main(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_id) local: vec3<u32>,
        @builtin(num_workgroups) groups: vec3<u32>) {
    let k = thread_index(group, local, groups);
    if k >= p.pins {
        return;
    }
    let pin = pins[k];
    x[pin.node] = vec4<f32>(pin.goal, 0.0);
    v[pin.node] = vec4<f32>(0.0);
    watch_move(pin.node, pin.goal, vec3<f32>(0.0));
}
