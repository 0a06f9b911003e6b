//! The demo's state and actions, independent of the browser: a fabric on the
//! GPU backend, the camera, the pins that grabbing, gravity and unravelling
//! hold, the floor it may be dropped on, and the contact-release schedules.

use std::future::Future;
use std::sync::Arc;

use serde::Serialize;
use yarn_backend_wgpu::{Gpu, Mode, Raised, Wgpu, wgpu};
use yarn_model::{Backend, BackendError, Collider, Params, Plane, State, V3};
use yarn_render::{RenderError, Renderer, View, Yarn};
use yarn_topology::{Fabric, Geometry, Pattern, Pin, Side, StitchKind, TopologyError, Vec3};

/// The texture format [`Demo::draw`] targets when drawing offscreen (a
/// canvas uses its own preferred format's sRGB view).
pub const OFFSCREEN_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8UnormSrgb;

/// The names [`Demo::set`] takes: the numeric settings. The pattern is set
/// by name, with [`Demo::set_pattern`].
pub const SETTINGS: &str =
    "stretch, bend, curl, contact, friction, self-contact, damping, gravity, floor, substeps, width, height";

/// Frames between two contact releases while unravelling or laddering.
const FRAMES_PER_RELEASE: u64 = 2;
/// How far the loose end is pulled while unravelling, in stitch heights,
/// and how much farther each frame.
const PULL: f64 = 3.0;
const PULL_PER_FRAME: f64 = 0.05;
/// Gravity when it is on, in model units per s² (as the drape example).
const GRAVITY: f64 = 9.81;
/// How high above the floor the patch starts when dropped on it, in yarn
/// radii: with the default damping it falls at about g/β, 1 a second, so a
/// short drop lands in a couple of seconds.
const DROP: f64 = 3.0;
/// The self-contact stiffness k_sc the floor turns on where it is off:
/// `yarn-gate drape`'s, so a patch dropped on the floor keeps its loops
/// apart.
const SELF_CONTACT: f64 = 1600.0;
/// The farthest from the cursor a grab reaches, in pixels.
const GRAB_RADIUS: f32 = 40.0;
/// Patch sides, in stitches.
const SIDES: std::ops::RangeInclusive<usize> = 2..=128;
/// Substeps per frame.
const SUBSTEPS: std::ops::RangeInclusive<u32> = 1..=500;

/// What the demo simulates and how fast it steps.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Settings {
    /// Patch width in stitches (default: 16).
    pub width: usize,
    /// Patch height in rows (default: 16).
    pub height: usize,
    /// Substeps per frame (default: 22, as in the paper).
    pub substeps_per_frame: u32,
    /// Gravity on, with the top row held (default: off).
    pub gravity: bool,
    /// A floor under the patch, which is laid flat above it and dropped
    /// under gravity, nothing held, with self-contact on (default: off).
    pub floor: bool,
    /// The knit-purl pattern the patch is knitted in (default:
    /// stockinette, the plain knit the model was fitted to).
    pub pattern: Pattern,
    /// The model and solver parameters.
    pub params: Params,
}

impl Default for Settings {
    fn default() -> Self {
        Self {
            width: 16,
            height: 16,
            substeps_per_frame: 22,
            gravity: false,
            floor: false,
            pattern: Pattern::Stockinette,
            params: Params::default(),
        }
    }
}

