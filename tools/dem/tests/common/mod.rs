//! Helpers shared by the integration tests: where the real data lives, temp dirs, reading with
//! a spacing, SRTM tiles of one height, and a small
//! TIFF writer for the layouts the `tiff` crate's encoder does not write (tiles, the floating
//! point predictor, big-endian, unsupported variants).
#![allow(dead_code)] // each test binary uses a different subset

use std::path::{Path, PathBuf};
// Each test file uses its own subset.
#[allow(unused_imports)]
pub use testdata::data;

use tiff::encoder::compression::{CompressionAlgorithm, Deflate, Lzw, Packbits};

pub fn temp_dir() -> tempfile::TempDir {
    tempfile::Builder::new()
        .prefix("dem-test-")
        .tempdir()
        .expect("create a temp dir")
}

pub fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, bytes).expect("write test file");
    path
}

/// Options that set only the spacing, in metres.
pub fn spacing(metres: f64) -> dem::ReadOptions {
    dem::ReadOptions {
        spacing: Some(metres),
        ..dem::ReadOptions::default()
    }
}

/// The grid in one file; panics with the reader's error (which names the file).
pub fn read(path: &Path, opts: &dem::ReadOptions) -> dem::HeightGrid {
    read_mosaic(&[path.to_path_buf()], opts)
}

/// The grid of files read together (an SRTM mosaic); panics with the reader's error.
pub fn read_mosaic(paths: &[PathBuf], opts: &dem::ReadOptions) -> dem::HeightGrid {
    dem::read(paths, opts).unwrap_or_else(|e| panic!("{e}"))
}

/// An SRTM3 tile (1201 x 1201 big-endian samples): every sample `value`, voids (-32768)
/// where `void(x, y)`.
pub fn hgt3(value: i16, void: impl Fn(usize, usize) -> bool) -> Vec<u8> {
    let mut out = Vec::with_capacity(1201 * 1201 * 2);
    for y in 0..1201 {
        for x in 0..1201 {
            let v = if void(x, y) { -32768 } else { value };
            out.extend(v.to_be_bytes());
        }
    }
    out
}

/// Display of the error from reading `paths` with `opts`; panics if the read succeeds.
pub fn read_err(paths: &[PathBuf], opts: &dem::ReadOptions) -> String {
    match dem::read(paths, opts) {
        Ok(g) => panic!(
            "expected an error, got a {}x{} grid ({})",
            g.width, g.height, g.description
        ),
        Err(e) => {
            let s = e.to_string();
            assert!(!s.contains('\n'), "error is not one line: {s:?}");
            s
        }
    }
}

pub fn assert_close(actual: f64, expected: f64, tolerance: f64, what: &str) {
    assert!(
        (actual - expected).abs() <= tolerance,
        "{what}: {actual} is not within {tolerance} of {expected}"
    );
}

/// CRC-32 (IEEE) as PNG chunks use it, to forge headers in tests.
pub fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = 0xFFFF_FFFFu32;
    for &b in bytes {
        crc ^= u32::from(b);
        for _ in 0..8 {
            crc = if crc & 1 != 0 {
                (crc >> 1) ^ 0xEDB8_8320
            } else {
                crc >> 1
            };
        }
    }
    !crc
}

/// Rewrites the width and height in a PNG's IHDR (and its CRC).
pub fn patch_png_size(png: &mut [u8], width: u32, height: u32) {
    assert_eq!(&png[12..16], b"IHDR");
    png[16..20].copy_from_slice(&width.to_be_bytes());
    png[20..24].copy_from_slice(&height.to_be_bytes());
    let crc = crc32(&png[12..29]);
    png[29..33].copy_from_slice(&crc.to_be_bytes());
}

/// Sample data of a test TIFF (already interleaved if more than one sample per pixel).
#[derive(Clone, Debug)]
pub enum Samples {
    U8(Vec<u8>),
    U16(Vec<u16>),
    I16(Vec<i16>),
    I32(Vec<i32>),
    F32(Vec<f32>),
    F64(Vec<f64>),
}

