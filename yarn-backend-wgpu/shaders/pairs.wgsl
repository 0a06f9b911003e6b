// Self-contact's per-segment passes (`touch.wgsl`): each segment sums its
// candidates' pushes (entry point `forces`, before the step) or friction
// changes from x and v* (entry point `friction`, after it) on its first
// node and on its last, once for both, and stores them for the node passes,
// which add the sums of the two segments each node touches. CPU twin: the
// pair passes and per-segment sums of yarn-backend-cpu's
// `fabric/touching.rs`.

@group(0) @binding(0) var<uniform> p: Params;
@group(0) @binding(1) var<storage, read> x: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> v: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read_write> lists: array<u32>;

fn v_star(j: u32) -> vec3<f32> {
    return v[j].xyz;
}

@compute @workgroup_size(WORKGROUP)
fn forces(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_id) local: vec3<u32>,
          @builtin(num_workgroups) groups: vec3<u32>) {
    let s = thread_index(group, local, groups);
    if s < p.nodes && segment_end(s) != NONE {
        store_sums(s, segment_sums(s, false));
    }
}

@compute @workgroup_size(WORKGROUP)
fn friction(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_id) local: vec3<u32>,
            @builtin(num_workgroups) groups: vec3<u32>) {
    let s = thread_index(group, local, groups);
    if s < p.nodes && segment_end(s) != NONE {
        store_sums(s, segment_sums(s, true));
    }
}
