//! The paper's eight losses (Srinivasan et al. 2024, "Losses").

mod cluster;
mod cycle;
mod distortion;
mod entropy;
mod surface;
mod texture;

pub use cluster::Cluster;
pub use cycle::{Cycle2d, Cycle3d};
pub use distortion::{AreaScale, Conformal, Stretch, StretchOptions};
pub use entropy::Entropy;
pub use surface::Surface;
pub use texture::Texture;

use crate::registry::LossRegistry;

/// The paper's eight losses: what a config without a `[losses]` table trains with. Listed, not
/// taken from the registry, so losses an application registers later never join such a config
/// silently. In name order, the order those configs have always summed their terms in.
pub const PAPER: [&str; 8] =
    ["cluster", "conformal", "cycle_2d", "cycle_3d", "entropy", "stretch", "surface", "texture"];

/// Adds every built-in loss to `r`.
pub fn add_all(r: &mut LossRegistry) {
    r.add::<Cycle3d>();
    r.add::<Cycle2d>();
    r.add::<Entropy>();
    r.add::<Surface>();
    r.add::<Cluster>();
    r.add::<Conformal>();
    r.add::<Stretch>();
    r.add::<Texture>();
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_paper_list_names_exactly_the_builtins() {
        let r = LossRegistry::with_builtins();
        let names: Vec<&str> = r.list().map(|i| i.name).collect();
        assert_eq!(names, PAPER);
    }
}
