//! Advance with rollback, written once: a batch of substeps that fails
//! (diverges, overflows) leaves the state and the re-seated contacts as
//! they were before it, on every backend.
//!
//! This module owns the order of the steps (save the state, save the
//! re-seats, run, and on failure put back the re-seats, then the state);
//! it must not know how a backend stores its state or runs its substeps.

use crate::{BackendError, Model, Real};

/// A loaded fabric that can run a batch of substeps and take it back.
pub trait Rollback {
    /// The scalar of its host model.
    type Real: Real;

    /// The host model, whose re-seated contacts the batch closes.
    fn model_mut(&mut self) -> &mut Model<Self::Real>;

    /// Keep the state the batch starts from, for [`Rollback::restore`].
    fn save(&mut self);

    /// Run `substeps` substeps, closing the host model's re-seated contacts
    /// as the substeps do.
    ///
    /// # Errors
    /// Whatever stops the batch: a divergence, an overflow, a device error.
    fn run(&mut self, substeps: u64) -> Result<(), BackendError>;

    /// Put back the state [`Rollback::save`] kept. The host model's
    /// re-seated contacts are already back when this is called, so a
    /// backend that copies them (into contact lists or GPU buffers) copies
    /// them again here.
    ///
    /// # Errors
    /// A device error while restoring.
    fn restore(&mut self) -> Result<(), BackendError>;
}

/// Run `substeps` substeps on `fabric`; if they fail, put the state and
/// the re-seated contacts back as they were and return the error.
///
/// # Errors
/// The batch's error, or a device error while restoring.
pub fn advance_with_rollback<R: Rollback + ?Sized>(fabric: &mut R, substeps: u64) -> Result<(), BackendError> {
    fabric.save();
    let reseats = fabric.model_mut().save_reseats();
    let result = fabric.run(substeps);
    if result.is_err() {
        fabric.model_mut().restore_reseats(&reseats);
        fabric.restore()?;
    }
    result
}
