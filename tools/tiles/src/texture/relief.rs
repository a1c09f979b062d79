//! Pre-lit shaded relief from the full-resolution heights (paper, section 5: when no photo
//! texture exists, one is computed from the terrain, lit before filtering so that the
//! lighting does not change with the mesh's level of detail).
//!
//! Each sample gets a normal from central differences of its neighbours (one-sided at the
//! grid's edges) and a Lambert term against a sun given by azimuth (degrees clockwise from
//! north) and elevation; a texel takes the bilinear blend of its four samples' colours, so the
//! lighting varies smoothly across a cell instead of in facets. With `tint` the grey is
//! multiplied into a hypsometric colour ramp over the grid's height range.

use super::lanczos::Image;
use crate::grid::Grid;

/// How the relief is lit and coloured.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Relief {
    /// Degrees clockwise from north (315: the cartographers' north-west light).
    pub azimuth_deg: f64,
    /// Degrees above the horizon.
    pub elevation_deg: f64,
    /// Colour by height (hypsometric tint) under the shading; grey without.
    pub tint: bool,
}

impl Default for Relief {
    fn default() -> Self {
        Relief {
            azimuth_deg: 315.0,
            elevation_deg: 45.0,
            tint: false,
        }
    }
}

impl Relief {
    pub fn validate(&self) -> Result<(), String> {
        if !self.azimuth_deg.is_finite() {
            return Err(format!(
                "--sun-azimuth {} is not a number of degrees",
                self.azimuth_deg
            ));
        }
        if !(self.elevation_deg > 0.0 && self.elevation_deg <= 90.0) {
            return Err(format!(
                "--sun-elevation {} must be above 0 and at most 90 degrees",
                self.elevation_deg
            ));
        }
        Ok(())
    }

    /// Unit vector towards the sun in (east, north, up).
    fn sun(&self) -> [f64; 3] {
        let (az, el) = (
            self.azimuth_deg.to_radians(),
            self.elevation_deg.to_radians(),
        );
        [az.sin() * el.cos(), az.cos() * el.cos(), el.sin()]
    }
}

/// Light reaching a face turned away from the sun (sky light), as a fraction of full sun.
const AMBIENT: f64 = 0.12;

/// Hypsometric colour stops, from the lowest to the highest height of the grid.
const RAMP: [(f64, [f64; 3]); 5] = [
    (0.0, [86.0, 135.0, 74.0]),
    (0.25, [156.0, 170.0, 96.0]),
    (0.5, [178.0, 146.0, 96.0]),
    (0.75, [150.0, 124.0, 104.0]),
    (1.0, [250.0, 250.0, 250.0]),
];

fn ramp(t: f64) -> [f64; 3] {
    let t = t.clamp(0.0, 1.0);
    for pair in RAMP.windows(2) {
        let ((t0, c0), (t1, c1)) = (pair[0], pair[1]);
        if t <= t1 {
            let f = (t - t0) / (t1 - t0);
            return [0, 1, 2].map(|k| c0[k] + f * (c1[k] - c0[k]));
        }
    }
    RAMP[RAMP.len() - 1].1
}

/// The lit colour of every sample in a window of the grid.
struct Lit {
    x0: usize,
    y0: usize,
    width: usize,
    colours: Vec<[f32; 3]>,
}

/// A relief ready to render over one grid: the sun and the grid's height range (for the tint).
#[derive(Clone, Copy, Debug)]
pub struct Lighting {
    pub relief: Relief,
    sun: [f64; 3],
    lo: f64,
    range: f64,
}

impl Lighting {
    pub fn new(grid: &Grid, relief: Relief) -> Lighting {
        let range = grid
            .heights
            .iter()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &h| {
                (lo.min(h), hi.max(h))
            });
        Lighting::with_range(range, relief)
    }

    /// The lighting of a grid whose heights span `(lo, hi)` (the tint's ramp runs between).
    pub fn with_range((lo, hi): (f32, f32), relief: Relief) -> Lighting {
        Lighting {
            relief,
            sun: relief.sun(),
            lo: f64::from(lo),
            range: f64::from(hi - lo).max(1e-6),
        }
    }
}

