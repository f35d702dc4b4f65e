//! A scale from a printed checkerboard in the photos: in every photo where OpenCV finds the
//! whole board, its pose (solvePnP on the known square size) gives the camera's distance to
//! the board's centre in metres; the board's centre is triangulated in the model from those
//! photos; metres per model unit is the median ratio of the two distances over the photos.
//! Nothing depends on the order OpenCV reports the corners in, so a board seen from opposite
//! sides (numbered from the other corner) agrees with itself.

use nalgebra::{Point2, Point3, Rotation3, Vector3};
use opencv::core::{Mat, Point2d, Point3d, Size, TermCriteria, Vector};
use opencv::prelude::*;
use serde::Serialize;

use super::{Scale, TraitsError};
use crate::scene::Scene;

/// How the checkerboard scale came out.
#[derive(Clone, Debug, Serialize)]
pub struct CheckerboardReport {
    /// Photos where the whole board was found and its pose fitted.
    pub views: Vec<String>,
    pub metres_per_unit: f64,
    /// Median absolute deviation of the per-photo ratios, relative to their median.
    pub relative_spread: f64,
}

fn cv(e: opencv::Error) -> TraitsError {
    TraitsError::Scale(format!("OpenCV: {e}"))
}

/// The board's pose in one photo: the camera-frame position of its centre (metres) and the
/// photo's mean corner residual in pixels, or `None` where the board is not found whole.
fn board_in_photo(
    scene: &Scene,
    image: &crate::scene::Image,
    inner: (u32, u32),
    square_m: f64,
) -> Result<Option<(Vector3<f64>, f64)>, TraitsError> {
    let colour = scene
        .load_image(image)
        .map_err(|e| TraitsError::Scale(e.to_string()))?;
    let mut grey = Mat::default();
    opencv::imgproc::cvt_color_def(&colour, &mut grey, opencv::imgproc::COLOR_BGR2GRAY)
        .map_err(cv)?;
    let pattern = Size::new(inner.0 as i32, inner.1 as i32);
    let mut corners = Vector::<opencv::core::Point2f>::new();
    let found = opencv::calib3d::find_chessboard_corners(
        &grey,
        pattern,
        &mut corners,
        opencv::calib3d::CALIB_CB_ADAPTIVE_THRESH | opencv::calib3d::CALIB_CB_NORMALIZE_IMAGE,
    )
    .map_err(cv)?;
    if !found || corners.len() != (inner.0 * inner.1) as usize {
        return Ok(None);
    }
    let criteria = TermCriteria::new(
        opencv::core::TermCriteria_COUNT + opencv::core::TermCriteria_EPS,
        30,
        1e-3,
    )
    .map_err(cv)?;
    opencv::imgproc::corner_sub_pix(
        &grey,
        &mut corners,
        Size::new(5, 5),
        Size::new(-1, -1),
        criteria,
    )
    .map_err(cv)?;
    // Corners as normalized camera coordinates (the camera model's own undistortion), so the
    // pose needs no intrinsics: K = I, no distortion.
    let camera = scene.reconstruction.camera_of(image);
    let mut normalized = Vector::<Point2d>::new();
    for c in corners.iter() {
        // OpenCV's pixel centres are at integers, COLMAP's at +0.5.
        let uv = Point2::new(c.x as f64 + 0.5, c.y as f64 + 0.5);
        let Some(ray) = camera.unproject(&uv) else {
            return Ok(None);
        };
        normalized.push(Point2d::new(ray.x / ray.z, ray.y / ray.z));
    }
    let mut object = Vector::<Point3d>::new();
    for row in 0..inner.1 {
        for col in 0..inner.0 {
            object.push(Point3d::new(
                col as f64 * square_m,
                row as f64 * square_m,
                0.0,
            ));
        }
    }
    let identity = Mat::eye(3, 3, opencv::core::CV_64F)
        .map_err(cv)?
        .to_mat()
        .map_err(cv)?;
    let no_distortion = Mat::default();
    let mut rvec = Mat::default();
    let mut tvec = Mat::default();
    let solved = opencv::calib3d::solve_pnp(
        &object,
        &normalized,
        &identity,
        &no_distortion,
        &mut rvec,
        &mut tvec,
        false,
        opencv::calib3d::SOLVEPNP_ITERATIVE,
    )
    .map_err(cv)?;
    if !solved {
        return Ok(None);
    }
    let at = |m: &Mat, k: i32| m.at::<f64>(k).copied().map_err(cv);
    let r = Vector3::new(at(&rvec, 0)?, at(&rvec, 1)?, at(&rvec, 2)?);
    let t = Vector3::new(at(&tvec, 0)?, at(&tvec, 1)?, at(&tvec, 2)?);
    let camera_from_board = Rotation3::new(r);
    // The corner residual in pixels (normalized residual × focal length).
    let focal = {
        let centre = camera.unproject(&Point2::new(
            camera.width as f64 / 2.0,
            camera.height as f64 / 2.0,
        ));
        let side = camera.unproject(&Point2::new(
            camera.width as f64 / 2.0 + 1.0,
            camera.height as f64 / 2.0,
        ));
        match (centre, side) {
            (Some(a), Some(b)) => 1.0 / (b.x / b.z - a.x / a.z).abs().max(1e-12),
            _ => 1.0,
        }
    };
    let mut residual = 0.0;
    for (o, n) in object.iter().zip(normalized.iter()) {
        let p = camera_from_board * Vector3::new(o.x, o.y, o.z) + t;
        residual += ((p.x / p.z - n.x).powi(2) + (p.y / p.z - n.y).powi(2)).sqrt() * focal;
    }
    residual /= object.len() as f64;
    let centre_board = Vector3::new(
        0.5 * (inner.0 - 1) as f64 * square_m,
        0.5 * (inner.1 - 1) as f64 * square_m,
        0.0,
    );
    Ok(Some((camera_from_board * centre_board + t, residual)))
}

