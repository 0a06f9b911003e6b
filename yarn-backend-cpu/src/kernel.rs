//! The CPU kernel behind [`Serial`](crate::Serial) and
//! [`Rayon`](crate::Rayon): SPEC §4 as passes over fixed blocks of nodes,
//! with the state stored by component so the per-node loops vectorise.
//! `Serial` runs the blocks in order on the calling thread; `Rayon` runs
//! them in parallel.
//!
//! No node is written by two threads. Each substep runs:
//! 1. *contacts*: the tether force of every alive contact, into its slot;
//! 2. *blocks* of [`BLOCK`] nodes, each in its thread's scratch: the unit
//!    tangent, inverse length and stretch force of every segment its nodes
//!    touch, the bending forces of every joint they touch, then per node
//!    the sum of its segments, joints and contacts (through a per-node
//!    contact list in contact order), and the damped velocity update. The
//!    two segments and joints a block shares with each neighbour are
//!    computed by both, so blocks never wait on each other;
//! 3. *friction*: the Jacobi change of every compressed alive contact;
//! 4. *blocks*: each node sums its contacts' friction changes and moves;
//! 5. pins.
//!
//! Without friction (μ = 0) passes 3 and 4 are skipped and the move joins
//! pass 2, writing a second position buffer.
//!
//! The blocks are fixed by the node count, not the thread count, so the
//! result does not depend on how many threads run. The element formulas
//! are those of [`yarn_model::terms`], operation for operation, written with
//! selects instead of early returns so the loops vectorise; the kernel
//! agrees with [`yarn_model::step::substep`] to float rounding (only the
//! order of each node's sum differs).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Mutex, PoisonError};

use rayon::prelude::*;
use yarn_model::terms::{MIN_SIN_THETA, gravity_force};
use yarn_model::{BackendError, ContactRest, Model, Params, Real, State, V3};
use yarn_topology::{Fabric, Pin};

/// Nodes per block: a block's `f32` scratch (16 numbers per node) fits the
/// first-level cache, and the two segments and joints it recomputes at
/// each edge cost nothing against the work.
const BLOCK: usize = 512;

/// Fewest blocks per rayon task (about 12 µs of work): a patch under 1,024
/// nodes runs on one thread instead of paying to wake another, and larger
/// ones split finely enough that no thread idles long at the end of a
/// pass. Measured with `yarn-gate bench` against 1, 4 and 8.
const TASK_BLOCKS: usize = 2;

/// Fewest contacts per rayon task in the contact passes, whose blocks are
/// also [`BLOCK`] long (a contact costs about as much as a node's share of
/// a block).
const TASK_CONTACTS: usize = 2048;

/// How the blocks of a pass are run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Exec {
    /// In order, on the calling thread.
    Sequential,
    /// On the current rayon pool.
    Parallel,
}

/// Run one pass: the same `body` over a sequential or a parallel iterator.
macro_rules! run_pass {
    ($exec:expr, $sequential:expr, $parallel:expr, $min_len:expr, $body:expr) => {
        match $exec {
            Exec::Sequential => $sequential.for_each($body),
            Exec::Parallel => $parallel.with_min_len($min_len).for_each($body),
        }
    };
}

/// Substeps between two looks at which blocks may sleep or must wake: the
/// look scans every awake velocity, so it is not taken every substep.
const SLEEP_CHECK: u64 = 10;

/// A 3-vector field stored by component.
#[derive(Debug, Clone, Default)]
struct Field<T> {
    x: Vec<T>,
    y: Vec<T>,
    z: Vec<T>,
}

/// One block of a [`Field`], writable.
struct BlockMut<'a, T> {
    x: &'a mut [T],
    y: &'a mut [T],
    z: &'a mut [T],
}

impl<T: Real> Field<T> {
    fn zeros(n: usize) -> Self {
        Self { x: vec![T::zero(); n], y: vec![T::zero(); n], z: vec![T::zero(); n] }
    }

    fn from_vectors(v: &[V3<T>]) -> Self {
        Self {
            x: v.iter().map(|p| p.x).collect(),
            y: v.iter().map(|p| p.y).collect(),
            z: v.iter().map(|p| p.z).collect(),
        }
    }

