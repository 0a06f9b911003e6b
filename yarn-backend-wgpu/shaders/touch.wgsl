// Self-contact between segments of yarn (`yarn_model::self_contact`): the
// pair arithmetic of `yarn_model::terms` and `yarn_model::step`, operation
// for operation, and each segment's sums over its candidate list (summed
// by the passes that add them to the nodes: the pushes in `gather.wgsl`,
// friction in `friction.wgsl`). Used by the passes
// that declare `p`, `x`, `v`, `lists` (read and write) and `v_star`.
//
// A pair beyond the reach adds exactly zero, so the sums do not depend on
// which far pairs a list holds, nor on when it was built. Every pair is
// computed from its lower-numbered segment, so both segments see the same
// numbers; a node takes the sum of the segment it starts, then that of the
// segment it ends, each over the partners in order: the order of
// `Serial<f32>` (yarn-backend-cpu's `fabric/touching.rs`). Each pair's
// friction impulse is shared among the most pairs that push any of its
// nodes (`step::pair_sharing`), counted by the gather's pass.

// A value on each of a pair's four nodes: p0, p1, q0, q1.
struct Quad {
    p0: vec3<f32>,
    p1: vec3<f32>,
    q0: vec3<f32>,
    q1: vec3<f32>,
}

const NO_QUAD: Quad = Quad(vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0));

// `terms::CONTACT_ONSET`: the push's onset as a fraction of the reach, a
// power of two so that the onset is exact (a test holds it to the Rust one).
const CONTACT_ONSET: f32 = 0.0625;

// `terms::push_depth`: the push per unit stiffness at `depth` into the
// reach, depth²/(2ε) up to the onset ε, then depth − ε/2.
fn push_depth(depth: f32) -> f32 {
    let onset = mul(p.reach, CONTACT_ONSET);
    return select(depth - mul(onset, 0.5), div_rounded(mul(depth, depth), onset + onset), depth <= onset);
}

// `terms::self_contact_forces`, zero out of reach or where the closest
// points coincide.
fn pair_forces(p0: vec3<f32>, p1: vec3<f32>, q0: vec3<f32>, q1: vec3<f32>) -> Quad {
    let c = closest_gap(p0, p1, q0, q1);
    let d = norm(c.gap);
    if !(d < p.reach && d > 0.0) {
        return NO_QUAD;
    }
    let push = mul3(c.gap, div_rounded(mul(p.self_contact, push_depth(p.reach - d)), d));
    let p_share = mul3(push, c.s);
    let q_share = mul3(push, c.t);
    return Quad(push - p_share, p_share, q_share - push, -q_share);
}

// `step::self_contact_friction` from x and v* of the pair's four nodes and
// its `sharing`, zero where it returns `None`.
fn pair_friction(x: Quad, w: Quad, sharing: f32) -> Quad {
    let c = closest_gap(x.p0, x.p1, x.q0, x.q1);
    let d = norm(c.gap);
    if !(d < p.reach && d > 0.0) {
        return NO_QUAD;
    }
    let n = vec3<f32>(div_rounded(c.gap.x, d), div_rounded(c.gap.y, d), div_rounded(c.gap.z, d));
    let shares = vec4<f32>(p.one - c.s, c.s, p.one - c.t, c.t);
    // Each product is kept whole before it is added (`kept3`): lavapipe
    // fused these sums in about half of 2,048 random pairs.
    let q_side = kept3(mul3(w.q0, shares.z)) + kept3(mul3(w.q1, shares.w));
    let p_side = kept3(mul3(w.p0, shares.x)) + kept3(mul3(w.p1, shares.y));
    let relative = q_side - p_side;
    let slip_velocity = relative - mul3(n, dot3(relative, n));
    let slip = norm(slip_velocity);
    if slip <= 0.0 {
        return NO_QUAD;
    }
    let inverse_mass = mul(shares.x, shares.x) + mul(shares.y, shares.y) + mul(shares.z, shares.z)
        + mul(shares.w, shares.w);
    let cut = mul(mul(mul(mul(p.friction, p.self_impulse), push_depth(p.reach - d)), inverse_mass), sharing);
    let retention = max(1.0 - div_rounded(cut, slip), 0.0);
    let j = mul3(slip_velocity, div_rounded(retention - 1.0, mul(inverse_mass, sharing)));
    return Quad(-mul3(j, shares.x), -mul3(j, shares.y), mul3(j, shares.z), mul3(j, shares.w));
}

// The pair of segment s (from `s` to `end`) and its partner j, from the
// lower-numbered of the two: positions, and for friction v* and its
// sharing.
struct Pair {
    x: Quad,
    w: Quad,
    sharing: f32,
    // Whether s is the pair's q (the higher-numbered).
    s_is_q: bool,
}

