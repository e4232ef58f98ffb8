//! GPU time and pipeline statistics per pass, written by the graph around every pass it runs,
//! so the overlay and the bench see every pass (future ones too) without code of their own.

use crate::gpu::Gpu;
use anyhow::Result;
use ash::vk;

/// The most passes one frame can time and count; a frame with more runs the rest unmeasured.
pub const MAX_PASSES: usize = 24;

/// Shader invocations counted by the pipeline statistics queries.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ShaderInvocations {
    pub vertex: u64,
    pub fragment: u64,
}

/// One pass of a finished frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PassProfile {
    pub name: &'static str,
    /// GPU milliseconds (None without timestamps).
    pub gpu_ms: Option<f64>,
    /// None without pipeline statistics.
    pub invocations: Option<ShaderInvocations>,
}

/// Every pass a finished frame ran, in order.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FrameProfile {
    pub passes: Vec<PassProfile>,
}

impl FrameProfile {
    /// GPU milliseconds of the pass `name` (0 when it did not run or there are no timestamps).
    pub fn ms(&self, name: &str) -> f64 {
        self.get(name).and_then(|p| p.gpu_ms).unwrap_or(0.0)
    }

    /// GPU milliseconds of every pass whose name starts with `prefix` ("shadow": the static
    /// cache, the copy and the map).
    pub fn ms_prefixed(&self, prefix: &str) -> f64 {
        self.passes.iter().filter(|p| p.name.starts_with(prefix)).filter_map(|p| p.gpu_ms).sum()
    }

    /// Shader invocations of the pass `name` (None when it did not run or cannot be counted).
    pub fn invocations(&self, name: &str) -> Option<ShaderInvocations> {
        self.get(name).and_then(|p| p.invocations)
    }

    pub fn get(&self, name: &str) -> Option<&PassProfile> {
        self.passes.iter().find(|p| p.name == name)
    }

    /// GPU time of every pass.
    pub fn total_ms(&self) -> f64 {
        self.passes.iter().filter_map(|p| p.gpu_ms).sum()
    }
}

pub(super) struct Profiler {
    timestamps: Option<vk::QueryPool>,
    stats: Option<vk::QueryPool>,
    timestamp_period_ns: f64,
}

impl Profiler {
    pub fn new(gpu: &Gpu, frames_in_flight: usize) -> Result<Profiler> {
        let d = &gpu.device;
        let per_slot = MAX_PASSES as u32;
        let timestamps = gpu.own(if gpu.caps.timestamps {
            let info = vk::QueryPoolCreateInfo::default().query_type(vk::QueryType::TIMESTAMP).query_count(2 * per_slot * frames_in_flight as u32);
            Some(unsafe { d.create_query_pool(&info, None)? })
        } else {
            None
        });
        let stats = if gpu.caps.pipeline_statistics {
            let info = vk::QueryPoolCreateInfo::default()
                .query_type(vk::QueryType::PIPELINE_STATISTICS)
                .query_count(per_slot * frames_in_flight as u32)
                .pipeline_statistics(vk::QueryPipelineStatisticFlags::VERTEX_SHADER_INVOCATIONS | vk::QueryPipelineStatisticFlags::FRAGMENT_SHADER_INVOCATIONS);
            Some(unsafe { d.create_query_pool(&info, None)? })
        } else {
            None
        };
        Ok(Profiler { timestamps: timestamps.keep(), stats, timestamp_period_ns: gpu.caps.timestamp_period_ns as f64 })
    }

    pub fn begin_frame(&self, gpu: &Gpu, cb: vk::CommandBuffer, slot: usize) {
        let n = MAX_PASSES as u32;
        unsafe {
            if let Some(pool) = self.timestamps {
                gpu.device.cmd_reset_query_pool(cb, pool, 2 * n * slot as u32, 2 * n);
            }
            if let Some(pool) = self.stats {
                gpu.device.cmd_reset_query_pool(cb, pool, n * slot as u32, n);
            }
        }
    }

    /// Start measuring pass number `i` of the frame (its shader invocations only when `count`);
    /// returns whether it is measured, and whether it is counted.
    pub fn begin_pass(&self, gpu: &Gpu, cb: vk::CommandBuffer, slot: usize, i: usize, count: bool) -> (bool, bool) {
        if i >= MAX_PASSES {
            return (false, false);
        }
        let n = MAX_PASSES as u32;
        let counted = count && self.stats.is_some();
        unsafe {
            if let Some(pool) = self.timestamps {
                gpu.device.cmd_write_timestamp2(cb, vk::PipelineStageFlags2::ALL_COMMANDS, pool, 2 * n * slot as u32 + 2 * i as u32);
            }
            if let Some(pool) = self.stats.filter(|_| counted) {
                gpu.device.cmd_begin_query(cb, pool, n * slot as u32 + i as u32, vk::QueryControlFlags::empty());
            }
        }
        (true, counted)
    }

    pub fn end_pass(&self, gpu: &Gpu, cb: vk::CommandBuffer, slot: usize, i: usize, (measured, counted): (bool, bool)) {
        if !measured {
            return;
        }
        let n = MAX_PASSES as u32;
        unsafe {
            if let Some(pool) = self.stats.filter(|_| counted) {
                gpu.device.cmd_end_query(cb, pool, n * slot as u32 + i as u32);
            }
            if let Some(pool) = self.timestamps {
                gpu.device.cmd_write_timestamp2(cb, vk::PipelineStageFlags2::ALL_COMMANDS, pool, 2 * n * slot as u32 + 2 * i as u32 + 1);
            }
        }
    }

    /// The profile of `slot`'s last frame and whether every query of it was ready (a frame the
    /// GPU has not finished reads as zeros where it is not).
    pub fn read(&self, gpu: &Gpu, slot: usize, ran: &[(&'static str, bool)]) -> Option<(FrameProfile, bool)> {
        if self.timestamps.is_none() && self.stats.is_none() {
            return None;
        }
        let n = MAX_PASSES as u32;
        let count = ran.len().min(MAX_PASSES);
        let mut times = vec![0u64; 2 * count];
        let times_ok = match self.timestamps {
            Some(pool) if count > 0 => unsafe { gpu.device.get_query_pool_results(pool, 2 * n * slot as u32, &mut times, vk::QueryResultFlags::TYPE_64) }.is_ok(),
            _ => false,
        };
        // Each counted pass's query on its own: the others were reset and never begun.
        let invocations = |i: usize| -> Option<ShaderInvocations> {
            let pool = self.stats?;
            let mut v = [[0u64; 2]; 1];
            unsafe { gpu.device.get_query_pool_results(pool, n * slot as u32 + i as u32, &mut v, vk::QueryResultFlags::TYPE_64) }.ok()?;
            Some(ShaderInvocations { vertex: v[0][0], fragment: v[0][1] })
        };
        let mut complete = times_ok || self.timestamps.is_none() || count == 0;
        let passes = ran
            .iter()
            .enumerate()
            .map(|(i, &(name, counted))| {
                let invocations = if counted && i < count { invocations(i) } else { None };
                complete &= invocations.is_some() || !(counted && i < count);
                PassProfile {
                    name,
                    gpu_ms: (times_ok && i < count).then(|| times[2 * i + 1].saturating_sub(times[2 * i]) as f64 * self.timestamp_period_ns * 1e-6),
                    invocations,
                }
            })
            .collect();
        Some((FrameProfile { passes }, complete))
    }

    pub fn destroy(&mut self, gpu: &Gpu) {
        for pool in self.timestamps.take().into_iter().chain(self.stats.take()) {
            unsafe { gpu.device.destroy_query_pool(pool, None) };
        }
    }
}
