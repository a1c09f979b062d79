//! Texture tiles (paper, section 5): one pre-lit colour texture per geometry tile, a photo or
//! a shaded relief, filtered into a mip pyramid with a Lanczos kernel and compressed to BC1.
//!
//! # Texel-to-sample mapping
//!
//! A tile spans 256 x 256 cells of the height grid (samples 0..=256 of its own). Its texture
//! has an *interior* of `T x T` texels (`T` a power of two) covering exactly those cells, so
//! interior texel `i` covers tile-local sample coordinates `[i, i + 1) * 256 / T` and has its
//! centre at `(i + 0.5) * 256 / T`. Around the interior lies a *gutter* of `g = T / 32` texels
//! on every side, holding the neighbouring tiles' texels, so the stored layer is
//! `S = T + 2g` texels square and a tile-local sample coordinate `s` maps to
//!
//! ```text
//! u = (g + s * T / 256) / S          (v likewise, rows running south)
//! ```
//!
//! The interiors of all tiles are windows of one global texel grid, and a gutter texel holds
//! exactly what the neighbour's interior texel there holds, at every mip whose texel grid
//! still lines up with the tile: bilinear and trilinear filtering across a tile's edge read
//! the same values from either side, so there is no seam.
//!
//! # Mips
//!
//! Mip `m` is `S >> m` texels square (the size Vulkan gives a mip chain of an `S`-texel image)
//! down to 4 x 4, one BC1 block. `S = 17 * T / 16`, so for `m <= log2(T) - 4` the mip is
//! exactly `S / 2^m` and its gutter `g / 2^m >= 0.5` texel: these are the *aligned* mips,
//! computed as one dyadic Lanczos pyramid over a margin wide enough that every stored texel
//! has all its taps (tiles then agree texel for texel). The remaining coarse mips (2 for
//! `T = 512`: 8 and 4 texels) are resampled from the last aligned one to their rounded sizes;
//! they serve tiles a few pixels across, where a seam is below a pixel.

pub mod lanczos;
pub mod relief;

use bytemuck::{Pod, Zeroable};

use crate::grid::Grid;
use crate::mesh::TILE_CELLS;
use lanczos::{resample, Image};
use relief::Lighting;

/// `FileHeader::texture_format`: no textures.
pub const FORMAT_NONE: u32 = 0;
/// `FileHeader::texture_format`: BC1 (DXT1) RGB blocks, 8 bytes per 4 x 4 texels.
pub const FORMAT_BC1: u32 = 1;

/// `FileHeader::texture_source`: what the texture shows.
pub const SOURCE_PHOTO: u32 = 1;
pub const SOURCE_RELIEF: u32 = 2;
pub const SOURCE_TINTED_RELIEF: u32 = 3;
/// A photo laid on the heights by its georeferencing (`SOURCE_PHOTO` spans the grid).
pub const SOURCE_GEOREFERENCED_PHOTO: u32 = 4;

pub const TEXTURE_MAGIC: [u8; 4] = *b"TXTR";

/// The smallest and largest interior a tile's texture may have, texels.
pub const MIN_INTERIOR: u32 = 64;
pub const MAX_INTERIOR: u32 = 4096;

/// The size of every tile's texture layer and its mip chain (see the module documentation).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Layout {
    /// `T`: texels across the tile's 256 cells.
    pub interior: u32,
    /// `g = T / 32`: texels of the neighbours on each side.
    pub gutter: u32,
    /// `S = T + 2g`: texels across the stored layer (mip 0).
    pub size: u32,
    /// Mips stored, `S >> m` down to 4 texels.
    pub mips: u32,
}

impl Layout {
    pub fn new(interior: u32) -> Result<Layout, String> {
        if !interior.is_power_of_two() || !(MIN_INTERIOR..=MAX_INTERIOR).contains(&interior) {
            return Err(format!(
                "{interior} texels per tile: must be a power of two in {MIN_INTERIOR}..={MAX_INTERIOR}"
            ));
        }
        let gutter = interior / 32;
        let size = interior + 2 * gutter;
        let mips = (0..32).take_while(|&m| size >> m >= 4).count() as u32;
        Ok(Layout {
            interior,
            gutter,
            size,
            mips,
        })
    }

    /// Texels across mip `m`.
    pub fn mip_size(&self, m: u32) -> u32 {
        (self.size >> m).max(1)
    }

