//! Interactive edits on a small synthetic plant: merge then split along the true boundary,
//! split then merge, undo/redo, project save/reload/replay, and a save killed mid-way.

mod common;

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use frond::edit::project::{PROJECT_FORMAT, PROJECT_VERSION, Project, ProjectInput};
use frond::edit::{Command, EditError, PixelRef, Session, open_project, save_session};
use frond::eval::{GroundTruth, LeafScores, MatchingOptions, score_leaves};
use frond::scene::Scene;
use frond::segment::{SegmentLabel, SegmentOptions, segment_scene};
use frond::synth::{Preset, SynthOptions};
use frond::util::progress::NoProgress;
use nalgebra::Point2;
use tempfile::TempDir;

fn dataset() -> &'static Path {
    static DIR: OnceLock<(TempDir, PathBuf)> = OnceLock::new();
    common::synth_dataset(
        &DIR,
        SynthOptions {
            preset: Preset::Broadleaf,
            seed: 43,
            views: 16,
            width: 480,
            height: 360,
            target_points: 25_000,
            ..SynthOptions::default()
        },
    )
}

fn truth() -> &'static GroundTruth {
    static TRUTH: OnceLock<GroundTruth> = OnceLock::new();
    TRUTH.get_or_init(|| GroundTruth::load(dataset()).unwrap())
}

fn session() -> Session {
    let scene = Scene::open(dataset()).unwrap();
    let segmentation = segment_scene(&scene, &SegmentOptions::default(), &NoProgress).unwrap();
    Session::new(scene, segmentation)
}

/// GT leaves recovered by a segment that is almost exactly the leaf (IoU ≥ 0.95).
fn cleanly_recovered(scores: &LeafScores) -> Vec<i64> {
    scores
        .matches
        .iter()
        .filter(|m| m.iou >= 0.95)
        .map(|m| m.gt_leaf)
        .collect()
}

fn scores(session: &Session) -> LeafScores {
    score_leaves(
        &truth().points.leaf_ids,
        &session.leaf_ids(),
        &MatchingOptions::default(),
    )
}

/// Pixel of point `p` in view `view`.
fn pixel_of(session: &Session, view: usize, p: usize) -> PixelRef {
    let model = &session.scene().reconstruction;
    let image = &model.images()[view];
    let uv = model
        .project(image, &session.segmentation().points.positions[p])
        .unwrap();
    PixelRef {
        image_id: image.id,
        pixel: [uv.x, uv.y],
    }
}

/// Points of GT leaf `leaf` seen in `view`.
fn leaf_points_in_view(session: &Session, leaf: i64, view: usize) -> Vec<usize> {
    let points = &session.segmentation().points;
    (0..points.len())
        .filter(|&p| truth().points.leaf_ids[p] == leaf)
        .filter(|&p| points.views[p].binary_search(&(view as u32)).is_ok())
        .collect()
}

/// The point of a leaf in a view nearest its projected centroid.
fn central_point(session: &Session, leaf: i64, view: usize) -> usize {
    let members = leaf_points_in_view(session, leaf, view);
    let uv: Vec<Point2<f64>> = members
        .iter()
        .map(|&p| {
            let r = pixel_of(session, view, p).pixel;
            Point2::new(r[0], r[1])
        })
        .collect();
    let centre = uv
        .iter()
        .fold(Point2::origin(), |acc, p| acc + p.coords / uv.len() as f64);
    members[(0..members.len())
        .min_by(|&a, &b| (uv[a] - centre).norm().total_cmp(&(uv[b] - centre).norm()))
        .unwrap()]
}

fn read_mask(view: usize, session: &Session) -> (u32, u32, Vec<u16>) {
    let name = &session.scene().reconstruction.images()[view].name;
    let mask = image::open(dataset().join("gt/masks").join(name))
        .unwrap()
        .to_luma16();
    (mask.width(), mask.height(), mask.into_raw())
}