impl Samples {
    fn bits(&self) -> u16 {
        match self {
            Samples::U8(_) => 8,
            Samples::U16(_) | Samples::I16(_) => 16,
            Samples::I32(_) | Samples::F32(_) => 32,
            Samples::F64(_) => 64,
        }
    }

    fn format(&self) -> u16 {
        match self {
            Samples::U8(_) | Samples::U16(_) => 1,
            Samples::I16(_) | Samples::I32(_) => 2,
            Samples::F32(_) | Samples::F64(_) => 3,
        }
    }

    /// Big-endian bytes of sample `i` (the writer reverses them for little-endian files).
    fn be_bytes(&self, i: usize) -> Vec<u8> {
        match self {
            Samples::U8(v) => v[i].to_be_bytes().to_vec(),
            Samples::U16(v) => v[i].to_be_bytes().to_vec(),
            Samples::I16(v) => v[i].to_be_bytes().to_vec(),
            Samples::I32(v) => v[i].to_be_bytes().to_vec(),
            Samples::F32(v) => v[i].to_be_bytes().to_vec(),
            Samples::F64(v) => v[i].to_be_bytes().to_vec(),
        }
    }
}

#[derive(Clone, Copy, Debug)]
pub enum Layout {
    Strips { rows: u32 },
    Tiles { width: u32, height: u32 },
}

#[derive(Clone, Debug)]
pub enum TagValue {
    Short(Vec<u16>),
    Double(Vec<f64>),
    Ascii(String),
}

#[derive(Clone, Debug)]
pub struct TiffSpec {
    pub width: u32,
    pub height: u32,
    pub samples: Samples,
    pub samples_per_pixel: u16,
    pub layout: Layout,
    /// 1 none, 5 LZW, 8 Deflate, 32773 PackBits; anything else is written uncompressed but
    /// labelled with this code (to test refusals).
    pub compression: u16,
    /// 1 none, 2 horizontal (integers), 3 floating point.
    pub predictor: u16,
    pub photometric: u16,
    pub big_endian: bool,
    pub extra_tags: Vec<(u16, TagValue)>,
}

impl TiffSpec {
    pub fn new(width: u32, height: u32, samples: Samples) -> TiffSpec {
        TiffSpec {
            width,
            height,
            samples,
            samples_per_pixel: 1,
            layout: Layout::Strips { rows: 8 },
            compression: 1,
            predictor: 1,
            photometric: 1,
            big_endian: false,
            extra_tags: Vec::new(),
        }
    }

    /// GeoTIFF tags for a geographic grid whose top-left pixel corner is at (lon, lat).
    pub fn geographic(mut self, lon: f64, lat: f64, step_deg: f64) -> TiffSpec {
        self.extra_tags.extend([
            (33550, TagValue::Double(vec![step_deg, step_deg, 0.0])),
            (33922, TagValue::Double(vec![0.0, 0.0, 0.0, lon, lat, 0.0])),
            (
                34735,
                TagValue::Short(vec![1, 1, 0, 2, 1024, 0, 1, 2, 1025, 0, 1, 1]),
            ),
        ]);
        self
    }

    /// GeoTIFF tags for a projected grid in the given linear unit (9001 m, 9002 ft).
    pub fn projected(mut self, step: f64, unit: u16) -> TiffSpec {
        self.extra_tags.extend([
            (33550, TagValue::Double(vec![step, step, 0.0])),
            (
                33922,
                TagValue::Double(vec![0.0, 0.0, 0.0, 500_000.0, 4_000_000.0, 0.0]),
            ),
            (
                34735,
                TagValue::Short(vec![
                    1, 1, 0, 3, 1024, 0, 1, 1, 1025, 0, 1, 1, 3076, 0, 1, unit,
                ]),
            ),
        ]);
        self
    }

    pub fn nodata(mut self, text: &str) -> TiffSpec {
        self.extra_tags
            .push((42113, TagValue::Ascii(text.to_string())));
        self
    }

