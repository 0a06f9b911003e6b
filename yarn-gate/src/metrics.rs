//! The behavioural metrics of SPEC §6, as plain functions over a backend
//! and its states: the relaxation with its energy trace, edge curl, and
//! directional stiffness.

use nalgebra::{Matrix3, Vector3};
use serde::Serialize;
use yarn_model::statics::{self, StaticOptions};
use yarn_model::{Backend, BackendError, Model, State, step, widen};
use yarn_topology::{Fabric, Pin, Side};

/// One sample of a relaxation.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Sample {
    /// Substeps taken when sampled.
    pub substep: u64,
    /// Total energy (potential + kinetic).
    pub total: f64,
    /// Bending energy.
    pub bend: f64,
    /// Largest node speed.
    pub max_speed: f64,
}

/// The record of a free relaxation.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Relaxation {
    /// Samples at regular intervals, first at substep 0, last at the end.
    pub trace: Vec<Sample>,
    /// The largest max-speed seen in any sample.
    pub peak_speed: f64,
}

impl Relaxation {
    /// The first sample.
    pub fn initial(&self) -> &Sample {
        &self.trace[0]
    }

    /// The last sample.
    pub fn last(&self) -> &Sample {
        &self.trace[self.trace.len() - 1]
    }
}

/// Advance `backend`, loaded with `fabric`, by `steps` substeps, sampling
/// energy ([`Backend::measure`]) and speed `samples` times along the way
/// (plus once at the start). `progress` is called with the substeps done
/// so far.
///
/// # Errors
/// Whatever the backend reports.
pub fn relax<B: Backend>(
    backend: &mut B,
    fabric: &Fabric,
    steps: u64,
    samples: u64,
    mut progress: impl FnMut(u64),
) -> Result<Relaxation, BackendError> {
    let samples = samples.clamp(1, steps.max(1));
    let mut trace = Vec::with_capacity(samples as usize + 1);
    let mut record = |backend: &mut B, substep: u64| -> Result<(), BackendError> {
        let (energy, state) = backend.measure(fabric)?;
        trace.push(Sample { substep, total: energy.total(), bend: energy.bend, max_speed: state.max_speed() });
        Ok(())
    };
    record(backend, 0)?;
    let mut done = 0;
    for k in 1..=samples {
        let target = steps * k / samples;
        backend.advance(target - done)?;
        done = target;
        record(backend, done)?;
        progress(done);
    }
    let peak_speed = trace.iter().map(|s| s.max_speed).fold(0.0, f64::max);
    Ok(Relaxation { trace, peak_speed })
}

/// Mean signed distance of each edge family from the interior mid-plane, in
/// yarn radii (SPEC §6 "Curl").
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Curl {
    /// Course edges (top and bottom rows).
    pub course: f64,
    /// Wale edges (left and right columns).
    pub wale: f64,
}

impl Curl {
    /// |course| + |wale|: the figure the gate thresholds.
    pub fn total(&self) -> f64 {
        self.course.abs() + self.wale.abs()
    }
}

/// Fit a plane to the interior nodes, orient its normal toward the technical
/// face (course × wale), and average the signed distance of each edge
/// family's nodes, divided by the yarn radius. `None` when the fabric has no
/// interior nodes or no nodes on an edge family (a strip one stitch wide).
pub fn curl(fabric: &Fabric, positions: &[Vector3<f64>]) -> Option<Curl> {
    let boundary = fabric.boundary();
    let interior: Vec<_> = positions.iter().zip(boundary).filter(|(_, b)| b.is_interior()).map(|(p, _)| *p).collect();
    if interior.len() < 3 {
        return None;
    }
    let centroid = interior.iter().sum::<Vector3<f64>>() / interior.len() as f64;
    let covariance = interior.iter().map(|p| (p - centroid) * (p - centroid).transpose()).sum::<Matrix3<f64>>();
    let eigen = covariance.symmetric_eigen();
    let smallest = eigen.eigenvalues.imin();
    let mut normal: Vector3<f64> = eigen.eigenvectors.column(smallest).into_owned();
    if normal.dot(&fabric.course().cross(&fabric.wale())) < 0.0 {
        normal = -normal;
    }
    let family = |on: fn(&yarn_topology::Boundary) -> bool| {
        let distances: Vec<f64> =
            positions.iter().zip(boundary).filter(|(_, b)| on(b)).map(|(p, _)| (p - centroid).dot(&normal)).collect();
        (!distances.is_empty()).then(|| distances.iter().sum::<f64>() / distances.len() as f64 / fabric.yarn_radius())
    };
    Some(Curl { course: family(|b| b.on_course_edge())?, wale: family(|b| b.on_wale_edge())? })
}

