//! Plant traits (`frond traits`): per-organ measurements of a reconstructed plant (or of a
//! synthetic plant's ground truth, by the same code) as a long table, one row per organ and
//! trait: leaves (area, midrib length, width, perimeter, inclination, azimuth, insertion
//! height, deformation, branch), branches (length, radii, insertion angle and height), the
//! internodes and divergence angles along every axis, and the whole plant (height, crown
//! diameter, hull volume, leaf count and area, projected leaf area from above).
//!
//! Takes a [`PlantOrgans`] (leaf meshes, skeleton records, the up direction) and a
//! [`Scale`]; returns a [`TraitTable`]. Files: `traits.csv` and `traits.json`, one writer
//! each ([`io`]).

pub mod accuracy;
pub mod hull;
pub mod io;
pub mod marker;
pub mod measures;
pub mod phyllotaxis;

use std::collections::BTreeMap;

use nalgebra::{Matrix3, Point2, Point3, SymmetricEigen, Vector3};
use serde::{Deserialize, Serialize};

use crate::branch::plant::SkeletonRecord;
use crate::mesh::TriMesh;

/// Errors of the traits stage.
#[derive(Debug, thiserror::Error)]
pub enum TraitsError {
    #[error("{path}: {message}")]
    Input { path: String, message: String },
    #[error("writing {path}: {message}")]
    Output { path: String, message: String },
    #[error("scale: {0}")]
    Scale(String),
}

/// One leaf as the traits see it.
#[derive(Clone, Debug)]
pub struct LeafOrgan {
    pub id: u32,
    /// World frame (the reconstruction's).
    pub mesh: TriMesh,
    /// Where the leaf meets its petiole, when the reconstruction knows it.
    pub base_world: Option<Point3<f64>>,
    /// The branch the leaf is attached to, and where along it (0 = base, 1 = tip).
    pub branch: Option<(u32, f64)>,
    /// A leaf the reconstruction synthesized (the average leaf posed on a segment too small
    /// to fit, or at a branch tip) rather than fitted to its own points.
    pub synthesized: bool,
    /// For a leaflet: its compound leaf (the report's compound-leaf id; in the truth, the
    /// rachis's branch id).
    pub compound_leaf: Option<u32>,
}

/// What traits are measured from.
#[derive(Clone, Debug)]
pub struct PlantOrgans {
    pub plant: String,
    /// Unit up direction (world frame).
    pub up_world: Vector3<f64>,
    pub leaves: Vec<LeafOrgan>,
    pub branches: Vec<SkeletonRecord>,
}

/// How model units become metres.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Scale {
    /// Metres per model unit.
    pub metres_per_unit: f64,
    /// Where the scale came from, as the user gave it.
    pub source: String,
}

impl Scale {
    /// A factor given directly.
    pub fn factor(metres_per_unit: f64) -> Result<Self, TraitsError> {
        if !(metres_per_unit.is_finite() && metres_per_unit > 0.0) {
            return Err(TraitsError::Scale(format!(
                "the factor must be a positive number of metres per model unit, not {metres_per_unit}"
            )));
        }
        Ok(Self {
            metres_per_unit,
            source: format!("factor {metres_per_unit} m per model unit"),
        })
    }

    /// A known distance between two points of the model: `X1,Y1,Z1:X2,Y2,Z2:METRES` (model
    /// coordinates, e.g. picked on two marker corners or the ends of a ruler).
    pub fn parse_two_points(text: &str) -> Result<Self, TraitsError> {
        let parts: Vec<&str> = text.split(':').collect();
        let point = |s: &str| -> Result<Point3<f64>, TraitsError> {
            let v: Vec<f64> = s
                .split(',')
                .map(|c| c.trim().parse::<f64>())
                .collect::<Result<_, _>>()
                .map_err(|_| TraitsError::Scale(format!("`{s}` is not X,Y,Z")))?;
            match v.as_slice() {
                [x, y, z] if v.iter().all(|c| c.is_finite()) => Ok(Point3::new(*x, *y, *z)),
                _ => Err(TraitsError::Scale(format!("`{s}` is not X,Y,Z"))),
            }
        };
        let [a, b, metres] = parts.as_slice() else {
            return Err(TraitsError::Scale(format!(
                "`{text}`: expected X1,Y1,Z1:X2,Y2,Z2:METRES"
            )));
        };
        let (a, b) = (point(a)?, point(b)?);
        let metres: f64 = metres
            .trim()
            .parse()
            .map_err(|_| TraitsError::Scale(format!("`{metres}` is not a distance in metres")))?;
        let units = (b - a).norm();
        if !positive(units) {
            return Err(TraitsError::Scale(format!(
                "`{text}`: the two points are the same"
            )));
        }
        let mut scale = Self::factor(metres / units)?;
        scale.source = format!("{metres} m between {a} and {b} ({units} model units)");
        Ok(scale)
    }

