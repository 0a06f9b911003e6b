//! `yarn-gate drape`: drop a patch, flat or folded, onto a collider under
//! gravity with self-contact on, and measure whether yarn passed through
//! yarn or through the collider on the way: the closest approach of any
//! two segments that may touch, how many substeps had a pair closer than
//! [`TOO_CLOSE_RADII`], how close the yarn came to each collider, and the
//! energy and speed at the end. Then draw it.
//!
//! This module owns the command ([`DrapeArgs`]), the scene it builds
//! ([`drape_start`]) and the measurements ([`DrapeReport`]). The contact
//! model is `yarn_model`'s; the backends run it.

use std::path::PathBuf;

use indicatif::ProgressBar;
use serde::Serialize;
use yarn_model::self_contact::Candidates;
use yarn_model::step::segment_end;
use yarn_model::terms::closest_gap;
use yarn_model::{Backend, Collider, Model, Params, Plane, State, V3, widen};
use yarn_render::{View, tube_obj};
use yarn_topology::Fabric;

use crate::GateError;
use crate::backends::{BackendWork, with_backend};
use crate::cli::{
    Outcome, PATTERN_HELP, PatternArg, SUBSTEPS, parse_degrees, parse_distance, parse_image, parse_pattern, parse_size,
    with_bar,
};
use crate::preset::Preset;
use crate::render::checked_renderer;

/// Two segments closer than this, in yarn radii, count as passing into
/// each other: a tenth of a radius inside the diameter the contact holds.
pub const TOO_CLOSE_RADII: f64 = 1.9;

/// Gravity of a drape, in model units per s²: Earth's, as the soak and the
/// pareto drape use.
pub const DRAPE_GRAVITY: f64 = 9.81;

/// The self-contact stiffness a drape runs with when its preset has none:
/// twice the yarn's stretch. Measured on the folded 16x16 drop (3,000
/// substeps, `drape --fold --self-contact K`), the closest approach over
/// the run was 1.692 r at 400, 1.763 r at 800, 1.818 r at 1,600, 1.854 r
/// at 3,200 and 1.881 r at 6,400 (docs/self-contact.md, "Choosing the
/// stiffness"); with the C1 push it replaced, 6,400 diverged, and 1,600
/// was a factor of four from that.
pub const DRAPE_SELF_CONTACT: f64 = 1600.0;

/// The collider shapes `drape` can drop onto.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum ColliderArg {
    /// A floor: the plane y = 0 facing up.
    #[default]
    Plane,
}

/// `yarn-gate drape`: drop, measure, draw.
#[derive(Debug, clap::Args)]
pub struct DrapeArgs {
    /// The model (see `render --help`). Self-contact is turned on at
    /// k_sc = 1,600 when the preset has it off.
    #[arg(long, value_enum, default_value_t = Preset::Default)]
    preset: Preset,
    #[arg(long, default_value = "stockinette", value_parser = parse_pattern, help = PATTERN_HELP)]
    pattern: PatternArg,
    /// Patch size in stitches, WIDTHxHEIGHT.
    #[arg(long, default_value = "16x16", value_parser = parse_size)]
    size: (usize, usize),
    /// What to drop the patch on.
    #[arg(long, value_enum, default_value_t = ColliderArg::Plane)]
    collider: ColliderArg,
    /// Height of the patch's lowest point above the collider, in model
    /// units.
    #[arg(long, default_value_t = 2.0, value_parser = parse_distance, allow_negative_numbers = true)]
    drop: f64,
    /// Fold the patch in half across its courses before dropping it, so
    /// its two halves land on each other.
    #[arg(long)]
    fold: bool,
    /// The self-contact stiffness k_sc; 0 runs with self-contact off, to
    /// see what it prevents [default: the preset's, or 1,600 where it has
    /// none].
    #[arg(long)]
    self_contact: Option<f64>,
    /// Substeps to run.
    #[arg(long, default_value_t = 6_000)]
    steps: u64,
    /// Backend (see `check --help`).
    #[arg(long, default_value = "rayon")]
    backend: String,
    /// The PNG to write.
    #[arg(long, default_value = "drape.png")]
    out: PathBuf,
    /// Also write the tube surface as a Wavefront OBJ mesh here.
    #[arg(long)]
    obj: Option<PathBuf>,
    /// Image size in pixels, WIDTHxHEIGHT.
    #[arg(long, default_value = "1280x960", value_parser = parse_image)]
    image: (u32, u32),
    /// Camera rotation about the vertical axis, in degrees; 0 looks along
    /// the fold's crease, at its cross-section.
    #[arg(long, default_value_t = 20.0, value_parser = parse_degrees, allow_negative_numbers = true)]
    orbit: f32,
    /// Camera angle above the floor, in degrees.
    #[arg(long, default_value_t = 35.0, value_parser = parse_degrees, allow_negative_numbers = true)]
    elevation: f32,
    /// Print the report as JSON.
    #[arg(long)]
    json: bool,
}

