//! Geomorphing (paper, section 5, figure 6): the per-vertex level rule, the placement of
//! every drawn vertex from it (the morph pass, `spirv/shaders/morph.comp`), and the CPU mirror
//! of that arithmetic, so that tests and the error meter can check the surface the GPU draws
//! (and a test reads that surface back to check this mirror).
//!
//! # The level of a vertex
//!
//! Every vertex `v` gets a continuous level from where it is and from the camera alone:
//!
//! ```text
//! l(v) = Λ(τ / S(v)),   S(v) = |J z| at v = (x, y, own height), relative to the camera,
//! ```
//!
//! `|J z|` being the pixels a vertical metre at `v` spans on screen (the Jacobian of the
//! projection applied to world up; formula in [`crate::lod`]), and `Λ` the inverse of the
//! set's error function below. Two tiles holding the same grid point compute `l` from the same
//! integers (its sample column and row relative to the camera's tile, its height code on the
//! set's shared lattice) with the same instructions, so they get the same level bit for bit,
//! with no maximum over neighbours and nothing carried between tiles. Where `|J z|` is small
//! (far away, or seen from above) the level is coarse, where it is large it is fine, within
//! one tile as across tiles: a tile's far side morphs towards coarser levels while its near
//! side does not.
//!
//! # The error of a blend, and `Λ`
//!
//! Between levels `k` and `k + 1` at weight `t` (`l = k + t`) a vertex sits at
//! `(1 - t) S_k(v) + t S_(k+1)(v)`, `S_k` the level-`k` surface (levels are nested: `S_k(v)`
//! is `v`'s own height from its own level on, and the stored offset below it). Each surface is
//! within its error of the source, so the blend is within
//!
//! ```text
//! E(l) = (1 - t) E_k + t E_(k+1),
//! ```
//!
//! linear in `t`. That is more than the error "at the fractional level" on the levels' own
//! geometric scale: with errors doubling per level, `E_(k+1) (2 - t)` against
//! `E_(k+1) 2^(1 - t)`, up to 6% more near `t = 0.56`. So `Λ` inverts the linear `E`, not the
//! geometric one: `E(l(v)) <= τ / S(v)`, the vertex's error projects to at most `τ` pixels.
//! `E_k` is the level table of where the vertex lies ([`crate::levels`]): inside a tile, that
//! tile's measured error of level `k` (plus half its morph unit under the rules that read the
//! stored offsets, which are rounded to whole units: `--morph-shader two-levels` and
//! `forward-differences`); on a side, the larger of the two tiles'; at a corner, the largest of the
//! tiles there. So the table, too, is the same in every tile holding the vertex. Each table
//! falls by at least [`crate::levels::MIN_RATIO`] a level (a coarser level is taken as worse
//! where the spacing rule left it better than a finer one), so `Λ` is continuous:
//!
//! ```text
//! Λ(r) = Σ_k clamp((E_k - r) / (E_k - E_(k+1)), 0, 1)    (k = 0 .. n-2),
//! ```
//!
//! which is `k + t` where `E_k > r >= E_(k+1)`, `0` above `E_0` and the finest level below
//! `E_(n-1)`: eight clamped multiply-adds on the GPU, no search, no branch.
//!
//! # The morph: each vertex from its parents
//!
//! The vertices of a tile's meshes form a hierarchy ([`parents`]): every vertex but the
//! tile's corners lies midway between two parents of a coarser scale, an edge's midpoint
//! between the edge's ends and a cell's centre between its parent cell's centre and the
//! parent's corner it faces, and a mesh that lacks the vertex holds the segment between its
//! parents as an edge (a fan's rim or spoke), so that mesh's surface there is the parents'
//! mean. A parent's block is never after its child's (a leaf's fan holds its corners; a cell
//! is split only when its centre is a vertex). The morph pass places the drawn vertices coarse
//! to fine, a vertex `v` of block `j >= 1` at
//!
//! ```text
//! m(v) = (m(p) + m(q)) / 2 + w_v d_v,   d_v = own(v) - (own(p) + own(q)) / 2,
//! w_v = clamp(l(v) - j + 1, 0, 1),
//! ```
//!
//! its parents' placed mean plus its share of its own detail; block 0 stays at its own height.
//! It reads no stored offset (the coarser surfaces come from the parents' own heights, exact
//! where the offsets are rounded), so its tables hold the measured errors alone, and the
//! set's morph units, which a distributed build takes from the input's scan
//! (`tiles::units`), do not change what it draws.
//! Unrolled, the drawn surface is `D = Σ_v w_v d_v φ_v` over the hierarchical hat functions
//! `φ_v` (linear on every mesh holding `v`, 1 at `v`, 0 at every other vertex of it), and the
//! level-`k` surface is the same sum with `w = 1` on blocks `0..=k` and 0 beyond.
//!
//! **Where the levels agree.** If every vertex whose `φ_v` reaches a point `q` has the level
//! `l = k + t`, the weights are 1 on blocks up to `k`, `t` on block `k + 1`, 0 beyond, and
//! `D(q) = (1 - t) S_k(q) + t S_(k+1)(q)`: the blend above, within `E(l) <= τ / S` (and what the
//! previous per-vertex rule, `--morph-shader two-levels`, places: that rule blends each vertex
//! between the stored surfaces at its own level, whatever its parents do).
//!
//! **Where they differ**, `D(q)` differs from that blend at `q`'s own level by
//! `Σ_v (w_v - w(l(q))) d_v φ_v(q)`, over the vertices of every coarser scale whose hat reaches
//! `q`: up to a cell of their scale away, so at coarse scales far from `q`. Where such a vertex
//! is coarser than `q` needs (`w_v < w(l(q))`), its missing detail, allowed at its own
//! `|J z|`, is seen at `q`'s larger one; the next section raises vertices over their star to
//! take most of that away. Where a vertex is finer than `q` needs, the excess is a partial sum
//! of finer details, not bounded here either; "Within a block" below takes away the case
//! measured. The rule aims at [`TAU_MARGIN`] of `τ` (3% below) to leave room for what is
//! left. What the GPU's surface delivers is measured: the error meter rasterises this mirror's
//! surface against the source on every measured frame (`max_error_px`), and a test reads the
//! vertex shader's heights back and compares them with this mirror vertex for vertex.
//!
//! # Over the star
//!
//! A vertex's triangles reach the box of half-width `s`, its scale, around it, in every mesh
//! holding it (a fan's centre or rim vertex of scale `s` lies in a cell of size `2 s`, and a
//! cell's corner in cells no larger than `s`). Where that box comes nearer the camera than the
//! vertex, points there need a finer level than `l(v)`. Measured before this: the Puget
//! flyover at 1024 x 768 in 120 frames at tau 3 reached 3.069 px at frame 20, inside a triangle
//! of a scale-8 vertex at level 0.003 whose neighbour, four samples nearer, wanted 0.149. So
//! the morph pass (not the two-levels rule) takes, for `e(v) = τ / |J z(v)|` the error allowed
//! at `v` and the corners `q_k = (x ± r_x, y ± r_y)` at `v`'s own height, the farthest point
//! `p_k` of the segment from `v` to `q_k` that is in view (in clip space: inside the image and
//! at least twice the near plane's depth away; [`in_view`]), and `D_k` how deep in view the
//! segment reaches (the largest of [`depth_in_view`] at `v`, `q_k` and their midpoint: the
//! distance to the image's nearest edge as a share of the half-image),
//!
//! ```text
//! e*(v) = e(v) - max_k ω_k · max(e(v) - e(p_k), 0),   ω_k = clamp(D_k / STAR_RAMP, 0, 1),
//! l*(v) = Λ(e*(v)).
//! ```
//!
//! The reach `r` ([`TileMorph::reach`]) is `s` along each axis in which `v` is not on a line
//! between the tile's 4 x 4 parts (nor within `s` of its mesh's last column or row), and 0
//! across such a line, so every `p_k` lies in the closed box of every part whose mesh holds `v`
//! (on a line, on the line itself), at a height within the tile's range. On a tile's side
//! (which is drawn at the tile's level, whatever its parts') `r` is `s` along the side, across
//! a line or not, and [`SIDE_REACH`] samples at most across it, into both tiles.
//!
//! - **Within every mesh drawing the vertex.** A point that counts is in view in the box of
//!   each part `P` holding `v`, so its `|J z|` is within that part's bound and `Λ(e(p_k))`
//!   within `P`'s drawn level `G_P` ("Part by part" below), as `l(v)` is when `v` is on
//!   screen: `l*(v) <= G_P` for every such part. A side's vertex takes the side's table, and
//!   each tile's parts along the side cover, under that table, the strip `SIDE_REACH` deep on
//!   both sides of the side ([`crate::lod::morph_parts`]), so its `l*` is within the level of
//!   each tile drawing it. A vertex that a mesh's next level adds has `w = 0` when it arrives,
//!   as before; a coarser part's fans, which take in a line's vertices, are not bent by a finer
//!   part's needs. The test `the_placed_level_stays_within_every_part_that_draws_the_vertex`
//!   checks it vertex by vertex (its control: the whole star's box, across lines, would break
//!   it).
//! - **Continuous** in the camera, and no faster than the image: the point `p_k` slides along
//!   the segment to the edge of the view as the corner leaves it, and the weight moves at most
//!   as fast as `v`, `q_k` or their midpoint moves on the image, over `STAR_RAMP` (each depth
//!   is a minimum of distances to edges, and max and clamp add no speed), vanishing as the
//!   segment leaves the view. The rule before weighted each corner by the share of its segment
//!   in view, which is as continuous but not as slow: a segment nearly parallel to an edge of
//!   the view has its share swept in a frame by a small turn. On the Puget flyover's first 12
//!   s in 300 frames at tau 5, long segments along lines between parts, just off the image's
//!   side, went from half in view to 4% in one frame and dropped their vertex's level from
//!   0.60 to 0.22: a 32 m jump, 0.62 px on screen (bench/README.md). The rule before that
//!   weighted each corner by how far inside the image the corner itself was, over 0.3 of the
//!   half-width, so a vertex near the image's edges whose corners were off it was barely
//!   raised; the depth here is the segment's deepest point, the vertex's own included.
//! - **The same in every tile** holding a vertex of a tile's side: its corners are computed
//!   from the same integers with the same table and arithmetic.
//! - **Not a bound**: the points stand at the vertex's height, not on the surface, and
//!   `|J z|` inside the box is not bounded by that on the segments (its depth is, being
//!   affine). Measured (bench/README.md, "Over the side"): the 4K mirror's 30 frames a second
//!   flight at tau 1 1.043 px before, 0.975 px now; the Puget flyover at 1024 x 768 in 120
//!   frames 2.927 and 4.996 px at tau 3 and 5 before. The case that showed it: a coast
//!   cliff, a side vertex at level 0.80 whose star reached neither across the side nor along it
//!   past a line, 26 samples from a sample that needed 0.96.
//!
//! # Within a block
//!
//! A vertex `c` of block `j` whose parent `p` is of block `j` too refines the surface that
//! `p`'s detail made: at level `j` both are at their own heights, at `j - 1` neither is. A
//! point between them that needs less than `j` wants neither detail; at `p`'s weight `w_p`
//! and `c`'s `w_c < w_p` it gets `(w_p - w_c)` of `p`'s detail without the matching share of
//! `c`'s, which level `j` puts there to cancel it where `p`'s was too much. So each vertex
//! takes the larger of its own level and the levels its parents pass on
//! ([`hierarchy::held_level`]): a parent passes its level held to its own block,
//! `clamp(l*(p), j_p - 1, j_p)`, so that
//!
//! ```text
//! w_c = clamp(max(l*(c), held(p), held(q)) - j + 1, 0, 1) >= w_p   when j_p = j,
//! ```
//!
//! and a child of a finer block takes nothing from it (`held(p) <= j_p <= j - 1`). Where a
//! block's vertices around a point share a weight this is the blend at that weight, within
//! `(1 - t) E_(j-1) + t E_j`, which is at most `E_(j-1)`: no more than the point's own level
//! allowed. What a vertex takes from its parents is held to the level of the coarsest part
//! whose closed box holds it (the tile's level on its border; [`tiles::parts::coarsest_level`]),
//! as its own placed level is ("Over the star"): a parent on the tile's side, held only by the
//! tile's level, would otherwise pass a weight to a vertex on a line that a coarser part's
//! fans take in, and that vertex would leave the mesh at that weight when its finer part
//! coarsened. So the drawn level is unchanged, every vertex a part holding it lacks still has
//! weight 0, and a block that a part's next level adds still starts on the surface drawn
//! before (the test `the_placed_level_stays_within_every_part_that_draws_the_vertex` checks
//! the weights vertex by vertex; without the hold it found a line's vertex at weight 0.28 in a
//! part at level 0). Measured (bench/README.md, "A vertex at its parents' weight"): the 4K
//! Puget flyover in 120 frames at 1024 x 768 and tau 1 measured 1.008 px on frame 18, where
//! the star raised a vertex to level 0.75 and its child of the same block, at 0, sat at its
//! parents' mean; now 0.965 px. Passing the level itself across blocks too (not held) took
//! the same set at tau 5 from 5.043 to 4.653 px but made a 1.2 px pop: a finer block then
//! arrives with weights above 0. The test `a_vertex_takes_its_parents_weight_within_its_block`
//! measures the first case and its control.
//!
//! # The level a tile is drawn at
//!
//! A tile is drawn at the level `G` that covers the level of every on-screen vertex that a
//! level can move ([`crate::lod::morph_level`]): the largest, over the tile's interior and its
//! four sides (each with its own level table), of `ceil(Λ_part(τ / S_part))`, `S_part` the
//! proved bound of [`crate::lod`] over the pieces of that part's box that touch the frustum.
//! Every on-screen vertex of the interior or a side lies in the box of its part, so its `S(v)`
//! is within that bound and its level at most `G`: off-screen parts do not raise it, and a
//! rougher neighbour raises it only as far as the shared side needs (a side vertex takes the
//! larger table of the two tiles, so that both give it one level). Were some on-screen vertex
//! to want more than the drawn mesh has, it would start off the coarser surface when the finer
//! level arrived. The tile's four corners are left out: they are vertices of block 0, at their
//! own height on every level, so their level moves nothing and no level adds them; their
//! tables (the largest of the four tiles around a corner) only made a tile finer where a
//! rougher tile touched it diagonally (the N48W125 orbit at tau 1: 43.1k triangles with them,
//! 38.5k without, discrete 28.8k). The test `the_drawn_level_covers_every_vertex_on_screen`
//! checks the cover vertex by vertex, that the corners are block-0 vertices and that some
//! corner on screen does want more than its tile's level, and that the largest table over the
//! whole box, the rule before, drew finer (the controls). Vertices whose level reaches their
//! own block `j` sit at their own height, bit for bit (every weight below `j` is exactly 0),
//! so a vertex off screen whose level exceeds `G` is simply on level `G`'s surface.
//!
//! # Part by part
//!
//! A tile is 257 x 257 samples; under a low camera its near corner wants the finest level while
//! its far side could do with a much coarser one, and the whole tile took the finest. By
//! default each of a tile's 4 x 4 parts is drawn at its own level instead
//! ([`crate::lod::morph_parts`]: the rule above over the part's box and its stretch of the
//! tile's sides), in one conforming mesh the index builder makes on the GPU
//! ([`tiles::parts`], [`crate::parts`]): inside a part the part's level's fans; on a line
//! between parts the finest adjacent part's vertices, which the coarser part's fans take in
//! along their edges, so the mesh has no T-junction and the parts need no stitching; on the
//! tile's border the tile's level (the largest part's), so that stitching to the neighbours is
//! as before. Every on-screen vertex lies in the box of each part whose fans hold it, so the
//! cover above holds part by part, and with it what follows. The tile's level is the largest
//! of its parts' and the memory manager sees only that: the mixed array fits in its array's
//! room. `--whole-tiles` draws each tile at one level (the comparison); where index arrays are
//! sent from the file, a tile is drawn at its largest part's level throughout.
//!
//! The side tables from each tile's errors near the side alone (which the file records,
//! [`tiles::format::LevelEntry::side_error`]) were tried and measured twice: they cut the
//! N48W125 orbit at tau 1 to 1.14x discrete's triangles, but the error reached 2.06 px at tau
//! 2 there (bench/README.md). Found the second time: the worst sample lies on the side of a
//! tile drawn at level 1, between a corner and a side vertex 128 rows (4 km) away. A
//! segment whose one end is a block-0 vertex blends, all along, at the other end's level, so
//! the error near the corner is the far vertex's `τ / S(v)` seen at the corner's larger
//! `|J z|`. Smaller side tables lower `G`, lengthen such segments and expose it. Sides keep the
//! whole tiles' tables until the vertex rule bounds `|J z|` over a vertex's star, not at the
//! vertex alone.
//!
//! # Continuity
//!
//! `l(v)` is continuous in the camera, so a vertex moves continuously while the camera does,
//! and new ground coming on screen needs nothing: its vertices already have their levels. The
//! mesh changes when a tile's drawn level does. A vertex the finer level adds (block `G + 1`)
//! has `l <= G` wherever it is on screen (the drawn level covers it), so `w_v = 0`: it starts
//! at its parents' placed mean, which is the surface drawn before at its place, exactly, and
//! the level change moves nothing until the camera does. (The previous rule placed it on the
//! stored coarser surfaces at its own level, while the surface drawn there interpolated its
//! neighbours' blends at their levels: where levels varied across a coarse triangle, a new
//! vertex jumped, up to 0.88 px at tau 3 on the N48W125 flyover; bench/README.md.) What can
//! still jump is a vertex the level adds that lies off screen with a level above `G`, in a
//! triangle that reaches the screen. Drawn part by part, the mesh also changes when a part's
//! level does, and the same holds part by part: a vertex a part's finer level adds is on
//! screen only where that part's box covers it. The error meter's `pop_px` measures what is
//! left.

