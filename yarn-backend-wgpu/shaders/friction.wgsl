// Friction and move (SPEC §4 steps 3–4), both modes: each node sums the
// Jacobi friction changes of its contacts, all from x and v* (node a gets
// −Δw/2, b +Δw/2), then its self-contacts' (capped, `touch.wgsl`), then
// its colliders' (from v*), and moves. It writes the other pair of state
// buffers, since its neighbours still read this one.
//
// With self-contact and friction (entry point `main_touching`, which the
// backend chooses then, so that `main` compiles none of it), the
// self-contacts' changes are summed here, segment by segment, and a node
// adds the sum of the segment it starts and then of the one it ends,
// taken from the thread before it as in `gather.wgsl` (a workgroup covers
// WORKGROUP − 1 nodes). CPU twin: the friction pass and segment sums of
// yarn-backend-cpu's `fabric/touching.rs`.
// A segment visits only the slots that pushed, from none to a dozen, so a
// thread looping over its own kept a warp busy as long as its fullest
// segment (a fifth of the lanes busy, on average). Instead a workgroup
// shares out its segments' visits: a scan in workgroup memory lays them
// end to end, each round every thread computes one and leaves its shares
// in workgroup memory, and the segment's own thread adds them in slot
// order: the sums of `Serial<f32>`, bit for bit. Shared out the same way,
// the pushes were slower (127 µs a substep against 103 at a million nodes
// on an H100): their slots, loaded segment by segment, are read row by
// row.

@group(0) @binding(0) var<uniform> p: Params;
@group(0) @binding(1) var<storage, read> x: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> v: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read_write> x_next: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read_write> v_next: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read> start: array<u32>;
@group(0) @binding(6) var<storage, read> incident: array<Contact>;
@group(0) @binding(7) var<storage, read_write> lists: array<u32>;
@group(0) @binding(8) var<storage, read> chain: array<Chain>;

fn v_star(j: u32) -> vec3<f32> {
    return v[j].xyz;
}

// Per thread's segment: the visits up to and including its own (an
// inclusive scan), the node it ends at, and which of its first 32 slots
// pushed.
var<workgroup> visits_through: array<u32, WORKGROUP>;
var<workgroup> ends: array<u32, WORKGROUP>;
var<workgroup> visited: array<u32, WORKGROUP>;
// Per visit of the round: the pair's friction changes on its segment's
// first node and last.
var<workgroup> firsts: array<vec3<f32>, WORKGROUP>;
var<workgroup> lasts: array<vec3<f32>, WORKGROUP>;

// The slot of a segment's visit number `rank`: the `rank`-th set bit of
// `first32` (the first 32 slots it visits), then the slots past 32 in turn.
fn slot_of(rank: u32, first32: u32) -> u32 {
    let within = countOneBits(first32);
    if rank >= within {
        return 32u + rank - within;
    }
    var bits = first32;
    for (var k = 0u; k < rank; k++) {
        bits &= bits - 1u;
    }
    return countTrailingZeros(bits);
}

// The workgroup's thread whose segment makes visit `visit`: the first whose
// inclusive count passes it.
fn owner_of(visit: u32) -> u32 {
    var low = 0u;
    var high = WORKGROUP - 1u;
    while low < high {
        let middle = (low + high) / 2u;
        if visits_through[middle] > visit {
            high = middle;
        } else {
            low = middle + 1u;
        }
    }
    return low;
}

// Segment s's visits: which of its first 32 slots pushed (`marks`), and
// how many in all, those and every slot past 32. None where it is no
// segment (`end` NONE).
struct Visits {
    marks: u32,
    count: u32,
}

fn visits_of(s: u32, end: u32) -> Visits {
    if end == NONE {
        return Visits(0u, 0u);
    }
    let count = lists[field_at(s, COUNT)];
    let first32 = min(count, 32u);
    var marks = 0u;
    if first32 > 0u {
        marks = lists[field_at(s, PUSHING)] & (0xffffffffu >> (32u - first32));
    }
    return Visits(marks, countOneBits(marks) + count - first32);
}

