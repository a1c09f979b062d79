//! Push-pull void filling ([`crate::fill`]) one band of rows at a time, bit for bit as the
//! whole grid is filled, so that a DEM larger than memory can be read band by band.
//!
//! A filled sample of level `i` is its pulled value, or, where that is a void, a blend of the
//! filled level `i + 1` at the two rows (and columns) its taps name. A pulled sample of level
//! `i + 1` is the mean of a 2x2 block of level `i`. So rows `a..b` of the filled grid need rows
//! of level `i` near `a / 2^i .. b / 2^i`, and those need the grid's rows from about
//! `a - 2^(i+1)` to `b + 2^(i+1)`: a margin that doubles with each level the fill descends.
//!
//! One pass over the grid's rows ([`Scanner`]) finds what is global: how deep the pyramid
//! goes (the first level with no void, where the whole-grid fill stops pulling) and, when it
//! goes deeper than `stored_at`, the filled level `stored_at`, kept whole (`1 / 4^stored_at`
//! of the grid). A band ([`Plan::fill`]) then pulls its own levels below that from its rows and
//! their margin, and pushes down from the stored (or void-free) level, with the same taps and
//! the same arithmetic as the whole-grid fill: the same bits. The margin is at most
//! `2^(stored_at + 1) + 2` rows either side.
//!
//! The pass splits by rows ([`Scanner::part`], [`Plan::join`]): shares that start on a row of
//! the top pulled level each pull their own rows of it, and those rows, put together, are the
//! pass's. So the shards of a distributed build each scan their own rows, and every shard
//! plans the fill from all the shares without reading the rest of the grid.

use std::borrow::Cow;

use crate::fill::{pull, pull_push, push_rows, tap, Level};

/// The level a [`Plan`] keeps whole when the pyramid goes deeper: 1/4096 of the grid, so a
/// 65537² grid keeps about a million samples; a band's margin is then at most 130 rows.
pub const STORED: usize = 6;

/// What filling a band needs to know about the whole grid.
#[derive(Clone, Debug)]
pub struct Plan {
    /// Width and height of each level, from the grid (level 0) up.
    dims: Vec<(usize, usize)>,
    /// The first level (from 1) with no void, where the pyramid ends; 0 when the grid has no
    /// void and nothing is filled.
    depth: usize,
    /// The filled level `stored.0`, whole, when the pyramid ends above it.
    stored: Option<(usize, Level)>,
    /// Voids of the grid.
    pub voids: u64,
}

/// A share of a [`Scanner`]'s pass: what rows `first_row..` of the grid, from a row of the
/// top pulled level, pull up to it and hold. Shares that cover the grid's rows once join into
/// the pass's plan ([`Plan::join`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Pulled {
    /// The first row of the top level these rows pull.
    pub first: usize,
    /// The top level's width.
    pub width: usize,
    /// Its rows `first..`, whole width (NaN: void).
    pub top: Vec<f32>,
    /// Per level from 0: whether a sample of it pulled from these rows is a void.
    pub void: Vec<bool>,
    /// Voids and samples of these grid rows.
    pub voids: u64,
    pub samples: u64,
}

impl Pulled {
    /// One line of text: the figures, the void levels as `0`/`1`, then every top sample as the
    /// 8 hex digits of its bits (so it reads back exact).
    pub fn to_line(&self) -> String {
        let mut line = format!(
            "{} {} {} {} {} ",
            self.first,
            self.width,
            self.voids,
            self.samples,
            self.void
                .iter()
                .map(|&v| if v { '1' } else { '0' })
                .collect::<String>()
        );
        line.reserve(self.top.len() * 8);
        for h in &self.top {
            line.push_str(&format!("{:08x}", h.to_bits()));
        }
        line
    }

