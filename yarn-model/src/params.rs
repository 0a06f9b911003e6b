//! Model and solver parameters (SPEC §1, paper Table 1), their validation,
//! and the derived stability bound.

/// Model and solver parameters. Lengths are model units (yarn radius 0.9),
/// time is seconds.
///
/// ```
/// use yarn_model::{Params, ParamError};
///
/// let p = Params::default();
/// assert!(p.substep < p.stability_bound());
/// // Above about half the analytic bound the step diverges, so it is refused.
/// let too_big = Params { substep: 0.6 * p.stability_bound(), ..p };
/// assert!(matches!(too_big.validate(), Err(ParamError::SubstepUnstable { .. })));
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Params {
    /// Stretch stiffness k_s of each yarn segment. Large, because real yarn
    /// barely stretches; raising it shrinks the stable substep as
    /// 1/sqrt(k_s) (default: 800).
    pub stretch_stiffness: f64,
    /// Bending stiffness k_b about the rest turning angle. Raise it for a
    /// stiffer, springier yarn (default: 6).
    pub bend_stiffness: f64,
    /// Rest-curl fraction κ in [0, 1]: the yarn wants κ times its assembled
    /// turning angle. 1 gives a dead, flat patch; lower values store more
    /// bending and curl the free edges harder (default: 0.55).
    pub rest_curl: f64,
    /// Contact tether stiffness k_c holding each crossing near its rest
    /// separation. Lower it for looser, slidier knit (default: 250).
    pub contact_stiffness: f64,
    /// Coulomb friction coefficient μ at compressed contacts (and at
    /// stretched ones with [`Params::friction_in_tension`]) and at
    /// self-contacts. 0 turns the friction pass off (default: 0.3).
    pub friction: f64,
    /// Whether a stretched contact has friction too, sized by how far it
    /// is stretched as a compressed one is by how far it is compressed
    /// ([`crate::step::friction_change`]). A contact stands for two loops
    /// hooked through each other, and a hook pulled apart presses its
    /// yarns together at the crossing. Off, only compressed contacts have
    /// friction, as in the paper (SPEC §4 step 3). On, a free 4x4 patch
    /// with self-contact at μ = 1 comes nearly to rest where it otherwise
    /// keeps rolling (docs/self-contact.md) (default: off).
    pub friction_in_tension: bool,
    /// Viscous damping rate β in 1/s, applied implicitly. Higher settles
    /// faster but slows all motion (default: 10).
    pub damping: f64,
    /// Mass m of each node. Lighter nodes need a smaller substep (default: 0.005).
    pub mass: f64,
    /// Substep h in seconds. Must stay below [`Params::substep_limit`] ×
    /// [`Params::stability_bound`] (0.49 of it by default);
    /// smaller is more accurate and slower (default: 0.000666667).
    pub substep: f64,
    /// Gravity g along −y in model units per s². 0 for the gate; set it to
    /// drape a pinned fabric (default: 0).
    pub gravity: f64,
    /// The largest substep [`Params::validate`] accepts, as a fraction of
    /// the analytic bound 2/ω_max, in (0, 1] (default: 0.49, which is
    /// [`STABLE_FRACTION`], the measured one). Raise it only to explore
    /// instability, as `yarn-gate stress` does.
    pub substep_limit: f64,
    /// Sleeping (CPU backends): a block of nodes whose speeds all stay
    /// below this for [`SLEEP_AFTER`] substeps, its fastest never faster
    /// than when the run began (a block speeding up is not settling),
    /// stops being integrated until
    /// a neighbouring block moves at twice this speed, a pin lands in it,
    /// or the parameters, state or contacts change. 0 never sleeps
    /// (default: 0).
    pub sleep_speed: f64,
    /// Self-contact stiffness k_sc: two segments of yarn whose closest
    /// distance is under one yarn diameter 2r ([`crate::self_contact`])
    /// are pushed apart with a stiffness that ramps from 0 to k_sc over the
    /// first r/8 of depth and is k_sc beyond
    /// ([`crate::terms::self_contact_energy`]). 0 turns self-contact off. Every backend
    /// runs it but `wgpu`'s fixed point. 1,600 (twice k_s) held a folded
    /// patch dropped on a floor to 1.82 r at worst (`yarn-gate drape`)
    /// (default: 0).
    pub self_contact_stiffness: f64,
    /// The skin of the self-contact candidate lists, in yarn radii: a list
    /// holds the pairs within 2r plus this, and is rebuilt once some node
    /// has moved half of it. Larger rebuilds less often but checks more
    /// pairs each substep (default: 0.5).
    pub self_contact_skin: f64,
    /// Collider stiffness k_col: a node whose centreline comes closer than
    /// the yarn radius r to a collider's surface is pushed out with the
    /// energy ½ k_col δ² of its depth δ ([`crate::Collider`]). Stiffer
    /// holds the yarn closer to r but, once colliders are set, shrinks the
    /// stable substep when it passes k_s (default: 800).
    pub collider_stiffness: f64,
}

