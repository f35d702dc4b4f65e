//! Phyllotaxis against manual measures: the organ sequence along the predicted main stem
//! (internodes and signed divergence angles, [`super::phyllotaxis`]) aligned to a
//! measured one (ROMI's `measures.json`: `angles` in radians, `internodes` in millimetres,
//! one entry per interval between successive organs) by dynamic time warping with merges and
//! splits, as ROMI's own evaluator aligns sequences.
//!
//! The alignment walks both interval sequences in order. A step either matches one predicted
//! interval with one measured interval, merges up to [`MAX_RUN`] consecutive predicted
//! intervals into one measured one (the prediction has extra organs between them: the
//! internodes add up, and so do the angles, modulo 360°), or splits one predicted interval
//! over up to [`MAX_RUN`] measured ones (organs the prediction missed). Intervals at either
//! end may stay unmatched (a stem found shorter or longer than the measured one), each at the
//! cost of one unit. A step's cost is `|Δangle| / 45° + |Δinternode| / median measured
//! internode`; the 45° is a constant, the internode unit follows the plant.
//!
//! The measures do not say in which sense their angles turn, so both senses are aligned and
//! the cheaper one is reported (as `sense`).

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::TraitsError;
use super::phyllotaxis::StemSequence;
use crate::util::stats::median;

fn input_error(path: &Path, message: impl std::fmt::Display) -> TraitsError {
    TraitsError::Input {
        path: path.display().to_string(),
        message: message.to_string(),
    }
}

/// The most intervals one step merges or splits.
pub const MAX_RUN: usize = 3;
/// The angle that costs as much as one median internode.
pub const ANGLE_UNIT_DEG: f64 = 45.0;
/// The cost of leaving an end interval unmatched.
pub const END_COST: f64 = 1.0;

/// A measured organ sequence (ROMI `measures.json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Measures {
    /// Radians, one per interval.
    pub angles: Vec<f64>,
    /// Millimetres, one per interval.
    pub internodes: Vec<f64>,
}

impl Measures {
    /// Reads and checks a `measures.json`.
    pub fn read(path: &Path) -> Result<Self, TraitsError> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| input_error(path, format!("cannot read: {e}")))?;
        let measures: Self = serde_json::from_str(&text).map_err(|e| {
            input_error(
                path,
                format!("not a measures file (angles, internodes): {e}"),
            )
        })?;
        if measures.angles.len() != measures.internodes.len() {
            return Err(input_error(
                path,
                format!(
                    "{} angles but {} internodes: one of each per interval",
                    measures.angles.len(),
                    measures.internodes.len()
                ),
            ));
        }
        if measures.angles.is_empty() {
            return Err(input_error(path, "no intervals"));
        }
        if let Some(k) = measures
            .angles
            .iter()
            .zip(&measures.internodes)
            .position(|(a, i)| !a.is_finite() || !i.is_finite() || *i < 0.0)
        {
            return Err(input_error(
                path,
                format!("interval {k}: angle and internode must be finite, internode ≥ 0"),
            ));
        }
        Ok(measures)
    }
}

/// One interval: internode (mm) and divergence angle (degrees, [0, 360); `None` where a
/// predicted organ runs along the stem and has no azimuth).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Interval {
    pub internode_mm: f64,
    pub angle_deg: Option<f64>,
}

/// What one alignment step did.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StepKind {
    Match,
    /// Several predicted intervals against one measured.
    Merge,
    /// One predicted interval against several measured.
    Split,
    /// A predicted interval at an end with no measured partner.
    ExtraPredicted,
    /// A measured interval at an end with no predicted partner.
    Missed,
}

/// One step: the predicted intervals `predicted.0..predicted.1` against the measured ones
/// `measured.0..measured.1`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct AlignmentStep {
    pub kind: StepKind,
    pub predicted: (usize, usize),
    pub measured: (usize, usize),
    pub cost: f64,
}