fn pair_of(s: u32, end: u32, j: u32, friction: bool) -> Pair {
    let j_end = segment_end(j);
    let own = Quad(x[s].xyz, x[end].xyz, x[j].xyz, x[j_end].xyz);
    var w = NO_QUAD;
    var sharing = 1.0;
    if friction {
        w = Quad(v_star(s), v_star(end), v_star(j), v_star(j_end));
        sharing = max(max(max(max(pushing_at(s), pushing_at(end)), pushing_at(j)), pushing_at(j_end)), 1.0);
    }
    if s < j {
        return Pair(own, w, sharing, false);
    }
    return Pair(Quad(own.q0, own.q1, own.p0, own.p1), Quad(w.q0, w.q1, w.p0, w.p1), sharing, true);
}

// A pair's values on segment s's first node and its last. Each is kept
// whole (`kept3`) before it is summed: a compiler may fuse a bare product
// into the add.
fn first_share(q: Quad, s_is_q: bool) -> vec3<f32> {
    return kept3(select(q.p0, q.q0, s_is_q));
}

fn last_share(q: Quad, s_is_q: bool) -> vec3<f32> {
    return kept3(select(q.p1, q.q1, s_is_q));
}

// A segment's sums over its candidates, in order, on its first node and on
// its last, and for the pushes how many of them push.
struct Sums {
    first: vec3<f32>,
    last: vec3<f32>,
    pushing: f32,
}

const NO_SUMS: Sums = Sums(vec3<f32>(0.0), vec3<f32>(0.0), 0.0);

// A pair's push, zero where the pair is surely out of reach (`apart`), as
// the exact test would find it; or with `friction` its friction change,
// which friction's pass asks only of pairs that pushed at these positions,
// never apart.
fn pair_values(pair: Pair, friction: bool) -> Quad {
    if friction {
        return pair_friction(pair.x, pair.w, pair.sharing);
    }
    if apart(pair.x.p0, pair.x.p1, pair.x.q0, pair.x.q1, p.reach) {
        return NO_QUAD;
    }
    return pair_forces(pair.x.p0, pair.x.p1, pair.x.q0, pair.x.q1);
}

// Whether a pair's push moves any of its nodes: friction visits only the
// pairs that push.
fn pushes(values: Quad) -> bool {
    return any(values.p0 != vec3<f32>(0.0)) || any(values.p1 != vec3<f32>(0.0)) || any(values.q0 != vec3<f32>(0.0))
        || any(values.q1 != vec3<f32>(0.0));
}

// Add a pair's values on a segment's first node (`first`) and last
// (`last`) to the segment's `sums`, in slot order.
fn add_shares(sums: ptr<function, Sums>, first: vec3<f32>, last: vec3<f32>) {
    (*sums).first += first;
    (*sums).last += last;
}

// Add the push of the pair in slot k of a segment's list to the segment's
// `sums`, and if it pushes count it and mark slot k in `marked` (the first
// 32).
fn add_push(sums: ptr<function, Sums>, marked: ptr<function, u32>, pair: Pair, k: u32) {
    let values = pair_values(pair, false);
    if pushes(values) {
        (*sums).pushing += 1.0;
        if k < 32u {
            *marked |= 1u << k;
        }
    }
    add_shares(sums, first_share(values, pair.s_is_q), last_share(values, pair.s_is_q));
}

// Segment s's pushes and how many pairs push, and in `marked` which of its
// first 32 slots push. Each thread over its own slots, two at a time: both
// pairs are loaded before either is summed, so that their loads overlap.
fn segment_pushes(s: u32, end: u32, marked: ptr<function, u32>) -> Sums {
    var sums = NO_SUMS;
    let count = lists[field_at(s, COUNT)];
    for (var k = 0u; k < count; k += 2u) {
        // Where k is the last, its own pair again, unused.
        let pair = pair_of(s, end, lists[slot_at(s, k)], false);
        let next = pair_of(s, end, lists[slot_at(s, min(k + 1u, count - 1u))], false);
        add_push(&sums, marked, pair, k);
        if k + 1u < count {
            add_push(&sums, marked, next, k + 1u);
        }
    }
    return sums;
}

// How many pairs push node i, as the gather's pass counted them
// (`step::pushing_pairs`): those of the segment it starts and of the one
// it ends, summed once there and kept in v*'s fourth component
// (`update.wgsl`'s `node_pushing`).
fn pushing_at(i: u32) -> f32 {
    return v[i].w;
}

// Where node i's velocity is final (after friction, or v* without it):
// flag a node whose velocity passed the divergence speed, which with
// self-contact is half a radius a substep (`Model::divergence_speed`);
// `check.wgsl` reports it. A pinned node is not watched: its pin stops it
// in the same substep, and a node its pin stops has not diverged (the
// reference's rule, and the CPU's).
fn watch_speed(i: u32, velocity: vec3<f32>) {
    // The pinned row is read only for a node past the speed.
    if (p.flags & SELF_CONTACT) != 0u && !all(abs(velocity) <= vec3<f32>(p.max_speed))
        && lists[field_at(i, PINNED)] == 0u {
        lists[SPEEDING] = 1u;
    }
}
