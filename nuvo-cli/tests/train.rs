//! End-to-end tests of `nuvo train` and `nuvo bake` as a user runs them: a real process on the
//! bundled bunny, with tiny networks so the suite stays fast.

use std::path::Path;
use std::time::{Duration, Instant};

mod common;
use common::{nuvo, run, tiny_config, train_unbaked};

#[test]
fn train_writes_every_output_a_script_relies_on() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = tiny_config(dir.path(), 12, 5);
    let out_dir = dir.path().join("run");
    let out = run(nuvo().arg("train").arg(&cfg).arg("--out").arg(&out_dir));
    assert!(out.status.success());
    for f in [
        "config.toml",
        "log.jsonl",
        "checkpoint.safetensors",
        "atlas.obj",
        "atlas.mtl",
        "atlas.glb",
        "uv_layout.png",
        "checker.png",
        "normal_grids.png",
        "metrics.json",
        "renders/view_0.png",
    ] {
        assert!(out_dir.join(f).is_file(), "{f} missing");
    }
    let m: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out_dir.join("metrics.json")).unwrap()).unwrap();
    for k in ["boundary", "stretch", "conformal", "editability"] {
        let v = m["metrics"]["image"][k].as_f64().unwrap();
        assert!((0.0..=1.0).contains(&v), "{k} = {v}");
    }
    assert_eq!(m["steps"], 12);
    assert_eq!(m["bake"]["faces"], 69451);
    let log = std::fs::read_to_string(out_dir.join("log.jsonl")).unwrap();
    assert_eq!(log.lines().count(), 12);
    // The OBJ reads back with UVs on every face.
    let mesh = nuvo_geometry_probe(&out_dir.join("atlas.obj"));
    assert_eq!(mesh, (69451, true));
}

/// Face count and whether UVs are present, read with a minimal OBJ scan (no crate dependency).
fn nuvo_geometry_probe(path: &Path) -> (usize, bool) {
    let text = std::fs::read_to_string(path).unwrap();
    let faces: Vec<&str> = text.lines().filter(|l| l.starts_with("f ")).collect();
    (faces.len(), faces.iter().all(|f| f.split_whitespace().skip(1).all(|c| c.contains('/'))))
}

#[test]
fn a_run_killed_mid_way_resumes_to_the_same_parameters() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = tiny_config(dir.path(), 80, 10);
    let full = dir.path().join("full");
    assert!(train_unbaked(&cfg, &full).status.success());

    let killed = dir.path().join("killed");
    let mut child = nuvo().arg("train").arg(&cfg).arg("--out").arg(&killed).arg("--no-bake").spawn().unwrap();
    // Kill (SIGKILL) once a few checkpoints exist but before the end.
    let log = killed.join("log.jsonl");
    let start = Instant::now();
    loop {
        let lines = std::fs::read_to_string(&log).map(|t| t.lines().count()).unwrap_or(0);
        if lines >= 35 || start.elapsed() > Duration::from_secs(120) {
            break;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    child.kill().unwrap();
    let status = child.wait().unwrap();
    assert!(!status.success(), "the run finished before it could be killed; raise its step count");
    let out = run(nuvo().arg("train").arg(&cfg).arg("--out").arg(&killed).arg("--no-bake").arg("--resume"));
    assert!(out.status.success());
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("resuming from step")
            || String::from_utf8_lossy(&out.stdout).contains("resuming from step")
    );
    let a = std::fs::read(full.join("checkpoint.safetensors")).unwrap();
    let b = std::fs::read(killed.join("checkpoint.safetensors")).unwrap();
    assert!(a == b, "the resumed run's checkpoint differs from the uninterrupted run's");
    let lines: Vec<serde_json::Value> = std::fs::read_to_string(log)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
        .collect();
    let steps: Vec<u64> = lines.iter().map(|l| l["step"].as_u64().unwrap()).collect();
    assert_eq!(steps, (0..80).collect::<Vec<_>>(), "log has gaps or duplicates");
    // `seconds` counts on across the resume instead of restarting at 0.
    let seconds: Vec<f64> = lines.iter().map(|l| l["seconds"].as_f64().unwrap()).collect();
    assert!(seconds.windows(2).all(|w| w[1] >= w[0]), "seconds went back: {seconds:?}");
}

