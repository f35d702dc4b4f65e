//! Which photos the incremental mapper builds the model from when a capture is dense.
//!
//! COLMAP's incremental mapper costs more per photo as the photos get denser: every photo of
//! one plant sees the same surface, so a denser orbit makes every track longer, and each
//! registration, triangulation and bundle adjustment works on tracks as long as the number
//! of photos that share them (measured on a 200-photo orbit: 41 global and 395 local bundle
//! adjustments, 274 s of mapping against 2.5 s for 25 photos). A photo taken a few degrees
//! from a photo already in the model adds observations, not geometry. So the mapper builds
//! the model from *keyframes*: in file-name order (the capture order of a walk around the
//! plant), a photo is a keyframe unless a verified pair joins it to an earlier keyframe whose
//! camera is turned less than [`KeyframeOptions::max_angle_deg`] from its own. The other
//! photos are then registered to the model one by one (COLMAP's `image_registrator`: a pose
//! from each photo's 2D–3D matches, no growing bundle adjustment), and one bundle adjustment
//! over all photos refines the lot. The keyframes of a dense orbit are about as many as a
//! sparse orbit's photos, whatever the density, so mapping stops growing faster than the
//! photos.
//!
//! The angle is the rotation between the two cameras, from the pair's verified essential
//! matrix (or fundamental matrix and the cameras' intrinsics: [`super::database`]); photos of
//! one plant all look at it, so the rotation is the angle between the viewing directions. Only
//! a photo's strong pairs count (at least half the inliers of its strongest pair): the
//! geometry of a weak pair is unreliable (on a 36-photo orbit, pairs of 20–99 inliers between
//! photos 27–156° apart gave rotations of 2.5–7.4°). A
//! share of features in common was tried first and does not transfer: synthetic photos 6°
//! apart share 46 % of their features, the real Arabidopsis photos 6° apart 19–25 %. Takes the
//! number of photos and their verified pairs with inliers and rotations; returns the keyframes
//! (indices, ascending).

/// When a photo is a keyframe.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct KeyframeOptions {
    /// A photo whose camera is turned less than this (degrees) from a keyframe's, in a
    /// verified pair, is registered to the model instead of building it; 0 (or not a
    /// positive number): every photo builds the model (COLMAP's mapper as is).
    pub max_angle_deg: f64,
}

impl Default for KeyframeOptions {
    fn default() -> Self {
        // Half the 16° triangulation angle COLMAP asks of the pair that starts a model:
        // keyframes are 8–16° apart, and orbits of 36 photos (16–20° apart) keep every photo.
        Self { max_angle_deg: 8.0 }
    }
}

/// A pair covers a photo when it has at least this share of the inliers of the photo's
/// strongest pair.
const STRONG_PAIR_SHARE: f64 = 0.5;

