//! nuvo-atlas: everything that starts from a mesh and its UVs — baking Nuvo's charts onto a mesh,
//! packing them into one atlas, writing OBJ/MTL and GLB, drawing pictures, and measuring the
//! paper's metrics with a software renderer. It does not depend on the trainer: its inputs are a
//! [`nuvo_geometry::TriMesh`] and plain arrays.
//!
//! | module | what |
//! |---|---|
//! | [`mod@bake`] | per-vertex chart probabilities + chart UVs → one UV layer in the packed atlas |
//! | [`pack`] | grid packing of the `n` square charts, with gutters, as affine maps |
//! | [`islands`] | repacking a layout's UV islands at one texel density, rotated, with gutters |
//! | [`export`] | OBJ + MTL and binary glTF writers, in the input's own coordinates |
//! | [`pictures`] | UV layout, labelled checkerboard, textured renders, chart-grid (normal) PNGs |
//! | [`mod@render`], [`camera`] | z-buffer rasteriser producing triangle id / barycentrics / depth |
//! | [`metrics`] | Boundary, Stretch, Conformal, Editability over seeded views (definitions there) |
//! | [`uvstats`] | charts, flips, utilisation and overlaps of a UV layout |
//! | [`partuv`] | the PartUV comparison's charts, seams, angular score, area distortions, packing |
//! | [`necks`] | cutting islands at their necks where the packer says the atlas gets tighter |
//! | [`creases`] | cutting islands along sharp creases where the renders say the atlas gains |
//! | [`join`] | joining small islands into a neighbouring one where that stays injective |
//! | [`refine`] | local/global ARAP refinement of each UV island from its current UVs, never adding flips |
//! | [`injective`] | every island made injective (no flip, no self-overlap) and its distortion lowered by SLIM |
//! | [`texture`] | baking a colour texture (the input's appearance) through the atlas's UVs, gutters filled |
//! | [`untangle`] | turning flipped faces back by moving single UV vertices (the bake's option) |
//! | [`load`] | choosing the mesh reader by extension |
//!
//! The exact metric definitions and defaults are in the [`metrics`], [`uvstats`] and [`partuv`]
//! module docs and in `atlas/README.md`.

#![warn(missing_docs)]

pub mod bake;
pub mod camera;
pub mod creases;
pub mod enclaves;
pub mod error;
pub mod export;
mod font;
mod geom;
pub mod gltf_scene;
pub mod injective;
pub mod islands;
pub mod join;
pub mod load;
pub mod metrics;
mod mincut;
pub mod necks;
pub mod pack;
pub mod partuv;
pub mod pictures;
mod raster;
pub mod refine;
pub mod render;
#[cfg(test)]
mod testmesh;
pub mod texture;
pub mod untangle;
pub mod uvstats;

pub use bake::{BakeOptions, Baked, ChartFields, RoundTrip, bake};
pub use camera::{Camera, orbit_views};
pub use error::AtlasError;
pub use metrics::{EvalOptions, Metrics, evaluate};
pub use pack::AtlasLayout;
pub use partuv::{PartUvMetrics, partuv_metrics};
pub use render::{GBuffer, Pixel, render};