/// Two recovered leaves whose image regions touch, and the view where the user would split
/// them: their border is at least 20 px long and the less visible of the two shows the most
/// points (no leaf seen edge-on); with the pixels along their shared border.
fn touching_pair(session: &Session, recovered: &[i64]) -> (i64, i64, usize, Vec<Point2<f64>>) {
    let mut best: Option<(usize, i64, i64, usize)> = None;
    for view in 0..session.scene().reconstruction.images().len() {
        let (w, h, mask) = read_mask(view, session);
        let mut counts: HashMap<(i64, i64), usize> = HashMap::new();
        for y in 0..h as usize {
            for x in 0..w as usize {
                let a = mask[y * w as usize + x] as i64 - 1;
                for (nx, ny) in [(x + 1, y), (x, y + 1)] {
                    if nx < w as usize && ny < h as usize {
                        let b = mask[ny * w as usize + nx] as i64 - 1;
                        if a >= 0
                            && b >= 0
                            && a != b
                            && recovered.contains(&a)
                            && recovered.contains(&b)
                        {
                            *counts.entry((a.min(b), a.max(b))).or_insert(0) += 1;
                        }
                    }
                }
            }
        }
        for ((a, b), n) in counts {
            if n < 20 {
                continue;
            }
            let visible = leaf_points_in_view(session, a, view)
                .len()
                .min(leaf_points_in_view(session, b, view).len());
            if best.is_none_or(|bst| visible > bst.0) {
                best = Some((visible, a, b, view));
            }
        }
    }
    let (_, a, b, view) = best.expect("two recovered leaves touch in some view");
    let (w, h, mask) = read_mask(view, session);
    let mut border = Vec::new();
    for y in 0..h as usize {
        for x in 0..w as usize {
            let here = mask[y * w as usize + x] as i64 - 1;
            for (nx, ny) in [(x + 1, y), (x, y + 1)] {
                if nx < w as usize && ny < h as usize {
                    let there = mask[ny * w as usize + nx] as i64 - 1;
                    if (here, there) == (a, b) || (here, there) == (b, a) {
                        border.push(Point2::new(x as f64 + 1.0, y as f64 + 0.5));
                    }
                }
            }
        }
    }
    (a, b, view, border)
}

/// A polyline through border pixels: ordered along their principal direction, averaged in
/// 10-pixel steps, extended by 15 px at both ends (how a user traces a boundary).
fn trace_border(pixels: &[Point2<f64>]) -> Vec<[f64; 2]> {
    let line = stroke_along(pixels);
    let (s, e) = (
        Point2::new(line[0][0], line[0][1]),
        Point2::new(line[1][0], line[1][1]),
    );
    let direction = (e - s).normalize();
    let mut bins: BTreeMap<i64, (nalgebra::Vector2<f64>, usize)> = BTreeMap::new();
    for p in pixels {
        let t = ((p - s).dot(&direction) / 10.0).floor() as i64;
        let entry = bins.entry(t).or_insert((nalgebra::Vector2::zeros(), 0));
        entry.0 += p.coords;
        entry.1 += 1;
    }
    let mut points: Vec<Point2<f64>> = bins
        .values()
        .map(|(sum, n)| Point2::from(sum / *n as f64))
        .collect();
    if points.len() < 2 {
        return line;
    }
    let first = points[0] - (points[1] - points[0]).normalize() * 15.0;
    let n = points.len();
    let last = points[n - 1] + (points[n - 1] - points[n - 2]).normalize() * 15.0;
    points.insert(0, first);
    points.push(last);
    points.iter().map(|p| [p.x, p.y]).collect()
}

/// A straight stroke along the principal direction of `pixels`, overhanging by 15 px.
fn stroke_along(pixels: &[Point2<f64>]) -> Vec<[f64; 2]> {
    let n = pixels.len() as f64;
    let centre = pixels
        .iter()
        .fold(Point2::origin(), |acc, p| acc + p.coords / n);
    let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
    for p in pixels {
        let d = p - centre;
        sxx += d.x * d.x;
        sxy += d.x * d.y;
        syy += d.y * d.y;
    }
    let angle = 0.5 * (2.0 * sxy).atan2(sxx - syy);
    let direction = nalgebra::Vector2::new(angle.cos(), angle.sin());
    let extent = pixels
        .iter()
        .map(|p| (p - centre).dot(&direction).abs())
        .fold(0.0, f64::max)
        + 15.0;
    let (a, b) = (centre - direction * extent, centre + direction * extent);
    vec![[a.x, a.y], [b.x, b.y]]
}

#[test]
fn split_along_the_true_boundary_separates_merged_leaves() {
    let mut session = session();
    let before = scores(&session);
    assert!(before.matched >= 5, "{before:?}");
    let (a, b, view, border) = touching_pair(&session, &cleanly_recovered(&before));
    // Merge the two leaves (the automatic segmentation "merged" them).
    let (pa, pb) = (
        central_point(&session, a, view),
        central_point(&session, b, view),
    );
    session
        .apply(Command::MergeByClick {
            first: pixel_of(&session, view, pa),
            second: pixel_of(&session, view, pb),
        })
        .unwrap();
    let merged = scores(&session);
    assert!(
        merged.matched < before.matched,
        "merging loses a leaf: {merged:?}"
    );
    assert_eq!(merged.under_segmented, before.under_segmented + 1);
    // A stroke along their border in that view splits them again.
    let image_id = session.scene().reconstruction.images()[view].id;
    session
        .apply(Command::SplitByStroke {
            image_id,
            stroke: trace_border(&border),
            closed: false,
        })
        .unwrap();
    let split = scores(&session);

    assert_eq!(
        split.matched, before.matched,
        "the split recovers both leaves: {split:?}"
    );
    assert!(split.recall > merged.recall);
}

