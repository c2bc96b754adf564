//! A training run on disk: the output folder, the step loop, checkpoints, the log, resume, the time
//! budget, stopping once the atlas has settled, and NaN rollback.
//!
//! Files in the output folder (fixed names scripts can rely on):
//! - `config.toml`: the resolved config (defaults filled in), written before the first step;
//! - `log.jsonl`: one JSON object per step (`step`, `total`, `terms`, `lr_factor`, `sigma`,
//!   `seconds`, `skipped`, and `moved` at the settling probe's looks, `crate::settling`);
//!   `seconds` is the wall time of training up to that step since the run began, summed over
//!   resumed sessions (the steps a killed session ran after its last checkpoint are redone and
//!   counted once);
//! - `checkpoint.safetensors`: parameters and optimiser state, every `checkpoint_every` steps and at
//!   the end, written atomically.
//!
//! A resumed run continues from the checkpoint with the same batches and optimiser state, so it
//! reaches the same parameters as an uninterrupted run; log lines after the checkpoint are dropped.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::checkpoint::Checkpoint;
use crate::trainer::{StepOutcome, TrainError, Trainer};
use nuvo_fsio::write_bytes_atomic as write_atomic;

/// Fixed file names inside an output folder.
pub mod files {
    pub const CONFIG: &str = "config.toml";
    pub const LOG: &str = "log.jsonl";
    pub const CHECKPOINT: &str = "checkpoint.safetensors";
}

/// Receives progress; the CLI draws a progress bar with it.
pub trait Observer {
    /// Before the first step (`resumed_from` is the checkpoint's step when resuming).
    fn started(&mut self, _trainer: &Trainer, _resumed_from: Option<u64>) {}
    /// After every step.
    fn stepped(&mut self, _outcome: &StepOutcome, _trainer: &Trainer) {}
    /// Something worth telling the user (skipped steps, rollbacks, checkpoints).
    fn note(&mut self, _message: &str) {}
    /// After a checkpoint of `step` steps is saved and the log is written up to it: a moment to
    /// look at the run so far (the CLI refreshes the run's report).
    fn checkpointed(&mut self, _step: u64) {}
}

/// An observer that ignores everything.
pub struct Silent;
impl Observer for Silent {}

/// How to run.
#[derive(Clone, Debug)]
pub struct RunOptions {
    /// The output folder.
    pub out_dir: PathBuf,
    /// Continue from the folder's checkpoint instead of refusing to overwrite it.
    pub resume: bool,
}

/// What a run did.
#[derive(Clone, Debug)]
pub struct RunSummary {
    /// Steps completed in total (including those before a resume).
    pub steps: u64,
    /// Steps skipped for NaN/inf.
    pub skipped: u64,
    /// Rollbacks to the last checkpoint.
    pub rollbacks: u32,
    /// Wall time of this invocation.
    pub seconds: f64,
    /// Whether the time budget stopped the run before `steps`.
    pub stopped_by_budget: bool,
    /// Whether the run stopped because the atlas had settled (`training.stop_when_settled`).
    pub settled: bool,
    /// The last step's outcome.
    pub last: Option<StepOutcome>,
}

/// Rollbacks allowed before the run gives up.
const MAX_ROLLBACKS: u32 = 3;

fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> TrainError + '_ {
    move |source| TrainError::Io { path: path.to_owned(), source }
}

