//! A fabric made ready to simulate in one precision: its element tables and
//! rest values, the parameters as coefficients, the pins and contact
//! liveness. Backends build one on load and keep it current; the state
//! (positions and velocities) is kept apart in [`State`].

use yarn_topology::{Fabric, Link, Pin, YarnSpan, available_memory, check_memory};

use std::sync::atomic::{AtomicU64, Ordering};

use crate::collider::Surface;
use crate::real::{cast, widen};
use crate::self_contact::{ContactRule, MAX_STEP_RADII};
use crate::{BackendError, Collider, Params, Real, V3};

/// The parameters in a backend's precision, with the derived factors the
/// substep uses (SPEC §4).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Coefficients<T> {
    /// Stretch stiffness k_s.
    pub stretch: T,
    /// Bending stiffness k_b.
    pub bend: T,
    /// Rest-curl fraction κ.
    pub rest_curl: T,
    /// Contact stiffness k_c.
    pub contact: T,
    /// Friction coefficient μ.
    pub friction: T,
    /// Node mass m.
    pub mass: T,
    /// Substep h.
    pub h: T,
    /// Gravity g.
    pub gravity: T,
    /// h / m: velocity change per unit force.
    pub h_over_m: T,
    /// 1 / (1 + βh): the implicit damping factor.
    pub damping_factor: T,
    /// h k_c / (m/2): normal velocity change per unit contact compression,
    /// used by the friction filter.
    pub friction_impulse: T,
    /// Self-contact stiffness k_sc (0: off).
    pub self_contact: T,
    /// h k_sc / m: the velocity change per unit of the self-contact push's
    /// depth ([`crate::terms::push_depth`]) on a node of unit share, used
    /// by the friction filter.
    pub self_contact_impulse: T,
    /// Collider stiffness k_col.
    pub collider: T,
    /// h k_col / m: the velocity change per unit collider depth, used by
    /// the friction filter.
    pub collider_impulse: T,
}

impl<T: Real> Coefficients<T> {
    /// Convert validated parameters.
    pub fn new(p: &Params) -> Self {
        Self {
            stretch: T::of(p.stretch_stiffness),
            bend: T::of(p.bend_stiffness),
            rest_curl: T::of(p.rest_curl),
            contact: T::of(p.contact_stiffness),
            friction: T::of(p.friction),
            mass: T::of(p.mass),
            h: T::of(p.substep),
            gravity: T::of(p.gravity),
            h_over_m: T::of(p.substep / p.mass),
            damping_factor: T::of(1.0 / (1.0 + p.damping * p.substep)),
            friction_impulse: T::of(p.substep * p.contact_stiffness / (0.5 * p.mass)),
            self_contact: T::of(p.self_contact_stiffness),
            self_contact_impulse: T::of(p.substep * p.self_contact_stiffness / p.mass),
            collider: T::of(p.collider_stiffness),
            collider_impulse: T::of(p.substep * p.collider_stiffness / p.mass),
        }
    }
}

/// A persistent contact in a backend's precision.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactRest<T> {
    /// First node.
    pub a: u32,
    /// Second node.
    pub b: u32,
    /// Rest separation d_c.
    pub rest: T,
}

/// Scalars a backend holds per node, counted generously: the model's rest
/// tables, the state, its next and saved copies, and a copy read out.
const SCALARS_PER_NODE: u64 = 32;

/// Scalars a backend holds per contact, besides its two node indices.
const SCALARS_PER_CONTACT: u64 = 12;

/// Index bytes a backend holds per node besides its scalars: the node's
/// [`Link`], on the host and again on a device.
const INDEX_BYTES_PER_NODE: u64 = 2 * size_of::<Link>() as u64;

/// How far, in mean segment lengths, a node may travel in one substep
/// before it counts as diverged ([`Model::divergence_speed`]).
pub const DIVERGENCE_REACH: f64 = 10.0;

