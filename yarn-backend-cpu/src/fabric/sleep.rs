//! Sleeping (see [`yarn_model::Params::sleep_speed`]): blocks of nodes that
//! have stayed slow, and not sped up, for [`yarn_model::SLEEP_AFTER`]
//! substeps stop being integrated until a neighbouring block moves fast, a
//! pin lands in them, or the scene changes.
//!
//! This module owns which blocks sleep and why they wake. It does not run
//! the passes; they skip the blocks it reports asleep, and the caller
//! rebuilds the live contact lists when the set changes.

use yarn_model::{Model, Real, V3};

use super::field::{BLOCK, Field};

/// Substeps between two looks at which blocks may sleep or must wake: the
/// look scans every awake velocity, so it is not taken every substep.
pub(crate) const SLEEP_CHECK: u64 = 10;

/// Per block: asleep or not, and since when it has been quiet.
#[derive(Debug)]
pub(crate) struct Sleep {
    /// Asleep (not integrated).
    asleep: Vec<bool>,
    /// Substeps its nodes have all stayed below the sleep speed without
    /// speeding up.
    quiet: Vec<u32>,
    /// Its fastest node's speed squared at the first look of its quiet
    /// run (meaningless while `quiet` is 0), which no later look of the run
    /// may pass.
    quiet_since2: Vec<f64>,
    /// The other blocks it shares a segment or a contact with.
    neighbours: Vec<Vec<u32>>,
    /// The other blocks it has a self-contact candidate pair with, from the
    /// last list build.
    touching: Vec<Vec<u32>>,
}

impl Sleep {
    /// Every block of `model`'s nodes awake.
    pub(crate) fn new<T: Real>(model: &Model<T>) -> Self {
        let blocks = model.node_count().div_ceil(BLOCK);
        Self {
            asleep: vec![false; blocks],
            quiet: vec![0; blocks],
            quiet_since2: vec![0.0; blocks],
            neighbours: neighbours(model, blocks),
            touching: vec![Vec::new(); blocks],
        }
    }

    /// The blocks that touch through self-contact: those of each candidate
    /// pair of segments (by their first nodes), so yarn landing on a
    /// sleeping block wakes it.
    pub(crate) fn set_touching<T: Real>(&mut self, model: &Model<T>, pairs: impl Iterator<Item = [u32; 2]>) {
        let links = model.links();
        let ends = |a: u32| [Some(a), links[a as usize].next()].into_iter().flatten().map(|i| i as usize / BLOCK);
        let mut touching = vec![Vec::new(); self.asleep.len()];
        for [a, b] in pairs {
            for p in ends(a) {
                for q in ends(b) {
                    if p != q {
                        touching[p].push(q as u32);
                        touching[q].push(p as u32);
                    }
                }
            }
        }
        for list in &mut touching {
            list.sort_unstable();
            list.dedup();
        }
        self.touching = touching;
    }

    /// Per block, whether it is asleep.
    pub(crate) fn asleep(&self) -> &[bool] {
        &self.asleep
    }

    /// Blocks asleep now.
    pub(crate) fn sleeping_blocks(&self) -> usize {
        self.asleep.iter().filter(|&&a| a).count()
    }

    /// Wake every block and restart their quiet counts; returns whether
    /// any was asleep.
    pub(crate) fn wake_all(&mut self) -> bool {
        self.quiet.fill(0);
        let any = self.asleep.iter().any(|&a| a);
        self.asleep.fill(false);
        any
    }

    /// Every [`SLEEP_CHECK`] substeps: count quiet substeps, put blocks
    /// that have stayed below `limit`, and below their speed at the first
    /// look of the run, long enough (with no pin and no fast
    /// neighbour) to sleep, with their velocities zeroed and their next
    /// positions at their positions, and wake sleepers next to a block
    /// moving at twice `limit`. Returns whether any block changed.
    pub(crate) fn update<T: Real>(
        &mut self,
        limit: f64,
        pins: &[(u32, V3<T>)],
        positions: &Field<T>,
        velocities: &mut Field<T>,
        next_positions: &mut Field<T>,
    ) -> bool {
        if limit <= 0.0 {
            return false;
        }
        let blocks = self.asleep.len();
        // The fastest node of each awake block, squared.
        let speed2: Vec<f64> = (0..blocks)
            .map(|block| {
                if self.asleep[block] {
                    return 0.0;
                }
                let [x, y, z] = velocities.block(block);
                let mut max = T::zero();
                for k in 0..x.len() {
                    let s = x[k] * x[k] + y[k] * y[k] + z[k] * z[k];
                    max = if s > max { s } else { max };
                }
                max.to_f64()
            })
            .collect();
        let mut pinned = vec![false; blocks];
        for &(node, _) in pins {
            pinned[node as usize / BLOCK] = true;
        }
        let (sleep2, wake2) = (limit * limit, 4.0 * limit * limit);
        let fast_neighbour = |block: usize| {
            self.neighbours[block].iter().chain(&self.touching[block]).any(|&n| speed2[n as usize] > wake2)
        };
        let mut changed = false;
        for block in 0..blocks {
            if self.asleep[block] {
                if pinned[block] || fast_neighbour(block) {
                    (self.asleep[block], self.quiet[block], changed) = (false, 0, true);
                }
                continue;
            }
            // Slow but faster than when it turned slow is not settling: a
            // block pushed from rest would be frozen short of where it goes.
            let slow = speed2[block] < sleep2 && !pinned[block];
            if !slow || self.quiet[block] == 0 || speed2[block] > self.quiet_since2[block] {
                (self.quiet[block], self.quiet_since2[block]) = (0, speed2[block]);
            }
            if slow {
                self.quiet[block] += SLEEP_CHECK as u32;
            }
            if self.quiet[block] >= yarn_model::SLEEP_AFTER && !fast_neighbour(block) {
                (self.asleep[block], changed) = (true, true);
                let range = block * BLOCK..((block + 1) * BLOCK).min(positions.len());
                for (v, (x, next)) in [&mut velocities.x, &mut velocities.y, &mut velocities.z].into_iter().zip([
                    (&positions.x, &mut next_positions.x),
                    (&positions.y, &mut next_positions.y),
                    (&positions.z, &mut next_positions.z),
                ]) {
                    v[range.clone()].fill(T::zero());
                    next[range.clone()].copy_from_slice(&x[range.clone()]);
                }
            }
        }
        changed
    }
}

/// Per block, the other blocks it shares a segment or a contact with.
fn neighbours<T: Real>(model: &Model<T>, blocks: usize) -> Vec<Vec<u32>> {
    let mut out = vec![Vec::new(); blocks];
    let mut link = |a: usize, b: usize| {
        if a != b {
            out[a].push(b as u32);
            out[b].push(a as u32);
        }
    };
    for (a, b, _) in model.springs() {
        link(a / BLOCK, b / BLOCK);
    }
    for c in model.contacts() {
        link(c.a as usize / BLOCK, c.b as usize / BLOCK);
    }
    for list in &mut out {
        list.sort_unstable();
        list.dedup();
    }
    out
}
