//! The Rust mirrors of the WGSL structs in `common.wgsl`, uploaded with
//! `bytemuck`. A test checks every size and field offset against naga's
//! layouter, so the two cannot drift apart.

use bytemuck::{Pod, Zeroable};

/// Mirrors `Params`: the parameters and counts every pass reads.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub(crate) struct GpuParams {
    pub(crate) nodes: u32,
    pub(crate) contacts: u32,
    pub(crate) pins: u32,
    pub(crate) flags: u32,
    pub(crate) stretch: f32,
    pub(crate) bend: f32,
    pub(crate) contact: f32,
    pub(crate) friction: f32,
    pub(crate) h: f32,
    pub(crate) h_over_m: f32,
    pub(crate) damping_factor: f32,
    pub(crate) friction_impulse: f32,
    pub(crate) gravity_y: f32,
    pub(crate) min_sin: f32,
    pub(crate) scale: f32,
    pub(crate) max_force: f32,
    /// Always 1.0: see `mul` in `common.wgsl`.
    pub(crate) one: f32,
    /// The divergence speed.
    pub(crate) max_speed: f32,
    /// How far a re-seated contact closes per substep.
    pub(crate) reseat_step: f32,
    /// Entries in the reseat buffer.
    pub(crate) reseats: u32,
    /// Self-contact: k_sc, h k_sc / m, and the reach 2r.
    pub(crate) self_contact: f32,
    pub(crate) self_impulse: f32,
    pub(crate) reach: f32,
    /// The yarn radius r, k_col and h k_col / m.
    pub(crate) radius: f32,
    pub(crate) collider: f32,
    pub(crate) collider_impulse: f32,
    /// The candidate grid: cell edge, 2r plus the skin, half the skin,
    /// buckets − 1, slots per segment's list.
    pub(crate) cell: f32,
    pub(crate) search_reach: f32,
    pub(crate) half_skin: f32,
    pub(crate) mask: u32,
    pub(crate) slots: u32,
    /// How many of `surfaces` are set.
    pub(crate) colliders: u32,
    /// The workgroups of a full rebuild.
    pub(crate) rebuild_x: u32,
    pub(crate) rebuild_y: u32,
    /// The longest segment the grid holds; longer ones are long.
    pub(crate) short: f32,
    /// How far ahead, in seconds, a node's speed is projected when it
    /// decides whether to ask for a rebuild of the lists: none where every
    /// substep may rebuild, [`LOOKAHEAD`] cadences where only every
    /// [`CADENCE`]-th does.
    pub(crate) lookahead: f32,
    pub(crate) surfaces: [GpuSurface; MAX_COLLIDERS],
}

/// The most colliders the GPU holds (`MAX_COLLIDERS` in `common.wgsl`):
/// they ride in the parameters' uniform, so no pass needs another binding.
pub const MAX_COLLIDERS: usize = 8;

/// Mirrors `Surface`: a plane collider as the substep uses it.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default, Pod, Zeroable)]
pub(crate) struct GpuSurface {
    pub(crate) normal: [f32; 3],
    pub(crate) offset: f32,
    pub(crate) thickness: f32,
    pub(crate) friction: f32,
    pub(crate) _pad: [f32; 2],
}

/// `Params::flags` bit: friction is on, so the move is in the friction pass.
pub(crate) const FRICTION_ON: u32 = 1;

/// `Params::flags` bit: the device's `fma` is fused (see `fma_test.wgsl`).
pub(crate) const FUSED_FMA: u32 = 2;

/// `status[0]` bit: a fixed-point force or sum overflowed.
pub(crate) const OVERFLOWED: u32 = 1;

/// `status[0]` bit: a velocity diverged.
pub(crate) const DIVERGED: u32 = 2;

/// `status[0]` bit: more self-contact candidates lay near a segment than
/// its list holds; `status[1]` says how many.
pub(crate) const CROWDED: u32 = 4;

/// `status[0]` bit: yarn stretched past what the candidate grid's search
/// covers.
pub(crate) const STRETCHED: u32 = 8;

/// `status[0]` bit: the pushes ran on self-contact lists that some node
/// had moved half the skin from, which may miss a pair within reach.
pub(crate) const LATE_REBUILD: u32 = 16;

/// Natively, a substep in every `CADENCE` may rebuild the self-contact
/// lists (`plan.wgsl` and the two list passes run then); the others skip
/// those passes, which cost about 4 µs each even when they rebuild nothing
/// (about 13 µs of a 16x16 patch's 48 a substep on an H100).
pub(crate) const CADENCE: u64 = 8;

/// Where only every [`CADENCE`]-th substep may rebuild, a node asks for a
/// rebuild once it has moved half the skin less how far it would go at its
/// speed in this many cadences, so a node that does not speed up before
/// the next substep that may rebuild is not late. Two cadences rebuilt a
/// 16x16 patch dropped at ten times gravity 3.2 times as often as the
/// check at every substep, and one 1.1 times, with no batch late.
pub(crate) const LOOKAHEAD: f32 = 1.0;

