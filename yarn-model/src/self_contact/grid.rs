//! The GPU's search for self-contact candidates, on the CPU: the twins of
//! `grid_insert.wgsl` and `grid_find.wgsl` in yarn-backend-wgpu, in their
//! index-loop shape and order, so that a list the GPU built can be checked
//! entry for entry.
//!
//! Each segment's midpoint falls in a cell of a cubic grid, and each cell
//! hashes to one of a power-of-two number of buckets. A bucket is a linked
//! list threaded through `next` (one entry per segment), pushed at its head;
//! the GPU pushes with `atomicExchange`, so the order within a bucket
//! varies from run to run. A segment then walks the buckets of the cells
//! around its own, keeps each other segment that lies in the cell it asked
//! for (a bucket holds every cell that hashes to it) and may touch under
//! the model's rule within the reach, and sorts what it kept. The sorted
//! list does not depend on the order within the buckets, so the GPU's lists
//! equal these whatever order its atomics ran in.
//!
//! Two segments within reach R of each other have midpoints within
//! (ℓ_a + ℓ_b)/2 + R, so while both are at most `short` long, 1.5 times the
//! fabric's longest rest segment, the 27 cells around a segment's own
//! (cells of edge `short` + R, fixed when the fabric loads) hold every
//! segment it may touch. A segment stretched longer than that is *long*: it
//! goes into one list of its own instead of the grid, which every segment
//! checks, and it searches the cells of its bounding box, widened by
//! R + short/2, for the segments of the grid. So a yarn stretched by a pin
//! or a snag costs only its own long segments, and the search never misses
//! a pair. Past [`MAX_LONG`] long segments at once, or a long segment
//! whose box spans more than [`MAX_BOX`] cells a side, the yarn is
//! stretched past any physical state, and the search reports it instead.

use crate::terms::closest_gap;
use crate::{Model, Real, V3};

/// A bucket or `next` entry that holds no segment.
pub const EMPTY: u32 = u32::MAX;

/// The most long segments a search holds at once.
pub const MAX_LONG: u32 = 4096;

/// The most cells along each side of a long segment's search box.
pub const MAX_BOX: i32 = 16;

/// How far the search keeps pairs, beyond 2r: the model's skin.
fn reach<T: Real>(model: &Model<T>) -> f64 {
    (2.0 + model.params().self_contact_skin) * model.contact_rule().radius()
}

/// The grid a fabric's segments are hashed into, fixed when it loads.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GridShape<T> {
    /// The cell's edge: `short` plus the reach.
    pub cell: T,
    /// Buckets − 1; the bucket count is a power of two.
    pub mask: u32,
    /// Pairs closer than this are kept: 2r plus the skin.
    pub reach: T,
    /// The longest a segment in the grid may be; longer ones are long.
    pub short: T,
}

impl<T: Real> GridShape<T> {
    /// The grid for `model`: segments up to 1.5 times its longest rest
    /// segment in cells of that plus the reach, and a bucket for each node,
    /// rounded up to a power of two.
    pub fn new(model: &Model<T>) -> Self {
        let longest = model.segment_rest().iter().map(|l| l.to_f64()).fold(0.0, f64::max);
        let (reach, short) = (reach(model), 1.5 * longest);
        Self {
            cell: T::of(short + reach),
            mask: (model.node_count().max(1).next_power_of_two() - 1) as u32,
            reach: T::of(reach),
            short: T::of(short),
        }
    }

    /// How many buckets there are.
    pub fn buckets(&self) -> usize {
        self.mask as usize + 1
    }

    /// The cell holding `m`. Coordinates are clamped to ±2³⁰ cells, and a
    /// NaN counts as 0, so no position makes the index overflow.
    pub fn cell_of(&self, m: &V3<T>) -> [i32; 3] {
        let bound = f64::from(1u32 << 30);
        // `as` takes a NaN to 0.
        let index = |c: T| (c / self.cell).floor().to_f64().clamp(-bound, bound) as i32;
        [index(m.x), index(m.y), index(m.z)]
    }