fn light(grid: &Grid, l: &Lighting, (x0, y0): (usize, usize), (x1, y1): (usize, usize)) -> Lit {
    let (sun, lo, range) = (l.sun, l.lo, l.range);
    let h = |x: usize, y: usize| f64::from(grid.at(x, y));
    let width = x1 + 1 - x0;
    let mut colours = Vec::with_capacity(width * (y1 + 1 - y0));
    for y in y0..=y1 {
        let (ya, yb) = (y.saturating_sub(1), (y + 1).min(grid.height - 1));
        for x in x0..=x1 {
            let (xa, xb) = (x.saturating_sub(1), (x + 1).min(grid.width - 1));
            let east = (h(xb, y) - h(xa, y)) / ((xb - xa).max(1) as f64 * grid.spacing_x);
            // Rows run south: the northward slope is minus the slope along the rows.
            let north = -(h(x, yb) - h(x, ya)) / ((yb - ya).max(1) as f64 * grid.spacing_y);
            let n = [-east, -north, 1.0];
            let len = (n[0] * n[0] + n[1] * n[1] + 1.0).sqrt();
            let lambert = ((n[0] * sun[0] + n[1] * sun[1] + n[2] * sun[2]) / len).max(0.0);
            let light = AMBIENT + (1.0 - AMBIENT) * lambert;
            let base = if l.relief.tint {
                ramp((h(x, y) - lo) / range)
            } else {
                [255.0; 3]
            };
            colours.push(base.map(|c| (c * light) as f32));
        }
    }
    Lit {
        x0,
        y0,
        width,
        colours,
    }
}