    fn len(&self) -> usize {
        self.x.len()
    }

    fn get(&self, i: usize) -> V3<T> {
        V3::new(self.x[i], self.y[i], self.z[i])
    }

    fn set(&mut self, i: usize, v: V3<T>) {
        (self.x[i], self.y[i], self.z[i]) = (v.x, v.y, v.z);
    }

    fn to_vectors(&self, out: &mut Vec<V3<T>>) {
        out.clear();
        out.extend((0..self.len()).map(|i| self.get(i)));
    }

    /// The three components of block `b`.
    fn block(&self, b: usize) -> [&[T]; 3] {
        let range = b * BLOCK..((b + 1) * BLOCK).min(self.len());
        [&self.x[range.clone()], &self.y[range.clone()], &self.z[range]]
    }

    fn blocks_mut(&mut self) -> impl Iterator<Item = BlockMut<'_, T>> {
        let Self { x, y, z } = self;
        x.chunks_mut(BLOCK).zip(y.chunks_mut(BLOCK)).zip(z.chunks_mut(BLOCK)).map(|((x, y), z)| BlockMut { x, y, z })
    }

    fn par_blocks_mut(&mut self) -> impl IndexedParallelIterator<Item = BlockMut<'_, T>> {
        let Self { x, y, z } = self;
        x.par_chunks_mut(BLOCK).zip(y.par_chunks_mut(BLOCK)).zip(z.par_chunks_mut(BLOCK)).map(|((x, y), z)| BlockMut {
            x,
            y,
            z,
        })
    }
}

impl<T> BlockMut<'_, T> {
    fn components(&mut self) -> [&mut [T]; 3] {
        [&mut *self.x, &mut *self.y, &mut *self.z]
    }
}

/// One node's part in a contact.
#[derive(Debug, Clone, Copy)]
struct Incidence<T> {
    node: u32,
    contact: u32,
    /// +1 if the node is the contact's `a`, −1 if its `b`.
    sign: T,
}

/// Per-block working memory. Segment and joint arrays are indexed from two
/// elements before the block's first node; entries past either end of the
/// yarn stay zero, so the per-node sum needs no branches.
#[derive(Debug, Clone)]
struct Scratch<T> {
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
}

impl<T: Real> Scratch<T> {
    fn new() -> Self {
        Self {
            tangent: Field::zeros(BLOCK + 3),
            inv_length: vec![T::zero(); BLOCK + 3],
            stretch: Field::zeros(BLOCK + 3),
            fa: Field::zeros(BLOCK + 2),
            fc: Field::zeros(BLOCK + 2),
            force: Field::zeros(BLOCK),
            gap: Field::zeros(BLOCK),
            relative: Field::zeros(BLOCK),
        }
    }
}

/// A loaded fabric: the model, the state by component, and the buffers the
/// passes reuse, so stepping allocates nothing.
#[derive(Debug)]
pub(crate) struct Kernel<T: Real> {
    model: Model<T>,
    positions: Field<T>,
    velocities: Field<T>,
    /// κθ0 of every joint, refreshed with the parameters.
    target: Vec<T>,
    /// The alive contacts, in contact order: the contact passes run over
    /// these only, so released contacts cost nothing.
    live: Vec<ContactRest<T>>,
    /// Each contact's slot in `live`, or `u32::MAX` when it is not there.
    slot: Vec<u32>,
    /// The alive contacts of node i are `incident[start[i]..start[i + 1]]`,
    /// each naming its slot in `live`.
    start: Vec<u32>,
    incident: Vec<Incidence<T>>,
    /// Per contact, in blocks of [`BLOCK`] contacts: the force on its `a`
    /// node, then the friction change Δw.
    contact_force: Field<T>,
    friction: Field<T>,
    /// Without friction, the forces and the move share a pass, which writes
    /// the new positions here while other blocks still read the old ones.
    next_positions: Field<T>,
    /// One scratch per thread that may run blocks, by rayon thread index;
    /// each is locked only by its own thread.
    scratch: Vec<Mutex<Scratch<T>>>,
    exec: Exec,
    /// Substeps completed since load.
    substeps: u64,
    /// Set by a block whose damped velocity passed the divergence speed (or
    /// is not finite) in the last substep.
    diverged: AtomicBool,
    /// The state at the start of the current `advance`, to put back if it
    /// diverges.
    saved: [Field<T>; 2],
    /// Per block: asleep (not integrated), and the substeps its nodes have
    /// all stayed below the sleep speed.
    asleep: Vec<bool>,
    quiet: Vec<u32>,
    /// Per block: the other blocks it shares a segment or a contact with.
    neighbours: Vec<Vec<u32>>,
}

