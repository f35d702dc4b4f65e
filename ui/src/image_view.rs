//! The image panel: one input photo with zoom and pan, overlays of the session's state
//! (projected points coloured by segment, graph edges, gradient image, segment boundaries,
//! fitted leaf outlines, branches with radius circles) and the editing tools, which turn
//! clicks and strokes into the library's `Command`s. Photos, thumbnails and gradient images
//! are decoded on worker threads. The photo and the overlays under the handles are composed
//! on the CPU into one panel-sized texture (resampling and line rasterising here are drawing,
//! not geometry).
//!
//! Library calls: `ViewCache::projected` (through `Session::views`) for the points a photo
//! sees, `Reconstruction::project` for leaf outlines, `TriMesh::boundary_edges` for the
//! outlines themselves, `branch::handles::project_branches` with a `scene::PhotoView` for the
//! branch curves and handles, `GradientImage::for_image` for the gradient layer,
//! `Session::{pick_segment, pick_branch, boundary}` for clicks and boundaries; handle drags go
//! through `tools::{grab_handle, release_handle}`.

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::mpsc::{Receiver, TryRecvError, channel};

use egui::{
    Color32, ColorImage, Pos2, Rect, Sense, Shape, Stroke, TextureHandle, Vec2, pos2, vec2,
};
use frond::branch::handles::{BranchHandles, HandlePick, project_branches};
use frond::edit::{BranchStroke, BranchTarget, Command, PixelRef};
use frond::leaf::TemplatePick;
use frond::scene::{Image, ImageId, PhotoView, Reconstruction, Scene};
use frond::segment::SegmentLabel;
use frond::segment::views::Projected;
use nalgebra::{Point2, Point3};

use crate::tools::{Tool, grab_handle, release_handle};
use crate::workspace::Workspace;

/// Largest side of a photo texture (texels); larger photos are shown downscaled.
const PHOTO_TEXTURE_SIZE: u32 = 2048;
/// Largest side of a filmstrip thumbnail (texels).
const THUMBNAIL_SIZE: u32 = 160;
/// Control points and branch ends are grabbed within this distance (screen points).
const GRAB_DISTANCE: f32 = 12.0;
/// Skeleton samples per branch curve drawn in a photo.
const BRANCH_CURVE_SAMPLES: usize = 48;
/// The colour branches are drawn in.
const WOOD: Color32 = Color32::from_rgb(235, 150, 60);

/// Stroke samples closer than this to the previous one are skipped (screen points).
const STROKE_STEP: f32 = 2.0;

/// Which overlays are drawn.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Overlays {
    pub photo: bool,
    pub points: bool,
    pub edges: bool,
    pub gradient: bool,
    pub boundaries: bool,
    pub leaf_outlines: bool,
    pub branches: bool,
}

impl Default for Overlays {
    fn default() -> Self {
        Self {
            photo: true,
            points: true,
            edges: false,
            gradient: false,
            boundaries: true,
            leaf_outlines: true,
            branches: true,
        }
    }
}

impl Overlays {
    /// Every overlay with its menu name, for toggles.
    pub fn toggles(&mut self) -> [(&'static str, &mut bool); 7] {
        [
            ("Photo", &mut self.photo),
            ("Points by segment", &mut self.points),
            ("Graph edges", &mut self.edges),
            ("Gradient image", &mut self.gradient),
            ("Segment boundaries", &mut self.boundaries),
            ("Leaf outlines", &mut self.leaf_outlines),
            ("Branches", &mut self.branches),
        ]
    }
}

/// What the panel asks the application to do.
#[derive(Clone, Debug, PartialEq)]
pub enum Action {
    Apply(Command),
    SetGenericLeaf(TemplatePick),
    Message(String),
}

/// Maps image pixels (COLMAP convention) to screen points and back, for the last frame drawn.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ViewTransform {
    pub rect: Rect,
    /// Image position at the panel's centre.
    pub center: Vec2,
    /// Screen points per image pixel.
    pub zoom: f32,
}

impl ViewTransform {
    pub fn screen_from_image(&self, uv: [f64; 2]) -> Pos2 {
        self.rect.center() + (vec2(uv[0] as f32, uv[1] as f32) - self.center) * self.zoom
    }

    pub fn screen_from_uv(&self, uv_image: &Point2<f64>) -> Pos2 {
        self.screen_from_image([uv_image.x, uv_image.y])
    }

    pub fn image_from_screen(&self, p: Pos2) -> [f64; 2] {
        let uv = self.center + (p - self.rect.center()) / self.zoom;
        [uv.x as f64, uv.y as f64]
    }
}

enum Loadable {
    Loading(Receiver<Result<ColorImage, String>>),
    /// Its pixels, composed on the CPU into the panel's one texture.
    Ready(Arc<ColorImage>),
    Failed(String),
}

