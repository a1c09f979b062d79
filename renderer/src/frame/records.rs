//! What a frame writes for its shaders and its log: the stitches' indices, the morph constants
//! and one record per draw (the shader interface, [`crate::interface`]), and the frame's log
//! record from its plan.

use bytemuck::Zeroable;
use tiles::parts::PartKey;

use crate::camera::Camera;
use crate::error::FrameError;
use crate::fault::Fault;
use crate::interface::{FrameConstants, LevelCoefficients, MorphFrame, TileRecord, RECORDS_OFFSET};
use crate::log::FrameRecord;
use crate::morph::{MorphRule, TileMorph, MAX_LEVELS};
use crate::plan::Plan;
use crate::stitch::{Stitch, MAX_RECORDS};
use crate::terrain::Terrain;
use crate::textures::TexturePlan;
use crate::vulkan::Buffer;

use super::pass::DrawCounts;

/// Writes this frame's stitches (their pulled indices) into `buffer`; returns per stitch
/// (first index, index count).
pub(super) fn write_stitches(
    buffer: &mut Buffer,
    stitches: &[(usize, Stitch)],
) -> Result<Vec<(u32, u32)>, FrameError> {
    let mut ranges = Vec::with_capacity(stitches.len());
    let mut indices: Vec<u32> = Vec::new();
    for (_, s) in stitches {
        ranges.push((indices.len() as u32, s.indices.len() as u32));
        indices.extend(s.gpu_indices());
    }
    if !indices.is_empty() && !buffer.write(0, bytemuck::cast_slice(&indices)) {
        return Err(FrameError::StitchesOverflow {
            bytes: 4 * indices.len() as u64,
            capacity: buffer.size,
        });
    }
    Ok(ranges)
}

/// One draw as its record describes it: the tile, its level, where its vertices' heights go
/// in the read-back buffer, how it morphs (None: discrete), and its parts' levels when it is
/// drawn part by part (None: at its level throughout).
pub type DrawnTile = (usize, u32, usize, Option<TileMorph>, Option<PartKey>);

/// Where a record's vertices go: the tile's first sample relative to the camera's tile, its
/// layer (its samples `2^layer` base samples apart) and its layer's height lattice.
fn place(
    r: &mut TileRecord,
    terrain: &Terrain,
    info: &crate::tile::TileInfo,
    cam_tile: (f64, f64),
) {
    r.tile_offset = Terrain::tile_offset(cam_tile, info);
    (r.height_base, r.height_step) = (info.header.height_base, terrain.height_step_of(info));
    r.layer = info.layer;
}

/// Writes the frame's morph constants and tile records, one per draw in order (a draw's record
/// is its index); returns each draw as written, with how it morphs only when `describe` (for
/// the error meter and the read-back), and how many draws are unmorphed because the morph
/// pass's heights (`capacity` of them) cannot hold the frame's vertices. Then every draw is: their
/// records say `heights` = `u32::MAX`, the morph pass skips them and the vertex shader draws
/// their own heights, so the frame is drawn as discrete levels are, crack-free (a morphed
/// tile beside an unmorphed one would open a seam).
pub(super) fn write_records(
    buffer: &mut Buffer,
    terrain: &Terrain,
    camera: &Camera,
    (plan, textures): (&Plan, &TexturePlan),
    morph: Option<(&MorphFrame, &FrameConstants)>,
    fault: Option<Fault>,
    (describe, capacity): (bool, usize),
) -> Result<(Vec<DrawnTile>, u64), FrameError> {
    if plan.draws.len() > MAX_RECORDS {
        return Err(FrameError::TooManyTiles {
            tiles: plan.draws.len(),
            max: MAX_RECORDS,
        });
    }
    let (cam_tile, _) = terrain.camera_tile(camera.position);
    let mut drawn = Vec::with_capacity(plan.draws.len());
    let mut heights = 0usize;
    // Only the morph pass needs room (its frames count their draws); other frames' offsets
    // serve the read-back alone.
    let pass = morph.is_some_and(|(_, c)| c.draws > 0);
    let placed = !pass || drawn_vertices(terrain, plan) <= capacity;
    let unmorphed = if placed { 0 } else { plan.draws.len() as u64 };
    let records: Vec<TileRecord> = plan
        .draws
        .iter()
        .zip(&textures.draws)
        .map(|(d, texture)| {
            let info = &terrain.tiles[d.tile];
            let mut r = TileRecord::zeroed();
            (r.texture_layer, r.texture_finest) = match texture {
                Some(t) => (t.layer, t.finest as f32),
                None => (u32::MAX, 0.0),
            };
            if let Some(fault) = fault {
                fault.spoil_record(&mut r, info);
            }
            place(&mut r, terrain, info, cam_tile);
            r.positions = (d.vertex_offset / 4) as u32;
            (r.level, r.cap) = (d.level, d.level as f32);
            r.heights = if placed { heights as u32 } else { u32::MAX };
            let levels = d.key.map_or([d.level as u8; 16], |k| k.levels);
            [r.parts_lo, r.parts_hi] = tiles::parts::packed_levels(&levels);
            let mut starts = [u32::MAX; 8];
            let (mut start, mut rows) = (0u32, d.morph_offset as u32);
            for (j, l) in info.levels.iter().enumerate().take(MAX_LEVELS) {
                r.blocks[j] = [start, l.block_len, rows, 0];
                if j > 0 {
                    starts[j - 1] = start;
                }
                if j < 8 {
                    r.units[j] = l.morph_unit;
                }
                start += l.block_len;
                rows += (j as u32 * l.block_len).div_ceil(4) * 4;
            }
            (r.starts_lo, r.starts_hi) = split(starts);
            if morph.is_some() {
                r.tables = info.tables.map(|t| LevelCoefficients::of(&t));
                r.extent = [info.header.mesh_max_x, info.header.mesh_max_y, 0, 0];
            }
            let tile_morph = morph
                .filter(|_| describe && placed)
                .map(|(frame, c)| TileMorph {
                    view_proj: glam::Mat4::from_cols_array(&c.view_proj),
                    camera: glam::Vec4::from_array(c.camera),
                    spacing_y: c.spacing_y,
                    height_step: r.height_step,
                    frame: *frame,
                    tile_offset: r.tile_offset,
                    cap: r.cap,
                    tables: r.tables,
                    extent: [r.extent[0], r.extent[1]],
                    layer: r.layer,
                    parts: d.key,
                    // The morph pass runs exactly when the frame's constants count its draws.
                    rule: if c.draws > 0 {
                        MorphRule::Hierarchical
                    } else {
                        MorphRule::TwoLevels
                    },
                });
            drawn.push((d.tile, d.level, heights, tile_morph, d.key));
            heights += info.levels[d.level as usize].vertex_count() as usize;
            r
        })
        .collect();
    let frame = morph.map_or_else(MorphFrame::zeroed, |(m, _)| *m);
    let written = buffer.write(0, bytemuck::bytes_of(&frame))
        && (records.is_empty()
            || buffer.write(RECORDS_OFFSET as usize, bytemuck::cast_slice(&records)));
    if !written {
        return Err(FrameError::RecordsOverflow {
            records: records.len(),
            capacity: buffer.size,
        });
    }
    Ok((drawn, unmorphed))
}

