//! Camera prediction for prefetching (paper, section 6, last paragraph): a quadratic fitted by
//! least squares through the last poses flown, extrapolated up to a few seconds ahead.
//!
//! The predictor sees only what [`Predictor::observe`] was given, one pose per frame as it is
//! drawn, so a flight never reads its own future. Each channel (x, y, z, heading unwrapped,
//! pitch, field of view) gets its own fit in time, `p(t) = c0 + c1 t + c2 t^2` with `t` relative
//! to the newest pose. The prediction starts from the newest pose itself (not the fitted `c0`),
//! so a still camera is predicted exactly, and a decelerating channel stops where the fit says
//! its speed reaches zero rather than turning back (a camera that brakes does not reverse).
//!
//! How far ahead: the horizons are at least 0.25, 0.5, 1 and 2 s, and at least 1, 2, 4 and 8
//! frames at the pace the poses arrive ([`Predictor::horizons`]), capped at 4 s. The seconds
//! matter at interactive frame rates and for the page cache; the frames matter because the
//! upload budget is per frame: a tile that needs k frames of budget is only in time if it is
//! predicted k frames ahead, and at a few frames per second (lavapipe, or a headless flight of
//! 120 frames over 48 s) one second is only two or three frames.
//!
//! Error bounds (the unit tests check them, at 30 and at 2.5 frames per second):
//! - straight line at constant speed: exact (to rounding) at every horizon;
//! - constant turn of radius `r` at speed `v`: within `v^3 h^3 / (6 r^2)` plus the window's
//!   share of the same term (`v^3 (h + window)^3 / (6 r^2)`), and at least five times closer
//!   than a straight line; at 100 m/s on r = 2 km a few centimetres 1 s ahead at 30 frames per
//!   second, about 3 m 3.2 s ahead at 2.5 frames per second; heading exact;
//! - stop and go: never more than `v h` (a constant-velocity guess's worst), and exact again
//!   once the window holds only still poses.

use std::collections::VecDeque;

use glam::DVec3;

use crate::camera::Camera;

/// Poses kept for the fit.
pub const DEFAULT_POSES: usize = 6;

/// The shortest horizons the prefetcher looks ahead, seconds, soonest first.
pub const HORIZONS_S: [f64; 4] = [0.25, 0.5, 1.0, 2.0];

/// The shortest horizons in frames at the pace poses arrive, soonest first.
pub const HORIZON_FRAMES: [f64; 4] = [1.0, 2.0, 4.0, 8.0];

/// No horizon is longer than this, seconds: beyond it a fit of the last few poses says little.
pub const MAX_HORIZON_S: f64 = 4.0;

#[derive(Clone, Copy, Debug, PartialEq)]
struct Pose {
    time: f64,
    /// x, y, z, yaw (unwrapped: continuous across the +-pi seam), pitch, fov.
    channels: [f64; 6],
}

/// Fits the last poses flown and extrapolates them.
#[derive(Clone, Debug)]
pub struct Predictor {
    poses: VecDeque<Pose>,
    capacity: usize,
    /// Predictions not yet due: (due time, predicted position).
    pending: VecDeque<(f64, DVec3)>,
}

impl Default for Predictor {
    fn default() -> Self {
        Predictor::new(DEFAULT_POSES)
    }
}

impl Predictor {
    /// A predictor fitting the last `poses` poses (at least 3 for the quadratic).
    pub fn new(poses: usize) -> Predictor {
        Predictor {
            poses: VecDeque::with_capacity(poses.max(1)),
            capacity: poses.max(1),
            pending: VecDeque::new(),
        }
    }

    /// Adds the pose drawn at `time` (seconds, increasing). Time going back (a new flight, or
    /// the timed flight after a warm-up) starts afresh.
    pub fn observe(&mut self, time: f64, camera: &Camera) {
        if self.poses.back().is_some_and(|p| time <= p.time) {
            self.poses.clear();
            self.pending.clear();
        }
        let yaw = match self.poses.back() {
            // The heading nearest the last one, so a turn through +-pi stays continuous.
            Some(p) => p.channels[3] + wrap(camera.yaw - p.channels[3]),
            None => camera.yaw,
        };
        if self.poses.len() == self.capacity {
            self.poses.pop_front();
        }
        let c = camera.position;
        self.poses.push_back(Pose {
            time,
            channels: [c.x, c.y, c.z, yaw, camera.pitch, camera.fov_y],
        });
    }

