//! How well a reconstruction's traits match the truth: the ground-truth traits are computed
//! by the same code from the true meshes and branches, and compared organ by organ (leaves
//! paired by the evaluation's point matching, branches by their centrelines).

use std::collections::BTreeMap;

use nalgebra::Point3;
use serde::Serialize;

use super::{PlantOrgans, TraitTable, branch_length, branch_organ_id, leaf_organ_id, plant_traits};
use crate::branch::plant::SkeletonRecord;
use crate::eval::Summary;
use crate::eval::align::Similarity;

/// One leaf's traits, true and reconstructed.
#[derive(Clone, Debug, Serialize)]
pub struct LeafComparison {
    pub gt_leaf: u32,
    pub leaf: u32,
    /// The true and the reconstructed one-sided area and midrib length (truth's units), so a
    /// bias (too small, too long) shows, not only the size of the error.
    pub gt_area: f64,
    pub area: f64,
    pub gt_length: f64,
    pub length: f64,
    pub area_relative_error: f64,
    pub length_relative_error: f64,
    pub inclination_error_deg: f64,
}

/// One matched branch.
#[derive(Clone, Debug, Serialize)]
pub struct BranchComparison {
    pub gt_branch: u32,
    pub branch: u32,
    /// True and reconstructed length (truth's units).
    pub gt_length: f64,
    pub length: f64,
    pub length_relative_error: f64,
    /// True and reconstructed insertion height (the base's height above each plant's own
    /// base, truth's units) and their absolute difference; `None` for a stem (a root branch
    /// in either) or where either has no base.
    pub gt_insertion_height: Option<f64>,
    pub insertion_height: Option<f64>,
    pub insertion_height_error: Option<f64>,
    /// Symmetric mean centreline distance / the tolerance it was matched under.
    pub distance: f64,
}

/// The accuracy of one plant's traits.
#[derive(Clone, Debug, Serialize)]
pub struct TraitAccuracy {
    pub gt_leaves: usize,
    pub leaves: Vec<LeafComparison>,
    pub leaf_area_relative_error: Summary,
    pub leaf_length_relative_error: Summary,
    pub leaf_inclination_error_deg: Summary,
    pub gt_branches: usize,
    pub branches: Vec<BranchComparison>,
    pub branch_length_relative_error: Summary,
    /// Absolute insertion height error of the matched side branches (truth's units).
    pub branch_insertion_height_error: Summary,
    pub plant_height_relative_error: Option<f64>,
    pub total_leaf_area_relative_error: Option<f64>,
}

/// Applies a similarity (prediction → truth frame) to every organ.
pub fn transform_organs(organs: &mut PlantOrgans, similarity: &Similarity) {
    for leaf in &mut organs.leaves {
        for p in &mut leaf.mesh.positions {
            *p = similarity.apply(&p.cast::<f64>()).cast::<f32>();
        }
        leaf.mesh.compute_normals();
        leaf.base_world = leaf.base_world.map(|b| similarity.apply(&b));
    }
    for branch in &mut organs.branches {
        for c in branch
            .centerline
            .iter_mut()
            .chain(branch.control_points.iter_mut())
        {
            let p = similarity.apply(&Point3::from(*c));
            *c = [p.x, p.y, p.z];
        }
        branch.radius_start *= similarity.scale;
        branch.radius_end *= similarity.scale;
        branch.length *= similarity.scale;
    }
    organs.up_world = similarity.rotation * organs.up_world;
}

