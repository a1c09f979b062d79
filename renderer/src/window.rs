//! Window mode: winit + ash-window + swapchain. Fly with WASD (Q/E down/up, Shift faster) and
//! the mouse (drag with the left button to look), `+`/`-` double or halve tau, `L` toggles
//! level colours, `F12` saves a screenshot, Escape or closing the window quits. Resizing
//! recreates the swapchain; a minimised window renders nothing.

use std::collections::HashSet;
use std::path::PathBuf;
use std::time::Instant;

use glam::DVec3;
use raw_window_handle::{HasDisplayHandle, HasWindowHandle};
use winit::application::ApplicationHandler;
use winit::dpi::PhysicalSize;
use winit::event::{ElementState, MouseButton, WindowEvent};
use winit::event_loop::{ActiveEventLoop, ControlFlow, EventLoop};
use winit::keyboard::{KeyCode, PhysicalKey};
use winit::window::{Window, WindowId};

use crate::camera::Camera;
use crate::frame::{Finished, FrameInput, Present, Renderer};
use crate::headless::{write_png, FlightResult};
use crate::log::FrameRecord;
use crate::path::{CameraPath, Keyframe};
use crate::settings::{ByDevice, MemoryOptions, Settings, Shading};
use crate::terrain::Terrain;
use crate::vulkan::swapchain::Swapchain;
use crate::vulkan::{Gpu, GpuOptions, VkError};

pub struct WindowOptions {
    pub gpu: GpuOptions,
    pub size: (u32, u32),
    pub settings: Settings,
    /// The choices left to the device.
    pub by_device: ByDevice,
    pub memory: MemoryOptions,
    /// Keep every frame's requests (`--trace`).
    pub trace: bool,
    /// Close after this many frames (for scripted runs and tests).
    pub frames: Option<u64>,
    /// Ask the window for a new size at a frame (for tests of resizing).
    pub resize_at: Vec<(u64, (u32, u32))>,
    pub screenshot_dir: PathBuf,
    /// Write the flown path here on exit.
    pub record: Option<PathBuf>,
    pub start: Camera,
}

struct Live {
    window: Window,
    swapchain: Swapchain,
}

struct App<'a> {
    gpu: Gpu,
    terrain: &'a Terrain,
    options: WindowOptions,
    renderer: Option<Renderer>,
    live: Option<Live>,
    camera: Camera,
    keys: HashSet<KeyCode>,
    dragging: bool,
    last_cursor: Option<(f64, f64)>,
    last_frame: Instant,
    started: Instant,
    frames: u64,
    records: Vec<FrameRecord>,
    path: Vec<Keyframe>,
    screenshot: bool,
    resize_pending: bool,
    error: Option<String>,
    trace: Option<String>,
    pool_bytes: u64,
    planned_from: u64,
    texture_bytes: u64,
    staging: bool,
    built_indices: bool,
    made_indices: bool,
    decoded_levels: bool,
}

