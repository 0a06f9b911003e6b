//! Energy and exact force of each potential term (SPEC §3), one element at a
//! time. Every backend evaluates these same formulas; the finite-difference
//! tests below hold each force to the negative gradient of its energy.
//!
//! A force function returns the force on the element's *first* node(s); the
//! rest follow from Newton's third law, which callers apply.

use crate::{Real, V3};

/// Below this sin θ a bending joint is treated as straight and skipped
/// (SPEC §3): the bending direction is undefined there and the energy is
/// flat to first order.
pub const MIN_SIN_THETA: f64 = 1e-4;

/// Energy ½ k (ℓ − rest)² of a spring between `a` and `b`.
///
/// The stretch spring (SPEC §3, U = ½ k_s (ℓ − ℓ0)²) and the two-sided
/// contact tether (U = ½ k_c (d_c − ℓ)²) are the same function of ℓ, so both
/// use this kernel with their own stiffness and rest value.
#[inline]
pub fn spring_energy<T: Real>(a: &V3<T>, b: &V3<T>, rest: T, k: T) -> T {
    let stretch = (b - a).norm() - rest;
    T::of(0.5) * k * stretch * stretch
}

/// Force on node `a` of a spring between `a` and `b`; node `b` gets the
/// negation. Zero when the nodes coincide, where the direction is undefined.
#[inline]
pub fn spring_force<T: Real>(a: &V3<T>, b: &V3<T>, rest: T, k: T) -> V3<T> {
    let d = b - a;
    let length = d.norm();
    if length > T::zero() { d * (k * (length - rest) / length) } else { V3::zeros() }
}

/// A bending joint's unit tangents u, v and inverse segment lengths.
struct Joint<T> {
    u: V3<T>,
    v: V3<T>,
    inv_l0: T,
    inv_l1: T,
}

/// The joint at `b`, or `None` if either segment has zero length.
///
/// Each tangent is its segment times the reciprocal length: one division
/// per segment, which vectorising backends reproduce operation for
/// operation.
#[inline]
fn joint<T: Real>(a: &V3<T>, b: &V3<T>, c: &V3<T>) -> Option<Joint<T>> {
    let (d0, d1) = (b - a, c - b);
    let (l0, l1) = (d0.norm(), d1.norm());
    if !(l0 > T::zero() && l1 > T::zero()) {
        return None;
    }
    let (inv_l0, inv_l1) = (T::one() / l0, T::one() / l1);
    Some(Joint { u: d0 * inv_l0, v: d1 * inv_l1, inv_l0, inv_l1 })
}

/// s = u·v clamped to [−1, 1]: the cosine of the turning angle.
#[inline]
fn cosine<T: Real>(u: &V3<T>, v: &V3<T>) -> T {
    (u.x * v.x + u.y * v.y + u.z * v.z).clamp(-T::one(), T::one())
}

/// Energy ½ k_b (θ − target)² of the bending joint (a, b, c), where
/// `target` is κθ0 (SPEC §3).
#[inline]
pub fn bend_energy<T: Real>(a: &V3<T>, b: &V3<T>, c: &V3<T>, target: T, k: T) -> T {
    match joint(a, b, c) {
        Some(Joint { u, v, .. }) => {
            let theta = cosine(&u, &v).turning_angle();
            T::of(0.5) * k * (theta - target) * (theta - target)
        }
        // A degenerate joint has no angle; it stores no bending energy.
        None => T::zero(),
    }
}

/// Forces `[f_a, f_b, f_c]` of the bending joint (a, b, c), or `None` when
/// sin θ < [`MIN_SIN_THETA`] or a segment has zero length.
///
/// With ∇θ = −∇s / sin θ (the SPEC §3 erratum to the paper's eq. 6) and
/// c = k_b (θ − target) / sin θ: f_a = −c (v − s u)/ℓ0, f_c = c (u − s v)/ℓ1,
/// and the middle node gets −(f_a + f_c).
#[inline]
pub fn bend_forces<T: Real>(a: &V3<T>, b: &V3<T>, c: &V3<T>, target: T, k: T) -> Option<[V3<T>; 3]> {
    let Joint { u, v, inv_l0, inv_l1 } = joint(a, b, c)?;
    let s = cosine(&u, &v);
    let sin_theta = (T::one() - s * s).sqrt();
    #[allow(clippy::neg_cmp_op_on_partial_ord, reason = "a NaN angle skips the joint too")]
    if !(sin_theta >= T::of(MIN_SIN_THETA)) {
        return None;
    }
    let coeff = k * (s.turning_angle() - target) / sin_theta;
    let (fa, fc) = ((v - u * s) * (-coeff * inv_l0), (u - v * s) * (coeff * inv_l1));
    Some([fa, -(fa + fc), fc])
}

