//! Certified rest: when a patch has stopped moving, and the proof of it.
//!
//! A relaxation is at rest when what is left to move is small, not when it
//! moves slowly: with friction and soft modes a patch creeps at a speed
//! that passes any speed or energy-rate test (the trap the paper's fixed
//! 12,000-substep window fell into: its patch was still rolling, and went
//! on to fold through itself). So a [`Certificate`] asks three things:
//!
//! - **Displacement**: the Newton step d = H⁻¹F, the displacement the
//!   residual force F would still cause against the exact stiffness H
//!   (the Hessian of the energy, pinned nodes held), is below
//!   [`REST_DISPLACEMENT`] yarn radii at every node. d weighs each mode's
//!   force by its own stiffness, |F|/k per mode, so the softest mode the
//!   patch has dominates: a small force on a soft roll still certifies no
//!   rest. d is found by conjugate gradients on H, preconditioned by the
//!   linear stiffness K the quasi-static solve uses
//!   ([`yarn_model::statics::LinearStiffness`]); H times a vector
//!   is a central difference of the exact force. If CG meets a direction
//!   of negative curvature the state is a saddle, not a rest. CG stops at
//!   a 1e-2 reduction, 300 iterations or a direction too soft to tell from
//!   a free one; what it leaves unsolved counts as its residual force over
//!   the softest stiffness it met, at least 1e-6 (|F|/k, for
//!   the part of the force it did not resolve).
//! - **Energy**: the energy that step would still release, ½ F·d, is
//!   below [`REST_ENERGY`] of the fabric's bending scale, ½ k_b Σ θ0²: the
//!   energy it would take to straighten every loop. (Not of the potential
//!   energy itself, which is zero at an exact rest.)
//! - **Speed**: the distance the fastest node would coast before the
//!   damping stops it, v_max / β, is below [`REST_COAST`] yarn radii.
//!
//! The thresholds are ten times finer than the doubling test's 0.05 r
//! ([`DOUBLING_CURL`]), so a certified rest leaves the gate's figures to
//! move by less than the doubling test allows.
//!
//! Friction holds a patch where forces are left, far from any minimum,
//! and a frictionless criterion refuses it. So a run on the dynamics, which
//! watched its state over a [`Window`] of its work, may instead be
//! certified **still**:
//!
//! - **Creep**: the farthest any node moved over the window, scaled to as
//!   much work again as the run took (what it would move over a doubling at
//!   that rate), is below [`REST_DISPLACEMENT`] yarn radii.
//! - **Speed**: as above.
//!
//! Stillness is asked of the motion rather than of the forces: friction
//! filters the slip between a contact's two nodes, not where they are, and
//! the yarn between contacts has none, so no test of each node's force
//! against what friction at it could hold tells a held patch from one that
//! drifts with its contacts stuck.

use nalgebra::{Matrix3, Vector3};
use serde::Serialize;
use yarn_model::statics::LinearStiffness;
use yarn_model::{Model, State, V3, step};

/// The largest Newton step at a certified rest, in yarn radii.
pub const REST_DISPLACEMENT: f64 = 0.01;
/// The largest energy still to release at a certified rest, as a fraction
/// of the fabric's bending scale ½ k_b Σ θ0².
pub const REST_ENERGY: f64 = 1e-6;
/// The largest coasting distance v_max / β at a certified rest, in yarn
/// radii.
pub const REST_COAST: f64 = 0.01;
/// Doubling the relaxation may move each curl by less than this, in yarn
/// radii, or by less than [`DOUBLING_FRACTION`] of itself.
pub const DOUBLING_CURL: f64 = 0.05;
/// Doubling may move each stiffness, width and height by less than this
/// fraction.
pub const DOUBLING_FRACTION: f64 = 0.05;

/// Conjugate-gradient iterations the Newton step may take; what is left
/// unsolved then counts as its residual force over the softest stiffness
/// met.
const CG_ITERATIONS: usize = 300;
/// CG stops when the residual's preconditioned norm falls by this factor:
/// the step to about 1 %, which is enough to judge it against
/// [`REST_DISPLACEMENT`].
const CG_REDUCTION: f64 = 1e-2;
/// A Rayleigh quotient pᵀHp / pᵀp below this in size is a mode the
/// difference cannot tell from a free one: CG stops there, the force left
/// counting over this stiffness, and only one below minus this is a
/// saddle. The force's rounding in the difference is about 1e-7 of it.
const NULL_CURVATURE: f64 = 1e-6;
/// The central difference's step, as the largest node displacement, in
/// model units.
const DIFFERENCE_STEP: f64 = 1e-6;

