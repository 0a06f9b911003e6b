//! The reference substep (SPEC §4), the force accumulation and the energy,
//! written as plain serial loops in element order. This is the function
//! every backend must compute; `yarn_backend_cpu::Reference` runs it as is,
//! and the conformance suite holds the fast backends to it.

use crate::collider::Surface;
use crate::self_contact::{Candidates, find_pairs};
use crate::terms::{
    Closest, bend_energy, bend_forces, gravity_energy, gravity_force, push_depth, self_contact_energy,
    self_contact_forces, spring_energy, spring_force,
};
use crate::{Coefficients, Model, Real, State, V3};

/// The skin, in yarn radii, of a self-contact search made for one
/// evaluation ([`accumulate_forces`], [`potential`]): a margin over 2r for
/// the rounding of distances in the model's precision, so no pair that the
/// force counts is missed.
const FRESH_SKIN_RADII: f64 = 1e-3;

/// The node at the far end of the segment that node `a` starts (`a` itself
/// where none leaves it, which a candidate pair never names).
pub fn segment_end<T: Real>(model: &Model<T>, a: usize) -> usize {
    model.links()[a].next().map_or(a, |n| n as usize)
}

/// The segment pairs within reach at `x` for one evaluation: empty with
/// self-contact off.
fn touching<T: Real>(model: &Model<T>, x: &[V3<T>]) -> Vec<[u32; 2]> {
    let mut pairs = Vec::new();
    if model.self_contact() {
        find_pairs(model, x, FRESH_SKIN_RADII * model.contact_rule().radius(), &mut pairs);
    }
    pairs
}

/// Energy of a state, split by term, in `f64`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Energy {
    /// Σ ½ k_s (ℓ − ℓ0)².
    pub stretch: f64,
    /// Σ ½ k_b (θ − κθ0)².
    pub bend: f64,
    /// Σ ½ k_c (d_c − ℓ)² over alive contacts.
    pub contact: f64,
    /// Σ of the self-contact energy ([`crate::terms::self_contact_energy`])
    /// over segment pairs in self-contact.
    pub self_contact: f64,
    /// Σ ½ k_col δ² over nodes pressing into a collider.
    pub collider: f64,
    /// Σ m g y.
    pub gravity: f64,
    /// Σ ½ m |v|².
    pub kinetic: f64,
}

impl Energy {
    /// The potential U (SPEC §3).
    pub fn potential(&self) -> f64 {
        self.stretch + self.bend + self.contact + self.self_contact + self.collider + self.gravity
    }

    /// Potential plus kinetic energy.
    pub fn total(&self) -> f64 {
        self.potential() + self.kinetic
    }
}

/// Buffers the substep reuses, so that stepping allocates nothing once warm.
#[derive(Debug, Clone, Default)]
pub struct Scratch<T: Real> {
    /// Force per node from the last accumulation.
    pub forces: Vec<V3<T>>,
    /// Friction velocity correction per node from the persistent contacts
    /// (SPEC §4 step 3).
    pub friction: Vec<V3<T>>,
    /// Per node: the sum of its self-contacts' friction corrections, in
    /// pair order ([`self_contact_friction`]).
    pub self_friction: Vec<V3<T>>,
    /// Per node: how many self-contact pairs push it ([`pushing_pairs`]).
    pub self_pushing: Vec<u32>,
    /// The self-contact candidate list, kept between substeps.
    pub candidates: Candidates<T>,
}

/// F = −∇U(x) over alive contacts (SPEC §4 step 1), written into `forces`,
/// which is resized to the node count. Springs and joints follow each
/// yarn ([`Model::springs`], [`Model::joints`]), wrapping around closed
/// ones, and never join two. With self-contact on, every segment pair
/// within reach pushes apart ([`crate::self_contact`]); every node pressing
/// into a collider is pushed out ([`crate::collider`]).
pub fn accumulate_forces<T: Real>(model: &Model<T>, x: &[V3<T>], forces: &mut Vec<V3<T>>) {
    accumulate_forces_over(model, x, &touching(model, x), forces);
}

/// [`accumulate_forces`] with the self-contact candidate pairs given: a
/// list that holds every pair within reach (more add nothing).
fn accumulate_forces_over<T: Real>(model: &Model<T>, x: &[V3<T>], pairs: &[[u32; 2]], forces: &mut Vec<V3<T>>) {
    let c = model.coeffs();
    forces.clear();
    forces.resize(x.len(), gravity_force(c.mass, c.gravity));
    for (a, b, rest) in model.springs() {
        let f = spring_force(&x[a], &x[b], rest, c.stretch);
        forces[a] += f;
        forces[b] -= f;
    }
    for ([a, b, c_], theta0) in model.joints() {
        if let Some([fa, fb, fc]) = bend_forces(&x[a], &x[b], &x[c_], c.rest_curl * theta0, c.bend) {
            forces[a] += fa;
            forces[b] += fb;
            forces[c_] += fc;
        }
    }
    for (contact, _) in model.contacts().iter().zip(model.alive()).filter(|(_, alive)| **alive) {
        let (a, b) = (contact.a as usize, contact.b as usize);
        let f = spring_force(&x[a], &x[b], contact.rest, c.contact);
        forces[a] += f;
        forces[b] -= f;
    }
    let reach = T::of(2.0 * model.contact_rule().radius());
    for &[a, b] in pairs {
        let [a0, b0] = [a as usize, b as usize];
        let (a1, b1) = (segment_end(model, a0), segment_end(model, b0));
        if let Some(f) = self_contact_forces(&x[a0], &x[a1], &x[b0], &x[b1], reach, c.self_contact) {
            forces[a0] += f[0];
            forces[a1] += f[1];
            forces[b0] += f[2];
            forces[b1] += f[3];
        }
    }
    let radius = T::of(model.contact_rule().radius());
    for surface in model.surfaces() {
        for (f, x) in forces.iter_mut().zip(x) {
            if let Some(push) = surface.force(x, radius, c.collider) {
                *f += push;
            }
        }
    }
}

/// The energy of `state`, by term, evaluated in `T` and reported in `f64`.
pub fn energy<T: Real>(model: &Model<T>, state: &State<T>) -> Energy {
    let c = model.coeffs();
    let sum = |values: &mut dyn Iterator<Item = T>| values.map(Real::to_f64).sum::<f64>();
    Energy {
        kinetic: 0.5 * c.mass.to_f64() * sum(&mut state.velocities.iter().map(|v| v.norm_squared())),
        ..potential(model, &state.positions)
    }
}

