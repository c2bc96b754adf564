//! The distortion losses: conformal (angle) and uniform stretch (area), from the finite-difference
//! UV vectors `D t_i(εp)`, `D t_i(εq)` that the context computes once for both.

use nuvo_autodiff::Var;
use serde::Deserialize;

use crate::context::StepContext;
use crate::loss::{Loss, LossError, chart_weighted_mean};
use crate::registry::{LossInfo, OptionDoc, no_options, parse_options};

pub(super) const CONFORMAL: LossInfo = LossInfo {
    name: "conformal",
    summary: "c(x)-weighted squared cosine between the UV images of two orthogonal tangent vectors",
    default_weight: 0.4,
    options: &[],
};

pub(super) const STRETCH: LossInfo = LossInfo {
    name: "stretch",
    summary: "c(x)-weighted squared difference between the UV parallelogram area and the learned σ",
    default_weight: 0.1,
    options: &[
        OptionDoc {
            name: "area",
            default: "\"paper\"",
            doc: "\"paper\": the area spanned by D t(εp), D t(εq) as in the paper (∝ ε²); \
                  \"jacobian\": that area / ε², the local UV area per unit surface area, independent of ε",
        },
        OptionDoc {
            name: "signed",
            default: "false",
            doc: "use the signed area (positive when the UV image keeps the orientation of (p, q, n)), so \
                  mirrored (folded) regions cost ≈ 4σ²; an extension of the paper, which uses |area|",
        },
    ],
};

/// `L_conformal = (1/|G|) Σ_x Σ_i c(x)[i] · cos²(D t_i(εp), D t_i(εq))`.
pub struct Conformal;

/// `L_stretch = (1/|G|) Σ_x Σ_i c(x)[i] · (‖D t_i(εp) × D t_i(εq)‖ − σ)²`.
pub struct Stretch {
    options: StretchOptions,
}

/// Options of [`Stretch`].
#[derive(Clone, Copy, Debug, Default, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct StretchOptions {
    /// How the parallelogram area is measured; see [`AreaScale`].
    pub area: AreaScale,
    /// Compare the *signed* area with σ (an extension of the paper, which uses the absolute area):
    /// a mirrored region, where the map reverses the orientation of the tangent frame `(p, q, n)`,
    /// then costs about `4σ²` instead of nothing, which pushes folded maps to cut and unfold.
    pub signed: bool,
}

/// The scale of the stretch loss's area.
#[derive(Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum AreaScale {
    /// The paper's formula literally: the area spanned by `D t(εp)` and `D t(εq)`, proportional to ε².
    #[default]
    Paper,
    /// The same area divided by ε²: the Jacobian's area factor on the tangent plane.
    Jacobian,
}

pub(super) fn build_conformal(options: &toml::Table) -> Result<Box<dyn Loss>, LossError> {
    no_options(CONFORMAL.name, options)?;
    Ok(Box::new(Conformal))
}

pub(super) fn build_stretch(options: &toml::Table) -> Result<Box<dyn Loss>, LossError> {
    Ok(Box::new(Stretch { options: parse_options(STRETCH.name, options)? }))
}

/// Keeps the cosine finite when a mapping collapses a tangent vector to zero.
const COSINE_FLOOR: f32 = 1e-20;

impl Loss for Conformal {
    fn evaluate(&self, ctx: &mut StepContext<'_>) -> Result<Var, LossError> {
        let per_chart: Vec<Var> = (0..ctx.charts())
            .map(|i| {
                let (a, b) = ctx.uv_differentials(i);
                let t = &mut *ctx.tape;
                let ab = t.mul(a, b);
                let dot = t.sum_each_row(ab);
                let aa = t.square(a);
                let na = t.sum_each_row(aa);
                let bb = t.square(b);
                let nb = t.sum_each_row(bb);
                let dot2 = t.square(dot);
                let norms = t.mul(na, nb);
                let norms = t.add_scalar(norms, COSINE_FLOOR);
                t.div(dot2, norms)
            })
            .collect();
        Ok(chart_weighted_mean(ctx, &per_chart))
    }
}

/// The area of the parallelogram spanned by two 2-D vectors, `a_u b_v − a_v b_u`, signed or its
/// absolute value (`B×1`).
fn parallelogram_area(ctx: &mut StepContext<'_>, a: Var, b: Var, signed: bool) -> Var {
    let t = &mut *ctx.tape;
    let (au, av) = (t.slice_cols(a, 0, 1), t.slice_cols(a, 1, 1));
    let (bu, bv) = (t.slice_cols(b, 0, 1), t.slice_cols(b, 1, 1));
    let l = t.mul(au, bv);
    let r = t.mul(av, bu);
    let cross = t.sub(l, r);
    if signed { cross } else { t.abs(cross) }
}

