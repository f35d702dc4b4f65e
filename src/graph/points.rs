//! The point set the segmentation works on: positions, colours and the views that see each
//! point, taken from a COLMAP model's points (sparse or semi-dense) or from fused dense points.

use nalgebra::Point3;

use crate::scene::{Reconstruction, Scene};

/// What a point set's `point_ids` are.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum PointIds {
    /// COLMAP point3D ids of the scene's model.
    #[default]
    ModelPoint3D,
    /// Rows of `fused.ply` (dense points that are not the model's points).
    FusedRow,
}

/// Points with visibility, indexed 0..n. View indices refer to `Reconstruction::images()`.
#[derive(Clone, Debug, Default)]
pub struct PointSet {
    pub positions: Vec<Point3<f64>>,
    pub colors: Vec<[u8; 3]>,
    /// Sorted, deduplicated view indices per point.
    pub views: Vec<Vec<u32>>,
    /// Each point's id in the input (see `id_kind`).
    pub point_ids: Vec<u64>,
    pub id_kind: PointIds,
    /// Per point: whether `frond densify`'s thin-organ sweep found it (empty when the input
    /// does not say: sparse points, COLMAP's dense points).
    pub thin_organ: Vec<bool>,
    /// Per point: whether it fills a gap of the main stereo partners' points (`frond
    /// densify`'s fill partners): the segmentation leaves these points out, the leaf stage and
    /// the skeleton label them from its segments (empty when the input does not say).
    pub gap_fill: Vec<bool>,
}

impl PointSet {
    /// Whether point `i` was found by the thin-organ sweep (false when the input does not say).
    pub fn is_thin_organ(&self, i: usize) -> bool {
        self.thin_organ.get(i).copied().unwrap_or(false)
    }

    /// Whether point `i` fills a gap of the main stereo points (false when the input does not
    /// say).
    pub fn is_gap_fill(&self, i: usize) -> bool {
        self.gap_fill.get(i).copied().unwrap_or(false)
    }

    pub fn len(&self) -> usize {
        self.positions.len()
    }

    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    /// The model's 3D points with their tracks' images.
    pub fn from_reconstruction(model: &Reconstruction) -> Self {
        let mut set = PointSet::default();
        for point in model.points() {
            let mut views: Vec<u32> = point
                .track
                .iter()
                .filter_map(|t| model.image_position(t.image_id).map(|i| i as u32))
                .collect();
            views.sort_unstable();
            views.dedup();
            set.positions.push(point.position_world);
            set.colors.push(point.color);
            set.views.push(views);
            set.point_ids.push(point.id);
        }
        set
    }

    /// Dense points when the scene has them (with visibility), else the model's points. Dense
    /// points keep the model's point3D ids when they are the model's points (row `i` of
    /// `fused.ply` is point3D `i + 1` at the same position, as in Frond's dense workspaces);
    /// otherwise their ids are their rows in `fused.ply`.
    pub fn from_scene(scene: &Scene) -> Self {
        let Some(dense) = scene.dense.as_ref().filter(|d| !d.visible_in.is_empty()) else {
            return Self::from_reconstruction(&scene.reconstruction);
        };
        let model = &scene.reconstruction;
        let mut set = PointSet::default();
        for (i, p) in dense.positions_world.iter().enumerate() {
            let mut views: Vec<u32> = dense.visible_in[i]
                .iter()
                .filter_map(|id| model.image_position(*id).map(|v| v as u32))
                .collect();
            views.sort_unstable();
            views.dedup();
            set.positions.push(p.cast::<f64>());
            set.colors.push(dense.colors[i]);
            set.views.push(views);
            set.point_ids.push(i as u64);
        }
        if dense.thin_organ.len() == set.positions.len() {
            set.thin_organ.clone_from(&dense.thin_organ);
        }
        if dense.gap_fill.len() == set.positions.len() && dense.gap_fill.iter().any(|&f| f) {
            set.gap_fill.clone_from(&dense.gap_fill);
        }
        set.id_kind = PointIds::FusedRow;
        if fused_rows_are_model_points(&set.positions, model) {
            set.id_kind = PointIds::ModelPoint3D;
            for id in &mut set.point_ids {
                *id += 1;
            }
        }
        set
    }

    /// The points that are not gap fills, and the gap fills (each in order); neither says
    /// which points are gap fills any more.
    pub fn split_gap_fills(self) -> (Self, Self) {
        if !self.gap_fill.iter().any(|&f| f) {
            let none = Self {
                id_kind: self.id_kind,
                ..Self::default()
            };
            return (
                Self {
                    gap_fill: Vec::new(),
                    ..self
                },
                none,
            );
        }
        let (fills, main): (Vec<usize>, Vec<usize>) =
            (0..self.len()).partition(|&i| self.is_gap_fill(i));
        let (mut main, mut fills) = (self.subset(&main), self.subset(&fills));
        main.gap_fill.clear();
        fills.gap_fill.clear();
        (main, fills)
    }

