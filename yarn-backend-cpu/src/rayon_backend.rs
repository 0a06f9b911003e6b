//! The `Rayon` backend: SPEC §4 as data-parallel passes with a
//! deterministic gather, in `f32`.
//!
//! No node is written by two threads. Each substep runs:
//! 1. *segments*: unit tangent, length and stretch force of every segment;
//! 2. *joints*: bending forces on the first and last node of every joint
//!    (the middle one is their negated sum), from the cached tangents;
//! 3. *contacts*: tether force of every alive contact;
//! 4. *nodes*: each node gathers its two segments, three joints and its
//!    contacts (through a per-node contact list, in a fixed order), then
//!    takes the damped velocity update;
//! 5. *friction*: the Jacobi correction of every compressed alive contact;
//! 6. *nodes*: each node gathers its friction corrections and moves.
//!
//! Every pass writes only its own element's slot, so the result does not
//! depend on the thread count. The element passes call the kernels of
//! [`yarn_model::terms`], so the backend agrees with `Serial<f32>` to float
//! rounding (only the order of the per-node sums differs).

use rayon::prelude::*;
use yarn_model::terms::{bend_end_forces, gravity_force, spring_force};
use yarn_model::{Backend, BackendError, Model, Params, State, V3, step};
use yarn_topology::{Fabric, Pin};

type V = V3<f32>;

/// Elements per rayon task: large enough that scheduling costs little
/// against the work, small enough to balance two to dozens of threads.
const CHUNK: usize = 2048;

/// The parallel CPU backend, in `f32`.
#[derive(Debug, Default)]
pub struct Rayon {
    pool: Option<rayon::ThreadPool>,
    loaded: Option<Loaded>,
}

#[derive(Debug)]
struct Loaded {
    model: Model<f32>,
    state: State<f32>,
    /// Contacts of each node: `incident[start[i]..start[i + 1]]` holds
    /// (contact index, +1 if the node is the contact's `a`, −1 if `b`).
    start: Vec<u32>,
    incident: Vec<(u32, f32)>,
    /// Per segment: unit tangent and stretch force magnitude k(ℓ − ℓ0),
    /// plus the length, for the joints.
    segments: Vec<(V, f32, f32)>,
    /// Per joint: the forces on its first and last node.
    joints: Vec<(V, V)>,
    /// Per contact: the force on its `a` node, then the friction change Δw.
    contact_force: Vec<V>,
    friction: Vec<V>,
}

impl Rayon {
    /// A backend on rayon's global thread pool.
    pub fn new() -> Self {
        Self::default()
    }

    /// A backend on its own pool of `threads` threads.
    ///
    /// # Errors
    /// The pool's build error, if the threads cannot be started.
    pub fn with_threads(threads: usize) -> Result<Self, rayon::ThreadPoolBuildError> {
        Ok(Self { pool: Some(rayon::ThreadPoolBuilder::new().num_threads(threads).build()?), loaded: None })
    }

    fn loaded(&mut self) -> Result<&mut Loaded, BackendError> {
        self.loaded.as_mut().ok_or(BackendError::NotLoaded)
    }
}

impl Loaded {
    fn new(fabric: &Fabric, params: &Params) -> Result<Self, BackendError> {
        let model = Model::<f32>::new(fabric, params)?;
        let n = model.node_count();
        let mut degree = vec![0u32; n + 1];
        for c in &model.contacts {
            degree[c.a as usize + 1] += 1;
            degree[c.b as usize + 1] += 1;
        }
        let start: Vec<u32> = degree
            .iter()
            .scan(0, |sum, d| {
                *sum += d;
                Some(*sum)
            })
            .collect();
        let mut fill = start.clone();
        let mut incident = vec![(0, 0.0); model.contacts.len() * 2];
        for (k, c) in model.contacts.iter().enumerate() {
            for (node, sign) in [(c.a, 1.0), (c.b, -1.0)] {
                incident[fill[node as usize] as usize] = (k as u32, sign);
                fill[node as usize] += 1;
            }
        }
        let contacts = model.contacts.len();
        Ok(Self {
            state: State::at_rest(fabric),
            start,
            incident,
            segments: vec![(V::zeros(), 0.0, 0.0); n.saturating_sub(1)],
            joints: vec![(V::zeros(), V::zeros()); n.saturating_sub(2)],
            contact_force: vec![V::zeros(); contacts],
            friction: vec![V::zeros(); contacts],
            model,
        })
    }

