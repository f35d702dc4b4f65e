//! Drawing: [`Lighting`] and the view uniforms, the colour pass (multisampled, resolved) and the
//! id-and-depth pass, drawing static meshes and instance batches into a pass, and the frames
//! built from them: [`Renderer::render`] (colour, depth and ids, read back),
//! [`Renderer::render_instanced`] ([`InstanceBatch`]es, timed in [`FrameStats`]) and
//! [`Renderer::encode_color_frame`] (the GUI's frame, encoded into the caller's encoder).

use image::RgbaImage;
use nalgebra::Vector3;
use serde::Serialize;

use super::meshes::{INSTANCE_BYTES, instance_bytes};
use super::targets::Targets;
use super::{
    GpuScene, InstanceTransform, MeshHandle, RenderError, RenderOutput, Renderer, ViewCamera,
};

/// Background of instanced frames (a pale sky, linear).
const SKY: wgpu::Color = wgpu::Color {
    r: 0.52,
    g: 0.66,
    b: 0.82,
    a: 1.0,
};

/// Lighting of the colour pass.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lighting {
    /// Direction toward the key light, world frame.
    pub direction_world: Vector3<f64>,
    pub ambient: f32,
    pub key: f32,
    pub fill: f32,
}

impl Default for Lighting {
    fn default() -> Self {
        Self {
            direction_world: Vector3::new(0.35, -0.45, 1.0),
            ambient: 0.42,
            key: 0.5,
            fill: 0.12,
        }
    }
}

/// One instanced draw: `mesh` drawn once per transform in `instances` (a range into the
/// transforms given to [`Renderer::render_instanced`]).
#[derive(Clone, Debug, PartialEq)]
pub struct InstanceBatch {
    pub mesh: MeshHandle,
    pub instances: std::ops::Range<u32>,
}

/// What one instanced frame cost.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct FrameStats {
    pub draw_calls: usize,
    pub instances: usize,
    pub triangles: usize,
    /// Wall-clock seconds from encoding to the GPU finishing the frame.
    pub seconds: f64,
}