#[test]
fn merge_by_click_repairs_an_over_split_leaf() {
    let mut session = session();
    let before = scores(&session);
    let largest = cleanly_recovered(&before)
        .into_iter()
        .max_by_key(|&leaf| {
            truth()
                .points
                .leaf_ids
                .iter()
                .filter(|&&l| l == leaf)
                .count()
        })
        .unwrap();
    let view = (0..session.scene().reconstruction.images().len())
        .max_by_key(|&v| leaf_points_in_view(&session, largest, v).len())
        .unwrap();
    // Cut the leaf across its width through its middle.
    let members = leaf_points_in_view(&session, largest, view);
    let uv: Vec<Point2<f64>> = members
        .iter()
        .map(|&p| {
            let r = pixel_of(&session, view, p).pixel;
            Point2::new(r[0], r[1])
        })
        .collect();
    let along = stroke_along(&uv);
    let (s, e) = (
        Point2::new(along[0][0], along[0][1]),
        Point2::new(along[1][0], along[1][1]),
    );
    let middle = nalgebra::center(&s, &e);
    let normal = nalgebra::Vector2::new(-(e - s).y, (e - s).x).normalize();
    let half_width = uv
        .iter()
        .map(|p| (p - middle).dot(&normal).abs())
        .fold(0.0, f64::max);
    let across = normal * (half_width + 10.0);
    let stroke = vec![
        [middle.x - across.x, middle.y - across.y],
        [middle.x + across.x, middle.y + across.y],
    ];
    let image_id = session.scene().reconstruction.images()[view].id;
    // The leaf's image boundary, cached; an edit that moves its points forgets it.
    let segment = session.segment_of()[members[0]] as u32;
    session.compute_boundary(segment, view).unwrap();
    assert!(session.boundary(segment, view).is_some());
    session
        .apply(Command::SplitByStroke {
            image_id,
            stroke,
            closed: false,
        })
        .unwrap();
    assert!(session.boundary(segment, view).is_none());
    let split = scores(&session);
    assert_eq!(split.over_segmented, before.over_segmented + 1, "{split:?}");
    // One click on each half merges them back.
    let direction = (e - s).normalize();
    let ends: Vec<usize> = [1.0f64, -1.0]
        .iter()
        .map(|sign| {
            (0..members.len())
                .max_by(|&a, &b| {
                    ((uv[a] - middle).dot(&direction) * sign)
                        .total_cmp(&((uv[b] - middle).dot(&direction) * sign))
                })
                .unwrap()
        })
        .collect();
    session
        .apply(Command::MergeByClick {
            first: pixel_of(&session, view, members[ends[0]]),
            second: pixel_of(&session, view, members[ends[1]]),
        })
        .unwrap();
    let repaired = scores(&session);
    assert_eq!(repaired.over_segmented, before.over_segmented);
    assert_eq!(repaired.matched, before.matched);
    // Boundaries computed after the merge are forgotten again by undoing it.
    let merged = session.segment_of()[members[0]] as u32;
    session.compute_boundary(merged, view).unwrap();
    assert!(session.undo());
    assert!(session.boundary(merged, view).is_none());
}

/// A few edits that apply to any segmentation: mark, merge, split.
fn scripted_edits(session: &Session) -> Vec<Command> {
    let (a, b, view, border) = touching_pair(session, &cleanly_recovered(&scores(session)));
    let (pa, pb) = (
        central_point(session, a, view),
        central_point(session, b, view),
    );
    let image_id = session.scene().reconstruction.images()[view].id;
    vec![
        Command::MarkNonLeaf {
            at: pixel_of(session, view, pa),
            label: SegmentLabel::Stem,
        },
        Command::MarkLeaf {
            at: pixel_of(session, view, pa),
        },
        Command::MergeByClick {
            first: pixel_of(session, view, pa),
            second: pixel_of(session, view, pb),
        },
        Command::SplitByStroke {
            image_id,
            stroke: trace_border(&border),
            closed: false,
        },
        Command::ConfirmSegment {
            at: pixel_of(session, view, pa),
        },
    ]
}

