// The total force on one node (SPEC §4 step 1) as the gather computes it:
// its own segments, joints and contacts, recomputing the elements it shares
// with its neighbours, summed in the CPU kernel's order. A node finds its
// neighbours along its yarn through `chain`, so segments and joints stop
// at an open yarn's ends and wrap around a closed one's (the CPU twin is
// `chain_force` in yarn-backend-cpu's `fabric/chain.rs`). Used by the
// passes that declare `p`, `x`, `chain`, `start` and `incident`: each
// node's contacts, copied out in contact order so one load brings the
// whole record.

struct Stretched {
    segment: Segment,
    force: vec3<f32>,
}

// The segment from node s to its next node, zero when s is NONE or at an
// open yarn's end.
fn segment(s: u32) -> Stretched {
    if s == NONE || chain[s].next == NONE {
        return Stretched(Segment(vec3<f32>(0.0), 0.0), vec3<f32>(0.0));
    }
    let d = x[chain[s].next].xyz - x[s].xyz;
    return Stretched(segment_of(d), spring_force(d, chain[s].rest_length, p.stretch));
}

// The joint centred on node b from its segments in and out, zero when b is
// NONE or lacks a neighbour.
fn joint(b: u32, s0: Segment, s1: Segment) -> JointForces {
    if b == NONE || chain[b].prev == NONE || chain[b].next == NONE {
        return JointForces(vec3<f32>(0.0), vec3<f32>(0.0));
    }
    return joint_forces(s0, s1, chain[b].rest_turn, p.bend, p.min_sin);
}

fn node_force(node: u32) -> vec3<f32> {
    let prev = chain[node].prev;
    let next = chain[node].next;
    var before_prev = NONE;
    if prev != NONE {
        before_prev = chain[prev].prev;
    }
    let s0 = segment(before_prev);
    let s1 = segment(prev);
    let s2 = segment(node);
    let s3 = segment(next);
    let j0 = joint(prev, s0.segment, s1.segment);
    let j1 = joint(node, s1.segment, s2.segment);
    let j2 = joint(next, s2.segment, s3.segment);
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
