//! `nuvo report`: one self-contained HTML page for one or several runs, or a sweep of them.
//!
//! A researcher compares runs by looking at them, and this page puts everything side by side:
//! - the metrics: the paper's set, PartUV's set and the atlas's health, as one table sortable by
//!   any column;
//! - the config keys whose values differ between the runs;
//! - every objective term's curve, against step and against training seconds (SVG by plotters);
//! - each run's pictures, and a 3-D view of its `atlas.glb` (the vendored `<model-viewer>`);
//! - each run's full metrics and config.
//!
//! Invariants:
//! - **Self-contained.** Everything on the page is inside the file: pictures and the model as
//!   `data:` URIs, the viewer's script inline. It opens from disk and fetches nothing.
//! - **Reads any run folder as it is** ([`run`]). A run that is still training shows what it has
//!   logged so far. A folder from an older version shows what it has. A missing or damaged file
//!   leaves its part out with a warning.
//! - **Written atomically.** A report being rewritten while someone has it open is never seen half
//!   written.

pub mod config_diff;
pub mod curves;
pub mod html;
pub mod log;
pub mod metrics;
pub mod run;

use std::path::{Path, PathBuf};

pub use run::Run;

/// The file name `nuvo train`, `nuvo unwrap` and `nuvo ablate` give the report of their run or sweep.
pub const REPORT_HTML: &str = "report.html";

/// Why there is no report.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// An input that is not a run folder or a sweep of them.
    #[error("{path}: {message}")]
    Input { path: PathBuf, message: String },
    #[error("cannot read {path}: {source}")]
    Read {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("cannot write {path}: {source}")]
    Write {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// plotters failed to draw a curve (a bug, not bad input).
    #[error("cannot draw a loss curve: {0}")]
    Plot(String),
}

/// What was written.
#[derive(Clone, Debug)]
pub struct ReportSummary {
    /// The run folders on the page, in page order.
    pub runs: Vec<PathBuf>,
    /// What could not be read, per run (also shown on the page).
    pub warnings: Vec<String>,
    /// Size of the page in bytes.
    pub bytes: usize,
}

/// Writes the report of `inputs` (run folders and sweeps of them, in this order) to `out`.
pub fn write_report(inputs: &[PathBuf], out: &Path) -> Result<ReportSummary, ReportError> {
    let dirs = run::run_folders(inputs)?;
    let runs = run::read_runs(&dirs);
    write_runs(&runs, out)
}

/// Writes the report of runs already read (a sweep that knows its variants' order and names).
pub fn write_runs(runs: &[Run], out: &Path) -> Result<ReportSummary, ReportError> {
    if runs.is_empty() {
        return Err(ReportError::Input { path: out.to_path_buf(), message: "no runs to report on".into() });
    }
    let page = html::page(runs)?;
    nuvo_fsio::write_bytes_atomic(out, page.as_bytes())
        .map_err(|source| ReportError::Write { path: out.to_path_buf(), source })?;
    Ok(ReportSummary {
        runs: runs.iter().map(|r| r.dir.clone()).collect(),
        warnings: runs
            .iter()
            .flat_map(|r| r.warnings.iter().map(move |w| format!("{}: {w}", r.label)))
            .collect(),
        bytes: page.len(),
    })
}
