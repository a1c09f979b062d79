//! The static-mesh limit (`vkterrain --static-grid N`, `tilebench limit`): what the device
//! takes to draw `N` triangles as terrain-like fans with the simplest shaders, so that "a
//! flight runs at the device's limit" is a ratio measured in one run rather than a guess.
//!
//! The mesh is a grid of fans, one per 2 x 2 cells (a centre and its eight neighbours, eight
//! triangles, primitive restart between fans), the shape of a full-resolution terrain level,
//! seen from above so that it covers the whole image, as the terrain does in the flights. The
//! vertex shader computes each position from its index (no memory read, no morph) and the
//! fragment shader writes one colour; attachments, depth test and clear are the terrain
//! pass's. Each frame is one command buffer, submitted and waited for, timed on the GPU.

use ash::vk;
use glam::{DVec3, Mat4};

use crate::camera::Camera;
use crate::target::{Target, COLOR_FORMAT, DEPTH_FORMAT};
use crate::vulkan::buffer::BufferDesc;
use crate::vulkan::pipeline::LimitPipeline;
use crate::vulkan::sync::{self, Commands};
use crate::vulkan::timestamps::Timestamps;
use crate::vulkan::{Buffer, Gpu, VkError, VkResult};

/// Metres between the grid's vertices (any: the camera frames the grid).
const SPACING: f32 = 10.0;

/// The fan grid with at least `triangles` triangles: `(vertices per row, indices)`.
pub fn fan_grid(triangles: u64) -> (u32, Vec<u32>) {
    let fans = triangles.div_ceil(8).max(1);
    let k = (fans as f64).sqrt().ceil() as u32;
    let side = 2 * k + 1;
    let at = |x: u32, y: u32| y * side + x;
    let mut indices = Vec::with_capacity(fans as usize * 11);
    'fans: for b in 0..k {
        for a in 0..k {
            if indices.len() as u64 >= fans * 11 {
                break 'fans;
            }
            let (cx, cy) = (2 * a + 1, 2 * b + 1);
            indices.push(at(cx, cy));
            // The ring counter-clockwise seen from above (x east, rows south), closed.
            let ring = [
                (-1i32, -1i32),
                (-1, 0),
                (-1, 1),
                (0, 1),
                (1, 1),
                (1, 0),
                (1, -1),
                (0, -1),
                (-1, -1),
            ];
            for (dx, dy) in ring {
                indices.push(at(cx.wrapping_add_signed(dx), cy.wrapping_add_signed(dy)));
            }
            indices.push(u32::MAX);
        }
    }
    (side, indices)
}

/// The static mesh's per-frame GPU times (ms, the whole command buffer: clear, draw) over
/// `frames` frames at `extent`, and the triangles it drew.
pub fn static_grid(
    gpu: &Gpu,
    triangles: u64,
    extent: (u32, u32),
    frames: u32,
) -> VkResult<(u64, Vec<f64>)> {
    let (side, indices) = fan_grid(triangles);
    let drawn = indices.iter().filter(|&&i| i == u32::MAX).count() as u64 * 8;
    let pipeline = LimitPipeline::new(gpu, COLOR_FORMAT, DEPTH_FORMAT)?;
    let result = (|| {
        let bytes = 4 * indices.len() as u64;
        let mut index_buffer = Buffer::new(
            gpu,
            BufferDesc::upload(bytes.max(4), vk::BufferUsageFlags::INDEX_BUFFER),
            "static-mesh limit indices",
        )?;
        let written = index_buffer.write(0, bytemuck::cast_slice(&indices));
        let target = Target::new(gpu, extent.0, extent.1);
        let commands = Commands::new(gpu, "static-mesh limit commands");
        let timestamps = Timestamps::new(gpu, "static-mesh limit timestamps");
        let fence = sync::fence(gpu, false, "static-mesh limit fence");
        let times = match (&target, &commands, &timestamps, &fence, written) {
            (Ok(target), Ok(commands), Ok(timestamps), Ok(fence), true) => {
                let push = push_constants(side, extent);
                let run = Run {
                    gpu,
                    pipeline: &pipeline,
                    target,
                    timestamps,
                    indices: (index_buffer.raw, indices.len() as u32),
                    push: &push,
                };
                run.frames(commands, *fence, frames)
            }
            (Err(e), ..) | (_, Err(e), ..) | (_, _, Err(e), ..) | (.., Err(e), _) => {
                Err(VkError::Unsupported(e.to_string()))
            }
            (.., false) => Err(VkError::Unsupported(
                "the limit's index buffer is not host-visible".into(),
            )),
        };
        gpu.wait_idle();
        if let Ok(f) = fence {
            sync::destroy_fence(gpu, f);
        }
        if let Ok(t) = timestamps {
            t.destroy(gpu);
        }
        if let Ok(c) = commands {
            c.destroy(gpu);
        }
        if let Ok(t) = target {
            t.destroy(gpu);
        }
        index_buffer.destroy(gpu);
        times
    })();
    pipeline.destroy(gpu);
    Ok((drawn, result?))
}

