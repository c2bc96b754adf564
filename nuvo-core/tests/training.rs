//! End-to-end behaviour of the trainer and training runs on an analytic scene (a unit sphere).

use std::sync::atomic::{AtomicU64, Ordering};

use nuvo_autodiff::{MatmulPrecision, Shape, Var};
use nuvo_core::config::{self, LoadedConfig};
use nuvo_core::run::{RunOptions, Silent, files, run};
use nuvo_core::trainer::ONE_CHART_SHAPE_SETTLED;
use nuvo_core::warm_start::ProjectionPrior;
use nuvo_core::{Checkpoint, TrainError, Trainer};
use nuvo_geometry::SourceRegistry;
use nuvo_geometry::testdata::sphere_sources as sources;
use nuvo_losses::{Loss, LossError, LossInfo, LossRegistry, RegisteredLoss, StepContext};

const SMALL: &str = r#"
seed = 7
[geometry]
source = "sphere"
[model]
charts = 2
depth = 3
width = 32
grid_resolution = 16
[training]
steps = 60
batch_3d = 256
batch_uv = 256
checkpoint_every = 20
[optimizer]
lr_mlp = 1e-3
"#;

fn small(extra: &str) -> LoadedConfig {
    config::from_str("small.toml", &format!("{SMALL}{extra}")).unwrap()
}

fn trainer(cfg: &LoadedConfig) -> Trainer {
    Trainer::new(cfg, &sources(), &LossRegistry::with_builtins()).unwrap()
}

fn param_values(t: &Trainer) -> Vec<f32> {
    let p = t.params();
    p.ids().flat_map(|id| p.value(id).data().to_vec()).collect()
}

#[test]
fn training_lowers_the_loss_and_writes_the_run_folder() {
    let cfg = small("");
    let mut t = trainer(&cfg);
    assert_eq!(t.terms().len(), 8, "the paper's eight losses by default");
    let first = t.step().unwrap();
    assert!(first.skipped.is_none() && first.total.is_finite());
    let dir = tempfile::tempdir().unwrap();
    let opts = RunOptions { out_dir: dir.path().join("run"), resume: false };
    let summary = run(&mut t, &opts, &mut Silent).unwrap();
    assert_eq!(summary.steps, 60);
    assert_eq!(summary.skipped, 0);
    let last = summary.last.unwrap();
    assert!(last.total < first.total, "loss went from {} to {}", first.total, last.total);
    for f in [files::CONFIG, files::LOG, files::CHECKPOINT] {
        assert!(opts.out_dir.join(f).is_file(), "{f} missing");
    }
    let log = std::fs::read_to_string(opts.out_dir.join(files::LOG)).unwrap();
    // The first step ran before `run`, so the log covers steps 1..60.
    assert_eq!(log.lines().count(), 59);
    let line: serde_json::Value = serde_json::from_str(log.lines().last().unwrap()).unwrap();
    assert_eq!(line["step"], 59);
    assert!(line["terms"]["cycle_3d"].is_number() && line["terms"]["texture"].is_number());
    // The resolved config reads back as the same experiment.
    let saved = std::fs::read_to_string(opts.out_dir.join(files::CONFIG)).unwrap();
    assert_eq!(config::from_str("saved.toml", &saved).unwrap().config, cfg.config);
}

#[test]
fn same_seed_same_parameters_different_seed_different() {
    let run_steps = |extra: &str| {
        let mut t = trainer(&small(extra));
        for _ in 0..15 {
            t.step().unwrap();
        }
        param_values(&t)
    };
    let a = run_steps("");
    assert_eq!(a, run_steps(""));
    assert_eq!(
        a,
        run_steps("[output]\ndir = \"elsewhere\"\n"),
        "the output folder must not change the result"
    );
    let mut other = small("");
    other.config.seed = 8;
    let mut t = Trainer::new(&other, &sources(), &LossRegistry::with_builtins()).unwrap();
    for _ in 0..15 {
        t.step().unwrap();
    }
    assert_ne!(a, param_values(&t));
}

