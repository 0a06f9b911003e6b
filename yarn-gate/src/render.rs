//! `yarn-gate render`: relax a patch on a backend, then draw its yarn as
//! tubes into a PNG, and optionally write the tube surface as an OBJ mesh.
//!
//! This module owns the command ([`RenderArgs`]) and the relaxation before
//! drawing. How tubes are swept and shaded is `yarn_render`'s; it draws on
//! its own GPU context whatever backend relaxed the patch.

use std::path::{Path, PathBuf};

use indicatif::ProgressBar;
use yarn_backend_wgpu::Gpu;
use yarn_model::statics::StaticOptions;
use yarn_model::{Backend, Params, State, widen};
use yarn_render::{Renderer, View, tube_obj};
use yarn_topology::Fabric;

use crate::GateError;
use crate::backends::{BackendWork, with_backend};
use crate::check::STATIC_BUDGET;
use crate::check::rest::PROGRESS;
use crate::cli::{
    Outcome, PATTERN_HELP, PatternArg, SUBSTEPS, check_folder, parse_degrees, parse_image, parse_pattern, parse_size,
    with_bar,
};
use crate::preset::Preset;
use crate::settle::{Settle, Statics};

/// Which side of the fabric `render` looks at; each sets the camera's
/// default orbit and elevation ([`ViewSide::angles`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum ViewSide {
    /// The technical face, the +z side, where a knit stitch shows its V
    /// and a purl its bumps: orbit 0°, elevation 0°.
    #[default]
    Face,
    /// The back, from behind: orbit 180°, elevation 0°.
    Back,
    /// Edge-on, looking along the course at the left and right columns,
    /// to show the fabric's thickness and how its course edges curl:
    /// orbit 90°, elevation 0°.
    Edge,
}

impl ViewSide {
    /// The camera's (orbit, elevation) in degrees. Elevation 0 looks
    /// square at the face or back, so the columns of Vs and the rows of
    /// bumps read straight; an angled view foreshortens them.
    pub fn angles(self) -> (f32, f32) {
        match self {
            ViewSide::Face => (0.0, 0.0),
            ViewSide::Back => (180.0, 0.0),
            ViewSide::Edge => (90.0, 0.0),
        }
    }
}