    /// The cameras travelled a circle of known radius (a turntable, a rail orbit, ROMI's plant
    /// imager): the circle is fitted to the camera centres (plane by PCA, then the centre of
    /// an algebraic least-squares circle in that plane, so a partial arc works, and the mean
    /// distance from it) and its radius in model units set against `radius_metres`. Also returns the fit's RMS residual as a share of
    /// the radius, so a path that is no circle is visible.
    pub fn from_camera_orbit(
        centres_world: &[Point3<f64>],
        radius_metres: f64,
    ) -> Result<(Self, f64), TraitsError> {
        if !(radius_metres.is_finite() && radius_metres > 0.0) {
            return Err(TraitsError::Scale(format!(
                "the orbit radius must be a positive number of metres, not {radius_metres}"
            )));
        }
        if centres_world.len() < 3 {
            return Err(TraitsError::Scale(format!(
                "a circle needs at least 3 camera centres, the scene has {}",
                centres_world.len()
            )));
        }
        let n = centres_world.len() as f64;
        let centroid = centres_world
            .iter()
            .fold(Vector3::zeros(), |s, c| s + c.coords)
            / n;
        let mut covariance = Matrix3::zeros();
        for c in centres_world {
            let d = c.coords - centroid;
            covariance += d * d.transpose();
        }
        let eigen = SymmetricEigen::new(covariance / n);
        let mut order = [0usize, 1, 2];
        order.sort_by(|a, b| eigen.eigenvalues[*b].total_cmp(&eigen.eigenvalues[*a]));
        let (u, v) = (
            eigen.eigenvectors.column(order[0]).into_owned(),
            eigen.eigenvectors.column(order[1]).into_owned(),
        );
        let planar: Vec<Point2<f64>> = centres_world
            .iter()
            .map(|c| {
                let d = c.coords - centroid;
                Point2::new(d.dot(&u), d.dot(&v))
            })
            .collect();
        let on_circle: Vec<(f64, f64, usize)> = planar.iter().map(|p| (p.x, p.y, 0)).collect();
        let (cx, cy) =
            crate::util::geometry::concentric_circle_centre(&on_circle, 1).ok_or_else(|| {
                TraitsError::Scale("the camera centres lie on a line, not a circle".into())
            })?;
        let centre = Point2::new(cx, cy);
        let radius = planar.iter().map(|p| (p - centre).norm()).sum::<f64>() / n;
        if !positive(radius) {
            return Err(TraitsError::Scale(
                "the camera centres fit no circle".into(),
            ));
        }
        let residual = (planar
            .iter()
            .map(|p| ((p - centre).norm() - radius).powi(2))
            .sum::<f64>()
            / n)
            .sqrt()
            / radius;
        let mut scale = Self::factor(radius_metres / radius)?;
        scale.source = format!(
            "cameras on a circle of {radius_metres} m ({radius} model units, RMS residual {:.1} % of the radius, {} cameras)",
            100.0 * residual,
            centres_world.len()
        );
        Ok((scale, residual))
    }
}

/// One row of the long table.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TraitRow {
    pub plant: String,
    pub organ_id: String,
    /// `leaf`, `stem`, `branch`, `internode` or `plant`.
    pub organ_type: String,
    #[serde(rename = "trait")]
    pub trait_name: String,
    pub value: f64,
    pub unit: String,
}

/// A plant's traits.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TraitTable {
    pub format: String,
    pub version: u32,
    pub plant: String,
    /// `None`: the values are in model units (COLMAP models are up to scale).
    pub scale: Option<Scale>,
    pub up_world: [f64; 3],
    pub rows: Vec<TraitRow>,
}

pub const TRAITS_FORMAT: &str = "frond traits";
pub const TRAITS_VERSION: u32 = 1;

impl TraitTable {
    /// The value of one organ's trait.
    pub fn value(&self, organ_id: &str, trait_name: &str) -> Option<f64> {
        self.rows
            .iter()
            .find(|r| r.organ_id == organ_id && r.trait_name == trait_name)
            .map(|r| r.value)
    }
}

/// Organ ids as the table writes them (`leaf_003`, `branch_012`, the glb node names).
pub fn leaf_organ_id(id: u32) -> String {
    format!("leaf_{id:03}")
}

pub fn branch_organ_id(id: u32) -> String {
    format!("branch_{id:03}")
}

#[derive(Clone, Copy)]
enum Kind {
    Length,
    Area,
    Volume,
    Angle,
    Count,
    Id,
    Flag,
}

struct Units {
    factor: f64,
    metric: bool,
}

impl Units {
    fn convert(&self, kind: Kind, value: f64) -> (f64, String) {
        let suffix = |power: i32| -> String {
            match (self.metric, power) {
                (true, 1) => "m".into(),
                (true, p) => format!("m{p}"),
                (false, 1) => "model units".into(),
                (false, p) => format!("model units^{p}"),
            }
        };
        match kind {
            Kind::Length => (value * self.factor, suffix(1)),
            Kind::Area => (value * self.factor.powi(2), suffix(2)),
            Kind::Volume => (value * self.factor.powi(3), suffix(3)),
            Kind::Angle => (value, "deg".into()),
            Kind::Count => (value, "count".into()),
            Kind::Id => (value, "id".into()),
            Kind::Flag => (value, "flag".into()),
        }
    }
}

/// Measurements of one leaf (model units, degrees).
#[derive(Clone, Debug, PartialEq)]
pub struct LeafTraits {
    pub area: f64,
    pub length: f64,
    pub width: f64,
    pub perimeter: f64,
    pub inclination_deg: f64,
    pub azimuth_deg: f64,
    pub base_world: Point3<f64>,
    pub tip_world: Point3<f64>,
    pub normal_world: Vector3<f64>,
    /// RMS distance of the leaf surface from its fitted plane.
    pub deformation: f64,
}

/// Area-weighted vertex weights of a mesh (a third of each incident triangle's area).
fn vertex_weights(mesh: &TriMesh) -> Vec<f64> {
    let mut w = vec![0.0; mesh.positions.len()];
    for (t, tri) in mesh.triangles.iter().enumerate() {
        let a = mesh.triangle_area(t) as f64 / 3.0;
        for &v in tri {
            if let Some(slot) = w.get_mut(v as usize) {
                *slot += a;
            }
        }
    }
    w
}

/// A horizontal frame (east, north) for azimuths: world x projected on the horizontal plane
/// (world y where x is vertical), and up × east.
fn horizontal_frame(up: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
    let mut east = Vector3::x() - up * up.x;
    if east.norm() < 1e-6 {
        east = Vector3::y() - up * up.y;
    }
    let east = east.normalize();
    (east, up.cross(&east))
}

