//! The 3D panel: the session's points (coloured by segment), fitted textured leaves, branches,
//! control-point handles and camera frusta, drawn by the library's render core into its own
//! targets and composited into the window's render pass through an `egui_wgpu` callback. An
//! orbit camera turns about the plant: drag to orbit, right or middle drag to pan, scroll to
//! zoom, double-click to frame the plant again. While the view moves, a quarter of the points
//! is drawn at half resolution; the full frame follows once it stops. The branch tools work
//! here too, in pixels of the orbit camera's view.
//!
//! Library calls: the marker meshes `TriMesh::{add_octahedron, add_tetrahedron, add_frustum}`
//! with `scene::PhotoView::frustum_corners_world`, `BranchTree::mesh` for the branches,
//! `render::Renderer` to upload and draw (from the orbit's `render::ViewCamera`),
//! `branch::handles::project_branches` for the handles a drag grabs (through
//! `tools::{grab_handle, release_handle}`) and `Session::pick_branch_in_view` for clicks.

use std::sync::Arc;

use eframe::egui_wgpu::{self, CallbackResources, CallbackTrait, RenderState};
use eframe::wgpu;
use egui::{Color32, Sense};
use frond::branch::CylinderMeshing;
use frond::branch::handles::{HandlePick, project_branches};
use frond::mesh::TriMesh;
use frond::render::{GpuScene, Lighting, MeshHandle, Orbit, Renderer, TextureHandle, ViewCamera};
use frond::scene::PhotoView;
use frond::segment::foreground::PointClass;
use image::RgbaImage;
use nalgebra::Point3;

use crate::image_view::{Action, segment_color};
use crate::tools::{Tool, grab_handle, release_handle};
use crate::workspace::Workspace;
use frond::edit::{BranchStroke, BranchTarget, Command, ViewCameraRecord as EditCamera};

/// Side of the palette texture: colour `k` is texel `(k mod side, k div side)`.
const PALETTE_SIDE: u32 = 64;
/// Reserved palette entries (segments use the rest).
const WOOD: u32 = 0;
const HANDLE: u32 = 1;
const FRUSTUM: u32 = 2;
const UNASSIGNED: u32 = 3;
const FIRST_SEGMENT: u32 = 4;
/// What each palette mesh is, in `SceneData::palette_meshes` order.
const PALETTE_PARTS: [Part; 4] = [
    Part::MovingPoints,
    Part::Points,
    Part::Branches,
    Part::Handles,
];

/// A part of the 3D scene, for showing and hiding.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Part {
    /// A quarter of the points as tetrahedra, drawn while the view moves.
    MovingPoints,
    /// Every point as an octahedron, drawn once the view is still.
    Points,
    Branches,
    /// Radius spheres and camera frusta.
    Handles,
    Leaf,
}

/// Which parts the 3D panel shows.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Show3d {
    pub points: bool,
    pub leaves: bool,
    pub branches: bool,
    pub handles: bool,
}

impl Default for Show3d {
    fn default() -> Self {
        Self {
            points: true,
            leaves: true,
            branches: true,
            handles: true,
        }
    }
}

