//! How a flight draws and what memory it may use: the settings the command line, the window's
//! keys and the tests choose, read by the frame loop ([`crate::frame`]) and the plan
//! ([`crate::plan`]).

use memory::{IndexArrays, Scheme};

use crate::plan::LevelRule;
use crate::prefetch::PrefetchOptions;

/// How to draw.
#[derive(Clone, Debug)]
pub struct Settings {
    /// Pixel tolerance.
    pub tau: f64,
    /// Draw every visible tile at this level.
    pub forced_level: Option<u32>,
    /// Draw every visible tile at its finest level (the baseline).
    pub brute_force: bool,
    pub shading: Shading,
    /// Samples the `Tiles` shading's grid is moved by (0: the tiles; tests use other lines).
    pub tile_grid_offset: f32,
    pub wireframe: bool,
    pub sky: [f32; 3],
    /// Diagnostic: leave the seams open, to see (and test) what stitching closes.
    pub no_stitch: bool,
    /// Skip the tiles' back-facing triangles (off: `--no-cull`). While the camera is above
    /// the terrain, a back face of a height field is always hidden: the ray to it arrives from
    /// below the surface, so it crossed the surface nearer the camera first. Stitches, seen
    /// edge-on from either side, are never culled, nor is the wireframe.
    pub cull_back_faces: bool,
    /// Diagnostic: shade every tile with the fragment shader that holds every shading, not the
    /// textured tiles with its texture path alone (the same frames; `--one-fragment-shader`).
    pub one_fragment_shader: bool,
    /// How the level for tau is chosen (the guaranteed bound, or the old sampling).
    pub bound: crate::lod::Bound,
    /// Continuous levels, heights blended between levels (off: `--no-geomorph`).
    pub geomorph: bool,
    /// Geomorphing: draw each tile's 4 x 4 parts at levels of their own ([`crate::parts`];
    /// off: `--whole-tiles`, each tile at one level). Needs index arrays built on the GPU;
    /// where they are sent, a tile is drawn at its parts' largest level throughout. Unless
    /// the user chose, the device decides ([`parts_pay_on`]).
    pub part_by_part: bool,
    /// Part by part: what building a mix costs, in triangles ([`crate::parts::BuildCost`]).
    pub part_build_cost: crate::parts::BuildCost,
    pub morph_shader: MorphShader,
    /// When a pyramid's tiles are checked (`--checks`; a base grid's on the frame that first
    /// needs them).
    pub checks: crate::plan::CheckPolicy,
}

/// How the terrain is coloured.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Shading {
    /// The tile set's texture tiles: a photo, or the shaded relief tiletool bakes without
    /// one (tiles without a texture slot fall back to `Tint`).
    Photo,
    /// Grey, lit by each triangle's own normal: the mesh as the level of detail made it.
    Relief,
    /// A hypsometric tint lit by each triangle's normal (the shading without textures).
    #[default]
    Tint,
    /// Level colours (coarse blue to fine red) over the tint.
    Level,
    /// One flat colour per tile, neighbours always different (a diagnostic: where the tile
    /// borders fall on screen). The grid may be moved by `Settings::tile_grid_offset`.
    Tiles,
}

impl Shading {
    pub const ALL: [Shading; 5] = [
        Shading::Photo,
        Shading::Relief,
        Shading::Tint,
        Shading::Level,
        Shading::Tiles,
    ];

    /// The next mode in [`Shading::ALL`] (the window's key).
    pub fn next(self) -> Shading {
        let i = Shading::ALL.iter().position(|&s| s == self).unwrap_or(0);
        Shading::ALL[(i + 1) % Shading::ALL.len()]
    }
}

/// Which vertex shader blends the levels.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum MorphShader {
    /// The morph pass places every drawn vertex from its parents' morphed heights, coarse to
    /// fine; the vertex shader reads the result (the default; `crate::morph`).
    #[default]
    Hierarchical,
    /// The previous per-vertex rule: the two stored levels around each vertex's level, two
    /// bytes read (`--morph-shader two-levels`).
    TwoLevels,
    /// The paper's clamped forward differences as dot products over every stored level (the
    /// reference, `--morph-shader forward-differences`).
    ForwardDifferences,
}

