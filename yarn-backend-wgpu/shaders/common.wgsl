// Shared by every pass (prepended to each pass file when it is loaded): the
// parameters, the thread index, and the element formulas of
// `yarn_model::terms`, operation for operation, written with selects so a
// degenerate element contributes zero instead of branching.

// Mirrors `GpuParams` in src/layout.rs; a test checks the layout.
struct Params {
    nodes: u32,
    contacts: u32,
    pins: u32,
    // Bit 0: friction is on (μ > 0), so the move happens in the friction pass.
    flags: u32,
    stretch: f32,
    bend: f32,
    contact: f32,
    friction: f32,
    h: f32,
    h_over_m: f32,
    damping_factor: f32,
    friction_impulse: f32,
    gravity_y: f32,
    min_sin: f32,
    // Fixed-point scale S and the largest force it quantises safely.
    scale: f32,
    max_force: f32,
    // Always 1.0; see `mul`.
    one: f32,
    // The speed beyond which a node has diverged (`Model::divergence_speed`).
    max_speed: f32,
    // How far a re-seated contact's rest separation closes per substep, and
    // how many the reseat pass holds (`reseat.wgsl`).
    reseat_step: f32,
    reseats: u32,
    // Self-contact (`touch.wgsl`): k_sc, h k_sc / m, and the reach 2r.
    self_contact: f32,
    self_impulse: f32,
    reach: f32,
    // The yarn radius r, k_col and h k_col / m, for the colliders.
    radius: f32,
    collider: f32,
    collider_impulse: f32,
    // The candidate grid (`grid_insert.wgsl`, `grid_find.wgsl`): the cell's
    // edge, the reach 2r plus the skin, half the skin, buckets − 1, slots
    // per segment's list.
    cell: f32,
    search_reach: f32,
    half_skin: f32,
    mask: u32,
    slots: u32,
    // How many of `surfaces` are set.
    colliders: u32,
    // The workgroups of a full rebuild, for `plan.wgsl`'s indirect dispatch.
    rebuild_x: u32,
    rebuild_y: u32,
    // The longest segment the grid holds; longer ones are long (`grid.wgsl`).
    short: f32,
    // How far ahead a node's speed is projected when it decides whether to
    // ask for a rebuild (`watch.wgsl`): none where every substep may
    // rebuild, a few substeps where only some do.
    lookahead: f32,
    surfaces: array<Surface, MAX_COLLIDERS>,
}

// Mirrors `GpuSurface`: a plane collider (`yarn_model::collider::Surface`),
// its unit normal n, n · (a point on it), the depth of solid behind it and
// its friction coefficient.
struct Surface {
    normal: vec3<f32>,
    offset: f32,
    thickness: f32,
    friction: f32,
}

const MAX_COLLIDERS: u32 = 8u;

// Mirrors `GpuContact`.
struct Contact {
    a: u32,
    b: u32,
    rest: f32,
    alive: u32,
}

// Mirrors `GpuChain`: node i's place in its yarn. The rest length of the
// segment from i to `next` and the turning angle κθ0 the joint centred on i
// rests at (both zero where there is none), and i's neighbours along its
// yarn, NONE at an open yarn's ends (a closed yarn's wrap around).
struct Chain {
    rest_length: f32,
    rest_turn: f32,
    prev: u32,
    next: u32,
}

const NONE: u32 = 0xffffffffu;

// Mirrors `GpuPin`.
struct Pin {
    goal: vec3<f32>,
    node: u32,
}

const WORKGROUP: u32 = 128u;
const FRICTION_ON: u32 = 1u;
// Bit 1: the device's `fma` rounds once (`Gpu::new` tests it), so the
// correction steps below are exact and are taken.
const FUSED_FMA: u32 = 2u;
// Bits of `status[0]`, which the host reads and clears after each batch
// (in the browser, when the page asks): a fixed-point force or sum
// overflowed; the state diverged.
const OVERFLOWED: u32 = 1u;
const DIVERGED: u32 = 2u;
// More self-contact candidates near a segment than its list holds
// (`status[1]`: how many); yarn stretched past what the grid's search
// covers (`grid.wgsl`).
const CROWDED: u32 = 4u;
const STRETCHED: u32 = 8u;
// The pushes ran on lists a node had moved half the skin from
// (`lists[LATE]`): the batch runs again with a rebuild check every substep.
const LATE_REBUILD: u32 = 16u;
// `Params::flags` bit: self-contact is on.
const SELF_CONTACT: u32 = 4u;
// `Params::flags` bit: stretched contacts have friction too.
const FRICTION_IN_TENSION: u32 = 8u;

