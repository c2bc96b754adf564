//! `nuvo ablate CONFIG`: train the base config and its variants one after another, then write the
//! paper's ablation table (Markdown and CSV) next to the per-variant run folders.

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use nuvo_core::ablation::{self, Row, Variant, VariantError};
use nuvo_core::config;
use nuvo_core::manifest::{Shard, ShardSource};
use nuvo_core::run::{files, logged_seconds};
use nuvo_fsio::write_bytes_atomic;
use nuvo_geometry::SourceRegistry;
use nuvo_losses::LossRegistry;

use crate::train::Progress;

#[derive(clap::Args)]
pub struct AblateArgs {
    /// The base experiment config; its `[ablation]` table lists the variants (default: the base plus
    /// one run per loss with that loss removed).
    config: PathBuf,
    /// Sweep folder (default: the config's `output.dir`): one sub-folder per variant, plus
    /// `ablation.md` and `ablation.csv`.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Override a value of the base config for every variant (repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    set: Vec<String>,
    /// Run only the variants with these names or folder names (repeatable).
    #[arg(long = "only", value_name = "NAME")]
    only: Vec<String>,
    /// Reuse finished variants' metrics and continue interrupted ones from their checkpoints.
    #[arg(long)]
    resume: bool,
    /// Write no `report.html` (`nuvo report`) of the sweep.
    #[arg(long)]
    no_report: bool,
    /// Run only shard I of N of the planned variants (variant i when i mod N = I), resuming its
    /// variants; default: from SLURM_ARRAY_TASK_ID/SLURM_ARRAY_TASK_COUNT, or JOB_COMPLETION_INDEX
    /// with --shards. A sharded run writes no table: `--collect` assembles it once all are done.
    #[arg(long, value_name = "I/N", conflicts_with = "shards")]
    shard: Option<String>,
    /// The number of shards of a Kubernetes indexed job (its `completions`).
    #[arg(long, value_name = "N")]
    shards: Option<usize>,
    /// Train nothing: assemble the table and report from the variants' folders (after a sharded
    /// sweep); a variant without metrics is a row saying so.
    #[arg(long, conflicts_with_all = ["shard", "shards", "resume", "dry_run"])]
    collect: bool,
    /// Variants trained at once on this machine, as K shards in child processes (threads split
    /// between them; each shard's output in `OUT/ablate-shard-K.log`), then collected.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u16).range(1..),
          conflicts_with_all = ["shard", "shards", "collect", "dry_run"])]
    jobs: u16,
    /// Print the planned variants and exit.
    #[arg(long)]
    dry_run: bool,
}

