//! The tile pyramid's cut (`renderer::cut`), CPU only: it covers what the base grid sees, each
//! base tile once; far views take the top tile and near ones the base grid; on a set large
//! enough for the pyramid to matter it draws far fewer tiles for about the same triangles,
//! which the rule without its look ahead does not; and its neighbours are at most a layer
//! apart, which the cut without its balance does not keep.

mod common;

use std::f64::consts::TAU;

use glam::DVec3;
use renderer::camera::Camera;
use renderer::cut::{cut, cut_with, stand_in, Checks, Cut, Node, Rules};
use renderer::path::CameraPath;
use renderer::terrain::Terrain;

const EXTENT: (u32, u32) = (1024, 768);

/// The Puget sample and a GENERATED 2049² mirror tiling of SRTM N55W003 (see
/// `common::mirror`), both with their pyramids, in `dir`.
fn sets(dir: &std::path::Path) -> Vec<Terrain> {
    let puget = dir.join("puget");
    let mirror = dir.join("mirror");
    std::fs::create_dir_all(&puget).unwrap();
    std::fs::create_dir_all(&mirror).unwrap();
    let puget = common::tileset_with(
        &puget,
        &[testdata::sample()],
        common::puget_options(),
        &common::with_pyramid(),
    );
    let mirror = common::mirror_with(&mirror, 2049, &common::with_pyramid());
    [puget, mirror]
        .iter()
        .map(|p| Terrain::open_pyramid(p).unwrap_or_else(|e| panic!("{}: {e}", p.display())))
        .collect()
}

/// The cameras of the orbit and the flyover, and a few random ones above the ground.
fn cameras(terrain: &Terrain, rng: &mut splitmix::Rng) -> Vec<Camera> {
    let mut out = Vec::new();
    for path in [CameraPath::orbit(terrain), CameraPath::flyover(terrain)] {
        for k in 0..24 {
            let t = path.keys[0].time + k as f64 * path.duration() / 24.0;
            out.push(path.at(t));
        }
    }
    let (lo, hi) = terrain.bounds();
    out.extend((0..8).map(|_| Camera {
        position: DVec3::new(
            rng.range(lo.x, hi.x),
            rng.range(lo.y, hi.y),
            hi.z + rng.range(50.0, 5000.0),
        ),
        yaw: rng.range(0.0, TAU),
        pitch: rng.range(-0.9, -0.02),
        fov_y: 1.0,
    }));
    out
}

/// A camera `up` times the set's width above the middle of it, looking straight down.
fn straight_down(terrain: &Terrain, up: f64, fov_y: f64) -> Camera {
    let (lo, hi) = terrain.bounds();
    let centre = (lo + hi) * 0.5;
    Camera {
        position: DVec3::new(centre.x, centre.y, hi.z + up * (hi.x - lo.x)),
        yaw: 0.0,
        pitch: -std::f64::consts::FRAC_PI_2 + 1e-3,
        fov_y,
    }
}

/// For each base tile (row-major), how many of the cut's tiles cover it.
fn cover(pyramid: &Terrain, c: &Cut) -> Vec<u32> {
    let mut covered = vec![0u32; pyramid.base().len()];
    for n in &c.nodes {
        let (xs, ys) = pyramid.base_tiles_under(n.tile);
        for y in ys {
            for x in xs.clone() {
                covered[(y * pyramid.tiles_x + x) as usize] += 1;
            }
        }
    }
    covered
}

