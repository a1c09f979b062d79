//! The tile pool: one buffer of device memory, allocated at start, that holds every chunk the
//! memory manager hands out; the staging ring that feeds it when the CPU cannot (or must not)
//! write it directly; and the barriers that order it all against the frames in flight.
//!
//! Two transfer paths. Where device memory is host-visible and coherent (unified memory:
//! lavapipe, integrated GPUs) the CPU writes tile data straight into the pool, but only into
//! ranges no frame in flight reads (the manager guarantees that for new blocks and fresh
//! chunks and flags the rest). Everything else, all uploads on a discrete GPU, or all of them
//! with `--force-staging`, goes through the ring and a copy recorded at the start of the frame,
//! after a barrier that waits for earlier frames' reads of the pool.

use ash::vk;
use gpu_allocator::MemoryLocation;

use super::buffer::BufferDesc;
use super::sync;
use super::{Buffer, Gpu, VkResult};

/// What the pool is bound as.
const POOL_USAGE: vk::BufferUsageFlags = vk::BufferUsageFlags::from_raw(
    vk::BufferUsageFlags::VERTEX_BUFFER.as_raw()
        | vk::BufferUsageFlags::INDEX_BUFFER.as_raw()
        | vk::BufferUsageFlags::STORAGE_BUFFER.as_raw()
        | vk::BufferUsageFlags::TRANSFER_SRC.as_raw()
        | vk::BufferUsageFlags::TRANSFER_DST.as_raw(),
);

pub struct TilePool {
    pub buffer: Buffer,
    direct: bool,
}

impl TilePool {
    /// Allocates `bytes` of device memory, host-mapped when the device has unified memory and
    /// `force_staging` is off.
    pub fn new(gpu: &Gpu, bytes: u64, force_staging: bool) -> VkResult<TilePool> {
        let unified = gpu.unified_memory() && !force_staging;
        let desc = BufferDesc {
            size: bytes.max(4),
            usage: POOL_USAGE,
            location: if unified {
                MemoryLocation::CpuToGpu
            } else {
                MemoryLocation::GpuOnly
            },
        };
        let mut buffer = Buffer::new(gpu, desc, "tile pool")?;
        let direct = unified && buffer.is_coherent() && buffer.mapped().is_some();
        Ok(TilePool { buffer, direct })
    }

    /// Whether the CPU writes tile data straight into the pool.
    pub fn direct(&self) -> bool {
        self.direct
    }

    /// Writes into the pool from the CPU (direct path only).
    pub fn write(&mut self, offset: u64, bytes: &[u8]) -> bool {
        self.direct && self.buffer.write(offset as usize, bytes)
    }

    /// Reads a range back through a GPU copy (for tests and diagnostics; waits for the device).
    pub fn read(&self, gpu: &Gpu, offset: u64, len: u64) -> VkResult<Vec<u8>> {
        gpu.wait_idle();
        let mut readback = Buffer::new(gpu, BufferDesc::readback(len.max(4)), "pool read-back")?;
        let result = sync::run_once(gpu, "pool read-back", |cmd| {
            let region = vk::BufferCopy::default()
                .src_offset(offset)
                .size(len.max(1));
            // SAFETY: recording; both buffers are live and the range lies in the pool.
            unsafe {
                gpu.device
                    .cmd_copy_buffer(cmd, self.buffer.raw, readback.raw, &[region]);
            }
            sync::host_read_barrier(gpu, cmd);
        })
        .map(|()| {
            readback
                .mapped()
                .map(|m| m[..len as usize].to_vec())
                .unwrap_or_default()
        });
        readback.destroy(gpu);
        result
    }

    pub fn destroy(self, gpu: &Gpu) {
        self.buffer.destroy(gpu);
    }
}

/// A frame slot's share of the staging ring: host-visible, filled from the start each time the
/// slot is reused (after its fence), so no frame in flight reads what is written.
pub struct Staging {
    buffer: Buffer,
    used: u64,
    /// Payload bytes pushed (`used` less alignment padding).
    sent: u64,
}

impl Staging {
    pub fn new(gpu: &Gpu, bytes: u64, name: &str) -> VkResult<Staging> {
        let buffer = Buffer::new(
            gpu,
            // Copies read it; so does the compact levels' decoder (`vulkan::decode`).
            BufferDesc::upload(
                bytes.max(4),
                vk::BufferUsageFlags::TRANSFER_SRC | vk::BufferUsageFlags::STORAGE_BUFFER,
            ),
            name,
        )?;
        Ok(Staging {
            buffer,
            used: 0,
            sent: 0,
        })
    }

    pub fn reset(&mut self) {
        (self.used, self.sent) = (0, 0);
    }

    /// Copies `bytes` in; returns their offset, or None when the slot is full.
    pub fn push(&mut self, bytes: &[u8]) -> Option<u64> {
        let at = self.used.next_multiple_of(4);
        let end = at + bytes.len() as u64;
        if end > self.buffer.size || !self.buffer.write(at as usize, bytes) {
            return None;
        }
        self.used = end;
        self.sent += bytes.len() as u64;
        Some(at)
    }

