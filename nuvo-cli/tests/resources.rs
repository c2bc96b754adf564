//! Resource limits, measured with the OS's peak RSS (Linux `VmHWM`, printed by `nuvo train`):
//! memory stays flat over thousands of steps, and a 2M-face mesh trains and bakes in bounded memory.

use std::io::Write;
use std::path::Path;

mod common;
use common::{nuvo, run, tiny_config, tiny_config_for, train_unbaked};

/// The last `peak RSS N MB` that `nuvo train` printed (after training, and after baking).
fn peak_rss_mb(stdout: &[u8]) -> u64 {
    let text = String::from_utf8_lossy(stdout);
    let at = text.rfind("peak RSS ").unwrap_or_else(|| panic!("no peak RSS in:\n{text}"));
    text[at + 9..].split_whitespace().next().unwrap().parse().unwrap()
}

#[test]
fn memory_stays_flat_over_thousands_of_steps() {
    if !Path::new("/proc/self/status").exists() {
        eprintln!("skipped: no /proc to read the peak RSS from");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let mut peaks = Vec::new();
    for steps in [300, 3000] {
        let cfg = tiny_config(dir.path(), steps, 1000);
        let out = dir.path().join(format!("s{steps}"));
        let o = train_unbaked(&cfg, &out);
        assert!(o.status.success());
        peaks.push(peak_rss_mb(&o.stdout));
    }
    eprintln!("peak RSS after 300 steps: {} MB, after 3000 steps: {} MB", peaks[0], peaks[1]);
    assert!(peaks[1] <= peaks[0] + peaks[0] / 10 + 4, "memory grew: {peaks:?} MB");
}

/// Writes a closed torus of `rings × segments × 2` triangles as OBJ.
fn write_torus(path: &Path, rings: usize, segments: usize) {
    let mut w = std::io::BufWriter::new(std::fs::File::create(path).unwrap());
    let tau = std::f64::consts::TAU;
    for i in 0..rings {
        let a = tau * i as f64 / rings as f64;
        for j in 0..segments {
            let b = tau * j as f64 / segments as f64;
            let r = 1.0 + 0.35 * b.cos();
            writeln!(w, "v {:.6} {:.6} {:.6}", r * a.cos(), r * a.sin(), 0.35 * b.sin()).unwrap();
        }
    }
    let id = |i: usize, j: usize| (i % rings) * segments + (j % segments) + 1;
    for i in 0..rings {
        for j in 0..segments {
            let (p, q, r, s) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
            writeln!(w, "f {p} {q} {r}\nf {p} {r} {s}").unwrap();
        }
    }
}

#[test]
fn a_two_million_face_mesh_trains_and_bakes_in_bounded_memory() {
    let dir = tempfile::tempdir().unwrap();
    let mesh = dir.path().join("torus_2m.obj");
    write_torus(&mesh, 1000, 1000);
    let cfg = tiny_config_for(dir.path(), &mesh, 3, 1000);
    let out = dir.path().join("run");
    let o = run(nuvo().arg("train").arg(&cfg).arg("--out").arg(&out));
    assert!(o.status.success());
    let peak = peak_rss_mb(&o.stdout);
    eprintln!("2M faces: peak RSS of train + bake {peak} MB");
    assert!(peak < 4096, "{peak} MB");
    let obj = std::fs::read_to_string(out.join("atlas.obj")).unwrap();
    assert_eq!(obj.lines().filter(|l| l.starts_with("f ")).count(), 2_000_000);
    assert!(out.join("atlas.glb").exists() && out.join("metrics.json").exists());
}