    /// [`Pulled::to_line`] read back.
    pub fn from_line(line: &str) -> Result<Pulled, String> {
        let mut words = line.split(' ');
        let mut number = |what: &str| -> Result<u64, String> {
            words
                .next()
                .and_then(|w| w.parse().ok())
                .ok_or_else(|| format!("a bad {what} in the pulled rows"))
        };
        let (first, width) = (number("first row")? as usize, number("width")? as usize);
        let (voids, samples) = (number("void count")?, number("sample count")?);
        let void = words
            .next()
            .filter(|w| !w.is_empty() && w.bytes().all(|b| b == b'0' || b == b'1'))
            .ok_or("bad void levels in the pulled rows")?
            .bytes()
            .map(|b| b == b'1')
            .collect();
        let hex = words.next().unwrap_or_default();
        if words.next().is_some() || !hex.len().is_multiple_of(8) || width == 0 {
            return Err("pulled rows of a bad length".into());
        }
        let top = hex
            .as_bytes()
            .chunks_exact(8)
            .map(|h| {
                std::str::from_utf8(h)
                    .ok()
                    .and_then(|h| u32::from_str_radix(h, 16).ok())
                    .map(f32::from_bits)
                    .ok_or_else(|| "a bad sample in the pulled rows".to_string())
            })
            .collect::<Result<Vec<f32>, String>>()?;
        if !top.len().is_multiple_of(width) {
            return Err("pulled rows of a bad length".into());
        }
        Ok(Pulled {
            first,
            width,
            top,
            void,
            voids,
            samples,
        })
    }
}

/// One pass over a grid's rows, north to south, pulling levels `1..=stored_at` as rows arrive.
pub struct Scanner {
    dims: Vec<(usize, usize)>,
    /// Per level from 1: the even row waiting for its odd partner.
    pending: Vec<Option<Vec<f32>>>,
    /// Per level from 0: whether a pulled sample of it is a void.
    void: Vec<bool>,
    /// Level `dims.len() - 1`, pulled, whole.
    top: Vec<f32>,
    voids: u64,
    samples: u64,
}

impl Scanner {
    /// A scan of a `width` x `height` grid that keeps level `stored_at` whole (fewer levels when
    /// the grid reaches 1x1 sooner).
    pub fn new(width: usize, height: usize, stored_at: usize) -> Scanner {
        let mut dims = vec![(width, height)];
        while dims.len() <= stored_at.max(1) {
            let &(w, h) = dims.last().expect("level 0");
            if (w, h) == (1, 1) && dims.len() > 1 {
                break;
            }
            dims.push((w.div_ceil(2), h.div_ceil(2)));
        }
        let levels = dims.len();
        Scanner {
            dims,
            pending: vec![None; levels],
            void: vec![false; levels],
            top: Vec::new(),
            voids: 0,
            samples: 0,
        }
    }

    /// The grid's next row (NaN: void).
    pub fn row(&mut self, row: &[f32]) {
        debug_assert_eq!(row.len(), self.dims[0].0);
        let voids = row.iter().filter(|v| v.is_nan()).count();
        self.voids += voids as u64;
        self.samples += row.len() as u64;
        self.void[0] |= voids > 0;
        self.feed(1, row.to_vec());
    }

    /// A row of level `i - 1` arrives for level `i`.
    fn feed(&mut self, i: usize, row: Vec<f32>) {
        let width = self.dims[i - 1].0;
        match self.pending[i].take() {
            None => self.pending[i] = Some(row),
            Some(mut even) => {
                even.extend_from_slice(&row);
                let coarse = pull(&even, width, 2).samples;
                self.arrive(i, coarse);
            }
        }
    }

    /// A pulled row of level `i`.
    fn arrive(&mut self, i: usize, row: Vec<f32>) {
        self.void[i] |= row.iter().any(|v| v.is_nan());
        if i + 1 == self.dims.len() {
            self.top.extend_from_slice(&row);
        } else {
            self.feed(i + 1, row);
        }
    }

    /// Grid rows per row of the top pulled level: a share of the pass ([`Scanner::part`])
    /// starts on a multiple of it, and ends on one or on the grid's last row.
    pub fn unit(&self) -> usize {
        1 << (self.dims.len() - 1)
    }

    /// An odd level's last row pairs with itself (`pull` clamps its second row).
    fn close(&mut self) {
        for i in 1..self.dims.len() {
            if let Some(last) = self.pending[i].take() {
                let coarse = pull(&last, self.dims[i - 1].0, 1).samples;
                self.arrive(i, coarse);
            }
        }
    }