impl Show3d {
    /// Every part with its menu name, for toggles.
    pub fn toggles(&mut self) -> [(&'static str, &mut bool); 4] {
        [
            ("3D: points", &mut self.points),
            ("3D: fitted leaves", &mut self.leaves),
            ("3D: branches", &mut self.branches),
            ("3D: radius spheres and cameras", &mut self.handles),
        ]
    }

    fn shows(&self, part: Part, moving: bool) -> bool {
        match part {
            Part::MovingPoints => self.points && moving,
            Part::Points => self.points && !moving,
            Part::Branches => self.branches,
            Part::Handles => self.handles,
            Part::Leaf => self.leaves,
        }
    }
}
/// The view counts as moving for this long after its camera last changed (seconds).
const SETTLE_SECONDS: f64 = 0.25;
/// Control points are grabbed within this distance (screen points).
const GRAB_DISTANCE_PX: f64 = 12.0;
/// Background (linear RGB).
const BACKGROUND: [f64; 4] = [0.045, 0.05, 0.06, 1.0];

/// The plant's points to frame: the foreground's plant class, else every point.
fn framed_points(workspace: &Workspace) -> Vec<Point3<f64>> {
    let segmentation = workspace.session.segmentation();
    let points = &segmentation.points.positions;
    let plant: Vec<Point3<f64>> = points
        .iter()
        .zip(&segmentation.foreground.class)
        .filter(|(_, c)| **c == PointClass::Plant)
        .map(|(p, _)| *p)
        .collect();
    if plant.len() >= 3 {
        plant
    } else {
        points.clone()
    }
}

/// The orbit framing the open plant.
fn frame_orbit(workspace: &Workspace) -> Option<Orbit> {
    Orbit::framing(
        &framed_points(workspace),
        &workspace.session.segmentation().foreground.up,
    )
}

/// What the 3D panel draws, in the world frame, ready to upload.
pub struct SceneData {
    /// Changes whenever the content does (workspace revision and fit).
    pub key: (u64, u64),
    pub palette: RgbaImage,
    /// Meshes drawn with the palette: a quarter of the points as tetrahedra (drawn while the
    /// view moves), every point as an octahedron (once it is still), branches, and handles
    /// with frusta.
    pub palette_meshes: Vec<TriMesh>,
    /// Fitted leaves with their textures.
    pub leaves: Vec<(TriMesh, RgbaImage)>,
    pub points: usize,
}

fn palette_uv(index: u32) -> [f32; 2] {
    let index = index % (PALETTE_SIDE * PALETTE_SIDE);
    [
        ((index % PALETTE_SIDE) as f32 + 0.5) / PALETTE_SIDE as f32,
        ((index / PALETTE_SIDE) as f32 + 0.5) / PALETTE_SIDE as f32,
    ]
}

impl SceneData {
    /// Builds the panel's content from the workspace.
    pub fn build(workspace: &Workspace, extent: f64) -> Self {
        let session = &workspace.session;
        let segmentation = session.segmentation();
        let mut palette = RgbaImage::new(PALETTE_SIDE, PALETTE_SIDE);
        let mut set = |index: u32, colour: Color32| {
            let index = index % (PALETTE_SIDE * PALETTE_SIDE);
            palette.put_pixel(
                index % PALETTE_SIDE,
                index / PALETTE_SIDE,
                image::Rgba([colour.r(), colour.g(), colour.b(), 255]),
            );
        };
        set(WOOD, Color32::from_rgb(150, 105, 70));
        set(HANDLE, Color32::from_rgb(255, 170, 60));
        set(FRUSTUM, Color32::from_rgb(120, 170, 230));
        set(UNASSIGNED, Color32::from_gray(110));
        let segments = session.segments();
        for (id, state) in segments.iter().enumerate() {
            if let Some(state) = state {
                set(
                    FIRST_SEGMENT + id as u32,
                    segment_color(id as i32, Some(state.label)),
                );
            }
        }

        // Points: small octahedra once the view is still, a quarter of them as tetrahedra
        // while it moves; background points left out.
        let mut moving = TriMesh::default();
        let mut points = TriMesh::default();
        let point_radius = extent * 0.0035;
        let mut shown = 0;
        for (index, (p, (&segment, class))) in segmentation
            .points
            .positions
            .iter()
            .zip(
                session
                    .segment_of()
                    .iter()
                    .zip(&segmentation.foreground.class),
            )
            .enumerate()
        {
            if *class == PointClass::Outlier || (segment < 0 && *class != PointClass::Plant) {
                continue;
            }
            let colour = if segment >= 0 {
                FIRST_SEGMENT + segment as u32
            } else {
                UNASSIGNED
            };
            // A fixed quarter of the points (by an index hash) while the view moves.
            if (index as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 62 == 0 {
                moving.add_tetrahedron(p, point_radius, palette_uv(colour));
            }
            points.add_octahedron(p, point_radius, palette_uv(colour));
            shown += 1;
        }

        // Branches and their control points.
        let tree = session.branches();
        let mut branches = tree.mesh(&CylinderMeshing::default());
        let wood = palette_uv(WOOD);
        for uv in &mut branches.uvs {
            *uv = wood;
        }
        // Radius spheres at the branch ends (never smaller than a visible handle).
        let mut handles = TriMesh::default();
        for branch in &tree.branches {
            let controls = branch.cylinder.skeleton.control_points();
            let ends = [
                (controls.first(), branch.cylinder.radius_start),
                (controls.last(), branch.cylinder.radius_end),
            ];
            for (p, radius) in ends {
                if let Some(p) = p {
                    handles.add_octahedron(
                        p,
                        (radius * 1.3).max(extent * 0.006),
                        palette_uv(HANDLE),
                    );
                }
            }
        }
        // Camera frusta, a tenth of the plant's extent deep.
        let model = &session.scene().reconstruction;
        for image in model.images() {
            let corners = PhotoView::new(model, image).frustum_corners_world(extent * 0.1);
            handles.add_frustum(
                &image.center_world(),
                &corners,
                extent * 0.0015,
                palette_uv(FRUSTUM),
            );
        }

        let leaves = workspace
            .leaves
            .as_ref()
            .map(|(_, leaves)| {
                leaves
                    .leaves
                    .iter()
                    .map(|l| (l.fit.mesh.clone(), l.fit.texture.clone()))
                    .collect()
            })
            .unwrap_or_default();
        Self {
            key: (
                workspace.revision,
                workspace.leaves.as_ref().map_or(u64::MAX, |(r, _)| *r),
            ),
            palette,
            palette_meshes: vec![moving, points, branches, handles],
            leaves,
            points: shown,
        }
    }
}

/// The status line at the panel's bottom left: what the 3D view shows.
fn status_ui(painter: &egui::Painter, rect: egui::Rect, data: &SceneData, workspace: &Workspace) {
    painter.text(
        rect.left_bottom() + egui::vec2(10.0, -10.0),
        egui::Align2::LEFT_BOTTOM,
        format!(
            "3D · {} points · {} leaves · {} branches",
            data.points,
            data.leaves.len(),
            workspace.session.branches().branches.len()
        ),
        egui::FontId::proportional(13.0),
        Color32::from_gray(220),
    );
}

/// A scene on the GPU: the content key it was built for, and what each mesh is.
type UploadedScene = ((u64, u64), GpuScene, Vec<(Part, MeshHandle)>);
/// What a rendered frame shows: content key, camera, moving, parts shown.
type FrameKey = ((u64, u64), [u64; 8], bool, Show3d);

/// GPU state of the 3D panel, kept in egui_wgpu's callback resources.
pub struct View3dResources {
    renderer: Renderer,
    /// The uploaded scene and what each of its meshes is.
    scene: Option<UploadedScene>,
    frame_key: Option<FrameKey>,
    blit_pipeline: wgpu::RenderPipeline,
    blit_layout: wgpu::BindGroupLayout,
    sampler: wgpu::Sampler,
    blit_group: Option<wgpu::BindGroup>,
    /// Whether the window's target is not sRGB (the frame is then bound as plain UNORM).
    encoded_target: bool,
    /// Seconds the CPU spent encoding the last re-rendered frame, and its triangles.
    pub last_frame: (f64, usize),
}

const BLIT_SHADER: &str = r#"
@group(0) @binding(0) var frame: texture_2d<f32>;
@group(0) @binding(1) var frame_sampler: sampler;

struct Varyings {
    @builtin(position) position: vec4<f32>,
    @location(0) uv: vec2<f32>,
};

@vertex
fn vs_main(@builtin(vertex_index) index: u32) -> Varyings {
    let uv = vec2<f32>(f32((index << 1u) & 2u), f32(index & 2u));
    var out: Varyings;
    out.position = vec4<f32>(uv.x * 2.0 - 1.0, 1.0 - uv.y * 2.0, 0.0, 1.0);
    out.uv = uv;
    return out;
}

// The frame is bound as sRGB (decoded to linear) for an sRGB window target, else as plain
// UNORM so the encoded bytes pass through unchanged: no per-pixel conversion either way.
@fragment
fn fs_main(in: Varyings) -> @location(0) vec4<f32> {
    return vec4<f32>(textureSample(frame, frame_sampler, in.uv).rgb, 1.0);
}
"#;

impl View3dResources {
    /// Puts the 3D panel's GPU state into eframe's renderer (once, at start-up).
    pub fn install(render_state: &RenderState) -> Result<(), String> {
        let device = &render_state.device;
        let adapter = render_state.adapter.get_info();
        // Every sample costs on a software rasteriser: no multisampling there.
        let samples = if adapter.device_type == wgpu::DeviceType::Cpu {
            1
        } else {
            4
        };
        let renderer =
            Renderer::with_device(device.clone(), render_state.queue.clone(), adapter, samples)
                .map_err(|e| e.to_string())?;
        let shader = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("3d panel blit"),
            source: wgpu::ShaderSource::Wgsl(BLIT_SHADER.into()),
        });
        let blit_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("3d panel blit"),
            entries: &[
                wgpu::BindGroupLayoutEntry {
                    binding: 0,
                    visibility: wgpu::ShaderStages::FRAGMENT,
                    ty: wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Float { filterable: true },
                        view_dimension: wgpu::TextureViewDimension::D2,
                        multisampled: false,
                    },
                    count: None,
                },
                wgpu::BindGroupLayoutEntry {
                    binding: 1,
                    visibility: wgpu::ShaderStages::FRAGMENT,
                    ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
                    count: None,
                },
            ],
        });
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("3d panel blit"),
            bind_group_layouts: &[Some(&blit_layout)],
            immediate_size: 0,
        });
        let fragment_entry = "fs_main";
        let blit_pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("3d panel blit"),
            layout: Some(&layout),
            vertex: wgpu::VertexState {
                module: &shader,
                entry_point: Some("vs_main"),
                compilation_options: Default::default(),
                buffers: &[],
            },
            fragment: Some(wgpu::FragmentState {
                module: &shader,
                entry_point: Some(fragment_entry),
                compilation_options: Default::default(),
                targets: &[Some(wgpu::ColorTargetState {
                    format: render_state.target_format,
                    blend: None,
                    write_mask: wgpu::ColorWrites::ALL,
                })],
            }),
            primitive: wgpu::PrimitiveState::default(),
            depth_stencil: None,
            multisample: wgpu::MultisampleState::default(),
            multiview_mask: None,
            cache: None,
        });
        let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("3d panel blit"),
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            ..Default::default()
        });
        render_state
            .renderer
            .write()
            .callback_resources
            .insert(Self {
                renderer,
                scene: None,
                frame_key: None,
                blit_pipeline,
                blit_layout,
                sampler,
                blit_group: None,
                encoded_target: !render_state.target_format.is_srgb(),
                last_frame: (0.0, 0),
            });
        Ok(())
    }

    fn upload(&mut self, data: &SceneData) -> Result<(GpuScene, Vec<(Part, MeshHandle)>), String> {
        let started = std::time::Instant::now();
        let renderer = &self.renderer;
        let mut scene = renderer.new_scene();
        let palette = renderer.add_texture(&mut scene, &data.palette);
        let mut parts = Vec::new();
        // Every palette mesh gets a slot, empty or not, so that edits can replace it.
        for (k, (mesh, part)) in data.palette_meshes.iter().zip(PALETTE_PARTS).enumerate() {
            let handle = renderer
                .add_mesh(&mut scene, mesh, palette, k as u32 + 1, false)
                .map_err(|e| e.to_string())?;
            parts.push((part, handle));
        }
        for (k, (mesh, texture)) in data.leaves.iter().enumerate() {
            let texture: TextureHandle = renderer.add_cutout_texture(&mut scene, texture);
            let handle = renderer
                .add_mesh(&mut scene, mesh, texture, 100 + k as u32, true)
                .map_err(|e| e.to_string())?;
            parts.push((Part::Leaf, handle));
        }
        tracing::debug!(
            "3D content uploaded in {:.1} ms",
            started.elapsed().as_secs_f64() * 1000.0
        );
        Ok((scene, parts))
    }

    /// Brings the uploaded scene up to `data`: when only the palette meshes changed (points,
    /// branches, handles: an edit), their geometry is replaced and the textured leaves stay;
    /// otherwise (a new fit, a first upload) everything is uploaded.
    fn update(&mut self, data: &SceneData) -> Result<(), String> {
        if let Some((key, scene, parts)) = self.scene.as_mut()
            && key.1 == data.key.1
        {
            let started = std::time::Instant::now();
            for (&(_, handle), mesh) in parts.iter().zip(&data.palette_meshes) {
                self.renderer
                    .replace_mesh_geometry(scene, handle, mesh)
                    .map_err(|e| e.to_string())?;
            }
            *key = data.key;
            tracing::debug!(
                "3D points and branches re-uploaded in {:.1} ms",
                started.elapsed().as_secs_f64() * 1000.0
            );
            return Ok(());
        }
        let (scene, parts) = self.upload(data)?;
        self.scene = Some((data.key, scene, parts));
        Ok(())
    }
}

