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

/// Every verified two-view geometry with inliers: `(image_id, image_id, inlier matches)`.
pub fn verified_inliers(path: &Path) -> Result<Vec<(u32, u32, usize)>, DatabaseError> {
    let db = open_read_only(path)?;
    let mut statement = db
        .prepare("SELECT pair_id, rows FROM two_view_geometries WHERE rows > 0")
        .map_err(|e| error(path, e))?;
    let rows = statement
        .query_map([], |row| Ok((row.get::<_, i64>(0)?, row.get::<_, i64>(1)?)))
        .map_err(|e| error(path, e))?;
    let mut pairs = Vec::new();
    for row in rows {
        let (pair_id, inliers) = row.map_err(|e| error(path, e))?;
        let (first, second) = (pair_id / PAIR_ID_BASE, pair_id % PAIR_ID_BASE);
        let (Ok(first), Ok(second)) = (u32::try_from(first), u32::try_from(second)) else {
            return Err(error(
                path,
                format!("two-view geometry with a bad pair id {pair_id}"),
            ));
        };
        pairs.push((first, second, inliers.max(0) as usize));
    }
    Ok(pairs)
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
             CREATE TABLE two_view_geometries (pair_id INTEGER PRIMARY KEY NOT NULL, rows INTEGER NOT NULL, cols INTEGER NOT NULL, data BLOB);",
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
                "INSERT INTO two_view_geometries VALUES (?1, ?2, 2, NULL)",
                rusqlite::params![pair_id, rows],
            )
            .unwrap();
        }
        drop(db);
        // A pair id no image pair can have is an error naming it.
        let err = verified_inliers(&path).unwrap_err().to_string();
        assert!(err.contains("-5"), "{err}");
        let db = rusqlite::Connection::open(&path).unwrap();
        db.execute("DELETE FROM two_view_geometries WHERE pair_id < 0", [])
            .unwrap();
        drop(db);
        // Pairs without inliers are not verified.
        assert_eq!(verified_inliers(&path).unwrap(), vec![(1, 2, 40)]);
        assert_eq!(verified_pairs(&path).unwrap(), (1, 40));
    }
}