/// The comparison of a predicted stem with the measures.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PhyllotaxisComparison {
    /// `counter_clockwise` or `clockwise`: the sense the predicted angles were read in.
    pub sense: String,
    pub predicted: Vec<Interval>,
    pub measured: Vec<Interval>,
    pub organs_predicted: usize,
    pub organs_measured: usize,
    /// (predicted − measured) / measured organs.
    pub organ_count_error: f64,
    pub steps: Vec<AlignmentStep>,
    pub total_cost: f64,
    /// Per matched interval (one-to-one steps), in sequence order (angles where both are
    /// known).
    pub internode_errors_mm: Vec<f64>,
    pub angle_errors_deg: Vec<f64>,
    pub median_internode_error_mm: Option<f64>,
    pub median_angle_error_deg: Option<f64>,
    /// Measured intervals in one-to-one steps, as a share of all measured intervals.
    pub matched_share: f64,
    /// Medians over every paired step (matches, merges and splits, each comparing the
    /// combined intervals of its two sides).
    pub median_paired_internode_error_mm: Option<f64>,
    pub median_paired_angle_error_deg: Option<f64>,
}

/// The absolute difference of two angles on the circle, degrees in [0, 180].
pub fn circular_difference_deg(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(360.0);
    d.min(360.0 - d)
}

/// Several consecutive intervals read as one: internodes add, angles add modulo 360° (an
/// unknown angle makes the sum unknown).
fn combined(intervals: &[Interval]) -> Interval {
    Interval {
        internode_mm: intervals.iter().map(|i| i.internode_mm).sum(),
        angle_deg: intervals
            .iter()
            .map(|i| i.angle_deg)
            .sum::<Option<f64>>()
            .map(|a| a.rem_euclid(360.0)),
    }
}

/// The angle difference of two intervals, when both angles are known.
fn angle_difference(a: &Interval, b: &Interval) -> Option<f64> {
    Some(circular_difference_deg(a.angle_deg?, b.angle_deg?))
}

/// An unknown angle costs nothing: the internodes still place the step.
fn step_cost(a: &Interval, b: &Interval, internode_unit_mm: f64) -> f64 {
    angle_difference(a, b).unwrap_or(0.0) / ANGLE_UNIT_DEG
        + (a.internode_mm - b.internode_mm).abs() / internode_unit_mm
}

