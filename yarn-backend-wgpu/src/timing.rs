//! The GPU's stage counters ([`yarn_model::Backend::advance_timed`]):
//! where the adapter has timestamp queries, each dispatch of the batch
//! runs in a compute pass of its own with a timestamp at its start and
//! end; where it has none, the batch runs as usual and then each kind of
//! pass is dispatched alone, as many times, and timed by the wall clock.
//!
//! Either way the fused substep (`fused.wgsl`) cannot be split, so stages
//! are timed on the unfused passes, which give the same result, and the
//! report says so. This module owns the timing; what the passes are comes
//! from `record.rs`. An untimed advance never reaches it.

use std::time::Instant;

use yarn_model::BackendError;
use yarn_model::stages::{Stage, StagePart, StageTimes, TimingMethod};

use crate::fabric::{GpuFabric, finish};
use crate::gpu::{Gpu, read_mapped};
use crate::record::Dispatch;

/// Queries per query set: WebGPU's most.
const QUERIES_PER_SET: u32 = wgpu::QUERY_SET_MAX_QUERIES;

/// The timestamps of one timed batch, being recorded.
#[derive(Debug, Default)]
pub(crate) struct Timestamps {
    sets: Vec<wgpu::QuerySet>,
    /// Per dispatch recorded, in order: its pass and stages.
    labels: Vec<(&'static str, &'static [Stage])>,
    /// Where the resolved timestamps are copied to be read.
    readback: Option<wgpu::Buffer>,
}

impl Timestamps {
    /// Record `dispatch` in a compute pass of its own, timestamped at its
    /// start and end.
    pub(crate) fn record(&mut self, gpu: &Gpu, encoder: &mut wgpu::CommandEncoder, dispatch: &Dispatch<'_>) {
        let index = 2 * self.labels.len() as u32;
        let set = (index / QUERIES_PER_SET) as usize;
        if set == self.sets.len() {
            self.sets.push(gpu.device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("stage timestamps"),
                ty: wgpu::QueryType::Timestamp,
                count: QUERIES_PER_SET,
            }));
        }
        let within = index % QUERIES_PER_SET;
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some(dispatch.pass),
            timestamp_writes: Some(wgpu::ComputePassTimestampWrites {
                query_set: &self.sets[set],
                beginning_of_pass_write_index: Some(within),
                end_of_pass_write_index: Some(within + 1),
            }),
        });
        dispatch.record(&mut pass);
        self.labels.push((dispatch.pass, dispatch.stages));
    }

    /// Resolve every timestamp recorded into a buffer to read after the
    /// submission.
    pub(crate) fn resolve(&mut self, device: &wgpu::Device, encoder: &mut wgpu::CommandEncoder) {
        let queries = 2 * self.labels.len() as u64;
        let bytes = (queries * wgpu::QUERY_SIZE as u64).max(8);
        let resolved = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("stage timestamps resolved"),
            size: bytes,
            usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        for (k, set) in self.sets.iter().enumerate() {
            let first = k as u64 * u64::from(QUERIES_PER_SET);
            let count = (queries - first).min(u64::from(QUERIES_PER_SET)) as u32;
            encoder.resolve_query_set(set, 0..count, &resolved, first * wgpu::QUERY_SIZE as u64);
        }
        let readback = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("stage timestamps readback"),
            size: bytes,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        encoder.copy_buffer_to_buffer(&resolved, 0, &readback, 0, bytes);
        self.readback = Some(readback);
    }

    /// Each pass's total, from the resolved timestamps, in the order the
    /// passes first ran.
    fn parts(&self, gpu: &Gpu) -> Result<Vec<StagePart>, BackendError> {
        let Some(readback) = &self.readback else { return Ok(Vec::new()) };
        let bytes = pollster::block_on(read_mapped(&gpu.device, readback)).map_err(BackendError::Device)?;
        let ticks: Vec<u64> = bytemuck::pod_collect_to_vec(&bytes);
        let seconds_per_tick = f64::from(gpu.queue.get_timestamp_period()) * 1e-9;
        let mut parts = Vec::new();
        for (k, &(pass, stages)) in self.labels.iter().enumerate() {
            let (start, end) = (ticks[2 * k], ticks[2 * k + 1]);
            add(&mut parts, pass, stages, end.saturating_sub(start) as f64 * seconds_per_tick);
        }
        Ok(parts)
    }
}