/// Runs the window until it closes; returns the flight, the device's name and the number of
/// validation messages.
pub fn run(
    terrain: &Terrain,
    mut options: WindowOptions,
) -> Result<(FlightResult, String, u64, bool), String> {
    let event_loop =
        EventLoop::new().map_err(|e| format!("cannot open a window (is there a display?): {e}"))?;
    event_loop.set_control_flow(ControlFlow::Poll);
    let display = event_loop
        .display_handle()
        .map_err(|e| format!("no display handle: {e}"))?
        .as_raw();
    options.gpu.display = Some(display);
    let gpu = Gpu::new(&options.gpu).map_err(|e| e.to_string())?;
    let (by_device, settings, memory) = (
        options.by_device,
        &mut options.settings,
        &mut options.memory,
    );
    by_device.apply(&gpu, settings, memory);
    let camera = options.start;
    let mut app = App {
        gpu,
        terrain,
        options,
        renderer: None,
        live: None,
        camera,
        keys: HashSet::new(),
        dragging: false,
        last_cursor: None,
        last_frame: Instant::now(),
        started: Instant::now(),
        frames: 0,
        records: Vec::new(),
        path: Vec::new(),
        screenshot: false,
        resize_pending: false,
        error: None,
        trace: None,
        pool_bytes: 0,
        planned_from: 0,
        texture_bytes: 0,
        staging: false,
        built_indices: false,
        made_indices: false,
        decoded_levels: false,
    };
    let result = terrain.with_checks_ahead(|| event_loop.run_app(&mut app));
    app.shutdown();
    if let Some(e) = app.error.take() {
        return Err(e);
    }
    result.map_err(|e| e.to_string())?;
    if let Some(record) = &app.options.record {
        let mut keys = std::mem::take(&mut app.path);
        let end = Keyframe {
            time: app.started.elapsed().as_secs_f64(),
            camera: app.camera,
        };
        // Keyframes are sampled every half second; end on where the flight ended (a path
        // needs two keyframes, so a very short flight gets its end one second later).
        match keys.last() {
            Some(last) if end.time <= last.time => keys.push(Keyframe {
                time: last.time + 1.0,
                ..end
            }),
            _ => keys.push(end),
        }
        if keys.len() < 2 {
            keys.push(Keyframe {
                time: end.time + 1.0,
                ..end
            });
        }
        let path = CameraPath { keys };
        std::fs::write(record, path.to_csv()).map_err(|e| format!("{}: {e}", record.display()))?;
    }
    let validation = app.gpu.validation_messages();
    let result = FlightResult {
        records: std::mem::take(&mut app.records),
        trace: app.trace.take(),
        pool_bytes: app.pool_bytes,
        planned_from: app.planned_from,
        texture_bytes: app.texture_bytes,
        staging: app.staging,
        built_indices: app.built_indices,
        made_indices: app.made_indices,
        decoded_levels: app.decoded_levels,
        prime_ms: None,
        first_view_check_ms: 0.0,
        error: None,
    };
    // What the flight ended with (the window's keys may switch geomorphing).
    let parts = app.options.settings.geomorph && app.options.settings.part_by_part;
    Ok((result, app.gpu.device_name.clone(), validation, parts))
}

