//! One frame, step by step (DESIGN.md, "The frame"): cull, choose levels, stitch, make tiles
//! resident, record one indexed fan draw per tile plus the stitches, submit, and time it all.

use std::collections::HashMap;
use std::time::Instant;

use ash::vk;
use bytemuck::{Pod, Zeroable};
use glam::DVec3;

use crate::camera::Camera;
use crate::log::FrameRecord;
use crate::residency::{Residency, WholeTileLru};
use crate::stitch::{stitch_side, Stitch};
use crate::target::{Target, COLOR_FORMAT, DEPTH_FORMAT};
use crate::terrain::Terrain;
use crate::vulkan::buffer::BufferDesc;
use crate::vulkan::pipeline::TerrainPipeline;
use crate::vulkan::timestamps::Timestamps;
use crate::vulkan::{Buffer, Gpu, VkError, VkResult};
use crate::{cull, lod};

/// How to draw.
#[derive(Clone, Debug)]
pub struct Settings {
    /// Pixel tolerance.
    pub tau: f64,
    /// Draw every visible tile at this level.
    pub forced_level: Option<u32>,
    /// Draw every visible tile at its finest level (the baseline).
    pub brute_force: bool,
    pub level_colours: bool,
    pub wireframe: bool,
    pub sky: [f32; 3],
    /// Diagnostic: leave the seams open, to see (and test) what stitching closes.
    pub no_stitch: bool,
}

/// Where a windowed frame goes: the acquired swapchain image, copied into after rendering.
#[derive(Clone, Copy, Debug)]
pub struct Present {
    pub image: vk::Image,
    pub extent: vk::Extent2D,
    /// Signalled when the image is acquired; the copy waits for it.
    pub acquired: vk::Semaphore,
    /// Signalled when the copy is done; presentation waits for it.
    pub done: vk::Semaphore,
}

/// Where a frame goes: the render target, whether to read it back, and the window image to
/// copy it into.
pub struct Output<'t> {
    pub target: &'t mut Target,
    pub screenshot: bool,
    pub present: Option<Present>,
}

/// Per-draw constants, laid out as the vertex shader's push-constant block.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct DrawConstants {
    view_proj: [f32; 16],
    camera: [f32; 4],
    tile_offset: [i32; 2],
    spacing_y: f32,
    height_step: f32,
    height_base: i32,
    level: u32,
    pad: [u32; 2],
    tint: [f32; 4],
}

const _: () = assert!(
    std::mem::size_of::<DrawConstants>() == crate::vulkan::pipeline::PUSH_CONSTANT_BYTES as usize
);

/// Debug colours of levels 0.. (coarse blue to fine red).
const LEVEL_COLOURS: [[f32; 3]; 10] = [
    [0.10, 0.20, 0.90],
    [0.10, 0.55, 0.95],
    [0.10, 0.85, 0.85],
    [0.15, 0.80, 0.30],
    [0.60, 0.90, 0.10],
    [0.95, 0.90, 0.10],
    [0.98, 0.60, 0.10],
    [0.95, 0.30, 0.10],
    [0.85, 0.10, 0.10],
    [0.60, 0.05, 0.40],
];

/// A tile's data on the GPU: all vertex blocks, and every level's index array.
struct GpuTile {
    vertices: Buffer,
    indices: Buffer,
    /// Per level: byte offset in `indices`, index count, index type.
    levels: Vec<(u64, u32, vk::IndexType)>,
}

pub struct Renderer {
    pipeline: TerrainPipeline,
    pool: vk::CommandPool,
    cmd: vk::CommandBuffer,
    fence: vk::Fence,
    timestamps: Timestamps,
    tiles: HashMap<usize, GpuTile>,
    residency: Box<dyn Residency>,
    stitch_buffer: Option<Buffer>,
    frame: u64,
}

/// A frame recorded once and replayed (see [`Renderer::record_static`]).
pub struct StaticFrame {
    cmd: vk::CommandBuffer,
    stitch: Option<Buffer>,
    staging: Vec<Buffer>,
    record: FrameRecord,
}

