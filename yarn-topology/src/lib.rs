//! Stitch charts to yarn: the topology layer of yarnify.
//!
//! This crate owns *what is connected to what* and the assembled rest
//! geometry: a [`Chart`] of stitch kinds becomes a [`Fabric`], one open
//! polyline of yarn nodes with its stretch springs, bending triples,
//! persistent contacts, boundary edge families and the course and wale
//! directions (SPEC §2). A fabric can also be built from user parts with
//! [`Fabric::from_parts`], which validates every index and coordinate;
//! such a fabric may hold several yarns ([`YarnSpan`]), each a contiguous
//! run of nodes, open or closed, whose springs and joints never join two
//! yarns.
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
//!
//! Two open yarns and a closed ring, with contacts between them:
//!
//! ```
//! use yarn_topology::{Fabric, FabricParts, Vec3, YarnSpan};
//!
//! let strands = (0..12).map(|i| Vec3::new(f64::from(i % 6), f64::from(i / 6) * 3.0, 0.0));
//! let ring = (0..6).map(|i| f64::from(i) * std::f64::consts::TAU / 6.0).map(|t| Vec3::new(t.cos(), 6.0 + t.sin(), 0.0));
//! let fabric = Fabric::from_parts(FabricParts {
//!     positions: strands.chain(ring).collect(),
//!     yarns: vec![YarnSpan::open(0..6), YarnSpan::open(6..12), YarnSpan::closed(12..18)],
//!     contacts: vec![[2, 8], [11, 15]],
//!     ..FabricParts::default()
//! })?;
//! assert_eq!(fabric.springs().len(), 5 + 5 + 6);
//! assert_eq!(fabric.triples().len(), 4 + 4 + 6);
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
pub use fabric::{
    Boundary, Contact, Fabric, FabricParts, Front, Link, Pin, Side, Spring, Triple, YarnSpan, validate_pins,
    validate_yarns,
};
pub use geometry::{Geometry, LoopShape};
pub use memory::{available_memory, check_memory, limit_memory};
pub use pattern::Pattern;

/// A 3-vector of model-unit coordinates.
pub type Vec3 = nalgebra::Vector3<f64>;
