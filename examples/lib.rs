//! Runnable examples of yarnify live beside this file, one folder each:
//! `serial/`, `rayon/`, `wgpu/`, `render/`, `drape/` and `statics/`. Run one with
//! `cargo run --release --example NAME`.
//!
//! This library holds what they share.

/// `full` substeps, or a hundredth of them when `YARNIFY_EXAMPLE_QUICK` is
/// set: the tests run every example that way, so none can rot.
pub fn substeps(full: u64) -> u64 {
    if std::env::var_os("YARNIFY_EXAMPLE_QUICK").is_some() { (full / 100).max(1) } else { full }
}

/// A fabric's node positions in `f32`, the renderer's input.
pub fn positions_f32(positions: &[nalgebra::Vector3<f32>]) -> Vec<[f32; 3]> {
    positions.iter().map(|p| [p.x, p.y, p.z]).collect()
}

/// Run an example's body and turn an error into its message (not its debug
/// form) and a failing exit code.
pub fn main_with(body: fn() -> Result<(), Box<dyn std::error::Error>>) -> std::process::ExitCode {
    match body() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            std::process::ExitCode::FAILURE
        }
    }
}
