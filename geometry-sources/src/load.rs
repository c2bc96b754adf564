//! Loading any supported mesh file by its extension.

use std::path::Path;

use crate::error::GeometryError;
use crate::mesh::TriMesh;

/// The mesh file extensions [`load_mesh`] understands (lower case).
pub const MESH_EXTENSIONS: &[&str] = &["obj", "gltf", "glb", "ply"];

/// Reads a triangle mesh from `.obj`, `.gltf`, `.glb` or `.ply` (case-insensitive extension), with
/// its UVs when the file has them for every face (a PLY mesh has none; a PLY without faces is a
/// point cloud, an error here). The result is validated ([`TriMesh::validate`]) and has at
/// least one face; degenerate faces are kept (see [`TriMesh::has_area`]).
pub fn load_mesh(path: &Path) -> Result<TriMesh, GeometryError> {
    GeometryError::require_file(path)?;
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).unwrap_or_default();
    match ext.as_str() {
        "obj" => crate::obj::load_obj(path),
        "gltf" | "glb" => crate::gltf_io::load_gltf(path),
        "ply" => crate::ply::read_ply_mesh(path),
        _ => Err(GeometryError::invalid(
            path,
            format!("unsupported mesh extension `.{ext}`; supported: {}", dotted(MESH_EXTENSIONS)),
        )),
    }
}

/// `["a", "b"]` → "`.a`, `.b`".
pub(crate) fn dotted(exts: &[&str]) -> String {
    exts.iter().map(|e| format!("`.{e}`")).collect::<Vec<_>>().join(", ")
}
