//! nuvo-atlas: everything that starts from a mesh and its UVs.

pub mod camera;
pub mod error;
mod raster;
pub mod render;
mod vecmath;

pub use camera::{Camera, orbit_views};
pub use error::AtlasError;
pub use render::{GBuffer, Pixel, render};