/// Substeps a block must stay below [`Params::sleep_speed`], and not speed
/// up, before it sleeps.
pub const SLEEP_AFTER: u32 = 100;

/// The fraction of the analytic bound 2/ω_max below which the explicit
/// step is stable, as measured: `yarn-gate stress` found the largest stable
/// substep at 0.501–0.528 × 2/ω_max (bisected to ±0.004) for k_s, k_c, k_b
/// and the mass each scaled 0.25x to 4x, on every backend, with kicked and
/// pulled patches. The reason is the chain: neighbouring nodes swinging
/// against each other load two springs at once, a mode at twice ω_max, so
/// the step's bound is about 2/(2ω_max). 0.49 keeps clear of the lowest
/// measurement.
pub const STABLE_FRACTION: f64 = 0.49;

impl Default for Params {
    /// The default model. It is the paper's ([`Params::paper`]) until a
    /// later change to the model departs from it (SPEC §7).
    fn default() -> Self {
        Self::paper()
    }
}

impl Params {
    /// The `paper` preset: the paper's Table 1 parameters (SPEC §1), with
    /// gravity off as its gate runs them (SPEC §6). It keeps reproducing the
    /// paper's figures whatever the default model becomes.
    pub fn paper() -> Self {
        Self {
            // Paper Table 1: stiff enough that loops unbend before yarn stretches.
            stretch_stiffness: 800.0,
            bend_stiffness: 6.0,
            // The paper's "lively curl of real jersey".
            rest_curl: 0.55,
            contact_stiffness: 250.0,
            friction: 0.3,
            // The paper's friction acts only where a contact is compressed.
            friction_in_tension: false,
            // Table 1's value; the paper's §7 prints 6, which SPEC §1 marks as an error.
            damping: 10.0,
            mass: 5e-3,
            // 1/1500 s: ωh ≈ 0.27 at the stiffest spring, well inside the bound.
            substep: 1.0 / 1500.0,
            // The gate measures the yarn alone (SPEC §6).
            gravity: 0.0,
            substep_limit: STABLE_FRACTION,
            sleep_speed: 0.0,
            // The paper's model has no self-contact.
            self_contact_stiffness: 0.0,
            self_contact_skin: 0.5,
            // As stiff as the yarn's stretch, so a floor never lowers the
            // stability bound; colliders exist only where a scene sets them.
            collider_stiffness: 800.0,
        }
    }
}

/// Why a [`Params`] value was refused. Each variant names the field and the
/// valid range or bound.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ParamError {
    /// A field is NaN or infinite.
    #[error("parameter `{name}` is {value}; it must be a finite number")]
    NotFinite {
        /// Field name.
        name: &'static str,
        /// The rejected value.
        value: f64,
    },
    /// A field is outside its valid range.
    #[error("parameter `{name}` is {value}; it must be {valid}")]
    OutOfRange {
        /// Field name.
        name: &'static str,
        /// The rejected value.
        value: f64,
        /// The valid range, in words.
        valid: &'static str,
    },
    /// The substep is at or above the stable limit: [`STABLE_FRACTION`] (or
    /// [`Params::substep_limit`]) of the analytic bound.
    #[error(
        "substep {substep} s is not below {bound} s, the stable limit: {limit_note}; use a smaller substep, a larger mass or softer springs",
        limit_note = limit_note(*bound, *analytic)
    )]
    SubstepUnstable {
        /// The rejected substep.
        substep: f64,
        /// The limit it must stay below.
        bound: f64,
        /// The analytic bound 2/ω_max (ω_max from the stiffest element).
        analytic: f64,
    },
}

/// Why the stable limit is where it is, for [`ParamError::SubstepUnstable`].
fn limit_note(bound: f64, analytic: f64) -> String {
    let fraction = bound / analytic;
    if (fraction - STABLE_FRACTION).abs() < 1e-12 {
        format!(
            "{STABLE_FRACTION} of the analytic 2/ω_max = {analytic} s, since a chain of springs swings at \
             twice ω_max (`yarn-gate stress` measured divergence above 0.50–0.53 of it)"
        )
    } else {
        format!("{fraction} (`substep_limit`) of the analytic 2/ω_max = {analytic} s")
    }
}

