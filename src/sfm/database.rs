//! Reading a COLMAP feature database (`database.db`, SQLite): the images and their SIFT
//! descriptors, as COLMAP's `feature_extractor` wrote them. Frond matches the descriptors
//! itself ([`super::matching`]) and hands the matches back to COLMAP as a text file for
//! geometric verification, so it never writes the database. Takes the database path; returns
//! [`DatabaseImage`]s with [`Descriptors`].

use std::path::{Path, PathBuf};

use super::matching::Descriptors;

/// Why the database could not be read.
#[derive(Debug, thiserror::Error)]
#[error("{path}: {message}")]
pub struct DatabaseError {
    pub path: PathBuf,
    pub message: String,
}

/// One image of the database, with its descriptors.
#[derive(Clone, Debug)]
pub struct DatabaseImage {
    pub image_id: u32,
    /// The photo's name relative to COLMAP's image folder.
    pub name: String,
    pub camera_id: u32,
    pub descriptors: Descriptors,
    /// Each feature's scale in pixels (empty when the keypoints carry no shape).
    pub scales: Vec<f32>,
}

fn error(path: &Path, message: impl std::fmt::Display) -> DatabaseError {
    DatabaseError {
        path: path.to_path_buf(),
        message: message.to_string(),
    }
}

fn open_read_only(path: &Path) -> Result<rusqlite::Connection, DatabaseError> {
    let flags =
        rusqlite::OpenFlags::SQLITE_OPEN_READ_ONLY | rusqlite::OpenFlags::SQLITE_OPEN_NO_MUTEX;
    rusqlite::Connection::open_with_flags(path, flags).map_err(|e| error(path, e))
}

/// Every image of the database with its descriptors, ordered by name.
pub fn read_images(path: &Path) -> Result<Vec<DatabaseImage>, DatabaseError> {
    let db = open_read_only(path)?;
    let mut statement = db
        .prepare(
            "SELECT images.image_id, images.name, images.camera_id, \
             descriptors.rows, descriptors.cols, descriptors.data, \
             keypoints.rows, keypoints.cols, keypoints.data \
             FROM images LEFT JOIN descriptors ON images.image_id = descriptors.image_id \
             LEFT JOIN keypoints ON images.image_id = keypoints.image_id",
        )
        .map_err(|e| error(path, e))?;
    let rows = statement
        .query_map([], |row| {
            Ok((
                row.get::<_, i64>(0)?,
                row.get::<_, String>(1)?,
                row.get::<_, i64>(2)?,
                row.get::<_, Option<i64>>(3)?,
                row.get::<_, Option<i64>>(4)?,
                row.get::<_, Option<Vec<u8>>>(5)?,
                row.get::<_, Option<i64>>(6)?,
                row.get::<_, Option<i64>>(7)?,
                row.get::<_, Option<Vec<u8>>>(8)?,
            ))
        })
        .map_err(|e| error(path, e))?;
    let mut images = Vec::new();
    for row in rows {
        let (image_id, name, camera_id, count, columns, data, key_rows, key_columns, key_data) =
            row.map_err(|e| error(path, e))?;
        let record = |message: String| error(path, format!("image {image_id} ({name}): {message}"));
        let image_id = u32::try_from(image_id).map_err(|_| record("bad image id".into()))?;
        let camera_id = u32::try_from(camera_id).map_err(|_| record("bad camera id".into()))?;
        let descriptors = match (count, columns, data) {
            (Some(count), Some(columns), Some(data)) => {
                let count = usize::try_from(count).map_err(|_| record("bad row count".into()))?;
                if columns != 128 {
                    return Err(record(format!(
                        "descriptors have {columns} columns (SIFT has 128)"
                    )));
                }
                Descriptors::from_u8(&data, count).map_err(record)?
            }
            _ => Descriptors::default(),
        };
        let scales = match (key_rows, key_columns, key_data) {
            (Some(rows), Some(columns), Some(data)) => {
                keypoint_scales(&data, rows, columns).map_err(record)?
            }
            _ => Vec::new(),
        };
        if !scales.is_empty() && scales.len() != descriptors.len() {
            return Err(record(format!(
                "{} keypoints but {} descriptors",
                scales.len(),
                descriptors.len()
            )));
        }
        images.push(DatabaseImage {
            image_id,
            name,
            camera_id,
            descriptors,
            scales,
        });
    }
    images.sort_by(|a, b| a.name.cmp(&b.name));
    Ok(images)
}

