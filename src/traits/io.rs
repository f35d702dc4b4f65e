//! Reading what traits are measured from (a reconstruction's output folder, a synthetic
//! dataset's ground truth) and writing `traits.csv` / `traits.json` (the only writers).

use std::path::Path;

use nalgebra::{Point3, Vector3};
use serde::Deserialize;

use super::{
    LeafOrgan, PlantOrgans, TRAITS_FORMAT, TRAITS_VERSION, TraitRow, TraitTable, TraitsError,
};
use crate::branch::plant::{SkeletonFile, SkeletonRecord};
use crate::mesh::TriMesh;
use crate::pipeline::ReconstructionReport;
use crate::pipeline::files::SegmentsFile;
use crate::util::atomic::write_atomic;

pub const TRAITS_CSV: &str = "traits.csv";
pub const TRAITS_JSON: &str = "traits.json";
/// The CSV header, in column order.
pub const CSV_COLUMNS: [&str; 6] = ["plant", "organ_id", "organ_type", "trait", "value", "unit"];

fn input(path: &Path, message: impl std::fmt::Display) -> TraitsError {
    TraitsError::Input {
        path: path.display().to_string(),
        message: message.to_string(),
    }
}

fn output(path: &Path, message: impl std::fmt::Display) -> TraitsError {
    TraitsError::Output {
        path: path.display().to_string(),
        message: message.to_string(),
    }
}

/// The organs of a `frond reconstruct` output folder: leaf meshes from `plant.glb`, the branch
/// tree from `skeleton.json`, the up direction from `segments.json`, leaf bases and the
/// branch each leaf is attached to from `report.json`.
pub fn read_reconstruction(out: &Path, plant: &str) -> Result<PlantOrgans, TraitsError> {
    let segments_path = out.join(crate::pipeline::files::SEGMENTS_FILE);
    let segments = SegmentsFile::read(&segments_path).map_err(|e| input(&segments_path, e))?;
    let report_path = out.join("report.json");
    let report = ReconstructionReport::read(&report_path).map_err(|e| input(&report_path, e))?;
    let skeleton_path = out.join("skeleton.json");
    let branches = SkeletonFile::read(&skeleton_path)
        .map_err(|e| input(&skeleton_path, e))?
        .branches;
    let glb_path = out.join("plant.glb");
    let bytes = std::fs::read(&glb_path).map_err(|e| input(&glb_path, e))?;
    let nodes =
        crate::model::gltf::read_glb_meshes(&bytes, &glb_path).map_err(|e| input(&glb_path, e))?;
    let mut leaves = Vec::new();
    for node in nodes {
        let Some(id) = node
            .name
            .strip_prefix("leaf_")
            .and_then(|s| s.parse::<u32>().ok())
        else {
            continue;
        };
        let fitted = report.leaves.iter().find(|l| l.segment == id);
        let mut base_world = fitted.map(|l| Point3::from(l.base));
        // Every fitted leaf's branch (reports before it was recorded: petioles only).
        let mut branch = report
            .attachment
            .leaves
            .iter()
            .find(|l| l.leaf == id)
            .map(|l| (l.branch, l.parent_fraction))
            .or_else(|| {
                report
                    .attachment
                    .petioles
                    .iter()
                    .find(|p| p.leaf == id)
                    .map(|p| (p.branch, p.parent_fraction))
            });
        if fitted.is_none() {
            // A posed leaf: the posed record whose base is nearest the mesh.
            let nearest = report.attachment.posed.iter().min_by(|a, b| {
                distance_to_vertices(&node.mesh, &Point3::from(a.base))
                    .total_cmp(&distance_to_vertices(&node.mesh, &Point3::from(b.base)))
            });
            if let Some(posed) = nearest {
                base_world = Some(Point3::from(posed.base));
                branch = Some((posed.branch, 1.0));
            }
        }
        let compound_leaf = report
            .compound_leaves
            .iter()
            .find(|c| c.leaflets.contains(&id))
            .map(|c| c.id);
        leaves.push(LeafOrgan {
            id,
            mesh: node.mesh,
            base_world,
            branch,
            synthesized: fitted.is_none(),
            compound_leaf,
        });
    }
    let mut branches = branches;
    extend_to_tip_leaves(&mut branches, &mut leaves, &report.attachment.petioles);
    Ok(PlantOrgans {
        plant: plant.to_owned(),
        up_world: Vector3::from(segments.up),
        leaves,
        branches,
    })
}

