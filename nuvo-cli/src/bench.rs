//! `nuvo bench`: speed of the engine, reported in ms/step and GFLOP/s.
//!
//! FLOP accounting: a `B×i · i×o` product is `2·B·i·o` FLOPs. An MLP step (forward + backward) is
//! counted as 3× the forward FLOPs minus the first layer's input gradient, which is never computed
//! because the input needs no gradient (PyTorch skips it too).

use std::collections::BTreeMap;
use std::time::Instant;

use nuvo_autodiff::nn::{Mlp, MlpConfig};
use nuvo_autodiff::optim::{Adam, AdamConfig};
use nuvo_autodiff::{Activation, MatmulPrecision, ParamStore, Shape, Tape, Tensor};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

#[derive(clap::Args)]
pub struct BenchArgs {
    /// What to measure: the engine's GEMMs and MLP steps (`all`, `gemm`, `mlp`), or a full Nuvo
    /// training step on the bundled bunny (`step`, sized by `--charts/--depth/--width/--batch`).
    #[arg(value_enum, default_value = "all")]
    what: What,
    /// Rows per batch (`step`: 3-D samples and UV samples each).
    #[arg(long, default_value_t = 4096)]
    batch: usize,
    /// Timed iterations per case (after 3 warm-up iterations; `step`: 1 warm-up).
    #[arg(long, default_value_t = 20)]
    iters: usize,
    /// `step`: number of charts.
    #[arg(long, default_value_t = 4)]
    charts: usize,
    /// `step`: fully-connected layers per network.
    #[arg(long, default_value_t = 8)]
    depth: usize,
    /// `step`: channels per hidden layer.
    #[arg(long, default_value_t = 256)]
    width: usize,
    /// `step`: the mesh to sample.
    #[arg(long, default_value = "assets/stanford-bunny.obj")]
    mesh: std::path::PathBuf,
    /// `step`, `mlp`: the networks' arithmetic (`training.matmul`): `f32`, or `bf16` on AMX tiles or AVX-512 BF16.
    #[arg(long, value_parser = ["f32", "bf16"], default_value = "f32")]
    matmul: String,
    /// `step`: time the steps of a trained run instead (its folder or checkpoint; its stored config,
    /// its networks as trained), so settings that depend on the trained state (such as
    /// `training.chart_support`) are timed as they run late in training. Ignores the sizing flags.
    #[arg(long, value_name = "RUN")]
    from: Option<std::path::PathBuf>,
    /// `step --from`: override a value of the run's config, e.g. `--set training.chart_support=0`.
    #[arg(long = "set", value_name = "KEY=VALUE", requires = "from")]
    set: Vec<String>,
}

#[derive(Clone, Copy, clap::ValueEnum, PartialEq)]
enum What {
    All,
    Mlp,
    Gemm,
    Step,
}

/// Runs the cases on a rayon worker thread, as the trainer runs its steps (see `Trainer::step`), so
/// the engine's kernels are timed as training uses them.
pub fn run(args: &BenchArgs) -> anyhow::Result<()> {
    rayon::scope(|_| run_on_worker(args))
}

fn run_on_worker(args: &BenchArgs) -> anyhow::Result<()> {
    println!("threads: {}", rayon::current_num_threads());
    if args.what == What::Step {
        return step_case(args);
    }
    if matches!(args.what, What::All | What::Gemm) {
        gemm_cases(args);
    }
    if matches!(args.what, What::All | What::Mlp) {
        for (depth, width) in [(8, 256), (4, 128)] {
            mlp_case(args, depth, width)?;
        }
    }
    Ok(())
}

/// One full Nuvo training step (all eight losses, uniform samples of the mesh), timed, and the
/// process's peak resident memory.
fn step_case(args: &BenchArgs) -> anyhow::Result<()> {
    if let Some(run) = &args.from {
        return trained_step_case(args, run);
    }
    let text = format!(
        "[geometry]\nsource = \"mesh\"\npath = {:?}\n[model]\ncharts = {}\ndepth = {}\nwidth = {}\n\
         [training]\nsteps = 1000\nbatch_3d = {}\nbatch_uv = {}\nmatmul = {:?}\n",
        args.mesh.display().to_string(),
        args.charts,
        args.depth,
        args.width,
        args.batch,
        args.batch,
        args.matmul
    );
    let loaded = nuvo_core::config::from_str("bench.toml", &text)?;
    let mut trainer = nuvo_core::Trainer::new(
        &loaded,
        &nuvo_geometry::SourceRegistry::with_builtins(),
        &nuvo_losses::LossRegistry::with_builtins(),
    )?;
    crate::train::report_matmul(&trainer);
    let (c, t, s) = trainer.model().macs_per_point();
    let (n, b) = (args.charts as f64, args.batch as f64);
    // Forward MACs: c(x), t_i at x and two offsets, s_i(t_i(x)); s_i(u), t_i(s_i(u)), c(s_i(u)).
    let fwd = 2.0 * (b * (c as f64 + 3.0 * n * t as f64 + n * s as f64) + b * n * (s + t + c) as f64);
    let (median, min) = time_steps(&mut trainer, args.iters)?;
    println!(
        "nuvo step n={} {}×{} batch {}+{}: median {:.3} s  min {:.3} s  ~{:.0} GFLOP/step (3× forward)  {:.1} GFLOP/s  peak RSS {}",
        args.charts,
        args.depth,
        args.width,
        args.batch,
        args.batch,
        median,
        min,
        3.0 * fwd / 1e9,
        3.0 * fwd / median / 1e9,
        crate::peak_rss_kib()
            .map(|kb| format!("{:.0} MB", kb as f64 / 1024.0))
            .unwrap_or_else(|| "unknown".into())
    );
    Ok(())
}

