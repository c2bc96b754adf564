//! Elementwise binary arithmetic with 2-D broadcasting of rows, columns and scalars.

use super::{Op, bcast_at, reduce_into};
use crate::kernels;
use crate::shape::Shape;
use crate::tape::{GradSink, Reader, Tape, Var};

/// Which arithmetic operation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum BinaryKind {
    Add,
    Sub,
    Mul,
    Div,
}

/// One row of an operand: a slice, or a single value broadcast along the row.
enum RowView<'a> {
    Slice(&'a [f32]),
    Scalar(f32),
}

fn row_view(data: &[f32], s: Shape, r: usize) -> RowView<'_> {
    let r = if s.rows == 1 { 0 } else { r };
    let row = &data[r * s.cols..(r + 1) * s.cols];
    if s.cols == 1 { RowView::Scalar(row[0]) } else { RowView::Slice(row) }
}

fn forward_with(
    out: &mut [f32],
    shape: Shape,
    a: (&[f32], Shape),
    b: (&[f32], Shape),
    f: impl Fn(f32, f32) -> f32 + Sync,
) {
    kernels::for_each_row(out, shape.cols, |r, o| match (row_view(a.0, a.1, r), row_view(b.0, b.1, r)) {
        (RowView::Slice(x), RowView::Slice(y)) => {
            o.iter_mut().zip(x).zip(y).for_each(|((o, &x), &y)| *o = f(x, y))
        }
        (RowView::Slice(x), RowView::Scalar(y)) => o.iter_mut().zip(x).for_each(|(o, &x)| *o = f(x, y)),
        (RowView::Scalar(x), RowView::Slice(y)) => o.iter_mut().zip(y).for_each(|(o, &y)| *o = f(x, y)),
        (RowView::Scalar(x), RowView::Scalar(y)) => o.fill(f(x, y)),
    });
}

impl Tape {
    fn binary(&mut self, kind: BinaryKind, a: Var, b: Var) -> Var {
        let (sa, sb) = (self.shape(a), self.shape(b));
        let shape =
            sa.broadcast(sb).unwrap_or_else(|| panic!("{kind:?}: shapes {sa} and {sb} do not broadcast"));
        let mut out = self.alloc(shape);
        let (va, vb) = ((self.value(a), sa), (self.value(b), sb));
        let o = out.as_mut_slice();
        match kind {
            BinaryKind::Add => forward_with(o, shape, va, vb, |x, y| x + y),
            BinaryKind::Sub => forward_with(o, shape, va, vb, |x, y| x - y),
            BinaryKind::Mul => forward_with(o, shape, va, vb, |x, y| x * y),
            BinaryKind::Div => forward_with(o, shape, va, vb, |x, y| x / y),
        }
        self.push(Op::Binary { kind, a, b }, shape, out, &[a, b])
    }

    /// `a + b` with broadcasting (see [`Shape::broadcast`]).
    pub fn add(&mut self, a: Var, b: Var) -> Var {
        self.binary(BinaryKind::Add, a, b)
    }
    /// `a − b` with broadcasting.
    pub fn sub(&mut self, a: Var, b: Var) -> Var {
        self.binary(BinaryKind::Sub, a, b)
    }
    /// `a ⊙ b` with broadcasting.
    pub fn mul(&mut self, a: Var, b: Var) -> Var {
        self.binary(BinaryKind::Mul, a, b)
    }
    /// `a ⊘ b` with broadcasting.
    pub fn div(&mut self, a: Var, b: Var) -> Var {
        self.binary(BinaryKind::Div, a, b)
    }
}

pub(crate) fn backward(
    r: &Reader<'_>,
    s: &mut GradSink<'_>,
    out: &[f32],
    g: &[f32],
    kind: BinaryKind,
    a: Var,
    b: Var,
) {
    let (sa, sb) = (r.shape(a), r.shape(b));
    let so = sa.broadcast(sb).expect("shapes were checked in forward");
    let (va, vb) = (r.value(a), r.value(b));
    let gat = |i: usize, j: usize| g[i * so.cols + j];
    if s.needs(a) {
        match kind {
            BinaryKind::Add | BinaryKind::Sub => reduce_into(s, a, sa, so, gat),
            BinaryKind::Mul => reduce_into(s, a, sa, so, |i, j| gat(i, j) * bcast_at(vb, sb, i, j)),
            BinaryKind::Div => reduce_into(s, a, sa, so, |i, j| gat(i, j) / bcast_at(vb, sb, i, j)),
        }
    }
    if s.needs(b) {
        match kind {
            BinaryKind::Add => reduce_into(s, b, sb, so, gat),
            BinaryKind::Sub => reduce_into(s, b, sb, so, |i, j| -gat(i, j)),
            BinaryKind::Mul => reduce_into(s, b, sb, so, |i, j| gat(i, j) * bcast_at(va, sa, i, j)),
            // d(a/b)/db = −(a/b)/b = −out/b.
            BinaryKind::Div => {
                reduce_into(s, b, sb, so, |i, j| -gat(i, j) * out[i * so.cols + j] / bcast_at(vb, sb, i, j))
            }
        }
    }
}
