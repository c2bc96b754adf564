//! `nuvo batch MANIFEST -o DIR`: `nuvo unwrap` over every item of a manifest that this shard owns,
//! as child processes (one per item, `--jobs` at once), each into `DIR/<name>/`; and `nuvo batch
//! --summary DIR`, the table of every item.
//!
//! Each item runs as a child process of this same binary. A child can be killed at the item's time
//! limit, and whatever an item does (a crash, a panic, running out of memory) stays with that item
//! while the batch goes on. What to run and which shard runs it live in `nuvo_core::manifest`; the
//! record each item leaves and the summary live in `nuvo_core::batch_record`.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use anyhow::Context;
use nuvo_core::batch_record::{self, ITEM_LOG, ITEMS, RECORD, Record, SUMMARY_CSV, SUMMARY_MD, Status};
use nuvo_core::manifest::{self, Item, Shard, ShardSource};
use nuvo_fsio::write_bytes_atomic;

#[derive(clap::Args)]
pub struct BatchArgs {
    /// The manifest: one input per line, or a .csv (input,name,set) or .toml (`[[item]]` input, name,
    /// set) with per-item names and `--set` overrides; relative paths are relative to it.
    #[arg(required_unless_present = "summary", value_name = "MANIFEST")]
    manifest: Option<PathBuf>,
    /// The batch folder: one sub-folder per item, plus summary.md and summary.csv.
    #[arg(short = 'o', long = "out", required_unless_present = "summary")]
    out: Option<PathBuf>,
    /// Run only shard I of N (items i with i mod N = I). Default: from SLURM_ARRAY_TASK_ID and
    /// SLURM_ARRAY_TASK_COUNT, or from JOB_COMPLETION_INDEX with --shards; else every item.
    #[arg(long, value_name = "I/N", conflicts_with = "shards")]
    shard: Option<String>,
    /// The number of shards of a Kubernetes indexed job (its `completions`).
    #[arg(long, value_name = "N")]
    shards: Option<usize>,
    /// Items run at once on this machine; the threads are split between them.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u16).range(1..))]
    jobs: u16,
    /// Seconds an item may take before it is stopped and recorded as timed out.
    #[arg(long, value_name = "SECONDS", default_value_t = 1800.0)]
    item_timeout: f64,
    /// An override for every item's `nuvo unwrap` (repeatable; the manifest's own come after).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    set: Vec<String>,
    /// Also write each item's report.html (about 1 MB of viewer and the model each; off by default
    /// for data sets of thousands of items).
    #[arg(long)]
    item_reports: bool,
    /// Write DIR/summary.md and DIR/summary.csv of a batch folder (every shard's items) and print
    /// the table; runs nothing.
    #[arg(long, value_name = "DIR", conflicts_with_all = ["manifest", "out", "shard", "shards"])]
    summary: Option<PathBuf>,
}

