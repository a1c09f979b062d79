//! Index arrays built on the GPU (`vulkan::indices`, lavapipe, validation on) against the
//! arrays the file stores: for every level of every tile, the same fans in the same order, and
//! index for index the file's array with each ring rotated as `tiles::rings` says (the builder
//! starts each ring where its cache model says, the GPU where the previous fan's cell is).
//! Tiles past the data's edge (meshes that stop inside the tile) and both index widths are
//! covered; a wrong mesh extent, a missing vertex and a wrong expected count are caught. On
//! another device the test says on stderr whether it applies (see [`Bench::new`]). And the
//! arrays the CPU makes instead (`--index-builder cpu`) draw the builder's frames.

use std::io::Write as _;

use memory::Part;
use renderer::terrain::Terrain;
use renderer::vulkan::indices::{Build, IndexBuilder, MAX_BUILDS_PER_DISPATCH};
use renderer::vulkan::pool::TilePool;
use renderer::vulkan::{sync, Gpu, GpuOptions};

mod common;

/// Bytes of pool the test uses: a tile's blocks, then one region per level.
const POOL_BYTES: u64 = 24 << 20;

struct Bench {
    gpu: Gpu,
    pool: TilePool,
    builder: IndexBuilder,
}

impl Bench {
    /// The device's bench, or `None` (and why, on stderr) on a device the test does not apply
    /// to. The test needs 16-bit storage (the builder writes 16-bit index arrays) and a pool
    /// the CPU writes in place (the blocks go in without the upload path). Lavapipe has both,
    /// so there they are asserted; elsewhere they are the device's (a discrete GPU's pool is
    /// not host-visible), so the test says whether it applies rather than fail on them.
    fn new() -> Option<Bench> {
        let gpu = Gpu::new(&GpuOptions {
            validation: true,
            ..Default::default()
        })
        .expect("Vulkan device");
        let pool = TilePool::new(&gpu, POOL_BYTES, false).expect("pool");
        // Lavapipe reports itself as llvmpipe (the name the summary's `device` shows).
        let lavapipe = gpu.device_name.starts_with("llvmpipe");
        if lavapipe {
            assert!(gpu.storage_16bit, "lavapipe stores 16-bit values");
            assert!(
                pool.direct(),
                "lavapipe's memory is host-visible: the test writes the pool from the CPU"
            );
        } else if gpu.storage_16bit && pool.direct() {
            notice(&format!(
                "indices: {} is not lavapipe; it has 16-bit storage and a pool the CPU writes \
                 in place, so the test runs (those two are asserted on lavapipe only)",
                gpu.device_name
            ));
        } else {
            notice(&format!(
                "indices: DOES NOT APPLY to {} (not lavapipe), nothing was checked: the test \
                 needs 16-bit storage ({}) and a pool the CPU writes in place ({}); run it on \
                 lavapipe (VK_ICD_FILENAMES=/usr/share/vulkan/icd.d/lvp_icd.x86_64.json)",
                gpu.device_name,
                gpu.storage_16bit,
                pool.direct()
            ));
            pool.destroy(&gpu);
            return None;
        }
        let builder =
            IndexBuilder::new(&gpu, &pool.buffer, 1, 64, MAX_BUILDS_PER_DISPATCH).expect("builder");
        Some(Bench { gpu, pool, builder })
    }