/// How fast a re-seated contact's rest separation closes back to its
/// knitted value, in mean segment lengths per simulated second
/// ([`Model::reseat_step`]).
pub const RESEAT_SPEED: f64 = 10.0;

/// A contact revived while its nodes were not at its knitted rest
/// separation d_c. Its two-sided tether would snap them to d_c with the
/// energy ½ k_c (ℓ − d_c)², enough to blow a fabric up when they have
/// drifted apart, so instead its rest separation is re-seated at its
/// length ℓ (no energy added) and moves back to d_c by
/// [`Model::reseat_step`] after every substep: the yarns are drawn back
/// together (or apart) at [`RESEAT_SPEED`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reseat<T> {
    /// The contact.
    pub contact: u32,
    /// Its knitted rest separation d_c, where the closing stops.
    pub knit: T,
}

/// A fabric's element tables and rest values in precision `T`, with the
/// current parameters, pins and contact liveness.
///
/// The chain (springs and bending joints) is held per node, the layout the
/// gathering backends read: node i's [`Link`] to its neighbours along its
/// yarn, the rest length of the segment that leaves it (to its next node)
/// and the rest angle of the joint centred on it. A node at an open yarn's
/// end starts no segment or no joint, and its entries there are zero; a
/// closed yarn's links wrap around. [`Model::springs`] and
/// [`Model::joints`] list the elements that exist, in node order: for a
/// fabric of one open yarn, spring i is (i, i + 1) and joint i is
/// (i, i + 1, i + 2).
///
/// Its fields are private so that the rule tying them together holds: a
/// contact that comes alive away from its rest separation is re-seated
/// ([`Reseat`]), and only [`Model::set_contacts_alive`] changes liveness.
#[derive(Debug, Clone, PartialEq)]
pub struct Model<T> {
    /// The fabric's yarns.
    yarns: Vec<YarnSpan>,
    /// Each node's neighbours along its yarn.
    links: Vec<Link>,
    /// Per node: rest length of the segment from it to its next node (zero
    /// where none leaves it).
    segment_rest: Vec<T>,
    /// Per node: rest turning angle θ0 of the joint centred on it (zero
    /// where it has no joint).
    joint_rest: Vec<T>,
    /// Springs and joints that exist.
    springs: usize,
    joints: usize,
    /// The persistent contacts.
    contacts: Vec<ContactRest<T>>,
    /// Liveness of each contact; dead contacts exert no force or friction.
    alive: Vec<bool>,
    /// The contacts whose rest separation (in `contacts`) is re-seated and
    /// still closing, in contact order.
    reseating: Vec<Reseat<T>>,
    /// Pinned nodes and their targets.
    pins: Vec<(u32, V3<T>)>,
    /// The parameters, converted.
    coeffs: Coefficients<T>,
    params: Params,
    nodes: usize,
    /// The mean spring rest length, or for a fabric without springs
    /// (every yarn a lone node) twice the yarn radius, the contacts'
    /// floor: the length the divergence speed and the re-seat step scale
    /// with.
    mean_rest: f64,
    /// Which segment pairs may touch under self-contact.
    rule: ContactRule,
    /// Changes whenever the parameters or contact liveness do; unique
    /// across models ([`Model::revision`]).
    revision: u64,
    /// The colliders as given, and as the substep uses them.
    colliders: Vec<Collider>,
    surfaces: Vec<Surface<T>>,
}

/// The source of [`Model::revision`]s.
static REVISIONS: AtomicU64 = AtomicU64::new(1);

fn next_revision() -> u64 {
    REVISIONS.fetch_add(1, Ordering::Relaxed)
}