/// Decodes an image file to a texture-sized RGBA image.
fn decode(path: &std::path::Path, max_side: u32) -> Result<ColorImage, String> {
    let image = image::open(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let image = if image.width().max(image.height()) > max_side {
        image.thumbnail(max_side, max_side)
    } else {
        image
    };
    let rgba = image.to_rgba8();
    Ok(ColorImage::from_rgba_unmultiplied(
        [rgba.width() as usize, rgba.height() as usize],
        rgba.as_raw(),
    ))
}

/// The gradient image of a view as grey levels (scaled so the 99th percentile is white).
fn gradient_image(scene: &Scene, view: usize) -> Result<ColorImage, String> {
    let image = &scene.reconstruction.images()[view];
    let gradient = frond::graph::gradient::GradientImage::for_image(scene, image)
        .map_err(|e| e.to_string())?;
    let grey = gradient.to_grey();
    Ok(ColorImage::from_gray_iter(
        [gradient.width as usize, gradient.height as usize],
        grey.into_iter(),
    ))
}

/// The image panel's state.
pub struct ImagePanel {
    pub view: usize,
    /// Screen points per image pixel.
    pub zoom: f32,
    pub center: Vec2,
    fitted: bool,
    pub overlays: Overlays,
    /// The label the Mark non-leaf tool gives.
    pub non_leaf_label: SegmentLabel,
    photos: HashMap<usize, Loadable>,
    gradients: HashMap<usize, Loadable>,
    thumbnails: Vec<Option<TextureHandle>>,
    thumbnail_receiver: Option<Receiver<(usize, ColorImage)>>,
    /// The scene shared with gradient workers (made on first use).
    shared_scene: Option<Arc<Scene>>,
    /// Leaf outlines as world segments, with the workspace revision of the fit.
    outlines: Option<(u64, Vec<[Point3<f64>; 2]>)>,
    stroke: Vec<[f64; 2]>,
    merge_first: Option<PixelRef>,
    drag: Option<HandlePick>,
    /// The transform of the last frame drawn.
    pub transform: Option<ViewTransform>,
    /// The photo as seen at the current zoom and pan with the gradient image, the points,
    /// segment boundaries, leaf outlines and branch curves drawn on it, composed on the CPU
    /// into one panel-sized texture (a quad per point, several full layers or tessellated
    /// lines by the ten thousand cost far more on a software rasteriser), and what it was
    /// composed for.
    composite: Option<(CompositeKey, TextureHandle)>,
    /// How long the last composition took on the UI thread (ms).
    pub last_compose_ms: Option<f32>,
}

/// What the composite depends on.
#[derive(Clone, Copy, Debug, PartialEq)]
struct CompositeKey {
    view: usize,
    /// The session's revision and the revision the leaves were fitted at.
    revision: u64,
    leaves: Option<u64>,
    size: [usize; 2],
    center: [u32; 2],
    zoom: u32,
    overlays: Overlays,
    /// Whether the photo and the gradient image had arrived.
    photo: bool,
    gradient: bool,
}

impl Default for ImagePanel {
    fn default() -> Self {
        Self {
            view: 0,
            zoom: 1.0,
            center: Vec2::ZERO,
            fitted: false,
            overlays: Overlays::default(),
            non_leaf_label: SegmentLabel::Stem,
            photos: HashMap::new(),
            gradients: HashMap::new(),
            thumbnails: Vec::new(),
            thumbnail_receiver: None,
            shared_scene: None,
            outlines: None,
            stroke: Vec::new(),
            merge_first: None,
            drag: None,
            transform: None,
            composite: None,
            last_compose_ms: None,
        }
    }
}

/// A colour per segment: golden-ratio hues for leaves, fixed colours for the other labels.
pub fn segment_color(segment: i32, label: Option<SegmentLabel>) -> Color32 {
    match label {
        None => Color32::from_rgba_unmultiplied(90, 90, 90, 110),
        Some(SegmentLabel::Leaf) => {
            let hue = (segment as f32 * 0.618_034).fract();
            egui::ecolor::Hsva::new(hue, 0.7, 0.95, 1.0).into()
        }
        Some(SegmentLabel::Stem) => Color32::from_rgb(170, 110, 60),
        Some(SegmentLabel::Pot) => Color32::from_rgb(120, 120, 150),
        Some(SegmentLabel::Other) => Color32::from_gray(150),
    }
}

/// The photo (covering `image_size` camera pixels) resampled bilinearly into a panel-sized
/// image of `size` texels, `pixels_per_point` per screen point; transparent off the photo.
fn resample_photo(
    photo: &ColorImage,
    image_size: Vec2,
    transform: &ViewTransform,
    size: [usize; 2],
    pixels_per_point: f32,
) -> ColorImage {
    let [width, height] = size;
    let [pw, ph] = photo.size;
    let mut pixels = vec![Color32::TRANSPARENT; width * height];
    if pw == 0 || ph == 0 {
        return ColorImage::new(size, pixels);
    }
    let texel = |x: usize, y: usize| photo.pixels[y * pw + x];
    let lerp = |a: Color32, b: Color32, t: f32| {
        let mix = |p: u8, q: u8| (p as f32 + (q as f32 - p as f32) * t).round() as u8;
        Color32::from_rgba_premultiplied(
            mix(a.r(), b.r()),
            mix(a.g(), b.g()),
            mix(a.b(), b.b()),
            mix(a.a(), b.a()),
        )
    };
    // Per axis: the two photo texels a panel texel falls between and the weight of the
    // second; `None` off the photo.
    let taps = |texel: usize, axis: usize| -> Option<(usize, usize, f32)> {
        let (rect_min, rect_center, center, extent, texels) = if axis == 0 {
            (
                transform.rect.min.x,
                transform.rect.center().x,
                transform.center.x,
                image_size.x,
                pw,
            )
        } else {
            (
                transform.rect.min.y,
                transform.rect.center().y,
                transform.center.y,
                image_size.y,
                ph,
            )
        };
        let screen = rect_min + (texel as f32 + 0.5) / pixels_per_point;
        let along = center + (screen - rect_center) / transform.zoom;
        if along < 0.0 || along >= extent {
            return None;
        }
        let f = (along * texels as f32 / extent - 0.5).clamp(0.0, (texels - 1) as f32);
        let first = f.floor() as usize;
        Some((first, (first + 1).min(texels - 1), f.fract()))
    };
    let columns: Vec<Option<(usize, usize, f32)>> = (0..width).map(|x| taps(x, 0)).collect();
    for y in 0..height {
        let Some((y0, y1, ty)) = taps(y, 1) else {
            continue;
        };
        for (x, column) in columns.iter().enumerate() {
            let Some((x0, x1, tx)) = *column else {
                continue;
            };
            let top = lerp(texel(x0, y0), texel(x1, y0), tx);
            let bottom = lerp(texel(x0, y1), texel(x1, y1), tx);
            pixels[y * width + x] = lerp(top, bottom, ty);
        }
    }
    ColorImage::new(size, pixels)
}

/// Splats projected points as squares (about 2.4·√zoom screen points wide, 2–7) into a
/// panel-sized image, `pixels_per_point` texels per point; later points overwrite earlier
/// ones, translucent colours are blended over what is there.
fn splat_points(
    image: &mut ColorImage,
    projections: &[Projected],
    transform: &ViewTransform,
    pixels_per_point: f32,
    color_of: impl Fn(u32) -> Color32,
) {
    let [width, height] = image.size;
    let half = ((1.2 * transform.zoom.sqrt()).clamp(1.0, 3.5) * pixels_per_point).round() as i64;
    let (w, h) = (width as i64, height as i64);
    for projected in projections {
        let point = projected.point;
        let p =
            (transform.screen_from_uv(&projected.uv_image) - transform.rect.min) * pixels_per_point;
        let (x, y) = (p.x.floor() as i64, p.y.floor() as i64);
        if x < -half || y < -half || x >= w + half || y >= h + half {
            continue;
        }
        let color = color_of(point);
        for yy in (y - half + 1).max(0)..(y + half).min(h) {
            let row = yy as usize * width;
            for xx in (x - half + 1).max(0)..(x + half).min(w) {
                let under = &mut image.pixels[row + xx as usize];
                *under = if color.a() == 255 {
                    color
                } else {
                    under.blend(color)
                };
            }
        }
    }
}

/// A thin quad from `a` to `b` added to a mesh (cheaper than tessellated lines by the 100k).
fn add_segment(mesh: &mut egui::Mesh, a: Pos2, b: Pos2, width: f32, color: Color32) {
    let d = b - a;
    let length = d.length();
    if length < 1e-3 {
        return;
    }
    let n = vec2(-d.y, d.x) / length * (width * 0.5);
    let base = mesh.vertices.len() as u32;
    for p in [a - n, a + n, b + n, b - n] {
        mesh.colored_vertex(p, color);
    }
    mesh.add_triangle(base, base + 1, base + 2);
    mesh.add_triangle(base, base + 2, base + 3);
}

/// Draws an anti-aliased line `width` texels wide from `a` to `b` (texel coordinates, origin
/// at the image's corner) into `image`: each texel's coverage is its centre's distance to the
/// segment against the half width, ±½ texel, and `color` is blended over by coverage.
fn draw_line(image: &mut ColorImage, a: Vec2, b: Vec2, width: f32, color: Color32) {
    let [w, h] = image.size;
    let reach = 0.5 * width + 0.5;
    let (min, max) = (a.min(b) - Vec2::splat(reach), a.max(b) + Vec2::splat(reach));
    if !(min.x.is_finite() && min.y.is_finite() && max.x.is_finite() && max.y.is_finite())
        || max.x < 0.0
        || max.y < 0.0
        || min.x >= w as f32
        || min.y >= h as f32
    {
        return;
    }
    let ab = b - a;
    let length_sq = ab.length_sq();
    let (x0, x1) = (
        min.x.floor().max(0.0) as usize,
        (max.x.ceil() as usize).min(w),
    );
    let (y0, y1) = (
        min.y.floor().max(0.0) as usize,
        (max.y.ceil() as usize).min(h),
    );
    for y in y0..y1 {
        for x in x0..x1 {
            let p = vec2(x as f32 + 0.5, y as f32 + 0.5);
            let t = if length_sq > 1e-12 {
                ((p - a).dot(ab) / length_sq).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let coverage = (reach - (p - (a + ab * t)).length()).clamp(0.0, 1.0);
            if coverage > 0.0 {
                let under = &mut image.pixels[y * w + x];
                *under = under.blend(color.gamma_multiply(coverage));
            }
        }
    }
}

/// [`draw_line`] through a polyline of screen points (closed: back to the first).
fn draw_polyline(
    image: &mut ColorImage,
    transform: &ViewTransform,
    pixels_per_point: f32,
    points: &[Pos2],
    closed: bool,
    width_points: f32,
    color: Color32,
) {
    let texel = |p: Pos2| (p - transform.rect.min) * pixels_per_point;
    let width = width_points * pixels_per_point;
    for pair in points.windows(2) {
        draw_line(image, texel(pair[0]), texel(pair[1]), width, color);
    }
    if closed && points.len() > 2 {
        draw_line(
            image,
            texel(points[points.len() - 1]),
            texel(points[0]),
            width,
            color,
        );
    }
}

impl ImagePanel {
    /// Forgets everything of the previous workspace.
    pub fn reset(&mut self) {
        *self = Self {
            overlays: self.overlays,
            non_leaf_label: self.non_leaf_label,
            ..Self::default()
        };
    }

    /// Shows another view, fitted to the panel.
    pub fn select_view(&mut self, view: usize) {
        if view != self.view {
            self.view = view;
            self.fitted = false;
            self.stroke.clear();
            self.merge_first = None;
            self.drag = None;
        }
    }

    /// Fits the photo to the panel on the next frame.
    pub fn fit(&mut self) {
        self.fitted = false;
    }

    /// Cancels the stroke, drag or first merge click in progress.
    pub fn cancel_gesture(&mut self) {
        self.stroke.clear();
        self.merge_first = None;
        self.drag = None;
    }

    /// Whether all photos' decoding has settled (for tests and screenshots).
    pub fn is_idle(&self) -> bool {
        self.thumbnail_receiver.is_none()
            && self
                .photos
                .values()
                .chain(self.gradients.values())
                .all(|l| !matches!(l, Loadable::Loading(_)))
    }

    fn poll_loads(&mut self, ctx: &egui::Context) {
        for loads in [&mut self.photos, &mut self.gradients] {
            for load in loads.values_mut() {
                if let Loadable::Loading(receiver) = load {
                    match receiver.try_recv() {
                        Ok(Ok(image)) => *load = Loadable::Ready(Arc::new(image)),
                        Ok(Err(message)) => *load = Loadable::Failed(message),
                        Err(TryRecvError::Empty) => ctx.request_repaint(),
                        Err(TryRecvError::Disconnected) => {
                            *load = Loadable::Failed("the decoding thread stopped".into())
                        }
                    }
                }
            }
        }
        if let Some(receiver) = &self.thumbnail_receiver {
            loop {
                match receiver.try_recv() {
                    Ok((view, image)) => {
                        if view < self.thumbnails.len() {
                            self.thumbnails[view] = Some(ctx.load_texture(
                                format!("thumbnail_{view}"),
                                image,
                                egui::TextureOptions::LINEAR,
                            ));
                        }
                    }
                    Err(TryRecvError::Empty) => {
                        ctx.request_repaint();
                        break;
                    }
                    Err(TryRecvError::Disconnected) => {
                        self.thumbnail_receiver = None;
                        break;
                    }
                }
            }
        }
    }

    fn request_photo(&mut self, workspace: &Workspace, view: usize) {
        if self.photos.contains_key(&view) {
            return;
        }
        let scene = workspace.session.scene();
        let image = &scene.reconstruction.images()[view];
        let load = match scene.image_path(image) {
            None => Loadable::Failed("the model has no images folder".into()),
            Some(path) => {
                let (sender, receiver) = channel();
                std::thread::spawn(move || {
                    let _ = sender.send(decode(&path, PHOTO_TEXTURE_SIZE));
                });
                Loadable::Loading(receiver)
            }
        };
        self.photos.insert(view, load);
    }

    fn request_gradient(&mut self, workspace: &Workspace, view: usize) {
        if self.gradients.contains_key(&view) {
            return;
        }
        let scene = Arc::clone(
            self.shared_scene
                .get_or_insert_with(|| Arc::new(workspace.session.scene().clone())),
        );
        let (sender, receiver) = channel();
        std::thread::spawn(move || {
            let _ = sender.send(gradient_image(&scene, view));
        });
        self.gradients.insert(view, Loadable::Loading(receiver));
    }

    fn request_thumbnails(&mut self, workspace: &Workspace) {
        let scene = workspace.session.scene();
        let count = scene.reconstruction.images().len();
        if self.thumbnails.len() == count {
            return;
        }
        self.thumbnails = vec![None; count];
        let paths: Vec<Option<PathBuf>> = scene
            .reconstruction
            .images()
            .iter()
            .map(|image| scene.image_path(image))
            .collect();
        let (sender, receiver) = channel();
        std::thread::spawn(move || {
            for (view, path) in paths.into_iter().enumerate() {
                let Some(path) = path else { continue };
                match decode(&path, THUMBNAIL_SIZE) {
                    Ok(image) => {
                        if sender.send((view, image)).is_err() {
                            return;
                        }
                    }
                    Err(e) => tracing::warn!("thumbnail: {e}"),
                }
            }
        });
        self.thumbnail_receiver = Some(receiver);
    }

    /// Leaf outlines (boundary edges of the fitted leaf meshes) of the latest fit.
    fn outlines(&mut self, workspace: &Workspace) -> &[[Point3<f64>; 2]] {
        let Some((revision, leaves)) = &workspace.leaves else {
            return &[];
        };
        if self.outlines.as_ref().is_none_or(|(r, _)| r != revision) {
            let mut segments = Vec::new();
            for leaf in &leaves.leaves {
                let mesh = &leaf.fit.mesh;
                segments.extend(mesh.boundary_edges().into_iter().map(|[a, b]| {
                    [
                        mesh.positions[a as usize].cast::<f64>(),
                        mesh.positions[b as usize].cast::<f64>(),
                    ]
                }));
            }
            self.outlines = Some((*revision, segments));
        }
        self.outlines.as_ref().map_or(&[], |(_, s)| s.as_slice())
    }

    /// The filmstrip: a thumbnail per view; clicking one shows it.
    pub fn filmstrip_ui(&mut self, ui: &mut egui::Ui, workspace: &Workspace) {
        self.request_thumbnails(workspace);
        self.poll_loads(ui.ctx());
        let images = workspace.session.scene().reconstruction.images();
        egui::ScrollArea::horizontal().show(ui, |ui| {
            ui.horizontal(|ui| {
                for (view, image) in images.iter().enumerate() {
                    let selected = view == self.view;
                    let size = vec2(THUMBNAIL_SIZE as f32 * 0.6, THUMBNAIL_SIZE as f32 * 0.45);
                    let response = ui
                        .vertical(|ui| {
                            let (rect, response) = ui.allocate_exact_size(size, Sense::click());
                            let painter = ui.painter_at(rect);
                            painter.rect_filled(rect, 2.0, Color32::from_gray(30));
                            if let Some(Some(texture)) = self.thumbnails.get(view) {
                                let aspect = texture.aspect_ratio();
                                let fitted = if aspect > size.x / size.y {
                                    vec2(size.x, size.x / aspect)
                                } else {
                                    vec2(size.y * aspect, size.y)
                                };
                                painter.image(
                                    texture.id(),
                                    Rect::from_center_size(rect.center(), fitted),
                                    Rect::from_min_max(pos2(0.0, 0.0), pos2(1.0, 1.0)),
                                    Color32::WHITE,
                                );
                            }
                            let stroke = if selected {
                                Stroke::new(2.0, ui.visuals().selection.stroke.color)
                            } else {
                                Stroke::new(1.0, Color32::from_gray(70))
                            };
                            painter.rect_stroke(rect, 2.0, stroke, egui::StrokeKind::Inside);
                            ui.add(
                                egui::Label::new(egui::RichText::new(&image.name).small())
                                    .truncate(),
                            );
                            response
                        })
                        .inner;
                    if response.on_hover_text(&image.name).clicked() {
                        self.select_view(view);
                    }
                }
            });
        });
    }

    /// Draws the panel and turns the active tool's gestures into actions.
    pub fn ui(&mut self, ui: &mut egui::Ui, workspace: &Workspace, tool: Tool) -> Vec<Action> {
        let model = &workspace.session.scene().reconstruction;
        let images = model.images();
        if images.is_empty() {
            ui.label("The model has no registered images.");
            return Vec::new();
        }
        self.view = self.view.min(images.len() - 1);
        let view = self.view;
        let image = &images[view];
        let camera = model.camera_of(image);
        let size = vec2(camera.width as f32, camera.height as f32);
        if self.overlays.photo {
            self.request_photo(workspace, view);
        }
        if self.overlays.gradient {
            self.request_gradient(workspace, view);
        }
        self.poll_loads(ui.ctx());

        let (response, painter) = ui.allocate_painter(ui.available_size(), Sense::click_and_drag());
        let transform = self.navigate(ui, &response, size, tool);
        let image_rect = Rect::from_min_max(
            transform.screen_from_image([0.0, 0.0]),
            transform.screen_from_image([size.x as f64, size.y as f64]),
        );
        let photo = self.ready(view, Layer::Photo);
        let gradient = self.ready(view, Layer::Gradient);
        self.placeholder_ui(&painter, image_rect, photo.is_some() || gradient.is_some());

        let pixels_per_point = ui.ctx().pixels_per_point();
        let key = self.composite_key(workspace, &transform, pixels_per_point, &photo, &gradient);
        let composed = self.composes(workspace, &photo, &gradient);
        let recompose = composed && self.composite.as_ref().is_none_or(|(k, _)| *k != key);
        let handles = self.branch_handles(workspace, tool, recompose);
        if !composed {
            self.composite = None;
        } else if recompose {
            let layers = PhotoLayers {
                photo,
                gradient,
                size,
            };
            self.compose_ui(ui.ctx(), workspace, &transform, key, &layers, &handles);
        }
        self.composite_ui(&painter, image_rect, response.rect);
        if self.overlays.edges {
            graph_edges_ui(&painter, &transform, workspace, view);
        }
        if self.overlays.branches {
            branch_handles_ui(&painter, &transform, &handles, tool);
        }

        let response = response.on_hover_cursor(tool.cursor());
        let actions = self.tool_input(ui, &response, &transform, workspace, &handles, tool);
        self.gestures_ui(ui, &painter, &response, &transform, image.id);
        self.status_ui(&painter, response.rect, &image.name, images.len());
        actions
    }

    /// Fits the photo to the panel on the first frame; zooms about the cursor; pans with the
    /// middle or right button, or any button when navigating. Returns this frame's transform.
    fn navigate(
        &mut self,
        ui: &egui::Ui,
        response: &egui::Response,
        size: Vec2,
        tool: Tool,
    ) -> ViewTransform {
        let rect = response.rect;
        if !self.fitted && rect.width() > 1.0 && rect.height() > 1.0 {
            self.zoom = (rect.width() / size.x).min(rect.height() / size.y) * 0.96;
            self.center = size * 0.5;
            self.fitted = true;
        }
        if let Some(hover) = response.hover_pos() {
            let (scroll, pinch) = ui.input(|i| (i.smooth_scroll_delta.y, i.zoom_delta()));
            let factor = (scroll * 0.002).exp() * pinch;
            if (factor - 1.0).abs() > 1e-4 {
                let anchor = self.center + (hover - rect.center()) / self.zoom;
                self.zoom = (self.zoom * factor).clamp(0.02, 64.0);
                self.center = anchor - (hover - rect.center()) / self.zoom;
            }
        }
        let panning = response.dragged_by(egui::PointerButton::Middle)
            || response.dragged_by(egui::PointerButton::Secondary)
            || (tool == Tool::Navigate && response.dragged_by(egui::PointerButton::Primary));
        if panning {
            self.center -= response.drag_delta() / self.zoom;
        }
        let transform = ViewTransform {
            rect,
            center: self.center,
            zoom: self.zoom,
        };
        self.transform = Some(transform);
        transform
    }

    /// Branches projected into this view: for composing their curves (`recompose`), for the
    /// handles a branch tool shows and grabs, and for leaf-at-tip marks; none otherwise (not
    /// every frame).
    fn branch_handles(
        &self,
        workspace: &Workspace,
        tool: Tool,
        recompose: bool,
    ) -> Vec<BranchHandles> {
        let tree = workspace.session.branches();
        let needed = (self.overlays.branches
            && (recompose || tool.is_branch_tool() || tree.branches.iter().any(|b| b.leaf_at_tip)))
            || matches!(tool, Tool::MoveBranch | Tool::Radius);
        if !needed {
            return Vec::new();
        }
        let model = &workspace.session.scene().reconstruction;
        let view = PhotoView::new(model, &model.images()[self.view]);
        project_branches(tree, &view, BRANCH_CURVE_SAMPLES)
    }

    /// A decoded layer of view `view`, when it has arrived and its overlay is on.
    fn ready(&self, view: usize, layer: Layer) -> Option<Arc<ColorImage>> {
        let (loads, shown) = match layer {
            Layer::Photo => (&self.photos, self.overlays.photo),
            Layer::Gradient => (&self.gradients, self.overlays.gradient),
        };
        match loads.get(&view) {
            Some(Loadable::Ready(pixels)) if shown => Some(Arc::clone(pixels)),
            _ => None,
        }
    }

    /// A grey backdrop where no photo or gradient image is shown yet, and the photo's loading
    /// state (or why it is unavailable) over it.
    fn placeholder_ui(&self, painter: &egui::Painter, image_rect: Rect, layer_shown: bool) {
        if !layer_shown {
            painter.rect_filled(image_rect, 0.0, Color32::from_gray(40));
        }
        if !self.overlays.photo {
            return;
        }
        let message = match self.photos.get(&self.view) {
            Some(Loadable::Ready(..)) => None,
            Some(Loadable::Failed(message)) => Some((
                format!("photo unavailable: {message}"),
                Color32::from_rgb(230, 160, 80),
            )),
            _ => Some(("loading photo …".to_owned(), Color32::from_gray(160))),
        };
        if let Some((text, color)) = message {
            painter.text(
                image_rect.center(),
                egui::Align2::CENTER_CENTER,
                text,
                egui::FontId::proportional(14.0),
                color,
            );
        }
    }

    /// What the composite of this frame depends on.
    fn composite_key(
        &self,
        workspace: &Workspace,
        transform: &ViewTransform,
        pixels_per_point: f32,
        photo: &Option<Arc<ColorImage>>,
        gradient: &Option<Arc<ColorImage>>,
    ) -> CompositeKey {
        let rect = transform.rect;
        CompositeKey {
            view: self.view,
            revision: workspace.revision,
            leaves: workspace.leaves.as_ref().map(|(revision, _)| *revision),
            size: [
                (rect.width() * pixels_per_point).round().max(1.0) as usize,
                (rect.height() * pixels_per_point).round().max(1.0) as usize,
            ],
            center: [self.center.x.to_bits(), self.center.y.to_bits()],
            zoom: self.zoom.to_bits(),
            overlays: self.overlays,
            photo: photo.is_some(),
            gradient: gradient.is_some(),
        }
    }

    /// Whether anything is composed: a layer, points, or an overlay with something to draw.
    fn composes(
        &self,
        workspace: &Workspace,
        photo: &Option<Arc<ColorImage>>,
        gradient: &Option<Arc<ColorImage>>,
    ) -> bool {
        let overlays = self.overlays;
        let session = &workspace.session;
        photo.is_some()
            || gradient.is_some()
            || overlays.points
            || (overlays.boundaries && session.segments().iter().any(Option::is_some))
            || (overlays.leaf_outlines && workspace.leaves.is_some())
            || (overlays.branches && !session.branches().branches.is_empty())
    }

    /// Composes the photo, the gradient image and the overlays that go under the handles
    /// (points, segment boundaries, leaf outlines, branch curves) into the panel's texture.
    fn compose_ui(
        &mut self,
        ctx: &egui::Context,
        workspace: &Workspace,
        transform: &ViewTransform,
        key: CompositeKey,
        layers: &PhotoLayers,
        handles: &[BranchHandles],
    ) {
        let started = std::time::Instant::now();
        let pixels_per_point = ctx.pixels_per_point();
        let mut canvas = layers.resample(transform, key.size, pixels_per_point);
        let composer = Composer {
            transform,
            pixels_per_point,
        };
        let overlays = self.overlays;
        let (session, view) = (&workspace.session, self.view);
        if overlays.points {
            let projected =
                session
                    .views()
                    .projected(session.scene(), &session.segmentation().points, view);
            let segment_of = session.segment_of();
            splat_points(
                &mut canvas,
                &projected,
                transform,
                pixels_per_point,
                |point| session_segment_color(workspace, segment_of[point as usize]),
            );
        }
        if overlays.boundaries {
            composer.boundaries(&mut canvas, workspace, view);
        }
        if overlays.leaf_outlines {
            let model = &session.scene().reconstruction;
            let image = &model.images()[view];
            composer.leaf_outlines(&mut canvas, self.outlines(workspace), model, image);
        }
        if overlays.branches {
            composer.branch_curves(&mut canvas, handles);
        }
        let texture = ctx.load_texture("photo_view", canvas, egui::TextureOptions::NEAREST);
        self.composite = Some((key, texture));
        self.last_compose_ms = Some(started.elapsed().as_secs_f32() * 1000.0);
    }

    /// Draws the composite over the photo's part of the panel (the rest of it is transparent:
    /// fewer fragments for a software rasteriser).
    fn composite_ui(&self, painter: &egui::Painter, image_rect: Rect, rect: Rect) {
        let shown = image_rect.intersect(rect);
        if let Some((_, texture)) = &self.composite
            && shown.is_positive()
        {
            let uv = Rect::from_min_max(
                ((shown.min - rect.min) / rect.size()).to_pos2(),
                ((shown.max - rect.min) / rect.size()).to_pos2(),
            );
            painter.image(texture.id(), shown, uv, Color32::WHITE);
        }
    }

    /// Routes the primary button to the active tool: strokes (Split, Draw branch), handle
    /// drags (Move point, Radius) or clicks (the others).
    fn tool_input(
        &mut self,
        ui: &egui::Ui,
        response: &egui::Response,
        transform: &ViewTransform,
        workspace: &Workspace,
        handles: &[BranchHandles],
        tool: Tool,
    ) -> Vec<Action> {
        let image_id = workspace.session.scene().reconstruction.images()[self.view].id;
        let pointer_image = response
            .interact_pointer_pos()
            .or(response.hover_pos())
            .map(|p| transform.image_from_screen(p));
        match tool {
            Tool::Navigate => Vec::new(),
            Tool::Split | Tool::DrawBranch => {
                self.stroke_input(ui, response, transform, pointer_image, image_id, tool)
            }
            Tool::MoveBranch | Tool::Radius => {
                let press_origin = ui.input(|i| i.pointer.press_origin());
                let pointer = (press_origin, pointer_image);
                self.handle_input(response, transform, pointer, image_id, handles, tool)
            }
            _ => match pointer_image.filter(|_| response.clicked()) {
                Some(pixel) => self.click(workspace, tool, PixelRef { image_id, pixel }, self.view),
                None => Vec::new(),
            },
        }
    }

    /// A stroke of Split or Draw branch: samples while the button is down, the command when
    /// it is released (Shift closes a split stroke).
    fn stroke_input(
        &mut self,
        ui: &egui::Ui,
        response: &egui::Response,
        transform: &ViewTransform,
        pointer_image: Option<[f64; 2]>,
        image_id: ImageId,
        tool: Tool,
    ) -> Vec<Action> {
        let primary = egui::PointerButton::Primary;
        let press_origin = ui.input(|i| i.pointer.press_origin());
        if response.drag_started_by(primary)
            && let Some(origin) = press_origin
        {
            // The drag starts where the button went down, not where it was noticed.
            self.stroke = vec![transform.image_from_screen(origin)];
            if let Some(p) = pointer_image {
                self.stroke.push(p);
            }
        } else if response.dragged_by(primary)
            && let Some(p) = pointer_image
            && let Some(last) = self.stroke.last()
        {
            let moved = transform.screen_from_image(p) - transform.screen_from_image(*last);
            if moved.length() >= STROKE_STEP {
                self.stroke.push(p);
            }
        } else if response.drag_stopped_by(primary) {
            let stroke = std::mem::take(&mut self.stroke);
            if stroke.len() >= 2 {
                return vec![Action::Apply(if tool == Tool::Split {
                    Command::SplitByStroke {
                        image_id,
                        stroke,
                        closed: ui.input(|i| i.modifiers.shift),
                    }
                } else {
                    Command::DrawBranch {
                        stroke: BranchStroke::Image { image_id, stroke },
                        radius: None,
                    }
                })];
            }
        }
        Vec::new()
    }

    /// A handle drag of Move point or Radius: the handle under the press, the command where
    /// it is released. `pointer`: where the button went down (screen) and where the pointer
    /// is (image pixels).
    fn handle_input(
        &mut self,
        response: &egui::Response,
        transform: &ViewTransform,
        pointer: (Option<Pos2>, Option<[f64; 2]>),
        image_id: ImageId,
        handles: &[BranchHandles],
        tool: Tool,
    ) -> Vec<Action> {
        let primary = egui::PointerButton::Primary;
        let (press_origin, pointer_image) = pointer;
        if response.drag_started_by(primary)
            && let Some(origin) = press_origin
        {
            // The grab distance is in screen points; the handles are in image pixels.
            let tolerance_px = GRAB_DISTANCE as f64 / transform.zoom as f64;
            self.drag = grab_handle(
                tool,
                handles,
                transform.image_from_screen(origin),
                tolerance_px,
            );
            if self.drag.is_none() {
                return vec![Action::Message(
                    if tool == Tool::MoveBranch {
                        "no control point there: drag a square handle"
                    } else {
                        "no branch end there: drag from an end's circle"
                    }
                    .into(),
                )];
            }
        } else if response.drag_stopped_by(primary)
            && let (Some(drag), Some(pixel)) = (self.drag.take(), pointer_image)
        {
            let to = BranchTarget::Image {
                at: PixelRef { image_id, pixel },
            };
            return vec![Action::Apply(release_handle(drag, pixel, to))];
        }
        Vec::new()
    }

    /// The gestures in progress: the stroke being drawn, the first merge click, the handle
    /// being dragged.
    fn gestures_ui(
        &self,
        ui: &egui::Ui,
        painter: &egui::Painter,
        response: &egui::Response,
        transform: &ViewTransform,
        image_id: ImageId,
    ) {
        let accent = ui.visuals().selection.stroke.color;
        if self.stroke.len() >= 2 {
            let points: Vec<Pos2> = self
                .stroke
                .iter()
                .map(|&uv| transform.screen_from_image(uv))
                .collect();
            painter.add(Shape::line(
                points.clone(),
                Stroke::new(4.0, Color32::BLACK),
            ));
            painter.add(Shape::line(points, Stroke::new(2.0, accent)));
        }
        if let Some(first) = &self.merge_first
            && first.image_id == image_id
        {
            let p = transform.screen_from_image(first.pixel);
            painter.circle_stroke(p, 7.0, Stroke::new(2.5, accent));
            if let Some(hover) = response.hover_pos() {
                painter.line_segment([p, hover], Stroke::new(1.5, accent));
            }
        }
        if let (Some(drag), Some(hover)) = (self.drag, response.hover_pos()) {
            match drag {
                HandlePick::ControlPoint { .. } => {
                    painter.rect_stroke(
                        Rect::from_center_size(hover, Vec2::splat(10.0)),
                        0.0,
                        Stroke::new(2.0, accent),
                        egui::StrokeKind::Middle,
                    );
                }
                HandlePick::End { disc, .. } => {
                    let c = transform.screen_from_uv(&disc.centre_px);
                    painter.circle_stroke(c, (hover - c).length(), Stroke::new(2.0, accent));
                }
            }
        }
    }

    /// The status line at the panel's bottom left: photo name, its place, zoom.
    fn status_ui(&self, painter: &egui::Painter, rect: Rect, name: &str, views: usize) {
        painter.text(
            rect.left_bottom() + vec2(10.0, -10.0),
            egui::Align2::LEFT_BOTTOM,
            format!(
                "{}  ·  {}/{}  ·  {:.0} %",
                name,
                self.view + 1,
                views,
                self.zoom * 100.0
            ),
            egui::FontId::proportional(13.0),
            Color32::from_gray(220),
        );
    }

    /// A click of a click tool.
    fn click(
        &mut self,
        workspace: &Workspace,
        tool: Tool,
        at: PixelRef,
        view: usize,
    ) -> Vec<Action> {
        let session = &workspace.session;
        let command = match tool {
            Tool::Confirm => Command::ConfirmSegment { at },
            Tool::MarkLeaf => Command::MarkLeaf { at },
            Tool::MarkNonLeaf => Command::MarkNonLeaf {
                at,
                label: self.non_leaf_label,
            },
            Tool::Reset => Command::ResetSegment { at },
            Tool::Merge => match self.merge_first.take() {
                Some(first) if first.image_id == at.image_id => {
                    Command::MergeByClick { first, second: at }
                }
                _ => {
                    return match session.pick_segment(&at) {
                        Ok(_) => {
                            self.merge_first = Some(at);
                            vec![Action::Message(
                                "first segment picked: click a point of the other segment".into(),
                            )]
                        }
                        Err(e) => vec![Action::Message(e.to_string())],
                    };
                }
            },
            Tool::GenericLeaf => {
                return vec![match session.pick_segment(&at) {
                    Ok(segment) => Action::SetGenericLeaf(TemplatePick {
                        segment,
                        view: Some(view),
                    }),
                    Err(e) => Action::Message(e.to_string()),
                }];
            }
            Tool::LeafAtTip | Tool::DeleteBranch => match session.pick_branch(&at) {
                Ok(point) => {
                    if tool == Tool::DeleteBranch {
                        Command::DeleteBranch {
                            branch: point.branch,
                        }
                    } else {
                        let enabled = session
                            .branches()
                            .get(point.branch)
                            .is_some_and(|b| !b.leaf_at_tip);
                        Command::SetLeafAtTip {
                            branch: point.branch,
                            enabled,
                        }
                    }
                }
                Err(e) => return vec![Action::Message(e.to_string())],
            },
            _ => return Vec::new(),
        };
        vec![Action::Apply(command)]
    }
}

/// A decoded layer of a view.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Layer {
    Photo,
    Gradient,
}

/// The photo and the gradient image a composite starts from, and the camera size (pixels)
/// they cover.
struct PhotoLayers {
    photo: Option<Arc<ColorImage>>,
    gradient: Option<Arc<ColorImage>>,
    size: Vec2,
}

impl PhotoLayers {
    /// The photo resampled into a panel-sized canvas of `size` texels, the gradient image
    /// blended over it (or alone without a photo); transparent where neither is.
    fn resample(
        &self,
        transform: &ViewTransform,
        size: [usize; 2],
        pixels_per_point: f32,
    ) -> ColorImage {
        let mut canvas = match &self.photo {
            Some(photo) => resample_photo(photo, self.size, transform, size, pixels_per_point),
            None => ColorImage::filled(size, Color32::TRANSPARENT),
        };
        if let Some(gradient) = &self.gradient {
            let grey = resample_photo(gradient, self.size, transform, size, pixels_per_point);
            for (under, over) in canvas.pixels.iter_mut().zip(&grey.pixels) {
                *under = if self.photo.is_some() {
                    under.blend(over.gamma_multiply_u8(200))
                } else {
                    *over
                };
            }
        }
        canvas
    }
}

/// Draws the line overlays of a composite into its canvas: the panel's transform and texels
/// per screen point.
struct Composer<'a> {
    transform: &'a ViewTransform,
    pixels_per_point: f32,
}