/// What was drawn for a tile this frame.
struct Draw {
    tile: usize,
    level: u32,
}

impl Renderer {
    pub fn new(gpu: &Gpu, gpu_budget_bytes: u64) -> VkResult<Renderer> {
        let pipeline = TerrainPipeline::new(gpu, COLOR_FORMAT, DEPTH_FORMAT)?;
        let pool_info = vk::CommandPoolCreateInfo::default()
            .queue_family_index(gpu.queue_family)
            .flags(vk::CommandPoolCreateFlags::RESET_COMMAND_BUFFER);
        // SAFETY: valid create infos on a live device; each object is destroyed in `destroy`.
        let (pool, cmd, fence) = unsafe {
            let pool = gpu.device.create_command_pool(&pool_info, None)?;
            let alloc = vk::CommandBufferAllocateInfo::default()
                .command_pool(pool)
                .level(vk::CommandBufferLevel::PRIMARY)
                .command_buffer_count(1);
            let cmd = gpu.device.allocate_command_buffers(&alloc)?[0];
            let fence = gpu
                .device
                .create_fence(&vk::FenceCreateInfo::default(), None)?;
            (pool, cmd, fence)
        };
        gpu.name(pool, "frame command pool");
        gpu.name(cmd, "frame commands");
        gpu.name(fence, "frame fence");
        let timestamps = Timestamps::new(gpu)?;
        Ok(Renderer {
            pipeline,
            pool,
            cmd,
            fence,
            timestamps,
            tiles: HashMap::new(),
            residency: Box::new(WholeTileLru::new(gpu_budget_bytes)),
            stitch_buffer: None,
            frame: 0,
        })
    }

    /// Renders one frame into `target`; with `screenshot`, returns its RGBA8 pixels.
    pub fn render(
        &mut self,
        gpu: &Gpu,
        terrain: &Terrain,
        camera: &Camera,
        settings: &Settings,
        output: Output<'_>,
    ) -> VkResult<(FrameRecord, Option<Vec<u8>>)> {
        let present = output.present;
        let screenshot = output.screenshot;
        let (mut record, staging) = self.record(
            gpu,
            terrain,
            camera,
            settings,
            &*output.target,
            screenshot,
            present,
        )?;
        self.submit_and_wait(gpu, self.cmd, present)?;
        for s in staging {
            s.destroy(gpu);
        }
        record.gpu_ms = self.timestamps.read_ms(gpu).unwrap_or(f64::NAN);
        let pixels = if screenshot {
            output.target.pixels()
        } else {
            None
        };
        self.frame += 1;
        Ok((record, pixels))
    }

