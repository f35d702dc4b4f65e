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

/// A usable photo much less sharp than the rest of its capture (motion or focus blur): kept,
/// and named when it is not registered.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BlurredPhoto {
    pub photo: String,
    /// Its sharpness over the capture's median sharpness.
    pub relative_sharpness: f64,
}

/// A photo is blurred when its sharpness is below this fraction of the capture's median.
pub const BLUR_FRACTION: f64 = 0.25;

/// What the check found.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct PhotoCheck {
    /// Usable photos by size, the largest group first.
    pub groups: Vec<SizeGroup>,
    pub rejected: Vec<RejectedPhoto>,
    /// Usable photos much less sharp than the capture's median (see [`sharpness`]).
    pub blurred: Vec<BlurredPhoto>,
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

/// A decoded photo's width, height, pixel hash and sharpness, or why it is unusable.
type Inspection = Result<(u32, u32, u64, f64), String>;

/// Sharpness of a photo: the variance of the Laplacian of its grey image, resized to 512
/// pixels on its long side first so that photos of different sizes compare (blur is judged
/// against the capture's own median, so lighting and content cancel out).
pub fn sharpness(image: &image::DynamicImage) -> f64 {
    let grey = image.to_luma8();
    let (w, h) = grey.dimensions();
    let scale = 512.0 / w.max(h) as f64;
    let (sw, sh) = (
        ((w as f64 * scale).round() as u32).max(3),
        ((h as f64 * scale).round() as u32).max(3),
    );
    let small = image::imageops::resize(&grey, sw, sh, image::imageops::FilterType::Triangle);
    let at = |x: u32, y: u32| small.get_pixel(x, y)[0] as f64;
    let mut sum = 0.0;
    let mut sum_sq = 0.0;
    let mut n = 0.0;
    for y in 1..sh - 1 {
        for x in 1..sw - 1 {
            let l = at(x - 1, y) + at(x + 1, y) + at(x, y - 1) + at(x, y + 1) - 4.0 * at(x, y);
            sum += l;
            sum_sq += l * l;
            n += 1.0;
        }
    }
    if n == 0.0 {
        return 0.0;
    }
    let mean = sum / n;
    sum_sq / n - mean * mean
}

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
    Ok((
        image.width(),
        image.height(),
        hasher.finish(),
        sharpness(&image),
    ))
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
    let mut sharpness: Vec<(String, f64)> = Vec::new();
    for (name, result) in inspected {
        match result {
            Err(reason) => check.rejected.push(RejectedPhoto {
                photo: name,
                reason,
            }),
            Ok((width, height, hash, sharp)) => {
                if let Some(first) = seen.get(&hash) {
                    check.rejected.push(RejectedPhoto {
                        photo: name,
                        reason: format!("has the same pixels as {first} (a duplicate)"),
                    });
                } else {
                    seen.insert(hash, name.clone());
                    sharpness.push((name.clone(), sharp));
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
    let mut values: Vec<f64> = sharpness.iter().map(|(_, v)| *v).collect();
    values.sort_by(f64::total_cmp);
    // Against the capture itself: at least 5 photos, so that the median means something.
    if values.len() >= 5 && values[values.len() / 2] > 0.0 {
        let median = values[values.len() / 2];
        check.blurred = sharpness
            .into_iter()
            .filter(|(_, v)| *v < BLUR_FRACTION * median)
            .map(|(photo, v)| BlurredPhoto {
                photo,
                relative_sharpness: v / median,
            })
            .collect();
        check.blurred.sort_by(|a, b| a.photo.cmp(&b.photo));
    }
    check
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A textured photo (blocks of random grey), optionally blurred.
    fn textured(seed: u64, blur: f32) -> image::DynamicImage {
        let mut rng = crate::util::rng::Rng::seed_from(seed);
        let blocks: Vec<u8> = (0..64 * 48).map(|_| rng.below(256) as u8).collect();
        let image = image::GrayImage::from_fn(640, 480, |x, y| {
            image::Luma([blocks[(y / 10 * 64 + x / 10) as usize]])
        });
        let image = if blur > 0.0 {
            image::imageops::blur(&image, blur)
        } else {
            image
        };
        image::DynamicImage::ImageLuma8(image)
    }

    #[test]
    fn a_blurred_photo_among_sharp_ones_is_named_and_kept() {
        let dir = tempfile::tempdir().unwrap();
        let mut paths = Vec::new();
        for k in 0..6u64 {
            let path = dir.path().join(format!("p{k}.png"));
            textured(k, if k == 4 { 4.0 } else { 0.0 })
                .save(&path)
                .unwrap();
            paths.push(path);
        }
        let check = check_photos(&paths);
        assert_eq!(check.usable(), 6);
        assert_eq!(check.blurred.len(), 1, "{check:?}");
        assert_eq!(check.blurred[0].photo, "p4.png");
        assert!(check.blurred[0].relative_sharpness < BLUR_FRACTION);
        // A capture blurred all alike is judged against itself: nothing stands out.
        for (k, path) in paths.iter().enumerate() {
            textured(k as u64, 4.0).save(path).unwrap();
        }
        assert!(check_photos(&paths).blurred.is_empty());
    }

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
