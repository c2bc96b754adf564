//! `nuvo report`: the page of a run, of a run still training and of two runs, and the same pages
//! opened in a real browser (headless Chromium, driven by `tests/browser/check_report.mjs`).
//!
//! The browser test needs Debian's `chromium` (or `CHROMIUM=/path/to/chromium`) and Node.js; it
//! installs its one npm package (`playwright-core`, pinned in `tests/browser/package-lock.json`)
//! itself when it is missing. Without Chromium it fails and says how to install it: `.ci/run` does.

use std::path::{Path, PathBuf};
use std::process::Command;

mod common;
use common::{nuvo, run, tiny_config};

/// Trains the tiny bunny run into `out` with `overrides`; `nuvo train` writes its report too.
fn train(cfg: &Path, out: &Path, overrides: &[&str]) {
    let mut cmd = nuvo();
    cmd.arg("train").arg(cfg).arg("--out").arg(out);
    for o in overrides {
        cmd.args(["--set", o]);
    }
    let o = run(&mut cmd);
    assert!(o.status.success());
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains(&format!("wrote {}", out.join("report.html").display())), "{stdout}");
}

/// The number of times `needle` occurs in `haystack`.
fn count(haystack: &str, needle: &str) -> usize {
    haystack.matches(needle).count()
}

#[test]
fn a_runs_report_holds_its_metrics_curves_pictures_model_and_config() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = tiny_config(dir.path(), 20, 1000);
    let out = dir.path().join("run");
    train(&cfg, &out, &[]);
    let page = std::fs::read_to_string(out.join("report.html")).unwrap();
    // Self-contained: nothing is fetched (no src or href in the markup that is not a data: URI or
    // an anchor; the browser test below also watches every request the scripts make).
    let markup: String = page
        .split("<script")
        .enumerate()
        .map(|(i, s)| if i == 0 { s } else { s.split_once("</script>").map_or("", |(_, rest)| rest) })
        .collect();
    for attr in ["src=\"", "href=\""] {
        for rest in markup.split(attr).skip(1) {
            assert!(
                rest.starts_with("data:") || rest.starts_with('#'),
                "{attr}{}",
                &rest[..rest.len().min(60)]
            );
        }
    }
    let log = std::fs::read_to_string(out.join("log.jsonl")).unwrap();
    let first: serde_json::Value = serde_json::from_str(log.lines().next().unwrap()).unwrap();
    let terms = first["terms"].as_object().unwrap();
    // A panel per term and the total, against step and against seconds.
    assert_eq!(count(&page, "<svg class=\"plot\""), 2 * (terms.len() + 1));
    for t in terms.keys() {
        assert!(page.contains(&format!("data-curve=\"{t}\"")), "{t}");
    }
    let pngs = 3 + std::fs::read_dir(out.join("renders")).unwrap().count(); // layout, checker, grids, renders
    assert_eq!(count(&page, "<img class=\"picture\""), pngs);
    assert_eq!(count(&page, "<model-viewer class=\"viewer\" src=\"data:model/gltf-binary;base64,"), 1);
    assert!(page.contains("customElements.define(\"model-viewer\""), "the viewer is embedded");
    let metrics: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("metrics.json")).unwrap()).unwrap();
    // Every number the readers of finished runs look up is where they look.
    {
        use nuvo_core::outputs::metric_paths::*;
        for p in [
            BOUNDARY,
            STRETCH,
            CONFORMAL,
            EDITABILITY,
            UV_EFFICIENCY,
            CHARTS,
            SEAM_LENGTH,
            ANGULAR,
            AREA_WORST_CHART,
            AREA_OVERALL,
            PACKING,
            FLIPPED_FACES,
            OVERLAPPING_FACES,
            STEPS,
        ] {
            assert!(metrics.pointer(p).is_some_and(serde_json::Value::is_number), "{p} in metrics.json");
        }
    }
    let editability = metrics["metrics"]["image"]["editability"].as_f64().unwrap();
    assert!(
        page.contains(&format!("data-value=\"{editability}\">{editability:.4}</td>")),
        "Editability in the table"
    );
    assert!(page.contains("finished: step 20 of 20 logged"));
    assert!(page.contains("[training]\nsteps = 20"), "the resolved config");
}

