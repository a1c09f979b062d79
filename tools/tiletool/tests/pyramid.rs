//! The tile pyramid end to end: `tiletool build --pyramid` on real data, its layers in `info`,
//! its error bound checked by `verify` against the source (and caught when forged), corrupted
//! layers refused, banded builds the same bytes, and layer tiles textured where they lie.
//! (Files from before it still read: `cli.rs`, `old_versions_still_read`.)

mod common;

use std::path::{Path, PathBuf};
use std::process::Output;

use common::{build_sample, s, stderr, tiletool};
use testdata::{data, sample};
use tiles::format::{DirEntry, FileHeader, LayerHeader};

/// The sample cropped so that its size is no multiple of 2 or 4 (999 x 998 cells): the
/// layers' last column and row are clamped onto the grid's.
const CROP: [&str; 6] = [
    "--spacing",
    "160",
    "--vertical-scale",
    "0.1",
    "--crop",
    "3,5,1000x999",
];

fn build_cropped(dir: &Path, name: &str, extra: &[&str]) -> PathBuf {
    let out = dir.join(name);
    let src = sample();
    let mut args = vec!["build", s(&src), "-o", s(&out), "--quiet"];
    args.extend(CROP);
    args.extend(extra);
    let o = tiletool(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    out
}

fn verify_against_source(file: &Path) -> Output {
    let src = sample();
    let mut args = vec!["verify", s(file), "--source", s(&src)];
    args.extend(CROP);
    tiletool(&args)
}

/// `bytes` with their checksums made good, written to `dir/name`.
fn write_resealed(dir: &Path, name: &str, mut bytes: Vec<u8>) -> PathBuf {
    tiles::format::reseal(&mut bytes).expect("reseal");
    let path = dir.join(name);
    std::fs::write(&path, &bytes).expect("write");
    path
}

/// Where every directory entry of pyramid layer `p` lies in the file.
fn layer_entries(bytes: &[u8], p: u32) -> Vec<usize> {
    let h: FileHeader = bytemuck::pod_read_unaligned(&bytes[..size_of::<FileHeader>()]);
    let (layers, _) = tiles::format::layer_layout(&h).expect("layout");
    let l = layers[p as usize - 1];
    (0..(l.tiles_x * l.tiles_y) as usize)
        .map(|i| l.directory_offset as usize + i * size_of::<DirEntry>())
        .collect()
}

#[test]
fn the_pyramid_is_built_listed_and_verified_and_a_forged_bound_is_caught() {
    let dir = tempfile::tempdir().expect("temp dir");
    let file = build_cropped(dir.path(), "pyramid.vkt", &["--pyramid"]);

    let o = tiletool(&["info", s(&file), "--json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let info: serde_json::Value = serde_json::from_slice(&o.stdout).expect("json");
    assert_eq!(info["format_version"], 3);
    let layers = info["pyramid"].as_array().expect("pyramid");
    // 1000 x 999 samples in 4 x 4 tiles; layer 1 is 501 x 500 samples in 2 x 2 tiles; layer 2
    // is 251 x 251 in one.
    let shape: Vec<_> = layers
        .iter()
        .map(|l| {
            (
                l["factor"].as_u64().unwrap(),
                l["grid_width"].as_u64().unwrap(),
                l["grid_height"].as_u64().unwrap(),
                l["tiles_x"].as_u64().unwrap() * l["tiles_y"].as_u64().unwrap(),
                l["spacing_x_m"].as_f64().unwrap(),
            )
        })
        .collect();
    assert_eq!(
        shape,
        [(2, 501, 500, 4, 320.0), (4, 251, 251, 1, 640.0)],
        "{info:#}"
    );
    // The bound grows up the pyramid: a layer's bound is its children's plus its own.
    let d: Vec<f64> = layers
        .iter()
        .map(|l| l["max_decimation_error_m"].as_f64().unwrap())
        .collect();
    assert!(0.0 < d[0] && d[0] < d[1], "{d:?}");

    // A layer tile's levels are built no finer than a quarter of its decimation error: the
    // finest levels of rough tiles stop there (their vertices would never be drawn).
    let set = tiles::TileSet::open(&file).expect("open");
    let mut floored = 0;
    for p in 1..=set.pyramid_layers() {
        let layer = set.layer(p).unwrap();
        for ty in 0..layer.header().tiles_y {
            for tx in 0..layer.header().tiles_x {
                let d = layer.decimation_error(tx, ty).unwrap();
                let tile = layer.tile(tx, ty).unwrap();
                for (i, e) in tile.levels().iter().enumerate() {
                    let want = set.level_error(i as u32).max(f64::from(d) / 4.0);
                    assert_eq!(
                        f64::from(e.error_bound),
                        want as f32 as f64,
                        "layer {p} tile {tx},{ty} level {i}"
                    );
                    floored += usize::from(want > set.level_error(i as u32));
                }
            }
        }
    }
    assert!(floored > 0, "no level of any layer tile is floored");
    drop(set);

    // Against the source: every layer's levels within their errors of the subsampled grid,
    // and every source sample within the finest level's error plus the tile's bound.
    let o = verify_against_source(&file);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        out.contains("21 tiles"),
        "16 base tiles, 4 + 1 above: {out}"
    );

    // The control: the same file whose top tile (layer 2) claims no decimation error.
    let mut bytes = std::fs::read(&file).expect("read");
    for p in [2] {
        for at in layer_entries(&bytes, p) {
            let mut e: DirEntry =
                bytemuck::pod_read_unaligned(&bytes[at..][..size_of::<DirEntry>()]);
            e.decimation_error = 0.0;
            bytes[at..][..size_of::<DirEntry>()].copy_from_slice(bytemuck::bytes_of(&e));
        }
    }
    let forged = write_resealed(dir.path(), "forged.vkt", bytes);
    // Without the source, the levels' floors no longer follow from the claimed bound.
    let o = tiletool(&["verify", s(&forged)]);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("error bound"), "{err}");
    let o = verify_against_source(&forged);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("layer 2 tile 0,0") && err.contains("plus the decimation error 0.000 m"),
        "{err}"
    );
    assert!(!err.contains("panicked"), "{err}");

    // Each level's error against the base grid, which the renderer chooses layer tiles by,
    // is recomputed by verify from the stored fans; a table that claims less is caught.
    let mut bytes = std::fs::read(&file).expect("read");
    let h: FileHeader = bytemuck::pod_read_unaligned(&bytes[..size_of::<FileHeader>()]);
    let (layers, _) = tiles::format::layer_layout(&h).expect("layout");
    let at = layers[0].errors_offset as usize + 3 * 4; // layer 1, tile 0,0, level 3
    let claimed = f32::from_le_bytes(bytes[at..at + 4].try_into().unwrap());
    assert!(claimed > 0.0);
    bytes[at..at + 4].copy_from_slice(&(claimed * 0.5).to_le_bytes());
    let low = write_resealed(dir.path(), "low.vkt", bytes);
    let o = verify_against_source(&low);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("layer 1 tile 0,0 level 3: recomputed error against the base grid"),
        "{err}"
    );
}

