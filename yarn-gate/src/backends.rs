//! Backends by the names the command line gives them.
//!
//! This module owns the one `match` from a name to a backend, the list of
//! names an unknown one is answered with, and what a command over several
//! backends does when a GPU one finds no adapter (leaves it out, with a
//! warning). It knows nothing of what a command does with a backend: that
//! is the command's [`BackendWork`].

use yarn_backend_cpu::{Rayon, Reference, Serial};
use yarn_backend_wgpu::{GpuError, Mode, Wgpu};
use yarn_model::Backend;

use crate::GateError;

/// The names [`with_backend`] accepts, as the unknown-backend error lists
/// them.
pub(crate) const BACKENDS: &str =
    "serial, serial-f64, serial-f32, rayon, wgpu (= wgpu-gather), wgpu-fixed, reference-f32, reference-f64";

/// A command's work on one backend, written once for every backend type.
pub(crate) trait BackendWork {
    /// What the work yields on one backend.
    type Output;

    /// Do the work on `backend`, which the command line called `name`.
    ///
    /// # Errors
    /// Whatever the work fails with.
    fn run<B: Backend>(&mut self, name: &str, backend: B) -> Result<Self::Output, GateError>;

    /// Say that [`for_each_backend`] left `name` out for want of a GPU:
    /// by default, a warning on stderr. Work that keeps a progress bar
    /// across backends overrides it to print around its bar.
    fn left_out(&mut self, name: &str, reason: &GpuError) {
        eprintln!("{}", left_out_warning(name, reason));
    }
}

/// The warning [`BackendWork::left_out`] prints.
pub(crate) fn left_out_warning(name: &str, reason: &GpuError) -> String {
    format!("warning: {name} left out: {reason}")
}

/// Run `work` on the backend called `name`; `threads` sizes the rayon
/// backend's pool (0: one thread per core).
///
/// # Errors
/// [`GateError::UnknownBackend`] for a name not in [`BACKENDS`],
/// [`GateError::Gpu`] when a GPU backend finds no adapter,
/// [`GateError::ThreadPool`], or the work's own error.
pub(crate) fn with_backend<W: BackendWork>(name: &str, threads: usize, work: &mut W) -> Result<W::Output, GateError> {
    match name {
        "serial" | "serial-f64" => work.run(name, Serial::<f64>::new()),
        "serial-f32" => work.run(name, Serial::<f32>::new()),
        "rayon" => work.run(name, rayon(threads)?),
        "wgpu" | "wgpu-gather" => work.run(name, Wgpu::new(Mode::Gather)?),
        "wgpu-fixed" => work.run(name, Wgpu::new(Mode::FixedPointAtomic)?),
        "reference-f32" => work.run(name, Reference::<f32>::new()),
        "reference-f64" => work.run(name, Reference::<f64>::new()),
        other => Err(GateError::UnknownBackend { name: other.into(), known: BACKENDS.into() }),
    }
}

/// Run `work` on each backend of `names` in turn, as [`with_backend`]
/// does, and collect what it yields; a GPU backend is left out, with a
/// warning ([`BackendWork::left_out`]), when there is no adapter.
///
/// # Errors
/// The first error other than a missing adapter; the missing adapter when
/// every backend named was left out, since then nothing ran.
pub(crate) fn for_each_backend<W: BackendWork>(
    names: &[String],
    threads: usize,
    work: &mut W,
) -> Result<Vec<W::Output>, GateError> {
    let mut outputs = Vec::with_capacity(names.len());
    let mut missing = None;
    for name in names {
        match with_backend(name, threads, work) {
            Ok(output) => outputs.push(output),
            Err(GateError::Gpu(reason @ GpuError::NoAdapter { .. })) => {
                work.left_out(name, &reason);
                missing = Some(reason);
            }
            Err(e) => return Err(e),
        }
    }
    match missing {
        Some(reason) if outputs.is_empty() => Err(GateError::Gpu(reason)),
        _ => Ok(outputs),
    }
}

/// The rayon backend on `threads` threads (0: one per core).
fn rayon(threads: usize) -> Result<Rayon, GateError> {
    if threads == 0 {
        return Ok(Rayon::new());
    }
    Rayon::with_threads(threads).map_err(|e| GateError::ThreadPool { threads, reason: e.to_string() })
}