impl<T: Real> Kernel<T> {
    /// Load `fabric` at rest, to run with `threads` threads as `exec` says.
    pub(crate) fn new(fabric: &Fabric, params: &Params, exec: Exec, threads: usize) -> Result<Self, BackendError> {
        let model = Model::<T>::new(fabric, params)?;
        let n = model.node_count();
        let state = State::<T>::at_rest(fabric);
        let mut kernel = Self {
            positions: Field::from_vectors(&state.positions),
            velocities: Field::from_vectors(&state.velocities),
            target: Vec::new(),
            live: Vec::new(),
            slot: Vec::new(),
            start: Vec::new(),
            incident: Vec::new(),
            contact_force: Field::zeros(0),
            friction: Field::zeros(0),
            next_positions: Field::zeros(n),
            scratch: (0..threads.max(1)).map(|_| Mutex::new(Scratch::new())).collect(),
            exec,
            substeps: 0,
            diverged: AtomicBool::new(false),
            saved: [Field::zeros(n), Field::zeros(n)],
            asleep: vec![false; n.div_ceil(BLOCK)],
            quiet: vec![0; n.div_ceil(BLOCK)],
            neighbours: neighbours(&model, n.div_ceil(BLOCK)),
            model,
        };
        kernel.refresh_targets();
        kernel.refresh_contacts();
        Ok(kernel)
    }

    /// Rebuild the contacts the passes run over, their per-node lists and
    /// their buffers: the alive contacts with a node in an awake block.
    fn refresh_contacts(&mut self) {
        let model = &self.model;
        let (_, entries) = model.incidence();
        let awake = |node: u32| !self.asleep[node as usize / BLOCK];
        let mut slot = vec![u32::MAX; model.contacts.len()];
        self.live.clear();
        for (k, c) in model.contacts.iter().enumerate() {
            if model.alive[k] && (awake(c.a) || awake(c.b)) {
                slot[k] = self.live.len() as u32;
                self.live.push(*c);
            }
        }
        let mut start = vec![0u32; model.node_count() + 1];
        self.incident = entries
            .into_iter()
            .filter(|&(_, contact)| slot[contact as usize] != u32::MAX)
            .map(|(node, contact)| {
                start[node as usize + 1] += 1;
                let sign = if model.contacts[contact as usize].a == node { T::one() } else { -T::one() };
                Incidence { node, contact: slot[contact as usize], sign }
            })
            .collect();
        for i in 0..model.node_count() {
            start[i + 1] += start[i];
        }
        self.start = start;
        self.slot = slot;
        self.contact_force = Field::zeros(self.live.len());
        self.friction = Field::zeros(self.live.len());
    }

    fn refresh_targets(&mut self) {
        let kappa = self.model.coeffs.rest_curl;
        self.target = self.model.rest_angle.iter().map(|&theta0| kappa * theta0).collect();
    }

    pub(crate) fn set_params(&mut self, params: &Params) -> Result<(), BackendError> {
        self.model.set_params(params)?;
        self.refresh_targets();
        self.wake_all();
        Ok(())
    }

    pub(crate) fn set_pins(&mut self, pins: &[Pin]) -> Result<(), BackendError> {
        self.model.set_pins(pins)?;
        self.wake_all();
        Ok(())
    }

