//! Which photos the incremental mapper builds the model from when a capture is dense.
//!
//! COLMAP's incremental mapper costs more per photo as the photos get denser: every photo of
//! one plant sees the same surface, so a denser orbit makes every track longer, and each
//! registration, triangulation and bundle adjustment works on tracks as long as the number
//! of photos that share them (measured on a 200-photo orbit: 41 global and 395 local bundle
//! adjustments, 273 s of mapping against 2 s for 25 photos). A photo that shares most of what
//! it sees with a photo already in the model adds observations, not geometry. So the mapper
//! builds the model from *keyframes* (photos that do not share at least
//! [`KeyframeOptions::min_overlap`] of their features with an earlier keyframe), the other
//! photos are then registered to it one by one (COLMAP's `image_registrator`: each is a
//! pose from its 2D–3D matches, no growing bundle adjustment), and one bundle adjustment
//! over all photos refines the lot. The keyframes of a dense orbit are about as many as a
//! sparse orbit's photos, whatever the density, so mapping stops growing faster than the
//! photos.
//!
//! Overlap of a verified pair: its inlier matches over the features of the photo with fewer
//! features (a share of what the photos see, so it does not depend on the image size or the
//! feature count). Takes the features per photo and the verified pairs with their inliers;
//! returns the keyframes (indices, ascending). Photos are visited in file-name order (the
//! capture order of a walk around the plant); every photo left out shares at least the
//! overlap with a keyframe.

/// When a photo is a keyframe.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct KeyframeOptions {
    /// A photo sharing at least this share of its features (verified inliers) with a
    /// keyframe is registered to the model instead of building it; 0 or more than 1: every
    /// photo builds the model (COLMAP's mapper as is).
    pub min_overlap: f64,
}

impl Default for KeyframeOptions {
    fn default() -> Self {
        // Measured on a synthetic 200-photo orbit (two rings at 12° and 38° elevation, 800×600,
        // 3,650 features per photo): photos 0–4° apart share 0.54 of their features, 4–8°
        // 0.46, 8–12° 0.37, 12–16° 0.28, 16–20° 0.22. At 0.4 the keyframes are about 8–10°
        // apart, half the 16° triangulation angle COLMAP asks of the pair that starts a model,
        // and a 36-photo orbit (photos 16–20° apart) keeps every photo.
        Self { min_overlap: 0.4 }
    }
}

/// Shares of features between verified pairs: `(i, j, overlap)` for `inliers` given as
/// `(i, j, inlier matches)` and `features[i]` per photo (pairs with a photo without features
/// are left out).
fn overlaps(features: &[usize], inliers: &[(usize, usize, usize)]) -> Vec<Vec<(usize, f64)>> {
    let mut adjacent = vec![Vec::new(); features.len()];
    for &(i, j, count) in inliers {
        if i == j || i >= features.len() || j >= features.len() {
            continue;
        }
        let fewer = features[i].min(features[j]);
        if fewer == 0 {
            continue;
        }
        let overlap = count as f64 / fewer as f64;
        adjacent[i].push((j, overlap));
        adjacent[j].push((i, overlap));
    }
    adjacent
}

/// The keyframes (ascending indices) of photos with `features[i]` features each and the
/// verified pairs `inliers` (`(i, j, inlier matches)`): greedily in index order, a photo is a
/// keyframe unless it shares at least `options.min_overlap` with an earlier keyframe. Every
/// photo is a keyframe when the option is off (≤ 0 or > 1).
pub fn select_keyframes(
    features: &[usize],
    inliers: &[(usize, usize, usize)],
    options: &KeyframeOptions,
) -> Vec<usize> {
    let n = features.len();
    if !(options.min_overlap > 0.0 && options.min_overlap <= 1.0) {
        return (0..n).collect();
    }
    let adjacent = overlaps(features, inliers);
    let mut keyframe = vec![false; n];
    for i in 0..n {
        let covered = adjacent[i]
            .iter()
            .any(|&(k, overlap)| keyframe[k] && overlap >= options.min_overlap);
        keyframe[i] = !covered;
    }
    (0..n).filter(|&i| keyframe[i]).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A ring of `n` photos 360/n degrees apart, each with 3,000 features, whose verified
    /// pairs (up to 20° apart) share 0.6 − 0.022 per degree of their features (0.54 at 3°,
    /// 0.38 at 10°: as measured on synthetic orbits).
    fn ring(n: usize) -> (Vec<usize>, Vec<(usize, usize, usize)>) {
        let features = vec![3000; n];
        let step = 360.0 / n as f64;
        let mut pairs = Vec::new();
        for i in 0..n {
            for s in 1..n {
                let angle = s as f64 * step;
                if angle > 20.0 {
                    break;
                }
                let j = (i + s) % n;
                let overlap = 0.6 - 0.022 * angle;
                pairs.push((i.min(j), i.max(j), (overlap * 3000.0) as usize));
            }
        }
        (features, pairs)
    }

    #[test]
    fn a_dense_ring_keeps_photos_about_ten_degrees_apart_however_dense() {
        let options = KeyframeOptions::default();
        let mut counts = Vec::new();
        for n in [100, 200, 400] {
            let (features, pairs) = ring(n);
            let keyframes = select_keyframes(&features, &pairs, &options);
            // Photos share ≥ 0.4 up to 9.1° apart: keyframes are the first photo past that.
            let step = 360.0 / n as f64;
            let spacing = (9.1 / step).ceil() as usize;
            assert!(
                keyframes.windows(2).all(|w| w[1] - w[0] == spacing),
                "{n} photos: {keyframes:?}"
            );
            let adjacent = overlaps(&features, &pairs);
            for i in (0..n).filter(|i| !keyframes.contains(i)) {
                assert!(
                    adjacent[i]
                        .iter()
                        .any(|&(k, o)| keyframes.contains(&k) && o >= options.min_overlap),
                    "{n} photos: photo {i} is not covered by a keyframe"
                );
            }
            counts.push(keyframes.len());
        }
        // 4× the photos, about as many keyframes (360° / 9–11°).
        assert!(counts.iter().all(|&c| (30..=40).contains(&c)), "{counts:?}");
    }

    #[test]
    fn a_sparse_ring_and_disabled_options_keep_every_photo() {
        // Neighbours share 0.3 (photos 15–20° apart): none is redundant.
        let features = vec![2000; 36];
        let pairs: Vec<_> = (0..36).map(|i| (i, (i + 1) % 36, 600)).collect();
        let all: Vec<usize> = (0..36).collect();
        assert_eq!(
            select_keyframes(&features, &pairs, &KeyframeOptions::default()),
            all
        );
        let (features, pairs) = ring(50);
        for off in [0.0, -1.0, 1.5, f64::NAN] {
            let options = KeyframeOptions { min_overlap: off };
            assert_eq!(
                select_keyframes(&features, &pairs, &options),
                (0..50).collect::<Vec<_>>()
            );
        }
    }

    #[test]
    fn overlap_is_a_share_of_the_smaller_photo_and_bad_pairs_are_ignored() {
        // Photo 1 has few features, all matched with photo 0: it is redundant although the
        // matches are a small share of photo 0's features. Pairs naming missing photos, a
        // photo with itself or a photo without features change nothing.
        let features = vec![4000, 500, 0, 4000];
        let pairs = vec![
            (0, 1, 450),
            (1, 1, 500),
            (0, 9, 4000),
            (0, 2, 10),
            (2, 3, 5),
        ];
        let keyframes = select_keyframes(&features, &pairs, &KeyframeOptions::default());
        assert_eq!(keyframes, vec![0, 2, 3]);
    }
}