/// A petiole leaving its branch at or beyond this arc fraction leaves from the tip.
const TIP_FRACTION: f64 = 0.999;

/// A branch whose tip carries a leaf is the organ up to that leaf: the skeleton ends where
/// the branch's own points end (the leaf's segment takes the top of a petiole, the level sets
/// stop half a level short of a tip), and the model draws a petiole from there to the leaf
/// (`report.json`'s `attachment.petioles` at fraction 1). The branch runs on to the point of
/// the leaf's surface nearest its tip, where the petiole meets the blade (not to the fitted
/// base point, the template's base, which on semi-dense broadleaf plants lies a median
/// 8–25 mm from the true base of a 15–20 cm leaf); of several leaves there, the nearest.
/// The insertion fractions on the branch (its children's and its leaves') are rescaled to
/// the longer branch, so every insertion keeps its place, and the tip leaf sits at 1.
fn extend_to_tip_leaves(
    branches: &mut [SkeletonRecord],
    leaves: &mut [LeafOrgan],
    petioles: &[crate::pipeline::PetioleRecord],
) {
    let mut extended: Vec<(u32, f64, u32)> = Vec::new();
    for branch in branches.iter_mut() {
        let Some(tip_world) = branch.centerline.last().map(|p| Point3::from(*p)) else {
            continue;
        };
        let nearest_leaf = petioles
            .iter()
            .filter(|p| p.branch == branch.id && p.parent_fraction >= TIP_FRACTION)
            .filter_map(|p| {
                let leaf = leaves.iter().find(|l| l.id == p.leaf)?;
                let meets_world = nearest_on_mesh(&leaf.mesh, &tip_world).or(leaf.base_world)?;
                Some((leaf.id, meets_world))
            })
            .map(|(leaf, meets_world)| ((meets_world - tip_world).norm(), meets_world, leaf))
            .filter(|(gap, _, _)| gap.is_finite() && *gap > 0.0)
            .min_by(|a, b| a.0.total_cmp(&b.0).then(a.2.cmp(&b.2)));
        let Some((gap, meets_world, leaf)) = nearest_leaf else {
            continue;
        };
        let length = super::branch_length(branch);
        if !length.is_finite() || length <= 0.0 {
            continue;
        }
        branch
            .centerline
            .push([meets_world.x, meets_world.y, meets_world.z]);
        branch.length = length + gap;
        extended.push((branch.id, length / branch.length, leaf));
    }
    for (id, shrink, tip_leaf) in extended {
        for child in branches.iter_mut().filter(|b| b.parent == Some(id)) {
            child.parent_fraction *= shrink;
        }
        for leaf in leaves.iter_mut() {
            if let Some((branch, fraction)) = leaf.branch.as_mut()
                && *branch == id
            {
                *fraction = if leaf.id == tip_leaf {
                    1.0
                } else {
                    *fraction * shrink
                };
            }
        }
    }
}

/// The point of a mesh's surface nearest `p` (`None` for a mesh without triangles).
fn nearest_on_mesh(mesh: &TriMesh, p: &Point3<f64>) -> Option<Point3<f64>> {
    let query = p.cast::<f32>();
    let vertex = |i: u32| mesh.positions.get(i as usize);
    mesh.triangles
        .iter()
        .filter_map(|t| {
            let (a, b, c) = (vertex(t[0])?, vertex(t[1])?, vertex(t[2])?);
            let q = crate::mesh::closest_point_on_triangle(&query, a, b, c);
            Some(((q - query).norm(), q))
        })
        .min_by(|x, y| x.0.total_cmp(&y.0))
        .map(|(_, q)| q.cast::<f64>())
}

fn distance_to_vertices(mesh: &TriMesh, p: &Point3<f64>) -> f64 {
    mesh.positions
        .iter()
        .map(|v| (v.cast::<f64>() - p).norm())
        .fold(f64::INFINITY, f64::min)
}

