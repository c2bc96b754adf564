//! Packs the islands of UV'd meshes anew and prints, per mesh, the islands, the packing
//! efficiency, PartUV's angular score after the packing and the time `pack_islands` took: how a
//! change of the packer is measured on finished atlases without baking them again.
//!
//! ```sh
//! cargo run --release -p nuvo-atlas --example pack_bench -- [--resolution 2048] [--gutter 4] [--search 0] ATLAS.obj...
//! ```

use std::time::Instant;

use nuvo_atlas::islands::{IslandPacking, pack_islands};
use nuvo_atlas::{load, partuv_metrics};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut opts = IslandPacking { resolution: 2048, gutter: 4, rotate: true, search: 0 };
    let mut paths = Vec::new();
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--resolution" => opts.resolution = args.next().ok_or("--resolution needs a value")?.parse()?,
            "--gutter" => opts.gutter = args.next().ok_or("--gutter needs a value")?.parse()?,
            "--search" => opts.search = args.next().ok_or("--search needs a value")?.parse()?,
            _ => paths.push(a),
        }
    }
    if paths.is_empty() {
        return Err("usage: pack_bench [--resolution N] [--gutter N] [--search ATTEMPTS] ATLAS.obj...".into());
    }
    let (mut sum_before, mut sum_after, mut sum_angular, mut sum_s) = (0.0, 0.0, 0.0, 0.0);
    println!("{:<60} {:>7} {:>8} {:>8} {:>8} {:>7}", "mesh", "islands", "before", "after", "angular", "s");
    for path in &paths {
        let mesh = load::load_mesh(path.as_ref())?;
        let before = partuv_metrics(&mesh)?;
        let t = Instant::now();
        let packed = pack_islands(&mesh, &opts)?;
        let s = t.elapsed().as_secs_f64();
        let after = partuv_metrics(&packed.mesh)?;
        println!(
            "{:<60} {:>7} {:>8.4} {:>8.4} {:>8.4} {:>7.3}",
            path, packed.islands, before.packing_efficiency, packed.efficiency, after.angular_score, s
        );
        sum_before += before.packing_efficiency;
        sum_after += packed.efficiency;
        sum_angular += after.angular_score;
        sum_s += s;
    }
    let n = paths.len() as f64;
    println!(
        "{:<60} {:>7} {:>8.4} {:>8.4} {:>8.4} {:>7.3}",
        "mean",
        "",
        sum_before / n,
        sum_after / n,
        sum_angular / n,
        sum_s / n
    );
    Ok(())
}
