//! The `Rayon` backend: the CPU kernel's blocks run on a rayon pool.

use yarn_model::{Backend, BackendError, Params, V3};
use yarn_topology::Fabric;

use crate::kernel::{Exec, Kernel};

/// The parallel CPU backend, in `f32`: the passes of
/// [`Serial`](crate::Serial), with each pass's blocks spread over a rayon
/// thread pool. The result does not depend on the thread count.
#[derive(Debug, Default)]
pub struct Rayon {
    pool: Option<rayon::ThreadPool>,
    kernel: Option<Kernel<f32>>,
}

impl Rayon {
    /// A backend on rayon's global thread pool.
    pub fn new() -> Self {
        Self::default()
    }

    /// Blocks of 512 nodes asleep now (see [`yarn_model::Params::sleep_speed`]);
    /// 0 before load.
    pub fn sleeping_blocks(&self) -> usize {
        self.kernel.as_ref().map_or(0, Kernel::sleeping_blocks)
    }

    /// A backend on its own pool of `threads` threads.
    ///
    /// # Errors
    /// The pool's build error, if the threads cannot be started.
    pub fn with_threads(threads: usize) -> Result<Self, rayon::ThreadPoolBuildError> {
        Ok(Self { pool: Some(rayon::ThreadPoolBuilder::new().num_threads(threads).build()?), kernel: None })
    }

    fn kernel(&mut self) -> Result<&mut Kernel<f32>, BackendError> {
        self.kernel.as_mut().ok_or(BackendError::NotLoaded)
    }

    /// Run `work` on the kernel inside the pool (or rayon's global pool),
    /// so its passes start from a worker thread instead of each blocking
    /// the calling thread until a worker picks it up.
    fn install<R: Send>(&mut self, work: impl FnOnce(&mut Kernel<f32>) -> R + Send) -> Result<R, BackendError> {
        let kernel = self.kernel.as_mut().ok_or(BackendError::NotLoaded)?;
        Ok(match &self.pool {
            Some(pool) => pool.install(|| work(kernel)),
            None => rayon::scope(|_| work(kernel)),
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
        self.kernel = Some(Kernel::new(fabric, params, Exec::Parallel, self.threads())?);
        Ok(())
    }

    forward_to_kernel!(f32);

    fn compute_forces(&mut self, forces: &mut Vec<V3<f32>>) -> Result<(), BackendError> {
        self.install(|kernel| kernel.compute_forces(forces))
    }

    fn advance(&mut self, substeps: u64) -> Result<(), BackendError> {
        self.install(|kernel| kernel.advance(substeps))?
    }
}