#[test]
fn a_corrupted_or_forged_layer_is_refused() {
    let dir = tempfile::tempdir().expect("temp dir");
    let file = build_cropped(dir.path(), "pyramid.vkt", &["--pyramid", "--levels", "4"]);
    let bytes = std::fs::read(&file).expect("read");
    let entry = |p: u32, i: usize| -> DirEntry {
        let at = layer_entries(&bytes, p)[i];
        bytemuck::pod_read_unaligned(&bytes[at..][..size_of::<DirEntry>()])
    };
    let h: FileHeader = bytemuck::pod_read_unaligned(&bytes[..size_of::<FileHeader>()]);
    let layer_header_at = size_of::<FileHeader>() + 16 * size_of::<DirEntry>();
    assert_eq!((h.tiles_x, h.tiles_y, h.pyramid_layers), (4, 4, 2));

    let resealed = |mut b: Vec<u8>| {
        tiles::format::reseal(&mut b).expect("reseal");
        b
    };
    let cases: Vec<(&str, Vec<u8>, &str)> = vec![
        (
            // A bit flipped inside layer 1's tile 1,0: its checksum no longer matches.
            "tile.vkt",
            {
                let mut b = bytes.clone();
                b[entry(1, 1).offset as usize + 300] ^= 0x10;
                b
            },
            "pyramid layer 1 tile 1,0: checksum mismatch",
        ),
        (
            // A layer header that does not follow from the grid, checksums made good.
            "layer.vkt",
            resealed({
                let mut b = bytes.clone();
                let mut l: LayerHeader =
                    bytemuck::pod_read_unaligned(&b[layer_header_at..][..size_of::<LayerHeader>()]);
                l.tiles_x = 3;
                b[layer_header_at..][..size_of::<LayerHeader>()]
                    .copy_from_slice(bytemuck::bytes_of(&l));
                b
            }),
            "pyramid layer 1 does not match",
        ),
        (
            // More layers than the grid has.
            "layers.vkt",
            resealed({
                let mut b = bytes.clone();
                let mut h = h;
                h.pyramid_layers = 3;
                b[..size_of::<FileHeader>()].copy_from_slice(bytemuck::bytes_of(&h));
                b
            }),
            "3 pyramid layers, but a 1000x999 grid has 2 at most",
        ),
        (
            // A decimation error that is no distance.
            "nan.vkt",
            resealed({
                let mut b = bytes.clone();
                let at = layer_entries(&b, 2)[0];
                let mut e: DirEntry =
                    bytemuck::pod_read_unaligned(&b[at..][..size_of::<DirEntry>()]);
                e.decimation_error = f32::NAN;
                b[at..][..size_of::<DirEntry>()].copy_from_slice(bytemuck::bytes_of(&e));
                b
            }),
            "pyramid layer 2: tile 0,0: decimation error NaN",
        ),
        (
            // Cut inside layer 1's directory.
            "truncated.vkt",
            bytes[..layer_header_at + 100].to_vec(),
            "truncated",
        ),
    ];
    for (name, content, what) in cases {
        let p = dir.path().join(name);
        std::fs::write(&p, &content).expect("write");
        for cmd in ["info", "verify"] {
            let o = tiletool(&[cmd, s(&p)]);
            let err = stderr(&o);
            assert_eq!(o.status.code(), Some(1), "{cmd} {name}: {err}");
            assert!(!err.contains("panicked"), "{cmd} {name}: {err}");
            assert!(err.contains(name), "{cmd} {name}: {err}");
            assert!(err.contains(what), "{cmd} {name}: want {what:?} in {err}");
        }
    }
}