/// One frame's request to the GPU: what to draw and from where.
struct View3dCallback {
    data: Arc<SceneData>,
    camera: ViewCamera,
    /// Draw only the coarse points (the view is moving).
    moving: bool,
    show: Show3d,
}

fn camera_key(camera: &ViewCamera) -> [u64; 8] {
    let q = camera.camera_from_world.rotation.coords;
    let t = camera.camera_from_world.translation.vector;
    [
        ((camera.width as u64) << 32) | camera.height as u64,
        camera.fx.to_bits(),
        q.x.to_bits() ^ q.w.to_bits().rotate_left(17),
        q.y.to_bits() ^ q.z.to_bits().rotate_left(29),
        t.x.to_bits(),
        t.y.to_bits(),
        t.z.to_bits(),
        camera.near.to_bits(),
    ]
}

impl CallbackTrait for View3dCallback {
    fn prepare(
        &self,
        device: &wgpu::Device,
        _queue: &wgpu::Queue,
        _screen_descriptor: &egui_wgpu::ScreenDescriptor,
        egui_encoder: &mut wgpu::CommandEncoder,
        resources: &mut CallbackResources,
    ) -> Vec<wgpu::CommandBuffer> {
        let Some(resources) = resources.get_mut::<View3dResources>() else {
            return Vec::new();
        };
        if resources
            .scene
            .as_ref()
            .is_none_or(|(key, _, _)| *key != self.data.key)
        {
            if let Err(e) = resources.update(&self.data) {
                resources.scene = None;
                tracing::warn!("3D panel: {e}");
                return Vec::new();
            }
            resources.frame_key = None;
        }
        let frame_key = (
            self.data.key,
            camera_key(&self.camera),
            self.moving,
            self.show,
        );
        if resources.frame_key == Some(frame_key) {
            return Vec::new();
        }
        let Some((_, scene, parts)) = resources.scene.as_mut() else {
            return Vec::new();
        };
        for &(part, handle) in parts.iter() {
            scene.set_visible(handle, self.show.shows(part, self.moving));
        }
        let scene = &*scene;
        let clock = std::time::Instant::now();
        match resources.renderer.encode_color_frame(
            egui_encoder,
            scene,
            &self.camera,
            &Lighting::default(),
            BACKGROUND,
        ) {
            Ok((_, triangles)) => {
                resources.last_frame = (clock.elapsed().as_secs_f64(), triangles);
            }
            Err(e) => {
                tracing::warn!("3D panel: {e}");
                return Vec::new();
            }
        }
        if let Some(view) = resources.renderer.color_view(resources.encoded_target) {
            resources.blit_group = Some(device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("3d panel frame"),
                layout: &resources.blit_layout,
                entries: &[
                    wgpu::BindGroupEntry {
                        binding: 0,
                        resource: wgpu::BindingResource::TextureView(view),
                    },
                    wgpu::BindGroupEntry {
                        binding: 1,
                        resource: wgpu::BindingResource::Sampler(&resources.sampler),
                    },
                ],
            }));
        }
        resources.frame_key = Some(frame_key);
        Vec::new()
    }

    fn paint(
        &self,
        _info: egui::PaintCallbackInfo,
        render_pass: &mut wgpu::RenderPass<'static>,
        resources: &CallbackResources,
    ) {
        let Some(resources) = resources.get::<View3dResources>() else {
            return;
        };
        let Some(group) = &resources.blit_group else {
            return;
        };
        render_pass.set_pipeline(&resources.blit_pipeline);
        render_pass.set_bind_group(0, group, &[]);
        render_pass.draw(0..3, 0..1);
    }
}