impl Renderer {
    /// The view uniforms (clip transform, camera depth row, lighting, eye) as a bind group.
    fn view_bind_group(&self, camera: &ViewCamera, lighting: &Lighting) -> wgpu::BindGroup {
        use wgpu::util::DeviceExt;
        let clip_from_world = camera.clip_from_camera() * camera.camera_from_world.to_homogeneous();
        let camera_matrix = camera.camera_from_world.to_homogeneous();
        let light = lighting.direction_world.normalize();
        let mut uniform: Vec<f32> = Vec::with_capacity(32);
        // Column-major, as WGSL expects.
        uniform.extend(clip_from_world.iter().map(|v| *v as f32));
        uniform.extend((0..4).map(|c| camera_matrix[(2, c)] as f32));
        uniform.extend([light.x as f32, light.y as f32, light.z as f32, 0.0]);
        uniform.extend([
            lighting.ambient,
            lighting.key,
            lighting.fill,
            self.color_samples as f32,
        ]);
        let eye_world = camera.camera_from_world.inverse().translation.vector;
        uniform.extend([
            eye_world.x as f32,
            eye_world.y as f32,
            eye_world.z as f32,
            1.0,
        ]);
        let uniform_bytes: Vec<u8> = uniform.iter().flat_map(|v| v.to_le_bytes()).collect();
        let view_buffer = self
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("view"),
                contents: &uniform_bytes,
                usage: wgpu::BufferUsages::UNIFORM,
            });
        self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("view"),
            layout: &self.view_layout,
            entries: &[wgpu::BindGroupEntry {
                binding: 0,
                resource: view_buffer.as_entire_binding(),
            }],
        })
    }

    /// Renders one colour frame of the static meshes plus instance `batches` (ranges into
    /// `transforms`), waits for the GPU to finish and reports what was drawn and how long it
    /// took. With `read_color` the frame is also read back (not included in the time).
    pub fn render_instanced(
        &mut self,
        scene: &GpuScene,
        camera: &ViewCamera,
        lighting: &Lighting,
        transforms: &[InstanceTransform],
        batches: &[InstanceBatch],
        read_color: bool,
    ) -> Result<(FrameStats, Option<RgbaImage>), RenderError> {
        let (width, height) = (camera.width, camera.height);
        self.check_size(width, height)?;
        if let Some(batch) = batches.iter().find(|b| {
            b.instances.end as usize > transforms.len() || b.instances.start > b.instances.end
        }) {
            return Err(RenderError::Mesh {
                object_id: 0,
                message: format!(
                    "instance range {:?} outside the {} transforms",
                    batch.instances,
                    transforms.len()
                ),
            });
        }
        self.ensure_targets(width, height);
        let start = std::time::Instant::now();
        let needed = (transforms.len().max(1) as u64) * INSTANCE_BYTES;
        if self
            .instance_buffer
            .as_ref()
            .is_none_or(|b| b.size() < needed)
        {
            self.instance_buffer = Some(self.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("instances"),
                size: needed.next_power_of_two(),
                usage: wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }));
        }
        let (Some(targets), Some(instance_buffer)) =
            (self.targets.as_ref(), self.instance_buffer.as_ref())
        else {
            return Err(RenderError::Readback("render targets missing".into()));
        };
        if !transforms.is_empty() {
            self.queue
                .write_buffer(instance_buffer, 0, &instance_bytes(transforms));
        }
        let view_group = self.view_bind_group(camera, lighting);
        let mut encoder = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("instanced frame"),
            });
        let mut stats = FrameStats::default();
        {
            let mut pass = begin_color_pass(&mut encoder, targets, SKY);
            let (draws, triangles) = draw_meshes(
                &mut pass,
                &self.color_pipeline,
                &view_group,
                scene,
                &self.identity_instance,
            );
            let (batch_draws, instances, batch_triangles) =
                draw_batches(&mut pass, scene, instance_buffer, batches);
            stats.draw_calls = draws + batch_draws;
            stats.instances = instances;
            stats.triangles = triangles + batch_triangles;
        }
        self.queue.submit([encoder.finish()]);
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| RenderError::Readback(e.to_string()))?;
        stats.seconds = start.elapsed().as_secs_f64();
        if !read_color {
            return Ok((stats, None));
        }
        let encoder = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("frame readback"),
            });
        let mut bytes = self.submit_and_read(encoder, &[&targets.color_resolved], width, height)?;
        let color = RgbaImage::from_raw(width, height, bytes.pop().unwrap_or_default())
            .ok_or_else(|| RenderError::Readback("colour buffer has the wrong size".into()))?;
        Ok((stats, Some(color)))
    }

    /// Encodes a colour frame of the static meshes into `encoder` without submitting it (the
    /// GUI's 3D panel: the caller submits with its own work, then samples
    /// [`Renderer::color_view`]). Returns the draw calls and triangles encoded.
    pub fn encode_color_frame(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        scene: &GpuScene,
        camera: &ViewCamera,
        lighting: &Lighting,
        background: [f64; 4],
    ) -> Result<(usize, usize), RenderError> {
        self.check_size(camera.width, camera.height)?;
        self.ensure_targets(camera.width, camera.height);
        let view_group = self.view_bind_group(camera, lighting);
        let Some(targets) = self.targets.as_ref() else {
            return Err(RenderError::Readback("render targets missing".into()));
        };
        let [r, g, b, a] = background;
        let mut pass = begin_color_pass(encoder, targets, wgpu::Color { r, g, b, a });
        Ok(draw_meshes(
            &mut pass,
            &self.color_pipeline,
            &view_group,
            scene,
            &self.identity_instance,
        ))
    }

    /// Renders `scene` from `camera`: colour, depth and object ids.
    pub fn render(
        &mut self,
        scene: &GpuScene,
        camera: &ViewCamera,
        lighting: &Lighting,
    ) -> Result<RenderOutput, RenderError> {
        let (width, height) = (camera.width, camera.height);
        self.check_size(width, height)?;
        self.ensure_targets(width, height);
        let Some(targets) = self.targets.as_ref() else {
            return Err(RenderError::Readback("render targets missing".into()));
        };

        let view_group = self.view_bind_group(camera, lighting);

        let mut encoder = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("render"),
            });
        {
            let mut pass = begin_color_pass(&mut encoder, targets, wgpu::Color::BLACK);
            draw_meshes(
                &mut pass,
                &self.color_pipeline,
                &view_group,
                scene,
                &self.identity_instance,
            );
        }
        let id_view = targets
            .id
            .create_view(&wgpu::TextureViewDescriptor::default());
        let depth_view = targets
            .linear_depth
            .create_view(&wgpu::TextureViewDescriptor::default());
        {
            let clear = |store| wgpu::Operations {
                load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
                store,
            };
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("id and depth"),
                color_attachments: &[
                    Some(wgpu::RenderPassColorAttachment {
                        view: &id_view,
                        depth_slice: None,
                        resolve_target: None,
                        ops: clear(wgpu::StoreOp::Store),
                    }),
                    Some(wgpu::RenderPassColorAttachment {
                        view: &depth_view,
                        depth_slice: None,
                        resolve_target: None,
                        ops: clear(wgpu::StoreOp::Store),
                    }),
                ],
                depth_stencil_attachment: Some(cleared_depth(&targets.depth_single)),
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            draw_meshes(
                &mut pass,
                &self.id_pipeline,
                &view_group,
                scene,
                &self.identity_instance,
            );
        }
        let mut unpadded = self.submit_and_read(
            encoder,
            &[&targets.color_resolved, &targets.id, &targets.linear_depth],
            width,
            height,
        )?;
        let depth_bytes = unpadded.pop().unwrap_or_default();
        let id_bytes = unpadded.pop().unwrap_or_default();
        let color_bytes = unpadded.pop().unwrap_or_default();
        let color = RgbaImage::from_raw(width, height, color_bytes)
            .ok_or_else(|| RenderError::Readback("colour buffer has the wrong size".into()))?;
        let object_id = id_bytes
            .chunks_exact(4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect();
        let depth = depth_bytes
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect();
        Ok(RenderOutput {
            width,
            height,
            color,
            depth,
            object_id,
        })
    }
}