/// A layer tile's levels past its floor add no vertex and store the fans of the level before:
/// `verify` compares them with that level instead of walking them again. A broken fan in such
/// a level (checksums made good) makes it differ, so it is walked and caught. The control:
/// the file as built verifies.
#[test]
fn a_broken_fan_in_a_layer_tiles_repeated_level_is_caught() {
    let dir = tempfile::tempdir().expect("temp dir");
    let file = build_cropped(dir.path(), "pyramid.vkt", &["--pyramid"]);
    let o = tiletool(&["verify", s(&file)]);
    assert!(o.status.success(), "{}", stderr(&o));
    let set = tiles::format::TileSet::open(&file).expect("open");
    let mut bytes = std::fs::read(&file).expect("read");
    // The top layer's first tile whose last level repeats the one before.
    let top = set.pyramid_layers();
    let layer = set.layer(top).expect("top layer");
    let tile = layer.tile(0, 0).expect("tile");
    let levels = tile.header.levels;
    let last = tile.level(levels - 1).expect("level").entry;
    let before = tile.level(levels - 2).expect("level").entry;
    assert_eq!(last.block_len, 0, "the top tile's last level adds vertices");
    assert_eq!(last.triangle_count, before.triangle_count);
    let entry: DirEntry = bytemuck::pod_read_unaligned(
        &bytes[layer_entries(&bytes, top)[0]..][..size_of::<DirEntry>()],
    );
    // Swap the first fan's second and third ring entries: the ring no longer walks its cell.
    let w = last.index_width as usize;
    let at = entry.offset as usize + last.index_offset as usize;
    bytes[at + 2 * w..at + 4 * w].rotate_left(w);
    let broken = write_resealed(dir.path(), "broken.vkt", bytes);
    let o = tiletool(&["verify", s(&broken)]);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    let want = format!("layer {top} tile 0,0 level {}: fan 0", levels - 1);
    assert!(err.contains(&want), "want {want:?} in {err}");
}

