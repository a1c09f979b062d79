//! The vertex hierarchy the morph pass walks (module header of [`crate::morph`], "The morph"):
//! each vertex's scale and its two parents, the checks that every placed vertex's parents are
//! drawn with it, and the CPU mirror of `morph.comp`'s placement.

use super::{MorphRule, TileMorph};

/// Samples per tile side.
const SIDE: usize = 257;

pub use tiles::compact::{parents, scale_of};

/// The vertices of blocks `0..=level` of `tile`: `(x, y, block)` in index order.
pub fn block_points(tile: &tiles::format::Tile, level: u32) -> Vec<(u32, u32, usize)> {
    (0..=level)
        .map_while(|j| tile.level(j))
        .enumerate()
        .flat_map(|(j, b)| {
            b.positions.iter().map(move |&p| {
                let (x, y, _) = tiles::pack::unpack(p);
                (x, y, j)
            })
        })
        .collect()
}

/// The first of `points` (`(x, y, block)`, a tile's vertices) of block 1 or later whose
/// parents are not both among them in its block or an earlier one, if any (block 0 is at its
/// own height and needs none). The morph reads every placed vertex's parents; the meshes
/// guarantee them (a leaf's fan holds its corners, a cell straddling the mesh's extent is
/// split in block 0), and the tests check it on real tile sets.
pub fn orphan(points: &[(u32, u32, usize)]) -> Option<(u32, u32, usize)> {
    let mut block = vec![usize::MAX; SIDE * SIDE];
    for &(x, y, j) in points {
        block[y as usize * SIDE + x as usize] = j;
    }
    points.iter().copied().find(|&(x, y, j)| {
        let before = |(px, py): (u32, u32)| block[py as usize * SIDE + px as usize] <= j;
        j > 0 && !parents(x, y).is_some_and(|[a, b]| before(a) && before(b))
    })
}

/// The level a placed vertex of block `j` passes to its children (module header, "Within a
/// block"): its level `l` held to its own block, `clamp(l, j - 1, j)`. A child of the same
/// block takes at least the parent's weight from it; a child of a finer block takes nothing
/// (the held level is at most `j`, and a finer block's weight starts at `j`).
pub fn held_level(l: f32, j: usize) -> f32 {
    l.clamp(j as f32 - 1.0, j as f32)
}

/// The morph pass's placement of blocks `0..=level` (module header), as `morph.comp` computes
/// it, into `vertices` (index order): heights and their slopes. Drawn part by part, only the
/// vertices the mix holds are placed (the others stay at their own heights, undrawn); a mesh
/// holds every vertex's parents (they are corners of its cell, or the ends of its cell's
/// edge), so no placed vertex reads an unplaced one. Each vertex takes the larger of its own
/// level and its parents' held levels ([`held_level`]), unless the rule is
/// [`MorphRule::OwnLevels`] (the rule before, kept as a control). Returns each vertex's
/// weight `w` in index order: 1 in block 0, 0 where not placed.
pub(super) fn hierarchical(
    tile: &tiles::format::Tile,
    level: u32,
    morph: &TileMorph,
    (units, bias): (&[f32], i8),
    vertices: &mut [(u32, u32, f32, f32)],
) -> Vec<f32> {
    let mut weights = vec![0.0f32; vertices.len()];
    // Per grid point: own height, morphed height, slope, and the level passed to children.
    let mut grid = vec![(f32::NAN, f32::NAN, 0.0f32, 0.0f32); SIDE * SIDE];
    // Per vertex of blocks 1..: its index, block and level; by scale, coarsest first.
    let mut by_scale: [Vec<(usize, usize, f32)>; 9] = Default::default();
    let base = tile.header.height_base;
    let inherit = morph.rule != MorphRule::OwnLevels;
    let mut start = 0usize;
    for (j, block) in (0..=level).map_while(|j| tile.level(j)).enumerate() {
        for (i, &p) in block.positions.iter().enumerate() {
            let (x, y, code) = tiles::pack::unpack(p);
            let own = (base + code as i32) as f32 * morph.height_step;
            grid[y as usize * SIDE + x as usize] = (own, own, 0.0, 0.0);
            vertices[start + i].2 = own;
            if j == 0 {
                weights[start + i] = 1.0;
            }
            let held = morph
                .parts
                .is_none_or(|key| j <= usize::from(tiles::parts::presence_level(&key, x, y)));
            if j > 0 && held {
                let l = morph.placed(x, y, own);
                let s = scale_of(x, y).trailing_zeros().min(8) as usize;
                by_scale[s].push((start + i, j, l));
            }
        }
        start += block.positions.len();
    }
    for bucket in by_scale.iter().rev() {
        for &(index, j, l) in bucket {
            let (x, y, _, _) = vertices[index];
            let at = y as usize * SIDE + x as usize;
            let own = grid[at].0;
            let Some([p, q]) = parents(x, y) else {
                continue;
            };
            let (a, b) = (
                grid[p.1 as usize * SIDE + p.0 as usize],
                grid[q.1 as usize * SIDE + q.0 as usize],
            );
            // At least what its parents pass on, no further than the coarsest part holding
            // it draws (module header); the parts are looked up only where that raises it.
            let passed = a.3.max(b.3);
            let l = match inherit && passed > l {
                true => {
                    let bound = morph.parts.map_or(level, |key| {
                        u32::from(tiles::parts::coarsest_level(&key, x, y))
                    });
                    l.max(passed.min(bound as f32))
                }
                false => l,
            };
            let unit = units.get(j - 1).copied().unwrap_or(0.0);
            let detail = own - 0.5 * (a.0 + b.0) + f32::from(bias) * unit;
            let w = (l - j as f32 + 1.0).clamp(0.0, 1.0);
            let m = 0.5 * (a.1 + b.1) + w * detail;
            let slope = detail.abs() + 0.5 * (a.2 + b.2);
            grid[at] = (own, m, slope, held_level(l, j));
            vertices[index].2 = m;
            vertices[index].3 = slope;
            weights[index] = w;
        }
    }
    weights
}
