//! Every GPU allocation the frame loop makes, at start: the tile pool (halved until device
//! memory holds it), the texture slots, the index builder, the compact levels' decoder, the
//! pipelines and one slot per frame
//! in flight. How the budget splits between them is decided in `memory::budget`; this file only
//! asks the device for what was decided and undoes what it made when a later step fails.

use ash::vk;
use memory::budget::{self, Split, Textures};
use memory::textures::{TextureConfig, TextureSlots};
use memory::{Config, Manager, Scheme, Victim};

use super::ring::{Slot, SlotSizes};
use super::Renderer;
use crate::fault::Fault;
use crate::interface::{RECORDS_OFFSET, RECORD_BYTES};
use crate::parts::PartDraws;
use crate::prefetch::Prefetcher;
use crate::settings::{MemoryOptions, TextureFormat};
use crate::stitch::MAX_RECORDS;
use crate::target::{COLOR_FORMAT, DEPTH_FORMAT};
use crate::terrain::{cost_of, Terrain};
use crate::tile::Side;
use crate::vulkan::buffer::BufferDesc;
use crate::vulkan::decode::{Decoder, MAX_DECODES_PER_DISPATCH};
use crate::vulkan::indices::{self, IndexBuilder};
use crate::vulkan::morph_pass::{MORPH_GROUPS, MORPH_REGION_BYTES};
use crate::vulkan::pipeline::TerrainPipeline;
use crate::vulkan::pool::TilePool;
use crate::vulkan::sets::{SetBuffers, TerrainSets};
use crate::vulkan::sync::Commands;
use crate::vulkan::texture::{TextureArray, TextureDesc};
use crate::vulkan::{Buffer, Gpu, VkError, VkResult};

/// The smallest pool worth trying when device memory runs short.
const MIN_POOL: u64 = 1 << 20;

/// What [`Renderer::new`] has made so far beside the pool, destroyed together when a later
/// step fails.
#[derive(Default)]
struct Parts {
    textures: Option<TextureArray>,
    commands: Option<Commands>,
    pipeline: Option<TerrainPipeline>,
    slots: Vec<Slot>,
    builder: Option<IndexBuilder>,
    decoder: Option<Decoder>,
    morph_scratch: Option<Buffer>,
    sets: Option<TerrainSets>,
}

/// [`Parts`] once every step made its part: what the frame loop holds.
struct Made {
    textures: TextureArray,
    commands: Commands,
    pipeline: TerrainPipeline,
    slots: Vec<Slot>,
    builder: Option<IndexBuilder>,
    decoder: Option<Decoder>,
    morph_scratch: Buffer,
    sets: Option<TerrainSets>,
}

impl Parts {
    /// The parts as the loop holds them, or the parts to destroy if a step returned without
    /// making its part.
    fn complete(self) -> Result<Made, Box<Parts>> {
        match self {
            Parts {
                textures: Some(textures),
                commands: Some(commands),
                pipeline: Some(pipeline),
                slots,
                builder,
                decoder,
                morph_scratch: Some(morph_scratch),
                sets,
            } => Ok(Made {
                textures,
                commands,
                pipeline,
                slots,
                builder,
                decoder,
                morph_scratch,
                sets,
            }),
            incomplete => Err(Box::new(incomplete)),
        }
    }

    fn destroy(self, gpu: &Gpu) {
        gpu.wait_idle();
        if let Some(s) = self.sets {
            s.destroy(gpu);
        }
        if let Some(b) = self.builder {
            b.destroy(gpu);
        }
        if let Some(d) = self.decoder {
            d.destroy(gpu);
        }
        if let Some(b) = self.morph_scratch {
            b.destroy(gpu);
        }
        for s in self.slots {
            s.destroy(gpu);
        }
        if let Some(p) = self.pipeline {
            p.destroy(gpu);
        }
        if let Some(c) = self.commands {
            c.destroy(gpu);
        }
        if let Some(t) = self.textures {
            t.destroy(gpu);
        }
    }
}

