//! nuvo-atlas: everything that starts from a mesh and its UVs.

pub mod camera;
pub mod error;
pub mod load;
pub mod metrics;
mod raster;
pub mod render;
#[cfg(test)]
mod testmesh;
pub mod uvstats;
mod vecmath;

pub use camera::{Camera, orbit_views};
pub use error::AtlasError;
pub use render::{GBuffer, Pixel, render};
