//! End-to-end behaviour of the engine over many steps: learning, pooled memory, determinism.

use std::collections::BTreeMap;

use nuvo_autodiff::nn::{Mlp, MlpConfig};
use nuvo_autodiff::optim::{Adam, AdamConfig, CosineSchedule};
use nuvo_autodiff::{Activation, ParamStore, Shape, Tape, Tensor};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn target(x: f32, y: f32) -> f32 {
    (std::f32::consts::PI * x).sin() * (std::f32::consts::PI * y).cos()
}

struct Fit {
    tape: Tape,
    mlp: Mlp,
    adam: Adam,
    rng: ChaCha8Rng,
}

impl Fit {
    fn new(seed: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut params = ParamStore::new();
        let cfg = MlpConfig { depth: 4, width: 64, activation: Activation::Relu, init: Default::default() };
        let io = (nuvo_autodiff::posenc_width(2, 2), 1, Activation::Identity);
        let mlp = Mlp::new(&mut params, "f", "mlp", &cfg, io, &mut rng);
        let adam =
            Adam::new(&params, AdamConfig::default(), &BTreeMap::from([("mlp".to_owned(), 3e-3)])).unwrap();
        Fit { tape: Tape::new(params), mlp, adam, rng }
    }

    /// One step on a fresh random batch; returns the batch loss.
    fn step(&mut self, lr_factor: f32) -> f32 {
        const B: usize = 256;
        let pts: Vec<[f32; 2]> =
            (0..B).map(|_| [self.rng.random_range(-1.0..1.0), self.rng.random_range(-1.0..1.0)]).collect();
        let t = &mut self.tape;
        t.reset();
        t.params_mut().zero_grads();
        let x = t.input_with(Shape::new(B, 2), |d| d.copy_from_slice(pts.as_flattened()));
        let y = t.input_with(Shape::new(B, 1), |d| {
            d.iter_mut().zip(&pts).for_each(|(d, p)| *d = target(p[0], p[1]))
        });
        let e = t.posenc(x, 2);
        let p = self.mlp.forward(t, e);
        let r = t.sub(p, y);
        let sq = t.square(r);
        let loss = t.mean_all(sq);
        let value = t.scalar(loss);
        t.backward(loss);
        self.adam.step(t.params_mut(), lr_factor);
        value
    }

    /// Mean squared error on a fixed 32×32 grid.
    fn test_error(&mut self) -> f32 {
        let n = 32;
        let pts: Vec<[f32; 2]> = (0..n * n)
            .map(|i| {
                [-1.0 + 2.0 * (i % n) as f32 / (n - 1) as f32, -1.0 + 2.0 * (i / n) as f32 / (n - 1) as f32]
            })
            .collect();
        let t = &mut self.tape;
        t.reset();
        let x = t.input(&Tensor::from_rows(&pts));
        let e = t.posenc(x, 2);
        let p = self.mlp.forward(t, e);
        t.value(p).iter().zip(&pts).map(|(p, q)| (p - target(q[0], q[1])).powi(2)).sum::<f32>()
            / pts.len() as f32
    }
}

#[test]
fn a_small_mlp_fits_a_known_function() {
    let mut fit = Fit::new(1);
    let before = fit.test_error();
    let sched = CosineSchedule { total_steps: 1500, warmup_steps: 0, final_factor: 0.05 };
    for s in 0..1500 {
        fit.step(sched.factor(s));
    }
    let after = fit.test_error();
    eprintln!("test MSE before {before}, after {after}");
    // The target has variance 0.25; a fit explains almost all of it.
    assert!(after < 2e-3, "test MSE {after} (was {before} before training)");
    assert!(after < before / 50.0);
}

#[test]
fn steady_state_steps_allocate_nothing_and_memory_stays_flat() {
    let mut fit = Fit::new(2);
    fit.step(1.0);
    fit.step(1.0);
    let allocs = fit.tape.pool().allocations();
    let nodes = fit.tape.len();
    for _ in 0..200 {
        fit.step(1.0);
    }
    fit.tape.reset();
    let pooled = fit.tape.pool().pooled_floats();
    for _ in 0..200 {
        fit.step(1.0);
    }
    fit.tape.reset();
    assert_eq!(fit.tape.pool().allocations(), allocs, "pool allocated after warm-up");
    assert_eq!(fit.tape.pool().pooled_floats(), pooled, "pooled memory grew");
    assert!(nodes > 10);
}

#[test]
fn same_seed_same_parameters_on_one_or_two_threads() {
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| {
            let mut fit = Fit::new(3);
            for _ in 0..30 {
                fit.step(1.0);
            }
            let p = fit.tape.params();
            p.ids().flat_map(|id| p.value(id).data().to_vec()).collect::<Vec<f32>>()
        })
    };
    let a = run(2);
    assert_eq!(a, run(2), "two runs on the same thread count differ");
    assert_eq!(a, run(1), "one and two threads differ");
}

#[test]
#[should_panic(expected = "stale Var")]
fn using_a_var_after_reset_panics() {
    let mut t = Tape::default();
    let x = t.input(&Tensor::scalar(1.0));
    t.reset();
    let _ = t.value(x);
}
