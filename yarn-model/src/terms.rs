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

/// The closest points of segments p0p1 and q0q1, as the parameters
/// `(s, t)` in [0, 1] of p0 + s (p1 − p0) and q0 + t (q1 − q0).
///
/// Ericson's clamped solution (*Real-Time Collision Detection*, 2005,
/// §5.1.9): the lines' closest parameters, clamped to the segments, then
/// the other recomputed against the clamp. Parallel segments (the
/// determinant below 1e-6 of a·e) take s = 0 and the point of q nearest
/// p0; a zero-length segment takes its start.
#[inline]
pub fn closest_parameters<T: Real>(p0: &V3<T>, p1: &V3<T>, q0: &V3<T>, q1: &V3<T>) -> (T, T) {
    let (u, v, w) = (p1 - p0, q1 - q0, p0 - q0);
    let (a, e, f) = (u.dot(&u), v.dot(&v), v.dot(&w));
    let unit = |x: T| x.clamp(T::zero(), T::one());
    if a <= T::zero() {
        return (T::zero(), if e > T::zero() { unit(f / e) } else { T::zero() });
    }
    let c = u.dot(&w);
    if e <= T::zero() {
        return (unit(-c / a), T::zero());
    }
    let b = u.dot(&v);
    let det = a * e - b * b;
    let s = if det > T::of(1e-6) * a * e { unit((b * f - c * e) / det) } else { T::zero() };
    let t = (b * s + f) / e;
    if t < T::zero() {
        (unit(-c / a), T::zero())
    } else if t > T::one() {
        (unit((b - c) / a), T::one())
    } else {
        (s, t)
    }
}

/// The vector c_p − c_q between the closest points of segments p0p1 and
/// q0q1, with their parameters `(s, t)` ([`closest_parameters`]).
#[inline]
pub fn closest_gap<T: Real>(p0: &V3<T>, p1: &V3<T>, q0: &V3<T>, q1: &V3<T>) -> (V3<T>, T, T) {
    let (s, t) = closest_parameters(p0, p1, q0, q1);
    (p0 + (p1 - p0) * s - q0 - (q1 - q0) * t, s, t)
}

/// How deep into the reach the self-contact push takes to reach its full
/// stiffness, as a fraction of the reach D = 2r: ε = D/16 = r/8. Over
/// that depth the stiffness ramps from 0 to k, so the energy is C2 and the
/// quasi-static solve, whose steps assume a smooth Hessian, converges
/// where many pairs rest near d = D (a C1 penalty, whose stiffness jumps
/// from 0 to k there, left the gate's 4x4 patch at a saddle after 20,000
/// evaluations; with this onset it is certified in about 16,000). A power
/// of two, so ε = D · `CONTACT_ONSET` is exact in every precision and on
/// the GPU.
pub const CONTACT_ONSET: f64 = 1.0 / 16.0;

/// The self-contact push per unit stiffness at `depth` = D − d into the
/// reach D: depth²/(2ε) up to the onset ε = D · [`CONTACT_ONSET`], then
/// depth − ε/2. Its slope, the stiffness per unit k, rises from 0 to 1
/// over the onset and stays 1 beyond ([`self_contact_stiffness`]).
#[inline]
pub fn push_depth<T: Real>(depth: T, reach: T) -> T {
    let onset = reach * T::of(CONTACT_ONSET);
    if depth <= onset { depth * depth / (onset + onset) } else { depth - onset * T::of(0.5) }
}

/// The push's stiffness k · d[`push_depth`]/d depth at `depth` into the
/// reach: k · depth/ε up to the onset, then k. Never above k, so k alone
/// bounds the stable substep.
#[inline]
pub fn self_contact_stiffness<T: Real>(depth: T, reach: T, k: T) -> T {
    let onset = reach * T::of(CONTACT_ONSET);
    if depth <= onset { k * depth / onset } else { k }
}

/// Energy of self-contact between segments p0p1 and q0q1, where d is their
/// closest distance and D the contact distance (one yarn diameter, 2r),
/// δ = D − d and ε the onset ([`CONTACT_ONSET`]): k δ³/(6ε) up to ε, then
/// ½ k (δ − ε/2)² + k ε²/24, the two meeting with equal value, slope and
/// curvature; zero once d ≥ D.
#[inline]
pub fn self_contact_energy<T: Real>(p0: &V3<T>, p1: &V3<T>, q0: &V3<T>, q1: &V3<T>, reach: T, k: T) -> T {
    let d = closest_gap(p0, p1, q0, q1).0.norm();
    if d >= reach {
        return T::zero();
    }
    let (depth, onset) = (reach - d, reach * T::of(CONTACT_ONSET));
    if depth <= onset {
        k * depth * depth * depth / (T::of(6.0) * onset)
    } else {
        let past = depth - onset * T::of(0.5);
        T::of(0.5) * k * past * past + k * onset * onset / T::of(24.0)
    }
}

