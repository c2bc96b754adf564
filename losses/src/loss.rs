//! The [`Loss`] trait and its error type.

use nuvo_autodiff::Var;

use crate::context::StepContext;

/// Why a loss could not be built or evaluated.
#[derive(Debug, thiserror::Error)]
pub enum LossError {
    /// The loss's options table is wrong (unknown key, wrong type, bad value).
    #[error("loss `{loss}`: {message}")]
    Options { loss: String, message: String },
    /// No loss is registered under this name.
    #[error("unknown loss `{name}`; known losses: {known}")]
    Unknown { name: String, known: String },
    /// Evaluation failed (run-time plugins report their failures this way).
    #[error("loss `{loss}` failed: {message}")]
    Evaluation { loss: String, message: String },
}

/// One term of Nuvo's objective.
///
/// A loss records its *unweighted* value (a 1×1 [`Var`]) on the context's tape from the shared
/// quantities the context hands out; the trainer multiplies by the configured weight, sums the terms
/// and runs backward once. Losses hold only their options: no state between steps.
pub trait Loss: Send + Sync {
    /// Records the term for this step and returns it.
    fn evaluate(&self, ctx: &mut StepContext<'_>) -> Result<Var, LossError>;
}

/// `(1/|G|) Σ_x Σ_i c(x)[i] · d_i(x)`: the chart-probability-weighted batch mean that most of the
/// paper's 3-D losses share. `per_chart[i]` is `d_i`, a column over the first `r ≤ B` samples
/// (`r×1`; all `B` for most losses, the distortion samples for `conformal` and `stretch`), and the
/// mean is over those `r`.
pub fn chart_weighted_mean(ctx: &mut StepContext<'_>, per_chart: &[Var]) -> Var {
    let rows = ctx.tape.shape(per_chart[0]).rows;
    let all = ctx.chart_probs();
    let c = if rows < ctx.batch_3d() { ctx.tape.slice_rows(all, 0, rows) } else { all };
    let b = rows.max(1) as f32;
    let t = &mut *ctx.tape;
    let d = if per_chart.len() == 1 { per_chart[0] } else { t.concat_cols(per_chart) };
    let w = t.mul(d, c);
    let s = t.sum_all(w);
    t.scale(s, 1.0 / b)
}

/// Row-wise squared Euclidean distance `‖a − b‖²` (`B×k`, `B×k` → `B×1`).
pub fn squared_distance(ctx: &mut StepContext<'_>, a: Var, b: Var) -> Var {
    let t = &mut *ctx.tape;
    let d = t.sub(a, b);
    let sq = t.square(d);
    t.sum_each_row(sq)
}
