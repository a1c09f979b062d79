//! A reference RTIN mesher with the construction of Mapbox's Martini (0.2.0), written here
//! from its published algorithm so the mesh-economy benchmark can sweep any error threshold
//! on the same machine and measure the *true* error of the result.
//!
//! Martini splits right triangles at their hypotenuse midpoints. Its per-vertex error is the
//! deviation at the midpoint of each triangle's hypotenuse, maxed with its children's, which
//! is not a bound on the true error of the mesh (that is why the data README's table shows
//! measured errors up to twice the requested one); [`true_max_error`] measures it.

/// Martini's precomputed errors for a `(2^k + 1)²` grid.
pub struct Rtin {
    size: usize,
    heights: Vec<f32>,
    errors: Vec<f32>,
}

/// A triangle of the mesh, as three grid points.
pub type Triangle = [(u32, u32); 3];

impl Rtin {
    /// Computes the midpoint errors bottom-up. `heights` is `size x size`, `size = 2^k + 1`.
    pub fn new(heights: Vec<f32>, size: usize) -> Rtin {
        assert!((size - 1).is_power_of_two() && heights.len() == size * size);
        let tile = (size - 1) as u32;
        let num_triangles = (tile * tile * 2 - 2) as usize;
        let num_parents = num_triangles - (tile * tile) as usize;
        let mut errors = vec![0.0f32; size * size];
        for i in (0..num_triangles).rev() {
            let (a, b) = corners(i, tile);
            let (mx, my) = ((a.0 + b.0) >> 1, (a.1 + b.1) >> 1);
            let (cx, cy) = (mx + my - a.1, my + a.0 - mx);
            let h = |x: u32, y: u32| heights[y as usize * size + x as usize];
            let interpolated = (h(a.0, a.1) + h(b.0, b.1)) / 2.0;
            let middle = my as usize * size + mx as usize;
            let mut e = errors[middle].max((interpolated - heights[middle]).abs());
            if i < num_parents {
                let left = ((a.1 + cy) >> 1) as usize * size + ((a.0 + cx) >> 1) as usize;
                let right = ((b.1 + cy) >> 1) as usize * size + ((b.0 + cx) >> 1) as usize;
                e = e.max(errors[left]).max(errors[right]);
            }
            errors[middle] = e;
        }
        Rtin {
            size,
            heights,
            errors,
        }
    }

    /// The mesh for `max_error`: its triangles and its vertex count.
    pub fn mesh(&self, max_error: f32) -> (Vec<Triangle>, usize) {
        let max = (self.size - 1) as u32;
        let mut used = vec![false; self.size * self.size];
        let mut tris = Vec::new();
        self.split(
            (0, 0),
            (max, max),
            (max, 0),
            max_error,
            &mut used,
            &mut tris,
        );
        self.split(
            (max, max),
            (0, 0),
            (0, max),
            max_error,
            &mut used,
            &mut tris,
        );
        (tris, used.iter().filter(|&&u| u).count())
    }

    fn split(
        &self,
        a: (u32, u32),
        b: (u32, u32),
        c: (u32, u32),
        max_error: f32,
        used: &mut [bool],
        out: &mut Vec<Triangle>,
    ) {
        let m = ((a.0 + b.0) >> 1, (a.1 + b.1) >> 1);
        if a.0.abs_diff(c.0) + a.1.abs_diff(c.1) > 1
            && self.errors[m.1 as usize * self.size + m.0 as usize] > max_error
        {
            self.split(c, a, m, max_error, used, out);
            self.split(b, c, m, max_error, used, out);
        } else {
            for p in [a, b, c] {
                used[p.1 as usize * self.size + p.0 as usize] = true;
            }
            out.push([a, b, c]);
        }
    }

    pub fn heights(&self) -> &[f32] {
        &self.heights
    }
}

/// The two hypotenuse corners of Martini's triangle `i` (its implicit binary-tree numbering).
fn corners(i: usize, tile: u32) -> ((u32, u32), (u32, u32)) {
    let mut id = i + 2;
    let (mut ax, mut ay, mut bx, mut by, mut cx, mut cy) = (0u32, 0u32, 0u32, 0u32, 0u32, 0u32);
    if id & 1 == 1 {
        bx = tile;
        by = tile;
        cx = tile;
    } else {
        ax = tile;
        ay = tile;
        cy = tile;
    }
    loop {
        id >>= 1;
        if id <= 1 {
            break;
        }
        let (mx, my) = ((ax + bx) >> 1, (ay + by) >> 1);
        if id & 1 == 1 {
            bx = ax;
            by = ay;
            ax = cx;
            ay = cy;
        } else {
            ax = bx;
            ay = by;
            bx = cx;
            by = cy;
        }
        cx = mx;
        cy = my;
    }
    ((ax, ay), (bx, by))
}

/// The true max |height - mesh| over every grid sample, each triangle rasterised with f64
/// barycentric weights (edges included).
pub fn true_max_error(tris: &[Triangle], heights: &[f32], width: usize) -> f64 {
    let mut worst = 0.0f64;
    for t in tris {
        let p = t.map(|(x, y)| {
            (
                f64::from(x),
                f64::from(y),
                f64::from(heights[y as usize * width + x as usize]),
            )
        });
        let det = (p[1].1 - p[2].1) * (p[0].0 - p[2].0) + (p[2].0 - p[1].0) * (p[0].1 - p[2].1);
        let (x0, x1) = (
            t.iter().map(|v| v.0).min().unwrap_or(0),
            t.iter().map(|v| v.0).max().unwrap_or(0),
        );
        let (y0, y1) = (
            t.iter().map(|v| v.1).min().unwrap_or(0),
            t.iter().map(|v| v.1).max().unwrap_or(0),
        );
        for y in y0..=y1 {
            for x in x0..=x1 {
                let (fx, fy) = (f64::from(x), f64::from(y));
                let l0 =
                    ((p[1].1 - p[2].1) * (fx - p[2].0) + (p[2].0 - p[1].0) * (fy - p[2].1)) / det;
                let l1 =
                    ((p[2].1 - p[0].1) * (fx - p[2].0) + (p[0].0 - p[2].0) * (fy - p[2].1)) / det;
                let l2 = 1.0 - l0 - l1;
                if l0 < -1e-9 || l1 < -1e-9 || l2 < -1e-9 {
                    continue;
                }
                let z = l0 * p[0].2 + l1 * p[1].2 + l2 * p[2].2;
                worst = worst.max((f64::from(heights[y as usize * width + x as usize]) - z).abs());
            }
        }
    }
    worst
}
