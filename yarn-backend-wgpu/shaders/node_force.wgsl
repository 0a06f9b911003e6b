// The total force on one node (SPEC §4 step 1) as the gather computes it:
// its own segments, joints and contacts, recomputing the elements it shares
// with its neighbours, summed in the CPU kernel's order. Used by the passes
// that declare `p`, `x`, `chain`, `start` and `incident`: each node's
// contacts, copied out in contact order so one load brings the whole
// record.

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
        let c = incident[e];
        if c.alive != 0u {
            let force = spring_force(x[c.b].xyz - x[c.a].xyz, c.rest, p.contact);
            f += select(force, -force, c.b == node);
        }
    }
    return f;
}