/// Why the demo refused an action. Nothing changed when it did.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum DemoError {
    /// The simulation refused (bad parameters, a device failure).
    #[error(transparent)]
    Backend(#[from] BackendError),
    /// Drawing failed.
    #[error(transparent)]
    Render(#[from] RenderError),
    /// The fabric could not be built.
    #[error(transparent)]
    Topology(#[from] TopologyError),
    /// [`Demo::set`] got a name it does not know.
    #[error("unknown setting `{0}`; the settings are: {SETTINGS}")]
    UnknownSetting(String),
    /// [`Demo::set`] or [`Demo::setting`] was asked for the pattern, which
    /// is a name, not a number.
    #[error("the pattern is a name, not a number: set it with set_pattern, to one of: {}", pattern_names())]
    PatternIsAName,
    /// [`Demo::set`] got a value outside the setting's range.
    #[error("{name} = {value} is outside {range}")]
    OutOfRange {
        /// The setting.
        name: &'static str,
        /// The value given.
        value: f64,
        /// The values it takes.
        range: String,
    },
}

/// What the status line shows.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Status {
    /// The adapter's name and backend.
    pub adapter: String,
    /// The pattern's name ([`Pattern::name`]).
    pub pattern: &'static str,
    /// Purl stitches in the patch, as its chart has them.
    pub purls: usize,
    /// Yarn nodes.
    pub nodes: usize,
    /// Contacts, alive or not.
    pub contacts: usize,
    /// Contacts still alive.
    pub alive: usize,
    /// Substeps taken since the fabric was loaded.
    pub substeps: u64,
    /// Frames stepped since then.
    pub frames: u64,
    /// The node held by the cursor, if any.
    pub grabbed: Option<u32>,
    /// The loose end is being pulled and rows unknit.
    pub unravelling: bool,
    /// A dropped stitch is laddering down a wale.
    pub laddering: bool,
    /// The patch was dropped on the floor.
    pub floor: bool,
    /// Slots in each segment's self-contact candidate list.
    pub slots: u32,
    /// What the GPU last raised, in words, and what was done about it
    /// ([`Demo::settle`]).
    pub raised: Option<String>,
}

/// A node held by the cursor.
#[derive(Debug, Clone, Copy)]
struct Grab {
    node: u32,
    /// Its depth in the image when grabbed: the cursor drags it in that
    /// plane.
    depth: f32,
    target: Vec3,
}

/// Contacts being released one after another.
#[derive(Debug, Clone)]
struct Release {
    order: Vec<usize>,
    next: usize,
    /// Unravelling (the loose end is pulled), rather than a ladder.
    unravel: bool,
}

/// The live demo: a fabric on the GPU and everything done to it.
#[derive(Debug)]
pub struct Demo {
    backend: Wgpu,
    renderer: Renderer,
    settings: Settings,
    fabric: Fabric,
    /// Where the patch started: as knitted, or laid flat above the floor.
    start: Vec<Vec3>,
    /// Purl stitches in the fabric's chart.
    purls: usize,
    yarn: Yarn,
    view: View,
    alive: Vec<bool>,
    grab: Option<Grab>,
    release: Option<Release>,
    /// How far the loose end has been pulled, in stitch heights.
    pull: f64,
    frames: u64,
    substeps: u64,
    /// What the GPU last raised ([`Status::raised`]).
    raised: Option<String>,
}

impl Demo {
    /// A demo on `gpu`, drawing into textures of `format`.
    ///
    /// # Errors
    /// Settings that give no valid fabric or parameters, or a device
    /// failure.
    pub fn new(gpu: Arc<Gpu>, format: wgpu::TextureFormat, settings: Settings) -> Result<Self, DemoError> {
        let renderer = Renderer::for_format(&gpu, format);
        let mut backend = Wgpu::with_gpu(gpu, Mode::Gather);
        let Loaded { fabric, start, purls, yarn } = load(&mut backend, &renderer, &settings)?;
        let alive = vec![true; fabric.contacts().len()];
        let view = View { orbit: 0.35, elevation: 0.45, ..View::default() };
        Ok(Self {
            backend,
            renderer,
            settings,
            fabric,
            start,
            purls,
            yarn,
            view,
            alive,
            grab: None,
            release: None,
            pull: 0.0,
            frames: 0,
            substeps: 0,
            raised: None,
        })
    }

    /// Start again from the flat patch, with the current settings.
    ///
    /// # Errors
    /// A device failure.
    pub fn reset(&mut self) -> Result<(), DemoError> {
        self.reload(self.settings)
    }

    /// Load a fresh patch for `settings`, committing them only if it loads.
    fn reload(&mut self, settings: Settings) -> Result<(), DemoError> {
        let loaded = match load(&mut self.backend, &self.renderer, &settings) {
            Ok(loaded) => loaded,
            Err(e) => {
                // The backend may have let go of the old fabric: put it back.
                load(&mut self.backend, &self.renderer, &self.settings)?;
                self.upload_pins()?;
                return Err(e);
            }
        };
        self.alive = vec![true; loaded.fabric.contacts().len()];
        let Loaded { fabric, start, purls, yarn } = loaded;
        (self.settings, self.fabric, self.start, self.purls, self.yarn) = (settings, fabric, start, purls, yarn);
        (self.grab, self.release, self.pull, self.frames, self.substeps) = (None, None, 0.0, 0, 0);
        self.raised = None;
        self.upload_pins()
    }

    /// Change one setting by name (see [`SETTINGS`]): the model parameters
    /// `stretch` (k_s), `bend` (k_b), `curl` (κ), `contact` (k_c),
    /// `friction` (μ), `self-contact` (k_sc, 0 off), `damping` (β);
    /// `gravity` (0 off, else on); `floor` (0 off, else on: the patch is
    /// laid flat above a floor and dropped on it, which reloads it and
    /// turns self-contact on at 1,600 where it is off);
    /// `substeps` per frame; the patch's `width` and `height`, which
    /// reload it. The pattern is a name: see [`Demo::set_pattern`].
    ///
    /// # Errors
    /// An unknown name, a value out of range, or parameters the model
    /// refuses (e.g. a stiffness the substep cannot hold); the demo is
    /// unchanged.
    pub fn set(&mut self, name: &str, value: f64) -> Result<(), DemoError> {
        let mut settings = self.settings;
        let params = &mut settings.params;
        match name {
            "stretch" => params.stretch_stiffness = value,
            "bend" => params.bend_stiffness = value,
            "curl" => params.rest_curl = value,
            "contact" => params.contact_stiffness = value,
            "friction" => params.friction = value,
            "self-contact" => params.self_contact_stiffness = value,
            "damping" => params.damping = value,
            "gravity" => {
                settings.gravity = value != 0.0;
                settings.params.gravity = gravity_of(&settings);
            }
            "floor" => {
                settings.floor = value != 0.0;
                settings.params.gravity = gravity_of(&settings);
                if settings.floor && settings.params.self_contact_stiffness == 0.0 {
                    settings.params.self_contact_stiffness = SELF_CONTACT;
                }
                return self.reload(settings);
            }
            "substeps" => {
                settings.substeps_per_frame =
                    whole(value, &SUBSTEPS).ok_or_else(|| out_of_range("substeps", value, &SUBSTEPS))?;
                self.settings = settings;
                return Ok(());
            }
            "width" | "height" => {
                let side = whole(value, &SIDES).ok_or_else(|| out_of_range(side_name(name), value, &SIDES))?;
                *(if name == "width" { &mut settings.width } else { &mut settings.height }) = side;
                return self.reload(settings);
            }
            "pattern" => return Err(DemoError::PatternIsAName),
            _ => return Err(DemoError::UnknownSetting(name.to_owned())),
        }
        self.backend.set_params(&settings.params)?;
        self.settings = settings;
        self.upload_pins()
    }

    /// The current value of one setting by name, as [`Demo::set`] takes
    /// it (`gravity` is 1 when on, 0 when off).
    ///
    /// # Errors
    /// An unknown name.
    pub fn setting(&self, name: &str) -> Result<f64, DemoError> {
        let (settings, params) = (&self.settings, &self.settings.params);
        Ok(match name {
            "stretch" => params.stretch_stiffness,
            "bend" => params.bend_stiffness,
            "curl" => params.rest_curl,
            "contact" => params.contact_stiffness,
            "friction" => params.friction,
            "self-contact" => params.self_contact_stiffness,
            "damping" => params.damping,
            "gravity" => f64::from(u8::from(settings.gravity)),
            "floor" => f64::from(u8::from(settings.floor)),
            "substeps" => f64::from(settings.substeps_per_frame),
            "width" => settings.width as f64,
            "height" => settings.height as f64,
            "pattern" => return Err(DemoError::PatternIsAName),
            _ => return Err(DemoError::UnknownSetting(name.to_owned())),
        })
    }

    /// Knit the patch in the pattern named `name` (one of
    /// [`Pattern::ALL`]'s names, e.g. `rib-1x1`), which reloads it as a
    /// size change does.
    ///
    /// # Errors
    /// A name that is no pattern ([`TopologyError::UnknownPattern`], which
    /// lists them), or a device failure; the demo is unchanged.
    pub fn set_pattern(&mut self, name: &str) -> Result<(), DemoError> {
        let pattern = name.parse()?;
        self.reload(Settings { pattern, ..self.settings })
    }

    /// The current settings.
    pub fn settings(&self) -> &Settings {
        &self.settings
    }

    /// Advance one frame: the next scheduled contact release and pull, then
    /// [`Settings::substeps_per_frame`] substeps. Nothing is read back.
    ///
    /// # Errors
    /// A device failure.
    pub fn step(&mut self) -> Result<(), DemoError> {
        self.frames += 1;
        if let Some(release) = &mut self.release {
            if self.frames.is_multiple_of(FRAMES_PER_RELEASE)
                && let Some(&contact) = release.order.get(release.next)
            {
                release.next += 1;
                self.alive[contact] = false;
                self.backend.set_contacts_alive(&self.alive)?;
            }
            if release.unravel && self.pull < PULL {
                self.pull = (self.pull + PULL_PER_FRAME).min(PULL);
                self.upload_pins()?;
            }
        }
        let substeps = u64::from(self.settings.substeps_per_frame);
        self.backend.advance(substeps)?;
        self.substeps += substeps;
        Ok(())
    }

    /// Record a drawing of the current state into `target`, a texture view
    /// of the format the demo was made for, sized as set by
    /// [`Demo::resize`].
    ///
    /// # Errors
    /// A bad size or a device failure.
    pub fn draw(&self, encoder: &mut wgpu::CommandEncoder, target: &wgpu::TextureView) -> Result<(), DemoError> {
        let positions = self.backend.positions().ok_or(BackendError::NotLoaded)?;
        Ok(self.renderer.draw(encoder, target, positions, &self.yarn, &self.view)?)
    }

    /// The image size in pixels.
    pub fn resize(&mut self, width: u32, height: u32) {
        (self.view.width, self.view.height) = (width.max(1), height.max(1));
    }

    /// Turn the camera: `orbit` about the vertical, `elevation` up, in
    /// radians.
    pub fn orbit(&mut self, orbit: f32, elevation: f32) {
        self.view.orbit += orbit;
        self.view.elevation = (self.view.elevation + elevation).clamp(-1.45, 1.45);
    }

    /// Zoom in by `factor` (below 1 zooms out), within 0.5x to 8x.
    pub fn zoom(&mut self, factor: f32) {
        if factor.is_finite() && factor > 0.0 {
            self.view.zoom = (self.view.zoom * factor).clamp(0.5, 8.0);
        }
    }

    /// The camera.
    pub fn view(&self) -> &View {
        &self.view
    }

    /// Where node positions land on screen, for picking; see
    /// [`Yarn::project`].
    pub fn yarn(&self) -> &Yarn {
        &self.yarn
    }

    /// Read the positions back without blocking: submitted now, awaited
    /// later (in the browser, across frames). Only grabs and tests need
    /// them; the steady state reads nothing.
    ///
    /// # Errors
    /// A device failure.
    pub fn positions(&self) -> Result<impl Future<Output = Result<Vec<V3<f32>>, BackendError>> + 'static, DemoError> {
        Ok(self.backend.read_positions()?)
    }

    /// Grab the node nearest pixel (`x`, `y`) within a small radius, given
    /// the `positions` read back when the grab began. Returns the node, or
    /// `None` when nothing is near.
    ///
    /// # Errors
    /// A device failure.
    pub fn grab(&mut self, positions: &[V3<f32>], x: f32, y: f32) -> Result<Option<u32>, DemoError> {
        let projected: Vec<_> = positions.iter().map(|p| self.yarn.project(&self.view, [p.x, p.y, p.z])).collect();
        let Some(node) = nearest(&projected, x, y, GRAB_RADIUS) else { return Ok(None) };
        let (p, depth) = (positions[node], projected[node].map_or(0.5, |[_, _, depth]| depth));
        let node = node as u32;
        self.grab = Some(Grab { node, depth, target: Vec3::new(p.x.into(), p.y.into(), p.z.into()) });
        self.upload_pins()?;
        Ok(Some(node))
    }

    /// Move the grabbed node's target under pixel (`x`, `y`), in the plane
    /// it was grabbed in. Does nothing without a grab.
    ///
    /// # Errors
    /// A device failure.
    pub fn drag(&mut self, x: f32, y: f32) -> Result<(), DemoError> {
        let Some(grab) = &mut self.grab else { return Ok(()) };
        let [px, py, pz] = self.yarn.unproject(&self.view, x, y, grab.depth);
        grab.target = Vec3::new(px.into(), py.into(), pz.into());
        self.upload_pins()
    }

    /// Let go of the grabbed node.
    ///
    /// # Errors
    /// A device failure.
    pub fn let_go(&mut self) -> Result<(), DemoError> {
        self.grab = None;
        self.upload_pins()
    }

    /// Start (or stop) unravelling: the cast-on row is held, the loose end
    /// at the bind-off is pulled up and out, and contacts are released in
    /// yarn order from that end, so the top row unknits first.
    ///
    /// # Errors
    /// A device failure.
    pub fn unravel(&mut self, on: bool) -> Result<(), DemoError> {
        self.release = on.then(|| Release { order: unravel_order(&self.fabric, &self.alive), next: 0, unravel: true });
        self.pull = 0.0;
        self.upload_pins()
    }

    /// Drop the stitch at the top of the middle column: its contacts are
    /// released from the top row down, and the run ladders down the wale.
    ///
    /// # Errors
    /// A device failure.
    pub fn ladder(&mut self) -> Result<(), DemoError> {
        let order = ladder_order(&self.fabric, self.settings.width / 2);
        self.release = Some(Release { order, next: 0, unravel: false });
        self.upload_pins()
    }

    /// The fabric as built from the chart, at rest: its nodes, contacts
    /// and grid, for tests and tools.
    pub fn fabric(&self) -> &Fabric {
        &self.fabric
    }

    /// What the status line shows.
    pub fn status(&self) -> Status {
        Status {
            adapter: self.backend.gpu().adapter(),
            pattern: self.settings.pattern.name(),
            purls: self.purls,
            nodes: self.fabric.node_count(),
            contacts: self.alive.len(),
            alive: self.alive.iter().filter(|&&a| a).count(),
            substeps: self.substeps,
            frames: self.frames,
            grabbed: self.grab.map(|g| g.node),
            unravelling: self.release.as_ref().is_some_and(|r| r.unravel),
            laddering: self.release.as_ref().is_some_and(|r| !r.unravel),
            floor: self.settings.floor,
            slots: self.backend.list_slots().unwrap_or(0),
            raised: self.raised.clone(),
        }
    }

    /// What the GPU raised since the last look ([`Raised`]), read without
    /// blocking, to hand to [`Demo::settle`]: in the browser
    /// [`Demo::step`] cannot wait for it.
    ///
    /// # Errors
    /// A device failure.
    pub fn read_raised(&mut self) -> Result<impl Future<Output = Result<Raised, BackendError>> + 'static, DemoError> {
        Ok(self.backend.read_raised()?)
    }

    /// Act on what the GPU raised. Lists too short for a crush grow (the
    /// substeps that found them short ran without the candidates left
    /// over); an overflow, a divergence or yarn stretched past the search
    /// starts the patch again, since the state those substeps left cannot
    /// be trusted. [`Status::raised`] says which.
    ///
    /// # Errors
    /// Lists that long do not fit the device
    /// ([`BackendError::TooLarge`]), or a device failure.
    pub fn settle(&mut self, raised: Raised) -> Result<(), DemoError> {
        let Raised { first, end, .. } = raised;
        let failed = if raised.diverged {
            Some("the simulation diverged")
        } else if raised.overstretched {
            Some("yarn stretched past what the self-contact search covers")
        } else if raised.overflowed {
            Some("a fixed-point force overflowed")
        } else {
            None
        };
        if let Some(what) = failed {
            self.reset()?;
            self.raised = Some(format!(
                "{what} during substeps {first}..{end}: the patch started again; lower the substep or the stiffnesses"
            ));
        } else if let Some(needed) = raised.crowded {
            let had = self.backend.list_slots().unwrap_or(0);
            let slots = self.backend.grow_lists(needed)?;
            self.raised = Some(format!(
                "{needed} self-contact candidates lay near one segment during substeps {first}..{end}, more than \
                 its list's {had} slots: the lists grew to {slots}"
            ));
        }
        Ok(())
    }

    /// Send the pins of the current actions to the backend: the top row
    /// under gravity (unless the patch was dropped on the floor), or the
    /// cast-on row and the pulled loose end while unravelling; and the
    /// grabbed node.
    fn upload_pins(&mut self) -> Result<(), DemoError> {
        let rest = &self.start;
        let held =
            |side| self.fabric.side_nodes(side).into_iter().map(|node| Pin { node, target: rest[node as usize] });
        let unravelling = self.release.as_ref().is_some_and(|r| r.unravel);
        let mut pins: Vec<Pin> = if unravelling {
            held(Side::Bottom).collect()
        } else if self.settings.gravity && !self.settings.floor {
            held(Side::Top).collect()
        } else {
            Vec::new()
        };
        let mut hold = |node: u32, target: Vec3| {
            pins.retain(|p| p.node != node);
            pins.push(Pin { node, target });
        };
        if unravelling {
            let end = (self.fabric.node_count() - 1) as u32;
            let out = (self.fabric.wale() + self.fabric.course().cross(&self.fabric.wale()) * 0.5).normalize();
            hold(end, rest[end as usize] + out * (self.pull * Geometry::default().stitch_height));
        }
        if let Some(grab) = self.grab {
            hold(grab.node, grab.target);
        }
        Ok(self.backend.set_pins(&pins)?)
    }
}