    /// Records a whole frame into `self.cmd` (culling, levels, stitches, uploads, draws);
    /// returns its record and the staging buffers to free after it ran.
    #[allow(clippy::too_many_arguments)]
    fn record(
        &mut self,
        gpu: &Gpu,
        terrain: &Terrain,
        camera: &Camera,
        settings: &Settings,
        target: &Target,
        screenshot: bool,
        present: Option<Present>,
    ) -> VkResult<(FrameRecord, Vec<Buffer>)> {
        let extent = target.extent();
        let view = camera.view(extent.width, extent.height);
        let mut record = FrameRecord {
            frame: self.frame,
            tiles_per_level: vec![0; terrain.levels as usize],
            ..Default::default()
        };

        // 2. Cull, front to back.
        let t = Instant::now();
        let planes = view.frustum();
        let mut visible: Vec<(f64, usize)> = terrain
            .tiles
            .iter()
            .enumerate()
            .filter(|(_, tile)| cull::visible(&planes, camera.position, tile))
            .map(|(i, tile)| {
                (
                    camera
                        .position
                        .clamp(tile.min, tile.max)
                        .distance_squared(camera.position),
                    i,
                )
            })
            .collect();
        visible.sort_by(|a, b| a.0.total_cmp(&b.0));
        record.cpu_cull_ms = ms(t);
        record.tiles_visible = visible.len() as u64;

        // 3. Levels.
        let t = Instant::now();
        let finest = terrain.levels - 1;
        let draws: Vec<Draw> = visible
            .iter()
            .map(|&(_, i)| {
                let tile = &terrain.tiles[i];
                let level = if settings.brute_force {
                    finest
                } else if let Some(l) = settings.forced_level {
                    l.min(finest)
                } else {
                    lod::level_for(
                        tile,
                        lod::tolerable_error(&view, camera.position, tile, settings.tau),
                    )
                };
                Draw { tile: i, level }
            })
            .collect();
        record.cpu_lod_ms = ms(t);

        // 5. Stitches between visible neighbours (each pair once: east and south sides).
        let t = Instant::now();
        let level_of: HashMap<usize, u32> = draws.iter().map(|d| (d.tile, d.level)).collect();
        let mut stitches: Vec<(usize, Stitch)> = Vec::new();
        for d in &draws {
            let a = &terrain.tiles[d.tile];
            let mut s = Stitch::default();
            for (k, (dx, dy)) in [(1usize, (1i64, 0i64)), (2, (0, 1))] {
                let (nx, ny) = (i64::from(a.tx) + dx, i64::from(a.ty) + dy);
                let Some(j) = u32::try_from(nx)
                    .ok()
                    .zip(u32::try_from(ny).ok())
                    .and_then(|(x, y)| terrain.tile_index(x, y))
                else {
                    continue;
                };
                if let Some(&lb) = level_of.get(&j) {
                    if !stitch_side(&mut s, a, d.level, &terrain.tiles[j], lb, k) {
                        return Err(VkError::Unsupported(format!(
                            "tiles {},{} and {},{} do not share their border (corrupted tile set?)",
                            a.tx, a.ty, terrain.tiles[j].tx, terrain.tiles[j].ty
                        )));
                    }
                }
            }
            if s.triangles > 0 {
                stitches.push((d.tile, s));
            }
        }
        record.stitch_triangles = stitches.iter().map(|(_, s)| u64::from(s.triangles)).sum();
        record.cpu_stitch_ms = ms(t);

        // 4. Residency and uploads (recorded into this frame's command buffer).
        let t = Instant::now();
        // SAFETY: the previous frame's fence was waited on, so the buffer is idle.
        unsafe {
            gpu.device
                .reset_command_buffer(self.cmd, vk::CommandBufferResetFlags::empty())?;
            gpu.device.begin_command_buffer(
                self.cmd,
                &vk::CommandBufferBeginInfo::default()
                    .flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT),
            )?;
        }
        self.timestamps.begin(gpu, self.cmd);
        let in_use: std::collections::HashSet<usize> = draws.iter().map(|d| d.tile).collect();
        let mut staging: Vec<Buffer> = Vec::new();
        for d in &draws {
            let info = &terrain.tiles[d.tile];
            let evicted = self
                .residency
                .admit(d.tile, info.bytes, self.frame, &|t| in_use.contains(&t));
            for e in evicted {
                if let Some(old) = self.tiles.remove(&e) {
                    old.vertices.destroy(gpu);
                    old.indices.destroy(gpu);
                    record.evictions += 1;
                }
            }
            if !self.tiles.contains_key(&d.tile) {
                let (tile, stage) = self.upload(gpu, terrain, d.tile)?;
                record.upload_bytes += stage.size;
                staging.push(stage);
                self.tiles.insert(d.tile, tile);
            }
        }
        if !staging.is_empty() {
            let barrier = vk::MemoryBarrier::default()
                .src_access_mask(vk::AccessFlags::TRANSFER_WRITE)
                .dst_access_mask(
                    vk::AccessFlags::VERTEX_ATTRIBUTE_READ | vk::AccessFlags::INDEX_READ,
                );
            // SAFETY: recording; the copies above write the buffers the draws below read.
            unsafe {
                gpu.device.cmd_pipeline_barrier(
                    self.cmd,
                    vk::PipelineStageFlags::TRANSFER,
                    vk::PipelineStageFlags::VERTEX_INPUT,
                    vk::DependencyFlags::empty(),
                    &[barrier],
                    &[],
                    &[],
                );
            }
        }
        record.resident_bytes = self.residency.resident_bytes();
        let stitch_ranges = self.write_stitches(gpu, &stitches)?;
        record.cpu_upload_ms = ms(t);

