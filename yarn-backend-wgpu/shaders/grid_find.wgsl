// A rebuild's second pass (indirect, after `grid_insert.wgsl`): each
// segment walks the buckets of the cells it searches and the long list, and
// keeps, sorted, every segment that may touch it under the model's rule and
// is within 2r plus the skin; every node records where it is (its anchor).
// A list longer than its slots raises CROWDED, and yarn stretched past what
// the grid covers STRETCHED: the host puts the batch back and grows the
// lists, or reports it; nothing is truncated silently. It also empties the
// other half of the bucket heads for the next rebuild. CPU twin:
// `grid::find`.
//
// `rule` holds per node: its yarn's first node, its yarn's node count (the
// top bit set for a closed yarn) and how many segments after it are near
// it (`ContactRule::ahead`).

@group(0) @binding(0) var<uniform> p: Params;
@group(0) @binding(1) var<storage, read> x: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read_write> lists: array<u32>;
@group(0) @binding(3) var<storage, read_write> grid: array<atomic<u32>>;
@group(0) @binding(4) var<storage, read> rule: array<u32>;
@group(0) @binding(5) var<storage, read_write> status: array<atomic<u32>>;

const CLOSED: u32 = 0x80000000u;

// Whether `to` is at most `ahead` segments after `start` along a yarn of
// `len` nodes.
fn within(start: u32, to: u32, ahead: u32, len: u32, closed: bool) -> bool {
    if to >= start {
        return to - start <= ahead;
    }
    return closed && to + len - start <= ahead;
}

// `ContactRule::near_along_yarn`.
fn near_along_yarn(a: u32, b: u32) -> bool {
    if rule[3u * a] != rule[3u * b] {
        return false;
    }
    let len = rule[3u * a + 1u] & ~CLOSED;
    let closed = (rule[3u * a + 1u] & CLOSED) != 0u;
    return within(a, b, rule[3u * a + 2u], len, closed) || within(b, a, rule[3u * b + 2u], len, closed);
}

// `grid::may_touch`: whether segments i and j (i ≠ j) may touch.
fn may_touch(i: u32, j: u32) -> bool {
    if near_along_yarn(i, j) {
        return false;
    }
    let lo = min(i, j);
    let hi = max(i, j);
    let p0 = x[lo].xyz;
    let p1 = x[segment_end(lo)].xyz;
    let q0 = x[hi].xyz;
    let q1 = x[segment_end(hi)].xyz;
    return !apart(p0, p1, q0, q1, p.search_reach) && norm(closest_gap(p0, p1, q0, q1).gap) < p.search_reach;
}

// Keep j among segment i's `count` candidates so far, if it may touch i:
// insertion keeps the slots sorted; past the slots only the count grows.
fn keep(i: u32, j: u32, count: u32) -> u32 {
    if j == i || !may_touch(i, j) {
        return count;
    }
    if count < p.slots {
        var k = count;
        while k > 0u && lists[slot_at(i, k - 1u)] > j {
            lists[slot_at(i, k)] = lists[slot_at(i, k - 1u)];
            k -= 1u;
        }
        lists[slot_at(i, k)] = j;
    }
    return count + 1u;
}

// The search reached past what the grid covers.
fn overstretched() {
    atomicOr(&status[0], STRETCHED);
}

@compute @workgroup_size(WORKGROUP)
fn main(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_id) local: vec3<u32>,
        @builtin(num_workgroups) groups: vec3<u32>) {
    let i = thread_index(group, local, groups);
    if i >= p.nodes {
        return;
    }
    let generation = atomicLoad(&grid[GENERATION]);
    let other = heads_at(generation + 1u);
    for (var b = i; b <= p.mask; b += p.nodes) {
        atomicStore(&grid[other + b], EMPTY);
    }
    let at = x[i].xyz;
    lists[anchor_at(i, 0u)] = bitcast<u32>(at.x);
    lists[anchor_at(i, 1u)] = bitcast<u32>(at.y);
    lists[anchor_at(i, 2u)] = bitcast<u32>(at.z);
    let end = segment_end(i);
    lists[field_at(i, COUNT)] = 0u;
    let long_count = atomicLoad(&grid[LONG_COUNT]);
    if end == NONE {
        return;
    }
    if long_count > MAX_LONG {
        overstretched();
        return;
    }
    // `GridShape::search_box`: the 27 cells around a short segment's own;
    // a long one's bounding box, widened by the reach and half of short.
    let tip = x[end].xyz;
    var lo: vec3<i32>;
    var hi: vec3<i32>;
    if norm(tip - at) <= p.short {
        let home = cell_of(midpoint(at, tip));
        lo = home - vec3<i32>(1);
        hi = home + vec3<i32>(1);
    } else {
        let pad = vec3<f32>(p.search_reach + mul(p.short, 0.5));
        lo = cell_of(min(at, tip) - pad);
        hi = cell_of(max(at, tip) + pad);
        let size = hi - lo;
        if !(all(size >= vec3<i32>(0)) && all(size < vec3<i32>(MAX_BOX))) {
            overstretched();
            return;
        }
    }
    let heads = heads_at(generation);
    var count = 0u;
    for (var z = lo.z; z <= hi.z; z++) {
        for (var y = lo.y; y <= hi.y; y++) {
            for (var w = lo.x; w <= hi.x; w++) {
                let cell = vec3<i32>(w, y, z);
                var j = atomicLoad(&grid[heads + bucket(cell)]);
                // A list holds each segment once; the bound only keeps a
                // corrupted one from hanging the device.
                for (var steps = 0u; j != EMPTY && steps < p.nodes; steps++) {
                    // Only from its own cell's bucket: a bucket holds every
                    // cell that hashes to it.
                    if all(cell_of(midpoint(x[j].xyz, x[segment_end(j)].xyz)) == cell) {
                        count = keep(i, j, count);
                    }
                    j = atomicLoad(&grid[next_at(j)]);
                }
            }
        }
    }
    for (var k = 0u; k < long_count; k++) {
        count = keep(i, atomicLoad(&grid[long_at(k)]), count);
    }
    lists[field_at(i, COUNT)] = min(count, p.slots);
    if count > p.slots {
        atomicOr(&status[0], CROWDED);
        atomicMax(&status[1], count);
    }
}