/// Trains `trainer` to its configured number of steps (or budget), writing the output folder.
pub fn run(
    trainer: &mut Trainer,
    opts: &RunOptions,
    observer: &mut dyn Observer,
) -> Result<RunSummary, TrainError> {
    let dir = &opts.out_dir;
    std::fs::create_dir_all(dir).map_err(io_err(dir))?;
    let ckpt_path = dir.join(files::CHECKPOINT);
    let resumed_from = prepare_start(trainer, opts, &ckpt_path)?;
    let config_path = dir.join(files::CONFIG);
    let config_text = trainer.config().to_toml()?;
    write_atomic(&config_path, config_text.as_bytes()).map_err(io_err(&config_path))?;
    let log_path = dir.join(files::LOG);
    let (mut log, earlier_seconds) = open_log(&log_path, trainer.step_index())?;
    observer.started(trainer, resumed_from);

    let start = Instant::now();
    let budget = trainer.config().training.time_budget_minutes.map(|m| m * 60.0);
    let every = trainer.config().training.checkpoint_every;
    let max_bad = trainer.config().training.max_bad_steps;
    let mut snapshot = trainer.checkpoint()?;
    let mut summary = RunSummary {
        steps: 0,
        skipped: 0,
        rollbacks: 0,
        seconds: 0.0,
        stopped_by_budget: false,
        settled: false,
        last: None,
    };
    let mut consecutive_bad = 0u32;
    // The step whose state the checkpoint file holds, when the loop saved it.
    let mut saved_at: Option<u64> = None;
    while trainer.step_index() < trainer.total_steps() {
        if budget.is_some_and(|b| start.elapsed().as_secs_f64() >= b) {
            summary.stopped_by_budget = true;
            observer.note(&format!("time budget reached after step {}", trainer.step_index()));
            break;
        }
        if trainer.settled() {
            summary.settled = true;
            observer.note(&format!("the atlas settled after step {}", trainer.step_index()));
            break;
        }
        let outcome = trainer.step()?;
        let seconds = earlier_seconds + start.elapsed().as_secs_f64();
        write_log_line(&mut log, &outcome, seconds).map_err(io_err(&log_path))?;
        observer.stepped(&outcome, trainer);
        if let Some(why) = &outcome.skipped {
            summary.skipped += 1;
            consecutive_bad += 1;
            observer.note(&format!("step {} skipped: {why}", outcome.step));
            if consecutive_bad > max_bad {
                summary.rollbacks += 1;
                if summary.rollbacks > MAX_ROLLBACKS {
                    return Err(TrainError::Diverged(format!(
                        "{consecutive_bad} consecutive steps up to step {} were not finite (last: {why}) even after \
                         {MAX_ROLLBACKS} rollbacks with halved learning rates; the last good checkpoint is {}",
                        outcome.step,
                        ckpt_path.display()
                    )));
                }
                trainer.restore(&snapshot)?;
                for _ in 0..summary.rollbacks {
                    trainer.halve_learning_rates();
                }
                // The snapshot's step again, with other learning rates than the file holds.
                saved_at = None;
                consecutive_bad = 0;
                observer.note(&format!(
                    "rolled back to step {} and halved the learning rates ({} consecutive bad steps)",
                    snapshot.step,
                    max_bad + 1
                ));
            }
        } else {
            consecutive_bad = 0;
        }
        summary.last = Some(outcome);
        if trainer.step_index().is_multiple_of(every) && consecutive_bad == 0 {
            snapshot = trainer.checkpoint()?;
            snapshot.save(&ckpt_path)?;
            saved_at = Some(trainer.step_index());
            log.flush().map_err(io_err(&log_path))?;
            observer.checkpointed(trainer.step_index());
        }
    }
    log.flush().map_err(io_err(&log_path))?;
    if consecutive_bad == 0 {
        snapshot = trainer.checkpoint()?;
    }
    // Not again when the last step's state was just saved (a run ending on a checkpoint step,
    // as the README job's 250 steps do: 9.5 MB written twice on one core).
    if saved_at != Some(snapshot.step) {
        snapshot.save(&ckpt_path)?;
    }
    summary.steps = trainer.step_index();
    summary.seconds = start.elapsed().as_secs_f64();
    Ok(summary)
}

/// Loads the checkpoint when resuming; refuses to overwrite an existing run otherwise.
fn prepare_start(
    trainer: &mut Trainer,
    opts: &RunOptions,
    ckpt_path: &Path,
) -> Result<Option<u64>, TrainError> {
    let exists = ckpt_path.exists();
    match (opts.resume, exists) {
        (true, true) => {
            let ckpt = Checkpoint::load(ckpt_path)?;
            check_same_experiment(trainer, &ckpt)?;
            trainer.restore(&ckpt)?;
            Ok(Some(ckpt.step))
        }
        (true, false) => Err(TrainError::Resume(format!(
            "nothing to resume: {} does not exist (run without --resume to start)",
            ckpt_path.display()
        ))),
        (false, true) => Err(TrainError::Resume(format!(
            "{} already holds a run; pass --resume to continue it, or choose another --out",
            opts.out_dir.display()
        ))),
        (false, false) => Ok(None),
    }
}

/// Resuming only reproduces a run if everything but the output folder and the budget is the same.
fn check_same_experiment(trainer: &Trainer, ckpt: &Checkpoint) -> Result<(), TrainError> {
    let normalise = |mut c: crate::config::ExperimentConfig| {
        c.output = Default::default();
        c.training.time_budget_minutes = None;
        c
    };
    let saved = toml::from_str(&ckpt.config_toml)
        .map_err(|e| TrainError::Resume(format!("the checkpoint's config is unreadable: {e}")))?;
    if normalise(saved) != normalise(trainer.config().clone()) {
        return Err(TrainError::Resume(
            "the checkpoint was trained with a different config (only output.dir and \
             training.time_budget_minutes may change when resuming)"
                .into(),
        ));
    }
    Ok(())
}