    /// This scanner's share of the pass, given grid rows `first_row..` (a multiple of
    /// [`Scanner::unit`]) up to a multiple of it or to the grid's last row, or none.
    pub fn part(mut self, first_row: usize) -> Pulled {
        let unit = self.unit();
        let (width, height) = self.dims[0];
        let rows = (self.samples / width as u64) as usize;
        assert!(
            rows == 0
                || first_row.is_multiple_of(unit)
                    && (first_row + rows == height || rows.is_multiple_of(unit)),
            "a share of rows {first_row}..{} is not on rows of the top level",
            first_row + rows
        );
        if first_row + rows == height {
            self.close();
        }
        Pulled {
            first: first_row / unit,
            width: self.dims[self.dims.len() - 1].0,
            top: self.top,
            void: self.void,
            voids: self.voids,
            samples: self.samples,
        }
    }

    /// The plan, once every row has arrived; `None` when every sample is a void.
    pub fn finish(mut self) -> Option<Plan> {
        self.close();
        if self.voids == self.samples {
            return None;
        }
        if self.voids == 0 {
            let dims = self.dims;
            return Some(Plan {
                dims,
                depth: 0,
                stored: None,
                voids: 0,
            });
        }
        if let Some(depth) = (1..self.dims.len()).find(|&i| !self.void[i]) {
            return Some(Plan {
                dims: self.dims[..=depth].to_vec(),
                depth,
                stored: None,
                voids: self.voids,
            });
        }
        // Deeper than kept: the rest of the pyramid in memory, as `fill_voids` makes it, then
        // pushed down to the kept level.
        let k = self.dims.len() - 1;
        let (w, h) = self.dims[k];
        let mut top = self.top;
        let above = pull_push(&mut top, w, h);
        let mut dims = self.dims;
        dims.extend(above.iter().map(|l| (l.width, l.height)));
        let depth = dims.len() - 1;
        Some(Plan {
            dims,
            depth,
            stored: Some((
                k,
                Level {
                    width: w,
                    height: h,
                    samples: top,
                },
            )),
            voids: self.voids,
        })
    }
}

impl Plan {
    /// The plan of a `width` x `height` grid's pass from its shares ([`Scanner::part`]), in
    /// any order: the same as one pass over every row. An error when the shares do not cover
    /// the grid's rows once each; `Ok(None)` when every sample is a void.
    pub fn join(
        width: usize,
        height: usize,
        stored_at: usize,
        parts: &[Pulled],
    ) -> Result<Option<Plan>, String> {
        let mut scan = Scanner::new(width, height, stored_at);
        let (top_width, top_height) = scan.dims[scan.dims.len() - 1];
        let mut parts: Vec<&Pulled> = parts.iter().filter(|p| p.samples > 0).collect();
        parts.sort_by_key(|p| p.first);
        for p in parts {
            let next = scan.top.len() / top_width;
            if p.first != next {
                return Err(format!(
                    "the shares' pulled rows do not follow on: {} after {next}",
                    p.first
                ));
            }
            if p.width != top_width || p.void.len() != scan.void.len() {
                return Err("a share pulled to another grid's levels".into());
            }
            scan.top.extend_from_slice(&p.top);
            for (all, &this) in scan.void.iter_mut().zip(&p.void) {
                *all |= this;
            }
            scan.voids += p.voids;
            scan.samples += p.samples;
        }
        if scan.top.len() != top_width * top_height || scan.samples != (width * height) as u64 {
            return Err(format!(
                "the shares hold {} of the grid's {} rows",
                scan.samples / width as u64,
                height
            ));
        }
        Ok(scan.finish())
    }

    /// The plan of a `width` x `height` grid known to hold no void: nothing to fill.
    pub fn no_voids(width: usize, height: usize, stored_at: usize) -> Plan {
        Plan {
            dims: Scanner::new(width, height, stored_at).dims,
            depth: 0,
            stored: None,
            voids: 0,
        }
    }

