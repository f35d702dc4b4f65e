//! The batch manifest: a CSV file with a header row. Columns: `plant` (an id, used as the
//! output folder's name), `input` (a folder of photos or a COLMAP project; relative paths are
//! relative to the manifest), and optionally `scale` (metres per model unit), `scale_from`
//! (`X1,Y1,Z1:X2,Y2,Z2:METRES`), `checkerboard` (`COLSxROWS:SQUARE_METRES` of a printed board
//! in the photos) and `no_densify` (`true` to segment a COLMAP folder's points as
//! they are). Empty cells take the default.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use super::BatchError;
use crate::traits::Scale;

/// One plant of the manifest.
#[derive(Clone, Debug, PartialEq)]
pub struct ManifestEntry {
    pub plant: String,
    pub input: PathBuf,
    pub scale: Option<Scale>,
    /// A checkerboard in the photos to take the scale from: inner corners and square size.
    pub checkerboard: Option<((u32, u32), f64)>,
    pub no_densify: bool,
}

const COLUMNS: [&str; 6] = [
    "plant",
    "input",
    "scale",
    "scale_from",
    "checkerboard",
    "no_densify",
];

/// Splits CSV text into records of fields (RFC 4180: quoted fields may hold commas, doubled
/// quotes and line breaks). Blank lines are skipped. Errors name the 1-based line.
pub fn parse_csv(text: &str) -> Result<Vec<(usize, Vec<String>)>, String> {
    let mut records = Vec::new();
    let mut field = String::new();
    let mut fields: Vec<String> = Vec::new();
    let mut line = 1usize;
    let mut record_line = 1usize;
    let mut quoted = false;
    let mut chars = text.chars().peekable();
    let mut field_started_quoted = false;
    while let Some(c) = chars.next() {
        if quoted {
            match c {
                '"' if chars.peek() == Some(&'"') => {
                    chars.next();
                    field.push('"');
                }
                '"' => quoted = false,
                '\n' => {
                    line += 1;
                    field.push(c);
                }
                _ => field.push(c),
            }
            continue;
        }
        match c {
            '"' if field.is_empty() && !field_started_quoted => {
                quoted = true;
                field_started_quoted = true;
            }
            '"' => return Err(format!("line {line}: a quote inside an unquoted field")),
            ',' => {
                fields.push(std::mem::take(&mut field));
                field_started_quoted = false;
            }
            '\r' => {}
            '\n' => {
                fields.push(std::mem::take(&mut field));
                field_started_quoted = false;
                if !(fields.len() == 1 && fields[0].trim().is_empty()) {
                    records.push((record_line, std::mem::take(&mut fields)));
                }
                fields.clear();
                line += 1;
                record_line = line;
            }
            _ => field.push(c),
        }
    }
    if quoted {
        return Err(format!("line {record_line}: a quoted field is not closed"));
    }
    if !field.is_empty() || !fields.is_empty() {
        fields.push(field);
        if !(fields.len() == 1 && fields[0].trim().is_empty()) {
            records.push((record_line, fields));
        }
    }
    Ok(records)
}

fn manifest_error(path: &Path, message: impl std::fmt::Display) -> BatchError {
    BatchError::Manifest {
        path: path.display().to_string(),
        message: message.to_string(),
    }
}

/// Whether `id` can name a plant's folder: not empty, no path separators, not starting with a
/// dot, printable.
fn valid_plant_id(id: &str) -> bool {
    !id.is_empty()
        && !id.starts_with('.')
        && !id.contains(['/', '\\'])
        && id.chars().all(|c| !c.is_control())
}

