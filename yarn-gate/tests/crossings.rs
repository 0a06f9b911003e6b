//! Yarn never passes through yarn: a knitted patch soaked in random grabs
//! keeps the over/under order of every crossing.
//!
//! Two straight segments whose closest points lie inside both of them are
//! joined along their common normal, so the sign of
//! (t_p × t_q) · (c_q − c_p), for segments p and q with directions t and
//! closest points c, says which passes over the other, and it can change
//! only when the gap closes: when one passes through the other. So for any
//! two segments close enough to touch, that sign must not flip from one
//! substep to the next while their closest points stay inside both and
//! they stay far from parallel. Without
//! self-contact the same soak passes yarn through yarn, and the
//! certificate sees it.
//!
//! Beside it, ignored, a measurement of which pairs the self-contact lists
//! hold once a patch has settled.

use yarn_backend_cpu::Rayon;
use yarn_model::self_contact::pairs_within;
use yarn_model::step::segment_end;
use yarn_model::terms::closest_gap;
use yarn_model::{Backend, Model, Params, V3};
use yarn_topology::{Chart, Fabric, Geometry, Pin};

/// The patch's side in stitches, and the substeps of the soak.
const SIDE: usize = 6;
const SUBSTEPS: usize = 4000;
/// Substeps of each grab, and how far it drags its node in that time, in
/// stitch widths: ramped, so no node is flung (with self-contact a node may
/// move at most half a yarn radius a substep).
const GRAB_SUBSTEPS: usize = 200;
const DRAG: f64 = 1.5;
/// Below this |t̂_p × t̂_q| two segments count as parallel, and a sign
/// change says nothing.
const PARALLEL: f64 = 0.2;
/// Pairs closer than this, in yarn radii, are watched.
const WATCHED: f64 = 2.5;

/// The over/under sign of segments p0p1 and q0q1, when their closest
/// points lie inside both and they are far from parallel.
fn crossing(p0: &V3<f64>, p1: &V3<f64>, q0: &V3<f64>, q1: &V3<f64>) -> Option<f64> {
    let (gap, s, t) = closest_gap(p0, p1, q0, q1);
    let normal = (p1 - p0).normalize().cross(&(q1 - q0).normalize());
    let inside = |u: f64| u > 0.0 && u < 1.0;
    (inside(s) && inside(t) && normal.norm() > PARALLEL).then(|| -gap.dot(&normal).signum())
}

/// What a soak saw.
struct Soaked {
    /// Times two close segments changed over/under order between one
    /// substep and the next.
    flips: usize,
    /// The closest two segments that may touch came, in r.
    closest: f64,
}

/// Soak a `SIDE`x`SIDE` patch on `Rayon` with self-contact at `k_sc`, under
/// gravity: `SUBSTEPS / GRAB_SUBSTEPS` times a random node is grabbed and
/// dragged `DRAG` stitch widths in a random direction, ramped over the
/// grab, watching every close pair after every substep.
fn soak(k_sc: f64) -> Soaked {
    let chart = Chart::stockinette(SIDE, SIDE).expect("a chart");
    let fabric = Fabric::from_chart(&chart, &Geometry::default()).expect("a fabric");
    let params = Params { self_contact_stiffness: k_sc, gravity: 9.81, ..Params::default() };
    let mut backend = Rayon::new();
    backend.load(&fabric, &params).expect("load");
    let model = Model::<f64>::new(&fabric, &params).expect("model");
    let r = fabric.yarn_radius();
    let mut seed = 0x5eed_1234_abcd_ef01u64;
    let mut random = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 11) as f64 / (1u64 << 53) as f64
    };
    let (mut flips, mut closest) = (0, f64::INFINITY);
    let (mut pairs, mut previous) = (Vec::new(), Vec::<([u32; 2], f64)>::new());
    for _ in 0..SUBSTEPS / GRAB_SUBSTEPS {
        let node = (random() * fabric.node_count() as f64) as usize % fabric.node_count();
        let direction = V3::new(random() - 0.5, random() - 0.5, random() - 0.5).normalize();
        let from = backend.state().expect("state").positions[node].cast::<f64>();
        let drag = direction * (DRAG * Geometry::default().stitch_width);
        for k in 1..=GRAB_SUBSTEPS {
            let target = from + drag * (k as f64 / GRAB_SUBSTEPS as f64);
            backend.set_pins(&[Pin { node: node as u32, target }]).expect("pins");
            backend.advance(1).expect("no divergence");
            let x: Vec<V3<f64>> = backend.state().expect("state").positions.iter().map(|p| p.cast()).collect();
            pairs_within(&model, &x, WATCHED, &mut pairs);
            let now: Vec<([u32; 2], f64)> = pairs
                .iter()
                .filter_map(|&[a, b]| {
                    let (a, b) = (a as usize, b as usize);
                    let ends = [&x[a], &x[segment_end(&model, a)], &x[b], &x[segment_end(&model, b)]];
                    closest = closest.min(closest_gap(ends[0], ends[1], ends[2], ends[3]).0.norm() / r);
                    Some(([a as u32, b as u32], crossing(ends[0], ends[1], ends[2], ends[3])?))
                })
                .collect();
            // Both lists are sorted by pair.
            let mut old = previous.iter().peekable();
            for (pair, sign) in &now {
                while old.next_if(|(p, _)| p < pair).is_some() {}
                if let Some((_, was)) = old.next_if(|(p, _)| p == pair) {
                    flips += usize::from(was != sign);
                }
            }
            previous = now;
        }
    }
    Soaked { flips, closest }
}