    pub fn write(&self, path: &Path) {
        std::fs::write(path, self.encode()).expect("write test TIFF");
    }

    pub fn encode(&self) -> Vec<u8> {
        let spp = usize::from(self.samples_per_pixel);
        let bps = usize::from(self.samples.bits() / 8);
        let (w, h) = (self.width as usize, self.height as usize);
        let (cw, ch, across) = match self.layout {
            Layout::Strips { rows } => (w, rows as usize, 1),
            Layout::Tiles { width, height } => {
                (width as usize, height as usize, w.div_ceil(width as usize))
            }
        };
        let down = h.div_ceil(ch);
        let le = !self.big_endian;

        // Chunk bytes: rows of `cw` pixels; strips are cut short at the bottom, tiles padded.
        let mut chunks = Vec::new();
        for ty in 0..down {
            for tx in 0..across {
                let rows = match self.layout {
                    Layout::Strips { .. } => ch.min(h - ty * ch),
                    Layout::Tiles { .. } => ch,
                };
                let mut chunk = Vec::new();
                for r in 0..rows {
                    let y = ty * ch + r;
                    let mut row = Vec::with_capacity(cw * spp * bps);
                    for c in 0..cw {
                        let x = tx * cw + c;
                        for s in 0..spp {
                            if x < w && y < h {
                                let mut b = self.samples.be_bytes((y * w + x) * spp + s);
                                if le {
                                    b.reverse();
                                }
                                row.extend(b);
                            } else {
                                row.extend(std::iter::repeat_n(0, bps));
                            }
                        }
                    }
                    self.predict(&mut row, spp, bps);
                    chunk.extend(row);
                }
                chunks.push(self.compress(&chunk));
            }
        }

        let mut out = Vec::new();
        out.extend(if le { b"II\x2a\x00" } else { b"MM\x00\x2a" });
        out.extend([0; 4]); // IFD offset, patched below
        let mut offsets = Vec::new();
        for c in &chunks {
            offsets.push(out.len() as u32);
            out.extend(c);
        }
        let counts: Vec<u32> = chunks.iter().map(|c| c.len() as u32).collect();

        enum V {
            S(Vec<u16>),
            L(Vec<u32>),
            D(Vec<f64>),
            A(Vec<u8>),
        }
        let mut tags: Vec<(u16, V)> = vec![
            (256, V::L(vec![self.width])),
            (257, V::L(vec![self.height])),
            (258, V::S(vec![self.samples.bits(); spp])),
            (259, V::S(vec![self.compression])),
            (262, V::S(vec![self.photometric])),
            (277, V::S(vec![self.samples_per_pixel])),
            (284, V::S(vec![1])),
            (317, V::S(vec![self.predictor])),
            (339, V::S(vec![self.samples.format(); spp])),
        ];
        match self.layout {
            Layout::Strips { rows } => tags.extend([
                (273, V::L(offsets)),
                (278, V::L(vec![rows])),
                (279, V::L(counts)),
            ]),
            Layout::Tiles { width, height } => tags.extend([
                (322, V::L(vec![width])),
                (323, V::L(vec![height])),
                (324, V::L(offsets)),
                (325, V::L(counts)),
            ]),
        }
        for (tag, value) in &self.extra_tags {
            tags.push((
                *tag,
                match value {
                    TagValue::Short(v) => V::S(v.clone()),
                    TagValue::Double(v) => V::D(v.clone()),
                    TagValue::Ascii(s) => {
                        let mut b = s.as_bytes().to_vec();
                        b.push(0);
                        V::A(b)
                    }
                },
            ));
        }
        tags.sort_by_key(|(t, _)| *t);

        let u16b = |v: u16| if le { v.to_le_bytes() } else { v.to_be_bytes() };
        let u32b = |v: u32| if le { v.to_le_bytes() } else { v.to_be_bytes() };
        if out.len() % 2 == 1 {
            out.push(0);
        }
        let ifd = out.len() as u32;
        out[4..8].copy_from_slice(&u32b(ifd));
        let mut extra = Vec::new();
        let extra_start = ifd as usize + 2 + 12 * tags.len() + 4;
        let mut entries = Vec::new();
        entries.extend(u16b(tags.len() as u16));
        for (tag, value) in &tags {
            let (ty, count, bytes): (u16, usize, Vec<u8>) = match value {
                V::S(v) => (3, v.len(), v.iter().flat_map(|&x| u16b(x)).collect()),
                V::L(v) => (4, v.len(), v.iter().flat_map(|&x| u32b(x)).collect()),
                V::D(v) => (
                    12,
                    v.len(),
                    v.iter()
                        .flat_map(|&x| if le { x.to_le_bytes() } else { x.to_be_bytes() })
                        .collect(),
                ),
                V::A(v) => (2, v.len(), v.clone()),
            };
            entries.extend(u16b(*tag));
            entries.extend(u16b(ty));
            entries.extend(u32b(count as u32));
            if bytes.len() <= 4 {
                let mut b = bytes.clone();
                b.resize(4, 0);
                entries.extend(b);
            } else {
                if extra.len() % 2 == 1 {
                    extra.push(0);
                }
                entries.extend(u32b((extra_start + extra.len()) as u32));
                extra.extend(bytes);
            }
        }
        entries.extend([0; 4]); // no next IFD
        out.extend(entries);
        out.extend(extra);
        out
    }