pub fn run(args: &BatchArgs) -> anyhow::Result<()> {
    if let Some(dir) = &args.summary {
        if !dir.is_dir() {
            anyhow::bail!("--summary {}: no such folder", dir.display());
        }
        let rows = write_summary(dir)?;
        if rows.is_empty() {
            anyhow::bail!(
                "{}: no batch items here (no {ITEMS} and no item folder with a {RECORD})",
                dir.display()
            );
        }
        println!("{}", batch_record::markdown(&rows));
        return Ok(());
    }
    let (Some(manifest_path), Some(out)) = (&args.manifest, &args.out) else {
        anyhow::bail!("give a MANIFEST and -o DIR, or --summary DIR");
    };
    if !args.item_timeout.is_finite() || args.item_timeout <= 0.0 {
        anyhow::bail!("--item-timeout {}: must be above 0 seconds", args.item_timeout);
    }
    let items = manifest::load(manifest_path)?;
    let (shard, source) = Shard::resolve(args.shard.as_deref(), args.shards, |k| std::env::var(k).ok())?;
    std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    let list = out.join(ITEMS);
    write_bytes_atomic(&list, batch_record::items_json(&items).as_bytes())
        .with_context(|| format!("cannot write {}", list.display()))?;

    let mine: Vec<&Item> = items.iter().filter(|i| shard.owns(i.index)).collect();
    let (done, todo): (Vec<&Item>, Vec<&Item>) =
        mine.iter().partition(|i| batch_record::is_done(&out.join(&i.name)));
    let from = match source {
        ShardSource::Flag => "--shard",
        ShardSource::Slurm => "SLURM_ARRAY_TASK_ID",
        ShardSource::Kubernetes => "JOB_COMPLETION_INDEX",
        ShardSource::Whole => "the whole manifest",
    };
    let jobs = usize::from(args.jobs);
    let threads = threads_per_job(jobs);
    println!(
        "shard {shard} (from {from}): {} of {} items, {} already done, {} to run, {jobs} at a time with {threads} \
         thread(s) each, on {}",
        mine.len(),
        items.len(),
        done.len(),
        todo.len(),
        host()
    );
    for d in &done {
        println!("  {}: done before, skipped", d.name);
    }

    let next = AtomicUsize::new(0);
    let finished = AtomicUsize::new(0);
    let failed = Mutex::new(Vec::new());
    let exe = std::env::current_exe().context("cannot find the nuvo binary to run items with")?;
    let timeout = Duration::from_secs_f64(args.item_timeout);
    std::thread::scope(|scope| {
        for _ in 0..jobs.min(todo.len()) {
            scope.spawn(|| {
                while let Some(item) = todo.get(next.fetch_add(1, Ordering::SeqCst)) {
                    let record = run_item(&exe, args, item, out, shard, threads, timeout);
                    let k = finished.fetch_add(1, Ordering::SeqCst) + 1;
                    match record {
                        Ok(r) if r.status == Status::Done => {
                            println!("[{k}/{}] {}: done in {:.1} s", todo.len(), item.name, r.seconds);
                        }
                        Ok(r) => {
                            let why = r.error.unwrap_or_default();
                            println!(
                                "[{k}/{}] {}: {} after {:.1} s: {why}",
                                todo.len(),
                                item.name,
                                r.status.as_str(),
                                r.seconds
                            );
                            failed.lock().unwrap_or_else(|e| e.into_inner()).push(item.name.clone());
                        }
                        Err(e) => {
                            println!("[{k}/{}] {}: not run: {}", todo.len(), item.name, crate::one_line(&e));
                            failed.lock().unwrap_or_else(|e| e.into_inner()).push(item.name.clone());
                        }
                    }
                }
            });
        }
    });
    write_summary(out)?;
    println!("wrote {} and {}", out.join(SUMMARY_MD).display(), out.join(SUMMARY_CSV).display());
    let failed = failed.into_inner().unwrap_or_else(|e| e.into_inner());
    if !failed.is_empty() {
        anyhow::bail!(
            "{} of {} items of shard {shard} did not finish: {} (each folder's {RECORD} and {ITEM_LOG} say why; a rerun \
             retries them)",
            failed.len(),
            todo.len(),
            failed.join(", ")
        );
    }
    Ok(())
}

/// The threads each of `jobs` processes at once gets (a batch's items, an ablation's shards): the
/// machine's (or `RAYON_NUM_THREADS`, if set) split evenly, at least one.
pub(crate) fn threads_per_job(jobs: usize) -> usize {
    let total = std::env::var("RAYON_NUM_THREADS")
        .ok()
        .and_then(|v| v.parse().ok())
        .filter(|&n: &usize| n > 0)
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    (total / jobs).max(1)
}

/// Starts `cmd` (this binary with a subcommand) with `threads` threads, no input, and its output
/// and errors in a new file at `log_path`: how a batch starts its items and `nuvo ablate --jobs`
/// its shards.
pub(crate) fn spawn_logged(
    cmd: &mut Command,
    log_path: &Path,
    threads: usize,
) -> anyhow::Result<std::process::Child> {
    let log =
        std::fs::File::create(log_path).with_context(|| format!("cannot write {}", log_path.display()))?;
    cmd.env("RAYON_NUM_THREADS", threads.to_string())
        .stdin(Stdio::null())
        .stdout(log.try_clone().with_context(|| format!("cannot share {}", log_path.display()))?)
        .stderr(log);
    cmd.spawn().with_context(|| format!("cannot start {}", cmd.get_program().to_string_lossy()))
}

