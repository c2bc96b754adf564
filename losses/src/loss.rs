//! The [`Loss`] trait and its error type.

use nuvo_autodiff::Var;

use crate::context::{ChartRows, Reads, Samples, StepContext};

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

    /// What [`Self::evaluate`] reads of the context, so that the context can stack one network's
    /// evaluations of a step ([`Reads`]). Nothing by default: every quantity is still there, each
    /// evaluated on its own.
    fn reads(&self) -> Reads {
        Reads::NOTHING
    }
}

/// `(1/|G|) Σ_x Σ_i c(x)[i] · d_i(x)`: the chart-probability-weighted batch mean that most of the
/// paper's 3-D losses share. `per_chart[i]` is `(rows, d_i)`: chart `i`'s term, a column over the
/// samples its [`ChartRows`] name (every sample; the chart's support; the distortion samples, or
/// those of its support), weighted by `c(x)[i]` on those same rows. The mean divides by the batch
/// the samples are drawn from (`B`, or the `k` distortion samples), so the terms a support leaves
/// out count as zero.
///
/// # Panics
/// Unless `per_chart` holds charts `0..n` in order, all on the same kind of samples, each term with
/// as many rows as its handle names (programming errors a loss's tests catch: the row counts differ
/// as soon as a support is pruned).
pub fn chart_weighted_mean(ctx: &mut StepContext<'_>, per_chart: &[(ChartRows, Var)]) -> Var {
    let samples = per_chart.first().map(|(r, _)| r.samples).expect("a Nuvo atlas has at least one chart");
    for (i, &(r, d)) in per_chart.iter().enumerate() {
        assert!(
            r.chart == i && r.samples == samples && per_chart.len() == ctx.charts(),
            "chart_weighted_mean takes every chart in order, on one kind of samples"
        );
        let rows = ctx.row_count(r);
        assert_eq!(ctx.tape.shape(d).rows, rows, "chart {i}'s term covers other rows than {samples:?}");
    }
    let whole = if samples.is_distortion() { ctx.batch_distortion() } else { ctx.batch_3d() };
    let scale = 1.0 / whole.max(1) as f32;
    let terms: Vec<Var> = per_chart.iter().map(|&(_, d)| d).collect();
    if samples == Samples::All || samples == Samples::Distortion || !ctx.is_pruned() {
        let all = ctx.chart_probs();
        let c = if whole < ctx.batch_3d() { ctx.tape.slice_rows(all, 0, whole) } else { all };
        let t = &mut *ctx.tape;
        let d = if terms.len() == 1 { terms[0] } else { t.concat_cols(&terms) };
        let w = t.mul(d, c);
        let s = t.sum_all(w);
        return t.scale(s, scale);
    }
    let mut total: Option<Var> = None;
    for &(r, d) in per_chart {
        let c = ctx.chart_weights(r);
        let t = &mut *ctx.tape;
        let w = t.mul(d, c);
        let s = t.sum_all(w);
        total = Some(match total {
            Some(acc) => t.add(acc, s),
            None => s,
        });
    }
    let total = total.expect("a Nuvo atlas has at least one chart");
    ctx.tape.scale(total, scale)
}

