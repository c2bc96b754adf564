//! `nuvo unwrap INPUT`: one command from any mesh, point cloud or density grid to a UV atlas, with
//! every setting chosen by a rule from measured properties of the input (`nuvo_core::unwrap`), and
//! each choice printed with the numbers behind it.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use nuvo_core::run::{RunOptions, run};
use nuvo_core::trainer::build_source;
use nuvo_core::unwrap::{
    Decision, InputKind, RecipeInput, chart_trials, check_mesh, choose_charts, choose_orientation,
    choose_sampling, choose_texture, fit_steps, input_kind, profile_mesh, recipe,
};
use nuvo_core::{LoadedConfig, Trainer, config};
use nuvo_geometry::mesh_source::{MeshOptions, MeshSource, SamplingMode};
use nuvo_geometry::profile::MeshProfile;
use nuvo_geometry::{BuildContext, GeometrySource, SourceRegistry};
use nuvo_losses::LossRegistry;
use serde::Serialize;

use crate::train::{Progress, bake_into_report};

/// Default training budget in seconds: with loading, planning and the bake, a 100k-face mesh takes
/// under two minutes on 2 cores (BENCHMARKS.md, "nuvo unwrap").
pub const DEFAULT_TIME_BUDGET: f64 = 90.0;
/// Training stops at this multiple of the budget whatever the fitted step count, in case the
/// machine got slower after the steps were timed (then `nuvo train config.toml` may stop elsewhere).
pub const SAFETY_STOP: f64 = 1.3;

#[derive(clap::Args)]
pub struct UnwrapArgs {
    /// The geometry: a mesh (.obj, .gltf, .glb, or .ply with faces), a point cloud (.ply without
    /// faces, .xyz, .txt, .pts) or a density grid (.npy, with an optional NAME.json header giving
    /// `bounds_min`/`bounds_max`).
    input: PathBuf,
    /// Output folder (default: runs/unwrap/<input name>). Must not hold a run already.
    #[arg(short = 'o', long = "out")]
    out: Option<PathBuf>,
    /// Number of charts, or `auto` to choose it from the shape.
    #[arg(long, default_value = "auto")]
    charts: String,
    /// Seconds of training at most: a clean surface plans 400 steps and stops sooner once its
    /// charts hold still, or at 1.3× this budget on a slow machine; a fragmented input's 400
    /// steps are cut to fit it on this machine (then fixed in config.toml, so `nuvo train`
    /// reproduces the run).
    #[arg(long, default_value_t = DEFAULT_TIME_BUDGET)]
    time_budget: f64,
    /// Seed of every random choice.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Override any value of the chosen config, e.g. `--set training.steps=2000` (repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    set: Vec<String>,
    /// Write no `report.html` (`nuvo report`) into the output folder.
    #[arg(long)]
    no_report: bool,
    /// Print the decisions and the config, then stop without training.
    #[arg(long)]
    plan_only: bool,
}

/// What `unwrap.json` holds: the input, what was measured and decided, and where the time went.
#[derive(Serialize)]
struct UnwrapReport<'a> {
    input: &'a Path,
    kind: InputKind,
    profile: Option<&'a MeshProfile>,
    chart_trials: &'a [nuvo_core::unwrap::ChartTrial],
    decisions: &'a [Decision],
    steps: u64,
    seconds: Timings,
    /// Wall seconds of each phase of the bake, in order (`nuvo_core::outputs::PhaseSeconds`).
    bake_phases: Vec<Phase>,
}

#[derive(Serialize)]
struct Phase {
    phase: &'static str,
    seconds: f64,
}

#[derive(Clone, Copy, Default, Serialize)]
struct Timings {
    load_and_plan: f64,
    training: f64,
    bake: f64,
    total: f64,
}

