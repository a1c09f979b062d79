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

/// How far inside the view clip position `p` is, as a share of the half-image: its distance to
/// the image's nearest edge, and less within four near planes' depth (0 at twice the near
/// plane's depth and nearer, as off the image); as `depth_in_view` in `morph.comp`. It moves
/// no faster than `p` does on the image (or than `2 near / depth` does).
pub fn depth_in_view(m: &MorphFrame, p: Vec4) -> f32 {
    let near = 2.0 * m.near;
    if p.w <= near {
        return 0.0;
    }
    let d = (p.w - p.x.abs()).min(p.w - p.y.abs()).min(p.w - near);
    (d / p.w).max(0.0)
}

/// How fully the segment from clip position `a` (a vertex, `depth_a` its [`depth_in_view`],
/// the same for its four corners) to `b` (a corner of its star) counts towards the vertex's
/// level: how far inside the view the deepest of its ends and midpoint is, over
/// [`STAR_RAMP`](crate::morph::STAR_RAMP) (module header, "Over the star"); as `star_weight`
/// in `morph.comp`.
pub fn star_weight(m: &MorphFrame, depth_a: f32, a: Vec4, b: Vec4) -> f32 {
    let inside = depth_a
        .max(depth_in_view(m, b))
        .max(depth_in_view(m, 0.5 * (a + b)));
    (inside / m.ramp).clamp(0.0, 1.0)
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
    /// as [`star_weight`] gives: the placed level at the rule's [`TileMorph::reach`] (other
    /// reaches are the tests' controls).
    pub fn level_reaching(&self, x: u32, y: u32, own: f32, reach: Vec2) -> f32 {
        let (relative, _) = self.vertex(x, y, own);
        let clip = self.view_proj * relative.extend(1.0);
        let mut e = allowed_error(&self.frame, clip);
        if reach != Vec2::ZERO {
            // In base samples: a pyramid layer's are 2^layer apart.
            let reach = reach * (1u32 << self.layer) as f32;
            let east = self.view_proj.x_axis * (reach.x * self.camera.w);
            let south = self.view_proj.y_axis * (-reach.y * self.spacing_y);
            let depth = depth_in_view(&self.frame, clip);
            let lift = (0..4)
                .map(|k| {
                    let q = (clip + if k & 1 == 0 { -east } else { east })
                        + if k & 2 == 0 { -south } else { south };
                    in_view(&self.frame, clip, q).map_or(0.0, |(_, hi)| {
                        let weight = star_weight(&self.frame, depth, clip, q);
                        weight * (e - allowed_error(&self.frame, clip + (q - clip) * hi))
                    })
                })
                .fold(0.0f32, f32::max);
            e -= lift;
        }
        level_for(e, &self.tables[table_of(x, y)]).min(self.cap)
    }
}

#[cfg(test)]
mod tests {
    use glam::DVec3;

    use super::*;
    use crate::morph::{frame_constants, STAR_RAMP};
    use crate::test_rng::Rng;

    /// The star's weight moves no faster than the image: between two cameras a small turn and
    /// step apart, it changes by at most the largest move on the image (in half-images) of the
    /// segment's ends and midpoint, or of `2 near / depth` there, over the ramp. That bounds how
    /// far a frame's turn can lift or drop a vertex. The control: the share of the segment in
    /// view (the rule before, over its ramp of 0.3) jumps by far more than that on some of the
    /// same segments.
    #[test]
    fn the_stars_weight_moves_no_faster_than_the_image() {
        let mut rng = Rng(0x5eed_57a4_0f57);
        let share = |m: &MorphFrame, a: Vec4, b: Vec4| {
            in_view(m, a, b).map_or(0.0, |(lo, hi)| ((hi - lo) / 0.3).clamp(0.0, 1.0))
        };
        let (mut measured, mut share_jumps) = (0, 0);
        for _ in 0..20_000 {
            let first = rng.camera();
            let mut second = first;
            second.yaw += rng.range(-0.01, 0.01);
            second.pitch += rng.range(-0.01, 0.01);
            second.position += DVec3::new(
                rng.range(-30.0, 30.0),
                rng.range(-30.0, 30.0),
                rng.range(-5.0, 5.0),
            );
            // A vertex anywhere around the view, and a corner of its star up to 5 km away.
            let v = first.forward() * rng.range(1.0, 20_000.0)
                + DVec3::new(
                    rng.range(-5000.0, 5000.0),
                    rng.range(-5000.0, 5000.0),
                    rng.range(-500.0, 500.0),
                );
            let q = v + DVec3::new(rng.range(-5000.0, 5000.0), rng.range(-5000.0, 5000.0), 0.0);
            let mid = 0.5 * (v + q);
            let seen = |camera: &crate::camera::Camera| {
                let view = camera.view(480, 360);
                let clip = |p: DVec3| view.view_proj * (p - camera.position).as_vec3().extend(1.0);
                (frame_constants(&view, 1.0), [clip(v), clip(q), clip(mid)])
            };
            let (m1, c1) = seen(&first);
            let (m2, c2) = seen(&second);
            if c1.iter().chain(&c2).any(|c| c.w <= 1.0) {
                continue;
            }
            let on_image = |c: Vec4| [c.x / c.w, c.y / c.w, 2.0 * m1.near / c.w];
            let moved = c1
                .iter()
                .zip(&c2)
                .flat_map(|(&a, &b)| {
                    let (a, b) = (on_image(a), on_image(b));
                    (0..3).map(move |i| (a[i] - b[i]).abs())
                })
                .fold(0.0f32, f32::max);
            let bound = moved / STAR_RAMP;
            let weight =
                |m: &MorphFrame, c: &[Vec4; 3]| star_weight(m, depth_in_view(m, c[0]), c[0], c[1]);
            let change = (weight(&m1, &c1) - weight(&m2, &c2)).abs();
            assert!(
                change <= bound + 1e-4,
                "the weight moved {change} for an image move of {moved}"
            );
            measured += 1;
            let jump = (share(&m1, c1[0], c1[1]) - share(&m2, c2[0], c2[1])).abs();
            if jump > 0.1 && jump > 5.0 * moved / 0.3 {
                share_jumps += 1;
            }
        }
        assert!(measured > 10_000, "{measured} segments measured");
        assert!(
            share_jumps > 0,
            "the share of the segment in view never jumped"
        );
        eprintln!("{measured} segments; the share jumped on {share_jumps}");
    }
}