/// How close to rest a state is, and whether that counts as rest.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Certificate {
    /// The largest node displacement of the Newton step, in yarn radii.
    pub displacement: f64,
    /// The energy the Newton step would release, as a fraction of the
    /// fabric's bending scale ½ k_b Σ θ0².
    pub energy_left: f64,
    /// v_max / β, in yarn radii.
    pub coast: f64,
    /// The largest force on a free node.
    pub max_force: f64,
    /// The softest stiffness CG met, pᵀHp / pᵀp over its search
    /// directions: an upper bound on the softest mode's.
    pub softest_stiffness: f64,
    /// Whether CG met a direction of negative curvature (a saddle).
    pub saddle: bool,
    /// Hessian-vector products the Newton step took.
    pub hessian_products: usize,
    /// Whether CG reached its tolerance. If not, what it left unsolved
    /// counts in `displacement` as its residual's largest node force over
    /// the softest stiffness met.
    pub newton_converged: bool,
    /// The farthest any node moved over the [`Window`], scaled to as much
    /// work again as the run took, in yarn radii; `None` without a window.
    pub creep: Option<f64>,
    /// Whether every frictionless criterion holds.
    pub at_minimum: bool,
    /// Whether the state kept still over its window: creep and coast
    /// below their thresholds.
    pub still: bool,
    /// Whether the state is at rest: every frictionless criterion holds,
    /// or it kept still.
    pub certified: bool,
}

/// The last stretch of a run: where its nodes were `work` units of work
/// before the state judged, with `total` units done in all.
#[derive(Debug, Clone, Copy)]
pub struct Window<'a> {
    /// The positions at the window's start.
    pub since: &'a [V3<f64>],
    /// The work over the window.
    pub work: u64,
    /// The run's work in all, the window's included.
    pub total: u64,
}

impl Certificate {
    /// The certificate of `state` under `model` (its pins held), lengths
    /// in units of the yarn radius `r`.
    pub fn of(model: &Model<f64>, state: &State<f64>, r: f64) -> Self {
        Self::over(model, state, r, None)
    }

    /// [`Certificate::of`], and with a `window` also whether the state kept
    /// still over it (the module's second test).
    pub fn over(model: &Model<f64>, state: &State<f64>, r: f64, window: Option<Window>) -> Self {
        let coast = state.max_speed() / model.params().damping.max(f64::MIN_POSITIVE) / r;
        let free = free_nodes(model);
        let mut forces = Vec::new();
        step::accumulate_forces(model, &state.positions, &mut forces);
        zero_pinned(&mut forces, &free);
        let max_force = forces.iter().map(|f| f.norm()).fold(0.0, f64::max);
        let scale = 0.5 * model.coeffs().bend * model.joints().map(|(_, t)| t * t).sum::<f64>();
        let newton = newton_step(model, &state.positions, &forces, &free);
        let displacement = (newton.step.iter().map(|d| d.norm()).fold(0.0, f64::max) + newton.unresolved) / r;
        let energy_left = 0.5 * dot(&forces, &newton.step) / scale.max(f64::MIN_POSITIVE);
        let creep = window.map(|w| creep(&state.positions, &w, &free) / r);
        let still = creep.is_some_and(|creep| creep < REST_DISPLACEMENT) && coast < REST_COAST;
        let at_minimum =
            !newton.saddle && displacement < REST_DISPLACEMENT && energy_left < REST_ENERGY && coast < REST_COAST;
        Self {
            displacement,
            energy_left,
            coast,
            max_force,
            softest_stiffness: newton.softest,
            saddle: newton.saddle,
            hessian_products: newton.products,
            newton_converged: newton.converged,
            creep,
            at_minimum,
            still,
            certified: at_minimum || still,
        }
    }