use glam::{Mat4, Vec3, Vec4};

use crate::camera::{View, NEAR};
use crate::interface::{LevelCoefficients, MorphFrame};
pub use crate::levels::{LevelTable, MAX_LEVELS};
use crate::terrain::Terrain;

mod hierarchy;
mod star;
mod two_levels;

use hierarchy::hierarchical;
pub use hierarchy::{block_points, orphan, parents, scale_of};
pub use star::{depth_in_view, in_view, star_weight};
pub use two_levels::{height_slope, morphed_height, weights};

/// How far (samples) the star of a vertex on a tile's side reaches across the side, into both
/// tiles ([`TileMorph::reach`]; `SIDE_REACH` of the shader interface): the drawn level covers
/// that strip ([`crate::lod::morph_parts`]), so the deeper the reach, the finer the parts along
/// the sides. Measured (bench/README.md, "Over the side"): 16 brings the 4K mirror flight
/// within tau for +0-1.2% triangles; 64 cost up to 10% more triangles and doubled a pop.
pub use spirv::flags::SIDE_REACH;

/// The share of `tau` the vertex rule and the drawn level aim at: the excess over the blend's
/// bound where the levels of a point's vertices differ (module header, "The morph" and "Over
/// the star") is not bounded by the rule. With the star over tile sides and to the view's
/// edge, the Puget flyover in 120 frames at 1024 x 768 measured 2.882 and 4.757 px at tau 3 and
/// 5 (within the aim), the 4K mirror's flyover 0.975 px at tau 1 (0.5% over the aim, 4.3% over
/// tau before), the 4K Puget flyover 0.965 px at tau 1 since "Within a block" (1.008 before);
/// the test flights stay under the aim. 3% is kept for it.
pub const TAU_MARGIN: f64 = 0.97;