#[test]
fn undo_and_redo_restore_identical_labels() {
    let mut session = session();
    let initial = (session.segment_of().to_vec(), session.segments().to_vec());
    let mut states = vec![initial.clone()];
    for command in scripted_edits(&session) {
        session.apply(command).unwrap();
        states.push((session.segment_of().to_vec(), session.segments().to_vec()));
    }
    for expected in states.iter().rev().skip(1) {
        assert!(session.undo());
        assert_eq!(
            &(session.segment_of().to_vec(), session.segments().to_vec()),
            expected
        );
    }
    assert!(!session.undo());
    for expected in states.iter().skip(1) {
        assert!(session.redo());
        assert_eq!(
            &(session.segment_of().to_vec(), session.segments().to_vec()),
            expected
        );
    }
    assert!(!session.redo());
    // A new edit after an undo drops the redo tail.
    session.undo();
    session.apply(scripted_edits(&session)[0].clone()).unwrap();
    assert!(!session.can_redo());
}

#[test]
fn save_reload_and_replay_give_the_same_state() {
    let mut session = session();
    for command in scripted_edits(&session) {
        session.apply(command).unwrap();
    }
    session.undo();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("plant.frond");
    save_session(&session, &path).unwrap();
    let reopened = open_project(&path, &NoProgress).unwrap();
    assert_eq!(reopened.segment_of(), session.segment_of());
    assert_eq!(reopened.segments(), session.segments());
    assert_eq!(reopened.history().1, session.history().1);
    let mut reopened = reopened;
    assert!(
        reopened.redo(),
        "the undone command can be redone after reopening"
    );
    session.redo();
    assert_eq!(reopened.segment_of(), session.segment_of());

    // `frond replay` writes the same labels.
    let out = dir.path().join("out");
    let status = std::process::Command::new(env!("CARGO_BIN_EXE_frond"))
        .args(["replay"])
        .arg(&path)
        .arg("--out")
        .arg(&out)
        .status()
        .unwrap();
    assert!(status.success());
    let written = frond::eval::read_labelled_points(&out.join("segmentation.ply")).unwrap();
    let mut expected = session;
    expected.undo();
    assert_eq!(written.leaf_ids, expected.leaf_ids());
}

#[test]
fn bad_clicks_and_strokes_are_refused_without_changes() {
    let mut session = session();
    let image_id = session.scene().reconstruction.images()[0].id;
    let before = session.segment_of().to_vec();
    let err = session
        .apply(Command::MarkLeaf {
            at: PixelRef {
                image_id,
                pixel: [-500.0, -500.0],
            },
        })
        .unwrap_err();
    assert!(matches!(err, EditError::NothingUnderClick { .. }), "{err}");
    let err = session
        .apply(Command::SplitByStroke {
            image_id,
            stroke: vec![[10.0, 10.0]],
            closed: false,
        })
        .unwrap_err();
    assert!(matches!(err, EditError::InvalidStroke), "{err}");
    let err = session
        .apply(Command::MarkLeaf {
            at: PixelRef {
                image_id: 9999,
                pixel: [1.0, 1.0],
            },
        })
        .unwrap_err();
    assert!(matches!(err, EditError::UnknownImage(9999)), "{err}");
    assert_eq!(session.segment_of(), &before[..]);
    assert!(!session.can_undo());
}

fn big_project(marker: usize) -> Project {
    Project {
        format: PROJECT_FORMAT.to_owned(),
        version: PROJECT_VERSION,
        input: ProjectInput {
            model: PathBuf::from("sparse/0"),
            images: Some(PathBuf::from("images")),
        },
        segmentation: SegmentOptions::default(),
        history: (0..40_000)
            .map(|k| Command::MarkLeaf {
                at: PixelRef {
                    image_id: marker as u32,
                    pixel: [k as f64, 1.0],
                },
            })
            .collect(),
        position: 40_000,
    }
}

/// Helper process for the kill test: saves two versions of a project alternately, forever.
#[test]
#[ignore = "helper process of killed_save_leaves_the_previous_project_intact"]
fn save_loop_child() {
    let Ok(path) = std::env::var("FROND_SAVE_LOOP") else {
        return;
    };
    let versions = [big_project(1), big_project(2)];
    loop {
        for version in &versions {
            version.write(Path::new(&path)).unwrap();
        }
    }
}

#[test]
fn killed_save_leaves_the_previous_project_intact() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("project.frond");
    big_project(1).write(&path).unwrap();
    let versions: BTreeMap<u32, Project> = [(1, big_project(1)), (2, big_project(2))].into();
    for round in 0..6u64 {
        let mut child = std::process::Command::new(std::env::current_exe().unwrap())
            .args(["--ignored", "--exact", "save_loop_child", "--nocapture"])
            .env("FROND_SAVE_LOOP", &path)
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap();
        std::thread::sleep(std::time::Duration::from_millis(150 + 97 * round));
        child.kill().unwrap();
        child.wait().unwrap();
        let read = Project::read(&path).expect("the project file is whole after a kill");
        let marker = match &read.history[0] {
            Command::MarkLeaf { at } => at.image_id,
            other => panic!("unexpected {other:?}"),
        };
        assert_eq!(&read, &versions[&marker]);
    }
}

