//! Independent check of the camera models against OpenCV's own projection code:
//! OPENCV and FULL_OPENCV against `cv::projectPoints`, OPENCV_FISHEYE against
//! `cv::fisheye::projectPoints`.

use frond::scene::synthetic::example_camera;
use frond::scene::{Camera, CameraModelKind};
use nalgebra::Vector3;
use opencv::core::{Mat, Point2d, Point3d, Vector};

fn sample_points() -> Vec<Vector3<f64>> {
    let mut points = Vec::new();
    for i in 0..9 {
        for j in 0..7 {
            let x = -0.4 + 0.1 * i as f64;
            let y = -0.3 + 0.1 * j as f64;
            points.push(Vector3::new(x * 2.5, y * 2.5, 2.5));
        }
    }
    points
}

fn camera_matrix(camera: &Camera) -> Mat {
    let (fx, fy, cx, cy) = camera.focal_and_principal_point();
    Mat::from_slice_2d(&[[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]]).unwrap()
}

fn object_points(points: &[Vector3<f64>]) -> Vector<Point3d> {
    points.iter().map(|p| Point3d::new(p.x, p.y, p.z)).collect()
}

fn assert_close(camera: &Camera, points: &[Vector3<f64>], projected: &Vector<Point2d>) {
    assert_eq!(projected.len(), points.len());
    for (p, cv) in points.iter().zip(projected.iter()) {
        let ours = camera.project(p).unwrap();
        let d = ((ours.x - cv.x).powi(2) + (ours.y - cv.y).powi(2)).sqrt();
        assert!(d < 1e-8, "{}: ours {ours:?}, OpenCV {cv:?}", camera.model);
    }
}

#[test]
fn opencv_and_full_opencv_match_cv_project_points() {
    let points = sample_points();
    for model in [CameraModelKind::OpenCv, CameraModelKind::FullOpenCv] {
        let camera = example_camera(model, 1, 800, 600);
        let distortion: Vector<f64> = camera.params()[4..].iter().copied().collect();
        let zero: Vector<f64> = [0.0, 0.0, 0.0].into_iter().collect();
        let mut projected = Vector::<Point2d>::new();
        opencv::calib3d::project_points_def(
            &object_points(&points),
            &zero,
            &zero,
            &camera_matrix(&camera),
            &distortion,
            &mut projected,
        )
        .unwrap();
        assert_close(&camera, &points, &projected);
    }
}

#[test]
fn opencv_fisheye_matches_cv_fisheye_project_points() {
    let points = sample_points();
    let camera = example_camera(CameraModelKind::OpenCvFisheye, 1, 800, 600);
    let distortion: Vector<f64> = camera.params()[4..].iter().copied().collect();
    let zero: Vector<f64> = [0.0, 0.0, 0.0].into_iter().collect();
    let mut projected = Vector::<Point2d>::new();
    opencv::calib3d::fisheye_project_points_vec_def(
        &object_points(&points),
        &mut projected,
        &zero,
        &zero,
        &camera_matrix(&camera),
        &distortion,
    )
    .unwrap();
    assert_close(&camera, &points, &projected);
}
