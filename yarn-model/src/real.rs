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
    /// arccos of a cosine already clamped to [−1, 1], accurate to this
    /// type's precision. The bending term calls it once per joint per
    /// substep, so `f32` uses a polynomial instead of libm's `acosf`.
    fn turning_angle(self) -> Self;
}

impl Real for f32 {
    const NAME: &'static str = "f32";
    fn of(x: f64) -> Self {
        x as f32
    }
    fn to_f64(self) -> f64 {
        f64::from(self)
    }
    /// Abramowitz & Stegun 4.4.46: acos x = sqrt(1 − x) · p(x) on [0, 1],
    /// |error| ≤ 2e-8, below f32's resolution of angles near π/2; negative
    /// x by acos(−x) = π − acos x. Branch-light, and plain multiply-adds: `mul_add` would call a
    /// software `fmaf` on targets built without FMA. The coefficients are
    /// the published ones, rounded to f32 by the compiler.
    #[allow(clippy::excessive_precision)]
    fn turning_angle(self) -> Self {
        let x = self.abs();
        let p = -0.001_262_491_1_f32;
        let p = p * x + 0.006_670_090_1;
        let p = p * x + -0.017_088_125_6;
        let p = p * x + 0.030_891_881_0;
        let p = p * x + -0.050_174_304_6;
        let p = p * x + 0.088_978_987_4;
        let p = p * x + -0.214_598_801_6;
        let p = p * x + 1.570_796_305_0;
        let angle = (1.0 - x).max(0.0).sqrt() * p;
        if self < 0.0 { std::f32::consts::PI - angle } else { angle }
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
    fn turning_angle(self) -> Self {
        self.acos()
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn f32_turning_angle_matches_acos_to_f32_precision() {
        let worst = (0..=200_000)
            .map(|i| -1.0 + 2.0 * f64::from(i) / 200_000.0)
            .map(|x| ((x as f32).turning_angle() as f64 - (x as f32 as f64).acos()).abs())
            .fold(0.0, f64::max);
        // f32 resolves angles near π to about 2.4e-7; the polynomial adds 2e-8.
        assert!(worst < 5e-7, "worst error {worst:e}");
    }
}
