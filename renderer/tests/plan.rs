//! The frame plan without a GPU: culling is conservative, and under a budget far smaller than
//! the view needs the manager grants only what is resident, every visible tile is drawn, and
//! the seams are stitched at the levels granted (not the levels wanted).

mod common;

use std::path::Path;

use glam::DVec3;
use memory::{Config, Manager};
use renderer::camera::Camera;
use renderer::path::CameraPath;
use renderer::plan::{plan, stitch_granted, visible_tiles, Draw, LevelRule, Residency};
use renderer::terrain::Terrain;
use renderer::tile::Side;

const EXTENT: (u32, u32) = (640, 480);

fn puget() -> (tempfile::TempDir, Terrain) {
    let dir = tempfile::tempdir().expect("tempdir");
    let set = common::puget(dir.path());
    let terrain = Terrain::open(&set).unwrap_or_else(|e| panic!("{}: {e}", set.display()));
    let all: Vec<usize> = (0..terrain.tiles.len()).collect();
    terrain.check_all(&all);
    assert_eq!(terrain.failed_count(), 0, "{:?}", terrain.take_failures());
    (dir, terrain)
}

/// The Puget sample built in `dir`, and a copy of it named `name` whose bytes `damage` changed,
/// given the sample opened and tile `at`'s directory entry, then resealed where `reseal` says
/// (its checksums recomputed, so that only the semantic checks can see the damage).
fn damaged_puget(
    dir: &Path,
    name: &str,
    at: (u32, u32),
    reseal: bool,
    damage: impl FnOnce(&mut [u8], &tiles::TileSet, tiles::format::DirEntry),
) -> (std::path::PathBuf, std::path::PathBuf) {
    let set = common::puget(dir);
    let mut bytes = std::fs::read(&set).expect("read");
    let ts = tiles::TileSet::open(&set).expect("open");
    let entry = ts.dir_entry(at.0, at.1).expect("entry");
    damage(&mut bytes, &ts, entry);
    drop(ts);
    if reseal {
        tiles::format::reseal(&mut bytes).expect("reseal");
    }
    let damaged = dir.join(name);
    std::fs::write(&damaged, &bytes).expect("write");
    (set, damaged)
}

/// Cameras along both generated paths, and a few looking straight down and away.
fn cameras(terrain: &Terrain) -> Vec<Camera> {
    let mut out = Vec::new();
    for path in [CameraPath::orbit(terrain), CameraPath::flyover(terrain)] {
        let d = path.duration();
        out.extend((0..24).map(|k| path.at(path.keys[0].time + d * f64::from(k) / 24.0)));
    }
    let (lo, hi) = terrain.bounds();
    let centre = (lo + hi) * 0.5;
    for (yaw, pitch) in [(0.0, -1.5), (3.0, -0.2), (1.0, 0.3)] {
        out.push(Camera {
            position: DVec3::new(centre.x, centre.y, hi.z + 500.0),
            yaw,
            pitch,
            fov_y: 1.0,
        });
    }
    out
}

/// No tile with a point on screen is culled: every culled tile's box, sampled on a 9^3
/// lattice, projects outside the image or behind the camera.
#[test]
fn culling_never_drops_a_tile_on_screen() {
    let (_dir, terrain) = puget();
    let mut culled_total = 0;
    for camera in cameras(&terrain) {
        let view = camera.view(EXTENT.0, EXTENT.1);
        let visible = visible_tiles(&terrain, &view, camera.position);
        for (i, tile) in terrain.tiles.iter().enumerate() {
            if visible.contains(&i) {
                continue;
            }
            culled_total += 1;
            for k in 0..729 {
                let f = DVec3::new(
                    f64::from(k % 9) / 8.0,
                    f64::from(k / 9 % 9) / 8.0,
                    f64::from(k / 81) / 8.0,
                );
                let p = tile.min + (tile.max - tile.min) * f;
                if let Some((x, y)) = view.project(p - camera.position) {
                    let inside = (0.0..f64::from(EXTENT.0)).contains(&x)
                        && (0.0..f64::from(EXTENT.1)).contains(&y);
                    assert!(
                        !inside,
                        "tile ({}, {}) culled but {p:?} projects to ({x:.1}, {y:.1}) from {camera:?}",
                        tile.tx, tile.ty
                    );
                }
            }
        }
    }
    // The check is not vacuous: the cameras do cull.
    assert!(culled_total > 100, "only {culled_total} tiles culled");
}

/// Front to back: the box point nearest the camera gets no nearer along the list.
#[test]
fn visible_tiles_come_front_to_back() {
    let (_dir, terrain) = puget();
    for camera in cameras(&terrain) {
        let view = camera.view(EXTENT.0, EXTENT.1);
        let p = camera.position;
        let d: Vec<f64> = visible_tiles(&terrain, &view, p)
            .iter()
            .map(|&i| {
                let t = &terrain.tiles[i];
                p.clamp(t.min, t.max).distance(p)
            })
            .collect();
        assert!(d.windows(2).all(|w| w[0] <= w[1]), "{d:?}");
    }
}

