//! Matrix products with optionally transposed operands, through the `gemm` crate (no copies).

use super::Op;
use crate::kernels::{MatRef, gemm};
use crate::shape::Shape;
use crate::tape::{GradSink, Reader, Tape, Var};

impl Tape {
    /// `a · b`.
    pub fn matmul(&mut self, a: Var, b: Var) -> Var {
        self.matmul_t(a, b, false, false)
    }

    /// `op(a) · op(b)` where `op` transposes when the flag is set. Transposes are strides, not copies.
    pub fn matmul_t(&mut self, a: Var, b: Var, ta: bool, tb: bool) -> Var {
        let (sa, sb) = (self.shape(a), self.shape(b));
        let (m, k) = if ta { (sa.cols, sa.rows) } else { (sa.rows, sa.cols) };
        let (k2, n) = if tb { (sb.cols, sb.rows) } else { (sb.rows, sb.cols) };
        assert_eq!(
            k,
            k2,
            "matmul: {sa}{} · {sb}{} has mismatched inner dimensions",
            if ta { "ᵀ" } else { "" },
            if tb { "ᵀ" } else { "" }
        );
        let shape = Shape::new(m, n);
        let mut out = self.alloc(shape);
        let av = MatRef::new(self.value(a), sa).maybe_t(ta);
        let bv = MatRef::new(self.value(b), sb).maybe_t(tb);
        gemm(out.as_mut_slice(), av, bv, false);
        self.push(Op::MatMul { a, b, ta, tb }, shape, out, &[a, b])
    }
}

/// With `C = A'·B'` (`A' = op(A)`, `B' = op(B)`): `dA' = G·B'ᵀ` and `dB' = A'ᵀ·G`, each transposed
/// back when the operand was used transposed, all as strided GEMMs straight into the gradients.
pub(crate) fn backward(r: &Reader<'_>, s: &mut GradSink<'_>, g: &[f32], a: Var, b: Var, ta: bool, tb: bool) {
    let (sa, sb) = (r.shape(a), r.shape(b));
    let av = MatRef::new(r.value(a), sa).maybe_t(ta);
    let bv = MatRef::new(r.value(b), sb).maybe_t(tb);
    let gv = MatRef::new(g, Shape::new(av.rows, bv.cols));
    if s.needs(a) {
        let (dst, fresh) = s.slot(a);
        if ta { gemm(dst, bv, gv.t(), !fresh) } else { gemm(dst, gv, bv.t(), !fresh) }
    }
    if s.needs(b) {
        let (dst, fresh) = s.slot(b);
        if tb { gemm(dst, gv.t(), av, !fresh) } else { gemm(dst, av.t(), gv, !fresh) }
    }
}
