//! The fuzzer's regression suite: every finding kept in `tests/fuzz-findings/` is read without a
//! panic, and a short deterministic fuzzing session per parser finds nothing.

use std::path::Path;
use std::time::Duration;

use nuvo_tests::fuzz::{Target, findings_in, fuzz};

#[test]
fn kept_findings_no_longer_panic() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz-findings");
    let scratch = tempfile::tempdir().unwrap();
    let mut replayed = 0;
    for t in Target::ALL {
        let findings = findings_in(&dir, t);
        // Hand-minimised hostile inputs (overflowing sizes, indices past the end, non-finite
        // values) keep every reader's error paths covered even while the fuzzer finds nothing.
        assert!(!findings.is_empty(), "no kept input for {}", t.name());
        for f in findings {
            let bytes = std::fs::read(&f).unwrap();
            let outcome = t.check(&bytes, scratch.path());
            assert!(outcome.is_ok(), "{}: {outcome:?}", f.display());
            // The hand-made ones are broken on purpose: each must reach its reader's error path.
            let invalid = f.file_name().unwrap().to_string_lossy().starts_with("invalid-");
            assert!(!invalid || outcome == Ok(false), "{} was accepted", f.display());
            replayed += 1;
        }
    }
    // A file no target reads would be silently skipped: name it instead.
    let files = std::fs::read_dir(&dir).unwrap().count();
    assert_eq!(files, replayed, "{} holds files of no fuzz target", dir.display());
}

#[test]
fn a_short_session_per_parser_finds_no_panic() {
    let scratch = tempfile::tempdir().unwrap();
    for t in Target::ALL {
        let report = fuzz(t, 7, 400, Duration::from_secs(60), scratch.path());
        assert!(report.runs >= 100, "{}: only {} runs", t.name(), report.runs);
        let messages: Vec<&String> = report.findings.iter().map(|(_, m)| m).collect();
        assert!(messages.is_empty(), "{}: {messages:?}", t.name());
    }
}
