//! Measures how far density-source samples land from the matching marching-cubes mesh for a range of
//! `scale` values: the evidence behind `DEFAULT_SIGMA_MAX`.
//!
//! ```sh
//! cargo run --release -p nuvo-geometry --example sigma_sweep -- [unruly_bunny] [sigma_max ...]
//! ```
//! Prints, per sigma_max, the 50/80/90th percentiles of the distance (in voxels) of 20k samples from
//! `meshes/NAME.obj`, and the fraction of samples farther than 3 voxels.

use nuvo_geometry::testdata::{MeshDistance, data_dir};
use nuvo_geometry::{BuildContext, SourceRegistry};

fn main() {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    // `--min V`: treat stored values below V as empty (sets min_density = V * scale).
    let min_value: f32 = match args.iter().position(|a| a == "--min") {
        Some(i) => {
            let v = args.get(i + 1).and_then(|v| v.parse().ok()).expect("--min VALUE");
            args.drain(i..i + 2);
            v
        }
        None => 0.0,
    };
    let mut args = args.into_iter();
    let name = args.next().unwrap_or_else(|| "unruly_bunny".into());
    let mut sigmas: Vec<f32> = args.filter_map(|a| a.parse().ok()).collect();
    if sigmas.is_empty() {
        sigmas = vec![25.0, 50.0, 100.0, 200.0, 400.0, 800.0, 1600.0, 3200.0];
    }
    let data = data_dir();
    let mesh = nuvo_geometry::load_mesh(&data.join(format!("meshes/{name}.obj"))).expect("mesh");
    let oracle = MeshDistance::new(mesh, 2_000_000);
    let arr = nuvo_geometry::npy::read_npy(&data.join(format!("density/{name}.npy"))).expect("grid");
    let voxel = 2.0 / (arr.shape[0] - 1) as f32;
    let mut hist = [0usize; 8];
    for v in &arr.data {
        hist[match *v as u32 {
            0 => 0,
            1..=2 => 1,
            3..=5 => 2,
            6..=11 => 3,
            12..=30 => 4,
            31..=100 => 5,
            101..=254 => 6,
            _ => 7,
        }] += 1;
    }
    println!("value histogram (0, 1-2, 3-5, 6-11, 12-30, 31-100, 101-254, 255): {hist:?}");
    let ctx = BuildContext { base_dir: data.join("density") };
    for sigma in sigmas {
        let table: toml::Table = toml::from_str(&format!(
            "path = '{name}.npy'\nscale = {}\nmin_density = {}",
            sigma / 255.0,
            min_value * sigma / 255.0
        ))
        .expect("toml");
        let src = SourceRegistry::with_builtins().build("density", &table, &ctx).expect("source");
        let t = std::time::Instant::now();
        let s = src.sample(20_000, 1);
        let dt = t.elapsed().as_secs_f64();
        let mut d: Vec<f32> = s.positions.iter().map(|p| oracle.distance(*p) / voxel).collect();
        d.sort_by(f32::total_cmp);
        let q = |x: f64| d[((d.len() - 1) as f64 * x) as usize];
        let far = d.iter().filter(|&&x| x > 3.0).count() as f64 / d.len() as f64;
        println!(
            "sigma_max {sigma:6}: distance in voxels p50 {:.2} p80 {:.2} p90 {:.2}; >3 voxels {:.1}%; {dt:.2} s",
            q(0.5),
            q(0.8),
            q(0.9),
            100.0 * far
        );
    }
}