/// The checkpoint file holds the run's last step, whether the run ends on a checkpoint step (saved
/// there once) or between two (saved at the end).
#[test]
fn the_checkpoint_holds_the_last_step_on_or_between_checkpoint_steps() {
    let dir = tempfile::tempdir().unwrap();
    for (steps, name) in [(60, "on"), (50, "between")] {
        let mut cfg = small("");
        cfg.config.training.steps = steps;
        let mut t = trainer(&cfg);
        let out = dir.path().join(name);
        run(&mut t, &RunOptions { out_dir: out.clone(), resume: false }, &mut Silent).unwrap();
        let saved = Checkpoint::load(&out.join(files::CHECKPOINT)).unwrap();
        assert_eq!(saved.step, steps, "{name}");
        // The trainer's own state, through the same save and load (which sorts the parameters).
        let fresh = dir.path().join(format!("{name}.safetensors"));
        t.checkpoint().unwrap().save(&fresh).unwrap();
        assert!(saved == Checkpoint::load(&fresh).unwrap(), "{name}: the file is not the last state");
    }
}

#[test]
fn a_resumed_run_matches_an_uninterrupted_one() {
    let cfg = small("");
    let dir = tempfile::tempdir().unwrap();
    // Uninterrupted.
    let mut full = trainer(&cfg);
    run(&mut full, &RunOptions { out_dir: dir.path().join("full"), resume: false }, &mut Silent).unwrap();
    // "Killed" after 33 steps: the last checkpoint on disk is from step 20, and the log runs on.
    let out = dir.path().join("killed");
    let mut partial = trainer(&cfg);
    std::fs::create_dir_all(&out).unwrap();
    for s in 0..33 {
        partial.step().unwrap();
        if s + 1 == 20 {
            partial.checkpoint().unwrap().save(&out.join(files::CHECKPOINT)).unwrap();
        }
    }
    std::fs::write(out.join(files::LOG), (0..33).map(|s| format!("{{\"step\":{s}}}\n")).collect::<String>())
        .unwrap();
    drop(partial);
    let mut resumed = trainer(&cfg);
    let summary = run(&mut resumed, &RunOptions { out_dir: out.clone(), resume: true }, &mut Silent).unwrap();
    assert_eq!(summary.steps, 60);
    assert_eq!(param_values(&resumed), param_values(&full), "resumed parameters differ");
    let a = Checkpoint::load(&dir.path().join("full").join(files::CHECKPOINT)).unwrap();
    let b = Checkpoint::load(&out.join(files::CHECKPOINT)).unwrap();
    assert_eq!(a, b);
    // The log has each step exactly once.
    let steps: Vec<u64> = std::fs::read_to_string(out.join(files::LOG))
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap()["step"].as_u64().unwrap())
        .collect();
    assert_eq!(steps, (0..60).collect::<Vec<_>>());
}

#[test]
fn an_existing_run_is_not_overwritten_and_a_missing_one_cannot_resume() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("r");
    let mut t = trainer(&small(""));
    t.step().unwrap();
    std::fs::create_dir_all(&out).unwrap();
    t.checkpoint().unwrap().save(&out.join(files::CHECKPOINT)).unwrap();
    let e = run(&mut trainer(&small("")), &RunOptions { out_dir: out.clone(), resume: false }, &mut Silent)
        .unwrap_err();
    assert!(e.to_string().contains("--resume"), "{e}");
    let e = run(
        &mut trainer(&small("")),
        &RunOptions { out_dir: dir.path().join("none"), resume: true },
        &mut Silent,
    )
    .unwrap_err();
    assert!(e.to_string().contains("nothing to resume"), "{e}");
    // A checkpoint from another experiment is refused.
    let mut other = small("");
    other.config.model.width = 16;
    let e = run(
        &mut Trainer::new(&other, &sources(), &LossRegistry::with_builtins()).unwrap(),
        &RunOptions { out_dir: out, resume: true },
        &mut Silent,
    )
    .unwrap_err();
    assert!(e.to_string().contains("different config"), "{e}");
}

/// A loss that is NaN on calls `from..to` (counted across steps) and 0 otherwise.
struct NanOnCalls {
    calls: AtomicU64,
    from: u64,
    to: u64,
}

impl Loss for NanOnCalls {
    fn evaluate(&self, ctx: &mut StepContext<'_>) -> Result<Var, LossError> {
        let k = self.calls.fetch_add(1, Ordering::SeqCst);
        let x = ctx.x();
        let t = &mut *ctx.tape;
        let zero = t.scale(x, 0.0);
        let s = t.sum_all(zero);
        let v = if (self.from..self.to).contains(&k) { f32::NAN } else { 0.0 };
        let c = t.constant(Shape::SCALAR, v);
        Ok(t.add(s, c))
    }
}

