//! Reading meshes for evaluation: the one place that decides which reader handles which file.
//!
//! Only OBJ is read for now, through `nuvo_geometry::obj::load_obj`. When `nuvo-geometry` gains its
//! `load_mesh` (OBJ + glTF/GLB with `TEXCOORD_0`), [`load_mesh`] becomes a call to it.

use std::path::Path;

use nuvo_geometry::TriMesh;

use crate::error::AtlasError;

/// Reads the mesh at `path`, choosing the reader by extension (case-insensitive): `.obj`.
/// Errors name the file: missing, unreadable, malformed, or an unsupported extension.
pub fn load_mesh(path: &Path) -> Result<TriMesh, AtlasError> {
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    match ext.as_str() {
        "obj" => Ok(nuvo_geometry::obj::load_obj(path)?),
        _ => Err(AtlasError::UnsupportedFormat { path: path.to_path_buf(), ext }),
    }
}

/// [`load_mesh`], then requires texture coordinates ([`AtlasError::NoUv`] naming the file).
pub fn load_mesh_with_uv(path: &Path) -> Result<TriMesh, AtlasError> {
    let mesh = load_mesh(path)?;
    if mesh.uv.is_none() {
        return Err(AtlasError::NoUv { what: path.display().to_string() });
    }
    Ok(mesh)
}
