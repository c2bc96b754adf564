//! PLY reading (ASCII and binary, via the maintained `ply-rs-bw` fork of `ply-rs`, which caps
//! preallocation by header counts and reports truncation with line numbers).
//!
//! - As points ([`read_ply`]): the `vertex` element's `x y z` (and `nx ny nz` when all three are
//!   present); other elements are read past.
//! - As a mesh ([`read_ply_mesh`], what [`crate::load_mesh`] reads for `.ply`): the vertices in the
//!   file's order and the `face` element's `vertex_indices` (or `vertex_index`) lists,
//!   fan-triangulated like OBJ polygons, in the file's order; a file without faces is not a mesh.
//!
//! (The appearance reader, [`crate::appearance`], reads the same files with their vertex
//! colours.) Data after the last declared element means the header understates a count: an error.

use std::io::{BufRead, BufReader};
use std::path::Path;

use ply_rs_bw::parser::{Parser, Reader};
use ply_rs_bw::ply::{Property, PropertyAccess, PropertyAccessResult};

use crate::coords::V3;
use crate::error::GeometryError;
use crate::mesh::TriMesh;

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

/// A PLY `face` element: its vertex index list.
#[derive(Clone, Default)]
struct PlyFace {
    indices: Vec<i64>,
    /// The list had a type that cannot hold indices (floating point).
    bad_type: bool,
}

/// The property names of a face's vertex list, in order of preference.
const FACE_LIST: [&str; 2] = ["vertex_indices", "vertex_index"];

impl PropertyAccess for PlyFace {
    fn new() -> Self {
        PlyFace::default()
    }

    fn set_property(&mut self, name: &str, property: Property) -> PropertyAccessResult {
        if !FACE_LIST.contains(&name) {
            return PropertyAccessResult::Ignored;
        }
        self.indices = match property {
            Property::ListChar(v) => v.into_iter().map(i64::from).collect(),
            Property::ListUChar(v) => v.into_iter().map(i64::from).collect(),
            Property::ListShort(v) => v.into_iter().map(i64::from).collect(),
            Property::ListUShort(v) => v.into_iter().map(i64::from).collect(),
            Property::ListInt(v) => v.into_iter().map(i64::from).collect(),
            Property::ListUInt(v) => v.into_iter().map(i64::from).collect(),
            _ => {
                self.bad_type = true;
                return PropertyAccessResult::UnsupportedType;
            }
        };
        PropertyAccessResult::Set
    }
}

/// A PLY mesh as [`read_ply_mesh`] reads it: the mesh, the vertex colours when the `vertex`
/// element has a complete [`COLOUR_PROPERTIES`] triple (scaled as [`read_ply_colours`] scales
/// them), and a warning (without the file name) about a partial triple.
pub(crate) type PlyMesh = (TriMesh, Option<Vec<[f32; 3]>>, Option<String>);

/// Reads a PLY file as a triangle mesh (module docs), validated. Errors name the file: no `face`
/// element or no faces (a point cloud: read it with [`read_ply`]), a face list that is missing, of
/// a floating-point type or shorter than 3, an index out of range, and every error of [`read_ply`].
pub fn read_ply_mesh(path: &Path) -> Result<TriMesh, GeometryError> {
    read_ply_mesh_coloured(path).map(|(mesh, _, _)| mesh)
}

/// [`read_ply_mesh`] with the vertex colours (see [`PlyMesh`]).
pub(crate) fn read_ply_mesh_coloured(path: &Path) -> Result<PlyMesh, GeometryError> {
    let bad = |m: String| GeometryError::malformed(path, m);
    let mut faces: Vec<PlyFace> = Vec::new();
    let mut face_list_missing = false;
    let (points, has) = read_elements::<PlyColourPoint>(path, &mut |name, def, reader, header| {
        if name != "face" {
            return Ok(false);
        }
        face_list_missing = !FACE_LIST.iter().any(|k| def.properties.contains_key(*k));
        faces = Parser::<PlyFace>::new()
            .read_payload_for_element(reader, def, header)
            .map_err(|e| format!("element `face` ({} declared): {e}", def.count))?;
        Ok(true)
    })?;
    if faces.is_empty() {
        return Err(GeometryError::invalid(
            path,
            "the PLY file has no faces: it is a point cloud (`[geometry] source = \"point_cloud\"`), not a mesh",
        ));
    }
    if face_list_missing {
        return Err(bad(format!("the `face` element has no `{}` list", FACE_LIST[0])));
    }
    let mut mesh = TriMesh { positions: points.iter().map(|p| p.p).collect(), ..Default::default() };
    let n = mesh.positions.len() as i64;
    for (f, face) in faces.iter().enumerate() {
        if face.bad_type {
            return Err(bad(format!("face {}: the vertex index list is not of an integer type", f + 1)));
        }
        if face.indices.len() < 3 {
            return Err(bad(format!(
                "face {} has {} vertices; a face needs at least 3",
                f + 1,
                face.indices.len()
            )));
        }
        if let Some(&i) = face.indices.iter().find(|&&i| !(0..n).contains(&i)) {
            return Err(GeometryError::invalid(
                path,
                format!("face {} refers to vertex {i} but there are only {n} vertices (0-based)", f + 1),
            ));
        }
        let c = &face.indices;
        for k in 1..c.len() - 1 {
            mesh.triangles.push([c[0] as u32, c[k] as u32, c[k + 1] as u32]);
        }
    }
    mesh.validate().map_err(|m| GeometryError::invalid(path, m))?;
    let colours = has.colours.map(|set| points.iter().map(|p| p.c[set]).collect());
    Ok((mesh, colours, has.partial_colours))
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
    read_elements(path, &mut |_, _, _, _| Ok(false))
}

