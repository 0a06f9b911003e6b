// The divergence check, one dispatch at the end of each batch (so the
// substeps themselves pay nothing): a node whose position is not finite, or
// whose velocity is not finite or faster than `p.max_speed`, raises
// DIVERGED in `status[0]`. A blown-up state stays blown up (NaN and
// infinities do not heal), so checking the batch's end catches it. With
// self-contact, a node that passed the speed in any substep of the batch
// (`lists[SPEEDING]`, `touch.wgsl`'s `watch_speed`) raises it too: it may
// have jumped through yarn.

@group(0) @binding(0) var<uniform> p: Params;
@group(0) @binding(1) var<storage, read> x: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> v: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read_write> status: array<atomic<u32>>;
@group(0) @binding(4) var<storage, read_write> lists: array<u32>;

// The largest finite f32: NaN and the infinities fail `<=` against it.
const FINITE: f32 = 0x1.fffffep+127f;

@compute @workgroup_size(WORKGROUP)
fn main(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_id) local: vec3<u32>,
        @builtin(num_workgroups) groups: vec3<u32>) {
    let i = thread_index(group, local, groups);
    if i == 0u && (p.flags & SELF_CONTACT) != 0u && lists[SPEEDING] != 0u {
        atomicOr(&status[0], DIVERGED);
        lists[SPEEDING] = 0u;
    }
    if i == 0u && (p.flags & SELF_CONTACT) != 0u && lists[LATE] != 0u {
        atomicOr(&status[0], LATE_REBUILD);
        lists[LATE] = 0u;
    }
    if i >= p.nodes {
        return;
    }
    let fine = all(abs(x[i].xyz) <= vec3<f32>(FINITE)) && all(abs(v[i].xyz) <= vec3<f32>(p.max_speed));
    if !fine {
        atomicOr(&status[0], DIVERGED);
    }
}