/// Gravitational energy m g y of one node (SPEC §3).
#[inline]
pub fn gravity_energy<T: Real>(x: &V3<T>, mass: T, gravity: T) -> T {
    mass * gravity * x.y
}

/// Gravitational force (0, −m g, 0) on one node.
#[inline]
pub fn gravity_force<T: Real>(mass: T, gravity: T) -> V3<T> {
    V3::new(T::zero(), -mass * gravity, T::zero())
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    type P = V3<f64>;

    fn point() -> impl Strategy<Value = P> {
        (-3.0..3.0f64, -3.0..3.0f64, -3.0..3.0f64).prop_map(|(x, y, z)| P::new(x, y, z))
    }

    /// Central difference of `energy` along each coordinate of each point.
    /// ε ≈ eps_machine^(1/3) × scale balances truncation (∝ ε²) against
    /// rounding (∝ 1/ε); the scale is the element's size.
    fn numeric_gradient(points: &[P], energy: impl Fn(&[P]) -> f64) -> Vec<P> {
        let scale = points.iter().map(|p| p.norm()).fold(1.0, f64::max);
        let eps = f64::EPSILON.cbrt() * scale;
        (0..points.len())
            .map(|i| {
                P::from_fn(|k, _| {
                    let mut plus = points.to_vec();
                    let mut minus = points.to_vec();
                    plus[i][k] += eps;
                    minus[i][k] -= eps;
                    (energy(&plus) - energy(&minus)) / (2.0 * eps)
                })
            })
            .collect()
    }

    fn assert_force_is_minus_gradient(points: &[P], forces: &[P], energy: impl Fn(&[P]) -> f64) {
        let gradient = numeric_gradient(points, energy);
        let scale = forces.iter().map(|f| f.norm()).fold(1.0, f64::max);
        for (i, (f, g)) in forces.iter().zip(&gradient).enumerate() {
            let err = (f + g).norm();
            assert!(err <= 1e-6 * scale, "node {i}: force {f:?} vs -grad {:?} (err {err:e})", -g);
        }
    }

    proptest! {
        #[test]
        fn spring_force_is_minus_gradient(a in point(), b in point(), rest in 0.1..4.0f64, k in 1.0..1000.0f64) {
            prop_assume!((b - a).norm() > 0.05);
            let f = spring_force(&a, &b, rest, k);
            assert_force_is_minus_gradient(&[a, b], &[f, -f], |p| spring_energy(&p[0], &p[1], rest, k));
        }

        #[test]
        fn bend_force_is_minus_gradient(a in point(), b in point(), c in point(), target in 0.0..3.0f64, k in 0.1..20.0f64) {
            let forces = bend_forces(&a, &b, &c, target, k);
            let (u, v) = ((b - a).normalize(), (c - b).normalize());
            // Stay off the straight and fully-folded joints, where θ is not
            // differentiable and the FD stencil would straddle the kink.
            prop_assume!((b - a).norm() > 0.1 && (c - b).norm() > 0.1 && u.dot(&v).abs() < 0.99);
            let forces = forces.expect("joint is bent");
            assert_force_is_minus_gradient(&[a, b, c], &forces, |p| bend_energy(&p[0], &p[1], &p[2], target, k));
        }

        #[test]
        fn gravity_force_is_minus_gradient(x in point(), m in 1e-3..1.0f64, g in -20.0..20.0f64) {
            assert_force_is_minus_gradient(&[x], &[gravity_force(m, g)], |p| gravity_energy(&p[0], m, g));
        }
    }

    #[test]
    fn bend_sign_matches_the_erratum_not_the_paper() {
        // A right angle wanting to straighten: a pushed back along the
        // outgoing direction's normal would *increase* θ under the paper's
        // printed eq. (6); the corrected form must reduce it.
        let (a, b, c) = (P::new(-1.0, 0.0, 0.0), P::zeros(), P::new(0.0, 1.0, 0.0));
        let [fa, _, fc] = bend_forces(&a, &b, &c, 0.0, 1.0).unwrap();
        let step = 1e-3;
        let theta = |a: &P, c: &P| ((b - a).normalize().dot(&(c - b).normalize())).acos();
        assert!(theta(&(a + fa * step), &(c + fc * step)) < theta(&a, &c), "bending force must reduce θ toward 0");
    }

    #[test]
    fn straight_joint_is_skipped() {
        let (a, b, c) = (P::new(-1.0, 0.0, 0.0), P::zeros(), P::new(1.0, 0.0, 0.0));
        assert!(bend_forces(&a, &b, &c, 0.5, 6.0).is_none());
        assert!((bend_energy(&a, &b, &c, 0.5, 6.0) - 0.75).abs() < 1e-12);
    }
}
