//! The distortion losses: conformal (angle) and uniform stretch (area), from the finite-difference
//! UV vectors `D t_i(εp)`, `D t_i(εq)` that the context computes once for both.

use nuvo_autodiff::Var;
use serde::Deserialize;

use crate::context::{ChartRows, Reads, Samples, StepContext};
use crate::loss::{Loss, LossError, chart_weighted_mean};
use crate::registry::{LossInfo, OptionDoc, RegisteredLoss, no_options, parse_options};

/// `L_conformal = (1/|G|) Σ_x Σ_i c(x)[i] · cos²(D t_i(εp), D t_i(εq))`.
pub struct Conformal;

/// `L_stretch = (1/|G|) Σ_x Σ_i c(x)[i] · (‖D t_i(εp) × D t_i(εq)‖ − σ)²`, or its scale-free
/// variant (see [`StretchOptions::relative`]).
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
    /// Score `1 − E[A]²/E[A²]` (expectations weighted by `c(x)` as in the paper's sum) instead of
    /// `E[(A − σ)²]`. It is `min_σ E[(A/σ − 1)²]`: the same "uniform stretch" goal, measured relative
    /// to the stretch itself, so scaling every chart by λ leaves it unchanged. The paper's form is
    /// `σ²` times that at its optimum, so it falls as the charts shrink, and a strong stretch weight
    /// then buys uniformity by shrinking the atlas into a corner of each chart square. This form
    /// ranges over `[0, 1]`: 0 for uniform stretch, 1 for a collapsed map (or, with `signed`, for
    /// equal mirrored and unmirrored areas). A wholly mirrored atlas costs the same as its mirror
    /// image. The learned σ is unused.
    pub relative: bool,
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

/// Keeps the cosine finite when a mapping collapses a tangent vector to zero.
const COSINE_FLOOR: f32 = 1e-20;

impl RegisteredLoss for Conformal {
    const INFO: LossInfo = LossInfo {
        name: "conformal",
        summary: "c(x)-weighted squared cosine between the UV images of two orthogonal tangent vectors",
        default_weight: 0.4,
        options: &[],
    };

    fn from_options(options: &toml::Table) -> Result<Self, LossError> {
        no_options(Self::INFO.name, options)?;
        Ok(Conformal)
    }
}

impl Loss for Conformal {
    fn evaluate(&self, ctx: &mut StepContext<'_>) -> Result<Var, LossError> {
        let per_chart: Vec<(ChartRows, Var)> = (0..ctx.charts())
            .map(|i| {
                let rows = ChartRows::new(i, Samples::DistortionSupport);
                let (a, b) = ctx.uv_differentials(rows);
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
                (rows, t.div(dot2, norms))
            })
            .collect();
        Ok(chart_weighted_mean(ctx, &per_chart))
    }

