// SPDX-License-Identifier: MIT
//! The frame engine: what every composition (KinectFusion, the pose-driven mapper, …) uses to
//! keep a frame on the GPU.
//!
//! - [`FrameEncoder`]: one command encoder per frame; each stage records its dispatches into one
//!   compute pass of its own ([`FrameEncoder::stage`]), which carries GPU timestamps where the
//!   device has them ([`StageTimer`]).
//! - [`ReadbackRing`]: the one small readback of a frame (its summary and timestamps), copied
//!   into a ring of mappable buffers and collected when the GPU is done, a frame or more later,
//!   so the host never waits for the GPU inside a frame. It waits only when every slot is in
//!   flight (backpressure) or when asked to flush.

use std::collections::VecDeque;

use crate::gpu::{OneshotReceiver, oneshot};
use crate::{Error, Gpu, Result};

/// Most stages one frame can time.
pub const MAX_STAGES: usize = 16;

/// GPU time of one stage of a frame.
#[derive(Clone, Debug, PartialEq)]
pub struct StageTime {
    /// Stage name.
    pub name: &'static str,
    /// Milliseconds between the stage pass's first and last GPU timestamps.
    pub gpu_ms: f64,
}

/// Timestamp queries for the stages of one frame (2 per stage: start and end of its pass).
#[derive(Debug)]
pub struct StageTimer {
    query_set: wgpu::QuerySet,
    resolve: wgpu::Buffer,
    period_ns: f64,
}

impl StageTimer {
    /// Bytes the resolved timestamps of one frame take.
    pub const BYTES: u64 = (2 * MAX_STAGES * 8) as u64;

    /// A timer for `gpu`, or `None` when the device has no timestamp queries.
    pub fn new(gpu: &Gpu, label: &str) -> Option<Self> {
        if !gpu.has_timestamps {
            return None;
        }
        let query_set = gpu.device.create_query_set(&wgpu::QuerySetDescriptor { label: Some(&format!("{label}.timestamps")), ty: wgpu::QueryType::Timestamp, count: 2 * MAX_STAGES as u32 });
        let resolve = gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(&format!("{label}.timestamps.resolve")),
            size: Self::BYTES,
            usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        Some(Self { query_set, resolve, period_ns: f64::from(gpu.queue.get_timestamp_period()) })
    }

    /// Stage times from the resolved ticks of `names.len()` stages.
    pub fn stage_times(&self, names: &[&'static str], ticks: &[u64]) -> Vec<StageTime> {
        names
            .iter()
            .enumerate()
            .map(|(i, &name)| {
                let (start, end) = (ticks.get(2 * i).copied().unwrap_or(0), ticks.get(2 * i + 1).copied().unwrap_or(0));
                StageTime { name, gpu_ms: end.saturating_sub(start) as f64 * self.period_ns * 1e-6 }
            })
            .collect()
    }
}

/// One frame's command encoder, recording each stage into a compute pass of its own.
pub struct FrameEncoder<'a> {
    encoder: wgpu::CommandEncoder,
    timer: Option<&'a StageTimer>,
    stages: Vec<&'static str>,
}

impl<'a> FrameEncoder<'a> {
    /// A new frame, timed by `timer` when given.
    pub fn new(gpu: &Gpu, label: &str, timer: Option<&'a StageTimer>) -> Self {
        Self { encoder: gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(label) }), timer, stages: Vec::new() }
    }

    /// The compute pass of stage `name`; its dispatches are timed together.
    ///
    /// # Panics
    /// If more than [`MAX_STAGES`] stages are recorded (a bug in the composition).
    pub fn stage(&mut self, name: &'static str) -> wgpu::ComputePass<'_> {
        assert!(self.stages.len() < MAX_STAGES, "a frame times at most {MAX_STAGES} stages");
        let i = self.stages.len() as u32;
        self.stages.push(name);
        let timestamp_writes = self.timer.map(|t| wgpu::ComputePassTimestampWrites { query_set: &t.query_set, beginning_of_pass_write_index: Some(2 * i), end_of_pass_write_index: Some(2 * i + 1) });
        self.encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some(name), timestamp_writes })
    }

    /// The encoder itself, for copies between stages.
    pub fn encoder(&mut self) -> &mut wgpu::CommandEncoder {
        &mut self.encoder
    }

    /// The stages recorded so far.
    pub fn stage_names(&self) -> &[&'static str] {
        &self.stages
    }

    /// Resolves the timestamps (when timed) into `dst` at `offset` and finishes the encoder.
    pub fn finish(mut self, timestamps_to: Option<(&wgpu::Buffer, u64)>) -> (wgpu::CommandBuffer, Vec<&'static str>) {
        if let (Some(timer), Some((dst, offset))) = (self.timer, timestamps_to)
            && !self.stages.is_empty()
        {
            let n = 2 * self.stages.len() as u32;
            self.encoder.resolve_query_set(&timer.query_set, 0..n, &timer.resolve, 0);
            self.encoder.copy_buffer_to_buffer(&timer.resolve, 0, dst, offset, u64::from(n) * 8);
        }
        (self.encoder.finish(), self.stages)
    }
}

/// A completed readback: the bytes and what the caller attached to it.
#[derive(Debug)]
pub struct Readback<T> {
    /// What [`ReadbackRing::start`] was given.
    pub tag: T,
    /// The slot's bytes.
    pub bytes: Vec<u8>,
}

struct InFlight<T> {
    slot: usize,
    /// Bytes mapped from the slot's start.
    bytes: u64,
    tag: T,
    submission: wgpu::SubmissionIndex,
    mapped: OneshotReceiver<std::result::Result<(), wgpu::BufferAsyncError>>,
}

