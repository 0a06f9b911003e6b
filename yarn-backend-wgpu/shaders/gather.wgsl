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

// With self-contact, the pushes are summed in this pass, segment by
// segment (`segment_pushes`), and each node adds the sum of the segment it
// starts and then of the one it ends, as `Serial<f32>` does (CPU twin: the
// segment sums of yarn-backend-cpu's `fabric/touching.rs`, which its block
// pass adds). The segment a node ends is almost always the one before it,
// so a workgroup's threads take one segment each, from the one before its
// first node, and all but the first take the node their segment starts:
// the sum on a node from the segment it ends comes from the thread before,
// through workgroup memory, and only the counts of pushing pairs, which
// friction reads, go out to memory. A workgroup covers WORKGROUP − 1
// nodes; its first thread sums again the segment the workgroup before
// ends with. The first node of a closed yarn, whose segment before it
// closes the yarn elsewhere, sums that one itself.

// Per thread: the node its segment ends at (NONE for none), and the
// segment's sum on that node and how many of its pairs push.
var<workgroup> ends: array<u32, WORKGROUP>;
var<workgroup> lasts: array<vec3<f32>, WORKGROUP>;
var<workgroup> last_pushing: array<f32, WORKGROUP>;

// This thread's node's pushes: the sum of the segment it starts, and of
// the one it ends (`node_of` sets them).
var<private> pushed_first: vec3<f32>;
var<private> pushed_last: vec3<f32>;

// The node this thread takes, NONE for none; with self-contact, its pushes
// are summed first (above).
fn node_of(group: vec3<u32>, local: vec3<u32>, groups: vec3<u32>) -> u32 {
    if (p.flags & SELF_CONTACT) == 0u {
        return thread_index(group, local, groups);
    }
    let t = local.x;
    // For the first thread of all, NONE (the wrap of 0 − 1).
    let s = (group.y * groups.x + group.x) * (WORKGROUP - 1u) + t - 1u;
    var end = NONE;
    var sums = NO_SUMS;
    var marked = 0u;
    if s < p.nodes {
        end = segment_end(s);
        if end != NONE {
            sums = segment_pushes(s, end, &marked);
        }
    }
    ends[t] = end;
    lasts[t] = sums.last;
    last_pushing[t] = sums.pushing;
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
    if end != NONE {
        lists[field_at(s, PUSHING)] = marked;
    }
    var ended = NO_SUMS;
    if ends[t - 1u] == s {
        ended.last = lasts[t - 1u];
        ended.pushing = last_pushing[t - 1u];
    } else if chain[s].prev != NONE {
        var unused = 0u;
        ended = segment_pushes(chain[s].prev, s, &unused);
    }
    pushed_first = sums.first;
    pushed_last = ended.last;
    store_pushing(s, sums.pushing, ended.pushing);
    return s;
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
