//! Headless flights: render a path offscreen, frame `k` at path time `k * duration / N`
//! however long frames take (so two runs see the same views), write screenshots and the log.

use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::camera::Camera;
use crate::error::FrameError;
use crate::fault::Fault;
use crate::frame::{Finished, FrameInput, Renderer};
use crate::log::FrameRecord;
use crate::path::CameraPath;
use crate::settings::{MemoryOptions, Settings};
use crate::terrain::Terrain;
use crate::vulkan::{Gpu, VkError};

pub struct Flight<'a> {
    pub terrain: &'a Terrain,
    pub path: &'a CameraPath,
    pub frames: u64,
    pub size: (u32, u32),
    pub settings: Settings,
    pub memory: MemoryOptions,
    /// Keep every frame's requests (`vkterrain --trace`).
    pub trace: bool,
    /// Folder for screenshots, and how often (every k-th frame; 0 = never).
    pub out: Option<PathBuf>,
    pub screenshot_every: u64,
    /// Measure the draw-only limit: fly once to make tiles resident, record every frame's
    /// commands up front over what is resident (no uploads, no evictions), then time only
    /// their replay, one at a time (no culling, LOD, stitching, uploads or recording in the
    /// timed loop).
    pub draw_only: bool,
    /// Fly the path once untimed first, so the timed flight starts with its tiles resident.
    pub warmup: bool,
    /// After the warm-up, empty the pool: the timed flight streams its tiles from cold while
    /// the driver is warm (separates the streaming cold start from the driver's first use).
    pub forget_after_warmup: bool,
    /// Draw the first view once, untimed, before the timed flight (`--prime`): the driver
    /// compiles its shader variants and grows its memory then, and the first view's tiles
    /// arrive, as a loading screen would have it, instead of in the first frames.
    pub prime: bool,
}

#[derive(Debug, thiserror::Error)]
pub enum FlightError {
    #[error(transparent)]
    Gpu(#[from] VkError),
    #[error(transparent)]
    Frame(#[from] FrameError),
    #[error("{}: {error}", path.display())]
    Write { path: PathBuf, error: String },
    /// The vertex shader drew a height the CPU mirror does not compute
    /// (`--read-back-heights`).
    #[error(
        "tile {},{} vertex {}: the vertex shader's height differs from the CPU mirror's by {diff:.3e} m \
         ({over} of {vertices} vertices beyond float rounding)",
        tile.0, tile.1, tile.2
    )]
    MirrorMismatch {
        tile: (u32, u32, usize),
        diff: f64,
        over: u64,
        vertices: u64,
    },
    /// A timed frame failed.
    #[error("frame {frame}: {error}")]
    AtFrame { frame: u64, error: Box<FlightError> },
}

/// Writes an RGBA8 image as PNG through a temporary file.
pub fn write_png(path: &Path, width: u32, height: u32, rgba: Vec<u8>) -> Result<(), FlightError> {
    let err = |e: String| FlightError::Write {
        path: path.to_path_buf(),
        error: e,
    };
    let image = image::RgbaImage::from_raw(width, height, rgba)
        .ok_or_else(|| err("pixel buffer has the wrong size".into()))?;
    let tmp = path.with_extension("png.tmp");
    image
        .save_with_format(&tmp, image::ImageFormat::Png)
        .map_err(|e| err(e.to_string()))?;
    std::fs::rename(&tmp, path).map_err(|e| err(e.to_string()))
}

/// What a flight produced.
pub struct FlightResult {
    pub records: Vec<FrameRecord>,
    /// The requests of every frame (with `Flight::trace`).
    pub trace: Option<String>,
    pub pool_bytes: u64,
    /// Tiles whose tables the pool, its staging and the stitch buffer were sized from
    /// (`MemoryOptions::plan_sample`).
    pub planned_from: u64,
    /// Device memory of the texture slots.
    pub texture_bytes: u64,
    /// Uploads went through the staging ring.
    pub staging: bool,
    /// Index arrays were built (else sent from the file), and made on the CPU rather than by
    /// the GPU's builder.
    pub built_indices: bool,
    pub made_indices: bool,
    /// A compact set's levels were sent as their streams and decoded on the GPU.
    pub decoded_levels: bool,
    /// How long drawing the first view before the flight took (ms; None: not primed).
    pub prime_ms: Option<f64>,
    /// Checking the first view's tiles before the first frame (ms).
    pub first_view_check_ms: f64,
    /// Why the flight stopped early (the device was lost, a tile set changed under it, ...):
    /// `records` holds the frames that completed before.
    pub error: Option<FlightError>,
}

