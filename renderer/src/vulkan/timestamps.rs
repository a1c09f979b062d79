//! GPU times from timestamp queries, four per frame (start, terrain pass start and end, end),
//! and, where the device counts them, the terrain pass's pipeline statistics (one query over
//! the pass), read after the frame's fence.

use ash::vk;

use super::{Gpu, VkResult};

const QUERIES: u32 = 4;

/// What the terrain pass's pipeline statistics count, in the order the query returns them (the
/// flags' bit order).
const STATISTICS: vk::QueryPipelineStatisticFlags = vk::QueryPipelineStatisticFlags::from_raw(
    vk::QueryPipelineStatisticFlags::INPUT_ASSEMBLY_PRIMITIVES.as_raw()
        | vk::QueryPipelineStatisticFlags::VERTEX_SHADER_INVOCATIONS.as_raw()
        | vk::QueryPipelineStatisticFlags::CLIPPING_PRIMITIVES.as_raw()
        | vk::QueryPipelineStatisticFlags::FRAGMENT_SHADER_INVOCATIONS.as_raw(),
);

/// The terrain pass as the GPU counted it (pipeline statistics; how an implementation counts
/// is partly its own: vertex shader invocations depend on its vertex reuse).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PassStatistics {
    /// Primitives assembled: every triangle drawn, stitches included, on screen or not.
    pub primitives: u64,
    /// Vertex shader invocations.
    pub vertex_invocations: u64,
    /// Primitives out of the clipping stage: those on screen (clipping discards the rest).
    pub clipped_primitives: u64,
    /// Fragment shader invocations.
    pub fragment_invocations: u64,
}

pub struct Timestamps {
    pool: vk::QueryPool,
    /// One pipeline-statistics query over the terrain pass, where the device counts them.
    statistics: Option<vk::QueryPool>,
    /// Nanoseconds per tick; 0 when the queue cannot time.
    period_ns: f64,
}

impl Timestamps {
    pub fn new(gpu: &Gpu, name: &str) -> VkResult<Timestamps> {
        let info = vk::QueryPoolCreateInfo::default()
            .query_type(vk::QueryType::TIMESTAMP)
            .query_count(QUERIES);
        // SAFETY: valid create info.
        let pool = unsafe { gpu.device.create_query_pool(&info, None) }?;
        gpu.name(pool, name);
        // SAFETY: plain property query.
        let families = unsafe {
            gpu.instance
                .get_physical_device_queue_family_properties(gpu.physical)
        };
        let valid_bits = families
            .get(gpu.queue_family as usize)
            .map_or(0, |f| f.timestamp_valid_bits);
        let period_ns = if valid_bits > 0 {
            f64::from(gpu.properties.limits.timestamp_period)
        } else {
            0.0
        };
        let statistics = if gpu.pipeline_statistics {
            let info = vk::QueryPoolCreateInfo::default()
                .query_type(vk::QueryType::PIPELINE_STATISTICS)
                .pipeline_statistics(STATISTICS)
                .query_count(1);
            // SAFETY: valid create info; the feature is enabled.
            match unsafe { gpu.device.create_query_pool(&info, None) } {
                Ok(p) => {
                    gpu.name(p, &format!("{name} statistics"));
                    Some(p)
                }
                Err(e) => {
                    // SAFETY: no command buffer has used it.
                    unsafe { gpu.device.destroy_query_pool(pool, None) };
                    return Err(e.into());
                }
            }
        } else {
            None
        };
        Ok(Timestamps {
            pool,
            statistics,
            period_ns,
        })
    }

    /// The frame's first stamp (resets the pool first).
    pub fn begin(&self, gpu: &Gpu, cmd: vk::CommandBuffer) {
        // SAFETY: cmd is recording outside rendering; the pool has QUERIES queries.
        unsafe {
            gpu.device.cmd_reset_query_pool(cmd, self.pool, 0, QUERIES);
            if let Some(p) = self.statistics {
                gpu.device.cmd_reset_query_pool(cmd, p, 0, 1);
            }
        }
        self.stamp(gpu, cmd, vk::PipelineStageFlags::TOP_OF_PIPE, 0);
    }

