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
}

// Mirrors `GpuContact`.
struct Contact {
    a: u32,
    b: u32,
    rest: f32,
    alive: u32,
}

// Mirrors `GpuPin`.
struct Pin {
    goal: vec3<f32>,
    node: u32,
}

const WORKGROUP: u32 = 128u;
const FRICTION_ON: u32 = 1u;

// The global thread index of a dispatch that may be two-dimensional (a
// fabric with more workgroups than one dimension allows).
fn thread_index(group: vec3<u32>, local: vec3<u32>, groups: vec3<u32>) -> u32 {
    return (group.y * groups.x + group.x) * WORKGROUP + local.x;
}

// Abramowitz & Stegun 4.4.46, as `Real::turning_angle` for f32.
fn turning_angle(c: f32) -> f32 {
    let x = abs(c);
    var q = -0.0012624911;
    q = q * x + 0.0066700901;
    q = q * x + -0.0170881256;
    q = q * x + 0.0308918810;
    q = q * x + -0.0501743046;
    q = q * x + 0.0889789874;
    q = q * x + -0.2145988016;
    q = q * x + 1.5707963050;
    let angle = sqrt(max(1.0 - x, 0.0)) * q;
    return select(angle, 3.14159265358979 - angle, c < 0.0);
}

// `terms::spring_force`: the force on `a` of a spring from a to b = a + d.
fn spring_force(d: vec3<f32>, rest: f32, k: f32) -> vec3<f32> {
    let length = sqrt(d.x * d.x + d.y * d.y + d.z * d.z);
    let positive = length > 0.0;
    let scale = k * (length - rest) / select(1.0, length, positive);
    return select(vec3<f32>(0.0), d * scale, positive);
}

// A segment's unit tangent and inverse length (both zero when degenerate).
struct Segment {
    tangent: vec3<f32>,
    inv_length: f32,
}

fn segment_of(d: vec3<f32>) -> Segment {
    let length = sqrt(d.x * d.x + d.y * d.y + d.z * d.z);
    let inv = select(0.0, 1.0 / length, length > 0.0);
    return Segment(d * inv, inv);
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
    let s = clamp(u.x * v.x + u.y * v.y + u.z * v.z, -1.0, 1.0);
    let sin_theta = sqrt(1.0 - s * s);
    let keep = sin_theta >= min_sin && s0.inv_length > 0.0 && s1.inv_length > 0.0;
    let coeff = select(0.0, k * (turning_angle(s) - rest_angle) / select(1.0, sin_theta, keep), keep);
    return JointForces((v - u * s) * (-coeff * s0.inv_length), (u - v * s) * (coeff * s1.inv_length));
}

// `step::friction_change`: the change Δw to w = v_b − v_a of a contact with
// gap d = x_b − x_a, or zero when it is not compressed or does not slip.
fn friction_change(d: vec3<f32>, w: vec3<f32>, rest: f32, p: Params) -> vec3<f32> {
    let length = sqrt(d.x * d.x + d.y * d.y + d.z * d.z);
    let compressed = length < rest && length > 0.0;
    let n = d / select(1.0, length, compressed);
    let wt = w - n * (w.x * n.x + w.y * n.y + w.z * n.z);
    let slip = sqrt(wt.x * wt.x + wt.y * wt.y + wt.z * wt.z);
    let keep = compressed && slip > 0.0;
    let dv_normal = p.friction_impulse * (rest - length);
    let retention = max(1.0 - p.friction * dv_normal / select(1.0, slip, keep), 0.0);
    return select(vec3<f32>(0.0), wt * (retention - 1.0), keep);
}
