//! What touches the yarn besides its own chain and persistent contacts, on
//! the CPU: self-contact between segments ([`yarn_model::self_contact`])
//! and the colliders ([`yarn_model::collider`]).
//!
//! Self-contact runs as a Verlet list of segment pairs, rebuilt by
//! [`yarn_model::self_contact::find_pairs`] when some node has moved half
//! the skin since the last build or the model's revision changed. Of its
//! candidates, the *near list* keeps those that may come within reach
//! before it is next refreshed, which is far less often than every
//! substep and far more often than a rebuild
//! ([`SelfContacts::refresh_near`]). Two passes run over the near pairs:
//! *pair forces* (each pair's force on its four nodes, into its four
//! slots) and *pair friction* (each pushing pair's friction change and its
//! nodes' shares, from x and v*). Each pass gathers
//! a block's pairs by component into its thread's [`PairScratch`], finds
//! their closest points or friction impulses in a loop that vectorises
//! (the operations of `yarn_model::terms` and `step`, in their order), and
//! scatters the results into the slots. After each, the *segment sums*
//! (the twin of the sums in `gather.wgsl` and `friction.wgsl`) add up each
//! segment's slots on its first node and on its last, in the order of its
//! partners, and each node takes the sum of the segment it starts and then
//! of the one it ends, in the block pass and the move pass. That is the
//! GPU's order, so
//! `Serial<f32>` and `wgpu` agree bit for bit. No node or segment is
//! written by two threads, and the sums do not depend on the thread count
//! or on when either list was built (pairs out of reach add exactly zero).
//! The collider terms are per node and run inside those two passes.
//!
//! This module owns the list, its per-segment entries and the per-pair
//! arithmetic; `passes.rs` runs the passes.

use std::sync::atomic::{AtomicBool, Ordering};

use yarn_model::self_contact::PairSearch;
use yarn_model::step::{pair_sharing, segment_end};
use yarn_model::terms::{Closest, closest_gap, push_depth, self_contact_push};
use yarn_model::{Coefficients, Model, Real, V3};

use super::field::{BLOCK, BlockMut, Field};

/// Pairs per block of the per-pair fields: each pair has four slots.
pub(crate) const PAIRS_PER_BLOCK: usize = BLOCK / 4;

/// A pair's values on its four nodes, by slot: a, a's next, b, b's next.
pub(crate) type Slots<T> = [V3<T>; 4];

/// The near list's margin δ as a fraction of the skin
/// ([`SelfContacts::refresh_near`]).
const NEAR_MARGIN: f64 = 0.25;

/// The self-contact candidate list of a CPU fabric, the near list the pair
/// passes walk, and its per-pair buffers.
#[derive(Debug, Default)]
pub(crate) struct SelfContacts<T> {
    /// Per candidate pair: its segments' nodes [a, a's next, b, b's next].
    nodes: Vec<[u32; 4]>,
    /// The positions at the last build.
    anchor: Field<T>,
    /// Per candidate pair: its closest distance at the last build.
    built_gap: Vec<T>,
    /// Per node: how far it has moved since the last build, as of the
    /// last staleness check.
    moved: Vec<T>,
    /// [`Model::revision`] at the last build (0: never built).
    revision: u64,
    builds: u64,
    /// Segment s's candidate entries are `entries[start[s]..start[s + 1]]`,
    /// in the order of its partners: each 2 × pair, or 2 × pair + 1 where
    /// s is the pair's second segment.
    start: Vec<u32>,
    entries: Vec<u32>,
    /// Per node: how far it may have moved since the last build before the
    /// near list must be refreshed; empty when it must be.
    ceiling: Vec<T>,
    /// The near list ([`Self::refresh_near`]): the candidates that may
    /// push before its next refresh, in candidate order, by their nodes.
    /// The per-pair buffers below and the slots are by near pair.
    near: Vec<[u32; 4]>,
    /// Segment s's entries of near pairs are
    /// `near_entries[near_start[s]..near_start[s + 1]]`, in partner
    /// order: each the slot (4 × near pair + k) of the node s starts at;
    /// the node it ends at has the next slot.
    near_start: Vec<u32>,
    near_entries: Vec<u32>,
    /// Per near pair: whether it was within reach at the last force pass;
    /// the friction pass and the sums skip the others.
    pub(crate) active: Vec<bool>,
    /// Per near pair: its closest points at the last force pass, which the
    /// friction pass, at the same positions, reuses (written for pushing
    /// pairs only).
    pub(crate) closest: Vec<Closest<T>>,
    /// Per near pair, by slot k: the pair's force on its node k, and its
    /// friction change (written for pushing pairs only). A pair's four
    /// slots lie together, so a segment sum loads one pair's two in one
    /// cache line.
    pub(crate) force: Vec<Slots<T>>,
    pub(crate) friction: Vec<Slots<T>>,
    /// Per segment: its pushing pairs' sums, of the forces or of the
    /// friction changes, whichever pass ran last, on its first node and on
    /// its last, in partner order.
    pub(crate) first: Field<T>,
    pub(crate) last: Field<T>,
    /// The nodes that do not take the sums of the segment they start and
    /// of the one before them in the arrays (a yarn's ends, a ring's
    /// closure), ascending.
    irregular: Vec<u32>,
    /// Per node: how many pairs push it, from the segment it starts and
    /// the one it ends ([`yarn_model::step::pushing_pairs`]), as of the
    /// last force pass's sums.
    pub(crate) pushing: Vec<u32>,
}

