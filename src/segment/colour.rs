//! The colours of a plant's organs, measured on the plant itself: where its leaves and its stems
//! differ in colour, a segment's colour is evidence of what it is.
//!
//! Colours are compared as chromaticity (`r, g, b` over `r + g + b`), which shading and
//! exposure scale away. The leaf colour is the mean over the points of the segments already
//! called leaves; the stem colour the mean over the stem test's points in no leaf segment. Both
//! vary (leaves differ in hue, stems hold a few leaf rims), so the models decide only on a
//! plant where they lie apart by more than their points' own spread along the line that
//! joins them ([`MIN_COLOUR_SEPARATION`]); on a plant with green stems as green as its leaves
//! colour decides nothing.

use nalgebra::Vector3;

/// The leaf and stem colours lie at least this many times their points' pooled standard
/// deviation apart along the line that joins them, or colour decides nothing. Set before
/// measuring, not tuned. Measured where the rule runs (semi-dense synthetic plants): 1.04–1.47
/// on smallleaf seeds 1–8, 1.68 on medium 1, 1.82–2.45 on broadleaf 1–3, 1.41–1.98 on compound
/// 11–12; 0.94 on smallleaf 6 seen by 16 views of 480×360 (`tests/small_leaves.rs`), where
/// colours of thin organs blur into their surroundings.
pub const MIN_COLOUR_SEPARATION: f64 = 1.0;

/// A segment is leaf-coloured when its mean chromaticity, projected on the line from the stem
/// colour (0) to the leaf colour (1), lies at least this far along it: nearer the leaves than
/// the stems.
pub const MIN_LEAF_LIKENESS: f64 = 0.5;

/// Fewest points each model is measured from.
const MIN_MODEL_POINTS: usize = 50;

/// A plant's leaf and stem colours (chromaticity), when they are told apart.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OrganColours {
    stem: Vector3<f64>,
    /// From the stem colour to the leaf colour.
    stem_to_leaf: Vector3<f64>,
}

/// The chromaticity of a colour (`None` for black, which has none).
fn chromaticity(rgb: [u8; 3]) -> Option<Vector3<f64>> {
    let v = Vector3::new(rgb[0] as f64, rgb[1] as f64, rgb[2] as f64);
    let sum = v.sum();
    (sum > 0.0).then(|| v / sum)
}

/// Mean and count of the chromaticities of `points`' colours.
fn mean_chromaticity(
    colors: &[[u8; 3]],
    points: impl Iterator<Item = usize>,
) -> Option<(Vector3<f64>, usize)> {
    let (sum, count) = points
        .filter_map(|i| colors.get(i).copied().and_then(chromaticity))
        .fold((Vector3::zeros(), 0usize), |(sum, count), c| {
            (sum + c, count + 1)
        });
    (count > 0).then(|| (sum / count as f64, count))
}

impl OrganColours {
    /// Measures the models from the colours of `leaf_points` and `stem_points` (indices into
    /// `colors`). `None` when either has fewer than [`MIN_MODEL_POINTS`] coloured points or the
    /// two lie closer than [`MIN_COLOUR_SEPARATION`] times their spread.
    pub fn measure(
        colors: &[[u8; 3]],
        leaf_points: &[usize],
        stem_points: &[usize],
    ) -> Option<Self> {
        let (leaf, leaf_count) = mean_chromaticity(colors, leaf_points.iter().copied())?;
        let (stem, stem_count) = mean_chromaticity(colors, stem_points.iter().copied())?;
        if leaf_count < MIN_MODEL_POINTS || stem_count < MIN_MODEL_POINTS {
            return None;
        }
        let stem_to_leaf = leaf - stem;
        let separation = stem_to_leaf.norm();
        if separation <= 0.0 {
            return None;
        }
        let axis = stem_to_leaf / separation;
        let variance = |points: &[usize], mean: &Vector3<f64>| {
            let (sum, count) = points
                .iter()
                .filter_map(|&i| colors.get(i).copied().and_then(chromaticity))
                .fold((0.0, 0usize), |(sum, count), c| {
                    (sum + (c - mean).dot(&axis).powi(2), count + 1)
                });
            sum / count.max(1) as f64
        };
        let pooled = (0.5 * (variance(leaf_points, &leaf) + variance(stem_points, &stem))).sqrt();
        tracing::debug!(
            separation,
            pooled,
            ratio = separation / pooled.max(1e-12),
            "leaf and stem colours"
        );
        (separation >= MIN_COLOUR_SEPARATION * pooled).then_some(Self { stem, stem_to_leaf })
    }

    /// Measures the models on the first `count` points (indices into `colors`): the leaf
    /// colour from those `is_leaf` says are in leaf segments, the stem colour from those
    /// `is_stem` says the stem test found, in no leaf segment ([`Self::measure`]).
    pub fn measure_split(
        colors: &[[u8; 3]],
        count: usize,
        is_leaf: impl Fn(usize) -> bool,
        is_stem: impl Fn(usize) -> bool,
    ) -> Option<Self> {
        let (leaf, stem): (Vec<usize>, Vec<usize>) = (0..count.min(colors.len()))
            .filter(|&i| is_leaf(i) || is_stem(i))
            .partition(|&i| is_leaf(i));
        Self::measure(colors, &leaf, &stem)
    }