    /// Writes tile `t`'s blocks at 0 and builds `levels`' arrays after them (at the file's
    /// index width, or 4 bytes with `wide`); returns each array's bytes as built, and the
    /// failure the shader reported.
    fn build(
        &mut self,
        terrain: &Terrain,
        t: usize,
        levels: &[u32],
        wide: bool,
        tamper: impl Fn(&mut Build),
    ) -> (
        Vec<Vec<u8>>,
        Option<renderer::vulkan::indices::BuildFailure>,
    ) {
        let info = &terrain.tiles[t];
        let mut at = 0u64;
        for j in 0..info.levels.len() as u32 {
            let bytes = terrain.part(t, Part::Positions(j)).expect("positions");
            assert!(self.pool.write(at, bytes));
            at += bytes.len() as u64;
        }
        let mut builds = Vec::new();
        let mut regions = Vec::new();
        for &level in levels {
            let l = &info.levels[level as usize];
            let width = if wide { 4 } else { l.index_width };
            let bytes = u64::from(l.index_count) * u64::from(width);
            at = at.div_ceil(4) * 4;
            // Stale values where the array goes: the build must overwrite every index.
            assert!(self.pool.write(at, &vec![0x5a; bytes as usize]));
            let mut b = Build {
                vertex_word: 0,
                vertex_count: l.vertex_count(),
                index_at: (at / u64::from(width)) as u32,
                index_count: l.index_count,
                index_width: width,
                mesh_max_x: info.header.mesh_max_x,
                mesh_max_y: info.header.mesh_max_y,
                tile: t as u32,
                ..Default::default()
            };
            tamper(&mut b);
            builds.push(b);
            regions.push((at, bytes));
            at += bytes;
        }
        assert!(at <= POOL_BYTES, "pool too small for tile {t}");
        assert!(self.builder.write(0, &builds));
        let (gpu, builder) = (&self.gpu, &self.builder);
        sync::run_once(gpu, "index builds", |cmd| {
            builder.record(gpu, cmd, (0, builds.len() as u32), false)
        })
        .expect("builds run");
        let failure = self.builder.take_failure(0);
        let arrays = regions
            .iter()
            .map(|&(at, bytes)| self.pool.read(&self.gpu, at, bytes).expect("read back"))
            .collect();
        (arrays, failure)
    }
}

/// Writes `message` to the process's stderr itself, not through `eprintln!`, which the test
/// harness keeps to itself when a test passes: whether the test applied must show in every run.
fn notice(message: &str) {
    let _ = writeln!(std::io::stderr(), "{message}");
}

/// What the GPU must build for `level` of tile `t`: the file's array, rings rotated.
fn expected(terrain: &Terrain, t: usize, level: u32) -> Vec<u32> {
    let l = &terrain.tiles[t].levels[level as usize];
    let positions: Vec<u32> = (0..=level)
        .flat_map(|j| common::widen(terrain.part(t, Part::Positions(j)).expect("positions"), 4))
        .collect();
    let file = common::widen(
        terrain.part(t, Part::Indices(level)).expect("indices"),
        l.index_width,
    );
    tiles::rings::previous_cell_rings(file.iter().map(|&i| (i != u32::MAX).then_some(i)), |v| {
        let (x, y, _) = tiles::pack::unpack(positions[v as usize]);
        (x, y)
    })
}

/// Panics at the first index where `got` differs from `want`.
fn same(got: &[u32], want: &[u32], what: &str) {
    assert_eq!(got.len(), want.len(), "{what}: length");
    if let Some(k) = (0..got.len()).find(|&k| got[k] != want[k]) {
        let around = |v: &[u32]| v[k.saturating_sub(6)..(k + 6).min(v.len())].to_vec();
        panic!(
            "{what}: index {k} built {:?}, expected {:?}",
            around(got),
            around(want)
        );
    }
}

/// Builds every level of every tile and compares with the file; returns (arrays, of them
/// 32-bit, tiles whose mesh stops inside the tile).
fn check_every_level(bench: &mut Bench, terrain: &Terrain) -> (usize, usize, usize) {
    let (mut arrays, mut wide, mut partial) = (0, 0, 0);
    for t in 0..terrain.tiles.len() {
        let info = &terrain.tiles[t];
        let levels: Vec<u32> = (0..info.levels.len() as u32).collect();
        for chunk in levels.chunks(2 * MAX_BUILDS_PER_DISPATCH as usize) {
            let (built, failure) = bench.build(terrain, t, chunk, false, |_| {});
            assert_eq!(failure, None, "tile {t}");
            for (&level, got) in chunk.iter().zip(&built) {
                let l = &info.levels[level as usize];
                let want = terrain.part(t, Part::Indices(level)).expect("indices");
                // The same fans as the file's (a check that does not depend on the rings' rule).
                assert_eq!(
                    common::fans(got, l.index_width),
                    common::fans(want, l.index_width),
                    "tile {t} level {level}: fans"
                );
                let what = format!("tile {t} level {level}");
                same(
                    &common::widen(got, l.index_width),
                    &expected(terrain, t, level),
                    &what,
                );
                arrays += 1;
                wide += usize::from(l.index_width == 4);
            }
        }
        partial += usize::from(info.header.mesh_max_x < 256 || info.header.mesh_max_y < 256);
    }
    (arrays, wide, partial)
}