/// What [`read_elements`] hands every element other than `vertex` to: `(name, definition,
/// reader, header)`; it returns whether it read the element's payload itself (else it is read
/// past), or an error without the file name.
type ElementHook<'a> = dyn FnMut(
        &str,
        &ply_rs_bw::ply::ElementDef,
        &mut Reader<BufReader<std::fs::File>>,
        &ply_rs_bw::ply::Header,
    ) -> Result<bool, String>
    + 'a;

/// [`read_vertices`], with `other` given the chance to read each other element.
fn read_elements<P: PropertyAccess>(
    path: &Path,
    other: &mut ElementHook,
) -> Result<(Vec<P>, VertexProperties), GeometryError> {
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
        if name != "vertex" && other(name, def, &mut reader, &header).map_err(bad)? {
            continue;
        }
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

    /// An ASCII PLY with `body` after a header of `vertices` coloured vertices and `faces` faces.
    fn ply(
        dir: &Path,
        name: &str,
        vertices: usize,
        faces: usize,
        face_list: &str,
        body: &str,
    ) -> std::path::PathBuf {
        let p = dir.join(name);
        std::fs::write(
            &p,
            format!(
                "ply\nformat ascii 1.0\nelement vertex {vertices}\nproperty float x\nproperty float y\n\
                 property float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n\
                 element face {faces}\n{face_list}\nend_header\n{body}"
            ),
        )
        .unwrap();
        p
    }

    const QUAD: &str =
        "0 0 0 255 0 0\n1 0 0 0 255 0\n1 1 0 0 0 255\n0 1 0 255 255 255\n9 9 9 0 0 0\n4 3 2 1 0\n";

    #[test]
    fn a_ply_mesh_keeps_its_vertices_and_fans_its_polygons() {
        let dir = tempfile::tempdir().unwrap();
        let p = ply(dir.path(), "quad.ply", 5, 1, "property list uchar int vertex_indices", QUAD);
        let m = read_ply_mesh(&p).unwrap();
        assert_eq!(m.positions.len(), 5, "unreferenced vertices are kept, in order");
        assert_eq!(m.positions[4], [9.0, 9.0, 9.0]);
        assert_eq!(m.triangles, vec![[3, 2, 1], [3, 1, 0]]);
        assert_eq!(crate::load_mesh(&p).unwrap(), m);
        let (_, colours, warning) = read_ply_mesh_coloured(&p).unwrap();
        assert_eq!(colours.unwrap()[1], [0.0, 1.0, 0.0]);
        assert!(warning.is_none());
        // `vertex_index` and unsigned lists work too.
        let p = ply(dir.path(), "alt.ply", 5, 1, "property list uchar uint vertex_index", QUAD);
        assert_eq!(read_ply_mesh(&p).unwrap(), m);
    }

    #[test]
    fn a_bad_ply_mesh_is_an_error_naming_the_file_and_the_face() {
        let dir = tempfile::tempdir().unwrap();
        let list = "property list uchar int vertex_indices";
        let cases = [
            ("out_of_range.ply", 1, list, "0 0 0 1 1 1\n3 0 0 7\n", "face 1 refers to vertex 7"),
            ("two.ply", 1, list, "0 0 0 1 1 1\n2 0 0\n", "face 1 has 2 vertices"),
            (
                "float.ply",
                1,
                "property list uchar float vertex_indices",
                "0 0 0 1 1 1\n3 0 0 0\n",
                "element `face`",
            ),
            ("no_list.ply", 1, "property uchar flags", "0 0 0 1 1 1\n7\n", "vertex_indices"),
            ("no_faces.ply", 0, list, "0 0 0 1 1 1\n", "point cloud"),
        ];
        for (name, faces, face_list, body, want) in cases {
            let p = ply(dir.path(), name, 1, faces, face_list, body);
            let e = crate::load_mesh(&p).unwrap_err().to_string();
            assert!(e.contains(name) && e.contains(want), "{name}: {e}");
        }
    }

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