#[test]
fn the_cut_covers_what_the_base_grid_sees_each_tile_once() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut rng = splitmix::Rng(0x6375_745f_636f_7665);
    let (mut views, mut layer_tiles) = (0, 0);
    for pyramid in sets(dir.path()) {
        assert!(pyramid.top() >= 2, "{} layers", pyramid.top());
        let path = pyramid.set.path().to_path_buf();
        let base = Terrain::open(&path).unwrap();
        for camera in cameras(&pyramid, &mut rng) {
            let view = camera.view(EXTENT.0, EXTENT.1);
            for tau in [1.0, 4.0] {
                let seen = cut(&base, &view, camera.position, tau);
                let chosen = cut(&pyramid, &view, camera.position, tau);
                let covered = cover(&pyramid, &chosen);
                // No base tile twice: the cut's tiles do not overlap.
                assert!(covered.iter().all(|&c| c <= 1), "{covered:?}");
                // Every base tile the base grid alone would draw is under one of the cut's.
                for n in &seen.nodes {
                    assert_eq!(covered[n.tile], 1, "base tile {} uncovered", n.tile);
                }
                layer_tiles += chosen.nodes.iter().filter(|n| n.layer > 0).count();
                views += 1;
            }
        }
    }
    // The test saw layer tiles chosen, not only base tiles.
    assert!(
        layer_tiles > 100,
        "{layer_tiles} layer tiles in {views} cuts"
    );
}

/// A cut reads the outlines of the tiles it reaches and of their neighbours, not the set's:
/// over the GENERATED 2049² mirror set (85 tiles with its pyramid), a view of all of it from
/// far above reads the top layers alone (5 outlines when written), and a view down onto one
/// corner the tiles from the top down to it with their neighbours (23). The control: the base
/// grid without its pyramid finds the tiles in view by testing every base tile, and reads all
/// 64.
#[test]
fn a_cut_reads_the_tiles_it_reaches_not_the_set() {
    let dir = tempfile::tempdir().expect("temp dir");
    let set = common::mirror_with(dir.path(), 2049, &common::with_pyramid());
    let open = || Terrain::open_pyramid(&set).expect("open");
    let pyramid = open();
    assert_eq!(pyramid.tiles.outlines_read(), 0, "the open reads no tile");
    let (lo, hi) = pyramid.bounds();
    let extent = hi.x - lo.x;
    let far = straight_down(&pyramid, 3.0, 0.8);
    let near = Camera {
        position: DVec3::new(lo.x + 0.05 * extent, lo.y + 0.05 * extent, hi.z + 500.0),
        yaw: std::f64::consts::FRAC_PI_4,
        pitch: -1.2,
        fov_y: 1.0,
    };
    for (name, camera, most) in [("far", far, 10), ("near", near, 30)] {
        let pyramid = open();
        let view = camera.view(EXTENT.0, EXTENT.1);
        let c = cut(&pyramid, &view, camera.position, 1.0);
        let read = pyramid.tiles.outlines_read();
        assert!(
            read >= c.nodes.len() && read <= most,
            "{name}: {read} outlines read of {} for a cut of {}",
            pyramid.tiles.len(),
            c.nodes.len()
        );
        let base = Terrain::open(&set).expect("open");
        let _ = renderer::plan::visible_tiles(&base, &view, camera.position);
        assert_eq!(base.tiles.outlines_read(), 64, "{name}: the control");
    }
}

#[test]
fn far_views_take_the_top_tile_and_near_views_the_base_grid() {
    let dir = tempfile::tempdir().expect("temp dir");
    let set = common::mirror_with(dir.path(), 2049, &common::with_pyramid());
    let pyramid = Terrain::open_pyramid(&set).expect("open");
    let (lo, hi) = pyramid.bounds();
    let centre = (lo + hi) * 0.5;
    // High above the middle, looking straight down at all of it: one tile, the top one.
    let far = straight_down(&pyramid, 40.0, 0.5);
    let c = cut(&pyramid, &far.view(EXTENT.0, EXTENT.1), far.position, 1.0);
    assert_eq!(c.nodes.len(), 1, "{:?}", c.nodes);
    assert_eq!(c.nodes[0].layer, pyramid.top());
    // Just above the ground, looking along it: the base grid under the camera.
    let near = Camera {
        position: DVec3::new(centre.x, centre.y, hi.z + 10.0),
        yaw: 0.3,
        pitch: -0.3,
        fov_y: 1.0,
    };
    let c = cut(&pyramid, &near.view(EXTENT.0, EXTENT.1), near.position, 1.0);
    assert!(c.nodes.iter().any(|n| n.layer == 0), "{:?}", c.nodes);
}

