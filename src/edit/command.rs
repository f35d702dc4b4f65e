//! The user's actions, as data (serialised in project files).

use serde::{Deserialize, Serialize};

use super::branches::{BranchEditError, StrokeView};
use crate::render::ViewCamera;
use crate::scene::ImageId;
use crate::segment::SegmentLabel;

/// A position clicked in a view: image id and pixel (COLMAP convention).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PixelRef {
    pub image_id: ImageId,
    pub pixel: [f64; 2],
}

/// A render [`ViewCamera`] that is not one of the photos (the 3D panel's camera) as a command
/// records it: square pixels, the principal point at the image centre, no clip planes. COLMAP's
/// conventions: x right, y down, z forward; pixel centres at +0.5. The fields are the project
/// file's format.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ViewCameraRecord {
    /// Rotation of `camera_from_world` as a unit quaternion `[w, x, y, z]`.
    pub rotation: [f64; 4],
    /// Translation of `camera_from_world`.
    pub translation: [f64; 3],
    pub focal_px: f64,
    pub width: u32,
    pub height: u32,
}

impl ViewCameraRecord {
    /// The record of a render view: its pose, size and `fx` (the 3D panel's views have
    /// `fy = fx` and the principal point at the centre; the clip planes are not recorded).
    pub fn from_view(view: &ViewCamera) -> Self {
        let q = view.camera_from_world.rotation.quaternion().coords;
        let t = view.camera_from_world.translation.vector;
        Self {
            rotation: [q.w, q.x, q.y, q.z],
            translation: [t.x, t.y, t.z],
            focal_px: view.fx,
            width: view.width,
            height: view.height,
        }
    }

    /// The render view recorded, with clip planes `near` and `far`; an error when the record
    /// is not a valid pinhole (see [`StrokeView::from_view_camera`]).
    pub fn to_view(&self, near: f64, far: f64) -> Result<ViewCamera, BranchEditError> {
        let pinhole = StrokeView::from_view_camera(self)?;
        ViewCamera::from_colmap(&pinhole.camera, &pinhole.camera_from_world, near, far)
            .map_err(|e| BranchEditError::InvalidViewCamera(e.to_string()))
    }
}

/// A branch drawn by the user: where the stroke was drawn decides how it gets depth.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "in", rename_all = "snake_case")]
pub enum BranchStroke {
    /// Pixels in a photo (COLMAP convention).
    Image {
        image_id: ImageId,
        stroke: Vec<[f64; 2]>,
    },
    /// Pixels in the 3D panel's view.
    View {
        camera: ViewCameraRecord,
        stroke: Vec<[f64; 2]>,
    },
    /// Positions in the world frame (a 3D pen, a script).
    World { points: Vec<[f64; 3]> },
}

/// Where a dragged control point goes.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "in", rename_all = "snake_case")]
pub enum BranchTarget {
    /// A pixel of a photo; the control point keeps its depth in that view.
    Image { at: PixelRef },
    /// A pixel of the 3D panel's view; the control point keeps its depth in that view.
    View {
        camera: ViewCameraRecord,
        pixel: [f64; 2],
    },
    /// A position in the world frame.
    World { position: [f64; 3] },
}

/// An end of a branch.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BranchEnd {
    Start,
    End,
}

/// An edit. Clicks pick the point projecting nearest to the pixel (among points seen in that
/// view) and act on its segment.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "command", rename_all = "snake_case")]
pub enum Command {
    /// Accept the segment under the click and compute its image boundary (seed 004 §5.2).
    ConfirmSegment { at: PixelRef },
    /// Split the segment the stroke crosses: points projecting on either side are seeded,
    /// edges crossing the stroke are cut, and the segment is re-solved as a two-label graph
    /// cut (seed 004 §5.3). A closed stroke separates inside from outside.
    SplitByStroke {
        image_id: ImageId,
        stroke: Vec<[f64; 2]>,
        #[serde(default)]
        closed: bool,
    },
    /// Connect two clicked points and merge their segments.
    MergeByClick { first: PixelRef, second: PixelRef },
    /// The segment under the click is not a leaf (stem, pot or other).
    MarkNonLeaf {
        at: PixelRef,
        #[serde(default = "default_non_leaf")]
        label: SegmentLabel,
    },
    /// The segment under the click is a leaf.
    MarkLeaf { at: PixelRef },
    /// Return the segment's points to their automatic segments and labels.
    ResetSegment { at: PixelRef },
    /// Replace the branches by the automatic skeleton of the current non-leaf points.
    AutomaticSkeleton,
    /// A new branch from a point on an existing one (the first branch of an empty tree is
    /// the main stem), traced by the points under the stroke (seed 004 §7).
    DrawBranch {
        stroke: BranchStroke,
        /// Radii at the start and the end; default from the parent's radius there.
        #[serde(default)]
        radius: Option<[f64; 2]>,
    },
    /// Drag a control point of a branch. Moving a child's first control point slides its
    /// attachment along the parent; children follow their parent.
    MoveBranch {
        branch: u32,
        control_point: usize,
        to: BranchTarget,
    },
    /// Set the radius at one end of a branch (metres, in the model's units).
    SetRadius {
        branch: u32,
        end: BranchEnd,
        radius: f64,
    },
    /// Grow (or remove) a synthesized leaf at the branch's tip.
    SetLeafAtTip { branch: u32, enabled: bool },
    /// Delete a branch and everything growing from it.
    DeleteBranch { branch: u32 },
}

