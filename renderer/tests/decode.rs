//! Compact levels decoded on the GPU (`vulkan::decode`, lavapipe, validation on) against the
//! CPU decoder (`tiles::compact::decode_levels`): every level of every tile of the Puget
//! sample and of an SRTM3 tile (partial tiles at the data's edge, whose cut cells send raw
//! vertices), decoded level by level from the coarser blocks the GPU decoded before, equals
//! the CPU's block word for word, and the file's block (which numbers its vertices in the
//! order the stream decodes them). The controls: a residual
//! changed in a stream is decoded by both to the same other heights (the GPU follows the
//! stream, not the file); a stream cut short and a wrong vertex count are refused with the
//! tile and level.

use std::io::Write as _;
use std::ops::Range;

use renderer::vulkan::buffer::BufferDesc;
use renderer::vulkan::decode::{Decode, DecodeFailure, Decoder, MAX_DECODES_PER_DISPATCH};
use renderer::vulkan::pool::TilePool;
use renderer::vulkan::{sync, Buffer, Gpu, GpuOptions};
use tiles::compact;
use tiles::pack::pack;
use tiles::TileSet;

mod common;

const POOL_BYTES: u64 = 24 << 20;
const STREAM_BYTES: u64 = 8 << 20;

/// One tile's compact levels, and what the CPU makes of them.
#[derive(Clone)]
struct Case {
    tile: u32,
    stream: Vec<u8>,
    ranges: Vec<Range<usize>>,
    /// Per level, the CPU decoder's block, packed, in its order.
    blocks: Vec<Vec<u32>>,
    /// Per level, the file's block.
    file: Vec<Vec<u32>>,
}

impl Case {
    /// Tile `t` of `set` as the compact encoder writes it, decoded on the CPU.
    fn of(set: &TileSet, t: u32) -> Case {
        let tiles_x = set.header().tiles_x;
        let tile = set.tile(t % tiles_x, t / tiles_x).expect("tile");
        let stream = compact::encode(&tile);
        let file: Vec<Vec<u32>> = (0..tile.header.levels)
            .map(|j| tile.level(j).expect("level").positions.to_vec())
            .collect();
        let mut case = Case {
            tile: t,
            stream,
            ranges: Vec::new(),
            blocks: Vec::new(),
            file,
        };
        case.decode_on_cpu().expect("the encoder's stream decodes");
        case
    }

    fn decode_on_cpu(&mut self) -> Result<(), String> {
        let (sets, ranges) = compact::decode_levels(&self.stream, self.file.len() as u32)?;
        self.blocks = sets
            .iter()
            .map(|set| set.iter().map(|&(x, y, c)| pack(x, y, c)).collect())
            .collect();
        self.ranges = ranges;
        Ok(())
    }

    fn levels(&self) -> u32 {
        self.file.len() as u32
    }

    /// Where block `j` starts among the tile's vertices.
    fn block_start(&self, j: u32) -> u32 {
        self.file[..j as usize].iter().map(|b| b.len() as u32).sum()
    }

    fn vertex_count(&self) -> u32 {
        self.block_start(self.levels())
    }
}

struct Bench {
    gpu: Gpu,
    pool: TilePool,
    streams: Buffer,
    decoder: Decoder,
}

impl Bench {
    /// The device's bench, or `None` (and why, on stderr) on a device the test does not apply
    /// to: it writes the pool from the CPU, which lavapipe allows (asserted there).
    fn new() -> Option<Bench> {
        let gpu = Gpu::new(&GpuOptions {
            validation: true,
            ..Default::default()
        })
        .expect("Vulkan device");
        let pool = TilePool::new(&gpu, POOL_BYTES, false).expect("pool");
        if gpu.device_name.starts_with("llvmpipe") {
            assert!(pool.direct(), "lavapipe's memory is host-visible");
        } else if !pool.direct() {
            notice(&format!(
                "decode: DOES NOT APPLY to {} (not lavapipe), nothing was checked: the test \
                 writes the pool from the CPU; run it on lavapipe \
                 (VK_ICD_FILENAMES=/usr/share/vulkan/icd.d/lvp_icd.x86_64.json)",
                gpu.device_name
            ));
            pool.destroy(&gpu);
            return None;
        }
        let streams = Buffer::new(
            &gpu,
            BufferDesc::upload(STREAM_BYTES, ash::vk::BufferUsageFlags::STORAGE_BUFFER),
            "test streams",
        )
        .expect("streams");
        let decoder = Decoder::new(
            &gpu,
            &pool.buffer,
            &[&streams],
            64,
            MAX_DECODES_PER_DISPATCH,
        )
        .expect("decoder");
        Some(Bench {
            gpu,
            pool,
            streams,
            decoder,
        })
    }

