//! `nuvo batch` as a scheduler runs it: shards from Slurm's and Kubernetes' environment variables
//! covering a manifest exactly once, a shard killed mid-item and rerun, a broken item and an item
//! over its time limit recorded while the rest finish, and the summary of every item.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

mod common;
use common::{FAST_UNWRAP, nuvo, run};

/// A closed latitude-longitude ellipsoid with radii `r`, written as OBJ.
fn write_ellipsoid(path: &Path, r: [f64; 3], rings: usize, segments: usize) {
    let mut text = format!("v 0 0 {}\n", r[2]);
    for i in 1..rings {
        let theta = std::f64::consts::PI * i as f64 / rings as f64;
        for s in 0..segments {
            let phi = std::f64::consts::TAU * s as f64 / segments as f64;
            let (x, y, z) = (theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos());
            text += &format!("v {} {} {}\n", r[0] * x, r[1] * y, r[2] * z);
        }
    }
    text += &format!("v 0 0 {}\n", -r[2]);
    let ring = |i: usize, s: usize| 2 + (i - 1) * segments + s % segments;
    let last = 2 + (rings - 1) * segments;
    for s in 0..segments {
        text += &format!("f 1 {} {}\n", ring(1, s), ring(1, s + 1));
        for i in 1..rings - 1 {
            let (a, b, c, d) = (ring(i, s), ring(i + 1, s), ring(i + 1, s + 1), ring(i, s + 1));
            text += &format!("f {a} {b} {c}\nf {a} {c} {d}\n");
        }
        text += &format!("f {last} {} {}\n", ring(rings - 1, s + 1), ring(rings - 1, s));
    }
    std::fs::write(path, text).unwrap();
}

/// `n` small meshes of different shapes in `dir/meshes/`, and a text manifest of them.
fn manifest_of(dir: &Path, names: &[&str]) -> PathBuf {
    std::fs::create_dir_all(dir.join("meshes")).unwrap();
    let mut lines = String::from("# the test's meshes\n");
    for (k, name) in names.iter().enumerate() {
        let path = dir.join("meshes").join(format!("{name}.obj"));
        if *name == "broken" {
            std::fs::write(&path, "v 0 0 0\nv 1 0 0\nf 1 2 3\n").unwrap(); // a face on a missing vertex
        } else {
            let f = 1.0 + 0.25 * k as f64;
            write_ellipsoid(&path, [0.6 * f, 0.35, 0.3 + 0.1 * k as f64], 8 + k, 12 + 2 * k);
        }
        lines += &format!("meshes/{name}.obj\n");
    }
    let m = dir.join("manifest.txt");
    std::fs::write(&m, lines).unwrap();
    m
}

/// `nuvo batch MANIFEST -o OUT --set FAST_UNWRAP...` with `extra` arguments and `env`.
fn batch(manifest: &Path, out: &Path, extra: &[&str], env: &[(&str, &str)]) -> Command {
    let mut cmd = nuvo();
    cmd.arg("batch").arg(manifest).arg("-o").arg(out).args(extra);
    for s in FAST_UNWRAP {
        cmd.args(["--set", s]);
    }
    for var in
        ["SLURM_ARRAY_TASK_ID", "SLURM_ARRAY_TASK_COUNT", "SLURM_ARRAY_TASK_MIN", "JOB_COMPLETION_INDEX"]
    {
        cmd.env_remove(var);
    }
    cmd.envs(env.iter().copied());
    cmd
}

fn record(item_dir: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(item_dir.join("batch.json"))
        .unwrap_or_else(|e| panic!("{}: no batch.json: {e}", item_dir.display()));
    serde_json::from_str(&text).unwrap()
}