    fn reads(&self) -> Reads {
        Reads { uv_differentials: true, ..Reads::NOTHING }
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

impl Stretch {
    /// The loss with these options (the registry builds it from a `[losses.stretch]` table).
    pub fn new(options: StretchOptions) -> Self {
        Stretch { options }
    }

    /// Chart `i`'s parallelogram areas (a column over the distortion samples of its support) in
    /// the units `options.area` asks for.
    fn areas(&self, ctx: &mut StepContext<'_>, i: usize) -> (ChartRows, Var) {
        let eps = ctx.data().epsilon;
        let rows = ChartRows::new(i, Samples::DistortionSupport);
        let (a, b) = ctx.uv_differentials(rows);
        let area = parallelogram_area(ctx, a, b, self.options.signed);
        let area = match self.options.area {
            AreaScale::Paper => area,
            AreaScale::Jacobian => ctx.tape.scale(area, 1.0 / (eps * eps)),
        };
        (rows, area)
    }
}

/// Keeps `E[A]²/E[A²]` finite when every area is zero (the relative loss is then 1).
const SECOND_MOMENT_FLOOR: f32 = 1e-30;

/// `1 − E[A]²/(E[A²] + floor)` with `c(x)`-weighted expectations over the charts' areas.
fn relative_spread(ctx: &mut StepContext<'_>, areas: &[(ChartRows, Var)]) -> Var {
    let squares: Vec<(ChartRows, Var)> = areas.iter().map(|&(r, a)| (r, ctx.tape.square(a))).collect();
    let mean = chart_weighted_mean(ctx, areas);
    let mean_square = chart_weighted_mean(ctx, &squares);
    let t = &mut *ctx.tape;
    let mean2 = t.square(mean);
    let denominator = t.add_scalar(mean_square, SECOND_MOMENT_FLOOR);
    let ratio = t.div(mean2, denominator);
    let negated = t.scale(ratio, -1.0);
    t.add_scalar(negated, 1.0)
}

impl RegisteredLoss for Stretch {
    const INFO: LossInfo = LossInfo {
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
            OptionDoc {
                name: "relative",
                default: "false",
                doc: "score the spread of the area relative to its size, 1 − E[A]²/E[A²] (= min over σ of \
                      E[(A/σ − 1)²]), instead of (A − σ)²: invariant to the charts' overall size, so it does \
                      not reward shrinking them as the paper's form does; σ is then unused. An extension of \
                      the paper",
            },
        ],
    };

    fn from_options(options: &toml::Table) -> Result<Self, LossError> {
        Ok(Stretch { options: parse_options(Self::INFO.name, options)? })
    }
}

impl Loss for Stretch {
    fn evaluate(&self, ctx: &mut StepContext<'_>) -> Result<Var, LossError> {
        let areas: Vec<(ChartRows, Var)> = (0..ctx.charts()).map(|i| self.areas(ctx, i)).collect();
        if self.options.relative {
            return Ok(relative_spread(ctx, &areas));
        }
        let sigma = ctx.sigma();
        let per_chart: Vec<(ChartRows, Var)> = areas
            .iter()
            .map(|&(rows, area)| {
                let d = ctx.tape.sub(area, sigma);
                (rows, ctx.tape.square(d))
            })
            .collect();
        Ok(chart_weighted_mean(ctx, &per_chart))
    }

