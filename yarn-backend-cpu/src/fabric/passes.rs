//! The passes of one substep on the CPU (SPEC §4) and the element
//! arithmetic inside them, over the blocks of [`BLOCK`] nodes that
//! `field.rs` lays out. `Serial` runs the blocks in order on the calling
//! thread; `Rayon` runs them in parallel.
//!
//! No node is written by two threads. Each substep runs:
//! 1. *contact forces*: the tether force of every live contact, into its
//!    slot;
//! 2. *block forces*, per block of [`BLOCK`] nodes, in its thread's
//!    scratch: the unit tangent, inverse length and stretch force of every
//!    segment its nodes touch, the bending forces of every joint they
//!    touch, then per node the sum of its segments, joints and contacts
//!    (through the per-node contact lists, in contact order), and the
//!    damped velocity update, whose divergence test is fused in when
//!    there is no friction to change it (with friction, the move tests the
//!    velocity after friction). The two
//!    segments and joints a block shares with each neighbour are computed
//!    by both, so blocks never wait on each other. The loops take a node's
//!    neighbours along the yarn to be the nodes beside it; the few nodes
//!    next to where a yarn ends and another begins, or where a closed yarn
//!    wraps, are then recomputed from their links (`chain.rs`);
//! 3. *friction*: the Jacobi change of every compressed live contact;
//! 4. *move*, per block: each node sums its contacts' friction changes and
//!    moves;
//! 5. *pins*.
//!
//! Without friction (μ = 0) passes 3 and 4 are skipped and the move joins
//! pass 2, writing a second position buffer.
//!
//! The blocks are fixed by the node count, not the thread count, so the
//! result does not depend on how many threads run. The element formulas
//! are those of [`yarn_model::terms`], operation for operation, written with
//! selects instead of early returns so the loops vectorise; the passes
//! agree with [`yarn_model::step::substep`] to float rounding (only the
//! order of each node's sum differs).
//!
//! This module owns the passes' arithmetic and their order; it does not
//! decide which contacts are live or which blocks sleep.

use std::sync::PoisonError;
use std::sync::atomic::Ordering;

use yarn_model::stages::{self, Stage};
use yarn_model::step::collider_friction;
use yarn_model::terms::{Closest, MIN_SIN_THETA, gravity_force};
use yarn_model::{Real, V3};

use super::CpuFabric;
use super::field::{BLOCK, BlockMut, Field};
use super::touching::{self, PAIRS_PER_BLOCK};

/// Fewest blocks per rayon task (about 12 µs of work): a patch under 1,024
/// nodes runs on one thread instead of paying to wake another, and larger
/// ones split finely enough that no thread idles long at the end of a
/// pass. Measured with `yarn-gate bench` against 1, 4 and 8.
const TASK_BLOCKS: usize = 2;

/// Fewest contacts per rayon task in the contact passes, whose blocks are
/// also [`BLOCK`] long (a contact costs about as much as a node's share of
/// a block).
const TASK_CONTACTS: usize = 2048;

/// Fewest blocks of self-contact pair slots per rayon task: a block holds
/// [`BLOCK`] / 4 pairs, each about as costly as a node's share of a block.
const TASK_PAIRS: usize = 8;

/// How the blocks of a pass are run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Exec {
    /// In order, on the calling thread.
    Sequential,
    /// On the current rayon pool.
    Parallel,
}

/// What each timed pass covers (the stage counters).
const CONTACT_FORCES: &[Stage] = &[Stage::Forces];
/// The block pass with friction on: forces and v*.
const BLOCK_FORCES: &[Stage] = &[Stage::Forces];
/// The block pass without friction, which moves the nodes too.
const BLOCK_FORCES_AND_MOVE: &[Stage] = &[Stage::Forces, Stage::Move, Stage::Check];
const FRICTION: &[Stage] = &[Stage::Friction];
/// The move after friction, with the divergence test.
const MOVE: &[Stage] = &[Stage::Move, Stage::Check];
const PINS: &[Stage] = &[Stage::Pins];