// Segment s's friction sums by one thread, visit by visit, in the order
// the shared-out sums take: for a closed yarn's first node, whose segment
// before it closes the yarn elsewhere.
fn segment_friction(s: u32, end: u32) -> Sums {
    let visits = visits_of(s, end);
    var sums = NO_SUMS;
    for (var rank = 0u; rank < visits.count; rank++) {
        let pair = pair_of(s, end, lists[slot_at(s, slot_of(rank, visits.marks))], true);
        let values = pair_values(pair, true);
        add_shares(&sums, first_share(values, pair.s_is_q), last_share(values, pair.s_is_q));
    }
    return sums;
}

// This thread's node's self-contact friction change: the sum of the
// segment it starts, then of the one it ends (`touching_node_of` sets it;
// zero in `main`).
var<private> self_contact_change: vec3<f32>;

// With self-contact: the node this thread takes, NONE for none, once the
// workgroup has summed its segments' friction changes, shared out (above).
fn touching_node_of(group: vec3<u32>, local: vec3<u32>, groups: vec3<u32>) -> u32 {
    let t = local.x;
    // For the first thread of all, NONE (the wrap of 0 − 1).
    let first_segment = (group.y * groups.x + group.x) * (WORKGROUP - 1u) - 1u;
    let s = first_segment + t;
    var end = NONE;
    if s < p.nodes {
        end = segment_end(s);
    }
    let visits = visits_of(s, end);
    ends[t] = end;
    visited[t] = visits.marks;
    // Inclusive scan of the visits (Hillis and Steele).
    visits_through[t] = visits.count;
    workgroupBarrier();
    for (var stride = 1u; stride < WORKGROUP; stride *= 2u) {
        var before = 0u;
        if t >= stride {
            before = visits_through[t - stride];
        }
        workgroupBarrier();
        visits_through[t] += before;
        workgroupBarrier();
    }
    let total = workgroupUniformLoad(&visits_through[WORKGROUP - 1u]);
    let own_end = visits_through[t];
    let own_start = own_end - visits.count;
    var sums = NO_SUMS;
    for (var round = 0u; round < total; round += WORKGROUP) {
        let visit = round + t;
        if visit < total {
            let owner = owner_of(visit);
            var rank = visit;
            if owner > 0u {
                rank -= visits_through[owner - 1u];
            }
            let segment = first_segment + owner;
            let pair = pair_of(segment, ends[owner], lists[slot_at(segment, slot_of(rank, visited[owner]))], true);
            let values = pair_values(pair, true);
            firsts[t] = first_share(values, pair.s_is_q);
            lasts[t] = last_share(values, pair.s_is_q);
        }
        workgroupBarrier();
        for (var at = max(own_start, round); at < min(own_end, round + WORKGROUP); at++) {
            add_shares(&sums, firsts[at - round], lasts[at - round]);
        }
        workgroupBarrier();
    }
    // Each segment's sum on its last node, for the thread after it.
    lasts[t] = sums.last;
    workgroupBarrier();
    if t == 0u || s >= p.nodes {
        return NONE;
    }
    var ended = vec3<f32>(0.0);
    if ends[t - 1u] == s {
        ended = lasts[t - 1u];
    } else if chain[s].prev != NONE {
        ended = segment_friction(chain[s].prev, s).last;
    }
    self_contact_change = sums.first + ended;
    return s;
}

// Node i's friction and move.
fn friction_at(i: u32) {
    if i >= p.nodes {
        return;
    }
    let w = v[i].xyz;
    var velocity = w + node_friction(i);
    velocity += self_contact_change;
    velocity += collider_friction(x[i].xyz, w);
    watch_speed(i, velocity);
    let at = x[i].xyz + mul3(velocity, p.h);
    v_next[i] = vec4<f32>(velocity, 0.0);
    x_next[i] = vec4<f32>(at, 0.0);
    watch_move(i, at, velocity);
}

@compute @workgroup_size(WORKGROUP)
fn main(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_id) local: vec3<u32>,
        @builtin(num_workgroups) groups: vec3<u32>) {
    friction_at(thread_index(group, local, groups));
}

@compute @workgroup_size(WORKGROUP)
fn main_touching(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_id) local: vec3<u32>,
                 @builtin(num_workgroups) groups: vec3<u32>) {
    friction_at(touching_node_of(group, local, groups));
}
