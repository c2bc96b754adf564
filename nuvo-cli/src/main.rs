//! The `nuvo` command line.

mod bench;
mod demo;

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
    /// Fit a small MLP to a known function with the autodiff engine and report the error.
    Demo(demo::DemoArgs),
    /// Measure the engine: MLP forward+backward steps and raw GEMM throughput.
    Bench(bench::BenchArgs),
}

fn main() -> anyhow::Result<()> {
    match Cli::parse().command {
        Command::Demo(args) => demo::run(&args),
        Command::Bench(args) => bench::run(&args),
    }
}
