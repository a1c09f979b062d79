//! Camera paths: timed keyframes, interpolated smoothly (Catmull-Rom through positions,
//! shortest-arc interpolation of headings), read from a CSV file or generated from a tile
//! set's bounds so any new dataset can be flown at once.
//!
//! The CSV format, one keyframe per line after a header line:
//!
//! ```text
//! time_s,x_m,y_m,z_m,yaw_deg,pitch_deg,fov_deg
//! 0,1200,-3400,900,45,-10,60
//! ```
//!
//! x is metres east of the dataset's north-west sample, y metres north of it (so negative
//! over the data), z the height in metres; yaw 0 looks east and 90 north; pitch is above the
//! horizon; fov is vertical. Times must increase.

use std::path::Path;

use glam::DVec3;

use crate::camera::Camera;
use crate::terrain::Terrain;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Keyframe {
    pub time: f64,
    pub camera: Camera,
}

#[derive(Clone, Debug)]
pub struct CameraPath {
    pub keys: Vec<Keyframe>,
}

pub const CSV_HEADER: &str = "time_s,x_m,y_m,z_m,yaw_deg,pitch_deg,fov_deg";

impl CameraPath {
    pub fn duration(&self) -> f64 {
        self.keys.last().map_or(0.0, |k| k.time) - self.keys.first().map_or(0.0, |k| k.time)
    }

    /// Reads a CSV path; errors name the file and line.
    pub fn read(path: &Path) -> Result<CameraPath, String> {
        let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
        Self::parse(&text).map_err(|e| format!("{}: {e}", path.display()))
    }

    pub fn parse(text: &str) -> Result<CameraPath, String> {
        let mut keys = Vec::new();
        for (n, line) in text.lines().enumerate() {
            let line = line.trim();
            if line.is_empty() || line.starts_with('#') || line.starts_with("time") {
                continue;
            }
            let v: Vec<f64> = line
                .split(',')
                .map(|t| t.trim().parse::<f64>())
                .collect::<Result<_, _>>()
                .map_err(|_| format!("line {}: expected 7 numbers ({CSV_HEADER})", n + 1))?;
            if v.len() != 7 || v.iter().any(|x| !x.is_finite()) {
                return Err(format!(
                    "line {}: expected 7 finite numbers ({CSV_HEADER})",
                    n + 1
                ));
            }
            if v[6] <= 0.0 || v[6] >= 180.0 {
                return Err(format!(
                    "line {}: field of view {} is not in 0..180 degrees",
                    n + 1,
                    v[6]
                ));
            }
            if keys.last().is_some_and(|k: &Keyframe| k.time >= v[0]) {
                return Err(format!("line {}: times must increase", n + 1));
            }
            keys.push(Keyframe {
                time: v[0],
                camera: Camera {
                    position: DVec3::new(v[1], v[2], v[3]),
                    yaw: v[4].to_radians(),
                    pitch: v[5].to_radians(),
                    fov_y: v[6].to_radians(),
                },
            });
        }
        if keys.len() < 2 {
            return Err("a path needs at least two keyframes".into());
        }
        Ok(CameraPath { keys })
    }

    pub fn to_csv(&self) -> String {
        let mut s = format!("{CSV_HEADER}\n");
        for k in &self.keys {
            let c = k.camera;
            s += &format!(
                "{:.3},{:.3},{:.3},{:.3},{:.4},{:.4},{:.4}\n",
                k.time,
                c.position.x,
                c.position.y,
                c.position.z,
                c.yaw.to_degrees(),
                c.pitch.to_degrees(),
                c.fov_y.to_degrees()
            );
        }
        s
    }

