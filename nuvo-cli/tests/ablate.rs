//! End-to-end test of `nuvo ablate`: a tiny sweep on the bundled bunny with one variant that cannot
//! run, checking the table, the per-variant folders, that the failure is reported and not fatal, and
//! that `--resume` reuses finished variants.

use std::path::{Path, PathBuf};

mod common;
use common::{SMALLEST_MODEL, nuvo, repo, run};

fn sweep_config(dir: &Path) -> PathBuf {
    let bunny = repo().join("assets/stanford-bunny.obj");
    let text = format!(
        r#"seed = 1
[geometry]
source = "mesh"
path = {bunny:?}
{SMALLEST_MODEL}
[training]
steps = 3
batch_3d = 128
batch_uv = 128
[losses.cycle_3d]
[losses.cycle_2d]
[losses.surface]
[losses.texture]
[output]
atlas_resolution = 64
eval_views = 1
eval_resolution = 48
renders = 0
[ablation]
remove_each = ["texture", "surface"]
[[ablation.variants]]
name = "n=1"
set = ["model.charts=1"]
[[ablation.variants]]
name = "broken"
set = ["model.charts=0"]
"#
    );
    let p = dir.join("sweep.toml");
    std::fs::write(&p, text).unwrap();
    p
}

#[test]
fn a_sweep_writes_the_table_and_reports_a_failed_variant_without_stopping() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = sweep_config(dir.path());
    let out = dir.path().join("sweep");
    let o = run(nuvo().arg("ablate").arg(&cfg).arg("--out").arg(&out));
    assert!(!o.status.success(), "a failed variant makes the exit status non-zero");
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(stderr.contains("1 of 5 variants failed"), "{stderr}");

    let csv = std::fs::read_to_string(out.join("ablation.csv")).unwrap();
    let rows: Vec<Vec<&str>> = csv.lines().skip(1).map(|l| l.split(',').collect()).collect();
    let names: Vec<&str> = rows.iter().map(|r| r[0]).collect();
    assert_eq!(names, ["base", "w/o texture", "w/o surface", "n=1", "broken"]);
    for r in &rows[..4] {
        assert_eq!(r[10], "ok", "{r:?}");
        for v in &r[2..8] {
            let v: f64 = v.parse().unwrap();
            assert!((0.0..=1.0).contains(&v), "{r:?}");
        }
        assert_eq!(r[8], "3", "steps");
    }
    assert_eq!(rows[4][10], "failed");
    let broken = csv.lines().last().unwrap();
    assert!(broken.contains("model.charts") && broken.contains("must be at least 1"), "{csv}");
    let md = std::fs::read_to_string(out.join("ablation.md")).unwrap();
    assert!(md.contains("| w/o texture |") && md.contains("| broken | failed:"), "{md}");

    // Removing a loss really removes it from the variant's resolved config and its log.
    let resolved = std::fs::read_to_string(out.join("wo_texture/config.toml")).unwrap();
    assert!(!resolved.contains("[losses.texture]") && resolved.contains("[losses.surface]"), "{resolved}");
    assert!(!resolved.contains("[ablation]"), "{resolved}");
    let log = std::fs::read_to_string(out.join("wo_texture/log.jsonl")).unwrap();
    assert!(!log.contains("\"texture\"") && log.contains("\"surface\""));
    assert!(std::fs::read_to_string(out.join("n-1/config.toml")).unwrap().contains("charts = 1"));
    assert!(out.join("base/atlas.obj").exists() && out.join("n-1/metrics.json").exists());

    // The sweep's report shows every variant that ran, by its name, in the table's order.
    let report = std::fs::read_to_string(out.join("report.html")).unwrap();
    let columns: Vec<&str> =
        report.split("<article class=\"run\"").skip(1).map(|a| a.split("</h3>").next().unwrap()).collect();
    assert_eq!(columns.len(), 4, "the broken variant has no folder");
    for (column, name) in columns.iter().zip(["base", "w/o texture", "w/o surface", "n=1"]) {
        assert!(column.ends_with(name), "{column}");
    }

    // --resume reuses the finished variants: the table is the same and nothing is retrained.
    let before = std::fs::metadata(out.join("base/checkpoint.safetensors")).unwrap().modified().unwrap();
    let o = run(nuvo()
        .arg("ablate")
        .arg(&cfg)
        .arg("--out")
        .arg(&out)
        .arg("--resume")
        .args(["--only", "base", "--only", "n=1"]));
    assert!(o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("reusing its metrics"));
    let after = std::fs::metadata(out.join("base/checkpoint.safetensors")).unwrap().modified().unwrap();
    assert_eq!(before, after);
    let csv2 = std::fs::read_to_string(out.join("ablation.csv")).unwrap();
    assert_eq!(csv2.lines().nth(1).unwrap().split(',').take(9).collect::<Vec<_>>(), rows[0][..9]);
}