    fn reads(&self) -> Reads {
        Reads { uv_differentials: true, ..Reads::NOTHING }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::{Scene, check_loss_gradient, check_loss_gradient_on};

    #[test]
    fn a_sheared_map_has_squared_cosine_one_half() {
        // t(x) = (x + y, y): p = (1,0,0) ↦ (ε, 0), q = (0,1,0) ↦ (ε, ε); cos = 1/√2.
        let scene = Scene::plane_points(&[[0.1, 0.2, 0.0], [0.3, 0.1, 0.0]]).with_texture_shear(1.0);
        assert!((scene.evaluate(&Conformal) - 0.5).abs() < 1e-3, "{}", scene.evaluate(&Conformal));
    }

    #[test]
    fn the_distortion_losses_read_only_the_distortion_samples() {
        // The sheared map of the test above: cos² = ½ in the tangent frame of normal +z, and 0 in
        // that of normal +x (q = z, which t ignores, so the floor makes it 0).
        let scene = Scene::plane_points(&[[0.1, 0.2, 0.0], [0.3, 0.1, 0.0]])
            .with_normals(&[[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
            .with_texture_shear(1.0);
        assert!((scene.evaluate(&Conformal) - 0.25).abs() < 1e-3, "{}", scene.evaluate(&Conformal));
        let first = scene.clone().with_distortion_samples(1);
        assert!((first.evaluate(&Conformal) - 0.5).abs() < 1e-3, "{}", first.evaluate(&Conformal));
        let generic = Scene::generic().with_distortion_samples(3);
        check_loss_gradient_on(&generic, &Conformal);
        check_loss_gradient_on(
            &generic,
            &Stretch { options: StretchOptions { relative: true, ..Default::default() } },
        );
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
        let paper = Stretch { options: StretchOptions { area: AreaScale::Paper, ..Default::default() } };
        let want = (2.0 * eps * eps - 0.5).powi(2);
        assert!((scene.evaluate(&paper) - want).abs() < 1e-4);
        let jacobian =
            Stretch { options: StretchOptions { area: AreaScale::Jacobian, ..Default::default() } };
        assert!((scene.evaluate(&jacobian) - 2.25).abs() < 2e-3, "{}", scene.evaluate(&jacobian));
    }

    #[test]
    fn signed_stretch_charges_mirrored_maps() {
        // t(x) = (−2x, y) mirrors the tangent frame: the signed area is −2 (jacobian units), so the
        // loss is (−2 − 0.5)² = 6.25, against (2 − 0.5)² = 2.25 unsigned.
        let scene = Scene::plane_points(&[[0.1, 0.2, 0.0]]).with_texture_scale(-2.0).with_sigma(0.5);
        let signed = Stretch {
            options: StretchOptions { area: AreaScale::Jacobian, signed: true, ..Default::default() },
        };
        assert!((scene.evaluate(&signed) - 6.25).abs() < 5e-3, "{}", scene.evaluate(&signed));
        let unsigned =
            Stretch { options: StretchOptions { area: AreaScale::Jacobian, ..Default::default() } };
        assert!((scene.evaluate(&unsigned) - 2.25).abs() < 2e-3);
    }

    fn relative(signed: bool) -> Stretch {
        Stretch { options: StretchOptions { area: AreaScale::Jacobian, signed, relative: true } }
    }

    #[test]
    fn relative_stretch_is_the_scale_free_spread_of_the_area() {
        // t(x) = (k·x, y) has area factor k on the plane z = const (normal +z) and k/√2 on a plane
        // with normal (0, 1, 1)/√2 (tangents x and (0, 1, −1)/√2 map to (k, 0) and (0, 1/√2)). One
        // chart: 1 − E[A]²/E[A²] = 1 − ((1 + 1/√2)/2)² / ((1 + 1/2)/2) ≈ 0.028595, whatever k is.
        let r = std::f32::consts::FRAC_1_SQRT_2;
        let want = 1.0 - ((1.0 + r) / 2.0).powi(2) / 0.75;
        for k in [0.5, 2.0, 5.0] {
            let scene = Scene::plane_points(&[[0.1, 0.2, 0.0], [0.3, 0.1, 0.0]])
                .with_normals(&[[0.0, 0.0, 1.0], [0.0, r, r]])
                .with_texture_scale(k);
            let got = scene.evaluate(&relative(false));
            assert!((got - want).abs() < 1e-3, "k = {k}: {got} vs {want}");
        }
        // A uniform map costs nothing at any scale (the paper's form would charge (k − σ)²).
        let uniform = Scene::plane_points(&[[0.1, 0.2, 0.0], [0.3, 0.1, 0.0]]).with_texture_scale(3.0);
        assert!(uniform.evaluate(&relative(false)) < 1e-4);
    }

    #[test]
    fn signed_relative_stretch_charges_mixed_orientations_and_collapse() {
        // Normals +z and −z under the same map: signed areas k and −k, so E[A] = 0 and the loss is
        // 1; unsigned, the two areas are equal and the loss is 0.
        let scene = Scene::plane_points(&[[0.1, 0.2, 0.0], [0.3, 0.1, 0.0]])
            .with_normals(&[[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]])
            .with_texture_scale(2.0);
        assert!((scene.evaluate(&relative(true)) - 1.0).abs() < 1e-3);
        assert!(scene.evaluate(&relative(false)) < 1e-4);
        // A wholly mirrored map is its mirror image's equal.
        let mirrored = Scene::plane_points(&[[0.1, 0.2, 0.0]]).with_texture_scale(-2.0);
        assert!(mirrored.evaluate(&relative(true)) < 1e-4);
        // A collapsed map (zero area everywhere) is the worst case, not a way out.
        let collapsed =
            Scene::plane_points(&[[0.1, 0.2, 0.0]]).with_texture_scale(0.0).with_texture_shear(0.0);
        let got = collapsed.evaluate(&relative(false));
        assert!((got - 1.0).abs() < 1e-6, "{got}");
    }

    #[test]
    fn stretch_options_are_checked() {
        let ok: toml::Table = toml::from_str("area = \"jacobian\"").unwrap();
        assert!(Stretch::from_options(&ok).is_ok());
        let typo: toml::Table = toml::from_str("aera = \"jacobian\"").unwrap();
        let e = Stretch::from_options(&typo).err().unwrap().to_string();
        assert!(e.contains("aera") && e.contains("area"), "{e}");
        let bad: toml::Table = toml::from_str("area = \"huge\"").unwrap();
        let e = Stretch::from_options(&bad).err().unwrap().to_string();
        assert!(e.contains("huge") && e.contains("paper"), "{e}");
    }

    #[test]
    fn gradients_match_finite_differences() {
        check_loss_gradient(&Conformal);
        check_loss_gradient(&Stretch {
            options: StretchOptions { area: AreaScale::Jacobian, ..Default::default() },
        });
        check_loss_gradient(&Stretch {
            options: StretchOptions { area: AreaScale::Jacobian, signed: true, ..Default::default() },
        });
        check_loss_gradient(&relative(false));
        check_loss_gradient(&relative(true));
    }
}
