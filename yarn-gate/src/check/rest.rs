//! The gate at a certified rest, the default `check`.
//!
//! 1. Relax the free patch until its rest is certified
//!    ([`crate::certificate`]), by one of two paths ([`crate::settle`]).
//! 2. Measure at that rest: the curl of each edge family with its sign
//!    (SPEC §7: + toward the technical face), and the resting width and
//!    height as arc lengths ([`metrics::extent`]).
//! 3. Probe the stiffness along each axis: clamp the two gripped edges
//!    straight ([`metrics::straight_grips`]) at the resting separation
//!    (with self-contact, easing the assembled patch out to them first:
//!    `eased_out`), hold to a certified rest, pull the far grip out by
//!    [`PULL_STRAIN`], hold to a certified rest again, and read the change
//!    of the far grip's force along the axis.
//! 4. Double: run every relaxation and hold on for as much work again as
//!    it took, and check that no figure moves by more than
//!    [`DOUBLING_CURL`] or [`DOUBLING_FRACTION`].
//!
//! The verdict is the instrument's: every rest certified and nothing moved
//! by doubling. What the figures should be (which edges roll which way,
//! which direction is softer) is reported beside real knit's and the
//! paper's, not judged here.

use nalgebra::Vector3;
use serde::Serialize;
use yarn_model::statics::StaticOptions;
use yarn_model::{Backend, Model, Params, State, V3, step};
use yarn_topology::{Chart, Fabric, Geometry, Pin};

use super::{Criterion, PULL_STRAIN, criteria_table};
use crate::GateError;
use crate::certificate::{DOUBLING_CURL, DOUBLING_FRACTION, REST_COAST, REST_DISPLACEMENT, REST_ENERGY};
use crate::metrics::{self, Axis, Extent};
use crate::settle::{Dynamics, Rest, Settle, Settled, Statics};

/// The progress bar's line: work counts substeps or force evaluations.
pub(crate) const PROGRESS: &str = "{msg:>14} [{bar:40}] {pos}/{len} ({eta})";

/// What to run.
#[derive(Debug, Clone, PartialEq)]
pub struct RestConfig {
    /// The patch's stitches; at least 3×3, so that it has interior
    /// stitches to fit a mid-plane to.
    pub chart: Chart,
    /// The most work each relaxation and hold may take: substeps, or force
    /// evaluations.
    pub budget: u64,
    /// Model parameters.
    pub params: Params,
    /// Stitch geometry.
    pub geometry: Geometry,
}

/// The path the gate took to rest.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Path {
    /// A frictionless quasi-static solve in f64 from the assembled state.
    Static,
    /// The damped dynamics with friction from the assembled state.
    Dynamic,
}

/// Which way an edge family rolls (SPEC §7).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Roll {
    /// Toward the technical face (+z, where a knit stitch's V shows).
    Face,
    /// Toward the back.
    Back,
    /// Within [`super::MIN_CURL`] of the mid-plane.
    Flat,
}

impl Roll {
    fn of(curl: f64) -> Self {
        if curl >= super::MIN_CURL {
            Roll::Face
        } else if curl <= -super::MIN_CURL {
            Roll::Back
        } else {
            Roll::Flat
        }
    }

    fn words(self) -> &'static str {
        match self {
            Roll::Face => "toward the face",
            Roll::Back => "toward the back",
            Roll::Flat => "flat",
        }
    }
}

/// The figures measured at a rest, which doubling must not move.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Figures {
    /// Curl of the course edges (top and bottom rows), in yarn radii, +
    /// toward the technical face.
    pub curl_course: f64,
    /// Curl of the wale edges (left and right columns), likewise.
    pub curl_wale: f64,
    /// Resting width: arc length along the middle row.
    pub width: f64,
    /// Resting height: arc length up the middle column.
    pub height: f64,
    /// Course stiffness: force per unit strain pulling along a row.
    pub stiffness_course: f64,
    /// Wale stiffness: force per unit strain pulling up a column.
    pub stiffness_wale: f64,
}

