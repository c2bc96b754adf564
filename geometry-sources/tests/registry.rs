//! The source registry: built-in names, unknown names, option errors, relative paths.

mod common;

use common::*;
use nuvo_geometry::{GeometryError, SourceRegistry};

fn build(
    toml_text: &str,
    dir: &std::path::Path,
) -> Result<Box<dyn nuvo_geometry::GeometrySource>, GeometryError> {
    let mut table: toml::Table = toml::from_str(toml_text).unwrap();
    let name = table.remove("source").and_then(|v| v.as_str().map(str::to_owned)).unwrap();
    SourceRegistry::with_builtins().build(&name, &table, &ctx(dir))
}

#[test]
fn builtins_are_registered_and_unknown_names_list_them() {
    let reg = SourceRegistry::with_builtins();
    let names: Vec<&str> = reg.list().map(|(n, _)| n).collect();
    assert_eq!(names, ["density", "mesh", "point_cloud"]);
    assert!(reg.list().all(|(_, summary)| !summary.is_empty()));
    let e = reg.build("nerf", &toml::Table::new(), &ctx(".".as_ref())).err().unwrap().to_string();
    assert!(e.contains("nerf") && e.contains("density, mesh, point_cloud"), "{e}");
}

#[test]
fn relative_paths_resolve_against_the_context_and_options_are_checked() {
    let dir = tempfile::tempdir().unwrap();
    let sub = dir.path().join("meshes");
    std::fs::create_dir(&sub).unwrap();
    std::fs::write(sub.join("tri.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    let src = build("source = 'mesh'\npath = 'meshes/tri.obj'", dir.path()).unwrap();
    assert_eq!(src.kind(), "mesh");
    assert!(src.describe().contains("tri.obj"), "{}", src.describe());
    assert_eq!(src.mesh().unwrap().triangles.len(), 1);
    let s = src.sample(100, 1);
    assert_unit_normals(&s.normals);
    assert!(s.normals.iter().all(|n| n[2] > 0.9999));
    let visible = build(
        "source = 'mesh'\npath = 'meshes/tri.obj'\nsampling = 'visible'\nnormals = 'vertex'",
        dir.path(),
    )
    .unwrap();
    assert!(visible.describe().contains("visible"));
    for (toml_text, needles) in [
        ("source = 'mesh'\npth = 'meshes/tri.obj'", vec!["mesh", "unknown field `pth`", "path"]),
        ("source = 'mesh'\nsampling = 'uniform'", vec!["missing field `path`"]),
        (
            "source = 'mesh'\npath = 'meshes/tri.obj'\nsampling = 'visble'",
            vec!["visble", "uniform", "visible"],
        ),
        ("source = 'mesh'\npath = 'meshes/tri.obj'\nnormals = 'smooth'", vec!["smooth", "face", "vertex"]),
        (
            "source = 'mesh'\npath = 'meshes/tri.obj'\nsampling = 'visible'\ncameras = { radiuss = 3.0 }",
            vec!["radiuss"],
        ),
        (
            "source = 'mesh'\npath = 'meshes/tri.obj'\nsampling = 'visible'\ncameras = { fov_degrees = 200.0 }",
            vec!["fov_degrees"],
        ),
        ("source = 'mesh'\npath = 'meshes/missing.obj'", vec!["missing.obj"]),
        ("source = 'mesh'\npath = 42", vec!["path"]),
    ] {
        let e = build(toml_text, dir.path())
            .err()
            .unwrap_or_else(|| panic!("{toml_text} should fail"))
            .to_string();
        for n in needles {
            assert!(e.contains(n), "{toml_text}: `{n}` not in: {e}");
        }
    }
}
