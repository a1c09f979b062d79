//! Reads every file of the shared real data set (/work/shared/data, see its README) and checks
//! sizes, value ranges, void counts and spacings against what the README and the file headers
//! say.

mod common;

use common::{assert_close, data, read, read_err, read_mosaic};
use dem::{metres_per_degree_lat, metres_per_degree_lon, Crop, Encoding, ReadOptions};

fn read_one(rel: &str) -> dem::HeightGrid {
    read(&data(rel), &ReadOptions::default())
}

/// The raw big-endian samples of an .hgt file.
fn hgt_samples(rel: &str) -> Vec<i16> {
    let bytes = std::fs::read(data(rel)).expect("read hgt");
    bytes
        .chunks_exact(2)
        .map(|b| i16::from_be_bytes([b[0], b[1]]))
        .collect()
}

/// Spacing of a 3" grid at latitude `lat`, by the formula the crate documents.
fn srtm3_spacing(lat: f64) -> (f64, f64) {
    (
        metres_per_degree_lon(lat) / 1200.0,
        metres_per_degree_lat(lat) / 1200.0,
    )
}

fn check(grid: &dem::HeightGrid, size: (usize, usize), range: (f32, f32), voids: u64) {
    assert_eq!((grid.width, grid.height), size, "{}", grid.description);
    assert_eq!(grid.heights.len(), size.0 * size.1);
    assert_eq!(grid.min_max(), range, "{}", grid.description);
    assert_eq!(grid.voids_filled, voids, "{}", grid.description);
    assert!(grid.heights.iter().all(|h| h.is_finite()));
}

#[test]
fn srtm3_n41e001() {
    let g = read_one("srtm/N41E001.hgt");
    check(&g, (1201, 1201), (-20.0, 1204.0), 134);
    assert_eq!(g.description, "SRTM3 N41E001");
    // Centre latitude 41.5: ~69.6 m east-west, ~92.6 m north-south.
    let (dx, dy) = srtm3_spacing(41.5);
    assert_close(g.spacing_x, dx, 1e-9, "spacing_x");
    assert_close(g.spacing_y, dy, 1e-9, "spacing_y");
    assert_close(g.spacing_x, 69.58, 0.05, "spacing_x");
    assert_close(g.spacing_y, 92.55, 0.05, "spacing_y");
    // Row 0 is the first (northern) row of the file; valid samples are kept exactly.
    let raw = hgt_samples("srtm/N41E001.hgt");
    for (i, (&r, &h)) in raw.iter().zip(&g.heights).enumerate() {
        if r != -32768 {
            assert_eq!(f32::from(r), h, "sample {i}");
        }
    }
}

#[test]
fn srtm3_other_tiles() {
    let g = read_one("srtm/N42E001.hgt");
    check(&g, (1201, 1201), (349.0, 3100.0), 7652);
    let g = read_one("srtm/N43E007.hgt");
    check(&g, (1201, 1201), (-11.0, 2064.0), 1595);
    let g = read_one("srtm/N55W003.hgt");
    check(&g, (1201, 1201), (-22.0, 816.0), 0);
    let (dx, _) = srtm3_spacing(55.5);
    assert_close(g.spacing_x, dx, 1e-9, "N55W003 spacing_x");
}

#[test]
fn srtm1_n48w125_half_void() {
    let g = read_one("srtm/N48W125.hgt");
    check(&g, (3601, 3601), (-13.0, 1095.0), 6_483_876);
    assert_eq!(g.description, "SRTM1 N48W125");
    assert_close(
        g.spacing_y,
        metres_per_degree_lat(48.5) / 3600.0,
        1e-9,
        "spacing_y",
    );
    assert_close(g.spacing_y, 30.9, 0.1, "spacing_y");
    assert_close(
        g.spacing_x,
        metres_per_degree_lon(48.5) / 3600.0,
        1e-9,
        "spacing_x",
    );
    // The void northern half (Canada) is filled smoothly: no cliffs between neighbours.
    let mut worst = 0.0f32;
    for y in 0..1000 {
        for x in 1..g.width {
            worst = worst.max((g.get(x, y) - g.get(x - 1, y)).abs());
        }
    }
    assert!(
        worst < 50.0,
        "largest east-west step in the filled north: {worst} m"
    );
}

