//! The fused affine layer `act(x·W + b)`: one GEMM and one pass for bias and activation forward;
//! one pass for the activation derivative and GEMMs straight into `dW` and `dx` backward.

use serde::{Deserialize, Serialize};

use super::Op;
use super::unary::sigmoid;
use crate::kernels::{self, MatRef, gemm};
use crate::shape::Shape;
use crate::tape::{GradSink, Reader, Tape, Var};

/// Activation applied by a fused [`Tape::linear`] layer. Every derivative is computed from the
/// layer's output alone, so the pre-activation is never stored.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Activation {
    /// `y = z`.
    #[default]
    Identity,
    /// `y = max(z, 0)`.
    Relu,
    /// `y = 1 / (1 + e^{−z})`, the range (0, 1).
    Sigmoid,
    /// `y = tanh z`, the range (−1, 1).
    Tanh,
}

impl Activation {
    #[inline(always)]
    fn apply(self, z: f32) -> f32 {
        match self {
            Activation::Identity => z,
            Activation::Relu => z.max(0.0),
            Activation::Sigmoid => sigmoid(z),
            Activation::Tanh => z.tanh(),
        }
    }

    /// dy/dz from the output y.
    #[inline(always)]
    fn derivative_from_output(self, y: f32) -> f32 {
        match self {
            Activation::Identity => 1.0,
            Activation::Relu => (y > 0.0) as u8 as f32,
            Activation::Sigmoid => y * (1.0 - y),
            Activation::Tanh => 1.0 - y * y,
        }
    }
}

impl Tape {
    /// `act(x·w + b)` with `x: B×in`, `w: in×out`, `b: 1×out` (optional).
    pub fn linear(&mut self, x: Var, w: Var, b: Option<Var>, act: Activation) -> Var {
        let (sx, sw) = (self.shape(x), self.shape(w));
        assert_eq!(sx.cols, sw.rows, "linear: input {sx} does not fit weight {sw}");
        if let Some(b) = b {
            assert_eq!(self.shape(b), Shape::new(1, sw.cols), "linear: bias must be 1×{}", sw.cols);
        }
        let shape = Shape::new(sx.rows, sw.cols);
        let mut out = self.pool.take(shape.len());
        gemm(out.as_mut_slice(), MatRef::new(self.value(x), sx), MatRef::new(self.value(w), sw), false);
        let bias = b.map(|b| self.value(b));
        kernels::for_each_row(out.as_mut_slice(), shape.cols, |_, row| match bias {
            Some(bias) => row.iter_mut().zip(bias).for_each(|(y, &b)| *y = act.apply(*y + b)),
            None if act != Activation::Identity => row.iter_mut().for_each(|y| *y = act.apply(*y)),
            None => {}
        });
        let inputs = [x, w, b.unwrap_or(w)];
        self.push(Op::Linear { x, w, b, act }, shape, out, &inputs)
    }
}

#[allow(clippy::too_many_arguments)]
pub(crate) fn backward(
    r: &Reader<'_>,
    s: &mut GradSink<'_>,
    out: &[f32],
    g: &mut [f32],
    x: Var,
    w: Var,
    b: Option<Var>,
    act: Activation,
) {
    let (sx, sw) = (r.shape(x), r.shape(w));
    // dz = g ⊙ act'(y), in place.
    if act != Activation::Identity {
        kernels::update1(g, out, |g, y| g * act.derivative_from_output(y));
    }
    let dz = MatRef::new(g, Shape::new(sx.rows, sw.cols));
    if let Some(b) = b.filter(|&b| s.needs(b)) {
        let (db, fresh) = s.slot(b);
        kernels::column_sums_dense(db, g, sw.cols, !fresh);
    }
    if s.needs(w) {
        let (dw, fresh) = s.slot(w);
        gemm(dw, MatRef::new(r.value(x), sx).t(), dz, !fresh);
    }
    if s.needs(x) {
        let (dx, fresh) = s.slot(x);
        gemm(dx, dz, MatRef::new(r.value(w), sw).t(), !fresh);
    }
}