/// Flies the path and returns one record per frame; with `meter`, every k-th frame's error
/// against the source is measured (`max_error_px`).
pub fn fly(
    gpu: &Gpu,
    flight: &Flight,
    meter: Option<(crate::measure::ErrorMeter, u64)>,
) -> Result<FlightResult, FlightError> {
    let mut renderer = Renderer::new(gpu, flight.terrain, flight.size, flight.memory)?;
    if flight.trace {
        renderer.enable_trace();
    }
    if let Some((meter, every)) = meter {
        renderer.measure_error(meter, every);
    }
    let mut records = Vec::with_capacity(flight.frames.min(1 << 16) as usize);
    let mut prime_ms = None;
    // The first view's tiles are checked before the first frame (the rest as they are needed,
    // or ahead of need on a thread beside the frames).
    let (_, first) = camera_at(flight, 0);
    let begun = Instant::now();
    crate::plan::check_view(
        flight.terrain,
        &first,
        flight.size,
        flight.settings.planning(),
    );
    let first_view_check_ms = begun.elapsed().as_secs_f64() * 1000.0;
    let error = flight
        .terrain
        .with_checks_ahead(|| run(gpu, flight, &mut renderer, &mut records, &mut prime_ms))
        .err();
    if error.is_some() {
        // Frames submitted before the failure still count if the device can finish them.
        if let Ok(finished) = renderer.finish_all(gpu) {
            records.extend(finished.into_iter().map(|f| f.record));
        }
    }
    let trace = renderer.take_trace();
    let pool_bytes = renderer.manager().pool_bytes();
    let planned_from = renderer.manager().planned_from().0.len() as u64;
    let texture_bytes = renderer.texture_bytes();
    let staging = !renderer.pool().direct();
    let built_indices = renderer.builds_indices();
    let made_indices = renderer.makes_indices();
    let decoded_levels = renderer.decodes_levels();
    renderer.destroy(gpu);
    Ok(FlightResult {
        records,
        trace,
        pool_bytes,
        planned_from,
        texture_bytes,
        staging,
        built_indices,
        made_indices,
        decoded_levels,
        prime_ms,
        first_view_check_ms,
        error,
    })
}

/// Flies the timed frames, appending each finished frame's record to `records` (kept when
/// a later frame fails).
fn run(
    gpu: &Gpu,
    flight: &Flight,
    renderer: &mut Renderer,
    records: &mut Vec<FrameRecord>,
    prime_ms: &mut Option<f64>,
) -> Result<(), FlightError> {
    if flight.draw_only {
        *records = draw_only(gpu, flight, renderer)?;
        return Ok(());
    }
    if flight.warmup || flight.forget_after_warmup {
        warm_up(gpu, flight, renderer)?;
    } else if flight.prime {
        let begun = Instant::now();
        untimed(gpu, flight, renderer, 1)?;
        *prime_ms = Some(begun.elapsed().as_secs_f64() * 1000.0);
    }
    if flight.forget_after_warmup {
        renderer.forget_tiles(gpu)?;
    }
    for k in 0..flight.frames {
        let (t, camera) = camera_at(flight, k);
        let shot =
            flight.out.is_some() && flight.screenshot_every > 0 && k % flight.screenshot_every == 0;
        let input = FrameInput {
            camera: &camera,
            time_s: t,
            label: k,
            screenshot: shot,
            present: None,
        };
        let at = |error: FlightError| FlightError::AtFrame {
            frame: k,
            error: Box::new(error),
        };
        let finished = renderer
            .render(gpu, flight.terrain, &flight.settings, input)
            .map_err(|e| at(e.into()))?;
        keep(flight, finished, records).map_err(at)?;
    }
    let finished = renderer.finish_all(gpu)?;
    keep(flight, finished, records)?;
    Ok(())
}