impl<T: Real> Model<T> {
    /// Prepare `fabric` under `params`, with the fabric's own pins and every
    /// contact alive.
    ///
    /// # Errors
    /// [`BackendError::Params`] if the parameters do not validate;
    /// [`BackendError::Topology`] with `OutOfMemory` if a backend's arrays
    /// for this fabric would not fit the memory the system has free.
    pub fn new(fabric: &Fabric, params: &Params) -> Result<Self, BackendError> {
        params.validate()?;
        let scalar = size_of::<T>() as u64;
        let needed = fabric.node_count() as u64 * (SCALARS_PER_NODE * scalar + INDEX_BYTES_PER_NODE)
            + fabric.contacts().len() as u64 * (8 + SCALARS_PER_CONTACT * scalar);
        check_memory("the simulation's arrays (bytes)", needed, available_memory())?;
        Self::build(fabric, params)
    }

    /// [`Model::new`] without the memory check, for parameters already
    /// validated.
    fn build(fabric: &Fabric, params: &Params) -> Result<Self, BackendError> {
        let nodes = fabric.node_count();
        // A node starts at most one segment (to its next node) and centres
        // at most one joint, so both tables are indexed by node.
        let mut rest = vec![0.0; nodes];
        for s in fabric.springs() {
            rest[s.a as usize] = s.rest_length;
        }
        let mut joint_rest = vec![T::zero(); nodes];
        for t in fabric.triples() {
            joint_rest[t.b as usize] = T::of(t.rest_angle);
        }
        let mut model = Self {
            yarns: fabric.yarns().to_vec(),
            links: fabric.links(),
            segment_rest: rest.iter().map(|&l| T::of(l)).collect(),
            rule: ContactRule::new(fabric.yarn_radius(), fabric.yarns(), &rest),
            revision: next_revision(),
            colliders: Vec::new(),
            surfaces: Vec::new(),
            joint_rest,
            springs: fabric.springs().len(),
            joints: fabric.triples().len(),
            contacts: fabric.contacts().iter().map(|c| ContactRest { a: c.a, b: c.b, rest: T::of(c.rest) }).collect(),
            alive: vec![true; fabric.contacts().len()],
            reseating: Vec::new(),
            pins: Vec::new(),
            coeffs: Coefficients::new(params),
            params: *params,
            nodes,
            mean_rest: if fabric.springs().is_empty() {
                2.0 * fabric.yarn_radius()
            } else {
                fabric.springs().iter().map(|s| s.rest_length).sum::<f64>() / fabric.springs().len() as f64
            },
        };
        model.set_pins(fabric.pins())?;
        Ok(model)
    }

    /// This model in `f64`, to measure by: the rest values of `fabric`, the
    /// fabric it was built from, in `f64` (this model holds them rounded
    /// to `T`), with this model's parameters, pins, liveness and re-seated
    /// rest separations. Every backend's energy is evaluated against it
    /// ([`crate::step::energy`]), so all are measured by the same ruler.
    ///
    /// # Errors
    /// [`BackendError::LengthMismatch`] when `fabric` has another node,
    /// segment, joint or contact count than this model.
    pub fn in_f64(&self, fabric: &Fabric) -> Result<Model<f64>, BackendError> {
        check_len("fabric nodes", self.nodes, fabric.node_count())?;
        check_len("fabric yarns", self.yarns.len(), fabric.yarns().len())?;
        check_len("fabric springs", self.springs, fabric.springs().len())?;
        check_len("fabric joints", self.joints, fabric.triples().len())?;
        check_len("fabric contacts", self.contacts.len(), fabric.contacts().len())?;
        let mut model = Model::<f64>::build(fabric, &self.params)?;
        model.pins = self.pins.iter().map(|(node, target)| (*node, widen(target))).collect();
        model.alive.clone_from(&self.alive);
        model.set_colliders(&self.colliders)?;
        for r in &self.reseating {
            model.contacts[r.contact as usize].rest = self.contacts[r.contact as usize].rest.to_f64();
            model.reseating.push(Reseat { contact: r.contact, knit: r.knit.to_f64() });
        }
        Ok(model)
    }