#[derive(Deserialize)]
struct GtLeaf {
    id: u32,
    mesh: String,
    base: [f64; 3],
    #[serde(default)]
    branch: Option<u32>,
    #[serde(default)]
    compound_leaf: Option<u32>,
}

/// The organs of a synthetic dataset's ground truth (`gt/leaves.json` and its meshes,
/// `gt/branches.json`; z is up in the synthetic world). Each leaf sits at the tip of its
/// petiole branch.
pub fn read_ground_truth(dataset: &Path, plant: &str) -> Result<PlantOrgans, TraitsError> {
    let gt = dataset.join("gt");
    let leaves_path = gt.join("leaves.json");
    let text = std::fs::read_to_string(&leaves_path).map_err(|e| input(&leaves_path, e))?;
    let records: Vec<GtLeaf> = serde_json::from_str(&text).map_err(|e| input(&leaves_path, e))?;
    let mut leaves = Vec::with_capacity(records.len());
    for record in records {
        let path = gt.join(&record.mesh);
        let mesh = TriMesh::read_ply(&path).map_err(|e| input(&path, e))?;
        leaves.push(LeafOrgan {
            id: record.id,
            mesh,
            base_world: Some(Point3::from(record.base)),
            branch: record.branch.map(|b| (b, 1.0)),
            synthesized: false,
            compound_leaf: record.compound_leaf,
        });
    }
    let branches_path = gt.join("branches.json");
    let mut branches = SkeletonFile::read(&branches_path)
        .map_err(|e| input(&branches_path, e))?
        .branches;
    if let Some(soil_height) = soil_height(dataset)? {
        cut_at_the_soil(&mut branches, soil_height);
    }
    Ok(PlantOrgans {
        plant: plant.to_owned(),
        up_world: Vector3::z(),
        leaves,
        branches,
    })
}

/// The height of a synthetic dataset's soil surface (`meta.json`'s `plant.pot.soil_height`);
/// `None` without a `meta.json` or a pot in it.
fn soil_height(dataset: &Path) -> Result<Option<f64>, TraitsError> {
    let path = dataset.join("meta.json");
    let text = match std::fs::read_to_string(&path) {
        Ok(text) => text,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(input(&path, e)),
    };
    let meta: serde_json::Value = serde_json::from_str(&text).map_err(|e| input(&path, e))?;
    Ok(meta["plant"]["pot"]["soil_height"].as_f64())
}

/// The truth's stems as a photo shows them: from where they leave the soil (`soil_height`, z
/// up). The generator plants each stem 10 mm deep, while a reconstruction roots its stem on
/// the soil surface, so heights (insertion heights, the plant's height) are measured from one
/// datum and a stem's length is its length above the soil. Each root branch that starts below
/// the soil loses its centreline up to where it crosses it; its length, base radius (linear
/// along it), control points and its children's insertion fractions follow. Side branches are
/// left as they are; a root branch entirely below the soil too.
fn cut_at_the_soil(branches: &mut [SkeletonRecord], soil_height: f64) {
    let mut cuts: Vec<(u32, f64)> = Vec::new();
    for branch in branches.iter_mut().filter(|b| b.parent.is_none()) {
        let line = &branch.centerline;
        let Some(first_above) = line.iter().position(|c| c[2] >= soil_height) else {
            continue;
        };
        if first_above == 0 {
            continue;
        }
        let old_length = branch.centerline_length();
        let (a, b) = (
            Point3::from(line[first_above - 1]),
            Point3::from(line[first_above]),
        );
        let t = (soil_height - a.z) / (b.z - a.z);
        let crossing = a + (b - a) * t;
        let removed = line[..first_above]
            .windows(2)
            .map(|w| (Point3::from(w[1]) - Point3::from(w[0])).norm())
            .sum::<f64>()
            + (crossing - a).norm();
        if !(old_length > 0.0 && removed < old_length) {
            continue;
        }
        let mut centerline = vec![[crossing.x, crossing.y, crossing.z]];
        centerline.extend_from_slice(&line[first_above..]);
        branch.centerline = centerline;
        let share = removed / old_length;
        branch.radius_start += (branch.radius_end - branch.radius_start) * share;
        if branch.length > 0.0 {
            branch.length *= 1.0 - share;
        }
        let mut control_points = vec![[crossing.x, crossing.y, crossing.z]];
        control_points.extend(
            branch
                .control_points
                .iter()
                .filter(|c| c[2] > soil_height)
                .copied(),
        );
        branch.control_points = control_points;
        cuts.push((branch.id, share));
    }
    for (parent, share) in cuts {
        for child in branches.iter_mut().filter(|b| b.parent == Some(parent)) {
            child.parent_fraction =
                ((child.parent_fraction - share) / (1.0 - share)).clamp(0.0, 1.0);
        }
    }
}