/// What a drape measured.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DrapeReport {
    /// The backend that ran it.
    pub backend: String,
    /// Nodes in the patch.
    pub nodes: usize,
    /// Substeps run.
    pub substeps: u64,
    /// Whether the patch started folded.
    pub folded: bool,
    /// Self-contact stiffness k_sc (0: off).
    pub self_contact_stiffness: f64,
    /// The smallest centreline distance between two segments that may
    /// touch (not near along their yarn, not joined by a live persistent
    /// contact), over every substep, in yarn radii; `None` when no two
    /// came within 2r plus the skin.
    pub min_distance_r: Option<f64>,
    /// The same at the end of the run.
    pub end_distance_r: Option<f64>,
    /// Substeps after which some such pair was closer than
    /// [`TOO_CLOSE_RADII`] radii.
    pub substeps_too_close: u64,
    /// Per collider, the smallest height of any node's centreline above
    /// its surface over every substep, in yarn radii (1 is resting on it;
    /// below 0 is inside it).
    pub collider_min_height_r: Vec<f64>,
    /// The total energy at the end, potential plus kinetic.
    pub energy: f64,
    /// Its self-contact term.
    pub self_contact_energy: f64,
    /// Its collider term.
    pub collider_energy: f64,
    /// The fastest node's speed at the end.
    pub max_speed: f64,
    /// How many times the self-contact candidate list was built, where
    /// the backend counts it.
    pub list_builds: Option<u64>,
    /// How many batches ran again because they were late to rebuild the
    /// list ([`Backend::late_list_reruns`]), where the backend may be.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub list_reruns: Option<u64>,
    /// Segment pairs in the candidate list at the end (within 2r plus the
    /// skin), and of them those within 2r, pushing.
    pub candidate_pairs: usize,
    /// See `candidate_pairs`.
    pub touching_pairs: usize,
}

impl DrapeReport {
    /// Whether the drape ends clean: no pair of segments that may touch
    /// closer than [`TOO_CLOSE_RADII`] radii at the end, and every node's
    /// centreline above every collider's surface throughout. A penalty
    /// gives way while it pushes, so a drop may press pairs under that
    /// line for a while (`substeps_too_close` counts the substeps): the
    /// folded 16x16 drop at k_sc = 1,600 comes to 1.82 r and ends 1.98 r
    /// apart (docs/self-contact.md).
    pub fn clean(&self) -> bool {
        self.end_distance_r.is_none_or(|d| d >= TOO_CLOSE_RADII) && self.collider_min_height_r.iter().all(|&h| h > 0.0)
    }

    fn table(&self) -> String {
        let within = |d: Option<f64>| d.map_or("none within reach".into(), |d| format!("{d:.3} r"));
        let (distance, end) = (within(self.min_distance_r), within(self.end_distance_r));
        let heights: Vec<String> = self.collider_min_height_r.iter().map(|h| format!("{h:.3} r")).collect();
        format!(
            "drape on {}: {} nodes, {} substeps{}, k_sc {}\n\
             closest approach of segments that may touch: {distance} (at the end {end})\n\
             substeps with a pair closer than {TOO_CLOSE_RADII} r: {}\n\
             lowest centreline above each collider: {}\n\
             energy at the end: {:.6e} (self-contact {:.3e}, collider {:.3e}); max speed {:.3e}\n\
             self-contact list builds: {}{}; {} candidate pairs, {} within 2r at the end\n",
            self.backend,
            self.nodes,
            self.substeps,
            if self.folded { ", folded" } else { "" },
            self.self_contact_stiffness,
            self.substeps_too_close,
            heights.join(", "),
            self.energy,
            self.self_contact_energy,
            self.collider_energy,
            self.max_speed,
            self.list_builds.map_or("not counted".into(), |b| b.to_string()),
            self.list_reruns.map_or(String::new(), |r| format!(" ({r} batches run again, late to rebuild)")),
            self.candidate_pairs,
            self.touching_pairs,
        )
    }
}

