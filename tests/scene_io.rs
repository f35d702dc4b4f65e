//! Scene I/O: round trips through both formats, real COLMAP data, folder layouts, bad input.

mod common;

use std::path::Path;

use common::shared_data;

use frond::scene::synthetic::{SyntheticModelSpec, generate};
use frond::scene::{
    CameraModelKind, ModelFormat, Reconstruction, Scene, SceneSource, io, io_binary, io_text,
    read_model, write_model,
};
use proptest::prelude::*;

fn model_kind() -> impl Strategy<Value = CameraModelKind> {
    (0usize..CameraModelKind::ALL.len()).prop_map(|i| CameraModelKind::ALL[i])
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// write → read gives the same model, in both formats, for every camera model, with rigs.
    #[test]
    fn write_then_read_is_identity(
        camera_model in model_kind(),
        seed in 0u64..1000,
        num_points in 0usize..300,
        num_images in 1usize..9,
        shared_camera in any::<bool>(),
        rig_pairs in any::<bool>(),
    ) {
        let model = generate(&SyntheticModelSpec {
            num_points,
            num_images,
            camera_model,
            shared_camera,
            rig_pairs,
            seed,
            ..Default::default()
        });
        let dir = tempfile::tempdir().unwrap();
        for format in [ModelFormat::Binary, ModelFormat::Text] {
            let out = dir.path().join(format.to_string());
            write_model(&out, &model, format).unwrap();
            let (back, detected) = read_model(&out).unwrap();
            prop_assert_eq!(detected, format);
            prop_assert_eq!(&back, &model);
        }
    }
}

#[test]
fn binary_wins_when_both_formats_exist() {
    let model = generate(&SyntheticModelSpec::default());
    let dir = tempfile::tempdir().unwrap();
    write_model(dir.path(), &model, ModelFormat::Text).unwrap();
    let other = generate(&SyntheticModelSpec {
        seed: 99,
        ..Default::default()
    });
    write_model(dir.path(), &other, ModelFormat::Binary).unwrap();
    let (back, format) = read_model(dir.path()).unwrap();
    assert_eq!(format, ModelFormat::Binary);
    assert_eq!(back, other);
}

#[test]
fn figurine_binary_model_reads_and_reprojects_like_colmap() {
    let dir = shared_data("colmap_figurine/sparse/0");
    let (model, format) = read_model(&dir).unwrap();
    assert_eq!(format, ModelFormat::Binary);
    assert_eq!(model.cameras().len(), 23);
    assert_eq!(model.images().len(), 23);
    assert_eq!(model.points().len(), 1443);
    assert_eq!(model.num_observations(), 5931);
    assert!(
        model
            .cameras()
            .iter()
            .all(|c| c.model == CameraModelKind::SimpleRadial)
    );
    // Our projection reproduces the per-point mean reprojection error COLMAP stored.
    let mut worst: f64 = 0.0;
    for point in model.points() {
        let errors: Vec<f64> = model
            .reprojection_errors(point)
            .into_iter()
            .map(|e| e.expect("every observation projects"))
            .collect();
        let mean = errors.iter().sum::<f64>() / errors.len() as f64;
        worst = worst.max((mean - point.error).abs());
    }
    assert!(worst < 1e-6, "largest per-point difference {worst} px");
}

#[test]
fn figurine_dense_workspace_loads_images_of_the_right_size() {
    let scene = Scene::open(&shared_data("colmap_figurine/dense/0")).unwrap();
    assert_eq!(scene.reconstruction.images().len(), 23);
    assert!(
        scene
            .reconstruction
            .cameras()
            .iter()
            .all(|c| c.model == CameraModelKind::Pinhole)
    );
    let image = &scene.reconstruction.images()[0];
    assert_eq!(
        scene.image_file_status(image),
        frond::scene::ImageFileStatus::Present
    );
    let mat = scene.load_image(image).unwrap();
    use opencv::prelude::*;
    let camera = scene.reconstruction.camera_of(image);
    assert_eq!(mat.cols() as u32, camera.width);
    assert_eq!(mat.rows() as u32, camera.height);
}

#[test]
fn figurine_project_layout_picks_sparse_zero_and_reports_missing_images() {
    let source = SceneSource::locate(&shared_data("colmap_figurine")).unwrap();
    assert_eq!(source.layout, frond::scene::LayoutKind::Project);
    assert!(source.model_dir.ends_with("sparse/0"));
    assert_eq!(source.images_dir, None);
    let scene = Scene::from_source(source).unwrap();
    let image = &scene.reconstruction.images()[0];
    let err = scene.load_image(image).unwrap_err().to_string();
    assert!(err.contains("no images folder"), "{err}");
}

