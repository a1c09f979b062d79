//! The unit tests' random cameras and boxes, drawn from the project's one generator
//! ([`splitmix::Rng`]) under the names these tests use: `Rng(seed)`, `next()` in [0, 1),
//! `range` and `camera`.

pub struct Rng(pub u64);

impl Rng {
    /// Uniform in [0, 1).
    pub fn next(&mut self) -> f64 {
        self.draw(splitmix::Rng::unit)
    }

    /// Uniform in [a, b).
    pub fn range(&mut self, a: f64, b: f64) -> f64 {
        self.draw(|rng| rng.range(a, b))
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

    /// One draw of the shared generator from this state (the state is one `u64` in both).
    fn draw<T>(&mut self, f: impl FnOnce(&mut splitmix::Rng) -> T) -> T {
        let mut rng = splitmix::Rng(self.0);
        let value = f(&mut rng);
        self.0 = rng.0;
        value
    }
}