/// Aligns predicted intervals with measured ones (see the module docs); returns the steps
/// in order and the total cost.
pub fn align(predicted: &[Interval], measured: &[Interval]) -> (Vec<AlignmentStep>, f64) {
    let (n, m) = (predicted.len(), measured.len());
    let unit = median(measured.iter().map(|i| i.internode_mm))
        .filter(|u| *u > 0.0)
        .or_else(|| {
            let max = measured.iter().map(|i| i.internode_mm).fold(0.0, f64::max);
            (max > 0.0).then_some(max)
        })
        .unwrap_or(1.0);
    // cost[i][j]: the cheapest alignment of predicted[..i] with measured[..j]; a prefix of
    // one side may stay unmatched (the first row and column), and after the loop a suffix.
    let inf = f64::INFINITY;
    let mut cost = vec![vec![inf; m + 1]; n + 1];
    let mut back: Vec<Vec<Option<AlignmentStep>>> = vec![vec![None; m + 1]; n + 1];
    cost[0][0] = 0.0;
    for i in 1..=n {
        cost[i][0] = i as f64 * END_COST;
        back[i][0] = Some(AlignmentStep {
            kind: StepKind::ExtraPredicted,
            predicted: (i - 1, i),
            measured: (0, 0),
            cost: END_COST,
        });
    }
    for j in 1..=m {
        cost[0][j] = j as f64 * END_COST;
        back[0][j] = Some(AlignmentStep {
            kind: StepKind::Missed,
            predicted: (0, 0),
            measured: (j - 1, j),
            cost: END_COST,
        });
    }
    for i in 1..=n {
        for j in 1..=m {
            let mut best = (inf, None);
            let mut consider = |c: f64, step: AlignmentStep| {
                if c < best.0 {
                    best = (c, Some(step));
                }
            };
            for run in 1..=MAX_RUN.min(i) {
                let p = combined(&predicted[i - run..i]);
                let c = step_cost(&p, &measured[j - 1], unit);
                consider(
                    cost[i - run][j - 1] + c,
                    AlignmentStep {
                        kind: if run == 1 {
                            StepKind::Match
                        } else {
                            StepKind::Merge
                        },
                        predicted: (i - run, i),
                        measured: (j - 1, j),
                        cost: c,
                    },
                );
            }
            for run in 2..=MAX_RUN.min(j) {
                let q = combined(&measured[j - run..j]);
                let c = step_cost(&predicted[i - 1], &q, unit);
                consider(
                    cost[i - 1][j - run] + c,
                    AlignmentStep {
                        kind: StepKind::Split,
                        predicted: (i - 1, i),
                        measured: (j - run, j),
                        cost: c,
                    },
                );
            }
            cost[i][j] = best.0;
            back[i][j] = best.1;
        }
    }
    // Free end: the last paired cell, then the rest of one side unmatched.
    let mut end = (n, m, cost[n][m]);
    for (i, row) in cost.iter().enumerate().take(n) {
        let c = row[m] + (n - i) as f64 * END_COST;
        if c < end.2 {
            end = (i, m, c);
        }
    }
    for (j, paired) in cost[n].iter().enumerate().take(m) {
        let c = paired + (m - j) as f64 * END_COST;
        if c < end.2 {
            end = (n, j, c);
        }
    }
    let mut steps = Vec::new();
    for i in end.0..n {
        steps.push(AlignmentStep {
            kind: StepKind::ExtraPredicted,
            predicted: (i, i + 1),
            measured: (m, m),
            cost: END_COST,
        });
    }
    for j in end.1..m {
        steps.push(AlignmentStep {
            kind: StepKind::Missed,
            predicted: (n, n),
            measured: (j, j + 1),
            cost: END_COST,
        });
    }
    let mut tail = steps;
    let mut steps = Vec::new();
    let (mut i, mut j) = (end.0, end.1);
    while i > 0 || j > 0 {
        let Some(step) = back[i][j] else {
            break;
        };
        steps.push(step);
        i = step.predicted.0;
        j = step.measured.0;
    }
    steps.reverse();
    steps.append(&mut tail);
    (steps, end.2)
}