/// Keeps finished frames' records and writes their screenshots.
fn keep(
    flight: &Flight,
    finished: Vec<Finished>,
    records: &mut Vec<FrameRecord>,
) -> Result<(), FlightError> {
    for mut f in finished {
        if let (Some(dir), Some(pixels)) = (&flight.out, f.pixels) {
            let file = dir.join(format!("frame_{:06}.png", f.record.frame));
            write_png(&file, f.extent.0, f.extent.1, pixels)?;
        }
        if let Some(heights) = &f.heights {
            let bias = i8::from(Fault::from_env() == Some(Fault::MirrorBias));
            let check = crate::measure::check_heights(flight.terrain, heights, bias);
            f.record.heights_read_back = check.vertices;
            f.record.heights_max_diff_m = check.max_diff_m;
            if let (true, Some(tile)) = (check.over > 0, check.worst) {
                let frame = f.record.frame;
                records.push(f.record);
                return Err(FlightError::AtFrame {
                    frame,
                    error: Box::new(FlightError::MirrorMismatch {
                        tile,
                        diff: check.max_diff_m,
                        over: check.over,
                        vertices: check.vertices,
                    }),
                });
            }
        }
        records.push(f.record);
    }
    Ok(())
}

/// Path time and camera of frame `k`: `k * duration / frames` from the path's start.
fn camera_at(flight: &Flight, k: u64) -> (f64, Camera) {
    let t = k as f64 * flight.path.duration() / flight.frames as f64;
    (t, flight.path.at(flight.path.keys[0].time + t))
}

/// Flies the path once, untimed, so every tile it needs is resident.
fn warm_up(gpu: &Gpu, flight: &Flight, renderer: &mut Renderer) -> Result<(), FlightError> {
    untimed(gpu, flight, renderer, flight.frames)
}

/// Flies the path's first `frames` frames untimed and unmeasured (the timed flight's first
/// frame has nothing before it to pop from).
fn untimed(
    gpu: &Gpu,
    flight: &Flight,
    renderer: &mut Renderer,
    frames: u64,
) -> Result<(), FlightError> {
    let meter = renderer.take_meter();
    let result = untimed_frames(gpu, flight, renderer, frames);
    if let Some((meter, every)) = meter {
        renderer.measure_error(meter, every);
    }
    result
}

fn untimed_frames(
    gpu: &Gpu,
    flight: &Flight,
    renderer: &mut Renderer,
    frames: u64,
) -> Result<(), FlightError> {
    for k in 0..frames.min(flight.frames) {
        let (t, camera) = camera_at(flight, k);
        let input = FrameInput {
            camera: &camera,
            time_s: t,
            label: k,
            screenshot: false,
            present: None,
        };
        renderer.render(gpu, flight.terrain, &flight.settings, input)?;
    }
    renderer.finish_all(gpu)?;
    Ok(())
}

fn draw_only(
    gpu: &Gpu,
    flight: &Flight,
    renderer: &mut Renderer,
) -> Result<Vec<FrameRecord>, FlightError> {
    let cameras: Vec<(f64, Camera)> = (0..flight.frames).map(|k| camera_at(flight, k)).collect();
    warm_up(gpu, flight, renderer)?;
    let mut frames = Vec::with_capacity(cameras.len());
    for (_, camera) in &cameras {
        match renderer.record_static(gpu, flight.terrain, camera, &flight.settings) {
            Ok(f) => frames.push(f),
            Err(e) => {
                for f in frames {
                    renderer.destroy_static(gpu, f);
                }
                return Err(e.into());
            }
        }
    }
    let mut records = Vec::with_capacity(frames.len());
    let mut failure = None;
    for (k, (frame, (t, _))) in frames.iter().zip(&cameras).enumerate() {
        let begun = Instant::now();
        match renderer.replay(gpu, frame) {
            Ok(mut record) => {
                record.frame_ms = begun.elapsed().as_secs_f64() * 1000.0;
                record.frame = k as u64;
                record.time_s = *t;
                // Nothing but the replay ran in the timed loop.
                (
                    record.cpu_cull_ms,
                    record.cpu_lod_ms,
                    record.cpu_stitch_ms,
                    record.cpu_residency_ms,
                    record.cpu_upload_ms,
                    record.cpu_record_ms,
                ) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
                records.push(record);
            }
            Err(e) => {
                failure = Some(e);
                break;
            }
        }
    }
    for f in frames {
        renderer.destroy_static(gpu, f);
    }
    match failure {
        Some(e) => Err(e.into()),
        None => Ok(records),
    }
}
