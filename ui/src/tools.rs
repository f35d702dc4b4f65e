//! The editing tools: what each does, its shortcut, its cursor and the hint shown while it is
//! active; and the input routing of the two handle-dragging tools (Move point, Radius) shared
//! by the photo and the 3D view: which handle a press grabs and which command its release
//! applies. Draws nothing. Library calls: `frond::branch::handles::{nearest_control_point,
//! nearest_end}` for the grab, `EndDisc::radius_through` for a radius.

use egui::{CursorIcon, Key};
use frond::branch::handles::{BranchHandles, HandlePick, nearest_control_point, nearest_end};
use frond::edit::{BranchEnd, BranchTarget, Command};
use nalgebra::Point2;

/// An editing tool of the image panel.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Tool {
    Navigate,
    Confirm,
    Split,
    Merge,
    MarkLeaf,
    MarkNonLeaf,
    Reset,
    GenericLeaf,
    DrawBranch,
    MoveBranch,
    Radius,
    LeafAtTip,
    DeleteBranch,
}

/// Tools grouped as the tool strip shows them.
pub const TOOL_GROUPS: [(&str, &[Tool]); 3] = [
    ("View", &[Tool::Navigate]),
    (
        "Segments",
        &[
            Tool::Confirm,
            Tool::Split,
            Tool::Merge,
            Tool::MarkLeaf,
            Tool::MarkNonLeaf,
            Tool::Reset,
            Tool::GenericLeaf,
        ],
    ),
    (
        "Branches",
        &[
            Tool::DrawBranch,
            Tool::MoveBranch,
            Tool::Radius,
            Tool::LeafAtTip,
            Tool::DeleteBranch,
        ],
    ),
];

impl Tool {
    /// Every tool, in tool-strip order.
    pub fn all() -> impl Iterator<Item = Tool> {
        TOOL_GROUPS
            .iter()
            .flat_map(|(_, tools)| tools.iter().copied())
    }

    pub fn label(self) -> &'static str {
        match self {
            Tool::Navigate => "Navigate",
            Tool::Confirm => "Confirm",
            Tool::Split => "Split",
            Tool::Merge => "Merge",
            Tool::MarkLeaf => "Mark leaf",
            Tool::MarkNonLeaf => "Mark non-leaf",
            Tool::Reset => "Reset segment",
            Tool::GenericLeaf => "Generic leaf",
            Tool::DrawBranch => "Draw branch",
            Tool::MoveBranch => "Move point",
            Tool::Radius => "Radius",
            Tool::LeafAtTip => "Leaf at tip",
            Tool::DeleteBranch => "Delete branch",
        }
    }

    pub fn icon(self) -> &'static str {
        match self {
            Tool::Navigate => "✋",
            Tool::Confirm => "✔",
            Tool::Split => "✂",
            Tool::Merge => "🔗",
            Tool::MarkLeaf => "🍃",
            Tool::MarkNonLeaf => "🚫",
            Tool::Reset => "⟲",
            Tool::GenericLeaf => "★",
            Tool::DrawBranch => "✏",
            Tool::MoveBranch => "✚",
            Tool::Radius => "◎",
            Tool::LeafAtTip => "🌿",
            Tool::DeleteBranch => "🗑",
        }
    }

    pub fn shortcut(self) -> Key {
        match self {
            Tool::Navigate => Key::H,
            Tool::Confirm => Key::C,
            Tool::Split => Key::S,
            Tool::Merge => Key::M,
            Tool::MarkLeaf => Key::L,
            Tool::MarkNonLeaf => Key::N,
            Tool::Reset => Key::X,
            Tool::GenericLeaf => Key::G,
            Tool::DrawBranch => Key::B,
            Tool::MoveBranch => Key::V,
            Tool::Radius => Key::R,
            Tool::LeafAtTip => Key::T,
            Tool::DeleteBranch => Key::D,
        }
    }

    /// What to do with the tool, shown under the image while it is active.
    pub fn hint(self) -> &'static str {
        match self {
            Tool::Navigate => "Drag to pan, scroll to zoom, F to fit the photo.",
            Tool::Confirm => "Click a leaf to accept it and compute its image boundary.",
            Tool::Split => {
                "Drag a stroke across a segment to split it along the stroke; hold Shift for a closed loop (inside vs outside)."
            }
            Tool::Merge => "Click a point of one segment, then a point of another, to merge them.",
            Tool::MarkLeaf => "Click a segment to label it a leaf.",
            Tool::MarkNonLeaf => {
                "Click a segment to label it stem, pot or other (choose the label in the side panel)."
            }
            Tool::Reset => {
                "Click a segment to return its points to their automatic segments and labels."
            }
            Tool::GenericLeaf => {
                "Click a well-seen, flat, whole leaf: it becomes the generic leaf every leaf is fitted from."
            }
            Tool::DrawBranch => {
                "Drag from a point on a branch along a stem or petiole, in a photo or the 3D view; the points under the stroke give it depth."
            }
            Tool::MoveBranch => {
                "Drag a control point of a branch (squares in a photo), in a photo or the 3D view; children follow."
            }
            Tool::Radius => {
                "Drag out from a branch end (its circle in a photo, its sphere in the 3D view) to set its radius."
            }
            Tool::LeafAtTip => {
                "Click a branch, in a photo or the 3D view, to add or remove a leaf at its tip."
            }
            Tool::DeleteBranch => {
                "Click a branch, in a photo or the 3D view, to delete it and everything growing from it."
            }
        }
    }

    pub fn cursor(self) -> CursorIcon {
        match self {
            Tool::Navigate => CursorIcon::Grab,
            Tool::Split | Tool::DrawBranch => CursorIcon::Crosshair,
            Tool::MoveBranch => CursorIcon::Move,
            Tool::Radius => CursorIcon::ResizeHorizontal,
            Tool::DeleteBranch => CursorIcon::NotAllowed,
            _ => CursorIcon::PointingHand,
        }
    }

    /// Whether the tool acts on branches (works in photos and the 3D view; branch handles
    /// show while it is active).
    pub fn is_branch_tool(self) -> bool {
        matches!(
            self,
            Tool::DrawBranch
                | Tool::MoveBranch
                | Tool::Radius
                | Tool::LeafAtTip
                | Tool::DeleteBranch
        )
    }

    /// Whether the tool acts on segments (shown when the points overlay is on).
    pub fn is_segment_tool(self) -> bool {
        matches!(
            self,
            Tool::Confirm
                | Tool::Split
                | Tool::Merge
                | Tool::MarkLeaf
                | Tool::MarkNonLeaf
                | Tool::Reset
                | Tool::GenericLeaf
        )
    }
}

