//! Every differentiable operation: forward builders (methods on [`Tape`]) and backward kernels.
//!
//! One module per family. Each backward kernel receives the op's output value and its incoming
//! gradient `g` (which it may overwrite: the tape owns it and discards it afterwards) and adds the
//! vector-Jacobian products into its inputs' gradients through [`GradSink`].

mod binary;
mod custom;
mod gather;
mod grid;
mod layout;
mod linear;
mod matmul;
mod posenc;
mod reduce;
mod softmax;
mod unary;
mod vector;

pub use linear::Activation;
pub use posenc::posenc_width;

use crate::bf16::MatmulPrecision;
use crate::kernels;
use crate::params::ParamId;
use crate::shape::Shape;
use crate::tape::{GradSink, Reader, Span, Var};

pub(crate) use binary::BinaryKind;
pub(crate) use reduce::Axis;
pub(crate) use unary::UnaryKind;

/// A recorded operation and the inputs it needs for its backward pass.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Op {
    /// Data (no inputs). Requires grad only for [`Tape::leaf`].
    Leaf,
    /// A parameter; its value lives in the `ParamStore`.
    Param(ParamId),
    /// A copy that blocks gradients.
    StopGrad,
    MatMul {
        a: Var,
        b: Var,
        ta: bool,
        tb: bool,
    },
    Linear {
        x: Var,
        w: Var,
        b: Option<Var>,
        act: Activation,
        /// The precision the products ran at (already [`crate::MatmulPrecision::effective`]).
        precision: MatmulPrecision,
        /// Where the forward kept `xᵀ` packed for the weight gradient ([`crate::Tape::packed`]).
        packed_xt: Option<u32>,
        /// Where a ReLU layer kept the bits of `y > 0` for its backward ([`crate::Tape::masks`]).
        relu_mask: Option<u32>,
    },
    Binary {
        kind: BinaryKind,
        a: Var,
        b: Var,
    },
    Unary {
        kind: UnaryKind,
        a: Var,
    },
    Softmax {
        a: Var,
        log: bool,
    },
    Reduce {
        a: Var,
        axis: Axis,
        scale: f32,
    },
    ConcatCols {
        inputs: Span,
    },
    ConcatRows {
        inputs: Span,
    },
    SliceCols {
        a: Var,
        start: usize,
    },
    SliceRows {
        a: Var,
        start: usize,
    },
    GatherRows {
        a: Var,
        idx: Span,
    },
    GridSample {
        grid: Var,
        uv: Var,
        res: usize,
    },
    Cross {
        a: Var,
        b: Var,
    },
    PosEnc {
        x: Var,
        degree: usize,
    },
    CustomScalar {
        inputs: Span,
        grads: Span,
    },
}

impl Op {
    /// Leaves have no backward of their own.
    pub fn is_leaf(&self) -> bool {
        matches!(self, Op::Leaf | Op::Param(_) | Op::StopGrad)
    }
}

/// Runs the backward kernel of `op`.
pub(crate) fn backward(op: &Op, r: &Reader<'_>, s: &mut GradSink<'_>, out: &[f32], g: &mut [f32]) {
    match *op {
        Op::Leaf | Op::Param(_) | Op::StopGrad => {}
        Op::MatMul { a, b, ta, tb } => matmul::backward(r, s, g, a, b, ta, tb),
        Op::Linear { x, w, b, act, precision, packed_xt, relu_mask } => {
            linear::backward(r, s, out, g, x, w, b, act, precision, packed_xt, relu_mask)
        }
        Op::Binary { kind, a, b } => binary::backward(r, s, out, g, kind, a, b),
        Op::Unary { kind, a } => unary::backward(r, s, out, g, kind, a),
        Op::Softmax { a, log } => softmax::backward(r, s, out, g, a, log),
        Op::Reduce { a, axis, scale } => reduce::backward(r, s, g, a, axis, scale),
        Op::ConcatCols { inputs } => layout::concat_cols_backward(r, s, g, inputs),
        Op::ConcatRows { inputs } => layout::concat_rows_backward(r, s, g, inputs),
        Op::SliceCols { a, start } => layout::slice_cols_backward(r, s, g, a, start),
        Op::SliceRows { a, start } => layout::slice_rows_backward(r, s, g, a, start),
        Op::GatherRows { a, idx } => gather::backward(r, s, g, a, idx),
        Op::GridSample { grid, uv, res } => grid::backward(r, s, g, grid, uv, res),
        Op::Cross { a, b } => vector::cross_backward(r, s, g, a, b),
        Op::PosEnc { x, degree } => posenc::backward(r, s, out, g, x, degree),
        Op::CustomScalar { inputs, grads } => custom::backward(r, s, g, inputs, grads),
    }
}

/// Element `(r, c)` of a tensor of shape `s` broadcast to a larger shape.
#[inline(always)]
pub(crate) fn bcast_at(data: &[f32], s: Shape, r: usize, c: usize) -> f32 {
    let rr = if s.rows == 1 { 0 } else { r };
    let cc = if s.cols == 1 { 0 } else { c };
    data[rr * s.cols + cc]
}

/// Adds into `v`'s gradient the sum of `elem(r, c)` (a full `out`-shaped contribution) over the
/// dimensions in which `v` was broadcast to `out`.
pub(crate) fn reduce_into(
    s: &mut GradSink<'_>,
    v: Var,
    vs: Shape,
    out: Shape,
    elem: impl Fn(usize, usize) -> f32 + Sync,
) {
    let (dst, fresh) = s.slot(v);
    match (vs.rows != out.rows, vs.cols != out.cols) {
        (false, false) => kernels::for_each_row(dst, out.cols, |r, row| {
            for (c, d) in row.iter_mut().enumerate() {
                *d = if fresh { elem(r, c) } else { *d + elem(r, c) };
            }
        }),
        (true, false) => kernels::column_sums(dst, out.rows, out.cols, !fresh, elem),
        (false, true) => kernels::row_sums(dst, out.cols, !fresh, elem),
        (true, true) => {
            let t = kernels::total_sum(out.rows, out.cols, elem) as f32;
            dst[0] = if fresh { t } else { dst[0] + t };
        }
    }
}