/// One CSV field: quoted when it holds a comma, quote or line break (RFC 4180).
fn csv_field(text: &str) -> String {
    if text.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", text.replace('"', "\"\""))
    } else {
        text.to_owned()
    }
}

/// The long table as CSV text (header first).
pub fn csv_text(rows: &[TraitRow]) -> String {
    let mut text = CSV_COLUMNS.join(",");
    text.push('\n');
    for r in rows {
        let fields = [
            csv_field(&r.plant),
            csv_field(&r.organ_id),
            csv_field(&r.organ_type),
            csv_field(&r.trait_name),
            format!("{}", r.value),
            csv_field(&r.unit),
        ];
        text.push_str(&fields.join(","));
        text.push('\n');
    }
    text
}

/// Writes `traits.csv` and `traits.json` into `dir`, each atomically.
pub fn write_traits(dir: &Path, table: &TraitTable) -> Result<(), TraitsError> {
    std::fs::create_dir_all(dir).map_err(|e| output(dir, e))?;
    let csv = dir.join(TRAITS_CSV);
    write_atomic(&csv, csv_text(&table.rows).as_bytes()).map_err(|e| output(&csv, e))?;
    let json = dir.join(TRAITS_JSON);
    let text = serde_json::to_string_pretty(table).map_err(|e| output(&json, e))?;
    write_atomic(&json, text.as_bytes()).map_err(|e| output(&json, e))
}

