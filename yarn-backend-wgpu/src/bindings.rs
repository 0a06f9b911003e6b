//! A loaded fabric's GPU buffers and the bind groups of every pass over
//! them, with the uploads that fill them from the host model.
//!
//! This module owns the buffer layout and which buffer each pass binds
//! where; the per-mode choice of forces pass and its bindings is made once,
//! in [`forces_kernel`]. It does not record or submit any work.

use bytemuck::Pod;
use wgpu::util::DeviceExt;
use yarn_model::self_contact::grid::EMPTY;
use yarn_model::{Model, V3};

use crate::Mode;
use crate::gpu::{Gpu, Pipelines};
use crate::layout::{GpuChain, GpuContact, GpuReseat};

/// Which of each double-buffered pair holds the current state:
/// `x[parity.x]` and `v[parity.v]`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub(crate) struct Parity {
    pub(crate) x: usize,
    pub(crate) v: usize,
}

/// One bind group for each parity.
#[derive(Debug)]
pub(crate) struct ByParity([[wgpu::BindGroup; 2]; 2]);

impl ByParity {
    fn new(make: impl Fn(Parity) -> wgpu::BindGroup) -> Self {
        let at = |x, v| make(Parity { x, v });
        Self([[at(0, 0), at(0, 1)], [at(1, 0), at(1, 1)]])
    }

    pub(crate) fn at(&self, parity: Parity) -> &wgpu::BindGroup {
        &self.0[parity.x][parity.v]
    }
}

#[derive(Debug)]
pub(crate) struct Buffers {
    pub(crate) params: wgpu::Buffer,
    pub(crate) x: [wgpu::Buffer; 2],
    pub(crate) v: [wgpu::Buffer; 2],
    pub(crate) forces: wgpu::Buffer,
    /// Per node: its [`GpuChain`] record.
    pub(crate) chain: wgpu::Buffer,
    pub(crate) contacts: wgpu::Buffer,
    /// Each node's contacts, copied in contact order:
    /// `incident[start[i]..start[i + 1]]`.
    pub(crate) start: wgpu::Buffer,
    pub(crate) incident: wgpu::Buffer,
    pub(crate) pins: wgpu::Buffer,
    pub(crate) pin_count: u32,
    /// The re-seated contacts closing, with their slots in `incident`.
    pub(crate) reseats: wgpu::Buffer,
    pub(crate) reseat_count: u32,
    /// Fixed-point accumulators (three i32 per node).
    pub(crate) acc: wgpu::Buffer,
    /// `status[0]`: the OVERFLOWED and DIVERGED bits a batch raised, and
    /// the mappable copy each submission ends with, so reading it costs no
    /// second round trip.
    pub(crate) status: wgpu::Buffer,
    pub(crate) status_readback: wgpu::Buffer,
    /// The positions and velocities a batch started from, put back if it
    /// overflows or diverges.
    pub(crate) snapshot: [wgpu::Buffer; 2],
    /// Self-contact (a 16-byte stand-in each while it is off): the
    /// candidate lists with their per-node records and anchors
    /// (`lists.wgsl`), the rule (`grid_find.wgsl`), the grid
    /// (`grid.wgsl`), and the indirect workgroup counts of a rebuild
    /// (`plan.wgsl`).
    pub(crate) lists: wgpu::Buffer,
    pub(crate) rule: wgpu::Buffer,
    pub(crate) grid: wgpu::Buffer,
    pub(crate) rebuild: wgpu::Buffer,
}

impl Buffers {
    /// The buffers of `model` with its nodes at `positions` and
    /// `velocities` (no pins or re-seats yet: [`Groups`] and the uploads
    /// fill those).
    pub(crate) fn new(
        device: &wgpu::Device,
        model: &Model<f32>,
        positions: &[V3<f32>],
        velocities: &[V3<f32>],
        slots: u32,
    ) -> Self {
        let (start, incident, _) = incidence(model);
        let (x, v) = (vec4s(positions), vec4s(velocities));
        Self {
            params: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("params"),
                size: std::mem::size_of::<crate::layout::GpuParams>() as u64,
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
            x: [storage(device, "x0", &x), storage(device, "x1", &x)],
            v: [storage(device, "v0", &v), storage(device, "v1", &v)],
            forces: storage(device, "forces", &v),
            chain: storage(device, "chain", &chain(model)),
            contacts: storage(device, "contacts", &gpu_contacts(model)),
            start: storage(device, "start", &start),
            incident: storage(device, "incident", &incident),
            pins: storage(device, "pins", &[0u32; 4]),
            pin_count: 0,
            reseats: storage(device, "reseats", &[0u32; 4]),
            reseat_count: 0,
            acc: storage(device, "accumulators", &vec![0i32; 3 * model.node_count()]),
            status: storage(device, "status", &[0u32; 4]),
            status_readback: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("status readback"),
                size: 16,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
            snapshot: [x.len(), v.len()].map(|elements| {
                device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("snapshot"),
                    size: (elements.max(1) * 16) as u64,
                    usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
                    mapped_at_creation: false,
                })
            }),
            lists: storage(device, "lists", &lists(model, slots)),
            rule: storage(device, "rule", &rule(model)),
            grid: storage(device, "grid", &grid(model)),
            rebuild: device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("rebuild"),
                contents: bytemuck::cast_slice(&[0u32; 4]),
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::INDIRECT,
            }),
        }
    }
}

