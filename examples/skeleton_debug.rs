//! Prints the automatic skeleton of a COLMAP folder: per branch, parent, length, radii and
//! the sizes of its level-set nodes (a tuning aid).
use frond::branch::plant::{TubeTest, skeleton_points};
use frond::branch::skeleton::{SkeletonOptions, automatic_skeleton};
use frond::edit::Session;
use frond::scene::Scene;
use frond::segment::{SegmentOptions, segment_scene};
use frond::util::progress::NoProgress;

fn main() -> anyhow::Result<()> {
    let path = std::env::args()
        .nth(1)
        .ok_or_else(|| anyhow::anyhow!("usage: FOLDER"))?;
    let scene = Scene::open(std::path::Path::new(&path))?;
    let segmentation = segment_scene(&scene, &SegmentOptions::default(), &NoProgress)?;
    let session = Session::new(scene, segmentation);
    let points = skeleton_points(
        session.segmentation(),
        session.labels(),
        &TubeTest::default(),
    );
    let foreground = &session.segmentation().foreground;
    let (tree, stats) = automatic_skeleton(
        &points,
        &foreground.up,
        &foreground.plant_center,
        &SkeletonOptions::default(),
    )?;
    println!("{stats:?}");
    for b in &tree.branches {
        println!(
            "branch {:3} parent {:?} at {:.2} length {:.3} r {:.4}/{:.4} controls {}",
            b.id,
            b.parent,
            b.parent_fraction,
            b.cylinder.length(),
            b.cylinder.radius_start,
            b.cylinder.radius_end,
            b.cylinder.skeleton.control_points().len()
        );
    }
    Ok(())
}