/// Reads and checks a `traits.json`.
pub fn read_traits(path: &Path) -> Result<TraitTable, TraitsError> {
    let text = std::fs::read_to_string(path).map_err(|e| input(path, e))?;
    let table: TraitTable = serde_json::from_str(&text).map_err(|e| input(path, e))?;
    if table.format != TRAITS_FORMAT || table.version != TRAITS_VERSION {
        return Err(input(
            path,
            format!(
                "is `{}` version {}, expected `{TRAITS_FORMAT}` version {TRAITS_VERSION}",
                table.format, table.version
            ),
        ));
    }
    Ok(table)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn straight(
        id: u32,
        parent: Option<u32>,
        fraction: f64,
        a: [f64; 3],
        b: [f64; 3],
    ) -> SkeletonRecord {
        let samples = 11;
        let centerline: Vec<[f64; 3]> = (0..samples)
            .map(|k| {
                let t = k as f64 / (samples - 1) as f64;
                [0, 1, 2].map(|i| a[i] + t * (b[i] - a[i]))
            })
            .collect();
        SkeletonRecord {
            id,
            parent,
            parent_fraction: fraction,
            control_points: vec![a, b],
            radius_start: 0.003,
            radius_end: 0.002,
            length: (Point3::from(b) - Point3::from(a)).norm(),
            centerline,
            observed_length: None,
            bridged_length: None,
        }
    }

    fn leaf_at(id: u32, base: [f64; 3], branch: u32, fraction: f64) -> LeafOrgan {
        LeafOrgan {
            id,
            mesh: TriMesh::default(),
            base_world: Some(Point3::from(base)),
            branch: Some((branch, fraction)),
            synthesized: false,
            compound_leaf: None,
        }
    }

    fn petiole(
        leaf: u32,
        branch: u32,
        parent_fraction: f64,
        length: f64,
    ) -> crate::pipeline::PetioleRecord {
        crate::pipeline::PetioleRecord {
            leaf,
            branch,
            parent_fraction,
            length,
            observed_length: None,
            bridged_length: None,
        }
    }

    #[test]
    fn a_branch_runs_on_to_the_leaf_at_its_tip_and_its_insertions_keep_their_place() {
        // A 0.3 stem with a 0.1 side branch at its middle; the side branch's points stop
        // 0.02 short of its leaf, a second leaf hangs 0.05 beyond its tip, a third from its
        // middle, and a fourth from the stem's middle.
        let mut branches = vec![
            straight(0, None, 0.0, [0.0, 0.0, 0.0], [0.0, 0.0, 0.3]),
            straight(1, Some(0), 0.5, [0.0, 0.0, 0.15], [0.1, 0.0, 0.15]),
            straight(2, Some(1), 0.4, [0.04, 0.0, 0.15], [0.04, 0.05, 0.15]),
        ];
        let mut leaves = vec![
            leaf_at(10, [0.12, 0.0, 0.15], 1, 1.0),
            leaf_at(11, [0.15, 0.0, 0.15], 1, 1.0),
            leaf_at(12, [0.06, 0.03, 0.15], 1, 0.6),
            leaf_at(13, [0.03, 0.0, 0.15], 0, 0.5),
        ];
        let petioles = vec![
            petiole(11, 1, 1.0, 0.05),
            petiole(10, 1, 1.0, 0.02),
            petiole(12, 1, 0.6, 0.03),
            petiole(13, 0, 0.5, 0.03),
        ];
        let stem_before = branches[0].clone();
        extend_to_tip_leaves(&mut branches, &mut leaves, &petioles);
        // The nearest tip leaf ends the branch; the stem, with no leaf at its tip, is as it was.
        assert!((branches[1].length - 0.12).abs() < 1e-12);
        assert_eq!(branches[1].centerline.last(), Some(&[0.12, 0.0, 0.15]));
        assert!((branches[1].centerline_length() - 0.12).abs() < 1e-12);
        assert_eq!(branches[0], stem_before);
        // Insertions stay where they were: 0.04 and 0.06 along, now of 0.12.
        assert!((branches[2].parent_fraction - 0.04 / 0.12).abs() < 1e-12);
        let fraction = |id: u32| leaves.iter().find(|l| l.id == id).unwrap().branch.unwrap();
        assert_eq!(fraction(10), (1, 1.0));
        assert!((fraction(11).1 - 0.1 / 0.12).abs() < 1e-12);
        assert!((fraction(12).1 - 0.06 / 0.12).abs() < 1e-12);
        assert_eq!(fraction(13), (0, 0.5));
        // The traits see the longer branch.
        let organs = PlantOrgans {
            plant: "p".into(),
            up_world: Vector3::z(),
            leaves,
            branches,
        };
        let table = crate::traits::plant_traits(&organs, None);
        let length = table.value("branch_001", "length").unwrap();
        assert!((length - 0.12).abs() < 1e-12, "{length}");
    }

    #[test]
    fn a_branch_runs_on_to_where_its_leaf_blade_begins() {
        // The leaf's blade begins 0.01 beyond the tip; its fitted base point lies 0.03 inside.
        let mut branches = vec![straight(0, None, 0.0, [0.0, 0.0, 0.0], [0.0, 0.0, 0.1])];
        let mut leaf = leaf_at(5, [0.0, 0.0, 0.14], 0, 1.0);
        leaf.mesh.positions = vec![
            Point3::new(-0.02, 0.0, 0.11),
            Point3::new(0.02, 0.0, 0.11),
            Point3::new(0.0, 0.0, 0.2),
        ];
        leaf.mesh.triangles = vec![[0, 1, 2]];
        let mut leaves = vec![leaf];
        extend_to_tip_leaves(&mut branches, &mut leaves, &[petiole(5, 0, 1.0, 0.04)]);
        assert!(
            (branches[0].length - 0.11).abs() < 1e-6,
            "{}",
            branches[0].length
        );
        assert_eq!(leaves[0].branch, Some((0, 1.0)));
    }

    #[test]
    fn the_truths_stem_is_measured_from_where_it_leaves_the_soil() {
        // A stem planted 10 mm deep (z 0.09 to 0.4, soil at 0.1) with a side branch at its
        // middle (its own centreline left as it is).
        let mut branches = vec![
            straight(0, None, 0.0, [0.0, 0.0, 0.09], [0.0, 0.0, 0.4]),
            straight(1, Some(0), 0.5, [0.0, 0.0, 0.245], [0.1, 0.0, 0.245]),
        ];
        branches[0].radius_start = 0.0041;
        branches[0].radius_end = 0.001;
        let side_before = branches[1].centerline.clone();
        cut_at_the_soil(&mut branches, 0.1);
        let stem = &branches[0];
        assert_eq!(stem.centerline.first(), Some(&[0.0, 0.0, 0.1]));
        assert!((stem.centerline_length() - 0.3).abs() < 1e-12);
        assert!((stem.length - 0.3).abs() < 1e-12, "{}", stem.length);
        assert!(
            (stem.radius_start - 0.004).abs() < 1e-12,
            "{}",
            stem.radius_start
        );
        assert_eq!(stem.radius_end, 0.001);
        assert_eq!(stem.control_points, vec![[0.0, 0.0, 0.1], [0.0, 0.0, 0.4]]);
        // The side branch stays where it was on the stem.
        assert!((branches[1].parent_fraction - 0.145 / 0.3).abs() < 1e-12);
        assert_eq!(branches[1].centerline, side_before);
        let organs = PlantOrgans {
            plant: "p".into(),
            up_world: Vector3::z(),
            leaves: Vec::new(),
            branches: branches.clone(),
        };
        let table = crate::traits::plant_traits(&organs, None);
        let height = table.value("branch_001", "insertion_height").unwrap();
        assert!((height - 0.145).abs() < 1e-12, "{height}");
        assert!((table.value("branch_000", "length").unwrap() - 0.3).abs() < 1e-12);
        // A stem standing on the soil, or one wholly under it, is not cut.
        let on_soil = vec![straight(0, None, 0.0, [0.0, 0.0, 0.1], [0.0, 0.0, 0.4])];
        let mut cut = on_soil.clone();
        cut_at_the_soil(&mut cut, 0.1);
        assert_eq!(cut, on_soil);
        cut_at_the_soil(&mut cut, 0.5);
        assert_eq!(cut, on_soil);
    }

    #[test]
    fn the_soil_height_comes_from_the_datasets_meta_when_it_has_a_pot() {
        let dir = tempfile::tempdir().unwrap();
        assert_eq!(soil_height(dir.path()).unwrap(), None);
        let meta = dir.path().join("meta.json");
        std::fs::write(&meta, r#"{"plant": {"pot": {"soil_height": 0.107}}}"#).unwrap();
        assert_eq!(soil_height(dir.path()).unwrap(), Some(0.107));
        std::fs::write(&meta, r#"{"plant": {"height": 0.3}}"#).unwrap();
        assert_eq!(soil_height(dir.path()).unwrap(), None);
        std::fs::write(&meta, "{ not json").unwrap();
        let error = soil_height(dir.path()).unwrap_err().to_string();
        assert!(error.contains("meta.json"), "{error}");
    }

    #[test]
    fn csv_fields_with_commas_and_quotes_are_quoted() {
        let rows = vec![TraitRow {
            plant: "pot 3, \"left\"".into(),
            organ_id: "leaf_001".into(),
            organ_type: "leaf".into(),
            trait_name: "area".into(),
            value: 0.25,
            unit: "m2".into(),
        }];
        let text = csv_text(&rows);
        assert_eq!(
            text,
            "plant,organ_id,organ_type,trait,value,unit\n\"pot 3, \"\"left\"\"\",leaf_001,leaf,area,0.25,m2\n"
        );
    }

    #[test]
    fn traits_json_round_trips_and_refuses_other_files() {
        let dir = tempfile::tempdir().unwrap();
        let table = TraitTable {
            format: TRAITS_FORMAT.into(),
            version: TRAITS_VERSION,
            plant: "a".into(),
            scale: None,
            up_world: [0.0, 0.0, 1.0],
            rows: Vec::new(),
        };
        write_traits(dir.path(), &table).unwrap();
        assert_eq!(read_traits(&dir.path().join(TRAITS_JSON)).unwrap(), table);
        std::fs::write(dir.path().join("x.json"), r#"{"format":"other"}"#).unwrap();
        let err = read_traits(&dir.path().join("x.json"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("x.json"), "{err}");
    }
}
