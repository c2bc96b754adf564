//! PLY point reading (ASCII and binary, via the maintained `ply-rs-bw` fork of `ply-rs`, which caps
//! preallocation by header counts and reports truncation with line numbers). Only the `vertex`
//! element's `x y z` (and `nx ny nz` when all three are present) are kept; other elements are read
//! past. (The appearance reader, [`crate::appearance`], reads the same file with its vertex
//! colours.) Data after the last declared element means the header understates a count: an error.

use std::io::{BufRead, BufReader};
use std::path::Path;

use ply_rs_bw::parser::{Parser, Reader};
use ply_rs_bw::ply::{Property, PropertyAccess, PropertyAccessResult};

use crate::coords::V3;
use crate::error::GeometryError;

/// Points read from a file; `normals`, when present, has one (not yet normalised) entry per point.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PointSet {
    /// Point coordinates as stored.
    pub positions: Vec<V3>,
    /// Per-point normals when the file has them (any length, possibly zero: validated by the source).
    pub normals: Option<Vec<V3>>,
}

/// One PLY element with the coordinates we care about.
#[derive(Clone, Copy, Default)]
struct PlyPoint {
    p: V3,
    n: V3,
}

impl PropertyAccess for PlyPoint {
    fn new() -> Self {
        PlyPoint::default()
    }

    fn set_property(&mut self, name: &str, property: Property) -> PropertyAccessResult {
        let slot = match name {
            "x" => &mut self.p[0],
            "y" => &mut self.p[1],
            "z" => &mut self.p[2],
            "nx" => &mut self.n[0],
            "ny" => &mut self.n[1],
            "nz" => &mut self.n[2],
            _ => return PropertyAccessResult::Ignored,
        };
        match number(property) {
            Some(v) => *slot = v,
            None => return PropertyAccessResult::UnsupportedType,
        }
        PropertyAccessResult::Set
    }
}

/// A scalar property as `f32`; `None` for lists and other unsupported types.
fn number(property: Property) -> Option<f32> {
    Some(match property {
        Property::Float(v) => v,
        Property::Double(v) => v as f32,
        Property::Char(v) => f32::from(v),
        Property::UChar(v) => f32::from(v),
        Property::Short(v) => f32::from(v),
        Property::UShort(v) => f32::from(v),
        Property::Int(v) => v as f32,
        Property::UInt(v) => v as f32,
        _ => return None,
    })
}

/// The colour property names the appearance reader accepts, in order of preference.
pub(crate) const COLOUR_PROPERTIES: [[&str; 3]; 3] =
    [["red", "green", "blue"], ["r", "g", "b"], ["diffuse_red", "diffuse_green", "diffuse_blue"]];

/// A PLY vertex with its colours, for [`read_ply_colours`]: `c[set]` holds the channels of
/// [`COLOUR_PROPERTIES`]`[set]`, already scaled to `[0, 1]` by their type.
#[derive(Clone, Copy, Default)]
struct PlyColourPoint {
    p: V3,
    c: [[f32; 3]; 3],
}

impl PropertyAccess for PlyColourPoint {
    fn new() -> Self {
        PlyColourPoint::default()
    }

    fn set_property(&mut self, name: &str, property: Property) -> PropertyAccessResult {
        let slot = match name {
            "x" => &mut self.p[0],
            "y" => &mut self.p[1],
            "z" => &mut self.p[2],
            _ => {
                let found = COLOUR_PROPERTIES
                    .iter()
                    .enumerate()
                    .find_map(|(set, names)| names.iter().position(|n| *n == name).map(|k| (set, k)));
                let Some((set, k)) = found else { return PropertyAccessResult::Ignored };
                // Integers are 0..=255 (0..=65535 for `ushort`), floating point already in [0, 1].
                let max = match property {
                    Property::Float(_) | Property::Double(_) => 1.0,
                    Property::UShort(_) => 65535.0,
                    _ => 255.0,
                };
                match number(property) {
                    Some(v) => self.c[set][k] = v / max,
                    None => return PropertyAccessResult::UnsupportedType,
                }
                return PropertyAccessResult::Set;
            }
        };
        match number(property) {
            Some(v) => *slot = v,
            None => return PropertyAccessResult::UnsupportedType,
        }
        PropertyAccessResult::Set
    }
}

/// Reads the points of a PLY file.
pub fn read_ply(path: &Path) -> Result<PointSet, GeometryError> {
    let (points, has) = read_vertices::<PlyPoint>(path)?;
    Ok(PointSet {
        positions: points.iter().map(|p| p.p).collect(),
        normals: has.normals.then(|| points.iter().map(|p| p.n).collect()),
    })
}

/// Positions, their colours (when the file has them) and a warning, from [`read_ply_colours`].
pub(crate) type PlyColours = (Vec<V3>, Option<Vec<[f32; 3]>>, Option<String>);