#[test]
fn bust_text_and_binary_agree_within_text_rounding() {
    let dir = shared_data("colmap_bust_txt_bin/sparse/0");
    let read = |name: &str| std::fs::read(dir.join(name)).unwrap();
    let cameras_bin =
        io_binary::parse_cameras(&read("cameras.bin"), Path::new("cameras.bin")).unwrap();
    let cameras_txt = io_text::parse_cameras(
        &String::from_utf8(read("cameras.txt")).unwrap(),
        Path::new("cameras.txt"),
    )
    .unwrap();
    assert_eq!(cameras_bin.len(), 1);
    assert_eq!(cameras_txt.len(), 1);
    let (b, t) = (&cameras_bin[0], &cameras_txt[0]);
    assert_eq!(
        (b.id, b.model, b.width, b.height),
        (t.id, t.model, t.width, t.height)
    );
    for (x, y) in b.params().iter().zip(t.params()) {
        assert!((x - y).abs() <= 1e-5 * x.abs().max(1e-3), "{x} vs {y}");
    }

    let points_bin =
        io_binary::parse_points(&read("points3D.bin"), Path::new("points3D.bin")).unwrap();
    let points_txt = io_text::parse_points(
        &String::from_utf8(read("points3D.txt")).unwrap(),
        Path::new("points3D.txt"),
    )
    .unwrap();
    assert_eq!(points_bin.len(), 29_925);
    assert_eq!(points_txt.len(), points_bin.len());
    let by_id: std::collections::HashMap<u64, &frond::scene::Point3D> =
        points_txt.iter().map(|p| (p.id, p)).collect();
    for b in &points_bin {
        let t = by_id[&b.id];
        assert_eq!(b.color, t.color);
        assert_eq!(b.track, t.track);
        for axis in 0..3 {
            let (x, y) = (b.position_world[axis], t.position_world[axis]);
            assert!(
                (x - y).abs() <= 1e-5 * x.abs().max(1e-2),
                "point {}: {x} vs {y}",
                b.id
            );
        }
        assert!((b.error - t.error).abs() <= 1e-5 * b.error.abs().max(1e-2));
    }
}

#[test]
fn incomplete_model_folder_is_a_clear_error() {
    let err = read_model(&shared_data("colmap_bust_txt_bin/sparse/0"))
        .unwrap_err()
        .to_string();
    assert!(err.contains("incomplete COLMAP model"), "{err}");
    assert!(err.contains("points3D.bin"), "{err}");
    let err = Scene::open(Path::new("/definitely/not/here"))
        .unwrap_err()
        .to_string();
    assert!(err.contains("does not exist"), "{err}");
}

fn write_binary(dir: &Path, model: &Reconstruction) {
    write_model(dir, model, ModelFormat::Binary).unwrap();
}

#[test]
fn tracks_naming_missing_images_or_keypoints_are_rejected() {
    let model = generate(&SyntheticModelSpec {
        num_points: 50,
        ..Default::default()
    });
    let dir = tempfile::tempdir().unwrap();
    write_binary(dir.path(), &model);
    // Drop the first image from images.bin: its keypoints vanish, tracks still name it.
    let images: Vec<_> = model.images()[1..].to_vec();
    std::fs::write(
        dir.path().join("images.bin"),
        io_binary::encode_images(&images),
    )
    .unwrap();
    let err = read_model(dir.path()).unwrap_err().to_string();
    assert!(err.contains("is not in the model"), "{err}");
    assert!(err.contains("3D point"), "{err}");
}

#[test]
fn duplicate_ids_are_rejected() {
    let model = generate(&SyntheticModelSpec {
        num_points: 10,
        ..Default::default()
    });
    let dir = tempfile::tempdir().unwrap();
    write_binary(dir.path(), &model);
    let mut cameras = model.cameras().to_vec();
    cameras.push(cameras[0].clone());
    std::fs::write(
        dir.path().join("cameras.bin"),
        io_binary::encode_cameras(&cameras),
    )
    .unwrap();
    let err = read_model(dir.path()).unwrap_err().to_string();
    assert!(err.contains("duplicate camera id 1"), "{err}");
}

#[test]
fn every_truncation_of_every_binary_file_is_an_error_not_a_panic() {
    let model = generate(&SyntheticModelSpec {
        num_points: 30,
        num_images: 3,
        unmatched_keypoints_per_image: 2,
        rig_pairs: true,
        ..Default::default()
    });
    let files = io_binary::encode_model(&model);
    for (name, bytes) in &files {
        let path = Path::new(name);
        let step = (bytes.len() / 400).max(1);
        for cut in (0..bytes.len()).step_by(step) {
            let data = &bytes[..cut];
            let result = match *name {
                "cameras.bin" => io_binary::parse_cameras(data, path).map(|_| ()),
                "images.bin" => io_binary::parse_images(data, path).map(|_| ()),
                "points3D.bin" => io_binary::parse_points(data, path).map(|_| ()),
                "rigs.bin" => io_binary::parse_rigs(data, path).map(|_| ()),
                "frames.bin" => io_binary::parse_frames(data, path).map(|_| ()),
                other => panic!("unexpected file {other}"),
            };
            let err = result
                .expect_err("truncated file must not parse")
                .to_string();
            assert!(err.starts_with(name), "{err}");
        }
    }
}

#[test]
fn garbled_text_lines_name_file_and_line() {
    let model = generate(&SyntheticModelSpec {
        num_points: 20,
        ..Default::default()
    });
    let dir = tempfile::tempdir().unwrap();
    write_model(dir.path(), &model, ModelFormat::Text).unwrap();
    let path = dir.path().join("points3D.txt");
    let mut text = std::fs::read_to_string(&path).unwrap();
    text = text.replacen(" 0.", " 0.x", 1);
    std::fs::write(&path, text).unwrap();
    let err = read_model(dir.path()).unwrap_err().to_string();
    assert!(err.contains("points3D.txt: line 4"), "{err}");
    assert!(err.contains("is not a valid number"), "{err}");
}

#[test]
fn explicit_model_and_images_layout() {
    let model_dir = shared_data("colmap_figurine/dense/0/sparse");
    let images = shared_data("colmap_figurine/dense/0/images");
    let source = SceneSource::explicit(&model_dir, Some(&images)).unwrap();
    let scene = Scene::from_source(source).unwrap();
    assert!(
        scene
            .image_path(&scene.reconstruction.images()[0])
            .unwrap()
            .is_file()
    );
    assert!(SceneSource::explicit(&shared_data("colmap_figurine"), None).is_err());
    assert!(io::detect_format(&model_dir).is_some());
}