    /// Rows `y0..y1` of the filled grid. `read(a, b)` gives rows `a..b` of the grid as read
    /// (NaN: void); it is called once, for the band and its margin.
    /// True when the grid has no void, so [`fill`](Self::fill) reads exactly the rows asked.
    pub fn fills_nothing(&self) -> bool {
        self.depth == 0
    }

    pub fn fill<E>(
        &self,
        y0: usize,
        y1: usize,
        read: &mut dyn FnMut(usize, usize) -> Result<Vec<f32>, E>,
    ) -> Result<Vec<f32>, E> {
        if y0 >= y1 {
            return Ok(Vec::new());
        }
        if self.depth == 0 {
            return read(y0, y1);
        }
        let (a, b) = self.span_filled(0, y0, y1 - 1);
        let mut window = read(a, b + 1)?;
        let width = self.dims[0].0;
        let band = (y0 - a) * width..(y1 - a) * width;
        // A band without a void needs nothing from the pyramid; one with voids is filled in
        // place from the filled level 1 (level 0 is the biggest: it is not copied).
        if window[band.clone()].iter().any(|v| v.is_nan()) {
            let rows = Rows {
                first: a,
                samples: &window,
            };
            let (cw, ch) = self.dims[1];
            let (clo, chi) = (tap(y0, ch).0, tap(y1 - 1, ch).1);
            let coarse = Level {
                width: cw,
                height: ch,
                samples: self.filled(1, clo, chi, &rows),
            };
            push_rows(
                &mut window[band.clone()],
                width,
                (y0, self.dims[0].1),
                &coarse,
                clo,
            );
        }
        window.truncate(band.end);
        window.drain(..band.start);
        Ok(window)
    }

    /// Rows `lo..=hi` of pulled level `i` (level 0's borrowed from the rows read).
    fn pulled<'g>(&self, i: usize, lo: usize, hi: usize, grid: &Rows<'g>) -> Cow<'g, [f32]> {
        if i == 0 {
            return Cow::Borrowed(grid.get(lo, hi, self.dims[0].0));
        }
        let (fw, fh) = self.dims[i - 1];
        let first = 2 * lo;
        let fine = self.pulled(i - 1, first, (2 * hi + 1).min(fh - 1), grid);
        let mut out = Vec::with_capacity((hi - lo + 1) * self.dims[i].0);
        for cy in lo..=hi {
            let start = (2 * cy - first) * fw;
            let rows = if 2 * cy + 1 < fh { 2 } else { 1 };
            out.extend(pull(&fine[start..start + rows * fw], fw, rows).samples);
        }
        Cow::Owned(out)
    }

    /// Rows `lo..=hi` of filled level `i`.
    fn filled(&self, i: usize, lo: usize, hi: usize, grid: &Rows) -> Vec<f32> {
        let (w, h) = self.dims[i];
        if let Some((k, level)) = &self.stored {
            if *k == i {
                return level.samples[lo * w..(hi + 1) * w].to_vec();
            }
        }
        let mut rows = self.pulled(i, lo, hi, grid).into_owned();
        if i == self.depth || !rows.iter().any(|v| v.is_nan()) {
            return rows;
        }
        let (cw, ch) = self.dims[i + 1];
        let (clo, chi) = (tap(lo, ch).0, tap(hi, ch).1);
        let coarse = Level {
            width: cw,
            height: ch,
            samples: self.filled(i + 1, clo, chi, grid),
        };
        push_rows(&mut rows, w, (lo, h), &coarse, clo);
        rows
    }

    /// The grid rows (first, last) that [`Plan::pulled`] of level `i`'s rows `lo..=hi` reads.
    fn span_pulled(&self, i: usize, lo: usize, hi: usize) -> (usize, usize) {
        if i == 0 {
            return (lo, hi);
        }
        let fh = self.dims[i - 1].1;
        self.span_pulled(i - 1, 2 * lo, (2 * hi + 1).min(fh - 1))
    }

    /// The grid rows (first, last) that [`Plan::filled`] of level `i`'s rows `lo..=hi` may read.
    fn span_filled(&self, i: usize, lo: usize, hi: usize) -> (usize, usize) {
        if matches!(&self.stored, Some((k, _)) if *k == i) {
            return (usize::MAX, 0);
        }
        let own = self.span_pulled(i, lo, hi);
        if i == self.depth {
            return own;
        }
        let ch = self.dims[i + 1].1;
        let coarser = self.span_filled(i + 1, tap(lo, ch).0, tap(hi, ch).1);
        (own.0.min(coarser.0), own.1.max(coarser.1))
    }
}