#[test]
fn every_level_of_the_puget_sample_builds_as_the_file_says() {
    let dir = tempfile::tempdir().expect("temp dir");
    let terrain = common::open_checked(&common::puget(dir.path()));
    let Some(mut bench) = Bench::new() else {
        return;
    };
    let (arrays, wide, _) = check_every_level(&mut bench, &terrain);
    eprintln!("{arrays} arrays, {wide} of them 32-bit");
    assert_eq!(arrays, terrain.tiles.len() * terrain.levels as usize);
    // The builder writes 32-bit indices when a level has more vertices than 16 bits number;
    // the sample has none, so every level of one tile is built 32-bit too.
    let t = 5;
    let levels: Vec<u32> = (0..terrain.levels).collect();
    let (built, failure) = bench.build(&terrain, t, &levels, true, |_| {});
    assert_eq!(failure, None);
    for (&level, got) in levels.iter().zip(&built) {
        let l = &terrain.tiles[t].levels[level as usize];
        let want = terrain.part(t, Part::Indices(level)).expect("indices");
        assert_eq!(
            common::fans(got, 4),
            common::fans(want, l.index_width),
            "level {level}, 32-bit"
        );
        same(
            &common::widen(got, 4),
            &expected(&terrain, t, level),
            "32-bit",
        );
    }
    // Control: the same builds told the wrong expected count fail, and report it.
    let (_, failure) = bench.build(&terrain, 5, &[3], false, |b| b.index_count -= 1);
    let f = failure.expect("a wrong count is reported");
    assert_eq!((f.tile, f.expected + 1), (5, f.got));
    bench.builder.destroy(&bench.gpu);
    bench.pool.destroy(&bench.gpu);
    assert_eq!(bench.gpu.validation_messages(), 0);
}

/// An SRTM window whose last tile column and row hold 187 and 17 cells: meshes that stop
/// inside their tile, where cells straddling the data's edge are split and cells past it are
/// not drawn.
#[test]
fn tiles_past_the_data_edge_build_as_the_file_says_and_controls_fail() {
    let dir = tempfile::tempdir().expect("temp dir");
    let opts = dem::ReadOptions {
        crop: Some("1500,1500,700x530".parse().expect("crop")),
        ..Default::default()
    };
    let set = common::tileset(dir.path(), &common::data("srtm/N48W125.hgt"), opts);
    let terrain = common::open_checked(&set);
    let Some(mut bench) = Bench::new() else {
        return;
    };
    let (arrays, _, partial) = check_every_level(&mut bench, &terrain);
    eprintln!("{arrays} arrays, {partial} partial tiles");
    assert_eq!(partial, 5, "3 x 3 tiles, the last column and row partial");
    let t = terrain
        .tiles
        .iter()
        .position(|i| i.header.mesh_max_x < 256 && i.header.mesh_max_y < 256)
        .expect("a corner tile");
    let finest = terrain.tiles[t].levels.len() as u32 - 1;
    // Control 1: told the mesh covers the whole tile, the builder draws cells past the data
    // (vertices missing, counts wrong).
    let (_, failure) = bench.build(&terrain, t, &[finest], false, |b| {
        (b.mesh_max_x, b.mesh_max_y) = (256, 256)
    });
    assert!(failure.is_some(), "a wrong extent went unnoticed");
    // Control 2: without the level's last vertex, a fan lacks it.
    let (_, failure) = bench.build(&terrain, t, &[finest], false, |b| b.vertex_count -= 1);
    assert!(failure.is_some(), "a missing vertex went unnoticed");
    bench.builder.destroy(&bench.gpu);
    bench.pool.destroy(&bench.gpu);
    assert_eq!(bench.gpu.validation_messages(), 0);
}