    pub(crate) fn set_contacts_alive(&mut self, alive: &[bool]) -> Result<(), BackendError> {
        let mut positions = Vec::new();
        if self.model.revives(alive) {
            self.positions.to_vectors(&mut positions);
        }
        self.model.set_contacts_alive(alive, &positions)?;
        self.asleep.fill(false);
        self.quiet.fill(0);
        self.refresh_contacts();
        Ok(())
    }

    pub(crate) fn write_state(&mut self, state: &State<T>) -> Result<(), BackendError> {
        state.check_len(self.model.node_count())?;
        self.positions = Field::from_vectors(&state.positions);
        self.velocities = Field::from_vectors(&state.velocities);
        self.wake_all();
        Ok(())
    }

    /// Wake every sleeping block.
    fn wake_all(&mut self) {
        self.quiet.fill(0);
        if self.asleep.iter().any(|&a| a) {
            self.asleep.fill(false);
            self.refresh_contacts();
        }
    }

    /// Blocks asleep now, for tests and reports.
    pub(crate) fn sleeping_blocks(&self) -> usize {
        self.asleep.iter().filter(|&&a| a).count()
    }

    /// Every [`SLEEP_CHECK`] substeps: count quiet substeps, put blocks that
    /// have stayed slow long enough (with no pin and no fast neighbour) to
    /// sleep, and wake sleepers next to a block moving at twice the sleep
    /// speed.
    fn update_sleep(&mut self) {
        let limit = self.model.params().sleep_speed;
        if limit <= 0.0 {
            return;
        }
        let blocks = self.asleep.len();
        // The fastest node of each awake block, squared.
        let speed2: Vec<f64> = (0..blocks)
            .map(|b| {
                if self.asleep[b] {
                    return 0.0;
                }
                let [x, y, z] = self.velocities.block(b);
                let mut max = T::zero();
                for k in 0..x.len() {
                    let s = x[k] * x[k] + y[k] * y[k] + z[k] * z[k];
                    max = if s > max { s } else { max };
                }
                max.to_f64()
            })
            .collect();
        let mut pinned = vec![false; blocks];
        for &(node, _) in &self.model.pins {
            pinned[node as usize / BLOCK] = true;
        }
        let (sleep2, wake2) = (limit * limit, 4.0 * limit * limit);
        let fast_neighbour = |b: usize| self.neighbours[b].iter().any(|&n| speed2[n as usize] > wake2);
        let mut changed = false;
        for b in 0..blocks {
            if self.asleep[b] {
                if pinned[b] || fast_neighbour(b) {
                    (self.asleep[b], self.quiet[b], changed) = (false, 0, true);
                }
                continue;
            }
            self.quiet[b] = if speed2[b] < sleep2 && !pinned[b] { self.quiet[b] + SLEEP_CHECK as u32 } else { 0 };
            if self.quiet[b] >= yarn_model::SLEEP_AFTER && !fast_neighbour(b) {
                (self.asleep[b], changed) = (true, true);
                let range = b * BLOCK..((b + 1) * BLOCK).min(self.positions.len());
                for (v, (x, next)) in
                    [&mut self.velocities.x, &mut self.velocities.y, &mut self.velocities.z].into_iter().zip([
                        (&self.positions.x, &mut self.next_positions.x),
                        (&self.positions.y, &mut self.next_positions.y),
                        (&self.positions.z, &mut self.next_positions.z),
                    ])
                {
                    v[range.clone()].fill(T::zero());
                    next[range.clone()].copy_from_slice(&x[range.clone()]);
                }
            }
        }
        if changed {
            self.refresh_contacts();
        }
    }

    pub(crate) fn read_state(&self, state: &mut State<T>) {
        self.positions.to_vectors(&mut state.positions);
        self.velocities.to_vectors(&mut state.velocities);
    }

    /// F = −∇U(x) on every node (SPEC §4 step 1), into `forces`.
    pub(crate) fn compute_forces(&mut self, forces: &mut Vec<V3<T>>) {
        // Every node's force needs every alive contact.
        self.wake_all();
        self.contact_forces();
        let mut field = Field::zeros(self.model.node_count());
        let this = &*self;
        let body = |(b, mut out): (usize, BlockMut<'_, T>)| {
            this.with_scratch(|scratch| {
                this.block_forces(b, scratch);
                for (out, force) in out.components().into_iter().zip(scratch.force.block(0)) {
                    out.copy_from_slice(&force[..out.len()]);
                }
            });
        };
        run_pass!(self.exec, field.blocks_mut().enumerate(), field.par_blocks_mut().enumerate(), TASK_BLOCKS, body);
        field.to_vectors(forces);
    }