    /// Decodes every level of `cases` on the GPU, a level of every tile per submission (a
    /// level reads the coarser blocks decoded before it), each tile in a region of its own
    /// filled with stale words first; `tamper` may change a decode. Returns each case's
    /// blocks as the GPU wrote them, and the failures reported, by level.
    fn decode(
        &mut self,
        cases: &[Case],
        tamper: impl Fn(&Case, &mut Decode),
    ) -> (Vec<Vec<Vec<u32>>>, Vec<DecodeFailure>) {
        let (mut word, mut bit) = (0u32, 0u64);
        let mut regions = Vec::new();
        for case in cases {
            assert!(self.pool.write(
                u64::from(word) * 4,
                &vec![0x5a; case.vertex_count() as usize * 4]
            ));
            let at = bit / 8;
            assert!(self.streams.write(at as usize, &case.stream));
            regions.push((word, bit));
            word += case.vertex_count();
            // The next stream starts on a word, a word past this one's end.
            bit = ((at + case.stream.len() as u64).div_ceil(4) + 1) * 32;
        }
        assert!(u64::from(word) * 4 <= POOL_BYTES && bit / 8 <= STREAM_BYTES);
        let mut failures = Vec::new();
        let levels = cases.iter().map(Case::levels).max().unwrap_or(0);
        for j in 0..levels {
            let decodes: Vec<Decode> = cases
                .iter()
                .zip(&regions)
                .filter(|(case, _)| j < case.levels())
                .map(|(case, &(word, bit))| {
                    let r = &case.ranges[j as usize];
                    let mut d = Decode {
                        stream_bit: (bit + 8 * r.start as u64) as u32,
                        end_bit: (bit + 8 * r.end as u64) as u32,
                        known_word: word,
                        known_count: case.block_start(j),
                        out_word: word + case.block_start(j),
                        expected: case.file[j as usize].len() as u32,
                        tile: case.tile,
                        level: j,
                    };
                    tamper(case, &mut d);
                    d
                })
                .collect();
            assert!(self.decoder.write(0, &decodes));
            let (gpu, decoder) = (&self.gpu, &self.decoder);
            let host = (
                ash::vk::PipelineStageFlags::HOST,
                ash::vk::AccessFlags::HOST_READ,
            );
            sync::run_once(gpu, "decodes", |cmd| {
                decoder.record(gpu, cmd, (0, &[decodes.len() as u32]), host)
            })
            .expect("decodes run");
            failures.extend(self.decoder.take_failure(0));
        }
        let blocks = cases
            .iter()
            .zip(&regions)
            .map(|(case, &(word, _))| {
                let bytes = self
                    .pool
                    .read(
                        &self.gpu,
                        u64::from(word) * 4,
                        u64::from(case.vertex_count()) * 4,
                    )
                    .expect("read back");
                let words: Vec<u32> = bytemuck::pod_collect_to_vec(&bytes);
                (0..case.levels())
                    .map(|j| {
                        let s = case.block_start(j) as usize;
                        words[s..s + case.file[j as usize].len()].to_vec()
                    })
                    .collect()
            })
            .collect();
        (blocks, failures)
    }
}

impl Bench {
    fn destroy(self) {
        self.decoder.destroy(&self.gpu);
        self.streams.destroy(&self.gpu);
        self.pool.destroy(&self.gpu);
    }
}

/// Writes `message` to the process's stderr itself: whether the test applied must show in
/// every run, not only when it fails.
fn notice(message: &str) {
    let _ = writeln!(std::io::stderr(), "{message}");
}

