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
//! slots in pair order, in the block pass and the move pass, so no node is
//! written by two threads and the sum does not depend on the thread count
//! or on when the list was built (pairs out of reach add exactly zero).
//! The collider terms are per node and run inside those two passes.
//!
//! This module owns the list, its incidence and the per-pair arithmetic;
//! `passes.rs` runs the passes.

use std::sync::atomic::{AtomicBool, Ordering};

use yarn_model::self_contact::find_pairs;
use yarn_model::step::{capped_sum, segment_end, self_contact_friction};
use yarn_model::terms::self_contact_forces;
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
    /// [`Model::revision`] at the last build (0: never built).
    revision: u64,
    builds: u64,
    /// Node i's slots (4 × pair + k) are `slots[start[i]..start[i + 1]]`,
    /// in pair order.
    start: Vec<u32>,
    slots: Vec<u32>,
    /// Per slot: the pair's force on that node, and its friction change.
    pub(crate) force: Field<T>,
    pub(crate) friction: Field<T>,
}

impl<T: Real> SelfContacts<T> {
    /// Whether the list may miss a pair within 2r at `x`: some node has
    /// moved half the skin since the last build, or the model changed.
    /// Blocks are checked as `exec` runs them.
    pub(crate) fn stale(&self, model: &Model<T>, x: &Field<T>, exec: super::Exec) -> bool {
        if self.revision != model.revision() || self.anchor.len() != x.len() {
            return true;
        }
        let half = T::of(0.5 * model.params().self_contact_skin * model.contact_rule().radius());
        let moved = AtomicBool::new(false);
        let anchor = &self.anchor;
        let body = |block: usize| {
            let ([px, py, pz], [ax, ay, az]) = (x.block(block), anchor.block(block));
            let mut within = true;
            for k in 0..px.len() {
                let (dx, dy, dz) = (px[k] - ax[k], py[k] - ay[k], pz[k] - az[k]);
                // A NaN fails the comparison, so it rebuilds too.
                within &= dx * dx + dy * dy + dz * dz <= half * half;
            }
            if !within {
                moved.store(true, Ordering::Relaxed);
            }
        };
        let blocks = x.len().div_ceil(BLOCK);
        run_pass!(exec, (0..blocks), (0..blocks).into_par_iter(), 8, body);
        moved.into_inner()
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
        let mut start = vec![0u32; x.len() + 1];
        for nodes in &self.nodes {
            for &i in nodes {
                start[i as usize + 1] += 1;
            }
        }
        for i in 0..x.len() {
            start[i + 1] += start[i];
        }
        let mut fill = start.clone();
        self.slots = vec![0; self.nodes.len() * 4];
        for (slot, &i) in self.nodes.iter().flatten().enumerate() {
            self.slots[fill[i as usize] as usize] = slot as u32;
            fill[i as usize] += 1;
        }
        self.start = start;
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

    /// Node `i`'s slots, in pair order.
    pub(crate) fn slots_of(&self, i: usize) -> &[u32] {
        self.start.get(i + 1).map_or(&[], |&end| &self.slots[self.start[i] as usize..end as usize])
    }

    /// The force of pairs block `block` on their nodes, into `out`
    /// (slots 4 × pair + k): [`self_contact_forces`], zero out of reach.
    pub(crate) fn forces_block(&self, model: &Model<T>, x: &Field<T>, block: usize, out: &mut BlockMut<'_, T>) {
        let reach = T::of(2.0 * model.contact_rule().radius());
        let k_sc = model.coeffs().self_contact;
        let first = block * PAIRS_PER_BLOCK;
        for j in 0..out.x.len() / 4 {
            let p = self.nodes[first + j].map(|i| x.get(i as usize));
            let f = self_contact_forces(&p[0], &p[1], &p[2], &p[3], reach, k_sc).unwrap_or([V3::zeros(); 4]);
            for (k, f) in f.into_iter().enumerate() {
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
            let nodes = self.nodes[first + j].map(|i| i as usize);
            let (p, w) = (nodes.map(|i| x.get(i)), nodes.map(|i| v.get(i)));
            let dv = self_contact_friction([&p[0], &p[1], &p[2], &p[3]], [&w[0], &w[1], &w[2], &w[3]], reach, c)
                .unwrap_or([V3::zeros(); 4]);
            for (k, dv) in dv.into_iter().enumerate() {
                (out.x[4 * j + k], out.y[4 * j + k], out.z[4 * j + k]) = (dv.x, dv.y, dv.z);
            }
        }
    }

    /// The friction change at node `i`: its slots' changes in pair order,
    /// [`capped_sum`]med; `None` where it has no slot.
    pub(crate) fn friction_at(&self, i: usize) -> Option<V3<T>> {
        let slots = self.slots_of(i);
        (!slots.is_empty()).then(|| capped_sum(slots.iter().map(|&s| self.friction.get(s as usize))))
    }
}