/// The 3D panel's state.
#[derive(Default)]
pub struct View3d {
    pub orbit: Option<Orbit>,
    pub show: Show3d,
    data: Option<Arc<SceneData>>,
    extent: f64,
    /// The camera of the last frame and when it last changed.
    last_orbit: Option<Orbit>,
    moved_at: Option<std::time::Instant>,
    /// The panel's rectangle in the last frame.
    pub rect: Option<egui::Rect>,
    /// How long the last content build took on the UI thread (ms).
    pub last_build_ms: Option<f32>,
    /// A branch stroke being drawn (pixels of this view) and a grabbed handle.
    stroke: Vec<[f64; 2]>,
    grabbed: Option<HandlePick>,
}

impl View3d {
    /// Forgets the previous workspace.
    pub fn reset(&mut self) {
        *self = Self {
            show: self.show,
            ..Self::default()
        };
    }

    /// Triangles of the last content built, by part: points drawn while moving, points drawn
    /// once still, branches, handles and frusta, leaves.
    pub fn triangle_counts(&self) -> Option<[usize; 5]> {
        let data = self.data.as_ref()?;
        let meshes = &data.palette_meshes;
        let count = |k: usize| meshes.get(k).map_or(0, |m| m.triangles.len());
        Some([
            count(0),
            count(1),
            count(2),
            count(3),
            data.leaves.iter().map(|(m, _)| m.triangles.len()).sum(),
        ])
    }

