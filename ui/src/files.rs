//! The GUI's own files: recent files and autosaves, kept in a configuration folder
//! (`$FROND_CONFIG_DIR`, else `$XDG_CONFIG_HOME/frond`, else `~/.config/frond`).

use std::path::{Path, PathBuf};
use std::time::SystemTime;

use frond::util::atomic::write_atomic;

/// How many recent files are remembered.
pub const RECENT_LIMIT: usize = 10;

/// Where the GUI keeps its files.
#[derive(Clone, Debug)]
pub struct ConfigDir {
    pub dir: PathBuf,
}

impl ConfigDir {
    /// The user's configuration folder (see the module docs); `None` without a home.
    pub fn from_env() -> Option<Self> {
        let from = |var: &str| std::env::var_os(var).filter(|v| !v.is_empty());
        let dir = from("FROND_CONFIG_DIR")
            .map(PathBuf::from)
            .or_else(|| from("XDG_CONFIG_HOME").map(|d| PathBuf::from(d).join("frond")))
            .or_else(|| from("HOME").map(|h| PathBuf::from(h).join(".config/frond")))?;
        Some(Self { dir })
    }

    fn recent_file(&self) -> PathBuf {
        self.dir.join("recent.json")
    }

    /// Recent files, most recent first (missing or unreadable list: empty).
    pub fn recent(&self) -> Vec<PathBuf> {
        std::fs::read_to_string(self.recent_file())
            .ok()
            .and_then(|text| serde_json::from_str::<Vec<PathBuf>>(&text).ok())
            .unwrap_or_default()
    }

    /// Puts `path` first in the recent list.
    pub fn push_recent(&self, path: &Path) -> std::io::Result<Vec<PathBuf>> {
        let path = path.canonicalize().unwrap_or_else(|_| path.to_path_buf());
        let mut recent = self.recent();
        recent.retain(|p| *p != path);
        recent.insert(0, path);
        recent.truncate(RECENT_LIMIT);
        std::fs::create_dir_all(&self.dir)?;
        let text = serde_json::to_string_pretty(&recent).map_err(std::io::Error::other)?;
        write_atomic(&self.recent_file(), text.as_bytes())?;
        Ok(recent)
    }

    /// The autosave file of the work opened from `input` (a COLMAP folder or a project file):
    /// one per input, named after it and a stable hash of its absolute path.
    pub fn autosave_path(&self, input: &Path) -> PathBuf {
        let absolute = input.canonicalize().unwrap_or_else(|_| input.to_path_buf());
        let name: String = absolute
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default()
            .chars()
            .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
            .take(40)
            .collect();
        let hash = fnv1a(absolute.to_string_lossy().as_bytes());
        self.dir
            .join("autosave")
            .join(format!("{name}-{hash:016x}.frond"))
    }
}

/// FNV-1a, 64 bits: stable across builds (unlike `DefaultHasher`).
fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |hash, &b| {
        (hash ^ b as u64).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

/// The autosave of `input` when it holds work the saved project does not: it exists and is
/// newer than the project file (or there is no project file).
pub fn recoverable_autosave(
    config: &ConfigDir,
    input: &Path,
    project: Option<&Path>,
) -> Option<PathBuf> {
    let autosave = config.autosave_path(input);
    let modified = |p: &Path| -> Option<SystemTime> { std::fs::metadata(p).ok()?.modified().ok() };
    let autosaved = modified(&autosave)?;
    match project.and_then(modified) {
        Some(saved) if saved >= autosaved => None,
        _ => Some(autosave),
    }
}

/// An entry of the open dialog's listing.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DirEntry {
    pub path: PathBuf,
    pub name: String,
    pub is_dir: bool,
}

/// The folders and project files in `dir`, folders first, each group sorted by name; hidden
/// entries left out.
pub fn list_dir(dir: &Path) -> std::io::Result<Vec<DirEntry>> {
    let mut entries: Vec<DirEntry> = std::fs::read_dir(dir)?
        .filter_map(Result::ok)
        .filter_map(|entry| {
            let name = entry.file_name().to_string_lossy().into_owned();
            if name.starts_with('.') {
                return None;
            }
            let path = entry.path();
            let is_dir = path.is_dir();
            let is_project = path.extension().is_some_and(|e| e == "frond");
            (is_dir || is_project).then_some(DirEntry { path, name, is_dir })
        })
        .collect();
    entries.sort_by(|a, b| b.is_dir.cmp(&a.is_dir).then_with(|| a.name.cmp(&b.name)));
    Ok(entries)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recent_files_are_most_recent_first_unique_and_bounded() {
        let dir = tempfile::tempdir().unwrap();
        let config = ConfigDir {
            dir: dir.path().join("config"),
        };
        assert!(config.recent().is_empty());
        let paths: Vec<PathBuf> = (0..12)
            .map(|i| {
                let p = dir.path().join(format!("p{i}"));
                std::fs::create_dir(&p).unwrap();
                p.canonicalize().unwrap()
            })
            .collect();
        for p in &paths {
            config.push_recent(p).unwrap();
        }
        config.push_recent(&paths[5]).unwrap();
        let recent = config.recent();
        assert_eq!(recent.len(), RECENT_LIMIT);
        assert_eq!(recent[0], paths[5]);
        assert_eq!(recent[1], paths[11]);
        assert_eq!(recent.iter().filter(|p| **p == paths[5]).count(), 1);
    }

    #[test]
    fn autosaves_are_per_input_and_only_offered_when_newer_than_the_project() {
        let dir = tempfile::tempdir().unwrap();
        let config = ConfigDir {
            dir: dir.path().join("config"),
        };
        let a = dir.path().join("plant a");
        let b = dir.path().join("plant_a");
        std::fs::create_dir(&a).unwrap();
        std::fs::create_dir(&b).unwrap();
        assert_ne!(config.autosave_path(&a), config.autosave_path(&b));
        assert_eq!(config.autosave_path(&a), config.autosave_path(&a));
        assert_eq!(recoverable_autosave(&config, &a, None), None);

        let autosave = config.autosave_path(&a);
        std::fs::create_dir_all(autosave.parent().unwrap()).unwrap();
        std::fs::write(&autosave, "{}").unwrap();
        assert_eq!(
            recoverable_autosave(&config, &a, None),
            Some(autosave.clone())
        );
        // A project saved after the autosave holds everything.
        std::thread::sleep(std::time::Duration::from_millis(20));
        let project = dir.path().join("p.frond");
        std::fs::write(&project, "{}").unwrap();
        assert_eq!(recoverable_autosave(&config, &a, Some(&project)), None);
    }

    #[test]
    fn listing_shows_folders_then_projects() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir(dir.path().join("b_folder")).unwrap();
        std::fs::create_dir(dir.path().join(".hidden")).unwrap();
        std::fs::write(dir.path().join("a.frond"), "").unwrap();
        std::fs::write(dir.path().join("notes.txt"), "").unwrap();
        let names: Vec<String> = list_dir(dir.path())
            .unwrap()
            .into_iter()
            .map(|e| e.name)
            .collect();
        assert_eq!(names, ["b_folder", "a.frond"]);
    }
}
