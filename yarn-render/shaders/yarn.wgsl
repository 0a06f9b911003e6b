// The yarn as a swept tube (paper §9): one instance per segment, SIDES ring
// vertices at each end generated here from the node positions and their
// parallel-transport frames, so no tube geometry is stored. Lambert shading
// under a key light, an ambient floor and a rim term; two tones alternating
// along the yarn read as ply.

// Mirrors `Camera` in src/lib.rs.
struct Camera {
    view_proj: mat4x4<f32>,
    eye: vec3<f32>,
    radius: f32,
    light: vec3<f32>,
    segments: u32,
}

@group(0) @binding(0) var<uniform> camera: Camera;
// Node positions (xyz) and each node's frame normal (xyz), perpendicular to
// the yarn and transported along it without twisting.
@group(0) @binding(1) var<storage, read> positions: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> normals: array<vec4<f32>>;

const SIDES: u32 = 7u;
const TAU: f32 = 6.28318530718;

struct Out {
    @builtin(position) clip: vec4<f32>,
    @location(0) normal: vec3<f32>,
    @location(1) world: vec3<f32>,
    @location(2) tone: f32,
}

// The tangent at node j: the mean of its segments' directions.
fn tangent(j: u32) -> vec3<f32> {
    let last = camera.segments;
    let before = positions[min(j, last)].xyz - positions[select(j - 1u, 0u, j == 0u)].xyz;
    let after = positions[min(j + 1u, last)].xyz - positions[j].xyz;
    let sum = select(vec3<f32>(0.0), normalize(before), length(before) > 0.0)
        + select(vec3<f32>(0.0), normalize(after), length(after) > 0.0);
    return select(vec3<f32>(1.0, 0.0, 0.0), normalize(sum), length(sum) > 1e-6);
}

@vertex
fn vs(@builtin(vertex_index) vertex: u32, @builtin(instance_index) segment: u32) -> Out {
    // Six vertices per side: two triangles between ring k and ring k + 1.
    let side = vertex / 6u;
    let corner = vertex % 6u;
    let around = array<u32, 6>(0u, 1u, 0u, 0u, 1u, 1u)[corner];
    let along = array<u32, 6>(0u, 0u, 1u, 1u, 0u, 1u)[corner];
    let node = segment + along;
    let t = tangent(node);
    let n = normalize(normals[node].xyz - t * dot(normals[node].xyz, t));
    let b = cross(t, n);
    let angle = TAU * f32((side + around) % SIDES) / f32(SIDES);
    let direction = cos(angle) * n + sin(angle) * b;
    let world = positions[node].xyz + camera.radius * direction;
    var out: Out;
    out.clip = camera.view_proj * vec4<f32>(world, 1.0);
    out.normal = direction;
    out.world = world;
    // Two tones, changing every four segments.
    out.tone = f32((segment / 4u) % 2u);
    return out;
}

@fragment
fn fs(in: Out) -> @location(0) vec4<f32> {
    let n = normalize(in.normal);
    let to_eye = normalize(camera.eye - in.world);
    let key = max(dot(n, normalize(camera.light)), 0.0);
    let rim = pow(1.0 - max(dot(n, to_eye), 0.0), 3.0);
    let base = mix(vec3<f32>(0.80, 0.33, 0.25), vec3<f32>(0.93, 0.55, 0.38), in.tone);
    let colour = base * (0.22 + 0.78 * key) + vec3<f32>(0.35) * rim;
    return vec4<f32>(colour, 1.0);
}
