//! What touches the yarn besides its own chain and persistent contacts, on
//! the CPU: self-contact between segments ([`yarn_model::self_contact`])
//! and the colliders ([`yarn_model::collider`]).
//!
//! Self-contact runs as a Verlet list of segment pairs, rebuilt by
//! [`yarn_model::self_contact::find_pairs`] when some node has moved half
//! the skin since the last build or the model's revision changed, and as
//! two passes over the pairs: *pair forces* (each pair's force on its four
//! nodes, into its four slots) and *pair friction* (each pair's friction
//! change and its nodes' shares, from x and v*). Each node then gathers its
//! slots in the block pass and the move pass: first those of the segment
//! it starts, then those of the segment it ends, each in the order of the
//! partner segments. That is the order of the GPU's gather, which keeps a
//! sorted list per segment, so `Serial<f32>` and `wgpu` agree bit for bit.
//! No node is written by two threads, and the sum does not depend on the
//! thread count or on when the list was built (pairs out of reach add
//! exactly zero). The collider terms are per node and run inside those two
//! passes.
//!
//! This module owns the list, its per-segment entries and the per-pair
//! arithmetic; `passes.rs` runs the passes.

use std::sync::atomic::{AtomicBool, Ordering};

use yarn_model::self_contact::find_pairs;
use yarn_model::step::{cap, segment_end, self_contact_friction};
use yarn_model::terms::{closest_gap, self_contact_forces};
use yarn_model::{Model, Real, V3};

use super::field::{BLOCK, BlockMut, Field};

/// Pairs per block of the per-pair fields: each pair has four slots.
pub(crate) const PAIRS_PER_BLOCK: usize = BLOCK / 4;

/// The self-contact candidate list of a CPU fabric and its per-pair
/// buffers.
#[derive(Debug, Default)]
pub(crate) struct SelfContacts<T> {
    /// Per candidate pair: its segments' nodes [a, a's next, b, b's next].
    nodes: Vec<[u32; 4]>,
    /// The positions at the last build.
    anchor: Field<T>,
    /// Per pair: its closest distance at the last build.
    built_gap: Vec<T>,
    /// Per node: how far it has moved since the last build, as of the
    /// last staleness check.
    moved: Vec<T>,
    /// Per pair: whether it was within reach at the last force pass; the
    /// others have zero slots, which the friction pass and the gathers
    /// skip.
    pub(crate) active: Vec<bool>,
    /// [`Model::revision`] at the last build (0: never built).
    revision: u64,
    builds: u64,
    /// Segment s's entries are `entries[start[s]..start[s + 1]]`, in the
    /// order of its partners: each the slot (4 × pair + k) of the node s
    /// starts at; the node it ends at has the next slot.
    start: Vec<u32>,
    entries: Vec<u32>,
    /// Per slot: the pair's force on that node, and its friction change.
    pub(crate) force: Field<T>,
    pub(crate) friction: Field<T>,
}

impl<T: Real> SelfContacts<T> {
    /// Whether the list may miss a pair within 2r at `x`: some node has
    /// moved half the skin since the last build, or the model changed.
    /// Records how far each node has moved, for the force pass's bound.
    /// Blocks are checked as `exec` runs them.
    pub(crate) fn stale(&mut self, model: &Model<T>, x: &Field<T>, exec: super::Exec) -> bool {
        if self.revision != model.revision() || self.anchor.len() != x.len() {
            return true;
        }
        let half = T::of(0.5 * model.params().self_contact_skin * model.contact_rule().radius());
        let far = AtomicBool::new(false);
        let anchor = &self.anchor;
        let mut moved = std::mem::take(&mut self.moved);
        moved.resize(x.len(), T::zero());
        let body = |(block, moved): (usize, &mut [T])| {
            let ([px, py, pz], [ax, ay, az]) = (x.block(block), anchor.block(block));
            let mut within = true;
            for k in 0..px.len() {
                let (dx, dy, dz) = (px[k] - ax[k], py[k] - ay[k], pz[k] - az[k]);
                let squared = dx * dx + dy * dy + dz * dz;
                // A NaN fails the comparison, so it rebuilds too.
                within &= squared <= half * half;
                moved[k] = squared.sqrt();
            }
            if !within {
                far.store(true, Ordering::Relaxed);
            }
        };
        run_pass!(exec, moved.chunks_mut(BLOCK).enumerate(), moved.par_chunks_mut(BLOCK).enumerate(), 8, body);
        self.moved = moved;
        far.into_inner()
    }