impl Params {
    /// ω_max = sqrt(k_max / m) for the stiffest element, in 1/s (SPEC §1).
    ///
    /// k_max is the largest of the stretch, contact and self-contact
    /// stiffnesses (a self-contact's push, shared by the two nodes of each
    /// segment, loads no node with more than k_sc); the colliders' counts
    /// only where some are set ([`Params::validate_with_colliders`]). Bending
    /// acts as a stiffness near k_b/ℓ², which depends on segment lengths and
    /// is far below k_s at the default gauge, so it is left out.
    pub fn omega_max(&self) -> f64 {
        let k_max =
            [self.contact_stiffness, self.self_contact_stiffness].into_iter().fold(self.stretch_stiffness, f64::max);
        (k_max / self.mass).sqrt()
    }

    /// [`Params::stability_bound`] with the collider stiffness among the
    /// elements: the bound that holds once a collider is set. A scene
    /// without colliders is not held to it.
    pub fn stability_bound_with_colliders(&self) -> f64 {
        2.0 / (self
            .collider_stiffness
            .max(self.stretch_stiffness.max(self.contact_stiffness).max(self.self_contact_stiffness))
            / self.mass)
            .sqrt()
    }

    /// Check that the substep is stable against the colliders' stiffness
    /// too, as [`Params::validate`] does against the yarn's: below
    /// [`Params::substep_limit`] of [`Params::stability_bound_with_colliders`].
    ///
    /// # Errors
    /// [`ParamError::SubstepUnstable`] naming that bound.
    pub fn validate_with_colliders(&self) -> Result<(), ParamError> {
        let analytic = self.stability_bound_with_colliders();
        let bound = self.substep_limit * analytic;
        if self.substep >= bound {
            return Err(ParamError::SubstepUnstable { substep: self.substep, bound, analytic });
        }
        Ok(())
    }

    /// The explicit stability bound h < 2/ω_max, in seconds (SPEC §1).
    pub fn stability_bound(&self) -> f64 {
        2.0 / self.omega_max()
    }

    /// The largest substep [`Params::validate`] accepts:
    /// [`Params::substep_limit`] × [`Params::stability_bound`].
    pub fn stable_limit(&self) -> f64 {
        self.substep_limit * self.stability_bound()
    }

    /// Check every field, then the substep against
    /// [`Params::substep_limit`] × [`Params::stability_bound`].
    ///
    /// # Errors
    /// The first [`ParamError`] found, in field order.
    pub fn validate(&self) -> Result<(), ParamError> {
        use Valid::*;
        let fields = [
            ("stretch_stiffness", self.stretch_stiffness, Positive),
            ("bend_stiffness", self.bend_stiffness, NonNegative),
            ("rest_curl", self.rest_curl, Fraction),
            ("contact_stiffness", self.contact_stiffness, NonNegative),
            ("friction", self.friction, NonNegative),
            ("damping", self.damping, NonNegative),
            ("mass", self.mass, Positive),
            ("substep", self.substep, Positive),
            ("gravity", self.gravity, Any),
            ("substep_limit", self.substep_limit, Fraction),
            ("sleep_speed", self.sleep_speed, NonNegative),
            ("self_contact_stiffness", self.self_contact_stiffness, NonNegative),
            ("self_contact_skin", self.self_contact_skin, Positive),
            ("collider_stiffness", self.collider_stiffness, Positive),
        ];
        for (name, value, valid) in fields {
            if !value.is_finite() {
                return Err(ParamError::NotFinite { name, value });
            }
            if !valid.contains(value) {
                return Err(ParamError::OutOfRange { name, value, valid: valid.describe() });
            }
        }
        let bound = self.stable_limit();
        if self.substep >= bound {
            return Err(ParamError::SubstepUnstable { substep: self.substep, bound, analytic: self.stability_bound() });
        }
        Ok(())
    }
}

/// The valid range of one parameter.
#[derive(Clone, Copy)]
enum Valid {
    Positive,
    NonNegative,
    Fraction,
    Any,
}

impl Valid {
    fn contains(self, value: f64) -> bool {
        match self {
            Valid::Positive => value > 0.0,
            Valid::NonNegative => value >= 0.0,
            Valid::Fraction => (0.0..=1.0).contains(&value),
            Valid::Any => true,
        }
    }