impl App<'_> {
    fn shutdown(&mut self) {
        if let Some(mut r) = self.renderer.take() {
            match r.finish_all(&self.gpu) {
                Ok(finished) => self.keep(finished),
                Err(e) => self.error = self.error.take().or(Some(e.to_string())),
            }
            self.trace = r.take_trace();
            self.pool_bytes = r.manager().pool_bytes();
            self.planned_from = r.manager().planned_from().0.len() as u64;
            self.texture_bytes = r.texture_bytes();
            self.staging = !r.pool().direct();
            self.built_indices = r.builds_indices();
            self.made_indices = r.makes_indices();
            self.decoded_levels = r.decodes_levels();
            r.destroy(&self.gpu);
        }
        self.gpu.wait_idle();
        if let Some(live) = self.live.take() {
            live.swapchain.destroy(&self.gpu);
            drop(live.window);
        }
    }

    /// Keeps finished frames' records and saves their screenshots.
    fn keep(&mut self, finished: Vec<Finished>) {
        for f in finished {
            if let Some(pixels) = f.pixels {
                let file = self
                    .options
                    .screenshot_dir
                    .join(format!("vkterrain_{:06}.png", f.record.frame));
                match write_png(&file, f.extent.0, f.extent.1, pixels) {
                    Ok(()) => eprintln!("vkterrain: screenshot {}", file.display()),
                    Err(e) => eprintln!("vkterrain: {e}"),
                }
            }
            self.records.push(f.record);
        }
    }

    fn fail(&mut self, event_loop: &ActiveEventLoop, e: impl std::fmt::Display) {
        self.error = Some(e.to_string());
        event_loop.exit();
    }

    fn open(&mut self, event_loop: &ActiveEventLoop) -> Result<(), String> {
        let (w, h) = self.options.size;
        let attributes = Window::default_attributes()
            .with_title("vkterrain")
            .with_inner_size(PhysicalSize::new(w, h));
        let window = event_loop
            .create_window(attributes)
            .map_err(|e| e.to_string())?;
        let display = window.display_handle().map_err(|e| e.to_string())?.as_raw();
        let handle = window.window_handle().map_err(|e| e.to_string())?.as_raw();
        let size = window.inner_size();
        let swapchain = Swapchain::new(
            &self.gpu,
            display,
            handle,
            (size.width.max(1), size.height.max(1)),
        )
        .map_err(|e| e.to_string())?;
        let extent = swapchain.extent;
        self.live = Some(Live { window, swapchain });
        let mut renderer = Renderer::new(
            &self.gpu,
            self.terrain,
            (extent.width.max(1), extent.height.max(1)),
            self.options.memory,
        )
        .map_err(|e| e.to_string())?;
        if self.options.trace {
            renderer.enable_trace();
        }
        crate::plan::check_view(
            self.terrain,
            &self.camera,
            (extent.width, extent.height),
            self.options.settings.planning(),
        );
        self.renderer = Some(renderer);
        Ok(())
    }

    fn resize(&mut self) -> Result<bool, VkError> {
        let Some(live) = self.live.as_mut() else {
            return Ok(false);
        };
        let size = live.window.inner_size();
        if size.width == 0 || size.height == 0 {
            return Ok(false);
        }
        live.swapchain
            .recreate(&self.gpu, (size.width, size.height))?;
        let extent = live.swapchain.extent;
        eprintln!("vkterrain: swapchain {}x{}", extent.width, extent.height);
        if let Some(r) = self.renderer.as_mut() {
            let finished = r.resize(&self.gpu, (extent.width, extent.height))?;
            self.keep(finished);
        }
        Ok(true)
    }

    fn fly(&mut self, dt: f64) {
        let forward = self.camera.forward();
        let flat = DVec3::new(forward.x, forward.y, 0.0).normalize_or_zero();
        let right = DVec3::new(flat.y, -flat.x, 0.0);
        let ground =
            self.terrain
                .max_height_near(self.camera.position.x, self.camera.position.y, 10.0);
        let mut speed = (self.camera.position.z - ground).abs().max(50.0) * 0.8;
        if self.keys.contains(&KeyCode::ShiftLeft) || self.keys.contains(&KeyCode::ShiftRight) {
            speed *= 4.0;
        }
        let mut v = DVec3::ZERO;
        for (key, dir) in [
            (KeyCode::KeyW, forward),
            (KeyCode::KeyS, -forward),
            (KeyCode::KeyD, right),
            (KeyCode::KeyA, -right),
            (KeyCode::KeyE, DVec3::Z),
            (KeyCode::KeyQ, -DVec3::Z),
        ] {
            if self.keys.contains(&key) {
                v += dir;
            }
        }
        self.camera.position += v * speed * dt;
    }

    fn frame(&mut self, event_loop: &ActiveEventLoop) {
        if self.resize_pending {
            match self.resize() {
                Ok(true) => self.resize_pending = false,
                Ok(false) => return,
                Err(e) => return self.fail(event_loop, e),
            }
        }
        let now = Instant::now();
        let dt = (now - self.last_frame).as_secs_f64().min(0.25);
        self.last_frame = now;
        self.fly(dt);
        let Some(live) = self.live.as_mut() else {
            return;
        };
        let size = live.window.inner_size();
        if size.width == 0 || size.height == 0 {
            return; // minimised
        }
        let Some(renderer) = self.renderer.as_mut() else {
            return;
        };
        // Wait only for this frame's slot; frames that finished meanwhile come back here.
        let (acquired, finished) = match renderer.begin_frame(&self.gpu) {
            Ok(r) => r,
            Err(e) => return self.fail(event_loop, e),
        };
        self.keep(finished);
        let Some(live) = self.live.as_mut() else {
            return;
        };
        let index = match live.swapchain.acquire(acquired) {
            Ok(Some((i, suboptimal))) => {
                self.resize_pending |= suboptimal;
                i
            }
            Ok(None) => {
                self.resize_pending = true;
                return;
            }
            Err(e) => return self.fail(event_loop, e),
        };
        let present = Present {
            image: live.swapchain.images[index as usize],
            extent: live.swapchain.extent,
            acquired,
            done: live.swapchain.rendered[index as usize],
        };
        let shot = std::mem::take(&mut self.screenshot);
        let Some(renderer) = self.renderer.as_mut() else {
            return;
        };
        let time_s = self.started.elapsed().as_secs_f64();
        let input = FrameInput {
            camera: &self.camera,
            time_s,
            label: self.frames,
            screenshot: shot,
            present: Some(present),
        };
        let finished = match renderer.render(&self.gpu, self.terrain, &self.options.settings, input)
        {
            Ok(f) => f,
            Err(e) => return self.fail(event_loop, e),
        };
        self.keep(finished);
        let Some(live) = self.live.as_mut() else {
            return;
        };
        match live.swapchain.present(&self.gpu, index, present.done) {
            Ok(true) => {}
            Ok(false) => self.resize_pending = true,
            Err(e) => return self.fail(event_loop, e),
        }
        if self.path.last().is_none_or(|k| time_s - k.time >= 0.5) {
            self.path.push(Keyframe {
                time: time_s,
                camera: self.camera,
            });
        }
        self.frames += 1;
        for &(at, (w, h)) in &self.options.resize_at {
            if self.frames == at {
                let _ = live.window.request_inner_size(PhysicalSize::new(w, h));
            }
        }
        if self.options.frames.is_some_and(|n| self.frames >= n) {
            event_loop.exit();
        }
    }
}