/// Rows of the candidate lists after their 4-word header (`lists.wgsl`'s
/// `field_at`): field `row` of node i is word `4 + row × nodes + i`.
pub(crate) mod rows {
    /// 1 where a pin holds the node, else 0.
    pub(crate) const PINNED: usize = 0;
    pub(crate) const NEXT: usize = 1;
    /// Only the GPU writes these; the tests read them back.
    #[cfg(test)]
    pub(crate) const COUNT: usize = 2;
    #[cfg(test)]
    pub(crate) const ANCHOR: usize = 4;
    pub(crate) const SLOTS: usize = 7;

    /// Where field `row` of node i lies in lists of `nodes` nodes.
    pub(crate) fn at(nodes: usize, i: usize, row: usize) -> usize {
        4 + row * nodes + i
    }
}

/// The candidate lists of `model` (`lists.wgsl`) with `slots` slots per
/// segment, empty and marked stale so the first substep builds them: a
/// 16-byte stand-in with self-contact off.
pub(crate) fn lists(model: &Model<f32>, slots: u32) -> Vec<u32> {
    if !model.self_contact() {
        return vec![0; 4];
    }
    let n = model.node_count();
    let mut lists = vec![0u32; rows::at(n, 0, rows::SLOTS + slots as usize)];
    lists[0] = 1;
    for (i, link) in model.links().iter().enumerate() {
        lists[rows::at(n, i, rows::NEXT)] = link.raw()[1];
    }
    lists[rows::at(n, 0, rows::PINNED)..rows::at(n, 0, rows::PINNED + 1)].copy_from_slice(&pinned(model));
    lists
}

/// The lists' row of which nodes `model`'s pins hold (`rows::PINNED`).
pub(crate) fn pinned(model: &Model<f32>) -> Vec<u32> {
    model.pinned_nodes().into_iter().map(u32::from).collect()
}

/// Bytes of [`lists`] for `nodes` nodes and `slots` slots.
pub(crate) fn lists_bytes(nodes: usize, slots: u32) -> u64 {
    4 * (4 + (rows::SLOTS as u64 + u64::from(slots)) * nodes as u64)
}

/// The rule of `model`'s self-contact (`grid_find.wgsl`): per node, its
/// yarn's first node, its yarn's node count (the top bit set for a closed
/// yarn) and how many segments after it are near it; a 16-byte stand-in
/// with self-contact off.
pub(crate) fn rule(model: &Model<f32>) -> Vec<u32> {
    const CLOSED: u32 = 0x8000_0000;
    if !model.self_contact() {
        return vec![0; 4];
    }
    let rule = model.contact_rule();
    let mut out = Vec::with_capacity(3 * model.node_count());
    for (i, &ahead) in rule.ahead().iter().enumerate() {
        let yarn = rule.yarn_of(i);
        out.extend([yarn.start, yarn.len() as u32 | if yarn.closed { CLOSED } else { 0 }, ahead]);
    }
    out
}

/// The candidate grid of `model` (`grid.wgsl`): no long segment,
/// generation 0, every bucket and `next` empty; a 16-byte stand-in with
/// self-contact off.
pub(crate) fn grid(model: &Model<f32>) -> Vec<u32> {
    if !model.self_contact() {
        return vec![0; 4];
    }
    let mut grid = vec![EMPTY; crate::fabric::grid_len(model)];
    grid[..4].fill(0);
    grid
}

