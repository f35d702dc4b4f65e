//! The image panel: one input photo with zoom and pan, overlays of the session's state
//! (projected points coloured by segment, graph edges, gradient image, segment boundaries,
//! fitted leaf outlines, branches with radius circles) and the editing tools, which turn
//! clicks and strokes into the library's `Command`s. Photos, thumbnails and gradient images
//! are decoded on worker threads.

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::mpsc::{Receiver, TryRecvError, channel};

use egui::{
    Color32, ColorImage, Pos2, Rect, Sense, Shape, Stroke, TextureHandle, Vec2, pos2, vec2,
};
use frond::edit::{BranchEnd, BranchStroke, BranchTarget, Command, PixelRef};
use frond::leaf::TemplatePick;
use frond::scene::Scene;
use frond::segment::SegmentLabel;
use nalgebra::Point3;

use crate::tools::Tool;
use crate::workspace::Workspace;

/// Largest side of a photo texture (texels); larger photos are shown downscaled.
const PHOTO_TEXTURE_SIZE: u32 = 2048;
/// Largest side of a filmstrip thumbnail (texels).
const THUMBNAIL_SIZE: u32 = 160;
/// Control points and branch ends are grabbed within this distance (screen points).
const GRAB_DISTANCE: f32 = 12.0;
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
    let mut sorted: Vec<f32> = gradient
        .data
        .iter()
        .copied()
        .filter(|v| v.is_finite())
        .collect();
    let scale = if sorted.is_empty() {
        1.0
    } else {
        let k = (sorted.len() - 1) * 99 / 100;
        let (_, high, _) = sorted.select_nth_unstable_by(k, f32::total_cmp);
        high.max(1e-6)
    };
    let grey = gradient
        .data
        .iter()
        .map(|v| ((v / scale).clamp(0.0, 1.0) * 255.0) as u8);
    Ok(ColorImage::from_gray_iter(
        [gradient.width as usize, gradient.height as usize],
        grey,
    ))
}

/// The points seen in a view and their pixels (COLMAP convention).
type ViewProjections = Arc<Vec<(u32, [f32; 2])>>;

