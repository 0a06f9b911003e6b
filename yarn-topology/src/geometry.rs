//! The assembled stitch geometry: which loop shape a chart is knitted in,
//! its gauge, and how many nodes sample each loop.
//!
//! Two shapes exist. [`LoopShape::Interlooped`] is the default: every loop
//! is drawn through the loop below it, after Crane's parametric plain-knit
//! curve (K. Crane, *A Simple Parametric Model of Plain-Knit Yarns*, 2023,
//! <https://www.cs.cmu.edu/~kmcrane/Projects/Other/YarnCurve.pdf>),
//!
//! ```text
//! γ(t) = (t + a sin 2t,  h cos t,  d cos 2t)      (one stitch per 2π of t)
//! ```
//!
//! with the out-of-plane sign set per crossing by the stitch kinds (see
//! [`crate::loops`]). [`LoopShape::Arch`] is the paper's 8-node sin² arch
//! (SPEC §2), kept in the `paper` preset so that its figures reproduce bit
//! for bit.

use crate::TopologyError;

/// Which loop shape a chart is knitted in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum LoopShape {
    /// The paper's arch (SPEC §2): `SEG` = 8 nodes per loop on a sin²
    /// profile, heads tethered to the feet of the loop above by two
    /// contacts. No loop passes through another, and it has no purl.
    Arch,
    /// Loops drawn through the loop below (Crane 2023), knit or purl per
    /// stitch, with a persistent contact at each of the four crossings
    /// between a stitch and the loop below it.
    Interlooped,
}

/// The assembled loop geometry of a chart.
///
/// Coordinates: +x along the course (row), +y up the wale (column), +z
/// toward the technical face (SPEC §7).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Geometry {
    /// The loop shape (default: [`LoopShape::Interlooped`]).
    pub shape: LoopShape,
    /// Stitch width w_s along the course: the wale spacing (default: 7.32;
    /// Crane's 2π scaled so the yarn radius is 0.9).
    pub stitch_width: f64,
    /// Stitch height h_s up the wale: the course spacing (default: 5.83;
    /// Crane's h + 1 scaled, see [`Geometry::default`]).
    pub stitch_height: f64,
    /// Height of one loop from its sinker to its head, 2h in Crane's curve;
    /// it exceeds the stitch height so each head reaches into the row above
    /// (default: 9.33).
    pub loop_height: f64,
    /// Out-of-plane amplitude d: how far legs, heads and sinkers lie from
    /// the mid-plane (default: 1.75). Larger values make a thicker fabric.
    pub depth: f64,
    /// Loop roundness a of Crane's curve: how far the head overhangs the
    /// neck; unused by the arch (default: 1.5). Above 0.5 the head is wider
    /// than the neck.
    pub roundness: f64,
    /// Yarn radius r; contacts rest no closer than 2r (default: 0.9).
    pub yarn_radius: f64,
    /// Nodes sampling each loop: exactly 8 for the arch; even and at least
    /// 10 for interlooped loops, whose four crossings with the loop below,
    /// four with the loop above, head and sinker are nodes by construction
    /// (default: 24; see [`Geometry::default`] for the measurement).
    pub nodes_per_loop: usize,
}

impl Default for Geometry {
    /// Interlooped loops in Crane's shape (a = 3/2, h = 4, d = 3/2, rows
    /// h + 1 apart, one stitch per 2π), scaled by 1.1656 so that the yarn
    /// radius is 0.9, the paper's.
    ///
    /// - **Yarn radius.** The closest approach of two strands in Crane's
    ///   shape is the neck of each loop, where its two legs pass 2 × 0.7721
    ///   apart; the yarn radius is that half-gap, so the assembled yarn is
    ///   snug and does not interpenetrate (0.7721 × 1.1656 = 0.9).
    /// - **Depth and course spacing.** Crane's own d = 1, rows h + 1/2 apart,
    ///   leave the strands of adjacent rows 0.80 of a yarn diameter apart
    ///   (tubes that overlap); d = 3/2 and rows h + 1 apart clear them.
    /// - **Knit practice.** One loop is ℓ = 31.05 long, ℓ/d_yarn = 17.3.
    ///   Munden's constants come out as k_w = ℓ/w_s = 4.24, k_c = ℓ/h_s =
    ///   5.33 and k_s = k_c k_w = 22.6, against about 3.8–4.2, 5.0–5.5 and
    ///   19–23 reported from dry- to fully relaxed plain knit (Munden 1959;
    ///   Knapton et al. 1968): the shape is a relaxed plain knit, not tuned
    ///   to any gate figure.
    /// - **Nodes per loop.** 24, the knee of the sampling error: going from
    ///   16 to 24 nodes shrinks the largest gap between a chord and the
    ///   curve from 0.30 r to 0.084 r and lifts the assembled clearance from
    ///   0.86 to 0.96 of 2r, while 32 improves them only to 0.078 r and
    ///   0.96 for a third more nodes. The gate's figures do not converge in
    ///   n (see `docs/patterns.md`), so they cannot choose it.
    fn default() -> Self {
        Self {
            shape: LoopShape::Interlooped,
            stitch_width: 7.32,
            stitch_height: 5.83,
            loop_height: 9.33,
            depth: 1.75,
            roundness: 1.5,
            yarn_radius: 0.9,
            nodes_per_loop: 24,
        }
    }
}

impl Geometry {
    /// The `paper` preset: the paper's Table 1 gauge and its 8-node arch
    /// (SPEC §1–2). It keeps reproducing the paper's figures.
    pub fn paper() -> Self {
        Self {
            shape: LoopShape::Arch,
            stitch_width: 5.0,
            stitch_height: 4.2,
            loop_height: 4.8,
            depth: 1.6,
            roundness: 0.0,
            yarn_radius: 0.9,
            nodes_per_loop: crate::SEG,
        }
    }

    pub(crate) fn validate(&self) -> Result<(), TopologyError> {
        for (name, value) in [
            ("stitch_width", self.stitch_width),
            ("stitch_height", self.stitch_height),
            ("loop_height", self.loop_height),
            ("depth", self.depth),
            ("yarn_radius", self.yarn_radius),
        ] {
            if !(value.is_finite() && value > 0.0) {
                return Err(TopologyError::BadGeometry { name, value });
            }
        }
        if !(self.roundness.is_finite() && self.roundness >= 0.0) {
            return Err(TopologyError::BadGeometry { name: "roundness", value: self.roundness });
        }
        let n = self.nodes_per_loop;
        let ok = match self.shape {
            LoopShape::Arch => n == crate::SEG,
            LoopShape::Interlooped => n >= crate::loops::MIN_NODES_PER_LOOP && n.is_multiple_of(2),
        };
        if !ok {
            return Err(TopologyError::BadNodesPerLoop { shape: self.shape, got: n });
        }
        Ok(())
    }
}
