//! PLY point reading (ASCII and binary, via the maintained `ply-rs-bw` fork of `ply-rs`, which caps
//! preallocation by header counts and reports truncation with line numbers). Only the `vertex`
//! element's `x y z` (and `nx ny nz` when all three are present) are kept; other elements are read
//! past. Data after the last declared element means the header understates a count: an error.

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
        *slot = match property {
            Property::Float(v) => v,
            Property::Double(v) => v as f32,
            Property::Char(v) => f32::from(v),
            Property::UChar(v) => f32::from(v),
            Property::Short(v) => f32::from(v),
            Property::UShort(v) => f32::from(v),
            Property::Int(v) => v as f32,
            Property::UInt(v) => v as f32,
            _ => return PropertyAccessResult::UnsupportedType,
        };
        PropertyAccessResult::Set
    }
}

/// Reads the points of a PLY file.
pub fn read_ply(path: &Path) -> Result<PointSet, GeometryError> {
    let file =
        std::fs::File::open(path).map_err(|e| GeometryError::Io { path: path.to_path_buf(), source: e })?;
    let bad = |m: String| GeometryError::malformed(path, m);
    let mut reader = Reader::new(BufReader::new(file));
    let parser = Parser::<PlyPoint>::new();
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
    Ok(PointSet {
        positions: points.iter().map(|p| p.p).collect(),
        normals: (normal_props == 3).then(|| points.iter().map(|p| p.n).collect()),
    })
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