/// The gravity of `settings`: on when it is set or the patch lies on the
/// floor.
fn gravity_of(settings: &Settings) -> f64 {
    if settings.gravity || settings.floor { GRAVITY } else { 0.0 }
}

/// A patch just loaded.
struct Loaded {
    fabric: Fabric,
    /// Its positions as loaded.
    start: Vec<Vec3>,
    /// Purl stitches in its chart.
    purls: usize,
    yarn: Yarn,
}

/// Build the fabric for `settings` and load it into `backend`, laid flat
/// above a floor at y = 0 when the settings have one.
fn load(backend: &mut Wgpu, renderer: &Renderer, settings: &Settings) -> Result<Loaded, DemoError> {
    let chart = settings.pattern.chart(settings.width, settings.height)?;
    let fabric = Fabric::from_chart(&chart, &Geometry::default())?;
    backend.load(&fabric, &settings.params)?;
    let start = if settings.floor {
        backend.set_colliders(&[Collider::Plane(Plane::floor(0.0))])?;
        let laid = fabric.laid_flat(false, DROP * fabric.yarn_radius());
        let positions: Vec<V3<f32>> = laid.iter().map(|p| p.cast()).collect();
        backend.write_state(&State { velocities: vec![V3::zeros(); positions.len()], positions })?;
        laid
    } else {
        fabric.positions().to_vec()
    };
    let at: Vec<[f32; 3]> = start.iter().map(|p| [p.x as f32, p.y as f32, p.z as f32]).collect();
    let yarn = renderer.yarn(&at, fabric.yarns(), fabric.yarn_radius() as f32)?;
    Ok(Loaded { purls: chart.count(StitchKind::Purl), fabric, start, yarn })
}