/// The handle a press of `tool` grabs at `pixel_px` within `tolerance_px` (pixels of the view
/// the handles were projected into): a control point for Move point, a branch end's disc for
/// Radius; nothing for the other tools.
pub fn grab_handle(
    tool: Tool,
    handles: &[BranchHandles],
    pixel_px: [f64; 2],
    tolerance_px: f64,
) -> Option<HandlePick> {
    let pixel_px = Point2::from(pixel_px);
    match tool {
        Tool::MoveBranch => nearest_control_point(handles, &pixel_px, tolerance_px),
        Tool::Radius => nearest_end(handles, &pixel_px, tolerance_px),
        _ => None,
    }
}

/// The command that releasing a grabbed handle at `pixel_px` applies: a control point moves to
/// `to` (the same release, as the view's command names it); an end's radius becomes that of the
/// disc through the release.
pub fn release_handle(grabbed: HandlePick, pixel_px: [f64; 2], to: BranchTarget) -> Command {
    match grabbed {
        HandlePick::ControlPoint {
            branch,
            control_point,
        } => Command::MoveBranch {
            branch,
            control_point,
            to,
        },
        HandlePick::End { branch, end, disc } => Command::SetRadius {
            branch,
            end: if end == 0 {
                BranchEnd::Start
            } else {
                BranchEnd::End
            },
            radius: disc.radius_through(&Point2::from(pixel_px)),
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_tool_has_its_own_shortcut_and_label() {
        let tools: Vec<Tool> = Tool::all().collect();
        assert_eq!(tools.len(), 13);
        let mut keys: Vec<Key> = tools.iter().map(|t| t.shortcut()).collect();
        keys.sort_by_key(|k| k.name());
        keys.dedup();
        assert_eq!(keys.len(), tools.len());
        let mut labels: Vec<&str> = tools.iter().map(|t| t.label()).collect();
        labels.sort();
        labels.dedup();
        assert_eq!(labels.len(), tools.len());
    }
}
