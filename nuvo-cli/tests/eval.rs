//! `nuvo eval` as a process: exit codes and messages on good and bad input.

use std::process::{Command, Output};

use nuvo_geometry::testdata::data_file;

fn nuvo(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_nuvo")).args(args).output().expect("the nuvo binary runs")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn a_missing_file_fails_naming_it() {
    let o = nuvo(&["eval", "/nonexistent/nothing-here.obj"]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("nothing-here.obj"), "{}", stderr(&o));
}

#[test]
fn a_mesh_without_uvs_fails_naming_it() {
    let p = data_file("meshes/stanford-bunny.obj");
    let o = nuvo(&["eval", p.to_str().unwrap()]);
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(e.contains("stanford-bunny.obj") && e.contains("no texture coordinates"), "{e}");
}

#[test]
fn garbage_and_unknown_formats_fail_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let garbage = dir.path().join("garbage.obj");
    std::fs::write(&garbage, [0u8, 159, 146, 150, 255, 10, 102, 32, 49, 10]).unwrap();
    let o = nuvo(&["eval", garbage.to_str().unwrap()]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("garbage.obj"), "{}", stderr(&o));
    let other = dir.path().join("mesh.stl");
    std::fs::write(&other, "solid\n").unwrap();
    let o = nuvo(&["eval", other.to_str().unwrap()]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("mesh.stl") && stderr(&o).contains("unsupported"), "{}", stderr(&o));
    // A PLY is read as a mesh now; a broken one is named with what is wrong.
    let ply = dir.path().join("mesh.ply");
    std::fs::write(&ply, "ply\n").unwrap();
    let o = nuvo(&["eval", ply.to_str().unwrap()]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("mesh.ply") && stderr(&o).contains("PLY header"), "{}", stderr(&o));
}

#[test]
fn bad_options_fail_without_panicking() {
    let p = data_file("meshes/spot.obj");
    let o = nuvo(&["eval", p.to_str().unwrap(), "--views", "0"]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("views") && !stderr(&o).contains("panicked"), "{}", stderr(&o));
    let o = nuvo(&["eval", p.to_str().unwrap(), "--resolution", "-3"]);
    assert!(!o.status.success());
}

#[test]
fn spot_gives_a_table_and_json_and_pictures() {
    let p = data_file("meshes/spot.obj");
    let o = nuvo(&["eval", p.to_str().unwrap(), "--views", "3", "--resolution", "200"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let table = String::from_utf8(o.stdout).unwrap();
    for row in [
        "Boundary",
        "Stretch",
        "Conformal",
        "Editability",
        "charts",
        "UV utilisation",
        "PartUV metric set",
        "seam length",
        "angular score",
        "area distortion",
        "overall area dist.",
        "packing efficiency",
    ] {
        assert!(table.contains(row), "{table}");
    }
    let dir = tempfile::tempdir().unwrap();
    let pics = dir.path().join("pics");
    let o = nuvo(&[
        "eval",
        p.to_str().unwrap(),
        "--views",
        "3",
        "--resolution",
        "200",
        "--json",
        "--pictures",
        pics.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("valid JSON");
    let b = v["metrics"]["image"]["boundary"].as_f64().unwrap();
    assert!(b > 0.5 && b < 1.0, "{b}");
    assert_eq!(v["faces"], 5856);
    assert_eq!(v["metrics"]["options"]["views"], 3);
    // The PartUV metric set, under the names the benchmark script reads.
    let partuv = &v["metrics"]["partuv"];
    assert_eq!(partuv["charts"], v["metrics"]["uv"]["charts"], "{partuv}");
    for key in
        ["seam_length", "angular_score", "area_distortion", "overall_area_distortion", "packing_efficiency"]
    {
        let x = partuv[key].as_f64().unwrap_or_else(|| panic!("metrics.partuv.{key} missing: {partuv}"));
        assert!(x.is_finite() && x > 0.0, "{key} = {x}");
    }
    assert!(partuv["area_distortion"].as_f64().unwrap() >= 1.0);
    assert!(partuv["angular_score"].as_f64().unwrap() <= 1.0);
    for f in ["uv_layout.png", "checker.png", "checker_view_0.png"] {
        assert!(pics.join(f).is_file(), "{f} not written");
    }
}
