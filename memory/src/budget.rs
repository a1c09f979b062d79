//! How the GPU budget (`--gpu-budget-mb`) is split, decided once at start from plain numbers.
//! The texture slots get the user's share of the budget, as many whole slots as it holds (at
//! most one per tile and the device's array layers). The GPU index builder gets at most an
//! eighth: it saves bus bytes, not pool bytes, so it must not crowd out tile data; as many
//! lookups (arrays built at once) as fit, none below a few MB, and index arrays are then sent.
//! The morph pass, while geomorphing, gets at most a sixteenth: half for its scratch regions
//! (as many as fit), half for each frame slot's morphed heights (a float per vertex a frame
//! draws, at most every tile at its finest level); none when not one region and
//! [`MIN_MORPHED_VERTICES`] a slot fit (frames are then drawn unmorphed).
//! The tile pool gets the rest, at most what one storage-buffer binding can read, since the
//! shaders read the whole pool through one. Also here: the staging bytes a frame can need,
//! derived from the managers' budget rules ([`staging_bound`], [`texture_staging_bound`]).
//!
//! ```
//! use memory::budget::{BuilderCost, DeviceLimits, Split, TileSet, Wishes};
//! use memory::IndexArrays;
//!
//! let device = DeviceLimits {
//!     max_storage_range: 128 << 20,
//!     max_image_layers: 2048,
//!     storage_16bit: true,
//!     bc1_textures: true,
//! };
//! let wishes = Wishes {
//!     gpu_budget: 256 << 20,
//!     texture_share: 0.25,
//!     textures: true,
//!     index_arrays: IndexArrays::Built,
//!     frames_in_flight: 2,
//!     morph: None,
//! };
//! let builder = BuilderCost {
//!     lookup_bytes: 257 * 257 * 4,
//!     build_bytes: 32,
//!     status_bytes: 16,
//!     max_lookups: 8,
//! };
//! let set = TileSet { tiles: 100, texture: None };
//! let split = Split::new(&device, &wishes, &set, &builder);
//! // All eight lookups fit in the eighth (32 MiB): arrays are built.
//! assert_eq!(split.index_arrays, IndexArrays::Built);
//! assert_eq!(split.builder.map(|b| b.lookups), Some(8));
//! // No textures in the set: the pool gets the rest, capped at the 128 MiB one binding reads.
//! assert_eq!(split.pool_bytes, 128 << 20);
//! ```

use crate::cost::TileCost;
use crate::manager::IndexArrays;
use crate::textures::TextureConfig;

/// What the device allows, as plain numbers (Vulkan limits and features).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DeviceLimits {
    /// `maxStorageBufferRange`: bytes one storage-buffer binding can read.
    pub max_storage_range: u64,
    /// `maxImageArrayLayers`: the texture slots are layers of one array image.
    pub max_image_layers: u32,
    /// `storageBuffer16BitAccess`: the index builder's shader needs it.
    pub storage_16bit: bool,
    /// Whether BC1 textures can be sampled (`textureCompressionBC`).
    pub bc1_textures: bool,
}

/// What the user asked for.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Wishes {
    /// Bytes of device memory for textures, the index builder and the tile pool together.
    pub gpu_budget: u64,
    /// The share of `gpu_budget` the texture slots may take (clamped to 0..=1).
    pub texture_share: f64,
    /// Texture slots when the tile set has textures (false: geometry only).
    pub textures: bool,
    /// Built on the GPU when the device and the budget allow, else sent.
    pub index_arrays: IndexArrays,
    /// Frames recorded ahead (at least one): the builder has a build list per frame.
    pub frames_in_flight: usize,
    /// The morph pass's needs while geomorphing with it (None: it does not run).
    pub morph: Option<MorphCost>,
}

/// The morph pass's GPU memory (`renderer/src/vulkan/morph_pass.rs`): a scratch region per
/// workgroup, and per frame slot the morphed heights of the frame's drawn vertices.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MorphCost {
    pub region_bytes: u64,
    /// Workgroups at most (regions beyond it are not allocated).
    pub max_groups: u32,
    /// Bytes of one vertex's morphed height.
    pub vertex_bytes: u64,
    /// The most vertices a frame can draw: every tile at its finest level.
    pub max_vertices: u64,
}

/// The morph pass the budget holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MorphSize {
    /// Workgroups (scratch regions).
    pub groups: u32,
    /// Bytes of each frame slot's morphed heights: a frame drawing more vertices draws the
    /// tiles past them unmorphed.
    pub slot_bytes: u64,
    /// All of it: the regions and every slot's heights.
    pub bytes: u64,
}

impl MorphCost {
    /// What a sixteenth of `budget` holds for `slots` frame slots (module header), if enough.
    pub fn size(&self, budget: u64, slots: usize) -> Option<MorphSize> {
        let half = budget / 32;
        let slots = slots.max(1) as u64;
        let mut groups = self.max_groups.max(1);
        while groups > 1 && u64::from(groups) * self.region_bytes > half {
            groups /= 2;
        }
        let whole = self.max_vertices.max(1).saturating_mul(self.vertex_bytes);
        let slot_bytes = (half / slots).min(whole);
        let fits = u64::from(groups) * self.region_bytes <= half
            && slot_bytes >= (MIN_MORPHED_VERTICES * self.vertex_bytes).min(whole);
        fits.then(|| MorphSize {
            groups,
            slot_bytes,
            bytes: u64::from(groups) * self.region_bytes + slots * slot_bytes,
        })
    }
}

