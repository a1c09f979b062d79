//! A tile drawn part by part (`tiles::parts`) on real data: with every part at one level the
//! mixed mesh is that level's stored mesh, fan for fan; with parts at different levels it is
//! conforming (no T-junction: every inner edge is shared by two triangles), its outer border
//! (where it meets its neighbours) is the top level's, and it is never longer than the top
//! level's array (the renderer sizes the array's room by it). The control: the stored meshes of two levels spliced part by part
//! have T-junctions, and the check finds them.

mod common;

use std::collections::HashMap;

use tiles::format::Tile;
use tiles::pack::unpack;
use tiles::parts::{Blocks, PartKey, PartLevels, RESTART};
use tiles::TileSet;

/// 3 x 2 tiles, the third column and the second row partial, 9 levels, shared sides.
fn set(dir: &std::path::Path) -> TileSet {
    let out = common::relief_set(dir, (2 * 256 + 1 + 140, 257 + 100));
    TileSet::open(&out).expect("open")
}

fn blocks(tile: &Tile) -> Blocks {
    let n = tile.levels().len() as u32;
    let positions: Vec<&[u32]> = (0..n)
        .map(|j| tile.level(j).expect("level").positions)
        .collect();
    Blocks::new(positions, (tile.header.mesh_max_x, tile.header.mesh_max_y))
}

/// The fans of an index array: centre, and the ring without its closing repeat, rotated to
/// start at its smallest vertex (so rings compare whatever corner they start at).
fn fans(indices: impl Iterator<Item = Option<u32>>) -> Vec<(u32, Vec<u32>)> {
    let mut out = Vec::new();
    let mut cur: Vec<u32> = Vec::new();
    let mut close = |cur: &mut Vec<u32>| {
        if cur.is_empty() {
            return;
        }
        let mut ring = cur[1..cur.len() - 1].to_vec();
        let k = (0..ring.len()).min_by_key(|&k| ring[k]).unwrap_or(0);
        ring.rotate_left(k);
        out.push((cur[0], ring));
        cur.clear();
    };
    for i in indices {
        match i {
            Some(v) => cur.push(v),
            None => close(&mut cur),
        }
    }
    close(&mut cur);
    out
}

fn mixed(indices: &[u32]) -> impl Iterator<Item = Option<u32>> + '_ {
    indices.iter().map(|&i| (i != RESTART).then_some(i))
}

type Point = (u32, u32);

/// Every vertex's lattice point, blocks `0..` in order.
fn points(tile: &Tile) -> Vec<Point> {
    (0..tile.levels().len() as u32)
        .flat_map(|j| tile.level(j).expect("level").positions.to_vec())
        .map(|p| {
            let (x, y, _) = unpack(p);
            (x, y)
        })
        .collect()
}

/// Edges of the triangles of `fans` (lattice points) used once only, other than on the mesh's
/// outline: each is a T-junction or a hole.
fn open_edges(fans: &[(u32, Vec<u32>)], points: &[(u32, u32)], mesh_max: (u32, u32)) -> usize {
    let mut edges: HashMap<(Point, Point), i32> = HashMap::new();
    for (c, ring) in fans {
        for k in 0..ring.len() {
            let tri = [
                points[*c as usize],
                points[ring[k] as usize],
                points[ring[(k + 1) % ring.len()] as usize],
            ];
            for e in 0..3 {
                let (a, b) = (tri[e], tri[(e + 1) % 3]);
                let key = if a < b { (a, b) } else { (b, a) };
                *edges.entry(key).or_default() += 1;
            }
        }
    }
    let outline = |a: (u32, u32), b: (u32, u32)| {
        (a.0 == b.0 && (a.0 == 0 || a.0 == mesh_max.0))
            || (a.1 == b.1 && (a.1 == 0 || a.1 == mesh_max.1))
    };
    edges
        .iter()
        .filter(|(&(a, b), &n)| n != 2 && !(n == 1 && outline(a, b)))
        .count()
}

/// Parts at levels drawn from a simple generator, the top level at one of them.
fn wanted(seed: u64, levels: u8) -> PartLevels {
    let mut s = seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1;
    std::array::from_fn(|_| {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s % u64::from(levels)) as u8
    })
}