    /// The camera at time `t` (clamped to the path).
    pub fn at(&self, t: f64) -> Camera {
        let keys = &self.keys;
        let t = t.clamp(keys[0].time, keys[keys.len() - 1].time);
        let i = keys
            .partition_point(|k| k.time <= t)
            .clamp(1, keys.len() - 1)
            - 1;
        let (k1, k2) = (&keys[i], &keys[i + 1]);
        let u = (t - k1.time) / (k2.time - k1.time);
        let k0 = if i > 0 { &keys[i - 1] } else { k1 };
        let k3 = if i + 2 < keys.len() { &keys[i + 2] } else { k2 };
        let p = catmull_rom(
            k0.camera.position,
            k1.camera.position,
            k2.camera.position,
            k3.camera.position,
            u,
        );
        let mix_angle = |a: f64, b: f64| {
            let d = (b - a + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
                - std::f64::consts::PI;
            a + d * u
        };
        Camera {
            position: p,
            yaw: mix_angle(k1.camera.yaw, k2.camera.yaw),
            pitch: k1.camera.pitch + (k2.camera.pitch - k1.camera.pitch) * u,
            fov_y: k1.camera.fov_y + (k2.camera.fov_y - k1.camera.fov_y) * u,
        }
    }

    /// A circle around the dataset at a good height, looking at its centre.
    pub fn orbit(terrain: &Terrain) -> CameraPath {
        let (min, max) = terrain.bounds();
        let centre = (min + max) * 0.5;
        let extent = (max.x - min.x).max(max.y - min.y);
        let radius = 0.55 * extent;
        let height = max.z + 0.25 * extent;
        let keys = (0..=24)
            .map(|i| {
                let a = i as f64 / 24.0 * std::f64::consts::TAU;
                let position = DVec3::new(
                    centre.x + radius * a.cos(),
                    centre.y + radius * a.sin(),
                    height,
                );
                let to = DVec3::new(centre.x, centre.y, (min.z + max.z) * 0.5) - position;
                Keyframe {
                    time: i as f64 * 2.0,
                    camera: Camera {
                        position,
                        yaw: to.y.atan2(to.x),
                        pitch: (to.z / to.truncate().length()).atan(),
                        fov_y: 60f64.to_radians(),
                    },
                }
            })
            .collect();
        CameraPath { keys }
    }

    /// A low pass across the dataset, diagonally, following the ground closely enough for
    /// grazing views (the camera stays a little above the highest ground beneath it).
    pub fn flyover(terrain: &Terrain) -> CameraPath {
        let (min, max) = terrain.bounds();
        let extent = (max.x - min.x).max(max.y - min.y);
        let clearance = (0.01 * extent).max(30.0);
        let n = 16;
        let mut keys = Vec::with_capacity(n + 1);
        for i in 0..=n {
            let u = 0.08 + 0.84 * i as f64 / n as f64;
            // A gentle S-curve from the south-west to the north-east.
            let x = min.x + (max.x - min.x) * u;
            let y = min.y
                + (max.y - min.y)
                    * (u + 0.12 * (u * std::f64::consts::TAU).sin()).clamp(0.02, 0.98);
            let ground = terrain.max_height_near(x, y, 0.04 * extent);
            let z = ground + clearance * (1.0 + 2.0 * (u * 9.0).sin().abs());
            keys.push((x, y, z));
        }
        let keys = keys
            .iter()
            .enumerate()
            .map(|(i, &(x, y, z))| {
                let (nx, ny, _) = keys[(i + 1).min(keys.len() - 1)];
                let (px, py, _) = keys[i.saturating_sub(1)];
                let (dx, dy) = if i + 1 < keys.len() {
                    (nx - x, ny - y)
                } else {
                    (x - px, y - py)
                };
                Keyframe {
                    time: i as f64 * 3.0,
                    camera: Camera {
                        position: DVec3::new(x, y, z),
                        yaw: dy.atan2(dx),
                        // Mostly near the horizon: grazing views of the ground ahead.
                        pitch: -(4.0 + 6.0 * ((i as f64) * 0.7).sin().abs()).to_radians(),
                        fov_y: 60f64.to_radians(),
                    },
                }
            })
            .collect();
        CameraPath { keys }
    }
}

fn catmull_rom(p0: DVec3, p1: DVec3, p2: DVec3, p3: DVec3, u: f64) -> DVec3 {
    let (u2, u3) = (u * u, u * u * u);
    0.5 * ((2.0 * p1)
        + (-p0 + p2) * u
        + (2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3) * u2
        + (-p0 + 3.0 * p1 - 3.0 * p2 + p3) * u3)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_round_trips_and_interpolates_through_keys() {
        let text = format!(
            "{CSV_HEADER}\n0,0,0,100,0,-10,60\n1,100,0,100,90,-10,60\n2,200,50,120,180,0,50\n"
        );
        let path = CameraPath::parse(&text).expect("parses");
        let again = CameraPath::parse(&path.to_csv()).expect("round trip");
        assert_eq!(again.keys.len(), 3);
        let c = path.at(1.0);
        assert!((c.position - DVec3::new(100.0, 0.0, 100.0)).length() < 1e-9);
        assert!((c.yaw.to_degrees() - 90.0).abs() < 1e-9);
        let mid = path.at(0.5);
        assert!(mid.position.x > 0.0 && mid.position.x < 100.0);
        assert!((mid.yaw.to_degrees() - 45.0).abs() < 1e-9);
        assert_eq!(path.at(-5.0).position, path.keys[0].camera.position);
    }

    #[test]
    fn headings_take_the_short_way_round() {
        let text = "0,0,0,0,350,0,60\n1,0,0,0,10,0,60\n";
        let path = CameraPath::parse(text).expect("parses");
        let y = path.at(0.5).yaw.to_degrees().rem_euclid(360.0);
        assert!((y - 0.0).abs() < 1e-6 || (y - 360.0).abs() < 1e-6, "{y}");
    }

    #[test]
    fn bad_paths_are_rejected_with_the_line() {
        assert!(CameraPath::parse("0,0,0,0,0,0,60\n")
            .unwrap_err()
            .contains("two keyframes"));
        assert!(CameraPath::parse("0,0,0,0,0,0,60\n0,1,1,1,0,0,60\n")
            .unwrap_err()
            .contains("line 2"));
        assert!(CameraPath::parse("0,0,0,0,0,0\n")
            .unwrap_err()
            .contains("line 1"));
        assert!(CameraPath::parse("0,0,0,0,0,0,200\n1,0,0,0,0,0,60")
            .unwrap_err()
            .contains("field of view"));
    }
}