/// Reads a manifest (see the module documentation). Every problem names the line and column.
pub fn read_manifest(path: &Path) -> Result<Vec<ManifestEntry>, BatchError> {
    let text = std::fs::read_to_string(path).map_err(|e| manifest_error(path, e))?;
    let records = parse_csv(&text).map_err(|e| manifest_error(path, e))?;
    let Some((_, header)) = records.first() else {
        return Err(manifest_error(
            path,
            "empty: expected a header row `plant,input`",
        ));
    };
    let header: Vec<String> = header.iter().map(|h| h.trim().to_lowercase()).collect();
    for name in &header {
        if !COLUMNS.contains(&name.as_str()) {
            return Err(manifest_error(
                path,
                format!("unknown column `{name}` (columns: {})", COLUMNS.join(", ")),
            ));
        }
    }
    let column = |name: &str| header.iter().position(|h| h == name);
    let (Some(plant_column), Some(input_column)) = (column("plant"), column("input")) else {
        return Err(manifest_error(
            path,
            "the header must name the columns `plant` and `input`",
        ));
    };
    let base = path.parent().unwrap_or(Path::new("."));
    let mut seen = BTreeSet::new();
    let mut entries = Vec::new();
    for (line, fields) in &records[1..] {
        if fields.len() != header.len() {
            return Err(manifest_error(
                path,
                format!(
                    "line {line}: {} fields, the header has {}",
                    fields.len(),
                    header.len()
                ),
            ));
        }
        let cell = |name: &str| {
            column(name)
                .map(|k| fields[k].trim())
                .filter(|v| !v.is_empty())
        };
        let plant = fields[plant_column].trim().to_owned();
        if !valid_plant_id(&plant) {
            return Err(manifest_error(
                path,
                format!("line {line}: `{plant}` cannot name a folder (no slashes, no leading dot)"),
            ));
        }
        if !seen.insert(plant.clone()) {
            return Err(manifest_error(
                path,
                format!("line {line}: plant `{plant}` appears twice"),
            ));
        }
        let input_text = fields[input_column].trim();
        if input_text.is_empty() {
            return Err(manifest_error(
                path,
                format!("line {line}: plant `{plant}` has no input"),
            ));
        }
        let input = base.join(input_text);
        let scale = match (cell("scale"), cell("scale_from")) {
            (Some(_), Some(_)) => {
                return Err(manifest_error(
                    path,
                    format!("line {line}: give `scale` or `scale_from`, not both"),
                ));
            }
            (Some(f), None) => {
                let factor: f64 = f.parse().map_err(|_| {
                    manifest_error(path, format!("line {line}: scale `{f}` is not a number"))
                })?;
                Some(
                    Scale::factor(factor)
                        .map_err(|e| manifest_error(path, format!("line {line}: {e}")))?,
                )
            }
            (None, Some(text)) => Some(
                Scale::parse_two_points(text)
                    .map_err(|e| manifest_error(path, format!("line {line}: {e}")))?,
            ),
            (None, None) => None,
        };
        let checkerboard = match cell("checkerboard") {
            None => None,
            Some(text) => {
                if scale.is_some() {
                    return Err(manifest_error(
                        path,
                        format!(
                            "line {line}: give one of `scale`, `scale_from` and `checkerboard`"
                        ),
                    ));
                }
                Some(
                    crate::traits::marker::parse_checkerboard(text)
                        .map_err(|e| manifest_error(path, format!("line {line}: {e}")))?,
                )
            }
        };
        let no_densify = match cell("no_densify").map(|v| v.to_lowercase()) {
            None => false,
            Some(v) if ["true", "yes", "1"].contains(&v.as_str()) => true,
            Some(v) if ["false", "no", "0"].contains(&v.as_str()) => false,
            Some(v) => {
                return Err(manifest_error(
                    path,
                    format!("line {line}: no_densify `{v}` is not true or false"),
                ));
            }
        };
        entries.push(ManifestEntry {
            plant,
            input,
            scale,
            checkerboard,
            no_densify,
        });
    }
    Ok(entries)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(text: &str) -> (tempfile::TempDir, PathBuf) {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("plants.csv");
        std::fs::write(&path, text).unwrap();
        (dir, path)
    }

    #[test]
    fn quoted_fields_keep_commas_quotes_and_line_breaks() {
        let records = parse_csv("a,b\n\"x, y\",\"say \"\"hi\"\"\"\n\n\"two\nlines\",z").unwrap();
        assert_eq!(records.len(), 3);
        assert_eq!(records[1].1, ["x, y", "say \"hi\""]);
        assert_eq!(
            records[2],
            (4, vec!["two\nlines".to_owned(), "z".to_owned()])
        );
        assert!(parse_csv("a,\"b\n").is_err());
        assert!(parse_csv("a,b\"c\n").is_err());
    }

    #[test]
    fn a_manifest_gives_plants_with_inputs_relative_to_it() {
        let (dir, path) =
            write("plant,input,scale,no_densify\np1,photos/p1,,\np2,/data/p2,0.01,true\n");
        let entries = read_manifest(&path).unwrap();
        assert_eq!(entries.len(), 2);
        assert_eq!(entries[0].input, dir.path().join("photos/p1"));
        assert_eq!(entries[0].scale, None);
        assert!(!entries[0].no_densify);
        assert_eq!(entries[1].input, PathBuf::from("/data/p2"));
        assert_eq!(entries[1].scale.as_ref().unwrap().metres_per_unit, 0.01);
        assert!(entries[1].no_densify);
    }

    #[test]
    fn bad_manifests_name_the_line_and_the_problem() {
        let cases = [
            ("", "empty"),
            ("plant,folder\n", "unknown column `folder`"),
            ("plant,scale\n", "`plant` and `input`"),
            (
                "plant,input\np1,a\np1,b\n",
                "line 3: plant `p1` appears twice",
            ),
            (
                "plant,input\n../up,a\n",
                "line 2: `../up` cannot name a folder",
            ),
            ("plant,input\np1\n", "line 2: 1 fields"),
            ("plant,input,scale\np1,a,big\n", "line 2: scale `big`"),
            ("plant,input,scale\np1,a,-2\n", "line 2: scale"),
            ("plant,input,no_densify\np1,a,maybe\n", "no_densify `maybe`"),
            (
                "plant,input,checkerboard\np1,a,8by6\n",
                "line 2: scale: `8by6`",
            ),
            (
                "plant,input,scale,checkerboard\np1,a,1,8x6:0.03\n",
                "one of `scale`",
            ),
            ("plant,input\np1,\n", "has no input"),
        ];
        for (text, expected) in cases {
            let (_dir, path) = write(text);
            let message = read_manifest(&path).unwrap_err().to_string();
            assert!(message.contains(expected), "{text:?}: {message}");
            assert!(message.contains("plants.csv"), "{message}");
        }
    }
}
