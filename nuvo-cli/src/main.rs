//! The `nuvo` command line.

mod ablate;
mod batch;
mod bench;
mod demo;
mod eval;
mod losses;
mod report;
mod train;
mod unwrap;

use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// Neural UV mapping for unruly 3-D geometry (Nuvo, CVPR 2024).
#[derive(Parser)]
#[command(name = "nuvo", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Unwrap any mesh, point cloud or density grid with settings chosen for it (the way to start).
    Unwrap(unwrap::UnwrapArgs),
    /// Train an atlas from an experiment config, then bake, export, draw and measure it.
    Train(train::TrainArgs),
    /// Train the base config and its loss-ablation variants, then write the paper's ablation table.
    Ablate(ablate::AblateArgs),
    /// Unwrap every item of a manifest (or this shard's part of it, on a Slurm array or a Kubernetes
    /// indexed job), or summarise a batch folder.
    Batch(batch::BatchArgs),
    /// Bake, export, draw and measure the atlas of a run folder or checkpoint.
    Bake(train::BakeArgs),
    /// Write one self-contained HTML page of runs or sweeps: metrics, loss curves, pictures, config
    /// differences and a 3-D view of each atlas.
    Report(report::ReportArgs),
    /// Measure a mesh's UVs: the paper's Boundary/Stretch/Conformal/Editability and UV statistics.
    Eval(eval::EvalArgs),
    /// Fit a small MLP to a known function with the autodiff engine and report the error.
    Demo(demo::DemoArgs),
    /// Measure the engine: MLP forward+backward steps and raw GEMM throughput.
    Bench(bench::BenchArgs),
    /// List the built-in losses and describe loss plugins (--plugin PATH), with their options.
    Losses(losses::LossesArgs),
}

fn main() -> ExitCode {
    let result = match Cli::parse().command {
        Command::Unwrap(args) => unwrap::run_unwrap(&args),
        Command::Train(args) => train::train(&args),
        Command::Ablate(args) => ablate::run(&args),
        Command::Batch(args) => batch::run(&args),
        Command::Bake(args) => train::bake(&args),
        Command::Report(args) => report::run(&args),
        Command::Eval(args) => eval::run(&args),
        Command::Demo(args) => demo::run(&args),
        Command::Bench(args) => bench::run(&args),
        Command::Losses(args) => losses::run(&args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", one_line(&e));
            ExitCode::FAILURE
        }
    }
}

/// The error and its causes on one line, skipping a cause whose text its parent already shows.
pub(crate) fn one_line(e: &anyhow::Error) -> String {
    let mut msg = String::new();
    for cause in e.chain().map(|c| c.to_string()) {
        if !msg.contains(&cause) {
            msg += if msg.is_empty() { "" } else { ": " };
            msg += &cause;
        }
    }
    msg
}

/// Peak resident set size of this process in KiB (Linux `VmHWM`; `None` elsewhere).
pub(crate) fn peak_rss_kib() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    line.split_whitespace().nth(1)?.parse().ok()
}
