//! A frame's uploads written where the GPU will read them: blocks and sent index arrays straight
//! into the pool where that is safe (host-visible memory no frame in flight reads), else into
//! the slot's staging memory; a compact set's levels as their streams into the staging memory,
//! with the decoder's list; index arrays built on the GPU as the builder's list; texture mips
//! through the staging memory.

use ash::vk;
use memory::budget::TEXTURE_ALIGN;

use super::made::Array;
use super::Renderer;
use crate::error::FrameError;
use crate::fault::Fault;
use crate::plan::Plan;
use crate::settings::TextureFormat;
use crate::terrain::Terrain;
use crate::textures::TexturePlan;
use crate::vulkan::decode::Decode;
use crate::vulkan::indices;
use crate::vulkan::texture;

/// What a frame's commands must copy and build before its pass.
pub(super) struct Uploads {
    /// Copies inside the pool (tiles moved to larger chunks).
    pub moves: Vec<vk::BufferCopy>,
    /// Copies from the slot's staging memory into the pool.
    pub staged: Vec<vk::BufferCopy>,
    /// Index arrays built this frame for tiles drawn part by part, besides the manager's.
    pub part_builds: u32,
    /// Of the frame's builds, those the GPU's builder makes (the first in its list).
    pub on_gpu: u32,
    /// Copies of the index arrays made on the CPU ([`super::made`]) from the staging memory
    /// into the pool (the frame's builds the GPU's builder does not make).
    pub made: Vec<vk::BufferCopy>,
    /// The decoder's list, in waves: how many decodes each holds (a tile's finer level in a
    /// later wave than its coarser one).
    pub decode_waves: Vec<u32>,
    /// Bytes of geometry that went through the staging memory.
    pub staged_geometry: u64,
    /// Copies from the staging memory into the texture array.
    pub texture_copies: Vec<vk::BufferImageCopy>,
}

impl Renderer {
    /// Writes the plan's geometry uploads, then its texture mips, into slot `s`'s memory.
    pub(super) fn write_uploads(
        &mut self,
        terrain: &Terrain,
        plan: &Plan,
        textures: &TexturePlan,
        s: usize,
    ) -> Result<Uploads, FrameError> {
        self.slots[s].staging.reset();
        let moves = plan
            .moves
            .iter()
            .map(|m| {
                vk::BufferCopy::default()
                    .src_offset(m.src)
                    .dst_offset(m.dst)
                    .size(m.bytes)
            })
            .collect();
        if let Some(fault) = self.fault {
            fault.cut_file_before(self.frame, terrain);
        }
        if !plan.uploads.is_empty() {
            check_file(terrain)?;
        }
        let (staged, decodes) = self.write_geometry(terrain, plan, s)?;
        let decode_waves = self.write_decodes(decodes, s)?;
        let staged_geometry = self.slots[s].staging.sent();
        let texture_copies = self.write_texture_uploads(terrain, textures, s)?;
        // Last: arrays made on the CPU take what room the uploads left in the staging memory.
        let (part_builds, on_gpu, made) = self.write_builds(terrain, plan, s)?;
        Ok(Uploads {
            moves,
            staged,
            part_builds,
            on_gpu,
            made,
            decode_waves,
            staged_geometry,
            texture_copies,
        })
    }

    /// Writes the blocks and the index arrays sent from the file, and the compact levels'
    /// streams; returns the staged copies and the levels to decode.
    fn write_geometry(
        &mut self,
        terrain: &Terrain,
        plan: &Plan,
        s: usize,
    ) -> Result<(Vec<vk::BufferCopy>, Vec<Decode>), FrameError> {
        let mut staged = Vec::new();
        let mut decodes = Vec::new();
        for u in plan.uploads.iter().filter(|u| !u.built) {
            self.prefetcher.touched(terrain, u.tile as usize);
            if let (Some(_), memory::Part::Positions(level)) = (u.stream, u.part) {
                decodes.extend(self.stage_stream(terrain, u, level, s)?);
                continue;
            }
            let bytes = terrain
                .part(u.tile as usize, u.part)
                .ok_or(FrameError::MissingPart {
                    tile: u.tile,
                    part: u.part,
                })?;
            if bytes.is_empty() {
                continue;
            }
            if !u.in_flight && self.pool.write(u.dst, bytes) {
                continue;
            }
            let staging = &mut self.slots[s].staging;
            let at = staging.push(bytes).ok_or(FrameError::StagingFull {
                used: staging.used(),
                tile: u.tile,
                what: "",
            })?;
            staged.push(
                vk::BufferCopy::default()
                    .src_offset(at)
                    .dst_offset(u.dst)
                    .size(bytes.len() as u64),
            );
        }
        Ok((staged, decodes))
    }