    /// The horizons to look ahead, seconds, soonest first: each the longer of
    /// [`HORIZONS_S`] and [`HORIZON_FRAMES`] at the mean interval between the poses kept, at
    /// most [`MAX_HORIZON_S`]; one capped horizon is enough (below 2 frames per second the
    /// last ones would repeat it).
    pub fn horizons(&self) -> Vec<f64> {
        let n = self.poses.len();
        let interval = match (self.poses.front(), self.poses.back()) {
            (Some(a), Some(b)) if n >= 2 => (b.time - a.time) / (n - 1) as f64,
            _ => 0.0,
        };
        let mut out: Vec<f64> = Vec::with_capacity(HORIZONS_S.len());
        for (s, f) in HORIZONS_S.iter().zip(HORIZON_FRAMES) {
            let h = s.max(f * interval).min(MAX_HORIZON_S);
            if out.last().is_none_or(|&last| h > last) {
                out.push(h);
            }
        }
        out
    }

    /// The camera predicted `dt` seconds after the newest pose; None before the first pose.
    pub fn predict(&self, dt: f64) -> Option<Camera> {
        let last = *self.poses.back()?;
        let mut out = last.channels;
        // Position as one vector (its speed, not each axis, decides braking), then each angle.
        for group in [0..3, 3..4, 4..5, 5..6] {
            let fits: Vec<Fit> = group.clone().map(|ch| self.fit(ch)).collect();
            let step = advance(&fits, self.top_speed(group.clone()), dt);
            for (ch, d) in group.zip(step) {
                out[ch] += d;
            }
        }
        let [x, y, z, yaw, pitch, fov] = out;
        Some(Camera {
            position: DVec3::new(x, y, z),
            yaw: wrap(yaw),
            pitch: pitch.clamp(-1.55, 1.55),
            fov_y: fov.clamp(0.01, 3.1),
        })
    }

    /// Remembers where the camera is predicted to be `dt` from now, to be scored by
    /// [`Predictor::score`] when a frame reaches that time.
    pub fn remember(&mut self, dt: f64) {
        if let (Some(last), Some(c)) = (self.poses.back(), self.predict(dt)) {
            self.pending.push_back((last.time + dt, c.position));
        }
    }

    /// The largest distance, metres, between a remembered prediction now due and where the
    /// camera is (interpolated between the last two poses at the due time); NaN when none was
    /// due. Call after [`Predictor::observe`] of this frame's pose.
    pub fn score(&mut self) -> f64 {
        let n = self.poses.len();
        let Some(&now) = self.poses.back() else {
            return f64::NAN;
        };
        let before = if n >= 2 { self.poses[n - 2] } else { now };
        let mut worst = f64::NAN;
        while let Some(&(due, predicted)) = self.pending.front() {
            if due > now.time {
                break;
            }
            self.pending.pop_front();
            let span = now.time - before.time;
            let s = if span > 0.0 {
                ((due - before.time) / span).clamp(0.0, 1.0)
            } else {
                1.0
            };
            let at = |p: &Pose| DVec3::new(p.channels[0], p.channels[1], p.channels[2]);
            let actual = at(&before).lerp(at(&now), s);
            worst = worst.max(actual.distance(predicted));
        }
        worst
    }

    /// The fastest the group of channels moved between two consecutive poses.
    fn top_speed(&self, group: std::ops::Range<usize>) -> f64 {
        let mut top = 0.0f64;
        for (a, b) in self.poses.iter().zip(self.poses.iter().skip(1)) {
            let dt = b.time - a.time;
            let d2: f64 = group
                .clone()
                .map(|ch| (b.channels[ch] - a.channels[ch]).powi(2))
                .sum();
            top = top.max(d2.sqrt() / dt);
        }
        top
    }

