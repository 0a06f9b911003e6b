//! `yarn-gate render`: relax a patch on a backend, then draw its yarn as
//! tubes into a PNG, and optionally write the tube surface as an OBJ mesh.
//!
//! This module owns the command ([`RenderArgs`]) and the relaxation before
//! drawing. How tubes are swept and shaded is `yarn_render`'s; it draws on
//! its own GPU context whatever backend relaxed the patch.

use std::path::PathBuf;

use indicatif::ProgressBar;
use yarn_backend_wgpu::Gpu;
use yarn_model::statics::StaticOptions;
use yarn_model::{Backend, Params, State, widen};
use yarn_render::{Renderer, View, tube_obj};
use yarn_topology::{Chart, Fabric, Geometry};

use crate::GateError;
use crate::backends::{BackendWork, with_backend};
use crate::check::STATIC_BUDGET;
use crate::check::rest::PROGRESS;
use crate::cli::{Outcome, SUBSTEPS, parse_size, with_bar};
use crate::settle::{Settle, Statics};

/// `yarn-gate render`: relax, draw, save.
#[derive(Debug, clap::Args)]
pub struct RenderArgs {
    /// Patch size in stitches, WIDTHxHEIGHT.
    #[arg(long, default_value = "16x16", value_parser = parse_size)]
    size: (usize, usize),
    /// Substeps of free relaxation before drawing.
    #[arg(long, default_value_t = 3_000)]
    steps: u64,
    /// Backend for the relaxation (see `check --help`).
    #[arg(long, default_value = "rayon")]
    backend: String,
    /// The PNG to write.
    #[arg(long, default_value = "fabric.png")]
    out: PathBuf,
    /// Also write the tube surface as a Wavefront OBJ mesh here.
    #[arg(long)]
    obj: Option<PathBuf>,
    /// Image size in pixels, WIDTHxHEIGHT.
    #[arg(long, default_value = "1280x960", value_parser = parse_size)]
    image: (usize, usize),
    /// Camera rotation about the vertical axis, in degrees.
    #[arg(long, default_value_t = 0.0)]
    orbit: f32,
    /// Camera angle above the fabric's plane, in degrees.
    #[arg(long, default_value_t = 20.0)]
    elevation: f32,
    /// Draw the certified rest that `check` measures (its frictionless
    /// solve) instead of --steps substeps of the dynamics on --backend.
    #[arg(long)]
    at_rest: bool,
}

impl RenderArgs {
    /// Relax, draw and save; the outcome names the files and how much of
    /// the frame is yarn.
    ///
    /// # Errors
    /// A bad size, a backend failure, no GPU to draw on, or a file that
    /// cannot be written.
    pub fn run(&self) -> Result<Outcome, GateError> {
        let fabric = Fabric::from_chart(&Chart::stockinette(self.size.0, self.size.1)?, &Geometry::default())?;
        let positions = if self.at_rest {
            at_rest(&fabric)?
        } else {
            with_bar(self.steps, SUBSTEPS, "relaxing", |bar| {
                with_backend(&self.backend, 0, &mut Relax { fabric: &fabric, steps: self.steps, bar })
            })?
        };
        let radius = fabric.yarn_radius() as f32;
        let view = View {
            width: self.image.0 as u32,
            height: self.image.1 as u32,
            orbit: self.orbit.to_radians(),
            elevation: self.elevation.to_radians(),
            zoom: 1.0,
        };
        let frame = Renderer::new(&*Gpu::new()?)
            .render(&positions, fabric.yarns(), radius, &view)
            .and_then(|frame| frame.save_png(&self.out).map(|()| frame))
            .map_err(|e| GateError::Render(e.to_string()))?;
        let mut stdout =
            format!("wrote {} ({:.1} % of the frame is yarn)\n", self.out.display(), 100.0 * frame.coverage());
        if let Some(path) = &self.obj {
            let obj = tube_obj(&positions, fabric.yarns(), radius).map_err(|e| GateError::Render(e.to_string()))?;
            std::fs::write(path, obj).map_err(|e| GateError::io(path, e))?;
            stdout += &format!("wrote {}\n", path.display());
        }
        Ok(Outcome::text(stdout))
    }
}

/// The positions of `fabric` at the rest `check` certifies, by its static
/// path, in f32; an error if the rest did not certify within the budget.
fn at_rest(fabric: &Fabric) -> Result<Vec<[f32; 3]>, GateError> {
    let mut statics = Statics::new(fabric, &Params::default(), StaticOptions::default())?;
    let rest = with_bar(STATIC_BUDGET, PROGRESS, "relax", |bar| {
        statics.settle(&State::at_rest(fabric), &[], STATIC_BUDGET, &mut |done| bar.set_position(done))
    })?;
    if !rest.certificate.certified {
        return Err(GateError::NotAtRest { work: rest.work, certificate: rest.certificate.describe() });
    }
    Ok(rest.state.positions.iter().map(|p| [p.x as f32, p.y as f32, p.z as f32]).collect())
}

/// Advance a backend from rest by `steps` substeps, moving `bar`, and
/// hand back the positions in f32.
struct Relax<'a> {
    fabric: &'a Fabric,
    steps: u64,
    bar: &'a ProgressBar,
}

impl BackendWork for Relax<'_> {
    type Output = Vec<[f32; 3]>;

    fn run<B: Backend>(&mut self, _name: &str, mut backend: B) -> Result<Vec<[f32; 3]>, GateError> {
        backend.load(self.fabric, &Params::paper())?;
        let chunk = (self.steps / 100).max(1);
        let mut done = 0;
        while done < self.steps {
            let substeps = chunk.min(self.steps - done);
            backend.advance(substeps)?;
            done += substeps;
            self.bar.set_position(done);
        }
        let state = backend.state()?;
        Ok(state.positions.iter().map(widen).map(|p| [p.x as f32, p.y as f32, p.z as f32]).collect())
    }
}