#[test]
fn the_pyramid_draws_fewer_tiles_for_about_the_same_triangles() {
    // The orbit that sees all of a set of 64 base tiles (GENERATED mirror): the base grid
    // alone draws every visible tile at least at its coarsest level. The look ahead keeps a
    // layer tile only where it costs less than its children; the rule without it keeps every
    // layer tile that meets tau and draws several times the triangles (the control).
    let dir = tempfile::tempdir().expect("temp dir");
    let set = common::mirror_with(dir.path(), 2049, &common::with_pyramid());
    let pyramid = Terrain::open_pyramid(&set).expect("open");
    let base = Terrain::open(&set).expect("open");
    let path = CameraPath::orbit(&pyramid);
    let (mut draws, mut triangles) = ([0usize; 3], [0u64; 3]);
    for k in 0..24 {
        let camera = path.at(path.keys[0].time + k as f64 * path.duration() / 24.0);
        let view = camera.view(EXTENT.0, EXTENT.1);
        let cuts = [
            cut(&base, &view, camera.position, 1.0),
            cut(&pyramid, &view, camera.position, 1.0),
            cut_with(
                &pyramid,
                &view,
                camera.position,
                1.0,
                Rules {
                    weigh_children: false,
                    ..Rules::ALL
                },
            ),
        ];
        for (k, c) in cuts.iter().enumerate() {
            let p = if k == 0 { &base } else { &pyramid };
            draws[k] += c.nodes.len();
            triangles[k] += c.triangles(p);
        }
    }
    let ratio = |k: usize| triangles[k] as f64 / triangles[0] as f64;
    assert!(
        2 * draws[1] <= draws[0],
        "draws: base grid {}, pyramid {}",
        draws[0],
        draws[1]
    );
    assert!(
        ratio(1) <= 1.5,
        "triangles {:.2}x the base grid's",
        ratio(1)
    );
    assert!(
        ratio(2) > 1.5,
        "without the look ahead: triangles {:.2}x the base grid's",
        ratio(2)
    );
}

/// Where two tiles of the cut meet, they are at most one layer apart, so that a tile's side
/// meets either one tile of its own layer or two of the layer below (what stitching across
/// layers will have to close). Over the flights and random cameras of the first test; the
/// control is the same cuts unbalanced, which put neighbours two layers apart.
#[test]
fn neighbouring_tiles_of_the_cut_are_at_most_a_layer_apart() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut rng = splitmix::Rng(0x6e65_6967_6862_6f75);
    let (mut pairs, mut worst, mut unbalanced) = (0usize, 0u32, 0u32);
    let unbalanced_rules = Rules {
        balance: false,
        ..Rules::ALL
    };
    for pyramid in sets(dir.path()) {
        for camera in cameras(&pyramid, &mut rng) {
            let view = camera.view(EXTENT.0, EXTENT.1);
            for tau in [1.0, 4.0] {
                let balanced = cut(&pyramid, &view, camera.position, tau);
                let (n, w) = layers_apart(&pyramid, &balanced);
                (pairs, worst) = (pairs + n, worst.max(w));
                let loose = cut_with(&pyramid, &view, camera.position, tau, unbalanced_rules);
                unbalanced = unbalanced.max(layers_apart(&pyramid, &loose).1);
            }
        }
    }
    assert!(pairs > 1000, "{pairs} neighbouring pairs");
    assert!(worst <= 1, "neighbours {worst} layers apart");
    assert!(
        unbalanced >= 2,
        "unbalanced, neighbours at most {unbalanced} apart"
    );
}

/// Tiles that passed their checks, for [`stand_in`]: the rest are not checked yet; one
/// checked on the frame passes.
struct Passed {
    passed: Vec<bool>,
    later: usize,
    now: usize,
}