    /// One line for the table.
    pub fn describe(&self) -> String {
        let at_minimum = if self.saddle {
            format!("saddle (negative curvature), max force {:.1e}", self.max_force)
        } else {
            format!(
                "step {:.1e} r, energy left {:.1e}, coast {:.1e} r",
                self.displacement, self.energy_left, self.coast
            )
        };
        match self.creep {
            Some(creep) if self.still && !self.at_minimum => {
                format!("still: creep {creep:.1e} r, coast {:.1e} r", self.coast)
            }
            Some(creep) if !self.certified => format!("{at_minimum}; creep {creep:.1e} r"),
            _ => at_minimum,
        }
    }
}

/// The farthest any node moved from `window.since` to `x`, scaled to as
/// much work again as the run took. A patch no pin holds may drift and
/// turn as a whole, which moves none of its figures: that motion (the best
/// rigid fit) is left out.
fn creep(x: &[V3<f64>], window: &Window, free: &[bool]) -> f64 {
    let pairs: Vec<_> = window.since.iter().copied().zip(x.iter().copied()).collect();
    let (rotation, translation) =
        if free.iter().all(|f| *f) { crate::metrics::rigid_fit(&pairs) } else { (Matrix3::identity(), V3::zeros()) };
    let farthest = pairs.iter().map(|(x0, x)| (x - (rotation * x0 + translation)).norm()).fold(0.0, f64::max);
    farthest * window.total as f64 / window.work.max(1) as f64
}

/// Which nodes are free (not pinned).
fn free_nodes(model: &Model<f64>) -> Vec<bool> {
    model.pinned_nodes().into_iter().map(|pinned| !pinned).collect()
}

fn zero_pinned(v: &mut [V3<f64>], free: &[bool]) {
    v.iter_mut().zip(free).filter(|(_, free)| !**free).for_each(|(v, _)| *v = V3::zeros());
}

fn dot(a: &[V3<f64>], b: &[V3<f64>]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x.dot(y)).sum()
}

/// The rigid motions of a free fabric at `x` (three translations and three
/// rotations about the centroid), orthonormalised: the modes H does not
/// resist, which the Newton step leaves out. Empty when any node is
/// pinned, since pins hold the rigid motions.
fn rigid_modes(x: &[V3<f64>], free: &[bool]) -> Vec<Vec<V3<f64>>> {
    if free.iter().any(|f| !f) {
        return Vec::new();
    }
    let centroid = x.iter().sum::<V3<f64>>() / x.len() as f64;
    let mut modes: Vec<Vec<V3<f64>>> = Vec::with_capacity(6);
    for axis in 0..3 {
        let unit = Vector3::ith(axis, 1.0);
        modes.push(vec![unit; x.len()]);
        modes.push(x.iter().map(|p| unit.cross(&(p - centroid))).collect());
    }
    let mut basis: Vec<Vec<V3<f64>>> = Vec::with_capacity(6);
    for mut mode in modes {
        for b in &basis {
            let along = dot(b, &mode);
            mode.iter_mut().zip(b).for_each(|(m, b)| *m -= b * along);
        }
        let norm = dot(&mode, &mode).sqrt();
        if norm > 1e-12 {
            mode.iter_mut().for_each(|m| *m /= norm);
            basis.push(mode);
        }
    }
    basis
}

fn project_out(v: &mut [V3<f64>], basis: &[Vec<V3<f64>>]) {
    for b in basis {
        let along = dot(b, v);
        v.iter_mut().zip(b).for_each(|(v, b)| *v -= b * along);
    }
}

/// What [`newton_step`] found.
struct Newton {
    step: Vec<V3<f64>>,
    softest: f64,
    saddle: bool,
    products: usize,
    converged: bool,
    /// What CG left unsolved, as a length: its residual's largest node
    /// force over the softest stiffness met (0 when it converged).
    unresolved: f64,
}