/// [`curl`] at `positions` less [`curl`] as assembled: how far each edge
/// family has moved out of the mid-plane since knitting, in yarn radii.
/// The paper's arch reads zero as assembled, so for it this is `curl`;
/// interlooped loops read −0.01 r (course) and −0.16 r (wale) as assembled,
/// because a row's far sinker and the turns between rows lie at the
/// sinkers' depth, behind the loops' mean.
pub fn curl_since_assembly(fabric: &Fabric, positions: &[Vector3<f64>]) -> Option<Curl> {
    let (now, assembled) = (curl(fabric, positions)?, curl(fabric, fabric.positions())?);
    Some(Curl { course: now.course - assembled.course, wale: now.wale - assembled.wale })
}

/// The resting size of a patch generated from a chart, measured so that a
/// curled edge does not shrink it: the arc length of the line through the
/// stitch centres of the middle row (width) and of the middle column
/// (height), from the first stitch's centre to the last's. A stitch's
/// centre is the mean of its loop's own nodes (phases 1 to
/// `nodes_per_loop − 1`, which every row has). At assembly these are (W − 1) and (H − 1) stitch
/// pitches.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Extent {
    /// Arc length along the middle row, in model units.
    pub width: f64,
    /// Arc length up the middle column, in model units.
    pub height: f64,
}

/// The [`Extent`] of `fabric` at `positions`; `None` for a fabric not
/// generated from a chart, or one stitch wide or high.
pub fn extent(fabric: &Fabric, positions: &[Vector3<f64>]) -> Option<Extent> {
    let (w, h) = fabric.grid()?;
    if w < 2 || h < 2 {
        return None;
    }
    let per_loop = fabric.nodes_per_loop()?;
    let centre = |column: usize, row: usize| -> Option<Vector3<f64>> {
        let nodes: Option<Vec<usize>> = (1..per_loop).map(|p| fabric.stitch_node(column, row, p)).collect();
        let nodes = nodes?;
        Some(nodes.iter().map(|&i| positions[i]).sum::<Vector3<f64>>() / nodes.len() as f64)
    };
    let arc = |points: Option<Vec<Vector3<f64>>>| -> Option<f64> {
        Some(points?.windows(2).map(|p| (p[1] - p[0]).norm()).sum())
    };
    Some(Extent {
        width: arc((0..w).map(|column| centre(column, h / 2)).collect())?,
        height: arc((0..h).map(|row| centre(w / 2, row)).collect())?,
    })
}

/// The rigid motion (rotation, then translation) that best maps the
/// assembled interior of `fabric` onto its interior at `positions`, in the
/// least-squares sense (Kabsch): the frame a relaxed patch sits in.
fn interior_frame(fabric: &Fabric, positions: &[Vector3<f64>]) -> (Matrix3<f64>, Vector3<f64>) {
    let pairs: Vec<(Vector3<f64>, Vector3<f64>)> = fabric
        .positions()
        .iter()
        .zip(positions)
        .zip(fabric.boundary())
        .filter(|(_, b)| b.is_interior())
        .map(|((a, p), _)| (*a, *p))
        .collect();
    rigid_fit(&pairs)
}