impl Renderer {
    /// Plans the pool for `terrain` and allocates everything the loop will use.
    pub fn new(
        gpu: &Gpu,
        terrain: &Terrain,
        extent: (u32, u32),
        options: MemoryOptions,
    ) -> VkResult<Renderer> {
        let split = split_budget(gpu, terrain, &options);
        let config = Config {
            pool_bytes: split.pool_bytes,
            upload_budget: options.upload_budget,
            weight: options.weight,
            class_ratio: 2.0,
            scheme: options.scheme,
            victim: Victim::Mixture,
            downgrade_slack: options.downgrade_slack,
            prefetch_free: options.prefetch.free_share,
            index_arrays: split.index_arrays,
        };
        let fault = Fault::from_env();
        let (mut manager, pool) = allocate_pool(gpu, terrain, config, &options, fault)?;
        if !pool.direct() {
            // Every upload goes through the slot's staging memory (a direct pool is written
            // in place, and only streams decoded on the GPU are staged).
            manager.set_staging_cap(geometry_staging(&manager, &options).1);
        }
        let mut parts = Parts::default();
        let made = make_parts(
            &mut parts,
            gpu,
            terrain,
            (&pool, &manager),
            &options,
            &split,
            extent,
        );
        let made = match made {
            Ok(()) => parts.complete().map_err(|parts| {
                let e = VkError::Unsupported("the frame loop's objects were not all made".into());
                (e, *parts)
            }),
            Err(e) => Err((e, parts)),
        };
        let made = match made {
            Ok(made) => made,
            Err((e, parts)) => {
                parts.destroy(gpu);
                pool.destroy(gpu);
                return Err(e);
            }
        };
        Ok(Renderer {
            pipeline: made.pipeline,
            morph_scratch: made.morph_scratch,
            sets: made.sets,
            commands: made.commands,
            slots: made.slots,
            pool,
            manager,
            textures: made.textures,
            texture_slots: split.textures.config().cloned().map(TextureSlots::new),
            options,
            frame: 0,
            slot_ready: None,
            trace: None,
            last_end: None,
            meter: None,
            fault,
            collected: Vec::new(),
            prefetcher: Prefetcher::new(options.prefetch, terrain.tiles.len()),
            builder: made.builder,
            decoder: made.decoder,
            parts: PartDraws::default(),
        })
    }

    pub fn destroy(self, gpu: &Gpu) {
        gpu.wait_idle();
        if let Some(s) = self.sets {
            s.destroy(gpu);
        }
        for s in self.slots {
            s.destroy(gpu);
        }
        self.pool.destroy(gpu);
        if let Some(b) = self.builder {
            b.destroy(gpu);
        }
        if let Some(d) = self.decoder {
            d.destroy(gpu);
        }
        self.morph_scratch.destroy(gpu);
        self.textures.destroy(gpu);
        self.pipeline.destroy(gpu);
        self.commands.destroy(gpu);
    }
}

