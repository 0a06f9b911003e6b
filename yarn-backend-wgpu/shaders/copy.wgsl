// A plain copy of 16-byte elements, to measure the memory bandwidth a
// pass can reach on this device (`Gpu::copy_bandwidth`).

@group(0) @binding(0) var<storage, read> source: array<vec4<f32>>;
// Not used here; declared because the shared prelude's formulas read it.
@group(0) @binding(2) var<uniform> p: Params;
@group(0) @binding(1) var<storage, read_write> to: array<vec4<f32>>;

@compute @workgroup_size(WORKGROUP)
fn main(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_id) local: vec3<u32>,
        @builtin(num_workgroups) groups: vec3<u32>) {
    let i = thread_index(group, local, groups);
    if i < arrayLength(&to) {
        to[i] = source[i];
    }
}