/// The rigid motion (rotation, then translation) that best maps each
/// pair's first point onto its second, in the least-squares sense
/// (Kabsch).
pub(crate) fn rigid_fit(pairs: &[(Vector3<f64>, Vector3<f64>)]) -> (Matrix3<f64>, Vector3<f64>) {
    let count = pairs.len().max(1) as f64;
    let (from, to) = pairs.iter().fold((Vector3::zeros(), Vector3::zeros()), |(f, t), (a, p)| (f + a, t + p));
    let (from, to) = (from / count, to / count);
    let covariance = pairs.iter().map(|(a, p)| (p - to) * (a - from).transpose()).sum::<Matrix3<f64>>();
    let svd = covariance.svd(true, true);
    let (u, v_t) = (svd.u.expect("asked for U"), svd.v_t.expect("asked for V^T"));
    // A reflection is not a rigid motion: flip the least axis if needed.
    let sign = (u * v_t).determinant().signum();
    let rotation = u * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, sign)) * v_t;
    (rotation, to - rotation * from)
}

/// The grips of a stiffness hold along `axis` that clamp each gripped edge
/// straight: each edge's nodes held in their assembled (flat) layout,
/// carried rigidly into the frame the patch at `positions` sits in
/// (a least-squares rigid fit of the interior), with the far grip moved along the axis until the
/// grips' centroids are `separation` apart.
pub fn straight_grips(fabric: &Fabric, positions: &[Vector3<f64>], axis: Axis, separation: f64) -> Vec<Pin> {
    let (near, far) = axis.grips();
    let (near_nodes, far_nodes) = (fabric.side_nodes(near), fabric.side_nodes(far));
    let assembled = fabric.positions();
    let direction = axis.direction(fabric);
    let mean = |nodes: &[u32]| nodes.iter().map(|&i| assembled[i as usize]).sum::<Vector3<f64>>() / nodes.len() as f64;
    let shift = direction * (separation - (mean(&far_nodes) - mean(&near_nodes)).dot(&direction));
    let (rotation, translation) = interior_frame(fabric, positions);
    let place = |node: u32, offset: Vector3<f64>| Pin {
        node,
        target: rotation * (assembled[node as usize] + offset) + translation,
    };
    near_nodes.iter().map(|&n| place(n, Vector3::zeros())).chain(far_nodes.iter().map(|&n| place(n, shift))).collect()
}

/// A clear start for the hold whose grips are
/// [`straight_grips`]`(fabric, positions, axis, separation)`: the assembled
/// patch stretched affinely along `axis` about its near grip until the
/// grips' centroids are `separation` apart, carried rigidly into the frame
/// the patch at `positions` sits in, at rest. Its grips sit at their
/// targets up to the stretch across each grip's own depth. Starting from
/// the patch at `positions` instead would carry a rolled edge straight
/// through the fabric it has rolled over.
pub fn flat_between_grips(fabric: &Fabric, positions: &[Vector3<f64>], axis: Axis, separation: f64) -> State<f64> {
    let assembled = State::at_rest(fabric);
    let strain = separation / assembled_separation(fabric, axis) - 1.0;
    let mut flat = stretched(&assembled, &fabric.side_nodes(axis.grips().0), axis.direction(fabric), strain);
    let (rotation, translation) = interior_frame(fabric, positions);
    flat.positions.iter_mut().for_each(|p| *p = rotation * *p + translation);
    flat
}

/// How far apart the centroids of the grips along `axis` are, along it, in
/// the assembled patch.
pub fn assembled_separation(fabric: &Fabric, axis: Axis) -> f64 {
    let (near, far) = axis.grips();
    let (assembled, direction) = (fabric.positions(), axis.direction(fabric));
    let along = |side| {
        let nodes = fabric.side_nodes(side);
        nodes.iter().map(|&i| assembled[i as usize].dot(&direction)).sum::<f64>() / nodes.len() as f64
    };
    along(far) - along(near)
}

/// The direction of `axis` in the frame the patch at `positions` sits in.
pub fn axis_in_frame(fabric: &Fabric, positions: &[Vector3<f64>], axis: Axis) -> Vector3<f64> {
    interior_frame(fabric, positions).0 * axis.direction(fabric)
}

