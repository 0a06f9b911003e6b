//! What one substep dispatches, in order, on a loaded fabric: the plan
//! that [`GpuFabric`] records into one compute pass for an advance, into
//! one timestamped pass each for the stage counters, or one kind at a time
//! for the per-pass timing runs.
//!
//! This module owns the order of a substep's dispatches and which stages
//! each covers; it does not submit or read anything back.

use yarn_model::Stage;

use crate::bindings::{Parity, forces_kernel};
use crate::fabric::GpuFabric;
use crate::{Mode, WORKGROUP};

/// One dispatch of a substep.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Dispatch<'a> {
    /// The pass's name in the stage counters.
    pub(crate) pass: &'static str,
    /// The stages it covers.
    pub(crate) stages: &'static [Stage],
    pub(crate) pipeline: &'a wgpu::ComputePipeline,
    pub(crate) group: &'a wgpu::BindGroup,
    pub(crate) workgroups: (u32, u32),
    /// Where the GPU itself wrote the workgroup counts, instead of
    /// `workgroups`: the list rebuild, which `plan.wgsl` turns on or off.
    pub(crate) indirect: Option<&'a wgpu::Buffer>,
}

impl Dispatch<'_> {
    /// Record this dispatch into `pass`.
    pub(crate) fn record(&self, pass: &mut wgpu::ComputePass<'_>) {
        pass.set_pipeline(self.pipeline);
        pass.set_bind_group(0, self.group, &[]);
        match self.indirect {
            Some(counts) => pass.dispatch_workgroups_indirect(counts, 0),
            None => pass.dispatch_workgroups(self.workgroups.0, self.workgroups.1, 1),
        }
    }
}

const FUSED: &[Stage] = &[Stage::Forces, Stage::Friction, Stage::Move];
const FORCES: &[Stage] = &[Stage::Forces];
const FORCES_AND_MOVE: &[Stage] = &[Stage::Forces, Stage::Move];
/// `friction.wgsl` computes each node's friction and moves it.
const FRICTION_AND_MOVE: &[Stage] = &[Stage::Friction, Stage::Move];
const PINS: &[Stage] = &[Stage::Pins];
const RESEAT: &[Stage] = &[Stage::Reseat];
const CHECK: &[Stage] = &[Stage::Check];
/// The self-contact lists are part of finding the forces.
const LISTS: &[Stage] = &[Stage::Forces];

impl GpuFabric {
    /// Workgroups for `threads` threads (one, if even that does not fit:
    /// load refused such fabrics).
    fn workgroups(&self, threads: usize) -> (u32, u32) {
        self.gpu.groups(threads as u32).unwrap_or((1, 1))
    }

    /// Whether an advance runs gather mode's substep with friction as one
    /// dispatch (`fused.wgsl`) at this size.
    /// Whether a substep runs the friction pass: some contact or collider
    /// has friction (`FRICTION_ON`).
    pub(crate) fn friction_on(&self) -> bool {
        self.model.coeffs().friction > 0.0 || self.model.surfaces().iter().any(|s| s.friction > 0.0)
    }

    /// Self-contact and colliders take the unfused passes.
    pub(crate) fn fuses(&self) -> bool {
        self.mode == Mode::Gather
            && self.model.coeffs().friction > 0.0
            && self.model.node_count() < self.fuse_below
            && !self.model.self_contact()
            && self.model.surfaces().is_empty()
    }

    /// Hand the self-contact passes before a substep's forces, from `at`, to
    /// `each`: where `may_rebuild`, whether to rebuild (`plan.wgsl`) and the
    /// rebuild's two passes, dispatched indirectly by its answer. The
    /// pushes are summed in the forces pass (`gather.wgsl`). Nothing with
    /// self-contact off, or without `may_rebuild`.
    pub(crate) fn list_plan<'s>(&'s self, at: Parity, may_rebuild: bool, each: &mut impl FnMut(&Dispatch<'s>)) {
        if !self.model.self_contact() || !may_rebuild {
            return;
        }
        let (pipelines, groups) = (&self.gpu.pipelines, &self.groups);
        // The rebuild's passes take their workgroup counts from the plan's.
        let rebuild = |pass, pipeline, group| Dispatch {
            pass,
            stages: LISTS,
            pipeline,
            group,
            workgroups: (0, 0),
            indirect: Some(&self.buffers.rebuild),
        };
        each(&Dispatch {
            workgroups: (1, 1),
            indirect: None,
            ..rebuild("plan.wgsl", &pipelines.plan.entries[0], &groups.plan)
        });
        each(&rebuild("grid_insert.wgsl", &pipelines.grid_insert.entries[0], groups.grid_insert.at(at)));
        each(&rebuild("grid_find.wgsl", &pipelines.grid_find.entries[0], groups.grid_find.at(at)));
    }

