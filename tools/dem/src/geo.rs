//! Ground distances for grids laid out in degrees or in web-mercator tiles, so every reader
//! can hand back spacings in metres. The series for a degree on the WGS84 ellipsoid are the
//! usual ones (e.g. the USGS/NGA "length of a degree" tables); they are accurate to about a
//! metre per degree, far below what a terrain mesh can notice.

use crate::placement::{Crs, Placement};

/// Metres per degree of latitude at latitude `lat_deg`.
pub fn metres_per_degree_lat(lat_deg: f64) -> f64 {
    let phi = lat_deg.to_radians();
    111_132.92 - 559.82 * (2.0 * phi).cos() + 1.175 * (4.0 * phi).cos()
}

/// Metres per degree of longitude at latitude `lat_deg`.
pub fn metres_per_degree_lon(lat_deg: f64) -> f64 {
    let phi = lat_deg.to_radians();
    111_412.84 * phi.cos() - 93.5 * (3.0 * phi).cos()
}

/// Equator length of the web-mercator sphere (2 pi 6378137 m).
const EQUATOR_M: f64 = 40_075_016.686;

/// Latitude in degrees of a point `t` of the way down the web-mercator world (0 = top edge at
/// about 85.05 N, 1 = bottom edge).
pub fn mercator_latitude(t: f64) -> f64 {
    (std::f64::consts::PI * (1.0 - 2.0 * t))
        .sinh()
        .atan()
        .to_degrees()
}

/// Ground metres per pixel at `lat_deg` for a zoom-`zoom` tile `tile_px` pixels wide.
/// Mercator is conformal, so this holds for both axes.
pub fn mercator_metres_per_pixel(zoom: u32, tile_px: usize, lat_deg: f64) -> f64 {
    EQUATOR_M * lat_deg.to_radians().cos() / (2f64.powi(zoom as i32) * tile_px as f64)
}

/// The placement of slippy-map tile `zoom/x/y` of `width x height` pixels in web-mercator
/// metres (EPSG:3857): its pixels are areas, so pixel (0, 0)'s centre is half a pixel in from
/// the tile's north-west corner.
pub fn mercator_placement(
    zoom: u32,
    (x, y): (u64, u64),
    (width, height): (usize, usize),
) -> Placement {
    let tile = EQUATOR_M / 2f64.powi(zoom as i32);
    let (dx, dy) = (tile / width as f64, tile / height as f64);
    Placement {
        crs: Crs::Projected { code: Some(3857) },
        x0: -EQUATOR_M / 2.0 + x as f64 * tile + dx / 2.0,
        y0: EQUATOR_M / 2.0 - y as f64 * tile - dy / 2.0,
        dx,
        dy,
    }
}

/// Finds a `z-x-y` slippy-map tile address in a file name (`berkeley_14-2625-6369_terrain_rgb`),
/// returning `(z, x, y)`. Triples that cannot be a tile (x or y beyond 2^z, z > 30: dates and
/// the like) are skipped.
pub fn tile_address(name: &str) -> Option<(u32, u64, u64)> {
    // Split into maximal runs of digits; a tile address is three runs joined by single '-'.
    let bytes = name.as_bytes();
    let mut runs: Vec<(usize, usize)> = Vec::new();
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i].is_ascii_digit() {
            let start = i;
            while i < bytes.len() && bytes[i].is_ascii_digit() {
                i += 1;
            }
            runs.push((start, i));
        } else {
            i += 1;
        }
    }
    for w in runs.windows(3) {
        let joined = |a: (usize, usize), b: (usize, usize)| b.0 == a.1 + 1 && bytes[a.1] == b'-';
        if !(joined(w[0], w[1]) && joined(w[1], w[2])) {
            continue;
        }
        // Runs chained on by another `-digits` belong to a longer chain (1-2-3-4): skip.
        let chained_before =
            w[0].0 >= 2 && bytes[w[0].0 - 1] == b'-' && bytes[w[0].0 - 2].is_ascii_digit();
        let chained_after =
            w[2].1 + 1 < bytes.len() && bytes[w[2].1] == b'-' && bytes[w[2].1 + 1].is_ascii_digit();
        if chained_before || chained_after {
            continue;
        }
        let num = |r: (usize, usize)| name.get(r.0..r.1)?.parse::<u64>().ok();
        let (Some(z), Some(x), Some(y)) = (num(w[0]), num(w[1]), num(w[2])) else {
            continue;
        };
        if z <= 30 && x < (1u64 << z) && y < (1u64 << z) {
            return Some((z as u32, x, y));
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn degree_lengths() {
        // Known values: 1 degree of latitude is 110574 m at the equator, 111694 m at the pole;
        // of longitude 111320 m at the equator.
        assert!((metres_per_degree_lat(0.0) - 110_574.3).abs() < 1.0);
        assert!((metres_per_degree_lat(90.0) - 111_693.9).abs() < 1.0);
        assert!((metres_per_degree_lon(0.0) - 111_319.3).abs() < 1.0);
        assert!(metres_per_degree_lon(90.0).abs() < 1e-6);
        // 3 arc-seconds north-south is about 92.6 m.
        assert!((metres_per_degree_lat(46.5) / 1200.0 - 92.6).abs() < 0.1);
    }

    #[test]
    fn mercator() {
        assert!(mercator_latitude(0.5).abs() < 1e-12);
        assert!((mercator_latitude(0.0) - 85.051_128_78).abs() < 1e-6);
        let m = mercator_metres_per_pixel(0, 256, 0.0);
        assert!((m - 156_543.033_9).abs() < 0.01);
    }

    #[test]
    fn finds_tile_addresses() {
        assert_eq!(
            tile_address("berkeley_14-2625-6369_terrain_rgb"),
            Some((14, 2625, 6369))
        );
        assert_eq!(tile_address("12-655-1582.png"), Some((12, 655, 1582)));
        assert_eq!(tile_address("terrain-14-2625-6369"), Some((14, 2625, 6369)));
        assert_eq!(tile_address("fuji_terrain_rgb"), None);
        // A date is not a tile (2024 > 30), nor is a 4-part chain.
        assert_eq!(tile_address("dem-2024-01-15"), None);
        assert_eq!(tile_address("1-2-3-4"), None);
        // x out of range for z.
        assert_eq!(tile_address("3-9-1"), None);
    }
}