/// How deep in view (a share of the half-image) the segment from a vertex to a corner of its
/// star must reach for the corner to count fully towards the vertex's level (module header,
/// "Over the star"): a segment coming into view raises the vertex as it comes, at most as fast
/// as the image moves over this depth. Measured (bench/README.md, "A star's weight from how
/// deep it reaches in view"): 0.1, 0.15 and 0.3 pop alike; 0.1 stays nearest to tau.
pub const STAR_RAMP: f32 = 0.1;

/// The frame's constants of the vertex rule for `view` at tolerance `tau` (`MorphFrame` of the
/// shader interface). With `clip = view_proj * p` for `p` relative to the camera, `d = clip.w`
/// is the depth and `clip.xy = (f / aspect · x, -f · y)` in view coordinates, so the lod.rs
/// formula `j_x = f_x (w_x d + x w_z) / d²`, `j_y = f_y (w_y d + y w_z) / d²` reads
/// `|J z| = |A d + B ⊙ clip.xy| / d²` with `A = (f_x w_x, f_y w_y)` and
/// `B = (width / 2 · w_z, -height / 2 · w_z)`.
pub fn frame_constants(view: &View, tau: f64) -> MorphFrame {
    let w = (view.right.z, view.up.z);
    let wz = view.back.z;
    let (fx, fy) = view.focal;
    MorphFrame {
        jacobian: [
            (fx * w.0) as f32,
            (fy * w.1) as f32,
            (f64::from(view.width) * 0.5 * wz) as f32,
            (-f64::from(view.height) * 0.5 * wz) as f32,
        ],
        tau: (tau * TAU_MARGIN) as f32,
        near: NEAR as f32,
        ramp: STAR_RAMP,
        pad: 0.0,
    }
}