#[test]
fn three_shards_from_the_schedulers_variables_cover_every_item_exactly_once() {
    let dir = tempfile::tempdir().unwrap();
    let names = ["m0", "m1", "m2", "m3", "m4", "m5"];
    let manifest = manifest_of(dir.path(), &names);
    let out = dir.path().join("out");
    // Shard 0 and 1 as Slurm array tasks (the second array starts at 10), shard 2 as a
    // Kubernetes indexed-job pod.
    type Shard<'a> = (&'a [&'a str], &'a [(&'a str, &'a str)]);
    let shards: [Shard; 3] = [
        (&[], &[("SLURM_ARRAY_TASK_ID", "0"), ("SLURM_ARRAY_TASK_COUNT", "3")]),
        (
            &[],
            &[("SLURM_ARRAY_TASK_ID", "11"), ("SLURM_ARRAY_TASK_COUNT", "3"), ("SLURM_ARRAY_TASK_MIN", "10")],
        ),
        (&["--shards", "3"], &[("JOB_COMPLETION_INDEX", "2")]),
    ];
    for (k, (extra, env)) in shards.iter().enumerate() {
        let o = run(&mut batch(&manifest, &out, extra, env));
        assert!(o.status.success());
        let stdout = String::from_utf8_lossy(&o.stdout);
        assert!(stdout.contains(&format!("shard {k}/3")) && stdout.contains("2 of 6 items"), "{stdout}");
    }
    for (i, name) in names.iter().enumerate() {
        let item = out.join(name);
        let r = record(&item);
        assert_eq!(r["status"], "done", "{name}: {r}");
        assert_eq!(r["shard"], format!("{}/3", i % 3), "item {i} belongs to shard i mod 3");
        assert!(item.join("atlas.obj").is_file() && item.join("metrics.json").is_file(), "{name}");
        assert!(!item.join("report.html").exists(), "no per-item reports unless asked");
        assert!(
            std::fs::read_to_string(item.join("batch.log")).unwrap().contains("done in"),
            "the item's log"
        );
    }
    // Each shard ran only its items: a shard rerun finds them all done.
    let o = run(&mut batch(&manifest, &out, &["--shard", "1/3"], &[]));
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success() && stdout.contains("2 already done, 0 to run"), "{stdout}");

    let o = run(nuvo().arg("batch").arg("--summary").arg(&out));
    assert!(o.status.success());
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.starts_with("6 items: 6 done"), "{stdout}");
    let csv = std::fs::read_to_string(out.join("summary.csv")).unwrap();
    let rows: Vec<Vec<&str>> = csv.lines().skip(1).map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.iter().map(|r| r[0]).collect::<Vec<_>>(), names);
    for r in &rows {
        let editability: f64 = r[4].parse().unwrap();
        assert!(r[2] == "done" && (0.0..=1.0).contains(&editability), "{r:?}");
    }
}

#[test]
fn a_killed_shard_reruns_only_what_did_not_finish_and_a_broken_item_is_recorded() {
    let dir = tempfile::tempdir().unwrap();
    manifest_of(dir.path(), &["first", "second", "broken", "third"]);
    // A CSV manifest with a per-item override: the second item trains long enough to be killed.
    let manifest = dir.path().join("manifest.csv");
    std::fs::write(
        &manifest,
        "input,name,set\nmeshes/first.obj,,\nmeshes/second.obj,,training.steps=600;training.stop_when_settled=0.0;model.width=64;model.depth=3\nmeshes/broken.obj,,\nmeshes/third.obj,,\n",
    )
    .unwrap();
    let out = dir.path().join("out");

    // Kill the whole batch (its process group, as a scheduler does) once the second item started.
    let mut cmd = batch(&manifest, &out, &[], &[]);
    std::os::unix::process::CommandExt::process_group(&mut cmd, 0);
    let mut child = cmd.stdout(std::process::Stdio::null()).spawn().unwrap();
    let started = Instant::now();
    while !out.join("second").join("batch.log").exists() {
        assert!(started.elapsed() < Duration::from_secs(120), "the second item never started");
        assert!(child.try_wait().unwrap().is_none(), "the batch ended before it could be killed");
        std::thread::sleep(Duration::from_millis(20));
    }
    let killed = Command::new("kill").args(["-KILL", "--", &format!("-{}", child.id())]).status().unwrap();
    assert!(killed.success());
    child.wait().unwrap();
    assert_eq!(record(&out.join("first"))["status"], "done");
    assert!(
        !out.join("second").join("batch.json").exists(),
        "the killed item has no record: {:?}",
        std::fs::read_to_string(out.join("second").join("batch.json"))
    );
    let first_record = std::fs::read(out.join("first").join("batch.json")).unwrap();
    let first_atlas = std::fs::metadata(out.join("first").join("atlas.obj")).unwrap().modified().unwrap();

    let o = run(&mut batch(&manifest, &out, &["--jobs", "2"], &[]));
    assert_eq!(o.status.code(), Some(1), "a failed item makes the batch fail, after the rest");
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        stdout.contains("1 already done, 3 to run") && stdout.contains("first: done before, skipped"),
        "{stdout}"
    );
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(stderr.contains("1 of 3 items") && stderr.contains("broken"), "{stderr}");
    // The finished item was not redone; the killed one was, from scratch; the others finished.
    assert_eq!(std::fs::read(out.join("first").join("batch.json")).unwrap(), first_record);
    assert_eq!(
        std::fs::metadata(out.join("first").join("atlas.obj")).unwrap().modified().unwrap(),
        first_atlas
    );
    for name in ["second", "third"] {
        assert_eq!(record(&out.join(name))["status"], "done", "{name}");
    }
    let broken = record(&out.join("broken"));
    assert_eq!(broken["status"], "failed");
    let why = broken["error"].as_str().unwrap();
    assert!(why.contains("broken.obj"), "the error names the file: {why}");
    let md = std::fs::read_to_string(out.join("summary.md")).unwrap();
    assert!(md.starts_with("4 items: 3 done, 1 failed"), "{md}");
}