/// The flyover with a 2 MB pool and 64 KiB of uploads a frame (index arrays sent, blocks
/// without morph rows, as the renderer sends them): the plan draws every visible tile at a
/// level it holds, never above the level wanted but where a coarser index array waits for the
/// budget (the tile then stays at the level it drew the frame before), uploads within the
/// budget (plus the coarsest levels, which may overshoot), and stitches at the granted levels.
/// Stitching at the wanted levels instead (the old order) gives different seams: the negative
/// control.
#[test]
fn tight_budget_draws_what_is_resident_and_stitches_granted_levels() {
    let (_dir, terrain) = puget();
    let config = Config {
        pool_bytes: 2 << 20,
        upload_budget: 64 << 10,
        ..Config::default()
    };
    let mut manager = Manager::new(terrain.costs(false, false), config);
    let path = CameraPath::flyover(&terrain);
    let (mut coarser_frames, mut seams_differ) = (0, 0);
    let mut drawn_before = std::collections::HashMap::new();
    for f in 0..60u64 {
        let camera = path.at(path.keys[0].time + path.duration() * f as f64 / 60.0);
        let p = plan(
            &terrain,
            &mut manager,
            &camera,
            EXTENT,
            (
                LevelRule::Tau(1.0, renderer::lod::Bound::Guaranteed),
                renderer::plan::CheckPolicy::OnFrame,
            ),
            Residency {
                frame: f,
                completed: f.checked_sub(2),
                allow_uploads: true,
                prefetch: &[],
                prefetch_until: None,
            },
        )
        .expect("plan");
        manager.check().unwrap_or_else(|e| panic!("frame {f}: {e}"));
        assert_eq!(p.stats.tiles_missing, 0, "frame {f}");
        assert_eq!(p.draws.len() as u64, p.tiles_visible, "frame {f}");
        let sent: u64 = p.uploads.iter().map(|u| u.bytes).sum();
        assert!(
            sent <= config.upload_budget + p.stats.upload_overshoot_bytes,
            "frame {f}: {sent} bytes sent"
        );
        let mut coarser = 0;
        for d in &p.draws {
            assert!(
                d.level <= d.wanted || drawn_before.get(&d.tile) == Some(&d.level),
                "frame {f}: {d:?}"
            );
            let (_, index) = manager
                .resident_levels(d.tile as u32)
                .unwrap_or_else(|| panic!("frame {f}: tile {} drawn, not resident", d.tile));
            assert_eq!(index, Some(d.level), "frame {f}: tile {}", d.tile);
            coarser += u64::from(d.level < d.wanted);
        }
        assert_eq!(coarser, p.stats.tiles_coarser, "frame {f}");
        drawn_before = p.draws.iter().map(|d| (d.tile, d.level)).collect();
        let granted = stitch_granted(&terrain, &p.draws, false).expect("stitch");
        assert_eq!(granted, p.stitches, "frame {f}");
        if coarser > 0 {
            coarser_frames += 1;
            let wanted: Vec<Draw> = p
                .draws
                .iter()
                .map(|d| Draw {
                    level: d.wanted,
                    ..*d
                })
                .collect();
            if stitch_granted(&terrain, &wanted, false).expect("stitch") != p.stitches {
                seams_differ += 1;
            }
        }
    }
    assert!(coarser_frames > 0, "the budget never bound");
    assert!(
        seams_differ > 0,
        "stitching at wanted levels never differed"
    );
}

/// Which polyline segments a stitch closes: edges (as vertex pairs, in `a`'s frame) of its
/// triangles.
fn stitch_edges(s: &renderer::stitch::Stitch) -> std::collections::HashSet<(u32, u32)> {
    let mut edges = std::collections::HashSet::new();
    for t in s.indices.split(|&i| i == renderer::stitch::RESTART) {
        if t.len() == 3 {
            for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
                let (p, q) = (s.vertices[a as usize], s.vertices[b as usize]);
                edges.insert((p.min(q), p.max(q)));
            }
        }
    }
    edges
}

/// Every segment of either border polyline that the other does not share is an edge of a
/// stitching triangle (so no T-junction is left open), every stitch vertex lies on the shared
/// edge, and the triangles have no area in plan view. For every pair of neighbouring tiles of
/// the Puget set at every pair of levels. Dropping one triangle breaks it (the control).
#[test]
fn stitches_close_every_seam_at_every_level_pair() {
    use renderer::stitch::{stitch_side, DrawnSide, Stitch, LOCAL_BITS};
    use tiles::pack::unpack;
    let (_dir, terrain) = puget();
    let mut checked = 0;
    let mut control_failed = 0;
    for a in terrain.tiles.iter() {
        for side in Side::FORWARD {
            let k = side.index();
            let Some(j) = terrain.neighbour(a, side) else {
                continue;
            };
            let b = &terrain.tiles[j];
            for (la, lb, morph) in (0..terrain.levels).flat_map(|la| {
                (0..terrain.levels).flat_map(move |lb| [(la, lb, false), (la, lb, true)])
            }) {
                {
                    let mut s = Stitch::default();
                    let mine = DrawnSide {
                        tile: a,
                        level: la,
                        record: 0,
                    };
                    let theirs = DrawnSide {
                        tile: b,
                        level: lb,
                        record: 1,
                    };
                    assert!(
                        stitch_side(&mut s, mine, theirs, side, morph),
                        "borders differ"
                    );
                    // Each vertex is pulled from its own tile: a's first, then b's, each the
                    // border vertex it stands for.
                    let n = a.paged().expect("checked").sides().borders[la as usize][k].len();
                    assert_eq!(s.pulled.len(), s.vertices.len());
                    for (i, &p) in s.pulled.iter().enumerate() {
                        let (record, local) = (p >> LOCAL_BITS, p & ((1 << LOCAL_BITS) - 1));
                        let (tile, level, side, at) = if i < n {
                            (a, la, k, i)
                        } else {
                            (b, lb, side.opposite().index(), i - n)
                        };
                        assert_eq!(record, u32::from(i >= n));
                        assert_eq!(
                            tile.paged().expect("checked").sides().border_indices[level as usize]
                                [side][at],
                            local
                        );
                    }
                    if morph {
                        // Morphing keeps the triangles at shared vertices: one per segment
                        // of either polyline.
                        let m = a.paged().expect("checked").sides().borders[la as usize][k].len()
                            + b.paged().expect("checked").sides().borders[lb as usize]
                                [side.opposite().index()]
                            .len();
                        assert_eq!(s.triangles as usize, m - 2, "levels {la}/{lb}");
                    }
                    let on_edge = |p: u32| {
                        let (x, y, _) = unpack(p);
                        if side == Side::East {
                            x == 256
                        } else {
                            y == 256
                        }
                    };
                    assert!(s.vertices.iter().all(|&p| on_edge(p)));
                    let mine = a.paged().expect("checked").sides().borders[la as usize][k].clone();
                    let theirs: Vec<u32> = s.vertices[mine.len().min(s.vertices.len())..].to_vec();
                    let open = |edges: &std::collections::HashSet<(u32, u32)>| {
                        let segs = |line: &[u32]| -> Vec<(u32, u32)> {
                            line.windows(2)
                                .map(|w| (w[0].min(w[1]), w[0].max(w[1])))
                                .collect()
                        };
                        let (m, t) = (segs(&mine), segs(&theirs));
                        m.iter()
                            .filter(|e| !t.contains(e))
                            .chain(t.iter().filter(|e| !m.contains(e)))
                            .any(|e| !edges.contains(e))
                    };
                    if s.vertices.is_empty() {
                        continue; // identical borders: nothing to close
                    }
                    assert!(
                        !open(&stitch_edges(&s)),
                        "tiles {},{} k {k} levels {la}/{lb}",
                        a.tx,
                        a.ty
                    );
                    checked += 1;
                    // The control: without its last triangle the seam is open somewhere.
                    if s.triangles > 0 {
                        let mut cut = s.clone();
                        cut.indices.truncate(cut.indices.len() - 4);
                        control_failed += usize::from(open(&stitch_edges(&cut)));
                    }
                }
            }
        }
    }
    assert!(checked > 500, "only {checked} seams checked");
    assert!(
        control_failed > 0,
        "dropping a triangle never opened a seam"
    );
}