/// Feature scales from COLMAP's keypoint blob (`f32` rows of x, y and then scale and
/// orientation, or the affine shape a11, a12, a21, a22, whose scale is the mean length of its
/// columns); empty for bare points (2 columns).
fn keypoint_scales(bytes: &[u8], rows: i64, columns: i64) -> Result<Vec<f32>, String> {
    let rows = usize::try_from(rows).map_err(|_| "bad keypoint row count".to_owned())?;
    let columns = usize::try_from(columns).map_err(|_| "bad keypoint column count".to_owned())?;
    if !matches!(columns, 2 | 4 | 6) || bytes.len() != rows * columns * 4 {
        return Err(format!(
            "keypoint blob of {} bytes for {rows} × {columns} floats",
            bytes.len()
        ));
    }
    if columns == 2 {
        return Ok(Vec::new());
    }
    let values: Vec<f32> = bytes
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    Ok(values
        .chunks_exact(columns)
        .map(|k| {
            if columns == 4 {
                k[2]
            } else {
                0.5 * ((k[2] * k[2] + k[4] * k[4]).sqrt() + (k[3] * k[3] + k[5] * k[5]).sqrt())
            }
        })
        .collect())
}

/// Verified two-view geometries in the database: (pairs with inliers, inlier matches).
pub fn verified_pairs(path: &Path) -> Result<(usize, usize), DatabaseError> {
    let db = open_read_only(path)?;
    db.query_row(
        "SELECT COUNT(*), COALESCE(SUM(rows), 0) FROM two_view_geometries WHERE rows > 0",
        [],
        |row| Ok((row.get::<_, i64>(0)?, row.get::<_, i64>(1)?)),
    )
    .map(|(pairs, inliers)| (pairs.max(0) as usize, inliers.max(0) as usize))
    .map_err(|e| error(path, e))
}

/// COLMAP's pair id of two image ids (`i < j`): `i · 2147483647 + j`.
const PAIR_ID_BASE: i64 = 2_147_483_647;

/// A verified two-view geometry.
#[derive(Clone, Debug, PartialEq)]
pub struct VerifiedPair {
    pub image_ids: (u32, u32),
    pub inliers: usize,
    /// The angle (degrees) of the rotation between the two cameras, from the pair's essential
    /// matrix (or its fundamental matrix and the cameras' intrinsics, prior ones included);
    /// `None` when the pair has neither (a homography-only pair) or its cameras are unknown.
    pub rotation_deg: Option<f64>,
}