    /// The bucket of cell `c`.
    pub fn bucket(&self, c: [i32; 3]) -> u32 {
        let [x, y, z] = c.map(|v| v as u32);
        (x.wrapping_mul(73_856_093) ^ y.wrapping_mul(19_349_663) ^ z.wrapping_mul(83_492_791)) & self.mask
    }

    /// The cells segment p0p1 searches, as the lowest and highest corner:
    /// the 27 around its midpoint's while it is short; while long, those of
    /// its bounding box widened by the reach and half of `short`, or `None`
    /// past [`MAX_BOX`] a side.
    pub fn search_box(&self, p0: &V3<T>, p1: &V3<T>) -> Option<([i32; 3], [i32; 3])> {
        if (p1 - p0).norm() <= self.short {
            let home = self.cell_of(&midpoint(p0, p1));
            return Some((home.map(|c| c.wrapping_sub(1)), home.map(|c| c.wrapping_add(1))));
        }
        let pad = V3::repeat(self.reach + self.short * T::of(0.5));
        let (lo, hi) = (self.cell_of(&(p0.inf(p1) - pad)), self.cell_of(&(p0.sup(p1) + pad)));
        (0..3).all(|k| (0..MAX_BOX).contains(&hi[k].wrapping_sub(lo[k]))).then_some((lo, hi))
    }
}

/// The midpoint of the segment from `p` to `q`.
#[inline]
pub fn midpoint<T: Real>(p: &V3<T>, q: &V3<T>) -> V3<T> {
    (p + q) * T::of(0.5)
}

/// The node segment `a` ends at, or `None` where no segment starts at a.
#[inline]
fn end_of<T: Real>(model: &Model<T>, a: usize) -> Option<usize> {
    model.links()[a].next().map(|n| n as usize)
}

/// The grid as a rebuild fills it: the buckets' heads, each segment's
/// `next` in its bucket, and the long segments.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Grid {
    /// Per bucket: the segment pushed last, or [`EMPTY`].
    pub heads: Vec<u32>,
    /// Per node: the segment pushed before it onto its bucket.
    pub next: Vec<u32>,
    /// The long segments, in the order they came.
    pub long: Vec<u32>,
}

impl Grid {
    /// An empty grid for `shape` over `nodes` nodes.
    pub fn new<T: Real>(shape: &GridShape<T>, nodes: usize) -> Self {
        Self { heads: vec![EMPTY; shape.buckets()], next: vec![EMPTY; nodes], long: Vec::new() }
    }
}

/// Twin of `grid_insert.wgsl`: push segment `i` onto its bucket's list, or
/// onto the long list when it is longer than `shape.short`; a node that
/// starts no segment pushes nothing.
pub fn insert<T: Real>(shape: &GridShape<T>, model: &Model<T>, x: &[V3<T>], i: usize, grid: &mut Grid) {
    grid.next[i] = EMPTY;
    let Some(end) = end_of(model, i) else { return };
    if (x[end] - x[i]).norm() <= shape.short {
        let bucket = shape.bucket(shape.cell_of(&midpoint(&x[i], &x[end]))) as usize;
        grid.next[i] = std::mem::replace(&mut grid.heads[bucket], i as u32);
    } else {
        grid.long.push(i as u32);
    }
}

/// The search went past [`MAX_LONG`] long segments or a box of [`MAX_BOX`]
/// cells a side: the yarn is stretched past any physical state.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Overstretched;

