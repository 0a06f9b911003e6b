// Fixed-point mode, the paper's scheme (its Algorithm 1 and Appendix C):
// every element scatters round(f·S) into three i32 accumulators per node
// with atomicAdd. A force too large to quantise, or a sum that wraps, raises
// OVERFLOWED in `status[0]`, which the host checks after the batch; nothing
// wraps silently.

@group(0) @binding(0) var<uniform> p: Params;
@group(0) @binding(1) var<storage, read> x: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read_write> v: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read_write> out: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read> chain: array<Chain>;
@group(0) @binding(5) var<storage, read> contacts: array<Contact>;
@group(0) @binding(6) var<storage, read_write> acc: array<atomic<i32>>;
@group(0) @binding(7) var<storage, read_write> status: array<atomic<u32>>;

fn add(node: u32, f: vec3<f32>) {
    let q = f * p.scale;
    // Also catches NaN, which fails every comparison.
    if !(abs(q.x) <= p.max_force * p.scale && abs(q.y) <= p.max_force * p.scale && abs(q.z) <= p.max_force * p.scale) {
        atomicOr(&status[0], OVERFLOWED);
        return;
    }
    let quanta = vec3<i32>(round(q));
    for (var c = 0u; c < 3u; c++) {
        let old = atomicAdd(&acc[3u * node + c], quanta[c]);
        let sum = old + quanta[c];
        // Two's-complement overflow: both addends' signs differ from the sum's.
        if ((old ^ sum) & (quanta[c] ^ sum)) < 0 {
            atomicOr(&status[0], OVERFLOWED);
        }
    }
}

// Thread t handles the segment leaving node t, the joint centred on node t
// and contact t, where they exist; segments and joints follow each yarn
// through `chain`, wrapping around closed ones.
@compute @workgroup_size(WORKGROUP)
fn scatter(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_id) local: vec3<u32>,
           @builtin(num_workgroups) groups: vec3<u32>) {
    let t = thread_index(group, local, groups);
    if t < p.nodes {
        let here = chain[t];
        // t's neighbours are almost always the nodes beside it: read those
        // at once, and a closed yarn's wrap through its links.
        let at = x[t].xyz;
        var before = x[max(t, 1u) - 1u].xyz;
        var after = x[min(t + 1u, p.nodes - 1u)].xyz;
        if here.prev != NONE && here.prev + 1u != t {
            before = x[here.prev].xyz;
        }
        if here.next != NONE && here.next != t + 1u {
            after = x[here.next].xyz;
        }
        if here.next != NONE {
            let f = spring_force(after - at, here.rest_length, p.stretch);
            add(t, f);
            add(here.next, -f);
        }
        if here.prev != NONE && here.next != NONE {
            let joint = joint_forces(segment_of(at - before), segment_of(after - at), here.rest_turn, p.bend, p.min_sin);
            add(here.prev, joint.first);
            add(t, -(joint.first + joint.last));
            add(here.next, joint.last);
        }
    }
    if t < p.contacts {
        let c = contacts[t];
        if c.alive != 0u {
            let f = spring_force(x[c.b].xyz - x[c.a].xyz, c.rest, p.contact);
            add(c.a, f);
            add(c.b, -f);
        }
    }
}

// Read and clear node i's accumulators: its force, plus gravity. The
// update of `update.wgsl` calls this.
fn total_force(i: u32) -> vec3<f32> {
    let q = vec3<f32>(f32(atomicExchange(&acc[3u * i], 0)), f32(atomicExchange(&acc[3u * i + 1u], 0)),
                      f32(atomicExchange(&acc[3u * i + 2u], 0)));
    return q / p.scale + vec3<f32>(0.0, p.gravity_y, 0.0);
}

// Fixed point runs no self-contact: a thread's node is its index, and
// there is nothing to watch.
fn node_of(group: vec3<u32>, local: vec3<u32>, groups: vec3<u32>) -> u32 {
    return thread_index(group, local, groups);
}

fn watch_speed(i: u32, velocity: vec3<f32>) {}

fn watch_move(i: u32, at: vec3<f32>, velocity: vec3<f32>) {}
