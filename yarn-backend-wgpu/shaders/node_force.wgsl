// The total force on one node (SPEC §4 step 1) as the gather computes it:
// its own segments, joints and contacts, recomputing the elements it shares
// with its neighbours, summed in the CPU kernel's order. Used by the passes
// that declare `p`, `x`, `chain`, `start` and `incident`: each node's
// contacts, copied out in contact order so one load brings the whole
// record.
//
// Segments and joints follow each yarn through `chain`: they stop at an
// open yarn's ends and wrap around a closed one. Almost every node's
// neighbours along its yarn are the nodes beside it in the arrays, so the
// force is read as if they were (`chain_beside`: every load's index known
// at once, as for a fabric of one open yarn), each element checked against
// the links in the records those loads bring; an element that is not there
// (an open yarn's end, a break between two yarns) counts zero. Only a node
// within one of a closed yarn's wrap follows its links instead
// (`chain_linked`, whose CPU twin is `chain_force` in yarn-backend-cpu's
// `fabric/chain.rs`). Both sum the same elements in the same order.

struct Stretched {
    segment: Segment,
    force: vec3<f32>,
}

const NO_SEGMENT: Stretched = Stretched(Segment(vec3<f32>(0.0), 0.0), vec3<f32>(0.0));
const NO_JOINT: JointForces = JointForces(vec3<f32>(0.0), vec3<f32>(0.0));

fn stretched(d: vec3<f32>, rest_length: f32) -> Stretched {
    return Stretched(segment_of(d), spring_force(d, rest_length, p.stretch));
}

// Whether node k's links reach past the nodes beside it: a closed yarn's
// first or last node. (NONE, at an open yarn's end, does not.)
fn wraps(k: i32) -> bool {
    if k < 0 || k >= i32(p.nodes) {
        return false;
    }
    let c = chain[k];
    return (c.prev != NONE && c.prev != u32(k - 1)) || (c.next != NONE && c.next != u32(k + 1));
}

// The segment from node s to node s + 1, zero unless s + 1 is s's next
// along its yarn.
fn segment_beside(s: i32) -> Stretched {
    if s < 0 || s + 1 >= i32(p.nodes) || chain[s].next != u32(s + 1) {
        return NO_SEGMENT;
    }
    return stretched(x[s + 1].xyz - x[s].xyz, chain[s].rest_length);
}

// The joint (b − 1, b, b + 1) from its segments, zero unless b − 1 and
// b + 1 are b's neighbours along its yarn.
fn joint_beside(b: i32, s0: Segment, s1: Segment) -> JointForces {
    if b < 1 || b + 1 >= i32(p.nodes) || chain[b].prev != u32(b - 1) || chain[b].next != u32(b + 1) {
        return NO_JOINT;
    }
    return joint_forces(s0, s1, chain[b].rest_turn, p.bend, p.min_sin);
}

// Gravity, segments and joints of node i, whose neighbourhood does not
// wrap: + segment i, − segment i − 1, + the first-node force of joint
// i + 1, − both end forces of joint i, + the last-node force of joint i − 1.
fn chain_beside(i: i32) -> vec3<f32> {
    let s0 = segment_beside(i - 2);
    let s1 = segment_beside(i - 1);
    let s2 = segment_beside(i);
    let s3 = segment_beside(i + 1);
    let j0 = joint_beside(i - 1, s0.segment, s1.segment);
    let j1 = joint_beside(i, s1.segment, s2.segment);
    let j2 = joint_beside(i + 1, s2.segment, s3.segment);
    return vec3<f32>(0.0, p.gravity_y, 0.0) + s2.force - s1.force + j2.first - (j1.first + j1.last) + j0.last;
}

// The segment from node s to its next node, zero when s is NONE or at an
// open yarn's end.
fn segment_linked(s: u32) -> Stretched {
    if s == NONE || chain[s].next == NONE {
        return NO_SEGMENT;
    }
    return stretched(x[chain[s].next].xyz - x[s].xyz, chain[s].rest_length);
}

// The joint centred on node b from its segments in and out, zero when b is
// NONE or lacks a neighbour.
fn joint_linked(b: u32, s0: Segment, s1: Segment) -> JointForces {
    if b == NONE || chain[b].prev == NONE || chain[b].next == NONE {
        return NO_JOINT;
    }
    return joint_forces(s0, s1, chain[b].rest_turn, p.bend, p.min_sin);
}

// As `chain_beside`, with every neighbour found through the links.
fn chain_linked(node: u32) -> vec3<f32> {
    let prev = chain[node].prev;
    let next = chain[node].next;
    var before_prev = NONE;
    if prev != NONE {
        before_prev = chain[prev].prev;
    }
    let s0 = segment_linked(before_prev);
    let s1 = segment_linked(prev);
    let s2 = segment_linked(node);
    let s3 = segment_linked(next);
    let j0 = joint_linked(prev, s0.segment, s1.segment);
    let j1 = joint_linked(node, s1.segment, s2.segment);
    let j2 = joint_linked(next, s2.segment, s3.segment);
    return vec3<f32>(0.0, p.gravity_y, 0.0) + s2.force - s1.force + j2.first - (j1.first + j1.last) + j0.last;
}

fn node_force(node: u32) -> vec3<f32> {
    let i = i32(node);
    var f: vec3<f32>;
    // Node i reads the links of nodes i − 1 to i + 1 (whose joints it
    // shares); where one wraps, its neighbourhood is not beside it.
    if wraps(i - 1) || wraps(i) || wraps(i + 1) {
        f = chain_linked(node);
    } else {
        f = chain_beside(i);
    }
    for (var e = start[node]; e < start[node + 1u]; e++) {
        let c = incident[e];
        if c.alive != 0u {
            let force = spring_force(x[c.b].xyz - x[c.a].xyz, c.rest, p.contact);
            f += select(force, -force, c.b == node);
        }
    }
    return f;
}