impl Checks for Passed {
    fn state(&self, i: usize) -> Option<bool> {
        self.passed[i].then_some(true)
    }

    fn later(&mut self, _: usize) {
        self.later += 1;
    }

    fn now(&mut self, i: usize) -> bool {
        self.now += 1;
        self.passed[i] = true;
        true
    }
}

/// Where tiles of the cut are not checked yet, ancestors that passed stand in for them
/// (`renderer::cut::stand_in`): over the cameras of the first test, with none, half or most
/// tiles passed at random, the tiles drawn all passed, cover every base tile the cut covers
/// exactly once, are at most a layer apart, and are the cut itself once every tile passed; a
/// frame checks no more than the top layer's tiles itself. The control is the same stand-ins
/// unbalanced, which put neighbours two layers apart.
#[test]
fn ancestors_stand_in_for_tiles_not_checked_on_the_same_ground_a_layer_apart() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mut rng = splitmix::Rng(0x7374_616e_645f_696e);
    let (mut stood_in, mut unbalanced) = (0usize, 0u32);
    for pyramid in sets(dir.path()) {
        let tops = pyramid.layers[pyramid.top() as usize].len();
        for camera in cameras(&pyramid, &mut rng) {
            let view = camera.view(EXTENT.0, EXTENT.1);
            let wanted = cut(&pyramid, &view, camera.position, 1.0);
            for share in [0.0, 0.5, 0.9, 1.0] {
                let passed: Vec<bool> = (0..pyramid.tiles.len())
                    .map(|_| rng.range(0.0, 1.0) < share)
                    .collect();
                let mut checks = Passed {
                    passed: passed.clone(),
                    later: 0,
                    now: 0,
                };
                let drawn = stand_in(&pyramid, &wanted.nodes, &mut checks, true);
                assert!(checks.now <= tops, "{} checked on the frame", checks.now);
                let as_cut = drawn_as_cut(&pyramid, &drawn.tiles);
                let (want, got) = (cover(&pyramid, &wanted), cover(&pyramid, &as_cut));
                assert!(want
                    .iter()
                    .zip(&got)
                    .all(|(&w, &g)| g <= 1 && (w == 0 || g == 1)));
                assert!(layers_apart(&pyramid, &as_cut).1 <= 1);
                assert!(drawn.tiles.iter().all(|&t| checks.passed[t]));
                if share == 1.0 {
                    assert_eq!((drawn.stood_in, checks.later), (0, 0));
                    assert_eq!(drawn.tiles.len(), wanted.nodes.len());
                }
                stood_in += drawn.stood_in;
                let mut loose = Passed {
                    passed,
                    later: 0,
                    now: 0,
                };
                let drawn = stand_in(&pyramid, &wanted.nodes, &mut loose, false);
                let as_cut = drawn_as_cut(&pyramid, &drawn.tiles);
                unbalanced = unbalanced.max(layers_apart(&pyramid, &as_cut).1);
            }
        }
    }
    assert!(stood_in > 1000, "{stood_in} tiles stood in for");
    assert!(
        unbalanced >= 2,
        "unbalanced, neighbours at most {unbalanced} apart"
    );
}

/// Stand-ins' tiles as a cut (levels 0), to measure as one.
fn drawn_as_cut(pyramid: &Terrain, tiles: &[usize]) -> Cut {
    Cut {
        nodes: tiles
            .iter()
            .map(|&tile| Node {
                layer: pyramid.tiles[tile].layer,
                tile,
                level: 0,
            })
            .collect(),
        visited: 0,
    }
}