pub fn run_unwrap(args: &UnwrapArgs) -> anyhow::Result<()> {
    let started = Instant::now();
    let input = std::fs::canonicalize(&args.input).unwrap_or_else(|_| args.input.clone());
    let kind = input_kind(&input)?;
    let charts = parse_charts(&args.charts)?;
    if !(args.time_budget.is_finite() && args.time_budget > 0.0) {
        anyhow::bail!("--time-budget {}: must be a positive number of seconds", args.time_budget);
    }
    let out = args.out.clone().unwrap_or_else(|| {
        PathBuf::from("runs/unwrap").join(input.file_stem().unwrap_or_default().to_string_lossy().as_ref())
    });
    if out.join(nuvo_core::run::files::CHECKPOINT).exists() && !args.plan_only {
        anyhow::bail!("{} already holds a run; choose another -o/--out", out.display());
    }
    let mut decisions = vec![Decision {
        what: "source".into(),
        choice: kind.source().into(),
        why: format!("from the extension of {}", input.display()),
    }];
    let user_set = |key: &str| args.set.iter().any(|s| s.split('=').next().map(str::trim) == Some(key));

    // 1. What the input is, measured.
    let mut recipe_input = RecipeInput {
        kind,
        path: &input,
        sampling: SamplingMode::Uniform,
        flip_normals: false,
        charts: charts.unwrap_or(4),
        steps: planned_steps(&args.set)?,
        stop_after_seconds: Some(SAFETY_STOP * args.time_budget),
        seed: args.seed,
        bounds: None,
        texture: false,
    };
    let (mut mesh, mut profile) = (None, None);
    match kind {
        InputKind::Mesh => {
            if is_gltf(&input) {
                nuvo_atlas::gltf_scene::check_gltf_unwrappable(&input)?;
            }
            let t = Instant::now();
            let m = nuvo_geometry::load_mesh(&input)?;
            check_mesh(&input, &m)?;
            let p = profile_mesh(&m, args.seed);
            println!(
                "input: {} ({} vertices, {} faces; loaded and measured in {:.1} s)",
                input.display(),
                p.vertices,
                p.faces,
                t.elapsed().as_secs_f64()
            );
            let (sampling, d) = choose_sampling(&p);
            recipe_input.sampling = sampling;
            decisions.push(d);
            if let Some(d) = choose_orientation(&p, sampling) {
                recipe_input.flip_normals = true;
                decisions.push(d);
            }
            (mesh, profile) = (Some(m), Some(p));
        }
        InputKind::PointCloud => {}
        InputKind::Density => {
            recipe_input.bounds = nuvo_geometry::density::header_bounds(&input)?;
            if let Some([lo, hi]) = recipe_input.bounds {
                decisions.push(Decision {
                    what: "bounds".into(),
                    choice: format!("{lo:?} .. {hi:?}"),
                    why: format!("from the grid's header {}", input.with_extension("json").display()),
                });
            }
        }
    }

    // The input's colour, carried into texture.png when there is a mesh to bake it onto.
    if !user_set("output.texture") {
        let t = Instant::now();
        let (texture, d, warnings) = choose_texture(&input, kind, user_set("output.bake_mesh"))?;
        for w in warnings {
            eprintln!("warning: {w}");
        }
        recipe_input.texture = texture;
        if let Some(mut d) = d {
            d.why += &format!(" (read in {:.1} s)", t.elapsed().as_secs_f64());
            decisions.push(d);
        }
    }

    // 2. The source, built once (the mesh is not loaded again).
    let loaded = resolve(&recipe_input, &args.set, &out)?;
    // A `--set geometry.…` may change how the mesh is read: then the source reads it itself.
    let geometry_overridden = args.set.iter().any(|s| s.trim_start().starts_with("geometry."));
    let source: Box<dyn GeometrySource> = match mesh.take() {
        Some(m) if !geometry_overridden => {
            let opts = MeshOptions {
                path: input.clone(),
                sampling: recipe_input.sampling,
                normals: Default::default(),
                flip_normals: recipe_input.flip_normals,
                cameras: None,
            };
            let ctx = BuildContext { base_dir: PathBuf::from(".") };
            Box::new(MeshSource::from_mesh(input.clone(), m, &opts, &ctx)?)
        }
        _ => build_source(&loaded, &SourceRegistry::with_builtins())?,
    };
    println!("geometry: {}", source.describe());

    // 3. The chart count.
    let mut trials = Vec::new();
    if user_set("model.charts") {
        decisions.push(decision("charts", loaded.config.model.charts, "set with --set model.charts"));
    } else if let Some(n) = charts {
        decisions.push(decision("charts", n, "given with --charts"));
    } else {
        trials = chart_trials(&*source, args.seed)?;
        let (n, d) = choose_charts(&trials);
        recipe_input.charts = n;
        decisions.push(d);
    }
    let mut loaded = resolve(&recipe_input, &args.set, &out)?;
    for d in &decisions {
        println!("{}: {} ({})", d.what, d.choice, d.why);
    }
    if args.plan_only {
        println!("\n{}", toml::to_string(&loaded.config).context("cannot print the config")?);
        return Ok(());
    }

    // 4. The steps that fit the budget (`fit_steps`: timed on a trainer of the planned run unless
    // it stops once settled), then the run's own trainer on the same source (the warm start's
    // length follows the step count).
    let losses = LossRegistry::with_builtins();
    let mut trainer = Trainer::with_source(&loaded, source, &losses)?;
    crate::train::report_matmul(&trainer);
    if user_set("training.steps") {
        decisions.push(decision("steps", trainer.total_steps(), "set with --set training.steps"));
    } else {
        let (steps, d) = fit_steps(&mut trainer, args.time_budget)?;
        println!("{}: {} ({})", d.what, d.choice, d.why);
        decisions.push(d);
        if steps != trainer.total_steps() {
            recipe_input.steps = steps;
            loaded = resolve(&recipe_input, &args.set, &out)?;
            trainer = Trainer::with_source(&loaded, trainer.into_source(), &losses)?;
        }
    }
    let planned = started.elapsed().as_secs_f64();

    // 5. Train, bake, export, measure.
    let mut progress = Progress::new(trainer.total_steps());
    if !args.no_report {
        progress = progress.reporting_into(&out);
    }
    let summary = run(&mut trainer, &RunOptions { out_dir: out.clone(), resume: false }, &mut progress)?;
    progress.finish();
    let why = if summary.settled { " (the atlas had settled)" } else { "" };
    println!("trained {} steps in {:.1} s{why}", summary.steps, summary.seconds);
    let t = Instant::now();
    let report = bake_into_report(&mut trainer.atlas(), Some(trainer.source()), &out, &loaded)?;
    if is_gltf(&input)
        && let Some(uv) = &report.baked_uv
    {
        let scene = out.join("scene.glb");
        // The baked appearance replaces the scene's own base colour, which followed the old UVs.
        let texture = match report.metrics.as_ref().and_then(|m| m.texture.as_ref()) {
            Some(_) => {
                let p = out.join(nuvo_core::outputs::names::TEXTURE);
                Some(std::fs::read(&p).with_context(|| format!("cannot read {}", p.display()))?)
            }
            None => None,
        };
        let map = nuvo_atlas::gltf_scene::write_gltf_with_uvs(&input, uv, &scene, texture.as_deref())?;
        let map_path = out.join("scene_vertex_map.json");
        let json = serde_json::to_string(&map).context("cannot encode the scene's vertex map")?;
        nuvo_fsio::write_bytes_atomic(&map_path, json.as_bytes())
            .with_context(|| format!("cannot write {}", map_path.display()))?;
        println!("wrote {} (the input's scene with TEXCOORD_0) and {}", scene.display(), map_path.display());
    }
    let seconds = Timings {
        load_and_plan: planned,
        training: summary.seconds,
        bake: t.elapsed().as_secs_f64(),
        total: started.elapsed().as_secs_f64(),
    };
    let json = serde_json::to_string_pretty(&UnwrapReport {
        input: &input,
        kind,
        profile: profile.as_ref(),
        chart_trials: &trials,
        decisions: &decisions,
        steps: summary.steps,
        seconds,
        bake_phases: report.phase_seconds.iter().map(|&(phase, seconds)| Phase { phase, seconds }).collect(),
    })
    .context("cannot encode unwrap.json")?;
    let path = out.join("unwrap.json");
    nuvo_fsio::write_bytes_atomic(&path, json.as_bytes())
        .with_context(|| format!("cannot write {}", path.display()))?;
    if !args.no_report {
        crate::report::write_for_run(&out);
    }
    println!(
        "done in {:.1} s (planning {:.1} s, training {:.1} s, bake and metrics {:.1} s); {} reproduces it with \
         `nuvo train {}`",
        seconds.total,
        seconds.load_and_plan,
        seconds.training,
        seconds.bake,
        out.display(),
        out.join("config.toml").display()
    );
    Ok(())
}