/// Row-wise squared Euclidean distance `‖a − b‖²` (`B×k`, `B×k` → `B×1`).
pub fn squared_distance(ctx: &mut StepContext<'_>, a: Var, b: Var) -> Var {
    let t = &mut *ctx.tape;
    let d = t.sub(a, b);
    let sq = t.square(d);
    t.sum_each_row(sq)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::builtin::{Conformal, Cycle3d, Stretch, StretchOptions, Texture};
    use crate::testing::{Scene, check_loss_gradient_on};

    /// Two samples on the plane, two charts that differ only in chart 1's lifted surface, and
    /// `c(x) = (¼, ¾)` at the first sample, `(¾, ¼)` at the second.
    fn crossing_charts() -> Scene {
        let ln3 = 3.0f32.ln();
        Scene::plane_points(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
            .with_two_charts_shifted_z(0.5)
            .with_chart_logits_along_x(-2.0 * ln3, ln3)
            .with_texture_shear(1.0)
    }

    #[test]
    fn a_chart_support_leaves_out_exactly_the_terms_below_it() {
        let full = crossing_charts();
        let pruned = full.clone().with_chart_support(0.5);
        // cycle_3d: chart 0 maps back exactly, chart 1 misses by 0.5; only chart 1 weighs ¾ at the
        // first sample and ¼ at the second, and the support keeps the ¾.
        let (f, p) = (full.evaluate(&Cycle3d), pruned.evaluate(&Cycle3d));
        assert!((f - 0.125).abs() < 1e-6 && (p - 0.75 * 0.25 / 2.0).abs() < 1e-6, "{f} {p}");
        // conformal: both charts shear to a squared cosine of ½; the support keeps ¾ of each sample.
        let (f, p) = (full.evaluate(&Conformal), pruned.evaluate(&Conformal));
        assert!((f - 0.5).abs() < 1e-3 && (p - 0.375).abs() < 1e-3, "{f} {p}");
        // Below every probability, the support is every sample and nothing changes.
        let all = full.clone().with_chart_support(0.2);
        for loss in [&Cycle3d as &dyn crate::Loss, &Conformal, &Texture] {
            assert_eq!(all.evaluate(loss).to_bits(), full.evaluate(loss).to_bits());
        }
    }

    #[test]
    fn a_chart_below_the_threshold_everywhere_keeps_its_most_probable_sample() {
        // Above every probability: chart 0 keeps the second sample (¾), chart 1 the first (¾).
        let pruned = crossing_charts().with_chart_support(0.9);
        let p = pruned.evaluate(&Cycle3d);
        assert!((p - 0.75 * 0.25 / 2.0).abs() < 1e-6, "{p}");
        // With only the first sample carrying the distortion losses, chart 0 (¾ at the second sample
        // only) also keeps the first, where it weighs ¼: conformal sees ¾·½ + ¼·½.
        let first_only = crossing_charts().with_chart_support(0.5).with_distortion_samples(1);
        let p = first_only.evaluate(&Conformal);
        assert!((p - 0.5).abs() < 1e-3, "{p}");
    }

    #[test]
    fn pruned_losses_have_exact_gradients() {
        // Scene::generic's c(x)[1] is 0.46, 0.40, 0.47, 0.37 at its four samples: 0.43 keeps the
        // first and third for chart 1 and every sample for chart 0; 0.9 keeps one sample per chart.
        for tau in [0.43, 0.9] {
            for k in [4, 2] {
                let full = Scene::generic().with_distortion_samples(k);
                let scene = full.clone().with_chart_support(tau);
                assert!((scene.evaluate(&Cycle3d) - full.evaluate(&Cycle3d)).abs() > 1e-4, "nothing pruned");
                check_loss_gradient_on(&scene, &Cycle3d);
                check_loss_gradient_on(&scene, &Texture);
                check_loss_gradient_on(&scene, &Conformal);
                for relative in [false, true] {
                    let options = StretchOptions { relative, ..Default::default() };
                    check_loss_gradient_on(&scene, &Stretch::new(options));
                }
            }
        }
    }

    /// Pairs chart `i`'s term on its support with the weights of every sample.
    struct Mismatched;
    impl crate::Loss for Mismatched {
        fn evaluate(&self, ctx: &mut StepContext<'_>) -> Result<Var, LossError> {
            let per_chart: Vec<(ChartRows, Var)> = (0..ctx.charts())
                .map(|i| {
                    let t = ctx.tex(ChartRows::new(i, Samples::Support));
                    (ChartRows::new(i, Samples::All), ctx.tape.slice_cols(t, 0, 1))
                })
                .collect();
            Ok(chart_weighted_mean(ctx, &per_chart))
        }
    }

    #[test]
    #[should_panic(expected = "covers other rows")]
    fn a_term_paired_with_the_weights_of_other_rows_is_caught() {
        crossing_charts().with_chart_support(0.5).evaluate(&Mismatched);
    }

    /// Checks every per-chart getter's row count against [`StepContext::row_count`], on a step
    /// whose supports are pruned or not.
    struct RowCounts {
        pruned: bool,
    }
    impl crate::Loss for RowCounts {
        fn evaluate(&self, ctx: &mut StepContext<'_>) -> Result<Var, LossError> {
            assert_eq!(ctx.is_pruned(), self.pruned);
            let x = ctx.x();
            for i in 0..ctx.charts() {
                for samples in
                    [Samples::All, Samples::Support, Samples::Distortion, Samples::DistortionSupport]
                {
                    let r = ChartRows::new(i, samples);
                    let rows = ctx.row_count(r);
                    let (tex, back, picked, w) =
                        (ctx.tex(r), ctx.cycle_points(r), ctx.select(r, x), ctx.chart_weights(r));
                    for v in [tex, back, picked, w] {
                        assert_eq!(ctx.tape.shape(v).rows, rows, "chart {i}, {samples:?}");
                    }
                    if samples.is_distortion() {
                        let (a, b) = ctx.uv_differentials(r);
                        assert_eq!((ctx.tape.shape(a).rows, ctx.tape.shape(b).rows), (rows, rows));
                    }
                }
            }
            Ok(ctx.tape.constant(nuvo_autodiff::Shape::SCALAR, 0.0))
        }
    }

    #[test]
    fn every_getter_covers_the_rows_its_handle_names() {
        // Two samples, the first one alone a distortion sample; the support keeps one sample per
        // chart (chart 0 the second, chart 1 the first) plus chart 0's most probable distortion one.
        let scene = crossing_charts().with_chart_support(0.5).with_distortion_samples(1);
        scene.evaluate(&RowCounts { pruned: true });
        crossing_charts().evaluate(&RowCounts { pruned: false });
    }
}