#[test]
fn srtm3_mosaic_n41_n42() {
    let n41 = data("srtm/N41E001.hgt");
    let n42 = data("srtm/N42E001.hgt");
    let g = read_mosaic(&[n41.clone(), n42.clone()], &ReadOptions::default());
    // The order the files are given in does not matter.
    let g2 = read_mosaic(&[n42, n41], &ReadOptions::default());
    assert_eq!(g.heights, g2.heights);
    assert_eq!((g.width, g.height), (1201, 2401));
    assert_eq!(g.min_max(), (-20.0, 3100.0));
    assert_eq!(g.description, "SRTM3 mosaic N41E001..N42E001 (2 files)");

    // N42 on top; they share N42's last row = N41's first row.
    let top = hgt_samples("srtm/N42E001.hgt");
    let bottom = hgt_samples("srtm/N41E001.hgt");
    let mut voids = 0;
    for y in 0..2401 {
        for x in 0..1201 {
            let from_top = (y <= 1200).then(|| top[y * 1201 + x]);
            let from_bottom = (y >= 1200).then(|| bottom[(y - 1200) * 1201 + x]);
            let valid = [from_top, from_bottom]
                .into_iter()
                .flatten()
                .find(|&v| v != -32768);
            match valid {
                Some(v) => assert_eq!(g.get(x, y), f32::from(v), "{x},{y}"),
                None => voids += 1,
            }
        }
    }
    assert_eq!(g.voids_filled, voids);
    assert!(voids <= 134 + 7652);
    // Centre latitude 42.0.
    let (dx, dy) = srtm3_spacing(42.0);
    assert_close(g.spacing_x, dx, 1e-9, "spacing_x");
    assert_close(g.spacing_y, dy, 1e-9, "spacing_y");
}

#[test]
fn crop_of_a_mosaic() {
    let opts = ReadOptions {
        crop: Some("100,1000,1025x1025".parse::<Crop>().unwrap()),
        ..ReadOptions::default()
    };
    let paths = [data("srtm/N41E001.hgt"), data("srtm/N42E001.hgt")];
    let g = read_mosaic(&paths, &opts);
    assert_eq!((g.width, g.height), (1025, 1025));
    assert!(g.description.ends_with(", crop 100,1000,1025x1025"));
    let top = hgt_samples("srtm/N42E001.hgt");
    let v = top[1000 * 1201 + 100];
    assert_ne!(v, -32768);
    assert_eq!(g.get(0, 0), f32::from(v));
    // The spacing is taken at the window's centre row (1512 of 2401: 42 - 1512/1200 deg).
    let (dx, _) = srtm3_spacing(43.0 - 1512.0 / 1200.0);
    assert_close(g.spacing_x, dx, 1e-9, "spacing_x");
    // A window reaching past the mosaic is refused.
    let opts = ReadOptions {
        crop: Some("200,1400,1025x1025".parse().unwrap()),
        ..ReadOptions::default()
    };
    let e = read_err(&paths, &opts);
    assert!(
        e.contains("crop 200,1400,1025x1025 does not fit inside the 1201x2401 grid"),
        "{e}"
    );
}

#[test]
fn puget_16bit_png() {
    let path = data("puget/ps_height_1k.png");
    let e = read_err(std::slice::from_ref(&path), &ReadOptions::default());
    assert!(
        e.contains("ps_height_1k.png") && e.contains("--spacing"),
        "{e}"
    );
    let opts = ReadOptions {
        spacing: Some(160.0),
        vertical_scale: Some(0.1),
        ..ReadOptions::default()
    };
    let g = read(&path, &opts);
    assert_eq!((g.width, g.height), (1025, 1025));
    assert_eq!(g.min_max(), (0.0, (43798.0f64 * 0.1) as f32));
    assert_eq!((g.spacing_x, g.spacing_y), (160.0, 160.0));
    assert_eq!(g.voids_filled, 0);
    assert_eq!(g.description, "PNG 16-bit grey 1025x1025");
}

#[test]
fn puget_8bit_jpeg() {
    let opts = ReadOptions {
        spacing: Some(40.0),
        vertical_scale: Some(25.7),
        ..ReadOptions::default()
    };
    let g = read(&data("puget/ps_height_4k_8bit.jpg"), &opts);
    assert_eq!((g.width, g.height), (4096, 4096));
    let (lo, hi) = g.min_max();
    // README: 0..171 steps (JPEG noise may move the extremes by a step or two).
    assert!((0.0..=2.0 * 25.7).contains(&lo), "{lo}");
    assert!((hi / 25.7 - 171.0).abs() <= 2.0, "{hi}");
    assert!(
        g.description.starts_with("JPEG 8-bit grey"),
        "{}",
        g.description
    );
}