impl DrapeArgs {
    /// Drop, measure, draw and save; fails (exit 1) when the drape does not
    /// end clean ([`DrapeReport::clean`]).
    ///
    /// # Errors
    /// A bad size or chart, a backend failure, no GPU to draw on, or a
    /// file that cannot be written.
    pub fn run(&self) -> Result<Outcome, GateError> {
        let fabric = Fabric::from_chart(&self.pattern.chart(self.size)?, &self.preset.geometry())?;
        let ColliderArg::Plane = self.collider;
        let colliders = [Collider::Plane(Plane::floor(0.0))];
        let params = drape_params(self.preset.params(), self.self_contact);
        check_drop(&Model::new(&fabric, &params)?, self.drop)?;
        let view = View {
            width: self.image.0,
            height: self.image.1,
            orbit: self.orbit.to_radians(),
            elevation: self.elevation.to_radians(),
            zoom: 1.0,
        };
        let renderer = checked_renderer(&view, &self.out, self.obj.as_deref())?;
        let start = drape_start(&fabric, self.fold, self.drop);
        let (report, positions) = with_bar(self.steps, SUBSTEPS, "draping", |bar| {
            with_backend(
                &self.backend,
                0,
                &mut Drape {
                    fabric: &fabric,
                    params: &params,
                    colliders: &colliders,
                    start: &start,
                    steps: self.steps,
                    folded: self.fold,
                    bar,
                },
            )
        })?;
        let radius = fabric.yarn_radius() as f32;
        let frame = renderer
            .render(&positions, fabric.yarns(), radius, &view)
            .and_then(|frame| frame.save_png(&self.out).map(|()| frame))
            .map_err(|e| GateError::Render(e.to_string()))?;
        if let Some(path) = &self.obj {
            let obj = tube_obj(&positions, fabric.yarns(), radius).map_err(|e| GateError::Render(e.to_string()))?;
            std::fs::write(path, obj).map_err(|e| GateError::io(path, e))?;
        }
        let pass = report.clean();
        let files = format!(
            "wrote {} ({:.1} % of the frame is yarn){}\n",
            self.out.display(),
            100.0 * frame.coverage(),
            self.obj.as_ref().map_or(String::new(), |p| format!(", {}", p.display()))
        );
        Ok(Outcome::json_or(&report, self.json, || report.table() + &files).verdict(pass))
    }
}

/// `params` with gravity on and self-contact at `stiffness`, or where
/// that is `None` at the preset's own, or [`DRAPE_SELF_CONTACT`] where
/// the preset has it off.
pub fn drape_params(params: Params, stiffness: Option<f64>) -> Params {
    let own = params.self_contact_stiffness;
    let k_sc = stiffness.unwrap_or(if own > 0.0 { own } else { DRAPE_SELF_CONTACT });
    Params { gravity: DRAPE_GRAVITY, self_contact_stiffness: k_sc, ..params }
}

/// Refuse a `drop` from which a free fall under [`DRAPE_GRAVITY`] would
/// reach the floor at `model`'s divergence speed
/// ([`Model::divergence_speed`]) or faster: that run would stop as
/// diverged at the impact, for no fault of the step.
///
/// # Errors
/// [`GateError::DropTooHigh`], naming the highest drop allowed.
fn check_drop(model: &Model<f64>, drop: f64) -> Result<(), GateError> {
    let (speed, limit) = ((2.0 * DRAPE_GRAVITY * drop).sqrt(), model.divergence_speed());
    if speed < limit {
        return Ok(());
    }
    Err(GateError::DropTooHigh { drop, speed, limit, highest: limit * limit / (2.0 * DRAPE_GRAVITY) })
}

/// The start of a drape: the patch laid flat, face up, its lowest point
/// `drop` above the floor y = 0, folded in half with `fold`
/// ([`Fabric::laid_flat`]), at rest.
pub fn drape_start(fabric: &Fabric, fold: bool, drop: f64) -> State<f64> {
    let positions = fabric.laid_flat(fold, drop);
    State { velocities: vec![V3::zeros(); positions.len()], positions }
}

