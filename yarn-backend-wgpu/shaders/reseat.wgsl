// Re-seated contacts close (`yarn_model::Reseat`), after every substep
// while one is still open: rest moves toward d_c by one step without
// passing it, written to the contact record and to both nodes' copies of
// it. Dispatched only then.

// Mirrors `GpuReseat` in src/layout.rs; a test checks the layout.
struct Reseat {
    contact: u32,
    slot_a: u32,
    slot_b: u32,
    knit: f32,
}

@group(0) @binding(0) var<uniform> p: Params;
@group(0) @binding(1) var<storage, read_write> contacts: array<Contact>;
@group(0) @binding(2) var<storage, read_write> incident: array<Contact>;
@group(0) @binding(3) var<storage, read> reseats: array<Reseat>;

@compute @workgroup_size(WORKGROUP)
fn main(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_id) local: vec3<u32>,
        @builtin(num_workgroups) groups: vec3<u32>) {
    let k = thread_index(group, local, groups);
    if k >= p.reseats {
        return;
    }
    let r = reseats[k];
    let now = contacts[r.contact].rest;
    let rest = select(min(r.knit, now + p.reseat_step), max(r.knit, now - p.reseat_step), now > r.knit);
    contacts[r.contact].rest = rest;
    incident[r.slot_a].rest = rest;
    incident[r.slot_b].rest = rest;
}