// The global thread index of a dispatch that may be two-dimensional (a
// fabric with more workgroups than one dimension allows).
fn thread_index(group: vec3<u32>, local: vec3<u32>, groups: vec3<u32>) -> u32 {
    return (group.y * groups.x + group.x) * WORKGROUP + local.x;
}

// The CPU rounds every product, sum, square root and quotient on its own.
// A GPU compiler may fuse a product into the add that follows, and its
// `sqrt` and division may be off by an ulp or two; either moves a segment's
// length by an ulp, which k_s turns into a force error the size of the
// tolerance. So the formulas below round as the CPU does:
// - `mul`: a product times the uniform `p.one` (always 1.0), which the
//   compiler cannot see through, so the rounded product is what any fused
//   add receives;
// - `sqrt_rounded`, `div_rounded`: one correction step with the exact
//   residual from `fma`, which lands on the correctly rounded result. A
//   device whose `fma` is not fused (lavapipe) gets no exact residual, but
//   its `sqrt` and division are correctly rounded already: it skips the
//   step.
fn mul(a: f32, b: f32) -> f32 {
    return a * b * p.one;
}

fn mul3(a: vec3<f32>, b: f32) -> vec3<f32> {
    return a * b * p.one;
}

// `a` as computed: the select's condition never holds (no parameter sets
// every flag) but the compiler cannot know it, so it cannot merge the
// arithmetic on either side. A product added to a sum needs it: `mul3`'s
// `p.one` alone did not stop lavapipe from fusing a sum of two of them, nor
// the H200 from fusing a collider's push, or a pair's share, into a sum.
fn kept3(a: vec3<f32>) -> vec3<f32> {
    return select(a, vec3<f32>(0.0), p.flags == 0xffffffffu);
}

fn sqrt_rounded(x: f32) -> f32 {
    let s = sqrt(x);
    return select(s, fma(fma(-s, s, x), 0.5 / s, s), s > 0.0 && (p.flags & FUSED_FMA) != 0u);
}

// For b ≠ 0.
fn div_rounded(a: f32, b: f32) -> f32 {
    let q = a / b;
    return select(q, fma(fma(-q, b, a), 1.0 / b, q), (p.flags & FUSED_FMA) != 0u);
}

fn norm(d: vec3<f32>) -> f32 {
    return sqrt_rounded(mul(d.x, d.x) + mul(d.y, d.y) + mul(d.z, d.z));
}

// Abramowitz & Stegun 4.4.46, as `Real::turning_angle` for f32.
fn turning_angle(c: f32) -> f32 {
    let x = abs(c);
    var q = -0.0012624911;
    q = mul(q, x) + 0.0066700901;
    q = mul(q, x) + -0.0170881256;
    q = mul(q, x) + 0.0308918810;
    q = mul(q, x) + -0.0501743046;
    q = mul(q, x) + 0.0889789874;
    q = mul(q, x) + -0.2145988016;
    q = mul(q, x) + 1.5707963050;
    let angle = mul(sqrt_rounded(max(1.0 - x, 0.0)), q);
    return select(angle, 3.14159265358979 - angle, c < 0.0);
}

// v* = (v + h F / m) / (1 + βh) (SPEC §4 step 2), rounded as the CPU does.
fn damped_velocity(v: vec3<f32>, f: vec3<f32>) -> vec3<f32> {
    return mul3(v + mul3(f, p.h_over_m), p.damping_factor);
}

// `terms::spring_force`: the force on `a` of a spring from a to b = a + d.
fn spring_force(d: vec3<f32>, rest: f32, k: f32) -> vec3<f32> {
    let length = norm(d);
    let positive = length > 0.0;
    let scale = div_rounded(k * (length - rest), select(1.0, length, positive));
    return select(vec3<f32>(0.0), mul3(d, scale), positive);
}

// A segment's unit tangent and inverse length (both zero when degenerate).
struct Segment {
    tangent: vec3<f32>,
    inv_length: f32,
}

