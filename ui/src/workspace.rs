//! The open work: the library's editing session, where it is saved, whether it changed since,
//! and the last leaf reconstruction. Every edit goes through `Session::apply`, so the GUI holds
//! no algorithm and every edit is undoable.

use std::path::{Path, PathBuf};

use frond::edit::{Command, EditError, Session, open_project, save_session};
use frond::leaf::{LeafError, LeafOptions, LeafReconstruction, TemplatePick};
use frond::pipeline::{InputOptions, ScenePreparation, open_input};
use frond::scene::ImageFileStatus;
use frond::segment::{SegmentError, SegmentLabel, SegmentOptions, segment_scene};
use frond::util::progress::Progress;

/// The open work.
pub struct Workspace {
    pub session: Session,
    /// What was opened: a COLMAP folder or a project file (the autosave is keyed on it).
    pub input: PathBuf,
    /// The project file, once saved (or when opened from one).
    pub project_path: Option<PathBuf>,
    /// Counts edits, undos and redos.
    pub revision: u64,
    /// `revision` when last saved (`None`: never saved).
    pub saved_revision: Option<u64>,
    /// `revision` when last autosaved.
    pub autosaved_revision: u64,
    /// The last leaf reconstruction and the revision it was made at.
    pub leaves: Option<(u64, LeafReconstruction)>,
    /// The user's generic leaf (seed 004 §6.1), used by the next fit.
    pub generic_leaf: Option<TemplatePick>,
    /// Each registered image's file status, checked when opened.
    pub image_status: Vec<ImageFileStatus>,
    /// How the input became the scene (photos through SfM and stereo, a sparse COLMAP folder
    /// densified); `None` for projects.
    pub preparation: Option<ScenePreparation>,
}