/// The points of a PLY file (exactly [`read_ply`]'s positions, failing where it fails) with their
/// colours when the `vertex` element has one of the [`COLOUR_PROPERTIES`] triples (the first
/// complete one), scaled to `[0, 1]`: integer types from `0..=255` (`ushort`: `0..=65535`),
/// `float`/`double` as they are. The string is a warning (without the file name) when only some
/// channels of a triple are present.
pub(crate) fn read_ply_colours(path: &Path) -> Result<PlyColours, GeometryError> {
    let (points, has) = read_vertices::<PlyColourPoint>(path)?;
    let positions = points.iter().map(|p| p.p).collect();
    let colours = has.colours.map(|set| points.iter().map(|p| p.c[set]).collect());
    Ok((positions, colours, has.partial_colours))
}

/// What the `vertex` element of a PLY header declares besides `x y z`.
struct VertexProperties {
    normals: bool,
    /// The first complete colour triple of [`COLOUR_PROPERTIES`].
    colours: Option<usize>,
    /// A warning about a colour triple with only some of its channels.
    partial_colours: Option<String>,
}

/// Reads every element of a PLY file, keeping the `vertex` elements as `P`, with [`read_ply`]'s
/// checks and errors.
fn read_vertices<P: PropertyAccess>(path: &Path) -> Result<(Vec<P>, VertexProperties), GeometryError> {
    let file =
        std::fs::File::open(path).map_err(|e| GeometryError::Io { path: path.to_path_buf(), source: e })?;
    let bad = |m: String| GeometryError::malformed(path, m);
    let mut reader = Reader::new(BufReader::new(file));
    let parser = Parser::<P>::new();
    let header = parser.read_header(&mut reader).map_err(|e| bad(format!("not a valid PLY header: {e}")))?;
    let vertex =
        header.elements.get("vertex").ok_or_else(|| bad("the PLY file has no `vertex` element".into()))?;
    let has = |k: &str| vertex.properties.contains_key(k);
    if !(has("x") && has("y") && has("z")) {
        return Err(bad("the `vertex` element lacks one of the properties x, y, z".into()));
    }
    let normal_props = ["nx", "ny", "nz"].iter().filter(|k| has(k)).count();
    if normal_props != 0 && normal_props != 3 {
        return Err(bad("the `vertex` element has only some of nx, ny, nz".into()));
    }
    let colours = COLOUR_PROPERTIES.iter().position(|names| names.iter().all(|k| has(k)));
    let partial_colours = match colours {
        Some(_) => None,
        None => COLOUR_PROPERTIES.iter().find(|names| names.iter().any(|k| has(k))).map(|names| {
            format!("the `vertex` element has only some of {}: its colours are ignored", names.join(", "))
        }),
    };
    let props = VertexProperties { normals: normal_props == 3, colours, partial_colours };
    let mut points = Vec::new();
    for (name, def) in &header.elements {
        let items = parser
            .read_payload_for_element(&mut reader, def, &header)
            .map_err(|e| bad(format!("element `{name}` ({} declared): {e}", def.count)))?;
        if name == "vertex" {
            points = items;
        }
    }
    check_no_trailing_data(reader.get_mut()).map_err(bad)?;
    Ok((points, props))
}

/// Errors when anything but whitespace follows the declared elements.
fn check_no_trailing_data(r: &mut impl BufRead) -> Result<(), String> {
    let mut buf = [0u8; 4096];
    let mut extra = 0usize;
    loop {
        let n = r.read(&mut buf).map_err(|e| format!("read error after the last element: {e}"))?;
        if n == 0 {
            break;
        }
        if buf[..n].iter().any(|b| !b.is_ascii_whitespace()) {
            return Err(
                "data continues after the last element: the header declares fewer elements than the file holds"
                    .into(),
            );
        }
        extra += n;
        if extra > 1 << 16 {
            return Err("more than 64 KiB of trailing whitespace after the last element".into());
        }
    }
    Ok(())
}

/// Whether a PLY file's header declares faces (a mesh saved as PLY, of which [`read_ply`] reads
/// only the vertices). Reads the header only; `false` when there is no readable header.
pub fn declares_faces(path: &Path) -> bool {
    let Ok(f) = std::fs::File::open(path) else { return false };
    for line in BufReader::new(f).split(b'\n').take(200).map_while(Result::ok) {
        let line = String::from_utf8_lossy(&line);
        let words: Vec<&str> = line.split_whitespace().collect();
        if words.first() == Some(&"end_header") {
            break;
        }
        if words.len() == 3 && words[0] == "element" && words[1] == "face" {
            return words[2].parse::<u64>().is_ok_and(|n| n > 0);
        }
    }
    false
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn faces_are_found_in_the_header() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("m.ply");
        let header = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n";
        std::fs::write(&p, format!("{header}element face 1\nend_header\n")).unwrap();
        assert!(declares_faces(&p));
        std::fs::write(&p, format!("{header}end_header\n")).unwrap();
        assert!(!declares_faces(&p));
        assert!(!declares_faces(&dir.path().join("missing.ply")));
    }
}