    /// Passes 1–3: segment, joint and contact forces into their own slots.
    fn forces(&mut self) {
        let Self { model, state, segments, joints, contact_force, .. } = self;
        let c = model.coeffs;
        let x = &state.positions;
        segments.par_chunks_mut(CHUNK).enumerate().for_each(|(chunk, out)| {
            for (j, seg) in out.iter_mut().enumerate() {
                let i = chunk * CHUNK + j;
                let d = x[i + 1] - x[i];
                let length = d.norm();
                let tangent = if length > 0.0 { d / length } else { V::zeros() };
                *seg = (tangent, c.stretch * (length - model.spring_rest[i]), length);
            }
        });
        let segments = &*segments;
        joints.par_chunks_mut(CHUNK).enumerate().for_each(|(chunk, out)| {
            for (j, joint) in out.iter_mut().enumerate() {
                let i = chunk * CHUNK + j;
                let ((u, _, l0), (v, _, l1)) = (segments[i], segments[i + 1]);
                *joint = bend_end_forces(&u, &v, l0, l1, c.rest_curl * model.rest_angle[i], c.bend)
                    .unwrap_or((V::zeros(), V::zeros()));
            }
        });
        contact_force.par_chunks_mut(CHUNK).enumerate().for_each(|(chunk, out)| {
            for (j, f) in out.iter_mut().enumerate() {
                let k = chunk * CHUNK + j;
                let contact = model.contacts[k];
                *f = if model.alive[k] {
                    spring_force(&x[contact.a as usize], &x[contact.b as usize], contact.rest, c.contact)
                } else {
                    V::zeros()
                };
            }
        });
    }

    /// The total force on node `i` from the element passes.
    #[inline]
    fn gather(&self, i: usize, gravity: V) -> V {
        let n = self.state.positions.len();
        let mut f = gravity;
        if i + 1 < n {
            let (t, s, _) = self.segments[i];
            f += t * s;
        }
        if i >= 1 {
            let (t, s, _) = self.segments[i - 1];
            f -= t * s;
        }
        if i + 2 < n {
            f += self.joints[i].0;
        }
        if i >= 1 && i < n - 1 {
            let (fa, fc) = self.joints[i - 1];
            f -= fa + fc;
        }
        if i >= 2 {
            f += self.joints[i - 2].1;
        }
        for &(k, sign) in &self.incident[self.start[i] as usize..self.start[i + 1] as usize] {
            f += self.contact_force[k as usize] * sign;
        }
        f
    }