#[test]
fn parts_at_one_level_make_that_level_and_mixed_parts_make_a_conforming_mesh() {
    let dir = tempfile::tempdir().expect("temp dir");
    let set = set(dir.path());
    let (mut mixed_keys, mut differing, mut fewer, mut refused) = (0, 0, 0, 0);
    let (mut counted, mut uncounted) = (0, 0);
    for ty in 0..2 {
        for tx in 0..3 {
            let tile = set.tile(tx, ty).expect("tile");
            let n = tile.levels().len() as u32;
            let b = blocks(&tile);
            let points = points(&tile);
            let mesh_max = (tile.header.mesh_max_x, tile.header.mesh_max_y);
            for level in 0..n {
                let stored = fans(tile.level(level).expect("level").indices.iter());
                let key = PartKey {
                    levels: [level as u8; 16],
                };
                let made = b.indices(&key).expect("the blocks make the mesh");
                assert_eq!(fans(mixed(&made)), stored, "tile {tx},{ty} level {level}");
            }
            let (_, counts) = tiles::parts::tables(&tile);
            for seed in 0..60u64 {
                let top = n - 1 - (seed % 3) as u32;
                let Some(key) = b.key(&wanted(seed + 100 * u64::from(tx + 3 * ty), n as u8), top)
                else {
                    refused += 1;
                    continue;
                };
                if key.levels.iter().all(|&l| l == key.levels[0]) {
                    continue;
                }
                mixed_keys += 1;
                let g = u32::from(*key.levels.iter().max().expect("16 parts"));
                let made = b.indices(&key).expect("the blocks make the mixed mesh");
                let made_fans = fans(mixed(&made));
                let triangles: usize = made_fans.iter().map(|(_, ring)| ring.len()).sum();
                match counts.count(&key) {
                    Some(c) => {
                        assert_eq!(
                            c,
                            (made.len() as u32, triangles as u32),
                            "tables, key {:?}",
                            key.levels
                        );
                        counted += 1;
                    }
                    None => uncounted += 1,
                }
                assert_eq!(
                    open_edges(&made_fans, &points, mesh_max),
                    0,
                    "tile {tx},{ty} key {:?}: T-junctions",
                    key.levels
                );
                let top_level = tile.level(g).expect("level");
                assert!(
                    made.len() <= top_level.indices.len(),
                    "longer than level {g}'s array"
                );
                // On a whole tile, where the coarsest part's level draws less than the top, so
                // does the mix (on a partial one, parts past the mesh draw nothing at any level).
                let least = u32::from(*key.levels.iter().min().expect("16 parts"));
                // (A flat tile draws a few fans at every level.)
                let whole = mesh_max == (256, 256) && top_level.indices.len() > 2000;
                if whole
                    && tile.level(least).expect("level").indices.len() < top_level.indices.len()
                {
                    differing += 1;

                    fewer += usize::from(made.len() < top_level.indices.len());
                }
                // The tile's outer border is level g's: every vertex of level g on it is in
                // the mesh, and no other vertex on it. (A partial tile's last column or row is
                // the grid's edge, which no neighbour shares and which lies inside its parts:
                // it takes their levels, as inside.)
                let edge = 256;
                let on_border = |&(x, y): &(u32, u32)| x == 0 || y == 0 || x == edge || y == edge;
                let mut used: Vec<u32> = made.iter().copied().filter(|&i| i != RESTART).collect();
                used.sort_unstable();
                used.dedup();
                let border: Vec<u32> = used
                    .iter()
                    .copied()
                    .filter(|&i| on_border(&points[i as usize]))
                    .collect();
                let mut expected: Vec<u32> = top_level
                    .border
                    .iter()
                    .flat_map(|s| s.to_vec())
                    .filter(|&i| on_border(&points[i as usize]))
                    .collect();
                expected.sort_unstable();
                expected.dedup();
                assert_eq!(
                    border, expected,
                    "tile {tx},{ty}: the border is not level {g}'s"
                );
            }
        }
    }
    assert!(mixed_keys > 100, "{mixed_keys} mixed keys");
    assert!(
        differing > 40,
        "{differing} keys whose levels draw differently"
    );
    assert_eq!(
        fewer, differing,
        "a mix of finer and coarser parts drew no less than the finest"
    );
    assert!(
        counted * 10 > mixed_keys * 9,
        "{counted} of {mixed_keys} counted by the tables"
    );
    println!(
        "{mixed_keys} mixed keys, {fewer} shorter than the top level, {refused} refused, \
         {counted} counted by the tables ({uncounted} not)"
    );
}