/// H p for the Hessian H of `model`'s energy at `x`, by a central
/// difference of the exact force, pinned nodes and rigid modes left out.
fn hessian_product(
    model: &Model<f64>,
    x: &[V3<f64>],
    p: &[V3<f64>],
    free: &[bool],
    rigid: &[Vec<V3<f64>>],
) -> Vec<V3<f64>> {
    let scale = DIFFERENCE_STEP / p.iter().map(|v| v.norm()).fold(f64::MIN_POSITIVE, f64::max);
    let (mut plus, mut minus) = (Vec::new(), Vec::new());
    let shifted = |sign: f64| -> Vec<V3<f64>> { x.iter().zip(p).map(|(x, p)| x + p * (sign * scale)).collect() };
    step::accumulate_forces(model, &shifted(1.0), &mut plus);
    step::accumulate_forces(model, &shifted(-1.0), &mut minus);
    // F = −∇U, so H p = −(F(x + εp) − F(x − εp)) / 2ε.
    let mut hp: Vec<V3<f64>> = plus.iter().zip(&minus).map(|(a, b)| (b - a) / (2.0 * scale)).collect();
    zero_pinned(&mut hp, free);
    project_out(&mut hp, rigid);
    hp
}

/// Solve H d = F by preconditioned conjugate gradients, H the Hessian of
/// `model`'s energy at `x` applied by central differences of its force.
fn newton_step(model: &Model<f64>, x: &[V3<f64>], forces: &[V3<f64>], free: &[bool]) -> Newton {
    let n = x.len();
    let rigid = rigid_modes(x, free);
    let stiffness = LinearStiffness::new(model);
    let precondition = |r: &[V3<f64>]| -> Vec<V3<f64>> {
        let mut z = stiffness.as_ref().map_or_else(|| r.to_vec(), |k| k.solve(r));
        zero_pinned(&mut z, free);
        project_out(&mut z, &rigid);
        z
    };
    let mut products = 0;
    let mut hessian = |p: &[V3<f64>]| {
        products += 1;
        hessian_product(model, x, p, free, &rigid)
    };
    let mut residual = forces.to_vec();
    project_out(&mut residual, &rigid);
    let mut step = vec![V3::zeros(); n];
    let mut z = precondition(&residual);
    let mut p = z.clone();
    let mut rz = dot(&residual, &z);
    let target = rz.abs() * CG_REDUCTION * CG_REDUCTION;
    let (mut softest, mut saddle, mut converged) = (f64::INFINITY, false, false);
    for _ in 0..CG_ITERATIONS {
        if rz.abs() <= target || rz == 0.0 {
            converged = true;
            break;
        }
        let hp = hessian(&p);
        let curvature = dot(&p, &hp);
        let rayleigh = curvature / dot(&p, &p);
        softest = softest.min(rayleigh);
        if rayleigh < -NULL_CURVATURE {
            saddle = true;
            break;
        }
        if rayleigh < NULL_CURVATURE {
            // A mode too soft to tell from the difference's rounding: the
            // force left is not resolved, and counts below over this
            // stiffness at most (a free yarn under a load is no rest).
            break;
        }
        let alpha = rz / curvature;
        step.iter_mut().zip(&p).for_each(|(d, p)| *d += p * alpha);
        residual.iter_mut().zip(&hp).for_each(|(r, hp)| *r -= hp * alpha);
        z = precondition(&residual);
        let rz_next = dot(&residual, &z);
        let beta = rz_next / rz;
        rz = rz_next;
        p.iter_mut().zip(&z).for_each(|(p, z)| *p = z + *p * beta);
    }
    let converged = converged || rz.abs() <= target;
    let left = residual.iter().map(|r| r.norm()).fold(0.0, f64::max);
    let unresolved = if converged || saddle { 0.0 } else { left / softest.max(NULL_CURVATURE) };
    Newton { step, softest, saddle, products, converged, unresolved }
}

#[cfg(test)]
mod tests {
    use yarn_backend_cpu::Serial;
    use yarn_model::{Backend, Params};
    use yarn_topology::{Chart, Fabric, Geometry, Pin};

    use super::*;

    fn patch(size: usize) -> Fabric {
        Fabric::from_chart(&Chart::stockinette(size, size).unwrap(), &Geometry::paper()).unwrap()
    }

    /// With κ = 1 the assembled patch is an exact rest: it certifies.
    #[test]
    fn an_exact_rest_certifies() {
        let fabric = patch(4);
        let model = Model::<f64>::new(&fabric, &Params { rest_curl: 1.0, ..Params::paper() }).unwrap();
        let certificate = Certificate::of(&model, &State::at_rest(&fabric), fabric.yarn_radius());
        assert!(certificate.certified && certificate.displacement < 1e-9, "{certificate:?}");
    }

