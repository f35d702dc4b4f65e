//! Interactive edits on a small synthetic plant: merge then split along the true boundary,
//! split then merge, undo/redo, project save/reload/replay, and a save killed mid-way.

mod common;

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use frond::edit::project::{PROJECT_FORMAT, PROJECT_VERSION, Project, ProjectInput};
use frond::edit::{Command, EditError, PixelRef, Session, open_project, save_session};
use frond::eval::{GroundTruth, LeafScores, MatchingOptions, score_leaves};
use frond::graph::pipeline::{SegmentLabel, SegmentOptions, segment_scene};
use frond::scene::Scene;
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