    /// The content drawn, rebuilt when the workspace changed.
    pub fn data(&mut self, workspace: &Workspace) -> Arc<SceneData> {
        let key = (
            workspace.revision,
            workspace.leaves.as_ref().map_or(u64::MAX, |(r, _)| *r),
        );
        if self.orbit.is_none() {
            self.orbit = frame_orbit(workspace);
            self.extent = self.orbit.map_or(1.0, |o| o.half_height_at_target());
        }
        match &self.data {
            Some(data) if data.key == key => Arc::clone(data),
            _ => {
                let started = std::time::Instant::now();
                let data = Arc::new(SceneData::build(workspace, self.extent));
                self.last_build_ms = Some(started.elapsed().as_secs_f32() * 1000.0);
                self.data = Some(Arc::clone(&data));
                data
            }
        }
    }

    /// Draws the panel; `gpu` says whether the render core is installed in the window. The
    /// branch tools work here too (strokes and clicks are pixels of this view's camera);
    /// with any other tool the primary button orbits.
    pub fn ui(
        &mut self,
        ui: &mut egui::Ui,
        workspace: &Workspace,
        gpu: bool,
        tool: Tool,
    ) -> Vec<Action> {
        let mut actions = Vec::new();
        let (rect, response) = ui.allocate_exact_size(ui.available_size(), Sense::click_and_drag());
        self.rect = Some(rect);
        let data = self.data(workspace);
        if self.orbit.is_none() {
            ui.painter().text(
                rect.center(),
                egui::Align2::CENTER_CENTER,
                "no points to show",
                egui::FontId::proportional(14.0),
                Color32::from_gray(160),
            );
            return actions;
        }
        self.orbit_input(ui, &response, workspace, tool);
        let Some(orbit) = self.orbit else {
            return actions;
        };
        if tool.is_branch_tool() {
            actions.extend(self.branch_tool(ui, &response, workspace, &orbit, tool));
        }
        if self.last_orbit != Some(orbit) {
            if self.last_orbit.is_some() {
                self.moved_at = Some(std::time::Instant::now());
            }
            self.last_orbit = Some(orbit);
        }
        let moving = self
            .moved_at
            .is_some_and(|t| t.elapsed().as_secs_f64() < SETTLE_SECONDS);
        if moving {
            // Draw the full detail once the view has settled.
            ui.ctx()
                .request_repaint_after(std::time::Duration::from_secs_f64(SETTLE_SECONDS));
        }
        let painter = ui.painter_at(rect);
        let pixels_per_point = ui.ctx().pixels_per_point();
        // Half resolution while the view moves (a quarter of the fragments), full once still.
        let scale = if moving { 0.5 } else { 1.0 };
        let width = (rect.width() * pixels_per_point * scale).round().max(1.0) as u32;
        let height = (rect.height() * pixels_per_point * scale).round().max(1.0) as u32;
        if gpu {
            painter.add(egui_wgpu::Callback::new_paint_callback(
                rect,
                View3dCallback {
                    data: Arc::clone(&data),
                    camera: orbit.view_camera(width, height),
                    moving,
                    show: self.show,
                },
            ));
        } else {
            painter.rect_filled(rect, 0.0, Color32::from_gray(18));
            painter.text(
                rect.center(),
                egui::Align2::CENTER_CENTER,
                "3D view: needs the GPU renderer",
                egui::FontId::proportional(14.0),
                Color32::from_gray(160),
            );
        }
        status_ui(&painter, rect, &data, workspace);
        self.gestures_ui(ui, &painter, &response);
        actions
    }