/// A tile drawn part by part (`tiles::parts`): the GPU's mixed array is the CPU mesher's,
/// index for index (neither rotates the rings of a mixed array), and as long as the tables
/// say, for parts at many levels on whole and partial tiles. The control: the same build told
/// one part a level coarser makes another array (or another count, which it reports).
#[test]
fn tiles_drawn_part_by_part_build_as_the_cpu_mesher_says() {
    let dir = tempfile::tempdir().expect("temp dir");
    let puget = common::open_checked(&common::puget(dir.path()));
    let opts = dem::ReadOptions {
        crop: Some("1500,1500,700x530".parse().expect("crop")),
        ..Default::default()
    };
    let srtm = common::open_checked(&common::tileset(
        dir.path(),
        &common::data("srtm/N48W125.hgt"),
        opts,
    ));
    let Some(mut bench) = Bench::new() else {
        return;
    };
    let (mut built, mut controls) = (0, 0);
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut next = |n: u32| {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state % u64::from(n)) as u8
    };
    for terrain in [&puget, &srtm] {
        for t in 0..terrain.tiles.len() {
            let info = &terrain.tiles[t];
            let n = info.levels.len() as u32;
            let blocks = renderer::parts::blocks(terrain, t);
            let tile = terrain.set.tile(info.tx, info.ty).expect("tile");
            let (_, counts) = tiles::parts::tables(&tile);
            for _ in 0..6 {
                let top = n - 1 - u32::from(next(2));
                let wanted: tiles::parts::PartLevels = std::array::from_fn(|_| next(n));
                let Some(key) = blocks.key(&wanted, top) else {
                    continue;
                };
                let g = u32::from(*key.levels.iter().max().expect("parts"));
                let Some(want) = blocks.indices(&key) else {
                    panic!("tile {t}: the CPU mesher found no mesh");
                };
                let Some((length, _)) = counts.count(&key) else {
                    continue;
                };
                assert_eq!(length as usize, want.len(), "tile {t}: tables");
                let ends: Vec<u32> = info
                    .levels
                    .iter()
                    .map(|l| l.block_start + l.block_len)
                    .collect();
                let (arrays, failure) = bench.build(terrain, t, &[g], true, |b| {
                    b.part_by_part(&key, ends.iter().copied());
                    b.index_count = length;
                });
                assert_eq!(failure, None, "tile {t} key {:?}", key.levels);
                let got = common::widen(&arrays[0], 4);
                same(
                    &got[..want.len()],
                    &want,
                    &format!("tile {t} key {:?}", key.levels),
                );
                built += 1;
                // Control: one part a level coarser than the key says, where that changes the
                // part's mesh (the tables count another length).
                let coarser = (0..16).map(|q| {
                    let mut other = key;
                    other.levels[q] = other.levels[q].saturating_sub(1);
                    other
                });
                let other = coarser
                    .filter(|o| o.levels.iter().max() == key.levels.iter().max())
                    .find(|o| counts.count(o).is_some_and(|(l, _)| l != length));
                if let Some(other) = other {
                    let (arrays, failure) = bench.build(terrain, t, &[g], true, |b| {
                        b.part_by_part(&other, ends.iter().copied());
                        b.index_count = length;
                    });
                    let differs =
                        failure.is_some() || common::widen(&arrays[0], 4)[..want.len()] != want[..];
                    assert!(
                        differs,
                        "tile {t}: a part a level coarser built the same array"
                    );
                    controls += 1;
                }
            }
        }
    }
    eprintln!("{built} mixed arrays, {controls} controls");
    assert!(built >= 40, "{built} mixed arrays built");
    assert!(controls >= 20, "{controls} controls");
    bench.builder.destroy(&bench.gpu);
    bench.pool.destroy(&bench.gpu);
    assert_eq!(bench.gpu.validation_messages(), 0);
}