/// A checkerboard as users write it: `COLSxROWS:SQUARE_METRES`, counting inner corners
/// (e.g. `8x6:0.03` for 9×7 squares of 3 cm).
pub fn parse_checkerboard(text: &str) -> Result<((u32, u32), f64), TraitsError> {
    let parse = || -> Option<((u32, u32), f64)> {
        let (grid, square) = text.split_once(':')?;
        let (cols, rows) = grid.split_once(['x', 'X'])?;
        Some((
            (cols.trim().parse().ok()?, rows.trim().parse().ok()?),
            square.trim().parse().ok()?,
        ))
    };
    parse().ok_or_else(|| {
        TraitsError::Scale(format!(
            "`{text}`: expected COLSxROWS:SQUARE_METRES (inner corners), e.g. 8x6:0.03"
        ))
    })
}

/// Metres per model unit from a checkerboard of `inner` = (columns, rows) inner corners and
/// `square_m` metre squares seen in the scene's photos (at least two photos must show it
/// whole, with corner residuals under 2 pixels).
pub fn checkerboard_scale(
    scene: &Scene,
    inner: (u32, u32),
    square_m: f64,
) -> Result<(Scale, CheckerboardReport), TraitsError> {
    if inner.0 < 2 || inner.1 < 2 || !(square_m.is_finite() && square_m > 0.0) {
        return Err(TraitsError::Scale(format!(
            "a checkerboard needs at least 2×2 inner corners and a positive square size, not {}×{} of {square_m} m",
            inner.0, inner.1
        )));
    }
    use rayon::prelude::*;
    let images = scene.reconstruction.images();
    let found: Vec<Option<(usize, Vector3<f64>)>> = images
        .par_iter()
        .enumerate()
        .map(|(k, image)| {
            Ok(board_in_photo(scene, image, inner, square_m)?
                .filter(|(_, residual)| *residual < 2.0)
                .map(|(centre, _)| (k, centre)))
        })
        .collect::<Result<_, TraitsError>>()?;
    let found: Vec<(usize, Vector3<f64>)> = found.into_iter().flatten().collect();
    if found.len() < 2 {
        return Err(TraitsError::Scale(format!(
            "the {}×{} checkerboard was found whole in {} of {} photos; at least 2 are needed",
            inner.0,
            inner.1,
            found.len(),
            images.len()
        )));
    }
    // The board's centre in the model: the point nearest every photo's ray towards it.
    let rays: Vec<(Point3<f64>, Vector3<f64>)> = found
        .iter()
        .map(|(k, centre_camera)| {
            let image = &images[*k];
            let direction = image.camera_from_world.rotation.inverse() * centre_camera.normalize();
            (image.center_world(), direction)
        })
        .collect();
    let centre_world = crate::util::geometry::closest_point_to_lines(&rays).ok_or_else(|| {
        TraitsError::Scale(
            "the photos that show the checkerboard all look at it along one line".into(),
        )
    })?;
    let mut ratios: Vec<f64> = found
        .iter()
        .map(|(k, centre_camera)| {
            centre_camera.norm() / (images[*k].center_world() - centre_world).norm()
        })
        .filter(|r| r.is_finite() && *r > 0.0)
        .collect();
    if ratios.len() < 2 {
        return Err(TraitsError::Scale(
            "the checkerboard's centre coincides with a camera".into(),
        ));
    }
    ratios.sort_by(f64::total_cmp);
    let median = ratios[ratios.len() / 2];
    let mut deviations: Vec<f64> = ratios.iter().map(|r| (r - median).abs()).collect();
    deviations.sort_by(f64::total_cmp);
    let spread = deviations[deviations.len() / 2] / median;
    let mut scale = Scale::factor(median)?;
    scale.source = format!(
        "checkerboard of {}×{} inner corners, {square_m} m squares, in {} photos (spread {:.2} %)",
        inner.0,
        inner.1,
        found.len(),
        100.0 * spread
    );
    let report = CheckerboardReport {
        views: found.iter().map(|(k, _)| images[*k].name.clone()).collect(),
        metres_per_unit: median,
        relative_spread: spread,
    };
    Ok((scale, report))
}
