//! Colliders: static solids the yarn rests on and cannot pass, and the
//! penalty and friction they exert on each node.
//!
//! A node is pushed out of a collider when its centreline comes closer
//! than the yarn radius r to the collider's surface, with the energy
//! ½ k_col δ² of its depth δ ([`crate::Params::collider_stiffness`]), and
//! its slip along the surface is filtered by Coulomb friction with the
//! collider's own coefficient, as the persistent contacts' is (SPEC §4
//! step 3). Only a plane exists so far; [`Collider`] is an enum so that
//! spheres, capsules and meshes can join it, each with its own
//! [`Surface::height`].
//!
//! This module owns the shapes, their validation and the per-node term; the
//! backends own where it runs.

use crate::{Real, V3};

/// A static solid the fabric collides with, given in `f64` model units.
///
/// ```
/// use yarn_model::{Collider, Plane};
/// use yarn_topology::Vec3;
///
/// let floor = Collider::Plane(Plane::floor(-2.0));
/// assert!(floor.validate().is_ok());
/// let tilted = Plane { normal: Vec3::new(0.0, 0.0, 0.0), ..Plane::floor(0.0) };
/// assert!(Collider::Plane(tilted).validate().is_err());
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
#[non_exhaustive]
pub enum Collider {
    /// An infinite plane with a slab of solid behind it.
    Plane(Plane),
}

/// A plane: the surface through `point` facing along `normal`, with solid
/// `thickness` deep behind it. A node deeper than the slab is on the far
/// side and is left alone, so yarn that starts below a floor is not shot
/// up through it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plane {
    /// A point on the surface.
    pub point: yarn_topology::Vec3,
    /// The direction the surface faces; any length but zero.
    pub normal: yarn_topology::Vec3,
    /// How deep the solid reaches behind the surface, in model units
    /// (positive).
    pub thickness: f64,
    /// Coulomb friction coefficient μ between the yarn and the surface
    /// (non-negative).
    pub friction: f64,
}

impl Plane {
    /// A floor facing up (+y) at height `y`, ten units thick, with the
    /// yarn's default friction.
    pub fn floor(y: f64) -> Self {
        Self {
            point: yarn_topology::Vec3::new(0.0, y, 0.0),
            normal: yarn_topology::Vec3::new(0.0, 1.0, 0.0),
            thickness: 10.0,
            friction: crate::Params::default().friction,
        }
    }
}

/// Why a collider was refused. Each variant names the collider (its index
/// in the list given) and what to fix.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ColliderError {
    /// A coordinate or value is NaN or infinite.
    #[error("collider {index}: `{field}` is not finite; give finite numbers")]
    NotFinite {
        /// The collider's index.
        index: usize,
        /// Which field.
        field: &'static str,
    },
    /// A plane's normal has zero length, so it faces nowhere.
    #[error("collider {index}: the plane's normal is zero; give the direction it faces, e.g. (0, 1, 0) for a floor")]
    ZeroNormal {
        /// The collider's index.
        index: usize,
    },
    /// A value is out of its range.
    #[error("collider {index}: `{field}` is {value}; it must be {valid}")]
    OutOfRange {
        /// The collider's index.
        index: usize,
        /// Which field.
        field: &'static str,
        /// The rejected value.
        value: f64,
        /// The valid range, in words.
        valid: &'static str,
    },
}

impl Collider {
    /// Check the collider's values, as collider `0`.
    ///
    /// # Errors
    /// [`ColliderError`] naming the bad field.
    pub fn validate(&self) -> Result<(), ColliderError> {
        self.validate_as(0)
    }

    fn validate_as(&self, index: usize) -> Result<(), ColliderError> {
        let Collider::Plane(p) = self;
        let finite = |v: &yarn_topology::Vec3| v.iter().all(|c| c.is_finite());
        for (field, ok) in [
            ("point", finite(&p.point)),
            ("normal", finite(&p.normal)),
            ("thickness", p.thickness.is_finite()),
            ("friction", p.friction.is_finite()),
        ] {
            if !ok {
                return Err(ColliderError::NotFinite { index, field });
            }
        }
        if p.normal.norm() == 0.0 {
            return Err(ColliderError::ZeroNormal { index });
        }
        if p.thickness <= 0.0 {
            return Err(ColliderError::OutOfRange { index, field: "thickness", value: p.thickness, valid: "> 0" });
        }
        if p.friction < 0.0 {
            return Err(ColliderError::OutOfRange { index, field: "friction", value: p.friction, valid: ">= 0" });
        }
        Ok(())
    }
}