/// The camera above the grid's centre, looking down, framing its width.
fn push_constants(side: u32, extent: (u32, u32)) -> [u8; 72] {
    let width = f64::from(side - 1) * f64::from(SPACING);
    let fov_y = 60f64.to_radians();
    let aspect = f64::from(extent.0) / f64::from(extent.1.max(1));
    // The view is `2 h tan(fov / 2)` high and `aspect` times that wide: its width is the grid's.
    let h = width / (2.0 * (fov_y * 0.5).tan() * aspect);
    let camera = Camera {
        position: DVec3::new(width * 0.5, -width * 0.5, h),
        yaw: std::f64::consts::FRAC_PI_2,
        pitch: -std::f64::consts::FRAC_PI_2 + 1e-3,
        fov_y,
    };
    let view = camera.view(extent.0, extent.1);
    // Positions relative to the camera, as the terrain's: translate, then the view.
    let m = view.view_proj * Mat4::from_translation(-camera.position.as_vec3());
    let mut push = [0u8; 72];
    push[..64].copy_from_slice(bytemuck::cast_slice(&m.to_cols_array()));
    push[64..68].copy_from_slice(&side.to_le_bytes());
    push[68..72].copy_from_slice(&SPACING.to_le_bytes());
    push
}

/// One limit measurement's resources.
struct Run<'a> {
    gpu: &'a Gpu,
    pipeline: &'a LimitPipeline,
    target: &'a Target,
    timestamps: &'a Timestamps,
    indices: (vk::Buffer, u32),
    push: &'a [u8; 72],
}

impl Run<'_> {
    fn frames(&self, commands: &Commands, fence: vk::Fence, frames: u32) -> VkResult<Vec<f64>> {
        let gpu = self.gpu;
        let cmd = commands.allocate(gpu, "static-mesh limit frame")?;
        let mut times = Vec::with_capacity(frames as usize);
        for _ in 0..frames {
            sync::begin(gpu, cmd, true)?;
            self.timestamps.begin(gpu, cmd);
            self.timestamps.pass_begin(gpu, cmd);
            self.target.begin_rendering(gpu, cmd, [0.5, 0.7, 0.9]);
            // SAFETY: recording inside dynamic rendering; the index buffer outlives the frame,
            // which is waited for below.
            unsafe {
                gpu.device.cmd_bind_pipeline(
                    cmd,
                    vk::PipelineBindPoint::GRAPHICS,
                    self.pipeline.pipeline,
                );
                // The terrain tiles' state: their back faces culled (the grid has none).
                gpu.device.cmd_set_cull_mode(cmd, vk::CullModeFlags::BACK);
                gpu.device.cmd_push_constants(
                    cmd,
                    self.pipeline.layout,
                    vk::ShaderStageFlags::VERTEX,
                    0,
                    self.push,
                );
                gpu.device
                    .cmd_bind_index_buffer(cmd, self.indices.0, 0, vk::IndexType::UINT32);
                gpu.device.cmd_draw_indexed(cmd, self.indices.1, 1, 0, 0, 0);
                gpu.device.cmd_end_rendering(cmd);
            }
            self.timestamps.pass_end(gpu, cmd);
            self.timestamps.end(gpu, cmd);
            sync::end(gpu, cmd)?;
            sync::submit(gpu, cmd, fence, None, None)?;
            sync::wait_and_reset(gpu, fence)?;
            let ms = match self.timestamps.read_ticks(gpu) {
                Some(t) => self.timestamps.ms_between(t[0], t[3]),
                None => f64::NAN,
            };
            times.push(ms);
        }
        commands.free(gpu, cmd);
        Ok(times)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The grid has at least the triangles asked for, eight per fan, every index inside it,
    /// every fan a centre and its closed ring of eight neighbours.
    #[test]
    fn the_fan_grid_has_the_triangles_asked_for() {
        for n in [1u64, 8, 100, 401_000, 739_123] {
            let (side, indices) = fan_grid(n);
            let fans: Vec<&[u32]> = indices
                .split(|&i| i == u32::MAX)
                .filter(|f| !f.is_empty())
                .collect();
            assert_eq!(fans.len() as u64, n.div_ceil(8).max(1), "{n}");
            for f in &fans {
                assert_eq!(f.len(), 10);
                assert_eq!(f[1], f[9], "the ring is closed");
                let (cx, cy) = (f[0] % side, f[0] / side);
                for &v in &f[1..] {
                    let (x, y) = (v % side, v / side);
                    assert!(x.abs_diff(cx) <= 1 && y.abs_diff(cy) <= 1 && v != f[0]);
                }
            }
            assert!(indices.iter().all(|&i| i == u32::MAX || i < side * side));
        }
    }
}
