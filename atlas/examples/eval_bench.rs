//! Times `evaluate` on a mesh, giving it planar-projection UVs when it has none (e.g. the
//! 600k-triangle `unruly_vase.obj`), with a breakdown: load, one render, image metrics, UV stats.
//! With OUT.obj, also writes the UV'd mesh there so `nuvo eval OUT.obj` can be timed end to end.
//!
//! ```sh
//! cargo run --release -p nuvo-atlas --example eval_bench -- MESH.obj [VIEWS] [RESOLUTION] [OUT.obj]
//! ```

use std::time::Instant;

use nuvo_atlas::export::write_obj;
use nuvo_atlas::metrics::{EvalOptions, evaluate, image_metrics};
use nuvo_atlas::uvstats::analyse_uv;
use nuvo_atlas::{load, orbit_views, render};
use nuvo_geometry::{Similarity, TriMesh, UvLayer};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let path = std::env::args().nth(1).ok_or("usage: eval_bench MESH.obj [VIEWS] [RESOLUTION]")?;
    let views = std::env::args().nth(2).map_or(Ok(16), |s| s.parse())?;
    let resolution = std::env::args().nth(3).map_or(Ok(800), |s| s.parse())?;
    let t = Instant::now();
    let mut mesh = load::load_mesh(path.as_ref())?;
    println!(
        "load: {:.3} s, {} vertices, {} faces",
        t.elapsed().as_secs_f64(),
        mesh.positions.len(),
        mesh.triangles.len()
    );
    if mesh.uv.is_none() {
        planar_uv(&mut mesh);
        println!("no UVs: gave it the planar projection (x, y) → [0,1]²");
    }
    if let Some(out) = std::env::args().nth(4) {
        write_obj(out.as_ref(), &mesh, &Similarity::IDENTITY, None)?;
        println!("wrote {out}");
    }
    let bounds = mesh.bounds().ok_or("empty mesh")?;
    let cams = orbit_views(&bounds, views, 0, resolution, resolution);
    let mut best = f64::INFINITY;
    for cam in &cams {
        let t = Instant::now();
        let g = render(&mesh, cam)?;
        best = best.min(t.elapsed().as_secs_f64());
        std::hint::black_box(g);
    }
    println!("render: best of {views} views {:.1} ms at {resolution}²", best * 1e3);
    let opts = EvalOptions { views, resolution, ..Default::default() };
    let t = Instant::now();
    image_metrics(&mesh, &cams, &opts.image)?;
    println!("image metrics: {:.3} s for {views} views", t.elapsed().as_secs_f64());
    let t = Instant::now();
    analyse_uv(&mesh, None, opts.uv_raster)?;
    println!("UV stats: {:.3} s at {}²", t.elapsed().as_secs_f64(), opts.uv_raster);
    let t = Instant::now();
    let m = evaluate(&mesh, &opts)?;
    println!("evaluate: {:.3} s for {views} views at {resolution}²", t.elapsed().as_secs_f64());
    println!(
        "boundary {:.4} stretch {:.4} conformal {:.4} editability {:.4} charts {} utilisation {:.4}",
        m.image.boundary,
        m.image.stretch,
        m.image.conformal,
        m.image.editability,
        m.uv.charts,
        m.uv.utilisation
    );
    Ok(())
}

/// UVs by orthographic projection along z, the bounding box's x/y mapped into [0,1]² (aspect kept).
fn planar_uv(mesh: &mut TriMesh) {
    let b = mesh.bounds().expect("non-empty");
    let ext = (b.max[0] - b.min[0]).max(b.max[1] - b.min[1]).max(f32::MIN_POSITIVE);
    let coords = mesh.positions.iter().map(|p| [(p[0] - b.min[0]) / ext, (p[1] - b.min[1]) / ext]).collect();
    mesh.uv = Some(UvLayer { coords, triangles: mesh.triangles.clone() });
}