/// Compares a predicted stem sequence (model units, turned into millimetres by
/// `millimetres_per_unit`) with the measures.
pub fn compare(
    sequence: &StemSequence,
    millimetres_per_unit: f64,
    measures: &Measures,
) -> PhyllotaxisComparison {
    let measured: Vec<Interval> = measures
        .angles
        .iter()
        .zip(&measures.internodes)
        .map(|(a, i)| Interval {
            internode_mm: *i,
            angle_deg: Some(a.to_degrees().rem_euclid(360.0)),
        })
        .collect();
    let read = |mirror: bool| -> Vec<Interval> {
        sequence
            .internodes
            .iter()
            .zip(&sequence.angles_deg)
            .map(|(i, a)| Interval {
                internode_mm: i * millimetres_per_unit,
                angle_deg: a.map(|a| {
                    if mirror {
                        (360.0 - a).rem_euclid(360.0)
                    } else {
                        a
                    }
                }),
            })
            .collect()
    };
    let ccw = read(false);
    let cw = read(true);
    let (a, cost_a) = align(&ccw, &measured);
    let (b, cost_b) = align(&cw, &measured);
    let (sense, predicted, steps, total_cost) = if cost_b < cost_a {
        ("clockwise", cw, b, cost_b)
    } else {
        ("counter_clockwise", ccw, a, cost_a)
    };
    // Errors of every paired step, and of the one-to-one matches among them.
    let (mut internode_errors_mm, mut angle_errors_deg) = (Vec::new(), Vec::new());
    let (mut paired_internode, mut paired_angle) = (Vec::new(), Vec::new());
    for step in steps
        .iter()
        .filter(|s| matches!(s.kind, StepKind::Match | StepKind::Merge | StepKind::Split))
    {
        let p = combined(&predicted[step.predicted.0..step.predicted.1]);
        let q = combined(&measured[step.measured.0..step.measured.1]);
        let internode = (p.internode_mm - q.internode_mm).abs();
        let angle = angle_difference(&p, &q);
        paired_internode.push(internode);
        paired_angle.extend(angle);
        if step.kind == StepKind::Match {
            internode_errors_mm.push(internode);
            angle_errors_deg.extend(angle);
        }
    }
    let organs_predicted = sequence.organs.len();
    let organs_measured = measured.len() + 1;
    PhyllotaxisComparison {
        sense: sense.into(),
        organs_predicted,
        organs_measured,
        organ_count_error: (organs_predicted as f64 - organs_measured as f64)
            / organs_measured as f64,
        median_internode_error_mm: median(internode_errors_mm.iter().copied()),
        median_angle_error_deg: median(angle_errors_deg.iter().copied()),
        matched_share: internode_errors_mm.len() as f64 / measured.len() as f64,
        median_paired_internode_error_mm: median(paired_internode.iter().copied()),
        median_paired_angle_error_deg: median(paired_angle.iter().copied()),
        internode_errors_mm,
        angle_errors_deg,
        steps,
        total_cost,
        predicted,
        measured,
    }
}

impl PhyllotaxisComparison {
    /// A plain-text summary.
    pub fn to_text(&self) -> String {
        let mut out = String::new();
        let fmt = |v: Option<f64>| v.map_or("–".to_string(), |v| format!("{v:.1}"));
        out.push_str(&format!(
            "organs: {} predicted, {} measured ({:+.1} %)\n",
            self.organs_predicted,
            self.organs_measured,
            100.0 * self.organ_count_error
        ));
        let count = |k: StepKind| self.steps.iter().filter(|s| s.kind == k).count();
        out.push_str(&format!(
            "alignment ({} angles): {} matched, {} merged, {} split, {} extra at the ends, {} missed at the ends; cost {:.2}\n",
            self.sense.replace('_', "-"),
            count(StepKind::Match),
            count(StepKind::Merge),
            count(StepKind::Split),
            count(StepKind::ExtraPredicted),
            count(StepKind::Missed),
            self.total_cost
        ));
        out.push_str(&format!(
            "matched intervals: {:.0} % of the measured; median internode error {} mm, median angle error {}°\n",
            100.0 * self.matched_share,
            fmt(self.median_internode_error_mm),
            fmt(self.median_angle_error_deg)
        ));
        out.push_str(&format!(
            "all paired steps: median internode error {} mm, median angle error {}°\n",
            fmt(self.median_paired_internode_error_mm),
            fmt(self.median_paired_angle_error_deg)
        ));
        out.push_str(
            "step\tpredicted\tmeasured\tinternode mm (pred / meas)\tangle ° (pred / meas)\n",
        );
        for step in &self.steps {
            let p = (step.predicted.1 > step.predicted.0)
                .then(|| combined(&self.predicted[step.predicted.0..step.predicted.1]));
            let q = (step.measured.1 > step.measured.0)
                .then(|| combined(&self.measured[step.measured.0..step.measured.1]));
            let range = |r: (usize, usize)| {
                if r.1 > r.0 {
                    format!("{}..{}", r.0, r.1)
                } else {
                    "–".into()
                }
            };
            out.push_str(&format!(
                "{:?}\t{}\t{}\t{} / {}\t{} / {}\n",
                step.kind,
                range(step.predicted),
                range(step.measured),
                fmt(p.map(|p| p.internode_mm)),
                fmt(q.map(|q| q.internode_mm)),
                fmt(p.and_then(|p| p.angle_deg)),
                fmt(q.and_then(|q| q.angle_deg)),
            ));
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn intervals(pairs: &[(f64, f64)]) -> Vec<Interval> {
        pairs
            .iter()
            .map(|(i, a)| Interval {
                internode_mm: *i,
                angle_deg: Some(*a),
            })
            .collect()
    }

    fn kinds(steps: &[AlignmentStep]) -> Vec<StepKind> {
        steps.iter().map(|s| s.kind).collect()
    }

    /// A sequence of `n` intervals from a fixed pseudo-random walk.
    fn sequence(n: usize, seed: u64) -> Vec<Interval> {
        let mut state = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        let mut next = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 33) as f64 / (1u64 << 31) as f64
        };
        (0..n)
            .map(|_| Interval {
                internode_mm: 3.0 + 20.0 * next(),
                angle_deg: Some(100.0 + 80.0 * next()),
            })
            .collect()
    }