/// Border continuity (the CPU mirror of the vertex shader's morph): in a tile set built with
/// shared sides, every vertex two neighbouring tiles both hold on their shared side gets the
/// same morphed height from both tiles, bit for bit, from random cameras (each vertex's level
/// comes from its position and the camera alone). The control: built with independent sides,
/// some shared vertices morph to different heights.
#[test]
fn shared_side_vertices_morph_to_one_height_from_both_tiles() {
    use renderer::camera::Camera;
    use renderer::morph::{tile_vertices, TileMorph};
    let (a, b) = (
        tempfile::tempdir().expect("tempdir"),
        tempfile::tempdir().expect("tempdir"),
    );
    let shared = Terrain::open(&common::puget(a.path())).expect("open");
    let alone = Terrain::open(&common::puget_independent(b.path())).expect("open");
    assert!(shared.shared_sides && !alone.shared_sides);
    let mut seed = 0x2545_f491_4f6c_dd1du64;
    let mut random = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 11) as f64 / (1u64 << 53) as f64
    };
    for (terrain, name) in [(&shared, "shared"), (&alone, "independent")] {
        let finest = terrain.levels - 1;
        let (lo, hi) = terrain.bounds();
        let (mut compared, mut differing, mut morphed) = (0usize, 0usize, 0usize);
        for _trial in 0..6 {
            // Low over the set, looking somewhere level-ish: every level in view somewhere.
            let camera = Camera {
                position: glam::DVec3::new(
                    lo.x + (hi.x - lo.x) * random(),
                    lo.y + (hi.y - lo.y) * random(),
                    hi.z + 200.0 + 3000.0 * random(),
                ),
                yaw: random() * std::f64::consts::TAU,
                pitch: -0.05 - 0.5 * random(),
                fov_y: 1.0,
            };
            let tau = 0.5 + 4.0 * random();
            let morph = |i: usize| TileMorph::from_camera(terrain, &camera, (640, 480), tau, i);
            for (i, a) in terrain.tiles.iter().enumerate() {
                let ta = terrain.set.tile(a.tx, a.ty).expect("tile");
                let va = tile_vertices(&ta, finest, Some(&morph(i)));
                let plain = tile_vertices(&ta, finest, None);
                morphed += va.iter().zip(&plain).filter(|(m, p)| m.2 != p.2).count();
                for across in Side::FORWARD {
                    let east = across == Side::East;
                    let Some(j) = terrain.neighbour(a, across) else {
                        continue;
                    };
                    let b = &terrain.tiles[j];
                    let tb = terrain.set.tile(b.tx, b.ty).expect("tile");
                    let vb = tile_vertices(&tb, finest, Some(&morph(j)));
                    // Heights along the shared side, by position along it.
                    let side = |v: &[(u32, u32, f32)], at: u32| {
                        v.iter()
                            .filter(|p| if east { p.0 == at } else { p.1 == at })
                            .map(|p| (if east { p.1 } else { p.0 }, p.2.to_bits()))
                            .collect::<std::collections::HashMap<u32, u32>>()
                    };
                    let (mine, theirs) = (side(&va, 256), side(&vb, 0));
                    for (at, h) in &mine {
                        if let Some(g) = theirs.get(at) {
                            compared += 1;
                            differing += usize::from(g != h);
                        }
                    }
                }
            }
        }
        // Not vacuous: the cameras morph many vertices away from their own heights.
        assert!(morphed > 10_000, "{name}: only {morphed} vertices morphed");
        assert!(compared > 1000, "{name}: only {compared} shared vertices");
        if terrain.shared_sides {
            assert_eq!(differing, 0, "{name}: {differing} of {compared} differ");
        } else {
            assert!(differing > 0, "{name}: the control found no difference");
        }
        eprintln!("{name} sides: {differing} of {compared} shared side vertices differ");
    }
}

/// The Puget and SRTM N48W125 terrains of the level-cover tests (N48W125: smooth filled voids
/// beside rough coast, so neighbouring tiles' tables differ), built into `dirs`.
fn cover_terrains(dirs: (&Path, &Path)) -> [Terrain; 2] {
    let puget = Terrain::open(&common::puget(dirs.0)).expect("open");
    let n48 = common::tileset(
        dirs.1,
        &common::data("srtm/N48W125.hgt"),
        Default::default(),
    );
    [puget, Terrain::open(&n48).expect("open")]
}

/// The level-cover tests' views of `terrain`: every third camera of its paths and four low
/// random ones.
fn cover_views(terrain: &Terrain, rng: &mut splitmix::Rng) -> Vec<Camera> {
    let (lo, hi) = terrain.bounds();
    let mut views: Vec<Camera> = cameras(terrain).into_iter().step_by(3).collect();
    views.extend((0..4).map(|_| Camera {
        position: DVec3::new(
            lo.x + (hi.x - lo.x) * rng.unit(),
            lo.y + (hi.y - lo.y) * rng.unit(),
            hi.z + 100.0 + 2000.0 * rng.unit(),
        ),
        yaw: rng.unit() * std::f64::consts::TAU,
        pitch: -0.05 - 0.4 * rng.unit(),
        fov_y: 1.0,
    }));
    views
}

