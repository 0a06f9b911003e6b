// The candidate lists' layout and the closest-point arithmetic shared by
// the self-contact passes (`touch.wgsl`, `grid_insert.wgsl`,
// `grid_find.wgsl`, `plan.wgsl`, `check.wgsl`), which declare `p`, `x` and
// `lists`.
//
// `lists` (array<u32>) holds, after a small header, rows of one word per
// node (or per segment, which node i starts), each row a field, so that
// neighbouring threads read and write neighbouring words:
// - the node's record: whether a pin holds it (1) or not (0), the node
//   after it along its yarn (NONE where none), how many candidates the
//   segment it starts has, and which of its first 32 push (`gather.wgsl`);
// - the position it was at when the lists were last built (the anchor), as
//   f32 bits, x, y and z;
// - `p.slots` candidate rows: the partner segments, sorted, slot k of
//   every segment in row k.

// `lists[STALE]`: some node has moved, or at its speed soon will have
// moved, half the skin since the last build (set by the move, read by
// `plan.wgsl`); `lists[SPEEDING]`: some node's velocity after friction
// passed `p.max_speed` (set by the pass that moves it, read by
// `check.wgsl`); `lists[FAR]`: some node has moved half the skin since the
// last build, so the lists may miss a pair within reach until the next
// (set by the move, cleared by the rebuild); `lists[LATE]`: the pushes ran
// with `lists[FAR]` set (set by `gather.wgsl`, read by `check.wgsl`). Any
// thread may set any; all write the same 1.
const STALE: u32 = 0u;
const SPEEDING: u32 = 1u;
const FAR: u32 = 2u;
const LATE: u32 = 3u;
const RECORDS: u32 = 4u;

// Rows of the record, after the header.
const PINNED: u32 = 0u;
const NEXT: u32 = 1u;
const COUNT: u32 = 2u;
const PUSHING: u32 = 3u;
const ANCHOR: u32 = 4u;
const SLOTS: u32 = 7u;

// Where field `row` of node (or segment) i is.
fn field_at(i: u32, row: u32) -> u32 {
    return RECORDS + row * p.nodes + i;
}

// Component c of node i's anchor.
fn anchor_at(i: u32, c: u32) -> u32 {
    return field_at(i, ANCHOR + c);
}

fn slot_at(s: u32, k: u32) -> u32 {
    return field_at(s, SLOTS + k);
}

// The node segment s ends at (NONE where none starts at s).
fn segment_end(s: u32) -> u32 {
    return lists[field_at(s, NEXT)];
}

// `terms::closest_parameters` and `terms::closest_gap`: the vector between
// the closest points of segments p0p1 and q0q1, at parameters (s, t).
struct Closest {
    gap: vec3<f32>,
    s: f32,
    t: f32,
}

fn unit(c: f32) -> f32 {
    return clamp(c, 0.0, 1.0);
}

fn closest_parameters(p0: vec3<f32>, p1: vec3<f32>, q0: vec3<f32>, q1: vec3<f32>) -> vec2<f32> {
    let u = p1 - p0;
    let v = q1 - q0;
    let w = p0 - q0;
    let a = dot3(u, u);
    let e = dot3(v, v);
    let f = dot3(v, w);
    if a <= 0.0 {
        return vec2<f32>(0.0, select(0.0, unit(div_rounded(f, select(1.0, e, e > 0.0))), e > 0.0));
    }
    let c = dot3(u, w);
    if e <= 0.0 {
        return vec2<f32>(unit(div_rounded(-c, a)), 0.0);
    }
    let b = dot3(u, v);
    let det = mul(a, e) - mul(b, b);
    var s = 0.0;
    if det > mul(mul(1e-6, a), e) {
        s = unit(div_rounded(mul(b, f) - mul(c, e), det));
    }
    let t = div_rounded(mul(b, s) + f, e);
    if t < 0.0 {
        return vec2<f32>(unit(div_rounded(-c, a)), 0.0);
    }
    if t > 1.0 {
        return vec2<f32>(unit(div_rounded(b - c, a)), 1.0);
    }
    return vec2<f32>(s, t);
}

fn closest_gap(p0: vec3<f32>, p1: vec3<f32>, q0: vec3<f32>, q1: vec3<f32>) -> Closest {
    let st = closest_parameters(p0, p1, q0, q1);
    return Closest(p0 + mul3(p1 - p0, st.x) - q0 - mul3(q1 - q0, st.y), st.x, st.y);
}

// Whether segments p0p1 and q0q1 are surely farther apart than `reach` on
// some axis, with a sixteenth to spare for rounding: then the exact test
// would find them out of reach too, and it is skipped.
fn apart(p0: vec3<f32>, p1: vec3<f32>, q0: vec3<f32>, q1: vec3<f32>, reach: f32) -> bool {
    let gaps = max(min(q0, q1) - max(p0, p1), min(p0, p1) - max(q0, q1));
    return any(gaps > vec3<f32>(reach * 1.0625));
}

