//! The per-step quantities a plugin declared, recorded on the tape through the shared
//! [`StepContext`] and laid out exactly as the ABI describes (see [`Quantity`]).

use nuvo_autodiff::Var;
use nuvo_losses::{ChartRows, Samples, StepContext};
use nuvo_plugin_api::abi::SLOTS;
use nuvo_plugin_api::{Dims, Quantities, Quantity};

/// The sizes of the step `ctx` describes.
pub(crate) fn dims(ctx: &StepContext<'_>) -> Dims {
    Dims { charts: ctx.charts(), batch_3d: ctx.batch_3d(), batch_uv: ctx.batch_uv() }
}

/// One [`Var`] per declared quantity, in its slot. Built from the context's cached evaluations, so a
/// quantity another loss already needed costs nothing more.
pub(crate) fn gather(ctx: &mut StepContext<'_>, reads: Quantities) -> [Option<Var>; SLOTS] {
    let mut vars = [None; SLOTS];
    for q in reads.iter() {
        vars[q.slot()] = Some(quantity(ctx, q));
    }
    vars
}

/// Quantity `q` as one matrix (per-chart quantities stacked, chart 0 first).
fn quantity(ctx: &mut StepContext<'_>, q: Quantity) -> Var {
    match q {
        Quantity::X => ctx.x(),
        Quantity::Normals => ctx.normals(),
        Quantity::Uv => ctx.uv(),
        Quantity::ChartProbs => ctx.chart_probs(),
        Quantity::Tex => per_chart(ctx, |c, i| c.tex(ChartRows::new(i, Samples::All))),
        Quantity::UvDifferentials => per_chart(ctx, |c, i| {
            let (dp, dq) = c.uv_differentials(ChartRows::new(i, Samples::Distortion));
            c.tape.concat_cols(&[dp, dq])
        }),
        Quantity::SurfacePoints => ctx.all_surface_points(),
        Quantity::CyclePoints => per_chart(ctx, |c, i| c.cycle_points(ChartRows::new(i, Samples::All))),
        Quantity::CycleUv => per_chart(ctx, |c, i| c.cycle_uv(i)),
        Quantity::Sigma => ctx.sigma(),
    }
}

/// Every chart's block of a quantity, stacked.
fn per_chart(ctx: &mut StepContext<'_>, block: impl Fn(&mut StepContext<'_>, usize) -> Var) -> Var {
    let parts: Vec<Var> = (0..ctx.charts()).map(|i| block(ctx, i)).collect();
    if parts.len() == 1 { parts[0] } else { ctx.tape.concat_rows(&parts) }
}