/// The drawn level of a morphing tile covers the level of every vertex of it on screen that a
/// level moves (`renderer::morph`, "The level a tile is drawn at"): over Puget and SRTM
/// N48W125 (smooth filled voids beside rough coast, so neighbouring tiles' tables differ),
/// from the orbit, the flyover and low random cameras, at tau 1 and 3, every on-screen vertex
/// of every visible tile, at every level, has `l(v)` at most the tile's drawn level, except
/// the tile's corners, which are checked to be block-0 vertices (own height on every level).
/// Controls: the interior's table alone over the whole box does not cover them (the sides'
/// tables matter); the rule before (the largest of the nine tables over the whole box) drew
/// some tiles finer (it may draw a tile coarser only where a side's strip, which reaches into
/// the neighbour, needs more: counted); and some corner on screen does want more than its
/// tile's drawn level (leaving the corners out changed something).
#[test]
fn the_drawn_level_covers_every_vertex_on_screen() {
    use renderer::lod::{self, Bound};
    use renderer::morph::{table_of, TileMorph, TAU_MARGIN};
    let (dir, srtm_dir) = (
        tempfile::tempdir().expect("tempdir"),
        tempfile::tempdir().expect("tempdir"),
    );
    let terrains = cover_terrains((dir.path(), srtm_dir.path()));
    let mut rng = splitmix::Rng(0x6d6f_7270_685f_6c76);
    let (mut checked, mut interior_misses, mut coarser, mut tiles) = (0usize, 0usize, 0usize, 0);
    let (mut corners_above, mut finer) = (0usize, 0usize);
    for terrain in &terrains {
        let finest = terrain.levels - 1;
        // Every third camera of the paths (the test's cost is in its vertices).
        for camera in cover_views(terrain, &mut rng) {
            let view = camera.view(EXTENT.0, EXTENT.1);
            for tau in [1.0, 3.0] {
                for i in visible_tiles(terrain, &view, camera.position) {
                    let tile = &terrain.tiles[i];
                    let drawn =
                        lod::morph_level(&view, camera.position, tile, tau, Bound::Guaranteed);
                    let whole = |table: &renderer::levels::LevelTable| {
                        let r = lod::tolerable_error(
                            &view,
                            camera.position,
                            tile,
                            tau * TAU_MARGIN,
                            Bound::Guaranteed,
                        );
                        (table.level_f64(r).ceil() as u32).min(finest)
                    };
                    let (interior, before) = (whole(&tile.tables[0]), whole(&tile.drawn_table));
                    coarser += usize::from(drawn < before);
                    finer += usize::from(drawn > before);
                    tiles += 1;
                    let morph = TileMorph::from_camera(terrain, &camera, EXTENT, tau, i);
                    let data = terrain.set.tile(tile.tx, tile.ty).expect("tile");
                    let block0 = data.level(0).expect("level 0").positions.len();
                    let mut interior_missed = false;
                    for (k, (x, y, own)) in data.vertices().into_iter().enumerate() {
                        // Tables 5..=8 are the corners' (renderer::morph::table_of).
                        let corner = table_of(x, y) >= 5;
                        let (relative, l) = morph.vertex(x, y, own);
                        let clip = morph.view_proj * relative.extend(1.0);
                        let w = clip.w;
                        if w < 1e-3 || clip.x.abs() > w || clip.y.abs() > w {
                            continue;
                        }
                        if corner {
                            assert!(k < block0, "tile {i}: corner ({x}, {y}) in block > 0");
                            corners_above += usize::from(l > drawn as f32 + 1e-3);
                            continue;
                        }
                        checked += 1;
                        assert!(
                            l <= drawn as f32 + 1e-3,
                            "tile {i} drawn at {drawn}: vertex ({x}, {y}) on screen wants {l}"
                        );
                        interior_missed |= l > interior as f32 + 1e-3;
                    }
                    interior_misses += usize::from(interior_missed);
                }
            }
        }
    }
    eprintln!(
        "{checked} on-screen vertices covered; {coarser} of {tiles} tile draws coarser than \
         the rule before, {finer} finer (the strips); the interior's table alone misses in \
         {interior_misses}; {corners_above} corners on screen above their tile's drawn level"
    );
    assert!(
        corners_above > 0,
        "the control: no corner wants more than its tile's level"
    );
    assert!(checked > 1_000_000, "only {checked} vertices checked");
    assert!(
        interior_misses > 0,
        "the control: the interior's table always covered"
    );
    assert!(coarser > 0, "no tile drawn coarser than before");
}

