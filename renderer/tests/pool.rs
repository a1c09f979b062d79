//! The tile pool on lavapipe with the validation layer on: after flights that refine tiles
//! progressively within a small pool and a small upload budget (so chunks move and tiles are
//! evicted), every resident tile's blocks, morph rows (where they are sent) and index array
//! read back from GPU memory as the file stores them, through both transfer paths: blocks and
//! morph rows byte for byte, index arrays byte for byte when sent and fan for fan when built
//! on the GPU (each ring may start elsewhere, see `tests/indices.rs`). And leaving the morph
//! rows on disk, as by default, changes no frame.

use memory::{IndexArrays, Part};
use renderer::camera::Camera;
use renderer::frame::{FrameInput, Renderer};
use renderer::log::FrameRecord;
use renderer::path::CameraPath;
use renderer::prefetch::PrefetchOptions;
use renderer::settings::{MemoryOptions, MorphShader, Settings};
use renderer::terrain::Terrain;
use renderer::vulkan::{Gpu, GpuOptions};

mod common;

fn settings(forced_level: Option<u32>) -> Settings {
    Settings {
        tau: 1.0,
        forced_level,
        brute_force: false,
        shading: Default::default(),
        tile_grid_offset: 0.0,
        wireframe: false,
        sky: [0.5, 0.6, 0.9],
        no_stitch: false,
        cull_back_faces: true,
        one_fragment_shader: false,
        bound: Default::default(),
        geomorph: true,
        // Each tile at one level: the pool's index arrays are then the file's levels, which
        // this test compares (mixed arrays are compared with the CPU mesher in indices.rs).
        part_by_part: false,
        part_build_cost: renderer::parts::BuildCost::FREE,
        morph_shader: Default::default(),
        checks: renderer::plan::CheckPolicy::OnFrame,
    }
}

/// Compares every resident tile's data in the pool with the file (its morph rows where
/// `morph_rows`; else the tiles must have no room for them); returns how many tiles and bytes
/// were compared, and how many tiles' data another tile's chunk does not hold (the negative
/// control: most).
fn check_pool(
    gpu: &Gpu,
    renderer: &Renderer,
    terrain: &Terrain,
    morph_rows: bool,
) -> (usize, u64, usize) {
    let m = renderer.manager();
    let pool = renderer
        .pool()
        .read(gpu, 0, m.pool_bytes())
        .expect("pool read-back");
    assert_eq!(pool.len() as u64, m.pool_bytes());
    let (mut tiles, mut bytes, mut wrong_if_swapped) = (0, 0, 0);
    let resident: Vec<usize> = (0..terrain.tiles.len())
        .filter(|&t| m.layout_of(t as u32).is_some())
        .collect();
    for (k, &t) in resident.iter().enumerate() {
        let (offset, layout) = m.layout_of(t as u32).expect("resident");
        let (blocks, index) = m.resident_levels(t as u32).expect("resident");
        let cost = m.tile_cost(t as u32);
        let mut expect = |at: u64, part: Part| {
            let want = terrain.part(t, part).expect("part");
            let got = &pool[at as usize..at as usize + want.len()];
            assert!(
                got == want,
                "tile {t} {part:?} at {at}: pool differs from the file"
            );
            bytes += want.len() as u64;
        };
        for j in 0..=blocks.expect("blocks") {
            expect(offset + cost.positions_before(j), Part::Positions(j));
            if morph_rows {
                expect(offset + layout.morph + cost.morph_before(j), Part::Morph(j));
            } else {
                assert_eq!(cost.levels[j as usize].morph, 0, "tile {t}: room for rows");
            }
        }
        let level = index.expect("index array");
        // Where the drawn array is: the index region's start, or a promoted spare's place.
        let index_at = m.drawn_index_offset(t as u32).expect("resident");
        if renderer.builds_indices() {
            let want = terrain.part(t, Part::Indices(level)).expect("part");
            let at = index_at as usize;
            let width = cost.levels[level as usize].index_width;
            assert_eq!(
                common::fans(&pool[at..at + want.len()], width),
                common::fans(want, width),
                "tile {t} level {level}: the built array differs from the file's"
            );
            bytes += want.len() as u64;
        } else {
            expect(index_at, Part::Indices(level));
        }
        tiles += 1;
        // Negative control: another resident tile's chunk does not hold this tile's data.
        if let Some(&other) = resident.get((k + 1) % resident.len()).filter(|&&o| o != t) {
            let (o, _) = m.layout_of(other as u32).expect("resident");
            let want = terrain.part(t, Part::Positions(0)).expect("part");
            wrong_if_swapped += usize::from(&pool[o as usize..o as usize + want.len()] != want);
        }
    }
    (tiles, bytes, wrong_if_swapped)
}

