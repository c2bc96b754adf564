//! The one error type of this crate. Every variant names the file (when there is one) and the problem,
//! because users feed this crate broken files and must be told which and why.

use std::path::PathBuf;

/// Anything that can go wrong reading or sampling geometry.
#[derive(Debug, thiserror::Error)]
pub enum GeometryError {
    /// The file could not be read at all (missing, a directory, permissions).
    #[error("cannot read {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What the operating system said.
        #[source]
        source: std::io::Error,
    },
    /// The file was read but its content is not valid for its format.
    #[error("{path}: {message}")]
    Malformed {
        /// The file.
        path: PathBuf,
        /// The problem, as a sentence.
        message: String,
    },
    /// The content parsed but is unusable (no faces, NaN coordinates, ...).
    #[error("{path}: {message}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// The problem, as a sentence.
        message: String,
    },
    /// A source's options table is wrong (unknown key, wrong type, bad value).
    #[error("geometry source `{source_name}`: {message}")]
    Options {
        /// The registry name of the source whose options are wrong.
        source_name: String,
        /// The problem (serde names the key and the valid ones for unknown keys).
        message: String,
    },
    /// No source is registered under this name.
    #[error("unknown geometry source `{name}`; known sources: {known}")]
    UnknownSource {
        /// The name asked for.
        name: String,
        /// The registered names, comma-separated.
        known: String,
    },
}

impl GeometryError {
    /// Shorthand for [`GeometryError::Malformed`].
    pub fn malformed(path: impl Into<PathBuf>, message: impl Into<String>) -> Self {
        Self::Malformed { path: path.into(), message: message.into() }
    }

    /// Shorthand for [`GeometryError::Invalid`].
    pub fn invalid(path: impl Into<PathBuf>, message: impl Into<String>) -> Self {
        Self::Invalid { path: path.into(), message: message.into() }
    }

    /// Refuses a directory where a file is expected, before the extension dispatch would report a
    /// confusing "unsupported extension" or the OS an unexplained "Is a directory".
    pub(crate) fn require_file(path: &std::path::Path) -> Result<(), Self> {
        if path.is_dir() {
            return Err(Self::invalid(
                path,
                "is a directory, not a file; give the path of the file inside it",
            ));
        }
        Ok(())
    }
}