// ---- Branch edits (seed 004 §7) ----

use frond::branch::BranchTree;
use frond::edit::{BranchEnd, BranchStroke, BranchTarget, ViewCameraRecord};
use frond::eval::SkeletonRecord;
use nalgebra::Point3;

/// Mean distance from points along a branch's skeleton to a GT centreline.
fn mean_distance_to(tree: &BranchTree, id: u32, truth: &SkeletonRecord) -> f64 {
    let polyline: Vec<Point3<f64>> = truth.centerline.iter().map(|p| Point3::from(*p)).collect();
    let samples = tree
        .get(id)
        .unwrap()
        .cylinder
        .skeleton
        .sample_by_arc_length(50);
    samples
        .iter()
        .map(|(p, _)| {
            polyline
                .windows(2)
                .map(|w| frond::branch::spline::point_segment_distance(p, &w[0], &w[1]))
                .fold(f64::INFINITY, f64::min)
        })
        .sum::<f64>()
        / samples.len() as f64
}

/// The GT centreline projected into a view, and its length there in pixels.
fn projected_centerline(session: &Session, view: usize, truth: &SkeletonRecord) -> Vec<[f64; 2]> {
    let model = &session.scene().reconstruction;
    let image = &model.images()[view];
    truth
        .centerline
        .iter()
        .filter_map(|p| model.project(image, &Point3::from(*p)))
        .map(|uv| [uv.x, uv.y])
        .collect()
}

fn stroke_length(stroke: &[[f64; 2]]) -> f64 {
    stroke
        .windows(2)
        .map(|w| ((w[1][0] - w[0][0]).powi(2) + (w[1][1] - w[0][1]).powi(2)).sqrt())
        .sum()
}

/// The view a user would draw a GT branch in: not foreshortened, and where most of its
/// surface is seen (GT stem points observed in the view projecting within 4 px of its
/// centreline).
fn best_view_for(session: &Session, truth_branch: &SkeletonRecord) -> usize {
    let model = &session.scene().reconstruction;
    let points = &session.segmentation().points;
    let parts = truth().points.parts.as_ref().unwrap();
    let visible = |view: usize| {
        let stroke = projected_centerline(session, view, truth_branch);
        (0..points.len())
            .filter(|&p| parts[p] == frond::synth::Part::Stem)
            .filter(|&p| points.views[p].binary_search(&(view as u32)).is_ok())
            .filter_map(|p| model.project(&model.images()[view], &points.positions[p]))
            .filter(|uv| {
                stroke
                    .iter()
                    .any(|s| (uv - Point2::new(s[0], s[1])).norm() < 4.0)
            })
            .count()
    };
    // Among the views where it is not foreshortened (at least 70 % of its longest
    // projection), the one where it is most visible.
    let lengths: Vec<f64> = (0..model.images().len())
        .map(|v| stroke_length(&projected_centerline(session, v, truth_branch)))
        .collect();
    let longest = lengths.iter().copied().fold(0.0, f64::max);
    (0..model.images().len())
        .filter(|&v| lengths[v] >= 0.7 * longest)
        .max_by_key(|&v| (visible(v), std::cmp::Reverse(v)))
        .unwrap()
}

/// A session whose tree is empty (the automatic skeleton deleted, undoably).
fn session_without_branches() -> Session {
    let mut session = session();
    let root = session
        .branches()
        .branches
        .iter()
        .find(|b| b.parent.is_none())
        .map(|b| b.id)
        .expect("the automatic skeleton has a main stem");
    session
        .apply(Command::DeleteBranch { branch: root })
        .unwrap();
    assert!(session.branches().branches.is_empty());
    session
}

/// The GT stem and its longest petiole.
fn stem_and_petiole() -> (&'static SkeletonRecord, &'static SkeletonRecord) {
    let branches = &truth().branches;
    let stem = branches.iter().find(|b| b.parent.is_none()).unwrap();
    let petiole = branches
        .iter()
        .filter(|b| b.parent == Some(stem.id))
        .max_by(|a, b| a.centerline_length().total_cmp(&b.centerline_length()))
        .unwrap();
    (stem, petiole)
}