/// The fewest vertices a frame slot's morphed heights are worth having for (a few tiles at
/// their middle levels; fewer when the set has fewer at its finest).
pub const MIN_MORPHED_VERTICES: u64 = 1 << 16;

/// One tile's texture mip chain, as the tile set stores it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct MipChain {
    /// Bytes of each mip, finest first.
    pub mip_bytes: Vec<u64>,
    /// Texels across each mip, finest first.
    pub mip_texels: Vec<u32>,
}

impl MipChain {
    /// Bytes of one slot (the whole chain).
    pub fn slot_bytes(&self) -> u64 {
        self.mip_bytes.iter().sum()
    }
}

/// The tile set's sizes.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TileSet {
    pub tiles: usize,
    /// Every tile's texture chain; None when the set has no textures.
    pub texture: Option<MipChain>,
}

/// The index builder's GPU memory: a lookup (257 x 257 words) per array built at once, and per
/// frame slot a list of builds and a status word. The renderer fills it from its constants
/// (`renderer/src/vulkan/indices.rs`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BuilderCost {
    pub lookup_bytes: u64,
    /// Bytes of one build in a slot's list (the shader's `Build`).
    pub build_bytes: u64,
    pub status_bytes: u64,
    /// Arrays built at once at most (lookups beyond it are not allocated).
    pub max_lookups: u32,
}

impl BuilderCost {
    /// Bytes of a builder with `slots` frame slots of `capacity` builds each and `lookups`
    /// lookups (each clamped to at least one, lookups to at most `max_lookups`).
    pub fn bytes(&self, slots: usize, capacity: usize, lookups: u32) -> u64 {
        self.lookup_bytes * u64::from(lookups.min(self.max_lookups).max(1))
            + slots.max(1) as u64 * (capacity.max(1) as u64 * self.build_bytes + self.status_bytes)
    }
}

/// The texture slots, or why there are none.
#[derive(Clone, Debug, PartialEq)]
pub enum Textures {
    /// At least one slot of the set's chain.
    Slots(TextureConfig),
    /// The tile set has no textures.
    Absent,
    /// Not wanted ([`Wishes::textures`] is false).
    Unwanted,
    /// The device cannot sample BC1 textures.
    NoBc1,
    /// `share` bytes of the budget hold no slot of `slot_bytes` (or the set has no tiles, or
    /// the device no array layers).
    NoSlot { share: u64, slot_bytes: u64 },
}

impl Textures {
    pub fn config(&self) -> Option<&TextureConfig> {
        match self {
            Textures::Slots(c) => Some(c),
            _ => None,
        }
    }

    /// Bytes of all slots.
    pub fn bytes(&self) -> u64 {
        self.config().map_or(0, |c| c.slots as u64 * c.slot_bytes())
    }
}

/// The index builder the budget holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BuilderSize {
    /// Arrays built at once.
    pub lookups: u32,
    pub bytes: u64,
}

/// How the GPU budget is spent. The builder's eighth is of the whole budget, not of what the
/// textures leave: with a texture share above 7/8 the two together can exceed the budget, and
/// the pool then gets nothing (as `Renderer::new` decided before this module).
#[derive(Clone, Debug, PartialEq)]
pub struct Split {
    pub textures: Textures,
    /// None when index arrays are sent.
    pub builder: Option<BuilderSize>,
    /// [`IndexArrays::Built`] exactly when there is a builder.
    pub index_arrays: IndexArrays,
    /// Bytes for the tile pool (`Config::pool_bytes`).
    pub pool_bytes: u64,
    /// Index arrays a frame may build at most ([`builds_per_frame`]).
    pub builds_per_frame: usize,
    /// Frames in flight, at least one: the frame slots, each with its own build list.
    pub frame_slots: usize,
    /// The morph pass (None: not wished for, or the budget holds too little of it).
    pub morph: Option<MorphSize>,
}

impl Split {
    pub fn new(
        device: &DeviceLimits,
        wishes: &Wishes,
        set: &TileSet,
        builder: &BuilderCost,
    ) -> Split {
        let budget = wishes.gpu_budget;
        let textures = texture_slots(device, wishes, set);
        let frame_slots = wishes.frames_in_flight.max(1);
        let builds_per_frame = builds_per_frame(set.tiles);
        // As many lookups as fit in the eighth, halving from the most (fewer only build fewer
        // arrays at once).
        let lookups = std::iter::successors(Some(builder.max_lookups.max(1)), |&n| {
            (n > 1).then_some(n / 2)
        });
        let builder = lookups
            .map(|lookups| BuilderSize {
                lookups,
                bytes: builder.bytes(frame_slots, builds_per_frame, lookups),
            })
            .find(|b| b.bytes <= budget / 8)
            .filter(|_| device.storage_16bit && wishes.index_arrays == IndexArrays::Built);
        let index_arrays = match builder {
            Some(_) => IndexArrays::Built,
            None => IndexArrays::Sent,
        };
        let morph = wishes.morph.and_then(|m| m.size(budget, frame_slots));
        let others = textures
            .bytes()
            .saturating_add(builder.map_or(0, |b| b.bytes))
            .saturating_add(morph.map_or(0, |m| m.bytes));
        Split {
            morph,
            pool_bytes: budget.saturating_sub(others).min(device.max_storage_range),
            textures,
            builder,
            index_arrays,
            builds_per_frame,
            frame_slots,
        }
    }