    /// Orbits with the primary button (unless a branch tool drags with it), pans with the
    /// right or middle button, zooms with the wheel or a pinch, frames the plant again on a
    /// double click.
    fn orbit_input(
        &mut self,
        ui: &egui::Ui,
        response: &egui::Response,
        workspace: &Workspace,
        tool: Tool,
    ) {
        let Some(orbit) = self.orbit.as_mut() else {
            return;
        };
        let rect = response.rect;
        let drag_tool = matches!(tool, Tool::DrawBranch | Tool::MoveBranch | Tool::Radius);
        if response.dragged_by(egui::PointerButton::Primary) && !drag_tool {
            orbit.rotate(
                response.drag_delta().x as f64,
                response.drag_delta().y as f64,
            );
        }
        if response.dragged_by(egui::PointerButton::Secondary)
            || response.dragged_by(egui::PointerButton::Middle)
        {
            orbit.pan(
                response.drag_delta().x as f64,
                response.drag_delta().y as f64,
                rect.width().min(rect.height()) as f64,
            );
        }
        if response.hovered() {
            let (scroll, pinch) = ui.input(|i| (i.smooth_scroll_delta.y, i.zoom_delta()));
            let factor = (scroll as f64 * 0.002).exp() * pinch as f64;
            if (factor - 1.0).abs() > 1e-6 {
                orbit.zoom(factor);
            }
        }
        if response.double_clicked() {
            self.orbit = frame_orbit(workspace);
        }
    }