/// The vertices of `plan`'s drawn levels, all of each (the morphed heights a frame needs: the
/// records' `heights` offsets count the same).
pub(super) fn drawn_vertices(terrain: &Terrain, plan: &Plan) -> usize {
    plan.draws
        .iter()
        .map(|d| terrain.tiles[d.tile].levels[d.level as usize].vertex_count() as usize)
        .sum()
}

/// The halves of an eight-element array (a record's `_lo` and `_hi` vectors).
fn split<T: Copy + Default>(a: [T; 8]) -> ([T; 4], [T; 4]) {
    (
        std::array::from_fn(|i| a[i]),
        std::array::from_fn(|i| a[i + 4]),
    )
}

/// The frame's record from its plan (times and GPU results are added later).
pub(super) fn frame_record(
    plan: &Plan,
    textures: &TexturePlan,
    counts: DrawCounts,
    levels: u32,
) -> FrameRecord {
    let st = &plan.stats;
    let mut tiles_per_level = vec![0; levels as usize];
    for d in &plan.draws {
        tiles_per_level[d.level as usize] += 1;
    }
    FrameRecord {
        cpu_cull_ms: plan.cpu_cull_ms,
        cpu_lod_ms: plan.cpu_lod_ms,
        cpu_stitch_ms: plan.cpu_stitch_ms,
        cpu_residency_ms: plan.cpu_residency_ms,
        cpu_check_ms: plan.cpu_check_ms,
        tiles_checked: plan.tiles_checked,
        tiles_failed: plan.tiles_failed,
        gpu_ms: f64::NAN,
        gpu_draw_ms: f64::NAN,
        tiles_visible: plan.tiles_visible,
        tiles_drawn: plan.draws.len() as u64,
        triangles: counts.triangles,
        vertices: counts.vertices,
        stitch_triangles: counts.stitch_triangles,
        tiles_photo: counts.photo,
        upload_bytes: st.upload_bytes_blocks + st.upload_bytes_indices,
        resident_bytes: st.resident_bytes,
        evictions: st.evictions,
        upload_bytes_blocks: st.upload_bytes_blocks,
        upload_bytes_indices: st.upload_bytes_indices,
        index_builds: st.index_builds,
        index_build_bytes: st.index_build_bytes,
        upload_bytes_coarser: st.upload_bytes_coarser,
        uploads_deferred_bytes: st.uploads_deferred_bytes,
        upload_overshoot_bytes: st.upload_overshoot_bytes,
        tiles_coarser: st.tiles_coarser,
        tiles_missing: st.tiles_missing,
        chunks_free: st.chunks_free,
        chunk_moves: st.chunk_moves,
        chunk_move_bytes: st.chunk_move_bytes,
        hits: st.hits,
        misses: st.misses,
        used_bytes: st.used_bytes,
        prefetch_bytes: st.prefetch_bytes,
        prefetch_hits: st.prefetch_hits,
        prefetch_wasted_bytes: st.prefetch_wasted_bytes,
        upload_bytes_textures: textures.stats.upload_bytes,
        texture_slots_free: u64::from(textures.stats.slots_free),
        tiles_texture_coarser: u64::from(textures.stats.coarser + textures.stats.without_slot),
        tiles_per_level,
        max_error_px: f64::NAN,
        pop_px: f64::NAN,
        prediction_error_m: f64::NAN,
        heights_max_diff_m: f64::NAN,
        ..Default::default()
    }
}

/// The draws whose heights the read-back buffer receives, and how many heights they write.
pub(super) fn read_back_draws(terrain: &Terrain, drawn: Vec<DrawnTile>) -> (Vec<DrawnTile>, usize) {
    let n = drawn.last().map_or(0, |&(tile, level, start, _, _)| {
        start + terrain.tiles[tile].levels[level as usize].vertex_count() as usize
    });
    (drawn, n)
}
