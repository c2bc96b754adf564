//! `nuvo train CONFIG` and `nuvo bake RUN`: train an atlas, then bake, export, draw and measure it.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use indicatif::{ProgressBar, ProgressStyle};
use nuvo_core::outputs::{OutputReport, write_outputs};
use nuvo_core::run::{Observer, RunOptions, files, run};
use nuvo_core::trainer::build_source;
use nuvo_core::{Checkpoint, LoadedConfig, StepOutcome, TrainedAtlas, Trainer, config};
use nuvo_geometry::{GeometrySource, SourceRegistry};
use nuvo_losses::LossRegistry;

#[derive(clap::Args)]
pub struct TrainArgs {
    /// The experiment config (TOML), e.g. configs/bunny.toml.
    config: PathBuf,
    /// Output folder (overrides `output.dir`).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Override a config value, e.g. `--set training.steps=200` (repeatable; TOML values).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    set: Vec<String>,
    /// Continue the run in the output folder from its last checkpoint.
    #[arg(long)]
    resume: bool,
    /// Stop after training: no baking, exports, pictures or metrics.
    #[arg(long)]
    no_bake: bool,
    /// Write no `report.html` (`nuvo report`) into the run folder.
    #[arg(long)]
    no_report: bool,
}

#[derive(clap::Args)]
pub struct BakeArgs {
    /// A run folder (containing checkpoint.safetensors) or a checkpoint file.
    run: PathBuf,
    /// Output folder (default: the run folder).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Override a value of the run's stored config, e.g. `--set output.round_trip_tolerance=0`
    /// (repeatable; the `output` table is what a bake reads).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    set: Vec<String>,
    /// Bake the colours of this file into texture.png through the run's atlas (a mesh with
    /// vertex colours or textures, or a coloured point cloud, placed like the trained geometry,
    /// e.g. a high-resolution scan); sets `output.texture` and `output.texture_from`.
    #[arg(long, value_name = "FILE")]
    texture_from: Option<PathBuf>,
    /// Write no `report.html` (`nuvo report`) into the output folder.
    #[arg(long)]
    no_report: bool,
}

pub fn train(args: &TrainArgs) -> anyhow::Result<()> {
    let mut loaded = config::load(&args.config, &args.set)?;
    if let Some(out) = &args.out {
        loaded.config.output.dir = out.clone();
    }
    let mut trainer = build_trainer(&loaded)?;
    let out_dir = loaded.config.output.dir.clone();
    let mut progress = Progress::new(trainer.total_steps());
    if !args.no_report {
        progress = progress.reporting_into(&out_dir);
    }
    let opts = RunOptions { out_dir: out_dir.clone(), resume: args.resume };
    let summary = run(&mut trainer, &opts, &mut progress)?;
    progress.finish();
    let rss = crate::peak_rss_kib().map(|k| format!(", peak RSS {} MB", k / 1024)).unwrap_or_default();
    println!(
        "trained {} steps in {:.1} s ({} skipped, {} rollbacks{rss}){}; run folder {}",
        summary.steps,
        summary.seconds,
        summary.skipped,
        summary.rollbacks,
        if summary.stopped_by_budget {
            ", stopped by the time budget"
        } else if summary.settled {
            ", stopped once the atlas had settled"
        } else {
            ""
        },
        out_dir.display()
    );
    if !args.no_bake && loaded.config.output.bake {
        bake_into_report(&mut trainer.atlas(), Some(trainer.source()), &out_dir, &loaded)?;
        if let Some(k) = crate::peak_rss_kib() {
            println!("peak RSS {} MB over the whole run", k / 1024);
        }
    }
    if !args.no_report {
        crate::report::write_for_run(&out_dir);
    }
    Ok(())
}