/// The level the morph pass places a vertex at (`renderer::morph`, "Over the star") is never
/// below the vertex's own, and for every vertex on screen both are within the level of every
/// part whose closed box holds it (`lod::morph_parts`, the cover part by part; for a vertex
/// on the tile's side, which the tile draws at its level, within that level): the star
/// raises a vertex no further than each part drawing it allows, so a vertex that a part's next
/// level adds starts on the surface drawn without it, as before the star, and a coarser part's
/// fans, which take in a line's vertices, are not bent by a finer part's needs. (Before
/// 2026-12-04 the east and south parts' side stretches were found by comparing metres, and a
/// rounding lost them: a vertex on those sides was above its part's level.) The weights the
/// mirror places the tile's mix with, each vertex's parents' passed on ("Within a block"),
/// are 0 at every vertex of a block finer than a part holding it (without the hold to the
/// coarsest part, a line's vertex took 0.28 from a parent on the tile's side in a part at
/// level 0). Over Puget and SRTM N48W125,
/// from the paths and low random cameras, at tau 1 and 3. Controls: the star raises many
/// on-screen vertices above their own level, and the star's whole box (reaching across the
/// lines between parts and along no grid) would break the bound somewhere.
#[test]
fn the_placed_level_stays_within_every_part_that_draws_the_vertex() {
    use renderer::lod::{self, Bound};
    use renderer::morph::{tile_weights, TileMorph};
    use tiles::parts::PartKey;
    let (dir, srtm_dir) = (
        tempfile::tempdir().expect("tempdir"),
        tempfile::tempdir().expect("tempdir"),
    );
    let terrains = cover_terrains((dir.path(), srtm_dir.path()));
    let mut rng = splitmix::Rng(0x7374_6172_5f6c_766c);
    let (mut checked, mut raised, mut across) = (0usize, 0usize, 0usize);
    let mut inherited = 0usize;
    // The parts whose closed box holds tile-local coordinate c (one, or two on a line).
    let span = |c: u32| (c.saturating_sub(1) / 64).min(3)..=(c / 64).min(3);
    for terrain in &terrains {
        for camera in cover_views(terrain, &mut rng) {
            let view = camera.view(EXTENT.0, EXTENT.1);
            for tau in [1.0, 3.0] {
                for i in visible_tiles(terrain, &view, camera.position) {
                    let tile = &terrain.tiles[i];
                    let parts =
                        lod::morph_parts(&view, camera.position, tile, tau, Bound::Guaranteed);
                    let morph = TileMorph::from_camera(terrain, &camera, EXTENT, tau, i);
                    let data = terrain.set.tile(tile.tx, tile.ty).expect("tile");
                    let block0 = data.level(0).expect("level 0").positions.len();
                    // Each vertex's block, and its weight with its parents' passed on.
                    let blocks: Vec<u32> = (0..terrain.levels)
                        .flat_map(|j| {
                            let n = data.level(j).map_or(0, |b| b.positions.len());
                            std::iter::repeat_n(j, n)
                        })
                        .collect();
                    // The weights as the frame places them: part by part, at the finest
                    // part's level (vertices past it are not placed: weight 0).
                    let top = u32::from(parts.iter().copied().max().expect("parts"));
                    let mut drawn = morph;
                    (drawn.parts, drawn.cap) = (Some(PartKey { levels: parts }), top as f32);
                    let weights = tile_weights(&data, top, &drawn);
                    for (k, (x, y, own)) in data.vertices().into_iter().enumerate().skip(block0) {
                        let (relative, point) = morph.vertex(x, y, own);
                        let clip = morph.view_proj * relative.extend(1.0);
                        let w = clip.w;
                        if w < 1e-3 || clip.x.abs() > w || clip.y.abs() > w {
                            continue;
                        }
                        let placed = morph.placed(x, y, own);
                        let side = |c: u32| c == 0 || c == 256;
                        let within = if side(x) || side(y) {
                            parts.iter().copied().max().expect("parts")
                        } else {
                            span(x)
                                .flat_map(|i| span(y).map(move |j| parts[(4 * j + i) as usize]))
                                .min()
                                .expect("a part")
                        } as f32;
                        checked += 1;
                        assert!(
                            placed >= point,
                            "tile {i}: ({x}, {y}) placed {placed} below {point}"
                        );
                        assert!(
                            point <= within + 1e-3 && placed <= within + 1e-3,
                            "tile {i} parts {parts:?}: ({x}, {y}) placed at {placed}, own {point}, \
                             a part holding it at {within}"
                        );
                        raised += usize::from(placed > point + 0.01);
                        // A vertex that a part holding it lacks (the part's next level adds
                        // it) has weight 0, whatever its parents pass on ("Within a block").
                        let j = blocks[k] as f32;
                        let weight = weights.get(k).copied().unwrap_or(0.0);
                        assert!(
                            j <= within || weight == 0.0,
                            "tile {i} parts {parts:?}: ({x}, {y}) of block {j} at weight {weight} \
                             beyond a part holding it at {within}"
                        );
                        let own_weight = (placed - j + 1.0).clamp(0.0, 1.0);
                        inherited += usize::from(weight > own_weight + 0.01);
                        let s = renderer::morph::scale_of(x, y) as f32;
                        let whole = morph.level_reaching(x, y, own, glam::Vec2::splat(s));
                        across += usize::from(whole > within + 1e-3);
                    }
                }
            }
        }
    }
    eprintln!(
        "{checked} on-screen vertices within every part holding them; {raised} raised by \
         their star, {inherited} by their parents; the whole star's box would exceed a \
         part's level at {across}"
    );
    assert!(inherited > 0, "no vertex took a weight from its parents");
    assert!(checked > 1_000_000, "only {checked} vertices checked");
    assert!(
        raised > checked / 100,
        "the star raised only {raised} vertices"
    );
    assert!(
        across > 0,
        "the control: the whole star's box never exceeded a part's level"
    );
}

/// Opening reads the header, the directory and each tile's outline, not the tiles' data: a
/// tile whose data is damaged (its checksum no longer matches) opens with the rest, and its
/// check, the first time it is asked for, names the file, the tile and the checksum; its
/// neighbours pass. A failure is taken once. The control: the undamaged file's tiles all pass.
#[test]
fn a_damaged_tile_opens_and_fails_its_check_when_first_needed() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (_, damaged) = damaged_puget(dir.path(), "damaged.vkt", (2, 1), false, |bytes, _, e| {
        // A byte near the end of the blob: the finest level's data, far from the outline.
        bytes[(e.offset + e.len - 64) as usize] ^= 0x5a;
    });
    let terrain = Terrain::open(&damaged).expect("a damaged tile's data does not stop the open");
    assert!(
        terrain.tiles.iter().all(|t| t.usable().is_none()),
        "nothing checked at open"
    );
    let broken = terrain.tile_index(2, 1).expect("tile 2,1");
    let problem = terrain
        .check(broken)
        .err()
        .expect("the damaged tile fails")
        .to_string();
    assert!(
        problem.contains("damaged.vkt")
            && problem.contains("tile 2,1")
            && problem.contains("checksum"),
        "{problem}"
    );
    assert!(
        terrain.part(broken, memory::Part::Positions(0)).is_none(),
        "no data from it"
    );
    for side in Side::ALL {
        if let Some(j) = terrain.neighbour(&terrain.tiles[broken], side) {
            assert!(terrain.check(j).is_ok(), "{side:?} neighbour");
        }
    }
    assert_eq!(terrain.failed_count(), 1);
    let taken = terrain.take_failures();
    assert_eq!(taken.len(), 1);
    assert_eq!(taken[0].0, broken);
    assert!(
        terrain.take_failures().is_empty(),
        "a failure is taken once"
    );
    // The control.
    let (_dir, whole) = puget();
    assert!(whole.check(broken).is_ok());
}

/// A tile whose outline does not read (its header names another tile; checksums resealed)
/// does not stop the open, which reads no tile: the tile holds its place in the grid, and its
/// check, the first time it is asked for, fails naming the file, the tile and the problem. Its
/// neighbours, whose side tables would have taken its table in, read and pass. The control:
/// the sound file's tile passes.
#[test]
fn a_tile_whose_outline_does_not_read_fails_its_check_when_first_needed() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (_, damaged) = damaged_puget(dir.path(), "outline.vkt", (2, 1), true, |bytes, _, e| {
        // The tile header's column (after its 4-byte magic).
        let at = e.offset as usize + 4;
        bytes[at..at + 4].copy_from_slice(&3u32.to_le_bytes());
    });
    let terrain = Terrain::open(&damaged).expect("a damaged outline does not stop the open");
    assert_eq!(terrain.tiles.outlines_read(), 0, "the open reads no tile");
    let broken = terrain.tile_index(2, 1).expect("tile 2,1");
    let tile = &terrain.tiles[broken];
    assert_eq!((tile.tx, tile.ty), (2, 1));
    assert!(
        tile.min.x < tile.max.x && tile.min.y < tile.max.y,
        "it holds its place"
    );
    let problem = terrain.check(broken).err().expect("it fails").to_string();
    assert!(
        problem.contains("outline.vkt")
            && problem.contains("tile 2,1")
            && problem.contains("directory points at tile 3,1"),
        "{problem}"
    );
    assert_eq!(problem.matches("outline.vkt").count(), 1, "{problem}");
    for side in Side::ALL {
        if let Some(j) = terrain.neighbour(&terrain.tiles[broken], side) {
            assert!(terrain.check(j).is_ok(), "{side:?} neighbour");
        }
    }
    assert_eq!(terrain.failed_count(), 1);
    let (_dir, whole) = puget();
    assert!(whole.check(broken).is_ok(), "the control");
}