    /// Mips `0..aligned_mips()` line up with the tile and have at least half a texel of
    /// gutter: filtering them shows no seam.
    pub fn aligned_mips(&self) -> u32 {
        self.interior.trailing_zeros() - 4 + 1
    }

    /// The texture coordinate (0..1 across the layer) of tile-local sample coordinate `s`.
    pub fn uv(&self, s: f64) -> f64 {
        (f64::from(self.gutter) + s * f64::from(self.interior) / f64::from(TILE_CELLS))
            / f64::from(self.size)
    }

    /// BC1 bytes of mip `m`.
    pub fn mip_bytes(&self, m: u32) -> usize {
        let blocks = self.mip_size(m).div_ceil(4) as usize;
        blocks * blocks * 8
    }

    /// BC1 bytes of the whole chain.
    pub fn bytes(&self) -> usize {
        (0..self.mips).map(|m| self.mip_bytes(m)).sum()
    }

    /// Texels of margin around mip `m`'s layer that the dyadic pyramid needs so every texel
    /// of the aligned mips below has all its taps: 0 at the last aligned mip, and each finer
    /// mip `2 * margin + 3` (a reduction by two reads 4 texels either side of a centre that
    /// sits half a texel off the grid).
    /// Grid rows (or columns) beyond a tile's own 257 that its texture reads: the gutter and
    /// the finer mips' margins, one more for rounding out the bilinear taps, one for the
    /// relief's normals. A banded build holds them with the tile's band.
    pub fn rows_beyond_tile(&self) -> usize {
        let cells_per_texel = f64::from(TILE_CELLS) / f64::from(self.interior);
        (f64::from(self.gutter + self.margin(0)) * cells_per_texel).ceil() as usize + 2
    }

    fn margin(&self, m: u32) -> u32 {
        let last = self.aligned_mips() - 1;
        (m..last).fold(0, |e, _| 2 * e + 3)
    }
}

/// Where the height grid lies on a photo, in the photo's *pixel-edge* coordinates (pixel `p`
/// spans `[p, p + 1)`, its centre at `p + 0.5`): grid sample `(column, row)` lies at
/// `(origin.0 + column * step.0, origin.1 + row * step.1)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame {
    pub origin: (f64, f64),
    /// Photo pixels per grid cell, across and down.
    pub step: (f64, f64),
}

/// A photo (or any RGB picture) to drape over the heights, and where it lies on them.
#[derive(Clone, Debug)]
pub struct Photo {
    pub width: usize,
    pub height: usize,
    /// RGB, 3 bytes per pixel, row-major, row 0 north.
    pub rgb: Vec<u8>,
    pub frame: Frame,
    /// Whether `frame` comes from georeferencing (else the photo spans the grid).
    pub georeferenced: bool,
}

/// What the texture shows where the photo does not reach: a neutral grey, plainly not terrain.
pub const UNCOVERED: [f32; 3] = [128.0; 3];

impl Photo {
    /// A photo taken to cover the height grid exactly: its left edge on column 0, its right
    /// edge on the last column, top on row 0, bottom on the last row.
    pub fn spanning(width: usize, height: usize, rgb: Vec<u8>, grid: &Grid) -> Photo {
        let step = (
            width as f64 / (grid.width - 1) as f64,
            height as f64 / (grid.height - 1) as f64,
        );
        Photo {
            width,
            height,
            rgb,
            frame: Frame {
                origin: (0.0, 0.0),
                step,
            },
            georeferenced: false,
        }
    }

    /// Pixels across one grid cell (the photo's own density).
    pub fn pixels_per_cell(&self) -> f64 {
        self.frame.step.0.max(self.frame.step.1)
    }

    /// Whether grid position `(c, r)` (in cells, clamped into the grid first: beyond the grid
    /// the texture repeats its edge) lies on the photo.
    fn covers(&self, grid: &Grid, (c, r): (f64, f64)) -> bool {
        let c = c.clamp(0.0, (grid.width - 1) as f64);
        let r = r.clamp(0.0, (grid.height - 1) as f64);
        let x = self.frame.origin.0 + c * self.frame.step.0;
        let y = self.frame.origin.1 + r * self.frame.step.1;
        (0.0..=self.width as f64).contains(&x) && (0.0..=self.height as f64).contains(&y)
    }