/// Bakes a run from its checkpoint alone: the networks and the frame come from the checkpoint, the
/// geometry to bake onto from its stored config (not read at all with `output.bake_mesh`); no
/// losses, plugins or optimiser are built, so a run whose loss plugin is gone still bakes.
pub fn bake(args: &BakeArgs) -> anyhow::Result<()> {
    let (ckpt, mut loaded, ckpt_path) = load_run(&args.run, &args.set)?;
    if let Some(file) = &args.texture_from {
        if !file.is_file() {
            anyhow::bail!("--texture-from {}: no such file", file.display());
        }
        loaded.config.output.texture = true;
        loaded.config.output.texture_from = Some(std::path::absolute(file).unwrap_or_else(|_| file.clone()));
    }
    let mut atlas = TrainedAtlas::from_checkpoint(&ckpt, &loaded.config)
        .with_context(|| format!("the checkpoint {}", ckpt_path.display()))?;
    println!(
        "atlas: {} chart(s) after {} steps, from {}",
        atlas.charts(),
        atlas.steps(),
        ckpt_path.display()
    );
    let scene = match loaded.config.output.bake_mesh {
        Some(_) => None,
        None => {
            let started = Instant::now();
            let source = build_source(&loaded, &SourceRegistry::with_builtins())?;
            println!("geometry: {} (ready in {:.1} s)", source.describe(), started.elapsed().as_secs_f64());
            Some(source)
        }
    };
    let out =
        args.out.clone().unwrap_or_else(|| ckpt_path.parent().map(Path::to_path_buf).unwrap_or_default());
    bake_into_report(&mut atlas, scene.as_deref(), &out, &loaded)?;
    // A report of the folder's old outputs would now be stale.
    if !args.no_report {
        crate::report::write_for_run(&out);
    }
    Ok(())
}

/// A run's checkpoint (the run folder's, or the file itself), the config stored in it with
/// `overrides` applied, and the checkpoint's path.
fn load_run(run: &Path, overrides: &[String]) -> anyhow::Result<(Checkpoint, LoadedConfig, PathBuf)> {
    let ckpt_path = if run.is_dir() { run.join(files::CHECKPOINT) } else { run.to_path_buf() };
    let ckpt = Checkpoint::load(&ckpt_path)?;
    let loaded =
        config::from_str_with_overrides(&ckpt_path.display().to_string(), &ckpt.config_toml, overrides)
            .with_context(|| format!("the config stored in {}", ckpt_path.display()))?;
    Ok((ckpt, loaded, ckpt_path))
}

/// The trainer of a run (its folder or checkpoint file) as its checkpoint left it, built from the
/// config stored in the checkpoint with `overrides` applied; also that config and the checkpoint's path.
pub(crate) fn restore_run(
    run: &Path,
    overrides: &[String],
) -> anyhow::Result<(Trainer, LoadedConfig, PathBuf)> {
    let (ckpt, loaded, ckpt_path) = load_run(run, overrides)?;
    let mut trainer = build_trainer(&loaded)?;
    trainer.restore(&ckpt)?;
    Ok((trainer, loaded, ckpt_path))
}

/// Says what `training.matmul` asked for when it is not f32, and whether this CPU runs it.
pub(crate) fn report_matmul(trainer: &Trainer) {
    use nuvo_autodiff::{MatmulPrecision, bf16_kernel};
    match (trainer.config().training.matmul, trainer.matmul_precision(), bf16_kernel()) {
        (MatmulPrecision::Bf16, MatmulPrecision::Bf16, Some(kernel)) => {
            println!("matmul: bf16 factors, f32 accumulation, on {} (training.matmul)", kernel.describe())
        }
        (MatmulPrecision::Bf16, _, _) => eprintln!(
            "warning: training.matmul = \"bf16\" needs a CPU with AMX-BF16 (and a kernel that grants it) \
             or AVX-512 BF16; this one trains in f32"
        ),
        _ => {}
    }
}

