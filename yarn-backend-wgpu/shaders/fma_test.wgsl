// Whether this device's `fma` rounds once: with a = b = 1 + 2^-23 and
// c = -(1 + 2^-22), a fused multiply-add returns 2^-46, a separate multiply
// and add return 0. The inputs come from a buffer so nothing is folded at
// compile time (`Gpu::new` runs this once).

@group(0) @binding(0) var<storage, read> input: array<f32>;
@group(0) @binding(1) var<storage, read_write> output: array<f32>;
// Not used here; declared because the shared prelude's formulas read it.
@group(0) @binding(2) var<uniform> p: Params;

@compute @workgroup_size(1)
fn main() {
    output[0] = fma(input[0], input[1], input[2]);
}
