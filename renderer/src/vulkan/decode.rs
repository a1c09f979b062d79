//! Compact levels decoded on the GPU (`spirv/shaders/decode.comp`, issue 28): a level's bit
//! stream ([`tiles::compact`]) becomes its block of packed positions in the tile pool, from the
//! tile's coarser blocks already there, so that a refinement can cross the bus as the heights
//! it adds and which vertices they are, about a third of the positions' bytes. One workgroup
//! decodes one level, with a grid of height codes of its own (scratch); a dispatch decodes as
//! many levels as there are grids. Each frame slot has its own list and a status word the
//! shader raises, with a reason, when a stream is not a level of its tile.
//!
//! The block's vertices come out in the order the stream gives them
//! ([`tiles::compact::decode_levels`]): its raw vertices, then the walk's. The CPU decoder
//! makes the same sets in the same order, and `renderer/tests/decode.rs` compares the two
//! word for word on every level of real tiles.

use ash::vk;
use bytemuck::{Pod, Zeroable};

use super::compute::{self, PassBuffers, StoragePass};
use super::sync;
use super::{Buffer, Gpu, VkResult};

/// Levels decoded at once at most, each with a grid of 257 x 257 codes.
pub const MAX_DECODES_PER_DISPATCH: u32 = 8;
const GRID_BYTES: u64 = 257 * 257 * 4;

/// One level to decode (the shader's `Decode`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct Decode {
    /// The level's first bit in the streams buffer, and the bit after its last byte.
    pub stream_bit: u32,
    pub end_bit: u32,
    /// Pool word of block 0's first packed position, and the vertices of the coarser blocks.
    pub known_word: u32,
    pub known_count: u32,
    /// Pool word of the level's block, and the vertices the file says it holds.
    pub out_word: u32,
    pub expected: u32,
    /// Reported when the decode fails.
    pub tile: u32,
    pub level: u32,
}

/// Why the shader refused a stream (its reason codes).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Refusal {
    /// It ends before the level does, or runs past the level's bytes.
    EndsEarly,
    /// A raw vertex lies outside the grid or is known already.
    RawVertex,
    /// More vertices than the block holds.
    TooMany,
    /// A Rice parameter over 16.
    RiceParameter,
    /// A height code outside 0..=16383.
    CodeRange,
    /// Fewer vertices than the block holds.
    Count,
    /// Whole bytes left after the level's last code.
    BitsLeft,
    /// The coarser blocks hold a point outside the grid (not the tile's blocks).
    CoarserBlocks,
    Unknown(u32),
}

impl Refusal {
    fn from_code(code: u32) -> Self {
        match code {
            1 => Refusal::EndsEarly,
            2 => Refusal::RawVertex,
            3 => Refusal::TooMany,
            4 => Refusal::RiceParameter,
            5 => Refusal::CodeRange,
            6 => Refusal::Count,
            7 => Refusal::BitsLeft,
            8 => Refusal::CoarserBlocks,
            c => Refusal::Unknown(c),
        }
    }
}

/// A decode that failed (read after its frame completed): the first of `failed`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DecodeFailure {
    pub failed: u32,
    pub tile: u32,
    pub level: u32,
    pub reason: Refusal,
}

pub struct Decoder {
    pass: StoragePass,
    /// The grids (scratch), and per frame slot the decodes and the status.
    buffers: PassBuffers,
    capacity: usize,
    /// Grids in the scratch: workgroups per dispatch.
    groups: u32,
}

impl Decoder {
    /// A decoder writing into `pool`, for as many frame slots as `streams` (each slot's
    /// streams buffer, its staging memory in a frame) of up to `capacity` decodes each,
    /// `groups` (1 to [`MAX_DECODES_PER_DISPATCH`]) levels at once.
    pub fn new(
        gpu: &Gpu,
        pool: &Buffer,
        streams: &[&Buffer],
        capacity: usize,
        groups: u32,
    ) -> VkResult<Self> {
        let groups = groups.clamp(1, MAX_DECODES_PER_DISPATCH);
        let capacity = capacity.max(1);
        let sizes = (
            GRID_BYTES * u64::from(groups),
            (capacity * std::mem::size_of::<Decode>()) as u64,
        );
        let buffers = PassBuffers::new(gpu, sizes, streams.len(), "decode")?;
        let limit = u64::from(gpu.properties.limits.max_storage_buffer_range);
        let slots: Vec<Vec<(&Buffer, u64)>> = streams
            .iter()
            .enumerate()
            .map(|(s, &stream)| {
                vec![
                    (pool, pool.size.min(limit)),
                    (stream, stream.size.min(limit)),
                    (&buffers.scratch, vk::WHOLE_SIZE),
                    (&buffers.lists[s], vk::WHOLE_SIZE),
                    (&buffers.status[s], vk::WHOLE_SIZE),
                ]
            })
            .collect();
        match StoragePass::new(gpu, (spirv::DECODE_COMP, "decode"), 4, &slots) {
            Ok(pass) => Ok(Decoder {
                pass,
                buffers,
                capacity,
                groups,
            }),
            Err(e) => {
                buffers.destroy(gpu);
                Err(e)
            }
        }
    }