/// The multisampled colour pass (resolved into the readable colour target), cleared to
/// `clear`.
fn begin_color_pass<'a>(
    encoder: &'a mut wgpu::CommandEncoder,
    targets: &'a Targets,
    clear: wgpu::Color,
) -> wgpu::RenderPass<'a> {
    encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
        label: Some("colour"),
        color_attachments: &[Some(wgpu::RenderPassColorAttachment {
            view: targets
                .color_msaa
                .as_ref()
                .unwrap_or(&targets.color_resolved_view),
            depth_slice: None,
            resolve_target: targets
                .color_msaa
                .as_ref()
                .map(|_| &targets.color_resolved_view),
            ops: wgpu::Operations {
                load: wgpu::LoadOp::Clear(clear),
                // Multisampled samples are resolved and dropped; a single-sample target is
                // the result.
                store: if targets.color_msaa.is_some() {
                    wgpu::StoreOp::Discard
                } else {
                    wgpu::StoreOp::Store
                },
            },
        })],
        depth_stencil_attachment: Some(cleared_depth(&targets.depth_msaa)),
        timestamp_writes: None,
        occlusion_query_set: None,
        multiview_mask: None,
    })
}

/// A depth attachment cleared to the far plane and not kept after the pass.
fn cleared_depth(view: &wgpu::TextureView) -> wgpu::RenderPassDepthStencilAttachment<'_> {
    wgpu::RenderPassDepthStencilAttachment {
        view,
        depth_ops: Some(wgpu::Operations {
            load: wgpu::LoadOp::Clear(1.0),
            store: wgpu::StoreOp::Discard,
        }),
        stencil_ops: None,
    }
}

/// Draws every static mesh of the scene with one pipeline and the view's bind group; returns
/// the draw calls and triangles submitted.
fn draw_meshes(
    pass: &mut wgpu::RenderPass<'_>,
    pipeline: &wgpu::RenderPipeline,
    view_group: &wgpu::BindGroup,
    scene: &GpuScene,
    identity_instance: &wgpu::Buffer,
) -> (usize, usize) {
    pass.set_pipeline(pipeline);
    pass.set_bind_group(0, view_group, &[]);
    pass.set_vertex_buffer(1, identity_instance.slice(..));
    let mut draws = (0, 0);
    for mesh in scene.meshes.iter().filter(|m| m.is_static && m.visible) {
        let Some((vertices, indices)) = &mesh.buffers else {
            continue;
        };
        pass.set_bind_group(1, &mesh.bind_group, &[]);
        pass.set_vertex_buffer(0, vertices.slice(..));
        pass.set_index_buffer(indices.slice(..), wgpu::IndexFormat::Uint32);
        pass.draw_indexed(0..mesh.index_count, 0, 0..1);
        draws.0 += 1;
        draws.1 += mesh.index_count as usize / 3;
    }
    draws
}

/// Draws instance batches (the instance transforms bound at slot 1); returns the draw calls,
/// instances and triangles submitted.
fn draw_batches(
    pass: &mut wgpu::RenderPass<'_>,
    scene: &GpuScene,
    instance_buffer: &wgpu::Buffer,
    batches: &[InstanceBatch],
) -> (usize, usize, usize) {
    pass.set_vertex_buffer(1, instance_buffer.slice(..));
    let mut totals = (0, 0, 0);
    for batch in batches {
        let Some(mesh) = scene.meshes.get(batch.mesh.0) else {
            continue;
        };
        let Some((vertices, indices)) = &mesh.buffers else {
            continue;
        };
        if batch.instances.is_empty() {
            continue;
        }
        pass.set_bind_group(1, &mesh.bind_group, &[]);
        pass.set_vertex_buffer(0, vertices.slice(..));
        pass.set_index_buffer(indices.slice(..), wgpu::IndexFormat::Uint32);
        pass.draw_indexed(0..mesh.index_count, 0, batch.instances.clone());
        let count = batch.instances.len();
        totals.0 += 1;
        totals.1 += count;
        totals.2 += count * mesh.index_count as usize / 3;
    }
    totals
}
