// Gather mode for small fabrics (up to SMALL_THREADS × SMALL_NODES
// nodes): SMALL_BATCH whole substeps in one dispatch of one workgroup,
// with barriers between the phases instead of one dispatch per phase. On
// a small fabric the cost of a dispatch, not the arithmetic, sets the
// pace. Each thread keeps its nodes' new state in registers until every
// thread has read the old one, so one pair of state buffers suffices.

@group(0) @binding(0) var<uniform> p: Params;
@group(0) @binding(1) var<storage, read_write> x: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read_write> v: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> chain: array<vec2<f32>>;
@group(0) @binding(4) var<storage, read> contacts: array<Contact>;
@group(0) @binding(5) var<storage, read> start: array<u32>;
@group(0) @binding(6) var<storage, read> incident: array<u32>;
@group(0) @binding(7) var<storage, read> pins: array<Pin>;

// Mirrored by `SMALL_THREADS`, `SMALL_NODES` and `SMALL_BATCH` in src/lib.rs.
const SMALL_THREADS: u32 = 256u;
const SMALL_NODES: u32 = 16u;
const SMALL_BATCH: u32 = 16u;

@compute @workgroup_size(SMALL_THREADS)
fn main(@builtin(local_invocation_index) t: u32) {
    var x_new: array<vec3<f32>, SMALL_NODES>;
    var v_new: array<vec3<f32>, SMALL_NODES>;
    let friction = (p.flags & FRICTION_ON) != 0u;
    for (var s = 0u; s < SMALL_BATCH; s++) {
        // Forces from x and the damped update v* (SPEC §4 steps 1–2). Only
        // this thread reads its nodes' v, so v* can be stored at once.
        for (var k = 0u; k < SMALL_NODES; k++) {
            let i = t + k * SMALL_THREADS;
            if i < p.nodes {
                let velocity = (v[i].xyz + node_force(i) * p.h_over_m) * p.damping_factor;
                v[i] = vec4<f32>(velocity, 0.0);
                x_new[k] = x[i].xyz + velocity * p.h;
            }
        }
        storageBarrier();
        if friction {
            // Friction from x and v*, then the move (steps 3–4).
            for (var k = 0u; k < SMALL_NODES; k++) {
                let i = t + k * SMALL_THREADS;
                if i < p.nodes {
                    v_new[k] = v[i].xyz + node_friction(i);
                    x_new[k] = x[i].xyz + v_new[k] * p.h;
                }
            }
            storageBarrier();
        }
        for (var k = 0u; k < SMALL_NODES; k++) {
            let i = t + k * SMALL_THREADS;
            if i < p.nodes {
                x[i] = vec4<f32>(x_new[k], 0.0);
                if friction {
                    v[i] = vec4<f32>(v_new[k], 0.0);
                }
            }
        }
        storageBarrier();
        // Pins (step 5).
        for (var k = t; k < p.pins; k += SMALL_THREADS) {
            x[pins[k].node] = vec4<f32>(pins[k].goal, 0.0);
            v[pins[k].node] = vec4<f32>(0.0);
        }
        storageBarrier();
    }
}