/// Forces `[f_p0, f_p1, f_q0, f_q1]` of self-contact between segments
/// p0p1 and q0q1 ([`self_contact_energy`]), or `None` when they are at
/// least `reach` apart or their closest points coincide (no direction).
///
/// With closest points c_p, c_q at (s, t) and n = (c_p − c_q)/d, the pair
/// is pushed apart by k g(D − d) n, g the [`push_depth`], shared by the
/// segments' nodes as the closest points sit on them: (1 − s, s) on p and
/// −(1 − t, t) on q.
/// This is the exact gradient wherever the closest points are unique:
/// d is the minimum over (s, t) of a convex distance, so moving (s, t)
/// changes it only to second order (Danskin's theorem), and the clamped
/// cases hold (s, t) on the boundary.
#[inline]
pub fn self_contact_forces<T: Real>(
    p0: &V3<T>,
    p1: &V3<T>,
    q0: &V3<T>,
    q1: &V3<T>,
    reach: T,
    k: T,
) -> Option<[V3<T>; 4]> {
    self_contact_push(&Closest::of(p0, p1, q0, q1), reach, k)
}

/// The closest points of two segments, p0p1 and q0q1: the vector between
/// them ([`closest_gap`]), its length and their parameters. Self-contact's
/// force and friction both start from it, at the same positions, so a
/// backend may find it once for both.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Closest<T> {
    /// c_p − c_q.
    pub gap: V3<T>,
    /// |c_p − c_q|.
    pub distance: T,
    /// c_p's parameter on p0p1.
    pub s: T,
    /// c_q's parameter on q0q1.
    pub t: T,
}

impl<T: Real> Default for Closest<T> {
    /// Segments that do not touch.
    fn default() -> Self {
        Self { gap: V3::zeros(), distance: T::zero(), s: T::zero(), t: T::zero() }
    }
}

impl<T: Real> Closest<T> {
    /// The closest points of segments p0p1 and q0q1.
    #[inline]
    pub fn of(p0: &V3<T>, p1: &V3<T>, q0: &V3<T>, q1: &V3<T>) -> Self {
        let (gap, s, t) = closest_gap(p0, p1, q0, q1);
        Self { gap, distance: gap.norm(), s, t }
    }

    /// Whether the segments touch: closer than `reach`, and their closest
    /// points apart (so the push has a direction).
    #[inline]
    pub fn within(&self, reach: T) -> bool {
        self.distance < reach && self.distance > T::zero()
    }
}