/// This machine's name, for the records (which host ran an item, when many do).
fn host() -> String {
    std::env::var("HOSTNAME")
        .ok()
        .filter(|h| !h.is_empty())
        .or_else(|| std::fs::read_to_string("/proc/sys/kernel/hostname").ok().map(|h| h.trim().to_owned()))
        .unwrap_or_else(|| "unknown host".into())
}

/// Runs one item from scratch in `out/<name>/` and leaves its record there (module docs).
fn run_item(
    exe: &Path,
    args: &BatchArgs,
    item: &Item,
    out: &Path,
    shard: Shard,
    threads: usize,
    timeout: Duration,
) -> anyhow::Result<Record> {
    let dir = out.join(&item.name);
    if dir.exists() {
        // Not done (or it would have been skipped): what an earlier, killed or failed run left,
        // which its log marks as the batch's own. Anything else there is the user's: left alone.
        let empty = std::fs::read_dir(&dir).is_ok_and(|mut d| d.next().is_none());
        if !empty && !dir.join(ITEM_LOG).is_file() {
            anyhow::bail!(
                "{} exists and is not a batch item's folder (it has no {ITEM_LOG}); not touching it",
                dir.display()
            );
        }
        std::fs::remove_dir_all(&dir)
            .with_context(|| format!("cannot clear {} to redo it", dir.display()))?;
    }
    std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let log_path = dir.join(ITEM_LOG);
    let set: Vec<String> = args.set.iter().chain(&item.set).cloned().collect();
    let mut cmd = Command::new(exe);
    cmd.arg("unwrap").arg(&item.input).arg("-o").arg(&dir);
    for s in &set {
        cmd.arg("--set").arg(s);
    }
    if !args.item_reports {
        cmd.arg("--no-report");
    }
    let started = Instant::now();
    let mut child = spawn_logged(&mut cmd, &log_path, threads)?;
    let status = loop {
        if let Some(status) = child.try_wait().context("cannot wait for the item")? {
            break Some(status);
        }
        if started.elapsed() > timeout {
            let _ = child.kill();
            let _ = child.wait();
            break None;
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    let seconds = started.elapsed().as_secs_f64();
    let (status, error) = match status {
        Some(s) if s.success() => (Status::Done, None),
        Some(s) => {
            let why = last_error(&log_path).unwrap_or_else(|| format!("nuvo unwrap exited with {s}"));
            (Status::Failed, Some(why))
        }
        None => (
            Status::TimedOut,
            Some(format!("stopped at the item time limit of {:.0} s", timeout.as_secs_f64())),
        ),
    };
    let record = Record {
        status,
        input: item.input.clone(),
        set,
        shard: shard.to_string(),
        host: host(),
        seconds,
        error,
    };
    let path = dir.join(RECORD);
    let json = serde_json::to_string_pretty(&record).context("cannot encode the item's record")?;
    write_bytes_atomic(&path, json.as_bytes()).with_context(|| format!("cannot write {}", path.display()))?;
    Ok(record)
}

/// The last `error: ...` line of an item's log (the CLI's one-line error), without the prefix.
fn last_error(log: &Path) -> Option<String> {
    let text = std::fs::read_to_string(log).ok()?;
    let line = text.lines().rev().find(|l| l.starts_with("error: "))?;
    Some(line.trim_start_matches("error: ").to_owned())
}

/// Writes the batch folder's summary tables; returns their rows.
fn write_summary(dir: &Path) -> anyhow::Result<Vec<batch_record::Row>> {
    let rows = batch_record::summarise(dir);
    if rows.is_empty() {
        return Ok(rows);
    }
    for (name, text) in [(SUMMARY_MD, batch_record::markdown(&rows)), (SUMMARY_CSV, batch_record::csv(&rows))]
    {
        let path = dir.join(name);
        write_bytes_atomic(&path, text.as_bytes())
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    Ok(rows)
}
