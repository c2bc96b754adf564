//! Sums and means over everything, over each row, or over each column.

use super::Op;
use crate::kernels;
use crate::shape::Shape;
use crate::tape::{GradSink, Reader, Tape, Var};

/// What a reduction collapses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Axis {
    /// Everything → 1×1.
    All,
    /// Each row across its columns → rows×1.
    EachRow,
    /// Each column across the rows → 1×cols.
    EachCol,
}

impl Tape {
    fn reduce(&mut self, a: Var, axis: Axis, mean: bool) -> Var {
        let sa = self.shape(a);
        let (shape, count) = match axis {
            Axis::All => (Shape::SCALAR, sa.len()),
            Axis::EachRow => (Shape::new(sa.rows, 1), sa.cols),
            Axis::EachCol => (Shape::new(1, sa.cols), sa.rows),
        };
        let scale = if mean { 1.0 / count.max(1) as f32 } else { 1.0 };
        let mut out = self.alloc(shape);
        let x = self.value(a);
        let at = |r: usize, c: usize| x[r * sa.cols + c];
        let o = out.as_mut_slice();
        match axis {
            Axis::All => o[0] = kernels::total_sum(sa.rows, sa.cols, at) as f32,
            Axis::EachRow => kernels::row_sums(o, sa.cols, false, at),
            Axis::EachCol => kernels::column_sums_dense(o, x, sa.cols, false),
        }
        if mean {
            o.iter_mut().for_each(|v| *v *= scale);
        }
        self.push(Op::Reduce { a, axis, scale }, shape, out, &[a])
    }

    /// Sum of all elements (1×1).
    pub fn sum_all(&mut self, a: Var) -> Var {
        self.reduce(a, Axis::All, false)
    }
    /// Mean of all elements (1×1).
    pub fn mean_all(&mut self, a: Var) -> Var {
        self.reduce(a, Axis::All, true)
    }
    /// Sum of each row (rows×1).
    pub fn sum_each_row(&mut self, a: Var) -> Var {
        self.reduce(a, Axis::EachRow, false)
    }
    /// Mean of each row (rows×1).
    pub fn mean_each_row(&mut self, a: Var) -> Var {
        self.reduce(a, Axis::EachRow, true)
    }
    /// Sum of each column (1×cols).
    pub fn sum_each_col(&mut self, a: Var) -> Var {
        self.reduce(a, Axis::EachCol, false)
    }
    /// Mean of each column (1×cols).
    pub fn mean_each_col(&mut self, a: Var) -> Var {
        self.reduce(a, Axis::EachCol, true)
    }
}

/// Each input element receives `scale ×` the gradient of the output it was summed into.
pub(crate) fn backward(r: &Reader<'_>, s: &mut GradSink<'_>, g: &[f32], a: Var, axis: Axis, scale: f32) {
    if !s.needs(a) {
        return;
    }
    let sa = r.shape(a);
    let (dst, fresh) = s.slot(a);
    kernels::for_each_row(dst, sa.cols, |row, d| {
        for (c, d) in d.iter_mut().enumerate() {
            let gv = match axis {
                Axis::All => g[0],
                Axis::EachRow => g[row],
                Axis::EachCol => g[c],
            } * scale;
            *d = if fresh { gv } else { *d + gv };
        }
    });
}