/// Which of a tile's nine level tables a vertex at tile-local `(x, y)` takes: 0 inside, 1..=4
/// on the N, E, S, W sides, 5..=8 at the NW, NE, SW, SE corners (`table_of` in the shader).
pub fn table_of(x: u32, y: u32) -> usize {
    let column = match x {
        0 => 0,
        256 => 2,
        _ => 1,
    };
    let row = match y {
        0 => 0,
        256 => 2,
        _ => 1,
    };
    [5, 1, 6, 4, 0, 2, 7, 3, 8][row * 3 + column]
}

/// `l(v)` for a vertex whose unmorphed position is at `clip` (`view_proj` times the position
/// relative to the camera) with the level table `c`, as the shaders compute it: the finest
/// level behind the near plane.
pub fn vertex_level(m: &MorphFrame, c: &LevelCoefficients, clip: Vec4) -> f32 {
    level_for(allowed_error(m, clip), c)
}

/// The vertical error (m) that projects to `τ` pixels at clip position `clip` (`τ / |J z|`), 0
/// behind the near plane, as `allowed_error` in the shaders.
pub fn allowed_error(m: &MorphFrame, clip: Vec4) -> f32 {
    if clip.w < m.near {
        return 0.0;
    }
    let d = clip.w;
    let g = (
        m.jacobian[0] * d + m.jacobian[2] * clip.x,
        m.jacobian[1] * d + m.jacobian[3] * clip.y,
    );
    m.tau * d * d / (g.0 * g.0 + g.1 * g.1).max(1e-30).sqrt()
}