/// Measured: with self-contact no crossing flipped and segments came no
/// closer than 1.794 r; without it 448 flipped, and yarn met yarn (0 r).
#[test]
fn a_soak_of_random_grabs_keeps_every_crossing_and_without_self_contact_does_not() {
    let with = soak(1600.0);
    println!("with self-contact: {} crossings flipped, closest approach {:.3} r", with.flips, with.closest);
    let without = soak(0.0);
    println!("without: {} crossings flipped, closest approach {:.3} r", without.flips, without.closest);
    assert_eq!(with.flips, 0, "yarn passed through yarn with self-contact on");
    // The grabs press hard: the penalty gives a little (1.79 r measured),
    // far from letting yarn through.
    assert!(with.closest > 1.5, "two segments came {} r apart", with.closest);
    assert!(without.flips > 0 && without.closest < 1.0, "the soak never pressed yarn through yarn");
}

/// Who the self-contact lists hold once a patch has settled, and what that
/// costs the GPU's per-segment pair loops: for each side, after 3,000
/// substeps with self-contact at 1,600 (as `yarn-gate bench --settle 3000
/// --self-contact 1600` runs it), the candidate pairs per node, the share
/// of them within 2r (those push) and how the rest spread to 2r + the skin,
/// and per 32-segment warp how busy its lanes are: a warp's loop runs as
/// many times as its fullest segment's (the pushes in `gather.wgsl`; so
/// did friction's before its visits were shared out across the workgroup),
/// over every candidate for the pushes and over the pushing ones for
/// friction. About half a minute:
/// `cargo test --release -p yarn-gate --test crossings -- --ignored --nocapture measure_the_candidates`.
#[test]
#[ignore = "a measurement, printed"]
fn measure_the_candidates() {
    for side in [16, 48] {
        let fabric = Fabric::from_chart(&Chart::stockinette(side, side).unwrap(), &Geometry::default()).unwrap();
        let params = Params { self_contact_stiffness: 1600.0, ..Params::default() };
        let mut backend = Rayon::new();
        backend.load(&fabric, &params).unwrap();
        backend.advance(3000).unwrap();
        let x = backend.state().unwrap().positions;
        let model = Model::<f32>::new(&fabric, &params).unwrap();
        let r = model.contact_rule().radius();
        let lists = yarn_model::self_contact::grid::lists(&model, &x).unwrap();
        let gap = |a: usize, b: usize| {
            let (p0, p1, q0, q1) = (x[a], x[segment_end(&model, a)], x[b], x[segment_end(&model, b)]);
            f64::from(closest_gap(&p0, &p1, &q0, &q1).0.norm()) / r
        };
        let pushing: Vec<usize> = lists
            .iter()
            .enumerate()
            .map(|(a, list)| list.iter().filter(|&&b| gap(a, b as usize) < 2.0).count())
            .collect();
        let entries: usize = lists.iter().map(Vec::len).sum();
        let bins = [2.0, 2.1, 2.25, 2.5 + 1e-9];
        let within: Vec<String> = bins
            .iter()
            .map(|&edge| {
                let n: usize = lists
                    .iter()
                    .enumerate()
                    .map(|(a, list)| list.iter().filter(|&&b| gap(a, b as usize) < edge).count())
                    .sum();
                format!("{:.0} % within {edge:.2} r", 100.0 * n as f64 / entries as f64)
            })
            .collect();
        let busy = |per_segment: &[usize]| {
            let runs: usize = per_segment.chunks(32).map(|warp| warp.iter().max().copied().unwrap_or(0) * 32).sum();
            per_segment.iter().sum::<usize>() as f64 / runs as f64
        };
        let counts: Vec<usize> = lists.iter().map(Vec::len).collect();
        println!(
            "{side}x{side} ({} nodes): {:.2} candidate pairs a node, {}; lanes busy in a warp's loop: \
             pushes {:.0} %, friction {:.0} %",
            x.len(),
            entries as f64 / 2.0 / x.len() as f64,
            within.join(", "),
            100.0 * busy(&counts),
            100.0 * busy(&pushing)
        );
    }
}
