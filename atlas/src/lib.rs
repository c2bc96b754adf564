//! nuvo-atlas: everything that starts from a mesh and its UVs.

pub mod bake;
pub mod camera;
pub mod error;
pub mod export;
pub mod fsio;
pub mod load;
pub mod metrics;
pub mod pack;
mod raster;
pub mod render;
#[cfg(test)]
mod testmesh;
pub mod uvstats;
mod vecmath;

pub use camera::{Camera, orbit_views};
pub use error::AtlasError;
pub use render::{GBuffer, Pixel, render};