    pub fn texture_bytes(&self) -> u64 {
        self.textures.bytes()
    }

    pub fn builder_bytes(&self) -> u64 {
        self.builder.map_or(0, |b| b.bytes)
    }
}

/// Index arrays a frame may build at most: each visible tile's presence, refinement and
/// prefetched spare, and a few prefetched tiles not visible yet.
pub fn builds_per_frame(tiles: usize) -> usize {
    3 * tiles + 8
}

/// As many slots of the set's chain as the budget's texture share holds, at most one per tile
/// and the device's layer limit.
fn texture_slots(device: &DeviceLimits, wishes: &Wishes, set: &TileSet) -> Textures {
    let Some(chain) = &set.texture else {
        return Textures::Absent;
    };
    if !wishes.textures {
        return Textures::Unwanted;
    }
    if !device.bc1_textures {
        return Textures::NoBc1;
    }
    let slot_bytes = chain.slot_bytes();
    // Rounding to f64 can land above a budget over 2^53 bytes: the share stays within it.
    let share = ((wishes.gpu_budget as f64 * wishes.texture_share.clamp(0.0, 1.0)) as u64)
        .min(wishes.gpu_budget);
    // An empty chain (no tile set has one) holds no slot rather than dividing by zero.
    let slots = share
        .checked_div(slot_bytes)
        .unwrap_or(0)
        .min(set.tiles as u64)
        .min(u64::from(device.max_image_layers));
    if slots == 0 {
        return Textures::NoSlot { share, slot_bytes };
    }
    Textures::Slots(TextureConfig {
        slots: slots as usize,
        mip_bytes: chain.mip_bytes.clone(),
        mip_texels: chain.mip_texels.clone(),
    })
}

/// Staging bytes the geometry of one frame can need at most. [`crate::Manager::plan_frame`]
/// sends beyond its budget only for the presence of new tiles (each tile's level 0, at most
/// all of them) and, when nothing else was sent, one step larger than the budget (a level's
/// block and index array, within the largest tile's whole layout); prefetching spends only
/// what the frame left. No frame sends more than the whole tile set, which caps an unlimited
/// budget. The last term allows for each copy starting 4-aligned: up to 3 bytes lost before
/// each of 8 copies a tile (an allowance, not a count: the step term, unspent unless the step
/// goes alone, covers more). The progressive and per-level schemes only: under the whole-tile
/// scheme a new tile's presence is the whole tile, which the presence term does not cover.
pub fn staging_bound<'a>(costs: impl IntoIterator<Item = &'a TileCost>, upload_budget: u64) -> u64 {
    staging_estimate(costs, 1, upload_budget)
}

/// [`staging_bound`] from a sample of a set's tiles, each standing for `weight` tiles: an
/// estimate, not a bound, for a set too large to read every tile's costs (the manager then
/// holds a frame's uploads to it, `Manager::set_staging_cap`). With a weight of 1, the bound
/// over exactly these tiles.
pub fn staging_estimate<'a>(
    costs: impl IntoIterator<Item = &'a TileCost>,
    weight: u64,
    upload_budget: u64,
) -> u64 {
    let (mut tiles, mut presence, mut step, mut everything) = (0u64, 0, 0, 0);
    for c in costs {
        tiles += weight;
        everything += weight * c.whole();
        if let Some(level_0) = c.levels.first() {
            presence += weight * (c.block_bytes(0) + level_0.indices);
            step = step.max(c.need(c.finest()));
        }
    }
    let padding = 4 * 8 * (tiles + 1);
    upload_budget.min(everything) + presence + step + padding
}

/// Staging bytes the textures of one frame can need at most. [`crate::TextureSlots::plan`]
/// sends each newly placed slot's base mips whatever the budget, and finer mips only within
/// it: at most the budget (what geometry leaves of it, and never more than every slot's whole
/// chain) plus every slot's base. Each slot is placed at most once a frame, so at most one copy
/// per slot and mip, each starting [`TEXTURE_ALIGN`]-aligned.
pub fn texture_staging_bound(config: &TextureConfig, upload_budget: u64) -> u64 {
    let slots = config.slots as u64;
    let base: u64 = config.mip_bytes[config.base() as usize..].iter().sum();
    let padding = TEXTURE_ALIGN * slots * u64::from(config.mips());
    upload_budget.min(slots * config.slot_bytes()) + slots * base + padding
}