/// Per-block working memory, one per thread that may run blocks. Segment
/// and joint arrays are indexed from two elements before the block's first
/// node; entries past either end of the node arrays stay zero, so the
/// per-node sum needs no branches.
#[derive(Debug, Clone)]
pub(crate) struct Scratch<T> {
    /// Segment unit tangent, inverse length (zero for a degenerate
    /// segment), and stretch force on its first node.
    tangent: Field<T>,
    inv_length: Vec<T>,
    stretch: Field<T>,
    /// Joint forces on the first (`fa`) and last (`fc`) node.
    fa: Field<T>,
    fc: Field<T>,
    /// Total force on each node of the block.
    force: Field<T>,
    /// Per contact of a contact block: x_b − x_a and v_b − v_a.
    gap: Field<T>,
    relative: Field<T>,
    /// Per node of a block: the colliders' friction change from v*.
    collider_friction: Field<T>,
    /// The self-contact pair passes' gathered values.
    pairs: touching::PairScratch<T>,
}

impl<T: Real> Scratch<T> {
    pub(crate) fn new() -> Self {
        Self {
            tangent: Field::zeros(BLOCK + 3),
            inv_length: vec![T::zero(); BLOCK + 3],
            stretch: Field::zeros(BLOCK + 3),
            fa: Field::zeros(BLOCK + 2),
            fc: Field::zeros(BLOCK + 2),
            force: Field::zeros(BLOCK),
            gap: Field::zeros(BLOCK),
            relative: Field::zeros(BLOCK),
            collider_friction: Field::zeros(BLOCK),
            pairs: touching::PairScratch::new(),
        }
    }
}

impl<T: Real> CpuFabric<T> {
    /// F = −∇U(x) on every node (SPEC §4 step 1), into `forces`.
    pub(crate) fn compute_forces(&mut self, forces: &mut Vec<V3<T>>) {
        // Every node's force needs every alive contact.
        self.wake_all();
        self.self_contact_forces();
        self.contact_forces();
        let mut field = Field::zeros(self.model.node_count());
        let this = &*self;
        let body = |(block, mut out): (usize, BlockMut<'_, T>)| {
            this.with_scratch(|scratch| {
                this.block_forces(block, scratch);
                for (out, force) in out.components().into_iter().zip(scratch.force.block(0)) {
                    out.copy_from_slice(&force[..out.len()]);
                }
            });
        };
        run_pass!(self.exec, field.blocks_mut().enumerate(), field.par_blocks_mut().enumerate(), TASK_BLOCKS, body);
        field.to_vectors(forces);
    }

    /// Raise the divergence flag if a velocity component in `v` is past
    /// `limit` or not finite (a NaN fails the comparison, and the loop still
    /// vectorises).
    #[inline]
    fn flag_speeding(&self, v: &[T], limit: T) {
        if !v.iter().fold(true, |within, v| within & (v.abs() <= limit)) {
            self.diverged.store(true, Ordering::Relaxed);
        }
    }

    /// Run `work` with this thread's scratch.
    fn with_scratch(&self, work: impl FnOnce(&mut Scratch<T>)) {
        let slot = rayon::current_thread_index().unwrap_or(0) % self.scratch.len();
        work(&mut self.scratch[slot].lock().unwrap_or_else(PoisonError::into_inner));
    }

    /// Pass 1: the tether force of every alive contact, on its `a` node.
    fn contact_forces(&mut self) {
        let mut contact_force = std::mem::take(&mut self.contacts.force);
        let this = &*self;
        let body = |(block, mut out): (usize, BlockMut<'_, T>)| {
            this.with_scratch(|scratch| this.contact_block_forces(block, &mut out, scratch));
        };
        run_pass!(
            self.exec,
            contact_force.blocks_mut().enumerate(),
            contact_force.par_blocks_mut().enumerate(),
            TASK_CONTACTS / BLOCK,
            body
        );
        self.contacts.force = contact_force;
    }