/// `yarn-gate render`: relax, draw, save.
#[derive(Debug, clap::Args)]
pub struct RenderArgs {
    /// The model: `default` (the default parameters on interlooped loops)
    /// or `paper` (the paper's parameters on its 8-node arch, which knits
    /// no purl).
    #[arg(long, value_enum, default_value_t = Preset::Default)]
    preset: Preset,
    #[arg(long, default_value = "stockinette", value_parser = parse_pattern, help = PATTERN_HELP)]
    pattern: PatternArg,
    /// Patch size in stitches, WIDTHxHEIGHT (unused with a chart file
    /// --pattern).
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
    #[arg(long, default_value = "1280x960", value_parser = parse_image)]
    image: (u32, u32),
    /// The side to look at: `face` (the technical face, +z), `back` (from
    /// behind) or `edge` (edge-on along the course, to show thickness and
    /// curl). It sets the default --orbit and --elevation.
    #[arg(long, value_enum, default_value_t = ViewSide::Face)]
    side: ViewSide,
    /// Camera rotation about the vertical axis, in degrees, 0 facing the
    /// technical face [default: 0 for --side face, 180 back, 90 edge].
    #[arg(long, value_parser = parse_degrees, allow_negative_numbers = true)]
    orbit: Option<f32>,
    /// Camera angle above the fabric's plane, in degrees [default: 0].
    #[arg(long, value_parser = parse_degrees, allow_negative_numbers = true)]
    elevation: Option<f32>,
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
    /// A bad size, a chart file that cannot be read or parsed, a purl
    /// stitch with `--preset paper`, a backend failure, no GPU to draw on,
    /// or a file that cannot be written.
    pub fn run(&self) -> Result<Outcome, GateError> {
        let fabric = Fabric::from_chart(&self.pattern.chart(self.size)?, &self.preset.geometry())?;
        let params = self.preset.params();
        let view = self.view();
        let renderer = checked_renderer(&view, &self.out, self.obj.as_deref())?;
        let positions = if self.at_rest {
            at_rest(&fabric, &params)?
        } else {
            with_bar(self.steps, SUBSTEPS, "relaxing", |bar| {
                with_backend(&self.backend, 0, &mut Relax { fabric: &fabric, params: &params, steps: self.steps, bar })
            })?
        };
        let radius = fabric.yarn_radius() as f32;
        let frame = renderer
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

    /// The camera's (orbit, elevation) in degrees: --side's, unless
    /// --orbit or --elevation says otherwise.
    fn angles(&self) -> (f32, f32) {
        let (orbit, elevation) = self.side.angles();
        (self.orbit.unwrap_or(orbit), self.elevation.unwrap_or(elevation))
    }

    fn view(&self) -> View {
        let (orbit, elevation) = self.angles();
        let (width, height) = self.image;
        View { width, height, orbit: orbit.to_radians(), elevation: elevation.to_radians(), zoom: 1.0 }
    }
}

/// A renderer for `view`, once the GPU, the image size and the folders of
/// the PNG `out` and the mesh `obj` are known good: `render` and `drape`
/// check them before they simulate, so that no run is made only to be
/// lost.
///
/// # Errors
/// No adapter ([`GateError::NoAdapterToDraw`]) or another GPU failure, an
/// image size the device cannot draw, a folder that does not exist.
pub(crate) fn checked_renderer(view: &View, out: &Path, obj: Option<&Path>) -> Result<Renderer, GateError> {
    let renderer = Renderer::new(&*Gpu::new().map_err(GateError::drawing)?);
    renderer.check_size(view).map_err(|e| GateError::Render(e.to_string()))?;
    check_folder(out)?;
    obj.map_or(Ok(()), check_folder)?;
    Ok(renderer)
}

/// The positions of `fabric` at the rest `check` certifies, by its static
/// path, in f32; an error if the rest did not certify within the budget.
fn at_rest(fabric: &Fabric, params: &Params) -> Result<Vec<[f32; 3]>, GateError> {
    let mut statics = Statics::new(fabric, params, StaticOptions::default())?;
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
    params: &'a Params,
    steps: u64,
    bar: &'a ProgressBar,
}

impl BackendWork for Relax<'_> {
    type Output = Vec<[f32; 3]>;

    fn run<B: Backend>(&mut self, _name: &str, mut backend: B) -> Result<Vec<[f32; 3]>, GateError> {
        backend.load(self.fabric, self.params)?;
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

#[cfg(test)]
mod tests {
    use clap::Parser;

    use super::*;

    /// `render`'s arguments alone, as the binary parses them.
    #[derive(Debug, Parser)]
    struct Render {
        #[command(flatten)]
        args: RenderArgs,
    }

    fn angles(args: &[&str]) -> (f32, f32) {
        Render::try_parse_from(std::iter::once("render").chain(args.iter().copied())).unwrap().args.angles()
    }

    #[test]
    fn each_side_sets_the_camera_and_explicit_angles_override_it() {
        assert_eq!(angles(&[]), (0.0, 0.0), "the face, square on, by default");
        assert_eq!(angles(&["--side", "face"]), (0.0, 0.0));
        assert_eq!(angles(&["--side", "back"]), (180.0, 0.0), "the back is the face turned half round");
        assert_eq!(angles(&["--side", "edge"]), (90.0, 0.0), "edge-on along the course");
        assert_ne!(angles(&["--side", "back"]), angles(&["--side", "face"]));
        assert_eq!(angles(&["--side", "back", "--elevation", "20"]), (180.0, 20.0));
        assert_eq!(angles(&["--side", "edge", "--orbit", "45"]), (45.0, 0.0));
        assert_eq!(angles(&["--orbit", "-30", "--elevation", "15"]), (-30.0, 15.0));
        assert!(Render::try_parse_from(["render", "--side", "top"]).is_err());
    }

    #[test]
    fn render_takes_a_preset_and_a_pattern() {
        let render = Render::try_parse_from(["render", "--preset", "paper", "--pattern", "seed"]).unwrap();
        assert_eq!(
            (render.args.preset, render.args.pattern),
            (Preset::Paper, PatternArg::Named(yarn_topology::Pattern::Seed))
        );
        let render = Render::try_parse_from(["render"]).unwrap();
        assert_eq!((render.args.preset, render.args.pattern), (Preset::Default, PatternArg::default()));
    }
}