/// `[losses.nan_probe] from = F, to = T` (`T` absent: never finite again).
impl RegisteredLoss for NanOnCalls {
    const INFO: LossInfo = LossInfo { name: "nan_probe", summary: "test", default_weight: 1.0, options: &[] };
    fn from_options(options: &toml::Table) -> Result<Self, LossError> {
        let at = |key: &str| options.get(key).and_then(toml::Value::as_integer).map(|v| v as u64);
        Ok(NanOnCalls {
            calls: AtomicU64::new(0),
            from: at("from").unwrap_or(0),
            to: at("to").unwrap_or(u64::MAX),
        })
    }
}

fn registry_with_nan() -> LossRegistry {
    let mut r = LossRegistry::with_builtins();
    r.add::<NanOnCalls>();
    r
}

/// A config with the probe NaN on calls `from..to`.
fn with_probe(from: u64, to: Option<u64>) -> LoadedConfig {
    let to = to.map(|t| format!("to = {t}\n")).unwrap_or_default();
    small(&format!("[losses.cycle_3d]\n[losses.surface]\n[losses.nan_probe]\nfrom = {from}\n{to}"))
}

#[test]
fn a_nan_term_skips_the_step_names_the_term_and_leaves_parameters_untouched() {
    let cfg = with_probe(3, Some(5));
    let mut t = Trainer::new(&cfg, &sources(), &registry_with_nan()).unwrap();
    for _ in 0..3 {
        assert!(t.step().unwrap().skipped.is_none());
    }
    let before = param_values(&t);
    let o = t.step().unwrap();
    assert_eq!(o.skipped.as_deref(), Some("loss `nan_probe` is NaN"));
    assert_eq!(param_values(&t), before, "a skipped step changed parameters");
    assert!(t.step().unwrap().skipped.is_some());
    assert!(t.step().unwrap().skipped.is_none(), "training resumes once the term is finite");
    assert_ne!(param_values(&t), before);
}