fn point_segment_distance(p: &Point3<f64>, a: &Point3<f64>, b: &Point3<f64>) -> f64 {
    let ab = b - a;
    let t = if ab.norm_squared() > 0.0 {
        ((p - a).dot(&ab) / ab.norm_squared()).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (p - (a + ab * t)).norm()
}

fn polyline_distance(p: &Point3<f64>, line: &[[f64; 3]]) -> f64 {
    match line {
        [] => f64::INFINITY,
        [only] => (p - Point3::from(*only)).norm(),
        _ => line
            .windows(2)
            .map(|w| point_segment_distance(p, &Point3::from(w[0]), &Point3::from(w[1])))
            .fold(f64::INFINITY, f64::min),
    }
}

/// Symmetric mean distance between two centrelines.
fn centreline_distance(a: &SkeletonRecord, b: &SkeletonRecord) -> f64 {
    let one_way = |from: &SkeletonRecord, to: &SkeletonRecord| {
        let n = from.centerline.len().max(1) as f64;
        from.centerline
            .iter()
            .map(|c| polyline_distance(&Point3::from(*c), &to.centerline))
            .sum::<f64>()
            / n
    };
    one_way(a, b).max(one_way(b, a))
}

/// Compares the traits of a prediction (already in the truth's frame) with the truth's.
/// `leaf_pairs` are (GT leaf, predicted leaf) from the evaluation's matching. Branches are
/// paired greedily by symmetric mean centreline distance, within twice the true base radius
/// or 2 % of the plant height, whichever is larger.
pub fn compare(
    truth: &PlantOrgans,
    prediction: &PlantOrgans,
    leaf_pairs: &[(u32, u32)],
    plant_height: f64,
) -> (TraitAccuracy, TraitTable, TraitTable) {
    let gt_table = plant_traits(truth, None);
    let table = plant_traits(prediction, None);
    let mut leaves = Vec::new();
    for &(gt_leaf, leaf) in leaf_pairs {
        let (g, p) = (leaf_organ_id(gt_leaf), leaf_organ_id(leaf));
        let get = |t: &TraitTable, id: &str, name: &str| t.value(id, name);
        if let (Some(ga), Some(pa), Some(gl), Some(pl), Some(gi), Some(pi)) = (
            get(&gt_table, &g, "area"),
            get(&table, &p, "area"),
            get(&gt_table, &g, "length"),
            get(&table, &p, "length"),
            get(&gt_table, &g, "inclination"),
            get(&table, &p, "inclination"),
        ) {
            leaves.push(LeafComparison {
                gt_leaf,
                leaf,
                gt_area: ga,
                area: pa,
                gt_length: gl,
                length: pl,
                area_relative_error: (pa - ga).abs() / ga,
                length_relative_error: (pl - gl).abs() / gl,
                inclination_error_deg: (pi - gi).abs(),
            });
        }
    }
    let mut candidates = Vec::new();
    for g in &truth.branches {
        let tolerance = (2.0 * g.radius_start).max(0.02 * plant_height);
        for p in &prediction.branches {
            let d = centreline_distance(g, p);
            if d <= tolerance {
                candidates.push((d / tolerance, g, p));
            }
        }
    }
    candidates.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut used_gt = BTreeMap::new();
    let mut used_pred = BTreeMap::new();
    let mut branches = Vec::new();
    for (d, g, p) in candidates {
        if used_gt.contains_key(&g.id) || used_pred.contains_key(&p.id) {
            continue;
        }
        used_gt.insert(g.id, p.id);
        used_pred.insert(p.id, g.id);
        let gl = gt_table
            .value(&branch_organ_id(g.id), "length")
            .unwrap_or(branch_length(g));
        let pl = table
            .value(&branch_organ_id(p.id), "length")
            .unwrap_or(branch_length(p));
        // A stem's insertion height is 0 by definition (the plant's base is its foot).
        let inserted = g.parent.is_some() && p.parent.is_some();
        let gh = gt_table
            .value(&branch_organ_id(g.id), "insertion_height")
            .filter(|_| inserted);
        let ph = table
            .value(&branch_organ_id(p.id), "insertion_height")
            .filter(|_| inserted);
        branches.push(BranchComparison {
            gt_branch: g.id,
            branch: p.id,
            gt_length: gl,
            length: pl,
            length_relative_error: (pl - gl).abs() / gl,
            gt_insertion_height: gh,
            insertion_height: ph,
            insertion_height_error: gh.zip(ph).map(|(g, p)| (p - g).abs()),
            distance: d,
        });
    }
    let relative = |name: &str| {
        let g = gt_table.value("plant", name)?;
        let p = table.value("plant", name)?;
        (g > 0.0).then(|| (p - g).abs() / g)
    };
    let collect =
        |f: &dyn Fn(&LeafComparison) -> f64| Summary::of(&leaves.iter().map(f).collect::<Vec<_>>());
    let accuracy = TraitAccuracy {
        gt_leaves: truth.leaves.len(),
        leaf_area_relative_error: collect(&|l| l.area_relative_error),
        leaf_length_relative_error: collect(&|l| l.length_relative_error),
        leaf_inclination_error_deg: collect(&|l| l.inclination_error_deg),
        gt_branches: truth.branches.len(),
        branch_length_relative_error: Summary::of(
            &branches
                .iter()
                .map(|b| b.length_relative_error)
                .collect::<Vec<_>>(),
        ),
        branch_insertion_height_error: Summary::of(
            &branches
                .iter()
                .filter_map(|b| b.insertion_height_error)
                .collect::<Vec<_>>(),
        ),
        plant_height_relative_error: relative("height"),
        total_leaf_area_relative_error: relative("total_leaf_area"),
        leaves,
        branches,
    };
    (accuracy, gt_table, table)
}

/// A reconstruction output folder compared with a synthetic dataset's truth: the truth's
/// organs, the prediction's organs (aligned to the truth by its camera centres when
/// `pred_model`, real COLMAP, is given) and their trait accuracy, leaves paired by the
/// evaluation's point matching.
pub struct TraitComparison {
    pub truth: PlantOrgans,
    pub prediction: PlantOrgans,
    pub accuracy: TraitAccuracy,
}

/// See [`TraitComparison`].
pub fn compare_with_truth(
    dataset: &std::path::Path,
    out: &std::path::Path,
    pred_model: Option<&std::path::Path>,
) -> Result<TraitComparison, super::TraitsError> {
    let eval_error =
        |path: &std::path::Path, e: crate::eval::EvalError| super::TraitsError::Input {
            path: path.display().to_string(),
            message: e.to_string(),
        };
    let truth = crate::eval::GroundTruth::load(dataset).map_err(|e| eval_error(dataset, e))?;
    let mut prediction = crate::eval::Prediction::load(out).map_err(|e| eval_error(out, e))?;
    let mut organs = super::io::read_reconstruction(out, "prediction")?;
    let alignment = match pred_model {
        Some(model) => {
            let (similarity, report) = crate::eval::align_to_ground_truth(dataset, model)
                .map_err(|e| eval_error(model, e))?;
            prediction.transform(&similarity);
            transform_organs(&mut organs, &similarity);
            Some(report)
        }
        None => None,
    };
    let report = crate::eval::evaluate(
        &truth,
        &prediction,
        alignment,
        &crate::eval::EvalOptions::default(),
    )
    .map_err(|e| eval_error(out, e))?;
    let pairs: Vec<(u32, u32)> = report
        .leaf_geometry
        .iter()
        .filter(|g| g.gt_leaf >= 0 && g.segment >= 0)
        .map(|g| (g.gt_leaf as u32, g.segment as u32))
        .collect();
    let gt_organs = super::io::read_ground_truth(dataset, "truth")?;
    let (accuracy, _, _) = compare(&gt_organs, &organs, &pairs, truth.plant_height);
    Ok(TraitComparison {
        truth: gt_organs,
        prediction: organs,
        accuracy,
    })
}

/// Trait accuracy of a reconstruction output folder against a synthetic dataset
/// ([`compare_with_truth`]).
pub fn evaluate_traits(
    dataset: &std::path::Path,
    out: &std::path::Path,
    pred_model: Option<&std::path::Path>,
) -> Result<TraitAccuracy, super::TraitsError> {
    Ok(compare_with_truth(dataset, out, pred_model)?.accuracy)
}

impl TraitAccuracy {
    /// A short human-readable summary.
    pub fn to_text(&self) -> String {
        let median = |s: &Summary| s.median.map_or("-".to_owned(), |m| format!("{m:.4}"));
        let mut text = String::new();
        text.push_str(&format!(
            "leaves compared: {} of {} true leaves
",
            self.leaves.len(),
            self.gt_leaves
        ));
        text.push_str(&format!(
            "  median leaf area error {} (relative), length error {} (relative), inclination error {} deg
",
            median(&self.leaf_area_relative_error),
            median(&self.leaf_length_relative_error),
            median(&self.leaf_inclination_error_deg)
        ));
        text.push_str(&format!(
            "branches matched: {} of {} true branches; median length error {} (relative), insertion height error {} (truth's units)
",
            self.branches.len(),
            self.gt_branches,
            median(&self.branch_length_relative_error),
            median(&self.branch_insertion_height_error)
        ));
        let optional = |v: Option<f64>| v.map_or("-".to_owned(), |v| format!("{v:.4}"));
        text.push_str(&format!(
            "plant height error {}, total leaf area error {} (relative)
",
            optional(self.plant_height_relative_error),
            optional(self.total_leaf_area_relative_error)
        ));
        text
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::traits::LeafOrgan;
    use nalgebra::Vector3;

    fn organs(leaf_scale: f64, branch_extra: f64) -> PlantOrgans {
        let mesh = crate::traits::tests::rectangle(
            Point3::new(0.0, 0.0, 0.3),
            Vector3::x(),
            Vector3::y(),
            0.2 * leaf_scale,
            0.05 * leaf_scale,
        );
        PlantOrgans {
            plant: "p".into(),
            up_world: Vector3::z(),
            leaves: vec![LeafOrgan {
                id: 7,
                mesh,
                base_world: Some(Point3::new(0.0, 0.0, 0.3)),
                branch: None,
                synthesized: false,
                compound_leaf: None,
            }],
            branches: vec![SkeletonRecord {
                id: 3,
                parent: None,
                parent_fraction: 0.0,
                control_points: Vec::new(),
                radius_start: 0.01,
                radius_end: 0.01,
                length: 0.0,
                centerline: vec![[0.0, 0.0, 0.0], [0.0, 0.0, 0.3 + branch_extra]],
                observed_length: None,
                bridged_length: None,
            }],
        }
    }

    #[test]
    fn a_scaled_leaf_and_a_longer_stem_show_their_errors() {
        let truth = organs(1.0, 0.0);
        let prediction = organs(1.1, 0.003);
        let (accuracy, _, _) = compare(&truth, &prediction, &[(7, 7)], 0.3);
        let leaf = &accuracy.leaves[0];
        assert!((leaf.area_relative_error - 0.21).abs() < 1e-4, "{leaf:?}");
        assert!((leaf.length_relative_error - 0.1).abs() < 1e-4, "{leaf:?}");
        // The values behind the errors keep their sign: the prediction is the larger one.
        assert!((leaf.area / leaf.gt_area - 1.21).abs() < 1e-4, "{leaf:?}");
        assert!(
            (leaf.length / leaf.gt_length - 1.1).abs() < 1e-4,
            "{leaf:?}"
        );
        assert!(leaf.inclination_error_deg < 1e-6);
        assert_eq!(accuracy.branches.len(), 1);
        assert!((accuracy.branches[0].length_relative_error - 0.01).abs() < 1e-9);
        assert!(
            (accuracy.branches[0].length - accuracy.branches[0].gt_length - 0.003).abs() < 1e-9
        );
        // A stem far away is not matched.
        let mut far = organs(1.0, 0.0);
        for c in &mut far.branches[0].centerline {
            c[0] += 0.5;
        }
        let (accuracy, _, _) = compare(&truth, &far, &[], 0.3);
        assert!(accuracy.branches.is_empty());
        assert_eq!(accuracy.leaf_area_relative_error.count, 0);
    }

    #[test]
    fn a_branch_inserted_higher_shows_its_insertion_height_error() {
        // A side branch leaving the stem at 0.1 in the truth and 15 mm higher in the
        // prediction, otherwise alike: its insertion height is 15 mm off (stems have none).
        let with_side = |base: f64| {
            let mut organs = organs(1.0, 0.0);
            organs.branches.push(SkeletonRecord {
                id: 4,
                parent: Some(3),
                parent_fraction: base / 0.3,
                control_points: Vec::new(),
                radius_start: 0.01,
                radius_end: 0.005,
                length: 0.0,
                centerline: vec![[0.0, 0.0, base], [0.1, 0.0, base + 0.05]],
                observed_length: None,
                bridged_length: None,
            });
            organs
        };
        let (accuracy, _, _) = compare(&with_side(0.1), &with_side(0.115), &[], 0.3);
        assert_eq!(accuracy.branches.len(), 2, "{:?}", accuracy.branches);
        let side = accuracy.branches.iter().find(|b| b.gt_branch == 4).unwrap();
        assert_eq!(side.branch, 4);
        assert!(
            (side.insertion_height_error.unwrap() - 0.015).abs() < 1e-9,
            "{side:?}"
        );
        assert!(
            (side.insertion_height.unwrap() - 0.115).abs() < 1e-9,
            "{side:?}"
        );
        // The stems are matched, with no insertion height.
        let stem = accuracy.branches.iter().find(|b| b.gt_branch == 3).unwrap();
        assert_eq!(stem.insertion_height_error, None, "{stem:?}");
        assert_eq!(accuracy.branch_insertion_height_error.count, 1);
    }
}
