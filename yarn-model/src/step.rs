//! The reference substep (SPEC §4), the force accumulation and the energy,
//! written as plain serial loops in element order. This is the function
//! every backend must compute; `yarn_backend_cpu::Reference` runs it as is,
//! and the conformance suite holds the fast backends to it.

use crate::terms::{bend_energy, bend_forces, gravity_energy, gravity_force, spring_energy, spring_force};
use crate::{Model, Real, State, V3};

/// Energy of a state, split by term, in `f64`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Energy {
    /// Σ ½ k_s (ℓ − ℓ0)².
    pub stretch: f64,
    /// Σ ½ k_b (θ − κθ0)².
    pub bend: f64,
    /// Σ ½ k_c (d_c − ℓ)² over alive contacts.
    pub contact: f64,
    /// Σ m g y.
    pub gravity: f64,
    /// Σ ½ m |v|².
    pub kinetic: f64,
}

impl Energy {
    /// The potential U (SPEC §3).
    pub fn potential(&self) -> f64 {
        self.stretch + self.bend + self.contact + self.gravity
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
    /// Friction velocity correction per node (SPEC §4 step 3).
    pub friction: Vec<V3<T>>,
}

/// F = −∇U(x) over alive contacts (SPEC §4 step 1), written into `forces`,
/// which is resized to the node count.
pub fn accumulate_forces<T: Real>(model: &Model<T>, x: &[V3<T>], forces: &mut Vec<V3<T>>) {
    let c = model.coeffs();
    forces.clear();
    forces.resize(x.len(), gravity_force(c.mass, c.gravity));
    for (i, &rest) in model.spring_rest().iter().enumerate() {
        let f = spring_force(&x[i], &x[i + 1], rest, c.stretch);
        forces[i] += f;
        forces[i + 1] -= f;
    }
    for (i, &theta0) in model.rest_angle().iter().enumerate() {
        if let Some([fa, fb, fc]) = bend_forces(&x[i], &x[i + 1], &x[i + 2], c.rest_curl * theta0, c.bend) {
            forces[i] += fa;
            forces[i + 1] += fb;
            forces[i + 2] += fc;
        }
    }
    for (contact, _) in model.contacts().iter().zip(model.alive()).filter(|(_, alive)| **alive) {
        let (a, b) = (contact.a as usize, contact.b as usize);
        let f = spring_force(&x[a], &x[b], contact.rest, c.contact);
        forces[a] += f;
        forces[b] -= f;
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
        stretch: sum(&mut model
            .spring_rest()
            .iter()
            .enumerate()
            .map(|(i, &rest)| spring_energy(&x[i], &x[i + 1], rest, c.stretch))),
        bend: sum(&mut model
            .rest_angle()
            .iter()
            .enumerate()
            .map(|(i, &theta0)| bend_energy(&x[i], &x[i + 1], &x[i + 2], c.rest_curl * theta0, c.bend))),
        contact: sum(&mut model
            .contacts()
            .iter()
            .zip(model.alive())
            .filter(|(_, alive)| **alive)
            .map(|(k, _)| spring_energy(&x[k.a as usize], &x[k.b as usize], k.rest, c.contact))),
        gravity: sum(&mut x.iter().map(|p| gravity_energy(p, c.mass, c.gravity))),
        kinetic: 0.0,
    }
}

/// Friction velocity change of one compressed contact (SPEC §4 step 3):
/// the change `Δw` to the relative velocity w = v_b − v_a, or `None` when
/// the contact is not compressed or has no tangential slip. Node a gets
/// −Δw/2 and node b +Δw/2.
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
    if !(length < rest && length > T::zero()) {
        return None;
    }
    let n = d / length;
    let w = vb - va;
    let wt = w - n * w.dot(&n);
    let slip = wt.norm();
    if slip <= T::zero() {
        return None;
    }
    let dv_normal = c.friction_impulse * (rest - length);
    let retention = (T::one() - c.friction * dv_normal / slip).max(T::zero());
    Some(wt * (retention - T::one()))
}