/// `Λ(e)` under the table `c`, as `level_for` in the shaders.
pub fn level_for(e: f32, c: &LevelCoefficients) -> f32 {
    let term = |a: f32, b: f32| (a - e * b).clamp(0.0, 1.0);
    (0..4)
        .map(|k| term(c.a_lo[k], c.b_lo[k]) + term(c.a_hi[k], c.b_hi[k]))
        .sum()
}

/// What a morphing draw of one tile depends on, as its record and the frame's constants give
/// it to the vertex shader.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TileMorph {
    pub view_proj: Mat4,
    /// The camera relative to its tile's north-west corner (m), and metres per column.
    pub camera: Vec4,
    pub spacing_y: f32,
    pub height_step: f32,
    pub frame: MorphFrame,
    /// The tile's first sample relative to the camera's tile (columns, rows).
    pub tile_offset: [i32; 2],
    /// The level the draw's vertices morph to at most.
    pub cap: f32,
    /// The tile's nine level tables ([`table_of`]).
    pub tables: [LevelCoefficients; 9],
    /// The tile's mesh's last column and row (256 but in a partial tile).
    pub extent: [u32; 2],
    /// The tile's pyramid layer `p`: its samples are `2^p` base samples apart (0 in the base
    /// grid).
    pub layer: u32,
    /// How the draw's vertices morph.
    pub rule: MorphRule,
    /// The levels of the tile's parts when it is drawn part by part (None: at its level
    /// throughout): the morph pass places only the vertices the draw's mesh holds.
    pub parts: Option<tiles::parts::PartKey>,
}

