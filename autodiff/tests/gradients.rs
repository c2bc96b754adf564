//! Finite-difference gradient checks of every op on random shapes (property tests), including every
//! broadcasting combination and 1-row / 1-column tensors.
//!
//! Inputs are drawn away from each op's kinks and poles (ReLU and |x| at 0, log and division near 0,
//! texel boundaries of bilinear lookups), where a finite difference is not a derivative.

use nuvo_autodiff::gradcheck::{GradCheck, GradCheckError, check_gradients};
use nuvo_autodiff::{Activation, Shape, Tape, Tensor, Var};
use proptest::prelude::*;
use proptest::test_runner::{Config, RngSeed};

fn config() -> Config {
    Config { cases: 48, rng_seed: RngSeed::Fixed(0x5eed), failure_persistence: None, ..Config::default() }
}

/// A tensor of the given shape with values in `lo..hi`.
fn tensor(rows: usize, cols: usize, lo: f32, hi: f32) -> impl Strategy<Value = Tensor> {
    prop::collection::vec(lo..hi, rows * cols).prop_map(move |d| Tensor::from_vec(rows, cols, d))
}

/// A tensor with values in `±[lo, hi]` (random sign): away from zero.
fn tensor_away_from_zero(rows: usize, cols: usize, lo: f32, hi: f32) -> impl Strategy<Value = Tensor> {
    prop::collection::vec((lo..hi, any::<bool>()), rows * cols).prop_map(move |d| {
        Tensor::from_vec(rows, cols, d.into_iter().map(|(m, s)| if s { m } else { -m }).collect())
    })
}

fn dims() -> impl Strategy<Value = (usize, usize)> {
    (1usize..5, 1usize..5)
}

fn check(f: impl Fn(&mut Tape, &[Var]) -> Var, inputs: &[Tensor]) -> Result<(), TestCaseError> {
    check_gradients(f, inputs, GradCheck::default()).map_err(|e| TestCaseError::fail(e.to_string()))
}

/// The four ways an operand can relate to a `rows × cols` output under broadcasting.
fn broadcast_shape(rows: usize, cols: usize, kind: u8) -> Shape {
    match kind % 4 {
        0 => Shape::new(rows, cols),
        1 => Shape::new(1, cols),
        2 => Shape::new(rows, 1),
        _ => Shape::new(1, 1),
    }
}