/// One substep (SPEC §4), in place:
/// 1. F = −∇U(x) over alive contacts;
/// 2. v* = (v + hF/m) / (1 + βh);
/// 3. Jacobi friction: every compressed alive contact's correction computed
///    from v* and x, summed, then applied;
/// 4. x' = x + h v**;
/// 5. pinned nodes set to their targets with zero velocity.
pub fn substep<T: Real>(model: &Model<T>, state: &mut State<T>, scratch: &mut Scratch<T>) {
    let c = model.coeffs();
    accumulate_forces(model, &state.positions, &mut scratch.forces);
    for (v, f) in state.velocities.iter_mut().zip(&scratch.forces) {
        *v = (*v + f * c.h_over_m) * c.damping_factor;
    }
    if c.friction > T::zero() {
        let (x, v) = (&state.positions, &state.velocities);
        scratch.friction.clear();
        scratch.friction.resize(x.len(), V3::zeros());
        for (k, _) in model.contacts().iter().zip(model.alive()).filter(|(_, alive)| **alive) {
            let (a, b) = (k.a as usize, k.b as usize);
            if let Some(dw) = friction_change(&x[a], &x[b], &v[a], &v[b], k.rest, model) {
                let half = dw * T::of(0.5);
                scratch.friction[a] -= half;
                scratch.friction[b] += half;
            }
        }
        for (v, dv) in state.velocities.iter_mut().zip(&scratch.friction) {
            *v += dv;
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
    use proptest::prelude::*;
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

    /// Finite differences of U on every degree of freedom against the
    /// accumulated force, with ε = eps_machine^(1/3) × the patch scale.
    #[allow(clippy::needless_range_loop, reason = "node and axis indices name the degree of freedom")]
    fn check_gradient(fabric: &Fabric, params: &Params, state: &State<f64>, alive: &[bool]) {
        let mut model = Model::<f64>::new(fabric, params).unwrap();
        model.set_contacts_alive(alive, &state.positions).unwrap();
        let mut forces = Vec::new();
        accumulate_forces(&model, &state.positions, &mut forces);
        let scale = state.positions.iter().map(|p| p.amax()).fold(1.0, f64::max);
        let eps = f64::EPSILON.cbrt() * scale.min(10.0);
        let mut probe = state.clone();
        let force_scale = forces.iter().map(|f| f.amax()).fold(1.0, f64::max);
        for i in 0..state.len() {
            for k in 0..3 {
                let x0 = probe.positions[i][k];
                probe.positions[i][k] = x0 + eps;
                let up = energy(&model, &probe).potential();
                probe.positions[i][k] = x0 - eps;
                let down = energy(&model, &probe).potential();
                probe.positions[i][k] = x0;
                let numeric = -(up - down) / (2.0 * eps);
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
        /// randomly perturbed patch with some dead contacts.
        #[test]
        fn forces_are_minus_gradient_on_perturbed_patches(
            w in 1usize..4, h in 1usize..4,
            seed in any::<u64>(),
            amplitude in 0.05..0.6f64,
            term in 0usize..5,
        ) {
            let fabric = patch(w, h);
            let mut rng = seed;
            let mut next = || { rng ^= rng << 13; rng ^= rng >> 7; rng ^= rng << 17; (rng >> 11) as f64 / (1u64 << 53) as f64 - 0.5 };
            let mut state = State::<f64>::at_rest(&fabric);
            for p in &mut state.positions {
                *p += V3::new(next(), next(), next()) * (2.0 * amplitude);
            }
            let alive: Vec<bool> = (0..fabric.contacts().len()).map(|_| next() > -0.3).collect();
            let params = match term {
                0 => only(true, false, false, false),
                1 => only(false, true, false, false),
                2 => only(false, false, true, false),
                3 => only(false, false, false, true),
                _ => Params { gravity: 9.81, ..Params::default() },
            };
            check_gradient(&fabric, &params, &state, &alive);
        }
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

    proptest! {
        #[test]
        fn friction_never_increases_tangential_slip(
            gap in 0.1..1.79f64,
            dir in (-1.0..1.0f64, -1.0..1.0f64, -1.0..1.0f64),
            va in (-5.0..5.0f64, -5.0..5.0f64, -5.0..5.0f64),
            vb in (-5.0..5.0f64, -5.0..5.0f64, -5.0..5.0f64),
            mu in 0.0..2.0f64,
        ) {
            let model = two_node_contact(&Params { friction: mu, ..Params::default() });
            let rest = model.contacts()[0].rest; // 1.8, the 2r floor
            let dir = V3::new(dir.0, dir.1, dir.2);
            prop_assume!(dir.norm() > 0.1);
            let xa = V3::zeros();
            let xb = dir.normalize() * gap;
            let (va, vb) = (V3::new(va.0, va.1, va.2), V3::new(vb.0, vb.1, vb.2));
            let n = (xb - xa).normalize();
            let tangential = |w: V3<f64>| (w - n * w.dot(&n)).norm();
            let before = tangential(vb - va);
            let after = match friction_change(&xa, &xb, &va, &vb, rest, &model) {
                Some(dw) => tangential((vb + dw * 0.5) - (va - dw * 0.5)),
                None => before,
            };
            prop_assert!(after <= before * (1.0 + 1e-12) + 1e-12, "slip {before} -> {after}");
            // The normal part is untouched.
            if let Some(dw) = friction_change(&xa, &xb, &va, &vb, rest, &model) {
                prop_assert!(dw.dot(&n).abs() < 1e-9 * (1.0 + dw.norm()));
                prop_assert!(mu > 0.0);
            }
        }
    }

    #[test]
    fn friction_acts_only_on_compressed_contacts() {
        let model = two_node_contact(&Params::default());
        let (va, vb) = (V3::zeros(), V3::new(0.0, 3.0, 0.0));
        let apart = V3::new(2.0, 0.0, 0.0);
        assert!(friction_change(&V3::zeros(), &apart, &va, &vb, 1.8, &model).is_none());
        let pressed = V3::new(1.0, 0.0, 0.0);
        let dw = friction_change(&V3::zeros(), &pressed, &va, &vb, 1.8, &model).unwrap();
        // Δv_n = h k_c 0.8 / (m/2) = 53.3 > |w_t| / μ, so the slip is arrested.
        assert!((dw + vb).norm() < 1e-12, "{dw:?}");
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
        model.set_contacts_alive(&[false, true, true, true], &stretched.positions).unwrap();
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
