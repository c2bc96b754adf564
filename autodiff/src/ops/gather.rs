//! Gathering rows by index (Chamfer distances pick nearest neighbours this way).

use super::Op;
use crate::shape::Shape;
use crate::tape::{GradSink, Reader, Span, Tape, Var};

impl Tape {
    /// Rows `a[idx[0]], a[idx[1]], ...` stacked: a `idx.len() × cols` tensor. Indices may repeat.
    ///
    /// # Panics
    /// If an index is out of range (callers build indices from their own data structures).
    pub fn gather_rows(&mut self, a: Var, idx: &[u32]) -> Var {
        let sa = self.shape(a);
        if let Some(&bad) = idx.iter().find(|&&i| i as usize >= sa.rows) {
            panic!("gather_rows: index {bad} out of range for a {sa} tensor");
        }
        let shape = Shape::new(idx.len(), sa.cols);
        let mut out = self.alloc(shape);
        let x = self.value(a);
        for (o, &i) in out.as_mut_slice().chunks_exact_mut(sa.cols.max(1)).zip(idx) {
            let i = i as usize;
            o.copy_from_slice(&x[i * sa.cols..(i + 1) * sa.cols]);
        }
        let span = self.store_indices(idx);
        self.push(Op::GatherRows { a, idx: span }, shape, out, &[a])
    }
}

/// Scatter-add, sequential so repeated indices sum in a fixed order.
pub(crate) fn backward(r: &Reader<'_>, s: &mut GradSink<'_>, g: &[f32], a: Var, idx: Span) {
    if !s.needs(a) {
        return;
    }
    let cols = r.shape(a).cols;
    let idx = &r.idx_arena[idx.range()];
    let dst = s.slot_zeroed(a);
    for (k, &i) in idx.iter().enumerate() {
        let i = i as usize;
        dst[i * cols..(i + 1) * cols].iter_mut().zip(&g[k * cols..(k + 1) * cols]).for_each(|(d, s)| *d += s);
    }
}
