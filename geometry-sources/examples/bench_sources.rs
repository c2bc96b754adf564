//! Times the expensive paths of every source on the shared test data.
//!
//! ```sh
//! cargo run --release -p nuvo-geometry --example bench_sources -- /work/shared/data
//! ```
//! The argument defaults to `$NUVO_DATA` or `<workspace>/../shared/data`. Each figure is the best
//! of `--repeat N` runs (default 3), since the machine may be shared.

use std::path::{Path, PathBuf};
use std::time::Instant;

use nuvo_geometry::bvh::Bvh;
use nuvo_geometry::camera::{CameraOptions, CameraRig};
use nuvo_geometry::{BuildContext, GeometrySource, SourceRegistry};

fn best_of<T>(repeat: usize, mut f: impl FnMut() -> T) -> (f64, T) {
    let mut best = f64::INFINITY;
    let mut out = None;
    for _ in 0..repeat {
        let t = Instant::now();
        let v = f();
        best = best.min(t.elapsed().as_secs_f64());
        out = Some(v);
    }
    (best, out.expect("repeat >= 1"))
}

fn build(name: &str, toml_text: &str, dir: &Path) -> Box<dyn GeometrySource> {
    let table: toml::Table = toml::from_str(toml_text).expect("valid TOML");
    SourceRegistry::with_builtins()
        .build(name, &table, &BuildContext { base_dir: dir.to_path_buf() })
        .unwrap_or_else(|e| panic!("{e}"))
}

fn main() {
    let mut args = std::env::args().skip(1);
    let mut data = nuvo_geometry::testdata::data_dir();
    let mut repeat = 3;
    while let Some(a) = args.next() {
        if a == "--repeat" {
            repeat = args.next().and_then(|v| v.parse().ok()).expect("--repeat N");
        } else {
            data = PathBuf::from(a);
        }
    }
    let n = 100_000;
    println!("threads: {}", rayon::current_num_threads());

    let vase = data.join("meshes/unruly_vase.obj");
    let (t, mesh) = best_of(repeat, || nuvo_geometry::load_mesh(&vase).expect("vase loads"));
    println!("load unruly_vase.obj ({} faces): {t:.3} s", mesh.triangles.len());
    let (t, bvh) = best_of(repeat, || Bvh::build(&mesh));
    println!("BVH build ({} triangles, {} nodes): {t:.3} s", bvh.triangle_count(), bvh.node_count());
    // Ray throughput alone: 1M random camera rays (about half of them hit), in parallel.
    let mut canon = mesh.clone();
    let sim = nuvo_geometry::Similarity::normalizing(&canon.bounds().expect("non-empty"));
    canon.transform(&sim);
    let bvh = Bvh::build(&canon);
    let rig = CameraRig::from_options(
        &CameraOptions::default(),
        &BuildContext { base_dir: data.clone() },
        &canon.bounds().expect("non-empty"),
        &sim,
        "bench",
    )
    .expect("rig");
    let rays: Vec<_> = {
        use rand::SeedableRng;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        (0..1_000_000).map(|_| rig.random_ray(&mut rng)).collect()
    };
    let (t, hits) = best_of(repeat, || {
        use rayon::prelude::*;
        rays.par_iter().filter(|r| bvh.intersect(r.origin, r.dir, 0.0, f32::INFINITY).is_some()).count()
    });
    println!("1M rays ({hits} hits): {t:.3} s = {:.2} Mrays/s", 1.0 / t);
    let (t, _) = best_of(repeat, || {
        use rand::SeedableRng;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        (0..1_000_000).map(|_| rig.random_ray(&mut rng)).fold(0.0f32, |a, r| a + r.dir[0])
    });
    println!("1M ray generations (1 thread): {t:.3} s");

    let dir = data.join("meshes");
    let (t, s) = best_of(repeat, || {
        let src = build("mesh", "path = 'unruly_vase.obj'\nsampling = 'visible'", &dir);
        src.sample(n, 1)
    });
    println!("mesh visible: load + BVH + {} samples: {t:.3} s", s.len());
    let src = build("mesh", "path = 'unruly_vase.obj'\nsampling = 'visible'", &dir);
    let (t, s) = best_of(repeat, || src.sample(n, 2));
    println!("mesh visible: {} samples (built): {t:.3} s", s.len());
    let (t, s) = best_of(repeat, || src.sample(5000, 3));
    println!("mesh visible: {} samples (one training batch): {:.2} ms", s.len(), 1e3 * t);
    let src = build("mesh", "path = 'unruly_vase.obj'", &dir);
    let (t, s) = best_of(repeat, || src.sample(n, 2));
    println!("mesh uniform: {} samples (built): {t:.3} s", s.len());
}

#[allow(dead_code)]
fn unused() {}