/// Rows `first..` of the grid as read.
struct Rows<'a> {
    first: usize,
    samples: &'a [f32],
}

impl<'g> Rows<'g> {
    fn get(&self, lo: usize, hi: usize, width: usize) -> &'g [f32] {
        &self.samples[(lo - self.first) * width..(hi + 1 - self.first) * width]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fill::fill_voids;

    /// A grid with voids of every kind: scattered, a blob, a whole edge row, a run of rows.
    fn grid(seed: u64, width: usize, height: usize, density: f64) -> Vec<f32> {
        let mut rng = splitmix::Rng(seed);
        let blob = (
            rng.next_u64() as usize % width,
            rng.next_u64() as usize % height,
            1 + rng.next_u64() as usize % (width / 2 + 1),
        );
        let empty_rows = rng.next_u64() as usize % height;
        (0..width * height)
            .map(|i| {
                let (x, y) = (i % width, i / width);
                let r = rng.unit();
                let in_blob = x.abs_diff(blob.0).max(y.abs_diff(blob.1)) < blob.2;
                let void = r < density
                    || in_blob
                    || y == 0 && seed.is_multiple_of(3)
                    || (empty_rows..empty_rows + 3).contains(&y) && seed.is_multiple_of(2);
                if void {
                    f32::NAN
                } else {
                    (x as f32 * 0.37 - y as f32 * 1.3 + r as f32 * 50.0).sin() * 900.0
                }
            })
            .collect()
    }

    /// Every band of every grid, filled with the plan from one scan, equals the same rows of
    /// the whole-grid fill bit for bit: at several kept levels (so both the void-free end and
    /// the kept level are reached), odd and even sizes, sparse and dense voids.
    #[test]
    fn bands_fill_as_the_whole_grid_does() {
        let mut checked = (0u64, 0u64);
        for seed in 0..40u64 {
            let width = 1 + (seed as usize * 7) % 53;
            let height = 1 + (seed as usize * 13) % 97;
            let density = [0.0, 0.05, 0.5, 0.95][seed as usize % 4];
            let raw = grid(seed, width, height, density);
            let mut whole = raw.clone();
            let voids = fill_voids(&mut whole, width, height);
            for stored_at in [1, 2, 3, STORED] {
                let mut scan = Scanner::new(width, height, stored_at);
                for row in raw.chunks_exact(width) {
                    scan.row(row);
                }
                let Some(plan) = scan.finish() else {
                    assert_eq!(voids, None, "seed {seed}");
                    continue;
                };
                assert_eq!(Some(plan.voids), voids, "seed {seed}");
                if plan.stored.is_some() {
                    checked.1 += 1;
                }
                for band in [1, 2, 3, 5, 16, height] {
                    for y0 in (0..height).step_by(band) {
                        let y1 = (y0 + band).min(height);
                        let mut reads = 0;
                        let mut read = |a: usize, b: usize| {
                            reads += 1;
                            Ok::<_, ()>(raw[a * width..b * width].to_vec())
                        };
                        let got = plan.fill(y0, y1, &mut read).expect("read");
                        assert!(reads <= 1);
                        let want = &whole[y0 * width..y1 * width];
                        let same = got.len() == want.len()
                            && got
                                .iter()
                                .zip(want)
                                .all(|(a, b)| a.to_bits() == b.to_bits());
                        assert!(same, "seed {seed}, kept {stored_at}, rows {y0}..{y1}");
                        checked.0 += 1;
                    }
                }
            }
        }
        // Not vacuous: many bands, and the kept level was used.
        assert!(checked.0 > 5_000 && checked.1 > 10, "{checked:?}");
    }

