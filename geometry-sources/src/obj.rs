//! Wavefront OBJ reading (via `tobj`), with texture coordinates when the file has them.

use std::path::Path;

use crate::error::GeometryError;
use crate::mesh::{TriMesh, UvLayer};

/// Reads every object of an OBJ file into one triangle mesh, triangulating polygons. Texture
/// coordinates are kept per corner when every face has them; a file where only some faces do is
/// reported as malformed rather than silently mixed.
pub fn load_obj(path: &Path) -> Result<TriMesh, GeometryError> {
    load_obj_full(path, false).map(|read| read.mesh)
}

/// What [`load_obj_full`] reads besides the mesh, for the appearance reader
/// ([`crate::appearance`]); empty unless asked for.
#[derive(Debug, Default)]
pub(crate) struct ObjAppearance {
    /// The materials of every `mtllib` tobj could read (`Err` when it could read none and one
    /// failed).
    pub materials: Option<Result<Vec<tobj::Material>, tobj::LoadError>>,
    /// Per face of the mesh, tobj's material index (`None`: no or an unknown `usemtl`).
    pub face_material: Vec<Option<usize>>,
    /// Per vertex of the mesh, its colour as the file writes it (unscaled), `None` for a vertex
    /// without one.
    pub vertex_colours: Vec<Option<[f32; 3]>>,
    /// The file names of the `mtllib` lines, in file order.
    pub mtllibs: Vec<String>,
}

/// The mesh [`load_obj`] returns and, when `appearance` is set, what the appearance reader needs.
pub(crate) struct ObjRead {
    /// Exactly [`load_obj`]'s mesh.
    pub mesh: TriMesh,
    /// Filled only when asked for.
    pub appearance: ObjAppearance,
}

/// [`load_obj`], optionally keeping the materials, the faces' materials and the vertex colours.
/// The mesh and the errors are the same either way.
pub(crate) fn load_obj_full(path: &Path, appearance: bool) -> Result<ObjRead, GeometryError> {
    let opts = tobj::LoadOptions { triangulate: true, single_index: false, ..Default::default() };
    // `tobj::load_obj` with the MTL files checked first (see `load_mtl_checked`).
    let loaded = match std::fs::File::open(path) {
        Ok(f) => tobj::load_obj_buf(&mut std::io::BufReader::new(f), &opts, |mtl| {
            load_mtl_checked(&path.parent().map_or_else(|| mtl.to_path_buf(), |dir| dir.join(mtl)))
        }),
        Err(_) => Err(tobj::LoadError::OpenFileFailed),
    };
    let (models, materials) = loaded.map_err(|e| match e {
        tobj::LoadError::OpenFileFailed => GeometryError::Io {
            path: path.to_path_buf(),
            source: std::fs::metadata(path).err().unwrap_or_else(|| std::io::Error::other("cannot open")),
        },
        other => GeometryError::malformed(path, format!("not a valid OBJ file: {other}")),
    })?;
    let mut mesh = TriMesh::default();
    let mut uv = UvLayer::default();
    let mut faces_with_uv = 0usize;
    let mut extra = ObjAppearance::default();
    for model in &models {
        let m = &model.mesh;
        if appearance {
            extra.face_material.extend(std::iter::repeat_n(m.material_id, m.indices.len() / 3));
            let nv = m.positions.len() / 3;
            if m.vertex_color.len() == 3 * nv {
                extra.vertex_colours.extend(m.vertex_color.chunks_exact(3).map(|c| Some([c[0], c[1], c[2]])));
            } else {
                extra.vertex_colours.extend(std::iter::repeat_n(None, nv));
            }
        }
        let v0 = mesh.positions.len() as u32;
        let t0 = uv.coords.len() as u32;
        mesh.positions.extend(m.positions.chunks_exact(3).map(|c| [c[0], c[1], c[2]]));
        uv.coords.extend(m.texcoords.chunks_exact(2).map(|c| [c[0], c[1]]));
        mesh.triangles.extend(m.indices.chunks_exact(3).map(|c| [v0 + c[0], v0 + c[1], v0 + c[2]]));
        if m.texcoord_indices.len() == m.indices.len() && !m.texcoord_indices.is_empty() {
            faces_with_uv += m.indices.len() / 3;
            uv.triangles
                .extend(m.texcoord_indices.chunks_exact(3).map(|c| [t0 + c[0], t0 + c[1], t0 + c[2]]));
        }
    }
    if faces_with_uv > 0 && faces_with_uv != mesh.triangles.len() {
        return Err(GeometryError::malformed(
            path,
            format!(
                "{faces_with_uv} of {} faces have texture coordinates; all or none must",
                mesh.triangles.len()
            ),
        ));
    }
    // Read once more as text for what tobj does not say: which faces have texture indices, and
    // the file's own vertex numbering.
    let bytes = std::fs::read(path).map_err(|e| GeometryError::Io { path: path.to_path_buf(), source: e })?;
    let text = String::from_utf8_lossy(&bytes);
    if faces_with_uv > 0 {
        // tobj quietly reuses the previous texture index for a corner without one, so a file where
        // only some faces have `vt` indices would come back with made-up UVs: check the text.
        let (with, without) = count_faces_with_texture_indices(&text);
        if with > 0 && without > 0 {
            return Err(GeometryError::malformed(
                path,
                format!("{with} faces have texture coordinates and {without} do not; all or none must"),
            ));
        }
        mesh.uv = Some(uv);
    }
    if mesh.triangles.is_empty() {
        return Err(GeometryError::invalid(path, "the mesh has no faces"));
    }
    if let Some((numbered, colours)) = in_file_order(&text, &mesh, appearance) {
        mesh.positions = numbered.positions;
        mesh.triangles = numbered.triangles;
        if let Some(colours) = colours {
            // The vertices are now the file's `v` lines, so their colours are too.
            extra.vertex_colours = colours;
        }
    }
    mesh.validate().map_err(|m| GeometryError::invalid(path, m))?;
    if appearance {
        extra.materials = Some(materials);
        extra.mtllibs = text
            .lines()
            .filter_map(|l| l.trim_start().strip_prefix("mtllib"))
            .filter(|rest| rest.starts_with(char::is_whitespace))
            .map(|rest| rest.trim().to_owned())
            .filter(|name| !name.is_empty())
            .collect();
    }
    Ok(ObjRead { mesh, appearance: extra })
}