    /// Run `work` with this thread's scratch.
    fn with_scratch(&self, work: impl FnOnce(&mut Scratch<T>)) {
        let slot = rayon::current_thread_index().unwrap_or(0) % self.scratch.len();
        work(&mut self.scratch[slot].lock().unwrap_or_else(PoisonError::into_inner));
    }

    /// Pass 1: the tether force of every alive contact, on its `a` node.
    fn contact_forces(&mut self) {
        let mut contact_force = std::mem::take(&mut self.contact_force);
        let this = &*self;
        let body = |(b, mut out): (usize, BlockMut<'_, T>)| {
            this.with_scratch(|scratch| this.contact_block_forces(b, &mut out, scratch));
        };
        run_pass!(
            self.exec,
            contact_force.blocks_mut().enumerate(),
            contact_force.par_blocks_mut().enumerate(),
            TASK_CONTACTS / BLOCK,
            body
        );
        self.contact_force = contact_force;
    }

    /// Gather x_b − x_a of contacts `range` into `scratch.gap`, and, with
    /// `velocities`, v_b − v_a into `scratch.relative`: the scattered loads
    /// in one scalar loop, so the arithmetic after them vectorises.
    fn gather_contacts(&self, range: std::ops::Range<usize>, velocities: Option<&Field<T>>, scratch: &mut Scratch<T>) {
        let contacts = &self.live[range];
        for (field, out) in
            [(&self.positions, &mut scratch.gap)].into_iter().chain(velocities.map(|v| (v, &mut scratch.relative)))
        {
            for (j, c) in contacts.iter().enumerate() {
                let (a, b) = (c.a as usize, c.b as usize);
                out.set(j, field.get(b) - field.get(a));
            }
        }
    }