/// [`self_contact_forces`] from the pair's closest points.
#[inline]
pub fn self_contact_push<T: Real>(closest: &Closest<T>, reach: T, k: T) -> Option<[V3<T>; 4]> {
    let Closest { gap, distance: d, s, t } = *closest;
    if !closest.within(reach) {
        return None;
    }
    let push = gap * (k * push_depth(reach - d, reach) / d);
    let (p_share, q_share) = (push * s, push * t);
    Some([push - p_share, p_share, q_share - push, -q_share])
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
    /// rounding (∝ 1/ε); the scale is the element's size. The difference
    /// is Richardson-extrapolated from steps ε and ε/2, which cancels the
    /// ε² truncation that alone exceeded the tolerance on rare tight
    /// configurations where the force was right.
    fn numeric_gradient(points: &[P], energy: impl Fn(&[P]) -> f64) -> Vec<P> {
        let eps = fd_step(points);
        let central = |i: usize, k: usize, h: f64| {
            let mut plus = points.to_vec();
            let mut minus = points.to_vec();
            plus[i][k] += h;
            minus[i][k] -= h;
            (energy(&plus) - energy(&minus)) / (2.0 * h)
        };
        (0..points.len())
            .map(|i| P::from_fn(|k, _| (4.0 * central(i, k, eps / 2.0) - central(i, k, eps)) / 3.0))
            .collect()
    }

    /// The finite-difference step for `points`.
    fn fd_step(points: &[P]) -> f64 {
        f64::EPSILON.cbrt() * points.iter().map(|p| p.norm()).fold(1.0, f64::max)
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
        fn closest_parameters_are_the_closest_points(p0 in point(), p1 in point(), q0 in point(), q1 in point()) {
            let (s, t) = closest_parameters(&p0, &p1, &q0, &q1);
            let at = |s: f64, t: f64| (p0 + (p1 - p0) * s - q0 - (q1 - q0) * t).norm();
            let best = (0..=100).flat_map(|i| (0..=100).map(move |j| (f64::from(i) / 100.0, f64::from(j) / 100.0)))
                .map(|(s, t)| at(s, t)).fold(f64::INFINITY, f64::min);
            prop_assert!((0.0..=1.0).contains(&s) && (0.0..=1.0).contains(&t));
            // Segments within 1e-3 rad of parallel (the determinant below
            // 1e-6 of a·e) are taken as parallel: exact for parallel ones,
            // off for the others by at most the tilt, sin φ, times their
            // lengths.
            let (u, v) = (p1 - p0, q1 - q0);
            let det = u.norm_squared() * v.norm_squared() - u.dot(&v).powi(2);
            let parallel = det <= 1e-6 * u.norm_squared() * v.norm_squared();
            let slack = if parallel { u.cross(&v).norm() / (u.norm() * v.norm()) * (u.norm() + v.norm()) } else { 0.0 };
            prop_assert!(at(s, t) <= best + 1e-9 + slack, "({s}, {t}) gives {} but the grid finds {best}", at(s, t));
        }

        #[test]
        fn self_contact_force_is_minus_gradient(p0 in point(), p1 in point(), q0 in point(), q1 in point(), k in 1.0..1000.0f64) {
            let (u, v) = ((p1 - p0).normalize(), (q1 - q0).normalize());
            let (s, t) = closest_parameters(&p0, &p1, &q0, &q1);
            let d = (p0 + (p1 - p0) * s - q0 - (q1 - q0) * t).norm();
            // Off the parallel pairs, whose closest points are not unique,
            // and the touching ones, where the direction is undefined.
            prop_assume!((p1 - p0).norm() > 0.1 && (q1 - q0).norm() > 0.1 && u.cross(&v).norm() > 0.05 && d > 0.05);
            // And off the pairs whose stencil moves a closest point onto or
            // off a segment's end: there the energy is only C1, and the
            // difference across the switch is off by O(ε).
            let ends = |p: &[P]| {
                let (s, t) = closest_parameters(&p[0], &p[1], &p[2], &p[3]);
                [s == 0.0, s == 1.0, t == 0.0, t == 1.0]
            };
            let points = [p0, p1, q0, q1];
            let eps = fd_step(&points);
            prop_assume!((0..12).all(|dof| [-eps, eps].iter().all(|&h| {
                let mut moved = points;
                moved[dof / 3][dof % 3] += h;
                ends(&moved) == ends(&points)
            })));
            let reach = d + 1.0;
            let forces = self_contact_forces(&p0, &p1, &q0, &q1, reach, k).expect("within reach");
            assert_force_is_minus_gradient(&[p0, p1, q0, q1], &forces, |p| {
                self_contact_energy(&p[0], &p[1], &p[2], &p[3], reach, k)
            });
        }
        #[test]
        fn gravity_force_is_minus_gradient(x in point(), m in 1e-3..1.0f64, g in -20.0..20.0f64) {
            assert_force_is_minus_gradient(&[x], &[gravity_force(m, g)], |p| gravity_energy(&p[0], m, g));
        }
    }

    /// Within the onset, where the push ramps up, the force is still the
    /// energy's gradient, and at the onset the push and its stiffness run
    /// on without a jump (the energy is C2).
    #[test]
    fn self_contact_ramps_up_smoothly_over_the_onset() {
        let (p0, p1) = (P::new(-1.0, 0.0, 0.0), P::new(1.0, 0.0, 0.0));
        let (q0, q1) = (P::new(0.1, 1.0, -1.0), P::new(-0.2, 1.0, 1.0));
        let (reach, k) = (1.8, 800.0);
        let onset = reach * CONTACT_ONSET;
        for depth in [0.2 * onset, 0.7 * onset, 1.5 * onset] {
            let shift = P::new(0.0, reach - depth - 1.0, 0.0);
            let (q0, q1) = (q0 + shift, q1 + shift);
            let forces = self_contact_forces(&p0, &p1, &q0, &q1, reach, k).expect("within reach");
            assert!(((forces[0] + forces[1]).norm() - k * push_depth(depth, reach)).abs() < 1e-9, "depth {depth}");
            assert_force_is_minus_gradient(&[p0, p1, q0, q1], &forces, |p| {
                self_contact_energy(&p[0], &p[1], &p[2], &p[3], reach, k)
            });
        }
        let (below, above) = (onset * (1.0 - 1e-9), onset * (1.0 + 1e-9));
        assert!((push_depth(above, reach) - push_depth(below, reach)).abs() < 1e-9);
        assert!((self_contact_stiffness(above, reach, k) - self_contact_stiffness(below, reach, k)).abs() < 1e-5 * k);
        assert_eq!(push_depth(0.0, reach), 0.0);
        assert_eq!(self_contact_stiffness(0.0, reach, k), 0.0);
        assert_eq!(self_contact_stiffness(3.0 * onset, reach, k), k);
    }

    /// The end-point case: q ends beside the middle of p (a T), so its
    /// closest point is clamped to its end and p's is inside.
    #[test]
    fn self_contact_at_an_end_point_is_minus_gradient() {
        let (p0, p1) = (P::new(-1.0, 0.0, 0.0), P::new(1.2, 0.1, 0.0));
        let (q0, q1) = (P::new(0.3, 0.5, 0.2), P::new(0.1, 2.0, -0.3));
        let (s, t) = closest_parameters(&p0, &p1, &q0, &q1);
        assert!(t == 0.0 && s > 0.0 && s < 1.0, "({s}, {t})");
        let forces = self_contact_forces(&p0, &p1, &q0, &q1, 1.8, 800.0).expect("within reach");
        assert_eq!(forces[3], P::zeros(), "the far end of q carries none of it");
        assert_force_is_minus_gradient(&[p0, p1, q0, q1], &forces, |p| {
            self_contact_energy(&p[0], &p[1], &p[2], &p[3], 1.8, 800.0)
        });
    }

    /// Parallel segments: the closest points are not unique, but any
    /// choice pushes the two apart along their common normal, with no net
    /// force, and its size is the energy's slope along that normal.
    #[test]
    fn self_contact_of_parallel_segments_pushes_along_the_normal() {
        let (p0, p1) = (P::new(0.0, 0.0, 0.0), P::new(2.0, 0.0, 0.0));
        let (q0, q1) = (P::new(0.5, 1.5, 0.0), P::new(3.0, 1.5, 0.0));
        let (reach, k) = (1.8, 800.0);
        let f = self_contact_forces(&p0, &p1, &q0, &q1, reach, k).expect("within reach");
        let total_p = f[0] + f[1];
        assert!((total_p + f[2] + f[3]).norm() < 1e-12, "net force {:?}", total_p + f[2] + f[3]);
        assert!(total_p.x.abs() < 1e-12 && total_p.z.abs() < 1e-12 && total_p.y < 0.0, "{total_p:?}");
        let eps = 1e-6;
        let apart = |dy: f64| {
            let shift = P::new(0.0, dy, 0.0);
            self_contact_energy(&p0, &p1, &(q0 + shift), &(q1 + shift), reach, k)
        };
        let slope = (apart(eps) - apart(-eps)) / (2.0 * eps);
        assert!((-(f[2] + f[3]).y - slope).abs() < 1e-6 * slope.abs(), "force {:?} vs slope {slope}", f[2] + f[3]);
        // 0.3 deep, past the onset ε: ½ k (δ − ε/2)² + k ε²/24.
        let onset = reach * CONTACT_ONSET;
        assert!((0.5 * k * (0.3 - onset / 2.0).powi(2) + k * onset * onset / 24.0 - apart(0.0)).abs() < 1e-12);
    }

    #[test]
    fn self_contact_is_zero_out_of_reach() {
        let (p0, p1) = (P::new(0.0, 0.0, 0.0), P::new(1.0, 0.0, 0.0));
        let (q0, q1) = (P::new(0.0, 1.8, -1.0), P::new(0.0, 1.8, 1.0));
        assert!(self_contact_forces(&p0, &p1, &q0, &q1, 1.8, 800.0).is_none());
        assert_eq!(self_contact_energy(&p0, &p1, &q0, &q1, 1.8, 800.0), 0.0);
        assert!(self_contact_forces(&p0, &p1, &q0, &q1, 1.81, 800.0).is_some());
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