/// The steps the recipe plans for: a `--set training.steps=N`, else 1000 until the budget is fitted.
fn planned_steps(overrides: &[String]) -> anyhow::Result<u64> {
    for s in overrides {
        if let Some((k, v)) = s.split_once('=')
            && k.trim() == "training.steps"
        {
            return v
                .trim()
                .parse()
                .map_err(|_| anyhow::anyhow!("--set {s}: training.steps must be a whole number"));
        }
    }
    Ok(1000)
}

fn decision(what: &str, choice: impl ToString, why: &str) -> Decision {
    Decision { what: what.into(), choice: choice.to_string(), why: why.into() }
}

/// `auto` → `None`, a positive count → `Some(n)`.
fn parse_charts(s: &str) -> anyhow::Result<Option<usize>> {
    if s.eq_ignore_ascii_case("auto") {
        return Ok(None);
    }
    match s.parse::<usize>() {
        Ok(n) if (1..=64).contains(&n) => Ok(Some(n)),
        _ => anyhow::bail!("--charts {s}: expected `auto` or a number of charts from 1 to 64"),
    }
}

fn is_gltf(p: &Path) -> bool {
    p.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("gltf") || e.eq_ignore_ascii_case("glb"))
}

/// The recipe's config with the user's overrides, checked like any config file; outputs go to `out`.
fn resolve(r: &RecipeInput, overrides: &[String], out: &Path) -> Result<LoadedConfig, anyhow::Error> {
    let text = recipe(r);
    let mut loaded = config::from_str_with_overrides("the unwrap recipe", &text, overrides)?;
    loaded.config.output.dir = out.to_path_buf();
    Ok(loaded)
}