impl<T: Real> SelfContacts<T> {
    /// Whether the list may miss a pair within 2r at `x`: some node has
    /// moved half the skin since the last build, or the model changed.
    /// Records how far each node has moved, for the near list's bound, and
    /// marks the near list for a refresh once a node passes its ceiling.
    /// Blocks are checked as `exec` runs them.
    pub(crate) fn stale(&mut self, model: &Model<T>, x: &Field<T>, exec: super::Exec) -> bool {
        if self.revision != model.revision() || self.anchor.len() != x.len() {
            return true;
        }
        let half = T::of(0.5 * model.params().self_contact_skin * model.contact_rule().radius());
        let (far, past_ceiling) = (AtomicBool::new(false), AtomicBool::new(false));
        let (anchor, ceiling) = (&self.anchor, &self.ceiling);
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
            let ceiling = ceiling.get(block * BLOCK..block * BLOCK + moved.len()).unwrap_or(&[]);
            if ceiling.len() != moved.len() || !moved.iter().zip(ceiling).fold(true, |under, (m, c)| under & (m <= c)) {
                past_ceiling.store(true, Ordering::Relaxed);
            }
        };
        run_pass!(exec, moved.chunks_mut(BLOCK).enumerate(), moved.par_chunks_mut(BLOCK).enumerate(), 8, body);
        self.moved = moved;
        if past_ceiling.into_inner() {
            self.ceiling.clear();
        }
        far.into_inner()
    }

    /// Refresh the near list if some node has moved past its ceiling since
    /// the last refresh, or the list was rebuilt. It keeps the candidates
    /// whose distance at the build, less how far their nodes have moved
    /// since, is within reach plus a margin δ ([`NEAR_MARGIN`] of the
    /// skin), and lets each node move δ/2 further before the next refresh.
    /// Until then no other candidate can come within reach (its distance
    /// less its nodes' moves stays at least 2r), so the pair passes
    /// measure only these, and the sums walk only their entries, in the
    /// same order: what the passes compute does not change.
    pub(crate) fn refresh_near(&mut self, model: &Model<T>) {
        if self.ceiling.len() == self.moved.len() {
            return;
        }
        let skin = model.params().self_contact_skin * model.contact_rule().radius();
        let margin = T::of(NEAR_MARGIN * skin);
        // A thousandth of a radius for the rounding of the bound's terms.
        let clear = T::of(2.0 * model.contact_rule().radius() * 1.0005);
        let moved = |i: u32| self.moved[i as usize];
        // Per candidate: its index in the near list, or none.
        let mut index = vec![u32::MAX; self.nodes.len()];
        self.near.clear();
        for ((n, &gap), index) in self.nodes.iter().zip(&self.built_gap).zip(&mut index) {
            let bound = gap - moved(n[0]).max(moved(n[1])) - moved(n[2]).max(moved(n[3]));
            // A pair whose bound is not a number (a NaN position) is kept.
            if bound < clear + margin || !bound.to_f64().is_finite() {
                *index = self.near.len() as u32;
                self.near.push(*n);
            }
        }
        self.near_start.clear();
        self.near_start.push(0);
        self.near_entries.clear();
        for s in 0..self.start.len() - 1 {
            for &entry in &self.entries[self.start[s] as usize..self.start[s + 1] as usize] {
                let (pair, second) = (entry as usize / 2, entry % 2);
                if index[pair] != u32::MAX {
                    self.near_entries.push(4 * index[pair] + 2 * second);
                }
            }
            self.near_start.push(self.near_entries.len() as u32);
        }
        let rise = margin * T::of(0.5);
        self.ceiling.clear();
        self.ceiling.extend(self.moved.iter().map(|&m| m + rise));
        // Every pass writes what it reads for the pairs it reads (`active`
        // for all, the rest for those that push), so the buffers keep what
        // they held.
        let pairs = self.near.len();
        self.active.resize(pairs, false);
        self.closest.resize(pairs, Closest::default());
        self.force.resize(pairs, [V3::zeros(); 4]);
        self.friction.resize(pairs, [V3::zeros(); 4]);
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
            for (segment, entry) in [(a, 2 * pair), (b, 2 * pair + 1)] {
                self.entries[fill[segment as usize] as usize] = entry as u32;
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
        self.ceiling.clear();
        self.anchor.clone_from(x);
        self.revision = model.revision();
        self.builds += 1;
        self.first = Field::zeros(x.len());
        self.last = Field::zeros(x.len());
        let links = model.links();
        let regular = |i: usize| i > 0 && links[i].next().is_some() && links[i].prev() == Some(i as u32 - 1);
        self.irregular = (0..x.len()).filter(|&i| !regular(i)).map(|i| i as u32).collect();
        self.pushing = vec![0; x.len()];
    }

    /// The candidate pairs' segments, [a, b] by their first nodes.
    pub(crate) fn segment_pairs(&self) -> impl Iterator<Item = [u32; 2]> + '_ {
        self.nodes.iter().map(|n| [n[0], n[2]])
    }

    /// How many times the list has been built.
    pub(crate) fn builds(&self) -> u64 {
        self.builds
    }

    /// Segment `s`'s entries of near pairs, in partner order.
    fn near_entries_of(&self, s: usize) -> &[u32] {
        self.near_start.get(s + 1).map_or(&[], |&end| &self.near_entries[self.near_start[s] as usize..end as usize])
    }

    /// Segment `s`'s pushing near entries, in partner order.
    fn pushing_entries(&self, s: usize) -> impl Iterator<Item = usize> + '_ {
        self.near_entries_of(s).iter().map(|&slot| slot as usize).filter(|&slot| self.active[slot / 4])
    }

    /// Segment `s`'s sums over its pushing pairs, from `values` (the force
    /// or friction slots), on its first node and its last, in partner
    /// order, and their count: the twin of `segment_pushes` (`touch.wgsl`)
    /// and of `friction.wgsl`'s shared-out sums.
    fn segment_sums(&self, s: usize, values: &[Slots<T>]) -> ([V3<T>; 2], u32) {
        let (mut sums, mut count) = ([V3::zeros(); 2], 0);
        for slot in self.pushing_entries(s) {
            let (pair, k) = (&values[slot / 4], slot % 4);
            sums[0] += pair[k];
            sums[1] += pair[k + 1];
            count += 1;
        }
        (sums, count)
    }

    /// The segment sums of block `block` of segments, into `first` and
    /// `last`, of the forces or, with `friction`, of the friction changes.
    /// After the forces, also how many pairs push each node of the block
    /// (`pushing`, when given): those of the segment it starts and of the
    /// one it ends.
    pub(crate) fn sums_block(
        &self,
        model: &Model<T>,
        block: usize,
        friction: bool,
        (first, last, pushing): (&mut BlockMut<'_, T>, &mut BlockMut<'_, T>, Option<&mut [u32]>),
    ) {
        let values = if friction { &self.friction } else { &self.force };
        let (lo, len) = (block * BLOCK, first.x.len());
        let mut counts = [0u32; BLOCK];
        let (fx, fy, fz) = (&mut first.x[..len], &mut first.y[..len], &mut first.z[..len]);
        let (lx, ly, lz) = (&mut last.x[..len], &mut last.y[..len], &mut last.z[..len]);
        for (k, count) in counts[..len].iter_mut().enumerate() {
            let sums;
            (sums, *count) = self.segment_sums(lo + k, values);
            (fx[k], fy[k], fz[k]) = (sums[0].x, sums[0].y, sums[0].z);
            (lx[k], ly[k], lz[k]) = (sums[1].x, sums[1].y, sums[1].z);
        }
        let Some(pushing) = pushing else { return };
        // A segment of another block (a node's previous, across the
        // block's start or a ring's closure) is counted again.
        let count = |s: usize| match s.checked_sub(lo) {
            Some(k) if k < len => counts[k],
            _ => self.pushing_entries(s).count() as u32,
        };
        let links = &model.links()[lo..];
        for (k, pushing) in pushing.iter_mut().enumerate() {
            *pushing = counts[k] + links[k].prev().map_or(0, |p| count(p as usize));
        }
    }

    /// Add to `out` (nodes lo.., by component) each node's self-contact
    /// sums: `first`, that of the segment it starts, where it starts one,
    /// and `last`, that of the one it ends, where it ends one, in the GPU's
    /// order: `(x + first) + last` for the forces or, with `friction`,
    /// `x + (first + last)`. Most nodes start segment i and end segment
    /// i − 1, and runs of them are added in loops that vectorise; the
    /// irregular ones one at a time.
    pub(crate) fn add_sums(&self, model: &Model<T>, lo: usize, friction: bool, mut out: [&mut [T]; 3]) {
        let hi = lo + out[0].len();
        let from = self.irregular.partition_point(|&i| (i as usize) < lo);
        let irregular = self.irregular[from..].iter().map(|&i| i as usize).take_while(|&i| i < hi);
        let (first, last) = ([&self.first.x, &self.first.y, &self.first.z], [&self.last.x, &self.last.y, &self.last.z]);
        let mut start = lo;
        for end in irregular.chain([hi]) {
            if start < end {
                for ((out, first), last) in out.iter_mut().zip(first).zip(last) {
                    let (out, first, last) =
                        (&mut out[start - lo..end - lo], &first[start..end], &last[start - 1..end - 1]);
                    for k in 0..out.len() {
                        out[k] = if friction { out[k] + (first[k] + last[k]) } else { out[k] + first[k] + last[k] };
                    }
                }
            }
            if end < hi {
                let link = model.links()[end];
                let own = link.next().map(|_| self.first.get(end));
                let before = link.prev().map(|p| self.last.get(p as usize));
                let x = V3::new(out[0][end - lo], out[1][end - lo], out[2][end - lo]);
                let x = if friction {
                    x + (own.unwrap_or_else(V3::zeros) + before.unwrap_or_else(V3::zeros))
                } else {
                    let x = own.map_or(x, |own| x + own);
                    before.map_or(x, |before| x + before)
                };
                (out[0][end - lo], out[1][end - lo], out[2][end - lo]) = (x.x, x.y, x.z);
            }
            start = end + 1;
        }
    }

    /// The force of near pairs block `block` on their nodes, into `out`
    /// (slot k: on node k), whether each pushes, into `active`, and the
    /// closest points of those that do, into `closest`:
    /// [`yarn_model::terms::self_contact_forces`], zero out of reach. Only
    /// the near pairs ([`Self::refresh_near`]) may touch, and only they are
    /// measured. Their loads run first, in one scalar loop, so that their
    /// closest points ([`PairScratch::closest_points`]) are found in a loop
    /// that vectorises.
    pub(crate) fn forces_block(
        &self,
        model: &Model<T>,
        x: &Field<T>,
        block: usize,
        (out, active, closest): (&mut [Slots<T>], &mut [bool], &mut [Closest<T>]),
        scratch: &mut PairScratch<T>,
    ) {
        let reach = T::of(2.0 * model.contact_rule().radius());
        let k_sc = model.coeffs().self_contact;
        let first = block * PAIRS_PER_BLOCK;
        scratch.measured.clear();
        scratch.measured.extend(0..out.len());
        scratch.gather_ends(x, &self.near[first..]);
        scratch.closest_points();
        for (m, &j) in scratch.measured.iter().enumerate() {
            let pair = scratch.closest(m);
            // A pair that does not push is never read.
            active[j] = match self_contact_push(&pair, reach, k_sc) {
                Some(f) => {
                    (closest[j], out[j]) = (pair, f);
                    true
                }
                None => false,
            };
        }
    }

    /// The friction change of near pairs block `block` from x (the force
    /// pass's closest points) and `v` (v*), into `out`:
    /// [`yarn_model::step::self_contact_friction`], zero where it returns
    /// `None`. The pushing pairs' velocities and closest points are
    /// gathered first, so that their impulses ([`PairScratch::friction_impulses`])
    /// are found in a loop that vectorises.
    pub(crate) fn friction_block(
        &self,
        model: &Model<T>,
        v: &Field<T>,
        block: usize,
        out: &mut [Slots<T>],
        scratch: &mut PairScratch<T>,
    ) {
        let reach = T::of(2.0 * model.contact_rule().radius());
        let first = block * PAIRS_PER_BLOCK;
        scratch.measured.clear();
        // A pair that does not push is never read.
        scratch.measured.extend((0..out.len()).filter(|&j| self.active[first + j]));
        scratch.gather_ends(v, &self.near[first..]);
        let pushing = &self.pushing;
        for m in 0..scratch.measured.len() {
            let j = scratch.measured[m];
            scratch.set_closest(m, &self.closest[first + j]);
            let [a, b, c, d] = self.near[first + j].map(|i| i as usize);
            scratch.sharing[m] = pair_sharing([pushing[a], pushing[b], pushing[c], pushing[d]]);
        }
        scratch.friction_impulses(reach, model.coeffs());
        for (m, &j) in scratch.measured.iter().enumerate() {
            out[j] = scratch.friction_change(m);
        }
    }
}