/// Neighbouring base tiles both under the cut, and the most layers apart their cut tiles are.
fn layers_apart(pyramid: &Terrain, c: &Cut) -> (usize, u32) {
    let base = pyramid;
    // The layer of the cut's tile over each base tile (None: not covered).
    let mut layer = vec![None; base.base().len()];
    for n in &c.nodes {
        let (xs, ys) = pyramid.base_tiles_under(n.tile);
        for y in ys {
            for x in xs.clone() {
                layer[(y * base.tiles_x + x) as usize] = Some(n.layer);
            }
        }
    }
    let (mut pairs, mut worst) = (0, 0);
    for y in 0..base.tiles_y {
        for x in 0..base.tiles_x {
            let here = layer[(y * base.tiles_x + x) as usize];
            for (nx, ny) in [(x + 1, y), (x, y + 1)] {
                if nx >= base.tiles_x || ny >= base.tiles_y {
                    continue;
                }
                if let (Some(a), Some(b)) = (here, layer[(ny * base.tiles_x + nx) as usize]) {
                    pairs += 1;
                    worst = worst.max(a.abs_diff(b));
                }
            }
        }
    }
    (pairs, worst)
}

/// The error meter measures pops on the ground (`renderer::measure`): where a layer tile's
/// children replace it, or it replaces them, the jump between the two surfaces counts. On the
/// Puget sample with its pyramid, one camera of the orbit: the top tile at its coarsest level,
/// then every base tile at its finest, then the top tile again, each jump a pop of pixels;
/// the control is the base tiles drawn twice, no pop.
#[test]
fn the_meter_sees_the_pop_where_children_replace_their_parent() {
    use renderer::measure::{ErrorMeter, State};
    let dir = tempfile::tempdir().expect("temp dir");
    let inputs = [testdata::sample()];
    let set = common::tileset_with(
        dir.path(),
        &inputs,
        common::puget_options(),
        &common::with_pyramid(),
    );
    let terrain = Terrain::open_pyramid(&set).expect("open");
    let dem = dem::read(&inputs, &common::puget_options()).expect("read");
    let mut meter = ErrorMeter::new(&terrain, &common::grid_view(&dem)).expect("meter");
    let path = CameraPath::orbit(&terrain);
    let camera = path.at(path.keys[0].time);
    let at = |level| State {
        level,
        morph: None,
        parts: None,
    };
    let top = [(terrain.index_in(terrain.top(), 0), at(0))];
    let base: Vec<_> = (0..terrain.base().len())
        .map(|i| (i, at(terrain.levels - 1)))
        .collect();
    let mut fly = |draws: &[(usize, State)]| meter.frame(&terrain, &camera, EXTENT, draws);
    assert!(fly(&top).pop_px.is_nan(), "no previous frame");
    let down = fly(&base);
    let again = fly(&base);
    let up = fly(&top);
    assert!(down.pop_px > 1.0 && up.pop_px > 1.0, "{down:?} {up:?}");
    assert_eq!(again.pop_px, 0.0, "{again:?}");
}

/// A layer tile's levels past its floor add no vertex: they draw the same surface as its last
/// level that adds one, and its level table ends there. A table over all its levels (the
/// control) falls by the least ratio across those copies, makes the tile's real levels look
/// up to several times worse than measured and so draws it finer than it needs: on the 16K mirror
/// set's orbit, geomorphing drew 2.7 times the discrete cut's triangles that way.
#[test]
fn a_layer_tiles_table_ends_at_its_last_level_that_adds_vertices() {
    let dir = tempfile::tempdir().expect("temp dir");
    let set = common::mirror_with(dir.path(), 2049, &common::with_pyramid());
    let pyramid = Terrain::open_pyramid(&set).expect("open");
    let mut with_copies = 0;
    for tile in pyramid.tiles.iter().filter(|t| t.layer > 0) {
        let levels = &tile.levels;
        let copies = levels.iter().rev().take_while(|l| l.block_len == 0).count();
        let table = &tile.tables[0];
        assert_eq!(
            table.levels,
            levels.len() - copies,
            "{},{}",
            tile.tx,
            tile.ty
        );
        let errors: Vec<f32> = levels.iter().map(|l| l.max_error).collect();
        for (k, e) in errors.iter().enumerate().take(table.levels) {
            assert!(table.errors[k] >= *e, "level {k}: {table:?}");
        }
        if copies >= 2 {
            with_copies += 1;
            // The last level that adds vertices keeps its own error; over every level it
            // takes MIN_RATIO^copies times the copies' (about its own).
            let k = table.levels - 1;
            let control = renderer::levels::LevelTable::new(&errors);
            assert!(
                table.errors[k] <= errors[k] * 1.0001 && 1.4 * table.errors[k] < control.errors[k],
                "{},{} layer {}, level {k}: {} against {} over every level",
                tile.tx,
                tile.ty,
                tile.layer,
                table.errors[k],
                control.errors[k]
            );
        }
    }
    assert!(with_copies > 0, "no layer tile with levels past its floor");
}