/// The bind groups of every pass for every parity: the forces pass
/// writing the next positions (`step`) or the force buffer
/// (`forces_only`), friction, pins, the fused substep, the divergence
/// check, and the reseat pass (which binds no state).
#[derive(Debug)]
pub(crate) struct Groups {
    pub(crate) step: ByParity,
    pub(crate) forces_only: ByParity,
    pub(crate) friction: ByParity,
    pub(crate) pins: ByParity,
    pub(crate) fused: ByParity,
    pub(crate) check: ByParity,
    pub(crate) reseat: wgpu::BindGroup,
    /// Self-contact's list passes.
    pub(crate) plan: wgpu::BindGroup,
    pub(crate) grid_insert: ByParity,
    pub(crate) grid_find: ByParity,
}

impl Groups {
    pub(crate) fn new(gpu: &Gpu, mode: Mode, buffers: &Buffers) -> Self {
        let pipelines = &gpu.pipelines;
        let (x, v) = (&buffers.x, &buffers.v);
        // The layout and bindings, which the entry points share.
        let forces = forces_kernel(mode, false, pipelines, buffers);
        let forces_pass = |label, at: Parity, out: &wgpu::Buffer| {
            let mut bound = vec![&buffers.params, &x[at.x], &v[at.v], out];
            bound.extend(forces.bindings.iter().flatten());
            bind(gpu, forces.layout, label, &bound)
        };
        Self {
            step: ByParity::new(|at| forces_pass("step", at, &x[1 - at.x])),
            forces_only: ByParity::new(|at| forces_pass("forces", at, &buffers.forces)),
            friction: ByParity::new(|at| {
                let bound = [
                    &buffers.params,
                    &x[at.x],
                    &v[at.v],
                    &x[1 - at.x],
                    &v[1 - at.v],
                    &buffers.start,
                    &buffers.incident,
                    &buffers.lists,
                    &buffers.chain,
                ];
                bind(gpu, &pipelines.friction.layout, "friction", &bound)
            }),
            pins: ByParity::new(|at| {
                let bound = [&buffers.params, &x[at.x], &v[at.v], &buffers.pins, &buffers.lists];
                bind(gpu, &pipelines.pins.layout, "pins", &bound)
            }),
            check: ByParity::new(|at| {
                let bound = [&buffers.params, &x[at.x], &v[at.v], &buffers.status, &buffers.lists];
                bind(gpu, &pipelines.check.layout, "check", &bound)
            }),
            plan: bind(
                gpu,
                &pipelines.plan.layout,
                "plan",
                &[&buffers.params, &buffers.lists, &buffers.grid, &buffers.rebuild],
            ),
            grid_insert: ByParity::new(|at| {
                let bound = [&buffers.params, &x[at.x], &buffers.lists, &buffers.grid];
                bind(gpu, &pipelines.grid_insert.layout, "grid insert", &bound)
            }),
            grid_find: ByParity::new(|at| {
                let bound = [&buffers.params, &x[at.x], &buffers.lists, &buffers.grid, &buffers.rule, &buffers.status];
                bind(gpu, &pipelines.grid_find.layout, "grid find", &bound)
            }),
            reseat: reseat_group(gpu, buffers),
            fused: ByParity::new(|at| {
                let bound = [
                    &buffers.params,
                    &x[at.x],
                    &v[at.v],
                    &x[1 - at.x],
                    &v[1 - at.v],
                    &buffers.chain,
                    &buffers.start,
                    &buffers.incident,
                ];
                bind(gpu, &pipelines.fused.layout, "fused", &bound)
            }),
        }
    }
}

/// The reseat pass's bind group, remade when its buffer is.
pub(crate) fn reseat_group(gpu: &Gpu, buffers: &Buffers) -> wgpu::BindGroup {
    let bound = [&buffers.params, &buffers.contacts, &buffers.incident, &buffers.reseats];
    bind(gpu, &gpu.pipelines.reseat.layout, "reseat", &bound)
}

/// A mode's forces pass, chosen in this one place: its bind group layout,
/// the buffers it binds after `params, x, v, out`, and its pipelines.
#[derive(Debug)]
pub(crate) struct ForcesKernel<'a> {
    pub(crate) layout: &'a wgpu::BindGroupLayout,
    /// In binding order; `None` past the mode's last (no allocation, as
    /// the plan of every substep asks for this).
    pub(crate) bindings: [Option<&'a wgpu::Buffer>; 4],
    /// Fixed point's scatter into the accumulators, over one thread per
    /// node or contact, before the update; gather has none.
    pub(crate) scatter: Option<&'a wgpu::ComputePipeline>,
    /// The update that makes the substep's v* (`update.wgsl`'s `step`).
    pub(crate) step: &'a wgpu::ComputePipeline,
    /// The update that writes the force field (`update.wgsl`'s `forces`).
    pub(crate) forces: &'a wgpu::ComputePipeline,
    /// The step's name in the stage counters.
    pub(crate) step_name: &'static str,
}

