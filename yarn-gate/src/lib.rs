//! yarnify's behavioural gate.
//!
//! This crate owns the metrics of SPEC §6 ([`metrics`]), the `check` gate
//! built from them ([`check`]), the cross-backend conformance suite
//! ([`conformance`]), the GPU check ([`gpucheck`]), benchmarks
//! ([`mod@bench`]), and the `yarn-gate` command-line tool. It
//! drives backends only through the [`yarn_model::Backend`] trait, so every
//! backend is measured by the same code.
//!
//! Each command of the tool lives in the module of its library code: its
//! arguments (`CheckArgs` in [`check`], and so on) and a `run` that returns
//! an [`Outcome`]. The binary only parses, dispatches and prints.

#![forbid(unsafe_code)]

mod backends;
pub mod bench;
pub mod certificate;
pub mod check;
mod cli;
pub mod conformance;
pub mod drape;
pub mod gpucheck;
pub mod metrics;
pub mod pareto;
mod plot;
pub mod plotdata;
pub mod preset;
pub mod render;
pub mod settle;
pub mod stress;

pub use cli::Outcome;

use std::path::Path;

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
    /// No GPU adapter to draw with: `render` and `drape` draw on a GPU
    /// whichever backend simulates.
    #[error(
        "no GPU adapter found to draw the yarn ({reason}); drawing needs one whichever backend simulates. On Linux \
         without a GPU, install lavapipe (`apt-get install mesa-vulkan-drivers`)"
    )]
    NoAdapterToDraw {
        /// What wgpu said.
        reason: String,
    },
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
    /// A relaxation spent its budget without a certified rest.
    #[error("no certified rest after {work} units of work ({certificate}); raise the budget or relax longer")]
    NotAtRest {
        /// The work spent.
        work: u64,
        /// How far from rest it stopped.
        certificate: String,
    },
    /// Yarn passed through yarn while the gate ran the dynamics with
    /// self-contact: the push did not hold against the load there.
    #[error(
        "yarn passed through yarn {phase}after {work} substeps: segments {a} and {b} are {distance:.2} r apart; the \
         self-contact push did not hold against the load (raise `self_contact_stiffness` within the stable bound, or \
         pull less)"
    )]
    PassedThrough {
        /// Where in the gate ("in `hold wale` "), once the gate names it;
        /// empty before.
        phase: String,
        /// Substeps into that run when it was found (checked every
        /// [`crate::settle::CHUNK`]).
        work: u64,
        /// The segments, by their first nodes.
        a: u32,
        /// See `a`.
        b: u32,
        /// Their closest distance, in yarn radii.
        distance: f64,
    },
    /// `drape --drop` is so high that the fall would reach the
    /// divergence speed, at which a run stops, before the floor.
    #[error(
        "a drop of {drop} falls onto the floor at {speed:.0} units/s, at or past {limit:.0}, the speed at which a run \
         stops as diverged; drop from below {highest:.0}"
    )]
    DropTooHigh {
        /// The `--drop` given.
        drop: f64,
        /// The speed of a free fall from it at the floor.
        speed: f64,
        /// The model's divergence speed.
        limit: f64,
        /// The highest drop whose fall stays under it.
        highest: f64,
    },
    /// A benchmark asked for no timed runs, which leave no median to
    /// report.
    #[error("a benchmark needs at least one timed run; `repeats` is 0")]
    NoTimedRuns,
    /// The backend name is not known.
    #[error("unknown backend `{name}`; choose one of: {known}")]
    UnknownBackend {
        /// The name given.
        name: String,
        /// The names accepted.
        known: String,
    },
}

/// The exit code of a command that could not run because no GPU adapter
/// exists: `2` is every other error that stops a command, so a script (or
/// a test) can tell a machine without a GPU from a GPU run that failed.
pub const NO_ADAPTER_EXIT: u8 = 3;

impl GateError {
    /// Whether the command stopped because there is no GPU adapter at all
    /// (see [`NO_ADAPTER_EXIT`]), not because a GPU failed.
    pub fn is_no_adapter(&self) -> bool {
        matches!(
            self,
            GateError::Gpu(yarn_backend_wgpu::GpuError::NoAdapter { .. }) | GateError::NoAdapterToDraw { .. }
        )
    }

    /// A GPU that could not be opened to draw with: no adapter is
    /// [`GateError::NoAdapterToDraw`], whose advice is not to choose a CPU
    /// backend.
    pub(crate) fn drawing(error: yarn_backend_wgpu::GpuError) -> Self {
        match error {
            yarn_backend_wgpu::GpuError::NoAdapter { reason } => GateError::NoAdapterToDraw { reason },
            other => GateError::Gpu(other),
        }
    }

    /// The error with the gate's `phase` named, where it says where it
    /// happened ([`GateError::PassedThrough`]).
    pub(crate) fn during(self, phase: &str) -> Self {
        match self {
            GateError::PassedThrough { phase: at, work, a, b, distance } if at.is_empty() => {
                GateError::PassedThrough { phase: format!("in `{phase}` "), work, a, b, distance }
            }
            other => other,
        }
    }

    /// The error of a file or folder at `path` that could not be written
    /// (figures, tables, meshes all fail this way).
    pub(crate) fn io(path: &Path, reason: impl std::fmt::Display) -> Self {
        GateError::Io { path: path.display().to_string(), reason: reason.to_string() }
    }
}
