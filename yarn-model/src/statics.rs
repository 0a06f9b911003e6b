//! Quasi-static equilibrium: positions where the force F = −∇U vanishes,
//! found by minimising U directly instead of integrating motion until it
//! dies out. It uses the substep's own energy and force
//! ([`step::potential`], [`step::accumulate_forces`]).
//!
//! The method is L-BFGS whose initial inverse Hessian is a fixed
//! preconditioner: the fabric's springs and bends as one stiffness matrix
//! per coordinate (k_s along the yarn, k_c across each alive contact, about
//! k_b/ℓ² per bending joint on the second difference), factorised once
//! within its profile. The stiff stretch and contact modes, which hold the explicit
//! step to a small h, are then solved exactly each iteration, and L-BFGS
//! learns the soft rest.
//!
//! **Which equilibrium.** A knitted patch has many resting shapes within a
//! hair of each other in energy (its edges can roll and fold in more than
//! one way), and the damped dynamics settles into the one its path leads
//! to. A solve from the same start finds *a* minimum, usually a little
//! lower, not necessarily that one: on a 4x4 patch hung from its top row,
//! both converged, 8.8 yarn radii apart, their energies 0.02 % apart
//! (`cargo run --release --example statics`). Use it for a rested state
//! fast, not to reproduce a trajectory's end. Friction plays no part: with
//! μ > 0 the resting state depends on the path taken to it, so a solve is
//! only a frictionless equilibrium. Pinned nodes stay at their targets.
//!
//! ```
//! use yarn_model::statics::{StaticOptions, solve};
//! use yarn_model::{Model, Params, State};
//! use yarn_topology::{Chart, Fabric, Geometry};
//!
//! let fabric = Fabric::from_chart(&Chart::stockinette(4, 4)?, &Geometry::default())?;
//! let model = Model::<f64>::new(&fabric, &Params::default())?;
//! let mut state = State::at_rest(&fabric);
//! let report = solve(&model, &mut state, &StaticOptions::default());
//! assert!(report.energy < yarn_model::step::energy(&model, &State::at_rest(&fabric)).potential());
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use crate::{Model, State, V3, step};

/// When a solve stops.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StaticOptions {
    /// Stop when the largest force on a free node is below this.
    pub force_tolerance: f64,
    /// Stop after this many evaluations of U and F.
    pub max_evaluations: usize,
    /// Correction pairs L-BFGS keeps.
    pub memory: usize,
}

impl Default for StaticOptions {
    /// Forces below 1e-6, at most 5,000 evaluations, 20 pairs.
    fn default() -> Self {
        Self { force_tolerance: 1e-6, max_evaluations: 5_000, memory: 20 }
    }
}

/// What a solve did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StaticReport {
    /// Evaluations of U and F together; each costs about one force
    /// accumulation, so this compares with a dynamic run's substeps.
    pub evaluations: usize,
    /// L-BFGS iterations.
    pub iterations: usize,
    /// U at the end.
    pub energy: f64,
    /// The largest force on a free node at the end.
    pub max_force: f64,
    /// Whether that fell below the tolerance.
    pub converged: bool,
}

/// A symmetric positive definite matrix stored by its profile (row i holds
/// columns `first[i]..=i`) and factorised in place as L Lᵀ, whose fill
/// stays inside the same profile.
#[derive(Debug, Clone)]
struct Profile {
    first: Vec<usize>,
    /// Where each row starts in `entries`.
    offset: Vec<usize>,
    entries: Vec<f64>,
}

impl Profile {
    /// The matrix with these entries (i, j, value), repeats summed; each
    /// pair is given once, either way round.
    fn new(n: usize, triplets: &[(usize, usize, f64)]) -> Self {
        let mut first: Vec<usize> = (0..n).collect();
        for &(i, j, _) in triplets {
            let (i, j) = (i.max(j), i.min(j));
            first[i] = first[i].min(j);
        }
        let mut offset = Vec::with_capacity(n + 1);
        offset.push(0);
        for (i, &f) in first.iter().enumerate() {
            offset.push(offset[i] + i - f + 1);
        }
        let mut p = Self { first, entries: vec![0.0; offset[n]], offset };
        for &(i, j, value) in triplets {
            let (i, j) = (i.max(j), i.min(j));
            let at = p.offset[i] + j - p.first[i];
            p.entries[at] += value;
        }
        p
    }