/// The potential terms of [`energy`] at positions `x` (kinetic zero).
pub fn potential<T: Real>(model: &Model<T>, x: &[V3<T>]) -> Energy {
    let c = model.coeffs();
    let sum = |values: &mut dyn Iterator<Item = T>| values.map(Real::to_f64).sum::<f64>();
    Energy {
        stretch: sum(&mut model.springs().map(|(a, b, rest)| spring_energy(&x[a], &x[b], rest, c.stretch))),
        bend: sum(&mut model
            .joints()
            .map(|([a, b, j], theta0)| bend_energy(&x[a], &x[b], &x[j], c.rest_curl * theta0, c.bend))),
        contact: sum(&mut model
            .contacts()
            .iter()
            .zip(model.alive())
            .filter(|(_, alive)| **alive)
            .map(|(k, _)| spring_energy(&x[k.a as usize], &x[k.b as usize], k.rest, c.contact))),
        gravity: sum(&mut x.iter().map(|p| gravity_energy(p, c.mass, c.gravity))),
        ..touch_potential(model, x)
    }
}

/// The potential of what touches the yarn besides its own chain and
/// contacts at positions `x`: [`potential`]'s `self_contact` and
/// `collider`, every other term zero.
pub fn touch_potential<T: Real>(model: &Model<T>, x: &[V3<T>]) -> Energy {
    touch_potential_over(model, x, &touching(model, x))
}

/// [`accumulate_forces`] into `forces` and [`touch_potential`] at `x`,
/// from one search for the pairs within reach.
pub fn forces_and_touch_potential<T: Real>(model: &Model<T>, x: &[V3<T>], forces: &mut Vec<V3<T>>) -> Energy {
    let pairs = touching(model, x);
    accumulate_forces_over(model, x, &pairs, forces);
    touch_potential_over(model, x, &pairs)
}

/// [`touch_potential`] with the self-contact candidate pairs given: a list
/// that holds every pair within reach (more add nothing).
fn touch_potential_over<T: Real>(model: &Model<T>, x: &[V3<T>], pairs: &[[u32; 2]]) -> Energy {
    let c = model.coeffs();
    let sum = |values: &mut dyn Iterator<Item = T>| values.map(Real::to_f64).sum::<f64>();
    Energy {
        self_contact: {
            let reach = T::of(2.0 * model.contact_rule().radius());
            sum(&mut pairs.iter().map(|&[a, b]| {
                let (a, b) = (a as usize, b as usize);
                self_contact_energy(
                    &x[a],
                    &x[segment_end(model, a)],
                    &x[b],
                    &x[segment_end(model, b)],
                    reach,
                    c.self_contact,
                )
            }))
        },
        collider: {
            let radius = T::of(model.contact_rule().radius());
            sum(&mut model.surfaces().iter().flat_map(|s| x.iter().map(move |p| s.energy(p, radius, c.collider))))
        },
        ..Energy::default()
    }
}

/// Friction velocity change of one compressed contact (SPEC §4 step 3):
/// the change `Δw` to the relative velocity w = v_b − v_a, or `None` when
/// the contact is not compressed or has no tangential slip. Node a gets
/// −Δw/2 and node b +Δw/2. With [`crate::Params::friction_in_tension`] a
/// stretched contact has friction too, its normal impulse sized by
/// |rest − length|.
#[inline]
pub fn friction_change<T: Real>(
    xa: &V3<T>,
    xb: &V3<T>,
    va: &V3<T>,
    vb: &V3<T>,
    rest: T,
    model: &Model<T>,
) -> Option<V3<T>> {
    let c = model.coeffs();
    let d = xb - xa;
    let length = d.norm();
    let strained = length < rest || (model.params().friction_in_tension && length > rest);
    if !(strained && length > T::zero()) {
        return None;
    }
    let n = d / length;
    let w = vb - va;
    let wt = w - n * w.dot(&n);
    let slip = wt.norm();
    if slip <= T::zero() {
        return None;
    }
    let dv_normal = c.friction_impulse * (rest - length).abs();
    let retention = (T::one() - c.friction * dv_normal / slip).max(T::zero());
    Some(wt * (retention - T::one()))
}

/// Friction velocity changes of one self-contact pair, segments p0p1 and
/// q0q1 (SPEC §4 step 3 at their closest points): the change to each
/// node's velocity, or `None` when they are not within `reach` or do not
/// slip.
///
/// With closest points at (s, t), the nodes' shares in the contact are
/// (1 − s, s, 1 − t, t), and the slip is the tangential part of
/// w = v_q(t) − v_p(s). An impulse j on the pair changes w by j W, with
/// W m = (1 − s)² + s² + (1 − t)² + t² the pair's inverse effective mass
/// (2 for two nodes, as a persistent contact has).
///
/// The impulse that would stop the slip, −w_t / W, is shared: divided by
/// `sharing`, the most pushing pairs at any of the pair's four nodes
/// ([`pushing_pairs`]). Coulomb's limit then holds the pair's impulse to
/// |j| ≤ μ h N, with N = k_sc g(2r − d) the pair's own push
/// ([`crate::terms::push_depth`]), and each node gets its share of it.
/// So the changes of every pair stay equal and opposite, and a node's sum
/// over its pairs is never longer than its longest pair's slip: many
/// contacts slipping the same way at one node cannot reverse its slip,
/// and momentum is kept. Where they all slide, the node feels every
/// pair's limit, not one pair's shared out. (Dividing the limit by
/// `sharing` too, the rule before, let a free patch's roll creep on 1.4 to
/// 2.4 times as fast; a cap on each node's sum, before that, gave a node
/// less than its partners got back, and a free patch drifted.)
#[inline]
pub fn self_contact_friction<T: Real>(
    x: [&V3<T>; 4],
    v: [&V3<T>; 4],
    reach: T,
    sharing: T,
    c: &Coefficients<T>,
) -> Option<[V3<T>; 4]> {
    self_contact_friction_at(&Closest::of(x[0], x[1], x[2], x[3]), v, reach, sharing, c)
}

