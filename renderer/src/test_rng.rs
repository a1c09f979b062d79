//! A small deterministic generator for the unit tests' random cameras and boxes (xorshift64).

pub struct Rng(pub u64);

impl Rng {
    /// Uniform in [0, 1).
    pub fn next(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in [a, b).
    pub fn range(&mut self, a: f64, b: f64) -> f64 {
        a + (b - a) * self.next()
    }

    /// A camera at the origin looking anywhere: yaw in (-3, 3), pitch in (-1.4, 0.6) and a
    /// vertical field of view in (0.3, 1.6) radians.
    pub fn camera(&mut self) -> crate::camera::Camera {
        crate::camera::Camera {
            position: glam::DVec3::ZERO,
            yaw: self.range(-3.0, 3.0),
            pitch: self.range(-1.4, 0.6),
            fov_y: self.range(0.3, 1.6),
        }
    }
}