proptest! {
    #![proptest_config(config())]

    #[test]
    fn matmul_with_every_transpose_combination(m in 1usize..5, k in 1usize..5, n in 1usize..5, ta: bool, tb: bool,
        a in tensor(4, 4, -1.0, 1.0), b in tensor(4, 4, -1.0, 1.0)) {
        let (ra, ca) = if ta { (k, m) } else { (m, k) };
        let (rb, cb) = if tb { (n, k) } else { (k, n) };
        let a = Tensor::from_vec(ra, ca, a.data()[..ra * ca].to_vec());
        let b = Tensor::from_vec(rb, cb, b.data()[..rb * cb].to_vec());
        check(|t, v| t.matmul_t(v[0], v[1], ta, tb), &[a, b])?;
    }

    #[test]
    fn binary_ops_under_every_broadcast((r, c) in dims(), ka in 0u8..4, kb in 0u8..4, op in 0u8..4,
        a_vals in prop::collection::vec(-2.0f32..2.0, 16), b_vals in prop::collection::vec((0.5f32..2.0, any::<bool>()), 16)) {
        let sa = broadcast_shape(r, c, ka);
        let sb = broadcast_shape(r, c, kb);
        let a = Tensor::from_vec(sa.rows, sa.cols, a_vals[..sa.len()].to_vec());
        // b stays away from zero so division is smooth.
        let b = Tensor::from_vec(sb.rows, sb.cols, b_vals[..sb.len()].iter().map(|&(m, s)| if s { m } else { -m }).collect());
        check(|t, v| {
            let y = match op {
                0 => t.add(v[0], v[1]),
                1 => t.sub(v[0], v[1]),
                2 => t.mul(v[0], v[1]),
                _ => t.div(v[0], v[1]),
            };
            // Reuse both operands so their (broadcast) gradients also accumulate a second time.
            let z = t.mul(y, v[1]);
            t.add(z, v[0])
        }, &[a, b])?;
    }

    #[test]
    fn smooth_unary_ops((r, c) in dims(), x in tensor(4, 4, -1.5, 1.5), op in 0u8..7) {
        let x = Tensor::from_vec(r, c, x.data()[..r * c].to_vec());
        check(|t, v| match op {
            0 => t.neg(v[0]),
            1 => t.square(v[0]),
            2 => t.exp(v[0]),
            3 => t.sin(v[0]),
            4 => t.cos(v[0]),
            5 => t.sigmoid(v[0]),
            _ => t.tanh(v[0]),
        }, &[x])?;
    }

    #[test]
    fn scalar_affine_ops((r, c) in dims(), x in tensor(4, 4, -2.0, 2.0), s in -3.0f32..3.0) {
        let x = Tensor::from_vec(r, c, x.data()[..r * c].to_vec());
        check(|t, v| { let y = t.scale(v[0], s); t.add_scalar(y, s) }, &[x])?;
    }

    #[test]
    fn positive_domain_ops((r, c) in dims(), x in tensor(4, 4, 0.3, 3.0), log: bool) {
        let x = Tensor::from_vec(r, c, x.data()[..r * c].to_vec());
        check(|t, v| if log { t.log(v[0]) } else { t.sqrt(v[0]) }, &[x])?;
    }

    #[test]
    fn kinked_ops_away_from_the_kink((r, c) in dims(), x in tensor_away_from_zero(4, 4, 0.05, 2.0), relu: bool) {
        let x = Tensor::from_vec(r, c, x.data()[..r * c].to_vec());
        check(|t, v| if relu { t.relu(v[0]) } else { t.abs(v[0]) }, &[x])?;
    }

    #[test]
    fn softmax_and_log_softmax_over_columns((r, c) in dims(), x in tensor(4, 4, -3.0, 3.0), log: bool) {
        let x = Tensor::from_vec(r, c, x.data()[..r * c].to_vec());
        check(|t, v| if log { t.log_softmax(v[0]) } else { t.softmax(v[0]) }, &[x])?;
    }

    #[test]
    fn reductions((r, c) in dims(), x in tensor(4, 4, -2.0, 2.0), axis in 0u8..3, mean: bool) {
        let x = Tensor::from_vec(r, c, x.data()[..r * c].to_vec());
        check(|t, v| match (axis, mean) {
            (0, false) => t.sum_all(v[0]),
            (0, true) => t.mean_all(v[0]),
            (1, false) => t.sum_each_row(v[0]),
            (1, true) => t.mean_each_row(v[0]),
            (_, false) => t.sum_each_col(v[0]),
            (_, true) => t.mean_each_col(v[0]),
        }, &[x])?;
    }

    #[test]
    fn concat_and_slice_columns(r in 1usize..4, c1 in 1usize..4, c2 in 1usize..4, a in tensor(3, 3, -1.0, 1.0), b in tensor(3, 3, -1.0, 1.0), start in 0usize..6, len in 1usize..6) {
        let a = Tensor::from_vec(r, c1, a.data()[..r * c1].to_vec());
        let b = Tensor::from_vec(r, c2, b.data()[..r * c2].to_vec());
        let total = 2 * c1 + c2;
        let start = start % total;
        let len = 1 + (len - 1) % (total - start);
        // `a` appears twice: its gradient accumulates from two places.
        check(|t, v| { let cat = t.concat_cols(&[v[0], v[1], v[0]]); t.slice_cols(cat, start, len) }, &[a, b])?;
    }

    #[test]
    fn concat_and_slice_rows(c in 1usize..4, r1 in 1usize..4, r2 in 1usize..4, a in tensor(3, 3, -1.0, 1.0), b in tensor(3, 3, -1.0, 1.0), start in 0usize..6, len in 1usize..6) {
        let a = Tensor::from_vec(r1, c, a.data()[..r1 * c].to_vec());
        let b = Tensor::from_vec(r2, c, b.data()[..r2 * c].to_vec());
        let total = 2 * r1 + r2;
        let start = start % total;
        let len = 1 + (len - 1) % (total - start);
        check(|t, v| { let cat = t.concat_rows(&[v[0], v[1], v[0]]); t.slice_rows(cat, start, len) }, &[a, b])?;
    }

    #[test]
    fn gather_rows_with_repeats((r, c) in dims(), x in tensor(4, 4, -1.0, 1.0), idx in prop::collection::vec(0u32..4, 1..7)) {
        let x = Tensor::from_vec(r, c, x.data()[..r * c].to_vec());
        let idx: Vec<u32> = idx.into_iter().map(|i| i % r as u32).collect();
        check(|t, v| t.gather_rows(v[0], &idx), &[x])?;
    }

    #[test]
    fn bilinear_grid_lookup(res in 2usize..6, ch in 1usize..4, grid in tensor(25, 3, -1.0, 1.0),
        cells in prop::collection::vec((0usize..5, 0usize..5, 0.1f32..0.9, 0.1f32..0.9), 1..5)) {
        let grid = Tensor::from_vec(res * res, ch, grid.data()[..res * res * ch].to_vec());
        // Points strictly inside texel cells: the lookup is smooth there.
        let span = (res - 1) as f32;
        let uv: Vec<f32> = cells.iter().flat_map(|&(x, y, fx, fy)| {
            [((x % (res - 1)) as f32 + fx) / span, ((y % (res - 1)) as f32 + fy) / span]
        }).collect();
        let uv = Tensor::from_vec(cells.len(), 2, uv);
        check(|t, v| t.grid_sample(v[0], v[1], res), &[grid, uv])?;
    }

    #[test]
    fn cross_product(r in 1usize..5, a in tensor(4, 3, -1.0, 1.0), b in tensor(4, 3, -1.0, 1.0)) {
        let a = Tensor::from_vec(r, 3, a.data()[..r * 3].to_vec());
        let b = Tensor::from_vec(r, 3, b.data()[..r * 3].to_vec());
        check(|t, v| t.cross(v[0], v[1]), &[a.clone(), b])?;
        // The same operand on both sides (a × a = 0, but its gradient paths must still cancel).
        check(|t, v| t.cross(v[0], v[0]), &[a])?;
    }

    #[test]
    fn positional_encoding((r, d) in (1usize..4, 1usize..4), degree in 0usize..5, x in tensor(3, 3, -1.0, 1.0)) {
        let x = Tensor::from_vec(r, d, x.data()[..r * d].to_vec());
        check(|t, v| t.posenc(v[0], degree), &[x])?;
    }

    #[test]
    fn fused_linear_with_each_activation(b in 1usize..5, i in 1usize..5, o in 1usize..5, act in 0u8..4, with_bias: bool,
        x in tensor(4, 4, -1.0, 1.0), w in tensor(4, 4, -1.0, 1.0), bias in tensor(1, 4, -0.5, 0.5)) {
        let act = [Activation::Identity, Activation::Relu, Activation::Sigmoid, Activation::Tanh][act as usize];
        let x = Tensor::from_vec(b, i, x.data()[..b * i].to_vec());
        let w = Tensor::from_vec(i, o, w.data()[..i * o].to_vec());
        let bias = Tensor::from_vec(1, o, bias.data()[..o].to_vec());
        if act == Activation::Relu {
            // Skip draws whose pre-activations sit on the ReLU kink.
            for r in 0..b {
                for c in 0..o {
                    let z: f32 = (0..i).map(|k| x.get(r, k) * w.get(k, c)).sum::<f32>() + if with_bias { bias.get(0, c) } else { 0.0 };
                    prop_assume!(z.abs() > 0.02);
                }
            }
        }
        check(|t, v| t.linear(v[0], v[1], with_bias.then_some(v[2]), act), &[x, w, bias])?;
    }
}