fn build_trainer(loaded: &LoadedConfig) -> anyhow::Result<Trainer> {
    let started = Instant::now();
    let trainer = Trainer::new(loaded, &SourceRegistry::with_builtins(), &LossRegistry::with_builtins())?;
    let (c, t, s) = trainer.model().macs_per_point();
    let m = &loaded.config.model;
    println!("geometry: {} (ready in {:.1} s)", trainer.source().describe(), started.elapsed().as_secs_f64());
    println!(
        "model: {} chart(s), {} parameters; MACs/point chart {c}, texture {t}, surface {s}; normal grids {}²",
        m.charts,
        trainer.params().numel(),
        trainer.model().grid_resolution()
    );
    // The warm-start prior, a term too, has its own line below.
    let terms: Vec<String> = trainer
        .terms()
        .iter()
        .filter(|t| t.name != nuvo_core::trainer::WARM_START_TERM)
        .map(|t| format!("{}×{}", t.name, t.weight))
        .collect();
    println!("losses: {}", terms.join(", "));
    report_matmul(&trainer);
    let tau = trainer.config().training.chart_support;
    if tau > 0.0 {
        println!("chart support: the c(x)-weighted losses evaluate chart i only where c(x)[i] ≥ {tau:e}");
    }
    if let Some(w) = trainer.config().warm_start.as_ref().filter(|w| w.enabled()) {
        println!(
            "warm start: {} charts begin as {} projections, prior weight {} fading to 0 over {} steps",
            trainer.config().model.charts,
            w.projection.name(),
            w.weight,
            w.steps
        );
    }
    Ok(trainer)
}

/// Bakes, exports, draws and measures `atlas` into `out`, prints what was written, and returns the
/// report. `scene` is the geometry it was trained on (see [`write_outputs`]).
pub(crate) fn bake_into_report(
    atlas: &mut TrainedAtlas,
    scene: Option<&dyn GeometrySource>,
    out: &Path,
    loaded: &LoadedConfig,
) -> anyhow::Result<OutputReport> {
    let started = Instant::now();
    let report = write_outputs(atlas, scene, out, &loaded.config.output)?;
    print_report(&report, started.elapsed().as_secs_f64());
    Ok(report)
}

fn print_report(report: &OutputReport, seconds: f64) {
    if let Some(m) = &report.metrics {
        let i = &m.metrics.image;
        let u = &m.metrics.uv;
        println!(
            "atlas ({:.1} s): Boundary {:.4}  Stretch {:.4}  Conformal {:.4}  Editability {:.4}  ({} views)",
            seconds, i.boundary, i.stretch, i.conformal, i.editability, i.views_used
        );
        let b = &m.bake;
        let untangled = if b.untangle_moves > 0 {
            format!("; {} before untangling", b.flipped_before_untangle)
        } else {
            String::new()
        };
        println!(
            "       UV charts {}, utilisation {:.3}, flipped {} faces ({} on creases of the mesh{untangled}), \
             overlapping {} faces (at {}²), faces per chart {:?} ({} moved by the round-trip check, {} \
             from chart specks to the chart round them)",
            u.charts,
            u.utilisation,
            b.flipped_faces,
            b.flipped_on_creases,
            b.overlapping_faces,
            b.raster_resolution,
            b.faces_per_chart,
            b.reassigned_faces,
            b.absorbed_faces
        );
        let phases: Vec<String> = report.phase_seconds.iter().map(|(p, s)| format!("{p} {s:.1}")).collect();
        println!("       seconds per phase: {}", phases.join(", "));
        if let Some(inj) = m.layout.injective.as_ref().filter(|r| r.cones > 0) {
            println!(
                "       cone points cut open to their island's boundary: {} on {} islands",
                inj.cones, inj.coned_islands
            );
        }
        if let Some(inj) = m.layout.injective.as_ref().filter(|r| r.sided > 0) {
            println!(
                "       islands holding both sides of a thin wall, split between the sides: {}",
                inj.sided
            );
        }
        if let Some((c, [a, b])) = m.layout.creases.as_ref().and_then(|c| Some((c, c.editability?))) {
            println!(
                "       crease charts ({} regions between creases of the surface): {}, Editability estimated \
                 {a:.4} for the networks' charts and {b:.4} for them",
                c.regions,
                if c.chosen { "chosen" } else { "not chosen" }
            );
        }
        if let Some(n) = m.layout.necks.as_ref().filter(|n| !n.skipped) {
            println!(
                "       islands cut at their necks: {} (packing efficiency at 512²: {:.3} -> {:.3}; {} trials{}){}",
                n.cuts,
                n.efficiency_before,
                n.efficiency_after,
                n.trials,
                match n.paths.len() {
                    2 if n.chosen == 1 => "; the cautious path, at twice the seam price, of two",
                    2 => "; the priced path of two",
                    _ => "",
                },
                match n.editability {
                    Some([a, b]) if n.undone => format!(
                        "; undone: they cost {:.4} of Editability (estimated {a:.4} -> {b:.4}), more than the packing is worth",
                        a - b
                    ),
                    Some([a, b]) => format!("; Editability estimated {a:.4} -> {b:.4}"),
                    None => String::new(),
                }
            );
        }
    }
    if let Some(t) = report.metrics.as_ref().and_then(|m| m.texture.as_ref()) {
        println!(
            "       texture {}² from {} ({}): {} texels covered, {} on island edges, {} filled from neighbours",
            t.texels.resolution,
            t.from.display(),
            t.lookup,
            t.texels.covered_texels,
            t.texels.edge_texels,
            t.texels.filled_texels
        );
    }
    for w in &report.warnings {
        eprintln!("warning: {w}");
    }
    for f in &report.files {
        println!("wrote {}", f.display());
    }
}