#[test]
fn an_item_over_its_time_limit_is_stopped_and_recorded() {
    let dir = tempfile::tempdir().unwrap();
    let manifest = manifest_of(dir.path(), &["slow"]);
    let out = dir.path().join("out");
    // Far more steps than 0.2 s allow on any machine (a fast one once finished the item in time),
    // on one chart, which no settling stops early.
    let mut cmd = batch(&manifest, &out, &["--item-timeout", "0.2"], &[]);
    let o = run(cmd.args(["--set", "training.steps=10000000", "--set", "model.charts=1"]));
    assert_eq!(o.status.code(), Some(1), "{}", String::from_utf8_lossy(&o.stdout));
    let r = record(&out.join("slow"));
    assert_eq!(r["status"], "timed out", "{r}");
    assert!(r["seconds"].as_f64().unwrap() < 30.0);
}

#[test]
fn bad_manifests_and_shards_are_refused_before_anything_runs() {
    let dir = tempfile::tempdir().unwrap();
    let manifest = manifest_of(dir.path(), &["a"]);
    let out = dir.path().join("out");
    for (extra, env, says) in [
        (&["--shard", "3/3"][..], &[][..], "expected I/N"),
        (&[], &[("JOB_COMPLETION_INDEX", "0")][..], "--shards N"),
        (&[], &[("SLURM_ARRAY_TASK_ID", "4"), ("SLURM_ARRAY_TASK_COUNT", "2")][..], "--array=0-1"),
    ] {
        let o = run(&mut batch(&manifest, &out, extra, env));
        assert_eq!(o.status.code(), Some(1));
        assert!(String::from_utf8_lossy(&o.stderr).contains(says), "{}", String::from_utf8_lossy(&o.stderr));
    }
    assert!(!out.exists(), "nothing written");
    // A folder of the user's where an item's would go is never cleared.
    std::fs::create_dir_all(out.join("a")).unwrap();
    std::fs::write(out.join("a").join("mine.txt"), "keep").unwrap();
    let o = run(&mut batch(&manifest, &out, &[], &[]));
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stdout).contains("is not a batch item's folder"));
    assert_eq!(std::fs::read_to_string(out.join("a").join("mine.txt")).unwrap(), "keep");
    std::fs::remove_dir_all(&out).unwrap();
    let empty = dir.path().join("empty.txt");
    std::fs::write(&empty, "# nothing\n").unwrap();
    let o = run(&mut batch(&empty, &out, &[], &[]));
    assert!(String::from_utf8_lossy(&o.stderr).contains("empty.txt: the manifest lists no items"));
    let o = run(nuvo().arg("batch").arg("--summary").arg(dir.path().join("meshes")));
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("no batch items here"));
}
