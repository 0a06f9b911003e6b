//! The tube shader and its interface on the Rust side: the WGSL source
//! ([`SHADER`]), its ring size ([`SIDES`]) and [`Camera`], the mirror of its
//! uniform. This room fixes layouts only; it must not know how the camera
//! is placed or how a pass is recorded.

use bytemuck::{Pod, Zeroable};

/// The tube shader, shared with the browser demo.
pub const SHADER: &str = include_str!("../shaders/yarn.wgsl");

/// Ring vertices per tube section (`SIDES` in the shader).
pub const SIDES: u32 = 7;

/// Mirrors `Camera` in the shader.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub(crate) struct Camera {
    pub(crate) view_proj: [[f32; 4]; 4],
    pub(crate) eye: [f32; 3],
    pub(crate) radius: f32,
    pub(crate) light: [f32; 3],
    /// The node count.
    pub(crate) nodes: u32,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shader_validates_and_its_camera_matches() {
        let module = naga::front::wgsl::parse_str(SHADER).expect("parses");
        naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::empty())
            .validate(&module)
            .expect("validates");
        let mut layouter = naga::proc::Layouter::default();
        layouter.update(module.to_ctx()).expect("layout");
        let (handle, ty) = module.types.iter().find(|(_, t)| t.name.as_deref() == Some("Camera")).expect("Camera");
        assert_eq!(layouter[handle].size as usize, std::mem::size_of::<Camera>());
        let naga::TypeInner::Struct { members, .. } = &ty.inner else { panic!("Camera is a struct") };
        let offsets: Vec<u32> = members.iter().map(|m| m.offset).collect();
        assert_eq!(offsets, [0, 64, 76, 80, 92]);
        assert_eq!(
            [
                std::mem::offset_of!(Camera, view_proj),
                std::mem::offset_of!(Camera, eye),
                std::mem::offset_of!(Camera, radius),
                std::mem::offset_of!(Camera, light),
                std::mem::offset_of!(Camera, nodes),
            ]
            .map(|o| o as u32),
            offsets.as_slice()
        );
        assert!(SHADER.contains(&format!("const SIDES: u32 = {SIDES}u;")));
        assert!(SHADER.contains(&format!("const NONE: u32 = {:#x}u;", yarn_topology::Link::NONE)));
    }
}