    /// Copies `bytes` in at an offset that is a multiple of `align` (a power of two, at least
    /// 4); returns the offset, or None when the slot is full.
    pub fn push_aligned(&mut self, bytes: &[u8], align: u64) -> Option<u64> {
        let before = self.used;
        self.used = self.used.next_multiple_of(align);
        let at = self.push(bytes);
        if at.is_none() {
            self.used = before;
        }
        at
    }

    pub fn used(&self) -> u64 {
        self.used
    }

    /// The buffer itself (the decoder binds it).
    pub fn buffer(&self) -> &Buffer {
        &self.buffer
    }

    /// The buffer copies read from.
    pub fn raw(&self) -> vk::Buffer {
        self.buffer.raw
    }

    /// Payload bytes pushed since the last reset.
    pub fn sent(&self) -> u64 {
        self.sent
    }

    pub fn destroy(self, gpu: &Gpu) {
        self.buffer.destroy(gpu);
    }
}

/// Records the copies of index arrays made on the CPU (`frame::made`) from the slot's staging
/// memory into the pool, where the GPU's builder would have written them: after earlier
/// frames' reads and the frame's own copies of the regions they rewrite (a chunk moved this
/// frame), and visible to whatever reads the pool after them.
pub fn record_made(
    gpu: &Gpu,
    cmd: vk::CommandBuffer,
    pool: &TilePool,
    staging: &Staging,
    made: &[vk::BufferCopy],
) {
    if made.is_empty() {
        return;
    }
    let transfer = vk::PipelineStageFlags::TRANSFER;
    let earlier = vk::PipelineStageFlags::VERTEX_INPUT
        | vk::PipelineStageFlags::VERTEX_SHADER
        | vk::PipelineStageFlags::COMPUTE_SHADER
        | transfer;
    let written = vk::AccessFlags::TRANSFER_WRITE | vk::AccessFlags::SHADER_WRITE;
    sync::memory_barrier(
        gpu,
        cmd,
        (earlier, written),
        (transfer, vk::AccessFlags::TRANSFER_WRITE),
    );
    // SAFETY: recording outside rendering; each copy reads the staging slot and writes an
    // index region of the pool that no other copy of the frame writes.
    unsafe {
        gpu.device
            .cmd_copy_buffer(cmd, staging.buffer.raw, pool.buffer.raw, made);
    }
    // Readers: the draws' index reads, and every stage that binds the whole pool as storage
    // (the vertex shader, the morph pass), which synchronisation validation tracks as reads
    // of the regions written here; later copies (a chunk moved) and the host.
    let (readers, reads) = super::indices::IndexBuilder::READERS;
    let storage = vk::PipelineStageFlags::VERTEX_SHADER | vk::PipelineStageFlags::COMPUTE_SHADER;
    sync::memory_barrier(
        gpu,
        cmd,
        (transfer, vk::AccessFlags::TRANSFER_WRITE),
        (readers | storage, reads | vk::AccessFlags::SHADER_READ),
    );
}

/// Records this frame's pool transfers: in-pool moves, then copies from the staging slot, with
/// a barrier before them (earlier frames' reads and writes of the pool come first) and after
/// them (the draws read what they wrote).
pub fn record_transfers(
    gpu: &Gpu,
    cmd: vk::CommandBuffer,
    pool: &TilePool,
    staging: &Staging,
    moves: &[vk::BufferCopy],
    staged: &[vk::BufferCopy],
) {
    if moves.is_empty() && staged.is_empty() {
        return;
    }
    let transfer = vk::PipelineStageFlags::TRANSFER;
    // Write-after-read against earlier frames' draws (vertex input, vertex shader) needs only
    // the execution dependency; earlier transfers' writes are made visible.
    let draws = vk::PipelineStageFlags::VERTEX_INPUT | vk::PipelineStageFlags::VERTEX_SHADER;
    sync::memory_barrier(
        gpu,
        cmd,
        (draws | transfer, vk::AccessFlags::TRANSFER_WRITE),
        (
            transfer,
            vk::AccessFlags::TRANSFER_READ | vk::AccessFlags::TRANSFER_WRITE,
        ),
    );
    // SAFETY: recording outside rendering; regions lie in the pool and the staging slot (the
    // manager never overlaps a move's source and destination).
    unsafe {
        if !moves.is_empty() {
            gpu.device
                .cmd_copy_buffer(cmd, pool.buffer.raw, pool.buffer.raw, moves);
        }
        if !staged.is_empty() {
            gpu.device
                .cmd_copy_buffer(cmd, staging.buffer.raw, pool.buffer.raw, staged);
        }
    }
    let reads = vk::AccessFlags::INDEX_READ
        | vk::AccessFlags::VERTEX_ATTRIBUTE_READ
        | vk::AccessFlags::SHADER_READ;
    sync::memory_barrier(
        gpu,
        cmd,
        (transfer, vk::AccessFlags::TRANSFER_WRITE),
        (draws, reads),
    );
}
