// The yarns as swept tubes (paper §9): one instance per node, for the
// segment leaving it along its yarn, SIDES ring vertices at each end
// generated here from the node positions and their parallel-transport
// frames, so no tube geometry is stored. Each yarn is its own tube: a node
// at an open yarn's end starts no segment, and a closed yarn's last node's
// segment runs back to its first. Lambert shading under a key light, an
// ambient floor and a rim term; two tones alternating along the yarn read
// as ply.

// Mirrors `Camera` in src/shader.rs.
struct Camera {
    view_proj: mat4x4<f32>,
    eye: vec3<f32>,
    radius: f32,
    light: vec3<f32>,
    nodes: u32,
}

@group(0) @binding(0) var<uniform> camera: Camera;
// Node positions (xyz) and each node's frame normal (xyz), perpendicular to
// the yarn and transported along it without twisting.
@group(0) @binding(1) var<storage, read> positions: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> normals: array<vec4<f32>>;
// Each node's neighbours along its yarn (before, after), NONE at an open
// yarn's ends.
@group(0) @binding(3) var<storage, read> links: array<vec2<u32>>;

const SIDES: u32 = 7u;
const TAU: f32 = 6.28318530718;
const NONE: u32 = 0xffffffffu;

struct Out {
    @builtin(position) clip: vec4<f32>,
    @location(0) normal: vec3<f32>,
    @location(1) world: vec3<f32>,
    @location(2) tone: f32,
}

// The tangent at node j: the mean of its segments' directions.
fn tangent(j: u32) -> vec3<f32> {
    let link = links[j];
    let before = positions[j].xyz - positions[select(link.x, j, link.x == NONE)].xyz;
    let after = positions[select(link.y, j, link.y == NONE)].xyz - positions[j].xyz;
    let sum = select(vec3<f32>(0.0), normalize(before), length(before) > 0.0)
        + select(vec3<f32>(0.0), normalize(after), length(after) > 0.0);
    return select(vec3<f32>(1.0, 0.0, 0.0), normalize(sum), length(sum) > 1e-6);
}

@vertex
fn vs(@builtin(vertex_index) vertex: u32, @builtin(instance_index) segment: u32) -> Out {
    var out: Out;
    let next = links[segment].y;
    if next == NONE {
        // No segment leaves an open yarn's last node: every vertex at one
        // point outside the clip volume, a triangle of no area.
        out.clip = vec4<f32>(0.0, 0.0, 2.0, 1.0);
        return out;
    }
    // Six vertices per side: two triangles between this node's ring and the
    // next node's.
    let side = vertex / 6u;
    let corner = vertex % 6u;
    let around = array<u32, 6>(0u, 1u, 0u, 0u, 1u, 1u)[corner];
    let along = array<u32, 6>(0u, 0u, 1u, 1u, 0u, 1u)[corner];
    let node = select(segment, next, along == 1u);
    let t = tangent(node);
    let n = normalize(normals[node].xyz - t * dot(normals[node].xyz, t));
    let b = cross(t, n);
    let angle = TAU * f32((side + around) % SIDES) / f32(SIDES);
    let direction = cos(angle) * n + sin(angle) * b;
    let world = positions[node].xyz + camera.radius * direction;
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