/// A progress bar with the step, every loss term and the ETA; plain lines when stderr is not a
/// terminal.
pub(crate) struct Progress {
    bar: ProgressBar,
    total: u64,
    every: u64,
    started: Instant,
    /// The run folder whose `report.html` is refreshed at checkpoints, so that a long run can be
    /// watched in a browser (`None`: no report), and when it last was.
    report_dir: Option<PathBuf>,
    reported: Option<Instant>,
}

/// The least time between two refreshes of a training run's report: at the first checkpoint, then
/// at the first checkpoint after each such interval. A run that checkpoints every step (the
/// kill-and-resume tests do) must not spend its time drawing curves.
const REPORT_EVERY: std::time::Duration = std::time::Duration::from_secs(30);

impl Progress {
    pub(crate) fn new(total: u64) -> Self {
        let bar = ProgressBar::new(total);
        bar.set_style(
            ProgressStyle::with_template("{elapsed_precise} [{bar:30}] {pos}/{len} ETA {eta_precise}  {msg}")
                .expect("the template is valid")
                .progress_chars("=> "),
        );
        Progress {
            bar,
            total,
            every: (total / 20).max(1),
            started: Instant::now(),
            report_dir: None,
            reported: None,
        }
    }

    /// Also refresh `dir/report.html` at checkpoints ([`REPORT_EVERY`]).
    pub(crate) fn reporting_into(mut self, dir: &Path) -> Self {
        self.report_dir = Some(dir.to_path_buf());
        self
    }

    pub(crate) fn finish(&self) {
        self.bar.finish_and_clear();
    }
}

fn describe(o: &StepOutcome) -> String {
    let terms: Vec<String> = o.terms.iter().map(|(n, v)| format!("{n} {v:.3e}")).collect();
    format!("loss {:.4e} | {} | σ {:.3e}", o.total, terms.join(" "), o.sigma)
}

impl Observer for Progress {
    fn started(&mut self, trainer: &Trainer, resumed_from: Option<u64>) {
        if let Some(s) = resumed_from {
            self.note(&format!("resuming from step {s}"));
        }
        self.bar.set_position(trainer.step_index());
        self.started = Instant::now();
    }

    fn stepped(&mut self, o: &StepOutcome, _: &Trainer) {
        self.bar.set_position(o.step + 1);
        self.bar.set_message(describe(o));
        if self.bar.is_hidden() && ((o.step + 1).is_multiple_of(self.every) || o.step + 1 == self.total) {
            eprintln!(
                "step {}/{} ({:.0} s): {}",
                o.step + 1,
                self.total,
                self.started.elapsed().as_secs_f64(),
                describe(o)
            );
        }
    }

    fn note(&mut self, message: &str) {
        self.bar.println(message);
        if self.bar.is_hidden() {
            eprintln!("{message}");
        }
    }

    fn checkpointed(&mut self, _step: u64) {
        if self.reported.is_some_and(|t| t.elapsed() < REPORT_EVERY) {
            return;
        }
        self.reported = Some(Instant::now());
        if let Some(dir) = &self.report_dir
            && let Err(e) = crate::report::refresh(dir)
        {
            // Once: a report that cannot be written now will not be written at the next checkpoint.
            self.report_dir = None;
            self.note(&format!("warning: the run's report is not refreshed during training: {e}"));
        }
    }
}
