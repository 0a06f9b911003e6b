//! The storage layout of the CPU backends: a 3-vector field stored by
//! component, cut into fixed blocks of [`BLOCK`] nodes, so that the passes'
//! per-node loops vectorise and each block can go to its own thread.
//!
//! This module owns the layout only; it knows nothing of the model.

use rayon::prelude::*;
use yarn_model::{Real, V3};

/// Nodes per block: a block's `f32` scratch (16 numbers per node) fits the
/// first-level cache, and the two segments and joints it recomputes at
/// each edge cost nothing against the work.
pub(crate) const BLOCK: usize = 512;

/// A 3-vector field stored by component.
#[derive(Debug, Clone, Default)]
pub(crate) struct Field<T> {
    pub(crate) x: Vec<T>,
    pub(crate) y: Vec<T>,
    pub(crate) z: Vec<T>,
}

/// One block of a [`Field`], writable.
pub(crate) struct BlockMut<'a, T> {
    pub(crate) x: &'a mut [T],
    pub(crate) y: &'a mut [T],
    pub(crate) z: &'a mut [T],
}

impl<T: Real> Field<T> {
    pub(crate) fn zeros(n: usize) -> Self {
        Self { x: vec![T::zero(); n], y: vec![T::zero(); n], z: vec![T::zero(); n] }
    }

    pub(crate) fn from_vectors(v: &[V3<T>]) -> Self {
        Self {
            x: v.iter().map(|p| p.x).collect(),
            y: v.iter().map(|p| p.y).collect(),
            z: v.iter().map(|p| p.z).collect(),
        }
    }

    pub(crate) fn len(&self) -> usize {
        self.x.len()
    }

    pub(crate) fn get(&self, i: usize) -> V3<T> {
        V3::new(self.x[i], self.y[i], self.z[i])
    }

    pub(crate) fn set(&mut self, i: usize, v: V3<T>) {
        (self.x[i], self.y[i], self.z[i]) = (v.x, v.y, v.z);
    }

    pub(crate) fn to_vectors(&self, out: &mut Vec<V3<T>>) {
        out.clear();
        out.extend((0..self.len()).map(|i| self.get(i)));
    }

    /// The three components of block `block`.
    pub(crate) fn block(&self, block: usize) -> [&[T]; 3] {
        let range = block * BLOCK..((block + 1) * BLOCK).min(self.len());
        [&self.x[range.clone()], &self.y[range.clone()], &self.z[range]]
    }

    /// The three components of the first `n` entries.
    #[inline]
    pub(crate) fn prefix(&self, n: usize) -> [&[T]; 3] {
        [&self.x[..n], &self.y[..n], &self.z[..n]]
    }

    /// The three components of the first `n` entries, writable.
    #[inline]
    pub(crate) fn prefix_mut(&mut self, n: usize) -> [&mut [T]; 3] {
        [&mut self.x[..n], &mut self.y[..n], &mut self.z[..n]]
    }

    pub(crate) fn blocks_mut(&mut self) -> impl Iterator<Item = BlockMut<'_, T>> {
        let Self { x, y, z } = self;
        x.chunks_mut(BLOCK).zip(y.chunks_mut(BLOCK)).zip(z.chunks_mut(BLOCK)).map(|((x, y), z)| BlockMut { x, y, z })
    }

    pub(crate) fn par_blocks_mut(&mut self) -> impl IndexedParallelIterator<Item = BlockMut<'_, T>> {
        let Self { x, y, z } = self;
        x.par_chunks_mut(BLOCK).zip(y.par_chunks_mut(BLOCK)).zip(z.par_chunks_mut(BLOCK)).map(|((x, y), z)| BlockMut {
            x,
            y,
            z,
        })
    }
}

impl<T> BlockMut<'_, T> {
    pub(crate) fn components(&mut self) -> [&mut [T]; 3] {
        [&mut *self.x, &mut *self.y, &mut *self.z]
    }
}
