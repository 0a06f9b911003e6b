//! The WGSL sources: one file per pass under `shaders/`, each loaded with
//! the shared prelude `common.wgsl` in front (WGSL has no includes). The
//! browser build uses these same strings.

/// The prelude every pass starts with: parameters, indexing, and the
/// element formulas.
pub const COMMON: &str = include_str!("../shaders/common.wgsl");

/// One node's total force, for the passes that gather.
pub const NODE_FORCE: &str = include_str!("../shaders/node_force.wgsl");
/// The node update both accumulation modes share (entry points `step` and
/// `forces`), around the mode's `total_force`.
pub const UPDATE: &str = include_str!("../shaders/update.wgsl");
/// One node's sum of friction changes.
pub const NODE_FRICTION: &str = include_str!("../shaders/node_friction.wgsl");
/// The self-contact candidate lists' layout and the closest points of two
/// segments.
pub const LISTS: &str = include_str!("../shaders/lists.wgsl");
/// Self-contact: the pair forces and friction, summed over the lists.
pub const TOUCH: &str = include_str!("../shaders/touch.wgsl");
/// Self-contact: each moved node's watch on its anchor.
pub const WATCH: &str = include_str!("../shaders/watch.wgsl");
/// The candidate grid's layout and hashing.
pub const GRID: &str = include_str!("../shaders/grid.wgsl");

/// A pass: its own file, and the shared functions it calls.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Pass {
    /// The file name, for labels and messages.
    pub name: &'static str,
    /// Shared functions it calls, in order, after the prelude.
    pub uses: &'static [&'static str],
    /// The pass's own WGSL.
    pub body: &'static str,
}

impl Pass {
    /// The full WGSL module: the prelude, the shared functions, the pass.
    pub fn source(&self) -> String {
        let mut source = String::from(COMMON);
        for part in self.uses.iter().chain([&self.body]) {
            source.push('\n');
            source.push_str(part);
        }
        source
    }
}

/// Gather mode's forces and damped velocity update (entry points `step`
/// and `forces`, and with self-contact `step_touching` and
/// `forces_touching`).
pub const GATHER: Pass = Pass {
    name: "gather.wgsl",
    uses: &[NODE_FORCE, LISTS, TOUCH, WATCH, UPDATE],
    body: include_str!("../shaders/gather.wgsl"),
};
/// Fixed-point mode's scatter, then its velocity update (entry points
/// `scatter`, `step` and `forces`).
pub const FIXED: Pass = Pass { name: "fixed.wgsl", uses: &[UPDATE], body: include_str!("../shaders/fixed.wgsl") };
/// Friction and the move, both modes (entry point `main`, and with
/// self-contact and friction `main_touching`).
pub const FRICTION: Pass = Pass {
    name: "friction.wgsl",
    uses: &[NODE_FRICTION, LISTS, TOUCH, WATCH],
    body: include_str!("../shaders/friction.wgsl"),
};
/// Pins (entry point `main`).
pub const PINS: Pass = Pass { name: "pins.wgsl", uses: &[LISTS, WATCH], body: include_str!("../shaders/pins.wgsl") };

/// Gather mode's whole substep with friction, in one dispatch (entry
/// point `main`).
pub const FUSED: Pass = Pass { name: "fused.wgsl", uses: &[NODE_FORCE], body: include_str!("../shaders/fused.wgsl") };

/// Re-seated contacts closing (entry point `main`).
pub const RESEAT: Pass = Pass { name: "reseat.wgsl", uses: &[], body: include_str!("../shaders/reseat.wgsl") };

/// The divergence check at the end of a batch (entry point `main`).
pub const CHECK: Pass = Pass { name: "check.wgsl", uses: &[LISTS], body: include_str!("../shaders/check.wgsl") };

/// Whether the self-contact lists are rebuilt this substep (entry point
/// `main`, one thread).
pub const PLAN: Pass = Pass { name: "plan.wgsl", uses: &[LISTS, GRID], body: include_str!("../shaders/plan.wgsl") };

/// A rebuild's first pass: segments into the grid (entry point `main`).
pub const GRID_INSERT: Pass =
    Pass { name: "grid_insert.wgsl", uses: &[LISTS, GRID], body: include_str!("../shaders/grid_insert.wgsl") };

/// A rebuild's second pass: each segment's sorted candidates (entry point
/// `main`).
pub const GRID_FIND: Pass =
    Pass { name: "grid_find.wgsl", uses: &[LISTS, GRID], body: include_str!("../shaders/grid_find.wgsl") };

/// A plain copy, to measure bandwidth (entry point `main`).
pub const COPY: Pass = Pass { name: "copy.wgsl", uses: &[], body: include_str!("../shaders/copy.wgsl") };

/// Whether the device's `fma` is fused (entry point `main`).
pub const FMA_TEST: Pass = Pass { name: "fma_test.wgsl", uses: &[], body: include_str!("../shaders/fma_test.wgsl") };

/// Every pass, for validation.
pub const ALL: [Pass; 12] =
    [GATHER, FIXED, FRICTION, PINS, FUSED, RESEAT, CHECK, PLAN, GRID_INSERT, GRID_FIND, COPY, FMA_TEST];

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
        let broken = Pass { name: "broken.wgsl", uses: &[], body: "fn f() -> f32 { return undefined_name; }" };
        assert!(naga::front::wgsl::parse_str(&broken.source()).is_err());
    }
}