    /// Before the terrain pass (outside rendering), after `begin`.
    pub fn pass_begin(&self, gpu: &Gpu, cmd: vk::CommandBuffer) {
        self.stamp(gpu, cmd, vk::PipelineStageFlags::TOP_OF_PIPE, 1);
        if let Some(p) = self.statistics {
            // SAFETY: cmd is recording outside rendering; the query was reset by `begin`.
            unsafe {
                gpu.device
                    .cmd_begin_query(cmd, p, 0, vk::QueryControlFlags::empty())
            };
        }
    }

    /// After the terrain pass (outside rendering).
    pub fn pass_end(&self, gpu: &Gpu, cmd: vk::CommandBuffer) {
        if let Some(p) = self.statistics {
            // SAFETY: the query was begun by `pass_begin` in this command buffer.
            unsafe { gpu.device.cmd_end_query(cmd, p, 0) };
        }
        self.stamp(gpu, cmd, vk::PipelineStageFlags::BOTTOM_OF_PIPE, 2);
    }

    /// The finished frame's terrain pass as the GPU counted it, where the device counts.
    pub fn read_statistics(&self, gpu: &Gpu) -> Option<PassStatistics> {
        let pool = self.statistics?;
        let mut counts = [[0u64; 4]; 1];
        // SAFETY: the frame's fence was waited on, so the result is available.
        unsafe {
            gpu.device
                .get_query_pool_results(pool, 0, &mut counts, vk::QueryResultFlags::TYPE_64)
        }
        .ok()?;
        let [primitives, vertex_invocations, clipped_primitives, fragment_invocations] = counts[0];
        Some(PassStatistics {
            primitives,
            vertex_invocations,
            clipped_primitives,
            fragment_invocations,
        })
    }

    pub fn end(&self, gpu: &Gpu, cmd: vk::CommandBuffer) {
        self.stamp(gpu, cmd, vk::PipelineStageFlags::BOTTOM_OF_PIPE, 3);
    }

    fn stamp(&self, gpu: &Gpu, cmd: vk::CommandBuffer, stage: vk::PipelineStageFlags, q: u32) {
        // SAFETY: cmd is recording; q < QUERIES and was reset by `begin`.
        unsafe { gpu.device.cmd_write_timestamp(cmd, stage, self.pool, q) };
    }

    /// The finished frame's four stamps in ticks, if the queue can time.
    pub fn read_ticks(&self, gpu: &Gpu) -> Option<[u64; QUERIES as usize]> {
        if self.period_ns == 0.0 {
            return None;
        }
        let mut ticks = [0u64; QUERIES as usize];
        // SAFETY: the frame's fence was waited on, so every result is available.
        unsafe {
            gpu.device.get_query_pool_results(
                self.pool,
                0,
                &mut ticks,
                vk::QueryResultFlags::TYPE_64,
            )
        }
        .ok()?;
        Some(ticks)
    }

    /// Milliseconds between two tick counts of this queue.
    pub fn ms_between(&self, from: u64, to: u64) -> f64 {
        to.saturating_sub(from) as f64 * self.period_ns / 1e6
    }

    /// (whole frame, terrain pass) in milliseconds of the finished frame, if the queue can time.
    pub fn read_ms(&self, gpu: &Gpu) -> Option<(f64, f64)> {
        let t = self.read_ticks(gpu)?;
        Some((self.ms_between(t[0], t[3]), self.ms_between(t[1], t[2])))
    }

    pub fn destroy(self, gpu: &Gpu) {
        // SAFETY: no frame in flight uses the pool.
        unsafe {
            gpu.device.destroy_query_pool(self.pool, None);
            if let Some(p) = self.statistics {
                gpu.device.destroy_query_pool(p, None);
            }
        }
    }
}
