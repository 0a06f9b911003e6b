//! yarnify's behavioural gate.
//!
//! This crate owns the metrics of SPEC §6 ([`metrics`]), the `check` gate
//! built from them ([`check`]), the cross-backend conformance suite
//! ([`conformance`]), the GPU check ([`gpucheck`]), benchmarks
//! ([`mod@bench`]), and the `yarn-gate` command-line tool. It
//! drives backends only through the [`yarn_model::Backend`] trait, so every
//! backend is measured by the same code.

#![forbid(unsafe_code)]

pub mod bench;
pub mod check;
pub mod conformance;
pub mod gpucheck;
pub mod metrics;
pub mod pareto;
pub mod plotdata;
pub mod stress;

use yarn_model::BackendError;
use yarn_topology::TopologyError;

/// Why the gate could not run (as opposed to running and failing).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum GateError {
    /// The patch could not be built.
    #[error(transparent)]
    Topology(#[from] TopologyError),
    /// The backend refused or failed.
    #[error(transparent)]
    Backend(#[from] BackendError),
    /// No GPU could be opened.
    #[error(transparent)]
    Gpu(#[from] yarn_backend_wgpu::GpuError),
    /// A frame could not be drawn or saved (the renderer's message).
    #[error("{0}")]
    Render(String),
    /// A file could not be written.
    #[error("could not write {path}: {reason}")]
    Io {
        /// The file.
        path: String,
        /// The system's reason.
        reason: String,
    },
    /// Curl needs interior nodes: at least 3 stitches each way.
    #[error("a {width}x{height} patch has no interior stitches to fit a mid-plane to; use at least 3x3")]
    TooSmall {
        /// Patch width.
        width: usize,
        /// Patch height.
        height: usize,
    },
    /// The thread pool for a parallel backend could not start.
    #[error("could not start {threads} worker threads: {reason}")]
    ThreadPool {
        /// Threads asked for.
        threads: usize,
        /// The system's reason.
        reason: String,
    },
    /// The backend name is not known.
    #[error("unknown backend `{name}`; choose one of: {known}")]
    UnknownBackend {
        /// The name given.
        name: String,
        /// The names accepted.
        known: String,
    },
}
