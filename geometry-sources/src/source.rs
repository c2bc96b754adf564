//! The [`GeometrySource`] trait: what the trainer needs from any scene representation.

use std::path::Path;

use crate::frame::{Aabb, Similarity};
use crate::mesh::TriMesh;

/// Surface samples in the canonical frame. Invariant: `positions.len() == normals.len()` and every
/// normal has unit length.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SurfaceSamples {
    /// Sample points in the canonical frame.
    pub positions: Vec<[f32; 3]>,
    /// Unit normals, one per point, pointing out of the surface (towards the viewer for visible samples).
    pub normals: Vec<[f32; 3]>,
}

impl SurfaceSamples {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    /// True when there are no samples.
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }
}

/// A scene representation Nuvo can be trained on.
///
/// Sampling takes a `seed` rather than an RNG: the same `(n, seed)` must give the same samples on any
/// thread count, and the trainer derives the seed from the run seed and the step number, so a resumed
/// run draws exactly the batches an uninterrupted one would have.
pub trait GeometrySource: Send + Sync {
    /// The registry name of this kind of source (`mesh`, `point_cloud`, `density`, ...).
    fn kind(&self) -> &str;

    /// Draws `n` visible surface points with outward unit normals, in the canonical frame.
    fn sample(&self, n: usize, seed: u64) -> SurfaceSamples;

    /// The bounds of the geometry in the canonical frame (inside `[-1, 1]^3`).
    fn bounds(&self) -> Aabb;

    /// The map from the input's own coordinates into the canonical frame.
    fn to_canonical(&self) -> Similarity;

    /// The triangle mesh in the canonical frame, when this source has one (for baking and metrics).
    fn mesh(&self) -> Option<&TriMesh> {
        None
    }

    /// The vertex positions of [`GeometrySource::mesh`] exactly as the input file stored them, when
    /// the source read them from a file: writers use them instead of mapping the canonical ones back,
    /// which would change the last bits of a user's coordinates.
    fn input_positions(&self) -> Option<&[[f32; 3]]> {
        None
    }

    /// The file the geometry was read from, when there is one: where its colours are looked for
    /// when a bake carries the input's appearance over (`crate::appearance`).
    fn file(&self) -> Option<&Path> {
        None
    }

    /// One line describing what was loaded, for logs ("mesh assets/bunny.obj: 69451 faces ...").
    fn describe(&self) -> String;
}