    /// Where `points`' mean chromaticity lies on the line from the stem colour (0) to the leaf
    /// colour (1); `None` when none of them has a colour.
    pub fn leaf_likeness(&self, colors: &[[u8; 3]], points: &[usize]) -> Option<f64> {
        let (mean, _) = mean_chromaticity(colors, points.iter().copied())?;
        Some((mean - self.stem).dot(&self.stem_to_leaf) / self.stem_to_leaf.norm_squared())
    }

    /// Whether `points` are leaf-coloured ([`MIN_LEAF_LIKENESS`]).
    pub fn is_leaf_coloured(&self, colors: &[[u8; 3]], points: &[usize]) -> bool {
        self.leaf_likeness(colors, points)
            .is_some_and(|t| t >= MIN_LEAF_LIKENESS)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::util::rng::Rng;

    /// `n` colours around `rgb`, each channel jittered by up to `jitter` and the whole scaled
    /// by a random brightness (shading) between 0.4 and 1.
    fn around(rgb: [f64; 3], jitter: f64, n: usize, rng: &mut Rng) -> Vec<[u8; 3]> {
        (0..n)
            .map(|_| {
                let shade = rng.range(0.4, 1.0);
                let mut channel = |c: f64| {
                    (shade * (c + rng.range(-jitter, jitter)))
                        .round()
                        .clamp(0.0, 255.0) as u8
                };
                [channel(rgb[0]), channel(rgb[1]), channel(rgb[2])]
            })
            .collect()
    }

    const LEAF_GREEN: [f64; 3] = [60.0, 120.0, 50.0];
    const BARK: [f64; 3] = [110.0, 100.0, 60.0];

    /// Leaf-green points 0..n, bark-coloured points n..2n, then `extra`.
    fn plant(leaf: [f64; 3], stem: [f64; 3], n: usize, rng: &mut Rng) -> Vec<[u8; 3]> {
        let mut colors = around(leaf, 25.0, n, rng);
        colors.extend(around(stem, 25.0, n, rng));
        colors
    }

    #[test]
    fn a_segment_is_called_by_the_nearer_organ_colour_whatever_its_shading() {
        let mut rng = Rng::seed_from(7);
        let mut colors = plant(LEAF_GREEN, BARK, 400, &mut rng);
        let leaf: Vec<usize> = (0..400).collect();
        let stem: Vec<usize> = (400..800).collect();
        let models = OrganColours::measure(&colors, &leaf, &stem);
        let Some(models) = models else {
            panic!("leaf green and bark are told apart");
        };
        // A dark leaf (in shadow) and a pale piece of stem.
        let start = colors.len();
        colors.extend(around(LEAF_GREEN.map(|c| 0.3 * c), 8.0, 25, &mut rng));
        colors.extend(around(BARK, 25.0, 25, &mut rng));
        let dark_leaf: Vec<usize> = (start..start + 25).collect();
        let stem_piece: Vec<usize> = (start + 25..start + 50).collect();
        assert!(models.is_leaf_coloured(&colors, &dark_leaf));
        assert!(!models.is_leaf_coloured(&colors, &stem_piece));
        let t = models.leaf_likeness(&colors, &leaf).unwrap_or(f64::NAN);
        assert!(
            (t - 1.0).abs() < 1e-9,
            "the leaf model's own points are at 1: {t}"
        );
    }

    #[test]
    fn stems_as_green_as_the_leaves_make_colour_decide_nothing() {
        let mut rng = Rng::seed_from(8);
        let colors = plant(LEAF_GREEN, [64.0, 118.0, 52.0], 400, &mut rng);
        let leaf: Vec<usize> = (0..400).collect();
        let stem: Vec<usize> = (400..800).collect();
        assert_eq!(OrganColours::measure(&colors, &leaf, &stem), None);
    }

    #[test]
    fn too_few_or_uncoloured_points_measure_no_model() {
        let mut rng = Rng::seed_from(9);
        let mut colors = plant(LEAF_GREEN, BARK, 400, &mut rng);
        let leaf: Vec<usize> = (0..400).collect();
        assert_eq!(
            OrganColours::measure(&colors, &leaf, &(400..440).collect::<Vec<_>>()),
            None
        );
        for c in &mut colors[400..] {
            *c = [0, 0, 0];
        }
        assert_eq!(
            OrganColours::measure(&colors, &leaf, &(400..800).collect::<Vec<_>>()),
            None
        );
        // Indices past the colours are skipped, not a panic.
        assert_eq!(OrganColours::measure(&colors, &leaf, &[5000, 5001]), None);
    }
}
