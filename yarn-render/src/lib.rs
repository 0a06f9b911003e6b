//! The swept-tube renderer for yarnify (paper §9): each yarn of a fabric
//! drawn as its own tube of radius r (a closed yarn's tube closes on
//! itself, and no tube bridges two yarns), offscreen on wgpu, to an RGBA
//! image or PNG; and the same tubes as a Wavefront OBJ mesh. Every entry
//! point takes the yarns as [`yarn_topology::YarnSpan`]s, a fabric's
//! `yarns()`; an empty list is one open yarn over every node.
//!
//! The tube is generated in the vertex shader (`shaders/yarn.wgsl`, the
//! file the browser demo uses too): one instance per node, for the segment
//! leaving it along its yarn, [`SIDES`] ring vertices at each end, around
//! each node's parallel-transport frame ([`transport_normals`]), so rings
//! do not twist along the yarn. No tube geometry is stored. Shading is Lambert under a key light with an
//! ambient floor and a rim term, in two tones that alternate along the
//! yarn; the frame is multisampled with a depth buffer, and the camera
//! frames the fabric's bounds.
//!
//! This crate owns drawing; it knows nothing of the model beyond positions
//! and which nodes make up each yarn.
//!
//! ```no_run
//! use yarn_backend_wgpu::Gpu;
//! use yarn_render::{Renderer, View};
//! use yarn_topology::{Chart, Fabric, Geometry};
//!
//! let fabric = Fabric::from_chart(&Chart::stockinette(8, 8)?, &Geometry::default())?;
//! let positions: Vec<[f32; 3]> =
//!     fabric.positions().iter().map(|p| [p.x as f32, p.y as f32, p.z as f32]).collect();
//! let renderer = Renderer::new(&*Gpu::new()?);
//! let frame = renderer.render(&positions, fabric.yarns(), fabric.yarn_radius() as f32, &View::default())?;
//! frame.save_png("fabric.png")?;
//! println!("{:.0} % of the frame is yarn", 100.0 * frame.coverage());
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

#![forbid(unsafe_code)]

mod camera;
mod error;
mod frame;
mod obj;
mod pipeline;
mod positions;
mod readback;
mod shader;
mod transport;
mod yarn;

pub use camera::View;
pub use error::RenderError;
pub use frame::{BACKGROUND, Frame};
pub use obj::tube_obj;
pub use pipeline::Renderer;
pub use shader::{SHADER, SIDES};
pub use transport::transport_normals;
pub use yarn::Yarn;
