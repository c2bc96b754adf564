//! Symmetric-Dirichlet isometric distortion, as a nuvo loss plugin.
//!
//! For each sample `x` and chart `i`, the UV differentials give the 2×2 Jacobian of `t_i` on the
//! tangent plane, `J = [D t_i(εp)  D t_i(εq)] / (ε·scale)` (columns: the images of the orthonormal
//! tangents `p`, `q`). The symmetric Dirichlet energy
//!
//! `E(J) = ‖J‖²_F + ‖J⁻¹‖²_F = ‖J‖²_F · (1 + 1/det(J)²)`
//!
//! is at least 4, and equals 4 exactly when `J` is a rotation: it penalises stretch *and* shear in both
//! directions, and grows without bound as a triangle of the surface collapses in UV (`det J → 0`),
//! which the paper's conformal and stretch losses do not. The loss is the chart-probability-weighted
//! batch mean `L = (1/B) Σ_x Σ_i c(x)[i] · E(J_i(x))`, with its analytic gradient with respect to the
//! UV differentials and the chart probabilities.
//!
//! Near-singular `J`: `det²` is replaced by `det² + floor²`, so `E ≤ ‖J‖²_F (1 + 1/floor²)`; with the
//! floor, `E` can dip below 4 by about `2·floor²` near rotations. The energy is a barrier: a randomly
//! initialised texture network has fold lines (`det J = 0`), and with a tiny floor the few samples near
//! them dominate the batch and make the term spiky. The default floor, 0.1, keeps early training smooth;
//! lower it (e.g. 1e-3) for a sharper barrier when the other losses already keep the atlas fold-free.
//!
//! `scale` sets the target size: `E` is minimal when `J / scale` is a rotation, i.e. when one unit of
//! surface (model frame, the object inside `[-0.5, 0.5]³`) maps to `scale` units of UV.

use nuvo_plugin_api::{Gradients, Inputs, LossPlugin, OptionDoc, Quantities, Quantity, export_loss_plugin};
use serde::Deserialize;

/// The `[losses.NAME]` options (besides `plugin` and `weight`).
#[derive(Clone, Copy, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct Options {
    /// UV length per unit of surface length at the optimum.
    pub scale: f32,
    /// Floor on `|det J|` in `J⁻¹`.
    pub floor: f32,
}

impl Default for Options {
    fn default() -> Self {
        Options { scale: 1.0, floor: 0.1 }
    }
}

/// The loss; see the crate docs.
pub struct SymmetricDirichlet {
    options: Options,
}

impl LossPlugin for SymmetricDirichlet {
    const NAME: &'static str = "symmetric_dirichlet";
    const DESCRIPTION: &'static str = "c(x)-weighted symmetric Dirichlet energy ‖J‖² + ‖J⁻¹‖² of each chart's \
        tangent-plane Jacobian (≥ 4, = 4 iff J/scale is a rotation): isometric distortion with a barrier \
        against UV fold-overs";
    const DEFAULT_WEIGHT: f32 = 0.01;
    const OPTIONS: &'static [OptionDoc] = &[
        OptionDoc::new("scale", "1.0", "UV length per unit of surface length (model frame) at the optimum"),
        OptionDoc::new("floor", "0.1", "det(J)² is replaced by det(J)² + floor² in J⁻¹, bounding the energy"),
    ];
    const READS: Quantities = Quantities::of(&[Quantity::ChartProbs, Quantity::UvDifferentials]);

    fn new(options: &str) -> Result<Self, String> {
        let options: Options = toml::from_str(options).map_err(|e| e.message().to_owned())?;
        if !(options.scale.is_finite() && options.scale > 0.0) {
            return Err(format!("`scale` must be a positive number, not {}", options.scale));
        }
        if !(options.floor.is_finite() && options.floor >= 0.0) {
            return Err(format!("`floor` must be a non-negative number, not {}", options.floor));
        }
        Ok(SymmetricDirichlet { options })
    }

    fn evaluate(&mut self, inputs: &Inputs<'_>, gradients: &mut Gradients<'_>) -> Result<f32, String> {
        let probs = inputs.get(Quantity::ChartProbs)?;
        let diffs = inputs.get(Quantity::UvDifferentials)?;
        let mut grad_probs = gradients.take(Quantity::ChartProbs)?;
        let mut grad_diffs = gradients.take(Quantity::UvDifferentials)?;
        let b = inputs.batch_3d();
        let per_sample = 1.0 / b.max(1) as f64;
        let to_jacobian = 1.0 / (f64::from(inputs.epsilon()) * f64::from(self.options.scale));
        let floor = f64::from(self.options.floor);
        let mut total = 0.0;
        for i in 0..inputs.charts() {
            for k in 0..b {
                let row = i * b + k;
                let (e, de) = energy(diffs.row(row), to_jacobian, floor);
                let w = f64::from(probs.row(k)[i]) * per_sample;
                total += w * e;
                grad_probs.row_mut(k)[i] = (e * per_sample) as f32;
                for (g, d) in grad_diffs.row_mut(row).iter_mut().zip(de) {
                    *g = (w * d) as f32;
                }
            }
        }
        Ok(total as f32)
    }
}