/// Opens the log for appending, first dropping lines at or after `from_step` (left by a run that
/// was killed after its last checkpoint); also returns the training seconds the kept lines record.
fn open_log(path: &Path, from_step: u64) -> Result<(std::io::BufWriter<std::fs::File>, f64), TrainError> {
    if from_step == 0 {
        let f = std::fs::File::create(path).map_err(io_err(path))?;
        return Ok((std::io::BufWriter::new(f), 0.0));
    }
    // A log lost since the checkpoint starts afresh, and lines that are not JSON are dropped
    // below; a log that cannot be read is an error, not silently emptied.
    let old = match std::fs::read(path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => String::new(),
        Err(source) => return Err(TrainError::Read { path: path.to_owned(), source }),
        Ok(bytes) => String::from_utf8_lossy(&bytes).into_owned(),
    };
    let kept: String = old
        .lines()
        .filter(|l| {
            serde_json::from_str::<serde_json::Value>(l)
                .ok()
                .and_then(|v| v.get("step").and_then(serde_json::Value::as_u64))
                .is_some_and(|s| s < from_step)
        })
        .flat_map(|l| [l, "\n"])
        .collect();
    write_atomic(path, kept.as_bytes()).map_err(io_err(path))?;
    let f = std::fs::OpenOptions::new().append(true).open(path).map_err(io_err(path))?;
    Ok((std::io::BufWriter::new(f), logged_seconds(&kept)))
}

/// The training seconds a log's text records: its last `seconds`, or, for logs written before
/// `seconds` counted across resumed sessions (it restarted at 0 in each), the sum of each
/// session's last value. 0 for an empty log.
pub fn logged_seconds(log: &str) -> f64 {
    let values = log
        .lines()
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok()?.get("seconds")?.as_f64());
    cumulative_seconds(values).last().copied().unwrap_or(0.0)
}

/// The training seconds since the run began at each of a log's `seconds` values, in order. Logs
/// written before `seconds` counted across resumed sessions restarted at 0 in each session: a
/// value below the one before it starts a new session, which adds the last session's end.
pub fn cumulative_seconds(values: impl IntoIterator<Item = f64>) -> Vec<f64> {
    let (mut finished_sessions, mut last) = (0.0, 0.0);
    values
        .into_iter()
        .map(|v| {
            if v < last {
                finished_sessions += last;
            }
            last = v;
            finished_sessions + v
        })
        .collect()
}

fn write_log_line(log: &mut impl Write, o: &StepOutcome, seconds: f64) -> std::io::Result<()> {
    let terms: serde_json::Map<String, serde_json::Value> =
        o.terms.iter().map(|(k, v)| (k.clone(), serde_json::json!(v))).collect();
    let mut line = serde_json::json!({
        "step": o.step,
        "total": o.total,
        "terms": terms,
        "lr_factor": o.lr_factor,
        "sigma": o.sigma,
        "seconds": seconds,
        "skipped": o.skipped,
    });
    if let Some(m) = o.moved {
        line["moved"] = serde_json::json!(m);
    }
    writeln!(log, "{line}")
}

#[cfg(test)]
mod tests {
    use super::logged_seconds;

    fn log(seconds: &[f64]) -> String {
        seconds.iter().enumerate().map(|(k, s)| format!("{{\"step\":{k},\"seconds\":{s}}}\n")).collect()
    }

    #[test]
    fn logged_seconds_reads_the_last_value_and_sums_sessions_of_old_logs() {
        assert_eq!(logged_seconds(""), 0.0);
        assert_eq!(logged_seconds(&log(&[0.5, 1.0, 2.5, 3.0])), 3.0);
        // An old log resumed twice: each session restarted at 0.
        assert_eq!(logged_seconds(&log(&[1.0, 2.0, 0.5, 1.5, 0.25])), 2.0 + 1.5 + 0.25);
        assert_eq!(logged_seconds("not json\n{\"step\":0}\n"), 0.0);
    }

    #[test]
    fn cumulative_seconds_carries_each_old_session_over_the_next() {
        assert_eq!(super::cumulative_seconds([1.0, 2.0, 0.5, 1.5, 0.25]), [1.0, 2.0, 2.5, 3.5, 3.75]);
        assert_eq!(super::cumulative_seconds([0.5, 1.0, 1.0]), [0.5, 1.0, 1.0]);
        assert!(super::cumulative_seconds([]).is_empty());
    }
}