#[test]
fn grid_lookup_clamps_outside_the_unit_square_with_zero_coordinate_gradient() {
    let mut t = Tape::default();
    let grid = t.input(&Tensor::from_vec(4, 1, vec![0.0, 1.0, 2.0, 3.0]));
    let uv = t.leaf(&Tensor::from_vec(2, 2, vec![-0.5, 0.25, 1.5, 0.5]));
    let out = t.grid_sample(grid, uv, 2);
    // (-0.5 → 0, 0.25): 0 + 0.25·(2 − 0) = 0.5; (1.5 → 1, 0.5): 1 + 0.5·(3 − 1) = 2.
    assert_eq!(t.value(out), &[0.5, 2.0]);
    let s = t.sum_all(out);
    t.backward(s);
    let g = t.grad(uv).unwrap();
    assert_eq!(g[0], 0.0, "clamped u has no gradient");
    assert_eq!(g[2], 0.0, "clamped u has no gradient");
    assert_eq!(g[1], 2.0);
    assert_eq!(g[3], 2.0);
}

#[test]
fn stop_grad_blocks_the_gradient() {
    // d/dx [x · stop(x)] = stop(x) = x, not 2x.
    let mut t = Tape::default();
    let x = t.leaf(&Tensor::from_vec(1, 3, vec![1.0, -2.0, 3.0]));
    let s = t.stop_grad(x);
    let y = t.mul(x, s);
    let l = t.sum_all(y);
    t.backward(l);
    assert_eq!(t.grad(x).unwrap(), &[1.0, -2.0, 3.0]);
}