/// Makes everything beside the pool into `parts`, in order; stops at the first failure.
fn make_parts(
    parts: &mut Parts,
    gpu: &Gpu,
    terrain: &Terrain,
    (pool, manager): (&TilePool, &Manager),
    options: &MemoryOptions,
    split: &Split,
    extent: (u32, u32),
) -> VkResult<()> {
    let textures = parts
        .textures
        .insert(texture_array(gpu, terrain, options, split)?);
    let commands = parts.commands.insert(Commands::new(gpu, "frame commands")?);
    let read_back = options.read_back_heights;
    if read_back && !gpu.vertex_stores {
        return Err(VkError::Unsupported(
            "reading heights back needs vertexPipelineStoresAndAtomics, which this device lacks"
                .into(),
        ));
    }
    let pipeline = parts.pipeline.insert(TerrainPipeline::new(
        gpu,
        COLOR_FORMAT,
        DEPTH_FORMAT,
        read_back,
    )?);
    let sizes = slot_sizes(terrain, options, manager, split, extent);
    for i in 0..split.frame_slots {
        parts.slots.push(Slot::new(gpu, commands, i, sizes)?);
    }
    if let Some(b) = split.builder {
        let (slots, builds) = (split.frame_slots, split.builds_per_frame);
        let builder = IndexBuilder::new(gpu, &pool.buffer, slots, builds, b.lookups)?;
        parts.builder = Some(builder);
    }
    if decodes_on_gpu(terrain, options) {
        // At most every level of every tile a frame (a new tile sends its levels up to the
        // one wanted whatever the budget), and of no more tiles than a frame may draw: a set
        // larger than that reaches it only through prefetching, which the budget bounds.
        let levels = terrain.levels.max(1) as usize;
        let capacity = terrain.tiles.len().min(MAX_RECORDS) * levels + 8;
        let streams: Vec<&Buffer> = parts.slots.iter().map(|s| s.staging.buffer()).collect();
        let decoder = Decoder::new(
            gpu,
            &pool.buffer,
            &streams,
            capacity,
            MAX_DECODES_PER_DISPATCH,
        )?;
        parts.decoder = Some(decoder);
    }
    // The budget's regions; reading heights back (a diagnostic) morphs every frame, with one
    // region if the budget had none; without any, a placeholder for the set's binding (every
    // frame is then drawn unmorphed).
    let groups = match (split.morph, options.read_back_heights) {
        (Some(m), _) => m.groups,
        (None, true) => 1,
        (None, false) => 0,
    };
    let scratch = parts.morph_scratch.insert(Buffer::new(
        gpu,
        BufferDesc {
            size: (u64::from(groups) * MORPH_REGION_BYTES).max(16),
            usage: vk::BufferUsageFlags::STORAGE_BUFFER,
            location: gpu_allocator::MemoryLocation::GpuOnly,
        },
        "morph pass scratch",
    )?);
    let buffers: Vec<SetBuffers<'_>> = parts
        .slots
        .iter()
        .map(|s| SetBuffers {
            records: &s.records,
            heights: &s.heights,
            morphed: &s.morphed,
        })
        .collect();
    let name = "frame descriptor sets";
    let sets = TerrainSets::new(
        gpu,
        pipeline,
        (&pool.buffer, scratch),
        &buffers,
        textures,
        name,
    )?;
    parts.sets = Some(sets);
    Ok(())
}

/// The texture slots' array as the split sized it (a one-texel placeholder without textures).
fn texture_array(
    gpu: &Gpu,
    terrain: &Terrain,
    options: &MemoryOptions,
    split: &Split,
) -> VkResult<TextureArray> {
    match (split.textures.config(), terrain.texture) {
        (Some(c), Some(layout)) => TextureArray::new(
            gpu,
            TextureDesc {
                format: match options.texture_format {
                    TextureFormat::Bc1 => vk::Format::BC1_RGB_UNORM_BLOCK,
                    TextureFormat::Rgb565 => vk::Format::R5G6B5_UNORM_PACK16,
                },
                size: layout.size,
                mips: layout.mips,
                layers: c.slots as u32,
                anisotropy: options.anisotropy.clamp(1.0, gpu.max_anisotropy),
            },
            "texture slots",
        ),
        _ => TextureArray::placeholder(gpu),
    }
}