    /// The fabric's yarns, in node order.
    pub fn yarns(&self) -> &[YarnSpan] {
        &self.yarns
    }

    /// Each node's neighbours along its yarn.
    pub fn links(&self) -> &[Link] {
        &self.links
    }

    /// Per node i: the rest length of the segment from i to its next node
    /// (`links()[i].next()`), zero where no segment leaves i.
    pub fn segment_rest(&self) -> &[T] {
        &self.segment_rest
    }

    /// Per node i: the rest turning angle θ0 of the joint centred on i
    /// (nodes `links()[i].prev()`, i, `links()[i].next()`), zero where i
    /// has no joint.
    pub fn joint_rest(&self) -> &[T] {
        &self.joint_rest
    }

    /// Every stretch spring `(a, b, ℓ0)`, from node a to the next node b
    /// of its yarn, in order of a.
    pub fn springs(&self) -> impl Iterator<Item = (usize, usize, T)> + '_ {
        self.links.iter().enumerate().filter_map(|(a, link)| Some((a, link.next()? as usize, self.segment_rest[a])))
    }

    /// Every bending joint `([a, b, c], θ0)`, centred on b with a before
    /// and c after it along its yarn, in order of b.
    pub fn joints(&self) -> impl Iterator<Item = ([usize; 3], T)> + '_ {
        self.links
            .iter()
            .enumerate()
            .filter_map(|(b, link)| Some(([link.prev()? as usize, b, link.next()? as usize], self.joint_rest[b])))
    }

    /// How many springs [`Model::springs`] lists.
    pub fn spring_count(&self) -> usize {
        self.springs
    }

    /// How many joints [`Model::joints`] lists.
    pub fn joint_count(&self) -> usize {
        self.joints
    }

    /// The persistent contacts, with their rest separations now (re-seated
    /// ones included).
    pub fn contacts(&self) -> &[ContactRest<T>] {
        &self.contacts
    }

    /// Liveness of each contact; dead contacts exert no force or friction.
    pub fn alive(&self) -> &[bool] {
        &self.alive
    }

    /// Pinned nodes and their targets.
    pub fn pins(&self) -> &[(u32, V3<T>)] {
        &self.pins
    }

    /// Per node, whether a pin holds it.
    pub fn pinned_nodes(&self) -> Vec<bool> {
        let mut pinned = vec![false; self.node_count()];
        self.pins.iter().for_each(|&(node, _)| pinned[node as usize] = true);
        pinned
    }

    /// The parameters in this model's precision, with the derived factors.
    pub fn coeffs(&self) -> &Coefficients<T> {
        &self.coeffs
    }

    /// Number of nodes.
    pub fn node_count(&self) -> usize {
        self.nodes
    }

    /// The speed beyond which a node has diverged: one that would cross
    /// [`DIVERGENCE_REACH`] mean segment lengths (twice the yarn radius in
    /// a fabric of lone nodes, which has no segment) in a single substep. No
    /// physical motion of the yarn comes near it; an explicit step that
    /// produces it has blown up.
    ///
    /// With self-contact on, a node that would move more than
    /// [`MAX_STEP_RADII`] yarn radii in one substep has diverged too, since
    /// it may have passed through yarn.
    pub fn divergence_speed(&self) -> f64 {
        let reach = DIVERGENCE_REACH * self.mean_rest.max(f64::MIN_POSITIVE);
        let reach = if self.self_contact() { reach.min(MAX_STEP_RADII * self.rule.radius()) } else { reach };
        reach / self.params.substep
    }

    /// With self-contact on, refuse positions `x` where two segments that
    /// may touch are closer than [`crate::self_contact::MIN_START_RADII`]
    /// yarn radii: yarn already deep in yarn, which the penalty would fling
    /// apart. Backends check the positions a fabric loads at and every
    /// state written.
    ///
    /// # Errors
    /// [`BackendError::Interpenetrating`] naming the closest such pair.
    pub fn check_apart(&self, x: &[V3<T>]) -> Result<(), BackendError> {
        if !self.self_contact() {
            return Ok(());
        }
        match crate::self_contact::closest_approach(self, x, crate::self_contact::MIN_START_RADII) {
            Some((distance, [a, b])) => Err(BackendError::Interpenetrating { a, b, distance }),
            None => Ok(()),
        }
    }

    /// Whether self-contact is on ([`Params::self_contact_stiffness`] > 0).
    pub fn self_contact(&self) -> bool {
        self.params.self_contact_stiffness > 0.0
    }

    /// Which segment pairs may touch under self-contact.
    pub fn contact_rule(&self) -> &ContactRule {
        &self.rule
    }

    /// A number that changes whenever the parameters or the contacts'
    /// liveness do, and that no other model shares: what a cached
    /// self-contact list ([`crate::self_contact::Candidates`]) checks to
    /// know it was built for this model as it is.
    pub fn revision(&self) -> u64 {
        self.revision
    }

    /// The parameters in force.
    pub fn params(&self) -> &Params {
        &self.params
    }

    /// Replace the parameters.
    ///
    /// # Errors
    /// [`BackendError::Params`] if they do not validate; the model is unchanged.
    pub fn set_params(&mut self, params: &Params) -> Result<(), BackendError> {
        params.validate()?;
        if !self.colliders.is_empty() {
            params.validate_with_colliders()?;
        }
        self.params = *params;
        self.coeffs = Coefficients::new(params);
        self.revision = next_revision();
        Ok(())
    }

    /// Replace the pins.
    ///
    /// # Errors
    /// [`BackendError::Topology`] for an out-of-range node or a non-finite
    /// target; the model is unchanged.
    pub fn set_pins(&mut self, pins: &[Pin]) -> Result<(), BackendError> {
        yarn_topology::validate_pins(pins, self.nodes)?;
        self.pins = pins.iter().map(|p| (p.node, cast(&p.target))).collect();
        Ok(())
    }

    /// Replace the colliders ([`crate::collider`]); none after load.
    ///
    /// # Errors
    /// [`BackendError::Collider`] naming the first bad collider, or
    /// [`BackendError::Params`] when the substep is too long for the
    /// collider stiffness ([`Params::validate_with_colliders`]); the model
    /// is unchanged.
    pub fn set_colliders(&mut self, colliders: &[Collider]) -> Result<(), BackendError> {
        if !colliders.is_empty() {
            self.params.validate_with_colliders()?;
        }
        self.surfaces = Surface::all(colliders)?;
        self.colliders = colliders.to_vec();
        Ok(())
    }

    /// The colliders as given.
    pub fn colliders(&self) -> &[Collider] {
        &self.colliders
    }

    /// The colliders as the substep uses them, validated and in `T`.
    pub fn surfaces(&self) -> &[Surface<T>] {
        &self.surfaces
    }

    /// Each node's alive contacts, for backends that gather per node: the
    /// contacts of node i are `entries[start[i]..start[i + 1]]`, each a
    /// (node, contact index) pair, in contact order. Dead contacts are left
    /// out, so a released contact costs nothing. `start` has one more entry
    /// than there are nodes.
    pub fn incidence(&self) -> (Vec<u32>, Vec<(u32, u32)>) {
        let live = || self.contacts.iter().enumerate().filter(|&(k, _)| self.alive[k]);
        let mut start = vec![0u32; self.nodes + 1];
        for (_, c) in live() {
            start[c.a as usize + 1] += 1;
            start[c.b as usize + 1] += 1;
        }
        for i in 0..self.nodes {
            start[i + 1] += start[i];
        }
        let mut fill = start.clone();
        let mut entries = vec![(0, 0); start[self.nodes] as usize];
        for (k, c) in live() {
            for node in [c.a, c.b] {
                entries[fill[node as usize] as usize] = (node, k as u32);
                fill[node as usize] += 1;
            }
        }
        (start, entries)
    }

    /// Whether [`Model::set_contacts_alive`] with `alive` needs the
    /// positions: some contact comes alive, or one is still closing.
    pub fn revives(&self, alive: &[bool]) -> bool {
        !self.reseating.is_empty() || alive.iter().zip(&self.alive).any(|(&now, &was)| now && !was)
    }

    /// Set the liveness of every contact, at `positions` (read only when
    /// [`Model::revives`] says so; otherwise they may be empty). A contact
    /// that comes alive away from its rest separation is re-seated
    /// at its length ([`Reseat`]), as is every alive contact still closing
    /// from an earlier revival; a contact that dies gets its knitted rest
    /// back.
    ///
    /// # Errors
    /// [`BackendError::LengthMismatch`] unless there is one flag per contact
    /// and, when they are read, one position per node; the model is
    /// unchanged then.
    pub fn set_contacts_alive(&mut self, alive: &[bool], positions: &[V3<T>]) -> Result<(), BackendError> {
        check_len("contact liveness flags", self.contacts.len(), alive.len())?;
        if alive != self.alive.as_slice() {
            self.revision = next_revision();
        }
        if !self.revives(alive) {
            self.alive.copy_from_slice(alive);
            return Ok(());
        }
        check_len("positions", self.nodes, positions.len())?;
        let mut knit: Vec<Option<T>> = vec![None; self.contacts.len()];
        for r in self.reseating.drain(..) {
            self.contacts[r.contact as usize].rest = r.knit;
            knit[r.contact as usize] = Some(r.knit);
        }
        for (k, c) in self.contacts.iter_mut().enumerate() {
            let revived = alive[k] && (!self.alive[k] || knit[k].is_some());
            let length = (positions[c.b as usize] - positions[c.a as usize]).norm();
            if revived && length != c.rest {
                self.reseating.push(Reseat { contact: k as u32, knit: c.rest });
                c.rest = length;
            }
        }
        self.alive.copy_from_slice(alive);
        Ok(())
    }

    /// The re-seated contacts still closing.
    pub fn reseating(&self) -> &[Reseat<T>] {
        &self.reseating
    }

    /// How far a re-seated rest separation closes in one substep:
    /// [`RESEAT_SPEED`] mean segment lengths per second, times h.
    pub fn reseat_step(&self) -> T {
        T::of(RESEAT_SPEED * self.mean_rest * self.params.substep)
    }

    /// Move every re-seated rest separation toward d_c by
    /// [`Model::reseat_step`], `substeps` times (rest ← max(d_c, rest −
    /// step) from above, min(d_c, rest + step) from below, as the backends
    /// do after each substep), dropping those that reach d_c. `changed(contact,
    /// rest)` hears each new rest separation. Returns how many of the
    /// substeps had one still closing: after them there is nothing to do.
    pub fn close_reseats(&mut self, substeps: u64, mut changed: impl FnMut(u32, T)) -> u64 {
        let step = self.reseat_step();
        let mut open = 0;
        while open < substeps && !self.reseating.is_empty() {
            open += 1;
            let contacts = &mut self.contacts;
            self.reseating.retain(|r| {
                let c = &mut contacts[r.contact as usize];
                c.rest = if c.rest > r.knit { r.knit.max(c.rest - step) } else { r.knit.min(c.rest + step) };
                changed(r.contact, c.rest);
                c.rest != r.knit
            });
        }
        open
    }

    /// The re-seated contacts and their rest separations now, to put back
    /// with [`Model::restore_reseats`] when an advance is undone.
    pub fn save_reseats(&self) -> Vec<(Reseat<T>, T)> {
        self.reseating.iter().map(|r| (*r, self.contacts[r.contact as usize].rest)).collect()
    }

    /// Put back what [`Model::save_reseats`] saved.
    pub fn restore_reseats(&mut self, saved: &[(Reseat<T>, T)]) {
        for &(r, rest) in saved {
            self.contacts[r.contact as usize].rest = rest;
        }
        self.reseating = saved.iter().map(|&(r, _)| r).collect();
    }
}