/// Per-thread working memory of the pair passes over one block of pairs:
/// which of them are measured, their four nodes' values gathered by
/// component, and what the pass finds for each, so that the pair
/// arithmetic runs in loops that vectorise between a scalar gather and a
/// scalar scatter.
#[derive(Debug, Clone)]
pub(crate) struct PairScratch<T> {
    /// The pairs measured, by their index in the block.
    measured: Vec<usize>,
    /// Per measured pair: the positions (force pass) or velocities
    /// (friction pass) of its nodes a, a's next, b, b's next.
    ends: [Field<T>; 4],
    /// Per measured pair: its closest points ([`Closest`]).
    gap: Field<T>,
    distance: Vec<T>,
    s: Vec<T>,
    t: Vec<T>,
    /// Per measured pair: its friction impulse (before its nodes' shares),
    /// its slip, and how many pairs it shares the impulse with
    /// ([`yarn_model::step::pair_sharing`]).
    impulse: Field<T>,
    slip: Vec<T>,
    sharing: Vec<T>,
}

impl<T: Real> PairScratch<T> {
    pub(crate) fn new() -> Self {
        let field = || Field::zeros(PAIRS_PER_BLOCK);
        Self {
            measured: Vec::with_capacity(PAIRS_PER_BLOCK),
            ends: std::array::from_fn(|_| field()),
            gap: field(),
            distance: vec![T::zero(); PAIRS_PER_BLOCK],
            s: vec![T::zero(); PAIRS_PER_BLOCK],
            t: vec![T::zero(); PAIRS_PER_BLOCK],
            impulse: field(),
            slip: vec![T::zero(); PAIRS_PER_BLOCK],
            sharing: vec![T::one(); PAIRS_PER_BLOCK],
        }
    }