/// The ground under a wide query comes from a pyramid layer (`Terrain::max_height_near`, which
/// places the flyover's keys), chosen by the file whether or not the terrain opened its
/// layers: on the GENERATED 2049² mirror set, at radii of 20 and 45 km (layers 1 and 2), the
/// terrain opened with and without them answers the same, bit for bit; no answer lies below
/// the highest source sample in the square, nor above the highest within two of the layer's
/// map cells of it by more than the layer's largest decimation error. The control: the same
/// grid built without a pyramid answers from its base tiles, differently at some points.
#[test]
fn a_wide_query_finds_the_ground_from_a_layer_the_same_either_way() {
    let dir = tempfile::tempdir().expect("tempdir");
    let size = 2049;
    let (with, without) = (dir.path().join("with"), dir.path().join("without"));
    std::fs::create_dir_all(&with).expect("mkdir");
    std::fs::create_dir_all(&without).expect("mkdir");
    let with = common::mirror_with(&with, size, &common::with_pyramid());
    let without = common::mirror(&without, size);
    let heights = common::mirror_heights(size);
    let highest = |x: f64, y: f64, r: f64| -> f64 {
        let span = |lo: f64, hi: f64| {
            (lo / 90.0).ceil().max(0.0) as usize..=((hi / 90.0).floor() as usize).min(size - 1)
        };
        let mut best = f32::MIN;
        for row in span(-y - r, -y + r) {
            for col in span(x - r, x + r) {
                best = best.max(heights[row * size + col]);
            }
        }
        f64::from(best)
    };
    let file = tiles::TileSet::open(&with).expect("open");
    let base = Terrain::open(&with).expect("open");
    let pyramid = Terrain::open_pyramid(&with).expect("open");
    let plain = Terrain::open(&without).expect("open");
    let extent = 90.0 * (size - 1) as f64;
    let mut differ = 0;
    for (p, r) in [(1u32, 20_000.0), (2, 45_000.0)] {
        let layer = file.layer(p).expect("layer");
        let h = *layer.header();
        let raise = (0..h.tiles_y)
            .flat_map(|ty| (0..h.tiles_x).map(move |tx| (tx, ty)))
            .filter_map(|(tx, ty)| layer.decimation_error(tx, ty))
            .fold(0.0f32, f32::max);
        let cell = 257.0 / 8.0 * f64::from(1u32 << p) * 90.0;
        for k in 0..64 {
            let (u, v) = (f64::from(k % 8) / 7.0, f64::from(k / 8) / 7.0);
            let (x, y) = (extent * (0.05 + 0.9 * u), -extent * (0.05 + 0.9 * v));
            let a = base.max_height_near(x, y, r);
            let at = format!("{x:.0}, {y:.0}, radius {r}");
            assert_eq!(
                a.to_bits(),
                pyramid.max_height_near(x, y, r).to_bits(),
                "{at}"
            );
            let (floor, ceiling) = (highest(x, y, r), highest(x, y, r + 2.0 * cell));
            assert!(a >= floor, "{at}: {a} m, below a sample at {floor} m");
            assert!(
                a <= ceiling + f64::from(raise),
                "{at}: {a} m, above {ceiling} m + {raise} m"
            );
            differ += usize::from(a != plain.max_height_near(x, y, r));
        }
    }
    assert!(differ > 0, "the control: no answer came from a layer");
}
