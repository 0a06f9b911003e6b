//! What touches the yarn besides its own chain and persistent contacts, on
//! the CPU: self-contact between segments ([`yarn_model::self_contact`])
//! and the colliders ([`yarn_model::collider`]).
//!
//! Self-contact runs as a Verlet list of segment pairs, rebuilt by
//! [`yarn_model::self_contact::find_pairs`] when some node has moved half
//! the skin since the last build or the model's revision changed, and as
//! passes over the pairs: *pair forces* (each pair's force on its four
//! nodes, into its four slots) and *pair friction* (each pushing pair's
//! friction change and its nodes' shares, from x and v*). After each, the
//! *segment sums* (the twin of `pairs.wgsl`) add up each segment's slots on
//! its first node and on its last, in the order of its partners, and each
//! node takes the sum of the segment it starts and then of the one it ends,
//! in the block pass and the move pass. That is the GPU's order, so
//! `Serial<f32>` and `wgpu` agree bit for bit. No node or segment is
//! written by two threads, and the sums do not depend on the thread count
//! or on when the list was built (pairs out of reach add exactly zero).
//! The collider terms are per node and run inside those two passes.
//!
//! This module owns the list, its per-segment entries and the per-pair
//! arithmetic; `passes.rs` runs the passes.

use std::sync::atomic::{AtomicBool, Ordering};

use yarn_model::self_contact::PairSearch;
use yarn_model::step::{cap, segment_end, self_contact_friction_at};
use yarn_model::terms::{Closest, closest_gap, self_contact_push};
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
    /// Per pair: its closest points at the last force pass, which the
    /// friction pass, at the same positions, reuses (written for pushing
    /// pairs only).
    pub(crate) closest: Vec<Closest<T>>,
    /// [`Model::revision`] at the last build (0: never built).
    revision: u64,
    builds: u64,
    /// Segment s's entries are `entries[start[s]..start[s + 1]]`, in the
    /// order of its partners: each the slot (4 × pair + k) of the node s
    /// starts at; the node it ends at has the next slot.
    start: Vec<u32>,
    entries: Vec<u32>,
    /// Per slot: the pair's force on that node, and its friction change
    /// (written for pushing pairs only).
    pub(crate) force: Field<T>,
    pub(crate) friction: Field<T>,
    /// Per segment: its pushing pairs' sums, of the forces or of the
    /// friction changes, whichever pass ran last.
    pub(crate) sums: Vec<SegmentSums<T>>,
}

/// A segment's sums over its pushing pairs, in partner order, on its first
/// node and on its last, with the longest change on each (friction).
#[derive(Debug, Clone, Copy)]
pub(crate) struct SegmentSums<T> {
    first: V3<T>,
    first_longest: T,
    last: V3<T>,
    last_longest: T,
}

impl<T: Real> Default for SegmentSums<T> {
    fn default() -> Self {
        Self { first: V3::zeros(), first_longest: T::zero(), last: V3::zeros(), last_longest: T::zero() }
    }
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

