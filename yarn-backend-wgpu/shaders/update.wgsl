// The node update both accumulation modes share (SPEC §4 steps 1–2): the
// damped velocity v* in place and, without friction, the move into `out`
// (`step_at`, entry point `step`); or the force alone into `out`
// (`forces_at`, entry point `forces`, for `Backend::compute_forces`). Each
// mode's file supplies `node_of` (the node a thread takes, NONE for none),
// `total_force(i)`, `watch_speed(i, velocity)` and `watch_move`
// (`touch.wgsl`'s, or nothing), and the bindings `p`, `x`, `v` and `out`;
// the colliders' push comes last, as on the CPU. A mode may add entry
// points of its own around `step_at` and `forces_at` (the gather's with
// self-contact).

// How many self-contact pairs push the node this thread takes, set by the
// gather's `touching_node_of` (0 elsewhere). `step_at` keeps it in v*'s
// fourth component, where friction's pass reads it (`pushing_at`) beside
// the velocity it loads anyway.
var<private> node_pushing: f32;

fn step_at(i: u32) {
    if i >= p.nodes {
        return;
    }
    let velocity = damped_velocity(v[i].xyz, with_colliders(total_force(i), x[i].xyz));
    v[i] = vec4<f32>(velocity, node_pushing);
    if (p.flags & FRICTION_ON) == 0u {
        watch_speed(i, velocity);
        let at = x[i].xyz + mul3(velocity, p.h);
        out[i] = vec4<f32>(at, 0.0);
        watch_move(i, at, velocity);
    }
}

fn forces_at(i: u32) {
    if i >= p.nodes {
        return;
    }
    out[i] = vec4<f32>(with_colliders(total_force(i), x[i].xyz), 0.0);
}

@compute @workgroup_size(WORKGROUP)
fn step(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_id) local: vec3<u32>,
        @builtin(num_workgroups) groups: vec3<u32>) {
    step_at(node_of(group, local, groups));
}

@compute @workgroup_size(WORKGROUP)
fn forces(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_id) local: vec3<u32>,
          @builtin(num_workgroups) groups: vec3<u32>) {
    forces_at(node_of(group, local, groups));
}
