// The candidate grid shared by `plan.wgsl`, `grid_insert.wgsl` and
// `grid_find.wgsl` (their CPU twins are in `yarn_model::self_contact::grid`,
// which says why it works): each segment up to `p.short` long falls in the
// cell of its midpoint, of edge `p.cell`, and each cell hashes to one of
// `p.mask + 1` buckets, a linked list of segments threaded through `next`;
// a longer segment goes into the long list instead.
//
// `grid` (array<atomic<u32>>) holds how many segments are long, the
// generation (how many rebuilds have started), two halves of bucket heads,
// `next`, and the long list. Each rebuild pushes onto the half of its
// generation while `grid_find.wgsl` empties the other for the next one, so
// no pass is needed to clear them.

const LONG_COUNT: u32 = 0u;
const GENERATION: u32 = 1u;
const HEADS: u32 = 4u;
const EMPTY: u32 = 0xffffffffu;
// The most long segments a rebuild holds (`grid::MAX_LONG`), and cells
// along each side of a long segment's search box (`grid::MAX_BOX`).
const MAX_LONG: u32 = 4096u;
const MAX_BOX: i32 = 16;

// Where the bucket heads of generation g start, segment s's `next`, and
// the long list's k-th entry.
fn heads_at(generation: u32) -> u32 {
    return HEADS + (generation & 1u) * (p.mask + 1u);
}

fn next_at(s: u32) -> u32 {
    return HEADS + 2u * (p.mask + 1u) + s;
}

fn long_at(k: u32) -> u32 {
    return HEADS + 2u * (p.mask + 1u) + p.nodes + k;
}

fn midpoint(a: vec3<f32>, b: vec3<f32>) -> vec3<f32> {
    return mul3(a + b, 0.5);
}

// `GridShape::cell_of`: clamped to ±2³⁰ cells.
fn cell_of(m: vec3<f32>) -> vec3<i32> {
    let q = floor(vec3<f32>(div_rounded(m.x, p.cell), div_rounded(m.y, p.cell), div_rounded(m.z, p.cell)));
    let bound = vec3<f32>(1073741824.0);
    return select(vec3<i32>(0), vec3<i32>(clamp(q, -bound, bound)), q == q);
}

// `GridShape::bucket`.
fn bucket(c: vec3<i32>) -> u32 {
    let u = bitcast<vec3<u32>>(c);
    return ((u.x * 73856093u) ^ (u.y * 19349663u) ^ (u.z * 83492791u)) & p.mask;
}