/// The Puget sample's tile set, checked, and lavapipe with the validation layer on.
fn puget_on_a_device() -> (tempfile::TempDir, Terrain, Gpu) {
    let dir = tempfile::tempdir().expect("temp dir");
    let set = common::puget(dir.path());
    let terrain = common::open_checked(&set);
    let gpu = Gpu::new(&GpuOptions {
        validation: true,
        ..Default::default()
    })
    .expect("Vulkan device");
    (dir, terrain, gpu)
}

/// Frame `k` of `n` along `path`: its camera and its time on the path.
fn along(path: &CameraPath, k: u64, n: u64) -> (Camera, f64) {
    let t = path.keys[0].time + path.duration() * k as f64 / n as f64;
    (path.at(t), t)
}

fn fly(force_staging: bool, index_arrays: IndexArrays, morph_rows: bool) {
    fly_with(force_staging, index_arrays, morph_rows, true);
}

fn fly_with(force_staging: bool, index_arrays: IndexArrays, morph_rows: bool, build_on_gpu: bool) {
    let (_dir, terrain, gpu) = puget_on_a_device();
    let memory = MemoryOptions {
        gpu_budget_bytes: 3 << 20,
        upload_budget: 256 << 10,
        frames_in_flight: 2,
        force_staging,
        index_arrays,
        morph_rows,
        build_on_gpu,
        ..Default::default()
    };
    let mut renderer = Renderer::new(&gpu, &terrain, (128, 96), memory).expect("renderer");
    assert_eq!(
        renderer.pool().direct(),
        !force_staging && gpu.unified_memory()
    );
    let path = CameraPath::flyover(&terrain);
    let mut records: Vec<FrameRecord> = Vec::new();
    // Coarse first (tiles take small chunks), then tau 1 (they refine, outgrow and move).
    for k in 0..40u64 {
        let (camera, t) = along(&path, k, 40);
        let input = FrameInput {
            camera: &camera,
            time_s: t,
            label: k,
            screenshot: false,
            present: None,
        };
        let s = settings((k < 10).then_some(1));
        let done = renderer.render(&gpu, &terrain, &s, input).expect("frame");
        records.extend(done.into_iter().map(|f| f.record));
    }
    records.extend(
        renderer
            .finish_all(&gpu)
            .expect("finish")
            .into_iter()
            .map(|f| f.record),
    );
    assert_eq!(records.len(), 40);
    assert!(records.windows(2).all(|w| w[0].frame + 1 == w[1].frame));
    let sum = |f: fn(&FrameRecord) -> u64| records.iter().map(f).sum::<u64>();
    assert!(
        sum(|r| r.chunk_moves) > 0,
        "no chunk moved: the test misses moves"
    );
    assert!(sum(|r| r.tiles_coarser) > 0, "the budget never bit");
    assert_eq!(sum(|r| r.tiles_missing), 0);
    assert_eq!(sum(|r| r.gpu_allocations), 0, "allocations after start");
    assert_eq!(
        renderer.builds_indices(),
        index_arrays == IndexArrays::Built
    );
    if index_arrays == IndexArrays::Built {
        assert!(
            sum(|r| r.index_builds) > 10,
            "few builds: the check is weak"
        );
        assert_eq!(sum(|r| r.upload_bytes_indices), 0, "built arrays were sent");
        let made = sum(|r| r.index_arrays_made);
        match build_on_gpu {
            true => assert_eq!(made, 0, "arrays made on the CPU"),
            false => assert!(
                made > 10,
                "{made} arrays made on the CPU: the check is weak"
            ),
        }
    } else {
        assert_eq!(sum(|r| r.index_builds), 0);
    }
    let (uploaded, staged) = (sum(|r| r.upload_bytes), sum(|r| r.staged_bytes));
    if force_staging {
        assert_eq!(
            staged, uploaded,
            "forced staging sends everything through the ring"
        );
    } else if gpu.unified_memory() {
        assert!(
            staged < uploaded / 2,
            "direct path staged {staged} of {uploaded}"
        );
    }
    let (tiles, bytes, control) = check_pool(&gpu, &renderer, &terrain, morph_rows);
    assert!(
        tiles >= 4 && bytes > 100_000,
        "{tiles} tiles, {bytes} bytes checked"
    );
    assert!(
        control * 2 >= tiles,
        "other chunks hold the same data: check is blind"
    );
    renderer.destroy(&gpu);
    assert_eq!(gpu.validation_messages(), 0);
}

