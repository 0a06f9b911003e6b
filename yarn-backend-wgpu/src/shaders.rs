//! The WGSL sources: one file per pass under `shaders/`, each loaded with
//! the shared prelude `common.wgsl` in front (WGSL has no includes). The
//! browser build uses these same strings.

/// The prelude every pass starts with: parameters, indexing, and the
/// element formulas.
pub const COMMON: &str = include_str!("../shaders/common.wgsl");

/// A pass's source, prelude first.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Pass {
    /// The file name, for labels and messages.
    pub name: &'static str,
    /// The pass's own WGSL.
    pub body: &'static str,
}

impl Pass {
    /// The full WGSL module: the prelude, then the pass.
    pub fn source(&self) -> String {
        format!("{COMMON}\n{}", self.body)
    }
}

/// Gather mode's forces and damped velocity update (entry points `step`
/// and `forces`).
pub const GATHER: Pass = Pass { name: "gather.wgsl", body: include_str!("../shaders/gather.wgsl") };
/// Fixed-point mode's scatter, then its velocity update (entry points
/// `scatter`, `step` and `forces`).
pub const FIXED: Pass = Pass { name: "fixed.wgsl", body: include_str!("../shaders/fixed.wgsl") };
/// Friction and the move, both modes (entry point `main`).
pub const FRICTION: Pass = Pass { name: "friction.wgsl", body: include_str!("../shaders/friction.wgsl") };
/// Pins (entry point `main`).
pub const PINS: Pass = Pass { name: "pins.wgsl", body: include_str!("../shaders/pins.wgsl") };

/// Every pass, for validation.
pub const ALL: [Pass; 4] = [GATHER, FIXED, FRICTION, PINS];

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// Parse and validate a pass as WebGPU would, with no native-only
    /// capability.
    pub(crate) fn validate(pass: &Pass) -> (naga::Module, naga::valid::ModuleInfo) {
        let module = naga::front::wgsl::parse_str(&pass.source())
            .unwrap_or_else(|e| panic!("{}: {}", pass.name, e.emit_to_string(&pass.source())));
        let info = naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::empty())
            .validate(&module)
            .unwrap_or_else(|e| panic!("{}: {}", pass.name, e.emit_to_string(&pass.source())));
        (module, info)
    }

    #[test]
    fn every_pass_validates_without_native_capabilities() {
        for pass in ALL {
            let (module, _) = validate(&pass);
            assert!(!module.entry_points.is_empty(), "{} has no entry point", pass.name);
        }
    }

    #[test]
    fn a_broken_pass_is_caught() {
        let broken = Pass { name: "broken.wgsl", body: "fn f() -> f32 { return undefined_name; }" };
        assert!(naga::front::wgsl::parse_str(&broken.source()).is_err());
    }
}