/// `tobj::load_mtl`, except that a colour line (`Ka`, `Kd`, `Ks`, `Ke`) with fewer than three
/// values is a parse error instead of a panic inside tobj (whose `parse_float3` unwraps). A failed
/// MTL only loses its materials (the mesh does not use them), as with any other MTL error.
fn load_mtl_checked(path: &Path) -> tobj::MTLLoadResult {
    let Ok(text) = std::fs::read_to_string(path) else {
        return tobj::load_mtl(path); // tobj's own error (missing, not UTF-8, ...)
    };
    let short_colour = text.lines().any(|line| {
        let mut words = line.split_whitespace();
        matches!(words.next(), Some("Ka" | "Kd" | "Ks" | "Ke")) && words.count() < 3
    });
    if short_colour {
        return Err(tobj::LoadError::MaterialParseError);
    }
    tobj::load_mtl_buf(&mut text.as_bytes())
}

/// The mesh's vertices in the file's own order (every `v` line, referenced or not) and its faces
/// indexing them (no UVs), or `None` when the file's `text` does not match what `tobj` read. With
/// `colours`, also each `v` line's colour from the same pass: `v x y z r g b` gives
/// `Some([r, g, b])` (as written), any other `v` line `None`.
///
/// `tobj` numbers the vertices of each object in the order the faces first use them, so a user's
/// vertex `i` would not be ours; a tool that hands UVs back to the user's mesh must keep the file's
/// numbering (`nuvo unwrap` writes `atlas.obj` in it). The file has already been read and checked by
/// `tobj`; this pass re-reads only the `v` and `f` lines, fan-triangulates polygons as `tobj` does,
/// and is used only if every corner lands on the same position as `tobj`'s, so it can never
/// change the geometry, only its numbering.
type VertexColours = Vec<Option<[f32; 3]>>;