    /// TIFF predictors, applied per chunk row in file byte order.
    fn predict(&self, row: &mut [u8], spp: usize, bps: usize) {
        let le = !self.big_endian;
        match self.predictor {
            2 => {
                // Horizontal differencing of integer samples (wrapping).
                let n = row.len() / bps;
                let get = |row: &[u8], i: usize| -> u64 {
                    let b = &row[i * bps..(i + 1) * bps];
                    let mut v = 0u64;
                    for k in 0..bps {
                        let byte = if le { b[bps - 1 - k] } else { b[k] };
                        v = (v << 8) | u64::from(byte);
                    }
                    v
                };
                let vals: Vec<u64> = (0..n).map(|i| get(row, i)).collect();
                let mask = if bps == 8 {
                    u64::MAX
                } else {
                    (1u64 << (8 * bps)) - 1
                };
                for i in (spp..n).rev() {
                    let d = vals[i].wrapping_sub(vals[i - spp]) & mask;
                    let bytes = d.to_be_bytes();
                    let b = &bytes[8 - bps..];
                    for k in 0..bps {
                        row[i * bps + k] = if le { b[bps - 1 - k] } else { b[k] };
                    }
                }
            }
            3 => {
                // TIFF Technical Note 3: bytes of each float, most significant first, split
                // into planes across the row, then differenced byte by byte.
                let n = row.len() / bps;
                let mut planes = vec![0u8; row.len()];
                for i in 0..n {
                    for k in 0..bps {
                        let byte = if le {
                            row[i * bps + bps - 1 - k]
                        } else {
                            row[i * bps + k]
                        };
                        planes[k * n + i] = byte;
                    }
                }
                for i in (spp..planes.len()).rev() {
                    planes[i] = planes[i].wrapping_sub(planes[i - spp]);
                }
                row.copy_from_slice(&planes);
            }
            _ => {}
        }
    }

    fn compress(&self, bytes: &[u8]) -> Vec<u8> {
        let mut out = Vec::new();
        match self.compression {
            5 => Lzw.write_to(&mut out, bytes),
            8 => Deflate::default().write_to(&mut out, bytes),
            32773 => Packbits.write_to(&mut out, bytes),
            50000 => {
                out = zstd::encode_all(bytes, 3).expect("zstd");
                Ok(0)
            }
            _ => {
                out.extend_from_slice(bytes);
                Ok(0)
            }
        }
        .expect("compress test chunk");
        out
    }
}
