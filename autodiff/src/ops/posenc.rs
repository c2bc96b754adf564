//! Positional encoding, fused (one pass forward, one pass backward).

use super::Op;
use crate::kernels;
use crate::shape::Shape;
use crate::tape::{GradSink, Reader, Tape, Var};

/// Output width of [`Tape::posenc`] for `d` input columns and degree `degree`.
pub fn posenc_width(d: usize, degree: usize) -> usize {
    d * (1 + 2 * degree)
}

impl Tape {
    /// Positional encoding of degree `L` (Nuvo's "degree 1" for the chart MLP, "degree 4" for the
    /// texture and surface MLPs), the mip-NeRF convention:
    ///
    /// `γ(x) = [x, sin(2⁰x), cos(2⁰x), sin(2¹x), cos(2¹x), …, sin(2^{L−1}x), cos(2^{L−1}x)]`
    ///
    /// applied to every column of `x` (`B×d` → `B×d(1+2L)`), laid out as blocks of `d` columns in that
    /// order. Frequencies are `2^k` radians per unit without a factor π, so inputs in `[−1, 1]` see
    /// at most `2^{L−1}` radians per unit. Degree 0 is the identity.
    pub fn posenc(&mut self, x: Var, degree: usize) -> Var {
        let sx = self.shape(x);
        let d = sx.cols;
        let shape = Shape::new(sx.rows, posenc_width(d, degree));
        let mut out = self.alloc(shape);
        let xv = self.value(x);
        kernels::for_each_row(out.as_mut_slice(), shape.cols, |r, o| {
            let xr = &xv[r * d..(r + 1) * d];
            o[..d].copy_from_slice(xr);
            for k in 0..degree {
                let f = (1u32 << k) as f32;
                let base = d * (1 + 2 * k);
                for j in 0..d {
                    let (sn, cs) = (f * xr[j]).sin_cos();
                    o[base + j] = sn;
                    o[base + d + j] = cs;
                }
            }
        });
        self.push(Op::PosEnc { x, degree }, shape, out, &[x])
    }
}

/// `dx = g_x + Σ_k 2^k (g_sin_k · cos_k − g_cos_k · sin_k)`, with sin/cos read from the output.
pub(crate) fn backward(r: &Reader<'_>, s: &mut GradSink<'_>, out: &[f32], g: &[f32], x: Var, degree: usize) {
    if !s.needs(x) {
        return;
    }
    let d = r.shape(x).cols;
    let w = posenc_width(d, degree);
    let (dst, fresh) = s.slot(x);
    kernels::for_each_row(dst, d, |row, dx| {
        let (o, gr) = (&out[row * w..(row + 1) * w], &g[row * w..(row + 1) * w]);
        for j in 0..d {
            let mut acc = gr[j];
            for k in 0..degree {
                let f = (1u32 << k) as f32;
                let base = d * (1 + 2 * k);
                acc += f * (gr[base + j] * o[base + d + j] - gr[base + d + j] * o[base + j]);
            }
            dx[j] = if fresh { acc } else { dx[j] + acc };
        }
    });
}