impl Composer<'_> {
    /// [`draw_polyline`] through screen points, `width` points wide.
    fn polyline(
        &self,
        canvas: &mut ColorImage,
        points: &[Pos2],
        closed: bool,
        width: f32,
        color: Color32,
    ) {
        draw_polyline(
            canvas,
            self.transform,
            self.pixels_per_point,
            points,
            closed,
            width,
            color,
        );
    }

    /// Every segment's image boundary computed in view `view`, outlined in black under its
    /// segment colour.
    fn boundaries(&self, canvas: &mut ColorImage, workspace: &Workspace, view: usize) {
        let session = &workspace.session;
        for (segment, state) in session.segments().iter().enumerate() {
            let (Some(state), Some(boundary)) = (state, session.boundary(segment as u32, view))
            else {
                continue;
            };
            let points: Vec<Pos2> = boundary
                .polygon
                .iter()
                .map(|&uv| self.transform.screen_from_image(uv))
                .collect();
            let color = segment_color(segment as i32, Some(state.label));
            self.polyline(canvas, &points, true, 3.5, Color32::BLACK);
            self.polyline(canvas, &points, true, 2.0, color);
        }
    }

    /// The fitted leaves' outlines (world segments) projected into `image`.
    fn leaf_outlines(
        &self,
        canvas: &mut ColorImage,
        outlines: &[[Point3<f64>; 2]],
        model: &Reconstruction,
        image: &Image,
    ) {
        for [a, b] in outlines {
            let (Some(ua), Some(ub)) = (model.project(image, a), model.project(image, b)) else {
                continue;
            };
            let ends = [
                self.transform.screen_from_uv(&ua),
                self.transform.screen_from_uv(&ub),
            ];
            self.polyline(canvas, &ends, false, 1.5, Color32::from_rgb(255, 240, 90));
        }
    }

    /// The branches' skeleton curves, in wood colour over a black outline.
    fn branch_curves(&self, canvas: &mut ColorImage, handles: &[BranchHandles]) {
        for handle in handles {
            let curve: Vec<Pos2> = handle
                .curve_px
                .iter()
                .map(|uv| self.transform.screen_from_uv(uv))
                .collect();
            self.polyline(canvas, &curve, false, 4.0, Color32::BLACK);
            self.polyline(canvas, &curve, false, 2.0, WOOD);
        }
    }
}