    /// Channel `ch` fitted through the kept poses: the least-squares quadratic's velocity and
    /// half-acceleration at the newest pose, and the least-squares line's slope.
    fn fit(&self, ch: usize) -> Fit {
        let none = Fit {
            velocity: 0.0,
            half_accel: 0.0,
            slope: 0.0,
        };
        let Some(last) = self.poses.back() else {
            return none;
        };
        if self.poses.len() < 2 {
            return none;
        }
        // Power sums of t (relative to the newest pose) and moments of the values.
        let (mut s, mut r) = ([0.0f64; 5], [0.0f64; 3]);
        for p in &self.poses {
            let (t, v) = (p.time - last.time, p.channels[ch]);
            let mut tk = 1.0;
            for (k, sk) in s.iter_mut().enumerate() {
                *sk += tk;
                if k < 3 {
                    r[k] += tk * v;
                }
                tk *= t;
            }
        }
        let line_det = s[0] * s[2] - s[1] * s[1];
        let slope = if line_det > 0.0 {
            (s[0] * r[1] - s[1] * r[0]) / line_det
        } else {
            0.0
        };
        let line = Fit {
            velocity: slope,
            half_accel: 0.0,
            slope,
        };
        if self.poses.len() < 3 {
            return line;
        }
        // Normal equations of c0 + c1 t + c2 t^2, by Cramer's rule.
        let m = [[s[0], s[1], s[2]], [s[1], s[2], s[3]], [s[2], s[3], s[4]]];
        let det = det3(m);
        if det.abs() <= 1e-12 * s[4] * s[4] || det.is_nan() {
            return line;
        }
        let solve = |col: usize| {
            let mut a = m;
            for (row, value) in r.iter().enumerate() {
                a[row][col] = *value;
            }
            det3(a) / det
        };
        Fit {
            velocity: solve(1),
            half_accel: solve(2),
            slope,
        }
    }
}

/// One channel's fit.
#[derive(Clone, Copy, Debug)]
struct Fit {
    velocity: f64,
    half_accel: f64,
    /// The straight line's slope: the mean velocity over the window.
    slope: f64,
}

/// How far a group of channels (the position's three, or one angle) goes in `dt`:
/// - velocity `c1` and half-acceleration `c2` from the quadratic;
/// - the velocity no faster than the fastest move between two poses flown (a quadratic
///   through a kink, such as a start, overshoots);
/// - no motion when the quadratic's velocity points against the window's mean motion (the
///   camera just stopped or turned back; guessing it stays is off by at most its speed);
/// - the acceleration's share at most half the velocity's (a short window's curvature is
///   noisy, and over a second it would dominate);
/// - a group slowing down stops where its speed reaches zero instead of turning back.
fn advance(fits: &[Fit], top_speed: f64, dt: f64) -> Vec<f64> {
    let dot = |a: &dyn Fn(&Fit) -> f64, b: &dyn Fn(&Fit) -> f64| -> f64 {
        fits.iter().map(|f| a(f) * b(f)).sum()
    };
    let (v, a, slope) = (
        |f: &Fit| f.velocity,
        |f: &Fit| f.half_accel,
        |f: &Fit| f.slope,
    );
    if dot(&v, &slope) <= 0.0 {
        return vec![0.0; fits.len()];
    }
    let fitted = dot(&v, &v).sqrt();
    let cap = if fitted > top_speed {
        top_speed / fitted
    } else {
        1.0
    };
    let speed = fitted * cap;
    let accel = dot(&a, &a).sqrt();
    // |c2| t^2 <= |c1| t / 2 at t = dt.
    let scale = if accel * dt > 0.5 * speed {
        0.5 * speed / (accel * dt)
    } else {
        1.0
    };
    let along = dot(&v, &a) * cap * scale;
    let mut t = dt;
    if along < 0.0 {
        // d/dt of the displacement along c1 is |c1|^2 + 2 t c1.c2: zero at this t.
        t = t.min(speed * speed / (-2.0 * along));
    }
    fits.iter()
        .map(|f| f.velocity * cap * t + f.half_accel * scale * t * t)
        .collect()
}