/// How a draw's vertices morph (`--morph-shader`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum MorphRule {
    /// The morph pass: each vertex from its parents' morphed heights (module header).
    #[default]
    Hierarchical,
    /// The morph pass's placement with each vertex at its own level alone, not raised to its
    /// parents' within its block ("Within a block" in the module header): the rule before,
    /// in this mirror only, the control of the test that the raise keeps the error within tau.
    OwnLevels,
    /// The previous per-vertex rule: the stored offsets of the two levels around the vertex's
    /// own level (the vertex shader's two-levels and forward-differences builds).
    TwoLevels,
}

impl TileMorph {
    /// How the renderer morphs tile `tile` seen from `camera` at `extent` pixels for `tau`,
    /// with no cap below its finest level: the frame's constants and the tile's record as
    /// `crate::frame` writes them.
    pub fn from_camera(
        terrain: &Terrain,
        camera: &crate::camera::Camera,
        extent: (u32, u32),
        tau: f64,
        tile: usize,
    ) -> TileMorph {
        let view = camera.view(extent.0, extent.1);
        let (cam_tile, rel) = terrain.camera_tile(camera.position);
        TileMorph {
            view_proj: view.view_proj,
            camera: Vec4::new(
                rel.x as f32,
                rel.y as f32,
                rel.z as f32,
                terrain.spacing.0 as f32,
            ),
            spacing_y: terrain.spacing.1 as f32,
            height_step: terrain.height_step_of(&terrain.tiles[tile]),
            frame: frame_constants(&view, tau),
            tile_offset: Terrain::tile_offset(cam_tile, &terrain.tiles[tile]),
            cap: terrain.levels.saturating_sub(1) as f32,
            tables: terrain.tiles[tile]
                .tables
                .map(|t| LevelCoefficients::of(&t)),
            extent: [
                terrain.tiles[tile].header.mesh_max_x,
                terrain.tiles[tile].header.mesh_max_y,
            ],
            layer: terrain.tiles[tile].layer,
            rule: MorphRule::Hierarchical,
            parts: None,
        }
    }

