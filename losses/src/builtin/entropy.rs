//! The chart-assignment entropy loss.

use nuvo_autodiff::{Shape, Var};

use crate::context::{Reads, StepContext};
use crate::loss::{Loss, LossError};
use crate::registry::{LossInfo, RegisteredLoss, no_options};

/// `L_entropy = −(1/|T|) Σ_u Σ_i log c(s_i(u))[i]`, from one chart-network evaluation on all charts'
/// surface points (log-softmax, so no epsilon is needed inside the log).
pub struct Entropy;

impl RegisteredLoss for Entropy {
    const INFO: LossInfo = LossInfo {
        name: "entropy",
        summary: "chart-assignment cross-entropy: −log c(s_i(u))[i], so chart i's surface claims chart i",
        default_weight: 0.04,
        options: &[],
    };

    fn from_options(options: &toml::Table) -> Result<Self, LossError> {
        no_options(Self::INFO.name, options)?;
        Ok(Entropy)
    }
}

impl Loss for Entropy {
    fn evaluate(&self, ctx: &mut StepContext<'_>) -> Result<Var, LossError> {
        let n = ctx.charts();
        let bu = ctx.batch_uv();
        let log_probs = ctx.chart_log_probs_at_surface_points();
        let t = &mut *ctx.tape;
        // Row block i (chart i's surface points) keeps column i.
        let mask = t.input_with(Shape::new(n * bu, n), |d| {
            d.fill(0.0);
            for i in 0..n {
                for k in 0..bu {
                    d[(i * bu + k) * n + i] = 1.0;
                }
            }
        });
        let picked = t.mul(log_probs, mask);
        let s = t.sum_all(picked);
        Ok(t.scale(s, -1.0 / bu.max(1) as f32))
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
    fn entropy_is_the_cross_entropy_of_constant_probabilities() {
        // Chart probabilities (1/4, 3/4) everywhere: −(ln ¼ + ln ¾) per UV point.
        let scene = Scene::plane_points(&[[0.0, 0.0, 0.0]]).with_two_charts_shifted_z(0.0);
        let want = -((0.25f32).ln() + (0.75f32).ln());
        assert!((scene.evaluate(&Entropy) - want).abs() < 1e-5);
    }

    #[test]
    fn a_single_chart_has_zero_entropy_loss() {
        let scene = Scene::plane_points(&[[0.0, 0.0, 0.0]]);
        assert!(scene.evaluate(&Entropy).abs() < 1e-7);
    }

    #[test]
    fn gradient_matches_finite_differences() {
        check_loss_gradient(&Entropy);
    }
}