#[test]
fn fuji_terrain_rgb() {
    let path = data("terrainrgb/fuji_terrain_rgb.png");
    let e = read_err(std::slice::from_ref(&path), &ReadOptions::default());
    assert!(e.contains("--encoding"), "{e}");
    // No tile address in the name: the spacing must be given.
    let opts = ReadOptions {
        encoding: Some(Encoding::TerrainRgb),
        ..ReadOptions::default()
    };
    let e = read_err(std::slice::from_ref(&path), &opts);
    assert!(e.contains("--spacing"), "{e}");
    let opts = ReadOptions {
        spacing: Some(20.0),
        ..opts
    };
    let g = read(&path, &opts);
    assert_eq!((g.width, g.height), (512, 512));
    let (lo, hi) = g.min_max();
    assert_close(f64::from(lo), 13.7, 0.06, "min");
    assert_close(f64::from(hi), 3751.0, 0.6, "max");
    assert_eq!(g.voids_filled, 0);
    assert_eq!(g.description, "terrain-rgb PNG RGBA 512x512");
}

#[test]
fn berkeley_terrain_rgb_spacing_from_tile_name() {
    let opts = ReadOptions {
        encoding: Some(Encoding::TerrainRgb),
        ..ReadOptions::default()
    };
    let g = read(
        &data("terrainrgb/berkeley_14-2625-6369_terrain_rgb.png"),
        &opts,
    );
    assert_eq!((g.width, g.height), (512, 512));
    let (lo, hi) = g.min_max();
    assert!(
        (18.5..=19.5).contains(&lo) && (251.5..=252.5).contains(&hi),
        "{lo}..{hi}"
    );
    assert!(
        g.description.contains("tile z14 y6369"),
        "{}",
        g.description
    );
    // Tile row 6369 of 2^14 has its centre at 37.14 N (web mercator).
    let n = 16384.0f64;
    let lat = (std::f64::consts::PI * (1.0 - 2.0 * (6369.5 / n)))
        .sinh()
        .atan()
        .to_degrees();
    assert_close(lat, 37.14, 0.01, "tile centre latitude");
    let expected = 40_075_016.686 * lat.to_radians().cos() / (n * 512.0);
    assert_close(g.spacing_x, expected, 1e-9, "spacing_x");
    assert_eq!(g.spacing_x, g.spacing_y);
    // Within 1% of the same formula at Berkeley's 37.85 N (~3.77 m).
    let at_berkeley = 40_075_016.686 * 37.85f64.to_radians().cos() / (n * 512.0);
    assert_close(
        g.spacing_x,
        at_berkeley,
        0.01 * at_berkeley,
        "spacing vs 37.85 N",
    );
    // --spacing wins over the name.
    let opts = ReadOptions {
        spacing: Some(5.0),
        ..opts
    };
    let g = read(
        &data("terrainrgb/berkeley_14-2625-6369_terrain_rgb.png"),
        &opts,
    );
    assert_eq!((g.spacing_x, g.spacing_y), (5.0, 5.0));
}

#[test]
fn geotiff_mt_rainier_geographic() {
    let g = read_one("geotiff/mt_rainier_90m.tif");
    check(&g, (1201, 1201), (263.0, 4371.0), 9033);
    assert_eq!(
        g.description,
        "GeoTIFF i16 uncompressed, tiled 256x256, geographic, nodata -32768"
    );
    // 3" cells centred from 47.0 N down to 46.0 N: centre 46.5 N.
    let (dx, dy) = srtm3_spacing(46.5);
    assert_close(g.spacing_x, dx, 1e-6, "spacing_x");
    assert_close(g.spacing_y, dy, 1e-6, "spacing_y");
    assert_close(g.spacing_y, 92.6, 0.1, "spacing_y");
    assert_close(g.spacing_x, 64.0, 0.1, "spacing_x");
}

#[test]
fn geotiff_mt_fuji() {
    let g = read_one("geotiff/mt_fuji_90m.tif");
    check(&g, (1201, 1201), (-16.0, 3742.0), 2437);
    let (dx, dy) = srtm3_spacing(35.5);
    assert_close(g.spacing_x, dx, 1e-6, "spacing_x");
    assert_close(g.spacing_y, dy, 1e-6, "spacing_y");
}

#[test]
fn geotiff_bigtujunga_projected() {
    let g = read_one("geotiff/bigtujunga.tif");
    check(&g, (1197, 643), (315.0, 2295.0), 0);
    assert_eq!((g.spacing_x, g.spacing_y), (30.0, 30.0));
    assert_eq!(
        g.description,
        "GeoTIFF i16 uncompressed, tiled 128x128, projected (metres), nodata 32767"
    );
}

