//! PLY reading and writing (ASCII, binary little- and big-endian), scalar and list properties.
//!
//! Used for COLMAP's `fused.ply`, Frond's `segmentation.ply` output contract and ground-truth
//! meshes. Values are held as `f64` columns, which represent every PLY scalar type exactly.

use std::fmt::Write as _;
use std::path::Path;

use super::error::{Location, SceneError, SceneResult};

/// A PLY scalar type.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ScalarType {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl ScalarType {
    fn from_name(name: &str) -> Option<Self> {
        Some(match name {
            "char" | "int8" => Self::I8,
            "uchar" | "uint8" => Self::U8,
            "short" | "int16" => Self::I16,
            "ushort" | "uint16" => Self::U16,
            "int" | "int32" => Self::I32,
            "uint" | "uint32" => Self::U32,
            "float" | "float32" => Self::F32,
            "double" | "float64" => Self::F64,
            _ => return None,
        })
    }

    fn name(self) -> &'static str {
        match self {
            Self::I8 => "char",
            Self::U8 => "uchar",
            Self::I16 => "short",
            Self::U16 => "ushort",
            Self::I32 => "int",
            Self::U32 => "uint",
            Self::F32 => "float",
            Self::F64 => "double",
        }
    }

    fn size(self) -> usize {
        match self {
            Self::I8 | Self::U8 => 1,
            Self::I16 | Self::U16 => 2,
            Self::I32 | Self::U32 | Self::F32 => 4,
            Self::F64 => 8,
        }
    }

    fn is_integer(self) -> bool {
        !matches!(self, Self::F32 | Self::F64)
    }

    fn decode(self, bytes: &[u8], little_endian: bool) -> f64 {
        macro_rules! num {
            ($t:ty, $n:expr) => {{
                let mut a = [0u8; $n];
                a.copy_from_slice(&bytes[..$n]);
                if little_endian {
                    <$t>::from_le_bytes(a) as f64
                } else {
                    <$t>::from_be_bytes(a) as f64
                }
            }};
        }
        match self {
            Self::I8 => num!(i8, 1),
            Self::U8 => num!(u8, 1),
            Self::I16 => num!(i16, 2),
            Self::U16 => num!(u16, 2),
            Self::I32 => num!(i32, 4),
            Self::U32 => num!(u32, 4),
            Self::F32 => num!(f32, 4),
            Self::F64 => num!(f64, 8),
        }
    }

    fn encode_le(self, value: f64, out: &mut Vec<u8>) {
        match self {
            Self::I8 => out.extend_from_slice(&(value as i8).to_le_bytes()),
            Self::U8 => out.extend_from_slice(&(value as u8).to_le_bytes()),
            Self::I16 => out.extend_from_slice(&(value as i16).to_le_bytes()),
            Self::U16 => out.extend_from_slice(&(value as u16).to_le_bytes()),
            Self::I32 => out.extend_from_slice(&(value as i32).to_le_bytes()),
            Self::U32 => out.extend_from_slice(&(value as u32).to_le_bytes()),
            Self::F32 => out.extend_from_slice(&(value as f32).to_le_bytes()),
            Self::F64 => out.extend_from_slice(&value.to_le_bytes()),
        }
    }
}

/// A property: a scalar, or a list with a count type and an item type.
#[derive(Clone, Debug, PartialEq)]
pub enum PropertyKind {
    Scalar(ScalarType),
    List { count: ScalarType, item: ScalarType },
}

/// A property of an element with its values: one per row for scalars; for lists the items of
/// all rows back to back, with `list_offsets[row]..list_offsets[row + 1]` the row's items.
#[derive(Clone, Debug, PartialEq)]
pub struct Column {
    pub name: String,
    pub kind: PropertyKind,
    pub values: Vec<f64>,
    pub list_offsets: Vec<usize>,
}

impl Column {
    /// A scalar column.
    pub fn scalar(name: &str, scalar: ScalarType, values: Vec<f64>) -> Self {
        Self {
            name: name.to_owned(),
            kind: PropertyKind::Scalar(scalar),
            values,
            list_offsets: Vec::new(),
        }
    }

    /// A list column from per-row lists.
    pub fn list(name: &str, count: ScalarType, item: ScalarType, rows: &[Vec<f64>]) -> Self {
        let mut offsets = Vec::with_capacity(rows.len() + 1);
        offsets.push(0);
        let mut values = Vec::new();
        for row in rows {
            values.extend_from_slice(row);
            offsets.push(values.len());
        }
        Self {
            name: name.to_owned(),
            kind: PropertyKind::List { count, item },
            values,
            list_offsets: offsets,
        }
    }

