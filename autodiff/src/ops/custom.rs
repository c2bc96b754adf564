//! Scalar terms computed outside the engine with their own gradients (run-time loss plugins).

use super::Op;
use crate::shape::Shape;
use crate::tape::{GradSink, Reader, Span, Tape, Var};

impl Tape {
    /// Records a scalar `value` computed elsewhere from `inputs`, together with its gradient with
    /// respect to each input (`grads[k]` has `inputs[k]`'s shape). Backward adds `g · grads[k]` into
    /// each input: the op's vector-Jacobian product. This is how a plugin loss, evaluated behind a C
    /// ABI, joins the graph.
    ///
    /// # Panics
    /// If the number or lengths of `grads` do not match `inputs` (callers validate plugin output first).
    pub fn custom_scalar(&mut self, inputs: &[Var], value: f32, grads: &[&[f32]]) -> Var {
        assert_eq!(
            inputs.len(),
            grads.len(),
            "custom_scalar: {} inputs but {} gradients",
            inputs.len(),
            grads.len()
        );
        let start = self.f32_arena.len() as u32;
        for (&v, g) in inputs.iter().zip(grads) {
            assert_eq!(
                self.shape(v).len(),
                g.len(),
                "custom_scalar: gradient length does not match input {}",
                self.shape(v)
            );
            self.store_floats(g);
        }
        let span = Span { start, len: self.f32_arena.len() as u32 - start };
        let vars = self.store_vars(inputs);
        let mut out = self.alloc(Shape::SCALAR);
        out.as_mut_slice()[0] = value;
        self.push(Op::CustomScalar { inputs: vars, grads: span }, Shape::SCALAR, out, inputs)
    }
}

pub(crate) fn backward(r: &Reader<'_>, s: &mut GradSink<'_>, g: &[f32], inputs: Span, grads: Span) {
    let mut offset = grads.start as usize;
    for &v in r.vars(inputs) {
        let n = r.shape(v).len();
        if s.needs(v) {
            let src = &r.f32_arena[offset..offset + n];
            let (dst, fresh) = s.slot(v);
            for (d, &j) in dst.iter_mut().zip(src) {
                *d = if fresh { g[0] * j } else { *d + g[0] * j };
            }
        }
        offset += n;
    }
}