/// The 3D panel's camera placed at a photo (the synthetic photos are centred pinholes).
fn view_camera_of_photo(session: &Session, view: usize) -> ViewCameraRecord {
    let image = &session.scene().reconstruction.images()[view];
    let camera = session.scene().reconstruction.camera_of(image);
    let (fx, fy, cx, cy) = camera.focal_and_principal_point();
    assert_eq!(fx, fy);
    assert!((cx - 0.5 * camera.width as f64).abs() < 1e-9);
    assert!((cy - 0.5 * camera.height as f64).abs() < 1e-9);
    let view = frond::render::ViewCamera::from_colmap(camera, &image.camera_from_world, 0.01, 10.0)
        .expect("a pinhole photo");
    ViewCameraRecord::from_view(&view)
}

#[test]
fn a_petiole_drawn_in_a_photo_or_the_3d_view_follows_the_true_one() {
    let mut session = session();
    let (_, petiole) = stem_and_petiole();
    let view = best_view_for(&session, petiole);
    let image_id = session.scene().reconstruction.images()[view].id;
    let stroke = projected_centerline(&session, view, petiole);
    let before = session.branches().clone();
    session
        .apply(Command::DrawBranch {
            stroke: BranchStroke::Image {
                image_id,
                stroke: stroke.clone(),
            },
            radius: None,
        })
        .unwrap();
    let tree = session.branches().clone();
    assert_eq!(tree.branches.len(), before.branches.len() + 1);
    let drawn = tree.branches.last().unwrap();
    let parent = tree
        .get(drawn.parent.expect("it grows from a branch"))
        .unwrap();
    let start = drawn.cylinder.skeleton.control_points()[0];
    assert!(
        (parent
            .cylinder
            .skeleton
            .point_at_fraction(drawn.parent_fraction)
            - start)
            .norm()
            < 1e-9,
        "it starts on its parent"
    );
    assert!(drawn.cylinder.radius_start < parent.cylinder.radius_at(drawn.parent_fraction));
    let error = mean_distance_to(&tree, drawn.id, petiole);
    eprintln!(
        "petiole ({:.3} m) drawn in photo {view}: mean distance {error:.5} m ({:.1} % of its length)",
        petiole.centerline_length(),
        100.0 * error / petiole.centerline_length()
    );
    assert!(error < 0.05 * petiole.centerline_length(), "{error}");

    // The same stroke in the 3D panel's camera placed at that photo (its snap points are not
    // limited to those the photo sees).
    session.undo();
    session
        .apply(Command::DrawBranch {
            stroke: BranchStroke::View {
                camera: view_camera_of_photo(&session, view),
                stroke,
            },
            radius: None,
        })
        .unwrap();
    let from_view = session.branches().clone();
    let view_error = mean_distance_to(&from_view, from_view.branches.last().unwrap().id, petiole);
    eprintln!("petiole drawn in the 3D view: mean distance {view_error:.5} m");
    assert!(
        view_error < 0.05 * petiole.centerline_length(),
        "{view_error}"
    );
}

#[test]
fn a_branch_picked_in_the_3d_view_is_the_one_picked_in_the_photo() {
    let session = session();
    let tree = session.branches();
    assert!(
        !tree.branches.is_empty(),
        "the automatic skeleton has branches"
    );
    let view = best_view_for(&session, stem_and_petiole().0);
    let image = &session.scene().reconstruction.images()[view];
    let mut checked = 0;
    for branch in &tree.branches {
        let middle = branch.cylinder.skeleton.point_at_fraction(0.5);
        let Some(uv) = session.scene().reconstruction.project(image, &middle) else {
            continue;
        };
        let at = PixelRef {
            image_id: image.id,
            pixel: [uv.x, uv.y],
        };
        let (Ok(in_photo), Ok(in_view)) = (
            session.pick_branch(&at),
            session.pick_branch_in_view(&view_camera_of_photo(&session, view), at.pixel),
        ) else {
            panic!("branch {} is under its own projected midpoint", branch.id);
        };
        assert_eq!(in_photo.branch, in_view.branch);
        assert!((in_photo.fraction - in_view.fraction).abs() < 1e-9);
        checked += 1;
    }
    assert!(checked > 0);
    let far = session.pick_branch_in_view(&view_camera_of_photo(&session, 0), [-500.0, -500.0]);
    assert!(
        matches!(far, Err(EditError::NothingUnderViewClick { .. })),
        "{far:?}"
    );
}