    /// The fraction of the height grid's area the photo covers.
    pub fn coverage(&self, grid: &Grid) -> f64 {
        let axis = |origin: f64, step: f64, cells: usize, pixels: usize| {
            // The grid's cells [0, cells] span [origin, origin + cells * step] in pixels.
            let (lo, hi) = (origin, origin + cells as f64 * step);
            let overlap = hi.min(pixels as f64) - lo.max(0.0);
            (overlap / (hi - lo)).clamp(0.0, 1.0)
        };
        let f = &self.frame;
        axis(f.origin.0, f.step.0, grid.width - 1, self.width)
            * axis(f.origin.1, f.step.1, grid.height - 1, self.height)
    }

    /// Pixels `x..x+w`, `y..y+h` as an [`Image`], clamped into the photo.
    fn window(&self, x: usize, y: usize, w: usize, h: usize) -> Image {
        let mut image = Image::new(w, h);
        for j in 0..h {
            let row = (y + j).min(self.height - 1) * self.width;
            for i in 0..w {
                let p = (row + (x + i).min(self.width - 1)) * 3;
                image.texels[j * w + i] = [
                    f32::from(self.rgb[p]),
                    f32::from(self.rgb[p + 1]),
                    f32::from(self.rgb[p + 2]),
                ];
            }
        }
        image
    }
}

/// What a tile set's textures show.
#[derive(Clone, Debug)]
pub enum Source {
    Photo(Photo),
    Relief(relief::Relief),
}

/// How to texture a tile set: what, and how many texels per tile.
#[derive(Clone, Debug)]
pub struct Texturing {
    pub source: Source,
    pub layout: Layout,
}

impl Texturing {
    /// The `FileHeader::texture_source` code.
    pub fn source_code(&self) -> u32 {
        match &self.source {
            Source::Photo(p) if p.georeferenced => SOURCE_GEOREFERENCED_PHOTO,
            Source::Photo(_) => SOURCE_PHOTO,
            Source::Relief(r) if r.tint => SOURCE_TINTED_RELIEF,
            Source::Relief(_) => SOURCE_RELIEF,
        }
    }
}

/// The interior a texture of `texels_per_sample` texels per grid cell needs: the power of two
/// nearest to `256 * texels_per_sample` (ties upward), within the allowed range.
pub fn interior_for(texels_per_sample: f64) -> u32 {
    let want = (f64::from(TILE_CELLS) * texels_per_sample).max(1.0);
    let below = 1u32 << (want.log2().floor() as u32).min(31);
    let pick = if want / f64::from(below) >= std::f64::consts::SQRT_2 {
        below.saturating_mul(2)
    } else {
        below
    };
    pick.clamp(MIN_INTERIOR, MAX_INTERIOR)
}

/// Mip 0 of tile `(tx, ty)` with `margin` extra texels on each side.
fn base_region(
    grid: &Grid,
    source: &Prepared,
    layout: &Layout,
    (tx, ty): (u32, u32),
    margin: u32,
) -> Image {
    let n = (layout.size + 2 * margin) as usize;
    let cells_per_texel = f64::from(TILE_CELLS) / f64::from(layout.interior);
    // Region texel 0's centre, in cells from the grid's north-west corner.
    let first = |t: u32| {
        f64::from(t * TILE_CELLS)
            + (0.5 - f64::from(layout.gutter) - f64::from(margin)) * cells_per_texel
    };
    let (cx, cy) = (first(tx), first(ty));
    match source {
        Prepared::Relief(lighting) => {
            relief::render(grid, lighting, (cx, cy), cells_per_texel, (n, n))
        }
        Prepared::Photo(photo, factor) => {
            // A layer's cells in base cells: the photo's frame is in base cells.
            let f = *factor as f64;
            let (cx, cy, cells_per_texel) = (cx * f, cy * f, cells_per_texel * f);
            let grid = &Grid {
                width: (grid.width - 1) * factor + 1,
                height: (grid.height - 1) * factor + 1,
                ..*grid
            };
            // In pixel *index* space (pixel p's centre at p) a cell position c lies at
            // origin + c * step - 0.5.
            let Frame {
                origin: (ox, oy),
                step: (kx, ky),
            } = photo.frame;
            let (x0, sx) = (ox + cx * kx - 0.5, cells_per_texel * kx);
            let (y0, sy) = (oy + cy * ky - 0.5, cells_per_texel * ky);
            // Only the pixels the taps reach, clamped into the photo.
            let reach = |start: f64, step: f64, len: usize| {
                let support = lanczos::RADIUS * step.max(1.0) + 1.0;
                let lo = (start - support).floor().max(0.0) as usize;
                let hi = (start + (n - 1) as f64 * step + support).ceil().max(0.0) as usize;
                let lo = lo.min(len - 1);
                (lo, hi.clamp(lo, len - 1) + 1 - lo)
            };
            let (wx, ww) = reach(x0, sx, photo.width);
            let (wy, wh) = reach(y0, sy, photo.height);
            let window = photo.window(wx, wy, ww, wh);
            let mut image = resample(&window, n, n, (x0 - wx as f64, sx), (y0 - wy as f64, sy));
            // Where the photo does not reach, grey rather than its edge pixels smeared on
            // (nothing to do for a photo that covers the grid, the usual case).
            if photo.coverage(grid) < 1.0 {
                for j in 0..n {
                    for i in 0..n {
                        let at = (
                            cx + i as f64 * cells_per_texel,
                            cy + j as f64 * cells_per_texel,
                        );
                        if !photo.covers(grid, at) {
                            image.texels[j * n + i] = UNCOVERED;
                        }
                    }
                }
            }
            image
        }
    }
}