/// Every verified two-view geometry with inliers, with the rotation between its cameras.
pub fn verified_geometries(path: &Path) -> Result<Vec<VerifiedPair>, DatabaseError> {
    let db = open_read_only(path)?;
    // Each image's intrinsic matrix, from its camera.
    let mut intrinsics_of = std::collections::HashMap::new();
    {
        let mut statement = db
            .prepare(
                "SELECT images.image_id, cameras.model, cameras.params \
                 FROM images JOIN cameras ON images.camera_id = cameras.camera_id",
            )
            .map_err(|e| error(path, e))?;
        let rows = statement
            .query_map([], |row| {
                Ok((
                    row.get::<_, i64>(0)?,
                    row.get::<_, i64>(1)?,
                    row.get::<_, Option<Vec<u8>>>(2)?,
                ))
            })
            .map_err(|e| error(path, e))?;
        for row in rows {
            let (image, model, params) = row.map_err(|e| error(path, e))?;
            if let Some(k) = intrinsics(model, params.as_deref().unwrap_or_default()) {
                intrinsics_of.insert(image, k);
            }
        }
    }
    let intrinsic = |image: u32| intrinsics_of.get(&i64::from(image));
    let mut statement = db
        .prepare("SELECT pair_id, rows, F, E FROM two_view_geometries WHERE rows > 0")
        .map_err(|e| error(path, e))?;
    let rows = statement
        .query_map([], |row| {
            Ok((
                row.get::<_, i64>(0)?,
                row.get::<_, i64>(1)?,
                row.get::<_, Option<Vec<u8>>>(2)?,
                row.get::<_, Option<Vec<u8>>>(3)?,
            ))
        })
        .map_err(|e| error(path, e))?;
    let mut pairs = Vec::new();
    for row in rows {
        let (pair_id, inliers, fundamental, essential) = row.map_err(|e| error(path, e))?;
        let (first, second) = (pair_id / PAIR_ID_BASE, pair_id % PAIR_ID_BASE);
        let (Ok(first), Ok(second)) = (u32::try_from(first), u32::try_from(second)) else {
            return Err(error(
                path,
                format!("two-view geometry with a bad pair id {pair_id}"),
            ));
        };
        let essential = matrix(essential.as_deref()).or_else(|| {
            // x₂ᵀ F x₁ = 0 in pixels, so E = K₂ᵀ F K₁.
            let f = matrix(fundamental.as_deref())?;
            Some(intrinsic(second)?.transpose() * f * intrinsic(first)?)
        });
        pairs.push(VerifiedPair {
            image_ids: (first, second),
            inliers: inliers.max(0) as usize,
            rotation_deg: essential.and_then(|e| rotation_angle_deg(&e)),
        });
    }
    Ok(pairs)
}

/// The intrinsic matrix of a COLMAP camera (model id and its parameter blob).
fn intrinsics(model: i64, params: &[u8]) -> Option<nalgebra::Matrix3<f64>> {
    let kind = crate::scene::CameraModelKind::from_id(i32::try_from(model).ok()?)?;
    let camera = crate::scene::Camera::new(1, kind, 1, 1, f64_values(params)).ok()?;
    let (fx, fy, cx, cy) = camera.focal_and_principal_point();
    (fx > 0.0 && fy > 0.0).then(|| nalgebra::Matrix3::new(fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0))
}

/// The little-endian `f64`s of a blob (a trailing partial value is ignored).
fn f64_values(blob: &[u8]) -> Vec<f64> {
    blob.chunks_exact(8)
        .map(|b| f64::from_le_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]]))
        .collect()
}

/// A 3×3 matrix from COLMAP's blob (row-major `f64`s); `None` when absent, of the wrong size
/// or all zero (not estimated).
fn matrix(blob: Option<&[u8]>) -> Option<nalgebra::Matrix3<f64>> {
    let blob = blob?;
    if blob.len() != 72 {
        return None;
    }
    let m = nalgebra::Matrix3::from_row_slice(&f64_values(blob));
    (m.iter().all(|v| v.is_finite()) && m.iter().any(|v| *v != 0.0)).then_some(m)
}

