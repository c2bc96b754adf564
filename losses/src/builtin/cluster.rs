//! The chart-assignment clustering loss.

use nuvo_autodiff::{Shape, Var};

use crate::context::{ChartRows, Samples, StepContext};
use crate::loss::{Loss, LossError, chart_weighted_mean, squared_distance};
use crate::registry::{LossInfo, RegisteredLoss, no_options};

/// `L_cluster = (1/|G|) Σ_x Σ_i c(x)[i] ‖μ_i − x‖²` with `μ_i = Σ_x c(x)[i]·x / Σ_x c(x)[i]` over the
/// batch. Gradients flow through the centroids too, as in the paper's formula.
pub struct Cluster;

/// Keeps a chart that has lost every point from dividing by zero.
const MASS_FLOOR: f32 = 1e-6;

impl RegisteredLoss for Cluster {
    const INFO: LossInfo = LossInfo {
        name: "cluster",
        summary: "c(x)-weighted squared distance from each sample to its charts' probability-weighted centroids",
        default_weight: 0.5,
        options: &[],
    };

    fn from_options(options: &toml::Table) -> Result<Self, LossError> {
        no_options(Self::INFO.name, options)?;
        Ok(Cluster)
    }
}

impl Loss for Cluster {
    fn evaluate(&self, ctx: &mut StepContext<'_>) -> Result<Var, LossError> {
        let x = ctx.x();
        let c = ctx.chart_probs();
        let b = ctx.batch_3d();
        let t = &mut *ctx.tape;
        let weighted_sums = t.matmul_t(c, x, true, false); // n×3
        let ones = t.constant(Shape::new(b, 1), 1.0);
        let mass = t.matmul_t(c, ones, true, false); // n×1
        let mass = t.add_scalar(mass, MASS_FLOOR);
        let centroids = t.div(weighted_sums, mass);
        let per_chart: Vec<(ChartRows, Var)> = (0..ctx.charts())
            .map(|i| {
                let mu = ctx.tape.slice_rows(centroids, i, 1);
                (ChartRows::new(i, Samples::All), squared_distance(ctx, x, mu))
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
    fn one_chart_gives_the_variance_of_the_points() {
        // Points at x = 0 and x = 2: centroid 1, squared distances 1 and 1.
        let scene = Scene::plane_points(&[[0.0, 0.0, 0.0], [2.0, 0.0, 0.0]]);
        assert!((scene.evaluate(&Cluster) - 1.0).abs() < 1e-5);
    }

    #[test]
    fn constant_probabilities_share_one_centroid() {
        // With c = (¼, ¾) everywhere both centroids are the mean, so the loss is still the variance.
        let scene = Scene::plane_points(&[[0.0, 1.0, 0.0], [0.0, 3.0, 0.0], [0.0, 2.0, 0.0]])
            .with_two_charts_shifted_z(0.0);
        assert!((scene.evaluate(&Cluster) - 2.0 / 3.0).abs() < 1e-5);
    }

    #[test]
    fn gradient_matches_finite_differences() {
        check_loss_gradient(&Cluster);
    }
}
