//! Reading meshes for evaluation: the one place that decides which reader handles which file.
//!
//! The readers live in `nuvo-geometry` (OBJ, glTF and GLB with `TEXCOORD_0`, PLY meshes without
//! UVs); this module adds the requirement that a mesh to be measured has texture coordinates.

use std::path::Path;

use nuvo_geometry::TriMesh;

use crate::error::AtlasError;

/// Reads the mesh at `path` (`.obj`, `.gltf`, `.glb`, `.ply` with faces). Errors name the file: missing, unreadable,
/// malformed, or an unsupported extension.
pub fn load_mesh(path: &Path) -> Result<TriMesh, AtlasError> {
    Ok(nuvo_geometry::load_mesh(path)?)
}

/// [`load_mesh`], then requires texture coordinates ([`AtlasError::NoUv`] naming the file).
pub fn load_mesh_with_uv(path: &Path) -> Result<TriMesh, AtlasError> {
    let mesh = load_mesh(path)?;
    if mesh.uv.is_none() {
        return Err(AtlasError::NoUv { what: path.display().to_string() });
    }
    Ok(mesh)
}