    /// The values of `field` at the four nodes of each measured pair (its
    /// nodes `nodes[j]`, j its index in the block) into `ends`, by
    /// component: the scattered loads in one scalar loop, whose stores go
    /// to slices fetched once.
    fn gather_ends(&mut self, field: &Field<T>, nodes: &[[u32; 4]]) {
        let Self { measured, ends: [p0, p1, q0, q1], .. } = self;
        let from = [&field.x[..], &field.y[..], &field.z[..]];
        let count = measured.len();
        let mut to = [p0.prefix_mut(count), p1.prefix_mut(count), q0.prefix_mut(count), q1.prefix_mut(count)];
        for (m, &j) in measured.iter().enumerate() {
            for (to, i) in to.iter_mut().zip(nodes[j]) {
                for (to, from) in to.iter_mut().zip(from) {
                    to[m] = from[i as usize];
                }
            }
        }
    }

    /// The closest points of measured pair `m`.
    fn closest(&self, m: usize) -> Closest<T> {
        Closest { gap: self.gap.get(m), distance: self.distance[m], s: self.s[m], t: self.t[m] }
    }

    /// Set the closest points of measured pair `m`.
    #[inline]
    fn set_closest(&mut self, m: usize, &Closest { gap, distance, s, t }: &Closest<T>) {
        self.gap.set(m, gap);
        (self.distance[m], self.s[m], self.t[m]) = (distance, s, t);
    }