/// The rotation angle (degrees) of an essential matrix's decomposition: of its two rotations
/// (R = U W Vᵀ and U Wᵀ Vᵀ), the smaller angle. The other is the "twisted pair" solution, a
/// half turn about the baseline away; for photos of one object a few degrees apart it is the
/// far one.
pub fn rotation_angle_deg(essential: &nalgebra::Matrix3<f64>) -> Option<f64> {
    let svd = essential.svd(true, true);
    let (mut u, mut v_t) = (svd.u?, svd.v_t?);
    if u.determinant() < 0.0 {
        u = -u;
    }
    if v_t.determinant() < 0.0 {
        v_t = -v_t;
    }
    let w = nalgebra::Matrix3::new(0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0);
    let angle = |r: nalgebra::Matrix3<f64>| ((r.trace() - 1.0) / 2.0).clamp(-1.0, 1.0).acos();
    let smaller = angle(u * w * v_t).min(angle(u * w.transpose() * v_t));
    smaller.is_finite().then(|| smaller.to_degrees())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A database with COLMAP's schema for the tables read here.
    fn write_test_database(path: &Path, images: &[(&str, Vec<[u8; 128]>)]) {
        let db = rusqlite::Connection::open(path).unwrap();
        db.execute_batch(
            "CREATE TABLE images (image_id INTEGER PRIMARY KEY, name TEXT NOT NULL UNIQUE, camera_id INTEGER NOT NULL);
             CREATE TABLE descriptors (image_id INTEGER PRIMARY KEY NOT NULL, rows INTEGER NOT NULL, cols INTEGER NOT NULL, data BLOB);
             CREATE TABLE keypoints (image_id INTEGER PRIMARY KEY NOT NULL, rows INTEGER NOT NULL, cols INTEGER NOT NULL, data BLOB);
             CREATE TABLE two_view_geometries (pair_id INTEGER PRIMARY KEY NOT NULL, rows INTEGER NOT NULL, cols INTEGER NOT NULL, data BLOB, config INTEGER NOT NULL DEFAULT 3, F BLOB, E BLOB, H BLOB);
             CREATE TABLE cameras (camera_id INTEGER PRIMARY KEY NOT NULL, model INTEGER NOT NULL, width INTEGER NOT NULL, height INTEGER NOT NULL, params BLOB, prior_focal_length INTEGER NOT NULL);",
        )
        .unwrap();
        for (k, (name, rows)) in images.iter().enumerate() {
            let id = k as i64 + 1;
            db.execute(
                "INSERT INTO images VALUES (?1, ?2, 1)",
                rusqlite::params![id, name],
            )
            .unwrap();
            let data: Vec<u8> = rows.iter().flatten().copied().collect();
            db.execute(
                "INSERT INTO descriptors VALUES (?1, ?2, 128, ?3)",
                rusqlite::params![id, rows.len() as i64, data],
            )
            .unwrap();
            // Affine shapes: feature k has scale k + 1.
            let keypoints: Vec<u8> = (0..rows.len())
                .flat_map(|k| {
                    let s = k as f32 + 1.0;
                    [10.0, 20.0, s, 0.0, 0.0, s]
                })
                .flat_map(f32::to_le_bytes)
                .collect();
            db.execute(
                "INSERT INTO keypoints VALUES (?1, ?2, 6, ?3)",
                rusqlite::params![id, rows.len() as i64, keypoints],
            )
            .unwrap();
        }
    }

    #[test]
    fn images_and_descriptors_are_read_in_name_order() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("database.db");
        let mut a = [0u8; 128];
        a[0] = 200;
        let mut b = [0u8; 128];
        b[5] = 100;
        b[6] = 100;
        write_test_database(&path, &[("b.png", vec![a, b]), ("a.png", vec![b])]);
        let images = read_images(&path).unwrap();
        assert_eq!(images.len(), 2);
        assert_eq!(images[0].name, "a.png");
        assert_eq!(images[0].image_id, 2);
        assert_eq!(images[1].descriptors.len(), 2);
        assert_eq!(images[1].scales, [1.0, 2.0]);
        // Rows are unit vectors.
        let row = images[1].descriptors.row(1);
        assert!((row[5] - std::f32::consts::FRAC_1_SQRT_2).abs() < 1e-6);
        assert_eq!(verified_pairs(&path).unwrap(), (0, 0));
    }

    #[test]
    fn a_bad_blob_names_the_image() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("database.db");
        write_test_database(&path, &[("a.png", vec![[1u8; 128]])]);
        let db = rusqlite::Connection::open(&path).unwrap();
        db.execute("UPDATE descriptors SET rows = 5", []).unwrap();
        drop(db);
        let err = read_images(&path).unwrap_err().to_string();
        assert!(err.contains("a.png"), "{err}");
        let missing = read_images(&dir.path().join("none.db"))
            .unwrap_err()
            .to_string();
        assert!(missing.contains("none.db"), "{missing}");
    }

    #[test]
    fn verified_pairs_are_read_with_their_image_ids() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("database.db");
        write_test_database(&path, &[("a.png", vec![[1u8; 128]]), ("b.png", vec![])]);
        let db = rusqlite::Connection::open(&path).unwrap();
        for (pair_id, rows) in [(PAIR_ID_BASE + 2, 40), (2 * PAIR_ID_BASE + 7, 0), (-5, 3)] {
            db.execute(
                "INSERT INTO two_view_geometries (pair_id, rows, cols) VALUES (?1, ?2, 2)",
                rusqlite::params![pair_id, rows],
            )
            .unwrap();
        }
        drop(db);
        // A pair id no image pair can have is an error naming it.
        let err = verified_geometries(&path).unwrap_err().to_string();
        assert!(err.contains("-5"), "{err}");
        let db = rusqlite::Connection::open(&path).unwrap();
        db.execute("DELETE FROM two_view_geometries WHERE pair_id < 0", [])
            .unwrap();
        drop(db);
        // Pairs without inliers are not verified.
        let pairs = verified_geometries(&path).unwrap();
        assert_eq!(pairs.len(), 1);
        assert_eq!((pairs[0].image_ids, pairs[0].inliers), ((1, 2), 40));
        // No matrices were stored: no rotation.
        assert_eq!(pairs[0].rotation_deg, None);
        assert_eq!(verified_pairs(&path).unwrap(), (1, 40));
    }

    /// The essential matrix [t]ₓ R of a camera pair whose rotation turns `degrees` about an
    /// oblique axis, the second camera moved sideways as on an orbit.
    fn essential(degrees: f64) -> nalgebra::Matrix3<f64> {
        let axis = nalgebra::Unit::new_normalize(nalgebra::Vector3::new(0.2, 1.0, 0.1));
        let r = nalgebra::Rotation3::from_axis_angle(&axis, degrees.to_radians());
        let t = nalgebra::Vector3::new(0.3, 0.02, 0.05);
        t.cross_matrix() * r.matrix()
    }

    #[test]
    fn the_rotation_of_an_essential_matrix_is_recovered() {
        for degrees in [0.5, 3.6, 8.0, 20.0, 45.0] {
            let found = rotation_angle_deg(&essential(degrees)).unwrap();
            assert!((found - degrees).abs() < 1e-6, "{degrees}° → {found}°");
            // Scale and sign of E do not matter.
            let scaled = rotation_angle_deg(&(-3.0 * essential(degrees))).unwrap();
            assert!((scaled - degrees).abs() < 1e-6);
        }
    }

    #[test]
    fn pairs_get_their_rotation_from_the_fundamental_matrix_and_the_camera() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("database.db");
        write_test_database(&path, &[("a.png", vec![[1u8; 128]]), ("b.png", vec![])]);
        // A SIMPLE_RADIAL camera (f, cx, cy, k) shared by both images.
        let (f, cx, cy) = (960.0, 400.0, 300.0);
        let params: Vec<u8> = [f, cx, cy, 0.01]
            .iter()
            .flat_map(|v: &f64| v.to_le_bytes())
            .collect();
        let db = rusqlite::Connection::open(&path).unwrap();
        db.execute(
            "INSERT INTO cameras VALUES (1, 2, 800, 600, ?1, 0)",
            rusqlite::params![params],
        )
        .unwrap();
        let k = nalgebra::Matrix3::new(f, 0.0, cx, 0.0, f, cy, 0.0, 0.0, 1.0);
        let k_inv = k.try_inverse().unwrap();
        let fundamental = k_inv.transpose() * essential(6.0) * k_inv * 1e3;
        let blob: Vec<u8> = fundamental
            .transpose()
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        db.execute(
            "INSERT INTO two_view_geometries (pair_id, rows, cols, F) VALUES (?1, 120, 2, ?2)",
            rusqlite::params![PAIR_ID_BASE + 2, blob],
        )
        .unwrap();
        drop(db);
        let pairs = verified_geometries(&path).unwrap();
        assert_eq!(pairs.len(), 1);
        let degrees = pairs[0].rotation_deg.unwrap();
        assert!((degrees - 6.0).abs() < 1e-6, "{degrees}");
    }
}
