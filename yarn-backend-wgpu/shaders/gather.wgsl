// Gather mode's forces (SPEC §4 step 1): each node's own
// (`node_force.wgsl`: no atomics, a fixed order) and, with self-contact,
// its pairs' (`touch.wgsl`, summed here), for the update of
// `update.wgsl`: the whole substep without friction, and
// `Backend::compute_forces`. With friction,
// `fused.wgsl` takes the substep of a small fabric without self-contact or
// colliders.

@group(0) @binding(0) var<uniform> p: Params;
@group(0) @binding(1) var<storage, read> x: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read_write> v: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read_write> out: array<vec4<f32>>;
// Per node: its segment's rest length, its joint's κθ0 and its neighbours.
@group(0) @binding(4) var<storage, read> chain: array<Chain>;
@group(0) @binding(5) var<storage, read> start: array<u32>;
@group(0) @binding(6) var<storage, read> incident: array<Contact>;
@group(0) @binding(7) var<storage, read_write> lists: array<u32>;

// With self-contact (entry points `step_touching` and `forces_touching`,
// which the backend chooses where the model has it, so that `step` and
// `forces` compile none of it), the pushes are summed in this pass,
// segment by segment (`segment_pushes`), and each node adds the sum of
// the segment it starts and then of the one it ends, as `Serial<f32>`
// does (CPU twin: the segment sums of yarn-backend-cpu's
// `fabric/touching.rs`, which its block pass adds). The segment a node
// ends is almost always the one before it, so a workgroup takes one
// segment a thread, from the one before its first node, and all but the
// first thread take the node their segment starts: the sum on a node from
// the segment it ends comes from the thread before, through workgroup
// memory, and only the counts of pushing pairs, which friction reads, go
// out to memory, in v*'s fourth component. A workgroup covers WORKGROUP −
// 1 nodes; its first thread's segment is summed again as the workgroup
// before ends with it. The first node of a closed yarn, whose segment
// before it closes the yarn elsewhere, sums that one itself.
//
// A warp loops over its segments' candidates as often as its fullest
// segment has them, so the workgroup's segments are first sorted by how
// many candidates they have (a counting sort in workgroup memory), and
// thread t sums the segment in place t of that order: warps of segments
// alike in length. Each segment is still summed by one thread in its own
// slot order, so the sums do not depend on which thread sums it.

// Per thread's segment: the node it ends at (NONE for none), its sums on
// its first node and on its last, and how many of its pairs push.
var<workgroup> ends: array<u32, WORKGROUP>;
var<workgroup> firsts: array<vec3<f32>, WORKGROUP>;
var<workgroup> lasts: array<vec3<f32>, WORKGROUP>;
var<workgroup> pushing_counts: array<f32, WORKGROUP>;

// The counting sort: per list length (LENGTHS − 1 and longer together),
// how many segments have it, then where the first of them goes; and which
// thread's segment is in each place.
const LENGTHS: u32 = 16u;
var<workgroup> by_length: array<atomic<u32>, LENGTHS>;
var<workgroup> order: array<u32, WORKGROUP>;

// This thread's node's pushes: the sum of the segment it starts, and of
// the one it ends (`touching_node_of` sets them).
var<private> pushed_first: vec3<f32>;
var<private> pushed_last: vec3<f32>;

// Without self-contact, a thread's node is its index.
fn node_of(group: vec3<u32>, local: vec3<u32>, groups: vec3<u32>) -> u32 {
    return thread_index(group, local, groups);
}

// With self-contact: the node this thread takes, NONE for none, once the
// workgroup has summed its segments' pushes (above).
fn touching_node_of(group: vec3<u32>, local: vec3<u32>, groups: vec3<u32>) -> u32 {
    let t = local.x;
    // For the first workgroup of all, thread 0's is NONE (the wrap of 0 − 1).
    let before = (group.y * groups.x + group.x) * (WORKGROUP - 1u) - 1u;
    let s = before + t;
    var end = NONE;
    var length = 0u;
    if s < p.nodes {
        end = segment_end(s);
        if end != NONE {
            length = lists[field_at(s, COUNT)];
        }
    }
    ends[t] = end;
    if t < LENGTHS {
        atomicStore(&by_length[t], 0u);
    }
    workgroupBarrier();
    let key = min(length, LENGTHS - 1u);
    let rank = atomicAdd(&by_length[key], 1u);
    workgroupBarrier();
    if t == 0u {
        var placed = 0u;
        for (var k = 0u; k < LENGTHS; k++) {
            placed += atomicExchange(&by_length[k], placed);
        }
    }
    workgroupBarrier();
    order[atomicLoad(&by_length[key]) + rank] = t;
    workgroupBarrier();
    // Sum the segment in place t.
    let u = order[t];
    let su = before + u;
    var sums = NO_SUMS;
    if su < p.nodes && ends[u] != NONE {
        var marked = 0u;
        sums = segment_pushes(su, ends[u], &marked);
        // Thread 0's segment is the workgroup before's to store.
        if u != 0u {
            lists[field_at(su, PUSHING)] = marked;
        }
    }
    firsts[u] = sums.first;
    lasts[u] = sums.last;
    pushing_counts[u] = sums.pushing;
    workgroupBarrier();
    if t == 0u || s >= p.nodes {
        return NONE;
    }
    // Lists a node has moved half the skin from may miss a pair within
    // reach: the batch is put back and run again with a rebuild check
    // every substep (`fabric.rs`).
    if s == 0u && lists[FAR] != 0u {
        lists[LATE] = 1u;
    }
    var ended = NO_SUMS;
    if ends[t - 1u] == s {
        ended.last = lasts[t - 1u];
        ended.pushing = pushing_counts[t - 1u];
    } else if chain[s].prev != NONE {
        var unused = 0u;
        ended = segment_pushes(chain[s].prev, s, &unused);
    }
    pushed_first = firsts[t];
    pushed_last = ended.last;
    node_pushing = pushing_counts[t] + ended.pushing;
    return s;
}

@compute @workgroup_size(WORKGROUP)
fn step_touching(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_id) local: vec3<u32>,
                 @builtin(num_workgroups) groups: vec3<u32>) {
    step_at(touching_node_of(group, local, groups));
}

@compute @workgroup_size(WORKGROUP)
fn forces_touching(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_id) local: vec3<u32>,
                   @builtin(num_workgroups) groups: vec3<u32>) {
    forces_at(touching_node_of(group, local, groups));
}

// The node's force, gathered (`node_force.wgsl`), then its self-contacts':
// the sum of the segment it starts, then of the one it ends.
fn total_force(i: u32) -> vec3<f32> {
    if (p.flags & SELF_CONTACT) == 0u {
        return node_force(i);
    }
    return node_force(i) + pushed_first + pushed_last;
}

fn v_star(j: u32) -> vec3<f32> {
    return v[j].xyz;
}
