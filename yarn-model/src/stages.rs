//! Stage counters: where a substep's time goes, stage by stage, as rapier's
//! `Counters` report a physics step's.
//!
//! This module owns the vocabulary ([`Stage`], [`StagePart`],
//! [`StageTimes`]) and the CPU's clock ([`StageClock`]); it knows nothing of
//! how a backend runs its passes. Each backend times its own passes and
//! names the stages each one covers: a pass that fuses several stages (the
//! CPU's block pass computes forces and the damped velocity, and without
//! friction moves the nodes too) is one part naming all of them, because a
//! fused pass cannot be split.
//!
//! Counting costs nothing when off: [`crate::Backend::advance`] never looks
//! at a clock, and only [`crate::Backend::advance_timed`] turns one on.

use std::time::{Duration, Instant};

/// A stage of the substep (SPEC §4), plus the work around it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Stage {
    /// Step 1, F = −∇U, with step 2's damped velocity update v* (every
    /// backend computes v* where the forces are summed).
    Forces,
    /// Step 3, the Jacobi friction change of every compressed contact.
    Friction,
    /// Step 4, x' = x + h v** (with each node's sum of friction changes).
    Move,
    /// Step 5, pinned nodes set to their targets.
    Pins,
    /// Re-seated contacts closing back to their knitted rest.
    Reseat,
    /// The divergence check.
    Check,
    /// Sleeping blocks found and woken (CPU).
    Sleep,
}

impl Stage {
    /// Its name in tables and JSON.
    pub fn name(self) -> &'static str {
        match self {
            Stage::Forces => "forces",
            Stage::Friction => "friction",
            Stage::Move => "move",
            Stage::Pins => "pins",
            Stage::Reseat => "reseat",
            Stage::Check => "check",
            Stage::Sleep => "sleep",
        }
    }
}

/// How a backend took its stage times.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TimingMethod {
    /// Wall-clock timers around each pass on the CPU.
    CpuTimers,
    /// GPU timestamp queries at the start and end of each pass.
    GpuTimestamps,
    /// Where the GPU has no timestamps: each pass dispatched alone many
    /// times and timed by the wall clock, after the substeps themselves.
    GpuPassRuns,
    /// One wall-clock time for the whole call: a backend that cannot split
    /// its substep.
    WallClock,
}

impl TimingMethod {
    /// Its name in tables and JSON.
    pub fn name(self) -> &'static str {
        match self {
            TimingMethod::CpuTimers => "cpu timers",
            TimingMethod::GpuTimestamps => "gpu timestamps",
            TimingMethod::GpuPassRuns => "gpu per-pass runs",
            TimingMethod::WallClock => "wall clock",
        }
    }
}

/// One timed pass and the stages it covers.
#[derive(Debug, Clone, PartialEq)]
pub struct StagePart {
    /// The pass, e.g. `"block forces"` or `"friction.wgsl"`.
    pub pass: &'static str,
    /// The stages it covers: more than one when they run fused.
    pub stages: Vec<Stage>,
    /// Seconds spent in it over every timed substep.
    pub seconds: f64,
}

/// Where the time of some substeps went, pass by pass.
#[derive(Debug, Clone, PartialEq)]
pub struct StageTimes {
    /// Substeps timed.
    pub substeps: u64,
    /// How the times were taken.
    pub method: TimingMethod,
    /// Every pass that ran, in the order a substep runs them.
    pub parts: Vec<StagePart>,
    /// Wall seconds of the whole call, timing included.
    pub wall_seconds: f64,
    /// Set when the times are not those of the passes `advance` runs: a
    /// GPU substep fused into one dispatch is timed as its unfused passes.
    pub note: Option<String>,
}

impl StageTimes {
    /// Seconds in the timed passes, all together.
    pub fn total_seconds(&self) -> f64 {
        self.parts.iter().map(|p| p.seconds).sum()
    }

    /// Microseconds a substep spends in `part`.
    pub fn micros_per_substep(&self, part: &StagePart) -> f64 {
        1e6 * part.seconds / self.substeps.max(1) as f64
    }
}

/// Wall-clock totals per pass, for CPU backends: started only by
/// [`crate::Backend::advance_timed`], so an untimed advance pays one
/// `Option` test per pass.
#[derive(Debug, Clone, Default)]
pub struct StageClock {
    /// Per pass, in the order first timed: its name, stages and total.
    parts: Vec<(&'static str, &'static [Stage], Duration)>,
}

impl StageClock {
    /// Add the time since `started` to `pass`, which covers `stages`.
    pub fn add(&mut self, pass: &'static str, stages: &'static [Stage], started: Instant) {
        let elapsed = started.elapsed();
        match self.parts.iter_mut().find(|(name, covers, _)| *name == pass && *covers == stages) {
            Some((_, _, total)) => *total += elapsed,
            None => self.parts.push((pass, stages, elapsed)),
        }
    }

    /// The totals as a report of `substeps` substeps that took
    /// `wall_seconds`.
    pub fn report(&self, substeps: u64, wall_seconds: f64) -> StageTimes {
        StageTimes {
            substeps,
            method: TimingMethod::CpuTimers,
            parts: self
                .parts
                .iter()
                .map(|&(pass, stages, total)| StagePart { pass, stages: stages.to_vec(), seconds: total.as_secs_f64() })
                .collect(),
            wall_seconds,
            note: None,
        }
    }
}

/// Start timing a pass when `clock` is on.
pub fn start(clock: &Option<StageClock>) -> Option<Instant> {
    clock.as_ref().map(|_| Instant::now())
}

/// Stop timing a pass started by [`start`], adding it to `clock`.
pub fn stop(clock: &mut Option<StageClock>, pass: &'static str, stages: &'static [Stage], started: Option<Instant>) {
    if let (Some(clock), Some(started)) = (clock.as_mut(), started) {
        clock.add(pass, stages, started);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_clock_sums_each_pass_once_in_first_timed_order() {
        let mut clock = Some(StageClock::default());
        for _ in 0..3 {
            let t = start(&clock);
            std::thread::sleep(Duration::from_millis(2));
            stop(&mut clock, "forces", &[Stage::Forces], t);
            let t = start(&clock);
            stop(&mut clock, "pins", &[Stage::Pins], t);
        }
        let report = clock.as_ref().map(|c| c.report(3, 1.0)).expect("on");
        let passes: Vec<&str> = report.parts.iter().map(|p| p.pass).collect();
        assert_eq!(passes, ["forces", "pins"]);
        assert!(report.parts[0].seconds >= 0.006, "{:?}", report.parts[0]);
        assert!(report.micros_per_substep(&report.parts[0]) >= 2000.0);
        // Off: nothing is started, so nothing is added.
        let mut off: Option<StageClock> = None;
        let t = start(&off);
        assert!(t.is_none());
        stop(&mut off, "forces", &[Stage::Forces], t);
        assert!(off.is_none());
    }
}