/// Twin of `grid_find.wgsl`: segment `i`'s candidates, sorted, into `out`:
/// every other segment of the grid in the cells it searches (found in its
/// own cell's bucket, so once) and every long segment, whose closest
/// distance to i, measured from the lower-numbered of the two so both
/// agree, is below the reach, unless the two are near along their yarn.
/// Empty for a node that starts no segment.
///
/// # Errors
/// [`Overstretched`] past [`MAX_LONG`] long segments, or when i's box
/// spans more than [`MAX_BOX`] cells a side.
pub fn find<T: Real>(
    shape: &GridShape<T>,
    model: &Model<T>,
    x: &[V3<T>],
    i: usize,
    grid: &Grid,
    out: &mut Vec<u32>,
) -> Result<(), Overstretched> {
    out.clear();
    let Some(end) = end_of(model, i) else { return Ok(()) };
    if grid.long.len() > MAX_LONG as usize {
        return Err(Overstretched);
    }
    let (lo, hi) = shape.search_box(&x[i], &x[end]).ok_or(Overstretched)?;
    let mut keep = |j: u32| {
        if j as usize != i && may_touch(shape, model, x, i, j as usize) {
            let at = out.partition_point(|&k| k < j);
            out.insert(at, j);
        }
    };
    for z in lo[2]..=hi[2] {
        for y in lo[1]..=hi[1] {
            for w in lo[0]..=hi[0] {
                let cell = [w, y, z];
                let mut j = grid.heads[shape.bucket(cell) as usize];
                // A list holds each segment once; the bound only keeps a
                // corrupted one from looping.
                for _ in 0..x.len() {
                    if j == EMPTY {
                        break;
                    }
                    let j_end = end_of(model, j as usize).unwrap_or(j as usize);
                    if shape.cell_of(&midpoint(&x[j as usize], &x[j_end])) == cell {
                        keep(j);
                    }
                    j = grid.next[j as usize];
                }
            }
        }
    }
    for &j in &grid.long {
        keep(j);
    }
    Ok(())
}

/// Whether segments i and j (i ≠ j) may touch: not near along their yarn,
/// and closer than the reach, measured from the lower one.
fn may_touch<T: Real>(shape: &GridShape<T>, model: &Model<T>, x: &[V3<T>], i: usize, j: usize) -> bool {
    if model.contact_rule().near_along_yarn(i, j) {
        return false;
    }
    let (lo, hi) = (i.min(j), i.max(j));
    let (lo_end, hi_end) = (end_of(model, lo).unwrap_or(lo), end_of(model, hi).unwrap_or(hi));
    let ends = [&x[lo], &x[lo_end], &x[hi], &x[hi_end]];
    !apart(ends, shape.reach) && closest_gap(ends[0], ends[1], ends[2], ends[3]).0.norm() < shape.reach
}

/// Whether segments p0p1 and q0q1 (`ends`) are surely farther apart than
/// `reach` on some axis, with a sixteenth to spare for rounding: then the
/// exact distance is beyond it too, and is not computed. Twin of `apart`
/// in `lists.wgsl`.
pub fn apart<T: Real>([p0, p1, q0, q1]: [&V3<T>; 4], reach: T) -> bool {
    let margin = reach * T::of(1.0625);
    (0..3).any(|k| {
        let gap = (q0[k].min(q1[k]) - p0[k].max(p1[k])).max(p0[k].min(p1[k]) - q0[k].max(q1[k]));
        gap > margin
    })
}