/// The forces pass of `mode`, for a model with self-contact where
/// `self_contact` (gather's entry points that sum the pushes; fixed point
/// runs none).
pub(crate) fn forces_kernel<'a>(
    mode: Mode,
    self_contact: bool,
    pipelines: &'a Pipelines,
    buffers: &'a Buffers,
) -> ForcesKernel<'a> {
    match mode {
        Mode::Gather => {
            let [step, forces, step_touching, forces_touching] = &pipelines.gather.entries;
            ForcesKernel {
                layout: &pipelines.gather.layout,
                bindings: [Some(&buffers.chain), Some(&buffers.start), Some(&buffers.incident), Some(&buffers.lists)],
                scatter: None,
                step: if self_contact { step_touching } else { step },
                forces: if self_contact { forces_touching } else { forces },
                step_name: "gather.wgsl step",
            }
        }
        Mode::FixedPointAtomic => ForcesKernel {
            layout: &pipelines.fixed.layout,
            bindings: [Some(&buffers.chain), Some(&buffers.contacts), Some(&buffers.acc), Some(&buffers.status)],
            scatter: Some(&pipelines.fixed.entries[0]),
            step: &pipelines.fixed.entries[1],
            forces: &pipelines.fixed.entries[2],
            step_name: "fixed.wgsl step",
        },
    }
}

fn bind(gpu: &Gpu, layout: &wgpu::BindGroupLayout, label: &str, buffers: &[&wgpu::Buffer]) -> wgpu::BindGroup {
    let entries: Vec<_> = buffers
        .iter()
        .enumerate()
        .map(|(i, buffer)| wgpu::BindGroupEntry { binding: i as u32, resource: buffer.as_entire_binding() })
        .collect();
    gpu.device.create_bind_group(&wgpu::BindGroupDescriptor { label: Some(label), layout, entries: &entries })
}

/// A storage buffer holding `data` (padded to one 16-byte element when
/// empty: a binding may not be).
pub(crate) fn storage(device: &wgpu::Device, label: &str, data: &[impl Pod]) -> wgpu::Buffer {
    let bytes: &[u8] = bytemuck::cast_slice(data);
    let contents = if bytes.is_empty() { &[0u8; 16][..] } else { bytes };
    device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some(label),
        contents,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
    })
}

pub(crate) fn vec4s(v: &[V3<f32>]) -> Vec<[f32; 4]> {
    v.iter().map(|p| [p.x, p.y, p.z, 0.0]).collect()
}

/// Per node i: the rest length of the segment leaving i, κθ0 of the joint
/// centred on i (zero where there is none) and i's neighbours along its
/// yarn.
pub(crate) fn chain(model: &Model<f32>) -> Vec<GpuChain> {
    let kappa = model.coeffs().rest_curl;
    model
        .links()
        .iter()
        .zip(model.segment_rest().iter().zip(model.joint_rest()))
        .map(|(link, (&rest_length, &theta0))| {
            let [prev, next] = link.raw();
            GpuChain { rest_length, rest_turn: kappa * theta0, prev, next }
        })
        .collect()
}

pub(crate) fn gpu_contacts(model: &Model<f32>) -> Vec<GpuContact> {
    model
        .contacts()
        .iter()
        .zip(model.alive())
        .map(|(c, &alive)| GpuContact { a: c.a, b: c.b, rest: c.rest, alive: u32::from(alive) })
        .collect()
}

/// Each node's alive contacts in contact order, as `start` offsets into
/// `incident`, which holds a copy of each contact record per node; and the
/// re-seated contacts with the slots of their two copies.
pub(crate) fn incidence(model: &Model<f32>) -> (Vec<u32>, Vec<GpuContact>, Vec<GpuReseat>) {
    let contacts = gpu_contacts(model);
    let (start, entries) = model.incidence();
    let mut slots = vec![[0u32; 2]; contacts.len()];
    for (entry, &(node, contact)) in entries.iter().enumerate() {
        slots[contact as usize][usize::from(contacts[contact as usize].b == node)] = entry as u32;
    }
    let reseats = model
        .reseating()
        .iter()
        .map(|r| {
            let [slot_a, slot_b] = slots[r.contact as usize];
            GpuReseat { contact: r.contact, slot_a, slot_b, knit: r.knit }
        })
        .collect();
    (start, entries.into_iter().map(|(_, contact)| contacts[contact as usize]).collect(), reseats)
}
