//! The paper's eight losses (Srinivasan et al. 2024, "Losses").

mod cluster;
mod cycle;
mod distortion;
mod entropy;
mod surface;
mod texture;

pub use cluster::Cluster;
pub use cycle::{Cycle2d, Cycle3d};
pub use distortion::{Conformal, Stretch, StretchOptions};
pub use entropy::Entropy;
pub use surface::Surface;
pub use texture::Texture;

use crate::registry::LossRegistry;

/// Registers every built-in loss.
pub fn register_all(r: &mut LossRegistry) {
    r.register(cycle::CYCLE_3D, cycle::build_3d);
    r.register(cycle::CYCLE_2D, cycle::build_2d);
    r.register(entropy::INFO, entropy::build);
    r.register(surface::INFO, surface::build);
    r.register(cluster::INFO, cluster::build);
    r.register(distortion::CONFORMAL, distortion::build_conformal);
    r.register(distortion::STRETCH, distortion::build_stretch);
    r.register(texture::INFO, texture::build);
}