/// Alignment of texture copies in the staging buffer: a multiple of the BC1 block's 8 bytes
/// and of the 4 Vulkan asks of buffer-to-image copy offsets.
pub const TEXTURE_ALIGN: u64 = 16;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cost::tests::tile;
    use crate::manager::{Config, Manager, Request, Scheme, Upload};
    use crate::textures::{tests::config as chain_544, TextureRequest, TextureSlots};
    use proptest::prelude::*;

    /// The builder's constants in `renderer/src/vulkan/indices.rs` (a `Build` is 8 words).
    const BUILDER: BuilderCost = BuilderCost {
        lookup_bytes: 257 * 257 * 4,
        build_bytes: 32,
        status_bytes: 16,
        max_lookups: 8,
    };
    const LOOKUP: u64 = 257 * 257 * 4;
    /// Bytes of a 544-texel slot's chain.
    const SLOT: u64 = 197_408;

    fn device() -> DeviceLimits {
        DeviceLimits {
            max_storage_range: 128 << 20,
            max_image_layers: 2048,
            storage_16bit: true,
            bc1_textures: true,
        }
    }

    fn wishes(gpu_budget: u64) -> Wishes {
        Wishes {
            gpu_budget,
            texture_share: 0.25,
            textures: true,
            index_arrays: IndexArrays::Built,
            frames_in_flight: 2,
            morph: None,
        }
    }

    /// The morph pass's constants in `renderer/src/vulkan/morph_pass.rs`, for a set of
    /// `max_vertices` vertices at its finest.
    fn morph(max_vertices: u64) -> MorphCost {
        MorphCost {
            region_bytes: 2 * 257 * 257 * 8,
            max_groups: 16,
            vertex_bytes: 4,
            max_vertices,
        }
    }

    /// The morph pass takes at most a sixteenth of the budget (half regions, half heights, no
    /// more heights than the set has vertices), and the pool what is left; a budget whose
    /// sixteenth holds no region, or too few heights, has none.
    #[test]
    fn the_morph_pass_takes_a_sixteenth_at_most() {
        let region = 2 * 257 * 257 * 8;
        // 1 GiB: a 32nd (32 MiB) holds all 16 regions (16.9 MB); 16 MiB of heights a slot.
        let mut w = wishes(1 << 30);
        w.morph = Some(morph(100_000_000));
        let s = Split::new(&device(), &w, &set(1000), &BUILDER);
        let m = s.morph.expect("morph");
        assert_eq!((m.groups, m.slot_bytes), (16, 16 << 20));
        assert_eq!(m.bytes, 16 * region + 2 * (16 << 20));
        assert!(m.bytes <= (1 << 30) / 16);
        // 64 MiB: a 32nd (2 MiB) holds one region (1.06 MB), not two; a mebibyte a slot.
        w.gpu_budget = 64 << 20;
        let s = Split::new(&device(), &w, &set(1000), &BUILDER);
        let m = s.morph.expect("morph");
        assert_eq!((m.groups, m.slot_bytes), (1, 1 << 20));
        let without = Split::new(&device(), &wishes(64 << 20), &set(1000), &BUILDER);
        assert_eq!(s.pool_bytes, without.pool_bytes - m.bytes);
        // A small set needs no more heights than it has vertices.
        w.morph = Some(morph(10_000));
        let m = Split::new(&device(), &w, &set(10), &BUILDER)
            .morph
            .expect("morph");
        assert_eq!(m.slot_bytes, 40_000);
        // 16 MiB: a 32nd (512 KiB) holds no region: no pass, and the pool keeps it all.
        w.gpu_budget = 16 << 20;
        let s = Split::new(&device(), &w, &set(10), &BUILDER);
        assert_eq!(s.morph, None);
        let without = Split::new(&device(), &wishes(16 << 20), &set(10), &BUILDER);
        assert_eq!(s.pool_bytes, without.pool_bytes);
        // 40 MiB: one region fits the 32nd (1.25 MiB), and 640 KiB of heights a slot.
        w.gpu_budget = 40 << 20;
        w.morph = Some(morph(100_000_000));
        let m = Split::new(&device(), &w, &set(10), &BUILDER)
            .morph
            .expect("morph");
        assert_eq!((m.groups, m.slot_bytes), (1, 655_360));
        // With six frames in flight, 213 KiB a slot hold fewer than 65,536 heights: none.
        w.frames_in_flight = 6;
        assert_eq!(Split::new(&device(), &w, &set(10), &BUILDER).morph, None);
    }

    fn chain() -> MipChain {
        let c = chain_544(0);
        MipChain {
            mip_bytes: c.mip_bytes,
            mip_texels: c.mip_texels,
        }
    }

    fn set(tiles: usize) -> TileSet {
        TileSet {
            tiles,
            texture: Some(chain()),
        }
    }

    #[test]
    fn a_budget_splits_as_computed_by_hand() {
        assert_eq!(chain().slot_bytes(), SLOT);
        // 64 MiB for 1000 tiles, two frames in flight.
        let s = Split::new(&device(), &wishes(64 << 20), &set(1000), &BUILDER);
        // A quarter (16 777 216 bytes) holds 84 slots.
        assert_eq!(s.textures.config().map(|c| c.slots), Some(84));
        assert_eq!(s.texture_bytes(), 84 * SLOT);
        // Per frame slot 3008 builds of 32 bytes and a status; all eight lookups fit the
        // eighth (8 MiB).
        assert_eq!((s.builds_per_frame, s.frame_slots), (3008, 2));
        let lists = 2 * (3008 * 32 + 16);
        assert_eq!(
            s.builder,
            Some(BuilderSize {
                lookups: 8,
                bytes: 8 * LOOKUP + lists
            })
        );
        assert_eq!(s.index_arrays, IndexArrays::Built);
        assert_eq!(s.pool_bytes, 67_108_864 - 16_582_272 - 2_306_112);
        // 8 MiB: the eighth (1 048 576) holds two lookups (720 936 bytes), not four
        // (1 249 328); a quarter holds 10 slots.
        let s = Split::new(&device(), &wishes(8 << 20), &set(1000), &BUILDER);
        assert_eq!(
            s.builder,
            Some(BuilderSize {
                lookups: 2,
                bytes: 720_936
            })
        );
        assert_eq!(s.texture_bytes(), 10 * SLOT);
        assert_eq!(s.pool_bytes, 8_388_608 - 1_974_080 - 720_936);
    }

    #[test]
    fn the_builder_cost_is_the_renderers_bytes_for() {
        // `IndexBuilder::bytes_for`: lookups clamped to 1..=8, slots and capacity to >= 1.
        assert_eq!(BUILDER.bytes(2, 10, 4), 4 * LOOKUP + 2 * (10 * 32 + 16));
        assert_eq!(BUILDER.bytes(0, 0, 0), LOOKUP + (32 + 16));
        assert_eq!(BUILDER.bytes(1, 1, 99), 8 * LOOKUP + (32 + 16));
        // Not a panic when the renderer allows no lookup at all: one is the least.
        let none = BuilderCost {
            max_lookups: 0,
            ..BUILDER
        };
        assert_eq!(none.bytes(1, 1, 8), LOOKUP + (32 + 16));
    }

    #[test]
    fn a_budget_too_small_for_one_lookup_sends_index_arrays() {
        // The eighth of 2 MiB (262 144 bytes) is less than one lookup (264 196).
        let s = Split::new(&device(), &wishes(2 << 20), &set(10), &BUILDER);
        assert_eq!((s.builder, s.index_arrays), (None, IndexArrays::Sent));
        assert_eq!(s.builder_bytes(), 0);
        // The pool gets what the textures (two slots of the quarter) leave.
        assert_eq!(s.texture_bytes(), 2 * SLOT);
        assert_eq!(s.pool_bytes, (2 << 20) - 2 * SLOT);
    }

    #[test]
    fn without_16bit_storage_or_when_sent_is_wanted_arrays_are_sent() {
        let no_16bit = DeviceLimits {
            storage_16bit: false,
            ..device()
        };
        let sent = Wishes {
            index_arrays: IndexArrays::Sent,
            ..wishes(64 << 20)
        };
        for (d, w) in [(no_16bit, wishes(64 << 20)), (device(), sent)] {
            let s = Split::new(&d, &w, &set(1000), &BUILDER);
            assert_eq!((s.builder, s.index_arrays), (None, IndexArrays::Sent));
            assert_eq!(s.pool_bytes, (64 << 20) - 84 * SLOT);
        }
    }

    #[test]
    fn no_texture_slots_say_why() {
        let split = |d: DeviceLimits, w: Wishes, s: TileSet| Split::new(&d, &w, &s, &BUILDER);
        let no_bc1 = DeviceLimits {
            bc1_textures: false,
            ..device()
        };
        let unwanted = Wishes {
            textures: false,
            ..wishes(64 << 20)
        };
        let bare = TileSet {
            tiles: 1000,
            texture: None,
        };
        // In this order: the set has none, they are not wanted, the device cannot sample them.
        let s = split(no_bc1, unwanted, bare.clone());
        assert_eq!(s.textures, Textures::Absent);
        assert_eq!(
            split(no_bc1, unwanted, set(1000)).textures,
            Textures::Unwanted
        );
        assert_eq!(
            split(no_bc1, wishes(64 << 20), set(1000)).textures,
            Textures::NoBc1
        );
        // A thousandth of 64 MiB (67 108 bytes) holds no 197 408-byte slot; the note says both.
        let thin = Wishes {
            texture_share: 0.001,
            ..wishes(64 << 20)
        };
        let s = split(device(), thin, set(1000));
        assert_eq!(
            s.textures,
            Textures::NoSlot {
                share: 67_108,
                slot_bytes: SLOT
            }
        );
        // A share below zero is none.
        let negative = Wishes {
            texture_share: -1.0,
            ..wishes(64 << 20)
        };
        let s = split(device(), negative, set(1000));
        assert_eq!(
            s.textures,
            Textures::NoSlot {
                share: 0,
                slot_bytes: SLOT
            }
        );
        // Without slots the pool gets all the builder leaves.
        assert_eq!(s.texture_bytes(), 0);
        assert_eq!(s.pool_bytes, (64 << 20) - s.builder_bytes());
    }

    #[test]
    fn slots_are_capped_by_the_tiles_and_the_layers() {
        let all = Wishes {
            texture_share: 2.0,
            ..wishes(1 << 30)
        };
        // The whole GiB (the share is clamped to 1) holds 5439 slots.
        let slots = |d: DeviceLimits, tiles| {
            Split::new(&d, &all, &set(tiles), &BUILDER)
                .textures
                .config()
                .map(|c| c.slots)
        };
        let many_layers = DeviceLimits {
            max_image_layers: 1 << 16,
            ..device()
        };
        assert_eq!(slots(many_layers, 10_000), Some(5439));
        assert_eq!(slots(many_layers, 7), Some(7));
        let few_layers = DeviceLimits {
            max_image_layers: 3,
            ..device()
        };
        assert_eq!(slots(few_layers, 10_000), Some(3));
        // The chain is the set's.
        let c = Split::new(&device(), &all, &set(7), &BUILDER).textures;
        assert_eq!(c.config().map(|c| &c.mip_bytes), Some(&chain().mip_bytes));
    }

    #[test]
    fn the_pool_is_capped_by_the_readable_range_and_never_underflows() {
        let narrow = DeviceLimits {
            max_storage_range: 16 << 20,
            ..device()
        };
        let s = Split::new(&narrow, &wishes(64 << 20), &set(1000), &BUILDER);
        assert_eq!(s.pool_bytes, 16 << 20);
        // The builder's eighth is of the whole budget: beside a share above 7/8 the textures
        // and the builder together exceed it, and the pool gets nothing.
        let all = Wishes {
            texture_share: 1.0,
            ..wishes(64 << 20)
        };
        let s = Split::new(&device(), &all, &set(1000), &BUILDER);
        assert!(s.texture_bytes() + s.builder_bytes() > 64 << 20);
        assert_eq!(s.pool_bytes, 0);
    }

    /// The split as `renderer/src/frame.rs` made it at e73847d (`Renderer::new` and
    /// `texture_config`, with `IndexBuilder::bytes_for`'s constants), transcribed with the
    /// device and the set as numbers: texture slots, (lookups, bytes), arrays, pool bytes.
    fn renderer_e73847d(
        d: &DeviceLimits,
        w: &Wishes,
        set: &TileSet,
    ) -> (Option<u64>, Option<(u32, u64)>, IndexArrays, u64) {
        let slot_config = set.texture.as_ref().and_then(|chain| {
            if !w.textures || !d.bc1_textures {
                return None;
            }
            let slot_bytes: u64 = chain.mip_bytes.iter().sum();
            let share = (w.gpu_budget as f64 * w.texture_share.clamp(0.0, 1.0)) as u64;
            let slots = (share / slot_bytes)
                .min(set.tiles as u64)
                .min(u64::from(d.max_image_layers));
            (slots > 0).then_some((slots, slot_bytes))
        });
        let texture_bytes = slot_config.map_or(0, |(n, b)| n * b);
        let slot_count = w.frames_in_flight.max(1);
        let builds_per_frame = 3 * set.tiles + 8;
        let bytes_for = |slots: usize, capacity: usize, lookups: u32| {
            LOOKUP * u64::from(lookups.clamp(1, 8))
                + slots.max(1) as u64 * ((capacity.max(1) * 32) as u64 + 16)
        };
        let builder_size = [8, 4, 2, 1]
            .into_iter()
            .map(|n| (n, bytes_for(slot_count, builds_per_frame, n)))
            .find(|&(_, bytes)| bytes <= w.gpu_budget / 8)
            .filter(|_| d.storage_16bit && w.index_arrays == IndexArrays::Built);
        let index_arrays = match builder_size {
            Some(_) => IndexArrays::Built,
            None => IndexArrays::Sent,
        };
        let builder_bytes = builder_size.map_or(0, |(_, bytes)| bytes);
        let pool = w
            .gpu_budget
            .saturating_sub(texture_bytes + builder_bytes)
            .min(d.max_storage_range);
        (slot_config.map(|c| c.0), builder_size, index_arrays, pool)
    }

    /// A BC1 chain of a layer `size` texels across, down to 4 texels.
    fn chain_of(size: u32) -> MipChain {
        let mip_texels: Vec<u32> = (0..32).map(|m| size >> m).take_while(|&t| t >= 4).collect();
        MipChain {
            mip_bytes: mip_texels
                .iter()
                .map(|&t| u64::from(t.div_ceil(4)).pow(2) * 8)
                .collect(),
            mip_texels,
        }
    }

    /// A number below 2^`max_bits`, its magnitude uniform (as likely 2 MB as 2 GB).
    fn magnitude(max_bits: u32) -> impl Strategy<Value = u64> {
        (0..=max_bits, any::<u64>()).prop_map(|(bits, x)| x.checked_shr(64 - bits).unwrap_or(0))
    }

    prop_compose! {
        fn inputs(max_bits: u32)(
            gpu_budget in magnitude(max_bits),
            texture_share in -0.5f64..1.5,
            textures in any::<bool>(),
            built in any::<bool>(),
            frames_in_flight in 0usize..5,
            tiles in prop_oneof![0usize..10, 0usize..20_000],
            size in prop::option::of(4u32..4500),
            max_storage_range in magnitude(34),
            max_image_layers in 0u32..4096,
            storage_16bit in any::<bool>(),
            bc1_textures in any::<bool>(),
            morph_vertices in prop::option::of(magnitude(32)),
        ) -> (DeviceLimits, Wishes, TileSet) {
            let index_arrays = if built { IndexArrays::Built } else { IndexArrays::Sent };
            let morph = morph_vertices.map(morph);
            (
                DeviceLimits { max_storage_range, max_image_layers, storage_16bit, bc1_textures },
                Wishes { gpu_budget, texture_share, textures, index_arrays, frames_in_flight, morph },
                TileSet { tiles, texture: size.map(chain_of) },
            )
        }
    }

    /// Checks what any split must be: within the budget, within the device, as large as
    /// allowed, and index arrays built exactly when the builder is there.
    fn check(d: &DeviceLimits, w: &Wishes, set: &TileSet, s: &Split) -> Result<(), TestCaseError> {
        let budget = w.gpu_budget;
        let (textures, builder) = (s.texture_bytes(), s.builder_bytes());
        let morph = s.morph.map_or(0, |m| m.bytes);
        prop_assert!(textures <= budget, "{s:?}");
        prop_assert!(builder <= budget / 8, "{s:?}");
        prop_assert!(s.pool_bytes <= d.max_storage_range);
        prop_assert!(s.morph.is_none() || w.morph.is_some());
        if let (Some(m), Some(cost)) = (s.morph, w.morph) {
            // A sixteenth at most: regions in half of it, heights in the other half.
            let whole = cost.max_vertices.max(1).saturating_mul(cost.vertex_bytes);
            prop_assert!(m.groups >= 1 && m.groups <= cost.max_groups);
            prop_assert!(m.slot_bytes <= whole);
            prop_assert!(u64::from(m.groups) * cost.region_bytes <= budget / 32);
            prop_assert!(m.slot_bytes * s.frame_slots as u64 <= budget / 32);
            prop_assert!(m.bytes <= budget / 16);
            prop_assert_eq!(
                m.bytes,
                u64::from(m.groups) * cost.region_bytes + s.frame_slots as u64 * m.slot_bytes
            );
        }
        if textures + builder + morph <= budget {
            prop_assert!(s.pool_bytes + textures + builder + morph <= budget, "{s:?}");
            // The pool takes all the rest it can read.
            prop_assert_eq!(
                s.pool_bytes,
                (budget - textures - builder - morph).min(d.max_storage_range)
            );
        } else {
            prop_assert_eq!(s.pool_bytes, 0);
        }
        prop_assert_eq!(s.builder.is_some(), s.index_arrays == IndexArrays::Built);
        match s.builder {
            Some(b) => {
                prop_assert!(d.storage_16bit && w.index_arrays == IndexArrays::Built);
                prop_assert_eq!(
                    b.bytes,
                    BUILDER.bytes(s.frame_slots, s.builds_per_frame, b.lookups)
                );
                // No larger count would have fitted.
                if b.lookups < BUILDER.max_lookups {
                    let more = BUILDER.bytes(s.frame_slots, s.builds_per_frame, 2 * b.lookups);
                    prop_assert!(more > budget / 8);
                }
            }
            None => {
                let one = BUILDER.bytes(s.frame_slots, s.builds_per_frame, 1);
                prop_assert!(
                    !d.storage_16bit || w.index_arrays == IndexArrays::Sent || one > budget / 8
                );
            }
        }
        match (&s.textures, &set.texture) {
            (Textures::Slots(c), Some(chain)) => {
                prop_assert!(w.textures && d.bc1_textures && c.slots >= 1);
                prop_assert!(
                    c.slots <= set.tiles && c.slots as u64 <= u64::from(d.max_image_layers)
                );
                let share = budget as f64 * w.texture_share.clamp(0.0, 1.0);
                prop_assert!(textures as f64 <= share);
                // As many as the share holds (or the budget, where the share rounds above it),
                // unless the tiles or the layers say fewer.
                let more = (c.slots as u64 + 1) * chain.slot_bytes();
                prop_assert!(
                    more as f64 > share
                        || more > budget
                        || c.slots == set.tiles
                        || c.slots as u64 == u64::from(d.max_image_layers)
                );
            }
            (Textures::Absent, None) => {}
            (Textures::Unwanted, Some(_)) => prop_assert!(!w.textures),
            (Textures::NoBc1, Some(_)) => prop_assert!(w.textures && !d.bc1_textures),
            (Textures::NoSlot { share, slot_bytes }, Some(chain)) => {
                prop_assert!(w.textures && d.bc1_textures);
                prop_assert_eq!(*slot_bytes, chain.slot_bytes());
                prop_assert!(share < slot_bytes || set.tiles == 0 || d.max_image_layers == 0);
            }
            (t, c) => prop_assert!(false, "textures {t:?} for a set whose chain is {c:?}"),
        }
        prop_assert_eq!(s.frame_slots, w.frames_in_flight.max(1));
        prop_assert_eq!(s.builds_per_frame, 3 * set.tiles + 8);
        Ok(())
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(2000))]

        /// Budgets the CLI takes in practice (up to 2^53 bytes, where f64 holds every byte
        /// count): without the morph pass, the renderer's split at e73847d, bit for bit; with
        /// it, the same but for the pool, which gives the pass its bytes; and every rule of a
        /// split.
        #[test]
        fn random_splits_match_the_renderers_and_keep_the_rules(
            (d, w, set) in inputs(53),
        ) {
            let unmorphed = Wishes { morph: None, ..w };
            let plain = Split::new(&d, &unmorphed, &set, &BUILDER);
            let (slots, builder, arrays, pool) = renderer_e73847d(&d, &w, &set);
            prop_assert_eq!(plain.textures.config().map(|c| c.slots as u64), slots);
            prop_assert_eq!(plain.builder.map(|b| (b.lookups, b.bytes)), builder);
            prop_assert_eq!((plain.index_arrays, plain.pool_bytes), (arrays, pool));
            check(&d, &unmorphed, &set, &plain)?;
            let s = Split::new(&d, &w, &set, &BUILDER);
            prop_assert_eq!(&s.textures, &plain.textures);
            prop_assert_eq!((s.builder, s.index_arrays), (plain.builder, plain.index_arrays));
            prop_assert!(s.pool_bytes <= plain.pool_bytes);
            check(&d, &w, &set, &s)?;
        }

        /// Any budget at all (the CLI takes up to 2^44 MB): the rules hold, nothing overflows.
        #[test]
        fn any_budget_keeps_the_rules((d, w, set) in inputs(64)) {
            let s = Split::new(&d, &w, &set, &BUILDER);
            check(&d, &w, &set, &s)?;
        }
    }

    #[test]
    fn the_staging_bound_is_budget_presence_step_and_alignment() {
        let tiles = [tile(3, 10), tile(5, 20)];
        let presence: u64 = tiles
            .iter()
            .map(|t| t.block_bytes(0) + t.levels[0].indices)
            .sum();
        let step = tiles[1].need(4);
        let everything: u64 = tiles.iter().map(TileCost::whole).sum();
        let padding = 4 * 8 * 3;
        assert_eq!(
            staging_bound(&tiles, 1000),
            1000 + presence + step + padding
        );
        // An unlimited budget is capped by the whole set.
        assert_eq!(
            staging_bound(&tiles, u64::MAX),
            everything + presence + step + padding
        );
        // Numbers by hand for tile(3, 10): block 0 is 40 bytes, its index array 240, the
        // finest layout 40 + 80 + 160 positions, 20 + 80 morph bytes, 960 index bytes.
        assert_eq!(
            staging_bound(&[tile(3, 10)], 0),
            (40 + 240) + (280 + 100 + 960) + 64
        );
        assert_eq!(staging_bound(&[] as &[TileCost], 1 << 20), 32);
    }

    #[test]
    fn the_texture_staging_bound_is_budget_bases_and_alignment() {
        let c = chain_544(4);
        // Base: mips 5..8 (200 + 32 + 8 bytes); 4 slots of 8 mips, 16 bytes of alignment each.
        assert_eq!(texture_staging_bound(&c, 1000), 1000 + 4 * 240 + 16 * 4 * 8);
        assert_eq!(
            texture_staging_bound(&c, u64::MAX),
            4 * SLOT + 4 * 240 + 16 * 4 * 8
        );
    }

    /// Bytes a frame's sent uploads take in a staging buffer written in plan order, each copy
    /// starting 4-aligned (`Staging::push`).
    fn staged(uploads: &[Upload]) -> u64 {
        uploads
            .iter()
            .filter(|u| u.sent() > 0)
            .fold(0, |used, u| used.next_multiple_of(4) + u.sent())
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(300))]

        /// On random flights (with prefetching, every upload staged), no frame's geometry
        /// needs more staging than [`staging_bound`].
        #[test]
        fn no_frame_stages_more_geometry_than_the_bound(
            finest in 0u32..7,
            shapes in proptest::collection::vec((0u32..7, 20u64..400), 1..30),
            frames in proptest::collection::vec(
                proptest::collection::vec((0u32..30, 0u32..7), 0..16), 1..40),
            pool_kib in 64u64..4096,
            upload in magnitude(19),
            per_level in any::<bool>(),
            built in any::<bool>(),
        ) {
            // Up to `finest + 1` levels a tile: in sets of coarse tiles presence is the larger
            // term, in the others the step.
            let tiles: Vec<TileCost> =
                shapes.iter().map(|&(l, s)| tile(1 + l % (finest + 1), s)).collect();
            let n = tiles.len() as u32;
            let config = Config {
                pool_bytes: pool_kib << 10,
                upload_budget: upload,
                scheme: if per_level { Scheme::PerLevel } else { Scheme::Progressive },
                index_arrays: if built { IndexArrays::Built } else { IndexArrays::Sent },
                ..Config::default()
            };
            let bound = staging_bound(&tiles, upload);
            let mut m = Manager::new(tiles, config);
            for (f, frame) in frames.iter().enumerate() {
                let f = f as u64;
                let mut seen = std::collections::HashSet::new();
                let requests: Vec<Request> = frame
                    .iter()
                    .filter(|(t, _)| seen.insert(t % n))
                    .map(|&(t, l)| Request { tile: t % n, wanted: l })
                    .collect();
                let mut p = m.plan_frame(f, f.checked_sub(2), &requests, true);
                let next: Vec<Request> = frames
                    .get(f as usize + 1)
                    .into_iter()
                    .flatten()
                    .map(|&(t, l)| Request { tile: t % n, wanted: l })
                    .collect();
                m.prefetch(&mut p, &next);
                prop_assert!(staged(&p.uploads) <= bound, "frame {f}: {} > {bound}", staged(&p.uploads));
            }
        }
    }

    #[test]
    fn no_frame_stages_more_texture_than_the_bound() {
        // Random visible sets, needs and budgets, one frame in flight; each copy starts
        // TEXTURE_ALIGN-aligned after whatever the geometry left.
        for slots in [1, 3, 8] {
            let c = chain_544(slots);
            let mut t = TextureSlots::new(c.clone());
            let mut state = 7u64;
            for frame in 0..400u64 {
                state = state
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                let requests: Vec<TextureRequest> = (0..(state >> 59) as u32)
                    .map(|k| TextureRequest {
                        tile: ((state >> (3 * k)) % 24) as u32 + k * 24,
                        finest: ((state >> 40) % 8) as u32,
                    })
                    .collect();
                let budget = [0, 5_000, 200_000, u64::MAX][(state >> 20) as usize % 4];
                let (_, uploads, _) = t.plan(frame, frame.checked_sub(1), &requests, budget);
                let geometry = 1 + (state >> 30) % 3;
                let end = uploads.iter().fold(geometry, |used, u| {
                    used.next_multiple_of(TEXTURE_ALIGN) + u.bytes
                });
                assert!(
                    end - geometry <= texture_staging_bound(&c, budget),
                    "frame {frame}: {} bytes staged",
                    end - geometry
                );
            }
        }
    }
}
