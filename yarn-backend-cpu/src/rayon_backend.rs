//! The `Rayon` backend: the CPU passes' blocks run on a rayon pool.

use yarn_model::{Backend, BackendError, Params, StageTimes, V3};
use yarn_topology::Fabric;

use crate::fabric::{CpuFabric, Exec};

/// The parallel CPU backend, in `f32`: the passes of
/// [`Serial`](crate::Serial), with each pass's blocks spread over a rayon
/// thread pool. The result does not depend on the thread count.
#[derive(Debug, Default)]
pub struct Rayon {
    pool: Option<rayon::ThreadPool>,
    loaded: Option<CpuFabric<f32>>,
}

impl Rayon {
    /// A backend on rayon's global thread pool.
    pub fn new() -> Self {
        Self::default()
    }

    /// Blocks of 512 nodes asleep now (see [`yarn_model::Params::sleep_speed`]);
    /// 0 before load.
    pub fn sleeping_blocks(&self) -> usize {
        self.loaded.as_ref().map_or(0, CpuFabric::sleeping_blocks)
    }

    /// A backend on its own pool of `threads` threads.
    ///
    /// # Errors
    /// The pool's build error, if the threads cannot be started.
    pub fn with_threads(threads: usize) -> Result<Self, rayon::ThreadPoolBuildError> {
        Ok(Self { pool: Some(rayon::ThreadPoolBuilder::new().num_threads(threads).build()?), loaded: None })
    }

    fn loaded(&mut self) -> Result<&mut CpuFabric<f32>, BackendError> {
        self.loaded.as_mut().ok_or(BackendError::NotLoaded)
    }

    /// Run `work` on the loaded fabric inside the pool (or rayon's global pool),
    /// so its passes start from a worker thread instead of each blocking
    /// the calling thread until a worker picks it up.
    fn install<R: Send>(&mut self, work: impl FnOnce(&mut CpuFabric<f32>) -> R + Send) -> Result<R, BackendError> {
        let loaded = self.loaded.as_mut().ok_or(BackendError::NotLoaded)?;
        Ok(match &self.pool {
            Some(pool) => pool.install(|| work(loaded)),
            None => rayon::scope(|_| work(loaded)),
        })
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
        self.loaded = Some(CpuFabric::new(fabric, params, Exec::Parallel, self.threads())?);
        Ok(())
    }

    forward_to_loaded!(f32);

    fn compute_forces(&mut self, forces: &mut Vec<V3<f32>>) -> Result<(), BackendError> {
        self.install(|loaded| loaded.compute_forces(forces))
    }

    fn advance(&mut self, substeps: u64) -> Result<(), BackendError> {
        self.install(|loaded| loaded.advance(substeps))?
    }

    fn advance_timed(&mut self, substeps: u64) -> Result<StageTimes, BackendError> {
        self.install(|loaded| loaded.advance_timed(substeps))?
    }
}