/// A source made ready for many tiles (the relief's height range found once).
pub enum Prepared<'a> {
    /// The photo, and base grid cells per cell of the grid it textures (`2^p` for pyramid
    /// layer `p`, whose grid is the base's subsampled).
    Photo(&'a Photo, usize),
    Relief(Lighting),
}

impl<'a> Prepared<'a> {
    /// `source` for a grid whose heights span `range` (lowest, highest).
    pub fn new(range: (f32, f32), source: &'a Source) -> Prepared<'a> {
        match source {
            Source::Photo(p) => Prepared::Photo(p, 1),
            Source::Relief(r) => Prepared::Relief(Lighting::with_range(range, *r)),
        }
    }

    /// The same source for pyramid layer `p`: a photo is sampled `2^p` base cells per layer
    /// cell; a relief is computed from the layer's own heights and spacing.
    pub fn for_layer(&self, p: u32) -> Prepared<'a> {
        match self {
            Prepared::Photo(photo, _) => Prepared::Photo(photo, 1 << p),
            Prepared::Relief(lighting) => Prepared::Relief(*lighting),
        }
    }
}

/// The uncompressed mip chain of tile `(tx, ty)`: `layout.mips` layers, mip 0 first.
pub fn mip_chain(grid: &Grid, source: &Prepared, layout: &Layout, tile: (u32, u32)) -> Vec<Image> {
    let aligned = layout.aligned_mips();
    let mut region = base_region(grid, source, layout, tile, layout.margin(0));
    let mut mips = Vec::with_capacity(layout.mips as usize);
    for m in 0..layout.mips {
        if m > 0 && m < aligned {
            let (src_margin, margin) = (layout.margin(m - 1), layout.margin(m));
            let n = (layout.mip_size(m) + 2 * margin) as usize;
            // Region texel j is layer texel j - margin, whose centre lies at source layer
            // coordinate 2 (j - margin) + 0.5, i.e. region index that + src_margin.
            let start = 0.5 + f64::from(src_margin) - 2.0 * f64::from(margin);
            region = resample(&region, n, n, (start, 2.0), (start, 2.0));
        }
        let layer = if m < aligned {
            let e = layout.margin(m) as usize;
            let s = layout.mip_size(m) as usize;
            region.crop(e, e, s, s)
        } else {
            let prev: &Image = &mips[m as usize - 1];
            let s = layout.mip_size(m) as usize;
            let step = prev.width as f64 / s as f64;
            resample(
                prev,
                s,
                s,
                (0.5 * step - 0.5, step),
                (0.5 * step - 0.5, step),
            )
        };
        mips.push(layer);
    }
    mips
}

/// The texture part of the `.vkt` format: a tile's texture blob starts with this header,
/// then `mips` [`MipEntry`]s, then each mip's BC1 blocks (row-major blocks, 16-byte aligned).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct TextureHeader {
    pub magic: [u8; 4],
    pub tx: u32,
    pub ty: u32,
    pub format: u32,
    pub interior: u32,
    pub gutter: u32,
    pub size: u32,
    pub mips: u32,
    /// crc32 of everything after this header (mip entries and blocks).
    pub crc: u32,
    pub reserved: [u32; 3],
}

/// One mip of a texture blob.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct MipEntry {
    /// From the start of the texture blob.
    pub offset: u32,
    pub len: u32,
    pub width: u32,
    pub height: u32,
    /// Sum over texels and channels of the squared difference between the BC1-decoded mip
    /// and the filtered mip it was compressed from (0..255 units): the compression loss.
    pub squared_error: f64,
    pub texels: u64,
}