    /// Workgroups for a node pass (`gather.wgsl`'s, `friction.wgsl`) that
    /// sums self-contact segment by segment where `segment_sums`: then each
    /// covers one node fewer than it has threads.
    fn node_workgroups(&self, segment_sums: bool) -> (u32, u32) {
        let nodes = self.model.node_count();
        if segment_sums {
            let per_group = WORKGROUP as usize - 1;
            self.workgroups(nodes.div_ceil(per_group) * WORKGROUP as usize)
        } else {
            self.workgroups(nodes)
        }
    }

    /// Workgroups for a gather forces pass, which with self-contact on
    /// (entry points `step_touching` and `forces_touching`) sums the
    /// pushes.
    pub(crate) fn forces_workgroups(&self) -> (u32, u32) {
        self.node_workgroups(self.model.self_contact())
    }

    /// Hand each dispatch of one substep from `at` to `each`, in order:
    /// fused when `fuse`, otherwise the self-contact passes (the lists'
    /// rebuild only where `may_rebuild`), the mode's forces pass, friction
    /// (when on), pins (when any), and the reseat pass when `reseat`.
    /// Returns the parity after the substep.
    pub(crate) fn substep_plan<'s>(
        &'s self,
        at: Parity,
        fuse: bool,
        reseat: bool,
        may_rebuild: bool,
        each: &mut impl FnMut(&Dispatch<'s>),
    ) -> Parity {
        let pipelines = &self.gpu.pipelines;
        let groups = &self.groups;
        let nodes = self.workgroups(self.model.node_count());
        let friction = self.friction_on();
        let mut next = at;
        if fuse {
            let group = groups.fused.at(at);
            each(&Dispatch {
                pass: "fused.wgsl",
                stages: FUSED,
                pipeline: &pipelines.fused.entries[0],
                group,
                workgroups: nodes,
                indirect: None,
            });
            next = Parity { x: 1 - at.x, v: 1 - at.v };
        } else {
            self.list_plan(at, may_rebuild, each);
            let forces = forces_kernel(self.mode, self.model.self_contact(), pipelines, &self.buffers);
            let group = groups.step.at(at);
            if let Some(scatter) = forces.scatter {
                let workgroups = self.workgroups(self.model.node_count().max(self.model.contacts().len()));
                each(&Dispatch {
                    pass: "fixed.wgsl scatter",
                    stages: FORCES,
                    pipeline: scatter,
                    group,
                    workgroups,
                    indirect: None,
                });
            }
            let stages = if friction { FORCES } else { FORCES_AND_MOVE };
            each(&Dispatch {
                pass: forces.step_name,
                stages,
                pipeline: forces.step,
                group,
                workgroups: self.forces_workgroups(),
                indirect: None,
            });
            if friction {
                let group = groups.friction.at(at);
                let segment_sums = self.model.self_contact() && self.model.coeffs().friction > 0.0;
                let [plain, touching] = &pipelines.friction.entries;
                each(&Dispatch {
                    pass: "friction.wgsl",
                    stages: FRICTION_AND_MOVE,
                    pipeline: if segment_sums { touching } else { plain },
                    group,
                    workgroups: self.node_workgroups(segment_sums),
                    indirect: None,
                });
                next.v = 1 - at.v;
            }
            next.x = 1 - at.x;
        }
        if let Some(workgroups) =
            (self.buffers.pin_count > 0).then(|| self.gpu.groups(self.buffers.pin_count)).flatten()
        {
            let group = groups.pins.at(next);
            each(&Dispatch {
                pass: "pins.wgsl",
                stages: PINS,
                pipeline: &pipelines.pins.entries[0],
                group,
                workgroups,
                indirect: None,
            });
        }
        if reseat {
            let workgroups = self.gpu.groups(self.buffers.reseat_count).unwrap_or((1, 1));
            let (pipeline, group) = (&pipelines.reseat.entries[0], &groups.reseat);
            each(&Dispatch { pass: "reseat.wgsl", stages: RESEAT, pipeline, group, workgroups, indirect: None });
        }
        next
    }

    /// The divergence check at the end of a batch, at parity `at`.
    pub(crate) fn check_dispatch(&self, at: Parity) -> Dispatch<'_> {
        Dispatch {
            pass: "check.wgsl",
            stages: CHECK,
            pipeline: &self.gpu.pipelines.check.entries[0],
            group: self.groups.check.at(at),
            workgroups: self.workgroups(self.model.node_count()),
            indirect: None,
        }
    }
}