    /// Row i from column `first[i]` to the diagonal.
    fn row(&self, i: usize) -> &[f64] {
        &self.entries[self.offset[i]..self.offset[i + 1]]
    }

    /// Cholesky in place; false if a pivot is not positive.
    fn factorise(&mut self) -> bool {
        for i in 0..self.first.len() {
            for j in self.first[i]..=i {
                let lo = self.first[i].max(self.first[j]);
                let (row_i, row_j) = (self.row(i), self.row(j));
                let dot: f64 = row_i[lo - self.first[i]..j - self.first[i]]
                    .iter()
                    .zip(&row_j[lo - self.first[j]..j - self.first[j]])
                    .map(|(a, b)| a * b)
                    .sum();
                let at = self.offset[i] + j - self.first[i];
                let sum = self.entries[at] - dot;
                if i == j {
                    if sum <= 0.0 {
                        return false;
                    }
                    self.entries[at] = sum.sqrt();
                } else {
                    self.entries[at] = sum / self.entries[self.offset[j + 1] - 1];
                }
            }
        }
        true
    }

    /// Solve L Lᵀ x = b in place, each coordinate alike, a row of L at a
    /// time in both sweeps.
    fn solve(&self, b: &mut [V3<f64>]) {
        for i in 0..self.first.len() {
            let (lo, row) = (self.first[i], self.row(i));
            let (off, diagonal) = row.split_at(i - lo);
            let sum = off.iter().zip(&b[lo..i]).fold(b[i], |sum, (l, x)| sum - x * *l);
            b[i] = sum / diagonal[0];
        }
        for i in (0..self.first.len()).rev() {
            let (lo, row) = (self.first[i], self.row(i));
            let (off, diagonal) = row.split_at(i - lo);
            let x = b[i] / diagonal[0];
            b[i] = x;
            b[lo..i].iter_mut().zip(off).for_each(|(b, l)| *b -= x * *l);
        }
    }
}

/// The preconditioner of `model`, factorised: springs, contacts and bends
/// as one stiffness per node pair, shared by x, y and z; a pinned node
/// decoupled (its row the identity). `None` if it is not positive
/// definite, which the solve then does without.
fn preconditioner(model: &Model<f64>, pinned: &[bool]) -> Option<Profile> {
    let c = model.coeffs();
    let mut triplets = Vec::new();
    // Entry (i, j) gains `value`, unless it couples a pinned node: a pinned
    // node's row and column stay empty but for its diagonal.
    let mut add = |i: usize, j: usize, value: f64| {
        if !pinned[i] && !pinned[j] {
            triplets.push((i, j, value));
        }
    };
    let mut spring = |i: usize, j: usize, k: f64| {
        add(i, i, k);
        add(j, j, k);
        add(i, j, -k);
    };
    for i in 0..model.spring_rest().len() {
        spring(i, i + 1, c.stretch);
    }
    for (contact, _) in model.contacts().iter().zip(model.alive()).filter(|(_, alive)| **alive) {
        spring(contact.a as usize, contact.b as usize, c.contact);
    }
    // A bend resists the second difference x_i − 2 x_{i+1} + x_{i+2} with a
    // stiffness of about k_b / ℓ².
    for i in 0..model.rest_angle().len() {
        let l = 0.5 * (model.spring_rest()[i] + model.spring_rest()[i + 1]);
        let k = c.bend / (l * l);
        let d = [1.0, -2.0, 1.0];
        for a in 0..3 {
            for b in 0..=a {
                add(i + a, i + b, k * d[a] * d[b]);
            }
        }
    }
    // A free fabric moves rigidly at no cost: a small diagonal pins that
    // down without touching the stiff modes.
    let floor = 1e-6 * c.stretch.max(c.contact);
    triplets.extend(pinned.iter().enumerate().map(|(i, &pinned)| (i, i, if pinned { 1.0 } else { floor })));
    let mut p = Profile::new(model.node_count(), &triplets);
    p.factorise().then_some(p)
}

/// The displacement K⁻¹F that the fabric's linear stiffness K (springs,
/// contacts and bends, the matrix that preconditions [`solve`]) predicts
/// the forces `forces` would still cause, pinned nodes held: what is left
/// to move, if the fabric responded linearly from here. `None` when K is
/// not positive definite.
pub fn predicted_displacement(model: &Model<f64>, forces: &[V3<f64>]) -> Option<Vec<V3<f64>>> {
    let mut pinned = vec![false; model.node_count()];
    for &(node, _) in model.pins() {
        pinned[node as usize] = true;
    }
    let factor = preconditioner(model, &pinned)?;
    let mut x: Vec<V3<f64>> = forces.iter().zip(&pinned).map(|(f, &pin)| if pin { V3::zeros() } else { *f }).collect();
    factor.solve(&mut x);
    Some(x)
}

