//! Finite-difference gradient checking, for this crate's ops and for any crate's losses.
//!
//! [`check_gradients`] records `f` on leaves holding `inputs`, runs `backward`, and compares every
//! analytic partial derivative (or a seeded sample of them for large inputs) with a central difference
//! `(L(x + h) − L(x − h)) / 2h`. A non-scalar output is projected to a scalar with fixed random
//! weights, so every output element's gradient is exercised.
//!
//! Tolerances: the engine is f32, so a central difference carries a rounding error of roughly
//! `1e-7·|L|/h` on top of its `O(h²)` truncation error; the defaults (`h = 1e-3`, `atol = 5e-3`,
//! `rtol = 1e-2`) leave room for that and still fail on a wrong derivative (a factor or sign error is
//! off by ~100%). Choose inputs away from kinks (ReLU, abs at 0) and poles (log, div near 0).

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::shape::Shape;
use crate::tape::{Tape, Var};
use crate::tensor::Tensor;

/// Settings of a gradient check.
#[derive(Clone, Copy, Debug)]
pub struct GradCheck {
    /// Finite-difference step.
    pub step: f32,
    /// Absolute tolerance.
    pub atol: f32,
    /// Relative tolerance (of the larger magnitude of the two derivatives).
    pub rtol: f32,
    /// At most this many elements per input are checked (a seeded sample when the input is larger).
    pub max_elements: usize,
    /// Seed of the projection weights and the element sample.
    pub seed: u64,
}

impl Default for GradCheck {
    fn default() -> Self {
        GradCheck { step: 1e-3, atol: 5e-3, rtol: 1e-2, max_elements: 48, seed: 0 }
    }
}

/// One partial derivative that disagrees with its finite difference.
#[derive(Clone, Debug, PartialEq)]
pub struct Mismatch {
    /// Which input.
    pub input: usize,
    /// Which element of it (row-major).
    pub element: usize,
    pub analytic: f32,
    pub numeric: f32,
}

/// Why a check failed: every mismatching element.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{} gradient mismatches, first: input {} element {}: analytic {} vs numeric {}",
    .0.len(), .0[0].input, .0[0].element, .0[0].analytic, .0[0].numeric)]
pub struct GradCheckError(pub Vec<Mismatch>);

/// Checks the gradient of `f` with respect to every input. `f` must be deterministic.
pub fn check_gradients(
    f: impl Fn(&mut Tape, &[Var]) -> Var,
    inputs: &[Tensor],
    cfg: GradCheck,
) -> Result<(), GradCheckError> {
    let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed);
    // Analytic gradients.
    let mut tape = Tape::default();
    let leaves: Vec<Var> = inputs.iter().map(|t| tape.leaf(t)).collect();
    let out = f(&mut tape, &leaves);
    let out_shape = tape.shape(out);
    let weights = projection(out_shape, &mut rng);
    // Project even scalar outputs, so the analytic and numeric sides see the same function.
    let w = tape.input(&weights);
    let p = tape.mul(out, w);
    let loss = tape.sum_all(p);
    tape.backward(loss);
    let analytic: Vec<Vec<f32>> = leaves
        .iter()
        .zip(inputs)
        .map(|(&l, t)| tape.grad(l).map(<[f32]>::to_vec).unwrap_or_else(|| vec![0.0; t.data().len()]))
        .collect();

    // Numeric gradients, projected in f64 to keep the final sum's rounding out of the difference.
    let eval = |xs: &[Tensor]| -> f64 {
        let mut tape = Tape::default();
        let vars: Vec<Var> = xs.iter().map(|t| tape.input(t)).collect();
        let out = f(&mut tape, &vars);
        tape.value(out).iter().zip(weights.data()).map(|(&o, &w)| o as f64 * w as f64).sum()
    };
    let mut mismatches = Vec::new();
    for (k, input) in inputs.iter().enumerate() {
        for e in sample_elements(input.data().len(), cfg.max_elements, &mut rng) {
            let mut xs = inputs.to_vec();
            let x0 = xs[k].data()[e];
            xs[k].data_mut()[e] = x0 + cfg.step;
            let up = eval(&xs);
            xs[k].data_mut()[e] = x0 - cfg.step;
            let down = eval(&xs);
            let numeric = ((up - down) / (2.0 * cfg.step as f64)) as f32;
            let a = analytic[k][e];
            let tol = cfg.atol + cfg.rtol * a.abs().max(numeric.abs());
            // A NaN on either side makes `agrees` false: it counts as a mismatch.
            let agrees = (a - numeric).abs() <= tol;
            if !agrees {
                mismatches.push(Mismatch { input: k, element: e, analytic: a, numeric });
            }
        }
    }
    if mismatches.is_empty() { Ok(()) } else { Err(GradCheckError(mismatches)) }
}

/// Projection weights in [0.5, 1.5] with random signs: never near zero, so no element is ignored.
fn projection(shape: Shape, rng: &mut ChaCha8Rng) -> Tensor {
    let data = (0..shape.len())
        .map(|_| {
            let m: f32 = rng.random_range(0.5..1.5);
            if rng.random::<bool>() { m } else { -m }
        })
        .collect();
    Tensor::from_vec(shape.rows, shape.cols, data)
}

fn sample_elements(len: usize, max: usize, rng: &mut ChaCha8Rng) -> Vec<usize> {
    if len <= max { (0..len).collect() } else { rand::seq::index::sample(rng, len, max).into_vec() }
}
