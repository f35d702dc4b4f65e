//! Per-view data the image-space steps share (seed 004 §5.3–5.4): the projection of every
//! point a view sees, and the view's watershed superpixels. Both depend only on the scene and
//! the points, never on the labels, so one [`ViewCache`] serves every edit of a session and
//! every leaf boundary. Projections are cached per view and point count: a session passes two
//! point sets, the segmentation's and, in the leaf stage, the same points followed by the
//! gap fills ([`crate::leaf::gap_fill`]). Takes a scene, its point set and the current labels; returns
//! projections, superpixels and segment boundaries (computed on demand, cached, callable from
//! many threads at once).

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use nalgebra::Point2;

use super::boundary::{Boundary, BoundaryError, BoundaryOptions, Oversegmentation};
use crate::graph::points::PointSet;
use crate::scene::Scene;

/// A point projected into a view.
#[derive(Clone, Copy, Debug)]
pub struct Projected {
    /// Index into the point set.
    pub point: u32,
    /// Pixel position (COLMAP convention).
    pub uv_image: Point2<f64>,
    /// Depth along the camera's z axis.
    pub depth_camera: f64,
}

/// Projections by (view, number of points).
type ProjectionsByView = HashMap<(usize, usize), Arc<Vec<Projected>>>;

/// Cached projections and superpixels per view index (see the module docs).
#[derive(Default)]
pub struct ViewCache {
    projections: Mutex<ProjectionsByView>,
    oversegmentations: Mutex<HashMap<usize, Arc<Oversegmentation>>>,
    options: BoundaryOptions,
}

impl ViewCache {
    pub fn new(options: BoundaryOptions) -> Self {
        Self {
            options,
            ..Self::default()
        }
    }

    pub fn options(&self) -> &BoundaryOptions {
        &self.options
    }

    /// Projections of the points seen in view `view` (computed once per point set, told apart
    /// by their number, see the module docs).
    pub fn projected(&self, scene: &Scene, points: &PointSet, view: usize) -> Arc<Vec<Projected>> {
        let mut cache = self.projections.lock().unwrap_or_else(|e| e.into_inner());
        cache
            .entry((view, points.len()))
            .or_insert_with(|| {
                let model = &scene.reconstruction;
                let image = &model.images()[view];
                let camera = model.camera_of(image);
                Arc::new(
                    (0..points.len())
                        .filter(|&p| points.views[p].binary_search(&(view as u32)).is_ok())
                        .filter_map(|p| {
                            let point_camera = image.camera_from_world * points.positions[p];
                            camera.project(&point_camera.coords).map(|uv| Projected {
                                point: p as u32,
                                uv_image: uv,
                                depth_camera: point_camera.z,
                            })
                        })
                        .collect(),
                )
            })
            .clone()
    }

    /// Superpixels of a view's photo (computed once).
    pub fn oversegmentation(
        &self,
        scene: &Scene,
        view: usize,
    ) -> Result<Arc<Oversegmentation>, BoundaryError> {
        if let Some(done) = self
            .oversegmentations
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .get(&view)
        {
            return Ok(done.clone());
        }
        let image = &scene.reconstruction.images()[view];
        let mat = scene
            .load_image(image)
            .map_err(|e| BoundaryError::Image(e.to_string()))?;
        let computed = Arc::new(Oversegmentation::compute(&mat, &self.options)?);
        self.oversegmentations
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .insert(view, computed.clone());
        Ok(computed)
    }

    /// The image boundary of segment `segment` in view `view` under the labels `segment_of`
    /// (seed 004 §5.4): the segment's projected points are the foreground seeds, every other
    /// point the view sees the background.
    pub fn boundary(
        &self,
        scene: &Scene,
        points: &PointSet,
        segment_of: &[i32],
        segment: u32,
        view: usize,
    ) -> Result<Boundary, BoundaryError> {
        self.boundary_with(scene, points, segment_of, segment, view, &self.options)
    }

    /// [`Self::boundary`] under other graph-cut settings (the view's superpixels stay those
    /// of the cache's options).
    pub fn boundary_with(
        &self,
        scene: &Scene,
        points: &PointSet,
        segment_of: &[i32],
        segment: u32,
        view: usize,
        options: &BoundaryOptions,
    ) -> Result<Boundary, BoundaryError> {
        let superpixels = self.oversegmentation(scene, view)?;
        let projected = self.projected(scene, points, view);
        let (foreground, background): (Vec<&Projected>, Vec<&Projected>) = projected
            .iter()
            .partition(|p| segment_of[p.point as usize] == segment as i32);
        let uv = |v: Vec<&Projected>| v.into_iter().map(|p| p.uv_image).collect::<Vec<_>>();
        superpixels.boundary(&uv(foreground), &uv(background), options)
    }
}