/// Every segment's candidates at `x` by the twins, serially: a list per
/// node (empty where no segment starts).
///
/// # Errors
/// [`Overstretched`], as [`find`].
pub fn lists<T: Real>(model: &Model<T>, x: &[V3<T>]) -> Result<Vec<Vec<u32>>, Overstretched> {
    let shape = GridShape::new(model);
    let mut grid = Grid::new(&shape, x.len());
    for i in 0..x.len() {
        insert(&shape, model, x, i, &mut grid);
    }
    let mut lists = vec![Vec::new(); x.len()];
    for (i, list) in lists.iter_mut().enumerate() {
        find(&shape, model, x, i, &grid, list)?;
    }
    Ok(lists)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Params;
    use crate::self_contact::find_pairs;
    use crate::self_contact::tests::crumpled;

    /// The lists are the pairs `find_pairs` finds, seen from both sides,
    /// in f64 and in f32, on a crumpled patch and at rest: the grid, the
    /// cell filter and the sort lose and duplicate nothing.
    #[test]
    fn the_lists_hold_every_pair_in_reach_once_from_both_sides() {
        let params = Params { self_contact_stiffness: 800.0, ..Params::default() };
        for amount in [0.0, 1.8] {
            let (fabric, x) = crumpled::<f64>(amount);
            let model = Model::<f64>::new(&fabric, &params).unwrap();
            let found = lists(&model, &x).unwrap();
            let mut pairs = Vec::new();
            find_pairs(&model, &x, params.self_contact_skin * fabric.yarn_radius(), &mut pairs);
            let mut from_lists: Vec<[u32; 2]> = Vec::new();
            for (i, list) in found.iter().enumerate() {
                assert!(list.windows(2).all(|w| w[0] < w[1]), "segment {i}'s list is sorted, without repeats");
                for &j in list {
                    assert!(found[j as usize].contains(&(i as u32)), "{i} lists {j} but not the other way");
                    if (i as u32) < j {
                        from_lists.push([i as u32, j]);
                    }
                }
            }
            assert_eq!(from_lists, pairs, "amount {amount}");
            assert!(amount == 0.0 || pairs.len() > 100, "{} pairs", pairs.len());
            // f32: the same search; pairs at the skin's edge may round
            // either way, so only those within 2r must agree.
            let model32 = Model::<f32>::new(&fabric, &params).unwrap();
            let (_, x32) = crumpled::<f32>(amount);
            let lists32 = lists(&model32, &x32).unwrap();
            for &[a, b] in &pairs {
                let (a, b) = (a as usize, b as usize);
                let (ea, eb) = (end_of(&model, a).unwrap(), end_of(&model, b).unwrap());
                if closest_gap(&x[a], &x[ea], &x[b], &x[eb]).0.norm() < 2.0 * fabric.yarn_radius() {
                    assert!(lists32[a].contains(&(b as u32)) && lists32[b].contains(&(a as u32)));
                }
            }
        }
    }

    /// A segment stretched long goes into the long list and searches its
    /// box: the lists still hold every pair in reach from both sides; one
    /// stretched past the widest box is refused, not searched.
    #[test]
    fn stretched_segments_are_searched_from_the_long_list_and_their_box() {
        let params = Params { self_contact_stiffness: 800.0, ..Params::default() };
        let (fabric, mut x) = crumpled::<f64>(0.5);
        let model = Model::<f64>::new(&fabric, &params).unwrap();
        let shape = GridShape::new(&model);
        // Three nodes pulled out across the patch, as a grab or a snag does.
        for (node, by) in [(30, 8.0), (31, -6.0), (100, 12.0)] {
            x[node].x += by;
            x[node].z += 0.5 * by;
        }
        let mut grid = Grid::new(&shape, x.len());
        for i in 0..x.len() {
            insert(&shape, &model, &x, i, &mut grid);
        }
        assert!(grid.long.len() >= 4, "{} long segments", grid.long.len());
        let found = lists(&model, &x).unwrap();
        let mut pairs = Vec::new();
        find_pairs(&model, &x, params.self_contact_skin * fabric.yarn_radius(), &mut pairs);
        let from_lists: Vec<[u32; 2]> = found
            .iter()
            .enumerate()
            .flat_map(|(i, list)| list.iter().filter(move |&&j| (i as u32) < j).map(move |&j| [i as u32, j]))
            .collect();
        assert_eq!(from_lists, pairs);
        for (i, list) in found.iter().enumerate() {
            assert!(list.iter().all(|&j| found[j as usize].contains(&(i as u32))));
        }
        x[5].x += shape.cell * f64::from(MAX_BOX) * 2.0;
        assert_eq!(lists(&model, &x), Err(Overstretched));
        assert_eq!(shape.cell_of(&V3::new(f64::NAN, 1e300, -1e300)), [0, 1 << 30, -(1 << 30)]);
    }
}