/// Positions and velocities of every node: the dynamic state.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct State<T: Real> {
    /// Node positions.
    pub positions: Vec<V3<T>>,
    /// Node velocities.
    pub velocities: Vec<V3<T>>,
}

impl<T: Real> State<T> {
    /// The fabric's assembled positions, at rest.
    pub fn at_rest(fabric: &Fabric) -> Self {
        Self {
            positions: fabric.positions().iter().map(cast).collect(),
            velocities: vec![V3::zeros(); fabric.node_count()],
        }
    }

    /// Number of nodes.
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    /// Whether the state holds no nodes.
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    /// The same state in another precision.
    pub fn cast<U: Real>(&self) -> State<U> {
        let convert = |v: &V3<T>| cast(&widen(v));
        State {
            positions: self.positions.iter().map(convert).collect(),
            velocities: self.velocities.iter().map(convert).collect(),
        }
    }

    /// The largest node speed.
    pub fn max_speed(&self) -> f64 {
        self.velocities.iter().map(|v| v.norm().to_f64()).fold(0.0, f64::max)
    }

    /// The first node whose position or velocity is not finite, or whose
    /// speed exceeds `limit`, with its speed (NaN or infinite for a
    /// non-finite one); `None` if every node is fine.
    pub fn first_diverged(&self, limit: f64) -> Option<(usize, f64)> {
        self.positions.iter().zip(&self.velocities).enumerate().find_map(|(i, (x, v))| {
            let speed = v.norm().to_f64();
            let finite = x.iter().all(|c| c.to_f64().is_finite());
            // A NaN speed fails the comparison, so it is not `within`.
            let within = speed <= limit;
            (!finite || !within).then_some((i, if finite { speed } else { f64::NAN }))
        })
    }