#[test]
fn custom_scalar_with_correct_gradient_passes_the_check() {
    let x = Tensor::from_vec(2, 3, vec![0.3, -0.7, 1.1, 0.2, 0.9, -1.4]);
    let f = |t: &mut Tape, v: &[Var]| {
        let xs = t.value(v[0]).to_vec();
        let value: f32 = xs.iter().map(|x| x * x * x).sum();
        let grad: Vec<f32> = xs.iter().map(|x| 3.0 * x * x).collect();
        t.custom_scalar(&[v[0]], value, &[&grad])
    };
    check_gradients(f, &[x], GradCheck::default()).unwrap();
}

/// The checker itself must catch wrong derivatives: a gradient 10% off, or with a flipped sign on one
/// element, is reported.
#[test]
fn the_checker_catches_a_wrong_derivative() {
    let x = Tensor::from_vec(2, 2, vec![0.5, -1.0, 1.5, 0.8]);
    for wrong in [|x: f32, _i: usize| 2.2 * x, |x: f32, i: usize| if i == 2 { -2.0 * x } else { 2.0 * x }] {
        let f = move |t: &mut Tape, v: &[Var]| {
            let xs = t.value(v[0]).to_vec();
            let value: f32 = xs.iter().map(|x| x * x).sum();
            let grad: Vec<f32> = xs.iter().enumerate().map(|(i, &x)| wrong(x, i)).collect();
            t.custom_scalar(&[v[0]], value, &[&grad])
        };
        let err: GradCheckError =
            check_gradients(f, std::slice::from_ref(&x), GradCheck::default()).unwrap_err();
        assert!(!err.0.is_empty());
    }
}

/// A chain that exercises accumulation into shared nodes and into parameters: a posenc-MLP loss.
#[test]
fn composite_mlp_loss_gradient() {
    let x = Tensor::from_vec(3, 2, vec![0.1, -0.4, 0.7, 0.2, -0.9, 0.5]);
    let w1 = Tensor::from_vec(10, 4, (0..40).map(|i| ((i * 37 % 17) as f32 - 8.0) / 10.0).collect());
    let w2 = Tensor::from_vec(4, 3, (0..12).map(|i| ((i * 11 % 7) as f32 - 3.0) / 5.0).collect());
    let f = |t: &mut Tape, v: &[Var]| {
        let e = t.posenc(v[0], 2);
        let h = t.linear(e, v[1], None, Activation::Tanh);
        let o = t.linear(h, v[2], None, Activation::Identity);
        let p = t.softmax(o);
        let lp = t.log(p);
        let sq = t.square(o);
        let s = t.add(lp, sq);
        t.mean_all(s)
    };
    check_gradients(f, &[x, w1, w2], GradCheck::default()).unwrap();
}
