//! Concatenating and slicing columns and rows, and stopping gradients.

use super::Op;
use crate::kernels;
use crate::shape::Shape;
use crate::tape::{GradSink, Reader, Span, Tape, Var};

impl Tape {
    /// Columns of `parts` side by side; all parts must have the same number of rows.
    pub fn concat_cols(&mut self, parts: &[Var]) -> Var {
        assert!(!parts.is_empty(), "concat_cols of nothing");
        let rows = self.shape(parts[0]).rows;
        for &p in parts {
            assert_eq!(
                self.shape(p).rows,
                rows,
                "concat_cols: parts have {} and {} rows",
                rows,
                self.shape(p).rows
            );
        }
        let cols = parts.iter().map(|&p| self.shape(p).cols).sum();
        let shape = Shape::new(rows, cols);
        let mut out = self.alloc(shape);
        let mut offset = 0;
        for &p in parts {
            let (pc, pv) = (self.shape(p).cols, self.value(p));
            kernels::for_each_row(out.as_mut_slice(), cols, |r, o| {
                o[offset..offset + pc].copy_from_slice(&pv[r * pc..(r + 1) * pc]);
            });
            offset += pc;
        }
        let inputs = self.store_vars(parts);
        self.push(Op::ConcatCols { inputs }, shape, out, parts)
    }

    /// Rows of `parts` one after another; all parts must have the same number of columns.
    pub fn concat_rows(&mut self, parts: &[Var]) -> Var {
        assert!(!parts.is_empty(), "concat_rows of nothing");
        let cols = self.shape(parts[0]).cols;
        for &p in parts {
            assert_eq!(
                self.shape(p).cols,
                cols,
                "concat_rows: parts have {} and {} columns",
                cols,
                self.shape(p).cols
            );
        }
        let rows = parts.iter().map(|&p| self.shape(p).rows).sum();
        let shape = Shape::new(rows, cols);
        let mut out = self.alloc(shape);
        let mut offset = 0;
        for &p in parts {
            let v = self.value(p);
            out.as_mut_slice()[offset..offset + v.len()].copy_from_slice(v);
            offset += v.len();
        }
        let inputs = self.store_vars(parts);
        self.push(Op::ConcatRows { inputs }, shape, out, parts)
    }

    /// Columns `start..start + len` of `a`.
    pub fn slice_cols(&mut self, a: Var, start: usize, len: usize) -> Var {
        let sa = self.shape(a);
        assert!(start + len <= sa.cols, "slice_cols {start}..{} of a {sa} tensor", start + len);
        let shape = Shape::new(sa.rows, len);
        let mut out = self.alloc(shape);
        let x = self.value(a);
        kernels::for_each_row(out.as_mut_slice(), len, |r, o| {
            o.copy_from_slice(&x[r * sa.cols + start..r * sa.cols + start + len]);
        });
        self.push(Op::SliceCols { a, start }, shape, out, &[a])
    }

    /// Rows `start..start + len` of `a`.
    pub fn slice_rows(&mut self, a: Var, start: usize, len: usize) -> Var {
        let sa = self.shape(a);
        assert!(start + len <= sa.rows, "slice_rows {start}..{} of a {sa} tensor", start + len);
        let shape = Shape::new(len, sa.cols);
        let mut out = self.alloc(shape);
        out.as_mut_slice().copy_from_slice(&self.value(a)[start * sa.cols..(start + len) * sa.cols]);
        self.push(Op::SliceRows { a, start }, shape, out, &[a])
    }

    /// The value of `a` with no gradient flowing back through it.
    pub fn stop_grad(&mut self, a: Var) -> Var {
        let shape = self.shape(a);
        let mut out = self.alloc(shape);
        out.as_mut_slice().copy_from_slice(self.value(a));
        self.push_node(Op::StopGrad, shape, out, false)
    }
}

pub(crate) fn concat_cols_backward(r: &Reader<'_>, s: &mut GradSink<'_>, g: &[f32], inputs: Span) {
    let cols: usize = r.vars(inputs).iter().map(|&p| r.shape(p).cols).sum();
    let mut offset = 0;
    for &p in r.vars(inputs) {
        let pc = r.shape(p).cols;
        if s.needs(p) {
            let (dst, fresh) = s.slot(p);
            kernels::for_each_row(dst, pc, |row, d| {
                let src = &g[row * cols + offset..row * cols + offset + pc];
                if fresh {
                    d.copy_from_slice(src);
                } else {
                    d.iter_mut().zip(src).for_each(|(d, s)| *d += s);
                }
            });
        }
        offset += pc;
    }
}

pub(crate) fn concat_rows_backward(r: &Reader<'_>, s: &mut GradSink<'_>, g: &[f32], inputs: Span) {
    let mut offset = 0;
    for &p in r.vars(inputs) {
        let n = r.shape(p).len();
        if s.needs(p) {
            s.add(p, &g[offset..offset + n]);
        }
        offset += n;
    }
}

pub(crate) fn slice_cols_backward(r: &Reader<'_>, s: &mut GradSink<'_>, g: &[f32], a: Var, start: usize) {
    if !s.needs(a) {
        return;
    }
    let sa = r.shape(a);
    let len = g.len() / sa.rows.max(1);
    let dst = s.slot_zeroed(a);
    kernels::for_each_row(dst, sa.cols, |row, d| {
        d[start..start + len].iter_mut().zip(&g[row * len..(row + 1) * len]).for_each(|(d, s)| *d += s);
    });
}

pub(crate) fn slice_rows_backward(r: &Reader<'_>, s: &mut GradSink<'_>, g: &[f32], a: Var, start: usize) {
    if !s.needs(a) {
        return;
    }
    let cols = r.shape(a).cols;
    let dst = s.slot_zeroed(a);
    dst[start * cols..start * cols + g.len()].iter_mut().zip(g).for_each(|(d, s)| *d += s);
}