/// Every pattern name, comma separated, for messages.
fn pattern_names() -> String {
    Pattern::ALL.map(Pattern::name).join(", ")
}

/// `value` as a whole number in `range`.
fn whole<T: TryFrom<u64> + PartialOrd>(value: f64, range: &std::ops::RangeInclusive<T>) -> Option<T> {
    (value.fract() == 0.0 && value >= 0.0 && value < u64::MAX as f64)
        .then(|| T::try_from(value as u64).ok())
        .flatten()
        .filter(|v| range.contains(v))
}

fn out_of_range<T: std::fmt::Display>(
    name: &'static str,
    value: f64,
    range: &std::ops::RangeInclusive<T>,
) -> DemoError {
    DemoError::OutOfRange { name, value, range: format!("the whole numbers {}..={}", range.start(), range.end()) }
}

fn side_name(name: &str) -> &'static str {
    if name == "width" { "width" } else { "height" }
}

/// The index of the point in `projected` (pixel x, y, depth; `None` behind
/// the camera) nearest pixel (`x`, `y`), if one lies within `radius`
/// pixels; the nearer to the camera wins a tie.
pub fn nearest(projected: &[Option<[f32; 3]>], x: f32, y: f32, radius: f32) -> Option<usize> {
    projected
        .iter()
        .enumerate()
        .filter_map(|(i, p)| p.map(|[px, py, depth]| (i, (px - x).powi(2) + (py - y).powi(2), depth)))
        .filter(|&(_, d2, _)| d2 <= radius * radius)
        .min_by(|a, b| a.1.total_cmp(&b.1).then(a.2.total_cmp(&b.2)))
        .map(|(i, _, _)| i)
}