/// Steps of a trained run, continued from its checkpoint (see `BenchArgs::from`).
fn trained_step_case(args: &BenchArgs, run: &std::path::Path) -> anyhow::Result<()> {
    let (mut trainer, _, ckpt) = crate::train::restore_run(run, &args.set)?;
    crate::train::report_matmul(&trainer);
    let t = &trainer.config().training;
    let sizes = format!("batch {}+{}, chart_support {}", t.batch_3d, t.batch_uv, t.chart_support);
    let (median, min) = time_steps(&mut trainer, args.iters)?;
    println!("nuvo step from {} ({sizes}): median {median:.3} s  min {min:.3} s", ckpt.display());
    Ok(())
}

/// Median and minimum seconds per training step over `iters` steps, after one warm-up step.
fn time_steps(trainer: &mut nuvo_core::Trainer, iters: usize) -> anyhow::Result<(f64, f64)> {
    trainer.step()?;
    let mut times: Vec<f64> = (0..iters.max(1))
        .map(|_| {
            let start = Instant::now();
            trainer.step().map(|_| start.elapsed().as_secs_f64())
        })
        .collect::<Result<_, _>>()?;
    times.sort_by(f64::total_cmp);
    Ok((times[times.len() / 2], times[0]))
}

/// Median and minimum of `iters` timed runs of `f` after 3 warm-ups, in seconds.
fn time(iters: usize, mut f: impl FnMut()) -> (f64, f64) {
    for _ in 0..3 {
        f();
    }
    let mut t: Vec<f64> = (0..iters.max(1))
        .map(|_| {
            let s = Instant::now();
            f();
            s.elapsed().as_secs_f64()
        })
        .collect();
    t.sort_by(f64::total_cmp);
    (t[t.len() / 2], t[0])
}

fn report(name: &str, flops: f64, (median, min): (f64, f64)) {
    println!(
        "{name:<44} median {:>8.2} ms  min {:>8.2} ms  {:>6.1} GFLOP/s (median)  {:>6.1} GFLOP/s (best)",
        median * 1e3,
        min * 1e3,
        flops / median / 1e9,
        flops / min / 1e9
    );
}

fn gemm_cases(args: &BenchArgs) {
    let (b, n) = (args.batch, 256);
    let fill = |r, c| {
        Tensor::from_vec(r, c, (0..r * c).map(|i| ((i * 7919 % 1000) as f32 - 500.0) / 1000.0).collect())
    };
    let (x, w, dy) = (fill(b, n), fill(n, n), fill(b, n));
    let flops = 2.0 * (b * n * n) as f64;
    let mut tape = Tape::default();
    let mut bench = |name: &str, ta: bool, tb: bool, lhs: &Tensor, rhs: &Tensor| {
        let t = time(args.iters, || {
            tape.reset();
            let a = tape.input(lhs);
            let c = tape.input(rhs);
            tape.matmul_t(a, c, ta, tb);
        });
        report(name, flops, t);
    };
    bench(&format!("gemm Y = X·W        ({b}×{n} · {n}×{n})"), false, false, &x, &w);
    bench(&format!("gemm dW = Xᵀ·dY     ({n}×{b} · {b}×{n})"), true, false, &x, &dy);
    bench(&format!("gemm dX = dY·Wᵀ     ({b}×{n} · {n}×{n})"), false, true, &dy, &w);
}

fn mlp_case(args: &BenchArgs, depth: usize, width: usize) -> anyhow::Result<()> {
    let b = args.batch;
    let (in_dim, out_dim) = (27, 3);
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let mut params = ParamStore::new();
    let cfg = MlpConfig { depth, width, activation: Activation::Relu, init: Default::default() };
    let mlp = Mlp::new(&mut params, "m", "mlp", &cfg, (in_dim, out_dim, Activation::Identity), &mut rng);
    let mut adam = Adam::new(&params, AdamConfig::default(), &BTreeMap::from([("mlp".to_owned(), 1e-4)]))?;
    let x = Tensor::from_vec(
        b,
        in_dim,
        (0..b * in_dim).map(|i| ((i * 31 % 200) as f32 - 100.0) / 100.0).collect(),
    );
    let mut tape = Tape::new(params);
    tape.set_matmul_precision(if args.matmul == "bf16" {
        MatmulPrecision::Bf16
    } else {
        MatmulPrecision::F32
    });
    let fwd_flops = 2.0 * (b * mlp.macs_per_row()) as f64;
    let step_flops = 3.0 * fwd_flops - 2.0 * (b * in_dim * width) as f64;
    let mut step = |with_adam: bool| {
        tape.reset();
        tape.params_mut().zero_grads();
        let xv = tape.input_with(Shape::new(b, in_dim), |d| d.copy_from_slice(x.data()));
        let y = mlp.forward(&mut tape, xv);
        let sq = tape.square(y);
        let loss = tape.mean_all(sq);
        tape.backward(loss);
        if with_adam {
            adam.step(tape.params_mut(), 1.0);
        }
    };
    let name = format!("mlp {depth}×{width} fwd+bwd, batch {b}");
    report(&name, step_flops, time(args.iters, || step(false)));
    let name = format!("mlp {depth}×{width} fwd+bwd+adam, batch {b}");
    report(&name, step_flops, time(args.iters, || step(true)));
    Ok(())
}