/// Run a drape on one backend, measuring after every substep.
struct Drape<'a> {
    fabric: &'a Fabric,
    params: &'a Params,
    colliders: &'a [Collider],
    start: &'a State<f64>,
    steps: u64,
    folded: bool,
    bar: &'a ProgressBar,
}

impl BackendWork for Drape<'_> {
    type Output = (DrapeReport, Vec<[f32; 3]>);

    fn run<B: Backend>(&mut self, _name: &str, mut backend: B) -> Result<Self::Output, GateError> {
        backend.load(self.fabric, self.params)?;
        backend.set_pins(&[])?;
        backend.set_colliders(self.colliders)?;
        backend.write_state(&self.start.cast())?;
        let mut ruler = Model::<f64>::new(self.fabric, self.params)?;
        ruler.set_pins(&[])?;
        ruler.set_colliders(self.colliders)?;
        let r = self.fabric.yarn_radius();
        let mut watch = Watch::new(self.colliders.len());
        let mut candidates = Candidates::default();
        for done in 1..=self.steps {
            backend.advance(1)?;
            let state = backend.state()?.cast::<f64>();
            watch.observe(&ruler, &mut candidates, &state.positions, r);
            if done % 100 == 0 || done == self.steps {
                self.bar.set_position(done);
            }
        }
        let (energy, state) = backend.measure(self.fabric)?;
        let report = DrapeReport {
            backend: backend.name(),
            nodes: self.fabric.node_count(),
            substeps: self.steps,
            folded: self.folded,
            self_contact_stiffness: self.params.self_contact_stiffness,
            min_distance_r: watch.closest.map(|d| d / r),
            end_distance_r: watch.last.map(|d| d / r),
            substeps_too_close: watch.too_close,
            collider_min_height_r: watch.lowest.iter().map(|h| h / r).collect(),
            energy: energy.total(),
            self_contact_energy: energy.self_contact,
            collider_energy: energy.collider,
            max_speed: state.max_speed(),
            list_builds: backend.self_contact_builds(),
            list_reruns: backend.late_list_reruns(),
            candidate_pairs: candidates.pairs().len(),
            touching_pairs: watch.touching,
        };
        Ok((report, state.positions.iter().map(widen).map(|p| [p.x as f32, p.y as f32, p.z as f32]).collect()))
    }
}

/// The running measurements of a drape.
struct Watch {
    /// The closest approach so far, and at the last look, in model units.
    closest: Option<f64>,
    last: Option<f64>,
    /// Pairs within 2r at the last look.
    touching: usize,
    too_close: u64,
    /// Per collider, the lowest centreline height so far.
    lowest: Vec<f64>,
}

impl Watch {
    fn new(colliders: usize) -> Self {
        Self { closest: None, last: None, touching: 0, too_close: 0, lowest: vec![f64::INFINITY; colliders] }
    }