/// [`self_contact_friction`] from the pair's closest points at x.
#[inline]
pub fn self_contact_friction_at<T: Real>(
    closest: &Closest<T>,
    v: [&V3<T>; 4],
    reach: T,
    sharing: T,
    c: &Coefficients<T>,
) -> Option<[V3<T>; 4]> {
    let Closest { gap, distance: d, s, t } = *closest;
    if !closest.within(reach) {
        return None;
    }
    let n = gap / d;
    let one = T::one();
    let shares = [one - s, s, one - t, t];
    let w = (v[2] * shares[2] + v[3] * shares[3]) - (v[0] * shares[0] + v[1] * shares[1]);
    let wt = w - n * w.dot(&n);
    let slip = wt.norm();
    if slip <= T::zero() {
        return None;
    }
    let inverse_mass = shares.iter().fold(T::zero(), |sum, &share| sum + share * share);
    // The limit on the shared impulse, times `sharing`: the pair's own.
    let cut = c.friction * c.self_contact_impulse * push_depth(reach - d, reach) * inverse_mass * sharing;
    let retention = (one - cut / slip).max(T::zero());
    let j = wt * ((retention - one) / (inverse_mass * sharing));
    Some([-(j * shares[0]), -(j * shares[1]), j * shares[2], j * shares[3]])
}

/// Per node, how many of the self-contact pairs `pairs` (segments by their
/// first nodes) push it at `x`: those within reach, counted on each of
/// their four nodes, into `pushing`.
pub fn pushing_pairs<T: Real>(model: &Model<T>, x: &[V3<T>], pairs: &[[u32; 2]], pushing: &mut Vec<u32>) {
    let reach = T::of(2.0 * model.contact_rule().radius());
    pushing.clear();
    pushing.resize(x.len(), 0);
    for &[a, b] in pairs {
        let ends = [a as usize, segment_end(model, a as usize), b as usize, segment_end(model, b as usize)];
        if Closest::of(&x[ends[0]], &x[ends[1]], &x[ends[2]], &x[ends[3]]).within(reach) {
            for i in ends {
                pushing[i] += 1;
            }
        }
    }
}

/// The `sharing` of [`self_contact_friction`] for a pair whose four nodes
/// are pushed by `pushing` pairs each ([`pushing_pairs`]): the most of
/// them, and at least 1.
#[inline]
pub fn pair_sharing<T: Real>(pushing: [u32; 4]) -> T {
    T::of(f64::from(pushing.into_iter().fold(1, u32::max)))
}

/// The friction change of every collider at a node at `x` with velocity
/// `v` ([`Surface::friction_change`]), summed in collider order.
#[inline]
pub fn collider_friction<T: Real>(surfaces: &[Surface<T>], x: &V3<T>, v: &V3<T>, radius: T, impulse: T) -> V3<T> {
    surfaces.iter().fold(V3::zeros(), |dv, s| s.friction_change(x, v, radius, impulse).map_or(dv, |change| dv + change))
}

