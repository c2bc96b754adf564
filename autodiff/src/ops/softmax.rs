//! Softmax and log-softmax across the columns of each row (one distribution per sample).

use super::Op;
use crate::kernels;
use crate::tape::{GradSink, Reader, Tape, Var};

impl Tape {
    /// Per row: `exp(a_j − max) / Σ exp(a_k − max)` (numerically stable).
    pub fn softmax(&mut self, a: Var) -> Var {
        self.softmax_impl(a, false)
    }

    /// Per row: `a_j − logsumexp(a)`; use this rather than `log(softmax)` for cross-entropies.
    pub fn log_softmax(&mut self, a: Var) -> Var {
        self.softmax_impl(a, true)
    }

    fn softmax_impl(&mut self, a: Var, log: bool) -> Var {
        let shape = self.shape(a);
        let mut out = self.alloc(shape);
        let x = self.value(a);
        kernels::for_each_row(out.as_mut_slice(), shape.cols, |r, o| {
            let xr = &x[r * shape.cols..(r + 1) * shape.cols];
            let m = xr.iter().copied().fold(f32::NEG_INFINITY, f32::max);
            let sum: f32 = xr.iter().map(|&v| (v - m).exp()).sum();
            if log {
                let lse = m + sum.ln();
                o.iter_mut().zip(xr).for_each(|(o, &v)| *o = v - lse);
            } else {
                o.iter_mut().zip(xr).for_each(|(o, &v)| *o = (v - m).exp() / sum);
            }
        });
        self.push(Op::Softmax { a, log }, shape, out, &[a])
    }
}

/// Softmax: `dx = y ⊙ (g − Σ g⊙y)`. Log-softmax: `dx = g − softmax ⊙ Σ g`, with softmax = `exp(y)`.
pub(crate) fn backward(r: &Reader<'_>, s: &mut GradSink<'_>, out: &[f32], g: &mut [f32], a: Var, log: bool) {
    if !s.needs(a) {
        return;
    }
    let cols = r.shape(a).cols;
    kernels::for_each_row(g, cols, |row, gr| {
        let y = &out[row * cols..(row + 1) * cols];
        if log {
            let gs: f32 = gr.iter().sum();
            gr.iter_mut().zip(y).for_each(|(g, &y)| *g -= y.exp() * gs);
        } else {
            let dot: f32 = gr.iter().zip(y).map(|(g, y)| g * y).sum();
            gr.iter_mut().zip(y).for_each(|(g, &y)| *g = y * (*g - dot));
        }
    });
    s.add(a, g);
}