    /// The gestures in progress: the branch stroke being drawn, the radius being dragged.
    fn gestures_ui(&self, ui: &egui::Ui, painter: &egui::Painter, response: &egui::Response) {
        let rect = response.rect;
        let pixels_per_point = ui.ctx().pixels_per_point();
        let accent = ui.visuals().selection.stroke.color;
        let screen =
            |[x, y]: [f64; 2]| rect.min + egui::vec2(x as f32, y as f32) / pixels_per_point;
        if self.stroke.len() >= 2 {
            let points: Vec<egui::Pos2> = self.stroke.iter().map(|&p| screen(p)).collect();
            painter.add(egui::Shape::line(points, egui::Stroke::new(2.0, accent)));
        }
        if let (Some(HandlePick::End { disc, .. }), Some(hover)) =
            (self.grabbed, response.hover_pos())
        {
            let c = screen([disc.centre_px.x, disc.centre_px.y]);
            painter.circle_stroke(c, (hover - c).length(), egui::Stroke::new(2.0, accent));
        }
    }

    /// The editing session's camera for this view (pixels at full resolution).
    pub fn edit_camera(&self, orbit: &Orbit, pixels_per_point: f32) -> Option<EditCamera> {
        let rect = self.rect?;
        let width = (rect.width() * pixels_per_point).round().max(1.0) as u32;
        let height = (rect.height() * pixels_per_point).round().max(1.0) as u32;
        Some(EditCamera::from_view(&orbit.view_camera(width, height)))
    }

