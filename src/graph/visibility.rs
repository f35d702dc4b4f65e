//! Which views see an edge: a view "sees" the segment between two points only if its middle is
//! not hidden behind other points. Per view, the points are splatted into a coarse z-buffer
//! (seed 004 §5.1 asks that each edge be visible in a view; the points' tracks only say that
//! each end is).

use nalgebra::Point3;
use rayon::prelude::*;

use super::ViewData;
use super::points::PointSet;

/// A z-buffer of one view at `1/scale` of the image resolution, splatted from the points
/// themselves (not the dense stereo depth of [`crate::mvs::RectifiedDepthMap`]).
pub struct SplatDepthMap {
    width: usize,
    height: usize,
    scale: f64,
    depth: Vec<f32>,
}

impl SplatDepthMap {
    /// Depth of the nearest splat at a pixel position (COLMAP convention), if any.
    fn depth_at(&self, x: f64, y: f64) -> Option<f32> {
        let (u, v) = (x / self.scale, y / self.scale);
        if u < 0.0 || v < 0.0 {
            return None;
        }
        let (u, v) = (u as usize, v as usize);
        (u < self.width && v < self.height)
            .then(|| self.depth[v * self.width + u])
            .filter(|d| d.is_finite())
    }
}

/// Coarse depth maps of all views, from the points themselves.
pub struct SplatDepthMaps {
    maps: Vec<Option<SplatDepthMap>>,
}

impl SplatDepthMaps {
    /// Splats every point into every view that can project it, keeping the nearest depth.
    /// `cell_px` is the z-buffer cell size in image pixels (about the points' projected
    /// spacing, so the splats close up into surfaces).
    pub fn build(points: &PointSet, views: &[ViewData<'_>], cell_px: f64) -> Self {
        let maps = views
            .par_iter()
            .map(|view| {
                let scale = cell_px.max(1.0);
                let width = (view.camera.width as f64 / scale).ceil() as usize;
                let height = (view.camera.height as f64 / scale).ceil() as usize;
                let mut depth = vec![f32::INFINITY; width * height];
                for p in &points.positions {
                    let camera_point = view.camera_from_world * p;
                    if camera_point.z <= 0.0 {
                        continue;
                    }
                    let Some(uv) = view.camera.project(&camera_point.coords) else {
                        continue;
                    };
                    let (u, v) = (uv.x / scale, uv.y / scale);
                    if u < 0.0 || v < 0.0 {
                        continue;
                    }
                    let (u, v) = (u as usize, v as usize);
                    if u >= width || v >= height {
                        continue;
                    }
                    // A 3×3 splat closes the gaps between neighbouring points.
                    for dv in v.saturating_sub(1)..=(v + 1).min(height - 1) {
                        for du in u.saturating_sub(1)..=(u + 1).min(width - 1) {
                            let cell = &mut depth[dv * width + du];
                            *cell = cell.min(camera_point.z as f32);
                        }
                    }
                }
                Some(SplatDepthMap {
                    width,
                    height,
                    scale,
                    depth,
                })
            })
            .collect();
        Self { maps }
    }

    /// Whether `point` is not hidden in view `v` (its depth is within `tolerance` of the
    /// nearest splat, relative to depth).
    pub fn sees(&self, v: usize, view: &ViewData<'_>, point: &Point3<f64>, tolerance: f64) -> bool {
        let Some(Some(map)) = self.maps.get(v) else {
            return true;
        };
        let camera_point = view.camera_from_world * point;
        let Some(uv) = view.camera.project(&camera_point.coords) else {
            return false;
        };
        match map.depth_at(uv.x, uv.y) {
            Some(nearest) => camera_point.z <= nearest as f64 * (1.0 + tolerance),
            None => true,
        }
    }
}