        // 6. Record the draws.
        let t = Instant::now();
        self.begin_rendering(gpu, target, settings.sky);
        let pipeline = if settings.wireframe {
            self.pipeline.wireframe.unwrap_or(self.pipeline.fill)
        } else {
            self.pipeline.fill
        };
        let (sx, sy) = terrain.spacing;
        let cells = f64::from(tiles::mesh::TILE_CELLS);
        let cam_tile = (
            (camera.position.x / (cells * sx)).floor(),
            (-camera.position.y / (cells * sy)).floor(),
        );
        let cam_rel = DVec3::new(
            camera.position.x - cam_tile.0 * cells * sx,
            camera.position.y + cam_tile.1 * cells * sy,
            camera.position.z,
        );
        let constants = |tile: usize, level: u32| {
            let info = &terrain.tiles[tile];
            let colour = LEVEL_COLOURS[(level as usize).min(LEVEL_COLOURS.len() - 1)];
            DrawConstants {
                view_proj: view.view_proj.to_cols_array(),
                camera: [
                    cam_rel.x as f32,
                    cam_rel.y as f32,
                    cam_rel.z as f32,
                    sx as f32,
                ],
                tile_offset: [
                    ((f64::from(info.tx) - cam_tile.0) * cells) as i32,
                    ((f64::from(info.ty) - cam_tile.1) * cells) as i32,
                ],
                spacing_y: sy as f32,
                height_step: terrain.height_step,
                height_base: info.header.height_base,
                level,
                pad: [0; 2],
                tint: [
                    colour[0],
                    colour[1],
                    colour[2],
                    if settings.level_colours { 0.65 } else { 0.0 },
                ],
            }
        };
        // SAFETY: recording inside dynamic rendering; every bound buffer lives until the fence.
        unsafe {
            gpu.device
                .cmd_bind_pipeline(self.cmd, vk::PipelineBindPoint::GRAPHICS, pipeline);
            let stages = vk::ShaderStageFlags::VERTEX | vk::ShaderStageFlags::FRAGMENT;
            for d in &draws {
                let Some(g) = self.tiles.get(&d.tile) else {
                    continue;
                };
                let (offset, count, index_type) = g.levels[d.level as usize];
                let c = constants(d.tile, d.level);
                gpu.device.cmd_push_constants(
                    self.cmd,
                    self.pipeline.layout,
                    stages,
                    0,
                    bytemuck::bytes_of(&c),
                );
                gpu.device
                    .cmd_bind_vertex_buffers(self.cmd, 0, &[g.vertices.raw], &[0]);
                gpu.device
                    .cmd_bind_index_buffer(self.cmd, g.indices.raw, offset, index_type);
                gpu.device.cmd_draw_indexed(self.cmd, count, 1, 0, 0, 0);
                let entry = &terrain.tiles[d.tile].levels[d.level as usize];
                record.triangles += u64::from(entry.triangle_count);
                record.vertices += u64::from(entry.vertex_count());
                record.tiles_drawn += 1;
                record.tiles_per_level[d.level as usize] += 1;
            }
            if let Some(buffer) = self.stitch_buffer.as_ref().filter(|_| !settings.no_stitch) {
                for ((tile, _), &(vertex_offset, index_offset, count)) in
                    stitches.iter().zip(&stitch_ranges)
                {
                    let c = constants(*tile, level_of[tile]);
                    gpu.device.cmd_push_constants(
                        self.cmd,
                        self.pipeline.layout,
                        stages,
                        0,
                        bytemuck::bytes_of(&c),
                    );
                    gpu.device.cmd_bind_vertex_buffers(
                        self.cmd,
                        0,
                        &[buffer.raw],
                        &[vertex_offset],
                    );
                    gpu.device.cmd_bind_index_buffer(
                        self.cmd,
                        buffer.raw,
                        index_offset,
                        vk::IndexType::UINT32,
                    );
                    gpu.device.cmd_draw_indexed(self.cmd, count, 1, 0, 0, 0);
                }
            }
            gpu.device.cmd_end_rendering(self.cmd);
        }
        if screenshot {
            target.record_readback(gpu, self.cmd);
        }
        if let Some(p) = &present {
            target.record_blit(gpu, self.cmd, p.image, p.extent, screenshot);
        }
        self.timestamps.end(gpu, self.cmd);
        // SAFETY: recording began above.
        unsafe { gpu.device.end_command_buffer(self.cmd)? };
        record.cpu_record_ms = ms(t);