/// The set's bounds come from its header alone, and hold every tile's box: the grid's extent
/// exactly (the tiles' boxes reach its edges), the heights within a height step (the tiles'
/// vertices are on the height lattice). The control: the tiles reach the header's range, so
/// the bounds are not merely loose.
#[test]
fn the_bounds_from_the_header_hold_every_tile() {
    let (_dir, terrain) = puget();
    let (lo, hi) = terrain.bounds();
    let step = f64::from(terrain.height_step);
    let (mut tlo, mut thi) = (DVec3::INFINITY, DVec3::NEG_INFINITY);
    for t in terrain.tiles.iter() {
        (tlo, thi) = (tlo.min(t.min), thi.max(t.max));
    }
    assert_eq!((lo.x, lo.y, hi.x, hi.y), (tlo.x, tlo.y, thi.x, thi.y));
    assert!(
        tlo.z >= lo.z - step && thi.z <= hi.z + step,
        "{tlo} {thi} in {lo} {hi}"
    );
    assert!(
        tlo.z <= lo.z + 2.0 * step && thi.z >= hi.z - 2.0 * step,
        "{tlo} {thi} in {lo} {hi}"
    );
}

/// Tiles read in any order get the same tables, and the tiles that hold a side or a corner
/// hold the same table for it (the larger errors of them all): the side tables of a tile and
/// its neighbour across a side are one, and so are the corner tables of the four tiles around
/// a corner. Each tile reads its outline and its neighbours' once, when first asked for. The
/// control: the tiles' own tables differ, so the sharing is not of equal tables.
#[test]
fn tiles_read_as_asked_for_share_their_side_and_corner_tables() {
    let dir = tempfile::tempdir().expect("tempdir");
    let set = common::puget(dir.path());
    let forward = Terrain::open(&set).expect("open");
    let backward = Terrain::open(&set).expect("open");
    let n = forward.tiles.len();
    let inner = forward.tile_index(1, 1).expect("tile 1,1");
    let _ = &backward.tiles[inner];
    assert_eq!(
        backward.tiles.outlines_read(),
        9,
        "a tile and its eight neighbours"
    );
    for i in (0..n).rev() {
        let _ = &backward.tiles[i];
    }
    assert_eq!(backward.tiles.outlines_read(), n, "each outline once");
    let mut own = std::collections::HashSet::new();
    for i in 0..n {
        let (a, b) = (&forward.tiles[i], &backward.tiles[i]);
        assert_eq!(a.tables, b.tables, "tile {i}");
        assert_eq!(a.drawn_table, b.drawn_table, "tile {i}");
        own.insert(format!("{:?}", a.tables[0]));
        for side in [Side::East, Side::South] {
            if let Some(j) = forward.neighbour(a, side) {
                let c = &forward.tiles[j];
                assert_eq!(
                    a.tables[1 + side.index()],
                    c.tables[1 + side.opposite().index()],
                    "tile {i} and its {side:?} neighbour"
                );
            }
        }
        // The SE corner of (x, y) is the SW of (x + 1, y), the NE of (x, y + 1) and the NW of
        // (x + 1, y + 1).
        let (x, y) = (a.tx, a.ty);
        let corner = [
            forward.tile_index(x + 1, y).map(|j| (j, 7)),
            forward.tile_index(x, y + 1).map(|j| (j, 6)),
            forward.tile_index(x + 1, y + 1).map(|j| (j, 5)),
        ];
        for (j, k) in corner.into_iter().flatten() {
            assert_eq!(
                a.tables[8], forward.tiles[j].tables[k],
                "tile {i}'s SE corner"
            );
        }
    }
    assert!(
        own.len() > n / 2,
        "{} distinct own tables of {n}",
        own.len()
    );
}

/// A tile's levels are checked as they are first needed ([`Terrain::check_through`]): a tile
/// whose level 6 holds a broken fan (checksums resealed, so only the semantic checks can tell)
/// passes its check through level 2 and hands out the bytes of levels 0-2, not level 6's;
/// asked for level 6 it fails, naming the file, the tile and the level, is counted once and
/// hands out nothing more. The controls: the same file checked at every level at once fails
/// the same way, and the undamaged set's tile passes through every level.
#[test]
fn a_tiles_finer_levels_are_checked_when_first_needed() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (set, broken_set) =
        damaged_puget(dir.path(), "broken.vkt", (2, 1), true, |bytes, ts, e| {
            let level = ts
                .tile(2, 1)
                .expect("tile")
                .level(6)
                .expect("level 6")
                .entry;
            // Swap the first fan's second and third ring entries: the ring no longer walks its
            // cell.
            let w = level.index_width as usize;
            let at = e.offset as usize + level.index_offset as usize;
            bytes[at + 2 * w..at + 4 * w].rotate_left(w);
        });

    let terrain = Terrain::open(&broken_set).expect("open");
    let broken = terrain.tile_index(2, 1).expect("tile 2,1");
    assert!(
        terrain.check_through(broken, 2).is_ok(),
        "levels 0-2 are sound"
    );
    let tile = &terrain.tiles[broken];
    assert_eq!(tile.checked_levels(), 3);
    assert_eq!((tile.usable_at(2), tile.usable_at(3)), (Some(true), None));
    assert!(terrain.part(broken, memory::Part::Positions(2)).is_some());
    assert!(
        terrain.part(broken, memory::Part::Positions(6)).is_none()
            && terrain.part(broken, memory::Part::Indices(3)).is_none(),
        "an unchecked level's bytes were handed out"
    );
    let problem = terrain
        .check_through(broken, 6)
        .err()
        .expect("level 6 is broken")
        .to_string();
    assert!(
        problem.contains("broken.vkt") && problem.contains("tile 2,1 level 6: fan 0"),
        "{problem}"
    );
    assert_eq!(tile.usable(), Some(false));
    assert!(terrain.part(broken, memory::Part::Positions(0)).is_none());
    assert!(terrain.check_through(broken, 1).is_err(), "failed for good");
    assert_eq!(terrain.failed_count(), 1);
    assert_eq!(terrain.take_failures(), vec![(broken, problem.clone())]);

    // The controls.
    let at_once = Terrain::open(&broken_set).expect("open");
    assert_eq!(at_once.check(broken).err(), Some(problem.as_str()));
    let sound = Terrain::open(&set).expect("open");
    assert!(sound.check_through(broken, 2).is_ok());
    assert_eq!(sound.tiles[broken].checked_levels(), 3);
    assert!(sound.check_through(broken, sound.levels - 1).is_ok());
    assert_eq!(sound.tiles[broken].checked_levels(), sound.levels);
}