/// One substep (SPEC §4), in place:
/// 1. F = −∇U(x) over alive contacts, and with self-contact on over the
///    pairs of the candidate list in `scratch`, refreshed first;
/// 2. v* = (v + hF/m) / (1 + βh);
/// 3. Jacobi friction: every compressed alive contact's correction, every
///    self-contact's ([`self_contact_friction`], shared among the pairs
///    at its nodes) and
///    every collider's, computed from v* and x, then applied in that
///    order;
/// 4. x' = x + h v**;
/// 5. pinned nodes set to their targets with zero velocity.
pub fn substep<T: Real>(model: &Model<T>, state: &mut State<T>, scratch: &mut Scratch<T>) {
    let c = model.coeffs();
    let pairs = if model.self_contact() {
        scratch.candidates.refresh(model, &state.positions);
        scratch.candidates.pairs()
    } else {
        &[]
    };
    accumulate_forces_over(model, &state.positions, pairs, &mut scratch.forces);
    for (v, f) in state.velocities.iter_mut().zip(&scratch.forces) {
        *v = (*v + f * c.h_over_m) * c.damping_factor;
    }
    let (x, v) = (&state.positions, &mut state.velocities);
    let surfaces = model.surfaces();
    if c.friction > T::zero() || !surfaces.is_empty() {
        let nodes = x.len();
        scratch.friction.clear();
        scratch.friction.resize(nodes, V3::zeros());
        scratch.self_friction.clear();
        scratch.self_friction.resize(nodes, V3::zeros());
        if c.friction > T::zero() {
            for (k, _) in model.contacts().iter().zip(model.alive()).filter(|(_, alive)| **alive) {
                let (a, b) = (k.a as usize, k.b as usize);
                if let Some(dw) = friction_change(&x[a], &x[b], &v[a], &v[b], k.rest, model) {
                    let half = dw * T::of(0.5);
                    scratch.friction[a] -= half;
                    scratch.friction[b] += half;
                }
            }
            let reach = T::of(2.0 * model.contact_rule().radius());
            pushing_pairs(model, x, pairs, &mut scratch.self_pushing);
            for &[a, b] in pairs {
                let ends = [a as usize, segment_end(model, a as usize), b as usize, segment_end(model, b as usize)];
                let sharing = pair_sharing(ends.map(|i| scratch.self_pushing[i]));
                if let Some(dv) = self_contact_friction(ends.map(|i| &x[i]), ends.map(|i| &v[i]), reach, sharing, c) {
                    for (i, dv) in ends.into_iter().zip(dv) {
                        scratch.self_friction[i] += dv;
                    }
                }
            }
        }
        let radius = T::of(model.contact_rule().radius());
        for (i, v) in v.iter_mut().enumerate() {
            let v_star = *v;
            *v += scratch.friction[i];
            *v += scratch.self_friction[i];
            if !surfaces.is_empty() {
                *v += collider_friction(surfaces, &x[i], &v_star, radius, c.collider_impulse);
            }
        }
    }
    for (x, v) in state.positions.iter_mut().zip(&state.velocities) {
        *x += v * c.h;
    }
    for &(node, target) in model.pins() {
        state.positions[node as usize] = target;
        state.velocities[node as usize] = V3::zeros();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Params;
    use crate::terms::closest_gap;
    use proptest::prelude::*;
    use std::sync::atomic::{AtomicU64, Ordering};
    use yarn_topology::{Chart, Fabric, FabricParts, Geometry};

    fn patch(w: usize, h: usize) -> Fabric {
        Fabric::from_chart(&Chart::stockinette(w, h).unwrap(), &Geometry::default()).unwrap()
    }

    /// Parameters with every potential term off except the ones named.
    fn only(stretch: bool, bend: bool, contact: bool, gravity: bool) -> Params {
        let p = Params::default();
        Params {
            stretch_stiffness: if stretch { p.stretch_stiffness } else { 1e-9 },
            bend_stiffness: if bend { p.bend_stiffness } else { 0.0 },
            contact_stiffness: if contact { p.contact_stiffness } else { 0.0 },
            gravity: if gravity { 9.81 } else { 0.0 },
            ..p
        }
    }

    /// A term of U that a finite-difference case tests, or all of them.
    #[derive(Debug, Clone, Copy, PartialEq, Eq)]
    enum Term {
        Stretch,
        Bend,
        Contact,
        Gravity,
        All,
    }

    impl Term {
        /// Parameters with every potential term off except this one (or
        /// with all on).
        fn params(self) -> Params {
            match self {
                Term::Stretch => only(true, false, false, false),
                Term::Bend => only(false, true, false, false),
                Term::Contact => only(false, false, true, false),
                Term::Gravity => only(false, false, false, true),
                Term::All => Params { gravity: 9.81, ..Params::default() },
            }
        }

        /// The single terms this case must carry.
        fn carries(self) -> &'static [Term] {
            match self {
                Term::All => &[Term::Stretch, Term::Bend, Term::Contact, Term::Gravity],
                Term::Stretch => &[Term::Stretch],
                Term::Bend => &[Term::Bend],
                Term::Contact => &[Term::Contact],
                Term::Gravity => &[Term::Gravity],
            }
        }
    }

    /// A finite-difference case: the term, the patch's width and height,
    /// a seed for its perturbation and contact liveness, and the
    /// perturbation's amplitude. A case with contacts is at least two rows
    /// tall, since a one-row patch has none.
    fn gradient_case() -> impl Strategy<Value = (Term, usize, usize, u64, f64)> {
        prop_oneof![Just(Term::Stretch), Just(Term::Bend), Just(Term::Contact), Just(Term::Gravity), Just(Term::All)]
            .prop_flat_map(|term| {
                let rows = if term.carries().contains(&Term::Contact) { 2usize..4 } else { 1usize..4 };
                (Just(term), 1usize..4, rows, any::<u64>(), 0.05..0.6f64)
            })
    }

    /// Whether `term` contributes at `x`: its energy is non-zero and, for
    /// bending, some joint is bent past [`crate::terms::MIN_SIN_THETA`]
    /// (a straight joint stores energy but exerts no force); for contacts,
    /// some contact is alive. Returns what it saw, for the message.
    fn present(term: Term, model: &Model<f64>, x: &[V3<f64>]) -> (bool, String) {
        let u = potential(model, x);
        let c = model.coeffs();
        let bent =
            model.joints().filter(|([a, b, j], _)| bend_forces(&x[*a], &x[*b], &x[*j], 0.0, c.bend).is_some()).count();
        let live = model.alive().iter().filter(|&&a| a).count();
        let seen = format!("{u:?}, {bent} bent joints, {live} live contacts");
        let here = match term {
            Term::Stretch => u.stretch > 0.0,
            Term::Bend => u.bend > 0.0 && bent > 0,
            Term::Contact => u.contact > 0.0 && live > 0,
            Term::Gravity => u.gravity != 0.0,
            Term::All => unreachable!("`All` is checked term by term"),
        };
        (here, seen)
    }

    /// Finite differences of U on every degree of freedom against the
    /// accumulated force, with ε = eps_machine^(1/3) × the patch scale.
    /// The central difference is Richardson-extrapolated from steps ε and
    /// ε/2, which cancels its ε² error: near a tight fold or a short
    /// segment that error alone (3.98e-4 on a 3x2 bend case, falling as
    /// ε² to 1.0e-7 at ε/64) exceeded the tolerance, where the force was
    /// right.
    #[allow(clippy::needless_range_loop, reason = "node and axis indices name the degree of freedom")]
    fn check_gradient(model: &Model<f64>, state: &State<f64>) {
        let mut forces = Vec::new();
        accumulate_forces(model, &state.positions, &mut forces);
        let scale = state.positions.iter().map(|p| p.amax()).fold(1.0, f64::max);
        let eps = f64::EPSILON.cbrt() * scale.min(10.0);
        let mut probe = state.clone();
        let force_scale = forces.iter().map(|f| f.amax()).fold(1.0, f64::max);
        for i in 0..state.len() {
            for k in 0..3 {
                let x0 = probe.positions[i][k];
                let mut central = |h: f64| {
                    probe.positions[i][k] = x0 + h;
                    let up = energy(model, &probe).potential();
                    probe.positions[i][k] = x0 - h;
                    let down = energy(model, &probe).potential();
                    probe.positions[i][k] = x0;
                    -(up - down) / (2.0 * h)
                };
                let numeric = (4.0 * central(eps / 2.0) - central(eps)) / 3.0;
                let err = (forces[i][k] - numeric).abs();
                assert!(
                    err <= 2e-5 * force_scale,
                    "node {i} axis {k}: force {} vs -dU/dx {numeric} (err {err:e})",
                    forces[i][k]
                );
            }
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(24))]

        /// Every term, alone and together, on every degree of freedom of a
        /// randomly perturbed patch with live and dead contacts. Each case
        /// first checks that it carries the term it tests, so a generator
        /// that stops producing one (a contact case on a one-row patch, say)
        /// fails instead of passing on nothing.
        #[test]
        fn forces_are_minus_gradient_on_perturbed_patches((term, w, h, seed, amplitude) in gradient_case()) {
            let fabric = patch(w, h);
            let mut rng = seed;
            let mut next = || { rng ^= rng << 13; rng ^= rng >> 7; rng ^= rng << 17; (rng >> 11) as f64 / (1u64 << 53) as f64 - 0.5 };
            let mut state = State::<f64>::at_rest(&fabric);
            for p in &mut state.positions {
                *p += V3::new(next(), next(), next()) * (2.0 * amplitude);
            }
            let contacts = fabric.contacts().len();
            let mut alive: Vec<bool> = (0..contacts).map(|_| next() > -0.3).collect();
            // At least one live contact, and one dead where there are two.
            if contacts > 0 {
                let live = ((next() + 0.5) * contacts as f64) as usize % contacts;
                alive[live] = true;
                if contacts > 1 {
                    alive[(live + 1) % contacts] = false;
                }
            }
            let mut model = Model::<f64>::new(&fabric, &term.params()).unwrap();
            model.set_contacts_alive(&alive, &state.positions).unwrap();
            for &single in term.carries() {
                let (here, seen) = present(single, &model, &state.positions);
                prop_assert!(here, "the {term:?} case on a {w}x{h} patch carries no {single:?} term: {seen}");
            }
            check_gradient(&model, &state);
        }
    }

    /// A fabric of several yarns laid as random walks (steps 0.4 to 1.5
    /// long, so no segment is zero), one yarn after another, each open or
    /// closed as `yarns` says (closed only from 3 nodes), with contacts
    /// between random nodes of any yarns, each pair once.
    fn yarns_fabric(yarns: &[(usize, bool)], seed: u64) -> Fabric {
        let mut rng = seed | 1;
        let mut next = move || {
            rng ^= rng << 13;
            rng ^= rng >> 7;
            rng ^= rng << 17;
            (rng >> 11) as f64 / (1u64 << 53) as f64
        };
        let (mut positions, mut spans) = (Vec::new(), Vec::new());
        for &(len, closed) in yarns {
            let start = positions.len() as u32;
            let mut at = yarn_topology::Vec3::new(3.0 * next(), 3.0 * next(), next());
            for _ in 0..len {
                positions.push(at);
                let step = yarn_topology::Vec3::new(next() - 0.5, next() - 0.5, next() - 0.5);
                at += step.normalize() * (0.4 + 1.1 * next());
            }
            let end = positions.len() as u32;
            spans.push(yarn_topology::YarnSpan { start, end, closed: closed && len >= 3 });
        }
        let n = positions.len();
        let mut between = std::collections::HashSet::new();
        let contacts = (0..n / 2)
            .map(|_| [(next() * n as f64) as u32 % n as u32, (next() * n as f64) as u32 % n as u32])
            .filter(|&[a, b]| a != b && between.insert((a.min(b), a.max(b))))
            .collect();
        Fabric::from_parts(FabricParts { positions, yarns: spans, contacts, ..FabricParts::default() }).unwrap()
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(24))]

        /// Every term together on every degree of freedom of random fabrics
        /// of several yarns, open and closed and at least one closed, each
        /// perturbed: the wrap-around springs and joints of a closed yarn
        /// are exact gradients like the rest, and no term joins two yarns
        /// (a spring across a break would be a force without an energy).
        #[test]
        fn forces_are_minus_gradient_on_several_yarns(
            yarns in proptest::collection::vec((1usize..9, any::<bool>()), 1..5),
            ring in 3usize..9,
            seed in any::<u64>(),
        ) {
            let mut yarns = yarns;
            yarns.push((ring, true));
            let fabric = yarns_fabric(&yarns, seed);
            prop_assert!(fabric.yarns().iter().any(|y| y.closed));
            let model = Model::<f64>::new(&fabric, &Term::All.params()).unwrap();
            check_gradient(&model, &State::<f64>::at_rest(&fabric));
            let mut state = State::<f64>::at_rest(&fabric);
            let mut rng = seed;
            let mut next = || {
                rng = rng.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
                (rng >> 11) as f64 / (1u64 << 53) as f64 - 0.5
            };
            for p in &mut state.positions {
                *p += V3::new(next(), next(), next()) * 0.3;
            }
            check_gradient(&model, &state);
        }
    }

    /// Two open yarns, the second starting 0.5 from where the first ends:
    /// a spring across the break would pull the two ends together. Each
    /// yarn's nodes feel exactly, bit for bit, the forces the yarn alone
    /// gives them, and so do the energies.
    #[test]
    fn an_isolated_yarn_end_feels_only_its_own_yarn() {
        let arc = |from: f64, n: usize| -> Vec<yarn_topology::Vec3> {
            (0..n).map(|i| yarn_topology::Vec3::new(from + i as f64, (0.3 * i as f64).sin(), 0.1 * i as f64)).collect()
        };
        let (a, b) = (arc(0.0, 10), arc(9.5, 12));
        let both: Vec<_> = a.iter().chain(&b).copied().collect();
        let spans = vec![yarn_topology::YarnSpan::open(0..10), yarn_topology::YarnSpan::open(10..22)];
        let fabric = |positions: Vec<yarn_topology::Vec3>, yarns| {
            Fabric::from_parts(FabricParts { positions, yarns, ..FabricParts::default() }).unwrap()
        };
        let (two, alone_a, alone_b) = (fabric(both, spans), fabric(a, Vec::new()), fabric(b, Vec::new()));
        let params = Params { gravity: 9.81, ..Params::default() };
        let forces = |fabric: &Fabric| {
            let model = Model::<f64>::new(fabric, &params).unwrap();
            let mut state = State::<f64>::at_rest(fabric);
            // Pull every node off its rest so every element is loaded, by
            // where it is (not its index, which differs between fabrics).
            for p in &mut state.positions {
                *p += V3::new(0.05 * (3.0 * p.x).cos(), 0.07, -0.03 * (2.0 * p.x).sin());
            }
            let mut f = Vec::new();
            accumulate_forces(&model, &state.positions, &mut f);
            (f, potential(&model, &state.positions))
        };
        let (f_two, u_two) = forces(&two);
        let (f_a, u_a) = forces(&alone_a);
        let (f_b, u_b) = forces(&alone_b);
        assert_eq!(&f_two[..10], f_a.as_slice(), "the first yarn's nodes");
        assert_eq!(&f_two[10..], f_b.as_slice(), "the second yarn's nodes");
        assert!(f_two[9].norm() > 1.0 && f_two[10].norm() > 1.0, "the ends must be loaded to mean anything");
        assert_eq!(two.springs().len(), 9 + 11);
        assert!((u_two.stretch - (u_a.stretch + u_b.stretch)).abs() <= 1e-12 * u_two.stretch);
        assert!((u_two.bend - (u_a.bend + u_b.bend)).abs() <= 1e-12 * u_two.bend);
    }

    /// A ring of 24 nodes as one closed yarn: at its rest shape with
    /// κ = 1 no node feels a force, the closing segment's spring and the
    /// two joints that wrap around included. Drawn apart at the closing
    /// segment, the closed ring pulls its last node toward its first where
    /// the same ring laid open does not.
    #[test]
    fn a_closed_ring_at_its_rest_shape_has_zero_force() {
        let n = 24;
        let positions: Vec<yarn_topology::Vec3> = (0..n)
            .map(|i| {
                let t = 2.0 * std::f64::consts::PI * i as f64 / n as f64;
                V3::new(5.0 * t.cos(), 5.0 * t.sin(), 0.3 * (3.0 * t).sin())
            })
            .collect();
        let ring = |closed: bool| {
            let yarns = vec![yarn_topology::YarnSpan { start: 0, end: n as u32, closed }];
            Fabric::from_parts(FabricParts { positions: positions.clone(), yarns, ..FabricParts::default() }).unwrap()
        };
        let (closed, open) = (ring(true), ring(false));
        assert_eq!((closed.springs().len(), closed.triples().len()), (n, n));
        let params = Params { rest_curl: 1.0, ..Params::default() };
        let forces = |fabric: &Fabric, x: &[V3<f64>]| {
            let mut f = Vec::new();
            accumulate_forces(&Model::<f64>::new(fabric, &params).unwrap(), x, &mut f);
            f
        };
        let rest = State::<f64>::at_rest(&closed).positions;
        let largest = forces(&closed, &rest).iter().map(|f| f.norm()).fold(0.0, f64::max);
        assert!(largest < 1e-10, "largest force {largest} on the ring at rest");
        let mut drawn = rest.clone();
        drawn[0] *= 1.1;
        let pull = forces(&closed, &drawn)[n - 1];
        assert!(pull.dot(&(drawn[0] - drawn[n - 1])) > 1.0, "the closing spring does not pull: {pull:?}");
        assert_eq!(forces(&open, &drawn)[n - 1], forces(&open, &rest)[n - 1], "the open ring's end felt node 0");
        // With κ < 1 the closed ring is pre-stressed everywhere, its wrap too.
        let model = Model::<f64>::new(&closed, &Params::default()).unwrap();
        let mut f = Vec::new();
        accumulate_forces(&model, &rest, &mut f);
        assert!(f[0].norm() > 1e-3 && f[n - 1].norm() > 1e-3, "{:?} {:?}", f[0], f[n - 1]);
    }

    #[test]
    fn ring_at_its_rest_curvature_has_zero_force() {
        // A closed-looking ring laid as an open polyline: every joint's rest
        // angle equals its shape, so with κ = 1 nothing pulls anywhere.
        let n = 24;
        let radius = 5.0;
        let positions = (0..n)
            .map(|i| {
                let t = 2.0 * std::f64::consts::PI * i as f64 / n as f64;
                V3::new(radius * t.cos(), radius * t.sin(), 0.3 * (3.0 * t).sin())
            })
            .collect();
        let fabric =
            Fabric::from_parts(FabricParts { positions, contacts: vec![[0, 12], [6, 18]], ..FabricParts::default() })
                .unwrap();
        let params = Params { rest_curl: 1.0, ..Params::default() };
        let model = Model::<f64>::new(&fabric, &params).unwrap();
        let mut forces = Vec::new();
        accumulate_forces(&model, &State::<f64>::at_rest(&fabric).positions, &mut forces);
        let largest = forces.iter().map(|f| f.norm()).fold(0.0, f64::max);
        assert!(largest < 1e-10, "largest force {largest}");
        // The same ring with κ < 1 is pre-stressed: the test can tell.
        let model = Model::<f64>::new(&fabric, &Params::default()).unwrap();
        accumulate_forces(&model, &State::<f64>::at_rest(&fabric).positions, &mut forces);
        assert!(forces.iter().map(|f| f.norm()).fold(0.0, f64::max) > 0.1);
    }

    fn two_node_contact(params: &Params) -> Model<f64> {
        let positions = vec![V3::zeros(), V3::new(1.0, 0.0, 0.0)];
        let fabric = Fabric::from_parts(FabricParts {
            positions,
            contacts: vec![[0, 1]],
            yarn_radius: Some(0.9),
            ..FabricParts::default()
        })
        .unwrap();
        Model::new(&fabric, params).unwrap()
    }

    /// Rounding allowed in the friction property, relative to 1 + the
    /// velocity it is measured on: about 60 times the worst that three runs
    /// of 100,000 to 300,000 cases measured (slip off the Coulomb filter
    /// 1.6e-14, normal part of Δw 4.8e-15). `PROPTEST_CASES=300000 cargo
    /// test --release -p yarn-model friction_never -- --nocapture` prints
    /// each as it grows, beside this bound.
    const FRICTION_ROUNDING: f64 = 1e-12;

    static WORST_SLIP: AtomicU64 = AtomicU64::new(0);
    static WORST_NORMAL: AtomicU64 = AtomicU64::new(0);

    /// Keep the largest `value` seen in `seen` (non-negative f64 bits
    /// order as the values do) and print it beside `bound` when it grows.
    fn worst(what: &str, seen: &AtomicU64, value: f64, bound: f64) {
        if seen.fetch_max(value.to_bits(), Ordering::Relaxed) < value.to_bits() {
            eprintln!("worst {what} so far: {value:e} (bound {bound:e})");
        }
    }

    proptest! {
        /// Friction at a contact of rest separation 1.8 (the 2r floor),
        /// with random velocities, μ and direction, at two separations drawn
        /// in every case: one compressed, where friction cuts the tangential
        /// slip |w_t| to max(0, |w_t| − μ Δv_n) and leaves the normal part
        /// alone, and one stretched, where it must not act at all, alone or
        /// inside a substep, unless stretched contacts have friction too
        /// ([`Params::friction_in_tension`]): then it cuts the slip as a
        /// compressed one does, Δv_n sized by the stretch.
        #[test]
        fn friction_never_increases_tangential_slip(
            compressed in 0.1..1.79f64,
            stretched in 1.81..4.0f64,
            dir in (-1.0..1.0f64, -1.0..1.0f64, -1.0..1.0f64),
            va in (-5.0..5.0f64, -5.0..5.0f64, -5.0..5.0f64),
            vb in (-5.0..5.0f64, -5.0..5.0f64, -5.0..5.0f64),
            mu in 0.0..2.0f64,
        ) {
            let params = Params { friction: mu, ..Params::default() };
            let model = two_node_contact(&params);
            let rest = model.contacts()[0].rest;
            prop_assert_eq!(rest, 1.8);
            let dir = V3::new(dir.0, dir.1, dir.2);
            prop_assume!(dir.norm() > 0.1);
            let n = dir.normalize();
            let (va, vb) = (V3::new(va.0, va.1, va.2), V3::new(vb.0, vb.1, vb.2));
            let tangential = |w: V3<f64>| (w - n * w.dot(&n)).norm();
            let xa = V3::zeros();

            // Compressed: friction acts, by the Coulomb filter.
            let xb = n * compressed;
            let before = tangential(vb - va);
            let dw = friction_change(&xa, &xb, &va, &vb, rest, &model);
            prop_assert!(dw.is_some() || before == 0.0, "no friction on a contact compressed to {compressed}");
            let dw = dw.unwrap_or_else(V3::zeros);
            let after = tangential((vb + dw * 0.5) - (va - dw * 0.5));
            let dv_normal = model.coeffs().friction_impulse * (rest - compressed);
            let expected = (before - mu * dv_normal).max(0.0);
            prop_assert!(after <= before * (1.0 + 1e-12) + 1e-12, "slip {before} -> {after}");
            let slip_error = (after - expected).abs() / (1.0 + before);
            let normal_error = dw.dot(&n).abs() / (1.0 + dw.norm());
            worst("slip off max(0, |w_t| - μ Δv_n)", &WORST_SLIP, slip_error, FRICTION_ROUNDING);
            worst("normal part of Δw", &WORST_NORMAL, normal_error, FRICTION_ROUNDING);
            prop_assert!(
                slip_error <= FRICTION_ROUNDING,
                "slip {before} -> {after}, not {expected} (error {slip_error:e})"
            );
            prop_assert!(normal_error <= FRICTION_ROUNDING, "friction changed the normal velocity: {dw:?}");

            // Stretched, with friction in tension: the same filter, by the stretch.
            let xb = n * stretched;
            let tense = two_node_contact(&Params { friction_in_tension: true, ..params });
            let dw = friction_change(&xa, &xb, &va, &vb, rest, &tense).unwrap_or_else(V3::zeros);
            let after = tangential((vb + dw * 0.5) - (va - dw * 0.5));
            let expected = (before - mu * tense.coeffs().friction_impulse * (stretched - rest)).max(0.0);
            let slip_error = (after - expected).abs() / (1.0 + before);
            prop_assert!(
                slip_error <= FRICTION_ROUNDING,
                "stretched to {stretched}: slip {before} -> {after}, not {expected} (error {slip_error:e})"
            );
            prop_assert!(dw.dot(&n).abs() / (1.0 + dw.norm()) <= FRICTION_ROUNDING, "normal velocity changed: {dw:?}");

            // Stretched: no change, alone or in a substep against μ = 0.
            let dw = friction_change(&xa, &xb, &va, &vb, rest, &model);
            prop_assert_eq!(dw, None, "friction acts on a contact stretched to {}", stretched);
            let start = State { positions: vec![xa, xb], velocities: vec![va, vb] };
            let (mut with, mut without) = (start.clone(), start);
            substep(&model, &mut with, &mut Scratch::default());
            substep(&two_node_contact(&Params { friction: 0.0, ..params }), &mut without, &mut Scratch::default());
            prop_assert_eq!(with, without, "friction acted on a contact stretched to {}", stretched);
        }
    }

    proptest! {
        /// Friction at a self-contact pair, random segments, velocities and
        /// sharing S: the pair's slip at its closest points shrinks by its
        /// share of stopping it, slip / S, or by its own Coulomb cut
        /// μ h k_sc g(2r − d) W, whichever is less, and never reverses; its
        /// normal relative velocity is kept, and the nodes' changes carry no
        /// net momentum.
        #[test]
        fn self_contact_friction_cuts_the_pairs_slip_without_reversing_it(
            ends in prop::array::uniform4((-1.5..1.5f64, -1.5..1.5f64, -0.8..0.8f64)),
            speeds in prop::array::uniform4((-5.0..5.0f64, -5.0..5.0f64, -5.0..5.0f64)),
            mu in 0.0..2.0f64,
            sharing in 1u32..8,
        ) {
            let params = Params { friction: mu, self_contact_stiffness: 800.0, ..Params::default() };
            let c = Coefficients::<f64>::new(&params);
            let x = ends.map(|(a, b, z)| V3::new(a, b, z));
            let v = speeds.map(|(a, b, z)| V3::new(a, b, z));
            let reach = 1.8;
            let (gap, s, t) = closest_gap(&x[0], &x[1], &x[2], &x[3]);
            prop_assume!(gap.norm() < reach && gap.norm() > 1e-3);
            let n = gap.normalize();
            let at = |v: &[V3<f64>; 4]| (v[2] * (1.0 - t) + v[3] * t) - (v[0] * (1.0 - s) + v[1] * s);
            let tangential = |w: V3<f64>| w - n * w.dot(&n);
            let before = tangential(at(&v));
            let Some(dv) = self_contact_friction(x.each_ref(), v.each_ref(), reach, f64::from(sharing), &c) else {
                prop_assert!(before.norm() == 0.0, "no friction on a pair within reach");
                return Ok(());
            };
            let after_v = [v[0] + dv[0], v[1] + dv[1], v[2] + dv[2], v[3] + dv[3]];
            let after = tangential(at(&after_v));
            let shares = [(1.0 - s), s, (1.0 - t), t];
            let w_m = shares.iter().map(|a| a * a).sum::<f64>();
            let cut = mu * c.self_contact_impulse * push_depth(reach - gap.norm(), reach) * w_m;
            let expected = before.norm() - (before.norm() / f64::from(sharing)).min(cut);
            prop_assert!((after.norm() - expected).abs() <= 1e-9 * (1.0 + before.norm()), "slip {} -> {}, not {expected}", before.norm(), after.norm());
            prop_assert!(after.dot(&before) >= -1e-12, "the slip reversed");
            prop_assert!((at(&after_v) - at(&v)).dot(&n).abs() <= 1e-9 * (1.0 + before.norm()), "the normal velocity changed");
            prop_assert!((dv[0] + dv[1] + dv[2] + dv[3]).norm() <= 1e-12 * (1.0 + before.norm()), "net momentum {dv:?}");
        }
    }

    /// Two parallel yarns 1.5 apart (reach 1.8), one with nodes a unit
    /// apart and one 0.6 apart, sliding past each other along their length:
    /// most nodes are pushed by three pairs or more, all slipping the same
    /// way, and the two sides' nodes by different counts. Self-contact
    /// friction keeps the patch's momentum (gravity off, so Σv only decays
    /// by the damping factor), and no node's change is longer than the
    /// longest change that would stop one of its pairs' slip, so many pairs
    /// do not add up past one. Where friction is weak (μ = 0.01) the pairs
    /// slide, and a node pushed by several takes more than one pair's
    /// Coulomb limit: each pair keeps its own.
    #[test]
    fn self_contact_friction_keeps_momentum_where_many_pairs_share_a_node() {
        let n = 7u32;
        let positions: Vec<_> = (0..2 * n)
            .map(|i| {
                if i < n {
                    yarn_topology::Vec3::new(f64::from(i), 0.0, 0.0)
                } else {
                    yarn_topology::Vec3::new(0.6 * f64::from(i - n) + 1.2, 1.5, 0.0)
                }
            })
            .collect();
        let fabric = Fabric::from_parts(FabricParts {
            positions,
            yarns: vec![yarn_topology::YarnSpan::open(0..n), yarn_topology::YarnSpan::open(n..2 * n)],
            yarn_radius: Some(0.9),
            ..FabricParts::default()
        })
        .unwrap();
        for friction in [1.0, 0.01] {
            let params = Params { gravity: 0.0, friction, self_contact_stiffness: 800.0, ..Params::default() };
            let model = Model::<f64>::new(&fabric, &params).unwrap();
            let mut state = State::<f64>::at_rest(&fabric);
            for (i, v) in state.velocities.iter_mut().enumerate() {
                let along = if i < n as usize { 0.02 } else { -0.03 };
                *v = V3::new(along, 0.001 * i as f64, -0.002 * (i % 3) as f64);
            }
            let c = model.coeffs();
            let momentum = |v: &[V3<f64>]| v.iter().sum::<V3<f64>>();
            let before = momentum(&state.velocities);
            // Each node's longest change that would stop a pair's slip, and
            // its longest under Coulomb's limit, neither shared, from v* as
            // the substep sees it.
            let reach = 2.0 * model.contact_rule().radius();
            let sticking = Coefficients::<f64>::new(&Params { friction: 1e12, ..params });
            let pairs = touching(&model, &state.positions);
            let mut pushing = Vec::new();
            pushing_pairs(&model, &state.positions, &pairs, &mut pushing);
            assert!(pushing.iter().filter(|&&k| k >= 3).count() >= 8, "{pushing:?}");
            let mut forces = Vec::new();
            accumulate_forces(&model, &state.positions, &mut forces);
            let v_star: Vec<_> =
                state.velocities.iter().zip(&forces).map(|(v, f)| (v + f * c.h_over_m) * c.damping_factor).collect();
            let (mut stopping, mut limited) = (vec![0.0f64; state.len()], vec![0.0f64; state.len()]);
            for &[a, b] in &pairs {
                let ends = [a as usize, segment_end(&model, a as usize), b as usize, segment_end(&model, b as usize)];
                let (x, v) = (ends.map(|i| &state.positions[i]), ends.map(|i| &v_star[i]));
                for (coefficients, longest) in [(&sticking, &mut stopping), (c, &mut limited)] {
                    if let Some(dv) = self_contact_friction(x, v, reach, 1.0, coefficients) {
                        for (i, dv) in ends.into_iter().zip(dv) {
                            longest[i] = longest[i].max(dv.norm());
                        }
                    }
                }
            }
            let mut scratch = Scratch::default();
            substep(&model, &mut state, &mut scratch);
            let after = momentum(&state.velocities);
            assert!(
                (after - before * c.damping_factor).norm() < 1e-12,
                "μ = {friction}: momentum {before:?} -> {after:?}, off by {:e}",
                (after - before * c.damping_factor).norm()
            );
            let moved = scratch.self_friction.iter().filter(|dv| dv.norm() > 0.0).count();
            assert!(moved >= 12, "μ = {friction}: friction changed {moved} nodes");
            for (i, dv) in scratch.self_friction.iter().enumerate() {
                assert!(
                    dv.norm() <= stopping[i] * (1.0 + 1e-12),
                    "μ = {friction}, node {i}: {} past {}",
                    dv.norm(),
                    stopping[i]
                );
            }
            if friction < 0.1 {
                let past_one_limit =
                    scratch.self_friction.iter().zip(&limited).filter(|(dv, limit)| dv.norm() > **limit * 1.01).count();
                assert!(past_one_limit >= 4, "{past_one_limit} nodes took more than one pair's Coulomb limit");
            }
        }
    }

    #[test]
    fn friction_acts_on_compressed_contacts_and_on_stretched_ones_where_asked() {
        let model = two_node_contact(&Params::default());
        let (va, vb) = (V3::zeros(), V3::new(0.0, 3.0, 0.0));
        let apart = V3::new(2.0, 0.0, 0.0);
        assert!(friction_change(&V3::zeros(), &apart, &va, &vb, 1.8, &model).is_none());
        let pressed = V3::new(1.0, 0.0, 0.0);
        let dw = friction_change(&V3::zeros(), &pressed, &va, &vb, 1.8, &model).unwrap();
        // Δv_n = h k_c 0.8 / (m/2) = 53.3 > |w_t| / μ, so the slip is arrested.
        assert!((dw + vb).norm() < 1e-12, "{dw:?}");
        // Stretched contacts have friction too where the parameters say so:
        // Δv_n = h k_c 0.2 / (m/2) = 13.3, μ Δv_n = 4 > |w_t| = 3, arrested.
        let tense = two_node_contact(&Params { friction_in_tension: true, ..Params::default() });
        let dw = friction_change(&V3::zeros(), &apart, &va, &vb, 1.8, &tense).unwrap();
        assert!((dw + vb).norm() < 1e-12, "{dw:?}");
        // Held at its rest length, a contact has no friction either way.
        assert!(friction_change(&V3::zeros(), &V3::new(1.8, 0.0, 0.0), &va, &vb, 1.8, &tense).is_none());
    }

    #[test]
    fn pins_hold_and_dead_contacts_are_inert() {
        let fabric = patch(2, 2);
        let mut model = Model::<f64>::new(&fabric, &Params::default()).unwrap();
        let target = V3::new(1.0, 2.0, 3.0);
        model.set_pins(&[yarn_topology::Pin { node: 5, target }]).unwrap();
        let mut state = State::at_rest(&fabric);
        let mut scratch = Scratch::default();
        for _ in 0..50 {
            substep(&model, &mut state, &mut scratch);
        }
        assert_eq!(state.positions[5], target);
        assert_eq!(state.velocities[5], V3::zeros());

        let mut forces_alive = Vec::new();
        let mut forces_dead = Vec::new();
        let mut stretched = State::<f64>::at_rest(&fabric);
        let k = model.contacts()[0];
        stretched.positions[k.b as usize] += V3::new(0.0, 1.0, 0.0);
        accumulate_forces(&model, &stretched.positions, &mut forces_alive);
        let mut alive = vec![true; model.contacts().len()];
        alive[0] = false;
        model.set_contacts_alive(&alive, &stretched.positions).unwrap();
        accumulate_forces(&model, &stretched.positions, &mut forces_dead);
        let removed = forces_alive[k.a as usize] - forces_dead[k.a as usize];
        let expected = spring_force(
            &stretched.positions[k.a as usize],
            &stretched.positions[k.b as usize],
            k.rest,
            model.coeffs().contact,
        );
        assert!((removed - expected).norm() < 1e-9, "dead contact still pulls: {removed:?} vs {expected:?}");
    }
}