    /// Self-contact, before the block pass: rebuild the candidate list if
    /// it may miss a pair within reach, then the force of every pair on
    /// its four nodes, into its slots.
    fn self_contact_forces(&mut self) {
        if !self.model.self_contact() {
            return;
        }
        if self.touching.stale(&self.model, &self.positions, self.exec) {
            self.touching.rebuild(&self.model, &self.positions, self.exec);
            // Only sleeping reads which blocks the pairs join; setting
            // `sleep_speed` is a new revision, which rebuilds.
            if self.model.params().sleep_speed > 0.0 {
                self.sleep.set_touching(&self.model, self.touching.segment_pairs());
            }
        }
        self.touching.refresh_near(&self.model);
        let mut force = std::mem::take(&mut self.touching.force);
        let mut active = std::mem::take(&mut self.touching.active);
        let mut closest = std::mem::take(&mut self.touching.closest);
        let this = &*self;
        type PairsBlock<'a, T> = (&'a mut [touching::Slots<T>], (&'a mut [bool], &'a mut [Closest<T>]));
        let body = |(block, (out, (active, closest))): (usize, PairsBlock<'_, T>)| {
            this.with_scratch(|scratch| {
                let pairs = (out, active, closest);
                this.touching.forces_block(&this.model, &this.positions, block, pairs, &mut scratch.pairs);
            });
        };
        run_pass!(
            self.exec,
            force
                .chunks_mut(PAIRS_PER_BLOCK)
                .zip(active.chunks_mut(PAIRS_PER_BLOCK).zip(closest.chunks_mut(PAIRS_PER_BLOCK)))
                .enumerate(),
            force
                .par_chunks_mut(PAIRS_PER_BLOCK)
                .zip(active.par_chunks_mut(PAIRS_PER_BLOCK).zip(closest.par_chunks_mut(PAIRS_PER_BLOCK)))
                .enumerate(),
            TASK_PAIRS,
            body
        );
        self.touching.closest = closest;
        self.touching.active = active;
        self.touching.force = force;
        self.segment_sums(false);
    }

    /// Each segment's sums of its pushing pairs' forces or, with
    /// `friction`, of their friction changes, on its first node and its
    /// last; after the forces, also how many pairs push each node.
    fn segment_sums(&mut self, friction: bool) {
        let mut first = std::mem::take(&mut self.touching.first);
        let mut last = std::mem::take(&mut self.touching.last);
        let mut pushing = std::mem::take(&mut self.touching.pushing);
        let this = &*self;
        type SumsBlock<'a, T> = ((BlockMut<'a, T>, BlockMut<'a, T>), &'a mut [u32]);
        let body = |(block, ((mut first, mut last), pushing)): (usize, SumsBlock<'_, T>)| {
            let pushing = (!friction).then_some(pushing);
            this.touching.sums_block(&this.model, block, friction, (&mut first, &mut last, pushing));
        };
        run_pass!(
            self.exec,
            first.blocks_mut().zip(last.blocks_mut()).zip(pushing.chunks_mut(BLOCK)).enumerate(),
            first.par_blocks_mut().zip(last.par_blocks_mut()).zip(pushing.par_chunks_mut(BLOCK)).enumerate(),
            TASK_BLOCKS,
            body
        );
        (self.touching.first, self.touching.last, self.touching.pushing) = (first, last, pushing);
    }

    /// Gather x_b − x_a of contacts `range` into `scratch.gap`, and, with
    /// `velocities`, v_b − v_a into `scratch.relative`: the scattered loads
    /// in one scalar loop, so the arithmetic after them vectorises.
    fn gather_contacts(&self, range: std::ops::Range<usize>, velocities: Option<&Field<T>>, scratch: &mut Scratch<T>) {
        let contacts = &self.contacts.live[range];
        for (field, out) in
            [(&self.positions, &mut scratch.gap)].into_iter().chain(velocities.map(|v| (v, &mut scratch.relative)))
        {
            for (j, c) in contacts.iter().enumerate() {
                let (a, b) = (c.a as usize, c.b as usize);
                out.set(j, field.get(b) - field.get(a));
            }
        }
    }

    /// Contact block `block` of the alive contacts: the operations of
    /// `terms::spring_force`.
    fn contact_block_forces(&self, block: usize, out: &mut BlockMut<'_, T>, scratch: &mut Scratch<T>) {
        let range = block * BLOCK..block * BLOCK + out.x.len();
        self.gather_contacts(range.clone(), None, scratch);
        let k_c = self.model.coeffs().contact;
        let (zero, one) = (T::zero(), T::one());
        let contacts = &self.contacts.live[range];
        let m = contacts.len();
        let (dx, dy, dz) = (&scratch.gap.x[..m], &scratch.gap.y[..m], &scratch.gap.z[..m]);
        let (fx, fy, fz) = (&mut out.x[..m], &mut out.y[..m], &mut out.z[..m]);
        for j in 0..m {
            let (x, y, z) = (dx[j], dy[j], dz[j]);
            let length = (x * x + y * y + z * z).sqrt();
            let (divisor, keep) = if length > zero { (length, one) } else { (one, zero) };
            let scale = k_c * (length - contacts[j].rest) / divisor * keep;
            (fx[j], fy[j], fz[j]) = (x * scale, y * scale, z * scale);
        }
    }

    /// Contact block `block` of the alive contacts: the operations of
    /// `step::friction_change` from x and v*, zeroed where it returns
    /// `None`.
    fn friction_block(&self, block: usize, out: &mut BlockMut<'_, T>, scratch: &mut Scratch<T>) {
        let range = block * BLOCK..block * BLOCK + out.x.len();
        self.gather_contacts(range.clone(), Some(&self.velocities), scratch);
        let c = *self.model.coeffs();
        let (zero, one) = (T::zero(), T::one());
        let in_tension = self.model.params().friction_in_tension;
        let contacts = &self.contacts.live[range];
        let m = contacts.len();
        let (dx, dy, dz) = (&scratch.gap.x[..m], &scratch.gap.y[..m], &scratch.gap.z[..m]);
        let (wx, wy, wz) = (&scratch.relative.x[..m], &scratch.relative.y[..m], &scratch.relative.z[..m]);
        let (ox, oy, oz) = (&mut out.x[..m], &mut out.y[..m], &mut out.z[..m]);
        for j in 0..m {
            let rest = contacts[j].rest;
            let length = (dx[j] * dx[j] + dy[j] * dy[j] + dz[j] * dz[j]).sqrt();
            let strained = (length < rest || (in_tension && length > rest)) && length > zero;
            let divisor = if strained { length } else { one };
            let n = [dx[j] / divisor, dy[j] / divisor, dz[j] / divisor];
            let normal = wx[j] * n[0] + wy[j] * n[1] + wz[j] * n[2];
            let wt = [wx[j] - n[0] * normal, wy[j] - n[1] * normal, wz[j] - n[2] * normal];
            let slip = (wt[0] * wt[0] + wt[1] * wt[1] + wt[2] * wt[2]).sqrt();
            let (slip, keep) = if strained && slip > zero { (slip, one) } else { (one, zero) };
            let dv_normal = c.friction_impulse * (rest - length).abs();
            let retention = (one - c.friction * dv_normal / slip).max(zero);
            let scale = (retention - one) * keep;
            (ox[j], oy[j], oz[j]) = (wt[0] * scale, wt[1] * scale, wt[2] * scale);
        }
    }

    /// The total force on each node of block `block`, into `scratch.force`,
    /// after [`Self::contact_forces`].
    fn block_forces(&self, block: usize, scratch: &mut Scratch<T>) {
        let (lo, hi) = (block * BLOCK, ((block + 1) * BLOCK).min(self.positions.len()));
        self.segments(lo, hi, scratch);
        self.joints(lo, hi, scratch);
        let c = *self.model.coeffs();
        let g = gravity_force(c.mass, c.gravity);
        let len = hi - lo;
        let Scratch { stretch: s, fa, fc, force, .. } = scratch;
        // Node lo + k: +segment k+2, −segment k+1, +fa of joint k+2,
        // −(fa + fc) of joint k+1, +fc of joint k (local indices).
        let sum = |out: &mut [T], s: &[T], fa: &[T], fc: &[T], g: T| {
            let (out, s, fa, fc) = (&mut out[..len], &s[..len + 3], &fa[..len + 2], &fc[..len + 2]);
            for k in 0..len {
                out[k] = g + s[k + 2] - s[k + 1] + fa[k + 2] - (fa[k + 1] + fc[k + 1]) + fc[k];
            }
        };
        sum(&mut force.x, &s.x, &fa.x, &fc.x, g.x);
        sum(&mut force.y, &s.y, &fa.y, &fc.y, g.y);
        sum(&mut force.z, &s.z, &fa.z, &fc.z, g.z);
        // Where the loops above took a neighbour across a yarn's break.
        for &i in self.breaks_in(lo, hi) {
            force.set(i as usize - lo, self.chain_force(i as usize));
        }
        for group in self.contacts.groups(block) {
            let i = group[0].node as usize - lo;
            let f = group.iter().fold(force.get(i), |f, e| f + self.contacts.force.get(e.contact as usize) * e.sign);
            force.set(i, f);
        }
        if self.model.self_contact() {
            self.touching.add_sums(&self.model, lo, false, force.prefix_mut(hi - lo));
        }
        let surfaces = self.model.surfaces();
        if !surfaces.is_empty() {
            let (radius, k) = (T::of(self.model.contact_rule().radius()), c.collider);
            for i in lo..hi {
                let x = self.positions.get(i);
                let f =
                    surfaces.iter().fold(force.get(i - lo), |f, s| s.force(&x, radius, k).map_or(f, |push| f + push));
                force.set(i - lo, f);
            }
        }
    }

    /// Segments lo−2 ..= hi (local 0 ..= len+2) of block [lo, hi), each
    /// from its node to the node after it in the arrays: unit tangent,
    /// inverse length, stretch force; zero past the arrays' ends. Where the
    /// node after it is not its next along the yarn (a yarn's last node),
    /// the value is not used: the nodes that would read it are breaks
    /// (`chain.rs`).
    fn segments(&self, lo: usize, hi: usize, scratch: &mut Scratch<T>) {
        let n = self.positions.len();
        let k_s = self.model.coeffs().stretch;
        // Local k is segment lo + k − 2; segments run 0 ..= n − 2.
        let first = 2usize.saturating_sub(lo);
        let last = (n + 1 - lo).min(hi - lo + 3).max(first);
        let Scratch { tangent: t, inv_length, stretch: f, .. } = scratch;
        for k in (0..first).chain(last..hi - lo + 3) {
            t.set(k, V3::zeros());
            f.set(k, V3::zeros());
            inv_length[k] = T::zero();
        }
        let (base, m) = (lo + first - 2, last - first);
        let x = &self.positions;
        let (px, py, pz) = (&x.x[base..=base + m], &x.y[base..=base + m], &x.z[base..=base + m]);
        let rest = &self.model.segment_rest()[base..base + m];
        let (tx, ty, tz) = (&mut t.x[first..last], &mut t.y[first..last], &mut t.z[first..last]);
        let (fx, fy, fz) = (&mut f.x[first..last], &mut f.y[first..last], &mut f.z[first..last]);
        let il = &mut inv_length[first..last];
        let (zero, one) = (T::zero(), T::one());
        // The operations of `terms::spring_force` and of the tangents in
        // `terms::bend_forces`, in the same order, so the rounding matches.
        for k in 0..m {
            let (dx, dy, dz) = (px[k + 1] - px[k], py[k + 1] - py[k], pz[k + 1] - pz[k]);
            let len = (dx * dx + dy * dy + dz * dz).sqrt();
            // A zero-length segment divides by 1 and is then zeroed, so
            // every value is computed and the loop has no branch.
            let (divisor, keep) = if len > zero { (len, one) } else { (one, zero) };
            let scale = k_s * (len - rest[k]) / divisor * keep;
            let inv = one / divisor * keep;
            (fx[k], fy[k], fz[k]) = (dx * scale, dy * scale, dz * scale);
            (tx[k], ty[k], tz[k]) = (dx * inv, dy * inv, dz * inv);
            il[k] = inv;
        }
    }

    /// Joints lo−2 .. hi (local 0 .. len+2) of block [lo, hi), centred on
    /// nodes lo−1 ..= hi with the nodes beside them in the arrays: bending
    /// forces on their first and last node; zero past the arrays' ends and
    /// where sin θ < [`MIN_SIN_THETA`] (SPEC §3). As for the segments, a
    /// joint that reaches across a yarn's break is read only by breaks.
    fn joints(&self, lo: usize, hi: usize, scratch: &mut Scratch<T>) {
        let n = self.positions.len();
        let k_b = self.model.coeffs().bend;
        // Local k is joint lo + k − 2, from segments k and k + 1; joints run
        // 0 ..= n − 3.
        let first = 2usize.saturating_sub(lo);
        let last = n.saturating_sub(lo).min(hi - lo + 2).max(first);
        let Scratch { tangent: t, inv_length, fa, fc, .. } = scratch;
        for k in (0..first).chain(last..hi - lo + 2) {
            fa.set(k, V3::zeros());
            fc.set(k, V3::zeros());
        }
        let m = last - first;
        // `target` is by centre node, local k's is lo + k − 1.
        let target = &self.target[lo + first - 1..lo + last - 1];
        let (ux, uy, uz) = (&t.x[first..=last], &t.y[first..=last], &t.z[first..=last]);
        let il = &inv_length[first..=last];
        let (fax, fay, faz) = (&mut fa.x[first..last], &mut fa.y[first..last], &mut fa.z[first..last]);
        let (fcx, fcy, fcz) = (&mut fc.x[first..last], &mut fc.y[first..last], &mut fc.z[first..last]);
        let (zero, one, min_sin) = (T::zero(), T::one(), T::of(MIN_SIN_THETA));
        // The operations of `terms::bend_forces`, in the same order.
        for k in 0..m {
            let (u, v) = ([ux[k], uy[k], uz[k]], [ux[k + 1], uy[k + 1], uz[k + 1]]);
            let s = (u[0] * v[0] + u[1] * v[1] + u[2] * v[2]).clamp(-one, one);
            let sin_theta = (one - s * s).sqrt();
            let (inv_l0, inv_l1) = (il[k], il[k + 1]);
            // As in the segments: a skipped joint divides by 1, then is zeroed.
            let (divisor, keep) =
                if sin_theta >= min_sin && inv_l0 > zero && inv_l1 > zero { (sin_theta, one) } else { (one, zero) };
            let coeff = k_b * (s.turning_angle() - target[k]) / divisor * keep;
            let (ca, cc) = (-coeff * inv_l0, coeff * inv_l1);
            (fax[k], fay[k], faz[k]) = ((v[0] - u[0] * s) * ca, (v[1] - u[1] * s) * ca, (v[2] - u[2] * s) * ca);
            (fcx[k], fcy[k], fcz[k]) = ((u[0] - v[0] * s) * cc, (u[1] - v[1] * s) * cc, (u[2] - v[2] * s) * cc);
        }
    }

    /// One substep: four passes, or two without friction.
    pub(crate) fn substep(&mut self) {
        let c = *self.model.coeffs();
        let limit = T::of(self.model.divergence_speed());
        let apply_friction = c.friction > T::zero() || self.model.surfaces().iter().any(|s| s.friction > T::zero());
        let started = stages::start(&self.clock);
        self.self_contact_forces();
        self.contact_forces();
        stages::stop(&mut self.clock, "contact forces", CONTACT_FORCES, started);
        let started = stages::start(&self.clock);
        // Pass 2: per block, all forces and the damped velocity update v*,
        // in place (blocks read only each other's positions); without
        // friction, the move too, into `next_positions`.
        let mut velocities = std::mem::take(&mut self.velocities);
        let mut next_positions = std::mem::take(&mut self.next_positions);
        let this = &*self;
        let body = |(block, (mut v, mut next_x)): (usize, (BlockMut<'_, T>, BlockMut<'_, T>))| {
            if this.sleep.asleep()[block] {
                return;
            }
            this.with_scratch(|scratch| {
                this.block_forces(block, scratch);
                let (forces, x) = (scratch.force.block(0), this.positions.block(block));
                for ((v, f), (next_x, x)) in
                    v.components().into_iter().zip(forces).zip(next_x.components().into_iter().zip(x))
                {
                    for (v, f) in v.iter_mut().zip(f) {
                        *v = (*v + *f * c.h_over_m) * c.damping_factor;
                    }
                    // With friction, v* is not the velocity the node moves
                    // with: the move tests the one after friction.
                    if !apply_friction {
                        this.flag_speeding(v, limit);
                        for ((next_x, x), v) in next_x.iter_mut().zip(x).zip(&*v) {
                            *next_x = *x + *v * c.h;
                        }
                    }
                }
            });
        };
        run_pass!(
            self.exec,
            velocities.blocks_mut().zip(next_positions.blocks_mut()).enumerate(),
            velocities.par_blocks_mut().zip(next_positions.par_blocks_mut()).enumerate(),
            TASK_BLOCKS,
            body
        );
        self.velocities = velocities;
        if apply_friction {
            stages::stop(&mut self.clock, "block forces", BLOCK_FORCES, started);
            self.next_positions = next_positions;
            self.friction_and_move();
        } else {
            self.next_positions = std::mem::replace(&mut self.positions, next_positions);
            stages::stop(&mut self.clock, "block forces", BLOCK_FORCES_AND_MOVE, started);
        }
        let started = stages::start(&self.clock);
        for &(node, target) in self.model.pins() {
            self.positions.set(node as usize, target);
            self.velocities.set(node as usize, V3::zeros());
        }
        stages::stop(&mut self.clock, "pins", PINS, started);
    }

    /// Pass 3: the Jacobi friction change of every compressed alive contact,
    /// from x and v* (SPEC §4 step 3). Pass 4: per block, each node adds its
    /// contacts' changes (a gets −Δw/2, b +Δw/2), then moves.
    fn friction_and_move(&mut self) {
        let started = stages::start(&self.clock);
        let mut friction = std::mem::take(&mut self.contacts.friction);
        let this = &*self;
        let body = |(block, mut out): (usize, BlockMut<'_, T>)| {
            this.with_scratch(|scratch| this.friction_block(block, &mut out, scratch));
        };
        run_pass!(
            self.exec,
            friction.blocks_mut().enumerate(),
            friction.par_blocks_mut().enumerate(),
            TASK_CONTACTS / BLOCK,
            body
        );
        self.contacts.friction = friction;
        if self.model.self_contact() && self.model.coeffs().friction > T::zero() {
            let mut friction = std::mem::take(&mut self.touching.friction);
            let this = &*self;
            let body = |(block, out): (usize, &mut [touching::Slots<T>])| {
                this.with_scratch(|scratch| {
                    this.touching.friction_block(&this.model, &this.velocities, block, out, &mut scratch.pairs);
                });
            };
            run_pass!(
                self.exec,
                friction.chunks_mut(PAIRS_PER_BLOCK).enumerate(),
                friction.par_chunks_mut(PAIRS_PER_BLOCK).enumerate(),
                TASK_PAIRS,
                body
            );
            self.touching.friction = friction;
            self.segment_sums(true);
        }
        stages::stop(&mut self.clock, "friction", FRICTION, started);
        let started = stages::start(&self.clock);
        let (h, half) = (self.model.coeffs().h, T::of(0.5));
        let limit = T::of(self.model.divergence_speed());
        let self_friction = self.model.self_contact() && self.model.coeffs().friction > T::zero();
        let mut positions = std::mem::take(&mut self.positions);
        let mut velocities = std::mem::take(&mut self.velocities);
        let this = &*self;
        let body = |(block, (mut x, mut v)): (usize, (BlockMut<'_, T>, BlockMut<'_, T>))| {
            if this.sleep.asleep()[block] {
                return;
            }
            let lo = block * BLOCK;
            let surfaces = this.model.surfaces();
            let with_colliders = !surfaces.is_empty();
            this.with_scratch(|scratch| {
                if with_colliders {
                    // From v*, before any contact's change.
                    let (radius, impulse) =
                        (T::of(this.model.contact_rule().radius()), this.model.coeffs().collider_impulse);
                    for j in 0..x.x.len() {
                        let (p, w) = (V3::new(x.x[j], x.y[j], x.z[j]), V3::new(v.x[j], v.y[j], v.z[j]));
                        scratch.collider_friction.set(j, collider_friction(surfaces, &p, &w, radius, impulse));
                    }
                }
                for group in this.contacts.groups(block) {
                    let j = group[0].node as usize - lo;
                    let dv = group.iter().fold(V3::zeros(), |dv, e| {
                        dv - this.contacts.friction.get(e.contact as usize) * (half * e.sign)
                    });
                    (v.x[j], v.y[j], v.z[j]) = (v.x[j] + dv.x, v.y[j] + dv.y, v.z[j] + dv.z);
                }
                if self_friction {
                    this.touching.add_sums(&this.model, lo, true, v.components());
                }
                if with_colliders {
                    for j in 0..x.x.len() {
                        let dv = scratch.collider_friction.get(j);
                        (v.x[j], v.y[j], v.z[j]) = (v.x[j] + dv.x, v.y[j] + dv.y, v.z[j] + dv.z);
                    }
                }
            });
            for (x, v) in x.components().into_iter().zip(v.components()) {
                this.flag_speeding(v, limit);
                for (x, v) in x.iter_mut().zip(&*v) {
                    *x += *v * h;
                }
            }
        };
        run_pass!(
            self.exec,
            positions.blocks_mut().zip(velocities.blocks_mut()).enumerate(),
            positions.par_blocks_mut().zip(velocities.par_blocks_mut()).enumerate(),
            TASK_BLOCKS,
            body
        );
        (self.positions, self.velocities) = (positions, velocities);
        stages::stop(&mut self.clock, "move", MOVE, started);
    }
}