/// The control: the stored fans of level `a` in part 0 and of level `b` elsewhere, spliced, have
/// T-junctions where the parts meet, and the check above finds them.
#[test]
fn spliced_levels_have_t_junctions_and_the_check_finds_them() {
    let dir = tempfile::tempdir().expect("temp dir");
    let set = set(dir.path());
    let tile = set.tile(0, 0).expect("tile");
    let n = tile.levels().len() as u32;
    let points = points(&tile);
    let in_part0 = |c: u32| points[c as usize].0 < 64 && points[c as usize].1 < 64;
    let fine = fans(tile.level(n - 1).expect("level").indices.iter());
    let coarse = fans(tile.level(n - 4).expect("level").indices.iter());
    let spliced: Vec<(u32, Vec<u32>)> = fine
        .into_iter()
        .filter(|(c, _)| in_part0(*c))
        .chain(coarse.into_iter().filter(|(c, _)| !in_part0(*c)))
        .collect();
    let mesh_max = (tile.header.mesh_max_x, tile.header.mesh_max_y);
    assert!(open_edges(&spliced, &points, mesh_max) > 0);
}

/// The part tables of a tile's first `n` levels (`tables_through`, what a renderer holds for
/// the levels it has checked) count every key within those levels as the whole tile's tables
/// do, and no key past them (the control: the whole tables count those). Grown from there to
/// every level (`counts_through`, as the renderer grows them when it checks a finer level),
/// they count every key as the whole tables do.
#[test]
fn the_first_levels_tables_count_as_the_whole_tiles_do() {
    let dir = tempfile::tempdir().expect("temp dir");
    let set = set(dir.path());
    let (mut within, mut past) = (0, 0);
    for ty in 0..2 {
        for tx in 0..3 {
            let tile = set.tile(tx, ty).expect("tile");
            let levels = tile.levels().len() as u32;
            let b = blocks(&tile);
            let (_, whole) = tiles::parts::tables(&tile);
            // The same counts made from the tile's blocks, as the index builder's check makes
            // them.
            let arrays: Vec<_> = (0..levels).filter_map(|j| tile.level(j)).collect();
            let direct = tiles::parts::Counts::new(&b, arrays.iter().map(|l| l.indices.iter()));
            for n in 1..=levels {
                let (_, first) = tiles::parts::tables_through(&tile, n);
                let grown = tiles::parts::counts_through(&tile, &first, levels);
                assert_eq!(grown.levels(), levels);
                for seed in 0..30u64 {
                    let top = (seed % u64::from(levels)) as u32;
                    let Some(key) = b.key(&wanted(seed * 7 + u64::from(n), levels as u8), top)
                    else {
                        continue;
                    };
                    let g = u32::from(*key.levels.iter().max().expect("16 parts"));
                    assert_eq!(
                        grown.count(&key),
                        whole.count(&key),
                        "{tx},{ty} grown from {n}"
                    );
                    assert_eq!(
                        direct.count(&key),
                        whole.count(&key),
                        "{tx},{ty} from blocks"
                    );
                    if g < n {
                        assert_eq!(first.count(&key), whole.count(&key), "{tx},{ty} n {n}");
                        within += 1;
                    } else {
                        assert_eq!(first.count(&key), None, "{tx},{ty} n {n}: past its levels");
                        assert!(whole.count(&key).is_some(), "the control");
                        past += 1;
                    }
                }
            }
        }
    }
    assert!(
        within > 100 && past > 100,
        "{within} keys within, {past} past"
    );
}