pub fn run(args: &AblateArgs) -> anyhow::Result<()> {
    let losses = LossRegistry::with_builtins();
    let sources = SourceRegistry::with_builtins();
    let base = config::load(&args.config, &args.set)?;
    let out = args.out.clone().unwrap_or_else(|| base.config.output.dir.clone());
    let (shard, source) = if args.collect {
        (Shard::WHOLE, ShardSource::Whole)
    } else {
        Shard::resolve(args.shard.as_deref(), args.shards, |k| std::env::var(k).ok())?
    };
    // `--only` names are checked against the whole plan, then the shard takes its part of them.
    let variants: Vec<Variant> = selected(ablation::plan(&base), &args.only)?
        .into_iter()
        .filter(|(i, _)| shard.owns(*i))
        .map(|(_, v)| v)
        .collect();
    if args.collect {
        return collect(args, &base, &out, &variants);
    }
    if args.jobs > 1 && source == ShardSource::Whole {
        run_shards_here(args, &out)?;
        return collect(args, &base, &out, &variants);
    }
    let sharded = source != ShardSource::Whole;
    if sharded {
        let names: Vec<&str> = variants.iter().map(|v| v.name.as_str()).collect();
        println!("shard {shard}: {} variant(s): {}", variants.len(), names.join(", "));
    }
    if args.dry_run {
        for v in &variants {
            println!(
                "{:<24} -> {}  remove {:?}  set {:?}",
                v.name,
                out.join(&v.dir_name).display(),
                v.remove,
                v.set
            );
        }
        return Ok(());
    }
    std::fs::create_dir_all(&out)?;
    let mut rows = Vec::new();
    for (k, v) in variants.iter().enumerate() {
        println!("[{}/{}] {} -> {}", k + 1, variants.len(), v.name, out.join(&v.dir_name).display());
        let started = Instant::now();
        let result = run_one(args, sharded, v, &out, (&sources, &losses));
        let dir = out.join(&v.dir_name);
        let logged = std::fs::read_to_string(dir.join(files::LOG)).ok().map(|t| logged_seconds(&t));
        let seconds = logged.filter(|&s| s > 0.0).unwrap_or_else(|| started.elapsed().as_secs_f64());
        let row = Row { name: v.name.clone(), dir, result, seconds };
        match &row.result {
            Ok(s) => println!(
                "[{}/{}] {}: Boundary {:.3}  Stretch {:.3}  Conformal {:.3}  UV Eff. {:.3}  Avg. {:.3}  ({:.0} s)",
                k + 1,
                variants.len(),
                v.name,
                s.boundary,
                s.stretch,
                s.conformal,
                s.uv_efficiency,
                s.average(),
                row.seconds
            ),
            Err(e) => println!("[{}/{}] {}: FAILED: {e}", k + 1, variants.len(), v.name),
        }
        rows.push(row);
        if !sharded {
            write_tables(&out, &rows)?;
        }
    }
    if sharded {
        let failed = rows.iter().filter(|r| r.result.is_err()).count();
        println!(
            "shard {shard} done ({failed} failed); once every shard is, `nuvo ablate {} --out {} --collect` writes the \
             table and the report",
            args.config.display(),
            out.display()
        );
        if failed > 0 {
            anyhow::bail!("{failed} of {} variants of shard {shard} failed", rows.len());
        }
        return Ok(());
    }
    println!("\n{}", ablation::markdown_table(&rows));
    println!("wrote {} and {}", out.join("ablation.md").display(), out.join("ablation.csv").display());
    if !args.no_report {
        write_sweep_report(&base, &out)?;
    }
    let failed = rows.iter().filter(|r| r.result.is_err()).count();
    if failed > 0 {
        anyhow::bail!("{failed} of {} variants failed (see the table for why)", rows.len());
    }
    Ok(())
}

/// `--jobs K`: the sweep as K shards, each a child `nuvo ablate --shard k/K` with its share of the
/// threads and its output in a log; returns once all have ended (their failures are the table's).
fn run_shards_here(args: &AblateArgs, out: &std::path::Path) -> anyhow::Result<()> {
    let jobs = usize::from(args.jobs);
    let threads = crate::batch::threads_per_job(jobs);
    let exe = std::env::current_exe().context("cannot find the nuvo binary to run shards with")?;
    std::fs::create_dir_all(out)?;
    let mut children = Vec::with_capacity(jobs);
    for k in 0..jobs {
        let log_path = out.join(format!("ablate-shard-{k}.log"));
        let mut cmd = std::process::Command::new(&exe);
        cmd.arg("ablate").arg(&args.config).arg("--out").arg(out).arg("--shard").arg(format!("{k}/{jobs}"));
        for s in &args.set {
            cmd.arg("--set").arg(s);
        }
        for o in &args.only {
            cmd.arg("--only").arg(o);
        }
        let child = crate::batch::spawn_logged(&mut cmd, &log_path, threads)?;
        children.push((k, log_path, child));
    }
    println!(
        "{jobs} shards running, {threads} thread(s) each; their output: {}",
        out.join("ablate-shard-*.log").display()
    );
    for (k, log_path, mut child) in children {
        let status = child.wait().context("cannot wait for a shard")?;
        println!("shard {k}/{jobs} ended ({status}); its output: {}", log_path.display());
    }
    Ok(())
}