/// How `options.gpu_budget_bytes` splits on this device for `terrain` (`memory::budget`),
/// saying on stderr why a tile set's textures are left out.
fn split_budget(gpu: &Gpu, terrain: &Terrain, options: &MemoryOptions) -> Split {
    let limits = &gpu.properties.limits;
    let device = budget::DeviceLimits {
        max_storage_range: u64::from(limits.max_storage_buffer_range),
        max_image_layers: limits.max_image_array_layers,
        storage_16bit: gpu.storage_16bit,
        // (Whether the device samples the slots' format.)
        bc1_textures: match options.texture_format {
            TextureFormat::Bc1 => gpu.bc_textures,
            TextureFormat::Rgb565 => gpu.rgb565_textures,
        },
    };
    let wishes = budget::Wishes {
        gpu_budget: options.gpu_budget_bytes,
        texture_share: options.texture_share,
        textures: options.textures,
        index_arrays: options.index_arrays,
        frames_in_flight: options.frames_in_flight,
        // Always: the window turns geomorphing on and off while it runs.
        morph: Some(budget::MorphCost {
            region_bytes: MORPH_REGION_BYTES,
            max_groups: MORPH_GROUPS,
            vertex_bytes: 4,
            max_vertices: finest_vertices(terrain, options),
        }),
    };
    let set = budget::TileSet {
        tiles: terrain.tiles.len(),
        texture: terrain.texture.map(|layout| budget::MipChain {
            mip_bytes: (0..layout.mips)
                .map(|m| options.texture_format.mip_bytes(&layout, m))
                .collect(),
            mip_texels: (0..layout.mips).map(|m| layout.mip_size(m)).collect(),
        }),
    };
    let split = Split::new(&device, &wishes, &set, &indices::builder_cost());
    match split.textures {
        Textures::NoBc1 => eprintln!(
            "vkterrain: note: the device cannot sample the texture slots' format ({:?}); drawing without the tile set's textures",
            options.texture_format
        ),
        Textures::NoSlot { share, slot_bytes } => eprintln!(
            "vkterrain: note: {:.1} MB of the GPU budget holds no {:.2} MB texture slot; drawing without textures",
            share as f64 / 1e6,
            slot_bytes as f64 / 1e6
        ),
        Textures::Slots(_) | Textures::Absent | Textures::Unwanted => {}
    }
    split
}

/// The sizes of each slot's buffers: stitches and records for every tile in view, heights for
/// every drawn vertex (with read-back), and the staging bounds of `memory::budget`.
fn slot_sizes(
    terrain: &Terrain,
    options: &MemoryOptions,
    manager: &Manager,
    split: &Split,
    extent: (u32, u32),
) -> SlotSizes {
    let textures = split.textures.config();
    SlotSizes {
        stitch: stitch_bound(terrain, manager),
        records: RECORDS_OFFSET + RECORD_BYTES * terrain.tiles.len().clamp(1, MAX_RECORDS) as u64,
        // Every tile at most once a frame, at its finest level at most.
        heights: if options.read_back_heights {
            4 * finest_vertices(terrain, options).max(1)
        } else {
            16
        },
        // The split's share (a placeholder without one: frames are drawn unmorphed); reading
        // heights back (a diagnostic) morphs every draw, past it.
        morphed: if options.read_back_heights {
            4 * finest_vertices(terrain, options).max(1)
        } else {
            split.morph.map_or(4, |m| m.slot_bytes)
        },
        staging: geometry_staging(manager, options).0
            + textures.map_or(0, |c: &TextureConfig| {
                budget::texture_staging_bound(c, options.upload_budget)
            }),
        extent,
    }
}

/// Bytes of a slot's staging memory for tile geometry (`budget::staging_bound`; estimated from
/// the tiles the pool was planned from, exact up to `MemoryOptions::plan_sample` tiles), and
/// what a frame's uploads may send within it: less the padding the uploads' alignment may
/// take (the manager holds new tiles back past it, which the bound over every tile never
/// makes it do).
fn geometry_staging(manager: &Manager, options: &MemoryOptions) -> (u64, u64) {
    let (sample, weight) = manager.planned_from();
    let costs = sample.iter().map(|&t| manager.tile_cost(t));
    let bytes = budget::staging_estimate(costs, weight, options.upload_budget);
    let padding = 4 * 8 * (sample.len() as u64 * weight + 1);
    (bytes, bytes.saturating_sub(padding))
}

/// Whether a compact set's levels travel as their streams, decoded on the GPU
/// (`MemoryOptions::decode_on_gpu`, version 5 compact sets, and not the whole-tile scheme,
/// which sends every level at once as the file's blocks).
pub(super) fn decodes_on_gpu(terrain: &Terrain, options: &MemoryOptions) -> bool {
    options.decode_on_gpu && terrain.has_streams() && options.scheme != Scheme::WholeTile
}

/// Vertices of every tile at its finest level: the most a frame can draw (estimated from the
/// sample of tiles the pool is planned from, `memory::costs`: exact up to
/// `MemoryOptions::plan_sample` tiles).
fn finest_vertices(terrain: &Terrain, options: &MemoryOptions) -> u64 {
    let (sample, weight) = memory::costs::sample(terrain.tiles.len(), options.plan_sample);
    sample
        .iter()
        .filter_map(|&t| terrain.tiles.outline(t as usize).levels.last())
        .map(|l| weight * u64::from(l.vertex_count()))
        .sum()
}