/// Every level of every tile of `set` decodes on the GPU as on the CPU; returns the cases and
/// the vertices compared.
fn check_every_level(bench: &mut Bench, set: &TileSet) -> (Vec<Case>, usize) {
    let h = set.header();
    let cases: Vec<Case> = (0..h.tiles_x * h.tiles_y)
        .map(|t| Case::of(set, t))
        .collect();
    let mut vertices = 0;
    for batch in cases.chunks(16) {
        let (blocks, failures) = bench.decode(batch, |_, _| {});
        assert_eq!(failures, vec![], "a valid stream was refused");
        for (case, got) in batch.iter().zip(&blocks) {
            for (j, (got, cpu)) in got.iter().zip(&case.blocks).enumerate() {
                assert_eq!(
                    got, cpu,
                    "tile {} level {j}: the GPU's block is not the CPU's",
                    case.tile
                );
                // Files number a block's vertices as its stream decodes them
                // (`tiles::build::Numbering::Decode`), so the block is the file's, in order.
                assert_eq!(
                    got, &case.file[j],
                    "tile {} level {j}: not the file's block",
                    case.tile
                );
                vertices += got.len();
            }
        }
    }
    (cases, vertices)
}

#[test]
fn every_level_decodes_on_the_gpu_as_on_the_cpu() {
    let Some(mut bench) = Bench::new() else {
        return;
    };
    let dir = tempfile::tempdir().expect("temp dir");
    let puget = TileSet::open(&common::puget(dir.path())).expect("open");
    let (cases, n) = check_every_level(&mut bench, &puget);
    assert!(n > 500_000, "{n} vertices compared");
    let srtm_dir = tempfile::tempdir().expect("temp dir");
    let srtm = common::tileset(
        srtm_dir.path(),
        &common::data("srtm/N43E007.hgt"),
        dem::ReadOptions::default(),
    );
    let srtm = TileSet::open(&srtm).expect("open");
    let (srtm_cases, m) = check_every_level(&mut bench, &srtm);
    // Raw vertices past the tiles' four corners: where the data's edge cuts cells.
    let raw: usize = srtm_cases
        .iter()
        .flat_map(|c| {
            c.ranges.iter().map(|r| {
                usize::from(u16::from_le_bytes([
                    c.stream[r.start],
                    c.stream[r.start + 1],
                ]))
            })
        })
        .sum();
    notice(&format!(
        "decode: {n} Puget and {m} SRTM vertices decoded on the GPU as on the CPU; \
         {raw} raw vertices in the SRTM tiles"
    ));
    assert!(
        raw > 4 * srtm_cases.len(),
        "{raw} raw vertices: the partial tiles' path went untested"
    );

    // The control: a residual changed. Flip bits from the end of the largest tile's finest
    // level until the CPU decodes another, valid, stream (same level ranges): the GPU must
    // follow it to the same other heights.
    let big = cases
        .iter()
        .max_by_key(|c| c.vertex_count())
        .expect("a tile")
        .clone();
    let last = big.levels() as usize - 1;
    let changed = (0..8 * (big.ranges[last].len() - 8))
        .map(|b| 8 * big.ranges[last].end - 9 - b)
        .find_map(|b| {
            let mut case = big.clone();
            case.stream[b / 8] ^= 1 << (b % 8);
            let ok = case.decode_on_cpu().is_ok()
                && case.ranges == big.ranges
                && case.blocks[last] != big.blocks[last];
            ok.then_some(case)
        })
        .expect("a residual bit whose change still decodes");
    let (blocks, failures) = bench.decode(std::slice::from_ref(&changed), |_, _| {});
    assert_eq!(failures, vec![]);
    assert_ne!(blocks[0][last], big.blocks[last], "the change went unseen");
    assert_eq!(
        blocks[0][last], changed.blocks[last],
        "the GPU and CPU read the changed stream differently"
    );

    // A stream cut short by a byte, and a block one vertex short, are refused with their
    // tile and level.
    let one = std::slice::from_ref(&big);
    let level = last as u32;
    let (_, failures) = bench.decode(one, |_, d| {
        if d.level == level {
            d.end_bit -= 8;
        }
    });
    assert_eq!(failures.len(), 1, "{failures:?}");
    assert_eq!((failures[0].tile, failures[0].level), (big.tile, level));
    let (_, failures) = bench.decode(one, |_, d| {
        if d.level == level {
            d.expected -= 1;
        }
    });
    assert_eq!(failures.len(), 1, "{failures:?}");
    assert_eq!((failures[0].tile, failures[0].level), (big.tile, level));
    notice(&format!(
        "decode: refusals {:?}",
        failures.iter().map(|f| f.reason).collect::<Vec<_>>()
    ));
    bench.destroy();
}