/// `E` for one row `[Dp_u, Dp_v, Dq_u, Dq_v]` of UV differentials, with `J = row · to_jacobian`, and
/// its gradient with respect to the row.
pub fn energy(row: &[f32], to_jacobian: f64, floor: f64) -> (f64, [f64; 4]) {
    let [au, av, bu, bv] = [row[0], row[1], row[2], row[3]].map(|v| f64::from(v) * to_jacobian);
    let frobenius = au * au + av * av + bu * bu + bv * bv;
    let det = au * bv - av * bu;
    let inv = 1.0 / (det * det + floor * floor);
    let e = frobenius * (1.0 + inv);
    // ∂E/∂J = 2J(1 + inv) − ‖J‖² inv² · 2det · ∂det/∂J, with ∂det/∂(au, av, bu, bv) = (bv, −bu, −av, au).
    let (s, t) = (2.0 * (1.0 + inv), 2.0 * frobenius * det * inv * inv);
    let de_dj = [s * au - t * bv, s * av + t * bu, s * bu + t * av, s * bv - t * au];
    (e, de_dj.map(|g| g * to_jacobian))
}

export_loss_plugin!(SymmetricDirichlet);

#[cfg(test)]
mod tests {
    use super::*;
    use nuvo_plugin_api::Dims;
    use nuvo_plugin_api::testing::{TestPlugin, TestStep};

    #[test]
    fn rotations_cost_four_and_scalings_cost_more() {
        let (c, s) = (0.6f32, 0.8f32);
        let (e, g) = energy(&[c, s, -s, c], 1.0, 0.0);
        assert!((e - 4.0).abs() < 1e-6, "{e}");
        assert!(g.iter().all(|g| g.abs() < 1e-6), "a rotation is a minimum: {g:?}");
        // J = 2R: ‖J‖² = 8, det = 4, E = 8 · (1 + 1/16).
        let (e, _) = energy(&[2.0 * c, 2.0 * s, -2.0 * s, 2.0 * c], 1.0, 0.0);
        assert!((e - 8.5).abs() < 1e-6, "{e}");
        // A collapsed Jacobian is bounded by the floor.
        let (e, _) = energy(&[1.0, 0.0, 1.0, 0.0], 1.0, 1e-2);
        assert!((e - 2.0 * (1.0 + 1e4)).abs() < 1e-6, "{e}");
    }

    #[test]
    fn the_energy_gradient_matches_finite_differences() {
        let row = [0.7f32, -0.2, 0.35, 1.1];
        let (_, g) = energy(&row, 3.0, 1e-3);
        for k in 0..4 {
            let h = 1e-3f32;
            let (mut up, mut down) = (row, row);
            up[k] += h;
            down[k] -= h;
            let numeric =
                (energy(&up, 3.0, 1e-3).0 - energy(&down, 3.0, 1e-3).0) / f64::from(up[k] - down[k]);
            assert!(
                (numeric - g[k]).abs() < 1e-4 * g[k].abs().max(1.0),
                "∂E/∂row[{k}]: {numeric} vs {}",
                g[k]
            );
        }
    }

    #[test]
    fn the_plugin_gradients_match_finite_differences_through_the_c_abi() {
        let step = TestStep::random(Dims { charts: 3, batch_3d: 7, batch_uv: 2 }, 1e-2, 11);
        let mut plugin = TestPlugin::new::<SymmetricDirichlet>("scale = 1.5\nfloor = 1e-3\n").unwrap();
        plugin.check_gradients(&step, 1e-2, 1e-2).unwrap();
        let value = plugin.evaluate(&step).unwrap().value;
        assert!(value >= 4.0 - 1e-5, "E ≥ 4 and c sums to 1 per sample: {value}");
    }

    #[test]
    fn options_are_checked_with_serde_wording() {
        let e = TestPlugin::new::<SymmetricDirichlet>("flor = 1e-3").err().unwrap();
        assert!(e.contains("unknown field `flor`, expected `scale` or `floor`"), "{e}");
        let e = TestPlugin::new::<SymmetricDirichlet>("scale = -1.0").err().unwrap();
        assert!(e.contains("`scale` must be a positive number"), "{e}");
        assert!(TestPlugin::new::<SymmetricDirichlet>("").is_ok());
    }

    #[test]
    fn documented_defaults_are_the_real_ones() {
        let written: String = SymmetricDirichlet::OPTIONS
            .iter()
            .map(|o| format!("{} = {}\n", text(o.name), text(o.default)))
            .collect();
        assert_eq!(toml::from_str::<Options>(&written).unwrap(), Options::default());
    }

    /// A static descriptor string.
    fn text(s: nuvo_plugin_api::abi::PluginStr) -> &'static str {
        // SAFETY: `OptionDoc::new` built it from a `&'static str`.
        unsafe { std::str::from_utf8_unchecked(std::slice::from_raw_parts(s.ptr, s.len)) }
    }
}