/// The colour of a segment as the session labels it.
fn session_segment_color(workspace: &Workspace, segment: i32) -> Color32 {
    let segments = workspace.session.segments();
    let label = (segment >= 0)
        .then(|| segments.get(segment as usize).copied().flatten())
        .flatten()
        .map(|s| s.label);
    segment_color(segment, label)
}

/// The segmentation graph's edges between points view `view` sees, as thin quads over the
/// composite: kept edges bright, edges the partition cut red.
fn graph_edges_ui(
    painter: &egui::Painter,
    transform: &ViewTransform,
    workspace: &Workspace,
    view: usize,
) {
    let session = &workspace.session;
    let segmentation = session.segmentation();
    let projected = session
        .views()
        .projected(session.scene(), &segmentation.points, view);
    let visible = transform.rect.expand(4.0);
    let mut uv_of: HashMap<u32, Point2<f64>> = HashMap::with_capacity(projected.len());
    uv_of.extend(projected.iter().map(|p| (p.point, p.uv_image)));
    let mut mesh = egui::Mesh::default();
    for edge in &segmentation.graph.edges {
        let a = segmentation.graph_points[edge.a as usize] as u32;
        let b = segmentation.graph_points[edge.b as usize] as u32;
        let (Some(ua), Some(ub)) = (uv_of.get(&a), uv_of.get(&b)) else {
            continue;
        };
        let pa = transform.screen_from_uv(ua);
        let pb = transform.screen_from_uv(ub);
        if !visible.contains(pa) && !visible.contains(pb) {
            continue;
        }
        let color = if edge.weight > 0.0 {
            Color32::from_rgba_unmultiplied(230, 230, 230, 110)
        } else {
            Color32::from_rgba_unmultiplied(255, 60, 60, 90)
        };
        add_segment(&mut mesh, pa, pb, 1.0, color);
    }
    painter.add(Shape::mesh(mesh));
}