/// One stiffness probe, both holds at rest.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Hold {
    /// The axis pulled.
    pub axis: Axis,
    /// The grips' separation in the unstrained hold: the resting width or
    /// height.
    pub separation: f64,
    /// The strain of the strained hold.
    pub strain: f64,
    /// The change of the far grip's force along the axis (positive when it
    /// resists the pull).
    pub force: f64,
    /// |F| on the far grip in the unstrained hold.
    pub baseline: f64,
    /// force / strain.
    pub stiffness: f64,
    /// The unstrained hold's rest.
    pub unstrained: Settled,
    /// The strained hold's rest.
    pub strained: Settled,
}

/// What doubling did.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Doubling {
    /// The relaxation run on: its work is twice what certification took.
    pub rest: Settled,
    /// The figures after doubling.
    pub figures: Figures,
    /// Each figure's change: curls in yarn radii, the rest as fractions.
    pub moved: Figures,
}

/// The result of the gate at rest. The flat fields are the stable JSON
/// interface.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RestReport {
    /// Always "default": the preset whose gate this is.
    pub preset: &'static str,
    /// The path to rest.
    pub path: Path,
    /// Backend (dynamics) or solver (statics) name.
    pub backend: String,
    /// What `work` counts: "substeps" or "force evaluations".
    pub unit: &'static str,
    /// Patch size in stitches, `WxH`.
    pub size: String,
    /// Node count.
    pub nodes: usize,
    /// Contact count.
    pub contacts: usize,
    /// Self-contact's stiffness k_sc (0: off).
    pub self_contact: f64,
    /// Friction coefficient μ (the dynamic path's; the static solve has
    /// none).
    pub friction: f64,
    /// Whether stretched contacts have friction too
    /// (`Params::friction_in_tension`).
    pub friction_in_tension: bool,
    /// Whether the relaxation's rest was certified.
    pub certified: bool,
    /// The relaxation: its certificate, work and wall time.
    pub rest: Settled,
    /// Total energy as assembled.
    pub energy_initial: f64,
    /// Total energy at rest.
    pub energy_rest: f64,
    /// The figures at rest.
    pub figures: Figures,
    /// Which way the course edges roll.
    pub roll_course: Roll,
    /// Which way the wale edges roll.
    pub roll_wale: Roll,
    /// The width as assembled, for comparison with the resting width.
    pub width_assembled: f64,
    /// The height as assembled.
    pub height_assembled: f64,
    /// The softer axis.
    pub softer: Axis,
    /// The stiffer axis's stiffness over the softer's.
    pub softer_by: f64,
    /// The two stiffness probes.
    pub holds: [Hold; 2],
    /// Every relaxation and hold run on to twice its work.
    pub doubling: Doubling,
    /// Every criterion with its verdict.
    pub criteria: Vec<Criterion>,
    /// True only when every criterion passes.
    pub pass: bool,
}