/// `Params::flags` bit: self-contact is on.
pub(crate) const SELF_CONTACT: u32 = 4;

/// `Params::flags` bit: stretched contacts have friction too
/// (`yarn_model::Params::friction_in_tension`).
pub(crate) const FRICTION_IN_TENSION: u32 = 8;

/// Mirrors `Contact`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub(crate) struct GpuContact {
    pub(crate) a: u32,
    pub(crate) b: u32,
    pub(crate) rest: f32,
    pub(crate) alive: u32,
}

/// Mirrors `Reseat` in `reseat.wgsl`: a re-seated contact and the slots of
/// its two copies in the per-node lists.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub(crate) struct GpuReseat {
    pub(crate) contact: u32,
    pub(crate) slot_a: u32,
    pub(crate) slot_b: u32,
    pub(crate) knit: f32,
}

/// Mirrors `Chain`: a node's segment rest length and the turning angle
/// κθ0 its joint rests at (zero where it has none), and its neighbours
/// along its yarn ([`yarn_topology::Link::NONE`] for a missing one).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub(crate) struct GpuChain {
    pub(crate) rest_length: f32,
    pub(crate) rest_turn: f32,
    pub(crate) prev: u32,
    pub(crate) next: u32,
}

/// Mirrors `Pin`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub(crate) struct GpuPin {
    pub(crate) goal: [f32; 3],
    pub(crate) node: u32,
}

#[cfg(test)]
mod tests {
    use std::mem::{offset_of, size_of};

    use super::*;
    use crate::shaders;

    /// (name, size) of the WGSL struct `name`, with each member's offset.
    fn wgsl_layout(name: &str) -> (u32, Vec<(String, u32)>) {
        wgsl_layout_in(&shaders::PINS, name)
    }

    fn wgsl_layout_in(pass: &shaders::Pass, name: &str) -> (u32, Vec<(String, u32)>) {
        let (module, _) = shaders::tests::validate(pass);
        let mut layouter = naga::proc::Layouter::default();
        layouter.update(module.to_ctx()).expect("layout");
        let (handle, ty) = module.types.iter().find(|(_, t)| t.name.as_deref() == Some(name)).expect(name);
        let naga::TypeInner::Struct { members, .. } = &ty.inner else { panic!("{name} is not a struct") };
        let members = members.iter().map(|m| (m.name.clone().unwrap_or_default(), m.offset)).collect();
        (layouter[handle].size, members)
    }

    fn offsets(name: &str) -> Vec<u32> {
        wgsl_layout(name).1.into_iter().map(|(_, offset)| offset).collect()
    }

    #[test]
    fn params_match_wgsl() {
        let (size, members) = wgsl_layout("Params");
        assert_eq!(size as usize, size_of::<GpuParams>());
        let rust = [
            offset_of!(GpuParams, nodes),
            offset_of!(GpuParams, contacts),
            offset_of!(GpuParams, pins),
            offset_of!(GpuParams, flags),
            offset_of!(GpuParams, stretch),
            offset_of!(GpuParams, bend),
            offset_of!(GpuParams, contact),
            offset_of!(GpuParams, friction),
            offset_of!(GpuParams, h),
            offset_of!(GpuParams, h_over_m),
            offset_of!(GpuParams, damping_factor),
            offset_of!(GpuParams, friction_impulse),
            offset_of!(GpuParams, gravity_y),
            offset_of!(GpuParams, min_sin),
            offset_of!(GpuParams, scale),
            offset_of!(GpuParams, max_force),
            offset_of!(GpuParams, one),
            offset_of!(GpuParams, max_speed),
            offset_of!(GpuParams, reseat_step),
            offset_of!(GpuParams, reseats),
            offset_of!(GpuParams, self_contact),
            offset_of!(GpuParams, self_impulse),
            offset_of!(GpuParams, reach),
            offset_of!(GpuParams, radius),
            offset_of!(GpuParams, collider),
            offset_of!(GpuParams, collider_impulse),
            offset_of!(GpuParams, cell),
            offset_of!(GpuParams, search_reach),
            offset_of!(GpuParams, half_skin),
            offset_of!(GpuParams, mask),
            offset_of!(GpuParams, slots),
            offset_of!(GpuParams, colliders),
            offset_of!(GpuParams, rebuild_x),
            offset_of!(GpuParams, rebuild_y),
            offset_of!(GpuParams, short),
            offset_of!(GpuParams, lookahead),
            offset_of!(GpuParams, surfaces),
        ];
        assert_eq!(members.len(), rust.len(), "field count differs: {members:?}");
        for ((name, wgsl), rust) in members.iter().zip(rust) {
            assert_eq!(*wgsl as usize, rust, "Params.{name}");
        }
    }