    /// Rebuild the list at `x`, with its incidence and buffers.
    pub(crate) fn rebuild(&mut self, model: &Model<T>, x: &Field<T>) {
        let mut positions = Vec::new();
        x.to_vectors(&mut positions);
        let mut pairs = Vec::new();
        find_pairs(model, &positions, model.params().self_contact_skin * model.contact_rule().radius(), &mut pairs);
        self.nodes = pairs
            .iter()
            .map(|&[a, b]| [a, segment_end(model, a as usize) as u32, b, segment_end(model, b as usize) as u32])
            .collect();
        // Pairs are sorted by (a, b), so each segment meets the partners
        // before it (as b) and then those after it (as a), each in order.
        let mut start = vec![0u32; x.len() + 1];
        for &[a, b] in &pairs {
            start[a as usize + 1] += 1;
            start[b as usize + 1] += 1;
        }
        for i in 0..x.len() {
            start[i + 1] += start[i];
        }
        let mut fill = start.clone();
        self.entries = vec![0; pairs.len() * 2];
        for (pair, &[a, b]) in pairs.iter().enumerate() {
            for (segment, slot) in [(a, 4 * pair), (b, 4 * pair + 2)] {
                self.entries[fill[segment as usize] as usize] = slot as u32;
                fill[segment as usize] += 1;
            }
        }
        self.start = start;
        self.built_gap = self
            .nodes
            .iter()
            .map(|n| {
                let p = n.map(|i| x.get(i as usize));
                closest_gap(&p[0], &p[1], &p[2], &p[3]).0.norm()
            })
            .collect();
        self.moved = vec![T::zero(); x.len()];
        self.active = vec![false; self.nodes.len()];
        self.anchor.clone_from(x);
        self.revision = model.revision();
        self.builds += 1;
        let slots = self.nodes.len() * 4;
        self.force = Field::zeros(slots);
        self.friction = Field::zeros(slots);
    }

