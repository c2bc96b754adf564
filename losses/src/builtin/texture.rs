//! The texture-optimisation loss: learned per-chart normal grids must reproduce the surface normals.

use nuvo_autodiff::Var;

use crate::context::{ChartRows, Samples, StepContext};
use crate::loss::{Loss, LossError, chart_weighted_mean, squared_distance};
use crate::registry::{LossInfo, RegisteredLoss, no_options};

/// `L_texture = (1/|G|) Σ_x Σ_i c(x)[i] ‖N_i(t_i(x)) − n(x)‖²`, with bilinear lookup; gradients reach
/// both the grid values and the texture coordinates.
pub struct Texture;

impl RegisteredLoss for Texture {
    const INFO: LossInfo = LossInfo {
        name: "texture",
        summary: "c(x)-weighted squared error of the normal grid N_i looked up at t_i(x) against n(x) (injectivity)",
        default_weight: 0.1,
        options: &[],
    };

    fn from_options(options: &toml::Table) -> Result<Self, LossError> {
        no_options(Self::INFO.name, options)?;
        Ok(Texture)
    }
}

impl Loss for Texture {
    fn evaluate(&self, ctx: &mut StepContext<'_>) -> Result<Var, LossError> {
        let normals = ctx.normals();
        let per_chart: Vec<(ChartRows, Var)> = (0..ctx.charts())
            .map(|i| {
                let rows = ChartRows::new(i, Samples::Support);
                let uv = ctx.tex(rows);
                let (grid, res) = ctx.normal_grid(i);
                let predicted = ctx.tape.grid_sample(grid, uv, res);
                let normals = ctx.select(rows, normals);
                (rows, squared_distance(ctx, predicted, normals))
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
    fn a_constant_grid_against_known_normals() {
        // Grid holds (0, 0, 1) everywhere; normals (0, 0, 1) and (1, 0, 0): errors 0 and 2.
        let scene = Scene::plane_points(&[[0.1, 0.2, 0.0], [0.3, 0.4, 0.0]])
            .with_normals(&[[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
            .with_constant_grid([0.0, 0.0, 1.0]);
        assert!((scene.evaluate(&Texture) - 1.0).abs() < 1e-6);
    }

    #[test]
    fn gradient_matches_finite_differences() {
        check_loss_gradient(&Texture);
    }
}