    /// Puts level `level`'s compact stream of the upload's tile into slot `s`'s staging memory;
    /// returns its decode into the upload's place (None for a level that adds no vertex).
    fn stage_stream(
        &mut self,
        terrain: &Terrain,
        u: &memory::Upload,
        level: u32,
        s: usize,
    ) -> Result<Option<Decode>, FrameError> {
        let l = &terrain.tiles[u.tile as usize].levels[level as usize];
        if l.block_len == 0 {
            return Ok(None);
        }
        let bytes =
            terrain
                .level_stream(u.tile as usize, level)
                .ok_or(FrameError::MissingPart {
                    tile: u.tile,
                    part: u.part,
                })?;
        let staging = &mut self.slots[s].staging;
        let at = staging.push(bytes).ok_or(FrameError::StagingFull {
            used: staging.used(),
            tile: u.tile,
            what: "'s compact level",
        })?;
        let bit =
            |bytes: u64| u32::try_from(8 * bytes).map_err(|_| FrameError::PastIndexing { bytes });
        let word =
            |bytes: u64| u32::try_from(bytes / 4).map_err(|_| FrameError::PastIndexing { bytes });
        Ok(Some(Decode {
            stream_bit: bit(at)?,
            end_bit: bit(at + bytes.len() as u64)?,
            known_word: word(u.chunk)?,
            known_count: l.block_start,
            out_word: word(u.dst)?,
            expected: l.block_len + u32::from(self.fault == Some(Fault::DecodeCount)),
            tile: u.tile,
            level,
        }))
    }

    /// Writes the frame's decodes into slot `s`'s list in waves (a tile's levels arrive in
    /// order, each after the coarser ones it reads); returns each wave's length.
    fn write_decodes(&mut self, decodes: Vec<Decode>, s: usize) -> Result<Vec<u32>, FrameError> {
        let Some(decoder) = self.decoder.as_mut() else {
            return Ok(Vec::new());
        };
        let mut seen: std::collections::HashMap<u32, u32> = std::collections::HashMap::new();
        let mut waved: Vec<(u32, Decode)> = decodes
            .into_iter()
            .map(|d| {
                let n = seen.entry(d.tile).or_insert(0);
                *n += 1;
                (*n - 1, d)
            })
            .collect();
        waved.sort_by_key(|&(wave, _)| wave);
        let waves = waved
            .iter()
            .fold(Vec::new(), |mut waves: Vec<u32>, &(w, _)| {
                waves.resize(waves.len().max(w as usize + 1), 0);
                waves[w as usize] += 1;
                waves
            });
        let list: Vec<Decode> = waved.into_iter().map(|(_, d)| d).collect();

        if !decoder.write(s, &list) {
            return Err(FrameError::TooManyDecodes {
                decodes: list.len(),
                capacity: decoder.capacity(),
            });
        }
        Ok(waves)
    }

    /// Writes the plan's index array builds ([`memory::gpu_builds`]: a build overlapped by a
    /// later one is left out) into slot `s`'s list, or with arrays made on the CPU
    /// ([`super::made`]) into its staging memory as far as it has room; returns how many
    /// builds are for part by part, how many the GPU's builder makes, and the copies of the
    /// arrays made.
    fn write_builds(
        &mut self,
        terrain: &Terrain,
        plan: &Plan,
        s: usize,
    ) -> Result<(u32, u32, Vec<vk::BufferCopy>), FrameError> {
        if self.builder.is_none() {
            return Ok((0, 0, Vec::new()));
        }
        // Part by part (crate::parts): the draws whose arrays are built here, replacing the
        // manager's build where it builds at the same place.
        let rebuilds = self.parts.rebuilds(plan);
        let replaced = |u: &memory::Upload| {
            rebuilds.iter().any(|&k| {
                let d = &plan.draws[k];
                d.tile == u.tile as usize && d.index_offset == u.dst
            })
        };
        let kept = memory::gpu_builds(&plan.uploads);
        let mut builds = Vec::with_capacity(kept.len() + rebuilds.len());
        let word = |bytes: u64, width: u64| {
            u32::try_from(bytes / width).map_err(|_| FrameError::PastIndexing { bytes })
        };
        for u in kept.into_iter().filter(|u| !replaced(u)) {
            let memory::Part::Indices(level) = u.part else {
                return Err(FrameError::BuiltNotIndices {
                    tile: u.tile,
                    part: u.part,
                });
            };
            let tile = &terrain.tiles[u.tile as usize];
            let l = &tile.levels[level as usize];
            let build = indices::Build {
                vertex_word: word(u.chunk, 4)?,
                vertex_count: l.vertex_count(),
                index_at: word(u.dst, u64::from(l.index_width))?,
                index_count: l.index_count,
                index_width: l.index_width,
                mesh_max_x: tile.header.mesh_max_x,
                mesh_max_y: tile.header.mesh_max_y,
                tile: u.tile,
                ..Default::default()
            };
            builds.push((build, u.tile as usize, Array::Level(level)));
        }
        let part_builds = rebuilds.len() as u32;
        for d in rebuilds.into_iter().map(|k| &plan.draws[k]) {
            let tile = &terrain.tiles[d.tile];
            let mut b = indices::Build {
                vertex_word: word(d.vertex_offset, 4)?,
                vertex_count: tile.levels[d.level as usize].vertex_count(),
                index_at: word(d.index_offset, u64::from(d.index_width))?,
                index_count: d.index_count,
                index_width: d.index_width,
                mesh_max_x: tile.header.mesh_max_x,
                mesh_max_y: tile.header.mesh_max_y,
                tile: d.tile as u32,
                ..Default::default()
            };
            let array = match &d.key {
                Some(key) => {
                    b.part_by_part(key, tile.levels.iter().map(|l| l.block_start + l.block_len));
                    Array::Mix(*key)
                }
                None => Array::Level(d.level),
            };
            builds.push((b, d.tile, array));
        }
        let (made, on_gpu) = match self.options.build_on_gpu {
            true => (Vec::new(), builds.into_iter().map(|b| b.0).collect()),
            false => super::made::make(terrain, builds, &mut self.slots[s].staging)?,
        };
        let Some(builder) = self.builder.as_mut() else {
            return Ok((0, 0, Vec::new()));
        };
        if !builder.write(s, &on_gpu) {
            return Err(FrameError::TooManyBuilds {
                builds: on_gpu.len(),
                capacity: builder.capacity(),
            });
        }
        Ok((part_builds, on_gpu.len() as u32, made))
    }