    /// The candidate pairs' segments, [a, b] by their first nodes.
    pub(crate) fn segment_pairs(&self) -> impl Iterator<Item = [u32; 2]> + '_ {
        self.nodes.iter().map(|n| [n[0], n[2]])
    }

    /// How many times the list has been built.
    pub(crate) fn builds(&self) -> u64 {
        self.builds
    }

    /// Segment `s`'s entries (`None`: no segment), in partner order.
    fn entries_of(&self, s: Option<u32>) -> &[u32] {
        let Some(s) = s.map(|s| s as usize) else { return &[] };
        self.start.get(s + 1).map_or(&[], |&end| &self.entries[self.start[s] as usize..end as usize])
    }

    /// The slots of the pushing pairs at node `i`: as the start of its own
    /// segment, then as the end of the segment before it (`prev`), each in
    /// partner order.
    fn slots_at(&self, i: usize, prev: Option<u32>) -> [impl Iterator<Item = usize> + '_; 2] {
        let pushing = move |segment: Option<u32>, node: usize| {
            let entries = self.entries_of(segment).iter();
            entries.filter_map(move |&slot| self.active[slot as usize / 4].then_some(slot as usize + node))
        };
        [pushing(Some(i as u32), 0), pushing(prev, 1)]
    }

    /// The self-contact force at node `i` added to `f`: the pushing pairs
    /// of the segment it starts, summed, then those of the segment it ends
    /// (`prev`). `f` itself where none pushes.
    pub(crate) fn force_at(&self, i: usize, prev: Option<u32>, f: V3<T>) -> V3<T> {
        self.slots_at(i, prev).into_iter().fold(f, |f, mut slots| match slots.next() {
            Some(first) => f + slots.fold(self.force.get(first), |sum, s| sum + self.force.get(s)),
            None => f,
        })
    }

    /// The force of pairs block `block` on their nodes, into `out`
    /// (slots 4 × pair + k), and whether each pushes, into `active`:
    /// [`self_contact_forces`], zero out of reach. A pair whose distance at
    /// the build, less how far its nodes have moved since, is still out of
    /// reach cannot touch, and is not measured.
    pub(crate) fn forces_block(
        &self,
        model: &Model<T>,
        x: &Field<T>,
        block: usize,
        (out, active): (&mut BlockMut<'_, T>, &mut [bool]),
    ) {
        let reach = T::of(2.0 * model.contact_rule().radius());
        // A thousandth of a radius for the rounding of the bound's terms.
        let clear = reach * T::of(1.0005);
        let k_sc = model.coeffs().self_contact;
        let first = block * PAIRS_PER_BLOCK;
        let moved = |i: u32| self.moved[i as usize];
        for (j, active) in active.iter_mut().enumerate() {
            let nodes = self.nodes[first + j];
            let nearest =
                self.built_gap[first + j] - moved(nodes[0]).max(moved(nodes[1])) - moved(nodes[2]).max(moved(nodes[3]));
            let f = if nearest >= clear {
                None
            } else {
                let p = nodes.map(|i| x.get(i as usize));
                self_contact_forces(&p[0], &p[1], &p[2], &p[3], reach, k_sc)
            };
            *active = f.is_some();
            for (k, f) in f.unwrap_or([V3::zeros(); 4]).into_iter().enumerate() {
                (out.x[4 * j + k], out.y[4 * j + k], out.z[4 * j + k]) = (f.x, f.y, f.z);
            }
        }
    }

    /// The friction change of pairs block `block` from `x` and `v` (v*),
    /// into `out`: [`self_contact_friction`], zero where it returns `None`.
    pub(crate) fn friction_block(
        &self,
        model: &Model<T>,
        (x, v): (&Field<T>, &Field<T>),
        block: usize,
        out: &mut BlockMut<'_, T>,
    ) {
        let reach = T::of(2.0 * model.contact_rule().radius());
        let c = model.coeffs();
        let first = block * PAIRS_PER_BLOCK;
        for j in 0..out.x.len() / 4 {
            if !self.active[first + j] {
                for k in 4 * j..4 * j + 4 {
                    (out.x[k], out.y[k], out.z[k]) = (T::zero(), T::zero(), T::zero());
                }
                continue;
            }
            let nodes = self.nodes[first + j].map(|i| i as usize);
            let (p, w) = (nodes.map(|i| x.get(i)), nodes.map(|i| v.get(i)));
            let dv = self_contact_friction([&p[0], &p[1], &p[2], &p[3]], [&w[0], &w[1], &w[2], &w[3]], reach, c)
                .unwrap_or([V3::zeros(); 4]);
            for (k, dv) in dv.into_iter().enumerate() {
                (out.x[4 * j + k], out.y[4 * j + k], out.z[4 * j + k]) = (dv.x, dv.y, dv.z);
            }
        }
    }

    /// The friction change at node `i`: the changes of its pushing pairs,
    /// summed over the segment it starts and then over the one it ends
    /// (`prev`), the sum [`cap`]ped to the longest change; `None` where no
    /// pair pushes it.
    pub(crate) fn friction_at(&self, i: usize, prev: Option<u32>) -> Option<V3<T>> {
        let mut total: Option<(V3<T>, T)> = None;
        for mut slots in self.slots_at(i, prev) {
            let Some(first) = slots.next() else { continue };
            let dv = self.friction.get(first);
            let (sum, longest) = slots.fold((dv, dv.norm()), |(sum, longest), s| {
                let dv = self.friction.get(s);
                (sum + dv, longest.max(dv.norm()))
            });
            total = Some(total.map_or((sum, longest), |(t, l)| (t + sum, l.max(longest))));
        }
        total.map(|(sum, longest)| cap(sum, longest))
    }
}