/// One L-BFGS correction pair: the step s and the change of gradient y.
type Pair = (Vec<V3<f64>>, Vec<V3<f64>>);

fn dot(a: &[V3<f64>], b: &[V3<f64>]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x.dot(y)).sum()
}

fn max_norm(g: &[V3<f64>]) -> f64 {
    g.iter().map(|v| v.norm()).fold(0.0, f64::max)
}

/// U and its gradient at positions, pinned nodes' gradient zeroed.
struct Objective<'a> {
    model: &'a Model<f64>,
    pinned: Vec<bool>,
    forces: Vec<V3<f64>>,
    evaluations: usize,
}

impl Objective<'_> {
    fn evaluate(&mut self, x: &[V3<f64>], gradient: &mut Vec<V3<f64>>) -> f64 {
        self.evaluations += 1;
        step::accumulate_forces(self.model, x, &mut self.forces);
        gradient.clear();
        gradient.extend(self.forces.iter().zip(&self.pinned).map(|(f, &pin)| if pin { V3::zeros() } else { -f }));
        step::potential(self.model, x).potential()
    }
}

/// Minimise U over `state`'s positions, in place, from where they are;
/// velocities become zero and pinned nodes go to their targets. Stops at
/// [`StaticOptions::force_tolerance`], at the evaluation budget, or when a
/// line search can no longer lower U.
pub fn solve(model: &Model<f64>, state: &mut State<f64>, options: &StaticOptions) -> StaticReport {
    let n = model.node_count();
    let mut pinned = vec![false; n];
    for &(node, target) in model.pins() {
        state.positions[node as usize] = target;
        pinned[node as usize] = true;
    }
    state.velocities.iter_mut().for_each(|v| *v = V3::zeros());
    let precondition = preconditioner(model, &pinned);
    let apply = |v: &mut Vec<V3<f64>>| {
        if let Some(p) = &precondition {
            p.solve(v);
        }
    };
    let mut objective = Objective { model, pinned, forces: Vec::new(), evaluations: 0 };
    let mut gradient = Vec::new();
    let mut energy = objective.evaluate(&state.positions, &mut gradient);
    let mut history: Vec<Pair> = Vec::new();
    let (mut trial, mut trial_gradient) = (state.positions.clone(), Vec::new());
    let mut iterations = 0;
    while max_norm(&gradient) > options.force_tolerance && objective.evaluations < options.max_evaluations {
        iterations += 1;
        // The two-loop recursion, with P⁻¹ as the initial inverse Hessian.
        let mut q = gradient.clone();
        let mut alphas = Vec::with_capacity(history.len());
        for (s, y) in history.iter().rev() {
            let a = dot(s, &q) / dot(y, s);
            q.iter_mut().zip(y).for_each(|(q, y)| *q -= y * a);
            alphas.push(a);
        }
        apply(&mut q);
        for ((s, y), a) in history.iter().zip(alphas.into_iter().rev()) {
            let b = dot(y, &q) / dot(y, s);
            q.iter_mut().zip(s).for_each(|(q, s)| *q += s * (a - b));
        }
        if dot(&q, &gradient) <= 0.0 {
            // Not downhill: forget the history and precondition alone.
            history.clear();
            q.clone_from(&gradient);
            apply(&mut q);
        }
        let slope = -dot(&q, &gradient);
        // Backtrack from the full step to the Armijo condition.
        let mut step = 1.0;
        let accepted = loop {
            if objective.evaluations >= options.max_evaluations || step < 1e-12 {
                break false;
            }
            trial.iter_mut().zip(&state.positions).zip(&q).for_each(|((t, x), d)| *t = x - d * step);
            let e = objective.evaluate(&trial, &mut trial_gradient);
            if e <= energy + 1e-4 * step * slope {
                let s: Vec<V3<f64>> = q.iter().map(|d| -d * step).collect();
                let y: Vec<V3<f64>> = trial_gradient.iter().zip(&gradient).map(|(a, b)| a - b).collect();
                if dot(&s, &y) > 0.0 {
                    history.push((s, y));
                    if history.len() > options.memory {
                        history.remove(0);
                    }
                }
                state.positions.clone_from(&trial);
                std::mem::swap(&mut gradient, &mut trial_gradient);
                energy = e;
                break true;
            }
            step *= 0.5;
        };
        if !accepted {
            break;
        }
    }
    let max_force = max_norm(&gradient);
    StaticReport {
        evaluations: objective.evaluations,
        iterations,
        energy,
        max_force,
        converged: max_force <= options.force_tolerance,
    }
}