#[test]
fn bake_redoes_the_outputs_from_a_run_folder() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = tiny_config(dir.path(), 6, 3);
    let run_dir = dir.path().join("run");
    assert!(train_unbaked(&cfg, &run_dir).status.success());
    assert!(!run_dir.join("atlas.obj").exists());
    let baked = dir.path().join("baked");
    // From another working directory: the run folder is self-contained.
    let out = run(nuvo().current_dir(dir.path()).arg("bake").arg(&run_dir).arg("--out").arg(&baked));
    assert!(out.status.success());
    assert!(baked.join("atlas.glb").is_file() && baked.join("metrics.json").is_file());
    let metrics = |dir: &Path| -> serde_json::Value {
        serde_json::from_slice(&std::fs::read(dir.join("metrics.json")).unwrap()).unwrap()
    };
    let plain = metrics(&baked);
    assert_eq!(plain["bake"]["reassigned_faces"], 0, "the round-trip check is off by default");
    assert_eq!(plain["bake"]["untangle_moves"], 0, "untangling is off by default");
    assert_eq!(plain["bake"]["flipped_before_untangle"], plain["bake"]["flipped_faces"]);
    // The bake counts at the atlas's resolution (the tiny config's 256), the metrics at 1024.
    assert_eq!(plain["bake"]["raster_resolution"], 256);
    assert_eq!(plain["metrics"]["uv"]["raster_resolution"], 1024);
    // `--set` edits the stored config for this bake; a typo is named.
    let checked = dir.path().join("checked");
    let set = [
        "--set",
        "output.round_trip_tolerance=0.1",
        "--set",
        "output.renders=0",
        "--set",
        "output.untangle=true",
    ];
    let out = run(nuvo().arg("bake").arg(&run_dir).args(set).arg("--out").arg(&checked));
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let bake = &metrics(&checked)["bake"];
    assert!(bake["reassigned_faces"].is_u64());
    // A 6-step run folds plenty; untangling turns faces back and never adds a flip.
    let count = |key: &str| bake[key].as_u64().unwrap();
    assert!(count("flipped_before_untangle") > 0, "{bake}");
    assert!(
        count("untangle_moves") > 0 && count("flipped_faces") < count("flipped_before_untangle"),
        "{bake}"
    );
    assert!(!checked.join("renders").exists(), "output.renders=0 was not applied");
    let out = run(nuvo().arg("bake").arg(&run_dir).args(["--set", "output.round_trip_tolerans=0.1"]));
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("output.round_trip_tolerans") && err.contains("round_trip_tolerance"), "{err}");
}

#[test]
fn bake_needs_the_checkpoint_and_the_geometry_but_not_the_loss_plugins() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = tiny_config(dir.path(), 4, 2);
    let run_dir = dir.path().join("run");
    assert!(train_unbaked(&cfg, &run_dir).status.success());
    let bake = |out: &str, set: &[&str]| {
        let mut cmd = nuvo();
        cmd.arg("bake").arg(&run_dir).arg("--out").arg(dir.path().join(out));
        for s in set {
            cmd.args(["--set", s]);
        }
        run(&mut cmd)
    };
    assert!(bake("before", &[]).status.success());
    // The run's config now names a loss plugin that is not on disk: training could not go on, but
    // baking builds no losses and gives the same atlas.
    let path = run_dir.join("checkpoint.safetensors");
    let mut ckpt = nuvo_core::Checkpoint::load(&path).unwrap();
    ckpt.config_toml.push_str("\n[losses.gone]\nplugin = \"/nonexistent/libgone.so\"\n");
    ckpt.save(&path).unwrap();
    let out = bake("after", &[]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    for file in ["atlas.obj", "atlas.glb", "metrics.json"] {
        let read = |d: &str| std::fs::read(dir.path().join(d).join(file)).unwrap();
        assert!(read("before") == read("after"), "{file} differs");
    }
    // Other geometry than the atlas was trained on is named, not baked.
    let other = dir.path().join("tetra.obj");
    std::fs::write(&other, "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n")
        .unwrap();
    let set_other = format!("geometry.path={:?}", other.display().to_string());
    let out = bake("other", &[&set_other]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("tetra.obj") && err.contains("not the geometry") && err.contains("output.bake_mesh"),
        "{err}"
    );
    // With `output.bake_mesh` the configured geometry is not even read.
    let bunny = common::repo().join("assets/stanford-bunny.obj");
    let set_mesh = format!("output.bake_mesh={:?}", bunny.display().to_string());
    let out = bake("onto", &["geometry.path=\"/nonexistent.obj\"", &set_mesh]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let read = |d: &str| std::fs::read(dir.path().join(d).join("metrics.json")).unwrap();
    assert!(read("onto") == read("before"), "baking onto the same mesh by path gives the same atlas");
}

#[test]
fn bench_times_the_steps_of_a_trained_run_with_overrides() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = tiny_config(dir.path(), 4, 2);
    let run_dir = dir.path().join("run");
    assert!(train_unbaked(&cfg, &run_dir).status.success());
    let bench = |set: &str| {
        run(nuvo().args(["bench", "step", "--iters", "2", "--from"]).arg(&run_dir).args(["--set", set]))
    };
    let out = bench("training.chart_support=0.25");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("chart_support 0.25") && text.contains("median"), "{text}");
    let out = bench("training.chart_suport=0.25");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("training.chart_suport") && err.contains("chart_support"), "{err}");
}

