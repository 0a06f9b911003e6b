//! How a CPU fabric runs a batch of substeps and takes it back
//! ([`yarn_model::Rollback`]): the state is copied into buffers kept for
//! it, and the live contact lists are rebuilt from the model's re-seated
//! rests after a rollback.
//!
//! This module owns the batch loop and its divergence test; the passes
//! themselves are in `passes.rs`.

use std::sync::atomic::Ordering;

use yarn_model::{BackendError, Model, Real, Rollback, State};

use super::CpuFabric;

impl<T: Real> Rollback for CpuFabric<T> {
    type Real = T;

    fn model_mut(&mut self) -> &mut Model<T> {
        &mut self.model
    }

    fn save(&mut self) {
        self.saved[0].clone_from(&self.positions);
        self.saved[1].clone_from(&self.velocities);
    }

    fn run(&mut self, substeps: u64) -> Result<(), BackendError> {
        for done in 1..=substeps {
            self.substep();
            self.after_substep(done);
            if self.diverged.swap(false, Ordering::Relaxed) {
                let limit = self.model.divergence_speed();
                let mut state = State::default();
                self.read_state(&mut state);
                // The flag looks at the velocity before the pins; a node the
                // pins stopped has not diverged (the reference's rule).
                if let Some((node, speed)) = state.first_diverged(limit) {
                    return Err(BackendError::Diverged { substep: self.substeps + done, node, speed, limit });
                }
            }
        }
        self.substeps += substeps;
        Ok(())
    }

    fn restore(&mut self) -> Result<(), BackendError> {
        self.positions.clone_from(&self.saved[0]);
        self.velocities.clone_from(&self.saved[1]);
        self.refresh_contacts();
        Ok(())
    }
}
