//! The frame plan without a GPU: culling is conservative, and under a budget far smaller than
//! the view needs the manager grants only what is resident, every visible tile is drawn, and
//! the seams are stitched at the levels granted (not the levels wanted).

mod common;

use glam::DVec3;
use memory::{Config, Manager};
use renderer::camera::Camera;
use renderer::path::CameraPath;
use renderer::plan::{plan, stitch_granted, visible_tiles, Draw, LevelRule};
use renderer::terrain::Terrain;

const EXTENT: (u32, u32) = (640, 480);

fn puget() -> (tempfile::TempDir, Terrain) {
    let dir = tempfile::tempdir().expect("tempdir");
    let set = common::puget(dir.path());
    let terrain = Terrain::open(&set).unwrap_or_else(|e| panic!("{}: {e}", set.display()));
    (dir, terrain)
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

/// The flyover with a 2 MB pool and 64 KiB of uploads a frame: the plan draws every visible
/// tile at a level it holds, never above the level wanted, uploads within the budget (plus
/// the coarsest levels, which may overshoot), and stitches at the granted levels. Stitching at
/// the wanted levels instead (the old order) gives different seams: the negative control.
#[test]
fn tight_budget_draws_what_is_resident_and_stitches_granted_levels() {
    let (_dir, terrain) = puget();
    let config = Config {
        pool_bytes: 2 << 20,
        upload_budget: 64 << 10,
        ..Config::default()
    };
    let mut manager = Manager::new(terrain.costs(), config);
    let path = CameraPath::flyover(&terrain);
    let (mut coarser_frames, mut seams_differ) = (0, 0);
    for f in 0..60u64 {
        let camera = path.at(path.keys[0].time + path.duration() * f as f64 / 60.0);
        let p = plan(
            &terrain,
            &mut manager,
            &camera,
            EXTENT,
            LevelRule::Tau(1.0, renderer::lod::Bound::Guaranteed),
            f,
            f.checked_sub(2),
            true,
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
            assert!(d.level <= d.wanted, "frame {f}: {d:?}");
            let (_, index) = manager
                .resident_levels(d.tile as u32)
                .unwrap_or_else(|| panic!("frame {f}: tile {} drawn, not resident", d.tile));
            assert_eq!(index, Some(d.level), "frame {f}: tile {}", d.tile);
            coarser += u64::from(d.level < d.wanted);
        }
        assert_eq!(coarser, p.stats.tiles_coarser, "frame {f}");
        let granted = stitch_granted(&terrain, &p.draws).expect("stitch");
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
            if stitch_granted(&terrain, &wanted).expect("stitch") != p.stitches {
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