impl Loss for Stretch {
    fn evaluate(&self, ctx: &mut StepContext<'_>) -> Result<Var, LossError> {
        let eps = ctx.data().epsilon;
        let sigma = ctx.sigma();
        let per_chart: Vec<Var> = (0..ctx.charts())
            .map(|i| {
                let (a, b) = ctx.uv_differentials(i);
                let area = parallelogram_area(ctx, a, b, self.options.signed);
                let t = &mut *ctx.tape;
                let area = match self.options.area {
                    AreaScale::Paper => area,
                    AreaScale::Jacobian => t.scale(area, 1.0 / (eps * eps)),
                };
                let d = t.sub(area, sigma);
                t.square(d)
            })
            .collect();
        Ok(chart_weighted_mean(ctx, &per_chart))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::{Scene, check_loss_gradient};

    #[test]
    fn a_sheared_map_has_squared_cosine_one_half() {
        // t(x) = (x + y, y): p = (1,0,0) ↦ (ε, 0), q = (0,1,0) ↦ (ε, ε); cos = 1/√2.
        let scene = Scene::plane_points(&[[0.1, 0.2, 0.0], [0.3, 0.1, 0.0]]).with_texture_shear(1.0);
        assert!((scene.evaluate(&Conformal) - 0.5).abs() < 1e-3, "{}", scene.evaluate(&Conformal));
    }

    #[test]
    fn an_isometry_is_conformal() {
        let scene = Scene::plane_points(&[[0.1, 0.2, 0.0]]);
        assert!(scene.evaluate(&Conformal) < 1e-6);
    }

    #[test]
    fn stretch_compares_the_parallelogram_area_with_sigma() {
        // t(x) = (2x, y): area of (2ε, 0) and (0, ε) is 2ε² (paper) or 2 (jacobian); σ = 0.5.
        let scene = Scene::plane_points(&[[0.1, 0.2, 0.0]]).with_texture_scale(2.0).with_sigma(0.5);
        let eps = scene.epsilon();
        let paper = Stretch { options: StretchOptions { area: AreaScale::Paper, signed: false } };
        let want = (2.0 * eps * eps - 0.5).powi(2);
        assert!((scene.evaluate(&paper) - want).abs() < 1e-4);
        let jacobian = Stretch { options: StretchOptions { area: AreaScale::Jacobian, signed: false } };
        assert!((scene.evaluate(&jacobian) - 2.25).abs() < 2e-3, "{}", scene.evaluate(&jacobian));
    }

    #[test]
    fn signed_stretch_charges_mirrored_maps() {
        // t(x) = (−2x, y) mirrors the tangent frame: the signed area is −2 (jacobian units), so the
        // loss is (−2 − 0.5)² = 6.25, against (2 − 0.5)² = 2.25 unsigned.
        let scene = Scene::plane_points(&[[0.1, 0.2, 0.0]]).with_texture_scale(-2.0).with_sigma(0.5);
        let signed = Stretch { options: StretchOptions { area: AreaScale::Jacobian, signed: true } };
        assert!((scene.evaluate(&signed) - 6.25).abs() < 5e-3, "{}", scene.evaluate(&signed));
        let unsigned = Stretch { options: StretchOptions { area: AreaScale::Jacobian, signed: false } };
        assert!((scene.evaluate(&unsigned) - 2.25).abs() < 2e-3);
    }

    #[test]
    fn stretch_options_are_checked() {
        let ok: toml::Table = toml::from_str("area = \"jacobian\"").unwrap();
        assert!(build_stretch(&ok).is_ok());
        let typo: toml::Table = toml::from_str("aera = \"jacobian\"").unwrap();
        let e = build_stretch(&typo).err().unwrap().to_string();
        assert!(e.contains("aera") && e.contains("area"), "{e}");
        let bad: toml::Table = toml::from_str("area = \"huge\"").unwrap();
        let e = build_stretch(&bad).err().unwrap().to_string();
        assert!(e.contains("huge") && e.contains("paper"), "{e}");
    }

    #[test]
    fn gradients_match_finite_differences() {
        check_loss_gradient(&Conformal);
        check_loss_gradient(&Stretch {
            options: StretchOptions { area: AreaScale::Jacobian, signed: false },
        });
        check_loss_gradient(&Stretch { options: StretchOptions { area: AreaScale::Jacobian, signed: true } });
    }
}
