//! The platform's file dialogs (the `rfd` crate: the XDG desktop portal, or zenity) where one is
//! available; the GUI's built-in browser stands in where none is (no session bus and no zenity,
//! as on a headless test machine) and stays in the File menu. A dialog blocks, so it runs on
//! its own thread and its answer is polled by the UI loop. Routes input only: the paths it
//! returns go to the same actions as the built-in dialogs.

use std::path::{Path, PathBuf};
use std::sync::mpsc::{Receiver, TryRecvError, channel};

/// What the user is asked for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Pick {
    /// A folder to open: photos or a COLMAP project.
    OpenFolder,
    /// A `.frond` project file to open.
    OpenProject,
    /// Where to save the project.
    SaveProject,
    /// The folder to export into.
    ExportFolder,
}

/// Whether a native dialog can be shown here: not turned off (`FROND_NATIVE_DIALOGS=0`), and
/// a desktop portal (which lives on the session bus) or zenity to show it.
pub fn available() -> bool {
    if std::env::var("FROND_NATIVE_DIALOGS").is_ok_and(|v| v == "0") {
        return false;
    }
    let bus = std::env::var_os("DBUS_SESSION_BUS_ADDRESS").is_some_and(|v| !v.is_empty());
    let zenity = std::env::var_os("PATH")
        .is_some_and(|paths| std::env::split_paths(&paths).any(|dir| dir.join("zenity").is_file()));
    bus || zenity
}

/// A native dialog being shown.
pub struct NativeDialog {
    pub pick: Pick,
    answer: Receiver<Option<PathBuf>>,
}

impl NativeDialog {
    /// Shows the dialog for `pick`, starting in `start` (a folder, or a suggested file).
    pub fn show(pick: Pick, start: &Path) -> Self {
        let (sender, answer) = channel();
        let start = start.to_path_buf();
        std::thread::spawn(move || {
            let (folder, file_name) = if start.is_dir() {
                (start.clone(), None)
            } else {
                (
                    start.parent().map(Path::to_path_buf).unwrap_or_default(),
                    start.file_name().map(|n| n.to_string_lossy().into_owned()),
                )
            };
            let dialog = rfd::FileDialog::new().set_directory(&folder);
            let chosen = match pick {
                Pick::OpenFolder => dialog
                    .set_title("Open a folder of photos or a COLMAP project")
                    .pick_folder(),
                Pick::OpenProject => dialog
                    .set_title("Open a Frond project")
                    .add_filter("Frond project", &["frond"])
                    .pick_file(),
                Pick::SaveProject => dialog
                    .set_title("Save the project as")
                    .add_filter("Frond project", &["frond"])
                    .set_file_name(file_name.unwrap_or_else(|| "plant.frond".into()))
                    .save_file(),
                Pick::ExportFolder => dialog.set_title("Export into a folder").pick_folder(),
            };
            // The UI may have gone; nothing to do then.
            let _ = sender.send(chosen);
        });
        Self { pick, answer }
    }

    /// `None` while the dialog is open; then the path chosen (`Some(None)`: cancelled, or no
    /// dialog could be shown after all).
    pub fn poll(&self) -> Option<Option<PathBuf>> {
        match self.answer.try_recv() {
            Ok(chosen) => Some(chosen),
            Err(TryRecvError::Empty) => None,
            Err(TryRecvError::Disconnected) => Some(None),
        }
    }
}