    #[test]
    fn identical_sequences_match_one_to_one_at_no_cost() {
        let s = sequence(12, 1);
        let (steps, cost) = align(&s, &s);
        assert!(cost.abs() < 1e-12);
        assert_eq!(kinds(&steps), vec![StepKind::Match; 12]);
        for (k, step) in steps.iter().enumerate() {
            assert_eq!(step.predicted, (k, k + 1));
            assert_eq!(step.measured, (k, k + 1));
        }
    }

    #[test]
    fn an_extra_organ_is_merged_and_a_missed_one_split() {
        let truth = sequence(10, 2);
        // An extra organ inside interval 4: it splits into two parts whose internodes and
        // angles add up to the true one.
        let mut extra = truth.clone();
        let t = truth[4];
        extra.splice(
            4..5,
            intervals(&[
                (0.4 * t.internode_mm, 30.0),
                (
                    0.6 * t.internode_mm,
                    (t.angle_deg.unwrap() - 30.0).rem_euclid(360.0),
                ),
            ]),
        );
        let (steps, cost) = align(&extra, &truth);
        assert!(cost < 1e-9, "{cost}");
        let merge: Vec<_> = steps.iter().filter(|s| s.kind == StepKind::Merge).collect();
        assert_eq!(merge.len(), 1);
        assert_eq!(merge[0].predicted, (4, 6));
        assert_eq!(merge[0].measured, (4, 5));
        // The prediction misses the organ between intervals 6 and 7.
        let mut missed = truth.clone();
        let joined = combined(&truth[6..8]);
        missed.splice(6..8, [joined]);
        let (steps, cost) = align(&missed, &truth);
        assert!(cost < 1e-9, "{cost}");
        let split: Vec<_> = steps.iter().filter(|s| s.kind == StepKind::Split).collect();
        assert_eq!(split.len(), 1);
        assert_eq!(split[0].predicted, (6, 7));
        assert_eq!(split[0].measured, (6, 8));
        assert_eq!(
            steps.iter().filter(|s| s.kind == StepKind::Match).count(),
            8
        );
    }

    #[test]
    fn a_stem_found_only_halfway_leaves_the_top_unmatched() {
        let truth = sequence(16, 3);
        let (steps, _) = align(&truth[..9], &truth);
        assert_eq!(
            steps.iter().filter(|s| s.kind == StepKind::Match).count(),
            9
        );
        assert_eq!(
            steps.iter().filter(|s| s.kind == StepKind::Missed).count(),
            7
        );
        // Every measured interval is accounted for once, in order.
        let covered: Vec<usize> = steps
            .iter()
            .flat_map(|s| s.measured.0..s.measured.1)
            .collect();
        assert_eq!(covered, (0..16).collect::<Vec<_>>());
        // And extra predicted intervals below the first measured organ.
        let mut longer = sequence(3, 9);
        longer.extend_from_slice(&truth);
        let (steps, _) = align(&longer, &truth);
        let covered: Vec<usize> = steps
            .iter()
            .flat_map(|s| s.predicted.0..s.predicted.1)
            .collect();
        assert_eq!(covered, (0..19).collect::<Vec<_>>());
        assert_eq!(
            steps.iter().filter(|s| s.kind == StepKind::Match).count(),
            16
        );
    }