fn in_file_order(text: &str, mesh: &TriMesh, colours: bool) -> Option<(TriMesh, Option<VertexColours>)> {
    let mut positions: Vec<[f32; 3]> = Vec::new();
    let mut vertex_colours: VertexColours = Vec::new();
    let mut triangles: Vec<[u32; 3]> = Vec::with_capacity(mesh.triangles.len());
    for line in text.lines() {
        let mut words = line.split_whitespace();
        match words.next() {
            Some("v") => {
                let mut c = [0.0f32; 3];
                for x in &mut c {
                    *x = words.next()?.parse().ok()?;
                }
                positions.push(c);
                if colours {
                    let rgb: Vec<f32> = words.map_while(|w| w.parse().ok()).collect();
                    vertex_colours.push(<[f32; 3]>::try_from(rgb).ok());
                }
            }
            Some("f") => {
                let corners: Vec<u32> = words
                    .map(|w| {
                        let i: i64 = w.split('/').next()?.parse().ok()?;
                        let n = positions.len() as i64;
                        let k = if i < 0 { n + i } else { i - 1 };
                        (0..n).contains(&k).then_some(k as u32)
                    })
                    .collect::<Option<_>>()?;
                for k in 1..corners.len().saturating_sub(1) {
                    triangles.push([corners[0], corners[k], corners[k + 1]]);
                }
            }
            _ => {}
        }
    }
    let same = triangles.len() == mesh.triangles.len()
        && triangles
            .iter()
            .zip(&mesh.triangles)
            .all(|(a, b)| (0..3).all(|k| positions[a[k] as usize] == mesh.positions[b[k] as usize]));
    same.then(|| (TriMesh { positions, triangles, uv: None }, colours.then_some(vertex_colours)))
}

/// Counts `f` lines whose corners all carry a `vt` index, and those with some corner without one.
fn count_faces_with_texture_indices(text: &str) -> (usize, usize) {
    let (mut with, mut without) = (0, 0);
    for line in text.lines() {
        let mut words = line.split_whitespace();
        if words.next() != Some("f") {
            continue;
        }
        if words.all(|w| w.split('/').nth(1).is_some_and(|t| !t.is_empty())) {
            with += 1;
        } else {
            without += 1;
        }
    }
    (with, without)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Writes `text` to `name` in `dir` (a test's own temporary directory, removed when the test
    /// drops it).
    fn write(dir: &tempfile::TempDir, name: &str, text: &str) -> std::path::PathBuf {
        let p = dir.path().join(name);
        std::fs::write(&p, text).unwrap();
        p
    }

    #[test]
    fn reads_quad_with_uvs_as_two_triangles() {
        let dir = tempfile::tempdir().unwrap();
        let p = write(
            &dir,
            "quad.obj",
            "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nf 1/1 2/2 3/3 4/4\n",
        );
        let m = load_obj(&p).unwrap();
        assert_eq!(m.triangles.len(), 2);
        let uv = m.uv.as_ref().unwrap();
        assert_eq!(uv.triangles.len(), 2);
        assert_eq!(uv.coords.len(), 4);
    }

    #[test]
    fn vertices_keep_the_file_order_even_unreferenced_ones() {
        let dir = tempfile::tempdir().unwrap();
        // The faces use vertex 3 first and never use vertex 5; negative indices count back.
        let p = write(&dir, "order.obj", "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 9 9 9\nf 3 4 1\nf 3 -4 -5\n");
        let m = load_obj(&p).unwrap();
        assert_eq!(m.positions.len(), 5);
        assert_eq!(m.positions[4], [9.0, 9.0, 9.0]);
        assert_eq!(m.positions[2], [1.0, 1.0, 0.0]);
        assert_eq!(m.triangles, vec![[2, 3, 0], [2, 1, 0]]);
    }

    #[test]
    fn a_short_colour_line_in_the_mtl_loses_the_materials_not_the_mesh() {
        let dir = tempfile::tempdir().unwrap();
        // tobj itself panics on `Kd 0.5`.
        write(&dir, "short.mtl", "newmtl m\nKd 0.5\n");
        let p = write(&dir, "short.obj", "mtllib short.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl m\nf 1 2 3\n");
        assert_eq!(load_obj(&p).unwrap().triangles.len(), 1);
        let read = load_obj_full(&p, true).unwrap();
        assert!(matches!(read.appearance.materials, Some(Err(tobj::LoadError::MaterialParseError))));
        assert_eq!(read.appearance.face_material, vec![None]);
    }

    #[test]
    fn empty_file_is_an_error_naming_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let p = write(&dir, "empty.obj", "");
        let e = load_obj(&p).unwrap_err().to_string();
        assert!(e.contains("empty.obj"), "{e}");
    }
}