#[test]
fn unknown_variant_names_list_the_planned_ones() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = sweep_config(dir.path());
    let o = run(nuvo().arg("ablate").arg(&cfg).args(["--only", "nope", "--dry-run"]));
    assert!(!o.status.success());
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(
        stderr.contains("--only nope") && stderr.contains("wo_texture, wo_surface, n-1, broken"),
        "{stderr}"
    );
}

#[test]
fn a_sweep_spread_over_an_array_is_collected_into_one_table() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = sweep_config(dir.path());
    let out = dir.path().join("sweep");
    let ablate = |extra: &[&str], env: &[(&str, &str)]| {
        let mut cmd = nuvo();
        cmd.arg("ablate").arg(&cfg).arg("--out").arg(&out).args(extra);
        for var in
            ["SLURM_ARRAY_TASK_ID", "SLURM_ARRAY_TASK_COUNT", "SLURM_ARRAY_TASK_MIN", "JOB_COMPLETION_INDEX"]
        {
            cmd.env_remove(var);
        }
        run(cmd.envs(env.iter().copied()))
    };
    // Before any shard ran, --collect says what is missing.
    let o = ablate(&["--collect"], &[]);
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stdout).contains("not run yet"));
    std::fs::remove_file(out.join("ablation.csv")).unwrap();

    // Plan: base, w/o texture, w/o surface, n=1, broken. Shard 0 of 2 (a Slurm array task) has
    // base, w/o surface and broken; shard 1 (by flag) has w/o texture and n=1.
    let o = ablate(&[], &[("SLURM_ARRAY_TASK_ID", "0"), ("SLURM_ARRAY_TASK_COUNT", "2")]);
    assert_eq!(o.status.code(), Some(1), "its broken variant fails the shard");
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("shard 0/2: 3 variant(s): base, w/o surface, broken"), "{stdout}");
    assert!(!out.join("ablation.csv").exists(), "a shard writes no table of its own");
    let o = ablate(&["--shard", "1/2"], &[]);
    assert!(o.status.success());
    assert!(out.join("wo_texture/metrics.json").exists() && out.join("base/metrics.json").exists());

    let o = ablate(&["--collect"], &[]);
    assert_eq!(o.status.code(), Some(1), "the broken variant is still missing");
    let csv = std::fs::read_to_string(out.join("ablation.csv")).unwrap();
    let rows: Vec<Vec<&str>> = csv.lines().skip(1).map(|l| l.split(',').collect()).collect();
    let status: Vec<(&str, &str)> = rows.iter().map(|r| (r[0], r[10])).collect();
    assert_eq!(
        status,
        [("base", "ok"), ("w/o texture", "ok"), ("w/o surface", "ok"), ("n=1", "ok"), ("broken", "failed")]
    );
    assert!(csv.lines().last().unwrap().contains("must be at least 1"), "{csv}");
    let report = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert_eq!(report.matches("<article class=\"run\"").count(), 4);
}

#[test]
fn jobs_train_variants_at_once_as_shards_and_collect_them() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = sweep_config(dir.path());
    let out = dir.path().join("sweep");
    let o = run(nuvo().arg("ablate").arg(&cfg).arg("--out").arg(&out).args([
        "--jobs",
        "2",
        "--only",
        "base",
        "--only",
        "n=1",
        "--only",
        "w/o texture",
    ]));
    assert!(o.status.success());
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("2 shards running") && stdout.contains("shard 1/2 ended"), "{stdout}");
    for k in 0..2 {
        let log = std::fs::read_to_string(out.join(format!("ablate-shard-{k}.log"))).unwrap();
        assert!(log.contains(&format!("shard {k}/2:")), "{log}");
    }
    let csv = std::fs::read_to_string(out.join("ablation.csv")).unwrap();
    let rows: Vec<(&str, &str)> =
        csv.lines().skip(1).map(|l| l.split(',').collect::<Vec<_>>()).map(|r| (r[0], r[10])).collect();
    assert_eq!(rows, [("base", "ok"), ("w/o texture", "ok"), ("n=1", "ok")]);
    assert!(out.join("report.html").is_file());
}