/// Longitude and latitude of the highest sample of a geographic grid, from its placement.
fn highest_point(grid: &dem::HeightGrid) -> (f64, f64) {
    let p = grid.placement.expect("the file says where it lies");
    assert!(matches!(p.crs, dem::Crs::Geographic { .. }), "{:?}", p.crs);
    let k = (0..grid.heights.len())
        .max_by(|&a, &b| grid.heights[a].total_cmp(&grid.heights[b]))
        .unwrap();
    let (col, row) = ((k % grid.width) as f64, (k / grid.width) as f64);
    (p.x0 + col * p.dx, p.y0 - row * p.dy)
}

#[test]
fn placements_put_the_summits_where_they_are() {
    // Published summit positions (USGS / GSI): the highest sample of each DEM must lie within
    // a few samples of them, which a placement off by a tile, a sign or a half-degree is not.
    for (file, name, (lon, lat)) in [
        (
            "geotiff/mt_rainier_90m.tif",
            "Mount Rainier",
            (-121.7603, 46.8529),
        ),
        ("geotiff/mt_fuji_90m.tif", "Mount Fuji", (138.7274, 35.3606)),
    ] {
        let (x, y) = highest_point(&read_one(file));
        assert!(
            (x - lon).abs() < 0.005 && (y - lat).abs() < 0.005,
            "{name}: highest sample at {x:.4}, {y:.4}, the summit is at {lon}, {lat}"
        );
    }
}

#[test]
fn placements_of_srtm_tiles_mosaics_and_crops() {
    let tile = read_one("srtm/N43E007.hgt").placement.unwrap();
    assert_eq!(tile.crs, dem::Crs::Geographic { code: Some(4326) });
    assert_eq!((tile.x0, tile.y0), (7.0, 44.0));
    assert_eq!((tile.dx, tile.dy), (1.0 / 1200.0, 1.0 / 1200.0));
    let crop = Crop {
        x: 600,
        y: 1200,
        width: 601,
        height: 1201,
    };
    let paths = [data("srtm/N41E001.hgt"), data("srtm/N42E001.hgt")];
    let opts = ReadOptions {
        crop: Some(crop),
        ..ReadOptions::default()
    };
    // The crop starts on row 1200 of the mosaic (43 N at the top): 42 N, and half a degree east.
    let p = read_mosaic(&paths, &opts).placement.unwrap();
    assert!(
        (p.x0 - 1.5).abs() < 1e-12 && (p.y0 - 42.0).abs() < 1e-12,
        "{p:?}"
    );
}

#[test]
fn placements_of_projected_and_web_mercator_grids() {
    let utm = read_one("geotiff/bigtujunga.tif");
    let p = utm.placement.unwrap();
    assert_eq!(p.crs, dem::Crs::Projected { code: Some(32611) });
    assert_eq!((p.dx, p.dy), (utm.spacing_x, utm.spacing_y));
    // UTM 11N eastings lie within 166..834 km of the zone's false origin; the San Gabriels
    // are near 34.3 N, about 3.8e6 m north of the equator.
    assert!((166e3..834e3).contains(&p.x0), "{p:?}");
    assert!((3.7e6..3.9e6).contains(&p.y0), "{p:?}");

    // Tile 14/2625/6369 of the web-mercator world: its west edge is at longitude
    // 2625 / 2^14 * 360 - 180 = -122.32 degrees, i.e. -122.32 / 180 * half the equator.
    let opts = ReadOptions {
        encoding: Some(Encoding::TerrainRgb),
        ..ReadOptions::default()
    };
    let tile = read(
        &data("terrainrgb/berkeley_14-2625-6369_terrain_rgb.png"),
        &opts,
    );
    let p = tile.placement.unwrap();
    assert_eq!(p.crs, dem::Crs::Projected { code: Some(3857) });
    let half_equator = std::f64::consts::PI * 6_378_137.0;
    let west = (2625.0 / 16384.0 * 360.0 - 180.0) / 180.0 * half_equator;
    let tile_m = 2.0 * half_equator / 16384.0;
    assert!((p.x0 - p.dx / 2.0 - west).abs() < 0.01, "{p:?} west {west}");
    assert!((p.dx * 512.0 - tile_m).abs() < 1e-6);
    // Unnamed tiles, raw files and grey pictures say nothing.
    let spaced = ReadOptions {
        spacing: Some(30.0),
        ..ReadOptions::default()
    };
    let fuji = read(
        &data("terrainrgb/fuji_terrain_rgb.png"),
        &ReadOptions {
            spacing: Some(30.0),
            ..opts
        },
    );
    assert_eq!(fuji.placement, None);
    let puget = read(&data("puget/ps_height_1k.png"), &spaced);
    assert_eq!(puget.placement, None);
}