impl ApplicationHandler for App<'_> {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        if self.live.is_none() {
            if let Err(e) = self.open(event_loop) {
                self.fail(event_loop, e);
            }
        }
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, _id: WindowId, event: WindowEvent) {
        match event {
            WindowEvent::CloseRequested => event_loop.exit(),
            WindowEvent::Resized(_) => self.resize_pending = true,
            WindowEvent::RedrawRequested => self.frame(event_loop),
            WindowEvent::MouseInput {
                state,
                button: MouseButton::Left,
                ..
            } => {
                self.dragging = state == ElementState::Pressed;
                self.last_cursor = None;
            }
            WindowEvent::CursorMoved { position, .. } if self.dragging => {
                if let Some((x, y)) = self.last_cursor {
                    self.camera.yaw -= (position.x - x) * 0.003;
                    self.camera.pitch =
                        (self.camera.pitch - (position.y - y) * 0.003).clamp(-1.5, 1.5);
                }
                self.last_cursor = Some((position.x, position.y));
            }
            WindowEvent::KeyboardInput { event, .. } => {
                let PhysicalKey::Code(code) = event.physical_key else {
                    return;
                };
                if event.state == ElementState::Released {
                    self.keys.remove(&code);
                    return;
                }
                self.keys.insert(code);
                if event.repeat {
                    return;
                }
                let s = &mut self.options.settings;
                match code {
                    KeyCode::Escape => event_loop.exit(),
                    KeyCode::Equal | KeyCode::NumpadAdd => s.tau = (s.tau * 2.0).min(64.0),
                    KeyCode::Minus | KeyCode::NumpadSubtract => s.tau = (s.tau / 2.0).max(0.25),
                    KeyCode::KeyL => {
                        s.shading = if s.shading == Shading::Level {
                            Shading::Tint
                        } else {
                            Shading::Level
                        }
                    }
                    KeyCode::KeyT => s.shading = s.shading.next(),
                    KeyCode::KeyG => s.geomorph = !s.geomorph,
                    KeyCode::F12 => self.screenshot = true,
                    _ => {}
                }
                if matches!(
                    code,
                    KeyCode::Equal | KeyCode::NumpadAdd | KeyCode::Minus | KeyCode::NumpadSubtract
                ) {
                    eprintln!("vkterrain: tau = {} px", s.tau);
                }
            }
            _ => {}
        }
    }

    fn about_to_wait(&mut self, _event_loop: &ActiveEventLoop) {
        if let Some(live) = &self.live {
            live.window.request_redraw();
        }
    }
}