/// Add `seconds` to `pass`'s part, making it if it is the first.
fn add(parts: &mut Vec<StagePart>, pass: &'static str, stages: &'static [Stage], seconds: f64) {
    match parts.iter_mut().find(|p| p.pass == pass) {
        Some(part) => part.seconds += seconds,
        None => parts.push(StagePart { pass, stages: stages.to_vec(), seconds }),
    }
}

impl GpuFabric {
    /// Advance `substeps` substeps and report where their time went: by
    /// timestamps when `timestamps` is set and the device has them,
    /// otherwise by per-pass timing runs.
    pub(crate) fn advance_timed(&mut self, substeps: u64, timestamps: bool) -> Result<StageTimes, BackendError> {
        let note = self.fuses().then(|| {
            format!(
                "advance runs fused.wgsl at {} nodes; its stages are timed on the unfused passes, \
                 which give the same result",
                self.model.node_count()
            )
        });
        let started = Instant::now();
        let (method, parts) = if timestamps && self.gpu.timestamps {
            self.timestamps = Some(Timestamps::default());
            let result = self.advance(substeps);
            let recorded = self.timestamps.take().unwrap_or_default();
            result?;
            (TimingMethod::GpuTimestamps, recorded.parts(&self.gpu)?)
        } else {
            // The passes to time are those the batch ran: the reseat pass
            // among them if a contact was closing when it started.
            let reseat = !self.model.reseating().is_empty();
            self.advance(substeps)?;
            (TimingMethod::GpuPassRuns, self.time_each_pass(substeps, reseat)?)
        };
        let wall_seconds = started.elapsed().as_secs_f64();
        Ok(StageTimes { substeps, method, parts, wall_seconds, note })
    }

    /// Dispatch each kind of pass of one unfused substep (with the reseat
    /// pass when `reseat`), and the check, `repeats` times alone from the
    /// current state, timing each by the wall clock; then put the state,
    /// the status, the accumulators and the re-seated rests back as they
    /// were.
    fn time_each_pass(&mut self, repeats: u64, reseat: bool) -> Result<Vec<StagePart>, BackendError> {
        let mut parts = Vec::new();
        {
            let mut plan: Vec<Dispatch<'_>> = Vec::new();
            let after = self.substep_plan(self.parity, false, reseat, true, &mut |d| plan.push(*d));
            plan.push(self.check_dispatch(after));
            let device = &self.gpu.device;
            let [saved_x, saved_v] = &self.buffers.snapshot;
            let (x, v) = (&self.buffers.x[self.parity.x], &self.buffers.v[self.parity.v]);
            let mut encoder = device.create_command_encoder(&Default::default());
            encoder.copy_buffer_to_buffer(x, 0, saved_x, 0, saved_x.size());
            encoder.copy_buffer_to_buffer(v, 0, saved_v, 0, saved_v.size());
            self.gpu.queue.submit([encoder.finish()]);
            finish(&self.gpu)?;
            for dispatch in &plan {
                let mut encoder = device.create_command_encoder(&Default::default());
                {
                    let mut pass = encoder.begin_compute_pass(&Default::default());
                    for _ in 0..repeats {
                        dispatch.record(&mut pass);
                    }
                }
                let started = Instant::now();
                self.gpu.queue.submit([encoder.finish()]);
                finish(&self.gpu)?;
                add(&mut parts, dispatch.pass, dispatch.stages, started.elapsed().as_secs_f64());
            }
            let mut encoder = device.create_command_encoder(&Default::default());
            encoder.copy_buffer_to_buffer(saved_x, 0, x, 0, saved_x.size());
            encoder.copy_buffer_to_buffer(saved_v, 0, v, 0, saved_v.size());
            encoder.clear_buffer(&self.buffers.status, 0, None);
            encoder.clear_buffer(&self.buffers.acc, 0, None);
            self.gpu.queue.submit([encoder.finish()]);
        }
        if reseat {
            self.upload_contacts();
        }
        finish(&self.gpu)?;
        Ok(parts)
    }
}