/// A fabric axis to pull along.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Axis {
    /// Along a row: grip the left and right columns.
    Course,
    /// Up a column: grip the bottom and top rows.
    Wale,
}

impl Axis {
    /// The two sides gripped: (near, far).
    pub fn grips(self) -> (Side, Side) {
        match self {
            Axis::Course => (Side::Left, Side::Right),
            Axis::Wale => (Side::Bottom, Side::Top),
        }
    }

    /// The fabric's direction along this axis, as assembled.
    pub fn direction(self, fabric: &Fabric) -> Vector3<f64> {
        match self {
            Axis::Course => fabric.course(),
            Axis::Wale => fabric.wale(),
        }
    }
}

/// The outcome of one stiffness probe.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Stiffness {
    /// The axis pulled.
    pub axis: Axis,
    /// Engineering strain applied between the grips.
    pub strain: f64,
    /// |ΔF|: the change, from the unstrained hold to the strained hold, of
    /// the total internal force on the far grip (right or top).
    pub force: f64,
    /// |ΣF| on the far grip in the unstrained hold: the pre-stress the
    /// relaxed patch still carries, which the strain's force is measured
    /// from.
    pub baseline: f64,
    /// force / strain.
    pub stiffness: f64,
    /// Largest node speed at the end of the strained hold: how close to
    /// equilibrium the reading is.
    pub residual_speed: f64,
}

/// Directional stiffness along `axis` (SPEC §6 "Anisotropy").
///
/// Grip the two edges across `axis` by pinning their nodes, stretch the
/// relaxed patch affinely to `strain` along the axis, hold for `steps`
/// substeps, and read the total internal force on the far grip. The same
/// hold at zero strain gives the baseline: a free relaxation of finite
/// length leaves some pre-stress and creep in the patch, and subtracting it
/// makes the reading the force *caused by the strain*. At a true equilibrium
/// the baseline is zero and this is SPEC §6's |F| / strain exactly.
///
/// The backend is left holding the strained state and its pins.
///
/// # Errors
/// Whatever the backend reports.
pub fn stiffness<B: Backend>(
    backend: &mut B,
    fabric: &Fabric,
    relaxed: &State<f64>,
    axis: Axis,
    strain: f64,
    steps: u64,
    mut progress: impl FnMut(u64),
) -> Result<Stiffness, BackendError> {
    let mut offset = 0;
    probe(fabric, relaxed, axis, strain, |pins, pulled| {
        backend.set_pins(pins)?;
        backend.write_state(&pulled.cast())?;
        advance_in_chunks(backend, steps, |done| progress(offset + done))?;
        offset += steps;
        let forces = backend.forces()?.iter().map(widen).collect();
        Ok((forces, backend.state()?.max_speed()))
    })
}

/// [`stiffness`] with each hold brought to rest by a quasi-static solve
/// ([`yarn_model::statics`]) on `model` (its pins are replaced by the
/// grips'): the readings of an equilibrium, with no baseline left but the
/// solve's residual. Friction plays no part.
pub fn static_stiffness(
    model: &Model<f64>,
    fabric: &Fabric,
    relaxed: &State<f64>,
    axis: Axis,
    strain: f64,
    options: &StaticOptions,
) -> Result<Stiffness, BackendError> {
    let mut model = model.clone();
    probe(fabric, relaxed, axis, strain, |pins, pulled| {
        model.set_pins(pins)?;
        let mut state = pulled.clone();
        statics::solve(&model, &mut state, options);
        let mut forces = Vec::new();
        step::accumulate_forces(&model, &state.positions, &mut forces);
        Ok((forces, 0.0))
    })
}