    /// Decodes a slot's list holds.
    pub fn capacity(&self) -> usize {
        self.capacity
    }

    /// Bytes of GPU memory the decoder holds beside the pool and the streams.
    pub fn bytes(&self) -> u64 {
        self.buffers.bytes()
    }

    /// Writes slot `s`'s decodes (its previous frame has completed); false if they do not fit.
    pub fn write(&mut self, s: usize, decodes: &[Decode]) -> bool {
        decodes.len() <= self.capacity
            && self.buffers.lists[s].write(0, bytemuck::cast_slice(decodes))
    }

    /// Who reads the blocks the decodes write: the index builds and the morph pass, the
    /// vertex shaders, and the copies (a chunk moved).
    pub const READERS: sync::Scope = (
        vk::PipelineStageFlags::from_raw(
            vk::PipelineStageFlags::COMPUTE_SHADER.as_raw()
                | vk::PipelineStageFlags::VERTEX_SHADER.as_raw()
                | vk::PipelineStageFlags::TRANSFER.as_raw(),
        ),
        vk::AccessFlags::from_raw(
            vk::AccessFlags::SHADER_READ.as_raw() | vk::AccessFlags::TRANSFER_READ.as_raw(),
        ),
    );

    /// Records slot `s`'s decodes, listed in `waves` (how many in each, in the list's order):
    /// after the copies that brought their coarser blocks (and earlier frames' reads of the
    /// blocks they write), before whatever reads the blocks (`readers`: stages and accesses).
    /// A wave's decodes run side by side; each wave sees the blocks the waves before it wrote,
    /// so a tile's finer level goes in a later wave than its coarser one.
    pub fn record(
        &self,
        gpu: &Gpu,
        cmd: vk::CommandBuffer,
        (s, waves): (usize, &[u32]),
        readers: sync::Scope,
    ) {
        if waves.iter().all(|&n| n == 0) {
            return;
        }
        let compute = vk::PipelineStageFlags::COMPUTE_SHADER;
        let shader = vk::AccessFlags::SHADER_READ | vk::AccessFlags::SHADER_WRITE;
        let earlier = vk::PipelineStageFlags::VERTEX_INPUT
            | vk::PipelineStageFlags::VERTEX_SHADER
            | vk::PipelineStageFlags::TRANSFER
            | vk::PipelineStageFlags::HOST
            | compute;
        let written = vk::AccessFlags::TRANSFER_WRITE
            | vk::AccessFlags::SHADER_WRITE
            | vk::AccessFlags::HOST_WRITE;
        sync::memory_barrier(gpu, cmd, (earlier, written), (compute, shader));
        self.pass.bind(gpu, cmd, s);
        let (mut first, mut dispatched) = (0, false);
        for &wave in waves {
            let end = first + wave;
            while first < end {
                if dispatched {
                    // The next dispatch reuses the grids, and may read blocks this one wrote.
                    sync::memory_barrier(gpu, cmd, (compute, shader), (compute, shader));
                }
                let n = (end - first).min(self.groups);
                self.pass.dispatch(gpu, cmd, bytemuck::bytes_of(&first), n);
                first += n;
                dispatched = true;
            }
        }
        sync::memory_barrier(gpu, cmd, (compute, vk::AccessFlags::SHADER_WRITE), readers);
    }

    /// After slot `s`'s frame completed: its first failed decode, if any (and the status is
    /// cleared for the slot's next frame).
    pub fn take_failure(&mut self, s: usize) -> Option<DecodeFailure> {
        let words = compute::take_status(&mut self.buffers.status[s])?;
        Some(DecodeFailure {
            failed: words[0],
            tile: words[1],
            level: words[2],
            reason: Refusal::from_code(words[3]),
        })
    }

    pub fn destroy(self, gpu: &Gpu) {
        self.pass.destroy(gpu);
        self.buffers.destroy(gpu);
    }
}