    /// The vertex's unmorphed position relative to the camera and its level `Λ(τ / S)` at its
    /// own `|J z|`, from its tile-local sample and its own height, as the shaders compute them:
    /// the level the tile's drawn level covers on screen, and the two-levels rule's.
    pub fn vertex(&self, x: u32, y: u32, own: f32) -> (Vec3, f32) {
        let (sx, sy) = (
            self.tile_offset[0].wrapping_add((x << self.layer) as i32),
            self.tile_offset[1].wrapping_add((y << self.layer) as i32),
        );
        let relative = Vec3::new(
            sx as f32 * self.camera.w,
            -(sy as f32) * self.spacing_y,
            own,
        ) - self.camera.truncate();
        let clip = self.view_proj * relative.extend(1.0);
        let table = &self.tables[table_of(x, y)];
        (
            relative,
            vertex_level(&self.frame, table, clip).min(self.cap),
        )
    }
}

/// The weight of its own detail the morph pass gives each vertex of a tile's blocks
/// `0..=level` (index order; module header, "The morph" and "Within a block"): 1 in block 0,
/// 0 for a vertex a part's mix does not hold.
pub fn tile_weights(tile: &tiles::format::Tile, level: u32, morph: &TileMorph) -> Vec<f32> {
    let mut vertices = tile_heights(tile, level, None, 0);
    hierarchical(tile, level, morph, (&morph_units(tile), 0), &mut vertices)
}

/// Each level's morph unit (m), as the morph reads them.
fn morph_units(tile: &tiles::format::Tile) -> Vec<f32> {
    tile.levels().iter().map(|l| l.morph_unit).collect()
}