/// A tile's sides are compared with a neighbour not checked yet as the neighbour stores them,
/// and only where they differ again with the neighbour's checksum
/// (`Terrain::check_through`): a neighbour whose side vertex is damaged (its checksum no longer
/// matches) leaves the tile passing, and fails its own check. The control: the same damage
/// with the checksum resealed fails the tile, naming the neighbour's side.
#[test]
fn a_neighbours_damaged_side_is_not_taken_for_the_tiles_own() {
    let dir = tempfile::tempdir().expect("tempdir");
    let set = common::puget(dir.path());
    let mut bytes = std::fs::read(&set).expect("read");
    let ts = tiles::TileSet::open(&set).expect("open");
    let entry = ts.dir_entry(3, 1).expect("entry");
    let level = ts.tile(3, 1).expect("tile").level(0).expect("level 0");
    // The first vertex of its west side at level 0: one bit of its height code.
    let v = level.border[Side::West.index()][0];
    let at = entry.offset as usize + level.entry.positions_offset as usize + 4 * v as usize + 3;
    drop(ts);
    bytes[at] ^= 1;
    for (name, reseal) in [("damaged.vkt", false), ("resealed.vkt", true)] {
        let mut bytes = bytes.clone();
        if reseal {
            tiles::format::reseal(&mut bytes).expect("reseal");
        }
        let path = dir.path().join(name);
        std::fs::write(&path, &bytes).expect("write");
        let terrain = Terrain::open(&path).expect("open");
        let (tile, east) = (terrain.tile_index(2, 1), terrain.tile_index(3, 1));
        let (tile, east) = (tile.expect("tile 2,1"), east.expect("tile 3,1"));
        let verdict = terrain.check_through(tile, 0).map(|_| ());
        if reseal {
            let problem = verdict.expect_err("the control: a side that differs");
            assert!(
                problem.contains("tile 2,1: its East side differs from tile 3,1's"),
                "{problem}"
            );
        } else {
            assert_eq!(verdict, Ok(()), "{name}");
            let problem = terrain.check_through(east, 0).err().expect("damaged");
            assert!(
                problem.contains("tile 3,1") && problem.contains("checksum"),
                "{problem}"
            );
        }
    }
}

/// A tile set that claims shared sides although its tiles were built with independent sides
/// (the flag forged, checksums resealed): the tiles whose sides differ from a neighbour's fail
/// their checks when needed, named with the neighbour; they are never drawn, rather than drawn
/// with seams that would crack. The control is every other test's set: built with shared sides,
/// every tile passes (`puget()` asserts it).
#[test]
fn a_forged_shared_sides_claim_fails_the_tiles_whose_sides_differ() {
    let dir = tempfile::tempdir().expect("tempdir");
    let alone = common::puget_independent(dir.path());
    let mut bytes = std::fs::read(&alone).expect("read");
    let at = std::mem::offset_of!(tiles::format::FileHeader, flags);
    bytes[at..at + 4].copy_from_slice(&tiles::format::FLAG_SHARED_SIDES.to_le_bytes());
    tiles::format::reseal(&mut bytes).expect("reseal");
    let forged = dir.path().join("forged.vkt");
    std::fs::write(&forged, &bytes).expect("write");
    let terrain = Terrain::open(&forged).expect("open");
    assert!(terrain.shared_sides, "the claim is taken at open");
    let all: Vec<usize> = (0..terrain.tiles.len()).collect();
    terrain.check_all(&all);
    let failures = terrain.take_failures();
    assert!(!failures.is_empty(), "the forged claim went unnoticed");
    for (i, problem) in &failures {
        let t = &terrain.tiles[*i];
        assert!(
            problem.contains(&format!("tile {},{}", t.tx, t.ty))
                && problem.contains("side differs"),
            "{problem}"
        );
    }
    // The same file without the claim: every tile passes.
    let genuine = Terrain::open(&alone).expect("open");
    genuine.check_all(&all);
    assert_eq!(genuine.failed_count(), 0, "{:?}", genuine.take_failures());
}

/// A GENERATED set four times the Puget sample's side: a 2049² mirror tiling of SRTM N55W003
/// (64 tiles, `common::mirror`, the grid bench/mirror.py makes for the 4K and 16K benchmark
/// sets). Opening checks no tile; checking the first view checks exactly the tiles in view,
/// each through the level the view draws it at, and those are fewer than the set's (the
/// control: were every tile checked, or none, the sets would differ); then every tile passes
/// its full check, sides against neighbours included.
#[test]
fn a_mirror_set_is_checked_where_it_is_seen_and_passes_everywhere() {
    let dir = tempfile::tempdir().expect("tempdir");
    let set = common::mirror(dir.path(), 2049);
    let terrain = Terrain::open(&set).unwrap_or_else(|e| panic!("{}: {e}", set.display()));
    assert_eq!(terrain.tiles.len(), 64);
    assert!(terrain.shared_sides);
    let checked = |terrain: &Terrain| -> Vec<usize> {
        (0..terrain.tiles.len())
            .filter(|&i| terrain.tiles[i].usable().is_some())
            .collect()
    };
    assert!(checked(&terrain).is_empty(), "nothing checked at open");
    let path = CameraPath::flyover(&terrain);
    let camera = path.at(path.keys[0].time);
    let rule = renderer::plan::LevelRule::Tau(1.0, renderer::lod::Bound::Guaranteed);
    renderer::plan::check_view(
        &terrain,
        &camera,
        EXTENT,
        (rule, renderer::plan::CheckPolicy::OnFrame),
    );
    let view = camera.view(EXTENT.0, EXTENT.1);
    let mut visible = visible_tiles(&terrain, &view, camera.position);
    visible.sort_unstable();
    assert!(
        !visible.is_empty() && visible.len() < terrain.tiles.len(),
        "the view sees {} of {} tiles",
        visible.len(),
        terrain.tiles.len()
    );
    assert_eq!(checked(&terrain), visible, "checked: the tiles in view");
    // Each through the level the view draws it at and no further: its finer levels wait for a
    // frame that needs them (the control: the view draws some tile coarser than its finest).
    let requests = renderer::plan::requests_for(&terrain, &view, camera.position, rule);
    for r in &requests {
        let t = &terrain.tiles[r.tile as usize];
        assert_eq!(t.checked_levels(), r.wanted + 1, "tile {},{}", t.tx, t.ty);
    }
    assert!(requests.iter().any(|r| r.wanted + 1 < terrain.levels));
    let all: Vec<usize> = (0..terrain.tiles.len()).collect();
    terrain.check_all(&all);
    assert_eq!(terrain.failed_count(), 0, "{:?}", terrain.take_failures());
    assert!(terrain.tiles.iter().all(|t| t.usable() == Some(true)));
}

