//! `tiletool info`: what a tile set holds, per level, from the file alone.

use std::path::Path;
use std::process::ExitCode;

use anyhow::Result;
use serde::Serialize;

#[derive(Serialize, Default, Clone)]
struct LevelInfo {
    level: u32,
    error_bound_m: f64,
    max_error_m: f64,
    vertices: u64,
    triangles: u64,
    indices: u64,
    bytes: u64,
    /// Tile levels where the spacing rule (or full resolution) left the error above e_i.
    limited_tiles: u64,
    limited_triangles: u64,
    limited_max_excess_m: f64,
    limited_worst_tile: Option<(u32, u32)>,
}

#[derive(Serialize, Default, Clone)]
struct MipInfo {
    mip: u32,
    size: u32,
    bytes: u64,
    /// Of the BC1-decoded mips against the filtered mips they were compressed from.
    psnr_db: f64,
    #[serde(skip)]
    squared_error: f64,
    #[serde(skip)]
    texels: u64,
}

#[derive(Serialize)]
struct TextureInfo {
    format: &'static str,
    /// photo, relief or tinted relief.
    source: &'static str,
    /// How the texture lies on the heights.
    placement: &'static str,
    interior_texels: u32,
    gutter_texels: u32,
    layer_texels: u32,
    /// Mips whose texel grid lines up with the tiles (seam-free filtering).
    aligned_mips: u32,
    bytes: u64,
    mips: Vec<MipInfo>,
}

/// One layer of the tile pyramid above the base grid.
#[derive(Serialize)]
struct LayerInfo {
    layer: u32,
    /// Base samples per layer sample.
    factor: u32,
    grid_width: u32,
    grid_height: u32,
    tiles_x: u32,
    tiles_y: u32,
    spacing_x_m: f64,
    spacing_y_m: f64,
    /// The largest of the layer's tiles' decimation errors: base samples lie at most this far
    /// from a tile's finest surface.
    max_decimation_error_m: f32,
    /// Summed over the layer's tiles and levels.
    triangles: u64,
    bytes: u64,
}

#[derive(Serialize)]
struct Info {
    file: String,
    file_bytes: u64,
    format_version: u32,
    description: String,
    grid_width: u32,
    grid_height: u32,
    spacing_x_m: f64,
    spacing_y_m: f64,
    height_min_m: f32,
    height_max_m: f32,
    voids_filled: u64,
    tiles_x: u32,
    tiles_y: u32,
    tile_size: u32,
    base_error_m: f64,
    levels: Vec<LevelInfo>,
    texture: Option<TextureInfo>,
    /// The tile pyramid above the base grid, from layer 1 (empty: none).
    pyramid: Vec<LayerInfo>,
}

/// The pyramid's layers, from their directories and tiles (each tile's checksum checked).
fn pyramid(set: &tiles::TileSet) -> Result<Vec<LayerInfo>> {
    let mut out = Vec::new();
    for p in 1..=set.pyramid_layers() {
        let layer = set.layer(p).expect("a layer the set has");
        let h = *layer.header();
        let (mut d, mut triangles, mut bytes) = (0.0f32, 0u64, 0u64);
        for ty in 0..h.tiles_y {
            for tx in 0..h.tiles_x {
                d = d.max(layer.decimation_error(tx, ty).unwrap_or(0.0));
                let tile = layer.tile(tx, ty)?;
                bytes += tile.blob_len() as u64;
                triangles += tile
                    .levels()
                    .iter()
                    .map(|e| u64::from(e.triangle_count))
                    .sum::<u64>();
            }
        }
        out.push(LayerInfo {
            layer: p,
            factor: 1 << p,
            grid_width: h.grid_width,
            grid_height: h.grid_height,
            tiles_x: h.tiles_x,
            tiles_y: h.tiles_y,
            spacing_x_m: h.spacing_x,
            spacing_y_m: h.spacing_y,
            max_decimation_error_m: d,
            triangles,
            bytes,
        });
    }
    Ok(out)
}