    /// A subset in the given order (ids keep their kind).
    pub fn subset(&self, indices: &[usize]) -> Self {
        Self {
            positions: indices.iter().map(|&i| self.positions[i]).collect(),
            colors: indices.iter().map(|&i| self.colors[i]).collect(),
            views: indices.iter().map(|&i| self.views[i].clone()).collect(),
            point_ids: indices.iter().map(|&i| self.point_ids[i]).collect(),
            id_kind: self.id_kind,
            thin_organ: if self.thin_organ.is_empty() {
                Vec::new()
            } else {
                indices.iter().map(|&i| self.is_thin_organ(i)).collect()
            },
            gap_fill: if self.gap_fill.is_empty() {
                Vec::new()
            } else {
                indices.iter().map(|&i| self.is_gap_fill(i)).collect()
            },
        }
    }
}

/// Whether row `i` of the fused points is the model's point3D `i + 1` (same position to
/// float precision) for every row.
fn fused_rows_are_model_points(positions: &[Point3<f64>], model: &Reconstruction) -> bool {
    if positions.is_empty() || model.points().len() != positions.len() {
        return false;
    }
    positions.iter().enumerate().all(|(i, p)| {
        model.point(i as u64 + 1).is_some_and(|q| {
            let tolerance = 1e-5 * (1.0 + p.coords.norm());
            (q.position_world - p).norm() <= tolerance
        })
    })
}

/// Views seen by both sorted lists (merge intersection).
pub fn common_views(a: &[u32], b: &[u32], out: &mut Vec<u32>) {
    out.clear();
    let (mut i, mut j) = (0, 0);
    while i < a.len() && j < b.len() {
        match a[i].cmp(&b[j]) {
            std::cmp::Ordering::Less => i += 1,
            std::cmp::Ordering::Greater => j += 1,
            std::cmp::Ordering::Equal => {
                out.push(a[i]);
                i += 1;
                j += 1;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gap_fills_split_off_in_order() {
        let mut set = PointSet::default();
        for k in 0..5 {
            set.positions.push(Point3::new(k as f64, 0.0, 0.0));
            set.colors.push([k as u8; 3]);
            set.views.push(vec![k as u32]);
            set.point_ids.push(10 + k as u64);
        }
        set.thin_organ = vec![true, false, false, false, false];
        // No fills: everything is the main set.
        let (main, fills) = set.clone().split_gap_fills();
        assert_eq!((main.len(), fills.len()), (5, 0));
        set.gap_fill = vec![false, true, false, true, true];
        assert!(set.is_gap_fill(1) && !set.is_gap_fill(2) && !set.is_gap_fill(9));
        let (main, fills) = set.split_gap_fills();
        assert_eq!(main.point_ids, vec![10, 12]);
        assert_eq!(fills.point_ids, vec![11, 13, 14]);
        assert_eq!(main.thin_organ, vec![true, false]);
        assert_eq!(fills.views, vec![vec![1], vec![3], vec![4]]);
        assert!(main.gap_fill.is_empty() && fills.gap_fill.is_empty());
    }

    #[test]
    fn a_subset_keeps_which_points_the_thin_organ_sweep_found() {
        let mut set = PointSet::default();
        for k in 0..4 {
            set.positions.push(Point3::new(k as f64, 0.0, 0.0));
            set.colors.push([0; 3]);
            set.views.push(vec![0, 1]);
            set.point_ids.push(k);
        }
        assert!(
            !set.is_thin_organ(1),
            "unknown reads as not found by the sweep"
        );
        assert!(set.subset(&[3, 1]).thin_organ.is_empty());
        set.thin_organ = vec![false, true, false, true];
        let subset = set.subset(&[3, 0, 1]);
        assert_eq!(subset.thin_organ, vec![true, false, true]);
        assert!(subset.is_thin_organ(2) && !subset.is_thin_organ(1));
    }

    #[test]
    fn intersection_of_sorted_views() {
        let mut out = Vec::new();
        common_views(&[1, 3, 5, 9], &[2, 3, 9, 10], &mut out);
        assert_eq!(out, vec![3, 9]);
        common_views(&[], &[1], &mut out);
        assert!(out.is_empty());
    }

    #[test]
    fn from_reconstruction_maps_tracks_to_view_positions() {
        let model =
            crate::scene::synthetic::generate(&crate::scene::synthetic::SyntheticModelSpec {
                num_points: 50,
                ..Default::default()
            });
        let set = PointSet::from_reconstruction(&model);
        assert_eq!(set.len(), 50);
        for (i, p) in model.points().iter().enumerate() {
            assert_eq!(set.views[i].len(), p.track.len());
            for &v in &set.views[i] {
                let image = &model.images()[v as usize];
                assert!(p.track.iter().any(|t| t.image_id == image.id));
            }
        }
    }
}
