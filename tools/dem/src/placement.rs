//! Where a grid lies, as far as its file says: the coordinates of its first sample's centre
//! and the step per column and per row, in the file's coordinate reference system. Two grids
//! in the same system can be laid over each other, as `tiletool` lays a photo on the heights.

/// The coordinate reference system of a [`Placement`]. Codes are EPSG codes when the file
/// gives one (a GeoTIFF's user-defined 32767 counts as none).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Crs {
    /// Longitude and latitude in degrees, e.g. EPSG:4326 (WGS 84).
    Geographic { code: Option<u16> },
    /// Easting and northing in metres (feet already converted), e.g. EPSG:32610 (UTM 10N).
    Projected { code: Option<u16> },
}

impl Crs {
    fn code(self) -> Option<u16> {
        match self {
            Crs::Geographic { code } | Crs::Projected { code } => code,
        }
    }
}

impl std::fmt::Display for Crs {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match (self, self.code()) {
            (_, Some(code)) => write!(f, "EPSG:{code}"),
            (Crs::Geographic { .. }, None) => write!(f, "geographic (datum not given)"),
            (Crs::Projected { .. }, None) => write!(f, "projected (system not given)"),
        }
    }
}

/// Sample `(column, row)` of one grid lies at `(origin.0 + column * step.0, origin.1 + row *
/// step.1)` in another's sample coordinates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Mapping {
    pub origin: (f64, f64),
    pub step: (f64, f64),
}

/// A grid's position: sample `(column, row)` has its centre at
/// `(x0 + column * dx, y0 - row * dy)`, row 0 being the northern one.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Placement {
    pub crs: Crs,
    /// Easting (or longitude) and northing (or latitude) of sample (0, 0)'s centre.
    pub x0: f64,
    pub y0: f64,
    /// Units per column eastward and per row southward, both positive.
    pub dx: f64,
    pub dy: f64,
}

impl Placement {
    /// The placement of the window whose first sample is `(x, y)` of this grid.
    pub fn window(&self, x: usize, y: usize) -> Placement {
        Placement {
            x0: self.x0 + x as f64 * self.dx,
            y0: self.y0 - y as f64 * self.dy,
            ..*self
        }
    }

    /// Where sample coordinates of this grid lie in `other`'s sample coordinates. `Err` says
    /// why the two cannot be compared (different systems).
    pub fn in_grid_of(&self, other: &Placement) -> Result<Mapping, String> {
        let same_kind = matches!(
            (self.crs, other.crs),
            (Crs::Geographic { .. }, Crs::Geographic { .. })
                | (Crs::Projected { .. }, Crs::Projected { .. })
        );
        let codes_differ = matches!(
            (self.crs.code(), other.crs.code()),
            (Some(a), Some(b)) if a != b
        );
        if !same_kind || codes_differ {
            return Err(format!(
                "it is in {} and the other in {}: reproject one onto the other (e.g. gdalwarp -t_srs)",
                other.crs, self.crs
            ));
        }
        let origin = (
            (self.x0 - other.x0) / other.dx,
            (other.y0 - self.y0) / other.dy,
        );
        Ok(Mapping {
            origin,
            step: (self.dx / other.dx, self.dy / other.dy),
        })
    }

    /// The extent `[west, east] x [south, north]` of the samples' centres of a
    /// `width x height` grid, for messages.
    pub fn extent(&self, width: usize, height: usize) -> String {
        let east = self.x0 + (width.max(1) - 1) as f64 * self.dx;
        let south = self.y0 - (height.max(1) - 1) as f64 * self.dy;
        let digits = match self.crs {
            Crs::Geographic { .. } => 4,
            Crs::Projected { .. } => 0,
        };
        format!(
            "x {:.digits$}..{:.digits$}, y {:.digits$}..{:.digits$} ({})",
            self.x0, east, south, self.y0, self.crs
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn utm(x0: f64, y0: f64, d: f64) -> Placement {
        Placement {
            crs: Crs::Projected { code: Some(32610) },
            x0,
            y0,
            dx: d,
            dy: d,
        }
    }

    #[test]
    fn maps_samples_between_grids() {
        let heights = utm(1000.0, 5000.0, 30.0);
        let photo = utm(970.0, 5015.0, 10.0);
        let map = heights.in_grid_of(&photo).unwrap();
        // Heights sample 0 is 3 photo pixels east and 1.5 south of photo pixel 0.
        assert_eq!(map.origin, (3.0, 1.5));
        assert_eq!(map.step, (3.0, 3.0));
        // A window moves its origin by whole samples.
        let w = heights.window(2, 1);
        assert_eq!((w.x0, w.y0), (1060.0, 4970.0));
    }

    #[test]
    fn refuses_different_systems() {
        let heights = utm(0.0, 0.0, 1.0);
        let mut other = heights;
        other.crs = Crs::Projected { code: Some(32611) };
        let e = heights.in_grid_of(&other).unwrap_err();
        assert!(e.contains("EPSG:32611") && e.contains("EPSG:32610"), "{e}");
        other.crs = Crs::Geographic { code: Some(4326) };
        assert!(heights.in_grid_of(&other).is_err());
        // A system the file does not name is taken to be the other's.
        other.crs = Crs::Projected { code: None };
        assert!(heights.in_grid_of(&other).is_ok());
    }
}
