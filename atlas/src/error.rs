//! The one error type of this crate. Every variant says which file or which input is wrong and why,
//! because the CLI shows these messages to users as they are.

use std::path::PathBuf;

use nuvo_geometry::GeometryError;

/// Anything that can go wrong loading, measuring, baking or writing an atlas.
#[derive(Debug, thiserror::Error)]
pub enum AtlasError {
    /// Reading the mesh failed (missing file, not a valid mesh...). The inner error names the file.
    #[error(transparent)]
    Geometry(#[from] GeometryError),
    /// The mesh has no texture coordinates, but the operation measures or exports them.
    #[error("{what}: the mesh has no texture coordinates (UVs); give a mesh whose faces carry UVs")]
    NoUv {
        /// The file, or `mesh` for an in-memory mesh.
        what: String,
    },
    /// The file extension is not one this crate can read.
    #[error("{path}: unsupported mesh format {ext:?}; supported: .obj")]
    UnsupportedFormat {
        /// The file.
        path: PathBuf,
        /// Its extension, lower-cased.
        ext: String,
    },
    /// Writing an output file failed. Nothing is left at `path` (writes are atomic).
    #[error("cannot write {path}: {source}")]
    Write {
        /// The destination.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// Encoding an output (PNG, glTF) failed before anything was written.
    #[error("cannot encode {path}: {message}")]
    Encode {
        /// The destination.
        path: PathBuf,
        /// What the encoder said.
        message: String,
    },
    /// An argument is out of its documented domain (array shapes, resolutions, cameras...).
    #[error("invalid {what}: {message}")]
    Invalid {
        /// Which argument.
        what: &'static str,
        /// What is wrong with it.
        message: String,
    },
    /// No camera saw any surface, so image-space metrics are undefined.
    #[error("no view sees any surface of the mesh (all {views} views are empty); is the mesh degenerate?")]
    NothingVisible {
        /// How many views were rendered.
        views: usize,
    },
}

impl AtlasError {
    /// Shorthand for [`AtlasError::Invalid`].
    pub fn invalid(what: &'static str, message: impl Into<String>) -> Self {
        Self::Invalid { what, message: message.into() }
    }
}

/// [`nuvo_fsio::write_atomic`] with the failure reported as [`AtlasError::Write`] naming
/// `path`.
pub(crate) fn write_atomic(
    path: &std::path::Path,
    fill: impl FnOnce(&mut dyn std::io::Write) -> std::io::Result<()>,
) -> Result<(), AtlasError> {
    nuvo_fsio::write_atomic(path, fill)
        .map_err(|source| AtlasError::Write { path: path.to_path_buf(), source })
}
