//! Stitch charts to yarn: the topology layer of yarnify.
//!
//! This crate owns *what is connected to what* and the assembled rest
//! geometry: a [`Chart`] of stitch kinds becomes a [`Fabric`], one open
//! polyline of yarn nodes with its stretch springs, bending triples,
//! persistent contacts, boundary edge families and the course and wale
//! directions (SPEC §2). A fabric can also be built from user parts with
//! [`Fabric::from_parts`], which validates every index and coordinate.
//!
//! A chart comes from a named [`Pattern`] (stockinette, garter, ribs,
//! seed), from [`Chart::new`], or from a plain-text chart of `k` and `p`
//! read bottom to top ([`Chart::parse`], [`Chart::from_file`]). Every chart
//! is the fabric as seen from its technical face; [`StitchKind`] says what
//! knit and purl mean there.
//!
//! It must not know about forces, parameters or backends: those live in
//! `yarn-model` and below.
//!
//! ```
//! use yarn_topology::{Chart, Fabric, Geometry};
//!
//! let chart = Chart::stockinette(16, 16)?;
//! let fabric = Fabric::from_chart(&chart, &Geometry::default())?;
//! // 16 rows of 16 loops of 24 nodes, a sinker node at each row's end and
//! // four nodes in each of the 15 turns between rows.
//! assert_eq!(fabric.node_count(), 16 * (16 * 24 + 1) + 15 * 4);
//! // Four crossings between each stitch and the loop below it.
//! assert_eq!(fabric.contacts().len(), 4 * 16 * 15);
//!
//! // The paper's arch: 8 nodes a loop, two contacts a stitch.
//! let paper = Fabric::from_chart(&chart, &Geometry::paper())?;
//! assert_eq!((paper.node_count(), paper.contacts().len()), (2048, 480));
//! # Ok::<(), yarn_topology::TopologyError>(())
//! ```

#![forbid(unsafe_code)]

mod arch;
mod chart;
mod error;
mod fabric;
mod geometry;
mod loops;
mod memory;
mod pattern;

pub use arch::SEG;
pub use chart::{Chart, StitchKind};
pub use error::TopologyError;
pub use fabric::{Boundary, Contact, Fabric, FabricParts, Front, Pin, Side, Spring, Triple, validate_pins};
pub use geometry::{Geometry, LoopShape};
pub use memory::{available_memory, check_memory, limit_memory};
pub use pattern::Pattern;

/// A 3-vector of model-unit coordinates.
pub type Vec3 = nalgebra::Vector3<f64>;