/// Why opening failed (the message names the file).
#[derive(Debug, thiserror::Error)]
pub enum OpenError {
    #[error("{0}")]
    Scene(#[from] frond::scene::SceneError),
    #[error("{0}")]
    Segment(#[from] SegmentError),
    #[error("{0}")]
    Project(#[from] frond::edit::ProjectError),
    #[error("{0}")]
    Pipeline(#[from] frond::pipeline::PipelineError),
}

/// Where the GUI writes what it computes from an input folder (SfM, dense points): beside it,
/// named after it with `_frond`.
pub fn work_folder(input: &Path) -> PathBuf {
    let name = input
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "input".into());
    input.with_file_name(format!("{name}_frond"))
}

impl Workspace {
    fn with_session(session: Session, input: &Path, project_path: Option<PathBuf>) -> Self {
        // Nothing to lose yet: a fresh segmentation is re-created by opening the input again.
        let saved_revision = Some(0);
        let scene = session.scene();
        let image_status = scene
            .reconstruction
            .images()
            .iter()
            .map(|image| scene.image_file_status(image))
            .collect();
        Self {
            image_status,
            session,
            input: input.to_path_buf(),
            project_path,
            revision: 0,
            saved_revision,
            autosaved_revision: 0,
            leaves: None,
            generic_leaf: None,
            preparation: None,
        }
    }

    /// Opens a project file (`*.frond`: its history is replayed), a folder of photos
    /// (structure from motion and semi-dense stereo into [`work_folder`], then segmented
    /// automatically) or a COLMAP folder (densified into the work folder first when its
    /// points are too sparse, then segmented automatically): the library's
    /// `pipeline::open_input`, as `frond reconstruct` runs it.
    pub fn open(path: &Path, progress: &dyn Progress) -> Result<Self, OpenError> {
        if path.is_file() && path.extension().is_some_and(|e| e == "frond") {
            let session = open_project(path, progress)?;
            return Ok(Self::with_session(session, path, Some(path.to_path_buf())));
        }
        progress.stage("reading the input", 0);
        let (scene, preparation) =
            open_input(path, &InputOptions::default(), &work_folder(path), progress)?;
        let segmentation = segment_scene(&scene, &SegmentOptions::default(), progress)?;
        progress.stage("automatic skeleton", 0);
        let mut workspace = Self::with_session(Session::new(scene, segmentation), path, None);
        workspace.preparation = Some(preparation);
        Ok(workspace)
    }

    /// Replaces the session by an autosave's (the project path and input stay); the result
    /// counts as unsaved.
    pub fn recover(&mut self, autosave: &Path, progress: &dyn Progress) -> Result<(), OpenError> {
        self.session = open_project(autosave, progress)?;
        self.revision += 1;
        self.autosaved_revision = self.revision;
        self.leaves = None;
        Ok(())
    }

    /// Whether there are changes since the last save.
    pub fn is_dirty(&self) -> bool {
        self.saved_revision != Some(self.revision)
    }

    /// Applies an edit.
    pub fn apply(&mut self, command: Command) -> Result<(), EditError> {
        self.session.apply(command)?;
        self.revision += 1;
        Ok(())
    }

    pub fn undo(&mut self) -> bool {
        let done = self.session.undo();
        self.revision += done as u64;
        done
    }

    pub fn redo(&mut self) -> bool {
        let done = self.session.redo();
        self.revision += done as u64;
        done
    }

    /// Undoes or redoes until `position` commands are applied.
    pub fn go_to(&mut self, position: usize) {
        loop {
            let (history, cursor) = self.session.history();
            let len = history.len();
            let moved = match cursor.cmp(&position.min(len)) {
                std::cmp::Ordering::Greater => self.undo(),
                std::cmp::Ordering::Less => self.redo(),
                std::cmp::Ordering::Equal => break,
            };
            if !moved {
                break;
            }
        }
    }

    /// Saves the project (atomically) at `path`.
    pub fn save(&mut self, path: &Path) -> Result<(), frond::edit::ProjectError> {
        save_session(&self.session, path)?;
        self.project_path = Some(path.to_path_buf());
        self.saved_revision = Some(self.revision);
        Ok(())
    }

    /// Writes the autosave when there are changes it does not hold.
    pub fn autosave(&mut self, path: &Path) -> Result<bool, frond::edit::ProjectError> {
        if self.autosaved_revision == self.revision || !self.is_dirty() {
            return Ok(false);
        }
        if let Some(folder) = path.parent() {
            std::fs::create_dir_all(folder).map_err(|e| frond::edit::ProjectError::File {
                path: folder.to_path_buf(),
                message: e.to_string(),
            })?;
        }
        save_session(&self.session, path)?;
        self.autosaved_revision = self.revision;
        Ok(true)
    }

    /// The leaf reconstruction when it matches the current edits.
    pub fn current_leaves(&self) -> Option<&LeafReconstruction> {
        self.leaves
            .as_ref()
            .filter(|(revision, _)| *revision == self.revision)
            .map(|(_, leaves)| leaves)
    }

    /// Reconstructs every leaf segment (seed 004 §6), with the user's generic leaf if chosen.
    pub fn fit_leaves(&mut self, progress: &dyn Progress) -> Result<(), LeafError> {
        let options = LeafOptions {
            template: self.generic_leaf,
            ..LeafOptions::default()
        };
        let leaves = self.session.fit_leaves(&options, progress)?;
        self.leaves = Some((self.revision, leaves));
        Ok(())
    }

    /// Exports what `frond reconstruct` writes (`plant.glb`, `plant.obj` with its materials
    /// and atlas pages, `segmentation.ply`, `segments.json`, `skeleton.json`, `report.json`)
    /// into `out` through the library's pipeline, fitting the leaves first when the last fit
    /// is older than the edits.
    pub fn export(&mut self, out: &Path, progress: &dyn Progress) -> Result<ExportSummary, String> {
        if self.current_leaves().is_none() {
            self.fit_leaves(progress).map_err(|e| e.to_string())?;
        }
        let Some(leaves) = self.current_leaves() else {
            return Err("the leaves were not reconstructed".into());
        };
        progress.stage("export", 0);
        let options = LeafOptions {
            template: self.generic_leaf,
            ..LeafOptions::default()
        };
        let report = frond::pipeline::write_plant(
            &self.session.plant_state(),
            leaves,
            &options,
            self.preparation.as_ref(),
            out,
        )
        .map_err(|e| format!("exporting to {}: {e}", out.display()))?;
        Ok(ExportSummary {
            folder: out.to_path_buf(),
            leaves: report.counts.leaves_fitted + report.counts.leaves_posed,
            branches: report.counts.branches + report.counts.petioles,
            triangles: report.counts.triangles,
        })
    }

    /// Live segments by label: (leaves, confirmed leaves, non-leaf).
    pub fn segment_counts(&self) -> (usize, usize, usize) {
        let mut counts = (0, 0, 0);
        for state in self.session.segments().iter().flatten() {
            if state.label == SegmentLabel::Leaf {
                counts.0 += 1;
                counts.1 += state.confirmed as usize;
            } else {
                counts.2 += 1;
            }
        }
        counts
    }

    /// The window title's name for the work.
    pub fn name(&self) -> String {
        let path = self.project_path.as_deref().unwrap_or(&self.input);
        path.file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| path.display().to_string())
    }
}

/// What an export wrote.
#[derive(Clone, Debug)]
pub struct ExportSummary {
    pub folder: PathBuf,
    pub leaves: usize,
    pub branches: usize,
    pub triangles: usize,
}