    /// Check that this state fits a model of `nodes` nodes.
    ///
    /// # Errors
    /// [`BackendError::LengthMismatch`] naming the wrong array.
    pub fn check_len(&self, nodes: usize) -> Result<(), BackendError> {
        check_len("positions", nodes, self.positions.len())?;
        check_len("velocities", nodes, self.velocities.len())
    }
}

fn check_len(what: &'static str, expected: usize, got: usize) -> Result<(), BackendError> {
    if expected == got { Ok(()) } else { Err(BackendError::LengthMismatch { what, expected, got }) }
}

#[cfg(test)]
mod tests {
    use yarn_topology::{Chart, Geometry};

    use super::*;

    /// A fabric of lone nodes has no segment to measure by: its divergence
    /// speed and re-seat step scale with twice the yarn radius instead of
    /// vanishing, so it can move at all; a fabric with segments keeps
    /// their mean.
    #[test]
    fn lone_nodes_measure_by_the_yarn_radius() {
        use yarn_topology::{FabricParts, Vec3, YarnSpan};
        let positions = vec![Vec3::zeros(), Vec3::new(3.0, 0.0, 0.0), Vec3::new(0.0, 3.0, 0.0)];
        let yarns = (0..3).map(|i| YarnSpan::open(i..i + 1)).collect();
        let lone =
            Fabric::from_parts(FabricParts { positions: positions.clone(), yarns, ..FabricParts::default() }).unwrap();
        let params = Params::default();
        let model = Model::<f64>::new(&lone, &params).unwrap();
        assert_eq!(model.spring_count(), 0);
        assert_eq!(model.divergence_speed(), DIVERGENCE_REACH * 1.8 / params.substep);
        assert_eq!(model.reseat_step(), RESEAT_SPEED * 1.8 * params.substep);
        let strand = Fabric::from_parts(FabricParts { positions, ..FabricParts::default() }).unwrap();
        let model = Model::<f64>::new(&strand, &params).unwrap();
        let mean = (3.0 + 18f64.sqrt()) / 2.0;
        assert!((model.divergence_speed() - DIVERGENCE_REACH * mean / params.substep).abs() < 1e-9);
    }

