//! `yarn-gate bench`: cost per node per substep of each backend over square
//! patches, as the median of repeated timed runs after a warm-up.

use std::time::Instant;

use serde::Serialize;
use yarn_model::{Backend, BackendError, Params};
use yarn_topology::{Chart, Fabric, Geometry, Pin, Side};

use crate::GateError;

/// How the benchmark runs.
#[derive(Debug, Clone, PartialEq)]
pub struct BenchConfig {
    /// Patch sides in stitches; each patch is side × side.
    pub sides: Vec<usize>,
    /// Timed runs per row; the median is reported.
    pub repeats: usize,
    /// Node-substeps per timed run; the substep count follows from the
    /// patch size, so every run does about the same work.
    pub work_per_run: u64,
    /// The model and solver parameters of the scene (friction and gravity
    /// among them).
    pub params: Params,
    /// Hold the top row in place, as a drape does.
    pub pin_top: bool,
    /// The fraction of contacts released, the last in yarn order first (the
    /// top rows, as after unravelling).
    pub dead: f64,
    /// Substeps run before timing, to let the fabric settle (the warm-up
    /// is a quarter of a run otherwise).
    pub settle: u64,
}

impl Default for BenchConfig {
    /// 8×8 to 64×64 stitches (512 to 32,768 nodes), 7 runs of about 20
    /// million node-substeps each.
    fn default() -> Self {
        Self {
            sides: vec![8, 16, 32, 64],
            repeats: 7,
            work_per_run: 20_000_000,
            params: Params::default(),
            pin_top: false,
            dead: 0.0,
            settle: 0,
        }
    }
}

/// One measured row.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BenchRow {
    /// Backend name.
    pub backend: String,
    /// Threads the backend ran on.
    pub threads: usize,
    /// Patch size, `WxH` stitches.
    pub size: String,
    /// Node count.
    pub nodes: usize,
    /// Contact count.
    pub contacts: usize,
    /// Substeps per timed run.
    pub substeps: u64,
    /// Friction coefficient μ of the scene.
    pub friction: f64,
    /// Gravity of the scene.
    pub gravity: f64,
    /// Pinned nodes.
    pub pins: usize,
    /// Released contacts.
    pub dead_contacts: usize,
    /// The sleep speed (0: sleeping off).
    pub sleep_speed: f64,
    /// Median nanoseconds per node per substep.
    pub ns_per_node_substep: f64,
    /// Fastest and slowest run, same unit: the spread of the repeats.
    pub ns_min: f64,
    /// See `ns_min`.
    pub ns_max: f64,
    /// Median substeps per second.
    pub substeps_per_s: f64,
}

/// Benchmark one backend over every size in `config`. `progress(done,
/// total)` counts timed runs.
///
/// # Errors
/// [`GateError`] for a bad size or a backend failure.
pub fn bench<B: Backend>(
    backend: &mut B,
    config: &BenchConfig,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<Vec<BenchRow>, GateError> {
    let total = (config.sides.len() * config.repeats) as u64;
    let mut rows = Vec::with_capacity(config.sides.len());
    for (k, &side) in config.sides.iter().enumerate() {
        let fabric = Fabric::from_chart(&Chart::stockinette(side, side)?, &Geometry::default())?;
        let nodes = fabric.node_count();
        backend.load(&fabric, &config.params)?;
        let pins: Vec<Pin> = if config.pin_top {
            let rest = fabric.positions();
            fabric.side_nodes(Side::Top).into_iter().map(|node| Pin { node, target: rest[node as usize] }).collect()
        } else {
            Vec::new()
        };
        backend.set_pins(&pins)?;
        let contacts = fabric.contacts().len();
        let alive_contacts = contacts - (config.dead.clamp(0.0, 1.0) * contacts as f64).round() as usize;
        backend.set_contacts_alive(&(0..contacts).map(|k| k < alive_contacts).collect::<Vec<_>>())?;
        // At least 50 substeps, so a huge fabric's run is not a handful of
        // substeps timed against the device waking up (on an H200, 4- and
        // 10-substep runs of 4M and 8M nodes varied 2-3x run to run).
        let substeps = (config.work_per_run / nodes as u64).max(50);
        // Warm-up: caches, the thread pool, and the release transient.
        backend.advance(config.settle.max(substeps / 4 + 1))?;
        let mut times = (0..config.repeats)
            .map(|r| {
                let start = Instant::now();
                backend.advance(substeps)?;
                let elapsed = start.elapsed().as_secs_f64();
                progress((k * config.repeats + r + 1) as u64, total);
                Ok(elapsed)
            })
            .collect::<Result<Vec<f64>, BackendError>>()?;
        times.sort_by(f64::total_cmp);
        let median = times[times.len() / 2];
        let per = |t: f64| t * 1e9 / (substeps as f64 * nodes as f64);
        rows.push(BenchRow {
            backend: backend.name(),
            threads: backend.threads(),
            size: format!("{side}x{side}"),
            nodes,
            contacts: fabric.contacts().len(),
            substeps,
            friction: config.params.friction,
            gravity: config.params.gravity,
            pins: pins.len(),
            dead_contacts: contacts - alive_contacts,
            sleep_speed: config.params.sleep_speed,
            ns_per_node_substep: per(median),
            ns_min: per(times[0]),
            ns_max: per(times[times.len() - 1]),
            substeps_per_s: substeps as f64 / median,
        });
    }
    Ok(rows)
}

/// The rows as a table, each row's scene (friction, gravity, pins) in its
/// last column.
pub fn table(rows: &[BenchRow]) -> String {
    let mut out = format!(
        "{:<16} {:>7} {:>7} {:>7} {:>8} {:>14} {:>16} {:>14}  scene\n",
        "backend", "threads", "size", "nodes", "contacts", "ns/node-step", "(min..max)", "substeps/s"
    );
    for r in rows {
        out += &format!(
            "{:<16} {:>7} {:>7} {:>7} {:>8} {:>14.2} {:>16} {:>14.0}  μ={} g={} pins={} dead={} sleep={}\n",
            r.backend,
            r.threads,
            r.size,
            r.nodes,
            r.contacts,
            r.ns_per_node_substep,
            format!("({:.2}..{:.2})", r.ns_min, r.ns_max),
            r.substeps_per_s,
            r.friction,
            r.gravity,
            r.pins,
            r.dead_contacts,
            r.sleep_speed
        );
    }
    out
}
