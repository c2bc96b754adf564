//! Fuzz the input parsers for a while: `cargo run --release -p nuvo-tests --example fuzz -- [TARGET|all]
//! [SECONDS per target] [SEED]`. Targets: npy, obj, glb, gltf, ply, xyz, toml. Inputs that make a
//! reader panic are written to `tests/fuzz-findings/` (replayed by `tests/tests/fuzz.rs`), and the
//! exit status is 1.

use std::path::Path;
use std::time::Duration;

use nuvo_tests::fuzz::{Target, fuzz};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let which = args.first().map(String::as_str).unwrap_or("all");
    let seconds: u64 = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(60);
    let seed: u64 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(1);
    let targets: Vec<Target> = if which == "all" {
        Target::ALL.to_vec()
    } else {
        match Target::from_name(which) {
            Some(t) => vec![t],
            None => {
                let names: Vec<&str> = Target::ALL.iter().map(|t| t.name()).collect();
                eprintln!("error: unknown target `{which}`; targets: all, {}", names.join(", "));
                std::process::exit(2);
            }
        }
    };
    let findings_dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz-findings");
    let scratch = tempfile::tempdir().expect("a scratch folder");
    let mut found = 0;
    for t in targets {
        let report = fuzz(t, seed, u64::MAX, Duration::from_secs(seconds), scratch.path());
        println!("{:>5}: {} inputs in {seconds} s, {} panics", t.name(), report.runs, report.findings.len());
        for (k, (input, message)) in report.findings.iter().enumerate() {
            let path = findings_dir.join(format!("seed{seed}-{k}.{}", t.name()));
            std::fs::write(&path, input).expect("the findings folder is writable");
            println!("       panic: {message} -> {}", path.display());
            found += 1;
        }
    }
    if found > 0 {
        std::process::exit(1);
    }
}
