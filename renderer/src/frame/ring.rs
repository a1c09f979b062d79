//! The ring of frames in flight: a slot per frame, each with what one frame needs of its own;
//! starting a frame waits only for the frame that last used its slot, and frames come back as
//! [`Finished`] when their fence has signalled.

use std::time::Instant;

use ash::vk;

use super::{DrawnTile, Finished, ReadBack, Renderer};
use crate::log::FrameRecord;
use crate::target::Target;
use crate::vulkan::buffer::BufferDesc;
use crate::vulkan::pool::Staging;
use crate::vulkan::sync::{self, Commands};
use crate::vulkan::timestamps::Timestamps;
use crate::vulkan::{Buffer, Gpu, VkError, VkResult};

/// Morphed heights (device memory, written by the morph pass, read by the vertex shader; a
/// transfer destination for `Fault::Unsynchronised` alone), for a slot or a replayed frame.
pub(super) fn morphed_buffer(gpu: &Gpu, size: u64, name: &str) -> VkResult<Buffer> {
    Buffer::new(
        gpu,
        BufferDesc {
            size,
            usage: vk::BufferUsageFlags::STORAGE_BUFFER | vk::BufferUsageFlags::TRANSFER_DST,
            location: gpu_allocator::MemoryLocation::GpuOnly,
        },
        name,
    )
}

/// A frame submitted from a slot and not yet collected.
struct Pending {
    record: FrameRecord,
    screenshot: bool,
    /// With read-back: the draws whose heights the slot's buffer receives, and how many
    /// heights they write.
    read_back: Option<(Vec<DrawnTile>, usize)>,
    started: Instant,
    submitted: Instant,
    /// When the next frame started (the end of this frame's CPU interval).
    ended: Option<Instant>,
}

/// One frame in flight's own objects.
pub(super) struct Slot {
    pub(super) cmd: vk::CommandBuffer,
    pub(super) fence: vk::Fence,
    pub(super) acquired: vk::Semaphore,
    pub(super) timestamps: Timestamps,
    pub(super) stitch: Buffer,
    pub(super) records: Buffer,
    /// The vertex shader's heights (read-back; 16 bytes unused otherwise).
    pub(super) heights: Buffer,
    /// The morph pass's heights for the frame's draws (`memory::budget`'s share: draws past
    /// it are drawn unmorphed).
    pub(super) morphed: Buffer,
    pub(super) staging: Staging,
    pub(super) target: Target,
    pending: Option<Pending>,
}

/// The bytes of a slot's buffers and its targets' extent.
#[derive(Clone, Copy)]
pub(super) struct SlotSizes {
    pub(super) stitch: u64,
    pub(super) records: u64,
    pub(super) heights: u64,
    pub(super) morphed: u64,
    pub(super) staging: u64,
    pub(super) extent: (u32, u32),
}

impl Slot {
    pub(super) fn new(
        gpu: &Gpu,
        commands: &Commands,
        i: usize,
        sizes: SlotSizes,
    ) -> VkResult<Slot> {
        Ok(Slot {
            cmd: commands.allocate(gpu, &format!("frame slot {i} commands"))?,
            fence: sync::fence(gpu, false, &format!("frame slot {i} fence"))?,
            acquired: sync::semaphore(gpu, &format!("frame slot {i} image acquired"))?,
            timestamps: Timestamps::new(gpu, &format!("frame slot {i} timestamps"))?,
            stitch: Buffer::new(
                gpu,
                BufferDesc::upload(sizes.stitch, vk::BufferUsageFlags::INDEX_BUFFER),
                &format!("frame slot {i} stitch geometry"),
            )?,
            records: Buffer::new(
                gpu,
                BufferDesc::upload(
                    sizes.records,
                    vk::BufferUsageFlags::STORAGE_BUFFER | vk::BufferUsageFlags::UNIFORM_BUFFER,
                ),
                &format!("frame slot {i} tile records"),
            )?,
            heights: Buffer::new(
                gpu,
                BufferDesc::readback_storage(sizes.heights),
                &format!("frame slot {i} heights read back"),
            )?,
            morphed: morphed_buffer(
                gpu,
                sizes.morphed,
                &format!("frame slot {i} morphed heights"),
            )?,
            staging: Staging::new(gpu, sizes.staging, &format!("frame slot {i} staging"))?,
            target: Target::new(gpu, sizes.extent.0, sizes.extent.1)?,
            pending: None,
        })
    }

    pub(super) fn destroy(self, gpu: &Gpu) {
        sync::destroy_fence(gpu, self.fence);
        sync::destroy_semaphore(gpu, self.acquired);
        self.timestamps.destroy(gpu);
        self.stitch.destroy(gpu);
        self.records.destroy(gpu);
        self.heights.destroy(gpu);
        self.morphed.destroy(gpu);
        self.staging.destroy(gpu);
        self.target.destroy(gpu);
    }

    /// Keeps the frame just submitted from this slot until it is collected.
    pub(super) fn submitted(
        &mut self,
        record: FrameRecord,
        screenshot: bool,
        read_back: Option<(Vec<DrawnTile>, usize)>,
        started: Instant,
    ) {
        self.pending = Some(Pending {
            record,
            screenshot,
            read_back,
            started,
            submitted: Instant::now(),
            ended: None,
        });
    }
}