/// What goes over the composite for branches: the leaf-at-tip marks, and the handles while a
/// branch tool is active (the curves are in the composite).
fn branch_handles_ui(
    painter: &egui::Painter,
    transform: &ViewTransform,
    handles: &[BranchHandles],
    tool: Tool,
) {
    // Handles (radius circles, control points, ids) only while a branch tool is active: a
    // plant with a hundred branches is otherwise cluttered, and slow on a software rasteriser.
    let show_handles = tool.is_branch_tool();
    for handle in handles {
        for disc in handle.ends.iter().flatten().filter(|_| show_handles) {
            let c = transform.screen_from_uv(&disc.centre_px);
            painter.circle_stroke(
                c,
                (disc.radius_px as f32 * transform.zoom).max(2.0),
                Stroke::new(1.5, Color32::from_rgb(255, 200, 120)),
            );
        }
        if handle.leaf_at_tip
            && let Some(tip) = handle.ends[1]
        {
            painter.circle_filled(
                transform.screen_from_uv(&tip.centre_px),
                5.0,
                Color32::from_rgb(120, 220, 90),
            );
        }
        if show_handles {
            for uv in handle.control_points_px.iter().flatten() {
                let p = transform.screen_from_uv(uv);
                let square = Rect::from_center_size(p, Vec2::splat(7.0));
                painter.rect_filled(square, 0.0, Color32::BLACK);
                painter.rect_stroke(
                    square,
                    0.0,
                    Stroke::new(1.5, WOOD),
                    egui::StrokeKind::Inside,
                );
            }
        }
        if show_handles && let Some(first) = handle.curve_px.first() {
            painter.text(
                transform.screen_from_uv(first) + vec2(6.0, -6.0),
                egui::Align2::LEFT_BOTTOM,
                format!("{}", handle.branch),
                egui::FontId::proportional(11.0),
                Color32::from_rgb(255, 210, 150),
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn view_transform_round_trips() {
        let transform = ViewTransform {
            rect: Rect::from_min_size(pos2(100.0, 50.0), vec2(800.0, 600.0)),
            center: vec2(320.0, 240.0),
            zoom: 1.75,
        };
        for uv in [[0.0, 0.0], [320.0, 240.0], [639.5, 10.25]] {
            let back = transform.image_from_screen(transform.screen_from_image(uv));
            assert!((back[0] - uv[0]).abs() < 1e-3 && (back[1] - uv[1]).abs() < 1e-3);
        }
        assert_eq!(
            transform.screen_from_image([320.0, 240.0]),
            pos2(500.0, 350.0)
        );
    }

    #[test]
    fn points_are_splatted_where_they_project() {
        let transform = ViewTransform {
            rect: Rect::from_min_size(pos2(50.0, 20.0), vec2(100.0, 80.0)),
            center: vec2(50.0, 40.0),
            zoom: 1.0,
        };
        let projections =
            [(0u32, [10.5, 20.5]), (1, [90.0, 70.0]), (2, [500.0, 10.0])].map(|(point, [u, v])| {
                Projected {
                    point,
                    uv_image: Point2::new(u, v),
                    depth_camera: 1.0,
                }
            });
        let mut image = ColorImage::filled([200, 160], Color32::TRANSPARENT);
        splat_points(&mut image, &projections, &transform, 2.0, |p| {
            [Color32::RED, Color32::GREEN, Color32::BLUE][p as usize]
        });
        // Image pixel (10.5, 20.5) is screen (60.5, 40.5), texel (21, 41) at 2 px per point.
        assert_eq!(image.pixels[41 * 200 + 21], Color32::RED);
        assert_eq!(image.pixels[140 * 200 + 180], Color32::GREEN);
        // Off-panel points leave nothing; most of the image stays transparent.
        assert!(!image.pixels.contains(&Color32::BLUE));
        let covered = image
            .pixels
            .iter()
            .filter(|c| **c != Color32::TRANSPARENT)
            .count();
        assert!(covered > 0 && covered <= 2 * 4 * 4, "{covered}");

        // A translucent point tints an opaque photo (it is blended over, not under).
        let mut photo = ColorImage::filled([200, 160], Color32::from_gray(200));
        let grey = Color32::from_rgba_unmultiplied(0, 0, 255, 110);
        splat_points(&mut photo, &projections[..1], &transform, 2.0, |_| grey);
        let tinted = photo.pixels[41 * 200 + 21];
        assert!(tinted.b() > tinted.r() && tinted.a() == 255, "{tinted:?}");
    }

    #[test]
    fn lines_cover_their_width_with_soft_edges_and_nothing_else() {
        let mut image = ColorImage::filled([40, 20], Color32::TRANSPARENT);
        // A horizontal line 3 texels wide along y = 10.
        draw_line(
            &mut image,
            vec2(5.0, 10.0),
            vec2(35.0, 10.0),
            3.0,
            Color32::RED,
        );
        let at = |x: usize, y: usize| image.pixels[y * 40 + x];
        for y in 9..=10 {
            assert_eq!(at(20, y), Color32::RED, "row {y}");
        }
        // Texel centres 1.5 from the axis: half covered; 2.5 away: untouched.
        assert!(
            at(20, 8).a() > 100 && at(20, 8).a() < 160,
            "{:?}",
            at(20, 8)
        );
        assert_eq!(at(20, 7), Color32::TRANSPARENT);
        assert_eq!(at(20, 12), Color32::TRANSPARENT);
        assert_eq!(at(38, 10), Color32::TRANSPARENT);
        let covered = image.pixels.iter().filter(|c| c.a() > 0).count();
        assert!((120..=140).contains(&covered), "{covered}");

        // Off the image, degenerate or not finite: nothing drawn, no panic.
        let before = image.pixels.clone();
        draw_line(
            &mut image,
            vec2(-50.0, -5.0),
            vec2(-10.0, -5.0),
            3.0,
            Color32::GREEN,
        );
        draw_line(
            &mut image,
            vec2(f32::NAN, 1.0),
            vec2(3.0, 3.0),
            3.0,
            Color32::GREEN,
        );
        draw_line(
            &mut image,
            vec2(100.0, 1.0),
            vec2(300.0, 3.0),
            3.0,
            Color32::GREEN,
        );
        assert_eq!(image.pixels, before);
        // A zero-length line is a dot.
        draw_line(
            &mut image,
            vec2(2.5, 2.5),
            vec2(2.5, 2.5),
            2.0,
            Color32::GREEN,
        );
        assert_eq!(image.pixels[2 * 40 + 2], Color32::GREEN);
    }

    #[test]
    fn the_photo_is_resampled_where_the_view_shows_it() {
        // A 4×2 photo of a 40×20 camera, shown at zoom 2 centred on the image.
        let photo = ColorImage::new([4, 2], (0..8).map(|k| Color32::from_gray(k * 30)).collect());
        let transform = ViewTransform {
            rect: Rect::from_min_size(pos2(0.0, 0.0), vec2(100.0, 60.0)),
            center: vec2(20.0, 10.0),
            zoom: 2.0,
        };
        let image = resample_photo(&photo, vec2(40.0, 20.0), &transform, [100, 60], 1.0);
        // The photo spans screen x 10..90, y 10..50; outside is transparent.
        assert_eq!(image.pixels[5 * 100 + 50], Color32::TRANSPARENT);
        assert_eq!(image.pixels[30 * 100 + 5], Color32::TRANSPARENT);
        // Near the centre of photo texel (0, 0) (camera pixel (5, 5), screen (20, 20)).
        assert!(image.pixels[20 * 100 + 20].r() <= 5);
        // Texel (3, 1) is at camera (35, 15), screen (80, 40).
        assert_eq!(image.pixels[40 * 100 + 80], Color32::from_gray(210));
        // Half-way between texels (1, 0) and (2, 0) (30 and 60): about their mean.
        let between = image.pixels[20 * 100 + 50];
        assert!((44..=52).contains(&between.r()), "{between:?}");
    }

    #[test]
    fn segments_get_distinct_colours_and_labels_their_own() {
        let leaf = Some(SegmentLabel::Leaf);
        let colours: std::collections::HashSet<Color32> =
            (0..20).map(|s| segment_color(s, leaf)).collect();
        assert_eq!(colours.len(), 20);
        assert_ne!(
            segment_color(1, Some(SegmentLabel::Stem)),
            segment_color(1, leaf)
        );
        assert!(segment_color(-1, None).a() < 255);
    }
}