/// The vertices of a tile's blocks `0..=level`, decoded: `(x, y, height)` in index order,
/// each height geomorphed as the vertex shader places it when `morph` is given.
pub fn tile_vertices(
    tile: &tiles::format::Tile,
    level: u32,
    morph: Option<&TileMorph>,
) -> Vec<(u32, u32, f32)> {
    tile_heights(tile, level, morph, 0)
        .into_iter()
        .map(|(x, y, h, _)| (x, y, h))
        .collect()
}

/// [`tile_vertices`] with how fast each vertex's height moves with the levels (metres per
/// level, 0 unmorphed: [`height_slope`], or its hierarchical counterpart), and `bias` morph
/// units added to every vertex's morph (to each stored offset, or to each detail): the
/// read-back check's negative control (a mirror one morph unit off must be told apart from the
/// GPU; 0 otherwise).
pub fn tile_heights(
    tile: &tiles::format::Tile,
    level: u32,
    morph: Option<&TileMorph>,
    bias: i8,
) -> Vec<(u32, u32, f32, f32)> {
    let mut vertices: Vec<(u32, u32, f32, f32)> = tile
        .vertices()
        .into_iter()
        .map(|(x, y, h)| (x, y, h, 0.0))
        .collect();
    let blocks = (0..=level).map_while(|j| tile.level(j));
    let end = blocks.clone().map(|b| b.positions.len()).sum::<usize>();
    vertices.truncate(end);
    let Some(morph) = morph else {
        return vertices;
    };
    let units = morph_units(tile);
    if morph.rule != MorphRule::TwoLevels {
        hierarchical(tile, level, morph, (&units, bias), &mut vertices);
        return vertices;
    }
    let base = tile.header.height_base;
    let mut offsets = Vec::with_capacity(MAX_LEVELS);
    let mut start = 0usize;
    for (j, block) in blocks.enumerate() {
        let n = block.positions.len();
        for (i, v) in vertices[start..start + n].iter_mut().enumerate() {
            let (_, _, code) = tiles::pack::unpack(block.positions[i]);
            let own = (base + code as i32) as f32 * morph.height_step;
            let (_, l) = morph.vertex(v.0, v.1, own);
            offsets.clear();
            offsets.extend((0..j).map(|k| block.morph[k * n + i].saturating_add(bias)));
            v.2 = morphed_height(own, &offsets, &units, l);
            v.3 = height_slope(&offsets, &units, l);
        }
        start += n;
    }
    vertices
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_rng::Rng;
    use glam::DVec3;

    /// The frame's constants give `|J z|` from the clip position, as the lod.rs formula gives it
    /// from the view (random cameras and points in front of them).
    #[test]
    fn the_clip_space_jacobian_is_the_views() {
        let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
        let table = LevelTable::new(&[16.0, 8.0, 4.0, 2.0, 1.0]);
        for _ in 0..500 {
            let camera = rng.camera();
            let view = camera.view(640, 480);
            let p = camera.forward() * rng.range(2.0, 3000.0)
                + DVec3::new(
                    rng.range(-300.0, 300.0),
                    rng.range(-300.0, 300.0),
                    rng.range(-300.0, 300.0),
                );
            if -view.to_view(p).z < 1.0 {
                continue;
            }
            let m = frame_constants(&view, 1.0);
            let clip = view.view_proj * p.as_vec3().extend(1.0);
            let d = clip.w;
            let g = (
                m.jacobian[0] * d + m.jacobian[2] * clip.x,
                m.jacobian[1] * d + m.jacobian[3] * clip.y,
            );
            let s = f64::from((g.0 * g.0 + g.1 * g.1).sqrt() / (d * d));
            let want = view.pixels_per_vertical_metre(p);
            assert!(
                (s - want).abs() <= 1e-3 * want + 1e-9,
                "{s} vs {want} at {p:?}"
            );
            // And the vertex's level is Λ of tau over it.
            let l = vertex_level(&m, &LevelCoefficients::of(&table), clip);
            let expected = table.level_f64(TAU_MARGIN / want);
            assert!((f64::from(l) - expected).abs() < 2e-3, "{l} vs {expected}");
        }
    }
}