    /// Contact block `b` of the alive contacts: the operations of
    /// `terms::spring_force`.
    fn contact_block_forces(&self, b: usize, out: &mut BlockMut<'_, T>, scratch: &mut Scratch<T>) {
        let range = b * BLOCK..b * BLOCK + out.x.len();
        self.gather_contacts(range.clone(), None, scratch);
        let k_c = self.model.coeffs.contact;
        let (zero, one) = (T::zero(), T::one());
        let contacts = &self.live[range];
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

    /// Contact block `b` of the alive contacts: the operations of
    /// `step::friction_change` from x and v*, zeroed where it returns
    /// `None`.
    fn friction_block(&self, b: usize, out: &mut BlockMut<'_, T>, scratch: &mut Scratch<T>) {
        let range = b * BLOCK..b * BLOCK + out.x.len();
        self.gather_contacts(range.clone(), Some(&self.velocities), scratch);
        let c = self.model.coeffs;
        let (zero, one) = (T::zero(), T::one());
        let contacts = &self.live[range];
        let m = contacts.len();
        let (dx, dy, dz) = (&scratch.gap.x[..m], &scratch.gap.y[..m], &scratch.gap.z[..m]);
        let (wx, wy, wz) = (&scratch.relative.x[..m], &scratch.relative.y[..m], &scratch.relative.z[..m]);
        let (ox, oy, oz) = (&mut out.x[..m], &mut out.y[..m], &mut out.z[..m]);
        for j in 0..m {
            let rest = contacts[j].rest;
            let length = (dx[j] * dx[j] + dy[j] * dy[j] + dz[j] * dz[j]).sqrt();
            let compressed = length < rest && length > zero;
            let divisor = if compressed { length } else { one };
            let n = [dx[j] / divisor, dy[j] / divisor, dz[j] / divisor];
            let normal = wx[j] * n[0] + wy[j] * n[1] + wz[j] * n[2];
            let wt = [wx[j] - n[0] * normal, wy[j] - n[1] * normal, wz[j] - n[2] * normal];
            let slip = (wt[0] * wt[0] + wt[1] * wt[1] + wt[2] * wt[2]).sqrt();
            let (slip, keep) = if compressed && slip > zero { (slip, one) } else { (one, zero) };
            let dv_normal = c.friction_impulse * (rest - length);
            let retention = (one - c.friction * dv_normal / slip).max(zero);
            let scale = (retention - one) * keep;
            (ox[j], oy[j], oz[j]) = (wt[0] * scale, wt[1] * scale, wt[2] * scale);
        }
    }

    /// The contact entries of block `b`'s nodes, one group per node that
    /// has contacts, each in contact order.
    fn contact_groups(&self, b: usize) -> impl Iterator<Item = &[Incidence<T>]> {
        let (lo, hi) = (b * BLOCK, ((b + 1) * BLOCK).min(self.start.len() - 1));
        self.incident[self.start[lo] as usize..self.start[hi] as usize].chunk_by(|p, q| p.node == q.node)
    }

    /// The total force on each node of block `b`, into `scratch.force`,
    /// after [`Self::contact_forces`].
    fn block_forces(&self, b: usize, scratch: &mut Scratch<T>) {
        let (lo, hi) = (b * BLOCK, ((b + 1) * BLOCK).min(self.positions.len()));
        self.segments(lo, hi, scratch);
        self.joints(lo, hi, scratch);
        let c = self.model.coeffs;
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
        for group in self.contact_groups(b) {
            let i = group[0].node as usize - lo;
            let f = group.iter().fold(force.get(i), |f, e| f + self.contact_force.get(e.contact as usize) * e.sign);
            force.set(i, f);
        }
    }

    /// Segments lo−2 ..= hi (local 0 ..= len+2) of block [lo, hi): unit
    /// tangent, inverse length, stretch force; zero past the yarn's ends.
    fn segments(&self, lo: usize, hi: usize, scratch: &mut Scratch<T>) {
        let n = self.positions.len();
        let k_s = self.model.coeffs.stretch;
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
        let rest = &self.model.spring_rest[base..base + m];
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

    /// Joints lo−2 .. hi (local 0 .. len+2) of block [lo, hi): bending
    /// forces on their first and last node; zero past the yarn's ends and
    /// where sin θ < [`MIN_SIN_THETA`] (SPEC §3).
    fn joints(&self, lo: usize, hi: usize, scratch: &mut Scratch<T>) {
        let n = self.positions.len();
        let k_b = self.model.coeffs.bend;
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
        let target = &self.target[lo + first - 2..lo + last - 2];
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

    /// Advance `substeps` substeps. A substep whose damped velocities pass
    /// the model's divergence speed, or turn non-finite, ends the call with
    /// [`BackendError::Diverged`], the state put back as it was before it.
    pub(crate) fn advance(&mut self, substeps: u64) -> Result<(), BackendError> {
        self.saved[0].clone_from(&self.positions);
        self.saved[1].clone_from(&self.velocities);
        let reseats = self.model.save_reseats();
        for done in 1..=substeps {
            self.substep();
            let (live, slot) = (&mut self.live, &self.slot);
            self.model.close_reseats(1, |contact, rest| {
                if let Some(c) = live.get_mut(slot[contact as usize] as usize) {
                    c.rest = rest;
                }
            });
            if (self.substeps + done).is_multiple_of(SLEEP_CHECK) {
                self.update_sleep();
            }
            if self.diverged.swap(false, Ordering::Relaxed) {
                let limit = self.model.divergence_speed();
                let mut state = State::default();
                self.read_state(&mut state);
                // The flag looks at v* before friction and pins; the state
                // after them names the node, or the first node past the
                // limit before them if they tamed it.
                let (node, speed) = state.first_diverged(limit).unwrap_or((0, f64::NAN));
                self.positions.clone_from(&self.saved[0]);
                self.velocities.clone_from(&self.saved[1]);
                self.model.restore_reseats(&reseats);
                self.refresh_contacts();
                return Err(BackendError::Diverged { substep: self.substeps + done, node, speed, limit });
            }
        }
        self.substeps += substeps;
        Ok(())
    }

    /// One substep: four passes, or two without friction.
    pub(crate) fn substep(&mut self) {
        let c = self.model.coeffs;
        let limit = T::of(self.model.divergence_speed());
        let apply_friction = c.friction > T::zero();
        self.contact_forces();
        // Pass 2: per block, all forces and the damped velocity update v*,
        // in place (blocks read only each other's positions); without
        // friction, the move too, into `next_positions`.
        let mut velocities = std::mem::take(&mut self.velocities);
        let mut next_positions = std::mem::take(&mut self.next_positions);
        let this = &*self;
        let body = |(b, (mut v, mut next_x)): (usize, (BlockMut<'_, T>, BlockMut<'_, T>))| {
            if this.asleep[b] {
                return;
            }
            this.with_scratch(|scratch| {
                this.block_forces(b, scratch);
                let (forces, x) = (scratch.force.block(0), this.positions.block(b));
                for ((v, f), (next_x, x)) in
                    v.components().into_iter().zip(forces).zip(next_x.components().into_iter().zip(x))
                {
                    // A NaN fails the comparison, so it is not `within`; the
                    // loop still vectorises.
                    let mut within = true;
                    for (v, f) in v.iter_mut().zip(f) {
                        *v = (*v + *f * c.h_over_m) * c.damping_factor;
                        within &= v.abs() <= limit;
                    }
                    if !within {
                        this.diverged.store(true, Ordering::Relaxed);
                    }
                    if !apply_friction {
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
            self.next_positions = next_positions;
            self.friction_and_move();
        } else {
            self.next_positions = std::mem::replace(&mut self.positions, next_positions);
        }
        for &(node, target) in &self.model.pins {
            self.positions.set(node as usize, target);
            self.velocities.set(node as usize, V3::zeros());
        }
    }

    /// Pass 3: the Jacobi friction change of every compressed alive contact,
    /// from x and v* (SPEC §4 step 3). Pass 4: per block, each node adds its
    /// contacts' changes (a gets −Δw/2, b +Δw/2), then moves.
    fn friction_and_move(&mut self) {
        let mut friction = std::mem::take(&mut self.friction);
        let this = &*self;
        let body = |(b, mut out): (usize, BlockMut<'_, T>)| {
            this.with_scratch(|scratch| this.friction_block(b, &mut out, scratch));
        };
        run_pass!(
            self.exec,
            friction.blocks_mut().enumerate(),
            friction.par_blocks_mut().enumerate(),
            TASK_CONTACTS / BLOCK,
            body
        );
        self.friction = friction;
        let (h, half) = (self.model.coeffs.h, T::of(0.5));
        let mut positions = std::mem::take(&mut self.positions);
        let mut velocities = std::mem::take(&mut self.velocities);
        let this = &*self;
        let body = |(b, (mut x, mut v)): (usize, (BlockMut<'_, T>, BlockMut<'_, T>))| {
            if this.asleep[b] {
                return;
            }
            for group in this.contact_groups(b) {
                let j = group[0].node as usize - b * BLOCK;
                let dv = group
                    .iter()
                    .fold(V3::zeros(), |dv, e| dv - this.friction.get(e.contact as usize) * (half * e.sign));
                (v.x[j], v.y[j], v.z[j]) = (v.x[j] + dv.x, v.y[j] + dv.y, v.z[j] + dv.z);
            }
            for (x, v) in x.components().into_iter().zip(v.components()) {
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
    }
}

/// Per block, the other blocks it shares a segment or a contact with.
fn neighbours<T: Real>(model: &Model<T>, blocks: usize) -> Vec<Vec<u32>> {
    let mut out = vec![Vec::new(); blocks];
    let mut link = |a: usize, b: usize| {
        if a != b {
            out[a].push(b as u32);
            out[b].push(a as u32);
        }
    };
    for b in 1..blocks {
        link(b - 1, b);
    }
    for c in &model.contacts {
        link(c.a as usize / BLOCK, c.b as usize / BLOCK);
    }
    for list in &mut out {
        list.sort_unstable();
        list.dedup();
    }
    out
}