impl MipEntry {
    /// PSNR (dB) of the compressed mip against the filtered one.
    pub fn psnr(&self) -> f64 {
        psnr(self.squared_error, self.texels)
    }
}

/// PSNR in dB of a summed squared error over `texels` RGB texels (infinite for no error).
pub fn psnr(squared_error: f64, texels: u64) -> f64 {
    if texels == 0 || squared_error <= 0.0 {
        return f64::INFINITY;
    }
    let mse = squared_error / (texels as f64 * 3.0);
    10.0 * (255.0 * 255.0 / mse).log10()
}

// intel_tex_2's prebuilt ISPC kernels are C++ objects and need the C++ runtime (g++'s
// libstdc++, which the build of shaderc installs anyway).
#[link(name = "stdc++")]
unsafe extern "C" {}

/// BC1-encodes one mip; returns the blocks and the squared error of their decoding.
pub fn encode_bc1(image: &Image) -> (Vec<u8>, f64) {
    let (w, h) = (image.width, image.height);
    // The encoder takes whole blocks: pad to a multiple of 4 by repeating the last texels
    // (the padding lies outside the mip and is never sampled).
    let (pw, ph) = (w.next_multiple_of(4), h.next_multiple_of(4));
    // The image's rows as RGBA bytes, each padded to `pw` texels, then the last row repeated.
    let mut padded = vec![0u8; pw * ph * 4];
    let (rows, pad) = padded.split_at_mut(h * pw * 4);
    for (row, texels) in rows
        .chunks_exact_mut(pw * 4)
        .zip(image.texels.chunks_exact(w))
    {
        let (inside, right) = row.split_at_mut(w * 4);
        lanczos::rgba8_into(texels, inside);
        for texel in right.chunks_exact_mut(4) {
            texel.copy_from_slice(&inside[(w - 1) * 4..]);
        }
    }
    let last = &rows[(h - 1) * pw * 4..];
    for row in pad.chunks_exact_mut(pw * 4) {
        row.copy_from_slice(last);
    }
    let blocks = intel_tex_2::bc1::compress_blocks(&intel_tex_2::RgbaSurface {
        width: pw as u32,
        height: ph as u32,
        stride: pw as u32 * 4,
        data: &padded,
    });
    let squared_error = bc1_squared_error(&padded, pw, &blocks, (w, h));
    let squared_error = squared_error as f64;
    (blocks, squared_error)
}

/// The squared error (over red, green and blue, in integers: exact) of BC1 `blocks` against
/// the RGBA texels they encode (`source`, rows of `stride` texels), over the `w x h` texels of
/// the mip: each block's palette decoded as [`decode_bc1`] decodes it, without writing the
/// decoded image (a generic decoder, its image and its clearing were about 5% of N48W125's
/// build).
fn bc1_squared_error(source: &[u8], stride: usize, blocks: &[u8], (w, h): (usize, usize)) -> u64 {
    let expand = |c: u16| {
        let (r, g, b) = (
            i32::from(c >> 11),
            i32::from((c >> 5) & 63),
            i32::from(c & 31),
        );
        [
            (r << 3) | (r >> 2),
            (g << 2) | (g >> 4),
            (b << 3) | (b >> 2),
        ]
    };
    let blocks_wide = stride / 4;
    let mut sum = 0u64;
    for (i, block) in blocks.chunks_exact(8).enumerate() {
        let (bx, by) = (i % blocks_wide * 4, i / blocks_wide * 4);
        if bx >= w || by >= h {
            continue;
        }
        let (a, b) = (
            u16::from_le_bytes([block[0], block[1]]),
            u16::from_le_bytes([block[2], block[3]]),
        );
        let (c, d) = (expand(a), expand(b));
        // As BC1 decodes: two thirds each way, or (a <= b) halfway and black.
        let mut palette = [c, d, [0; 3], [0; 3]];
        for k in 0..3 {
            if a > b {
                palette[2][k] = (2 * c[k] + d[k]) / 3;
                palette[3][k] = (c[k] + 2 * d[k]) / 3;
            } else {
                palette[2][k] = (c[k] + d[k]) / 2;
            }
        }
        for py in 0..4.min(h - by) {
            let codes = block[4 + py];
            let row = &source[((by + py) * stride + bx) * 4..];
            for px in 0..4.min(w - bx) {
                let colour = palette[usize::from(codes >> (2 * px) & 3)];
                let texel = &row[px * 4..px * 4 + 3];
                for k in 0..3 {
                    let e = i32::from(texel[k]) - colour[k];
                    sum += (e * e) as u64;
                }
            }
        }
    }
    sum
}