#[test]
fn persistent_nans_roll_back_then_give_up_with_a_clear_error() {
    let mut cfg = with_probe(8, None);
    cfg.config.training.max_bad_steps = 2;
    cfg.config.training.checkpoint_every = 5;
    let mut t = Trainer::new(&cfg, &sources(), &registry_with_nan()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let e =
        run(&mut t, &RunOptions { out_dir: dir.path().to_owned(), resume: false }, &mut Silent).unwrap_err();
    assert!(matches!(e, TrainError::Diverged(_)), "{e}");
    let msg = e.to_string();
    assert!(msg.contains("nan_probe") && msg.contains("rollbacks"), "{msg}");
    // The checkpoint left behind is the last good state (step 5).
    assert_eq!(Checkpoint::load(&dir.path().join(files::CHECKPOINT)).unwrap().step, 5);
}

#[test]
fn a_transient_nan_burst_is_survived_by_rolling_back() {
    let mut cfg = with_probe(12, Some(15));
    cfg.config.training.max_bad_steps = 2;
    cfg.config.training.checkpoint_every = 5;
    // Calls 12..15 are NaN: three bad steps in a row trigger one rollback to step 10, after which the
    // replayed steps are finite again.
    let mut t = Trainer::new(&cfg, &sources(), &registry_with_nan()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let s = run(&mut t, &RunOptions { out_dir: dir.path().to_owned(), resume: false }, &mut Silent).unwrap();
    assert_eq!(s.rollbacks, 1);
    assert_eq!(s.steps, 60);
    assert!((t.lr_scale() - 0.5).abs() < 1e-7);
    // The checkpoint holds the halved learning rates the run ended with.
    let saved = Checkpoint::load(&dir.path().join(files::CHECKPOINT)).unwrap();
    assert_eq!((saved.step, saved.lr_scale), (60, 0.5));
}

#[test]
fn config_mistakes_in_plugin_tables_name_the_key_and_line() {
    let bad_loss = small("[losses.cycle_3d]\n[losses.strech]\nweight = 0.1\n");
    let e = Trainer::new(&bad_loss, &sources(), &LossRegistry::with_builtins()).err().unwrap().to_string();
    assert!(e.contains("losses.strech") && e.contains("stretch") && e.contains("line"), "{e}");
    let bad_option = small("[losses.stretch]\nweight = 0.1\naera = \"paper\"\n");
    let e = Trainer::new(&bad_option, &sources(), &LossRegistry::with_builtins()).err().unwrap().to_string();
    assert!(e.contains("losses.stretch.aera") && e.contains("line 19") && e.contains("`area`"), "{e}");
    let bad_source = config::from_str("c.toml", &SMALL.replace("\"sphere\"", "\"sphear\"")).unwrap();
    let e = Trainer::new(&bad_source, &sources(), &LossRegistry::with_builtins()).err().unwrap().to_string();
    assert!(e.contains("geometry.source") && e.contains("sphere") && e.contains("line 4"), "{e}");
    let bad_geometry_key =
        config::from_str("c.toml", &SMALL.replace("source = \"sphere\"", "source = \"sphere\"\nradius = 2"))
            .unwrap();
    let e = Trainer::new(&bad_geometry_key, &sources(), &LossRegistry::with_builtins())
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("geometry.radius") && e.contains("line 5"), "{e}");
}

#[test]
fn zero_weight_and_removed_losses_are_ablations() {
    let t =
        trainer(&small("[losses.cycle_3d]\n[losses.cycle_2d]\nweight = 0\n[losses.surface]\nweight = 2.5\n"));
    let names: Vec<(&str, f32)> = t.terms().iter().map(|t| (t.name.as_str(), t.weight)).collect();
    assert_eq!(names, vec![("cycle_3d", 1.0), ("surface", 2.5)]);
}

#[test]
fn atlas_evaluation_gives_probabilities_and_unit_square_uvs() {
    let t = trainer(&small(""));
    let pts = [[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, -1.0, 0.0]];
    let fields = t.atlas().evaluate_atlas(&pts);
    let (p, uv) = (&fields.probs, &fields.uvs);
    assert_eq!(p.len(), 3 * 2);
    assert_eq!(uv.len(), 3 * 2 * 2);
    assert_eq!(fields.round_trip.len(), 3 * 2);
    assert!(fields.round_trip.iter().all(|d| d.is_finite() && *d >= 0.0));
    for row in p.chunks(2) {
        assert!((row.iter().sum::<f32>() - 1.0).abs() < 1e-5);
    }
    assert!(uv.iter().all(|&u| (0.0..=1.0).contains(&u)));
    // Without the round trip (the bake when its check is off), the same charts and UVs, bit for bit.
    assert_eq!(t.atlas().evaluate_charts(&pts), (fields.probs.clone(), fields.uvs.clone()));
}

#[test]
fn a_warmed_up_term_ramps_its_weight_and_the_total_follows() {
    let plain = "[losses.cycle_3d]\n[losses.surface]\n";
    let warm = "[losses.cycle_3d]\n[losses.surface]\nwarmup_steps = 4\n";
    let mut a = trainer(&small(plain));
    let mut b = trainer(&small(warm));
    let surface = &b.terms()[1];
    assert_eq!(surface.name, "surface");
    let ramp: Vec<f32> = (0..6).map(|s| surface.weight_at(s)).collect();
    assert_eq!(ramp, [2.5, 5.0, 7.5, 10.0, 10.0, 10.0]);
    // Step 0: the same batch and parameters, so the totals differ by exactly 3/4 of the surface term.
    let (oa, ob) = (a.step().unwrap(), b.step().unwrap());
    let surface_value = oa.terms.iter().find(|(n, _)| n == "surface").unwrap().1;
    assert_eq!(oa.terms, ob.terms, "unweighted values are logged unchanged");
    assert!((oa.total - ob.total - 0.75 * 10.0 * surface_value).abs() < 1e-4 * oa.total.abs().max(1.0));
}

/// Mean of `cycle_3d + cycle_2d` over the last 20 of 400 steps on a flat square with the
/// bijectivity losses only, for `model.init = init`.
fn flat_square_cycle_residual(init: &str) -> f32 {
    let dir = tempfile::tempdir().unwrap();
    let mesh = dir.path().join("plane.obj");
    let n = 20;
    let mut obj = String::new();
    for i in 0..=n {
        for j in 0..=n {
            obj +=
                &format!("v {} {} 0\n", -1.0 + 2.0 * i as f32 / n as f32, -1.0 + 2.0 * j as f32 / n as f32);
        }
    }
    for i in 0..n {
        for j in 0..n {
            let a = i * (n + 1) + j + 1;
            obj += &format!("f {a} {} {}\nf {a} {} {}\n", a + n + 1, a + n + 2, a + n + 2, a + 1);
        }
    }
    std::fs::write(&mesh, obj).unwrap();
    let text = format!(
        "seed = 0\n[geometry]\nsource = \"mesh\"\npath = {mesh:?}\n[model]\ncharts = 1\ndepth = 4\nwidth = 64\n\
         init = \"{init}\"\n[training]\nsteps = 400\nbatch_3d = 512\nbatch_uv = 512\n[optimizer]\nlr_mlp = 3e-3\n\
         [losses.cycle_3d]\n[losses.cycle_2d]\n[losses.surface]\n"
    );
    let loaded = config::from_str("plane.toml", &text).unwrap();
    let mut t =
        Trainer::new(&loaded, &SourceRegistry::with_builtins(), &LossRegistry::with_builtins()).unwrap();
    let mut last = Vec::new();
    for step in 0..400 {
        let o = t.step().unwrap();
        if step >= 380 {
            last.push(o.terms.iter().filter(|(n, _)| n.starts_with("cycle")).map(|(_, v)| v).sum::<f32>());
        }
    }
    last.iter().sum::<f32>() / last.len() as f32
}

/// A flat square is the easiest chart (an affine `t` and its inverse make both cycle losses zero).
/// With He-initialised networks the trainer stalls at a folded map; the default init learns it
/// (BENCHMARKS.md "Initialisation").
#[test]
fn the_bijectivity_losses_learn_a_flat_square_from_the_default_init() {
    let torch = flat_square_cycle_residual("torch");
    let he = flat_square_cycle_residual("he");
    assert!(torch < 8e-3, "cycle residual with the default init: {torch}");
    assert!(he > 3.0 * torch, "he {he} vs torch {torch}: the option does not change the init");
}

/// Share of sphere points whose most likely chart is the one the projection prior assigns, and the
/// mean squared distance of that chart's UV to the prior's target, after `steps` steps.
fn agreement_with_the_projection_prior(warm_start: &str, steps: usize) -> (f32, f32) {
    let six_charts = |extra: &str| {
        let mut cfg = small(extra);
        cfg.config.model.charts = 6;
        cfg.config.optimizer.lr_mlp = 3e-3;
        trainer(&cfg)
    };
    // The same seed fits the same prior, so this one shows what the trained runs were pulled to.
    let reference = six_charts("[warm_start]\nsteps = 1\n");
    let prior = ProjectionPrior::for_run(reference.config(), reference.source())
        .unwrap()
        .expect("warm start enabled");
    let mut t = six_charts(&format!("[losses.cycle_3d]\n{warm_start}"));
    for _ in 0..steps {
        t.step().unwrap();
    }
    let pts: Vec<[f32; 3]> = (0..400)
        .map(|k| {
            // A Fibonacci sphere: well-spread unit points (their own normals).
            let z = 1.0 - 2.0 * (k as f32 + 0.5) / 400.0;
            let r = (1.0 - z * z).sqrt();
            let a = k as f32 * 2.399_963;
            [r * a.cos(), r * a.sin(), z]
        })
        .collect();
    let fields = t.atlas().evaluate_atlas(&pts);
    let (probs, uvs) = (&fields.probs, &fields.uvs);
    let (mut agree, mut err) = (0usize, 0.0f32);
    for (k, p) in pts.iter().enumerate() {
        let row = &probs[k * 6..k * 6 + 6];
        let best = (0..6).max_by(|&a, &b| row[a].total_cmp(&row[b])).unwrap();
        let label = prior.label(&p.map(|c| c * 0.5), p);
        agree += usize::from(best == label);
        let target = prior.target_uv(label, &p.map(|c| c * 0.5));
        let uv = &uvs[(k * 6 + label) * 2..(k * 6 + label) * 2 + 2];
        err += (uv[0] - target[0]).powi(2) + (uv[1] - target[1]).powi(2);
    }
    (agree as f32 / pts.len() as f32, err / pts.len() as f32)
}

#[test]
fn the_warm_start_starts_charts_as_the_projections_of_the_faces_they_look_at() {
    let (agree, err) = agreement_with_the_projection_prior("[warm_start]\nsteps = 1000\n", 150);
    let (agree_cold, err_cold) = agreement_with_the_projection_prior("", 150);
    assert!(agree > 0.8 && err < 5e-3, "with the prior: agreement {agree}, UV error {err}");
    assert!(agree_cold < 0.6 && err_cold > 5.0 * err, "without: agreement {agree_cold}, UV error {err_cold}");
}

#[test]
fn the_warm_start_term_is_logged_while_it_fades_and_then_leaves_the_objective() {
    let mut t = trainer(&small("[warm_start]\nsteps = 3\n"));
    let names = |o: &nuvo_core::StepOutcome| o.terms.iter().any(|(n, _)| n == "warm_start");
    let seen: Vec<bool> = (0..5).map(|_| names(&t.step().unwrap())).collect();
    assert_eq!(seen, [true, true, true, false, false]);
}

#[test]
fn the_chart_support_waits_for_the_warm_start_then_prunes_deterministically() {
    let params_after = |tau: f32, steps: usize| {
        let mut cfg = small("[warm_start]\nsteps = 20\n");
        cfg.config.training.chart_support = tau;
        let mut t = trainer(&cfg);
        for _ in 0..steps {
            t.step().unwrap();
        }
        param_values(&t)
    };
    // While the prior weighs in, the threshold is not applied: bit-identical steps.
    assert!(params_after(0.45, 20) == params_after(0.0, 20), "pruned during the warm start");
    // Afterwards it is, and the same config still gives the same parameters.
    let a = params_after(0.45, 30);
    assert!(a != params_after(0.0, 30), "nothing was pruned");
    assert!(a == params_after(0.45, 30), "not deterministic");
}

#[test]
fn the_warm_start_draws_its_share_of_the_batch_and_timing_draws_it_whole() {
    let mut cfg = small("[warm_start]\nsteps = 2\nbatch_share = 0.3\n");
    cfg.config.training.batch_3d = 100;
    cfg.config.training.batch_uv = 64;
    let sizes = |t: &Trainer| (t.batch().points.len(), t.batch().uv.len(), t.batch().tangents_p.len());
    let mut t = trainer(&cfg);
    let mut seen = Vec::new();
    for _ in 0..3 {
        t.step().unwrap();
        seen.push(sizes(&t));
    }
    // 0.3 · 100 = 30 points (all with tangent frames), 0.3 · 64 ≈ 19 UV samples, then full.
    assert_eq!(seen, [(30, 19, 30), (30, 19, 30), (100, 64, 100)]);
    let mut timed = trainer(&cfg);
    timed.time_full_batches(true);
    timed.step().unwrap();
    assert_eq!(sizes(&timed), (100, 64, 100));
    // Back off, the next warm-start step draws its share again.
    timed.time_full_batches(false);
    timed.step().unwrap();
    assert_eq!(sizes(&timed), (30, 19, 30));
}

#[test]
fn pruned_steps_do_not_depend_on_the_thread_count() {
    // Wide (128) and large enough that the weight-gradient products of the pruned, odd-sized
    // batches take the engine's row-split GEMM path at inner sizes where its blocking matters.
    let params_with = |threads: usize| {
        let mut cfg = small("[warm_start]\nsteps = 5\n");
        cfg.config.model.width = 128;
        cfg.config.training.batch_3d = 1500;
        cfg.config.training.chart_support = 0.45;
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        let mut t = trainer(&cfg);
        pool.install(|| (0..12).for_each(|_| drop(t.step().unwrap())));
        param_values(&t)
    };
    assert!(params_with(1) == params_with(2), "1 and 2 threads differ");
    assert!(params_with(1) == params_with(3), "1 and 3 threads differ");
}

#[test]
fn trainers_stepping_at_once_on_one_pool_finish_with_their_own_bits() {
    // A step keeps the pool's other threads awake on its jobs while it runs alone (`keep_busy`);
    // two trainers stepping on one pool at once (as tests do on rayon's global pool) must neither
    // wait for each other forever nor change each other's results.
    let cfg = |seed: u64| {
        let mut cfg = small("[warm_start]\nsteps = 3\n");
        cfg.config.seed = seed;
        cfg.config.model.width = 64;
        cfg.config.training.batch_3d = 700;
        cfg
    };
    let steps = 10;
    let alone: Vec<Vec<f32>> = [1, 2]
        .map(|seed| {
            let mut t = trainer(&cfg(seed));
            (0..steps).for_each(|_| drop(t.step().unwrap()));
            param_values(&t)
        })
        .into();
    let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
    let together: Vec<Vec<f32>> = std::thread::scope(|threads| {
        let runs: Vec<_> = [1, 2]
            .map(|seed| {
                let (pool, cfg) = (&pool, cfg(seed));
                threads.spawn(move || {
                    let mut t = trainer(&cfg);
                    pool.install(|| (0..steps).for_each(|_| drop(t.step().unwrap())));
                    param_values(&t)
                })
            })
            .into();
        runs.into_iter().map(|r| r.join().unwrap()).collect()
    });
    assert!(alone[0] != alone[1], "the seeds train differently");
    assert!(together == alone, "stepping at once changed a trainer's bits");
}

#[test]
fn bf16_steps_do_not_depend_on_the_thread_count_and_differ_from_f32() {
    // Only where the CPU multiplies bf16 on AMX tiles; elsewhere `training.matmul = "bf16"` trains
    // in f32 and the run must say so (the trainer reports the precision that runs).
    let params_with = |threads: usize, matmul: MatmulPrecision| {
        let mut cfg = small("[warm_start]\nsteps = 3\n");
        cfg.config.model.width = 64;
        cfg.config.training.batch_3d = 700;
        cfg.config.training.matmul = matmul;
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        let mut t = trainer(&cfg);
        let runs = t.matmul_precision();
        pool.install(|| (0..6).for_each(|_| drop(t.step().unwrap())));
        (param_values(&t), runs)
    };
    let (bf16, runs) = params_with(1, MatmulPrecision::Bf16);
    if !nuvo_autodiff::bf16_matmul_available() {
        assert_eq!(runs, MatmulPrecision::F32);
        return;
    }
    assert_eq!(runs, MatmulPrecision::Bf16);
    assert!(bf16 == params_with(2, MatmulPrecision::Bf16).0, "1 and 2 threads differ");
    assert!(bf16 != params_with(1, MatmulPrecision::F32).0, "bf16 trained the f32 bits");
}

#[test]
fn warm_start_mistakes_are_located() {
    for (text, key) in [
        ("[warm_start]\nmin_alignment = 1.5\n", "warm_start.min_alignment"),
        ("[warm_start]\nweight = -1\n", "warm_start.weight"),
        ("[warm_start]\nbatch_share = 0\n", "warm_start.batch_share"),
        ("[warm_start]\nbatch_share = 1.5\n", "warm_start.batch_share"),
        ("[warm_start]\nstep = 3\n", "warm_start.step"),
        ("[warm_start]\nprojection = \"azimuthal\"\nocclusion = true\n", "warm_start.occlusion"),
    ] {
        let err = config::from_str("w.toml", &format!("{SMALL}{text}")).unwrap_err().to_string();
        assert!(err.contains(key), "{err}");
    }
}

/// `SMALL` run long enough to settle: 400 steps at most, a look every 25, checkpoints every 50.
fn settling(threshold: f32) -> LoadedConfig {
    let mut cfg = small("");
    cfg.config.training.steps = 400;
    cfg.config.training.checkpoint_every = 50;
    cfg.config.training.stop_when_settled = Some(threshold);
    cfg
}

fn logged_steps(dir: &std::path::Path) -> Vec<serde_json::Value> {
    std::fs::read_to_string(dir.join(files::LOG))
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

#[test]
fn a_settled_atlas_stops_the_run_at_the_second_calm_look() {
    // Looks after steps 25, 50, 75: the first has nothing to compare with; at a threshold no
    // movement exceeds, the second and third are calm, and the run stops after step 75.
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let summary =
        run(&mut trainer(&settling(0.999)), &RunOptions { out_dir: out.clone(), resume: false }, &mut Silent)
            .unwrap();
    assert!(summary.settled && !summary.stopped_by_budget);
    assert_eq!(summary.steps, 75);
    let log = logged_steps(&out);
    assert_eq!(log.len(), 75);
    let looked: Vec<u64> =
        log.iter().filter(|l| l.get("moved").is_some()).map(|l| l["step"].as_u64().unwrap()).collect();
    assert_eq!(looked, vec![49, 74], "a look after every 25th step that has one before it");
    let moved = &log[49]["moved"];
    assert!(
        moved["charts_changed"].as_f64().unwrap() <= 1.0 && moved["shape_change"].as_f64().unwrap() >= 0.0
    );
    // Never settled: a threshold of 0 while the charts still move runs to `steps` (stopped here by
    // a small `steps` to keep the test short).
    let mut never = settling(0.0);
    never.config.training.steps = 100;
    let summary = run(
        &mut trainer(&never),
        &RunOptions { out_dir: dir.path().join("never"), resume: false },
        &mut Silent,
    )
    .unwrap();
    assert!(!summary.settled);
    assert_eq!(summary.steps, 100);
    // One chart: no assignment to settle; it settles when its map's shape holds still, which a
    // map still learning does not, whatever the threshold on chart changes...
    let mut one = settling(0.999);
    one.config.training.steps = 100;
    one.config.model.charts = 1;
    let out = dir.path().join("one");
    let summary =
        run(&mut trainer(&one), &RunOptions { out_dir: out.clone(), resume: false }, &mut Silent).unwrap();
    assert!(!summary.settled);
    assert_eq!(summary.steps, 100);
    let shapes: Vec<f64> = logged_steps(&out)
        .iter()
        .filter_map(|l| l.get("moved"))
        .map(|m| m["shape_change"].as_f64().unwrap())
        .collect();
    assert_eq!(shapes.len(), 3, "looks after steps 50, 75 and 100");
    assert!(shapes.iter().all(|&s| s > f64::from(ONE_CHART_SHAPE_SETTLED)), "{shapes:?}");
    // ...and a map that does not move (no learning) settles at the second calm look.
    let mut frozen = one.clone();
    frozen.config.optimizer.lr_mlp = 0.0;
    frozen.config.optimizer.lr_grid = 0.0;
    frozen.config.optimizer.lr_sigma = 0.0;
    let summary = run(
        &mut trainer(&frozen),
        &RunOptions { out_dir: dir.path().join("frozen"), resume: false },
        &mut Silent,
    )
    .unwrap();
    assert!(summary.settled);
    assert_eq!(summary.steps, 75);
}

#[test]
fn a_resumed_run_settles_where_an_uninterrupted_one_does() {
    let cfg = settling(0.999);
    let dir = tempfile::tempdir().unwrap();
    let mut full = trainer(&cfg);
    run(&mut full, &RunOptions { out_dir: dir.path().join("full"), resume: false }, &mut Silent).unwrap();
    // "Killed" after 60 steps, with the checkpoint of step 50 (one calm look behind it).
    let out = dir.path().join("killed");
    std::fs::create_dir_all(&out).unwrap();
    let mut partial = trainer(&cfg);
    for s in 0..60 {
        partial.step().unwrap();
        if s + 1 == 50 {
            let ckpt = partial.checkpoint().unwrap();
            assert_eq!(ckpt.settled_looks, 1);
            ckpt.save(&out.join(files::CHECKPOINT)).unwrap();
        }
    }
    std::fs::write(out.join(files::LOG), (0..60).map(|s| format!("{{\"step\":{s}}}\n")).collect::<String>())
        .unwrap();
    let mut resumed = trainer(&cfg);
    let summary = run(&mut resumed, &RunOptions { out_dir: out.clone(), resume: true }, &mut Silent).unwrap();
    assert!(summary.settled);
    assert_eq!(summary.steps, 75);
    assert_eq!(param_values(&resumed), param_values(&full));
    assert_eq!(
        Checkpoint::load(&out.join(files::CHECKPOINT)).unwrap(),
        Checkpoint::load(&dir.path().join("full").join(files::CHECKPOINT)).unwrap()
    );
}

#[test]
fn a_config_without_losses_trains_the_papers_eight_and_no_loss_registered_later() {
    let registry = registry_with_nan();
    let t = Trainer::new(&small(""), &sources(), &registry).unwrap();
    let names: Vec<&str> = t.terms().iter().map(|t| t.name.as_str()).collect();
    assert_eq!(names, nuvo_losses::builtin::PAPER);
    // Listed, it is built like any other.
    let t = Trainer::new(&small("[losses.nan_probe]\n"), &sources(), &registry).unwrap();
    assert_eq!(t.terms().iter().map(|t| t.name.as_str()).collect::<Vec<_>>(), ["nan_probe"]);
}

#[test]
fn an_atlas_from_a_checkpoint_evaluates_like_the_trainer_it_came_from() {
    let mut t = trainer(&small(""));
    for _ in 0..3 {
        t.step().unwrap();
    }
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(files::CHECKPOINT);
    t.checkpoint().unwrap().save(&path).unwrap();
    let ckpt = Checkpoint::load(&path).unwrap();
    let pts = [[0.0, 0.0, 1.0], [0.6, 0.0, -0.8], [0.0, -1.0, 0.0]];
    let mut atlas = nuvo_core::TrainedAtlas::from_checkpoint(&ckpt, t.config()).unwrap();
    assert_eq!(atlas.evaluate_atlas(&pts), t.atlas().evaluate_atlas(&pts));
    assert_eq!((atlas.steps(), atlas.frame(), atlas.charts()), (3, t.source().to_canonical(), 2));
    let mut narrower = t.config().clone();
    narrower.model.width = 16;
    let e = nuvo_core::TrainedAtlas::from_checkpoint(&ckpt, &narrower).err().unwrap().to_string();
    assert!(
        e.contains("does not fit this model") && e.contains("`chart.l0.b` is 1×32 in the checkpoint, 1×16"),
        "{e}"
    );
}