/// Whether drawing tiles part by part pays on a device of this type, when the user has not
/// chosen (`--part-by-part`, `--whole-tiles`). A mix saves triangles and costs an index build
/// on the GPU (a dispatch, a barrier, a walk of the tile's cells). On a software rasteriser a
/// triangle costs about 0.3 us, and the saving wins (lavapipe: geomorph tau 1 at 0.72-1.22x
/// discrete tau 1's frame part by part, against 0.77-1.35x with whole tiles, at or below whole
/// tiles on each of the five flights; bench/README.md, "A build's worth"). On a GPU a
/// triangle costs about a nanosecond, and the builds lose: in the one run on a GPU (an NVIDIA
/// H200, bench/README.md, "On a real GPU") part by part took 2.0x and 2.8x discrete tau 1's
/// frame on the N48W125 flyover and orbit against 1.09x and 1.84x with whole tiles, and
/// gained 10% on the Puget flyover only.
pub fn parts_pay_on(device: ash::vk::PhysicalDeviceType) -> bool {
    device == ash::vk::PhysicalDeviceType::CPU
}

/// Whether a compact set's levels are best decoded on the GPU on a device of this type, when
/// the user has not chosen (`--decode`). On a GPU a level's stream crosses the bus at a third
/// of its positions' bytes and a compute pass decodes it while the CPU rebuilds nothing for
/// it. On a software rasteriser the "GPU" is the same cores, and the compute pass is slower
/// than the native decoder the check runs anyway: on lavapipe the first frame of a compact
/// set took 0.52-0.90 s decoded on the GPU against 0.39-0.62 s on the CPU (Puget 1K and
/// N48W125), and the 16K mirror's flyover 148 ms a frame against 75 (bench/README.md, "A
/// compact tile rebuilt as far as it is read").
pub fn decode_pays_on(device: ash::vk::PhysicalDeviceType) -> bool {
    device != ash::vk::PhysicalDeviceType::CPU
}

impl Settings {
    /// The level rule and the check policy, as [`crate::plan::plan`] takes them.
    pub fn planning(&self) -> (LevelRule, crate::plan::CheckPolicy) {
        (self.rule(), self.checks)
    }

    pub fn rule(&self) -> LevelRule {
        if self.brute_force {
            LevelRule::Finest
        } else if let Some(l) = self.forced_level {
            LevelRule::Forced(l)
        } else if self.geomorph {
            LevelRule::Morph(self.tau, self.bound, self.part_by_part)
        } else {
            LevelRule::Tau(self.tau, self.bound)
        }
    }
}

/// GPU memory and transfer settings.
#[derive(Clone, Copy, Debug)]
pub struct MemoryOptions {
    /// Device memory for tile data (the pool is at most this).
    pub gpu_budget_bytes: u64,
    /// Tile data sent per frame at most (see `memory::Manager::plan_frame` for the exceptions).
    pub upload_budget: u64,
    /// The eviction mixture's weight.
    pub weight: f64,
    pub frames_in_flight: usize,
    /// Send every upload through the staging ring, even where the pool is host-visible.
    pub force_staging: bool,
    /// Levels finer than wanted a tile may stay drawn rather than re-sending an index array.
    pub downgrade_slack: u32,
    /// How levels travel (progressive; the others are for comparison and the draw-only limit).
    pub scheme: Scheme,
    pub prefetch: PrefetchOptions,
    /// Allocate texture slots when the tile set has textures (false: geometry only).
    pub textures: bool,
    /// The share of `gpu_budget_bytes` the texture slots may take.
    pub texture_share: f64,
    /// Anisotropic filtering of the textures, up to the device's limit (1: off).
    pub anisotropy: f32,
    /// Build index arrays on the GPU from the resident blocks (the default; sent from the
    /// file instead when the device cannot store 16-bit values from a shader).
    pub index_arrays: IndexArrays,
    /// Read every drawn vertex's height back from the vertex shader (a buffer per frame slot),
    /// for the check against the CPU mirror (`vkterrain --read-back-heights`).
    pub read_back_heights: bool,
    /// Send each block's morph rows and hold them in the pool ([`Terrain::costs`]): only the
    /// vertex shaders of `--morph-shader two-levels` and `forward-differences` read them.
    ///
    /// [`Terrain::costs`]: crate::terrain::Terrain::costs
    pub morph_rows: bool,
    /// A compact set's levels (version 5) travel as their compact streams and a compute pass
    /// decodes them into the pool (`vulkan::decode`); false: the positions the CPU rebuilt at
    /// the tile's check are sent, as for other sets. Where the user did not choose, the device
    /// decides ([`decode_pays_on`]).
    pub decode_on_gpu: bool,
    /// Built index arrays (`index_arrays`) are made by the GPU's builder, a compute pass over
    /// the resident blocks (`vulkan::indices`); false: the CPU makes each from the tile's
    /// checked levels and the frame copies it into place (`frame::made`). Where the user did
    /// not choose, the device decides ([`builds_pay_on`]).
    pub build_on_gpu: bool,
    /// The texture slots' format: the file's BC1 blocks as they are, or decoded on the CPU to
    /// R5G6B5 as they are uploaded (four times the slot memory). Where the user did not choose,
    /// the device decides ([`texture_format_for`]).
    pub texture_format: TextureFormat,
    /// The most tiles the GPU pool, the staging memory and the stitch buffer are sized from:
    /// every tile of a set of up to this many, else one in each run of `tiles / plan_sample`
    /// (`memory::costs::sample`), so that a set of any size opens without reading every
    /// tile's table.
    pub plan_sample: usize,
}

