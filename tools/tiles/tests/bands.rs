//! A tile set built from heights read a band of tile rows at a time is the same bytes as one
//! built from the grid held whole: shared sides agreed across bands, textures whose filters
//! reach past a band's tiles, and independent sides, on a real SRTM mosaic with voids. The
//! band reads stay within a band and its texture margin (the memory bound).

use std::borrow::Cow;
use std::sync::Mutex;

use testdata::data;
use tiles::build::{build_tileset_from, Heights};
use tiles::texture::{relief::Relief, Layout, Source, Texturing};
use tiles::{build_tileset_textured, BuildError, BuildParams, Grid, TileSetMeta};

/// A whole grid served a band at a time, each read copied out (as a file reader's would be),
/// with the largest read and the number of reads kept.
struct Banded<'a> {
    grid: Grid<'a>,
    per_band: u32,
    reads: Mutex<(usize, usize)>,
}

impl Heights for Banded<'_> {
    fn shape(&self) -> Grid<'_> {
        Grid {
            heights: &[],
            ..self.grid
        }
    }

    fn rows(&self, y0: usize, y1: usize) -> Result<Cow<'_, [f32]>, BuildError> {
        let mut reads = self.reads.lock().expect("lock");
        reads.0 = reads.0.max(y1 - y0);
        reads.1 += 1;
        let w = self.grid.width;
        Ok(Cow::Owned(self.grid.heights[y0 * w..y1 * w].to_vec()))
    }

    fn band_tile_rows(&self) -> u32 {
        self.per_band
    }
}

#[test]
fn a_banded_build_is_the_whole_builds_bytes() {
    let paths = [data("srtm/N41E001.hgt"), data("srtm/N42E001.hgt")];
    let dem = dem::read(&paths, &dem::ReadOptions::default()).expect("read mosaic");
    assert!(dem.voids_filled > 0);
    let grid = Grid {
        width: dem.width,
        height: dem.height,
        first_row: 0,
        heights: &dem.heights,
        spacing_x: dem.spacing_x,
        spacing_y: dem.spacing_y,
    };
    let meta = TileSetMeta {
        description: dem.description.clone(),
        voids_filled: dem.voids_filled,
        compact: false,
    };
    let texturing = Texturing {
        source: Source::Relief(Relief::default()),
        layout: Layout::new(128).expect("layout"),
    };
    let dir = tempfile::tempdir().expect("tempdir");
    let cases = [
        (BuildParams::default(), Some(&texturing), [1, 3]),
        (
            BuildParams {
                shared_sides: false,
                levels: 6,
                ..BuildParams::default()
            },
            None,
            [2, 4],
        ),
    ];
    for (k, (params, texturing, bands)) in cases.iter().enumerate() {
        let whole = dir.path().join(format!("whole{k}.vkt"));
        build_tileset_textured(&grid, params, *texturing, &meta, &whole, &|| {}).expect("build");
        let want = std::fs::read(&whole).expect("read");
        for per_band in bands {
            let banded = Banded {
                grid,
                per_band: *per_band,
                reads: Mutex::new((0, 0)),
            };
            let out = dir.path().join(format!("banded{k}_{per_band}.vkt"));
            let summary = build_tileset_from(&banded, params, *texturing, &meta, &out, &|| {})
                .expect("banded build");
            let got = std::fs::read(&out).expect("read");
            assert!(
                got == want,
                "case {k}, {per_band} tile rows a band: the bytes differ"
            );
            let (largest, reads) = *banded.reads.lock().expect("lock");
            let margin = texturing.map_or(0, |t| t.layout.rows_beyond_tile());
            let bound = 256 * *per_band as usize + 1 + 2 * margin;
            assert!(largest <= bound, "a read of {largest} rows, bound {bound}");
            // Not vacuous: the grid (10 tile rows) was read in several bands, several times
            // (the scan, the agreement's passes, the build).
            let count = 10u32.div_ceil(*per_band) as usize;
            assert!(reads >= 2 * count, "{reads} reads of {count} bands");
            assert!(largest < dem.height, "read whole");
            if params.shared_sides {
                assert!(summary.agreement_passes > 1);
            }
        }
    }
}