    /// Rebuild the list at `x`, with its incidence and buffers; the search
    /// runs as `exec` runs passes.
    pub(crate) fn rebuild(&mut self, model: &Model<T>, x: &Field<T>, exec: super::Exec) {
        let mut positions = Vec::new();
        x.to_vectors(&mut positions);
        let pairs = find_pairs(model, &positions, exec);
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
        self.closest = vec![Closest::default(); self.nodes.len()];
        self.anchor.clone_from(x);
        self.revision = model.revision();
        self.builds += 1;
        let slots = self.nodes.len() * 4;
        self.force = Field::zeros(slots);
        self.friction = Field::zeros(slots);
        self.sums = vec![SegmentSums::default(); x.len()];
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

    /// Segment `s`'s sums over its pushing pairs, from `values` (the force
    /// or friction slots), on its first node and its last, in partner
    /// order: the twin of `pairs.wgsl`.
    fn segment_sums(&self, s: usize, values: &Field<T>, friction: bool) -> SegmentSums<T> {
        let mut sums = SegmentSums::default();
        for &slot in self.entries_of(Some(s as u32)).iter().filter(|&&slot| self.active[slot as usize / 4]) {
            let (first, last) = (values.get(slot as usize), values.get(slot as usize + 1));
            sums.first += first;
            sums.last += last;
            if friction {
                sums.first_longest = sums.first_longest.max(first.norm());
                sums.last_longest = sums.last_longest.max(last.norm());
            }
        }
        sums
    }

    /// The segment sums of a block of segments (`out`, from `block`), of
    /// the forces or, with `friction`, of the friction changes.
    pub(crate) fn sums_block(&self, block: usize, friction: bool, out: &mut [SegmentSums<T>]) {
        let values = if friction { &self.friction } else { &self.force };
        for (k, sums) in out.iter_mut().enumerate() {
            *sums = self.segment_sums(block * BLOCK + k, values, friction);
        }
    }

    /// Node `i`'s self-contact force added to `f`: the sum of the segment
    /// it starts (`own`: whether it starts one), then that of the one it
    /// ends (`prev`).
    pub(crate) fn force_at(&self, i: usize, own: bool, prev: Option<u32>, f: V3<T>) -> V3<T> {
        let f = if own { f + self.sums[i].first } else { f };
        prev.map_or(f, |p| f + self.sums[p as usize].last)
    }

    /// The force of pairs block `block` on their nodes, into `out`
    /// (slots 4 × pair + k), whether each pushes, into `active`, and the
    /// closest points of those that do, into `closest`:
    /// [`yarn_model::terms::self_contact_forces`], zero out of reach. A
    /// pair whose distance at the build, less how far its nodes have moved
    /// since, is still out of reach cannot touch, and is not measured.
    pub(crate) fn forces_block(
        &self,
        model: &Model<T>,
        x: &Field<T>,
        block: usize,
        (out, active, closest): (&mut BlockMut<'_, T>, &mut [bool], &mut [Closest<T>]),
    ) {
        let reach = T::of(2.0 * model.contact_rule().radius());
        // A thousandth of a radius for the rounding of the bound's terms.
        let clear = reach * T::of(1.0005);
        let k_sc = model.coeffs().self_contact;
        let first = block * PAIRS_PER_BLOCK;
        let moved = |i: u32| self.moved[i as usize];
        for (j, (active, closest)) in active.iter_mut().zip(closest).enumerate() {
            let nodes = self.nodes[first + j];
            let nearest =
                self.built_gap[first + j] - moved(nodes[0]).max(moved(nodes[1])) - moved(nodes[2]).max(moved(nodes[3]));
            let f = if nearest >= clear {
                None
            } else {
                let p = nodes.map(|i| x.get(i as usize));
                *closest = Closest::of(&p[0], &p[1], &p[2], &p[3]);
                self_contact_push(closest, reach, k_sc)
            };
            *active = f.is_some();
            // A pair that does not push is never read.
            for (k, f) in f.into_iter().flatten().enumerate() {
                (out.x[4 * j + k], out.y[4 * j + k], out.z[4 * j + k]) = (f.x, f.y, f.z);
            }
        }
    }

    /// The friction change of pairs block `block` from x (the force
    /// pass's closest points) and `v` (v*), into `out`:
    /// [`yarn_model::step::self_contact_friction`], zero where it returns
    /// `None`.
    pub(crate) fn friction_block(&self, model: &Model<T>, v: &Field<T>, block: usize, out: &mut BlockMut<'_, T>) {
        let reach = T::of(2.0 * model.contact_rule().radius());
        let c = model.coeffs();
        let first = block * PAIRS_PER_BLOCK;
        // A pair that does not push is never read.
        for j in (0..out.x.len() / 4).filter(|&j| self.active[first + j]) {
            let w = self.nodes[first + j].map(|i| v.get(i as usize));
            let dv = self_contact_friction_at(&self.closest[first + j], [&w[0], &w[1], &w[2], &w[3]], reach, c)
                .unwrap_or([V3::zeros(); 4]);
            for (k, dv) in dv.into_iter().enumerate() {
                (out.x[4 * j + k], out.y[4 * j + k], out.z[4 * j + k]) = (dv.x, dv.y, dv.z);
            }
        }
    }

    /// The friction change at node `i`: the segment sums of the one it
    /// starts (`own`: whether it starts one) and the one it ends (`prev`),
    /// added and [`cap`]ped to the longest change.
    pub(crate) fn friction_at(&self, i: usize, own: bool, prev: Option<u32>) -> V3<T> {
        let none = SegmentSums::default();
        let (own, before) = (if own { &self.sums[i] } else { &none }, prev.map_or(&none, |p| &self.sums[p as usize]));
        cap(own.first + before.last, own.first_longest.max(before.last_longest))
    }
}

/// [`yarn_model::self_contact::find_pairs`] at `positions` with the
/// model's skin, its search's pieces run as `exec` runs passes: the same
/// pairs, sorted.
fn find_pairs<T: Real>(model: &Model<T>, positions: &[V3<T>], exec: super::Exec) -> Vec<[u32; 2]> {
    let search = PairSearch::new(model, positions, model.params().self_contact_skin * model.contact_rule().radius());
    let mut pairs = Vec::new();
    match exec {
        super::Exec::Sequential => {
            search.find(0..search.pieces(), &mut pairs);
            pairs.sort_unstable();
        }
        super::Exec::Parallel => {
            use rayon::prelude::*;
            let pieces = search.pieces();
            let found: Vec<Vec<[u32; 2]>> = (0..pieces.div_ceil(PIECES_PER_TASK))
                .into_par_iter()
                .map(|task| {
                    let mut pairs = Vec::new();
                    search.find(task * PIECES_PER_TASK..pieces.min((task + 1) * PIECES_PER_TASK), &mut pairs);
                    pairs
                })
                .collect();
            pairs = found.concat();
            pairs.par_sort_unstable();
        }
    }
    pairs
}

/// Cells of the pair search per parallel task.
const PIECES_PER_TASK: usize = 4096;
