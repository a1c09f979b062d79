//! GPU times from timestamp queries, four per frame (start, terrain pass start and end, end),
//! read after the frame's fence.

use ash::vk;

use super::{Gpu, VkResult};

const QUERIES: u32 = 4;

pub struct Timestamps {
    pool: vk::QueryPool,
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
        Ok(Timestamps { pool, period_ns })
    }

    /// The frame's first stamp (resets the pool first).
    pub fn begin(&self, gpu: &Gpu, cmd: vk::CommandBuffer) {
        // SAFETY: cmd is recording outside rendering; the pool has QUERIES queries.
        unsafe {
            gpu.device.cmd_reset_query_pool(cmd, self.pool, 0, QUERIES);
        }
        self.stamp(gpu, cmd, vk::PipelineStageFlags::TOP_OF_PIPE, 0);
    }

    /// Before the terrain pass.
    pub fn pass_begin(&self, gpu: &Gpu, cmd: vk::CommandBuffer) {
        self.stamp(gpu, cmd, vk::PipelineStageFlags::TOP_OF_PIPE, 1);
    }

    /// After the terrain pass.
    pub fn pass_end(&self, gpu: &Gpu, cmd: vk::CommandBuffer) {
        self.stamp(gpu, cmd, vk::PipelineStageFlags::BOTTOM_OF_PIPE, 2);
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
        unsafe { gpu.device.destroy_query_pool(self.pool, None) };
    }
}
