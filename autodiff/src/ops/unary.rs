//! Elementwise unary functions and scalar affine maps.

use super::Op;
use crate::kernels;
use crate::tape::{GradSink, Reader, Tape, Var};

/// Which unary function. Derivatives are expressed from the input `x` and/or output `y`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum UnaryKind {
    Neg,
    Square,
    Sqrt,
    Abs,
    Exp,
    Log,
    Sin,
    Cos,
    Relu,
    Sigmoid,
    Tanh,
    Scale(f32),
    AddScalar(f32),
}

impl UnaryKind {
    #[inline(always)]
    fn apply(self, x: f32) -> f32 {
        match self {
            UnaryKind::Neg => -x,
            UnaryKind::Square => x * x,
            UnaryKind::Sqrt => x.sqrt(),
            UnaryKind::Abs => x.abs(),
            UnaryKind::Exp => x.exp(),
            UnaryKind::Log => x.ln(),
            UnaryKind::Sin => x.sin(),
            UnaryKind::Cos => x.cos(),
            UnaryKind::Relu => x.max(0.0),
            UnaryKind::Sigmoid => sigmoid(x),
            UnaryKind::Tanh => x.tanh(),
            UnaryKind::Scale(s) => x * s,
            UnaryKind::AddScalar(s) => x + s,
        }
    }

    /// dy/dx at input `x` with output `y`.
    #[inline(always)]
    fn derivative(self, x: f32, y: f32) -> f32 {
        match self {
            UnaryKind::Neg => -1.0,
            UnaryKind::Square => 2.0 * x,
            UnaryKind::Sqrt => 0.5 / y,
            UnaryKind::Abs => {
                if x > 0.0 {
                    1.0
                } else if x < 0.0 {
                    -1.0
                } else {
                    0.0
                }
            }
            UnaryKind::Exp => y,
            UnaryKind::Log => 1.0 / x,
            UnaryKind::Sin => x.cos(),
            UnaryKind::Cos => -x.sin(),
            UnaryKind::Relu => (x > 0.0) as u8 as f32,
            UnaryKind::Sigmoid => y * (1.0 - y),
            UnaryKind::Tanh => 1.0 - y * y,
            UnaryKind::Scale(s) => s,
            UnaryKind::AddScalar(_) => 1.0,
        }
    }
}

/// The logistic function, stable for large |x|.
#[inline(always)]
pub(crate) fn sigmoid(x: f32) -> f32 {
    if x >= 0.0 {
        1.0 / (1.0 + (-x).exp())
    } else {
        let e = x.exp();
        e / (1.0 + e)
    }
}

impl Tape {
    fn unary(&mut self, kind: UnaryKind, a: Var) -> Var {
        let shape = self.shape(a);
        let mut out = self.alloc(shape);
        kernels::map1(out.as_mut_slice(), self.value(a), |x| kind.apply(x));
        self.push(Op::Unary { kind, a }, shape, out, &[a])
    }

    /// `-a`.
    pub fn neg(&mut self, a: Var) -> Var {
        self.unary(UnaryKind::Neg, a)
    }
    /// `a²` elementwise.
    pub fn square(&mut self, a: Var) -> Var {
        self.unary(UnaryKind::Square, a)
    }
    /// `√a` elementwise. The gradient is infinite at 0: add a small constant first where 0 can occur.
    pub fn sqrt(&mut self, a: Var) -> Var {
        self.unary(UnaryKind::Sqrt, a)
    }
    /// `|a|` elementwise (subgradient 0 at 0).
    pub fn abs(&mut self, a: Var) -> Var {
        self.unary(UnaryKind::Abs, a)
    }
    /// `eᵃ` elementwise.
    pub fn exp(&mut self, a: Var) -> Var {
        self.unary(UnaryKind::Exp, a)
    }
    /// `ln a` elementwise.
    pub fn log(&mut self, a: Var) -> Var {
        self.unary(UnaryKind::Log, a)
    }
    /// `sin a` elementwise.
    pub fn sin(&mut self, a: Var) -> Var {
        self.unary(UnaryKind::Sin, a)
    }
    /// `cos a` elementwise.
    pub fn cos(&mut self, a: Var) -> Var {
        self.unary(UnaryKind::Cos, a)
    }
    /// `max(a, 0)` elementwise (subgradient 0 at 0).
    pub fn relu(&mut self, a: Var) -> Var {
        self.unary(UnaryKind::Relu, a)
    }
    /// The logistic sigmoid elementwise.
    pub fn sigmoid(&mut self, a: Var) -> Var {
        self.unary(UnaryKind::Sigmoid, a)
    }
    /// `tanh a` elementwise.
    pub fn tanh(&mut self, a: Var) -> Var {
        self.unary(UnaryKind::Tanh, a)
    }
    /// `s·a`.
    pub fn scale(&mut self, a: Var, s: f32) -> Var {
        self.unary(UnaryKind::Scale(s), a)
    }
    /// `a + s`.
    pub fn add_scalar(&mut self, a: Var, s: f32) -> Var {
        self.unary(UnaryKind::AddScalar(s), a)
    }
}

pub(crate) fn backward(
    r: &Reader<'_>,
    s: &mut GradSink<'_>,
    out: &[f32],
    g: &mut [f32],
    kind: UnaryKind,
    a: Var,
) {
    if !s.needs(a) {
        return;
    }
    let x = r.value(a);
    // g becomes the contribution g·f'(x) in place, then is added to a's gradient.
    kernels::update2(g, x, out, |g, x, y| g * kind.derivative(x, y));
    s.add(a, g);
}