/// The probe both kinds of hold share: grip, pull, `hold` (given the grips'
/// pins and the pulled state, the force on every node at rest and the
/// largest speed left), read the far grip, at zero strain and at `strain`.
fn probe(
    fabric: &Fabric,
    relaxed: &State<f64>,
    axis: Axis,
    strain: f64,
    mut settle: impl FnMut(&[Pin], &State<f64>) -> Result<(Vec<Vector3<f64>>, f64), BackendError>,
) -> Result<Stiffness, BackendError> {
    let (near, far) = axis.grips();
    let (near_nodes, far_nodes) = (fabric.side_nodes(near), fabric.side_nodes(far));
    let direction = axis.direction(fabric);
    // Stretch about the near grip's mean position, so the grips move apart
    // by `strain` times their separation.
    let mut hold = |strain: f64| -> Result<(Vector3<f64>, f64), BackendError> {
        let pulled = stretched(relaxed, &near_nodes, direction, strain);
        let pins: Vec<Pin> = near_nodes
            .iter()
            .chain(&far_nodes)
            .map(|&node| Pin { node, target: pulled.positions[node as usize] })
            .collect();
        let (forces, speed) = settle(&pins, &pulled)?;
        Ok((far_nodes.iter().map(|&i| forces[i as usize]).sum(), speed))
    };
    let (unstrained, _) = hold(0.0)?;
    let (strained, residual_speed) = hold(strain)?;
    let force = (strained - unstrained).norm();
    Ok(Stiffness { axis, strain, force, baseline: unstrained.norm(), stiffness: force / strain, residual_speed })
}

/// `state` stretched affinely by `strain` along `direction` about the mean
/// position of the nodes `near` along it, at rest: a grip's pull, with no
/// node left far from where the pull will leave it.
pub fn stretched(state: &State<f64>, near: &[u32], direction: Vector3<f64>, strain: f64) -> State<f64> {
    let origin = near.iter().map(|&i| state.positions[i as usize].dot(&direction)).sum::<f64>() / near.len() as f64;
    State {
        positions: state.positions.iter().map(|p| p + direction * (strain * (p.dot(&direction) - origin))).collect(),
        velocities: vec![Vector3::zeros(); state.len()],
    }
}

