//! The scalar type a backend computes in: `f32` for speed and GPU parity,
//! `f64` for the ground truth (SPEC §4).

use std::fmt::{Debug, Display};

/// A 3-vector in a backend's precision.
pub type V3<T> = nalgebra::Vector3<T>;

/// A floating-point scalar the model can be evaluated in: `f32` or `f64`.
pub trait Real: nalgebra::RealField + Copy + Default + Debug + Display + bytemuck::Pod + Send + Sync + 'static {
    /// Short name for reports: `"f32"` or `"f64"`.
    const NAME: &'static str;
    /// Convert from `f64`, rounding to nearest.
    fn of(x: f64) -> Self;
    /// Convert to `f64` exactly.
    fn to_f64(self) -> f64;
}

impl Real for f32 {
    const NAME: &'static str = "f32";
    fn of(x: f64) -> Self {
        x as f32
    }
    fn to_f64(self) -> f64 {
        f64::from(self)
    }
}

impl Real for f64 {
    const NAME: &'static str = "f64";
    fn of(x: f64) -> Self {
        x
    }
    fn to_f64(self) -> f64 {
        self
    }
}

/// Convert a vector between precisions.
pub(crate) fn cast<T: Real>(v: &nalgebra::Vector3<f64>) -> V3<T> {
    V3::new(T::of(v.x), T::of(v.y), T::of(v.z))
}

/// A vector in `f64`, exactly.
pub fn widen<T: Real>(v: &V3<T>) -> nalgebra::Vector3<f64> {
    nalgebra::Vector3::new(v.x.to_f64(), v.y.to_f64(), v.z.to_f64())
}