#[test]
fn config_mistakes_exit_non_zero_with_the_file_line_and_choices() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = tiny_config(dir.path(), 5, 5);
    let text = std::fs::read_to_string(&cfg).unwrap();
    let cases: Vec<(&str, String, Vec<&str>)> = vec![
        (
            "typo",
            text.replace("width = 24", "widht = 24"),
            vec!["tiny.toml line 8", "model.widht", "`width`"],
        ),
        ("wrong type", text.replace("steps = 5", "steps = \"five\""), vec!["training.steps", "line 11"]),
        (
            "zero size",
            text.replace("batch_3d = 256", "batch_3d = 0"),
            vec!["training.batch_3d", "at least 1"],
        ),
        ("unknown loss", format!("{text}[losses.strech]\n"), vec!["losses.strech", "stretch"]),
        (
            "unknown source",
            text.replace("\"mesh\"", "\"meshh\""),
            vec!["geometry.source", "mesh", "point_cloud"],
        ),
        ("syntax", text.replace("[model]", "[model"), vec!["tiny.toml", "line 5"]),
        ("missing mesh", text.replace("stanford-bunny.obj", "no-such-bunny.obj"), vec!["no-such-bunny.obj"]),
    ];
    for (name, bad, needles) in cases {
        std::fs::write(&cfg, &bad).unwrap();
        let out = nuvo().arg("train").arg(&cfg).arg("--out").arg(dir.path().join(name)).output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{name}: {err}");
        for n in needles {
            assert!(err.contains(n), "{name}: `{n}` not in: {err}");
        }
        assert!(!err.contains("panicked"), "{name}: {err}");
        assert!(!dir.path().join(name).join("checkpoint.safetensors").exists(), "{name} left a checkpoint");
    }
    let out = nuvo().args(["train", "/no/such/config.toml"]).output().unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("/no/such/config.toml"));
    let out = nuvo().arg("train").arg(&cfg).args(["--set", "training.steps"]).output().unwrap();
    assert!(String::from_utf8_lossy(&out.stderr).contains("KEY=VALUE"));
}

#[test]
fn one_and_two_threads_give_bit_identical_checkpoints_and_uvs() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = tiny_config(dir.path(), 6, 100);
    let mut outputs = Vec::new();
    for threads in ["1", "2"] {
        let out = dir.path().join(format!("t{threads}"));
        // Wide enough that the GEMMs and elementwise kernels take their parallel paths.
        let big =
            ["--set", "model.width=64", "--set", "training.batch_3d=2048", "--set", "training.batch_uv=2048"];
        let o = run(nuvo()
            .env("RAYON_NUM_THREADS", threads)
            .arg("train")
            .arg(&cfg)
            .args(big)
            .arg("--out")
            .arg(&out));
        assert!(o.status.success());
        let ckpt = std::fs::read(out.join("checkpoint.safetensors")).unwrap();
        let obj = std::fs::read(out.join("atlas.obj")).unwrap();
        outputs.push((ckpt, obj));
    }
    assert!(outputs[0].0 == outputs[1].0, "checkpoints differ between 1 and 2 threads");
    assert!(outputs[0].1 == outputs[1].1, "baked UVs differ between 1 and 2 threads");
}

#[test]
fn repeated_kills_while_checkpointing_every_step_still_resume_to_the_same_parameters() {
    // With a checkpoint after every step the process spends much of its time writing one, so the
    // kills below land inside checkpoint writes too; the atomic write (temp file + rename) must
    // leave the previous checkpoint intact every time.
    let dir = tempfile::tempdir().unwrap();
    let cfg = tiny_config(dir.path(), 60, 1);
    let full = dir.path().join("full");
    assert!(train_unbaked(&cfg, &full).status.success());
    let killed = dir.path().join("killed");
    let log = killed.join("log.jsonl");
    for (round, lines) in [7usize, 19, 26, 38, 51].into_iter().enumerate() {
        let mut cmd = nuvo();
        cmd.arg("train").arg(&cfg).arg("--out").arg(&killed).arg("--no-bake");
        if round > 0 {
            cmd.arg("--resume");
        }
        let mut child =
            cmd.stdout(std::process::Stdio::null()).stderr(std::process::Stdio::null()).spawn().unwrap();
        let start = Instant::now();
        while std::fs::read_to_string(&log).map(|t| t.lines().count()).unwrap_or(0) < lines
            && start.elapsed() < Duration::from_secs(60)
        {
            std::thread::sleep(Duration::from_micros(300));
        }
        child.kill().unwrap();
        child.wait().unwrap();
    }
    let out = run(nuvo().arg("train").arg(&cfg).arg("--out").arg(&killed).arg("--no-bake").arg("--resume"));
    assert!(out.status.success());
    let a = std::fs::read(full.join("checkpoint.safetensors")).unwrap();
    let b = std::fs::read(killed.join("checkpoint.safetensors")).unwrap();
    assert!(a == b, "after five kills the resumed run's checkpoint differs from the uninterrupted run's");
}