    /// The branch tools in the 3D view: Draw (stroke), Move and Radius (drag a handle), Leaf
    /// at tip and Delete (click a branch).
    fn branch_tool(
        &mut self,
        ui: &egui::Ui,
        response: &egui::Response,
        workspace: &Workspace,
        orbit: &Orbit,
        tool: Tool,
    ) -> Vec<Action> {
        let primary = egui::PointerButton::Primary;
        let pixels_per_point = ui.ctx().pixels_per_point();
        let rect = response.rect;
        let to_pixel = |p: egui::Pos2| {
            let v = (p - rect.min) * pixels_per_point;
            [v.x as f64, v.y as f64]
        };
        let Some(camera) = self.edit_camera(orbit, pixels_per_point) else {
            return Vec::new();
        };
        let session = &workspace.session;
        if matches!(tool, Tool::LeafAtTip | Tool::DeleteBranch) {
            let Some(p) = response
                .interact_pointer_pos()
                .filter(|_| response.clicked())
            else {
                return Vec::new();
            };
            return vec![match session.pick_branch_in_view(&camera, to_pixel(p)) {
                Ok(point) if tool == Tool::DeleteBranch => Action::Apply(Command::DeleteBranch {
                    branch: point.branch,
                }),
                Ok(point) => Action::Apply(Command::SetLeafAtTip {
                    branch: point.branch,
                    enabled: session
                        .branches()
                        .get(point.branch)
                        .is_some_and(|b| !b.leaf_at_tip),
                }),
                Err(e) => Action::Message(e.to_string()),
            }];
        }
        let press_origin = ui.input(|i| i.pointer.press_origin());
        let pointer = response.interact_pointer_pos();
        if response.drag_started_by(primary)
            && let Some(origin) = press_origin
        {
            if tool == Tool::DrawBranch {
                self.stroke = vec![to_pixel(origin)];
            } else {
                let view = orbit.view_camera(camera.width, camera.height);
                let handles = project_branches(session.branches(), &view, 0);
                self.grabbed = grab_handle(
                    tool,
                    &handles,
                    to_pixel(origin),
                    GRAB_DISTANCE_PX * pixels_per_point as f64,
                );
                if self.grabbed.is_none() {
                    return vec![Action::Message(
                        if tool == Tool::MoveBranch {
                            "no control point there: press on a branch's control point"
                        } else {
                            "no branch end there: press on an end's sphere or its rim"
                        }
                        .into(),
                    )];
                }
            }
        } else if response.dragged_by(primary)
            && let Some(p) = pointer
            && tool == Tool::DrawBranch
            && let Some(last) = self.stroke.last()
        {
            let pixel = to_pixel(p);
            if (pixel[0] - last[0]).hypot(pixel[1] - last[1]) >= 2.0 * pixels_per_point as f64 {
                self.stroke.push(pixel);
            }
        } else if response.drag_stopped_by(primary) {
            if tool == Tool::DrawBranch {
                let stroke = std::mem::take(&mut self.stroke);
                if stroke.len() >= 2 {
                    return vec![Action::Apply(Command::DrawBranch {
                        stroke: BranchStroke::View { camera, stroke },
                        radius: None,
                    })];
                }
            } else if let (Some(grabbed), Some(p)) = (self.grabbed.take(), pointer) {
                let pixel = to_pixel(p);
                let to = BranchTarget::View { camera, pixel };
                return vec![Action::Apply(release_handle(grabbed, pixel, to))];
            }
        }
        Vec::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn palette_entries_are_distinct_texel_centres() {
        let uvs: Vec<[f32; 2]> = (0..PALETTE_SIDE * PALETTE_SIDE).map(palette_uv).collect();
        let texel = 1.0 / PALETTE_SIDE as f32;
        for (k, uv) in uvs.iter().enumerate() {
            // The centre of texel (k mod side, k div side).
            let (x, y) = (k as u32 % PALETTE_SIDE, k as u32 / PALETTE_SIDE);
            assert_eq!(*uv, [(x as f32 + 0.5) * texel, (y as f32 + 0.5) * texel]);
        }
        let mut distinct = uvs.clone();
        distinct.sort_by(|a, b| a.partial_cmp(b).unwrap());
        distinct.dedup();
        assert_eq!(distinct.len(), uvs.len());
        // Entries past the texture wrap around.
        assert_eq!(palette_uv(PALETTE_SIDE * PALETTE_SIDE + 5), palette_uv(5));
    }
}