/// Advance by `steps` in a few chunks, reporting progress after each.
fn advance_in_chunks<B: Backend>(
    backend: &mut B,
    steps: u64,
    mut progress: impl FnMut(u64),
) -> Result<(), BackendError> {
    const CHUNKS: u64 = 20;
    let mut done = 0;
    for k in 1..=CHUNKS {
        let target = steps * k / CHUNKS;
        backend.advance(target - done)?;
        done = target;
        progress(done);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use yarn_topology::{Chart, Geometry};

    /// A hold's flat start is the assembled patch in the frame of the
    /// patch's interior, however far its edges rolled: unstretched at the
    /// assembled separation, and otherwise stretched so that its grips'
    /// centroids are the separation apart, each grip node within the
    /// stretch across its grip's depth of its target.
    #[test]
    fn a_hold_starts_flat_between_its_grips_however_far_the_edges_rolled() {
        let fabric = Fabric::from_chart(&Chart::stockinette(6, 6).unwrap(), &Geometry::default()).unwrap();
        let rotation = nalgebra::Rotation3::from_axis_angle(&Vector3::z_axis(), 0.3);
        let shift = Vector3::new(1.0, -2.0, 0.5);
        let moved: Vec<_> = fabric.positions().iter().map(|p| rotation * p + shift).collect();
        let lift = rotation * Vector3::z() * (4.0 * fabric.yarn_radius());
        let rolled: Vec<_> =
            moved.iter().zip(fabric.boundary()).map(|(p, b)| if b.is_interior() { *p } else { p + lift }).collect();
        let gap =
            |a: &[Vector3<f64>], b: &[Vector3<f64>]| a.iter().zip(b).map(|(a, b)| (a - b).norm()).fold(0.0, f64::max);
        for axis in [Axis::Course, Axis::Wale] {
            let (near, far) = (fabric.side_nodes(axis.grips().0), fabric.side_nodes(axis.grips().1));
            let direction = axis.direction(&fabric);
            let along = |x: &[Vector3<f64>], nodes: &[u32]| {
                nodes.iter().map(|&i| x[i as usize].dot(&(rotation * direction))).sum::<f64>() / nodes.len() as f64
            };
            let assembled = along(&moved, &far) - along(&moved, &near);
            let flat = flat_between_grips(&fabric, &rolled, axis, assembled);
            assert!(gap(&flat.positions, &moved) < 1e-9, "{axis:?}: not the assembled patch in its frame");
            assert!(flat.velocities.iter().all(|v| *v == Vector3::zeros()));

            let separation = 1.3 * assembled;
            let flat = flat_between_grips(&fabric, &rolled, axis, separation);
            assert!((along(&flat.positions, &far) - along(&flat.positions, &near) - separation).abs() < 1e-9);
            let depth = far.iter().map(|&i| fabric.positions()[i as usize].dot(&direction));
            let depth = depth.clone().fold(f64::MIN, f64::max) - depth.fold(f64::MAX, f64::min);
            let off = straight_grips(&fabric, &rolled, axis, separation)
                .iter()
                .map(|pin| (flat.positions[pin.node as usize] - pin.target).norm())
                .fold(0.0, f64::max);
            assert!(
                off <= 0.3 * depth + 1e-9 && off > 0.0,
                "{axis:?}: a grip node {off} from its target (depth {depth})"
            );
        }
    }

    #[test]
    fn a_flat_patch_reads_zero_curl_and_a_rolled_one_does_not() {
        // The arch's edge stitches are its interior's, so it reads zero as
        // assembled. (Interlooped loops read a little: their turns between
        // rows lie at the sinkers' depth; see the next test.)
        let fabric = Fabric::from_chart(&Chart::stockinette(6, 6).unwrap(), &Geometry::paper()).unwrap();
        let flat: Vec<_> = fabric.positions().to_vec();
        let c = curl(&fabric, &flat).unwrap();
        assert!(c.total() < 1e-9, "assembled patch reads {c:?}");
        // Lift the course edges toward the face by one radius: course reads
        // +1, and the wale edges (which share the corner stitches) less.
        let lifted: Vec<_> = flat
            .iter()
            .zip(fabric.boundary())
            .map(|(p, b)| if b.on_course_edge() { p + Vector3::z() * fabric.yarn_radius() } else { *p })
            .collect();
        let c = curl(&fabric, &lifted).unwrap();
        // The fitted mid-plane tilts slightly with the loops, so the lift
        // reads as a little less than one radius along its normal.
        assert!((c.course - 1.0).abs() < 1e-2, "{c:?}");
        assert!(c.wale > 0.0 && c.wale < 1.0, "{c:?}");
    }

    #[test]
    fn interlooped_loops_read_their_assembly_bias_and_zero_since_assembly() {
        let fabric = Fabric::from_chart(&Chart::stockinette(6, 6).unwrap(), &Geometry::default()).unwrap();
        let assembled = curl(&fabric, fabric.positions()).unwrap();
        assert!((assembled.course + 0.01).abs() < 0.01 && (assembled.wale + 0.16).abs() < 0.02, "{assembled:?}");
        let since = curl_since_assembly(&fabric, fabric.positions()).unwrap();
        assert_eq!((since.course, since.wale), (0.0, 0.0));
        let lifted: Vec<_> = fabric
            .positions()
            .iter()
            .zip(fabric.boundary())
            .map(|(p, b)| if b.on_course_edge() { p + Vector3::z() * fabric.yarn_radius() } else { *p })
            .collect();
        let c = curl_since_assembly(&fabric, &lifted).unwrap();
        assert!((c.course - 1.0).abs() < 2e-2, "{c:?}");
    }

    #[test]
    fn strips_without_interior_have_no_curl() {
        let fabric = Fabric::from_chart(&Chart::stockinette(2, 8).unwrap(), &Geometry::default()).unwrap();
        assert!(curl(&fabric, fabric.positions()).is_none());
    }
}
