//! Interactive edits (seed 004 §5.2–5.4) as a library that the GUI, the CLI replay and the
//! tests all drive.
//!
//! A [`Session`] owns the scene, the automatic segmentation and its graph, the current labels
//! and the per-(segment, view) image boundaries. Every user action is a serializable
//! [`Command`]; applying one records how to undo and redo it exactly. A project file
//! ([`project`]) stores the input's location and the command history; reopening it replays
//! the history and yields the same state.
//!
//! Takes a scene and its automatic segmentation ([`Session::new`]) and commands; returns the
//! current labels, branches and boundaries as the pipeline's [`PlantState`](crate::pipeline::PlantState)
//! ([`Session::plant_state`]).

pub mod branches;
pub mod command;
pub mod project;
pub mod session;
pub mod stroke;

pub use command::{BranchEnd, BranchStroke, BranchTarget, Command, PixelRef, ViewCameraRecord};
pub use project::{Project, ProjectError, open_project, save_session};
pub use session::{EditError, SegmentState, Session};