/// Decodes BC1 blocks of a `width x height` mip to RGBA bytes.
pub fn decode_bc1(blocks: &[u8], width: usize, height: usize) -> Vec<u8> {
    let mut out = vec![0u8; width * height * 4];
    texpresso::Format::Bc1.decompress(blocks, width, height, &mut out);
    out
}

fn align16(blob: &mut Vec<u8>) {
    blob.resize(blob.len().next_multiple_of(16), 0);
}

/// Builds tile `(tx, ty)`'s texture blob: filtered mips, BC1, PSNR per mip.
pub fn build_blob(
    grid: &Grid,
    source: &Prepared,
    layout: &Layout,
    (tx, ty): (u32, u32),
) -> (Vec<u8>, Vec<MipEntry>) {
    let mips = mip_chain(grid, source, layout, (tx, ty));
    let header_len =
        std::mem::size_of::<TextureHeader>() + mips.len() * std::mem::size_of::<MipEntry>();
    let mut blob = vec![0u8; header_len];
    align16(&mut blob);
    let mut entries = Vec::with_capacity(mips.len());
    for mip in &mips {
        let (blocks, squared_error) = encode_bc1(mip);
        entries.push(MipEntry {
            offset: blob.len() as u32,
            len: blocks.len() as u32,
            width: mip.width as u32,
            height: mip.height as u32,
            squared_error,
            texels: (mip.width * mip.height) as u64,
        });
        blob.extend_from_slice(&blocks);
        align16(&mut blob);
    }
    let at = std::mem::size_of::<TextureHeader>();
    blob[at..at + entries.len() * std::mem::size_of::<MipEntry>()]
        .copy_from_slice(bytemuck::cast_slice(&entries));
    let header = TextureHeader {
        magic: TEXTURE_MAGIC,
        tx,
        ty,
        format: FORMAT_BC1,
        interior: layout.interior,
        gutter: layout.gutter,
        size: layout.size,
        mips: layout.mips,
        crc: crc32fast::hash(&blob[at..]),
        reserved: [0; 3],
    };
    blob[..at].copy_from_slice(bytemuck::bytes_of(&header));
    (blob, entries)
}

/// A tile's texture as stored: the header and each mip's entry and BC1 blocks.
#[derive(Clone, Debug)]
pub struct TileTexture<'a> {
    pub header: TextureHeader,
    pub mips: Vec<(MipEntry, &'a [u8])>,
}

