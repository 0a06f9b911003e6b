// The node update both accumulation modes share (SPEC §4 steps 1–2): the
// damped velocity v* in place and, without friction, the move into `out`
// (entry point `step`); or the force alone into `out` (entry point
// `forces`, for `Backend::compute_forces`). Each mode's file supplies
// `node_of` (the node a thread takes, NONE for none; the gather's computes
// each node's self-contact pushes with it), `total_force(i)`,
// `watch_speed(i, velocity)` and `watch_move` (`touch.wgsl`'s, or nothing),
// and the bindings `p`, `x`, `v` and `out`; the colliders' push comes
// last, as on the CPU.

@compute @workgroup_size(WORKGROUP)
fn step(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_id) local: vec3<u32>,
        @builtin(num_workgroups) groups: vec3<u32>) {
    let i = node_of(group, local, groups);
    if i >= p.nodes {
        return;
    }
    let velocity = damped_velocity(v[i].xyz, with_colliders(total_force(i), x[i].xyz));
    v[i] = vec4<f32>(velocity, 0.0);
    if (p.flags & FRICTION_ON) == 0u {
        watch_speed(i, velocity);
        let at = x[i].xyz + mul3(velocity, p.h);
        out[i] = vec4<f32>(at, 0.0);
        watch_move(i, at, velocity);
    }
}

@compute @workgroup_size(WORKGROUP)
fn forces(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_id) local: vec3<u32>,
          @builtin(num_workgroups) groups: vec3<u32>) {
    let i = node_of(group, local, groups);
    if i >= p.nodes {
        return;
    }
    out[i] = vec4<f32>(with_colliders(total_force(i), x[i].xyz), 0.0);
}