#[test]
fn a_pyramid_leaves_the_base_tiles_alone_and_builds_the_same_bytes_in_bands() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (a, b) = (data("srtm/N42E001.hgt"), data("srtm/N41E001.hgt"));
    let build = |name: &str, extra: &[&str]| {
        let out = dir.path().join(name);
        let o = tiletool(
            &[
                &[
                    "build",
                    s(&a),
                    s(&b),
                    "-o",
                    s(&out),
                    "--quiet",
                    "--levels",
                    "6",
                ][..],
                extra,
            ]
            .concat(),
        );
        assert!(o.status.success(), "{}", stderr(&o));
        out
    };
    let whole = build("whole.vkt", &["--pyramid"]);
    // A tile row at a time, the layers' rows read through the subsampling in bands too.
    let banded = build("banded.vkt", &["--pyramid", "--band-rows", "1"]);
    assert!(
        std::fs::read(&whole).unwrap() == std::fs::read(&banded).unwrap(),
        "a banded pyramid build builds other bytes"
    );
    // The base tiles are the same blobs with or without the pyramid above them.
    let plain = build("plain.vkt", &[]);
    let (with, without) = (
        tiles::TileSet::open(&whole).unwrap(),
        tiles::TileSet::open(&plain).unwrap(),
    );
    assert_eq!(
        with.pyramid_layers(),
        4,
        "5 x 10 tiles, then 3 x 5, 2 x 3, 1 x 2, 1 x 1"
    );
    assert_eq!(without.pyramid_layers(), 0);
    let h = without.header();
    for ty in 0..h.tiles_y {
        for tx in 0..h.tiles_x {
            assert!(with.blob(tx, ty) == without.blob(tx, ty), "tile {tx},{ty}");
            assert!(
                with.texture_blob(tx, ty) == without.texture_blob(tx, ty),
                "texture {tx},{ty}"
            );
        }
    }
    let o = tiletool(&["verify", s(&whole), "--source", s(&a), s(&b)]);
    assert!(o.status.success(), "{}", stderr(&o));
}

/// PSNR (dB) over pairs of RGB pixels.
fn psnr(pairs: impl Iterator<Item = ([f64; 3], [f64; 3])>) -> f64 {
    let (mut sum, mut n) = (0.0, 0usize);
    for (a, b) in pairs {
        for k in 0..3 {
            sum += (a[k] - b[k]).powi(2);
        }
        n += 3;
    }
    10.0 * (255.0f64.powi(2) / (sum / n as f64).max(1e-12)).log10()
}

#[test]
fn a_layer_tile_wears_the_photo_of_the_ground_it_covers() {
    // Layer 1's tile 1,1 covers base cells 512..1024 across and down, two cells a texel: its
    // interior texel (x, y) is the mean of photo pixels 512 + 2x.., 512 + 2y.. (the photo spans
    // the grid, a pixel a cell). The control: the same comparison a layer texel off.
    let dir = tempfile::tempdir().expect("temp dir");
    let tex = testdata::sample_texture();
    let pyramid = ["--texture", s(&tex), "--pyramid", "--levels", "4"];
    let (out, _) = build_sample(dir.path(), "photo.vkt", &pyramid);
    let set = tiles::TileSet::open(&out).expect("open");
    let layer = set.layer(1).expect("layer 1");
    let layout = layer.texture_layout().expect("textured");
    let texture = layer.texture(1, 1).expect("sound").expect("a texture");
    let (e, blocks) = texture.mips[0];
    let (w, h) = (e.width as usize, e.height as usize);
    let rgba = tiles::texture::decode_bc1(blocks, w, h);
    let photo = image::open(&tex).expect("photo").to_rgb8();
    let g = layout.gutter as usize;
    let compare = |shift: i64| {
        psnr(
            (0..256usize)
                .flat_map(|y| (0..256usize).map(move |x| (x, y)))
                .map(|(x, y)| {
                    let t = &rgba[((g + y) * w + g + x) * 4..][..3];
                    let mut mean = [0.0; 3];
                    for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                        let px = (512 + 2 * x as i64 + dx + 2 * shift).clamp(0, 1023) as u32;
                        let py = (512 + 2 * y as i64 + dy).clamp(0, 1023) as u32;
                        let p = photo.get_pixel(px, py).0;
                        for k in 0..3 {
                            mean[k] += f64::from(p[k]) / 4.0;
                        }
                    }
                    ([0, 1, 2].map(|k| f64::from(t[k])), mean)
                }),
        )
    };
    let (aligned, shifted) = (compare(0), compare(1));
    assert!(aligned >= 28.0, "aligned: {aligned:.2} dB");
    assert!(
        shifted < aligned - 3.0,
        "a texel off is not worse: {shifted:.2} vs {aligned:.2} dB"
    );
}
