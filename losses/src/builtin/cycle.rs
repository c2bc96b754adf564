//! The two cycle-consistency (bijectivity) losses.

use nuvo_autodiff::Var;

use crate::context::{ChartRows, Reads, Samples, StepContext};
use crate::loss::{Loss, LossError, chart_weighted_mean, squared_distance};
use crate::registry::{LossInfo, RegisteredLoss, no_options};

/// `L_{3→2→3} = (1/|G|) Σ_x Σ_i c(x)[i] ‖s_i(t_i(x)) − x‖²`.
pub struct Cycle3d;

/// `L_{2→3→2} = (1/|T|) Σ_u Σ_i ‖t_i(s_i(u)) − u‖²`.
pub struct Cycle2d;

impl RegisteredLoss for Cycle3d {
    const INFO: LossInfo = LossInfo {
        name: "cycle_3d",
        summary: "3→2→3 cycle: c(x)-weighted squared distance between s_i(t_i(x)) and x (injectivity)",
        default_weight: 1.0,
        options: &[],
    };

    fn from_options(options: &toml::Table) -> Result<Self, LossError> {
        no_options(Self::INFO.name, options)?;
        Ok(Cycle3d)
    }
}

impl Loss for Cycle3d {
    fn evaluate(&self, ctx: &mut StepContext<'_>) -> Result<Var, LossError> {
        let x = ctx.x();
        let per_chart: Vec<(ChartRows, Var)> = (0..ctx.charts())
            .map(|i| {
                let rows = ChartRows::new(i, Samples::Support);
                let back = ctx.cycle_points(rows);
                let x = ctx.select(rows, x);
                (rows, squared_distance(ctx, back, x))
            })
            .collect();
        Ok(chart_weighted_mean(ctx, &per_chart))
    }

    fn reads(&self) -> Reads {
        Reads { cycle_points: true, ..Reads::NOTHING }
    }
}

impl RegisteredLoss for Cycle2d {
    const INFO: LossInfo = LossInfo {
        name: "cycle_2d",
        summary: "2→3→2 cycle: squared distance between t_i(s_i(u)) and u, every chart (surjectivity)",
        default_weight: 1.0,
        options: &[],
    };

    fn from_options(options: &toml::Table) -> Result<Self, LossError> {
        no_options(Self::INFO.name, options)?;
        Ok(Cycle2d)
    }
}

impl Loss for Cycle2d {
    fn evaluate(&self, ctx: &mut StepContext<'_>) -> Result<Var, LossError> {
        let u = ctx.uv();
        let per_chart: Vec<Var> = (0..ctx.charts())
            .map(|i| {
                let back = ctx.cycle_uv(i);
                squared_distance(ctx, back, u)
            })
            .collect();
        let bu = ctx.batch_uv().max(1) as f32;
        let t = &mut *ctx.tape;
        let all = if per_chart.len() == 1 { per_chart[0] } else { t.concat_cols(&per_chart) };
        let s = t.sum_all(all);
        Ok(t.scale(s, 1.0 / bu))
    }

    fn reads(&self) -> Reads {
        Reads { surface_points: true, ..Reads::NOTHING }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::{Scene, check_loss_gradient};

    #[test]
    fn cycle_3d_measures_the_height_above_the_chart_plane() {
        // t(x) = (x, y), s(u) = (u, v, 0): the round trip drops z, so the loss is mean z² = (0.01 + 0.09)/2.
        let scene = Scene::plane_points(&[[0.2, 0.3, 0.1], [0.5, 0.6, 0.3]]);
        assert!((scene.evaluate(&Cycle3d) - 0.05).abs() < 1e-6);
    }

    #[test]
    fn cycle_3d_weights_charts_by_probability() {
        // Two charts, probabilities (1/4, 3/4) everywhere; chart 1's s adds 1 to z, so its error is
        // (z − 1)²... here z = 0: chart 0 error 0, chart 1 error 1 → loss 3/4.
        let scene = Scene::plane_points(&[[0.2, 0.3, 0.0]]).with_two_charts_shifted_z(1.0);
        assert!((scene.evaluate(&Cycle3d) - 0.75).abs() < 1e-5, "{}", scene.evaluate(&Cycle3d));
    }

    #[test]
    fn cycle_2d_measures_the_uv_round_trip() {
        // t(x) = (2x, y) makes t(s(u)) = (2u, v): the error is u², mean over u = (0.01 + 0.16)/2.
        let scene = Scene::plane_points(&[[0.0, 0.0, 0.0]])
            .with_uv(&[[0.1, 0.5], [0.4, 0.9]])
            .with_texture_scale(2.0);
        assert!((scene.evaluate(&Cycle2d) - 0.085).abs() < 1e-6);
    }

    #[test]
    fn gradients_match_finite_differences() {
        check_loss_gradient(&Cycle3d);
        check_loss_gradient(&Cycle2d);
    }
}
