//! Over the star (module header of [`crate::morph`]): the level the morph pass places a vertex
//! at, raised towards what the points in view on the segments to its star's corners need.

use glam::{Vec2, Vec4};

use super::{allowed_error, level_for, scale_of, table_of, MorphFrame, TileMorph, SIDE_REACH};

/// The part of the segment from clip position `a` to `b` that is in view: inside the image and
/// at least twice the near plane's depth away, as `(lo, hi)` along it (`a + t (b - a)` for `t`
/// in `lo..=hi`), None where the segment misses the view; as `in_view` in `morph.comp`.
pub fn in_view(m: &MorphFrame, a: Vec4, b: Vec4) -> Option<(f32, f32)> {
    let planes = |p: Vec4| {
        [
            p.w - p.x,
            p.w + p.x,
            p.w - p.y,
            p.w + p.y,
            p.w - 2.0 * m.near,
        ]
    };
    let (fa, fb) = (planes(a), planes(b));
    let (mut lo, mut hi) = (0.0f32, 1.0f32);
    for (a, b) in fa.into_iter().zip(fb) {
        let d = b - a;
        if d > 0.0 {
            lo = lo.max(-a / d);
        } else if d < 0.0 {
            hi = hi.min(-a / d);
        } else if a < 0.0 {
            return None;
        }
    }
    (lo <= hi).then_some((lo, hi))
}

impl TileMorph {
    /// The level the morph pass places the vertex at (module header, "Over the star"), as
    /// `morph.comp` computes it: [`TileMorph::vertex`]'s, raised towards the levels on the
    /// segments in view to the corners of its star's box ([`TileMorph::reach`]).
    pub fn placed(&self, x: u32, y: u32, own: f32) -> f32 {
        self.level_reaching(x, y, own, self.reach(x, y))
    }

    /// How far (samples, east and north) the morph pass looks from the vertex at `(x, y)` for
    /// its star: its scale along each axis in which it is not on a line between parts (nor on
    /// the mesh's last column or row), else 0, so that the box lies in every part whose closed
    /// box holds the vertex; on a tile's side, its scale along the side and at most
    /// [`SIDE_REACH`] across it (the strips the tile's level covers). None at a tile's corner.
    pub fn reach(&self, x: u32, y: u32) -> Vec2 {
        let s = scale_of(x, y);
        let part = tiles::parts::PART_CELLS;
        let side = |c: u32| c == 0 || c == tiles::mesh::TILE_CELLS;
        if side(x) && side(y) {
            // A tile's corner: block 0, at its own height on every level.
            return Vec2::ZERO;
        }
        let reach = |c: u32, last: u32, along_side: bool| {
            if side(c) {
                s.min(SIDE_REACH) as f32
            } else if (along_side || !c.is_multiple_of(part)) && c + s <= last {
                s as f32
            } else {
                0.0
            }
        };
        Vec2::new(
            reach(x, self.extent[0], side(y)),
            reach(y, self.extent[1], side(x)),
        )
    }

    /// The vertex's level raised towards the levels on the segments to the corners `(x ±
    /// reach.x, y ± reach.y)` at its height, each at its farthest point [`in_view`] and as far
    /// as the segment is: the placed level at the rule's [`TileMorph::reach`] (other reaches are
    /// the tests' controls).
    pub fn level_reaching(&self, x: u32, y: u32, own: f32, reach: Vec2) -> f32 {
        let (relative, _) = self.vertex(x, y, own);
        let clip = self.view_proj * relative.extend(1.0);
        let mut e = allowed_error(&self.frame, clip);
        if reach != Vec2::ZERO {
            // In base samples: a pyramid layer's are 2^layer apart.
            let reach = reach * (1u32 << self.layer) as f32;
            let east = self.view_proj.x_axis * (reach.x * self.camera.w);
            let south = self.view_proj.y_axis * (-reach.y * self.spacing_y);
            let lift = (0..4)
                .map(|k| {
                    let q = (clip + if k & 1 == 0 { -east } else { east })
                        + if k & 2 == 0 { -south } else { south };
                    in_view(&self.frame, clip, q).map_or(0.0, |(lo, hi)| {
                        let weight = ((hi - lo) / self.frame.ramp).clamp(0.0, 1.0);
                        weight * (e - allowed_error(&self.frame, clip + (q - clip) * hi))
                    })
                })
                .fold(0.0f32, f32::max);
            e -= lift;
        }
        level_for(e, &self.tables[table_of(x, y)]).min(self.cap)
    }
}