/// The slice centroids `raw` moved across the leaf (along `minor`) onto the least-squares
/// quadratic of their across offset in their position along `major` (both from `centroid`);
/// with fewer than three slices, or slices all at one position, onto their mean offset.
fn across_quadratic(
    raw: &[Point3<f64>],
    centroid: &Point3<f64>,
    major: &Vector3<f64>,
    minor: &Vector3<f64>,
) -> Vec<Point3<f64>> {
    let along: Vec<f64> = raw.iter().map(|p| (p - centroid).dot(major)).collect();
    let across: Vec<f64> = raw.iter().map(|p| (p - centroid).dot(minor)).collect();
    let mean = across.iter().sum::<f64>() / across.len().max(1) as f64;
    let mut normal_matrix = Matrix3::zeros();
    let mut right = Vector3::zeros();
    for (t, y) in along.iter().zip(&across) {
        let row = Vector3::new(1.0, *t, t * t);
        normal_matrix += row * row.transpose();
        right += row * *y;
    }
    let fitted = (raw.len() >= 3)
        .then(|| normal_matrix.try_inverse())
        .flatten()
        .map(|inverse| inverse * right);
    raw.iter()
        .zip(along.iter().zip(&across))
        .map(|(p, (t, y))| {
            let target = fitted.map_or(mean, |c| c[0] + c[1] * t + c[2] * t * t);
            p + minor * (target - y)
        })
        .collect()
}

/// Measures one leaf. The midrib follows the leaf's main axis: the area-weighted centroids of
/// 16 slices across it, from the extreme vertex at the base end to the one at the tip end.
/// The base end is the one nearer `base_world` (or, without it, nearer `axis_world`, a point
/// on the plant's axis). `None` for a mesh without area.
pub fn leaf_traits(
    mesh: &TriMesh,
    base_world: Option<Point3<f64>>,
    axis_world: &Point3<f64>,
    up: &Vector3<f64>,
) -> Option<LeafTraits> {
    let area = mesh.area();
    if !positive(area) || mesh.positions.is_empty() {
        return None;
    }
    let points: Vec<Point3<f64>> = mesh.positions.iter().map(|p| p.cast::<f64>()).collect();
    let weights = vertex_weights(mesh);
    let total: f64 = weights.iter().sum();
    if !positive(total) {
        return None;
    }
    let centroid = Point3::from(
        points
            .iter()
            .zip(&weights)
            .map(|(p, w)| p.coords * *w)
            .sum::<Vector3<f64>>()
            / total,
    );
    let mut covariance = Matrix3::zeros();
    for (p, w) in points.iter().zip(&weights) {
        let d = p - centroid;
        covariance += d * d.transpose() * *w;
    }
    let eigen = SymmetricEigen::new(covariance / total);
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| eigen.eigenvalues[b].total_cmp(&eigen.eigenvalues[a]));
    let major: Vector3<f64> = eigen.eigenvectors.column(order[0]).into_owned();
    let minor: Vector3<f64> = eigen.eigenvectors.column(order[1]).into_owned();
    let normal: Vector3<f64> = eigen.eigenvectors.column(order[2]).into_owned();
    let along: Vec<f64> = points.iter().map(|p| (p - centroid).dot(&major)).collect();
    let (lo, hi) = along
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &t| {
            (lo.min(t), hi.max(t))
        });
    const SLICES: usize = 16;
    let span = (hi - lo).max(f64::MIN_POSITIVE);
    let slice_of = |t: f64| {
        (((t - lo) / span) * SLICES as f64)
            .floor()
            .clamp(0.0, (SLICES - 1) as f64) as usize
    };
    let mut widths = vec![(f64::INFINITY, f64::NEG_INFINITY); SLICES];
    for (p, t) in points.iter().zip(&along) {
        let s = (p - centroid).dot(&minor);
        let k = slice_of(*t);
        widths[k] = (widths[k].0.min(s), widths[k].1.max(s));
    }
    // Slice centroids from points sampled uniformly on the surface (vertex centroids follow
    // the mesh's tessellation, not its shape).
    let mut rng = crate::util::rng::Rng::seed_from(1);
    let mut sums = vec![(Vector3::zeros(), 0.0f64); SLICES];
    for sample in mesh.sample_surface(200 * SLICES, &mut rng) {
        let p = sample.position.cast::<f64>();
        let k = slice_of((p - centroid).dot(&major));
        sums[k].0 += p.coords;
        sums[k].1 += 1.0;
    }
    let raw: Vec<Point3<f64>> = sums
        .iter()
        .filter(|(_, w)| *w > 0.0)
        .map(|(s, w)| Point3::from(s / *w))
        .collect();
    // Across the leaf's width the midrib is a quadratic in the position along the leaf (a
    // leaf curving to one side keeps its arc), fitted by least squares to the slices'
    // centroids: an outline wider on one side here and on the other there (a fitted or a
    // damaged leaf) shifts the centroids from side to side, and sampling noise zigzags them;
    // neither is the midrib, and both would lengthen it. Bending lies along the normal and is
    // kept as measured.
    let centroids = across_quadratic(&raw, &centroid, &major, &minor);
    let (Some(first), Some(last)) = (centroids.first(), centroids.last()) else {
        return None;
    };
    // The midrib's ends: from the end slices' centroids, on along the midrib's direction
    // there until the leaf's extent along its axis (at most two slices further).
    let slice_width = span / SLICES as f64;
    let extend = |end: &Point3<f64>, inner: Option<&Point3<f64>>, target: f64| {
        let t_end = (end - centroid).dot(&major);
        let outward = if target >= t_end { major } else { -major };
        let direction = inner
            .and_then(|q| (end - q).try_normalize(1e-12))
            .filter(|d| d.dot(&outward) > 0.5)
            .unwrap_or(outward);
        let step = ((target - t_end) / direction.dot(&major))
            .abs()
            .min(2.0 * slice_width);
        end + direction * step
    };
    let second_last = centroids
        .len()
        .checked_sub(2)
        .and_then(|k| centroids.get(k));
    let low_end = extend(first, centroids.get(1), lo);
    let high_end = extend(last, second_last, hi);
    let mut midrib = vec![low_end];
    midrib.extend(centroids.iter().copied());
    midrib.push(high_end);
    let reference = base_world.unwrap_or(*axis_world);
    let base_at_low = (low_end - reference).norm() <= (high_end - reference).norm();
    let length: f64 = midrib.windows(2).map(|w| (w[1] - w[0]).norm()).sum();
    let width = widths
        .iter()
        .filter(|(a, b)| a.is_finite() && b.is_finite())
        .map(|(a, b)| b - a)
        .fold(0.0, f64::max);
    let perimeter: f64 = mesh
        .boundary_edges()
        .iter()
        .map(|[a, b]| (points[*a as usize] - points[*b as usize]).norm())
        .sum();
    let (base, tip) = if base_at_low {
        (low_end, high_end)
    } else {
        (high_end, low_end)
    };
    let inclination_deg = normal.dot(up).abs().clamp(0.0, 1.0).acos().to_degrees();
    let (east, north) = horizontal_frame(up);
    let direction = tip - base;
    let azimuth_deg = direction
        .dot(&north)
        .atan2(direction.dot(&east))
        .to_degrees()
        .rem_euclid(360.0);
    let deformation = (points
        .iter()
        .zip(&weights)
        .map(|(p, w)| (p - centroid).dot(&normal).powi(2) * w)
        .sum::<f64>()
        / total)
        .sqrt();
    Some(LeafTraits {
        area,
        length,
        width,
        perimeter,
        inclination_deg,
        azimuth_deg,
        base_world: base,
        tip_world: tip,
        normal_world: normal,
        deformation,
    })
}

