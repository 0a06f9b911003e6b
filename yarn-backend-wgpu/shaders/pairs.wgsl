// Self-contact's friction pass (`touch.wgsl`): each segment sums its
// pushing pairs' friction changes from x and v* on its first node and on
// its last, once for both, and stores them for `friction.wgsl`, which adds
// the sums of the two segments each node touches. (The pushes are summed
// in the gather's own pass, `gather.wgsl`.) CPU twin: the friction pass and
// per-segment sums of yarn-backend-cpu's `fabric/touching.rs`.
//
// Friction visits only the slots that pushed, from none to a dozen a
// segment, so a thread looping over its own kept a warp busy as long as
// its fullest segment (a fifth of the lanes busy, on average). Instead a
// workgroup shares out its segments' visits: a scan in workgroup memory
// lays them end to end, each round every thread computes one and leaves
// its shares in workgroup memory, and the segment's own thread adds them
// in slot order: the sums of `Serial<f32>`, bit for bit. Shared out the
// same way, the pushes were slower (127 µs a substep against 103 at a
// million nodes on an H100): their slots, loaded segment by segment, are
// read row by row.

@group(0) @binding(0) var<uniform> p: Params;
@group(0) @binding(1) var<storage, read> x: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> v: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read_write> lists: array<u32>;

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

// The friction changes of the segments of this thread's workgroup, shared
// out (above): each thread stores its own segment's sums.
fn shared_friction(group: vec3<u32>, local: u32, groups: vec3<u32>) {
    let s = thread_index(group, vec3<u32>(local, 0u, 0u), groups);
    var end = NONE;
    var count = 0u;
    if s < p.nodes {
        end = segment_end(s);
        if end != NONE {
            count = lists[field_at(s, COUNT)];
        }
    }
    // The visits: the slots of the first 32 that pushed, and any past 32.
    let first32 = min(count, 32u);
    var marks = 0u;
    if first32 > 0u {
        marks = lists[field_at(s, PUSHING)] & (0xffffffffu >> (32u - first32));
    }
    let own = countOneBits(marks) + count - first32;
    ends[local] = end;
    visited[local] = marks;
    // Inclusive scan of the visits (Hillis and Steele).
    visits_through[local] = own;
    workgroupBarrier();
    for (var stride = 1u; stride < WORKGROUP; stride *= 2u) {
        var before = 0u;
        if local >= stride {
            before = visits_through[local - stride];
        }
        workgroupBarrier();
        visits_through[local] += before;
        workgroupBarrier();
    }
    let total = workgroupUniformLoad(&visits_through[WORKGROUP - 1u]);
    let own_end = visits_through[local];
    let own_start = own_end - own;
    let first_segment = s - local;
    var sums = NO_SUMS;
    for (var round = 0u; round < total; round += WORKGROUP) {
        let visit = round + local;
        if visit < total {
            let owner = owner_of(visit);
            var rank = visit;
            if owner > 0u {
                rank -= visits_through[owner - 1u];
            }
            let segment = first_segment + owner;
            let pair = pair_of(segment, ends[owner], lists[slot_at(segment, slot_of(rank, visited[owner]))], true);
            let values = pair_values(pair, true);
            firsts[local] = first_share(values, pair.s_is_q);
            lasts[local] = last_share(values, pair.s_is_q);
        }
        workgroupBarrier();
        for (var at = max(own_start, round); at < min(own_end, round + WORKGROUP); at++) {
            add_shares(&sums, firsts[at - round], lasts[at - round]);
        }
        workgroupBarrier();
    }
    if end != NONE {
        store_sums(s, end, sums);
    }
}

@compute @workgroup_size(WORKGROUP)
fn friction(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_id) local: vec3<u32>,
            @builtin(num_workgroups) groups: vec3<u32>) {
    shared_friction(group, local.x, groups);
}
