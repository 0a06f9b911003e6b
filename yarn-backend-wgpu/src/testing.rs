//! How yarnify's own test suites (native ones; not in the browser) treat a
//! machine without a GPU: a test that needs one is skipped, and the skip is
//! counted, only when there is no adapter at all and nothing asked for one
//! in particular. Any other failure to open the GPU fails the test.
//!
//! libtest has no skip at run time, and it hides what a passing test
//! prints. So a skip writes one [`SKIP_MARKER`] line straight to the
//! process's standard error, past libtest's capture, and `scripts/test`
//! counts those lines in its closing "N passed, N failed, N skipped".
//! (cargo-nextest has no run-time skip either; a marker keeps the suite on
//! plain `cargo test`.)
//!
//! A test may not skip when:
//! - `CI` is set: CI installs lavapipe, so the GPU tests must run there;
//! - `WGPU_BACKEND` is set: an override that finds nothing is a mistake to
//!   report, not a machine without a GPU.
//!
//! ```no_run
//! # fn main() {
//! let Some(gpu) = yarn_backend_wgpu::testing::shared_gpu() else { return };
//! println!("testing on {}", gpu.adapter());
//! # }
//! ```

use std::collections::BTreeSet;
use std::io::Write;
use std::sync::{Arc, Mutex, OnceLock, PoisonError};

use crate::{Gpu, GpuError};

/// The start of the line a skipped test writes to standard error.
pub const SKIP_MARKER: &str = "yarnify-skip:";

/// The process's one GPU context for tests, or `None` after reporting a
/// skip for the calling test (see the module's documentation).
///
/// # Panics
/// When the GPU cannot be opened and the test may not skip.
pub fn shared_gpu() -> Option<Arc<Gpu>> {
    static GPU: OnceLock<Result<Arc<Gpu>, GpuError>> = OnceLock::new();
    match GPU.get_or_init(Gpu::new) {
        Ok(gpu) => Some(Arc::clone(gpu)),
        Err(error) => {
            skip_without_adapter(error);
            None
        }
    }
}

/// Report that the calling test skips because `error` says there is no
/// adapter. Each test is counted once, however often it asks.
///
/// # Panics
/// When `error` is not [`GpuError::NoAdapter`], or `CI` or `WGPU_BACKEND`
/// is set: then the test fails instead of skipping.
pub fn skip_without_adapter(error: &GpuError) {
    if !matches!(error, GpuError::NoAdapter { .. }) {
        panic!("the GPU could not be opened on a machine that has an adapter: {error}");
    }
    skip(&error.to_string());
}

/// Report that the calling test skips for want of a GPU adapter, which
/// `reason` describes (e.g. a command's stderr after it exited with its
/// no-adapter code).
///
/// # Panics
/// When `CI` or `WGPU_BACKEND` is set.
pub fn skip(reason: &str) {
    for var in ["CI", "WGPU_BACKEND"] {
        if std::env::var_os(var).is_some() {
            panic!("{var} is set, so the GPU tests must run, but: {reason}");
        }
    }
    static SKIPPED: Mutex<BTreeSet<String>> = Mutex::new(BTreeSet::new());
    let test = std::thread::current().name().unwrap_or("unnamed test").to_owned();
    let mut skipped = SKIPPED.lock().unwrap_or_else(PoisonError::into_inner);
    if skipped.insert(test.clone()) {
        let reason = reason.lines().next().unwrap_or("");
        // Straight to the file descriptor: `eprintln!` would be captured.
        let _ = std::io::stderr().write_all(format!("\n{SKIP_MARKER} {test}: {reason}\n").as_bytes());
    }
}