/// A validated collider as the substep uses it, in the backend's precision:
/// a plane as its unit normal n and offset c (n·x = c on the surface).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Surface<T> {
    /// The unit normal.
    pub normal: V3<T>,
    /// n · (a point on the surface).
    pub offset: T,
    /// Depth of the solid behind the surface.
    pub thickness: T,
    /// Coulomb friction coefficient μ.
    pub friction: T,
}

impl<T: Real> Surface<T> {
    /// Every collider of `colliders` validated and converted.
    ///
    /// # Errors
    /// The first [`ColliderError`], naming its collider's index.
    pub fn all(colliders: &[Collider]) -> Result<Vec<Self>, ColliderError> {
        colliders
            .iter()
            .enumerate()
            .map(|(index, c)| {
                c.validate_as(index)?;
                let Collider::Plane(p) = c;
                let n = p.normal.normalize();
                Ok(Self {
                    normal: V3::new(T::of(n.x), T::of(n.y), T::of(n.z)),
                    offset: T::of(n.dot(&p.point)),
                    thickness: T::of(p.thickness),
                    friction: T::of(p.friction),
                })
            })
            .collect()
    }

    /// The signed height of `x` above the surface, negative inside the
    /// solid, or `None` past the solid's far side.
    #[inline]
    pub fn height(&self, x: &V3<T>) -> Option<T> {
        let height = self.normal.dot(x) - self.offset;
        (height > -self.thickness).then_some(height)
    }

    /// How deep a node at `x` of yarn radius `radius` presses into the
    /// surface (r minus its centreline's [`Surface::height`]), when it does
    /// and is not past the solid's far side.
    #[inline]
    pub fn depth(&self, x: &V3<T>, radius: T) -> Option<T> {
        let depth = radius - self.height(x)?;
        (depth > T::zero()).then_some(depth)
    }

    /// ½ k δ² at `x`.
    #[inline]
    pub fn energy(&self, x: &V3<T>, radius: T, k: T) -> T {
        self.depth(x, radius).map_or(T::zero(), |d| T::of(0.5) * k * d * d)
    }

    /// −∇(½ k δ²) = k δ n at `x`, when it presses in.
    #[inline]
    pub fn force(&self, x: &V3<T>, radius: T, k: T) -> Option<V3<T>> {
        self.depth(x, radius).map(|d| self.normal * (k * d))
    }