    fn substep(&mut self) {
        self.forces();
        let c = self.model.coeffs;
        let gravity = gravity_force(c.mass, c.gravity);
        // Pass 4: gather and damp. The velocities are taken out of `self`
        // so the gather can borrow the rest of it while chunks write them.
        let mut velocities = std::mem::take(&mut self.state.velocities);
        velocities.par_chunks_mut(CHUNK).enumerate().for_each(|(chunk, out)| {
            for (j, v) in out.iter_mut().enumerate() {
                let i = chunk * CHUNK + j;
                *v = (*v + self.gather(i, gravity) * c.h_over_m) * c.damping_factor;
            }
        });
        self.state.velocities = velocities;
        if c.friction > 0.0 {
            let Self { model, state, friction, .. } = self;
            let (x, v) = (&state.positions, &state.velocities);
            friction.par_chunks_mut(CHUNK).enumerate().for_each(|(chunk, out)| {
                for (j, dw) in out.iter_mut().enumerate() {
                    let k = chunk * CHUNK + j;
                    let ct = model.contacts[k];
                    let (a, b) = (ct.a as usize, ct.b as usize);
                    *dw = if model.alive[k] {
                        step::friction_change(&x[a], &x[b], &v[a], &v[b], ct.rest, model).unwrap_or_else(V::zeros)
                    } else {
                        V::zeros()
                    };
                }
            });
        }
        // Pass 6: friction corrections, then the position update.
        let Self { state, start, incident, friction, .. } = self;
        let apply_friction = c.friction > 0.0;
        state.positions.par_chunks_mut(CHUNK).zip(state.velocities.par_chunks_mut(CHUNK)).enumerate().for_each(
            |(chunk, (xs, vs))| {
                for (j, (x, v)) in xs.iter_mut().zip(vs.iter_mut()).enumerate() {
                    let i = chunk * CHUNK + j;
                    if apply_friction {
                        for &(k, sign) in &incident[start[i] as usize..start[i + 1] as usize] {
                            // Node a gets −Δw/2, node b +Δw/2 (SPEC §4 step 3).
                            *v -= friction[k as usize] * (0.5 * sign);
                        }
                    }
                    *x += *v * c.h;
                }
            },
        );
        for &(node, target) in &self.model.pins {
            self.state.positions[node as usize] = target;
            self.state.velocities[node as usize] = V::zeros();
        }
    }
}

impl Backend for Rayon {
    type Real = f32;

    fn name(&self) -> String {
        format!("rayon-f32x{}", self.threads())
    }

    fn threads(&self) -> usize {
        self.pool.as_ref().map_or_else(rayon::current_num_threads, rayon::ThreadPool::current_num_threads)
    }

    fn load(&mut self, fabric: &Fabric, params: &Params) -> Result<(), BackendError> {
        self.loaded = Some(Loaded::new(fabric, params)?);
        Ok(())
    }

    fn set_params(&mut self, params: &Params) -> Result<(), BackendError> {
        self.loaded()?.model.set_params(params)
    }

    fn set_pins(&mut self, pins: &[Pin]) -> Result<(), BackendError> {
        self.loaded()?.model.set_pins(pins)
    }

    fn set_contacts_alive(&mut self, alive: &[bool]) -> Result<(), BackendError> {
        self.loaded()?.model.set_contacts_alive(alive)
    }

    fn write_state(&mut self, state: &State<f32>) -> Result<(), BackendError> {
        let loaded = self.loaded()?;
        state.check_len(loaded.model.node_count())?;
        loaded.state.clone_from(state);
        Ok(())
    }

    fn read_state(&mut self, state: &mut State<f32>) -> Result<(), BackendError> {
        state.clone_from(&self.loaded()?.state);
        Ok(())
    }

    fn compute_forces(&mut self, forces: &mut Vec<V>) -> Result<(), BackendError> {
        let pool = self.pool.as_ref();
        let loaded = self.loaded.as_mut().ok_or(BackendError::NotLoaded)?;
        let c = loaded.model.coeffs;
        let gravity = gravity_force(c.mass, c.gravity);
        install(pool, || {
            loaded.forces();
            forces.clear();
            forces.par_extend((0..loaded.state.len()).into_par_iter().map(|i| loaded.gather(i, gravity)));
        });
        Ok(())
    }

    fn advance(&mut self, substeps: u64) -> Result<(), BackendError> {
        let pool = self.pool.as_ref();
        let loaded = self.loaded.as_mut().ok_or(BackendError::NotLoaded)?;
        install(pool, || {
            for _ in 0..substeps {
                loaded.substep();
            }
        });
        Ok(())
    }
}

/// Run `work` on `pool`, or on rayon's global pool when there is none.
fn install(pool: Option<&rayon::ThreadPool>, work: impl FnOnce() + Send) {
    match pool {
        Some(pool) => pool.install(work),
        None => work(),
    }
}
