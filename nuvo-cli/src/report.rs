//! `nuvo report RUN_OR_SWEEP... [-o report.html]`: one self-contained HTML page for runs and
//! sweeps (`nuvo_report`), and the report `nuvo train`, `nuvo unwrap` and `nuvo ablate` write for
//! their own run or sweep.

use std::path::{Path, PathBuf};

use anyhow::Context;
use nuvo_report::{REPORT_HTML, ReportSummary, Run};

#[derive(clap::Args)]
pub struct ReportArgs {
    /// Run folders, and sweep folders (a folder of run folders, as `nuvo ablate` writes), shown side
    /// by side in this order; a run still training shows what it has logged so far.
    #[arg(required = true, value_name = "RUN_OR_SWEEP")]
    inputs: Vec<PathBuf>,
    /// The page to write (default: `report.html` in the folder when one folder is given, else
    /// `report.html` here).
    #[arg(short = 'o', long = "out")]
    out: Option<PathBuf>,
}

pub fn run(args: &ReportArgs) -> anyhow::Result<()> {
    let out = match (&args.out, args.inputs.as_slice()) {
        (Some(out), _) => out.clone(),
        (None, [one]) => one.join(REPORT_HTML),
        (None, _) => PathBuf::from(REPORT_HTML),
    };
    let summary = nuvo_report::write_report(&args.inputs, &out)?;
    print_summary(&summary, &out);
    Ok(())
}

/// Writes the report of the run in `dir` to `dir/report.html`, for `nuvo train` and `nuvo unwrap`.
/// The run itself is done by then, so a report that cannot be written is a warning, not a failure.
pub fn write_for_run(dir: &Path) {
    match refresh(dir) {
        Ok(summary) => print_summary(&summary, &dir.join(REPORT_HTML)),
        Err(e) => eprintln!("warning: no report: {e}"),
    }
}

/// (Re)writes `dir/report.html` from what the run folder holds now, saying nothing: at the end of
/// a run ([`write_for_run`]) and at its checkpoints while it trains.
pub fn refresh(dir: &Path) -> Result<ReportSummary, nuvo_report::ReportError> {
    nuvo_report::write_report(&[dir.to_path_buf()], &dir.join(REPORT_HTML))
}

/// Writes the report of a sweep's variants (their folders, named as in its table) to
/// `sweep/report.html`, for `nuvo ablate`.
pub fn write_for_sweep(sweep: &Path, variants: &[(String, PathBuf)]) -> anyhow::Result<()> {
    let runs: Vec<Run> = variants
        .iter()
        .filter(|(_, dir)| nuvo_report::run::is_run_folder(dir))
        .map(|(name, dir)| Run::read(dir, name.clone()))
        .collect();
    if runs.is_empty() {
        return Ok(());
    }
    let out = sweep.join(REPORT_HTML);
    let summary = nuvo_report::write_runs(&runs, &out)
        .with_context(|| format!("the sweep report {}", out.display()))?;
    print_summary(&summary, &out);
    Ok(())
}

fn print_summary(summary: &ReportSummary, out: &Path) {
    for w in &summary.warnings {
        eprintln!("warning: {w}");
    }
    println!(
        "wrote {} ({} run{}, {:.1} MB; opens from disk)",
        out.display(),
        summary.runs.len(),
        if summary.runs.len() == 1 { "" } else { "s" },
        summary.bytes as f64 / 1e6
    );
}