#[test]
fn a_main_stem_drawn_on_an_empty_tree_is_the_root() {
    let mut session = session_without_branches();
    let (stem, _) = stem_and_petiole();
    let view = best_view_for(&session, stem);
    let image_id = session.scene().reconstruction.images()[view].id;
    session
        .apply(Command::DrawBranch {
            stroke: BranchStroke::Image {
                image_id,
                stroke: projected_centerline(&session, view, stem),
            },
            radius: None,
        })
        .unwrap();
    let tree = session.branches();
    assert_eq!(tree.branches.len(), 1);
    assert_eq!(tree.branches[0].parent, None);
    let error = mean_distance_to(tree, tree.branches[0].id, stem);
    let radius = 0.5 * (stem.radius_start + stem.radius_end);
    eprintln!(
        "stem ({:.3} m long, radius {radius:.4}) drawn in photo {view}: mean distance {error:.4} m = {:.2} radii",
        stem.centerline_length(),
        error / radius
    );
    assert!(
        error < radius,
        "within a radius of the true centreline: {error}"
    );
}

#[test]
fn branches_drawn_in_3d_snap_to_the_points() {
    let mut session = session_without_branches();
    let (stem, petiole) = stem_and_petiole();
    // The GT centrelines with 3 mm of noise, as a hand in a 3D view would draw them.
    let mut rng = frond::util::rng::Rng::seed_from(7);
    let mut noisy = |b: &SkeletonRecord| -> Vec<[f64; 3]> {
        b.centerline
            .iter()
            .map(|p| {
                [
                    p[0] + rng.range(-0.003, 0.003),
                    p[1] + rng.range(-0.003, 0.003),
                    p[2] + rng.range(-0.003, 0.003),
                ]
            })
            .collect()
    };
    let (stem_stroke, petiole_stroke) = (noisy(stem), noisy(petiole));
    session
        .apply(Command::DrawBranch {
            stroke: BranchStroke::World {
                points: stem_stroke,
            },
            radius: Some([0.004, 0.003]),
        })
        .unwrap();
    session
        .apply(Command::DrawBranch {
            stroke: BranchStroke::World {
                points: petiole_stroke.clone(),
            },
            radius: None,
        })
        .unwrap();
    let tree = session.branches().clone();
    assert_eq!(tree.branches.len(), 2);
    assert_eq!(tree.branches[1].parent, Some(tree.branches[0].id));
    assert_eq!(tree.branches[0].cylinder.radius_start, 0.004);
    let stroke_error = {
        let mut unsnapped = BranchTree::default();
        unsnapped.branches.push(tree.branches[1].clone());
        unsnapped.branches[0].cylinder.skeleton =
            frond::branch::Spline::new(petiole_stroke.iter().map(|p| Point3::from(*p)).collect())
                .unwrap();
        mean_distance_to(&unsnapped, unsnapped.branches[0].id, petiole)
    };
    let snapped_error = mean_distance_to(&tree, tree.branches[1].id, petiole);
    eprintln!(
        "3D stroke: {stroke_error:.5} m from the petiole, snapped branch {snapped_error:.5} m"
    );
    assert!(snapped_error < stroke_error, "snapping brings it closer");
}