/// The gate at rest by the frictionless static path.
///
/// # Errors
/// [`GateError`] for a bad size or parameters, or a patch too small to have
/// interior stitches.
pub fn run_static(
    config: &RestConfig,
    progress: &mut dyn FnMut(&'static str, u64, u64),
) -> Result<RestReport, GateError> {
    let fabric = patch(config)?;
    let settler = Statics::new(&fabric, &config.params, StaticOptions::default())?;
    run(settler, Path::Static, &fabric, config, progress)
}

/// The gate at rest by the dynamics on `backend`.
///
/// # Errors
/// As [`run_static`], and the backend's failures.
pub fn run_dynamic<B: Backend>(
    backend: B,
    config: &RestConfig,
    progress: &mut dyn FnMut(&'static str, u64, u64),
) -> Result<RestReport, GateError> {
    let fabric = patch(config)?;
    let settler = Dynamics::new(backend, &fabric, &config.params)?;
    run(settler, Path::Dynamic, &fabric, config, progress)
}

fn patch(config: &RestConfig) -> Result<Fabric, GateError> {
    if config.chart.width() < 3 || config.chart.height() < 3 {
        return Err(config.too_small());
    }
    Ok(Fabric::from_chart(&config.chart, &config.geometry)?)
}

impl RestConfig {
    /// The error of a patch with no interior stitches, naming its size.
    fn too_small(&self) -> GateError {
        GateError::TooSmall { width: self.chart.width(), height: self.chart.height() }
    }
}

/// The force on the nodes of `fabric`'s far grip along `axis`, summed.
fn grip_force(model: &Model<f64>, fabric: &Fabric, state: &State<f64>, axis: Axis) -> V3<f64> {
    let mut forces = Vec::new();
    step::accumulate_forces(model, &state.positions, &mut forces);
    fabric.side_nodes(axis.grips().1).iter().map(|&i| forces[i as usize]).sum()
}

/// The most `eased_out` stretches the patch at a time on its way out to
/// a hold's grips.
const EASE_STRAIN: f64 = 0.05;

/// Each step of that way is settled for this fraction of the hold's budget.
const EASE_SHARE: u64 = 20;

/// `from` stretched affinely along `direction` about the near grip of
/// `axis` by `strain`, with `grips` put in place, at rest.
fn hold_start(
    fabric: &Fabric,
    axis: Axis,
    direction: Vector3<f64>,
    from: &State<f64>,
    grips: &[Pin],
    strain: f64,
) -> State<f64> {
    let mut state = metrics::stretched(from, &fabric.side_nodes(axis.grips().0), direction, strain);
    for pin in grips {
        state.positions[pin.node as usize] = pin.target;
    }
    state
}

/// Where a hold with self-contact starts: edges that rolled over the
/// fabric and are put straight at once pass through it
/// (`Model::check_apart` refuses that start) or, where they clear it, are
/// torn from the yarn beside them (at μ = 1 with friction in tension the
/// first substep of such a start diverged). So the hold starts from the
/// assembled patch, clear of itself, in the frame of the patch at `at`,
/// flat between grips at its own separation or at `separation` if that is
/// nearer, and eases it out along `direction` (`axis` in that frame) to
/// `separation` in steps of at most [`EASE_STRAIN`], each stretched
/// affinely from the last and settled for `share` units of work
/// (`progress` hears each step's). It only eases outward, which moves no
/// two points closer: a step inward would press a settled state whose
/// edges rolled again while it settled. The rest returned counts the whole
/// way's work and time.
fn eased_out<S: Settle>(
    settler: &mut S,
    fabric: &Fabric,
    at: &[V3<f64>],
    (axis, direction): (Axis, Vector3<f64>),
    separation: f64,
    share: u64,
    progress: &mut dyn FnMut(u64),
) -> Result<Rest, GateError> {
    let start = metrics::assembled_separation(fabric, axis).min(separation);
    let steps = ((separation / start - 1.0) / EASE_STRAIN).ceil().max(1.0) as u32;
    let flat = metrics::flat_between_grips(fabric, at, axis, start);
    let (mut from, mut work, mut seconds) = (start, 0, 0.0);
    let mut eased: Option<Rest> = None;
    for step in 1..=steps {
        let to = start + (separation - start) * f64::from(step) / f64::from(steps);
        let grips = metrics::straight_grips(fabric, at, axis, to);
        let last = eased.as_ref().map_or(&flat, |rest| &rest.state);
        let rest = settler.settle(
            &hold_start(fabric, axis, direction, last, &grips, to / from - 1.0),
            &grips,
            share,
            progress,
        )?;
        (from, work, seconds) = (to, work + rest.work, seconds + rest.seconds);
        eased = Some(rest);
    }
    // `steps` is at least one, so the way has a last step.
    Ok(Rest { work, seconds, ..eased.expect("at least one step") })
}

/// The two holds of one probe, each settled from the last.
struct Probe {
    axis: Axis,
    separation: f64,
    direction: Vector3<f64>,
    unstrained: Rest,
    strained: Rest,
}

impl Probe {
    #[allow(
        clippy::too_many_arguments,
        reason = "the probe's whole setting: path, model, patch, rest, axis, size, budget, progress"
    )]
    fn new<S: Settle>(
        settler: &mut S,
        model: &Model<f64>,
        fabric: &Fabric,
        relaxed: &Rest,
        axis: Axis,
        separation: f64,
        budget: u64,
        progress: &mut dyn FnMut(&'static str, u64, u64),
    ) -> Result<Self, GateError> {
        let at = &relaxed.state.positions;
        let direction = metrics::axis_in_frame(fabric, at, axis);
        let (label0, label1, easing) = match axis {
            Axis::Course => ("hold course", "pull course", "ease course"),
            Axis::Wale => ("hold wale", "pull wale", "ease wale"),
        };
        // Each hold starts from the state before it, with its grips put in
        // place; the strained one also stretched affinely along the axis,
        // so no node starts far from where the pull will leave it.
        let start =
            |from: &State<f64>, grips: &[Pin], strain: f64| hold_start(fabric, axis, direction, from, grips, strain);
        let grips = metrics::straight_grips(fabric, at, axis, separation);
        let unstrained = if model.self_contact() {
            let share = budget / EASE_SHARE;
            let eased = eased_out(settler, fabric, at, (axis, direction), separation, share, &mut |w| {
                progress(easing, w, share);
            })
            .map_err(|e| e.during(easing))?;
            let hold = settler
                .settle(&eased.state, &grips, budget, &mut |w| progress(label0, w, budget))
                .map_err(|e| e.during(label0))?;
            Rest { work: eased.work + hold.work, seconds: eased.seconds + hold.seconds, ..hold }
        } else {
            settler
                .settle(&start(&relaxed.state, &grips, 0.0), &grips, budget, &mut |w| progress(label0, w, budget))
                .map_err(|e| e.during(label0))?
        };
        let grips = metrics::straight_grips(fabric, at, axis, separation * (1.0 + PULL_STRAIN));
        let strained = settler
            .settle(&start(&unstrained.state, &grips, PULL_STRAIN), &grips, budget, &mut |w| {
                progress(label1, w, budget);
            })
            .map_err(|e| e.during(label1))?;
        Ok(Self { axis, separation, direction, unstrained, strained })
    }

    /// Both holds run on to twice their work.
    fn doubled<S: Settle>(
        &self,
        settler: &mut S,
        progress: &mut dyn FnMut(&'static str, u64, u64),
    ) -> Result<Self, GateError> {
        let mut on = |rest: &Rest| {
            settler
                .run_on(rest, rest.work, &mut |w| progress("double holds", w, rest.work))
                .map_err(|e| e.during("double holds"))
        };
        Ok(Self { unstrained: on(&self.unstrained)?, strained: on(&self.strained)?, ..*self })
    }

    fn read(&self, model: &Model<f64>, fabric: &Fabric) -> Hold {
        let f0 = grip_force(model, fabric, &self.unstrained.state, self.axis);
        let f1 = grip_force(model, fabric, &self.strained.state, self.axis);
        // The internal force on the far grip points back toward the near
        // one when the patch resists the pull.
        let force = -(f1 - f0).dot(&self.direction);
        Hold {
            axis: self.axis,
            separation: self.separation,
            strain: PULL_STRAIN,
            force,
            baseline: f0.norm(),
            stiffness: force / PULL_STRAIN,
            unstrained: self.unstrained.settled(),
            strained: self.strained.settled(),
        }
    }

    fn certified(&self) -> bool {
        self.unstrained.certificate.certified && self.strained.certificate.certified
    }
}

fn figures(fabric: &Fabric, state: &State<f64>, probes: [&Hold; 2]) -> Result<Figures, GateError> {
    let (width, height) = fabric.grid().unwrap_or((0, 0));
    let too_small = GateError::TooSmall { width, height };
    let curl = metrics::curl_since_assembly(fabric, &state.positions).ok_or(too_small.clone())?;
    let Extent { width, height } = metrics::extent(fabric, &state.positions).ok_or(too_small)?;
    Ok(Figures {
        curl_course: curl.course,
        curl_wale: curl.wale,
        width,
        height,
        stiffness_course: probes[0].stiffness,
        stiffness_wale: probes[1].stiffness,
    })
}

fn run<S: Settle>(
    mut settler: S,
    path: Path,
    fabric: &Fabric,
    config: &RestConfig,
    progress: &mut dyn FnMut(&'static str, u64, u64),
) -> Result<RestReport, GateError> {
    let budget = config.budget;
    let ruler = Model::<f64>::new(fabric, &config.params)?;
    let start = State::at_rest(fabric);
    let relaxed =
        settler.settle(&start, &[], budget, &mut |w| progress("relax", w, budget)).map_err(|e| e.during("relax"))?;
    let extent = metrics::extent(fabric, &relaxed.state.positions).ok_or_else(|| config.too_small())?;
    let course = Probe::new(&mut settler, &ruler, fabric, &relaxed, Axis::Course, extent.width, budget, progress)?;
    let wale = Probe::new(&mut settler, &ruler, fabric, &relaxed, Axis::Wale, extent.height, budget, progress)?;
    let holds = [course.read(&ruler, fabric), wale.read(&ruler, fabric)];
    let at_rest = figures(fabric, &relaxed.state, [&holds[0], &holds[1]])?;

    let relaxed_twice = settler
        .run_on(&relaxed, relaxed.work, &mut |w| progress("double relax", w, relaxed.work))
        .map_err(|e| e.during("double relax"))?;
    let (course_twice, wale_twice) = (course.doubled(&mut settler, progress)?, wale.doubled(&mut settler, progress)?);
    let holds_twice = [course_twice.read(&ruler, fabric), wale_twice.read(&ruler, fabric)];
    let twice = figures(fabric, &relaxed_twice.state, [&holds_twice[0], &holds_twice[1]])?;
    let fraction = |a: f64, b: f64| (b - a).abs() / a.abs().max(f64::MIN_POSITIVE);
    let moved = Figures {
        curl_course: (twice.curl_course - at_rest.curl_course).abs(),
        curl_wale: (twice.curl_wale - at_rest.curl_wale).abs(),
        width: fraction(at_rest.width, twice.width),
        height: fraction(at_rest.height, twice.height),
        stiffness_course: fraction(at_rest.stiffness_course, twice.stiffness_course),
        stiffness_wale: fraction(at_rest.stiffness_wale, twice.stiffness_wale),
    };
    let doubling = Doubling { rest: relaxed_twice.settled(), figures: twice, moved };

    let assembled = metrics::extent(fabric, fabric.positions()).ok_or_else(|| config.too_small())?;
    let (softer, softer_by) = if holds[0].stiffness <= holds[1].stiffness {
        (Axis::Course, holds[1].stiffness / holds[0].stiffness)
    } else {
        (Axis::Wale, holds[0].stiffness / holds[1].stiffness)
    };
    let criteria = criteria(&settler, path, &relaxed, [&course, &wale], &at_rest, &doubling);
    Ok(RestReport {
        preset: "default",
        path,
        backend: settler.name(),
        unit: settler.unit(),
        size: format!("{}x{}", config.chart.width(), config.chart.height()),
        nodes: fabric.node_count(),
        contacts: fabric.contacts().len(),
        self_contact: config.params.self_contact_stiffness,
        friction: config.params.friction,
        friction_in_tension: config.params.friction_in_tension,
        certified: relaxed.certificate.certified,
        rest: relaxed.settled(),
        energy_initial: step::energy(&ruler, &start).total(),
        energy_rest: step::energy(&ruler, &relaxed.state).total(),
        figures: at_rest,
        roll_course: Roll::of(at_rest.curl_course),
        roll_wale: Roll::of(at_rest.curl_wale),
        width_assembled: assembled.width,
        height_assembled: assembled.height,
        softer,
        softer_by,
        holds,
        doubling,
        pass: criteria.iter().all(|c| c.pass),
        criteria,
    })
}

/// The rest criteria's threshold on `path`, in words: a rest on the
/// dynamics may also have kept still.
fn rest_threshold(path: Path) -> String {
    let at_minimum = format!("step < {REST_DISPLACEMENT} r, energy left < {REST_ENERGY:e}, coast < {REST_COAST} r");
    match path {
        Path::Static => at_minimum,
        Path::Dynamic => {
            format!("{at_minimum}; or still: creep over a doubling < {REST_DISPLACEMENT} r, coast < {REST_COAST} r")
        }
    }
}

fn criteria<S: Settle>(
    settler: &S,
    path: Path,
    relaxed: &Rest,
    probes: [&Probe; 2],
    at_rest: &Figures,
    doubling: &Doubling,
) -> Vec<Criterion> {
    let unit = settler.unit();
    let mut criteria = vec![Criterion {
        name: "rest certified",
        measured: format!("{} after {} {unit}, {:.1} s", relaxed.certificate.describe(), relaxed.work, relaxed.seconds),
        threshold: rest_threshold(path),
        paper: "(fixed 12,000 substeps)",
        pass: relaxed.certificate.certified,
    }];
    for (probe, name) in probes.iter().zip(["course holds certified", "wale holds certified"]) {
        // The one not certified, or of the two the farther from its minimum.
        let badness = |rest: &Rest| (!rest.certificate.certified, rest.certificate.displacement);
        let worst =
            if badness(&probe.unstrained) >= badness(&probe.strained) { &probe.unstrained } else { &probe.strained };
        criteria.push(Criterion {
            name,
            measured: format!(
                "worst {} ({} + {} {unit})",
                worst.certificate.describe(),
                probe.unstrained.work,
                probe.strained.work
            ),
            threshold: rest_threshold(path),
            paper: "(fixed 12,000 substeps)",
            pass: probe.certified(),
        });
    }
    let m = &doubling.moved;
    let curl_limit = |curl: f64| DOUBLING_CURL.max(DOUBLING_FRACTION * curl.abs());
    criteria.extend([
        Criterion {
            name: "doubling: curl",
            measured: format!("course moved {:.1e} r, wale {:.1e} r", m.curl_course, m.curl_wale),
            threshold: format!("< {DOUBLING_CURL} r or {} %", 100.0 * DOUBLING_FRACTION),
            paper: "-",
            pass: m.curl_course < curl_limit(at_rest.curl_course) && m.curl_wale < curl_limit(at_rest.curl_wale),
        },
        Criterion {
            name: "doubling: stiffness",
            measured: format!(
                "course moved {:.2} %, wale {:.2} %",
                100.0 * m.stiffness_course,
                100.0 * m.stiffness_wale
            ),
            threshold: format!("< {} %", 100.0 * DOUBLING_FRACTION),
            paper: "-",
            pass: m.stiffness_course < DOUBLING_FRACTION && m.stiffness_wale < DOUBLING_FRACTION,
        },
        Criterion {
            name: "doubling: size",
            measured: format!("width moved {:.2} %, height {:.2} %", 100.0 * m.width, 100.0 * m.height),
            threshold: format!("< {} %", 100.0 * DOUBLING_FRACTION),
            paper: "-",
            pass: m.width < DOUBLING_FRACTION && m.height < DOUBLING_FRACTION,
        },
    ]);
    criteria
}

impl RestReport {
    /// The human-readable table: the criteria, then the figures at rest.
    pub fn table(&self) -> String {
        let path = match self.path {
            Path::Static => "frictionless static solve in f64".to_owned(),
            Path::Dynamic if self.friction > 0.0 => {
                let tension = if self.friction_in_tension { ", stretched contacts too," } else { "" };
                format!("dynamics with friction μ = {}{tension} on {}", self.friction, self.backend)
            }
            Path::Dynamic => format!("dynamics without friction on {}", self.backend),
        };
        let f = &self.figures;
        let touching =
            if self.self_contact > 0.0 { format!(", self-contact at {}", self.self_contact) } else { String::new() };
        let mut out = format!(
            "yarn-gate check: {} patch, {} nodes, {} contacts{touching}, at certified rest by {path}\n\n",
            self.size, self.nodes, self.contacts
        );
        out += &criteria_table(&self.criteria, self.pass);
        out += &format!(
            "\nat rest{}:\n\
             \x20 energy        {:.1} -> {:.1}\n\
             \x20 curl          course edges {:+.3} r ({}), wale edges {:+.3} r ({})\n\
             \x20               real stockinette: course toward the face, wale toward the back; paper -0.078 / -0.108\n\
             \x20 width, height {:.2} x {:.2} along the middle row and column (assembled {:.2} x {:.2})\n\
             \x20 stiffness     course {:.3}, wale {:.3}: {} softer, x{:.2}\n\
             \x20               real knit: a row stretches more (course softer); paper: course x6.4 stiffer\n",
            if self.certified { "" } else { " (NOT certified: a transient)" },
            self.energy_initial,
            self.energy_rest,
            f.curl_course,
            self.roll_course.words(),
            f.curl_wale,
            self.roll_wale.words(),
            f.width,
            f.height,
            self.width_assembled,
            self.height_assembled,
            f.stiffness_course,
            f.stiffness_wale,
            match self.softer {
                Axis::Course => "course",
                Axis::Wale => "wale",
            },
            self.softer_by,
        );
        out
    }
}

#[cfg(test)]
mod tests {
    use yarn_backend_cpu::Serial;

    use super::*;

    /// A patch at rest as assembled (κ = 1), without friction: both paths
    /// certify the relaxation at once, with no work, and bring each hold,
    /// pulled or not, to a certified rest with work. (Its stiffness is
    /// near zero, 1e-3 at most: with bending by turning angle alone and few
    /// contacts, a 4x4 patch has a mechanism that stretches it for free, so
    /// the two paths' stiffnesses are not compared here.)
    #[test]
    fn both_paths_certify_a_patch_at_rest_and_its_holds() {
        let params = Params { rest_curl: 1.0, friction: 0.0, ..Params::paper() };
        let chart = Chart::stockinette(4, 4).unwrap();
        let config = RestConfig { chart, budget: 400_000, params, geometry: Geometry::paper() };
        let statics = run_static(&config, &mut |_, _, _| {}).unwrap();
        let dynamics = run_dynamic(Serial::<f64>::new(), &config, &mut |_, _, _| {}).unwrap();
        for report in [&statics, &dynamics] {
            // The solve counts the one evaluation that finds the forces zero.
            assert!(report.certified && report.rest.work <= 1, "{}", report.table());
            for hold in &report.holds {
                assert!(hold.unstrained.certificate.certified && hold.strained.certificate.certified, "{hold:?}");
                assert!(hold.strained.work > 0, "{hold:?}");
            }
            assert!(report.figures.curl_course.abs() < 1e-6 && report.figures.curl_wale.abs() < 1e-6);
            let f = &report.figures;
            assert!(
                (f.width - report.width_assembled).abs() < 1e-9 && (f.height - report.height_assembled).abs() < 1e-9
            );
        }
        assert_eq!((statics.path, dynamics.path), (Path::Static, Path::Dynamic));
        assert_eq!((statics.unit, dynamics.unit), ("force evaluations", "substeps"));
    }

    /// A settler that notes how far apart along an axis the grips of each
    /// settle it is handed are, and hands the settle on.
    struct GripsNoted<'a> {
        settler: &'a mut Statics,
        fabric: &'a Fabric,
        axis: Axis,
        direction: Vector3<f64>,
        separations: Vec<f64>,
    }

    impl Settle for GripsNoted<'_> {
        fn name(&self) -> String {
            self.settler.name()
        }

        fn unit(&self) -> &'static str {
            self.settler.unit()
        }

        fn settle(
            &mut self,
            start: &State<f64>,
            pins: &[Pin],
            budget: u64,
            progress: &mut dyn FnMut(u64),
        ) -> Result<Rest, GateError> {
            let (near, far) = self.axis.grips();
            let along = |side| {
                let nodes = self.fabric.side_nodes(side);
                let on = |i: &u32| pins.iter().find(|pin| pin.node == *i).map(|pin| pin.target.dot(&self.direction));
                nodes.iter().filter_map(on).sum::<f64>() / nodes.len() as f64
            };
            self.separations.push(along(far) - along(near));
            self.settler.settle(start, pins, budget, progress)
        }

        fn run_on(&mut self, rest: &Rest, work: u64, progress: &mut dyn FnMut(u64)) -> Result<Rest, GateError> {
            self.settler.run_on(rest, work, progress)
        }
    }

    /// With self-contact the holds ease the assembled patch out to their
    /// grips: where the 4x4 patch's rolled edges, put straight at once, pass
    /// through the fabric (refused) or pull hard on the yarn beside them,
    /// the eased start is clear of itself, pulls on no free node a tenth as
    /// hard, and took work. The way there never presses the patch together:
    /// its grips start at the nearer of the assembled and the hold's
    /// separation and only move out.
    #[test]
    fn with_self_contact_a_hold_eases_the_assembled_patch_out_to_its_grips() {
        let params = Params { self_contact_stiffness: 1600.0, ..Params::default() };
        let fabric = Fabric::from_chart(&Chart::stockinette(4, 4).unwrap(), &Geometry::default()).unwrap();
        let model = Model::<f64>::new(&fabric, &params).unwrap();
        let mut settler = Statics::new(&fabric, &params, StaticOptions::default()).unwrap();
        let relaxed = settler.settle(&State::at_rest(&fabric), &[], super::super::STATIC_BUDGET, &mut |_| {}).unwrap();
        assert!(relaxed.certificate.certified, "{:?}", relaxed.certificate);
        let at = &relaxed.state.positions;
        let extent = metrics::extent(&fabric, at).unwrap();
        let largest_free_force = |state: &State<f64>, grips: &[Pin]| {
            let mut forces = Vec::new();
            step::accumulate_forces(&model, &state.positions, &mut forces);
            let pinned: Vec<usize> = grips.iter().map(|pin| pin.node as usize).collect();
            (0..forces.len()).filter(|i| !pinned.contains(i)).map(|i| forces[i].norm()).fold(0.0, f64::max)
        };
        let mut refused = 0;
        for (axis, separation) in [(Axis::Course, extent.width), (Axis::Wale, extent.height)] {
            let grips = metrics::straight_grips(&fabric, at, axis, separation);
            let direction = metrics::axis_in_frame(&fabric, at, axis);
            let straight = hold_start(&fabric, axis, direction, &relaxed.state, &grips, 0.0);
            refused += usize::from(model.check_apart(&straight.positions).is_err());
            let mut noted = GripsNoted { settler: &mut settler, fabric: &fabric, axis, direction, separations: vec![] };
            let eased = eased_out(&mut noted, &fabric, at, (axis, direction), separation, 1_000, &mut |_| {}).unwrap();
            let mut way = vec![metrics::assembled_separation(&fabric, axis).min(separation)];
            way.extend(&noted.separations);
            let outward = |w: &[f64]| w[1] >= w[0] * (1.0 - 1e-9) && w[1] <= w[0] * (1.0 + EASE_STRAIN + 1e-9);
            assert!(way.windows(2).all(outward), "{axis:?}: a step in or too far out: {way:?}");
            assert!((way[way.len() - 1] / separation - 1.0).abs() < 1e-9, "{axis:?}: {way:?} ends off {separation}");
            assert!(model.check_apart(&eased.state.positions).is_ok(), "{axis:?}: the eased start is through itself");
            assert!(eased.work > 0 && eased.pins == grips, "{axis:?}: {} work, pins {:?}", eased.work, eased.pins);
            let (pull, straight_pull) =
                (largest_free_force(&eased.state, &grips), largest_free_force(&straight, &grips));
            assert!(10.0 * pull < straight_pull, "{axis:?}: eased {pull}, straight at once {straight_pull}");
        }
        assert!(refused > 0, "neither axis's straight start passes through the fabric");
    }

    /// The gate builds its patch from the chart it is given: a seed chart's
    /// purl legs lie behind the face as assembled, where stockinette's lie
    /// in front, so the two read different edges before any work; and a
    /// chart too narrow for interior stitches is refused by its size.
    #[test]
    fn the_gate_at_rest_knits_the_chart_it_is_given() {
        let run = |pattern: yarn_topology::Pattern, (w, h)| {
            let chart = pattern.chart(w, h).unwrap();
            let config = RestConfig { chart, budget: 1, params: Params::default(), geometry: Geometry::default() };
            run_static(&config, &mut |_, _, _| {})
        };
        let seed = run(yarn_topology::Pattern::Seed, (4, 3)).unwrap();
        let plain = run(yarn_topology::Pattern::Stockinette, (4, 3)).unwrap();
        let fabric =
            Fabric::from_chart(&yarn_topology::Pattern::Seed.chart(4, 3).unwrap(), &Geometry::default()).unwrap();
        assert_eq!(
            (seed.size.as_str(), seed.nodes, seed.contacts),
            ("4x3", fabric.node_count(), fabric.contacts().len())
        );
        println!("seed {:?}\nstockinette {:?}", seed.figures, plain.figures);
        // Curl is measured since assembly, and one evaluation barely moves
        // the patch; its stiffness already tells the charts apart.
        assert_ne!(
            (seed.figures.stiffness_course, seed.figures.stiffness_wale),
            (plain.figures.stiffness_course, plain.figures.stiffness_wale),
            "the same patch whatever the chart"
        );
        assert_eq!(run(yarn_topology::Pattern::Rib1x1, (2, 5)), Err(GateError::TooSmall { width: 2, height: 5 }));
    }
}