/// A ring of mappable buffers for one small readback per frame, collected in submission order.
pub struct ReadbackRing<T> {
    label: String,
    buffers: Vec<wgpu::Buffer>,
    free: Vec<usize>,
    in_flight: VecDeque<InFlight<T>>,
}

impl<T> std::fmt::Debug for ReadbackRing<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ReadbackRing").field("label", &self.label).field("slots", &self.buffers.len()).field("in_flight", &self.in_flight.len()).finish()
    }
}

impl<T> ReadbackRing<T> {
    /// `slots` buffers of `size_bytes` each.
    pub fn new(gpu: &Gpu, label: &str, size_bytes: u64, slots: usize) -> Self {
        let buffers = (0..slots.max(1))
            .map(|i| {
                gpu.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(&format!("{label}.readback[{i}]")),
                    size: size_bytes.next_multiple_of(8),
                    usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                })
            })
            .collect::<Vec<_>>();
        let free = (0..buffers.len()).rev().collect();
        Self { label: label.to_owned(), buffers, free, in_flight: VecDeque::new() }
    }

    /// Readbacks started and not yet collected.
    pub fn in_flight(&self) -> usize {
        self.in_flight.len()
    }

    /// A free slot's buffer to copy into, or `None` when every slot is in flight.
    pub fn free_slot(&self) -> Option<(usize, &wgpu::Buffer)> {
        self.free.last().map(|&i| (i, &self.buffers[i]))
    }

    /// Maps `slot` once `submission` (which copied into it) is done.
    ///
    /// # Panics
    /// If `slot` is not free (a bug in the caller).
    pub fn start(&mut self, gpu: &Gpu, slot: usize, submission: wgpu::SubmissionIndex, tag: T) {
        let bytes = self.buffers[slot].size();
        self.start_bytes(gpu, slot, submission, tag, bytes);
    }

    /// As [`Self::start`], mapping (and reading back) only the slot's first `bytes`, a
    /// multiple of 4: what this submission copied into a slot sized for the largest readback.
    ///
    /// # Panics
    /// If `slot` is not free or `bytes` is not a multiple of 4 within the slot (bugs in the
    /// caller).
    pub fn start_bytes(&mut self, gpu: &Gpu, slot: usize, submission: wgpu::SubmissionIndex, tag: T, bytes: u64) {
        assert!(bytes.is_multiple_of(4) && bytes <= self.buffers[slot].size(), "{}: {bytes} bytes of a {}-byte slot", self.label, self.buffers[slot].size());
        let at = self.free.iter().position(|&s| s == slot).expect("start() takes the slot free_slot() gave");
        self.free.remove(at);
        let (sender, mapped) = oneshot();
        self.buffers[slot].map_async(wgpu::MapMode::Read, ..bytes, move |r| sender.send(r));
        gpu.counters.count_readback(bytes);
        self.in_flight.push_back(InFlight { slot, bytes, tag, submission, mapped });
    }

    /// The readbacks that completed, oldest first, without waiting for the GPU.
    pub fn collect(&mut self, gpu: &Gpu) -> Result<Vec<Readback<T>>> {
        #[cfg(not(target_arch = "wasm32"))]
        gpu.device.poll(wgpu::PollType::Poll).map_err(|e| Error::Poll(e.to_string()))?;
        gpu.check_lost()?;
        let mut out = Vec::new();
        while let Some(front) = self.in_flight.front() {
            let Some(result) = front.mapped.try_take() else { break };
            let done = self.in_flight.pop_front().expect("front exists");
            out.push(self.finish(done.slot, done.bytes, done.tag, result)?);
        }
        Ok(out)
    }

    /// Waits for the oldest readback in flight (counted as a host wait), or `None` when there
    /// is none.
    pub async fn wait_oldest(&mut self, gpu: &Gpu) -> Result<Option<Readback<T>>> {
        let Some(oldest) = self.in_flight.pop_front() else { return Ok(None) };
        gpu.counters.count_wait();
        let InFlight { slot, bytes, tag, submission, mapped } = oldest;
        #[cfg(not(target_arch = "wasm32"))]
        let result = {
            gpu.device
                .poll(wgpu::PollType::Wait { submission_index: Some(submission), timeout: Some(std::time::Duration::from_secs(crate::gpu::POLL_TIMEOUT_S)) })
                .map_err(|e| Error::Poll(e.to_string()))?;
            // The map callback runs during a poll once the copy is done.
            let mut polls = 0u32;
            loop {
                if let Some(r) = mapped.try_take() {
                    break r;
                }
                gpu.check_lost()?;
                polls += 1;
                if polls > 1000 {
                    return Err(Error::Poll(format!("{}: the readback was never mapped", self.label)));
                }
                gpu.device.poll(wgpu::PollType::Poll).map_err(|e| Error::Poll(e.to_string()))?;
            }
        };
        #[cfg(target_arch = "wasm32")]
        let result = {
            let _ = submission;
            mapped.await
        };
        gpu.check_lost()?;
        self.finish(slot, bytes, tag, result).map(Some)
    }

    fn finish(&mut self, slot: usize, mapped_bytes: u64, tag: T, result: std::result::Result<(), wgpu::BufferAsyncError>) -> Result<Readback<T>> {
        let buffer = &self.buffers[slot];
        let label = format!("{}.readback[{}]", self.label, slot);
        result.map_err(|e| Error::BufferMap { label: label.clone(), message: e.to_string() })?;
        let bytes = buffer.get_mapped_range(..mapped_bytes).map_err(|e| Error::BufferMap { label, message: e.to_string() })?.to_vec();
        buffer.unmap();
        self.free.push(slot);
        Ok(Readback { tag, bytes })
    }
}