    #[test]
    fn angles_compare_on_the_circle_and_add_modulo_a_turn() {
        assert!((circular_difference_deg(350.0, 10.0) - 20.0).abs() < 1e-12);
        assert!((circular_difference_deg(10.0, 350.0) - 20.0).abs() < 1e-12);
        assert!((circular_difference_deg(-90.0, 270.0)).abs() < 1e-12);
        let c = combined(&intervals(&[(1.0, 250.0), (2.0, 200.0)]));
        assert!(
            (c.angle_deg.unwrap() - 90.0).abs() < 1e-12 && (c.internode_mm - 3.0).abs() < 1e-12
        );
    }

    #[test]
    fn the_sense_of_the_angles_is_read_from_the_measures() {
        use crate::traits::phyllotaxis::{InsertedOrgan, OrganKind, StemSequence};
        let truth = sequence(8, 4);
        let measures = Measures {
            angles: truth
                .iter()
                .map(|i| i.angle_deg.unwrap().to_radians())
                .collect(),
            internodes: truth.iter().map(|i| i.internode_mm).collect(),
        };
        // The prediction in model units of 2 mm, turning the other way.
        let mut position = 0.0;
        let mut organs = vec![InsertedOrgan {
            kind: OrganKind::Branch,
            id: 0,
            position,
        }];
        for (k, i) in truth.iter().enumerate() {
            position += i.internode_mm / 2.0;
            organs.push(InsertedOrgan {
                kind: OrganKind::Branch,
                id: k as u32 + 1,
                position,
            });
        }
        let predicted = StemSequence {
            stem: 0,
            stem_length: position,
            organs,
            internodes: truth.iter().map(|i| i.internode_mm / 2.0).collect(),
            angles_deg: truth
                .iter()
                .map(|i| i.angle_deg.map(|a| 360.0 - a))
                .collect(),
        };
        let comparison = compare(&predicted, 2.0, &measures);
        assert_eq!(comparison.sense, "clockwise");
        assert_eq!(comparison.organs_predicted, 9);
        assert_eq!(comparison.organs_measured, 9);
        assert!(comparison.organ_count_error.abs() < 1e-12);
        assert!(comparison.median_angle_error_deg.unwrap() < 1e-9);
        assert!(comparison.median_internode_error_mm.unwrap() < 1e-9);
        assert!((comparison.matched_share - 1.0).abs() < 1e-12);
        assert!(comparison.median_paired_angle_error_deg.unwrap() < 1e-9);
        let text = comparison.to_text();
        assert!(text.contains("9 predicted, 9 measured"), "{text}");
    }

    #[test]
    fn bad_measures_files_are_named() {
        let dir = std::env::temp_dir().join(format!("frond_measures_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("measures.json");
        std::fs::write(&path, r#"{"angles": [1.0, 2.0], "internodes": [3.0]}"#).unwrap();
        let error = Measures::read(&path).unwrap_err().to_string();
        assert!(
            error.contains("measures.json") && error.contains("2 angles"),
            "{error}"
        );
        std::fs::write(&path, r#"{"angles": [1.0], "internodes": [-3.0]}"#).unwrap();
        assert!(Measures::read(&path).is_err());
        std::fs::write(&path, "[]").unwrap();
        assert!(Measures::read(&path).is_err());
        std::fs::write(&path, r#"{"angles": [1.0], "internodes": [3.0]}"#).unwrap();
        assert_eq!(Measures::read(&path).unwrap().angles.len(), 1);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