#[test]
fn branch_edits_undo_redo_and_replay() {
    let mut session = session();
    let initial = session.branches().clone();
    assert!(!initial.branches.is_empty(), "automatic skeleton");
    let root = initial
        .branches
        .iter()
        .find(|b| b.parent.is_none())
        .unwrap();
    let child = initial
        .branches
        .iter()
        .find(|b| b.parent == Some(root.id))
        .expect("a branch on the stem");
    let view = 0;
    let image_id = session.scene().reconstruction.images()[view].id;
    let tip = *child.cylinder.skeleton.control_points().last().unwrap();
    let tip_pixel = session
        .scene()
        .reconstruction
        .project(&session.scene().reconstruction.images()[view], &tip)
        .unwrap();
    let middle = root.cylinder.skeleton.control_points().len() / 2;
    let commands = vec![
        Command::SetRadius {
            branch: child.id,
            end: BranchEnd::Start,
            radius: 0.0021,
        },
        Command::SetLeafAtTip {
            branch: child.id,
            enabled: true,
        },
        Command::MoveBranch {
            branch: child.id,
            control_point: child.cylinder.skeleton.control_points().len() - 1,
            to: BranchTarget::Image {
                at: PixelRef {
                    image_id,
                    pixel: [tip_pixel.x + 15.0, tip_pixel.y - 10.0],
                },
            },
        },
        Command::MoveBranch {
            branch: root.id,
            control_point: middle,
            to: BranchTarget::World {
                position: {
                    let p = root.cylinder.skeleton.control_points()[middle];
                    [p.x + 0.01, p.y, p.z]
                },
            },
        },
        Command::MoveBranch {
            branch: child.id,
            control_point: 0,
            to: BranchTarget::World {
                position: [tip.x, tip.y, tip.z],
            },
        },
        Command::DeleteBranch { branch: child.id },
        Command::AutomaticSkeleton,
    ];
    let mut trees = vec![initial.clone()];
    for command in commands.clone() {
        let description = command.describe();
        session
            .apply(command)
            .unwrap_or_else(|e| panic!("{description}: {e}"));
        trees.push(session.branches().clone());
    }
    // Each edit did what it says.
    let edited_child = |k: usize| trees[k].get(child.id).unwrap().clone();
    assert_eq!(edited_child(1).cylinder.radius_start, 0.0021);
    assert!(edited_child(2).leaf_at_tip);
    let moved_tip = *edited_child(3)
        .cylinder
        .skeleton
        .control_points()
        .last()
        .unwrap();
    let depth =
        |p: &Point3<f64>| (session.scene().reconstruction.images()[view].camera_from_world * p).z;
    assert!(
        (depth(&moved_tip) - depth(&tip)).abs() < 1e-9,
        "a drag keeps the depth"
    );
    let reprojected = session
        .scene()
        .reconstruction
        .project(&session.scene().reconstruction.images()[view], &moved_tip)
        .unwrap();
    assert!((reprojected - Point2::new(tip_pixel.x + 15.0, tip_pixel.y - 10.0)).norm() < 1e-6);
    // Moving the stem carries every child's start along.
    for tree in &trees[4..6] {
        let stem = tree.get(root.id).unwrap();
        for b in tree.branches.iter().filter(|b| b.parent == Some(root.id)) {
            let start = b.cylinder.skeleton.control_points()[0];
            assert!(stem.cylinder.skeleton.distance_to(&start) < 1e-4 * stem.cylinder.length());
            assert!(
                (stem.cylinder.skeleton.point_at_fraction(b.parent_fraction) - start).norm() < 1e-9
            );
        }
    }
    assert_ne!(
        edited_child(5).parent_fraction,
        edited_child(4).parent_fraction,
        "the start slid"
    );
    assert!(trees[6].get(child.id).is_none());
    assert_eq!(
        trees[7], initial,
        "the automatic skeleton of unchanged labels is the first one"
    );

    for expected in trees.iter().rev().skip(1) {
        assert!(session.undo());
        assert_eq!(session.branches(), expected);
    }
    for expected in trees.iter().skip(1) {
        assert!(session.redo());
        assert_eq!(session.branches(), expected);
    }
    // A project with branch edits reopens to the same tree, with the undo position.
    for _ in 0..3 {
        session.undo();
    }
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("branches.frond");
    save_session(&session, &path).unwrap();
    let mut reopened = open_project(&path, &NoProgress).unwrap();
    assert_eq!(reopened.branches(), session.branches());
    assert!(reopened.redo());
    assert!(session.redo());
    assert_eq!(reopened.branches(), session.branches());
}

#[test]
fn bad_branch_edits_are_refused_without_changes() {
    let mut session = session();
    let before = session.branches().clone();
    let image_id = session.scene().reconstruction.images()[0].id;
    let id = before.branches[0].id;
    let count = before.branches[0].cylinder.skeleton.control_points().len();
    let refused = [
        Command::DeleteBranch { branch: 999 },
        Command::SetRadius {
            branch: id,
            end: BranchEnd::End,
            radius: f64::NAN,
        },
        Command::SetRadius {
            branch: id,
            end: BranchEnd::Start,
            radius: -1.0,
        },
        Command::MoveBranch {
            branch: id,
            control_point: count,
            to: BranchTarget::World {
                position: [0.0, 0.0, 0.0],
            },
        },
        Command::MoveBranch {
            branch: id,
            control_point: 0,
            to: BranchTarget::World {
                position: [f64::INFINITY, 0.0, 0.0],
            },
        },
        // Starts far from every branch.
        Command::DrawBranch {
            stroke: BranchStroke::Image {
                image_id,
                stroke: vec![[1.0, 1.0], [40.0, 40.0]],
            },
            radius: None,
        },
        Command::DrawBranch {
            stroke: BranchStroke::World {
                points: vec![[0.0, 0.0, 0.0]],
            },
            radius: None,
        },
        Command::DrawBranch {
            stroke: BranchStroke::View {
                camera: ViewCameraRecord {
                    rotation: [0.0; 4],
                    translation: [0.0; 3],
                    focal_px: 100.0,
                    width: 10,
                    height: 10,
                },
                stroke: vec![[1.0, 1.0], [5.0, 5.0]],
            },
            radius: None,
        },
        Command::SetLeafAtTip {
            branch: 12345,
            enabled: true,
        },
    ];
    for command in refused {
        let description = command.describe();
        let error = session.apply(command).unwrap_err();
        eprintln!("{description}: {error}");
        assert!(
            matches!(error, EditError::Branch(_)),
            "{description}: {error}"
        );
    }
    assert_eq!(session.branches(), &before);
    assert!(!session.can_undo());
}