fn default_non_leaf() -> SegmentLabel {
    SegmentLabel::Other
}

impl Command {
    /// A short description for history lists.
    pub fn describe(&self) -> String {
        match self {
            Command::ConfirmSegment { at } => format!("confirm segment (view {})", at.image_id),
            Command::SplitByStroke {
                image_id,
                stroke,
                closed,
            } => format!(
                "split by {} stroke of {} points (view {image_id})",
                if *closed { "closed" } else { "open" },
                stroke.len()
            ),
            Command::MergeByClick { first, .. } => {
                format!("merge two segments (view {})", first.image_id)
            }
            Command::MarkNonLeaf { label, .. } => format!("mark as {label:?}").to_lowercase(),
            Command::MarkLeaf { .. } => "mark as leaf".into(),
            Command::ResetSegment { .. } => "reset segment".into(),
            Command::AutomaticSkeleton => "automatic skeleton".into(),
            Command::DrawBranch { stroke, .. } => match stroke {
                BranchStroke::Image { image_id, .. } => format!("draw branch (view {image_id})"),
                BranchStroke::View { .. } => "draw branch (3D view)".into(),
                BranchStroke::World { .. } => "draw branch (3D points)".into(),
            },
            Command::MoveBranch {
                branch,
                control_point,
                ..
            } => format!("move control point {control_point} of branch {branch}"),
            Command::SetRadius { branch, end, .. } => {
                format!("set {end:?} radius of branch {branch}").to_lowercase()
            }
            Command::SetLeafAtTip { branch, enabled } => format!(
                "{} leaf at the tip of branch {branch}",
                if *enabled { "add" } else { "remove" }
            ),
            Command::DeleteBranch { branch } => format!("delete branch {branch}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn commands_round_trip_through_json() {
        let commands = vec![
            Command::SplitByStroke {
                image_id: 3,
                stroke: vec![[1.0, 2.0], [3.5, 4.0]],
                closed: false,
            },
            Command::MarkNonLeaf {
                at: PixelRef {
                    image_id: 1,
                    pixel: [10.0, 20.0],
                },
                label: SegmentLabel::Stem,
            },
            Command::AutomaticSkeleton,
            Command::DrawBranch {
                stroke: BranchStroke::View {
                    camera: ViewCameraRecord {
                        rotation: [1.0, 0.0, 0.0, 0.0],
                        translation: [0.0, 0.0, 2.0],
                        focal_px: 500.0,
                        width: 640,
                        height: 480,
                    },
                    stroke: vec![[1.0, 2.0], [30.0, 40.0]],
                },
                radius: Some([0.01, 0.005]),
            },
            Command::MoveBranch {
                branch: 2,
                control_point: 1,
                to: BranchTarget::World {
                    position: [0.1, 0.2, 0.3],
                },
            },
            Command::SetRadius {
                branch: 0,
                end: BranchEnd::End,
                radius: 0.002,
            },
            Command::SetLeafAtTip {
                branch: 1,
                enabled: true,
            },
            Command::DeleteBranch { branch: 4 },
        ];
        let text = serde_json::to_string(&commands).unwrap();
        assert!(text.contains("\"command\":\"split_by_stroke\""), "{text}");
        let back: Vec<Command> = serde_json::from_str(&text).unwrap();
        assert_eq!(back, commands);
    }

    #[test]
    fn a_render_view_round_trips_through_its_record() {
        let camera_from_world = nalgebra::Isometry3::new(
            nalgebra::Vector3::new(0.1, -0.2, 1.5),
            nalgebra::Vector3::new(0.3, -1.1, 0.4),
        );
        let view = ViewCamera {
            width: 640,
            height: 480,
            fx: 520.0,
            fy: 520.0,
            cx: 320.0,
            cy: 240.0,
            camera_from_world,
            near: 0.01,
            far: 20.0,
        };
        let record = ViewCameraRecord::from_view(&view);
        let back = record.to_view(view.near, view.far).unwrap();
        assert_eq!((back.width, back.height), (view.width, view.height));
        assert_eq!(
            [back.fx, back.fy, back.cx, back.cy],
            [520.0, 520.0, 320.0, 240.0]
        );
        let point_world = nalgebra::Point3::new(0.05, 0.1, -0.3);
        let (uv, depth) = view.project(&point_world).unwrap();
        let (uv_back, depth_back) = back.project(&point_world).unwrap();
        assert!((uv - uv_back).norm() < 1e-9 && (depth - depth_back).abs() < 1e-12);
        // The record is what the project file holds: a second trip keeps it (up to rounding
        // in the quaternion's normalisation).
        let again = ViewCameraRecord::from_view(&back);
        assert_eq!(
            (again.translation, again.focal_px, again.width, again.height),
            (
                record.translation,
                record.focal_px,
                record.width,
                record.height
            )
        );
        for (a, b) in again.rotation.iter().zip(&record.rotation) {
            assert!((a - b).abs() < 1e-15, "{again:?} {record:?}");
        }
        let invalid = ViewCameraRecord {
            focal_px: 0.0,
            ..record
        };
        assert!(invalid.to_view(0.01, 20.0).is_err());
    }
}
