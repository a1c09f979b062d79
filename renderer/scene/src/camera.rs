//! The camera: a position in world metres (f64: x east, y north, z up, origin at the
//! dataset's north-west sample), a heading and a field of view. Rendering happens relative to
//! the camera, so the matrices here never see large coordinates.

use glam::{DVec3, Mat4, Vec3};

/// Closest distance the projection resolves, metres.
pub const NEAR: f64 = 0.5;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    pub position: DVec3,
    /// Heading in radians: 0 looks east, pi/2 north.
    pub yaw: f64,
    /// Radians above the horizon.
    pub pitch: f64,
    /// Vertical field of view, radians.
    pub fov_y: f64,
}

/// Everything a frame needs from the camera at one image size.
#[derive(Clone, Copy, Debug)]
pub struct View {
    /// Projection times view, for points relative to the camera.
    pub view_proj: Mat4,
    pub width: u32,
    pub height: u32,
    /// Rows of the view rotation: right, up, backward (world to view).
    pub right: DVec3,
    pub up: DVec3,
    pub back: DVec3,
    /// Focal lengths in pixels (x, y).
    pub focal: (f64, f64),
}

impl Camera {
    pub fn forward(&self) -> DVec3 {
        DVec3::new(
            self.pitch.cos() * self.yaw.cos(),
            self.pitch.cos() * self.yaw.sin(),
            self.pitch.sin(),
        )
    }

    pub fn view(&self, width: u32, height: u32) -> View {
        let forward = self.forward().normalize();
        let world_up = if forward.z.abs() > 0.999 {
            DVec3::Y
        } else {
            DVec3::Z
        };
        let right = forward.cross(world_up).normalize();
        let up = right.cross(forward);
        let back = -forward;
        let aspect = f64::from(width) / f64::from(height.max(1));
        let f = 1.0 / (self.fov_y * 0.5).tan();
        // Vulkan clip space, reversed Z with an infinite far plane: depth = near / distance.
        let proj = Mat4::from_cols_array(&[
            (f / aspect) as f32,
            0.0,
            0.0,
            0.0,
            0.0,
            -f as f32,
            0.0,
            0.0,
            0.0,
            0.0,
            0.0,
            -1.0,
            0.0,
            0.0,
            NEAR as f32,
            0.0,
        ]);
        let (r, u, b) = (right.as_vec3(), up.as_vec3(), back.as_vec3());
        let view = Mat4::from_cols_array(&[
            r.x, u.x, b.x, 0.0, r.y, u.y, b.y, 0.0, r.z, u.z, b.z, 0.0, 0.0, 0.0, 0.0, 1.0,
        ]);
        View {
            view_proj: proj * view,
            width,
            height,
            right,
            up,
            back,
            focal: (
                f / aspect * f64::from(width) * 0.5,
                f * f64::from(height) * 0.5,
            ),
        }
    }
}

/// One vertical line of points relative to the camera: [`View::vertical`].
#[derive(Clone, Copy, Debug)]
pub struct Vertical<'a> {
    view: &'a View,
    /// Each view axis' dot product with the line's horizontal coordinates.
    horizontal: DVec3,
}

impl Vertical<'_> {
    /// [`View::project`] of the line's point at height `z` (relative to the camera).
    pub fn project(&self, z: f64) -> Option<(f64, f64)> {
        let (v, h) = (self.view, self.horizontal);
        self.view.on_image(DVec3::new(
            h.x + v.right.z * z,
            h.y + v.up.z * z,
            h.z + v.back.z * z,
        ))
    }
}

impl View {
    /// View-space coordinates of a point relative to the camera.
    pub fn to_view(&self, p: DVec3) -> DVec3 {
        DVec3::new(self.right.dot(p), self.up.dot(p), self.back.dot(p))
    }

    /// Pixel coordinates of a point relative to the camera, if it is in front of the near plane.
    pub fn project(&self, p: DVec3) -> Option<(f64, f64)> {
        self.on_image(self.to_view(p))
    }