/// Point and unit tangent at arc-length fraction `s` ∈ [0, 1] of a polyline.
pub(crate) fn polyline_at(line: &[[f64; 3]], s: f64) -> Option<(Point3<f64>, Vector3<f64>)> {
    let points: Vec<Point3<f64>> = line.iter().map(|c| Point3::from(*c)).collect();
    if points.len() < 2 {
        return None;
    }
    let lengths: Vec<f64> = points.windows(2).map(|w| (w[1] - w[0]).norm()).collect();
    let total: f64 = lengths.iter().sum();
    if !positive(total) {
        return None;
    }
    let mut target = s.clamp(0.0, 1.0) * total;
    for (k, l) in lengths.iter().enumerate() {
        if target <= *l || k + 1 == lengths.len() {
            let f = if *l > 0.0 {
                (target / l).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let d = points[k + 1] - points[k];
            let tangent = d.try_normalize(1e-15)?;
            return Some((points[k] + d * f, tangent));
        }
        target -= l;
    }
    None
}

/// A branch's length: the spline's arc length when recorded, else its centreline's.
pub fn branch_length(branch: &SkeletonRecord) -> f64 {
    if branch.length > 0.0 {
        branch.length
    } else {
        branch.centerline_length()
    }
}

/// The direction a branch leaves its base: from its first point to the point a tenth of its
/// length along (skipping the first sample's noise).
pub(crate) fn initial_direction(branch: &SkeletonRecord) -> Option<Vector3<f64>> {
    let (start, _) = polyline_at(&branch.centerline, 0.0)?;
    let (ahead, _) = polyline_at(&branch.centerline, 0.1)?;
    (ahead - start).try_normalize(1e-15)
}

/// Every trait of a plant. Angles in degrees; lengths, areas and volumes in metres when a
/// scale is given, else in model units.
pub fn plant_traits(organs: &PlantOrgans, scale: Option<&Scale>) -> TraitTable {
    let units = Units {
        factor: scale.map_or(1.0, |s| s.metres_per_unit),
        metric: scale.is_some(),
    };
    let up = organs
        .up_world
        .try_normalize(1e-12)
        .unwrap_or_else(Vector3::z);
    let mut rows = Vec::new();
    let mut push = |organ_id: &str, organ_type: &str, trait_name: &str, kind: Kind, value: f64| {
        if value.is_finite() {
            let (value, unit) = units.convert(kind, value);
            rows.push(TraitRow {
                plant: organs.plant.clone(),
                organ_id: organ_id.to_owned(),
                organ_type: organ_type.to_owned(),
                trait_name: trait_name.to_owned(),
                value,
                unit,
            });
        }
    };
    // The plant's base (where the stem leaves the soil): the root branch's start, else the lowest
    // organ point.
    let all_points: Vec<Point3<f64>> = organs
        .leaves
        .iter()
        .flat_map(|l| l.mesh.positions.iter().map(|p| p.cast::<f64>()))
        .chain(
            organs
                .branches
                .iter()
                .flat_map(|b| b.centerline.iter().map(|c| Point3::from(*c))),
        )
        .collect();
    let root = organs
        .branches
        .iter()
        .filter(|b| b.parent.is_none())
        .max_by(|a, b| branch_length(a).total_cmp(&branch_length(b)));
    let lowest = all_points
        .iter()
        .min_by(|a, b| a.coords.dot(&up).total_cmp(&b.coords.dot(&up)))
        .copied()
        .unwrap_or_else(Point3::origin);
    let base_world = root
        .and_then(|r| r.centerline.first().map(|c| Point3::from(*c)))
        .unwrap_or(lowest);
    let height_of = |p: &Point3<f64>| (p - base_world).dot(&up);

    // Leaves.
    let mut leaf_traits_by_id = BTreeMap::new();
    for leaf in &organs.leaves {
        let Some(t) = leaf_traits(&leaf.mesh, leaf.base_world, &base_world, &up) else {
            continue;
        };
        let id = leaf_organ_id(leaf.id);
        push(&id, "leaf", "area", Kind::Area, t.area);
        push(&id, "leaf", "length", Kind::Length, t.length);
        push(&id, "leaf", "width", Kind::Length, t.width);
        push(&id, "leaf", "perimeter", Kind::Length, t.perimeter);
        push(&id, "leaf", "inclination", Kind::Angle, t.inclination_deg);
        push(&id, "leaf", "azimuth", Kind::Angle, t.azimuth_deg);
        push(
            &id,
            "leaf",
            "insertion_height",
            Kind::Length,
            height_of(&t.base_world),
        );
        push(&id, "leaf", "deformation", Kind::Length, t.deformation);
        if let Some((branch, _)) = leaf.branch {
            push(&id, "leaf", "branch", Kind::Id, branch as f64);
        }
        if let Some(compound) = leaf.compound_leaf {
            push(&id, "leaf", "compound_leaf", Kind::Id, compound as f64);
        }
        push(
            &id,
            "leaf",
            "synthesized",
            Kind::Flag,
            if leaf.synthesized { 1.0 } else { 0.0 },
        );
        leaf_traits_by_id.insert(leaf.id, t);
    }

    // Branches.
    let by_id: BTreeMap<u32, &SkeletonRecord> = organs.branches.iter().map(|b| (b.id, b)).collect();
    for branch in &organs.branches {
        let id = branch_organ_id(branch.id);
        let kind = if branch.parent.is_none() {
            "stem"
        } else {
            "branch"
        };
        push(&id, kind, "length", Kind::Length, branch_length(branch));
        push(&id, kind, "base_radius", Kind::Length, branch.radius_start);
        push(&id, kind, "tip_radius", Kind::Length, branch.radius_end);
        if let Some(start) = branch.centerline.first() {
            push(
                &id,
                kind,
                "insertion_height",
                Kind::Length,
                height_of(&Point3::from(*start)),
            );
        }
        let parent = branch.parent.and_then(|p| by_id.get(&p));
        match (parent, initial_direction(branch)) {
            (Some(parent), Some(direction)) => {
                if let Some((_, tangent)) = polyline_at(&parent.centerline, branch.parent_fraction)
                {
                    let angle = tangent.dot(&direction).clamp(-1.0, 1.0).acos().to_degrees();
                    push(&id, kind, "insertion_angle", Kind::Angle, angle);
                }
                push(&id, kind, "parent", Kind::Id, parent.id as f64);
            }
            (None, Some(direction)) => {
                let angle = direction.dot(&up).clamp(-1.0, 1.0).acos().to_degrees();
                push(&id, kind, "inclination", Kind::Angle, angle);
            }
            _ => {}
        }
    }

    // Internodes and divergence angles along every axis, in insertion order: the organs
    // inserted on it are its child branches and the leaves attached to it directly.
    for axis in &organs.branches {
        let inserted = phyllotaxis::inserted_on(axis, organs, |leaf| {
            let t = leaf_traits_by_id.get(&leaf.id)?;
            (t.tip_world - t.base_world).try_normalize(1e-15)
        });
        for (k, pair) in inserted.windows(2).enumerate() {
            let organ_id = format!("{}/internode_{:02}", branch_organ_id(axis.id), k + 1);
            let (internode, signed) = phyllotaxis::interval(axis, &pair[0], &pair[1]);
            push(&organ_id, "internode", "length", Kind::Length, internode);
            if let Some(signed) = signed {
                // Unsigned here: the table does not say which way a spiral turns.
                let angle = signed.min(360.0 - signed);
                push(
                    &organ_id,
                    "internode",
                    "divergence_angle",
                    Kind::Angle,
                    angle,
                );
            }
        }
    }

    // The whole plant.
    let heights: Vec<f64> = all_points.iter().map(height_of).collect();
    if let (Some(top), Some(bottom)) = (
        heights.iter().copied().reduce(f64::max),
        heights.iter().copied().reduce(f64::min),
    ) {
        push(
            "plant",
            "plant",
            "height",
            Kind::Length,
            top - bottom.min(0.0),
        );
    }
    let (east, north) = horizontal_frame(&up);
    let horizontal: Vec<Point2<f64>> = all_points
        .iter()
        .map(|p| Point2::new(p.coords.dot(&east), p.coords.dot(&north)))
        .collect();
    push(
        "plant",
        "plant",
        "crown_diameter",
        Kind::Length,
        hull::diameter_2d(&horizontal),
    );
    // At most 4,000 points for the hull: every k-th, in order.
    let step = all_points.len().div_ceil(4000).max(1);
    let sample: Vec<Point3<f64>> = all_points.iter().step_by(step).copied().collect();
    push(
        "plant",
        "plant",
        "convex_hull_volume",
        Kind::Volume,
        hull::hull_volume(&sample),
    );
    push(
        "plant",
        "plant",
        "leaf_count",
        Kind::Count,
        leaf_traits_by_id.len() as f64,
    );
    let fitted = organs
        .leaves
        .iter()
        .filter(|l| !l.synthesized && leaf_traits_by_id.contains_key(&l.id))
        .count();
    push(
        "plant",
        "plant",
        "fitted_leaf_count",
        Kind::Count,
        fitted as f64,
    );
    let compound_leaves: std::collections::BTreeSet<u32> = organs
        .leaves
        .iter()
        .filter(|l| leaf_traits_by_id.contains_key(&l.id))
        .filter_map(|l| l.compound_leaf)
        .collect();
    push(
        "plant",
        "plant",
        "compound_leaf_count",
        Kind::Count,
        compound_leaves.len() as f64,
    );
    push(
        "plant",
        "plant",
        "total_leaf_area",
        Kind::Area,
        leaf_traits_by_id.values().map(|t| t.area).sum(),
    );
    let lengths: Vec<f64> = leaf_traits_by_id.values().map(|t| t.length).collect();
    push(
        "plant",
        "plant",
        "projected_leaf_area",
        Kind::Area,
        projected_area(&organs.leaves, &up, &lengths),
    );
    TraitTable {
        format: TRAITS_FORMAT.into(),
        version: TRAITS_VERSION,
        plant: organs.plant.clone(),
        scale: scale.cloned(),
        up_world: up.into(),
        rows,
    }
}

/// Leaf area seen from above: the leaves' triangles projected on the horizontal plane and
/// rasterized on a grid of cells 1/100 of the median leaf length (capped at 4096 cells a
/// side), overlaps counted once.
pub fn projected_area(leaves: &[LeafOrgan], up: &Vector3<f64>, leaf_lengths: &[f64]) -> f64 {
    let (east, north) = horizontal_frame(up);
    let project = |p: &Point3<f32>| {
        let p = p.cast::<f64>();
        Point2::new(p.coords.dot(&east), p.coords.dot(&north))
    };
    let triangles: Vec<[Point2<f64>; 3]> = leaves
        .iter()
        .flat_map(|l| {
            l.mesh.triangles.iter().filter_map(|t| {
                let c = t.map(|v| l.mesh.positions.get(v as usize).map(project));
                Some([c[0]?, c[1]?, c[2]?])
            })
        })
        .collect();
    if triangles.is_empty() {
        return 0.0;
    }
    let mut lo = Point2::new(f64::INFINITY, f64::INFINITY);
    let mut hi = Point2::new(f64::NEG_INFINITY, f64::NEG_INFINITY);
    for p in triangles.iter().flatten() {
        lo = lo.inf(p);
        hi = hi.sup(p);
    }
    let mut sorted = leaf_lengths.to_vec();
    sorted.sort_by(f64::total_cmp);
    let median = sorted.get(sorted.len() / 2).copied().unwrap_or(0.0);
    let extent = (hi.x - lo.x).max(hi.y - lo.y);
    if !positive(extent) {
        return 0.0;
    }
    let cell = (median / 100.0).max(extent / 4096.0);
    let nx = ((hi.x - lo.x) / cell).ceil() as usize + 1;
    let ny = ((hi.y - lo.y) / cell).ceil() as usize + 1;
    let mut covered = vec![false; nx * ny];
    for t in &triangles {
        let edge = |a: &Point2<f64>, b: &Point2<f64>, p: &Point2<f64>| {
            (b.x - a.x) * (p.y - a.y) - (b.y - a.y) * (p.x - a.x)
        };
        let area = edge(&t[0], &t[1], &t[2]);
        if area.abs() < 1e-30 {
            continue;
        }
        let (tlo, thi) = (t[0].inf(&t[1]).inf(&t[2]), t[0].sup(&t[1]).sup(&t[2]));
        let x0 = ((tlo.x - lo.x) / cell).floor().max(0.0) as usize;
        let x1 = (((thi.x - lo.x) / cell).ceil() as usize).min(nx - 1);
        let y0 = ((tlo.y - lo.y) / cell).floor().max(0.0) as usize;
        let y1 = (((thi.y - lo.y) / cell).ceil() as usize).min(ny - 1);
        for y in y0..=y1 {
            for x in x0..=x1 {
                let p = Point2::new(
                    lo.x + (x as f64 + 0.5) * cell,
                    lo.y + (y as f64 + 0.5) * cell,
                );
                let w = [
                    edge(&t[1], &t[2], &p),
                    edge(&t[2], &t[0], &p),
                    edge(&t[0], &t[1], &p),
                ];
                if w.iter().all(|v| v * area.signum() >= 0.0) {
                    covered[y * nx + x] = true;
                }
            }
        }
    }
    covered.iter().filter(|c| **c).count() as f64 * cell * cell
}

/// `true` for a positive number (not NaN).
fn positive(x: f64) -> bool {
    x > 0.0
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A flat rectangular leaf `length` × `width` in the plane through the origin spanned by
    /// `along` and `across`, as a grid of quads.
    pub(crate) fn rectangle(
        origin: Point3<f64>,
        along: Vector3<f64>,
        across: Vector3<f64>,
        length: f64,
        width: f64,
    ) -> TriMesh {
        let (nu, nv) = (20usize, 8usize);
        let mut mesh = TriMesh::default();
        for i in 0..=nu {
            for j in 0..=nv {
                let p = origin
                    + along * (length * i as f64 / nu as f64)
                    + across * (width * (j as f64 / nv as f64 - 0.5));
                mesh.positions.push(p.cast::<f32>());
            }
        }
        let index = |i: usize, j: usize| (i * (nv + 1) + j) as u32;
        for i in 0..nu {
            for j in 0..nv {
                mesh.triangles
                    .push([index(i, j), index(i + 1, j), index(i + 1, j + 1)]);
                mesh.triangles
                    .push([index(i, j), index(i + 1, j + 1), index(i, j + 1)]);
            }
        }
        mesh.compute_normals();
        mesh
    }

    fn record(id: u32, parent: Option<u32>, fraction: f64, line: &[[f64; 3]]) -> SkeletonRecord {
        SkeletonRecord {
            id,
            parent,
            parent_fraction: fraction,
            control_points: line.to_vec(),
            radius_start: 0.01,
            radius_end: 0.005,
            length: 0.0,
            centerline: line.to_vec(),
            observed_length: None,
            bridged_length: None,
        }
    }

    #[test]
    fn a_tilted_rectangle_measures_its_size_and_angles() {
        // 0.2 × 0.05, rising at 30° towards +y: its normal is 30° from vertical.
        let tilt = 30f64.to_radians();
        let along = Vector3::new(0.0, tilt.cos(), tilt.sin());
        let mesh = rectangle(Point3::new(0.0, 0.1, 0.5), along, Vector3::x(), 0.2, 0.05);
        let t = leaf_traits(
            &mesh,
            Some(Point3::new(0.0, 0.1, 0.5)),
            &Point3::origin(),
            &Vector3::z(),
        )
        .unwrap();
        assert!((t.area - 0.01).abs() < 1e-6, "{t:?}");
        assert!((t.length - 0.2).abs() < 0.001, "{t:?}");
        assert!((t.width - 0.05).abs() < 0.0001, "{t:?}");
        assert!((t.perimeter - 0.5).abs() < 1e-4, "{t:?}");
        assert!((t.inclination_deg - 30.0).abs() < 0.01, "{t:?}");
        // Base at y = 0.1, tip further along +y: azimuth 90° (north of east).
        assert!((t.azimuth_deg - 90.0).abs() < 0.5, "{t:?}");
        assert!(t.deformation < 1e-6, "{t:?}");
    }

    /// A leaf's traits with its base at the origin, z up.
    fn measured_from_origin(mesh: &TriMesh) -> LeafTraits {
        leaf_traits(
            mesh,
            Some(Point3::origin()),
            &Point3::origin(),
            &Vector3::z(),
        )
        .unwrap()
    }

    #[test]
    fn a_bent_leaf_is_measured_along_its_midrib_and_is_deformed() {
        // A leaf bent in a quarter circle of radius r: midrib length πr/2, chord r√2.
        let r = 0.1;
        let mut mesh = rectangle(Point3::origin(), Vector3::x(), Vector3::y(), 1.0, 0.04);
        for p in &mut mesh.positions {
            let angle = p.x as f64 * std::f64::consts::FRAC_PI_2;
            p.x = (r * angle.sin()) as f32;
            p.z = (r * (1.0 - angle.cos())) as f32;
        }
        let t = measured_from_origin(&mesh);
        let arc = r * std::f64::consts::FRAC_PI_2;
        assert!((t.length - arc).abs() < 0.01 * arc, "{} vs {arc}", t.length);
        assert!(t.deformation > 0.005, "{t:?}");
    }

    #[test]
    fn a_leaf_wider_on_alternate_sides_is_measured_along_its_straight_midrib() {
        // A flat leaf 0.2 long whose straight midrib has an outline 30 % wider on the left in
        // one stretch and on the right in the next (twice over): its slices' centroids swing
        // from side to side, but the midrib is 0.2 long. (A three-slice moving average of the
        // centroids measured 7.0 % more; what is left, 2.4 %, is the ends: the uneven outline
        // tilts the leaf's axis, and its corners then reach further along it.)
        let (length, width) = (0.2, 0.08);
        let mut mesh = rectangle(Point3::origin(), Vector3::x(), Vector3::y(), length, width);
        for p in &mut mesh.positions {
            let along = p.x as f64 / length;
            let swing = 0.3 * (4.0 * std::f64::consts::PI * along).sin();
            let across = p.y as f64;
            let side = if across >= 0.0 {
                1.0 + swing
            } else {
                1.0 - swing
            };
            p.y = (across * side) as f32;
        }
        let t = measured_from_origin(&mesh);
        assert!((t.length - length).abs() < 0.03 * length, "{t:?}");
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(24))]
        /// A leaf's size does not depend on where it is, how it is turned or whether it is
        /// seen in a mirror: the generator's leaves, moved rigidly (and mirrored), measure
        /// the same length, width, area and perimeter.
        #[test]
        fn a_leaf_measures_the_same_wherever_it_is_and_however_it_is_turned(
            leaf_index in 0usize..11,
            axis in (-1.0f64..1.0, -1.0f64..1.0, 0.1f64..1.0),
            angle in 0.0f64..std::f64::consts::TAU,
            shift in (-1.0f64..1.0, -1.0f64..1.0, -1.0f64..1.0),
            mirrored in proptest::bool::ANY,
        ) {
            let plant = crate::synth::plant::generate_plant(crate::synth::Preset::Broadleaf, 1);
            let leaf = &plant.leaves[leaf_index % plant.leaves.len()];
            let base = Point3::from(leaf.world_from_leaf.translation.vector);
            let rotation = nalgebra::Rotation3::from_axis_angle(
                &nalgebra::Unit::new_normalize(Vector3::new(axis.0, axis.1, axis.2)),
                angle,
            );
            let shift = Vector3::new(shift.0, shift.1, shift.2);
            let mirror = if mirrored { -1.0 } else { 1.0 };
            let moved = |p: &Point3<f64>| {
                let q = rotation * p + shift;
                Point3::new(mirror * q.x, q.y, q.z)
            };
            let mut mesh = leaf.mesh.clone();
            for p in &mut mesh.positions {
                *p = moved(&p.cast::<f64>()).cast::<f32>();
            }
            let up = Vector3::z();
            let before = leaf_traits(&leaf.mesh, Some(base), &Point3::origin(), &up).unwrap();
            let after = leaf_traits(&mesh, Some(moved(&base)), &moved(&Point3::origin()), &up)
                .unwrap();
            for (name, a, b) in [
                ("length", before.length, after.length),
                ("width", before.width, after.width),
                ("area", before.area, after.area),
                ("perimeter", before.perimeter, after.perimeter),
            ] {
                proptest::prop_assert!((a - b).abs() <= 0.005 * a, "{name}: {a} vs {b}");
            }
        }
    }

    /// The measurement on the synthetic generator's leaves (bent, cupped, of every shape)
    /// against the lengths it built them with.
    #[test]
    fn midrib_lengths_of_generated_leaves_match_their_construction() {
        use crate::synth::Preset;
        let mut errors = Vec::new();
        for preset in [Preset::Broadleaf, Preset::Medium] {
            for seed in 1..=3 {
                let plant = crate::synth::plant::generate_plant(preset, seed);
                for leaf in &plant.leaves {
                    let base = leaf.world_from_leaf.translation.vector;
                    let t = leaf_traits(
                        &leaf.mesh,
                        Some(Point3::from(base)),
                        &Point3::origin(),
                        &Vector3::z(),
                    )
                    .unwrap();
                    let truth = leaf.geometry.midrib_length();
                    errors.push(((t.length - truth) / truth, preset, seed, leaf.id));
                }
            }
        }
        errors.sort_by(|a, b| a.0.abs().total_cmp(&b.0.abs()));
        let median = errors[errors.len() / 2].0.abs();
        let worst = errors[errors.len() - 1];
        eprintln!("median {median}, worst {worst:?}, n {}", errors.len());
        assert!(median < 0.01, "median {median}");
        assert!(worst.0.abs() < 0.03, "worst {worst:?}");
    }

    #[test]
    fn units_follow_the_scale_and_say_so() {
        let mesh = rectangle(
            Point3::new(0.1, 0.0, 0.2),
            Vector3::x(),
            Vector3::y(),
            0.2,
            0.05,
        );
        let organs = PlantOrgans {
            plant: "p1".into(),
            up_world: Vector3::z(),
            leaves: vec![LeafOrgan {
                id: 4,
                mesh,
                base_world: None,
                branch: Some((0, 0.8)),
                synthesized: false,
                compound_leaf: Some(2),
            }],
            branches: vec![record(0, None, 0.0, &[[0.0, 0.0, 0.0], [0.0, 0.0, 0.3]])],
        };
        let model = plant_traits(&organs, None);
        let area = model
            .rows
            .iter()
            .find(|r| r.organ_id == "leaf_004" && r.trait_name == "area")
            .unwrap();
        assert_eq!(area.unit, "model units^2");
        let scaled = plant_traits(&organs, Some(&Scale::factor(2.0).unwrap()));
        let metric = scaled
            .rows
            .iter()
            .find(|r| r.organ_id == "leaf_004" && r.trait_name == "area")
            .unwrap();
        assert_eq!(metric.unit, "m2");
        assert!((metric.value - 4.0 * area.value).abs() < 1e-12);
        assert_eq!(
            scaled.value("leaf_004", "inclination"),
            model.value("leaf_004", "inclination")
        );
        assert!((scaled.value("branch_000", "length").unwrap() - 0.6).abs() < 1e-12);
        assert!((model.value("plant", "height").unwrap() - 0.3).abs() < 1e-6);
        assert_eq!(model.value("plant", "leaf_count"), Some(1.0));
        assert_eq!(model.value("leaf_004", "branch"), Some(0.0));
        assert_eq!(model.value("leaf_004", "compound_leaf"), Some(2.0));
        assert_eq!(model.value("plant", "compound_leaf_count"), Some(1.0));
        // Seen from above the flat leaf covers its own area (grid cells 1/100 of its length).
        let projected = model.value("plant", "projected_leaf_area").unwrap();
        assert!((projected - 0.01).abs() < 0.0005, "{projected}");
    }

    #[test]
    fn phyllotaxis_along_a_stem_gives_internodes_and_divergence_angles() {
        // A vertical stem with four branches every 0.1, turning 137.5° each.
        let stem = record(0, None, 0.0, &[[0.0, 0.0, 0.0], [0.0, 0.0, 0.5]]);
        let mut branches = vec![stem];
        for k in 0..4u32 {
            let fraction = 0.2 + 0.2 * k as f64;
            let angle = (137.5 * k as f64).to_radians();
            let start = [0.0, 0.0, 0.5 * fraction];
            let end = [0.1 * angle.cos(), 0.1 * angle.sin(), 0.5 * fraction + 0.1];
            branches.push(record(k + 1, Some(0), fraction, &[start, end]));
        }
        let organs = PlantOrgans {
            plant: "p".into(),
            up_world: Vector3::z(),
            leaves: Vec::new(),
            branches,
        };
        let table = plant_traits(&organs, None);
        for k in 1..=3 {
            let id = format!("branch_000/internode_{k:02}");
            assert!((table.value(&id, "length").unwrap() - 0.1).abs() < 1e-9);
            assert!((table.value(&id, "divergence_angle").unwrap() - 137.5).abs() < 1e-6);
        }
        // Each branch rises 45° from the stem.
        assert!((table.value("branch_001", "insertion_angle").unwrap() - 45.0).abs() < 1e-6);
        assert!((table.value("branch_002", "insertion_height").unwrap() - 0.2).abs() < 1e-9);
        assert!(table.value("branch_000", "insertion_angle").is_none());
    }

    #[test]
    fn scales_from_two_points_and_refuses_nonsense() {
        let s = Scale::parse_two_points("0,0,0:3,4,0:0.5").unwrap();
        assert!((s.metres_per_unit - 0.1).abs() < 1e-12);
        assert!(Scale::parse_two_points("0,0,0:0,0,0:1").is_err());
        assert!(Scale::parse_two_points("0,0:1,1,1:1").is_err());
        assert!(Scale::parse_two_points("0,0,0:1,1,1:-1").is_err());
        assert!(Scale::factor(0.0).is_err());
        assert!(Scale::factor(f64::NAN).is_err());
    }

    #[test]
    fn scales_from_a_tilted_partial_camera_orbit() {
        // 20 cameras over 200° of a circle of radius 2.5 model units, tilted and moved; the
        // rig's circle is 0.3 m, so 0.12 m per unit.
        let tilt = nalgebra::Rotation3::from_euler_angles(0.4, -0.2, 1.1);
        let centres: Vec<Point3<f64>> = (0..20)
            .map(|k| {
                let a = (k as f64 * 10.0).to_radians();
                let wobble = 0.01 * ((k * 7 % 5) as f64 - 2.0);
                Point3::new(3.0, -1.0, 0.5)
                    + tilt * Vector3::new((2.5 + wobble) * a.cos(), (2.5 + wobble) * a.sin(), 0.0)
            })
            .collect();
        let (scale, residual) = Scale::from_camera_orbit(&centres, 0.3).unwrap();
        assert!(
            (scale.metres_per_unit - 0.12).abs() < 0.12 * 0.005,
            "{scale:?}"
        );
        assert!(residual < 0.01 && residual > 0.0, "{residual}");
        // A line of cameras is no circle; two cameras are too few; the radius must be positive.
        let line: Vec<Point3<f64>> = (0..5).map(|k| Point3::new(k as f64, 0.0, 0.0)).collect();
        assert!(Scale::from_camera_orbit(&line, 0.3).is_err());
        assert!(Scale::from_camera_orbit(&centres[..2], 0.3).is_err());
        assert!(Scale::from_camera_orbit(&centres, -1.0).is_err());
    }
}