    /// Measure the state `x` of `model`'s fabric, of yarn radius `r`, with
    /// `candidates` kept from the last call (its Verlet list holds every
    /// pair within 2r, so the pairs closer than that are all seen).
    fn observe(&mut self, model: &Model<f64>, candidates: &mut Candidates<f64>, x: &[V3<f64>], r: f64) {
        candidates.refresh(model, x);
        let mut closest = f64::INFINITY;
        self.touching = 0;
        for &[a, b] in candidates.pairs() {
            let (a, b) = (a as usize, b as usize);
            let d = closest_gap(&x[a], &x[segment_end(model, a)], &x[b], &x[segment_end(model, b)]).0.norm();
            closest = closest.min(d);
            self.touching += usize::from(d < 2.0 * r);
        }
        self.last = closest.is_finite().then_some(closest);
        if closest.is_finite() {
            self.closest = Some(self.closest.map_or(closest, |c| c.min(closest)));
        }
        if closest < TOO_CLOSE_RADII * r {
            self.too_close += 1;
        }
        for (lowest, surface) in self.lowest.iter_mut().zip(model.surfaces()) {
            *lowest = x.iter().filter_map(|p| surface.height(p)).fold(*lowest, f64::min);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use yarn_backend_cpu::Rayon;
    use yarn_topology::Chart;

    fn drape(fabric: &Fabric, stiffness: f64, steps: u64) -> (DrapeReport, Vec<[f32; 3]>) {
        let params = drape_params(Params::default(), Some(stiffness));
        let colliders = [Collider::Plane(Plane::floor(0.0))];
        let start = drape_start(fabric, true, 2.0);
        let bar = ProgressBar::hidden();
        let mut work =
            Drape { fabric, params: &params, colliders: &colliders, start: &start, steps, folded: true, bar: &bar };
        work.run("rayon", Rayon::with_threads(2).unwrap()).unwrap()
    }

    /// The 16x16 patch dropped folded onto a floor under gravity: it
    /// starts clear of itself, ends with no pair of segments closer than
    /// [`TOO_CLOSE_RADII`] radii, and no node ever went below the floor's
    /// surface. Without self-contact the halves pass into each other.
    #[test]
    fn a_folded_patch_dropped_on_a_floor_never_passes_through_itself_or_the_floor() {
        let fabric =
            Fabric::from_chart(&Chart::stockinette(16, 16).unwrap(), &yarn_topology::Geometry::default()).unwrap();
        let (report, positions) = drape(&fabric, DRAPE_SELF_CONTACT, 3_000);
        println!("{}", report.table());
        let end = report.end_distance_r.expect("the layers touch at the end");
        assert!(end >= TOO_CLOSE_RADII, "{end} r at the end");
        assert!(report.collider_min_height_r[0] > 0.0, "a node went below the floor");
        assert!(report.clean(), "the command's verdict is the test's");
        assert!(positions.iter().all(|p| p[1] > 0.0));
        let lowest = positions.iter().map(|p| p[1]).fold(f32::MAX, f32::min);
        assert!(f64::from(lowest) < 1.5 * fabric.yarn_radius(), "the patch did not come down: lowest at {lowest}");
        let (without, _) = drape(&fabric, 0.0, 3_000);
        let through = without.min_distance_r.unwrap_or(f64::INFINITY);
        assert!(through < 1.0, "without self-contact the halves should pass into each other; closest {through} r");
        assert!(!without.clean(), "the drape without self-contact ends clean");
    }

    /// A drop whose fall would reach the divergence speed is refused
    /// before anything runs, naming the highest drop that does not; the
    /// highest is just under that speed, and a fall from it is accepted.
    #[test]
    fn a_drop_too_high_to_land_is_refused_by_the_highest_allowed() {
        let fabric =
            Fabric::from_chart(&Chart::stockinette(4, 4).unwrap(), &yarn_topology::Geometry::default()).unwrap();
        let model = Model::<f64>::new(&fabric, &drape_params(Params::default(), None)).unwrap();
        assert!(check_drop(&model, 0.0).is_ok() && check_drop(&model, 2.0).is_ok());
        let Err(GateError::DropTooHigh { highest, limit, .. }) = check_drop(&model, 1e6) else {
            panic!("a million units up is refused");
        };
        assert_eq!(limit, model.divergence_speed());
        assert!((2.0 * DRAPE_GRAVITY * highest).sqrt() <= limit * (1.0 + 1e-12));
        assert!(check_drop(&model, 0.999 * highest).is_ok());
        assert!(check_drop(&model, 1.001 * highest).is_err());
    }

    #[test]
    fn a_folded_start_is_clear_of_itself_and_above_the_floor() {
        let fabric =
            Fabric::from_chart(&Chart::stockinette(8, 8).unwrap(), &yarn_topology::Geometry::default()).unwrap();
        let start = drape_start(&fabric, true, 2.0);
        let model = Model::<f64>::new(&fabric, &drape_params(Params::default(), None)).unwrap();
        let lowest = start.positions.iter().map(|p| p.y).fold(f64::INFINITY, f64::min);
        assert!((lowest - 2.0).abs() < 1e-9);
        let (closest, _) = yarn_model::self_contact::closest_approach(&model, &start.positions, 3.0).unwrap();
        let flat = drape_start(&fabric, false, 2.0);
        let (closest_flat, _) = yarn_model::self_contact::closest_approach(&model, &flat.positions, 3.0).unwrap();
        assert!(
            closest >= closest_flat - 1e-9,
            "folding brought yarn closer: {closest} r against {closest_flat} r flat"
        );
        let width = |s: &State<f64>| {
            s.positions.iter().map(|p| p.x).fold(f64::MIN, f64::max)
                - s.positions.iter().map(|p| p.x).fold(f64::MAX, f64::min)
        };
        assert!(width(&start) < 0.75 * width(&flat), "the fold should halve the width");
    }
}