fn segment_of(d: vec3<f32>) -> Segment {
    let length = norm(d);
    let inv = select(0.0, div_rounded(1.0, select(1.0, length, length > 0.0)), length > 0.0);
    return Segment(mul3(d, inv), inv);
}

// `terms::bend_forces` from a joint's two segments: the forces on its first
// and last node (the middle node takes minus their sum).
struct JointForces {
    first: vec3<f32>,
    last: vec3<f32>,
}

fn joint_forces(s0: Segment, s1: Segment, rest_angle: f32, k: f32, min_sin: f32) -> JointForces {
    let u = s0.tangent;
    let v = s1.tangent;
    let s = clamp(mul(u.x, v.x) + mul(u.y, v.y) + mul(u.z, v.z), -1.0, 1.0);
    let sin_theta = sqrt_rounded(1.0 - mul(s, s));
    let keep = sin_theta >= min_sin && s0.inv_length > 0.0 && s1.inv_length > 0.0;
    let coeff = select(0.0, div_rounded(k * (turning_angle(s) - rest_angle), select(1.0, sin_theta, keep)), keep);
    return JointForces(
        mul3(v - mul3(u, s), -coeff * s0.inv_length),
        mul3(u - mul3(v, s), coeff * s1.inv_length),
    );
}

// `step::friction_change`: the change Δw to w = v_b − v_a of a contact with
// gap d = x_b − x_a, or zero when it is not compressed (or with
// FRICTION_IN_TENSION stretched) or does not slip.
fn friction_change(d: vec3<f32>, w: vec3<f32>, rest: f32) -> vec3<f32> {
    let length = norm(d);
    let in_tension = (p.flags & FRICTION_IN_TENSION) != 0u;
    let strained = (length < rest || (in_tension && length > rest)) && length > 0.0;
    let divisor = select(1.0, length, strained);
    let n = vec3<f32>(div_rounded(d.x, divisor), div_rounded(d.y, divisor), div_rounded(d.z, divisor));
    let wt = w - mul3(n, mul(w.x, n.x) + mul(w.y, n.y) + mul(w.z, n.z));
    let slip = norm(wt);
    let keep = strained && slip > 0.0;
    let dv_normal = p.friction_impulse * abs(rest - length);
    let retention = max(1.0 - div_rounded(p.friction * dv_normal, select(1.0, slip, keep)), 0.0);
    return select(vec3<f32>(0.0), mul3(wt, retention - 1.0), keep);
}

// x · y, rounded as nalgebra's `dot` for 3-vectors: (x0 y0 + x1 y1) + x2 y2.
fn dot3(a: vec3<f32>, b: vec3<f32>) -> f32 {
    return mul(a.x, b.x) + mul(a.y, b.y) + mul(a.z, b.z);
}

// `Surface::depth`: how deep a node at `at` presses into collider k (r less
// its centreline's height), or 0 where it does not or is past the far side.
fn collider_depth(k: u32, at: vec3<f32>) -> f32 {
    let s = p.surfaces[k];
    let height = dot3(s.normal, at) - s.offset;
    let depth = p.radius - height;
    return select(0.0, depth, depth > 0.0 && height > -s.thickness);
}

// `f` plus every collider's push on a node at `at` (`Surface::force`, in
// collider order), as the CPU's block pass adds them.
fn with_colliders(f: vec3<f32>, at: vec3<f32>) -> vec3<f32> {
    var sum = f;
    for (var k = 0u; k < p.colliders; k++) {
        let depth = collider_depth(k, at);
        if depth > 0.0 {
            sum += kept3(mul3(p.surfaces[k].normal, mul(p.collider, depth)));
        }
    }
    return sum;
}

// `step::collider_friction`: the colliders' friction change to the velocity
// `w` (v*) of a node at `at`, summed in collider order.
fn collider_friction(at: vec3<f32>, w: vec3<f32>) -> vec3<f32> {
    var dv = vec3<f32>(0.0);
    for (var k = 0u; k < p.colliders; k++) {
        let s = p.surfaces[k];
        let depth = collider_depth(k, at);
        let slip = w - kept3(mul3(s.normal, dot3(s.normal, w)));
        let speed = norm(slip);
        if depth > 0.0 && speed > 0.0 {
            let retention = max(1.0 - div_rounded(mul(mul(s.friction, p.collider_impulse), depth), speed), 0.0);
            dv += kept3(mul3(slip, retention - 1.0));
        }
    }
    return dv;
}