/// The morph places every vertex from its two parents (`renderer::morph::parents`): each is
/// the midpoint of its parents, which lie on a coarser scale; and in real tile sets (the Puget
/// sample and SRTM3 N55W003, whose last row and column of tiles are partial) every vertex of
/// block 1 or later has both parents in its block or an earlier one, at every level. The
/// control: a tile's vertices less one parent are caught.
#[test]
fn every_vertex_has_its_parents_in_its_block_or_before() {
    use renderer::morph::{block_points, orphan, parents, scale_of};
    for y in 0..=256u32 {
        for x in 0..=256u32 {
            let corner = (x == 0 || x == 256) && (y == 0 || y == 256);
            match parents(x, y) {
                None => assert!(corner, "({x}, {y}) has no parents"),
                Some([a, b]) => {
                    assert!(!corner, "corner ({x}, {y}) has parents");
                    assert_eq!((a.0 + b.0, a.1 + b.1), (2 * x, 2 * y), "({x}, {y})");
                    for p in [a, b] {
                        assert!(p.0 <= 256 && p.1 <= 256, "({x}, {y}): {p:?}");
                        assert!(scale_of(p.0, p.1) > scale_of(x, y), "({x}, {y}): {p:?}");
                    }
                }
            }
        }
    }
    let (a, b) = (
        tempfile::tempdir().expect("tempdir"),
        tempfile::tempdir().expect("tempdir"),
    );
    let srtm = common::tileset(
        b.path(),
        &common::data("srtm/N55W003.hgt"),
        dem::ReadOptions::default(),
    );
    let mut checked = 0;
    let mut control = None;
    for set in [common::puget(a.path()), srtm] {
        let terrain = Terrain::open(&set).expect("open");
        for info in terrain.tiles.iter() {
            let tile = terrain.set.tile(info.tx, info.ty).expect("tile");
            for level in 0..terrain.levels {
                let points = block_points(&tile, level);
                assert_eq!(
                    orphan(&points),
                    None,
                    "tile {},{} level {level}",
                    info.tx,
                    info.ty
                );
                checked += points.len();
            }
            let points = block_points(&tile, terrain.levels - 1);
            if control.is_none() {
                control = points.iter().find(|p| p.2 > 0).map(|&(x, y, _)| {
                    let [p, _] = parents(x, y).expect("parents");
                    let less: Vec<_> = points
                        .iter()
                        .copied()
                        .filter(|&(px, py, _)| (px, py) != p)
                        .collect();
                    orphan(&less)
                });
            }
        }
    }
    assert!(checked > 100_000, "{checked} vertices checked");
    assert!(
        matches!(control, Some(Some(_))),
        "the missing parent was not caught"
    );
}

/// Within a block, a vertex is placed at least at its parents' weight (`renderer::morph`,
/// "Within a block"): a parent's share of its detail then never reaches points beside its
/// child without the child's share of the correction. The case that showed it: the 4K Puget
/// flyover in 120 frames at 1024 x 768 and tau 1, frame 18, where a vertex raised by its star
/// to level 0.75 bent the surface through its child, still at its parents' mean, 1.008 px from
/// the source. Here every visible tile of frames 14-22 of that flight is drawn whole at its
/// morphing level and measured against the source by the error meter (the CPU mirror, which
/// `the_gpus_morphed_heights_equal_the_cpu_mirror` holds to the GPU): within tau on every
/// frame. The control: the same draws with each vertex at its own level alone
/// (`MorphRule::OwnLevels`, the rule before) exceed tau on some frame.
#[test]
fn a_vertex_takes_its_parents_weight_within_its_block() {
    use renderer::lod::{self, Bound};
    use renderer::measure::{ErrorMeter, State};
    use renderer::morph::{MorphRule, TileMorph};
    const SIZE: (u32, u32) = (1024, 768);
    let dir = tempfile::tempdir().expect("tempdir");
    let (input, options) = common::puget_4k();
    let set = common::tileset(dir.path(), &input, options.clone());
    let terrain = common::open_checked(&set);
    let dem = dem::read(&[input], &options).expect("read");
    let path = CameraPath::flyover(&terrain);
    let tau = 1.0;
    let mut worst = [0.0f64; 2];
    for (k, rule) in [MorphRule::Hierarchical, MorphRule::OwnLevels]
        .into_iter()
        .enumerate()
    {
        let mut meter = ErrorMeter::new(&terrain, &common::grid_view(&dem)).expect("meter");
        for frame in 14..=22 {
            let t = path.duration() * f64::from(frame) / 120.0;
            let camera = path.at(path.keys[0].time + t);
            let view = camera.view(SIZE.0, SIZE.1);
            let draws: Vec<(usize, State)> = visible_tiles(&terrain, &view, camera.position)
                .into_iter()
                .map(|i| {
                    let tile = &terrain.tiles[i];
                    let level =
                        lod::morph_level(&view, camera.position, tile, tau, Bound::Guaranteed);
                    let mut morph = TileMorph::from_camera(&terrain, &camera, SIZE, tau, i);
                    (morph.cap, morph.rule) = (level as f32, rule);
                    let state = State {
                        level,
                        morph: Some(morph),
                        parts: None,
                    };
                    (i, state)
                })
                .collect();
            let e = meter.frame(&terrain, &camera, SIZE, &draws).max_error_px;
            eprintln!("{rule:?} frame {frame}: {e:.4} px");
            worst[k] = worst[k].max(e);
        }
    }
    assert!(worst[0] <= tau, "a frame {} px from the source", worst[0]);
    assert!(
        worst[1] > tau,
        "the control: each vertex at its own level stayed within tau ({} px)",
        worst[1]
    );
}