#[test]
fn a_run_still_training_shows_its_curves_and_bad_folders_are_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = tiny_config(dir.path(), 30, 1000);
    let done = dir.path().join("done");
    train(&cfg, &done, &["output.bake=false"]);
    // The folder as it is mid-run: the config, the first ten log lines and half of the eleventh.
    let running = dir.path().join("running");
    std::fs::create_dir(&running).unwrap();
    std::fs::copy(done.join("config.toml"), running.join("config.toml")).unwrap();
    let log = std::fs::read_to_string(done.join("log.jsonl")).unwrap();
    let lines: Vec<&str> = log.lines().collect();
    let partial = format!("{}\n{}", lines[..10].join("\n"), &lines[10][..lines[10].len() / 2]);
    std::fs::write(running.join("log.jsonl"), partial).unwrap();

    let page_path = dir.path().join("running.html");
    let o = run(nuvo().arg("report").arg(&running).arg("-o").arg(&page_path));
    assert!(o.status.success());
    let page = std::fs::read_to_string(&page_path).unwrap();
    assert!(
        page.contains("no metrics yet (still training, or trained without a bake): step 10 of 30 logged"),
        "status"
    );
    assert!(page.contains("data-curve=\"total\""));
    assert!(page.contains("No <code>atlas.glb</code> (yet)"));
    assert!(!page.contains("customElements.define"), "no viewer script without a model to show");

    // Not a run folder, not a folder, no folder: one clear error each, and no page.
    let empty = dir.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    for (input, says) in [
        (empty.clone(), "neither a run folder"),
        (cfg.clone(), "not a folder"),
        (dir.path().join("gone"), "no such folder"),
    ] {
        let o = run(nuvo().arg("report").arg(&input).arg("-o").arg(dir.path().join("x.html")));
        assert_eq!(o.status.code(), Some(1));
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert!(stderr.contains(&input.display().to_string()) && stderr.contains(says), "{stderr}");
    }
    assert!(!dir.path().join("x.html").exists());
}

#[test]
fn a_training_run_refreshes_its_report_at_checkpoints() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = tiny_config(dir.path(), 1_000_000, 5);
    let out = dir.path().join("run");
    let mut child = nuvo()
        .arg("train")
        .arg(&cfg)
        .arg("--out")
        .arg(&out)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let started = std::time::Instant::now();
    let page_path = out.join("report.html");
    while !page_path.exists() {
        assert!(started.elapsed().as_secs() < 120, "no report.html after two minutes of training");
        assert!(child.try_wait().unwrap().is_none(), "training ended early");
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    child.kill().unwrap();
    child.wait().unwrap();
    let page = std::fs::read_to_string(&page_path).unwrap();
    let status = "no metrics yet (still training, or trained without a bake): step ";
    let at = page.find(status).map(|i| &page[i + status.len()..]).expect("the status of a running run");
    let step: u64 = at.split(' ').next().unwrap().parse().unwrap();
    assert!(step >= 5 && at.contains(" of 1000000 logged"), "{}", &at[..40]);
    assert!(page.contains("data-curve=\"total\""));
}

/// Where the browser test's npm package lives.
fn browser_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/browser")
}

/// Chromium, Node.js and playwright-core, or a panic that says what is missing and how to get it.
fn browser_prerequisites() -> PathBuf {
    let chromium =
        std::env::var_os("CHROMIUM").map_or_else(|| PathBuf::from("/usr/bin/chromium"), PathBuf::from);
    assert!(
        chromium.is_file(),
        "Chromium is missing ({}): the report's browser test needs it. Install Debian's package \
         (`apt-get install chromium`; .ci/run does) or set CHROMIUM to a Chromium binary.",
        chromium.display()
    );
    let node = Command::new("node").arg("--version").output();
    assert!(
        node.is_ok_and(|o| o.status.success()),
        "Node.js is missing: the report's browser test drives Chromium with playwright-core on Node.js 20+"
    );
    if !browser_dir().join("node_modules/playwright-core").is_dir() {
        let o = Command::new("npm")
            .args(["ci", "--no-audit", "--no-fund"])
            .current_dir(browser_dir())
            .output()
            .expect("npm runs");
        assert!(
            o.status.success(),
            "`npm ci` in {} failed (the browser test needs playwright-core from the npm registry):\n{}",
            browser_dir().display(),
            String::from_utf8_lossy(&o.stderr)
        );
    }
    chromium
}