        Ok((record, staging))
    }

    /// Submits `cmd` and waits for it: frames are measured one at a time.
    fn submit_and_wait(
        &self,
        gpu: &Gpu,
        cmd: vk::CommandBuffer,
        present: Option<Present>,
    ) -> VkResult<()> {
        let cmds = [cmd];
        let waits: Vec<vk::Semaphore> = present.iter().map(|p| p.acquired).collect();
        let stages = vec![vk::PipelineStageFlags::TRANSFER; waits.len()];
        let signals: Vec<vk::Semaphore> = present.iter().map(|p| p.done).collect();
        let submit = vk::SubmitInfo::default()
            .command_buffers(&cmds)
            .wait_semaphores(&waits)
            .wait_dst_stage_mask(&stages)
            .signal_semaphores(&signals);
        // SAFETY: the command buffer is complete; the fence is unsignalled.
        unsafe {
            gpu.device.queue_submit(gpu.queue, &[submit], self.fence)?;
            gpu.device.wait_for_fences(&[self.fence], true, u64::MAX)?;
            gpu.device.reset_fences(&[self.fence])?;
        }
        Ok(())
    }

    /// Records a frame into its own command buffer, for replay without any per-frame work
    /// (the draw-only limit). Tiles should be resident already (fly the path once first).
    pub fn record_static(
        &mut self,
        gpu: &Gpu,
        terrain: &Terrain,
        camera: &Camera,
        settings: &Settings,
        target: &Target,
    ) -> VkResult<StaticFrame> {
        let alloc = vk::CommandBufferAllocateInfo::default()
            .command_pool(self.pool)
            .level(vk::CommandBufferLevel::PRIMARY)
            .command_buffer_count(1);
        // SAFETY: allocation from our pool; freed in `destroy_static`.
        let cmd = unsafe { gpu.device.allocate_command_buffers(&alloc)? }[0];
        let own_cmd = std::mem::replace(&mut self.cmd, cmd);
        let own_stitch = self.stitch_buffer.take();
        let result = self.record(gpu, terrain, camera, settings, target, false, None);
        let stitch = std::mem::replace(&mut self.stitch_buffer, own_stitch);
        self.cmd = own_cmd;
        let (record, staging) = result?;
        Ok(StaticFrame {
            cmd,
            stitch,
            staging,
            record,
        })
    }

    /// Runs a recorded frame; returns its record with the GPU time.
    pub fn replay(&mut self, gpu: &Gpu, frame: &StaticFrame) -> VkResult<FrameRecord> {
        self.submit_and_wait(gpu, frame.cmd, None)?;
        let mut record = frame.record.clone();
        record.gpu_ms = self.timestamps.read_ms(gpu).unwrap_or(f64::NAN);
        Ok(record)
    }

    pub fn destroy_static(&self, gpu: &Gpu, frame: StaticFrame) {
        gpu.wait_idle();
        // SAFETY: the device is idle; the buffer came from our pool.
        unsafe { gpu.device.free_command_buffers(self.pool, &[frame.cmd]) };
        for b in frame.stitch.into_iter().chain(frame.staging) {
            b.destroy(gpu);
        }
    }

    /// Creates the tile's GPU buffers and records their upload from a staging buffer.
    fn upload(&self, gpu: &Gpu, terrain: &Terrain, index: usize) -> VkResult<(GpuTile, Buffer)> {
        let info = &terrain.tiles[index];
        let tile = terrain
            .set
            .tile(info.tx, info.ty)
            .map_err(|e| VkError::Unsupported(e.to_string()))?;
        let mut positions: Vec<u8> = Vec::new();
        let mut indices: Vec<u8> = Vec::new();
        let mut levels = Vec::new();
        for i in 0..terrain.levels {
            let Some(l) = tile.level(i) else { continue };
            positions.extend_from_slice(bytemuck::cast_slice(l.positions));
            while !indices.len().is_multiple_of(4) {
                indices.push(0);
            }
            let index_type = if l.entry.index_width == 2 {
                vk::IndexType::UINT16
            } else {
                vk::IndexType::UINT32
            };
            levels.push((indices.len() as u64, l.entry.index_count, index_type));
            indices.extend_from_slice(l.indices.bytes());
        }
        let name = format!("tile {},{}", info.tx, info.ty);
        let vertices = Buffer::new(
            gpu,
            BufferDesc::gpu_only(positions.len() as u64, vk::BufferUsageFlags::VERTEX_BUFFER),
            &format!("{name} vertex blocks"),
        )?;
        let index_buffer = Buffer::new(
            gpu,
            BufferDesc::gpu_only(indices.len() as u64, vk::BufferUsageFlags::INDEX_BUFFER),
            &format!("{name} index arrays"),
        )?;
        let mut staging = Buffer::new(
            gpu,
            BufferDesc::upload(
                (positions.len() + indices.len()) as u64,
                vk::BufferUsageFlags::TRANSFER_SRC,
            ),
            &format!("{name} staging"),
        )?;
        if !(staging.write(0, &positions) && staging.write(positions.len(), &indices)) {
            return Err(VkError::Unsupported(
                "staging memory is not host-visible".into(),
            ));
        }
        // SAFETY: recording outside rendering; sizes match the buffers.
        unsafe {
            gpu.device.cmd_copy_buffer(
                self.cmd,
                staging.raw,
                vertices.raw,
                &[vk::BufferCopy::default().size(positions.len() as u64)],
            );
            gpu.device.cmd_copy_buffer(
                self.cmd,
                staging.raw,
                index_buffer.raw,
                &[vk::BufferCopy::default()
                    .src_offset(positions.len() as u64)
                    .size(indices.len() as u64)],
            );
        }
        Ok((
            GpuTile {
                vertices,
                indices: index_buffer,
                levels,
            },
            staging,
        ))
    }

    /// Writes this frame's stitches into the host-visible stitch buffer; returns per stitch
    /// (vertex byte offset, index byte offset, index count).
    fn write_stitches(
        &mut self,
        gpu: &Gpu,
        stitches: &[(usize, Stitch)],
    ) -> VkResult<Vec<(u64, u64, u32)>> {
        let bytes: usize = stitches
            .iter()
            .map(|(_, s)| 4 * (s.vertices.len() + s.indices.len()))
            .sum();
        if bytes == 0 {
            return Ok(Vec::new());
        }
        if self
            .stitch_buffer
            .as_ref()
            .is_none_or(|b| (b.size as usize) < bytes)
        {
            if let Some(old) = self.stitch_buffer.take() {
                old.destroy(gpu);
            }
            let size = (bytes as u64).next_power_of_two().max(1 << 16);
            let usage = vk::BufferUsageFlags::VERTEX_BUFFER | vk::BufferUsageFlags::INDEX_BUFFER;
            self.stitch_buffer = Some(Buffer::new(
                gpu,
                BufferDesc::upload(size, usage),
                "stitch geometry",
            )?);
        }
        let buffer = self.stitch_buffer.as_mut().expect("created above");
        let mut ranges = Vec::with_capacity(stitches.len());
        let mut at = 0usize;
        for (_, s) in stitches {
            let v = at;
            buffer.write(v, bytemuck::cast_slice(&s.vertices));
            let i = v + 4 * s.vertices.len();
            buffer.write(i, bytemuck::cast_slice(&s.indices));
            at = i + 4 * s.indices.len();
            ranges.push((v as u64, i as u64, s.indices.len() as u32));
        }
        Ok(ranges)
    }

    fn begin_rendering(&self, gpu: &Gpu, target: &Target, sky: [f32; 3]) {
        let colour_range = vk::ImageSubresourceRange::default()
            .aspect_mask(vk::ImageAspectFlags::COLOR)
            .level_count(1)
            .layer_count(1);
        let depth_range = vk::ImageSubresourceRange::default()
            .aspect_mask(vk::ImageAspectFlags::DEPTH)
            .level_count(1)
            .layer_count(1);
        let barriers = [
            vk::ImageMemoryBarrier::default()
                .dst_access_mask(vk::AccessFlags::COLOR_ATTACHMENT_WRITE)
                .old_layout(vk::ImageLayout::UNDEFINED)
                .new_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)
                .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                .image(target.color.raw)
                .subresource_range(colour_range),
            vk::ImageMemoryBarrier::default()
                .dst_access_mask(
                    vk::AccessFlags::DEPTH_STENCIL_ATTACHMENT_WRITE
                        | vk::AccessFlags::DEPTH_STENCIL_ATTACHMENT_READ,
                )
                .old_layout(vk::ImageLayout::UNDEFINED)
                .new_layout(vk::ImageLayout::DEPTH_ATTACHMENT_OPTIMAL)
                .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                .image(target.depth.raw)
                .subresource_range(depth_range),
        ];
        let extent = target.extent();
        let colour = [vk::RenderingAttachmentInfo::default()
            .image_view(target.color.view)
            .image_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)
            .load_op(vk::AttachmentLoadOp::CLEAR)
            .store_op(vk::AttachmentStoreOp::STORE)
            .clear_value(vk::ClearValue {
                color: vk::ClearColorValue {
                    float32: [sky[0], sky[1], sky[2], 1.0],
                },
            })];
        // Reversed Z: clear to 0 (infinitely far).
        let depth = vk::RenderingAttachmentInfo::default()
            .image_view(target.depth.view)
            .image_layout(vk::ImageLayout::DEPTH_ATTACHMENT_OPTIMAL)
            .load_op(vk::AttachmentLoadOp::CLEAR)
            .store_op(vk::AttachmentStoreOp::DONT_CARE)
            .clear_value(vk::ClearValue {
                depth_stencil: vk::ClearDepthStencilValue {
                    depth: 0.0,
                    stencil: 0,
                },
            });
        let area = vk::Rect2D {
            offset: vk::Offset2D::default(),
            extent,
        };
        let info = vk::RenderingInfo::default()
            .render_area(area)
            .layer_count(1)
            .color_attachments(&colour)
            .depth_attachment(&depth);
        let viewport = vk::Viewport {
            x: 0.0,
            y: 0.0,
            width: extent.width as f32,
            height: extent.height as f32,
            min_depth: 0.0,
            max_depth: 1.0,
        };
        // SAFETY: recording; the images are the target's and transition from UNDEFINED (their
        // previous contents are not needed).
        unsafe {
            gpu.device.cmd_pipeline_barrier(
                self.cmd,
                vk::PipelineStageFlags::TOP_OF_PIPE,
                vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT
                    | vk::PipelineStageFlags::EARLY_FRAGMENT_TESTS
                    | vk::PipelineStageFlags::LATE_FRAGMENT_TESTS,
                vk::DependencyFlags::empty(),
                &[],
                &[],
                &barriers,
            );
            gpu.device.cmd_begin_rendering(self.cmd, &info);
            gpu.device.cmd_set_viewport(self.cmd, 0, &[viewport]);
            gpu.device.cmd_set_scissor(self.cmd, 0, &[area]);
        }
    }

    pub fn destroy(self, gpu: &Gpu) {
        gpu.wait_idle();
        for (_, t) in self.tiles {
            t.vertices.destroy(gpu);
            t.indices.destroy(gpu);
        }
        if let Some(b) = self.stitch_buffer {
            b.destroy(gpu);
        }
        self.timestamps.destroy(gpu);
        self.pipeline.destroy(gpu);
        // SAFETY: the device is idle; these are ours.
        unsafe {
            gpu.device.destroy_fence(self.fence, None);
            gpu.device.destroy_command_pool(self.pool, None);
        }
    }
}

fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1000.0
}
