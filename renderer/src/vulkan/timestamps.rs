//! GPU frame time from timestamp queries: two per frame, read after the frame's fence.

use ash::vk;

use super::{Gpu, VkResult};

pub struct Timestamps {
    pool: vk::QueryPool,
    /// Nanoseconds per tick; 0 when the queue cannot time.
    period_ns: f64,
}

impl Timestamps {
    pub fn new(gpu: &Gpu) -> VkResult<Timestamps> {
        let info = vk::QueryPoolCreateInfo::default()
            .query_type(vk::QueryType::TIMESTAMP)
            .query_count(2);
        // SAFETY: valid create info.
        let pool = unsafe { gpu.device.create_query_pool(&info, None) }?;
        gpu.name(pool, "frame timestamps");
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

    pub fn begin(&self, gpu: &Gpu, cmd: vk::CommandBuffer) {
        // SAFETY: cmd is recording; the pool has two queries.
        unsafe {
            gpu.device.cmd_reset_query_pool(cmd, self.pool, 0, 2);
            gpu.device
                .cmd_write_timestamp(cmd, vk::PipelineStageFlags::TOP_OF_PIPE, self.pool, 0);
        }
    }

    pub fn end(&self, gpu: &Gpu, cmd: vk::CommandBuffer) {
        // SAFETY: as above.
        unsafe {
            gpu.device.cmd_write_timestamp(
                cmd,
                vk::PipelineStageFlags::BOTTOM_OF_PIPE,
                self.pool,
                1,
            )
        };
    }

    /// Milliseconds between the two stamps of the finished frame, if the queue can time.
    pub fn read_ms(&self, gpu: &Gpu) -> Option<f64> {
        if self.period_ns == 0.0 {
            return None;
        }
        let mut ticks = [0u64; 2];
        // SAFETY: the frame's fence was waited on, so both results are available.
        unsafe {
            gpu.device.get_query_pool_results(
                self.pool,
                0,
                &mut ticks,
                vk::QueryResultFlags::TYPE_64,
            )
        }
        .ok()?;
        Some(ticks[1].saturating_sub(ticks[0]) as f64 * self.period_ns / 1e6)
    }

    pub fn destroy(self, gpu: &Gpu) {
        // SAFETY: no frame in flight uses the pool.
        unsafe { gpu.device.destroy_query_pool(self.pool, None) };
    }
}