    /// The Newton step solves H d = F: near an exact rest, stretched a
    /// little (so every spring is in tension and H has no negative
    /// curvature from a compressed one), H d matches the force to the CG
    /// tolerance.
    #[test]
    fn the_newton_step_solves_the_hessian_against_the_force() {
        let fabric = patch(4);
        let model = Model::<f64>::new(&fabric, &Params { rest_curl: 1.0, ..Params::paper() }).unwrap();
        let mut state = State::at_rest(&fabric);
        state.positions.iter_mut().for_each(|x| *x *= 1.0 + 1e-3);
        let free = vec![true; state.len()];
        let rigid = rigid_modes(&state.positions, &free);
        let mut forces = Vec::new();
        step::accumulate_forces(&model, &state.positions, &mut forces);
        project_out(&mut forces, &rigid);
        let newton = newton_step(&model, &state.positions, &forces, &free);
        assert!(!newton.saddle && newton.products >= 1, "{} products, softest {}", newton.products, newton.softest);
        let hd = hessian_product(&model, &state.positions, &newton.step, &free, &rigid);
        let residual = hd.iter().zip(&forces).map(|(a, b)| (a - b).norm_squared()).sum::<f64>().sqrt();
        let size = dot(&forces, &forces).sqrt();
        assert!(residual < 1e-2 * size, "|H d − F| = {residual:e} against |F| = {size:e}");
    }

    /// A state the frictionless criteria refuse certifies as still over a
    /// window in which it did not move, whatever rigid motion a free patch
    /// made meanwhile; a node that crept is scaled up to a doubling's worth
    /// and refuses it; and with a pin, a rigid motion is motion.
    #[test]
    fn a_window_without_motion_certifies_a_state_still() {
        let fabric = patch(4);
        let mut state = State::at_rest(&fabric);
        state.positions.iter_mut().enumerate().for_each(|(i, x)| x.y += 0.02 * (i as f64 * 0.37).sin());
        let r = fabric.yarn_radius();
        let model = Model::<f64>::new(&fabric, &Params::paper()).unwrap();
        let turn = nalgebra::Rotation3::from_euler_angles(0.3, -0.2, 0.1);
        let moved: Vec<V3<f64>> = state.positions.iter().map(|x| turn * x + V3::new(4.0, -1.0, 2.0)).collect();
        let window = Window { since: &moved, work: 2_000, total: 20_000 };
        assert!(!Certificate::of(&model, &state, r).certified);
        let still = Certificate::over(&model, &state, r, Some(window));
        assert!(still.certified && still.still && !still.at_minimum, "{still:?}");
        assert!(still.creep.unwrap() < 1e-9, "{still:?}");
        // One node 0.002 r away over a tenth of the run: 0.02 r over a
        // doubling, less the little of it the rigid fit takes up.
        let mut crept = state.positions.clone();
        crept[7].x += 0.002 * r;
        let creeping = Certificate::over(&model, &state, r, Some(Window { since: &crept, ..window }));
        let creep = creeping.creep.unwrap();
        assert!(!creeping.certified && creep > 0.019 && creep < 0.02 + 1e-9, "{creeping:?}");
        let mut pinned = model.clone();
        pinned.set_pins(&[Pin { node: 0, target: state.positions[0] }]).unwrap();
        let held = Certificate::over(&pinned, &state, r, Some(window));
        assert!(!held.still && held.creep.unwrap() > 1.0, "{held:?}");
    }

    /// The trap of a speed test: a patch stopped mid-relaxation (its
    /// velocities zeroed) passes the coasting test but is refused, because
    /// its forces would still move it far.
    #[test]
    fn a_stopped_transient_is_not_a_rest() {
        let fabric = patch(6);
        let mut backend = Serial::<f64>::new();
        backend.load(&fabric, &Params::paper()).unwrap();
        backend.advance(3_000).unwrap();
        let mut state = backend.state().unwrap();
        state.velocities.iter_mut().for_each(|v| *v = V3::zeros());
        let model = backend.model().unwrap().clone();
        let certificate = Certificate::of(&model, &state, fabric.yarn_radius());
        println!("{certificate:?}");
        assert_eq!(certificate.coast, 0.0);
        assert!(!certificate.certified && certificate.displacement > 10.0 * REST_DISPLACEMENT, "{certificate:?}");
    }
}