    /// The closest points of the measured pairs from their positions in
    /// `ends`: the operations of [`yarn_model::terms::closest_gap`] in the
    /// same order, so the rounding matches, with selects for its branches.
    fn closest_points(&mut self) {
        let m = self.measured.len();
        let Self { ends: [p0, p1, q0, q1], gap, distance, s: s_out, t: t_out, .. } = self;
        // Written out rather than with arrays' `map`, which is not always
        // inlined: the loop vectorises only where the slices' lengths are
        // seen to be `m`.
        let (p0, p1, q0, q1) = (p0.prefix(m), p1.prefix(m), q0.prefix(m), q1.prefix(m));
        let (gx, gy, gz) = (&mut gap.x[..m], &mut gap.y[..m], &mut gap.z[..m]);
        let (distance, s_out, t_out) = (&mut distance[..m], &mut s_out[..m], &mut t_out[..m]);
        let (zero, one, flat) = (T::zero(), T::one(), T::of(1e-6));
        let pick = |condition: bool, yes: T, no: T| if condition { yes } else { no };
        let unit = |x: T| pick(x < zero, zero, pick(x > one, one, x));
        let dot = |a: [T; 3], b: [T; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        for k in 0..m {
            let (p0k, q0k) = ([p0[0][k], p0[1][k], p0[2][k]], [q0[0][k], q0[1][k], q0[2][k]]);
            let u = [p1[0][k] - p0k[0], p1[1][k] - p0k[1], p1[2][k] - p0k[2]];
            let v = [q1[0][k] - q0k[0], q1[1][k] - q0k[1], q1[2][k] - q0k[2]];
            let w = [p0k[0] - q0k[0], p0k[1] - q0k[1], p0k[2] - q0k[2]];
            let (a, e, f, c, b) = (dot(u, u), dot(v, v), dot(v, w), dot(u, w), dot(u, v));
            // Every branch's value is computed and one is selected.
            let det = a * e - b * b;
            let s = pick(det > flat * a * e, unit((b * f - c * e) / det), zero);
            let t = (b * s + f) / e;
            let (below, above) = (t < zero, t > one);
            let s_below = unit(-c / a);
            let s = pick(below, s_below, pick(above, unit((b - c) / a), s));
            let t = pick(below, zero, pick(above, one, t));
            // Where a segment has no length.
            let (no_u, no_v) = (a <= zero, e <= zero);
            let s = pick(no_u, zero, pick(no_v, s_below, s));
            let t = pick(no_u, pick(e > zero, unit(f / e), zero), pick(no_v, zero, t));
            let gap = |i: usize| p0k[i] + u[i] * s - q0k[i] - v[i] * t;
            let g = [gap(0), gap(1), gap(2)];
            (gx[k], gy[k], gz[k]) = (g[0], g[1], g[2]);
            distance[k] = dot(g, g).sqrt();
            (s_out[k], t_out[k]) = (s, t);
        }
    }

    /// The friction impulses of the measured pairs, which push, into
    /// `impulse` and their slips into `slip`, from their closest points and
    /// their nodes' velocities in `ends`: the operations of
    /// [`yarn_model::step::self_contact_friction_at`] in the same order,
    /// up to the shares of the impulse, which [`Self::friction_change`]
    /// takes. The loop writes four rows rather than the twelve of the
    /// changes: writing twelve, it was not vectorised (seen in the
    /// disassembly).
    fn friction_impulses(&mut self, reach: T, c: &Coefficients<T>) {
        let m = self.measured.len();
        let Self { ends, gap, distance, s, t, impulse, slip: slip_out, sharing, .. } = self;
        let (v0, v1, v2, v3) = (ends[0].prefix(m), ends[1].prefix(m), ends[2].prefix(m), ends[3].prefix(m));
        let (gx, gy, gz, distance, s, t) = (&gap.x[..m], &gap.y[..m], &gap.z[..m], &distance[..m], &s[..m], &t[..m]);
        let [jx, jy, jz] = impulse.prefix_mut(m);
        let (slip_out, sharing) = (&mut slip_out[..m], &sharing[..m]);
        let (zero, one) = (T::zero(), T::one());
        let limit = c.friction * c.self_contact_impulse;
        for k in 0..m {
            let d = distance[k];
            let n = [gx[k] / d, gy[k] / d, gz[k] / d];
            let shares = [one - s[k], s[k], one - t[k], t[k]];
            let relative = |i: usize| {
                (v2[i][k] * shares[2] + v3[i][k] * shares[3]) - (v0[i][k] * shares[0] + v1[i][k] * shares[1])
            };
            let w = [relative(0), relative(1), relative(2)];
            let normal = w[0] * n[0] + w[1] * n[1] + w[2] * n[2];
            let wt = [w[0] - n[0] * normal, w[1] - n[1] * normal, w[2] - n[2] * normal];
            let slip = (wt[0] * wt[0] + wt[1] * wt[1] + wt[2] * wt[2]).sqrt();
            let inverse_mass =
                zero + shares[0] * shares[0] + shares[1] * shares[1] + shares[2] * shares[2] + shares[3] * shares[3];
            let cut = limit * push_depth(reach - d, reach) * inverse_mass * sharing[k];
            let retention = (one - cut / slip).max(zero);
            let scale = (retention - one) / (inverse_mass * sharing[k]);
            (jx[k], jy[k], jz[k], slip_out[k]) = (wt[0] * scale, wt[1] * scale, wt[2] * scale, slip);
        }
    }

    /// Measured pair `m`'s friction change on its four nodes, from its
    /// impulse ([`Self::friction_impulses`]): zero where it does not slip.
    fn friction_change(&self, m: usize) -> Slots<T> {
        if self.slip[m] <= T::zero() {
            return [V3::zeros(); 4];
        }
        let (j, s, t) = (self.impulse.get(m), self.s[m], self.t[m]);
        let one = T::one();
        [-(j * (one - s)), -(j * s), j * (one - t), j * t]
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

#[cfg(test)]
mod tests {
    use yarn_model::step::self_contact_friction_at;
    use yarn_model::terms::Closest;
    use yarn_model::{Coefficients, Params, Real, V3};

    use super::{PAIRS_PER_BLOCK, PairScratch};

    /// Pairs of segments that exercise every branch of the closest points:
    /// crossing, parallel, end to middle, touching, and with no length.
    fn pairs<T: Real>() -> Vec<[V3<T>; 4]> {
        let mut state = 0x9e37_79b9_7f4a_7c15_u64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            T::of((state >> 11) as f64 / (1u64 << 53) as f64 * 4.0 - 2.0)
        };
        let mut point = move || V3::new(next(), next(), next());
        let mut pairs = Vec::new();
        for k in 0..2048 {
            let [p0, p1, q0, q1] = [point(), point(), point(), point()];
            pairs.push(match k % 8 {
                0 => [p0, p0, q0, q1],
                1 => [p0, p1, q0, q0],
                2 => [p0, p0, q0, q0],
                3 => [p0, p1, p0 + q0 * T::of(0.1), p1 + q0 * T::of(0.1)],
                4 => [p0, p1, p1, q1],
                5 => [p0, p1, p0, p1],
                _ => [p0, p1, q0, q1],
            });
        }
        pairs
    }

    /// The vectorised closest points and friction are the scalar terms',
    /// bit for bit, so `Serial` still equals the GPU's gather mode.
    fn matches_the_scalar_terms<T: Real>() {
        let params = Params { self_contact_stiffness: 1600.0, ..Params::default() };
        let c = Coefficients::<T>::new(&params);
        let reach = T::of(1.5);
        let mut scratch = PairScratch::<T>::new();
        // Shared with 1 to 7 pairs.
        let sharing_of = |m: usize| T::of((1 + m % 7) as f64);
        let (mut pushing, mut slipping) = (0, 0);
        for block in pairs::<T>().chunks(PAIRS_PER_BLOCK) {
            scratch.measured = (0..block.len()).collect();
            for (m, pair) in block.iter().enumerate() {
                for (end, p) in scratch.ends.iter_mut().zip(pair) {
                    end.set(m, *p);
                }
            }
            scratch.closest_points();
            let found: Vec<Closest<T>> = (0..block.len()).map(|m| scratch.closest(m)).collect();
            for (pair, found) in block.iter().zip(&found) {
                let expected = Closest::of(&pair[0], &pair[1], &pair[2], &pair[3]);
                assert_eq!(format!("{found:?}"), format!("{expected:?}"), "{pair:?}");
            }
            // Friction at the pairs that push, with velocities of the same
            // kind as the positions.
            scratch.measured = (0..block.len()).filter(|&m| found[m].within(reach)).collect();
            for (k, &m) in scratch.measured.clone().iter().enumerate() {
                let v = [block[m][1] - block[m][0], block[m][3], block[m][2] * T::of(3.0), V3::zeros()];
                for (end, v) in scratch.ends.iter_mut().zip(v) {
                    end.set(k, v);
                }
                scratch.set_closest(k, &found[m]);
                scratch.sharing[k] = sharing_of(m);
            }
            scratch.friction_impulses(reach, &c);
            for (k, &m) in scratch.measured.iter().enumerate() {
                let v =
                    [scratch.ends[0].get(k), scratch.ends[1].get(k), scratch.ends[2].get(k), scratch.ends[3].get(k)];
                let expected =
                    self_contact_friction_at(&found[m], [&v[0], &v[1], &v[2], &v[3]], reach, sharing_of(m), &c);
                slipping += usize::from(expected.is_some());
                let expected = expected.unwrap_or([V3::zeros(); 4]);
                assert_eq!(format!("{:?}", scratch.friction_change(k)), format!("{expected:?}"), "{:?}", block[m]);
            }
            pushing += scratch.measured.len();
        }
        assert!(pushing > 200 && slipping > 200, "{pushing} pushing, {slipping} slipping");
    }

    #[test]
    fn vectorised_pair_arithmetic_matches_the_scalar_terms_in_f32() {
        matches_the_scalar_terms::<f32>();
    }

    #[test]
    fn vectorised_pair_arithmetic_matches_the_scalar_terms_in_f64() {
        matches_the_scalar_terms::<f64>();
    }
}
