//! Operations on rows that are 3-vectors.

use super::Op;
use crate::kernels;
use crate::shape::Shape;
use crate::tape::{GradSink, Reader, Tape, Var};

#[inline(always)]
fn cross(a: &[f32], b: &[f32]) -> [f32; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

impl Tape {
    /// Row-wise cross product of two `B×3` tensors.
    pub fn cross(&mut self, a: Var, b: Var) -> Var {
        let (sa, sb) = (self.shape(a), self.shape(b));
        assert!(sa.cols == 3 && sa == sb, "cross: needs two equal B×3 tensors, got {sa} and {sb}");
        let mut out = self.alloc(sa);
        let (va, vb) = (self.value(a), self.value(b));
        kernels::for_each_row(out.as_mut_slice(), 3, |r, o| {
            o.copy_from_slice(&cross(&va[3 * r..3 * r + 3], &vb[3 * r..3 * r + 3]));
        });
        self.push(Op::Cross { a, b }, Shape::new(sa.rows, 3), out, &[a, b])
    }
}

/// For `c = a × b`: `da = b × g` and `db = g × a`.
pub(crate) fn cross_backward(r: &Reader<'_>, s: &mut GradSink<'_>, g: &[f32], a: Var, b: Var) {
    let (va, vb) = (r.value(a), r.value(b));
    for (v, other, g_first) in [(a, vb, false), (b, va, true)] {
        if !s.needs(v) {
            continue;
        }
        let (dst, fresh) = s.slot(v);
        kernels::for_each_row(dst, 3, |row, d| {
            let gr = &g[3 * row..3 * row + 3];
            let o = &other[3 * row..3 * row + 3];
            let c = if g_first { cross(gr, o) } else { cross(o, gr) };
            for k in 0..3 {
                d[k] = if fresh { c[k] } else { d[k] + c[k] };
            }
        });
    }
}
