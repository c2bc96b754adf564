//! Name → constructor registry of geometry sources, consulted by the trainer's config loader.
//!
//! Built-in sources register themselves in [`SourceRegistry::with_builtins`]; an application can add
//! its own with [`SourceRegistry::register`] before loading a config (bevy-style registration).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use crate::error::GeometryError;
use crate::source::GeometrySource;

/// What a builder may need besides its options table.
#[derive(Clone, Debug)]
pub struct BuildContext {
    /// Relative paths in the options table are resolved against this folder (the config's folder,
    /// or the working directory for paths given on the command line).
    pub base_dir: PathBuf,
}

impl BuildContext {
    /// Resolves `path` against [`BuildContext::base_dir`] unless it is absolute.
    pub fn resolve(&self, path: &Path) -> PathBuf {
        if path.is_absolute() { path.to_path_buf() } else { self.base_dir.join(path) }
    }
}

/// Builds a source from its options: the `[geometry]` table without the `source` key.
pub type SourceBuilder = fn(&toml::Table, &BuildContext) -> Result<Box<dyn GeometrySource>, GeometryError>;

struct Entry {
    summary: &'static str,
    build: SourceBuilder,
}

/// The registry of geometry sources by name.
#[derive(Default)]
pub struct SourceRegistry {
    entries: BTreeMap<String, Entry>,
}

impl SourceRegistry {
    /// An empty registry.
    pub fn new() -> Self {
        Self::default()
    }

    /// A registry with every source this crate provides.
    pub fn with_builtins() -> Self {
        let mut r = Self::new();
        r.register(
            "mesh",
            "triangle mesh (.obj/.gltf/.glb), area-uniform or visible-surface sampling",
            crate::mesh_source::MeshSource::build,
        );
        r.register(
            "density",
            "volume density grid (.npy), volume-rendering weights along camera rays",
            crate::density::DensitySource::build,
        );
        r.register(
            "point_cloud",
            "point cloud (.ply/.xyz), random stored points with file or estimated normals",
            crate::point_cloud::PointCloudSource::build,
        );
        r
    }

    /// Registers (or replaces) the source `name`.
    pub fn register(&mut self, name: &str, summary: &'static str, build: SourceBuilder) {
        self.entries.insert(name.to_owned(), Entry { summary, build });
    }

    /// The registered names with their one-line summaries, sorted by name.
    pub fn list(&self) -> impl Iterator<Item = (&str, &'static str)> {
        self.entries.iter().map(|(k, e)| (k.as_str(), e.summary))
    }

    /// Builds source `name` from `options`; an unknown name lists the known ones.
    pub fn build(
        &self,
        name: &str,
        options: &toml::Table,
        ctx: &BuildContext,
    ) -> Result<Box<dyn GeometrySource>, GeometryError> {
        let entry = self.entries.get(name).ok_or_else(|| GeometryError::UnknownSource {
            name: name.to_owned(),
            known: self.entries.keys().cloned().collect::<Vec<_>>().join(", "),
        })?;
        (entry.build)(options, ctx)
    }
}