/// A `width x height` image of the lit relief whose texel `(i, j)` is centred on grid
/// position `(x0 + i * step, y0 + j * step)` in samples (fractional, clamped to the grid).
pub fn render(
    grid: &Grid,
    lighting: &Lighting,
    (x0, y0): (f64, f64),
    step: f64,
    (width, height): (usize, usize),
) -> Image {
    let clamp = |v: f64, n: usize| v.clamp(0.0, (n - 1) as f64);
    let xs: Vec<f64> = (0..width)
        .map(|i| clamp(x0 + i as f64 * step, grid.width))
        .collect();
    let ys: Vec<f64> = (0..height)
        .map(|j| clamp(y0 + j as f64 * step, grid.height))
        .collect();
    let lo = |v: &[f64]| v.iter().copied().fold(f64::INFINITY, f64::min).floor() as usize;
    let hi = |v: &[f64], n: usize| {
        (v.iter().copied().fold(f64::NEG_INFINITY, f64::max).floor() as usize + 1).min(n - 1)
    };
    let lit = light(
        grid,
        lighting,
        (lo(&xs), lo(&ys)),
        (hi(&xs, grid.width), hi(&ys, grid.height)),
    );
    // Each column's two samples (as indices into a row of `lit`) and weight, once for all rows
    // (`floor` is a library call).
    let columns: Vec<(usize, usize, f32)> = xs
        .iter()
        .map(|&x| {
            let xa = x.floor() as usize;
            let xb = (xa + 1).min(grid.width - 1);
            (xa - lit.x0, xb - lit.x0, (x - xa as f64) as f32)
        })
        .collect();
    let mut image = Image::new(width, height);
    let row_of = |y: usize| &lit.colours[(y - lit.y0) * lit.width..][..lit.width];
    // A grid row interpolated across to every column: the texels' upper or lower values.
    // Several rows of texels (about three at the relief's scale) read the same grid rows, and
    // the next grid row's upper values are this one's lower: each is found once, by the same
    // expression, so the texels are the same bits as interpolating each one on its own.
    let across = |y: usize, into: &mut Vec<[f32; 3]>| {
        let row = row_of(y);
        into.clear();
        into.extend(columns.iter().map(|&(xa, xb, fx)| {
            let (a, b) = (row[xa], row[xb]);
            [0, 1, 2].map(|k| a[k] + fx * (b[k] - a[k]))
        }));
    };
    let (mut upper, mut lower) = (Vec::with_capacity(width), Vec::with_capacity(width));
    let mut held: Option<(usize, usize)> = None;
    for (&y, out) in ys.iter().zip(image.texels.chunks_exact_mut(width)) {
        let ya = y.floor() as usize;
        let yb = (ya + 1).min(grid.height - 1);
        let fy = (y - ya as f64) as f32;
        match held {
            Some(rows) if rows == (ya, yb) => {}
            Some((_, was)) if was == ya => {
                std::mem::swap(&mut upper, &mut lower);
                across(yb, &mut lower);
            }
            _ => {
                across(ya, &mut upper);
                across(yb, &mut lower);
            }
        }
        held = Some((ya, yb));
        for ((texel, top), bottom) in out.iter_mut().zip(&upper).zip(&lower) {
            *texel = [0, 1, 2].map(|k| top[k] + fy * (bottom[k] - top[k]));
        }
    }
    image
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A plane rising `slope` metres per metre towards the east, 10 m spacing.
    fn plane(slope: f64) -> Vec<f32> {
        (0..32 * 32)
            .map(|i| ((i % 32) as f64 * 10.0 * slope) as f32)
            .collect()
    }

    fn grid(heights: &[f32]) -> Grid<'_> {
        Grid {
            width: 32,
            height: 32,
            first_row: 0,
            heights,
            spacing_x: 10.0,
            spacing_y: 10.0,
        }
    }

    fn grey(relief: &Relief, heights: &[f32]) -> f32 {
        let g = grid(heights);
        render(&g, &Lighting::new(&g, *relief), (10.0, 10.0), 1.0, (1, 1)).texels[0][0]
    }

    /// Texels from grid rows interpolated once and shared are the bits of each texel
    /// interpolated from its four samples on its own: a rough field, a fractional step
    /// (several texel rows a grid row), an origin off the lattice, and texels clamped past
    /// the last row and column.
    #[test]
    fn shared_rows_render_each_texels_bits() {
        let heights: Vec<f32> = (0..32 * 32u32)
            .map(|i| (i.wrapping_mul(2_654_435_761) >> 22) as f32 * 0.37)
            .collect();
        let g = grid(&heights);
        let lighting = Lighting::new(&g, Relief::default());
        for (origin, step, size) in [((0.3, 0.7), 0.35, (90, 95)), ((20.1, 25.6), 0.6, (40, 30))] {
            let image = render(&g, &lighting, origin, step, size);
            let lit = light(&g, &lighting, (0, 0), (31, 31));
            let at = |x: usize, y: usize| lit.colours[y * lit.width + x];
            for (t, texel) in image.texels.iter().enumerate() {
                let (i, j) = (t % size.0, t / size.0);
                let x = (origin.0 + i as f64 * step).clamp(0.0, 31.0);
                let y = (origin.1 + j as f64 * step).clamp(0.0, 31.0);
                let (xa, ya) = (x.floor() as usize, y.floor() as usize);
                let (xb, yb) = ((xa + 1).min(31), (ya + 1).min(31));
                let (fx, fy) = ((x - xa as f64) as f32, (y - ya as f64) as f32);
                let (a, b, c, d) = (at(xa, ya), at(xb, ya), at(xa, yb), at(xb, yb));
                let want = [0, 1, 2].map(|k| {
                    let top = a[k] + fx * (b[k] - a[k]);
                    let bottom = c[k] + fx * (d[k] - c[k]);
                    top + fy * (bottom - top)
                });
                assert_eq!(
                    texel.map(f32::to_bits),
                    want.map(f32::to_bits),
                    "texel {i},{j}"
                );
            }
        }
    }

    #[test]
    fn flat_ground_is_lit_by_the_sines_of_the_sun_elevation() {
        let flat = vec![5.0; 32 * 32];
        for el in [20.0, 45.0, 90.0] {
            let relief = Relief {
                elevation_deg: el,
                ..Relief::default()
            };
            let want = 255.0 * (AMBIENT + (1.0 - AMBIENT) * f64::sin(f64::to_radians(el)));
            assert!(
                (f64::from(grey(&relief, &flat)) - want).abs() < 0.01,
                "{el}"
            );
        }
    }

    #[test]
    fn a_slope_facing_the_sun_is_brighter_than_one_facing_away() {
        // Ground rising to the east faces west: lit by a western sun, dark under an eastern.
        let rising_east = plane(0.5);
        let west = Relief {
            azimuth_deg: 270.0,
            ..Relief::default()
        };
        let east = Relief {
            azimuth_deg: 90.0,
            ..Relief::default()
        };
        let flat = grey(&Relief::default(), &vec![0.0; 32 * 32]);
        assert!(grey(&west, &rising_east) > flat);
        assert!(grey(&east, &rising_east) < flat);
        // The exact Lambert term: normal (-0.5, 0, 1) / |.|, sun from the west at 45 degrees.
        let n = [-0.5f64, 0.0, 1.0];
        let len = (0.25f64 + 1.0).sqrt();
        let s = f64::to_radians(45.0);
        let lambert = (n[0] * -s.cos() + n[2] * s.sin()) / len;
        let want = 255.0 * (AMBIENT + (1.0 - AMBIENT) * lambert);
        assert!((f64::from(grey(&west, &rising_east)) - want).abs() < 0.01);
    }

    #[test]
    fn between_samples_the_light_is_blended_not_faceted() {
        // A ridge: the texel halfway between two differently lit samples takes their mean.
        let heights: Vec<f32> = (0..32 * 32)
            .map(|i| {
                let x = (i % 32) as f32;
                (x - 16.0).abs() * -5.0
            })
            .collect();
        let g = grid(&heights);
        let relief = Relief {
            azimuth_deg: 90.0,
            ..Relief::default()
        };
        let lighting = Lighting::new(&g, relief);
        let at = |x: f64| render(&g, &lighting, (x, 8.0), 1.0, (1, 1)).texels[0][0];
        let mid = at(20.5);
        assert!((mid - (at(20.0) + at(21.0)) / 2.0).abs() < 1e-3);
    }

    #[test]
    fn the_tint_follows_height() {
        let low = ramp(0.0);
        let high = ramp(1.0);
        assert!(high.iter().sum::<f64>() > low.iter().sum::<f64>());
        assert_eq!(ramp(0.5), RAMP[2].1);
    }
}
