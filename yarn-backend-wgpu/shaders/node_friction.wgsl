// The sum of one node's Jacobi friction changes (SPEC §4 step 3), all from
// x and v*: node a of a contact gets −Δw/2, node b +Δw/2. Used by the
// passes that declare `p`, `x`, `v`, `start` and `incident`.

fn node_friction(i: u32) -> vec3<f32> {
    var dv = vec3<f32>(0.0);
    for (var e = start[i]; e < start[i + 1u]; e++) {
        let c = incident[e];
        if c.alive != 0u {
            let dw = friction_change(x[c.b].xyz - x[c.a].xyz, v[c.b].xyz - v[c.a].xyz, c.rest);
            dv -= dw * select(0.5, -0.5, c.b == i);
        }
    }
    return dv;
}