    /// The items of row `row` of a list column.
    pub fn list_row(&self, row: usize) -> &[f64] {
        &self.values[self.list_offsets[row]..self.list_offsets[row + 1]]
    }
}

/// An element (`vertex`, `face`, …) with its rows.
#[derive(Clone, Debug, PartialEq)]
pub struct Element {
    pub name: String,
    pub count: usize,
    pub columns: Vec<Column>,
}

impl Element {
    pub fn column(&self, name: &str) -> Option<&Column> {
        self.columns.iter().find(|c| c.name == name)
    }
}

/// A parsed PLY file.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Ply {
    pub elements: Vec<Element>,
    pub comments: Vec<String>,
}

impl Ply {
    pub fn element(&self, name: &str) -> Option<&Element> {
        self.elements.iter().find(|e| e.name == name)
    }
}

#[derive(Clone, Copy, PartialEq)]
enum Encoding {
    Ascii,
    BinaryLittleEndian,
    BinaryBigEndian,
}

fn parse_error(path: &Path, location: Location, record: &str, message: String) -> SceneError {
    SceneError::Parse {
        path: path.to_path_buf(),
        location,
        record: record.to_owned(),
        message,
    }
}

/// Reads a PLY file.
pub fn read_ply(path: &Path) -> SceneResult<Ply> {
    let bytes = std::fs::read(path).map_err(|e| SceneError::io(path, e))?;
    parse_ply(&bytes, path)
}

/// Parses PLY bytes; `path` only names the source in errors.
pub fn parse_ply(bytes: &[u8], path: &Path) -> SceneResult<Ply> {
    const END: &[u8] = b"end_header";
    let header_end = bytes
        .windows(END.len())
        .position(|w| w == END)
        .ok_or_else(|| {
            parse_error(
                path,
                Location::Byte(0),
                "header",
                "no end_header".to_owned(),
            )
        })?;
    let mut body_start = header_end + END.len();
    if bytes.get(body_start) == Some(&b'\r') {
        body_start += 1;
    }
    if bytes.get(body_start) == Some(&b'\n') {
        body_start += 1;
    }
    let header = std::str::from_utf8(&bytes[..header_end]).map_err(|_| {
        parse_error(
            path,
            Location::Byte(0),
            "header",
            "header is not text".to_owned(),
        )
    })?;
    let mut lines = header.lines().enumerate();
    match lines.next() {
        Some((_, l)) if l.trim() == "ply" => {}
        _ => {
            return Err(parse_error(
                path,
                Location::Line(1),
                "header",
                "not a PLY file (first line is not 'ply')".to_owned(),
            ));
        }
    }
    let mut encoding = None;
    let mut ply = Ply::default();
    for (index, line) in lines {
        let number = index + 1;
        let tokens: Vec<&str> = line.split_ascii_whitespace().collect();
        let err = |m: String| parse_error(path, Location::Line(number), "header", m);
        match tokens.as_slice() {
            [] => {}
            ["format", f, _version] => {
                encoding = Some(match *f {
                    "ascii" => Encoding::Ascii,
                    "binary_little_endian" => Encoding::BinaryLittleEndian,
                    "binary_big_endian" => Encoding::BinaryBigEndian,
                    other => return Err(err(format!("unknown format '{other}'"))),
                })
            }
            ["comment", ..] => ply.comments.push(
                line.trim_start()
                    .trim_start_matches("comment")
                    .trim()
                    .to_owned(),
            ),
            ["obj_info", ..] => {}
            ["element", name, count] => {
                let count: usize = count
                    .parse()
                    .map_err(|_| err(format!("bad element count '{count}'")))?;
                ply.elements.push(Element {
                    name: (*name).to_owned(),
                    count,
                    columns: Vec::new(),
                });
            }
            ["property", "list", count, item, name] => {
                let (Some(count), Some(item)) =
                    (ScalarType::from_name(count), ScalarType::from_name(item))
                else {
                    return Err(err(format!("bad list property types in '{line}'")));
                };
                if !count.is_integer() {
                    return Err(err("list count type must be an integer".to_owned()));
                }
                let element = ply
                    .elements
                    .last_mut()
                    .ok_or_else(|| err("property before any element".to_owned()))?;
                element.columns.push(Column {
                    name: (*name).to_owned(),
                    kind: PropertyKind::List { count, item },
                    values: Vec::new(),
                    list_offsets: vec![0],
                });
            }
            ["property", scalar, name] => {
                let scalar = ScalarType::from_name(scalar)
                    .ok_or_else(|| err(format!("unknown property type '{scalar}'")))?;
                let element = ply
                    .elements
                    .last_mut()
                    .ok_or_else(|| err("property before any element".to_owned()))?;
                element
                    .columns
                    .push(Column::scalar(name, scalar, Vec::new()));
            }
            _ => return Err(err(format!("unrecognised header line '{line}'"))),
        }
    }
    let encoding = encoding.ok_or_else(|| {
        parse_error(
            path,
            Location::Byte(0),
            "header",
            "missing format line".to_owned(),
        )
    })?;
    let body = &bytes[body_start..];
    match encoding {
        Encoding::Ascii => parse_ascii_body(body, path, &mut ply)?,
        _ => parse_binary_body(
            body,
            body_start,
            path,
            &mut ply,
            encoding == Encoding::BinaryLittleEndian,
        )?,
    }
    Ok(ply)
}