#[cfg(test)]
mod tests {
    use yarn_topology::{Chart, Fabric, Geometry, Pin, Side};

    use super::*;
    use crate::Params;

    fn hung(width: usize, height: usize) -> (Fabric, Model<f64>) {
        let fabric = Fabric::from_chart(&Chart::stockinette(width, height).unwrap(), &Geometry::default()).unwrap();
        let params = Params { gravity: 9.81, friction: 0.0, ..Params::default() };
        let rest = fabric.positions();
        let pins: Vec<Pin> =
            fabric.side_nodes(Side::Top).into_iter().map(|node| Pin { node, target: rest[node as usize] }).collect();
        let mut model = Model::new(&fabric, &params).unwrap();
        model.set_pins(&pins).unwrap();
        (fabric, model)
    }

    /// A 4x4 patch hung from its top row converges: forces below 1e-6 in a
    /// few thousand evaluations, with U lower than where it started and the
    /// pins where they were put.
    #[test]
    fn a_hung_patch_converges_with_its_pins_in_place() {
        let (fabric, model) = hung(4, 4);
        let start = State::at_rest(&fabric);
        let mut state = start.clone();
        let report = solve(&model, &mut state, &StaticOptions::default());
        assert!(report.converged, "{report:?}");
        assert!(report.evaluations < 5_000 && report.iterations > 10, "{report:?}");
        assert!(report.energy < step::energy(&model, &start).potential());
        let mut forces = Vec::new();
        step::accumulate_forces(&model, &state.positions, &mut forces);
        let pinned: Vec<usize> = model.pins().iter().map(|&(node, _)| node as usize).collect();
        let worst =
            forces.iter().enumerate().filter(|(i, _)| !pinned.contains(i)).map(|(_, f)| f.norm()).fold(0.0, f64::max);
        assert!(worst <= 1e-6, "force {worst} left on a free node");
        for &(node, target) in model.pins() {
            assert_eq!(state.positions[node as usize], target);
        }
    }

    /// U never rises from one accepted step to the next: a budget of k
    /// evaluations ends no higher than a budget of fewer.
    #[test]
    fn more_evaluations_never_end_higher() {
        let (fabric, model) = hung(4, 4);
        let energies: Vec<f64> = [20, 80, 320]
            .iter()
            .map(|&budget| {
                let mut state = State::at_rest(&fabric);
                let options = StaticOptions { max_evaluations: budget, ..StaticOptions::default() };
                solve(&model, &mut state, &options).energy
            })
            .collect();
        assert!(energies.windows(2).all(|w| w[1] <= w[0]), "{energies:?}");
        assert!(energies[2] < energies[0], "{energies:?}");
    }

    #[test]
    fn the_profile_solves_what_it_factorised() {
        // Springs along a chain and one across it, with a diagonal: rows of
        // different profile lengths.
        let mut triplets = Vec::new();
        for (i, j, k) in [(0, 1, 2.0), (1, 2, 3.0), (2, 3, 4.0), (3, 4, 5.0), (0, 3, 1.5)] {
            triplets.extend([(i, i, k), (j, j, k), (i, j, -k)]);
        }
        triplets.extend((0..5).map(|i| (i, i, 0.25)));
        let mut dense = [[0.0; 5]; 5];
        for &(i, j, v) in &triplets {
            dense[i][j] += v;
            if i != j {
                dense[j][i] += v;
            }
        }
        let mut p = Profile::new(5, &triplets);
        assert_eq!(p.first, [0, 0, 1, 0, 3]);
        assert!(p.factorise());
        let x: Vec<V3<f64>> = (0..5).map(|i| V3::new(i as f64, 1.0 - i as f64, 0.5)).collect();
        let mut b: Vec<V3<f64>> = (0..5).map(|i| (0..5).map(|j| x[j] * dense[i][j]).sum()).collect();
        p.solve(&mut b);
        assert!(b.iter().zip(&x).all(|(a, b)| (a - b).norm() < 1e-12), "{b:?}");
    }
}