    /// The Coulomb friction change to the velocity `v` of a node at `x`
    /// pressing in (SPEC §4 step 3, one node against a fixed surface): its
    /// slip along the surface shrinks by μ h k δ / m, never past zero.
    /// `impulse` is h k / m.
    #[inline]
    pub fn friction_change(&self, x: &V3<T>, v: &V3<T>, radius: T, impulse: T) -> Option<V3<T>> {
        let depth = self.depth(x, radius)?;
        let slip = v - self.normal * self.normal.dot(v);
        let speed = slip.norm();
        if speed <= T::zero() {
            return None;
        }
        let retention = (T::one() - self.friction * impulse * depth / speed).max(T::zero());
        Some(slip * (retention - T::one()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use yarn_topology::Vec3;

    #[test]
    fn bad_planes_are_refused_by_name() {
        let floor = Plane::floor(0.0);
        let bad = |plane: Plane| Surface::<f64>::all(&[Collider::Plane(floor), Collider::Plane(plane)]).unwrap_err();
        assert_eq!(bad(Plane { normal: Vec3::zeros(), ..floor }), ColliderError::ZeroNormal { index: 1 });
        assert_eq!(
            bad(Plane { point: Vec3::new(f64::NAN, 0.0, 0.0), ..floor }),
            ColliderError::NotFinite { index: 1, field: "point" }
        );
        assert_eq!(
            bad(Plane { normal: Vec3::new(0.0, f64::INFINITY, 0.0), ..floor }),
            ColliderError::NotFinite { index: 1, field: "normal" }
        );
        assert!(matches!(bad(Plane { thickness: 0.0, ..floor }), ColliderError::OutOfRange { field: "thickness", .. }));
        assert!(matches!(bad(Plane { friction: -0.1, ..floor }), ColliderError::OutOfRange { field: "friction", .. }));
        let message = bad(Plane { normal: Vec3::zeros(), ..floor }).to_string();
        assert!(message.contains("collider 1") && message.contains("(0, 1, 0)"), "{message}");
    }

    /// The push is −∇ of the energy (central differences), zero above r
    /// and past the slab's far side, and a tilted normal of any length
    /// gives the same surface as its unit vector.
    #[test]
    fn the_push_is_minus_the_gradient_and_stops_at_both_faces() {
        let plane = Plane { normal: Vec3::new(0.3, 2.0, -0.4), thickness: 2.0, ..Plane::floor(1.0) };
        let [surface] = Surface::<f64>::all(&[Collider::Plane(plane)]).unwrap()[..] else { unreachable!() };
        let (r, k) = (0.9, 500.0);
        let n = plane.normal.normalize();
        let on = |height: f64| V3::new(plane.point.x, plane.point.y, plane.point.z) + V3::new(n.x, n.y, n.z) * height;
        for height in [0.3, 0.85, -0.5, -1.9] {
            let x = on(height);
            let f = surface.force(&x, r, k).unwrap();
            let eps = 1e-6;
            for axis in 0..3 {
                let (mut plus, mut minus) = (x, x);
                plus[axis] += eps;
                minus[axis] -= eps;
                let slope = (surface.energy(&plus, r, k) - surface.energy(&minus, r, k)) / (2.0 * eps);
                assert!((f[axis] + slope).abs() < 1e-5 * k, "height {height}, axis {axis}: {} vs {}", f[axis], -slope);
            }
            assert!((surface.height(&x).unwrap() - height).abs() < 1e-12);
        }
        assert_eq!(surface.force(&on(0.95), r, k), None, "above r the yarn does not touch");
        assert_eq!(surface.force(&on(-2.1), r, k), None, "past the slab is the far side");
    }

    /// Friction cuts the slip along the surface by μ h k δ / m, never past
    /// zero, and leaves the normal velocity alone.
    #[test]
    fn friction_cuts_slip_without_reversing_it() {
        let [surface] =
            Surface::<f64>::all(&[Collider::Plane(Plane { friction: 0.5, ..Plane::floor(0.0) })]).unwrap()[..]
        else {
            unreachable!()
        };
        let (r, impulse) = (0.9, 10.0);
        let x = V3::new(0.0, 0.8, 0.0);
        let v = V3::new(3.0, -1.0, 4.0);
        let dv = surface.friction_change(&x, &v, r, impulse).unwrap();
        assert_eq!(dv.y, 0.0);
        let cut = 0.5 * impulse * 0.1;
        assert!(((v + dv).xz().norm() - (5.0 - cut)).abs() < 1e-12);
        let slow = V3::new(0.1, -1.0, 0.0);
        assert_eq!(slow + surface.friction_change(&x, &slow, r, impulse).unwrap(), V3::new(0.0, -1.0, 0.0));
        assert_eq!(surface.friction_change(&V3::new(0.0, 1.0, 0.0), &v, r, impulse), None, "not touching");
    }

    /// A collider stiffer than the yarn tightens the stable substep only
    /// once a collider is set: the model refuses the collider, or later
    /// parameters, whose substep it makes unstable, and keeps what it had.
    #[test]
    fn a_stiff_collider_is_held_to_the_stability_bound_only_when_set() {
        let fabric = yarn_topology::Fabric::from_chart(
            &yarn_topology::Chart::stockinette(2, 2).unwrap(),
            &yarn_topology::Geometry::default(),
        )
        .unwrap();
        let base = crate::Params::default();
        let stiff = crate::Params { collider_stiffness: 100.0 * base.stretch_stiffness, ..base };
        assert_eq!(stiff.stability_bound(), base.stability_bound(), "no collider, no cost");
        let mut model = crate::Model::<f64>::new(&fabric, &stiff).unwrap();
        let floor = [Collider::Plane(Plane::floor(0.0))];
        assert!(matches!(
            model.set_colliders(&floor),
            Err(crate::BackendError::Params(crate::ParamError::SubstepUnstable { .. }))
        ));
        assert!(model.colliders().is_empty());
        model.set_params(&base).unwrap();
        model.set_colliders(&floor).unwrap();
        assert!(model.set_params(&stiff).is_err());
        assert_eq!(model.params(), &base);
    }
}
