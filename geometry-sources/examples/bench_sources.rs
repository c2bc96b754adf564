//! Times the expensive paths of every source on the shared test data (numbers in BENCHMARKS.md).
//!
//! ```sh
//! cargo run --release -p nuvo-geometry --example bench_sources -- /work/shared/data [--repeat N] [--mesh-only]
//! ```
//! `--mesh-only` times just the density grids' marching-cubes meshes.
//! The data folder defaults to `$NUVO_DATA` or `<workspace>/../shared/data`. Each figure is the best
//! of `--repeat N` runs (default 3) of wall-clock time, since the machine may be shared.

use std::path::{Path, PathBuf};
use std::time::Instant;

use nuvo_geometry::camera::{CameraOptions, CameraRig, area_radius};
use nuvo_geometry::isosurface::{NodeGrid, marching_cubes};
use nuvo_geometry::npy::read_npy;
use nuvo_geometry::raycast::RayCaster;
use nuvo_geometry::{BuildContext, GeometrySource, Similarity, SourceRegistry};
use rand::SeedableRng;
use rayon::prelude::*;

fn best_of<T>(repeat: usize, mut f: impl FnMut() -> T) -> (f64, T) {
    let mut best = f64::INFINITY;
    let mut out = None;
    for _ in 0..repeat.max(1) {
        let t = Instant::now();
        let v = f();
        best = best.min(t.elapsed().as_secs_f64());
        out = Some(v);
    }
    (best, out.expect("at least one run"))
}

fn build(name: &str, toml_text: &str, dir: &Path) -> Box<dyn GeometrySource> {
    let table: toml::Table = toml::from_str(toml_text).expect("valid TOML");
    SourceRegistry::with_builtins()
        .build(name, &table, &BuildContext { base_dir: dir.to_path_buf() })
        .unwrap_or_else(|e| panic!("{e}"))
}

/// Times building a source and drawing `n` samples, then `n` and 5000 samples from the built source.
fn bench_source(repeat: usize, label: &str, name: &str, toml_text: &str, dir: &Path, n: usize) {
    let (t, s) = best_of(repeat, || build(name, toml_text, dir).sample(n, 1));
    println!("{label}: load + prepare + {} samples: {t:.3} s", s.len());
    let src = build(name, toml_text, dir);
    let (t, s) = best_of(repeat, || src.sample(n, 2));
    println!("{label}: {} samples (prepared): {t:.3} s", s.len());
    let (t, s) = best_of(repeat, || src.sample(5000, 3));
    println!("{label}: {} samples (one training batch): {:.1} ms", s.len(), 1e3 * t);
}

/// Times marching cubes on the shared grids at their level 12 (on 1 and on all threads), and
/// building the density source with and without its mesh.
fn bench_density_mesh(repeat: usize, data: &Path) {
    let dir = data.join("density");
    for name in ["unruly_bunny", "unruly_vase"] {
        let arr = read_npy(&dir.join(format!("{name}.npy"))).expect("grid reads");
        let dims = [arr.shape[0], arr.shape[1], arr.shape[2]];
        let grid = NodeGrid { dims, values: &arr.data, min: [-1.0; 3], max: [1.0; 3] };
        let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().expect("pool");
        let (t1, _) = best_of(repeat, || one.install(|| marching_cubes(&grid, 12.0)));
        let (t, m) = best_of(repeat, || marching_cubes(&grid, 12.0));
        println!(
            "marching cubes {name}.npy {dims:?}: {} vertices, {} faces: {t:.3} s ({t1:.3} s on 1 thread)",
            m.positions.len(),
            m.triangles.len()
        );
        let path = format!("path = '{name}.npy'");
        let (t_on, _) = best_of(repeat, || build("density", &path, &dir));
        let (t_off, _) = best_of(repeat, || build("density", &format!("{path}\nextract_mesh = false"), &dir));
        println!(
            "density {name}.npy: build with its mesh {t_on:.3} s, with extract_mesh = false {t_off:.3} s"
        );
    }
}

fn main() {
    let mut args = std::env::args().skip(1);
    let mut data = nuvo_geometry::testdata::data_dir();
    let mut repeat = 3;
    let mut mesh_only = false;
    while let Some(a) = args.next() {
        if a == "--repeat" {
            repeat = args.next().and_then(|v| v.parse().ok()).expect("--repeat N");
        } else if a == "--mesh-only" {
            mesh_only = true;
        } else {
            data = PathBuf::from(a);
        }
    }
    let n = 100_000;
    println!("rayon threads: {}", rayon::current_num_threads());
    bench_density_mesh(repeat, &data);
    if mesh_only {
        return;
    }

    let vase = data.join("meshes/unruly_vase.obj");
    let (t, mut mesh) = best_of(repeat, || nuvo_geometry::load_mesh(&vase).expect("vase loads"));
    println!("load unruly_vase.obj ({} faces): {t:.3} s", mesh.triangles.len());
    let sim = Similarity::normalizing(&mesh.bounds().expect("non-empty"));
    mesh.transform(&sim);
    let (t, caster) = best_of(repeat, || RayCaster::build(&mesh));
    println!("area radius (99.5% of area): {:.3}", area_radius(&mesh));
    println!("ray caster build ({} non-degenerate triangles): {t:.3} s", caster.triangle_count());
    let ctx = BuildContext { base_dir: data.clone() };
    let rig = CameraRig::from_options(&CameraOptions::default(), &ctx, area_radius(&mesh), &sim, "bench")
        .expect("rig");
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
    let rays: Vec<_> = (0..1_000_000).map(|_| rig.random_ray(&mut rng)).collect();
    let (t, hits) = best_of(repeat, || {
        rays.par_iter().filter(|r| caster.intersect(r.origin, r.dir, f32::MAX).is_some()).count()
    });
    println!("1M random camera rays ({hits} hit): {t:.3} s = {:.2} Mrays/s", 1.0 / t);

    let meshes = data.join("meshes");
    bench_source(
        repeat,
        "mesh visible unruly_vase.obj",
        "mesh",
        "path = 'unruly_vase.obj'\nsampling = 'visible'",
        &meshes,
        n,
    );
    bench_source(repeat, "mesh uniform unruly_vase.obj", "mesh", "path = 'unruly_vase.obj'", &meshes, n);
    bench_source(
        repeat,
        "density unruly_vase.npy",
        "density",
        "path = 'unruly_vase.npy'",
        &data.join("density"),
        n,
    );
    let clouds = data.join("pointclouds");
    bench_source(
        repeat,
        "point_cloud bunny (file normals)",
        "point_cloud",
        "path = 'stanford-bunny_200k.ply'",
        &clouds,
        n,
    );
    let (t, _) = best_of(repeat, || {
        build("point_cloud", "path = 'stanford-bunny_200k.ply'\nnormals = 'estimate'", &clouds)
    });
    println!("point_cloud bunny: load + estimate 200k normals: {t:.3} s");
}