/// `--collect`: the table and report of the variants' folders as they are, training nothing.
fn collect(
    args: &AblateArgs,
    base: &config::LoadedConfig,
    out: &std::path::Path,
    variants: &[Variant],
) -> anyhow::Result<()> {
    let rows: Vec<Row> = variants
        .iter()
        .map(|v| {
            let dir = out.join(&v.dir_name);
            let result = ablation::load_variant(&args.config, &args.set, v)
                .map_err(|e| crate::one_line(&anyhow::Error::new(e)))
                .and_then(|l| ablation::finished_scores(&dir, l.config.training.steps));
            let seconds = std::fs::read_to_string(dir.join(files::LOG)).map_or(0.0, |t| logged_seconds(&t));
            Row { name: v.name.clone(), dir, result, seconds }
        })
        .collect();
    std::fs::create_dir_all(out)?;
    write_tables(out, &rows)?;
    println!("{}", ablation::markdown_table(&rows));
    println!("wrote {} and {}", out.join("ablation.md").display(), out.join("ablation.csv").display());
    if !args.no_report {
        write_sweep_report(base, out)?;
    }
    let missing: Vec<&str> = rows.iter().filter(|r| r.result.is_err()).map(|r| r.name.as_str()).collect();
    if !missing.is_empty() {
        anyhow::bail!(
            "{} of {} variants have no finished run: {}",
            missing.len(),
            rows.len(),
            missing.join(", ")
        );
    }
    Ok(())
}

/// The sweep's `report.html`: every planned variant that has a folder (also those an earlier
/// `--only` or another shard ran), in plan order.
fn write_sweep_report(base: &config::LoadedConfig, out: &std::path::Path) -> anyhow::Result<()> {
    let all: Vec<(String, PathBuf)> =
        ablation::plan(base).into_iter().map(|v| (v.name, out.join(v.dir_name))).collect();
    crate::report::write_for_sweep(out, &all)
}

/// The planned variants restricted to `only` (names or folder names), each with its place in the
/// plan (which shard owns it); an unknown name lists the planned ones.
fn selected(variants: Vec<Variant>, only: &[String]) -> anyhow::Result<Vec<(usize, Variant)>> {
    for o in only {
        if !variants.iter().any(|v| &v.name == o || &v.dir_name == o) {
            let names: Vec<&str> = variants.iter().map(|v| v.dir_name.as_str()).collect();
            anyhow::bail!("--only {o}: no such variant; planned: {}", names.join(", "));
        }
    }
    let wanted = |v: &Variant| only.is_empty() || only.iter().any(|o| o == &v.name || o == &v.dir_name);
    Ok(variants.into_iter().enumerate().filter(|(_, v)| wanted(v)).collect())
}

/// Loads, trains, bakes and measures one variant; any failure, even a panic, becomes the row's error.
fn run_one(
    args: &AblateArgs,
    sharded: bool,
    v: &Variant,
    out: &std::path::Path,
    registries: (&SourceRegistry, &LossRegistry),
) -> Result<ablation::Scores, String> {
    let attempt = || -> Result<ablation::Scores, VariantError> {
        let loaded = ablation::load_variant(&args.config, &args.set, v)?;
        let mut progress = Progress::new(loaded.config.training.steps);
        let scores = ablation::run_variant(
            &loaded,
            &out.join(&v.dir_name),
            args.resume || sharded,
            registries,
            &mut progress,
        );
        progress.finish();
        scores
    };
    match catch_unwind(AssertUnwindSafe(attempt)) {
        Ok(r) => r.map_err(|e| crate::one_line(&anyhow::Error::new(e))),
        Err(panic) => Err(format!(
            "internal error (panic): {}",
            panic
                .downcast_ref::<String>()
                .map(String::as_str)
                .or(panic.downcast_ref::<&str>().copied())
                .unwrap_or("?")
        )),
    }
}

fn write_tables(out: &std::path::Path, rows: &[Row]) -> anyhow::Result<()> {
    for (name, text) in
        [("ablation.md", ablation::markdown_table(rows)), ("ablation.csv", ablation::csv_table(rows))]
    {
        let path = out.join(name);
        write_bytes_atomic(&path, text.as_bytes())
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    Ok(())
}