fn parse_binary_body(
    body: &[u8],
    body_offset: usize,
    path: &Path,
    ply: &mut Ply,
    little_endian: bool,
) -> SceneResult<()> {
    let mut pos = 0usize;
    for element in &mut ply.elements {
        let min_row: usize = element
            .columns
            .iter()
            .map(|c| match c.kind {
                PropertyKind::Scalar(t) => t.size(),
                PropertyKind::List { count, .. } => count.size(),
            })
            .sum();
        if element.count.saturating_mul(min_row) > body.len() - pos {
            return Err(parse_error(
                path,
                Location::Byte((body_offset + pos) as u64),
                &format!("element '{}'", element.name),
                format!(
                    "{} rows cannot fit in the {} bytes left",
                    element.count,
                    body.len() - pos
                ),
            ));
        }
        for column in &mut element.columns {
            if matches!(column.kind, PropertyKind::Scalar(_)) {
                column.values.reserve_exact(element.count);
            }
        }
        for row in 0..element.count {
            for column in &mut element.columns {
                let truncated = |pos: usize| {
                    parse_error(
                        path,
                        Location::Byte((body_offset + pos) as u64),
                        &format!("{} {row}", element.name),
                        format!("file truncated in property '{}'", column.name),
                    )
                };
                match column.kind {
                    PropertyKind::Scalar(t) => {
                        let bytes = body
                            .get(pos..pos + t.size())
                            .ok_or_else(|| truncated(pos))?;
                        column.values.push(t.decode(bytes, little_endian));
                        pos += t.size();
                    }
                    PropertyKind::List { count, item } => {
                        let bytes = body
                            .get(pos..pos + count.size())
                            .ok_or_else(|| truncated(pos))?;
                        let n = count.decode(bytes, little_endian);
                        pos += count.size();
                        if n < 0.0 || (n as usize).saturating_mul(item.size()) > body.len() - pos {
                            return Err(truncated(pos));
                        }
                        for _ in 0..n as usize {
                            column
                                .values
                                .push(item.decode(&body[pos..pos + item.size()], little_endian));
                            pos += item.size();
                        }
                        column.list_offsets.push(column.values.len());
                    }
                }
            }
        }
    }
    Ok(())
}

fn parse_ascii_body(body: &[u8], path: &Path, ply: &mut Ply) -> SceneResult<()> {
    let text = std::str::from_utf8(body).map_err(|_| {
        parse_error(
            path,
            Location::Byte(0),
            "body",
            "ASCII body is not text".to_owned(),
        )
    })?;
    let mut lines = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty());
    for element in &mut ply.elements {
        for row in 0..element.count {
            let Some((index, line)) = lines.next() else {
                return Err(parse_error(
                    path,
                    Location::Byte(body.len() as u64),
                    &format!("{} {row}", element.name),
                    "file ends before all rows".to_owned(),
                ));
            };
            let err = |m: String| {
                parse_error(
                    path,
                    Location::Line(index + 1),
                    &format!("{} {row} (line {} of the body)", element.name, index + 1),
                    m,
                )
            };
            let mut tokens = line.split_ascii_whitespace();
            let mut next = |what: &str| -> SceneResult<f64> {
                let t = tokens
                    .next()
                    .ok_or_else(|| err(format!("missing value for '{what}'")))?;
                t.parse::<f64>()
                    .map_err(|_| err(format!("'{t}' is not a number ({what})")))
            };
            for column in &mut element.columns {
                match column.kind {
                    PropertyKind::Scalar(_) => {
                        let v = next(&column.name)?;
                        column.values.push(v);
                    }
                    PropertyKind::List { .. } => {
                        let n = next(&column.name)?;
                        if !(0.0..=1e6).contains(&n) {
                            return Err(err(format!("list length {n} is not plausible")));
                        }
                        for _ in 0..n as usize {
                            let v = next(&column.name)?;
                            column.values.push(v);
                        }
                        column.list_offsets.push(column.values.len());
                    }
                }
            }
        }
    }
    Ok(())
}