    #[test]
    fn surface_matches_wgsl() {
        let (size, members) = wgsl_layout("Surface");
        assert_eq!(size as usize, size_of::<GpuSurface>());
        let rust = [
            offset_of!(GpuSurface, normal),
            offset_of!(GpuSurface, offset),
            offset_of!(GpuSurface, thickness),
            offset_of!(GpuSurface, friction),
        ];
        assert_eq!(members.into_iter().map(|(_, o)| o as usize).collect::<Vec<_>>(), rust);
        assert!(shaders::COMMON.contains(&format!("const MAX_COLLIDERS: u32 = {MAX_COLLIDERS}u;")));
    }

    #[test]
    fn contact_and_pin_match_wgsl() {
        assert_eq!(wgsl_layout("Contact").0 as usize, size_of::<GpuContact>());
        assert_eq!(
            offsets("Contact"),
            [
                offset_of!(GpuContact, a),
                offset_of!(GpuContact, b),
                offset_of!(GpuContact, rest),
                offset_of!(GpuContact, alive)
            ]
            .map(|o| o as u32)
        );
        assert_eq!(wgsl_layout("Pin").0 as usize, size_of::<GpuPin>());
        assert_eq!(offsets("Pin"), [offset_of!(GpuPin, goal), offset_of!(GpuPin, node)].map(|o| o as u32));
    }

    #[test]
    fn chain_matches_wgsl() {
        let (size, members) = wgsl_layout_in(&shaders::GATHER, "Chain");
        assert_eq!(size as usize, size_of::<GpuChain>());
        let rust = [
            offset_of!(GpuChain, rest_length),
            offset_of!(GpuChain, rest_turn),
            offset_of!(GpuChain, prev),
            offset_of!(GpuChain, next),
        ];
        assert_eq!(members.into_iter().map(|(_, o)| o as usize).collect::<Vec<_>>(), rust);
        assert!(
            shaders::COMMON.contains(&format!("const NONE: u32 = {:#x}u;", yarn_topology::Link::NONE)),
            "NONE differs"
        );
    }

    #[test]
    fn reseat_matches_wgsl() {
        let (size, members) = wgsl_layout_in(&shaders::RESEAT, "Reseat");
        assert_eq!(size as usize, size_of::<GpuReseat>());
        let rust = [
            offset_of!(GpuReseat, contact),
            offset_of!(GpuReseat, slot_a),
            offset_of!(GpuReseat, slot_b),
            offset_of!(GpuReseat, knit),
        ];
        assert_eq!(members.into_iter().map(|(_, o)| o as usize).collect::<Vec<_>>(), rust);
    }

    #[test]
    fn shader_constants_match() {
        assert!(shaders::COMMON.contains(&format!("const WORKGROUP: u32 = {}u;", crate::WORKGROUP)));
        let common = shaders::COMMON;
        assert!(common.contains(&format!("const FRICTION_ON: u32 = {FRICTION_ON}u;")), "FRICTION_ON differs");
        assert!(common.contains(&format!("const FUSED_FMA: u32 = {FUSED_FMA}u;")), "FUSED_FMA differs");
        assert!(common.contains(&format!("const OVERFLOWED: u32 = {OVERFLOWED}u;")), "OVERFLOWED differs");
        assert!(common.contains(&format!("const DIVERGED: u32 = {DIVERGED}u;")), "DIVERGED differs");
        assert!(common.contains(&format!("const CROWDED: u32 = {CROWDED}u;")), "CROWDED differs");
        assert!(common.contains(&format!("const STRETCHED: u32 = {STRETCHED}u;")), "STRETCHED differs");
        assert!(common.contains(&format!("const LATE_REBUILD: u32 = {LATE_REBUILD}u;")), "LATE_REBUILD differs");
        assert!(common.contains(&format!("const SELF_CONTACT: u32 = {SELF_CONTACT}u;")), "SELF_CONTACT differs");
        assert!(
            common.contains(&format!("const FRICTION_IN_TENSION: u32 = {FRICTION_IN_TENSION}u;")),
            "FRICTION_IN_TENSION differs"
        );
        use crate::bindings::rows;
        let lists = shaders::LISTS;
        for (name, row) in [
            ("NEXT", rows::NEXT),
            ("COUNT", rows::COUNT),
            ("ANCHOR", rows::ANCHOR),
            ("PINNED", rows::PINNED),
            ("SLOTS", rows::SLOTS),
        ] {
            assert!(lists.contains(&format!("const {name}: u32 = {row}u;")), "{name} differs");
        }
        assert!(lists.contains("const RECORDS: u32 = 4u;"), "the lists' header differs");
        let grid = shaders::GRID;
        use yarn_model::self_contact::grid::{MAX_BOX, MAX_LONG};
        assert!(grid.contains(&format!("const MAX_LONG: u32 = {MAX_LONG}u;")));
        assert!(grid.contains(&format!("const MAX_BOX: i32 = {MAX_BOX};")));
        assert!(grid.contains(&format!("const EMPTY: u32 = {:#x}u;", yarn_model::self_contact::grid::EMPTY)));
        let onset = yarn_model::terms::CONTACT_ONSET;
        assert!(shaders::TOUCH.contains(&format!("const CONTACT_ONSET: f32 = {onset};")), "CONTACT_ONSET differs");
    }
}
