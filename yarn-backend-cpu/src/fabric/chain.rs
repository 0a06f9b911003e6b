//! Where the yarns break: the nodes whose chain force (gravity, segments
//! and joints) the block pass's contiguous loops get wrong, and that force
//! computed node by node from the nodes' links instead.
//!
//! The block pass takes node i's neighbours along the yarn to be i − 1 and
//! i + 1, which holds everywhere in a fabric of one open yarn (its two ends
//! are the ends of the arrays, where the loops already stop). Where one
//! yarn ends and the next begins, and where a closed yarn's last node joins
//! its first, it does not: the two nodes on each side of the break (whose
//! segments or joints reach across it) are recomputed by
//! [`CpuFabric::chain_force`], which follows the links.
//!
//! `chain_force` is the CPU twin of `node_force.wgsl` in
//! `yarn-backend-wgpu`: each node's own segments and joints found through
//! its links, the elements it shares with its neighbours recomputed, summed
//! in the block pass's order, so that on a node where both apply it equals
//! the block pass bit for bit, and the GPU's gather equals both. This
//! module owns the break list and that force; it does not run passes.

use yarn_model::terms::{MIN_SIN_THETA, gravity_force};
use yarn_model::{Model, Real, V3};

use super::CpuFabric;

/// The nodes, ascending, that [`CpuFabric::chain_force`] must compute: the
/// first two and last two nodes of every yarn that meets another yarn at
/// that end or wraps around (clipped to the yarn). Empty for a fabric of
/// one open yarn.
pub(crate) fn breaks<T: Real>(model: &Model<T>) -> Vec<u32> {
    let n = model.node_count();
    let mut nodes = Vec::new();
    for yarn in model.yarns() {
        let (first, last) = (yarn.start as usize, yarn.end as usize - 1);
        if yarn.closed || first > 0 {
            nodes.extend([first, first + 1].into_iter().filter(|&i| i <= last));
        }
        if yarn.closed || last + 1 < n {
            nodes.extend([last.wrapping_sub(1), last].into_iter().filter(|&i| (first..=last).contains(&i)));
        }
    }
    nodes.sort_unstable();
    nodes.dedup();
    nodes.into_iter().map(|i| i as u32).collect()
}

/// A segment as the block pass's `segments` computes it: the stretch force
/// on its first node, its unit tangent and its inverse length, all zero
/// where no segment leaves the node.
#[derive(Debug, Clone, Copy)]
struct Segment<T> {
    force: V3<T>,
    tangent: V3<T>,
    inv_length: T,
}

impl<T: Real> CpuFabric<T> {
    /// The breaks among nodes `lo..hi`.
    pub(crate) fn breaks_in(&self, lo: usize, hi: usize) -> &[u32] {
        let from = self.breaks.partition_point(|&i| (i as usize) < lo);
        let to = self.breaks.partition_point(|&i| (i as usize) < hi);
        &self.breaks[from..to]
    }

    /// Node i's gravity plus the forces of its own segments and joints,
    /// found through its links: + the segment leaving it, − the segment
    /// entering it, + the first-node force of the joint after it, − both
    /// end forces of its own joint, + the last-node force of the joint
    /// before it, in that order (the block pass's and `node_force.wgsl`'s).
    pub(crate) fn chain_force(&self, i: usize) -> V3<T> {
        let links = self.model.links();
        let at = |node: Option<u32>| node.map(|node| node as usize);
        let (prev, next) = (at(links[i].prev()), at(links[i].next()));
        let before_prev = prev.and_then(|p| at(links[p].prev()));
        let (s_pp, s_p, s_i, s_n) =
            (self.segment(before_prev), self.segment(prev), self.segment(Some(i)), self.segment(next));
        let j_p = self.joint(prev, &s_pp, &s_p);
        let j_i = self.joint(Some(i), &s_p, &s_i);
        let j_n = self.joint(next, &s_i, &s_n);
        let c = self.model.coeffs();
        gravity_force(c.mass, c.gravity) + s_i.force - s_p.force + j_n[0] - (j_i[0] + j_i[1]) + j_p[1]
    }

    /// The segment leaving node `from`, by the operations of the block
    /// pass's `segments`.
    fn segment(&self, from: Option<usize>) -> Segment<T> {
        let (zero, one) = (T::zero(), T::one());
        let none = Segment { force: V3::zeros(), tangent: V3::zeros(), inv_length: zero };
        let Some(a) = from else { return none };
        let Some(b) = self.model.links()[a].next().map(|b| b as usize) else { return none };
        let x = &self.positions;
        let (dx, dy, dz) = (x.x[b] - x.x[a], x.y[b] - x.y[a], x.z[b] - x.z[a]);
        let len = (dx * dx + dy * dy + dz * dz).sqrt();
        let (divisor, keep) = if len > zero { (len, one) } else { (one, zero) };
        let scale = self.model.coeffs().stretch * (len - self.model.segment_rest()[a]) / divisor * keep;
        let inv = one / divisor * keep;
        Segment {
            force: V3::new(dx * scale, dy * scale, dz * scale),
            tangent: V3::new(dx * inv, dy * inv, dz * inv),
            inv_length: inv,
        }
    }

    /// The forces `[f_a, f_c]` on the first and last node of the joint
    /// centred on `centre`, from its segments in and out, by the operations
    /// of the block pass's `joints`; zero where it has no joint.
    fn joint(&self, centre: Option<usize>, s0: &Segment<T>, s1: &Segment<T>) -> [V3<T>; 2] {
        let Some(b) = centre.filter(|&b| {
            let link = self.model.links()[b];
            link.prev().is_some() && link.next().is_some()
        }) else {
            return [V3::zeros(); 2];
        };
        let (zero, one, min_sin) = (T::zero(), T::one(), T::of(MIN_SIN_THETA));
        let (u, v) = (s0.tangent, s1.tangent);
        let s = (u[0] * v[0] + u[1] * v[1] + u[2] * v[2]).clamp(-one, one);
        let sin_theta = (one - s * s).sqrt();
        let (inv_l0, inv_l1) = (s0.inv_length, s1.inv_length);
        let (divisor, keep) =
            if sin_theta >= min_sin && inv_l0 > zero && inv_l1 > zero { (sin_theta, one) } else { (one, zero) };
        let coeff = self.model.coeffs().bend * (s.turning_angle() - self.target[b]) / divisor * keep;
        let (ca, cc) = (-coeff * inv_l0, coeff * inv_l1);
        [
            V3::new((v[0] - u[0] * s) * ca, (v[1] - u[1] * s) * ca, (v[2] - u[2] * s) * ca),
            V3::new((u[0] - v[0] * s) * cc, (u[1] - v[1] * s) * cc, (u[2] - v[2] * s) * cc),
        ]
    }
}