    /// The points above and below `(x, y)` (relative to the camera) as seen by
    /// [`project`](Self::project), bit for bit: the horizontal coordinates' part of the view
    /// transform is summed once for every height asked about. For readers that project many
    /// heights of one sample (the error meter: the drawn, the true and the previous height).
    pub fn vertical(&self, x: f64, y: f64) -> Vertical<'_> {
        // `to_view`'s dot products sum x, y, z in that order: the first two terms, now.
        let horizontal = |axis: DVec3| axis.x * x + axis.y * y;
        Vertical {
            view: self,
            horizontal: DVec3::new(
                horizontal(self.right),
                horizontal(self.up),
                horizontal(self.back),
            ),
        }
    }

    /// Pixel coordinates of view-space `v`, if it is in front of the near plane.
    fn on_image(&self, v: DVec3) -> Option<(f64, f64)> {
        let d = -v.z;
        (d >= NEAR).then(|| {
            (
                f64::from(self.width) * 0.5 + self.focal.0 * v.x / d,
                f64::from(self.height) * 0.5 - self.focal.1 * v.y / d,
            )
        })
    }

    /// How many pixels one metre of vertical displacement at `p` (relative to the camera)
    /// moves on screen: the norm of the projection's Jacobian applied to world up.
    /// Infinite at or behind the near plane.
    pub fn pixels_per_vertical_metre(&self, p: DVec3) -> f64 {
        let v = self.to_view(p);
        let d = -v.z;
        if d < NEAR {
            return f64::INFINITY;
        }
        let w = DVec3::new(self.right.z, self.up.z, self.back.z);
        let dx = self.focal.0 * (w.x / d + v.x * w.z / (d * d));
        let dy = self.focal.1 * (w.y / d + v.y * w.z / (d * d));
        (dx * dx + dy * dy).sqrt()
    }

    /// Frustum planes (left, right, bottom, top, near) as `n . p + d >= 0` inside, for points
    /// relative to the camera.
    pub fn frustum(&self) -> [glam::Vec4; 5] {
        let m = self.view_proj.transpose();
        let (r0, r1, r2, r3) = (m.x_axis, m.y_axis, m.z_axis, m.w_axis);
        [r3 + r0, r3 - r0, r3 + r1, r3 - r1, r3 - r2]
    }
}

/// Box relative to the camera, f32 (small numbers near the camera).
pub fn relative_box(min: DVec3, max: DVec3, camera: DVec3) -> (Vec3, Vec3) {
    ((min - camera).as_vec3(), (max - camera).as_vec3())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cam() -> Camera {
        Camera {
            position: DVec3::new(0.0, 0.0, 100.0),
            yaw: 0.3,
            pitch: -0.2,
            fov_y: 60f64.to_radians(),
        }
    }

    #[test]
    fn projection_matches_the_matrix() {
        let c = cam();
        let v = c.view(800, 600);
        let p = DVec3::new(500.0, 120.0, -80.0);
        let (sx, sy) = v.project(p).expect("in front");
        let clip = v.view_proj * p.as_vec3().extend(1.0);
        let (nx, ny) = (clip.x / clip.w, clip.y / clip.w);
        assert!(((f64::from(nx) + 1.0) * 400.0 - sx).abs() < 1e-2);
        assert!(((f64::from(ny) + 1.0) * 300.0 - sy).abs() < 1e-2);
        let depth = clip.z / clip.w;
        assert!(depth > 0.0 && depth < 1.0);
    }

    /// A vertical line's projections are `project`'s, bit for bit (the error meter's values
    /// must not move with the way it projects), including behind the near plane.
    #[test]
    fn a_vertical_projects_as_project_does() {
        let c = cam();
        let v = c.view(1024, 768);
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        };
        let mut behind = 0;
        for _ in 0..10_000 {
            let p = DVec3::new(next() * 5e4, next() * 5e4, next() * 3e3);
            let line = v.vertical(p.x, p.y);
            let (a, b) = (v.project(p), line.project(p.z));
            behind += usize::from(a.is_none());
            assert_eq!(
                a.map(|(x, y)| (x.to_bits(), y.to_bits())),
                b.map(|(x, y)| (x.to_bits(), y.to_bits())),
                "{p}"
            );
        }
        assert!(behind > 1000 && behind < 9000, "{behind} behind the camera");
    }

    #[test]
    fn vertical_jacobian_matches_a_finite_difference() {
        let c = cam();
        let v = c.view(1024, 768);
        for p in [
            DVec3::new(800.0, -50.0, -120.0),
            DVec3::new(200.0, 300.0, 40.0),
        ] {
            let (a, b) = (
                v.project(p).expect("front"),
                v.project(p + DVec3::Z * 1e-3).expect("front"),
            );
            let fd = ((b.0 - a.0).powi(2) + (b.1 - a.1).powi(2)).sqrt() / 1e-3;
            let j = v.pixels_per_vertical_metre(p);
            assert!((fd - j).abs() / j < 1e-3, "fd {fd} jacobian {j}");
        }
    }

    #[test]
    fn frustum_keeps_what_projects_on_screen() {
        let c = cam();
        let v = c.view(640, 480);
        let planes = v.frustum();
        let inside = |p: DVec3| {
            planes
                .iter()
                .all(|pl| pl.truncate().dot(p.as_vec3()) + pl.w >= -1e-3)
        };
        let ahead = c.forward() * 1000.0;
        assert!(inside(ahead));
        assert!(!inside(-ahead));
        assert!(!inside(ahead + v.right * 5000.0));
    }
}
