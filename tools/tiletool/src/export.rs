//! `tiletool export`: one level of one tile as a Wavefront OBJ, for MeshLab or Blender.
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
    let tmp = output.with_file_name(format!(
        ".{}.tmp.{}",
        output
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default(),
        std::process::id()
    ));
    std::fs::write(&tmp, obj).with_context(|| format!("{}: cannot write", output.display()))?;
    if let Err(e) = std::fs::rename(&tmp, output) {
        let _ = std::fs::remove_file(&tmp);
        bail!("{}: cannot write: {e}", output.display());
    }
    println!(
        "{}: {} vertices, {} triangles",
        output.display(),
        used,
        l.entry.triangle_count
    );
    Ok(ExitCode::SUCCESS)
}