impl Default for MemoryOptions {
    fn default() -> Self {
        MemoryOptions {
            gpu_budget_bytes: 1 << 30,
            upload_budget: memory::DEFAULT_UPLOAD_BUDGET,
            weight: memory::DEFAULT_WEIGHT,
            frames_in_flight: 2,
            force_staging: false,
            downgrade_slack: memory::DEFAULT_DOWNGRADE_SLACK,
            scheme: Scheme::Progressive,
            prefetch: PrefetchOptions::default(),
            textures: true,
            texture_share: DEFAULT_TEXTURE_SHARE,
            anisotropy: 16.0,
            index_arrays: IndexArrays::Built,
            read_back_heights: false,
            morph_rows: false,
            decode_on_gpu: true,
            build_on_gpu: true,
            texture_format: TextureFormat::Bc1,
            plan_sample: memory::costs::SAMPLE_TILES,
        }
    }
}

/// Whether index arrays are best built by the GPU's builder on a device of this type, when the
/// user has not chosen (`--index-builder`). On a GPU a build is a dispatch over the blocks
/// already resident, and no index crosses the bus. On a software rasteriser the "GPU" is the
/// same cores, and the builder's workgroup (one per array) runs on one of them: on lavapipe a
/// build took 6-13 ms of the frame's GPU time on the demo flight (7-21 ms a frame, 7-17% of
/// it), where the CPU makes the same array from the tile's checked levels natively (a whole
/// level's is the file's; a mix about a millisecond on this machine) and a copy puts it in
/// place (bench/README.md, "Index arrays made on the CPU").
pub fn builds_pay_on(device: ash::vk::PhysicalDeviceType) -> bool {
    device != ash::vk::PhysicalDeviceType::CPU
}

/// The texture slots' format ([`MemoryOptions::texture_format`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TextureFormat {
    /// BC1 blocks, as the tile set stores them (half a byte a texel).
    Bc1,
    /// R5G6B5, decoded from the BC1 blocks on the CPU at upload (two bytes a texel).
    Rgb565,
}

impl TextureFormat {
    /// Bytes of mip `m` of a layer of `layout` in this format (BC1: as the tile set stores it).
    pub fn mip_bytes(self, layout: &tiles::texture::Layout, m: u32) -> u64 {
        match self {
            TextureFormat::Bc1 => layout.mip_bytes(m) as u64,
            TextureFormat::Rgb565 => 2 * u64::from(layout.mip_size(m)).pow(2),
        }
    }
}

/// The texture slots' format on a device of this type, when the user has not chosen
/// (`--texture-format`): R5G6B5 on a software rasteriser, where sampling BC1 decodes its
/// blocks in software on every fetch (on lavapipe issue 25's flights took 0.79-0.95x the frame
/// time of BC1 slots, the CPU decoding each mip once as it is uploaded; bench/README.md,
/// "Texture slots decoded on a software rasteriser"), and on a device that cannot sample BC1
/// but can R5G6B5 (which would otherwise draw without textures); BC1 elsewhere.
pub fn texture_format_for(
    device: ash::vk::PhysicalDeviceType,
    bc1: bool,
    rgb565: bool,
) -> TextureFormat {
    if rgb565 && (device == ash::vk::PhysicalDeviceType::CPU || !bc1) {
        TextureFormat::Rgb565
    } else {
        TextureFormat::Bc1
    }
}