/// What `check_report.mjs` saw on a page.
fn open_in_browser(chromium: &Path, page: &Path, shots: &Path) -> serde_json::Value {
    std::fs::create_dir_all(shots).unwrap();
    let o = Command::new("node")
        .arg(browser_dir().join("check_report.mjs"))
        .arg(page)
        .arg(shots)
        .env("CHROMIUM", chromium)
        .output()
        .expect("node runs");
    assert!(
        o.status.success(),
        "the browser check failed:\n{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    serde_json::from_slice(&o.stdout).expect("the browser check prints JSON")
}

/// Share of pixels of a screenshot unlike its corner (the viewer's background), and its colours.
fn drawn_share_and_colours(png: &Path) -> (f64, usize) {
    let img = image::open(png).unwrap().to_rgb8();
    let background = *img.get_pixel(2, 2);
    let far = |a: &image::Rgb<u8>, b: &image::Rgb<u8>| a.0.iter().zip(b.0).any(|(x, y)| x.abs_diff(y) > 24);
    let drawn = img.pixels().filter(|p| far(p, &background)).count();
    let colours: std::collections::HashSet<[u8; 3]> = img.pixels().map(|p| p.0.map(|c| c >> 3)).collect();
    (drawn as f64 / (img.width() * img.height()) as f64, colours.len())
}

/// Share of pixels that differ between two screenshots of the same size.
fn changed_share(a: &Path, b: &Path) -> f64 {
    let (a, b) = (image::open(a).unwrap().to_rgb8(), image::open(b).unwrap().to_rgb8());
    assert_eq!(a.dimensions(), b.dimensions());
    let changed =
        a.pixels().zip(b.pixels()).filter(|(p, q)| p.0.iter().zip(q.0).any(|(x, y)| x.abs_diff(y) > 24));
    changed.count() as f64 / (a.width() * a.height()) as f64
}

#[test]
fn reports_open_in_a_real_browser_without_errors_and_the_model_turns() {
    let chromium = browser_prerequisites();
    let dir = tempfile::tempdir().unwrap();
    let cfg = tiny_config(dir.path(), 40, 1000);
    let (a, b) = (dir.path().join("a"), dir.path().join("b"));
    train(&cfg, &a, &[]);
    train(&cfg, &b, &["seed=5", "model.charts=3"]);
    let two = dir.path().join("two.html");
    assert!(run(nuvo().arg("report").arg(&a).arg(&b).arg("-o").arg(&two)).status.success());

    for (page, runs) in [(a.join("report.html"), 1), (two.clone(), 2)] {
        let shots = dir.path().join(format!("shots_{runs}"));
        let seen = open_in_browser(&chromium, &page, &shots);
        let context = format!("{}: {seen}", page.display());
        assert_eq!(seen["console_errors"], serde_json::json!([]), "{context}");
        assert_eq!(seen["requests"], serde_json::json!([]), "nothing fetched: {context}");
        assert_eq!(seen["runs"], runs, "{context}");
        assert_eq!(seen["metrics_rows"], runs, "{context}");
        let curves = seen["curves"].as_array().unwrap();
        assert!(curves.len() >= 5 && curves[0] == "total", "{context}");
        assert_eq!(seen["plots"].as_u64().unwrap() as usize, 2 * curves.len(), "{context}");
        assert_eq!(seen["broken_pictures"], serde_json::json!([]), "{context}");
        let pictures_per_run = 3 + std::fs::read_dir(a.join("renders")).unwrap().count();
        assert_eq!(seen["pictures"].as_u64().unwrap() as usize, runs * pictures_per_run, "{context}");
        let viewers = seen["viewers"].as_array().unwrap();
        assert_eq!(viewers.len(), runs, "{context}");
        for v in viewers {
            let (before, after) =
                (Path::new(v["before"].as_str().unwrap()), Path::new(v["after"].as_str().unwrap()));
            let (drawn, colours) = drawn_share_and_colours(before);
            assert!(
                drawn > 0.05 && colours > 20,
                "the 3-D view shows the model: {drawn:.3} drawn, {colours} colours"
            );
            let changed = changed_share(before, after);
            assert!(
                changed > 0.05,
                "dragging and zooming moves the model: {changed:.3} of the pixels changed"
            );
        }
        if runs == 2 {
            let sorted = &seen["sorted"];
            assert_eq!(sorted["up"].as_array().unwrap().len(), 2);
            let mut down = sorted["down"].as_array().unwrap().clone();
            down.reverse();
            assert_eq!(
                &down,
                sorted["up"].as_array().unwrap(),
                "a second click reverses the order: {context}"
            );
        }
    }
}
