//! Geometry sources for Nuvo.
//!
//! Nuvo needs one thing from the scene: batches of visible surface points with unit normals. Every
//! input kind (triangle mesh, point cloud, density field) implements [`GeometrySource`] and is built
//! by name through the [`SourceRegistry`], so an experiment config picks one with
//! `[geometry] source = "mesh"`.
//!
//! **Frame invariant.** Everything a source hands out (samples, bounds, its mesh) is in the
//! *canonical frame*: centred on the input's bounding-box centre and scaled so the longest half-extent
//! is 1, i.e. inside `[-1, 1]^3`. [`GeometrySource::to_canonical`] is the similarity that got it there;
//! writers apply its inverse so outputs land in the input's own coordinates.
//!
//! | source | input | sampling |
//! |---|---|---|
//! | `mesh` ([`mesh_source`]) | `.obj`, `.gltf`, `.glb`, `.ply` with faces | area-uniform, or first hits of camera rays |
//! | `point_cloud` ([`point_cloud`]) | `.ply` (its vertices), `.xyz` | random stored points; normals estimated if absent |
//! | `density` ([`density`]) | `.npy` 3-D grid | volume-rendering weights along camera rays; its mesh by marching cubes ([`isosurface`]) |

#![warn(missing_docs)]

pub mod appearance;
pub mod camera;
pub(crate) mod coords;
pub mod density;
pub mod error;
pub mod frame;
pub mod gltf_io;
pub mod isosurface;
pub mod load;
pub mod mesh;
pub mod mesh_source;
pub mod normals;
pub mod npy;
pub mod obj;
pub mod options;
pub mod ply;
pub mod point_cloud;
pub mod profile;
pub mod raycast;
pub mod registry;
pub mod sampling;
pub(crate) mod seeding;
pub mod source;
#[doc(hidden)]
pub mod testdata;
pub mod volume;
pub mod xyz;

pub use coords::MAX_COORDINATE;
pub use error::GeometryError;
pub use frame::{Aabb, Similarity};
pub use load::load_mesh;
pub use mesh::{TriMesh, UvLayer};
pub use registry::{BuildContext, SourceBuilder, SourceRegistry};
pub use source::{GeometrySource, SurfaceSamples};