/// Encodes a PLY as binary little-endian.
pub fn encode_ply_binary(ply: &Ply) -> Vec<u8> {
    let mut header = String::from("ply\nformat binary_little_endian 1.0\n");
    for c in &ply.comments {
        let _ = writeln!(header, "comment {c}");
    }
    for element in &ply.elements {
        let _ = writeln!(header, "element {} {}", element.name, element.count);
        for column in &element.columns {
            match &column.kind {
                PropertyKind::Scalar(t) => {
                    let _ = writeln!(header, "property {} {}", t.name(), column.name);
                }
                PropertyKind::List { count, item } => {
                    let _ = writeln!(
                        header,
                        "property list {} {} {}",
                        count.name(),
                        item.name(),
                        column.name
                    );
                }
            }
        }
    }
    header.push_str("end_header\n");
    let mut out = header.into_bytes();
    for element in &ply.elements {
        for row in 0..element.count {
            for column in &element.columns {
                match column.kind {
                    PropertyKind::Scalar(t) => t.encode_le(column.values[row], &mut out),
                    PropertyKind::List { count, item } => {
                        let items = column.list_row(row);
                        count.encode_le(items.len() as f64, &mut out);
                        for &v in items {
                            item.encode_le(v, &mut out);
                        }
                    }
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Ply {
        Ply {
            comments: vec!["written by frond".into()],
            elements: vec![
                Element {
                    name: "vertex".into(),
                    count: 3,
                    columns: vec![
                        Column::scalar("x", ScalarType::F32, vec![0.5, 1.0, -2.25]),
                        Column::scalar("red", ScalarType::U8, vec![0.0, 128.0, 255.0]),
                        Column::scalar("leaf_id", ScalarType::I32, vec![-1.0, 7.0, 7.0]),
                    ],
                },
                Element {
                    name: "face".into(),
                    count: 1,
                    columns: vec![Column::list(
                        "vertex_indices",
                        ScalarType::U8,
                        ScalarType::I32,
                        &[vec![0.0, 1.0, 2.0]],
                    )],
                },
            ],
        }
    }

    #[test]
    fn binary_round_trip() {
        let ply = sample();
        let bytes = encode_ply_binary(&ply);
        let back = parse_ply(&bytes, Path::new("t.ply")).unwrap();
        assert_eq!(back, ply);
    }

    #[test]
    fn ascii_and_big_endian() {
        let text = "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty list uchar int v\nend_header\n1.5 2 3 4\n-2 0\n";
        let ply = parse_ply(text.as_bytes(), Path::new("a.ply")).unwrap();
        let v = ply.element("vertex").unwrap();
        assert_eq!(v.column("x").unwrap().values, vec![1.5, -2.0]);
        assert_eq!(v.column("v").unwrap().list_row(0), &[3.0, 4.0]);
        assert!(v.column("v").unwrap().list_row(1).is_empty());

        let mut be =
            b"ply\nformat binary_big_endian 1.0\nelement vertex 1\nproperty int x\nend_header\n"
                .to_vec();
        be.extend_from_slice(&(-5i32).to_be_bytes());
        let ply = parse_ply(&be, Path::new("b.ply")).unwrap();
        assert_eq!(ply.elements[0].columns[0].values, vec![-5.0]);
    }

    #[test]
    fn truncated_and_lying_counts_are_errors() {
        let bytes = encode_ply_binary(&sample());
        for cut in [bytes.len() - 1, bytes.len() - 13] {
            let err = parse_ply(&bytes[..cut], Path::new("t.ply")).unwrap_err();
            assert!(err.to_string().starts_with("t.ply: byte"), "{err}");
        }
        let lying = b"ply\nformat binary_little_endian 1.0\nelement vertex 999999999999\nproperty float x\nend_header\n";
        let err = parse_ply(lying, Path::new("l.ply"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("cannot fit"), "{err}");
        assert!(parse_ply(b"plx\n", Path::new("x.ply")).is_err());
    }
}