/// Index arrays made on the CPU (`--index-builder cpu`, the default on a software rasteriser:
/// `settings::builds_pay_on`) draw what the GPU's builder draws: the Puget sample's orbit and
/// flyover, geomorphing part by part (mixes and whole levels) and with discrete levels, every
/// frame the same pixels and triangles, with the CPU's arrays counted in the log and none of
/// the builder's left; where the device decides, a software rasteriser makes them on the CPU.
/// The control: arrays made and never copied into the pool (`made-skip`) draw other frames.
#[test]
fn index_arrays_made_on_the_cpu_draw_what_the_gpus_builder_draws() {
    let dir = tempfile::tempdir().expect("temp dir");
    let set = common::puget(dir.path());
    let run = |name: &str, path: &str, extra: &[&str], fault: Option<&str>| {
        let out = dir.path().join(name);
        std::fs::create_dir_all(&out).expect("dir");
        let frames = common::flight_with_fault(&set, &out, path, 20, extra, fault);
        let json = std::fs::read(out.join("frames.json")).expect("summary");
        let summary: serde_json::Value = serde_json::from_slice(&json).expect("summary parses");
        let column = |c: &str| common::log_column(&out.join("frames.csv"), c);
        (
            frames,
            summary,
            column("triangles"),
            column("index_arrays_made"),
        )
    };
    for (path, mode) in [
        ("orbit", "--part-by-part"),
        ("flyover", "--part-by-part"),
        ("flyover", "--no-geomorph"),
    ] {
        let what = format!("{path} {mode}");
        let gpu = run("gpu", path, &[mode, "--index-builder", "gpu"], None);
        let cpu = run("cpu", path, &[mode, "--index-builder", "cpu"], None);
        for (k, (a, b)) in gpu.0.iter().zip(&cpu.0).enumerate() {
            assert!(
                a == b,
                "{what}: frame {k} differs with the arrays made on the CPU"
            );
        }
        assert_eq!(gpu.2, cpu.2, "{what}: triangles");
        assert_eq!(gpu.1["index_builder"], "gpu", "{what}");
        assert_eq!(cpu.1["index_builder"], "cpu", "{what}");
        let made: f64 = cpu.3.iter().sum();
        assert_eq!(
            gpu.3.iter().sum::<f64>(),
            0.0,
            "{what}: the builder's flight made arrays"
        );
        assert!(
            made >= 10.0,
            "{what}: {made} arrays made: the comparison is weak"
        );
        eprintln!("{what}: {made} arrays made on the CPU over 20 frames");
    }
    let auto = run("auto", "flyover", &[], None);
    let software = auto.1["device"]
        .as_str()
        .is_some_and(|d| d.contains("llvmpipe"));
    let chosen = if software { "cpu" } else { "gpu" };
    assert_eq!(auto.1["index_builder"], chosen);

    // The control.
    let cpu = run("cpu", "orbit", &["--index-builder", "cpu"], None);
    let skipped = run(
        "skip",
        "orbit",
        &["--index-builder", "cpu"],
        Some("made-skip"),
    );
    let differing = cpu.0.iter().zip(&skipped.0).filter(|(a, b)| a != b).count();
    assert!(
        differing >= 10,
        "arrays never copied drew {differing} of 20 frames otherwise"
    );
}

/// The triangles the frame log says a frame drew are the primitives the GPU assembled, as its
/// pipeline statistics count them (lavapipe counts them; a device that does not would leave
/// the columns empty and fail here): every frame of the Puget flyover with discrete levels,
/// geomorphing part by part with the index arrays made on the CPU and built on the GPU, whole
/// tiles, and brute force. Those on screen after clipping are fewer and not none, and every
/// frame shades fragments. The control: arrays made and never copied into the pool
/// (`made-skip`) leave the GPU assembling other primitives than the log counts.
#[test]
fn the_gpu_counts_the_triangles_the_log_says_it_drew() {
    let dir = tempfile::tempdir().expect("temp dir");
    let set = common::puget(dir.path());
    let run = |mode: &[&str], fault: Option<&str>| {
        let out = dir.path().join("counted");
        std::fs::create_dir_all(&out).expect("dir");
        common::flight_with_fault(&set, &out, "flyover", 12, mode, fault);
        let column = |c: &str| common::log_column(&out.join("frames.csv"), c);
        let logged: Vec<f64> = column("triangles")
            .iter()
            .zip(column("stitch_triangles"))
            .map(|(t, s)| t + s)
            .collect();
        let counted = column("gpu_primitives");
        let clipped = column("gpu_primitives_after_clipping");
        let fragments = column("gpu_fragment_invocations");
        (logged, counted, clipped, fragments)
    };
    for mode in [
        &["--no-geomorph"][..],
        &["--part-by-part", "--index-builder", "cpu"],
        &["--part-by-part", "--index-builder", "gpu"],
        &["--whole-tiles"],
        &["--brute-force"],
    ] {
        let (logged, counted, clipped, fragments) = run(mode, None);
        assert_eq!(
            logged, counted,
            "{mode:?}: triangles logged, counted by the GPU"
        );
        for (k, (&c, &all)) in clipped.iter().zip(&counted).enumerate() {
            assert!(
                c > 0.0 && c < all,
                "{mode:?}: frame {k}: {c} of {all} on screen"
            );
            assert!(fragments[k] > 0.0, "{mode:?}: frame {k} shaded no fragment");
        }
        let share = clipped.iter().sum::<f64>() / counted.iter().sum::<f64>();
        eprintln!(
            "{mode:?}: {} triangles over 12 frames, {:.0}% on screen",
            counted.iter().sum::<f64>(),
            share * 100.0
        );
    }
    // The control.
    let (logged, counted, ..) = run(
        &["--part-by-part", "--index-builder", "cpu"],
        Some("made-skip"),
    );
    let differing = logged.iter().zip(&counted).filter(|(a, b)| a != b).count();
    assert!(
        differing >= 3,
        "arrays never copied: the GPU counted the logged triangles on {} of 12 frames",
        12 - differing
    );
}