impl Renderer {
    /// Makes the next frame's slot free (waiting for the frame that last used it, and
    /// collecting any older frames already done); returns the semaphore a window image must be
    /// acquired with, and the frames finished meanwhile.
    pub fn begin_frame(&mut self, gpu: &Gpu) -> VkResult<(vk::Semaphore, Vec<Finished>)> {
        let n = self.slots.len() as u64;
        let slot = (self.frame % n) as usize;
        if self.slot_ready.is_some() {
            return Ok((self.slots[slot].acquired, Vec::new()));
        }
        let now = Instant::now();
        if let Some(prev) = self.frame.checked_sub(1) {
            if let Some(p) = self.slots[(prev % n) as usize].pending.as_mut() {
                p.ended.get_or_insert(now);
            }
        }
        // Oldest first: the slot's own frame (frame - n) must finish; later ones only if done.
        let mut finished = Vec::new();
        for f in self.frame.saturating_sub(n)..self.frame {
            let s = (f % n) as usize;
            if self.slots[s].pending.is_none() {
                continue;
            }
            if s != slot && !sync::is_signalled(gpu, self.slots[s].fence)? {
                break;
            }
            finished.push(self.collect(gpu, s)?);
        }
        self.slot_ready = Some(now);
        Ok((self.slots[slot].acquired, finished))
    }

    /// The newest frame after which every frame has finished.
    pub(super) fn completed(&self) -> Option<u64> {
        let n = self.slots.len() as u64;
        let oldest_pending = (self.frame.saturating_sub(n)..self.frame)
            .find(|f| self.slots[(f % n) as usize].pending.is_some());
        match oldest_pending {
            Some(f) => f.checked_sub(1),
            None => self.frame.checked_sub(1),
        }
    }

    /// Waits for the slot's frame and completes its record.
    fn collect(&mut self, gpu: &Gpu, s: usize) -> VkResult<Finished> {
        let slot = &mut self.slots[s];
        let Some(p) = slot.pending.take() else {
            return Err(VkError::Unsupported("no frame pending".into()));
        };
        sync::wait_and_reset(gpu, slot.fence)?;
        if let Some(f) = self.decoder.as_mut().and_then(|d| d.take_failure(s)) {
            return Err(VkError::InvalidData(super::uploads::decode_failure(f)));
        }
        if let Some(f) = self.builder.as_mut().and_then(|b| b.take_failure(s)) {
            return Err(VkError::InvalidData(super::uploads::build_failure(f)));
        }
        let slot = &mut self.slots[s];
        let mut record = p.record;
        // frame_ms: the interval between this frame's and the previous frame's completion on
        // the GPU (the cadence a display sees, whatever runs ahead); the first frame costs its
        // CPU time to submission plus its GPU time. Without timestamps: the CPU interval.
        record.pass_statistics = slot.timestamps.read_statistics(gpu);
        match slot.timestamps.read_ticks(gpu) {
            Some(t) => {
                record.gpu_ms = slot.timestamps.ms_between(t[0], t[3]);
                record.gpu_draw_ms = slot.timestamps.ms_between(t[1], t[2]);
                record.frame_ms = match self.last_end {
                    Some(prev) => slot.timestamps.ms_between(prev, t[3]),
                    None => (p.submitted - p.started).as_secs_f64() * 1000.0 + record.gpu_ms,
                };
                self.last_end = Some(t[3]);
            }
            None => {
                (record.gpu_ms, record.gpu_draw_ms) = (f64::NAN, f64::NAN);
                let end = p.ended.unwrap_or_else(Instant::now);
                record.frame_ms = (end - p.started).as_secs_f64() * 1000.0;
            }
        }
        let pixels = if p.screenshot {
            slot.target.pixels()
        } else {
            None
        };
        let heights = p.read_back.map(|(draws, n)| {
            let values = slot.heights.mapped().map_or_else(Vec::new, |m| {
                bytemuck::cast_slice::<u8, f32>(&m[..(4 * n).min(m.len()) / 4 * 4]).to_vec()
            });
            ReadBack { draws, values }
        });
        let e = slot.target.extent();
        Ok(Finished {
            record,
            pixels,
            extent: (e.width, e.height),
            heights,
        })
    }

    /// Waits for every frame in flight; returns them, oldest first.
    pub fn finish_all(&mut self, gpu: &Gpu) -> VkResult<Vec<Finished>> {
        let n = self.slots.len() as u64;
        let mut finished = std::mem::take(&mut self.collected);
        for f in self.frame.saturating_sub(n)..self.frame {
            let s = (f % n) as usize;
            if self.slots[s].pending.is_some() {
                finished.push(self.collect(gpu, s)?);
            }
        }
        // The GPU idles from here until the next submission: the next frame's interval starts
        // afresh (its CPU time plus its GPU time, as the first frame's).
        self.last_end = None;
        Ok(finished)
    }

    /// Waits for every frame in flight, then forgets every tile: the pool is empty, as at
    /// start, while the driver keeps whatever it warmed up (`vkterrain --warmup-driver`).
    pub fn forget_tiles(&mut self, gpu: &Gpu) -> VkResult<()> {
        self.finish_all(gpu)?;
        self.manager.forget_all();
        if let Some(slots) = &mut self.texture_slots {
            *slots = memory::textures::TextureSlots::new(slots.config().clone());
        }
        Ok(())
    }

    /// New render targets for a new window size (after every frame in flight finished).
    pub fn resize(&mut self, gpu: &Gpu, extent: (u32, u32)) -> VkResult<Vec<Finished>> {
        let finished = self.finish_all(gpu)?;
        gpu.wait_idle();
        for slot in &mut self.slots {
            let target = Target::new(gpu, extent.0, extent.1)?;
            std::mem::replace(&mut slot.target, target).destroy(gpu);
        }
        Ok(finished)
    }
}