#[test]
fn direct_writes_and_built_index_arrays_read_back_from_the_pool() {
    fly(false, IndexArrays::Built, false);
}

#[test]
fn staged_copies_chunk_moves_morph_rows_and_built_index_arrays_read_back_from_the_pool() {
    fly(true, IndexArrays::Built, true);
}

/// Arrays made on the CPU (`MemoryOptions::build_on_gpu` false) copied through the staging
/// memory into chunks that move: each level's array in the pool is the file's.
#[test]
fn staged_copies_chunk_moves_and_index_arrays_made_on_the_cpu_read_back_from_the_pool() {
    fly_with(true, IndexArrays::Built, false, false);
}

#[test]
fn direct_writes_of_sent_index_arrays_read_back_from_the_pool() {
    fly(false, IndexArrays::Sent, true);
}

/// One flight of the Puget sample (30 frames of the flyover at 160 x 120, every upload sent at
/// once and no prefetching, so that two flights plan alike), alternating geomorphing part by
/// part with discrete levels frame by frame: each frame's pixels and triangles, and the block
/// bytes sent.
fn frames(morph_rows: bool, shader: MorphShader) -> (Vec<(Vec<u8>, u64)>, u64) {
    let (_dir, terrain, gpu) = puget_on_a_device();
    let memory = MemoryOptions {
        upload_budget: u64::MAX,
        prefetch: PrefetchOptions {
            enabled: false,
            ..Default::default()
        },
        morph_rows,
        ..Default::default()
    };
    let mut renderer = Renderer::new(&gpu, &terrain, (160, 120), memory).expect("renderer");
    let path = CameraPath::flyover(&terrain);
    let mut done = Vec::new();
    for k in 0..30u64 {
        let (camera, t) = along(&path, k, 30);
        let input = FrameInput {
            camera: &camera,
            time_s: t,
            label: k,
            screenshot: true,
            present: None,
        };
        let s = Settings {
            geomorph: k % 2 == 0,
            part_by_part: true,
            morph_shader: shader,
            ..settings(None)
        };
        done.extend(renderer.render(&gpu, &terrain, &s, input).expect("frame"));
    }
    done.extend(renderer.finish_all(&gpu).expect("finish"));
    renderer.destroy(&gpu);
    assert_eq!(gpu.validation_messages(), 0);
    assert_eq!(done.len(), 30);
    let blocks = done.iter().map(|f| f.record.upload_bytes_blocks).sum();
    let frames = done
        .into_iter()
        .map(|f| (f.pixels.expect("screenshot"), f.record.triangles))
        .collect();
    (frames, blocks)
}

/// Leaving the morph rows on disk ([`MemoryOptions::morph_rows`] false, the default) changes no
/// pixel: the morph pass places every vertex from its parents' own heights and the discrete
/// shader reads positions alone. The Puget flyover flown with and without the rows, geomorphing
/// part by part and discrete levels in turn: every frame equal, and without the rows at most
/// 55% of the block bytes (Puget's positions are 3.5 of its 7.3 bytes a sample). The control:
/// the two-levels shader, which reads the rows, draws other frames without them.
#[test]
fn frames_are_the_same_without_the_morph_rows_no_shader_reads() {
    let (with, with_bytes) = frames(true, MorphShader::Hierarchical);
    let (without, without_bytes) = frames(false, MorphShader::Hierarchical);
    assert!(with.iter().all(|(_, triangles)| *triangles > 1_000));
    for (k, (a, b)) in with.iter().zip(&without).enumerate() {
        assert_eq!(a.1, b.1, "frame {k}: triangles");
        assert!(
            a.0 == b.0,
            "frame {k}: the pixels differ without the morph rows"
        );
    }
    assert!(
        without_bytes * 100 <= with_bytes * 55 && without_bytes > 0,
        "block bytes {without_bytes} without the rows, {with_bytes} with them"
    );
    // The control.
    let (rows, _) = frames(true, MorphShader::TwoLevels);
    let (no_rows, _) = frames(false, MorphShader::TwoLevels);
    let differ = rows
        .iter()
        .zip(&no_rows)
        .filter(|(a, b)| a.0 != b.0)
        .count();
    eprintln!(
        "block bytes {without_bytes} without the rows, {with_bytes} with them; the two-levels \
         shader without its rows: {differ} of 30 frames differ"
    );
    assert!(
        differ >= 10,
        "the two-levels shader drew {differ} of 30 frames otherwise without its rows"
    );
}