/// A drag of a branch handle in progress.
#[derive(Clone, Copy, Debug)]
enum BranchDrag {
    Move {
        branch: u32,
        control_point: usize,
    },
    Radius {
        branch: u32,
        end: BranchEnd,
        center: [f64; 2],
        /// Image pixels per metre at the end, across the view ray.
        px_per_metre: f64,
    },
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
    /// Per view: the points seen in it and their pixels.
    projections: HashMap<usize, ViewProjections>,
    /// The scene shared with gradient workers (made on first use).
    shared_scene: Option<Arc<Scene>>,
    /// Leaf outlines as world segments, with the workspace revision of the fit.
    outlines: Option<(u64, Vec<[Point3<f64>; 2]>)>,
    stroke: Vec<[f64; 2]>,
    merge_first: Option<PixelRef>,
    drag: Option<BranchDrag>,
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
            projections: HashMap::new(),
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
    projections: &[(u32, [f32; 2])],
    transform: &ViewTransform,
    pixels_per_point: f32,
    color_of: impl Fn(u32) -> Color32,
) {
    let [width, height] = image.size;
    let half = ((1.2 * transform.zoom.sqrt()).clamp(1.0, 3.5) * pixels_per_point).round() as i64;
    let (w, h) = (width as i64, height as i64);
    for &(point, uv) in projections {
        let p = (transform.screen_from_image([uv[0] as f64, uv[1] as f64]) - transform.rect.min)
            * pixels_per_point;
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

    fn projections(&mut self, workspace: &Workspace, view: usize) -> ViewProjections {
        Arc::clone(self.projections.entry(view).or_insert_with(|| {
            let session = &workspace.session;
            let model = &session.scene().reconstruction;
            let image = &model.images()[view];
            let points = &session.segmentation().points;
            Arc::new(
                (0..points.len())
                    .filter(|&p| points.views[p].binary_search(&(view as u32)).is_ok())
                    .filter_map(|p| {
                        let uv = model.project(image, &points.positions[p])?;
                        Some((p as u32, [uv.x as f32, uv.y as f32]))
                    })
                    .collect(),
            )
        }))
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
                let mut count: HashMap<(u32, u32), u32> = HashMap::new();
                for t in &mesh.triangles {
                    for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
                        *count.entry((a.min(b), a.max(b))).or_default() += 1;
                    }
                }
                segments.extend(
                    count
                        .into_iter()
                        .filter(|(_, n)| *n == 1)
                        .map(|((a, b), _)| {
                            [
                                mesh.positions[a as usize].cast::<f64>(),
                                mesh.positions[b as usize].cast::<f64>(),
                            ]
                        }),
                );
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
        let mut actions = Vec::new();
        let images = workspace.session.scene().reconstruction.images();
        if images.is_empty() {
            ui.label("The model has no registered images.");
            return actions;
        }
        self.view = self.view.min(images.len() - 1);
        let view = self.view;
        let model = &workspace.session.scene().reconstruction;
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
        let rect = response.rect;
        if !self.fitted && rect.width() > 1.0 && rect.height() > 1.0 {
            self.zoom = (rect.width() / size.x).min(rect.height() / size.y) * 0.96;
            self.center = size * 0.5;
            self.fitted = true;
        }
        // Zoom about the cursor; pan with the middle or right button, or any button when
        // navigating.
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

        let image_rect = Rect::from_min_max(
            transform.screen_from_image([0.0, 0.0]),
            transform.screen_from_image([size.x as f64, size.y as f64]),
        );
        let ready = |loads: &HashMap<usize, Loadable>| match loads.get(&view) {
            Some(Loadable::Ready(pixels)) => Some(Arc::clone(pixels)),
            _ => None,
        };
        let overlays = self.overlays;
        let photo = ready(&self.photos).filter(|_| overlays.photo);
        let gradient = ready(&self.gradients).filter(|_| overlays.gradient);
        if photo.is_none() && gradient.is_none() {
            painter.rect_filled(image_rect, 0.0, Color32::from_gray(40));
        }
        if overlays.photo {
            let message = match self.photos.get(&view) {
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

        let session = &workspace.session;
        let segment_of = session.segment_of();
        let segments = session.segments();
        let label_of = |segment: i32| -> Option<SegmentLabel> {
            (segment >= 0)
                .then(|| segments.get(segment as usize).copied().flatten())
                .flatten()
                .map(|s| s.label)
        };
        let projections = if overlays.points || overlays.edges {
            Some(self.projections(workspace, view))
        } else {
            None
        };
        let pixels_per_point = ui.ctx().pixels_per_point();
        let key = CompositeKey {
            view,
            revision: workspace.revision,
            leaves: workspace.leaves.as_ref().map(|(revision, _)| *revision),
            size: [
                (rect.width() * pixels_per_point).round().max(1.0) as usize,
                (rect.height() * pixels_per_point).round().max(1.0) as usize,
            ],
            center: [self.center.x.to_bits(), self.center.y.to_bits()],
            zoom: self.zoom.to_bits(),
            overlays,
            photo: photo.is_some(),
            gradient: gradient.is_some(),
        };
        let composed = photo.is_some()
            || gradient.is_some()
            || overlays.points
            || (overlays.boundaries && segments.iter().any(Option::is_some))
            || (overlays.leaf_outlines && workspace.leaves.is_some())
            || (overlays.branches && !session.branches().branches.is_empty());
        let recompose = composed && self.composite.as_ref().is_none_or(|(k, _)| *k != key);
        // Branches projected into this view: for composing their curves, for the handles a
        // branch tool shows and grabs, and for leaf-at-tip marks (not every frame otherwise).
        let handles = if (overlays.branches
            && (recompose
                || tool.is_branch_tool()
                || session.branches().branches.iter().any(|b| b.leaf_at_tip)))
            || matches!(tool, Tool::MoveBranch | Tool::Radius)
        {
            branch_handles(workspace, view)
        } else {
            Vec::new()
        };
        if !composed {
            self.composite = None;
        } else if recompose {
            let started = std::time::Instant::now();
            let mut canvas = match &photo {
                Some(photo) => resample_photo(photo, size, &transform, key.size, pixels_per_point),
                None => ColorImage::filled(key.size, Color32::TRANSPARENT),
            };
            if let Some(gradient) = &gradient {
                let grey = resample_photo(gradient, size, &transform, key.size, pixels_per_point);
                for (under, over) in canvas.pixels.iter_mut().zip(&grey.pixels) {
                    *under = if photo.is_some() {
                        under.blend(over.gamma_multiply_u8(200))
                    } else {
                        *over
                    };
                }
            }
            if let Some(projections) = projections.as_ref().filter(|_| overlays.points) {
                splat_points(
                    &mut canvas,
                    projections,
                    &transform,
                    pixels_per_point,
                    |point| {
                        let segment = segment_of[point as usize];
                        segment_color(segment, label_of(segment))
                    },
                );
            }
            let polyline = |canvas: &mut ColorImage, points: &[Pos2], closed, width, color| {
                draw_polyline(
                    canvas,
                    &transform,
                    pixels_per_point,
                    points,
                    closed,
                    width,
                    color,
                );
            };
            if overlays.boundaries {
                for (segment, state) in segments.iter().enumerate() {
                    let (Some(state), Some(boundary)) =
                        (state, session.boundary(segment as u32, view))
                    else {
                        continue;
                    };
                    let points: Vec<Pos2> = boundary
                        .polygon
                        .iter()
                        .map(|&uv| transform.screen_from_image(uv))
                        .collect();
                    let color = segment_color(segment as i32, Some(state.label));
                    polyline(&mut canvas, &points, true, 3.5, Color32::BLACK);
                    polyline(&mut canvas, &points, true, 2.0, color);
                }
            }
            if overlays.leaf_outlines {
                for [a, b] in self.outlines(workspace) {
                    let (Some(ua), Some(ub)) = (model.project(image, a), model.project(image, b))
                    else {
                        continue;
                    };
                    polyline(
                        &mut canvas,
                        &[
                            transform.screen_from_image([ua.x, ua.y]),
                            transform.screen_from_image([ub.x, ub.y]),
                        ],
                        false,
                        1.5,
                        Color32::from_rgb(255, 240, 90),
                    );
                }
            }
            if overlays.branches {
                for handle in &handles {
                    let curve: Vec<Pos2> = handle
                        .curve
                        .iter()
                        .map(|&uv| transform.screen_from_image(uv))
                        .collect();
                    polyline(&mut canvas, &curve, false, 4.0, Color32::BLACK);
                    polyline(&mut canvas, &curve, false, 2.0, WOOD);
                }
            }
            let texture =
                ui.ctx()
                    .load_texture("photo_view", canvas, egui::TextureOptions::NEAREST);
            self.composite = Some((key, texture));
            self.last_compose_ms = Some(started.elapsed().as_secs_f32() * 1000.0);
        }
        // Only the photo's part of the panel is drawn (the rest is transparent): fewer
        // fragments for a software rasteriser.
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
        let visible = rect.expand(4.0);
        if overlays.edges
            && let Some(projections) = &projections
        {
            let segmentation = session.segmentation();
            let mut uv_of: HashMap<u32, [f32; 2]> = HashMap::with_capacity(projections.len());
            uv_of.extend(projections.iter().copied());
            let mut mesh = egui::Mesh::default();
            for edge in &segmentation.graph.edges {
                let a = segmentation.graph_points[edge.a as usize] as u32;
                let b = segmentation.graph_points[edge.b as usize] as u32;
                let (Some(ua), Some(ub)) = (uv_of.get(&a), uv_of.get(&b)) else {
                    continue;
                };
                let pa = transform.screen_from_image([ua[0] as f64, ua[1] as f64]);
                let pb = transform.screen_from_image([ub[0] as f64, ub[1] as f64]);
                if !visible.contains(pa) && !visible.contains(pb) {
                    continue;
                }
                // Kept edges bright, edges the partition cut red.
                let color = if edge.weight > 0.0 {
                    Color32::from_rgba_unmultiplied(230, 230, 230, 110)
                } else {
                    Color32::from_rgba_unmultiplied(255, 60, 60, 90)
                };
                add_segment(&mut mesh, pa, pb, 1.0, color);
            }
            painter.add(Shape::mesh(mesh));
        }
        if overlays.branches {
            draw_branch_handles(&painter, &transform, &handles, tool);
        }

        // Tools.
        let pointer_image = response
            .interact_pointer_pos()
            .or(response.hover_pos())
            .map(|p| transform.image_from_screen(p));
        let at = |pixel: [f64; 2]| PixelRef {
            image_id: image.id,
            pixel,
        };
        let primary = egui::PointerButton::Primary;
        let press_origin = ui.input(|i| i.pointer.press_origin());
        let response = response.on_hover_cursor(tool.cursor());
        match tool {
            Tool::Navigate => {}
            Tool::Split | Tool::DrawBranch => {
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
                        actions.push(Action::Apply(if tool == Tool::Split {
                            Command::SplitByStroke {
                                image_id: image.id,
                                stroke,
                                closed: ui.input(|i| i.modifiers.shift),
                            }
                        } else {
                            Command::DrawBranch {
                                stroke: BranchStroke::Image {
                                    image_id: image.id,
                                    stroke,
                                },
                                radius: None,
                            }
                        }));
                    }
                }
            }
            Tool::MoveBranch | Tool::Radius => {
                if response.drag_started_by(primary)
                    && let Some(origin) = press_origin
                {
                    self.drag = grab_handle(&handles, &transform, origin, tool);
                    if self.drag.is_none() {
                        actions.push(Action::Message(
                            if tool == Tool::MoveBranch {
                                "no control point there: drag a square handle"
                            } else {
                                "no branch end there: drag from an end's circle"
                            }
                            .into(),
                        ));
                    }
                } else if response.drag_stopped_by(primary)
                    && let (Some(drag), Some(p)) = (self.drag.take(), pointer_image)
                {
                    actions.push(Action::Apply(match drag {
                        BranchDrag::Move {
                            branch,
                            control_point,
                        } => Command::MoveBranch {
                            branch,
                            control_point,
                            to: BranchTarget::Image { at: at(p) },
                        },
                        BranchDrag::Radius {
                            branch,
                            end,
                            center,
                            px_per_metre,
                        } => Command::SetRadius {
                            branch,
                            end,
                            radius: (p[0] - center[0]).hypot(p[1] - center[1]) / px_per_metre,
                        },
                    }));
                }
            }
            _ => {
                if response.clicked()
                    && let Some(p) = pointer_image
                {
                    actions.extend(self.click(workspace, tool, at(p), view));
                }
            }
        }

        // Gestures in progress.
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
            && first.image_id == image.id
        {
            let p = transform.screen_from_image(first.pixel);
            painter.circle_stroke(p, 7.0, Stroke::new(2.5, accent));
            if let Some(hover) = response.hover_pos() {
                painter.line_segment([p, hover], Stroke::new(1.5, accent));
            }
        }
        if let (Some(drag), Some(hover)) = (self.drag, response.hover_pos()) {
            match drag {
                BranchDrag::Move { .. } => {
                    painter.rect_stroke(
                        Rect::from_center_size(hover, Vec2::splat(10.0)),
                        0.0,
                        Stroke::new(2.0, accent),
                        egui::StrokeKind::Middle,
                    );
                }
                BranchDrag::Radius { center, .. } => {
                    let c = transform.screen_from_image(center);
                    painter.circle_stroke(c, (hover - c).length(), Stroke::new(2.0, accent));
                }
            }
        }
        painter.text(
            rect.left_bottom() + vec2(10.0, -10.0),
            egui::Align2::LEFT_BOTTOM,
            format!(
                "{}  ·  {}/{}  ·  {:.0} %",
                image.name,
                view + 1,
                images.len(),
                self.zoom * 100.0
            ),
            egui::FontId::proportional(13.0),
            Color32::from_gray(220),
        );
        actions
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

/// A branch's handles projected in a view.
struct BranchHandles {
    branch: u32,
    /// Skeleton samples (image pixels).
    curve: Vec<[f64; 2]>,
    control_points: Vec<[f64; 2]>,
    /// End centres with their radius in pixels and pixels per metre.
    ends: [Option<([f64; 2], f64, f64)>; 2],
    leaf_at_tip: bool,
}

/// Image pixels per metre across the view ray at `p` (for radius circles and drags).
fn px_per_metre(
    model: &frond::scene::Reconstruction,
    image: &frond::scene::Image,
    p: &Point3<f64>,
) -> Option<f64> {
    let ray = p - image.center_world();
    let distance = ray.norm();
    let across = frond::branch::any_perpendicular(&ray.try_normalize(1e-12)?);
    let step = distance * 1e-3;
    let a = model.project(image, p)?;
    let b = model.project(image, &(p + across * step))?;
    let scale = (b - a).norm() / step;
    (scale.is_finite() && scale > 0.0).then_some(scale)
}

fn branch_handles(workspace: &Workspace, view: usize) -> Vec<BranchHandles> {
    let model = &workspace.session.scene().reconstruction;
    let image = &model.images()[view];
    let project = |p: &Point3<f64>| model.project(image, p).map(|uv| [uv.x, uv.y]);
    workspace
        .session
        .branches()
        .branches
        .iter()
        .map(|branch| {
            let skeleton = &branch.cylinder.skeleton;
            let samples = skeleton.sample_by_arc_length(48);
            let end = |p: &Point3<f64>, radius: f64| {
                let uv = project(p)?;
                let scale = px_per_metre(model, image, p)?;
                Some((uv, radius * scale, scale))
            };
            let controls = skeleton.control_points();
            BranchHandles {
                branch: branch.id,
                curve: samples.iter().filter_map(|(p, _)| project(p)).collect(),
                control_points: controls.iter().filter_map(project).collect(),
                ends: [
                    controls
                        .first()
                        .and_then(|p| end(p, branch.cylinder.radius_start)),
                    controls
                        .last()
                        .and_then(|p| end(p, branch.cylinder.radius_end)),
                ],
                leaf_at_tip: branch.leaf_at_tip,
            }
        })
        .collect()
}

/// What goes over the composite for branches: the leaf-at-tip marks, and the handles while a
/// branch tool is active (the curves are in the composite).
fn draw_branch_handles(
    painter: &egui::Painter,
    transform: &ViewTransform,
    handles: &[BranchHandles],
    tool: Tool,
) {
    // Handles (radius circles, control points, ids) only while a branch tool is active: a
    // plant with a hundred branches is otherwise cluttered, and slow on a software rasteriser.
    let show_handles = tool.is_branch_tool();
    for handle in handles {
        for (uv, radius_px, _) in handle.ends.iter().flatten().filter(|_| show_handles) {
            let c = transform.screen_from_image(*uv);
            painter.circle_stroke(
                c,
                (*radius_px as f32 * transform.zoom).max(2.0),
                Stroke::new(1.5, Color32::from_rgb(255, 200, 120)),
            );
        }
        if handle.leaf_at_tip
            && let Some((uv, _, _)) = handle.ends[1]
        {
            painter.circle_filled(
                transform.screen_from_image(uv),
                5.0,
                Color32::from_rgb(120, 220, 90),
            );
        }
        if show_handles {
            for &uv in &handle.control_points {
                let p = transform.screen_from_image(uv);
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
        if show_handles && let Some(first) = handle.curve.first() {
            painter.text(
                transform.screen_from_image(*first) + vec2(6.0, -6.0),
                egui::Align2::LEFT_BOTTOM,
                format!("{}", handle.branch),
                egui::FontId::proportional(11.0),
                Color32::from_rgb(255, 210, 150),
            );
        }
    }
}

/// The handle under a press: a control point (Move) or a branch end (Radius).
fn grab_handle(
    handles: &[BranchHandles],
    transform: &ViewTransform,
    pointer: Pos2,
    tool: Tool,
) -> Option<BranchDrag> {
    let mut best: Option<(f32, BranchDrag)> = None;
    let mut consider = |distance: f32, drag: BranchDrag| {
        if distance <= GRAB_DISTANCE && best.as_ref().is_none_or(|(d, _)| distance < *d) {
            best = Some((distance, drag));
        }
    };
    for handle in handles {
        if tool == Tool::MoveBranch {
            for (control_point, &uv) in handle.control_points.iter().enumerate() {
                consider(
                    (transform.screen_from_image(uv) - pointer).length(),
                    BranchDrag::Move {
                        branch: handle.branch,
                        control_point,
                    },
                );
            }
        } else {
            for (k, end) in handle.ends.iter().enumerate() {
                let Some((uv, radius_px, px_per_metre)) = end else {
                    continue;
                };
                let c = transform.screen_from_image(*uv);
                // On the circle or inside it.
                let from_centre = (c - pointer).length();
                let radius = *radius_px as f32 * transform.zoom;
                consider(
                    (from_centre - radius).abs().min(from_centre),
                    BranchDrag::Radius {
                        branch: handle.branch,
                        end: if k == 0 {
                            BranchEnd::Start
                        } else {
                            BranchEnd::End
                        },
                        center: *uv,
                        px_per_metre: *px_per_metre,
                    },
                );
            }
        }
    }
    best.map(|(_, drag)| drag)
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
        let projections = [
            (0u32, [10.5f32, 20.5]),
            (1, [90.0, 70.0]),
            (2, [500.0, 10.0]),
        ];
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