fn det3(m: [[f64; 3]; 3]) -> f64 {
    m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
        - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
}

/// An angle in -pi..pi.
fn wrap(a: f64) -> f64 {
    let tau = std::f64::consts::TAU;
    a - tau * ((a + std::f64::consts::PI) / tau).floor()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn camera(position: DVec3, yaw: f64) -> Camera {
        Camera {
            position,
            yaw,
            pitch: -0.2,
            fov_y: 1.0,
        }
    }

    /// Feeds `pose(t)` at `fps` frames per second up to `until` (a prefix of the path only)
    /// and returns each horizon with the largest error there (metres, heading radians) over
    /// the prefix's last three seconds.
    fn errors(pose: impl Fn(f64) -> Camera, fps: f64, until: f64) -> Vec<(f64, f64, f64)> {
        let mut p = Predictor::default();
        let mut worst: Vec<(f64, f64, f64)> = Vec::new();
        let frames = (until * fps) as u32;
        for k in 0..=frames {
            let t = f64::from(k) / fps;
            p.observe(t, &pose(t));
            if t < until - 3.0 || (k as usize) < DEFAULT_POSES {
                continue;
            }
            let horizons = p.horizons();
            worst.resize(horizons.len(), (0.0, 0.0, 0.0));
            for (w, h) in worst.iter_mut().zip(horizons) {
                let predicted = p.predict(h).unwrap();
                let actual = pose(t + h);
                let e = predicted.position.distance(actual.position);
                let yaw = wrap(predicted.yaw - actual.yaw).abs();
                *w = (h, w.1.max(e), w.2.max(yaw));
            }
        }
        assert!(!worst.is_empty(), "nothing predicted");
        worst
    }

    #[test]
    fn horizons_are_the_longer_of_seconds_and_frames_at_most_four_seconds() {
        let line = |t: f64| camera(DVec3::new(10.0 * t, 0.0, 0.0), 0.0);
        let at = |fps: f64| {
            let mut p = Predictor::default();
            assert_eq!(p.horizons(), HORIZONS_S, "no poses yet");
            for k in 0..10 {
                let t = f64::from(k) / fps;
                p.observe(t, &line(t));
            }
            p.horizons()
        };
        let near = |a: Vec<f64>, b: &[f64]| {
            a.len() == b.len() && a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-9)
        };
        // Interactive rates: the seconds; a few frames per second: the frames; slower: capped.
        assert!(near(at(60.0), &[0.25, 0.5, 1.0, 2.0]), "{:?}", at(60.0));
        assert!(near(at(2.5), &[0.4, 0.8, 1.6, 3.2]), "{:?}", at(2.5));
        // The 8-frame horizon would be capped to 4 s again: left out.
        assert!(near(at(1.0), &[1.0, 2.0, 4.0]), "{:?}", at(1.0));
    }

    #[test]
    fn a_straight_line_is_predicted_exactly() {
        let v = DVec3::new(80.0, -35.0, 4.0);
        let line = |t: f64| camera(DVec3::new(100.0, 200.0, 900.0) + v * t, 0.7);
        for fps in [30.0, 2.5] {
            for (h, e, yaw) in errors(line, fps, 6.0) {
                assert!(
                    e < 1e-6 && yaw < 1e-9,
                    "{fps} fps, horizon {h}: {e} m, {yaw} rad"
                );
            }
        }
    }

    #[test]
    fn a_constant_turn_is_predicted_within_the_jerk_bound() {
        // 100 m/s on a circle of 2 km, facing along the motion, crossing the +-pi heading seam.
        let (v, r) = (100.0, 2000.0);
        let w = v / r;
        let turn = |t: f64| {
            let a = w * t + 2.5;
            camera(
                DVec3::new(r * a.cos(), r * a.sin(), 800.0),
                a + std::f64::consts::FRAC_PI_2,
            )
        };
        for fps in [30.0, 2.5] {
            let window = (DEFAULT_POSES - 1) as f64 / fps;
            let worst = errors(turn, fps, 10.0);
            for &(h, e, yaw) in &worst {
                // The cubic term the quadratic misses, over the horizon and the fitted window.
                let bound = v * w * w * (h + window).powi(3) / 6.0;
                assert!(e <= bound, "{fps} fps, horizon {h}: {e} m > {bound} m");
                assert!(
                    yaw < 1e-9,
                    "{fps} fps, horizon {h}: heading off by {yaw} rad"
                );
                // A straight line through the same samples would be off by about v w h^2 / 2:
                // the quadratic is at least five times closer.
                let straight = v * w * h * h / 2.0;
                assert!(
                    e < 0.2 * straight,
                    "{fps} fps, horizon {h}: {e} m vs {straight} m"
                );
            }
        }
    }

    #[test]
    fn stop_and_go_never_overshoots_past_a_constant_velocity_guess() {
        // Moves east at 60 m/s, stops dead at t = 2 s, waits, goes again at t = 6 s.
        let v = 60.0;
        let x = |t: f64| {
            if t < 2.0 {
                v * t
            } else if t < 6.0 {
                2.0 * v
            } else {
                2.0 * v + v * (t - 6.0)
            }
        };
        let path = |t: f64| camera(DVec3::new(x(t), 0.0, 500.0), 0.0);
        for fps in [30.0, 2.5] {
            let mut p = Predictor::default();
            for k in 0..=(8.0 * fps) as u32 {
                let t = f64::from(k) / fps;
                p.observe(t, &path(t));
                for h in p.horizons() {
                    let c = p.predict(h).unwrap();
                    let e = c.position.distance(path(t + h).position);
                    assert!(e <= v * h + 1e-6, "{fps} fps, t {t}, horizon {h}: {e} m");
                    // Braking never turns into going back.
                    let x = path(t).position.x;
                    assert!(c.position.x >= x - 1e-6, "{fps} fps, t {t}: reversed");
                }
                // Still for the whole window: exact.
                let still = t >= 2.0 + DEFAULT_POSES as f64 / fps && t + 1.0 < 6.0;
                if still {
                    let e = p.predict(1.0).unwrap().position.distance(path(t).position);
                    assert!(e < 1e-9, "{fps} fps, t {t}: {e} m while still");
                }
            }
        }
    }

    #[test]
    fn predictions_use_only_the_poses_given() {
        // Two paths share their first 3 s and then part; the predictions over the shared
        // prefix are identical, and differ after (so they do follow the poses).
        let a = |t: f64| camera(DVec3::new(50.0 * t, 0.0, 500.0), 0.0);
        let b = |t: f64| {
            let y = if t > 3.0 {
                400.0 * (t - 3.0).powi(2)
            } else {
                0.0
            };
            camera(DVec3::new(50.0 * t, y, 500.0), 0.0)
        };
        let (mut pa, mut pb) = (Predictor::default(), Predictor::default());
        let mut parted = false;
        for k in 0..150u32 {
            let t = f64::from(k) / 30.0;
            pa.observe(t, &a(t));
            pb.observe(t, &b(t));
            let (ca, cb) = (pa.predict(1.0).unwrap(), pb.predict(1.0).unwrap());
            if t <= 3.0 {
                assert_eq!(ca, cb, "t {t}: the prediction saw the future");
            } else {
                parted |= ca != cb;
            }
        }
        assert!(parted);
    }

    #[test]
    fn scored_error_is_the_distance_to_the_pose_flown() {
        let line = |t: f64| camera(DVec3::new(10.0 * t, 0.0, 0.0), 0.0);
        let mut p = Predictor::default();
        p.observe(0.0, &line(0.0));
        p.observe(0.1, &line(0.1));
        p.remember(0.25);
        assert!(p.score().is_nan(), "not due yet");
        // The camera then stops: the prediction (at 3.5 m) misses by 2.5 m at t = 0.35.
        p.observe(0.2, &line(0.1));
        p.observe(0.4, &line(0.1));
        let e = p.score();
        assert!((e - 2.5).abs() < 1e-9, "{e}");
        assert!(p.score().is_nan(), "scored once");
        // Time going back starts afresh.
        p.observe(0.0, &line(5.0));
        assert_eq!(p.predict(1.0).unwrap().position, line(5.0).position);
    }
}