    /// Writes the frame's texture mips into the slot's staging memory; returns the copies.
    fn write_texture_uploads(
        &mut self,
        terrain: &Terrain,
        textures: &TexturePlan,
        s: usize,
    ) -> Result<Vec<vk::BufferImageCopy>, FrameError> {
        let mut copies = Vec::with_capacity(textures.uploads.len());
        for u in &textures.uploads {
            let bytes = terrain.texture_mip(u.tile as usize, u.mip).ok_or(
                FrameError::MissingTextureMip {
                    tile: u.tile,
                    mip: u.mip,
                },
            )?;
            let texels = self.textures.desc.size >> u.mip;
            let decoded;
            let bytes = match self.options.texture_format {
                TextureFormat::Bc1 => bytes,
                TextureFormat::Rgb565 => {
                    decoded = crate::textures::rgb565_of_bc1(bytes, texels.max(1));
                    &decoded[..]
                }
            };
            let staging = &mut self.slots[s].staging;
            let at = staging
                .push_aligned(bytes, TEXTURE_ALIGN)
                .ok_or(FrameError::StagingFull {
                    used: staging.used(),
                    tile: u.tile,
                    what: "'s texture",
                })?;
            copies.push(texture::copy_region(at, u.slot, u.mip, texels.max(1)));
        }
        Ok(copies)
    }
}

/// Reading a mapped file that shrank would fault (SIGBUS): its length is checked before a
/// frame's reads. (A file cut between this check and the copies can still fault; tile sets are
/// meant to be replaced by rename, as tiletool writes them.)
fn check_file(terrain: &Terrain) -> Result<(), FrameError> {
    let path = terrain.set.path();
    let was = terrain.set.file_len();
    match std::fs::metadata(path).map(|m| m.len()) {
        Ok(len) if len >= was => Ok(()),
        now => Err(FrameError::FileChanged {
            path: path.to_path_buf(),
            now: now.map_or_else(|e| e.to_string(), |l| l.to_string()),
            was,
        }),
    }
}

/// The error for a build whose array did not come out as the file says.
pub(super) fn build_failure(f: indices::BuildFailure) -> String {
    let got = if f.got == u32::MAX {
        "lacks a vertex its fans need".to_string()
    } else {
        format!("has {} indices", f.got)
    };
    format!(
        "tile #{}: the index array built from its vertices {got} where the tile set says {} ({} such builds in the frame): the file's vertices do not make the mesh it claims",
        f.tile, f.expected, f.failed
    )
}

/// The error for a compact level the GPU refused to decode (a stream that passed the tile's
/// check on the CPU: the two decoders disagree).
pub(super) fn decode_failure(f: crate::vulkan::decode::DecodeFailure) -> String {
    format!(
        "tile #{} level {}: the GPU refused its compact stream ({:?}) that the CPU decoded ({} such levels in the frame)",
        f.tile, f.level, f.reason, f.failed
    )
}