    /// Released contacts revived with one pulled 3 units apart and one
    /// pushed 0.2 units together: both are re-seated at their length and
    /// step back to d_c, one from above and one from below; the rest are
    /// revived as they were. A released contact forgets its re-seating.
    #[test]
    fn revived_contacts_are_reseated_and_close_back() {
        let fabric = Fabric::from_chart(&Chart::stockinette(4, 4).unwrap(), &Geometry::default()).unwrap();
        let mut model = Model::<f64>::new(&fabric, &Params::default()).unwrap();
        let knit: Vec<f64> = model.contacts.iter().map(|c| c.rest).collect();
        let n = knit.len();
        let mut positions: Vec<V3<f64>> = fabric.positions().iter().map(cast).collect();
        let (far, near) = (model.contacts[0], model.contacts[n - 1]);
        let unit = |c: ContactRest<f64>, x: &[V3<f64>]| (x[c.b as usize] - x[c.a as usize]).normalize();
        let (out, inward) = (unit(far, &positions) * 3.0, unit(near, &positions) * 0.2);
        positions[far.b as usize] += out;
        positions[near.b as usize] -= inward;
        let length = |c: ContactRest<f64>, x: &[V3<f64>]| (x[c.b as usize] - x[c.a as usize]).norm();

        assert!(!model.revives(&vec![true; n]), "nothing was released");
        model.set_contacts_alive(&vec![false; n], &[]).unwrap();
        assert!(model.revives(&vec![true; n]));
        assert!(model.set_contacts_alive(&vec![true; n], &positions[1..]).is_err(), "short positions accepted");
        model.set_contacts_alive(&vec![true; n], &positions).unwrap();
        let reseated: Vec<u32> = model.reseating().iter().map(|r| r.contact).collect();
        assert!(reseated.contains(&0) && reseated.contains(&(n as u32 - 1)), "{reseated:?}");
        assert!((model.contacts[0].rest - length(far, &positions)).abs() < 1e-12);
        assert!((model.contacts[n - 1].rest - length(near, &positions)).abs() < 1e-12);

        let step = model.reseat_step();
        let (open, mut heard) = (model.reseating().len(), 0);
        assert_eq!(model.close_reseats(1, |_, _| heard += 1), 1);
        assert_eq!(heard, open, "not every re-seated contact was reported");
        assert!((model.contacts[n - 1].rest - (length(near, &positions) + step)).abs() < 1e-12);
        assert!((model.contacts[0].rest - (length(far, &positions) - step)).abs() < 1e-12);
        let needed = ((length(far, &positions) - knit[0]) / step).ceil() as u64;
        let open = model.close_reseats(10 * needed, |_, _| ());
        assert!(open + 1 >= needed - 1 && open < needed + 1, "closed in {open} more substeps, expected about {needed}");
        assert!(model.reseating().is_empty());
        assert_eq!(model.contacts.iter().map(|c| c.rest).collect::<Vec<_>>(), knit, "not back at d_c");

        model.set_contacts_alive(&vec![false; n], &[]).unwrap();
        model.set_contacts_alive(&vec![true; n], &positions).unwrap();
        let saved = model.save_reseats();
        model.close_reseats(3, |_, _| ());
        model.restore_reseats(&saved);
        assert!((model.contacts[0].rest - length(far, &positions)).abs() < 1e-12, "restore did not put it back");
        let mut killed = vec![true; n];
        killed[0] = false;
        model.set_contacts_alive(&killed, &positions).unwrap();
        assert_eq!(model.contacts[0].rest, knit[0], "a released contact kept its re-seated rest");
        assert!(model.reseating().iter().all(|r| r.contact != 0));
    }
}