    /// A pass split into shares by rows, each scanned alone and sent as text, joins into
    /// the plan of one pass: the same fill of every band, bit for bit. Shares at every
    /// multiple of the unit, so the grid's odd last rows and empty shares are among them. The
    /// controls: a share's pulled sample changed fills differently, and shares that leave out
    /// rows or overlap are refused.
    #[test]
    fn a_pass_in_shares_plans_the_same_fill() {
        let (mut joined, mut changed_differ) = (0, 0);
        for seed in 0..24u64 {
            let width = 1 + (seed as usize * 11) % 61;
            let height = 1 + (seed as usize * 29) % 157;
            let density = [0.05, 0.5, 0.95][seed as usize % 3];
            let raw = grid(seed, width, height, density);
            let mut whole = raw.clone();
            let voids = fill_voids(&mut whole, width, height);
            for stored_at in [1, 3, STORED] {
                let unit = Scanner::new(width, height, stored_at).unit();
                let cuts: Vec<usize> = (0..=height)
                    .step_by(unit * (1 + seed as usize % 2))
                    .chain([height, height])
                    .collect();
                let parts: Vec<Pulled> = cuts
                    .windows(2)
                    .map(|w| {
                        let mut scan = Scanner::new(width, height, stored_at);
                        for row in raw[w[0] * width..w[1] * width].chunks_exact(width) {
                            scan.row(row);
                        }
                        let part = scan.part(w[0]);
                        Pulled::from_line(&part.to_line()).expect("read back")
                    })
                    .collect();
                let plan = Plan::join(width, height, stored_at, &parts).expect("covers");
                let Some(plan) = plan else {
                    assert_eq!(voids, None, "seed {seed}");
                    continue;
                };
                let fill = |plan: &Plan| {
                    plan.fill(0, height, &mut |a, b| {
                        Ok::<_, ()>(raw[a * width..b * width].to_vec())
                    })
                    .expect("read")
                };
                let same = |got: &[f32]| {
                    got.iter()
                        .zip(&whole)
                        .all(|(a, b)| a.to_bits() == b.to_bits())
                };
                assert!(same(&fill(&plan)), "seed {seed}, kept {stored_at}");
                assert_eq!(Some(plan.voids), voids);
                joined += 1;
                // The controls.
                let short = &parts[1..];
                if parts[0].samples > 0 {
                    assert!(Plan::join(width, height, stored_at, short).is_err());
                }
                let twice: Vec<Pulled> = parts.iter().chain(&parts[..1]).cloned().collect();
                if parts[0].samples > 0 {
                    assert!(Plan::join(width, height, stored_at, &twice).is_err());
                }
                if plan.stored.is_some() {
                    let mut changed = parts.clone();
                    let Some(s) = changed
                        .iter_mut()
                        .flat_map(|p| p.top.iter_mut())
                        .find(|h| !h.is_nan())
                    else {
                        continue;
                    };
                    *s += 100.0;
                    let other = Plan::join(width, height, stored_at, &changed)
                        .expect("covers")
                        .expect("valid");
                    changed_differ += usize::from(!same(&fill(&other)));
                }
            }
        }
        assert!(
            joined > 40 && changed_differ > 5,
            "{joined} {changed_differ}"
        );
    }

    /// The control: a band filled from a plan of another grid differs somewhere.
    #[test]
    fn a_plan_of_other_voids_fills_differently() {
        let (width, height) = (40, 60);
        let raw = grid(7, width, height, 0.5);
        let other = grid(8, width, height, 0.5);
        let mut whole = raw.clone();
        fill_voids(&mut whole, width, height);
        let mut scan = Scanner::new(width, height, 2);
        for row in other.chunks_exact(width) {
            scan.row(row);
        }
        let plan = scan.finish().expect("valid samples");
        let got = plan
            .fill(0, height, &mut |a, b| {
                Ok::<_, ()>(raw[a * width..b * width].to_vec())
            })
            .expect("read");
        assert!(got
            .iter()
            .zip(&whole)
            .any(|(a, b)| a.to_bits() != b.to_bits()));
    }
}