/// Plans and allocates the tile pool; when device memory runs out, halves the budget and tries
/// again (down to [`MIN_POOL`]), saying so once on stderr: a smaller pool only means coarser
/// tiles.
fn allocate_pool(
    gpu: &Gpu,
    terrain: &Terrain,
    mut config: Config,
    options: &MemoryOptions,
    fault: Option<Fault>,
) -> VkResult<(Manager, TilePool)> {
    let mut first = None;
    loop {
        let (morph_rows, decode) = (options.morph_rows, decodes_on_gpu(terrain, options));
        let tiles = std::sync::Arc::clone(&terrain.tiles);
        let source = move |t: memory::TileId| {
            let o = tiles.outline(t as usize);
            cost_of(&o.levels, &o.streams, morph_rows, decode)
        };
        let manager = Manager::from_source(
            terrain.tiles.len(),
            Box::new(source),
            config,
            options.plan_sample,
        );
        let bytes = manager.pool_bytes();
        let wanted = *first.get_or_insert(bytes);
        let result = match fault {
            Some(Fault::OomAbove(limit)) if bytes > limit => Err(VkError::OutOfMemory),
            _ => TilePool::new(gpu, bytes, options.force_staging),
        };
        match result {
            Ok(pool) => {
                if bytes < wanted {
                    eprintln!(
                        "vkterrain: note: out of GPU memory for a {:.1} MB tile pool; flying with {:.1} MB (tiles may be drawn coarser)",
                        wanted as f64 / 1e6,
                        bytes as f64 / 1e6
                    );
                }
                return Ok((manager, pool));
            }
            Err(VkError::OutOfMemory | VkError::Allocation(_)) if bytes / 2 >= MIN_POOL => {
                config.pool_bytes = bytes / 2;
            }
            Err(e) => return Err(e),
        }
    }
}

/// Every tile's costs as the manager holds them.
pub(super) fn tile_costs(manager: &Manager) -> Vec<memory::TileCost> {
    (0..manager.tile_count())
        .map(|t| manager.tile_cost(t as u32).clone())
        .collect()
}

/// Bytes of stitch geometry a frame can need at most: every pair of neighbouring tiles, each
/// side at its longest border (a 4-index fan per triangle, fewer triangles than vertices), as
/// the level tables say: summed over the tiles the pool was planned from, each for the tiles it
/// stands for (`Manager::planned_from`; every tile of a set of up to
/// `MemoryOptions::plan_sample`).
fn stitch_bound(terrain: &Terrain, manager: &Manager) -> u64 {
    let longest = |t: usize, side: Side| {
        terrain
            .tiles
            .outline(t)
            .levels
            .iter()
            .map(|l| u64::from(l.border_len[side.index()]))
            .max()
            .unwrap_or(0)
            // A side holds at most a vertex per sample (a tile not checked yet may say more).
            .min(u64::from(tiles::mesh::TILE_CELLS) + 1)
    };
    let (sample, weight) = manager.planned_from();
    let mut bytes = 0;
    for i in sample.into_iter().map(|t| t as usize) {
        let (layer, tx, ty) = terrain.tiles.place(i);
        for side in Side::FORWARD {
            if let Some(j) = terrain.tiles.at(layer, tx, ty, side.step()) {
                bytes += weight * 16 * (longest(i, side) + longest(j, side.opposite()));
            }
        }
        // A pyramid layer's tile may meet the two tiles of the layer below on any side
        // instead (`stitch::stitch_across`), each side of them at most a vertex per sample.
        if layer > 0 {
            let finer = 2 * (u64::from(tiles::mesh::TILE_CELLS) + 1);
            bytes += weight
                * Side::ALL
                    .iter()
                    .map(|&side| 16 * (longest(i, side) + finer))
                    .sum::<u64>();
        }
    }
    bytes.max(4)
}
