//! Every malformed input of the generated corpus (`nuvo-tests::corpus`) through the real CLI: a
//! non-zero exit with a one-paragraph error naming the file and the problem, no panic, no hang, and
//! no output left looking complete.

use std::path::Path;
use std::process::Stdio;
use std::time::{Duration, Instant};

use nuvo_tests::corpus::{self, Case, Kind};

mod common;
use common::nuvo;

/// Runs `nuvo args...`, killing it after `limit`; returns (exit code, stderr).
fn run_limited(args: &[&std::ffi::OsStr], limit: Duration) -> (Option<i32>, String) {
    let mut child =
        nuvo().args(args).stdout(Stdio::null()).stderr(Stdio::piped()).spawn().expect("nuvo starts");
    let started = Instant::now();
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            let mut err = String::new();
            std::io::Read::read_to_string(child.stderr.as_mut().unwrap(), &mut err).unwrap();
            return (status.code(), err);
        }
        if started.elapsed() > limit {
            child.kill().unwrap();
            panic!("nuvo {args:?} hung for more than {limit:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn file_name(p: &Path) -> String {
    p.file_name().unwrap().to_string_lossy().into_owned()
}

/// The checks every failure must pass; returns a description of what is wrong, if anything.
fn judge(case: &Case, what: &str, code: Option<i32>, err: &str, out: Option<&Path>) -> Option<String> {
    let bad = |why: &str| Some(format!("{} ({what}): {why}\n--- stderr ---\n{err}", case.name));
    if code != Some(1) {
        return bad(&format!("exit code {code:?}, expected 1"));
    }
    if err.contains("panicked") || err.contains("RUST_BACKTRACE") {
        return bad("panicked");
    }
    let text = err.trim();
    if !text.starts_with("error: ") || text.contains("\n\n") || text.len() > 1200 {
        return bad("not a one-paragraph `error: ...` message");
    }
    let lower = text.to_lowercase();
    let names_file = lower.contains(&file_name(&case.input).to_lowercase())
        || (case.kind == Kind::Config && lower.contains(&file_name(&case.config).to_lowercase()));
    if !names_file {
        return bad("the message does not name the file");
    }
    if let Some(w) = case.expect.iter().find(|w| !lower.contains(&w.to_lowercase())) {
        return bad(&format!("the message does not say `{w}`"));
    }
    if let Some(out) = out {
        for f in ["checkpoint.safetensors", "metrics.json", "atlas.obj", "atlas.glb"] {
            if out.join(f).exists() {
                return bad(&format!("left {f} behind"));
            }
        }
    }
    None
}

#[test]
fn every_malformed_input_fails_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let cases = corpus::write(dir.path());
    let limit = Duration::from_secs(120);
    let mut failures = Vec::new();
    for case in &cases {
        let out = dir.path().join(format!("out_{}", case.name));
        let (code, err) = run_limited(
            &["train".as_ref(), case.config.as_os_str(), "--out".as_ref(), out.as_os_str()],
            limit,
        );
        eprintln!("{:<28} train: {}", case.name, err.trim());
        failures.extend(judge(case, "train", code, &err, Some(&out)));
        if case.kind == Kind::Mesh {
            let (code, err) = run_limited(&["eval".as_ref(), case.input.as_os_str()], limit);
            eprintln!("{:<28} eval:  {}", case.name, err.trim());
            failures.extend(judge(case, "eval", code, &err, None));
        }
    }
    assert!(
        failures.is_empty(),
        "{} of {} cases failed:\n\n{}",
        failures.len(),
        cases.len(),
        failures.join("\n\n")
    );
}