/// The alive contacts in the order unravelling releases them: by their
/// later node along the yarn, last first, so the yarn comes free from the
/// loose end backwards.
pub fn unravel_order(fabric: &Fabric, alive: &[bool]) -> Vec<usize> {
    let contacts = fabric.contacts();
    let mut order: Vec<usize> = (0..contacts.len()).filter(|&c| alive.get(c).copied().unwrap_or(true)).collect();
    order.sort_by_key(|&c| std::cmp::Reverse(contacts[c].a.max(contacts[c].b)));
    order
}

/// The contacts that hold the loops of `column` to the loops drawn through
/// them, from the top row down: the order in which a dropped stitch there
/// runs down its wale. For each row below the top, that is every contact
/// between one of the loop's own nodes and a node of the row above: the
/// four crossings of an interlooped loop, or the two tethers of the paper's
/// arch head. Empty for a fabric that is not a generated grid or a column
/// outside it.
pub fn ladder_order(fabric: &Fabric, column: usize) -> Vec<usize> {
    let (Some((columns, rows)), Some(n)) = (fabric.grid(), fabric.nodes_per_loop()) else { return Vec::new() };
    if column >= columns {
        return Vec::new();
    }
    // The row of every node on a loop (the turns between rows have none),
    // and which of them are the column's own: phases 1.. belong to one
    // stitch alone, phase 0 may be its neighbour's (Fabric::stitch_node).
    let mut row_of = vec![None; fabric.node_count()];
    let mut own = vec![false; fabric.node_count()];
    for row in 0..rows {
        for c in 0..columns {
            for p in 0..n {
                if let Some(node) = fabric.stitch_node(c, row, p) {
                    row_of[node] = Some(row);
                    own[node] |= c == column && p > 0;
                }
            }
        }
    }
    // The row of the loop held, when `node` is one of the column's own and
    // `above` lies in the row above it.
    let held = |node: u32, above: u32| {
        let row = row_of[node as usize].filter(|_| own[node as usize])?;
        (row_of[above as usize] == Some(row + 1)).then_some(row)
    };
    let mut order: Vec<(usize, usize)> = fabric
        .contacts()
        .iter()
        .enumerate()
        .filter_map(|(i, c)| Some((held(c.a, c.b).or_else(|| held(c.b, c.a))?, i)))
        .collect();
    // Top row first; within a row, in contact order (a stable sort).
    order.sort_by_key(|&(row, _)| std::cmp::Reverse(row));
    order.into_iter().map(|(_, i)| i).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use yarn_topology::{Chart, Contact};

    fn patch(w: usize, h: usize) -> Fabric {
        Fabric::from_chart(&Chart::stockinette(w, h).expect("size"), &Geometry::default()).expect("fabric")
    }

    #[test]
    fn the_nearest_point_within_reach_is_picked() {
        let projected = [Some([10.0, 10.0, 0.5]), None, Some([13.0, 10.0, 0.2]), Some([100.0, 100.0, 0.1])];
        assert_eq!(nearest(&projected, 12.0, 10.0, 5.0), Some(2));
        assert_eq!(nearest(&projected, 10.5, 10.0, 5.0), Some(0));
        assert_eq!(nearest(&projected, 50.0, 50.0, 5.0), None);
        // Equally near: the one in front.
        assert_eq!(nearest(&projected, 11.5, 10.0, 5.0), Some(2));
        assert_eq!(nearest(&[], 0.0, 0.0, 5.0), None);
    }

    #[test]
    fn unravelling_starts_at_the_loose_end_and_skips_dead_contacts() {
        let fabric = patch(4, 3);
        let mut alive = vec![true; fabric.contacts().len()];
        let order = unravel_order(&fabric, &alive);
        assert_eq!(order.len(), alive.len());
        let later = |c: usize| fabric.contacts()[c].a.max(fabric.contacts()[c].b);
        assert!(order.windows(2).all(|w| later(w[0]) >= later(w[1])));
        // The first released holds a foot of the top row.
        let top = fabric.side_nodes(Side::Top);
        assert!(top.contains(&later(order[0])));
        alive[order[0]] = false;
        assert_eq!(unravel_order(&fabric, &alive), order[1..]);
    }

    #[test]
    fn a_ladder_runs_down_one_column_from_the_top() {
        // Interlooped loops (the default geometry): the four crossings with
        // the loop drawn through it hold each loop below the top row.
        let fabric = patch(5, 4);
        let n = fabric.nodes_per_loop().expect("a grid");
        let order = ladder_order(&fabric, 2);
        assert_eq!(order.len(), 4 * 3);
        let loop_nodes =
            |row| (1..n).filter_map(|p| fabric.stitch_node(2, row, p)).map(|i| i as u32).collect::<Vec<_>>();
        for (four, row) in order.chunks(4).zip((0..3).rev()) {
            let (below, above) = (loop_nodes(row), loop_nodes(row + 1));
            for &c in four {
                let Contact { a, b, .. } = fabric.contacts()[c];
                assert!(
                    below.contains(&a) && above.contains(&b) || below.contains(&b) && above.contains(&a),
                    "contact {c} ({a}, {b}) does not join the loops of rows {row} and {} in column 2",
                    row + 1
                );
            }
        }
        assert!(ladder_order(&fabric, 5).is_empty());

        // The paper's arch: two tethers hold each head to the loop above.
        let arch = Fabric::from_chart(&Chart::stockinette(5, 4).expect("size"), &Geometry::paper()).expect("fabric");
        let order = ladder_order(&arch, 2);
        assert_eq!(order.len(), 2 * 3);
        let heads: Vec<u32> = (0..3).rev().map(|row| arch.head_node(2, row).expect("node") as u32).collect();
        for (pair, head) in order.chunks(2).zip(&heads) {
            for &c in pair {
                let contact = arch.contacts()[c];
                assert!(contact.a == *head || contact.b == *head);
            }
        }
    }

    #[test]
    fn whole_numbers_are_checked_against_their_range() {
        assert_eq!(whole(22.0, &SUBSTEPS), Some(22));
        for bad in [0.0, 2.5, -3.0, f64::NAN, f64::INFINITY, 1e30, 501.0] {
            assert_eq!(whole(bad, &SUBSTEPS), None, "{bad}");
        }
        assert_eq!(whole(128.0, &SIDES), Some(128));
        assert_eq!(whole(1.0, &SIDES), None);
    }
}