pub fn run(file: &Path, json: bool) -> Result<ExitCode> {
    let set = tiles::TileSet::open(file)?;
    let h = *set.header();
    let mut levels: Vec<LevelInfo> = (0..h.levels)
        .map(|i| LevelInfo {
            level: i,
            error_bound_m: set.level_error(i),
            ..Default::default()
        })
        .collect();
    for ty in 0..h.tiles_y {
        for tx in 0..h.tiles_x {
            let tile = set.tile(tx, ty)?;
            let mut block_bytes = 0u64;
            for (i, e) in tile.levels().iter().enumerate() {
                let l = &mut levels[i];
                block_bytes += u64::from(e.block_len) * (4 + i as u64);
                l.max_error_m = l.max_error_m.max(f64::from(e.max_error));
                l.vertices += u64::from(e.vertex_count());
                l.triangles += u64::from(e.triangle_count);
                l.indices += u64::from(e.index_count);
                l.bytes += block_bytes + u64::from(e.index_count) * u64::from(e.index_width);
                if e.limited_triangles > 0 {
                    l.limited_tiles += 1;
                    l.limited_triangles += u64::from(e.limited_triangles);
                    if f64::from(e.limited_excess) >= l.limited_max_excess_m {
                        l.limited_max_excess_m = f64::from(e.limited_excess);
                        l.limited_worst_tile = Some((tx, ty));
                    }
                }
            }
        }
    }
    let texture = match set.texture_layout() {
        None => None,
        Some(layout) => {
            use tiles::texture::{SOURCE_GEOREFERENCED_PHOTO, SOURCE_PHOTO, SOURCE_RELIEF};
            let mut mips: Vec<MipInfo> = (0..layout.mips)
                .map(|m| MipInfo {
                    mip: m,
                    size: layout.mip_size(m),
                    ..Default::default()
                })
                .collect();
            for ty in 0..h.tiles_y {
                for tx in 0..h.tiles_x {
                    let t = set.texture(tx, ty)?.expect("the set has textures");
                    for (sum, (e, bytes)) in mips.iter_mut().zip(&t.mips) {
                        sum.bytes += bytes.len() as u64;
                        sum.squared_error += e.squared_error;
                        sum.texels += e.texels;
                    }
                }
            }
            for m in &mut mips {
                m.psnr_db = tiles::texture::psnr(m.squared_error, m.texels);
            }
            let (source, placement) = match h.texture_source {
                SOURCE_PHOTO => (
                    "photo",
                    "spans the height grid exactly (first to last column and row): it had no georeferencing, or the heights had none",
                ),
                SOURCE_GEOREFERENCED_PHOTO => (
                    "photo",
                    "aligned with the heights by both files' georeferencing (grey where the photo does not reach)",
                ),
                SOURCE_RELIEF => ("relief", "computed from the heights"),
                _ => ("tinted relief", "computed from the heights"),
            };
            Some(TextureInfo {
                format: "BC1",
                source,
                placement,
                interior_texels: layout.interior,
                gutter_texels: layout.gutter,
                layer_texels: layout.size,
                aligned_mips: layout.aligned_mips(),
                bytes: mips.iter().map(|m| m.bytes).sum(),
                mips,
            })
        }
    };
    let info = Info {
        file: file.display().to_string(),
        file_bytes: set.file_len(),
        format_version: h.version,
        description: set.description(),
        grid_width: h.grid_width,
        grid_height: h.grid_height,
        spacing_x_m: h.spacing_x,
        spacing_y_m: h.spacing_y,
        height_min_m: h.height_min,
        height_max_m: h.height_max,
        voids_filled: h.voids_filled,
        tiles_x: h.tiles_x,
        tiles_y: h.tiles_y,
        tile_size: h.tile_size,
        base_error_m: h.base_error,
        levels,
        texture,
        pyramid: pyramid(&set)?,
    };
    if json {
        println!("{}", serde_json::to_string_pretty(&info)?);
        return Ok(ExitCode::SUCCESS);
    }
    println!(
        "{}  ({:.1} MB, format v{})",
        info.file,
        info.file_bytes as f64 / 1e6,
        info.format_version
    );
    println!("  source    {}", info.description);
    println!(
        "  grid      {} x {} samples, spacing {:.2} x {:.2} m, heights {:.1}..{:.1} m, {} voids filled",
        info.grid_width, info.grid_height, info.spacing_x_m, info.spacing_y_m, info.height_min_m, info.height_max_m, info.voids_filled
    );
    println!(
        "  tiles     {} x {} ({}) of {} x {}, {} levels, base error {} m",
        info.tiles_x,
        info.tiles_y,
        info.tiles_x * info.tiles_y,
        info.tile_size,
        info.tile_size,
        info.levels.len(),
        info.base_error_m
    );
    println!("  level     e_i (m)   max err (m)     vertices    triangles        bytes");
    for l in &info.levels {
        println!(
            "  {:>5} {:>11} {:>13.3} {:>12} {:>12} {:>12}",
            l.level, l.error_bound_m, l.max_error_m, l.vertices, l.triangles, l.bytes
        );
    }
    match &info.texture {
        None => println!("  texture   none (the renderer lights the terrain itself)"),
        Some(t) => {
            println!(
                "  texture   {} {}, {}: {} texels per tile + {}-texel gutters = {} per layer, {} mips ({} aligned), {:.1} MB",
                t.format, t.source, t.placement, t.interior_texels, t.gutter_texels, t.layer_texels,
                t.mips.len(), t.aligned_mips, t.bytes as f64 / 1e6
            );
            println!("    mip      texels   PSNR (dB)        bytes");
            for m in &t.mips {
                println!(
                    "  {:>5} {:>11} {:>11.2} {:>12}",
                    m.mip,
                    format!("{0}x{0}", m.size),
                    m.psnr_db,
                    m.bytes
                );
            }
        }
    }
    if info.pyramid.is_empty() {
        println!("  pyramid   none (built without --pyramid, or a single tile)");
    } else {
        println!("  pyramid   layer  factor        grid  tiles   spacing (m)  decimation error (m)    triangles        bytes");
    }
    for l in &info.pyramid {
        println!(
            "  {:>13} {:>7} {:>11} {:>6} {:>13.1} {:>21.3} {:>12} {:>12}",
            l.layer,
            l.factor,
            format!("{}x{}", l.grid_width, l.grid_height),
            l.tiles_x * l.tiles_y,
            l.spacing_x_m,
            l.max_decimation_error_m,
            l.triangles,
            l.bytes
        );
    }
    let limited: Vec<&LevelInfo> = info.levels.iter().filter(|l| l.limited_tiles > 0).collect();
    if !limited.is_empty() {
        println!("  where the spacing rule (cell spacing below e_i) stopped refinement above e_i:");
        for l in limited {
            let (wx, wy) = l.limited_worst_tile.unwrap_or_default();
            println!(
                "    level {}: {} tiles, {} triangles, up to {:.3} m over e_i = {} m (worst: tile {wx},{wy})",
                l.level, l.limited_tiles, l.limited_triangles, l.limited_max_excess_m, l.error_bound_m
            );
        }
    }
    Ok(ExitCode::SUCCESS)
}
