//! `tiletool export`: one level of one tile as a Wavefront OBJ, for MeshLab or Blender; or
//! one mip of its texture as a PNG.
//!
//! x is the source column, y the source row (both of the whole grid), z the stored elevation in
//! metres (after quantisation). Fans are expanded to triangles, wound counter-clockwise seen
//! from above with y pointing south, so viewers that treat y as up show the terrain mirrored
//! north-south but with correct normals.

use std::fmt::Write as _;
use std::path::Path;
use std::process::ExitCode;

use anyhow::{bail, Context, Result};

pub fn run(file: &Path, (tx, ty): (u32, u32), level: u32, output: &Path) -> Result<ExitCode> {
    let set = open_at(file, (tx, ty))?;
    let h = set.header();
    if level >= h.levels {
        bail!(
            "{}: level {level} does not exist (levels 0..={})",
            file.display(),
            h.levels - 1
        );
    }
    let tile = set.tile(tx, ty)?;
    let l = tile.level(level).context("level")?;
    let vertices = tile.vertices();
    let used = l.entry.vertex_count() as usize;
    let mut obj = String::with_capacity(used * 32 + l.entry.triangle_count as usize * 24);
    let _ = writeln!(
        obj,
        "# {} tile {tx},{ty} level {level}: e_i = {} m, measured max error {} m",
        file.display(),
        l.entry.error_bound,
        l.entry.max_error
    );
    let _ = writeln!(
        obj,
        "# x = source column, y = source row, z = elevation (m)"
    );
    let (ox, oy) = (tx * 256, ty * 256);
    for &(x, y, z) in &vertices[..used] {
        let _ = writeln!(obj, "v {} {} {z}", ox + x, oy + y);
    }
    for fan in l.indices.fans() {
        for w in fan[1..].windows(2) {
            // OBJ indices are 1-based.
            let _ = writeln!(obj, "f {} {} {}", fan[0] + 1, w[0] + 1, w[1] + 1);
        }
    }
    tiles::format::write_atomically(output, obj.as_bytes())
        .with_context(|| format!("{}: cannot write", output.display()))?;
    println!(
        "{}: {} vertices, {} triangles",
        output.display(),
        used,
        l.entry.triangle_count
    );
    Ok(ExitCode::SUCCESS)
}

/// Opens `file`, refusing a tile `(tx, ty)` outside it.
fn open_at(file: &Path, (tx, ty): (u32, u32)) -> Result<tiles::TileSet> {
    let set = tiles::TileSet::open(file)?;
    let h = set.header();
    if tx >= h.tiles_x || ty >= h.tiles_y {
        bail!(
            "{}: tile {tx},{ty} is outside the {}x{} tiles",
            file.display(),
            h.tiles_x,
            h.tiles_y
        );
    }
    Ok(set)
}

/// Mip `mip` of tile `(tx, ty)`'s texture, BC1-decoded, as a PNG (gutter included).
pub fn texture(file: &Path, (tx, ty): (u32, u32), mip: u32, output: &Path) -> Result<ExitCode> {
    let set = open_at(file, (tx, ty))?;
    let Some(texture) = set.texture(tx, ty)? else {
        bail!("{}: the tile set has no textures", file.display());
    };
    let Some((entry, blocks)) = texture.mips.get(mip as usize) else {
        bail!(
            "{}: texture mip {mip} does not exist (mips 0..={})",
            file.display(),
            texture.mips.len() - 1
        );
    };
    let (w, h) = (entry.width, entry.height);
    let rgba = tiles::texture::decode_bc1(blocks, w as usize, h as usize);
    let image = image::RgbaImage::from_raw(w, h, rgba).context("decoded size")?;
    let mut png = Vec::new();
    image
        .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .with_context(|| format!("{}: cannot encode", output.display()))?;
    tiles::format::write_atomically(output, &png)
        .with_context(|| format!("{}: cannot write", output.display()))?;
    println!(
        "{}: {w}x{h} texels, PSNR {:.2} dB against the filtered mip",
        output.display(),
        entry.psnr()
    );
    Ok(ExitCode::SUCCESS)
}
