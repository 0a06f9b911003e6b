// A rebuild's first pass (indirect: `plan.wgsl` dispatches it only when the
// lists are stale): each segment up to `p.short` long pushes itself onto its
// bucket's list, and each longer one onto the long list. CPU twin:
// `grid::insert`.

@group(0) @binding(0) var<uniform> p: Params;
@group(0) @binding(1) var<storage, read> x: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> lists: array<u32>;
@group(0) @binding(3) var<storage, read_write> grid: array<atomic<u32>>;

@compute @workgroup_size(WORKGROUP)
fn main(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_id) local: vec3<u32>,
        @builtin(num_workgroups) groups: vec3<u32>) {
    let i = thread_index(group, local, groups);
    if i >= p.nodes {
        return;
    }
    atomicStore(&grid[next_at(i)], EMPTY);
    let end = segment_end(i);
    if end == NONE {
        return;
    }
    let a = x[i].xyz;
    let b = x[end].xyz;
    if norm(b - a) <= p.short {
        let heads = heads_at(atomicLoad(&grid[GENERATION]));
        atomicStore(&grid[next_at(i)], atomicExchange(&grid[heads + bucket(cell_of(midpoint(a, b)))], i));
    } else {
        let k = atomicAdd(&grid[LONG_COUNT], 1u);
        if k < MAX_LONG {
            atomicStore(&grid[long_at(k)], i);
        }
    }
}