/// The keyframes (ascending indices) of `photos` photos with the verified pairs `pairs`
/// (`(i, j, inliers, rotation between their cameras in degrees if known)`): greedily in index
/// order, a photo is a keyframe unless one of its strong pairs joins it to an earlier keyframe
/// turned less than `options.max_angle_deg` from it. Every photo is a keyframe when the
/// option is off.
pub fn select_keyframes(
    photos: usize,
    pairs: &[(usize, usize, usize, Option<f64>)],
    options: &KeyframeOptions,
) -> Vec<usize> {
    if !(options.max_angle_deg > 0.0 && options.max_angle_deg.is_finite()) {
        return (0..photos).collect();
    }
    let valid = |i: usize, j: usize| i != j && i < photos && j < photos;
    let mut strongest = vec![0usize; photos];
    for &(i, j, inliers, _) in pairs {
        if valid(i, j) {
            strongest[i] = strongest[i].max(inliers);
            strongest[j] = strongest[j].max(inliers);
        }
    }
    let strong = |photo: usize, inliers: usize| {
        inliers as f64 >= STRONG_PAIR_SHARE * strongest[photo] as f64
    };
    let mut near = vec![Vec::new(); photos];
    for &(i, j, inliers, rotation) in pairs {
        if !valid(i, j) || !rotation.is_some_and(|r| r < options.max_angle_deg) {
            continue;
        }
        if strong(i, inliers) {
            near[i].push(j);
        }
        if strong(j, inliers) {
            near[j].push(i);
        }
    }
    let mut keyframe = vec![false; photos];
    for i in 0..photos {
        keyframe[i] = !near[i].iter().any(|&k| keyframe[k]);
    }
    (0..photos).filter(|&i| keyframe[i]).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A ring of `n` photos 360/n degrees apart whose verified pairs reach 20°, with inliers
    /// falling with the angle (2,000 at 0°, 1,000 at 12°) and the angle between their cameras.
    fn ring(n: usize) -> Vec<(usize, usize, usize, Option<f64>)> {
        let step = 360.0 / n as f64;
        let mut pairs = Vec::new();
        for i in 0..n {
            for s in 1..n {
                let angle = s as f64 * step;
                if angle > 20.0 {
                    break;
                }
                let j = (i + s) % n;
                let inliers = (2000.0 * (1.0 - angle / 24.0)) as usize;
                pairs.push((i.min(j), i.max(j), inliers, Some(angle)));
            }
        }
        pairs
    }

    #[test]
    fn a_dense_ring_keeps_photos_about_ten_degrees_apart_however_dense() {
        let options = KeyframeOptions::default();
        let mut counts = Vec::new();
        for n in [100, 200, 400] {
            let pairs = ring(n);
            let keyframes = select_keyframes(n, &pairs, &options);
            // The first photo 8° or more past a keyframe is the next keyframe.
            let step = 360.0 / n as f64;
            let spacing = (8.0 / step - 1e-9).ceil() as usize;
            assert!(
                keyframes.windows(2).all(|w| w[1] - w[0] == spacing),
                "{n} photos: {keyframes:?}"
            );
            // Every other photo is within 8° of a keyframe.
            for i in (0..n).filter(|i| !keyframes.contains(i)) {
                assert!(
                    pairs.iter().any(|&(a, b, _, r)| (a == i || b == i)
                        && keyframes.contains(&(a + b - i))
                        && r.is_some_and(|r| r < 8.0)),
                    "{n} photos: photo {i} is not covered by a keyframe"
                );
            }
            counts.push(keyframes.len());
        }
        // 4× the photos, about as many keyframes (360° / 8–11°).
        assert!(counts.iter().all(|&c| (32..=46).contains(&c)), "{counts:?}");
    }

    #[test]
    fn a_sparse_ring_unknown_rotations_and_disabled_options_keep_every_photo() {
        let all: Vec<usize> = (0..36).collect();
        // Photos 10° apart: none is within 8° of another.
        assert_eq!(
            select_keyframes(36, &ring(36), &KeyframeOptions::default()),
            all
        );
        // Pairs without a rotation (homographies) cover nothing.
        let unknown: Vec<_> = ring(200)
            .into_iter()
            .map(|(i, j, n, _)| (i, j, n, None))
            .collect();
        assert_eq!(
            select_keyframes(200, &unknown, &KeyframeOptions::default()).len(),
            200
        );
        for off in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            let options = KeyframeOptions { max_angle_deg: off };
            assert_eq!(
                select_keyframes(50, &ring(50), &options),
                (0..50).collect::<Vec<_>>()
            );
        }
    }

    #[test]
    fn weak_pairs_and_bad_pairs_cover_nothing() {
        // Photo 1 is 3° from photo 0 by a pair a tenth as strong as its best (with photo 2,
        // 20° away): a weak pair's geometry is not trusted, so photo 1 stays a keyframe. Photo
        // 3 is 3° from photo 2 by a strong pair and is covered. A photo paired with itself or
        // with a photo that does not exist stays a keyframe.
        let pairs = vec![
            (0, 1, 100, Some(3.0)),
            (1, 2, 1000, Some(20.0)),
            (2, 3, 900, Some(3.0)),
            (4, 4, 900, Some(1.0)),
            (4, 9, 900, Some(1.0)),
        ];
        assert_eq!(
            select_keyframes(5, &pairs, &KeyframeOptions::default()),
            vec![0, 1, 2, 4]
        );
    }
}
