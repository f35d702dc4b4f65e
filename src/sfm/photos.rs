//! Checking a folder of photos before any COLMAP step: every file is decoded whole (so files
//! that are not images, or are truncated, are found here and named, instead of crashing
//! COLMAP's matcher), exact duplicates are set aside, and the photos are grouped by size (one
//! shared camera per size). Takes the photo files; returns a [`PhotoCheck`].

use std::collections::{BTreeMap, HashMap};
use std::hash::{Hash, Hasher};
use std::path::{Path, PathBuf};

use rayon::prelude::*;
use serde::Serialize;

/// A photo left out of structure from motion, and why.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RejectedPhoto {
    pub photo: String,
    pub reason: String,
}

/// Photos of one size (they share a camera).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SizeGroup {
    pub width: u32,
    pub height: u32,
    /// File names, sorted.
    pub photos: Vec<String>,
}

/// What the check found.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct PhotoCheck {
    /// Usable photos by size, the largest group first.
    pub groups: Vec<SizeGroup>,
    pub rejected: Vec<RejectedPhoto>,
}

impl PhotoCheck {
    pub fn usable(&self) -> usize {
        self.groups.iter().map(|g| g.photos.len()).sum()
    }

    /// The rejected photos in words (one per line), for messages.
    pub fn rejected_summary(&self) -> String {
        self.rejected
            .iter()
            .map(|r| format!("  {}: {}", r.photo, r.reason))
            .collect::<Vec<_>>()
            .join("\n")
    }
}

fn name_of(path: &Path) -> String {
    path.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| path.display().to_string())
}

/// A JPEG ends with its end-of-image marker; decoders fill a cut-off file with grey instead of
/// failing, so the marker is checked (within a short tail, which some cameras append to).
fn jpeg_is_truncated(bytes: &[u8]) -> bool {
    let is_jpeg = bytes.starts_with(&[0xFF, 0xD8]);
    let tail = &bytes[bytes.len().saturating_sub(4096)..];
    is_jpeg && !tail.windows(2).any(|w| w == [0xFF, 0xD9])
}

/// A decoded photo's width, height and pixel hash, or why it is unusable.
type Inspection = Result<(u32, u32, u64), String>;

/// Decodes one photo: its size and a hash of its pixels.
fn inspect(path: &Path) -> Inspection {
    let bytes = std::fs::read(path).map_err(|e| format!("cannot be read ({e})"))?;
    if jpeg_is_truncated(&bytes) {
        return Err("is a truncated JPEG (no end-of-image marker)".into());
    }
    let image = image::ImageReader::new(std::io::Cursor::new(&bytes))
        .with_guessed_format()
        .map_err(|e| format!("cannot be read ({e})"))?
        .decode()
        .map_err(|e| format!("is not a readable image ({e})"))?;
    if image.width() < 16 || image.height() < 16 {
        return Err(format!(
            "is {}×{} pixels, too small for features",
            image.width(),
            image.height()
        ));
    }
    let mut hasher = std::collections::hash_map::DefaultHasher::new();
    image.width().hash(&mut hasher);
    image.height().hash(&mut hasher);
    image.as_bytes().hash(&mut hasher);
    Ok((image.width(), image.height(), hasher.finish()))
}

/// Checks `photos` (see the module docs). The order of `photos` decides which of two
/// duplicates is kept (the first).
pub fn check_photos(photos: &[PathBuf]) -> PhotoCheck {
    let inspected: Vec<(String, Inspection)> = photos
        .par_iter()
        .map(|path| (name_of(path), inspect(path)))
        .collect();
    let mut check = PhotoCheck::default();
    let mut seen: HashMap<u64, String> = HashMap::new();
    let mut by_size: BTreeMap<(u32, u32), Vec<String>> = BTreeMap::new();
    for (name, result) in inspected {
        match result {
            Err(reason) => check.rejected.push(RejectedPhoto {
                photo: name,
                reason,
            }),
            Ok((width, height, hash)) => {
                if let Some(first) = seen.get(&hash) {
                    check.rejected.push(RejectedPhoto {
                        photo: name,
                        reason: format!("has the same pixels as {first} (a duplicate)"),
                    });
                } else {
                    seen.insert(hash, name.clone());
                    by_size.entry((width, height)).or_default().push(name);
                }
            }
        }
    }
    check.groups = by_size
        .into_iter()
        .map(|((width, height), mut photos)| {
            photos.sort();
            SizeGroup {
                width,
                height,
                photos,
            }
        })
        .collect();
    check.groups.sort_by(|a, b| {
        b.photos
            .len()
            .cmp(&a.photos.len())
            .then(a.photos.cmp(&b.photos))
    });
    check
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write_png(path: &Path, width: u32, height: u32, shade: u8) {
        let image = image::RgbImage::from_fn(width, height, |x, y| {
            image::Rgb([shade, (x * 7 % 256) as u8, (y * 3 % 256) as u8])
        });
        image.save(path).unwrap();
    }

    #[test]
    fn bad_truncated_duplicate_and_odd_sized_photos_are_named() {
        let dir = tempfile::tempdir().unwrap();
        let p = |n: &str| dir.path().join(n);
        write_png(&p("a.png"), 64, 48, 10);
        write_png(&p("b.png"), 64, 48, 20);
        write_png(&p("c.png"), 64, 48, 10); // same pixels as a.png
        write_png(&p("d.png"), 48, 64, 30); // another size
        std::fs::write(p("e.png"), b"not an image").unwrap();
        // A JPEG cut in half.
        let jpeg = p("f.jpg");
        image::RgbImage::from_fn(64, 48, |x, _| image::Rgb([x as u8, 0, 0]))
            .save(&jpeg)
            .unwrap();
        let bytes = std::fs::read(&jpeg).unwrap();
        std::fs::write(&jpeg, &bytes[..bytes.len() / 2]).unwrap();
        // A PNG cut in half.
        write_png(&p("g.png"), 64, 48, 40);
        let bytes = std::fs::read(p("g.png")).unwrap();
        std::fs::write(p("g.png"), &bytes[..bytes.len() / 2]).unwrap();
        let files: Vec<PathBuf> = [
            "a.png", "b.png", "c.png", "d.png", "e.png", "f.jpg", "g.png",
        ]
        .iter()
        .map(|n| p(n))
        .collect();
        let check = check_photos(&files);
        assert_eq!(check.usable(), 3);
        assert_eq!(check.groups[0].photos, ["a.png", "b.png"]);
        assert_eq!((check.groups[0].width, check.groups[0].height), (64, 48));
        assert_eq!(check.groups[1].photos, ["d.png"]);
        let reasons: BTreeMap<&str, &str> = check
            .rejected
            .iter()
            .map(|r| (r.photo.as_str(), r.reason.as_str()))
            .collect();
        assert_eq!(reasons.len(), 4, "{reasons:?}");
        assert!(reasons["c.png"].contains("a.png"), "{reasons:?}");
        assert!(
            reasons["e.png"].contains("not a readable image"),
            "{reasons:?}"
        );
        assert!(reasons["f.jpg"].contains("truncated"), "{reasons:?}");
        assert!(
            reasons["g.png"].contains("not a readable image"),
            "{reasons:?}"
        );
        assert!(check.rejected_summary().contains("e.png"));
    }
}