/// Validates a texture blob against the tile set's layout; what is wrong, if anything.
pub fn parse_blob<'a>(
    blob: &'a [u8],
    layout: &Layout,
    (tx, ty): (u32, u32),
) -> Result<TileTexture<'a>, String> {
    let at = std::mem::size_of::<TextureHeader>();
    if blob.len() < at {
        return Err(format!(
            "texture of {} bytes is shorter than its header",
            blob.len()
        ));
    }
    let header: TextureHeader = bytemuck::pod_read_unaligned(&blob[..at]);
    if header.magic != TEXTURE_MAGIC {
        return Err("texture: bad magic".into());
    }
    if crc32fast::hash(&blob[at..]) != header.crc {
        return Err("texture checksum mismatch (corrupted file)".into());
    }
    if (header.tx, header.ty) != (tx, ty) {
        return Err(format!(
            "texture belongs to tile {},{}",
            header.tx, header.ty
        ));
    }
    if header.format != FORMAT_BC1
        || (header.interior, header.gutter, header.size, header.mips)
            != (layout.interior, layout.gutter, layout.size, layout.mips)
    {
        return Err("texture layout differs from the tile set's".into());
    }
    let entries_end = at + layout.mips as usize * std::mem::size_of::<MipEntry>();
    if blob.len() < entries_end {
        return Err("texture mip entries run past its end".into());
    }
    let mut mips = Vec::with_capacity(layout.mips as usize);
    for m in 0..layout.mips {
        let e_at = at + m as usize * std::mem::size_of::<MipEntry>();
        let e: MipEntry =
            bytemuck::pod_read_unaligned(&blob[e_at..e_at + std::mem::size_of::<MipEntry>()]);
        let size = layout.mip_size(m);
        let (start, end) = (e.offset as usize, e.offset as usize + e.len as usize);
        if e.width != size
            || e.height != size
            || e.len as usize != layout.mip_bytes(m)
            || start < entries_end
            || end > blob.len()
            || !start.is_multiple_of(16)
            || e.texels != u64::from(size) * u64::from(size)
            || !(e.squared_error.is_finite() && e.squared_error >= 0.0)
        {
            return Err(format!("texture mip {m}: entry does not fit the layout"));
        }
        mips.push((e, &blob[start..end]));
    }
    Ok(TileTexture { header, mips })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The squared error from the blocks' palettes is the one from the reference decoder's
    /// image, over blocks of both kinds (`a > b` and `a <= b`) and mips whose sides are not
    /// multiples of 4 (random bytes as blocks and as texels).
    #[test]
    fn bc1_errors_are_the_reference_decoders() {
        let mut x = 0x2545_f491_4f6c_dd1du64;
        let mut byte = || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 24) as u8
        };
        let (mut below, mut above) = (0, 0);
        for (w, h) in [(4, 4), (17, 17), (9, 6), (33, 5), (1, 1)] {
            let (pw, ph) = (usize::next_multiple_of(w, 4), usize::next_multiple_of(h, 4));
            let source: Vec<u8> = (0..pw * ph * 4).map(|_| byte()).collect();
            let mut blocks: Vec<u8> = (0..pw * ph / 2).map(|_| byte()).collect();
            // Every other block with equal endpoints (a <= b).
            for block in blocks.chunks_exact_mut(16) {
                block.copy_within(0..2, 2);
            }
            for block in blocks.chunks_exact(8) {
                match u16::from_le_bytes([block[0], block[1]])
                    > u16::from_le_bytes([block[2], block[3]])
                {
                    true => above += 1,
                    false => below += 1,
                }
            }
            let decoded = decode_bc1(&blocks, w, h);
            let reference: u64 = (0..w * h)
                .map(|t| {
                    let (x, y) = (t % w, t / w);
                    (0..3)
                        .map(|k| {
                            let e = i64::from(source[(y * pw + x) * 4 + k])
                                - i64::from(decoded[t * 4 + k]);
                            (e * e) as u64
                        })
                        .sum::<u64>()
                })
                .sum();
            assert_eq!(bc1_squared_error(&source, pw, &blocks, (w, h)), reference);
        }
        assert!(below > 10 && above > 10, "{below} {above}");
    }

    #[test]
    fn layouts_have_aligned_mips_down_to_a_17_texel_layer() {
        let l = Layout::new(512).unwrap();
        assert_eq!((l.gutter, l.size, l.mips), (16, 544, 8));
        assert_eq!(l.aligned_mips(), 6);
        for m in 0..l.aligned_mips() {
            assert_eq!(l.mip_size(m) << m, l.size, "mip {m} is exactly S / 2^m");
        }
        assert_eq!(l.mip_size(5), 17);
        assert_eq!((l.mip_size(6), l.mip_size(7)), (8, 4));
        assert_eq!(l.margin(5), 0);
        assert_eq!(l.margin(0), 93);
        let l = Layout::new(64).unwrap();
        assert_eq!((l.gutter, l.size, l.mips, l.aligned_mips()), (2, 68, 5, 3));
        assert!(
            Layout::new(100).is_err() && Layout::new(32).is_err() && Layout::new(8192).is_err()
        );
    }

    #[test]
    fn the_uv_of_the_tile_corners_is_the_gutter() {
        let l = Layout::new(256).unwrap();
        assert!((l.uv(0.0) - 8.0 / 272.0).abs() < 1e-12);
        assert!((l.uv(256.0) - 264.0 / 272.0).abs() < 1e-12);
    }

    #[test]
    fn interiors_round_the_density_to_a_power_of_two() {
        assert_eq!(interior_for(1.0), 256);
        assert_eq!(interior_for(2.0), 512);
        assert_eq!(interior_for(1.3), 256);
        assert_eq!(interior_for(1.5), 512);
        assert_eq!(interior_for(0.01), MIN_INTERIOR);
        assert_eq!(interior_for(1000.0), MAX_INTERIOR);
    }

    /// A smooth colour field over a 3 x 2 tile grid, as a photo of one pixel per cell.
    fn photo_grid() -> (Vec<f32>, Photo) {
        let (w, h) = (3 * 256 + 1, 2 * 256 + 1);
        let heights = vec![0.0; w * h];
        let (pw, ph) = (w - 1, h - 1);
        let mut rgb = Vec::with_capacity(pw * ph * 3);
        for y in 0..ph {
            for x in 0..pw {
                let (fx, fy) = (x as f64 / 40.0, y as f64 / 23.0);
                rgb.push((128.0 + 100.0 * fx.sin()) as u8);
                rgb.push((128.0 + 100.0 * (fy + fx * 0.3).cos()) as u8);
                rgb.push((128.0 + 60.0 * ((fx + fy) * 0.7).sin()) as u8);
            }
        }
        let photo = Photo::spanning(pw, ph, rgb, &grid_of(&heights));
        (heights, photo)
    }

    fn grid_of(heights: &[f32]) -> Grid<'_> {
        Grid {
            width: 3 * 256 + 1,
            height: 2 * 256 + 1,
            first_row: 0,
            heights,
            spacing_x: 10.0,
            spacing_y: 10.0,
        }
    }

    #[test]
    fn gutters_hold_the_neighbours_texels_at_every_aligned_mip() {
        let (heights, photo) = photo_grid();
        let grid = grid_of(&heights);
        let layout = Layout::new(128).unwrap();
        let source = Prepared::Photo(&photo, 1);
        let left = mip_chain(&grid, &source, &layout, (0, 1));
        let right = mip_chain(&grid, &source, &layout, (1, 1));
        for m in 0..layout.aligned_mips() {
            let (a, b) = (&left[m as usize], &right[m as usize]);
            let s = layout.mip_size(m) as usize;
            let interior = (layout.interior >> m) as usize;
            // Whole texels of gutter at this mip: the left tile's columns
            // interior..interior+2g are the right tile's 0..2g.
            let g = (s - interior) / 2;
            let mut worst = 0.0f32;
            for y in 0..s {
                for k in 0..2 * g {
                    let (p, q) = (a.at(interior + k, y), b.at(k, y));
                    for c in 0..3 {
                        worst = worst.max((p[c] - q[c]).abs());
                    }
                }
            }
            assert!(worst < 1e-3, "mip {m}: gutters differ by {worst}");
        }
    }

    #[test]
    fn the_photo_at_its_own_density_is_copied_texel_for_texel() {
        let (heights, photo) = photo_grid();
        let grid = grid_of(&heights);
        let layout = Layout::new(256).unwrap();
        let mips = mip_chain(&grid, &Prepared::Photo(&photo, 1), &layout, (1, 0));
        let g = layout.gutter as usize;
        for (y, x) in [(0, 0), (17, 200), (255, 255)] {
            let p = (y * photo.width + 256 + x) * 3;
            let t = mips[0].at(g + x, g + y);
            for (c, v) in t.iter().enumerate() {
                assert!((v - f32::from(photo.rgb[p + c])).abs() < 1e-3, "{x},{y}");
            }
        }
    }

    #[test]
    fn blobs_round_trip_and_refuse_damage() {
        let (heights, photo) = photo_grid();
        let grid = grid_of(&heights);
        let layout = Layout::new(64).unwrap();
        let (blob, entries) = build_blob(&grid, &Prepared::Photo(&photo, 1), &layout, (2, 1));
        let t = parse_blob(&blob, &layout, (2, 1)).unwrap();
        assert_eq!(t.mips.len(), layout.mips as usize);
        for (m, (e, bytes)) in t.mips.iter().enumerate() {
            assert_eq!(bytes.len(), layout.mip_bytes(m as u32));
            assert_eq!(e.squared_error, entries[m].squared_error);
            assert!(
                e.psnr().is_finite() && e.psnr() > 10.0,
                "mip {m}: {} dB",
                e.psnr()
            );
        }
        // Mip 0 holds this pattern's waves well; coarser mips squeeze a whole wave into a
        // block, which BC1's one colour line cannot follow (real floors: tests/textures.rs).
        assert!(t.mips[0].0.psnr() > 28.0, "{} dB", t.mips[0].0.psnr());
        assert!(
            parse_blob(&blob, &layout, (1, 1)).is_err(),
            "another tile's"
        );
        assert!(parse_blob(&blob, &Layout::new(128).unwrap(), (2, 1)).is_err());
        let mut bad = blob.clone();
        let last = bad.len() - 1;
        bad[last] ^= 1;
        assert!(parse_blob(&bad, &layout, (2, 1))
            .unwrap_err()
            .contains("checksum"));
        assert!(parse_blob(&blob[..20], &layout, (2, 1)).is_err());
    }
}