    fn describe(self) -> &'static str {
        match self {
            Valid::Positive => "greater than 0",
            Valid::NonNegative => "0 or greater",
            Valid::Fraction => "between 0 and 1",
            Valid::Any => "any finite number",
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The "(default: X)" in each field's doc must match `Default`: the docs
    /// are what users read, so they must not drift.
    #[test]
    fn documented_defaults_match_default() {
        let source = include_str!("params.rs");
        let defaults = Params::default();
        let actual = [
            ("stretch_stiffness", defaults.stretch_stiffness),
            ("bend_stiffness", defaults.bend_stiffness),
            ("rest_curl", defaults.rest_curl),
            ("contact_stiffness", defaults.contact_stiffness),
            ("friction", defaults.friction),
            ("damping", defaults.damping),
            ("mass", defaults.mass),
            ("substep", defaults.substep),
            ("gravity", defaults.gravity),
            ("substep_limit", defaults.substep_limit),
            ("sleep_speed", defaults.sleep_speed),
            ("self_contact_stiffness", defaults.self_contact_stiffness),
            ("self_contact_skin", defaults.self_contact_skin),
            ("collider_stiffness", defaults.collider_stiffness),
        ];
        let mut doc = String::new();
        let mut checked = 0;
        for line in source.lines().map(str::trim) {
            if let Some(text) = line.strip_prefix("///") {
                doc.push_str(text);
                continue;
            }
            if let Some(field) = line.strip_prefix("pub ").and_then(|l| l.split(':').next())
                && let Some(&(_, value)) = actual.iter().find(|(name, _)| *name == field)
            {
                let documented: f64 = doc
                    .split("(default: ")
                    .nth(1)
                    .and_then(|rest| rest.split([')', ',']).next())
                    .unwrap_or_else(|| panic!("`{field}` has no (default: X) in its doc"))
                    .parse()
                    .unwrap();
                let tolerance = 1e-6 * value.abs().max(1e-300);
                assert!(
                    (documented - value).abs() <= tolerance,
                    "`{field}`: doc says {documented}, Default is {value}"
                );
                checked += 1;
            }
            doc.clear();
        }
        assert_eq!(checked, actual.len(), "every field's documented default was checked");
    }

    #[test]
    fn defaults_are_valid_and_bound_matches_paper() {
        let p = Params::default();
        p.validate().unwrap();
        // Paper §7: ω ≈ 400 1/s for k_s = 800, m = 5e-3, so 2/ω = 5e-3 s.
        assert!((p.omega_max() - 400.0).abs() < 1e-9);
        assert!((p.stability_bound() - 5e-3).abs() < 1e-12);
    }

    #[test]
    fn validation_names_field_and_bound() {
        let p = Params::default();
        assert!(matches!(Params { mass: f64::NAN, ..p }.validate(), Err(ParamError::NotFinite { name: "mass", .. })));
        assert!(matches!(
            Params { stretch_stiffness: 0.0, ..p }.validate(),
            Err(ParamError::OutOfRange { name: "stretch_stiffness", .. })
        ));
        assert!(matches!(
            Params { friction: -0.1, ..p }.validate(),
            Err(ParamError::OutOfRange { name: "friction", .. })
        ));
        assert!(matches!(
            Params { rest_curl: 1.5, ..p }.validate(),
            Err(ParamError::OutOfRange { name: "rest_curl", .. })
        ));
        assert!(matches!(
            Params { gravity: f64::INFINITY, ..p }.validate(),
            Err(ParamError::NotFinite { name: "gravity", .. })
        ));
        match (Params { substep: 0.003, ..p }).validate() {
            Err(e @ ParamError::SubstepUnstable { substep, bound, analytic }) => {
                assert_eq!(substep, 0.003);
                assert!((bound - 2.45e-3).abs() < 1e-12 && (analytic - 5e-3).abs() < 1e-12);
                assert!(e.to_string().contains("twice ω_max"), "{e}");
            }
            other => panic!("expected SubstepUnstable, got {other:?}"),
        }
        // Exploring past the measured limit is allowed up to the analytic one.
        Params { substep: 0.003, substep_limit: 1.0, ..p }.validate().unwrap();
        assert!(Params { substep: 0.006, substep_limit: 1.0, ..p }.validate().is_err());
        assert!(Params { substep_limit: 1.5, ..p }.validate().is_err());
        // A self-contact stiffer than the springs sets the bound.
        let stiff = Params { self_contact_stiffness: 4.0 * p.stretch_stiffness, ..p };
        assert!((stiff.stability_bound() - 0.5 * p.stability_bound()).abs() < 1e-12);
        assert!(matches!(
            Params { self_contact_skin: 0.0, ..p }.validate(),
            Err(ParamError::OutOfRange { name: "self_contact_skin", .. })
        ));
        // Zero friction, damping and bending are legitimate scenes.
        Params { friction: 0.0, damping: 0.0, bend_stiffness: 0.0, ..p }.validate().unwrap();
    }
}