/// Which choices the user left to the device (`auto`, or neither of two flags), each made by
/// its rule above once the device is known ([`ByDevice::apply`]).
#[derive(Clone, Copy, Debug, Default)]
pub struct ByDevice {
    /// `Settings::part_by_part` ([`parts_pay_on`]).
    pub parts: bool,
    /// `MemoryOptions::decode_on_gpu` ([`decode_pays_on`]).
    pub decode: bool,
    /// `MemoryOptions::build_on_gpu` ([`builds_pay_on`]).
    pub builder: bool,
    /// `MemoryOptions::texture_format` ([`texture_format_for`]).
    pub texture_format: bool,
}

impl ByDevice {
    /// Makes each choice left to the device as `gpu` says.
    pub fn apply(
        self,
        gpu: &crate::vulkan::Gpu,
        settings: &mut Settings,
        memory: &mut MemoryOptions,
    ) {
        let device = gpu.properties.device_type;
        if self.parts {
            settings.part_by_part = parts_pay_on(device);
        }
        if self.decode {
            memory.decode_on_gpu = decode_pays_on(device);
        }
        if self.builder {
            memory.build_on_gpu = builds_pay_on(device);
        }
        if self.texture_format {
            memory.texture_format =
                texture_format_for(device, gpu.bc_textures, gpu.rgb565_textures);
        }
    }
}

/// The share of the GPU budget texture slots take by default.
pub const DEFAULT_TEXTURE_SHARE: f64 = 0.25;

#[cfg(test)]
mod tests {
    use ash::vk::PhysicalDeviceType as Kind;

    use super::{builds_pay_on, decode_pays_on, parts_pay_on, texture_format_for, TextureFormat};

    #[test]
    fn textures_are_decoded_on_a_software_rasteriser_or_without_bc1() {
        use TextureFormat::{Bc1, Rgb565};
        assert_eq!(texture_format_for(Kind::CPU, true, true), Rgb565);
        assert_eq!(texture_format_for(Kind::DISCRETE_GPU, true, true), Bc1);
        assert_eq!(
            texture_format_for(Kind::INTEGRATED_GPU, false, true),
            Rgb565
        );
        // Nothing to decode to: BC1 (or no textures, the budget's call).
        assert_eq!(texture_format_for(Kind::CPU, true, false), Bc1);
        // R5G6B5 is two bytes a texel; BC1 what the tile set stores, a 17-texel mip 5 x 5
        // blocks.
        let layout = tiles::texture::Layout::new(256).expect("layout");
        let m = (0..layout.mips)
            .find(|&m| layout.mip_size(m) == 17)
            .expect("a 17-texel mip");
        assert_eq!(Bc1.mip_bytes(&layout, m), 200);
        assert_eq!(Rgb565.mip_bytes(&layout, m), 578);
    }

    #[test]
    fn index_arrays_are_built_on_the_gpu_except_on_a_software_rasteriser() {
        assert!(!builds_pay_on(Kind::CPU));
        for gpu in [Kind::DISCRETE_GPU, Kind::INTEGRATED_GPU, Kind::VIRTUAL_GPU] {
            assert!(builds_pay_on(gpu), "{gpu:?}");
        }
    }

    #[test]
    fn compact_levels_decode_on_the_gpu_except_on_a_software_rasteriser() {
        assert!(!decode_pays_on(Kind::CPU));
        for gpu in [Kind::DISCRETE_GPU, Kind::INTEGRATED_GPU, Kind::VIRTUAL_GPU] {
            assert!(decode_pays_on(gpu), "{gpu:?}");
        }
    }

    #[test]
    fn part_by_part_is_the_software_rasterisers_default() {
        assert!(parts_pay_on(Kind::CPU));
        for gpu in [
            Kind::DISCRETE_GPU,
            Kind::INTEGRATED_GPU,
            Kind::VIRTUAL_GPU,
            Kind::OTHER,
        ] {
            assert!(!parts_pay_on(gpu), "{gpu:?}");
        }
    }
}
