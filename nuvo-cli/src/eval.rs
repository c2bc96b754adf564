//! `nuvo eval`: the paper's metrics, UV statistics and the PartUV metric set of a mesh's own UVs, as
//! a table or JSON.

use std::path::PathBuf;

use anyhow::Context;
use nuvo_atlas::load::load_mesh_with_uv;
use nuvo_atlas::metrics::{EvalOptions, Metrics, evaluate};
use nuvo_atlas::pictures::{PreviewOptions, write_previews};
use serde::Serialize;

/// Arguments of `nuvo eval`.
#[derive(clap::Args, Debug)]
pub struct EvalArgs {
    /// Mesh with texture coordinates (.obj).
    pub mesh: PathBuf,
    /// Number of random views the image metrics are averaged over.
    #[arg(long, default_value_t = EvalOptions::default().views)]
    pub views: usize,
    /// Side of the square renders, in pixels.
    #[arg(long, default_value_t = EvalOptions::default().resolution)]
    pub resolution: u32,
    /// Seed of the view directions.
    #[arg(long, default_value_t = EvalOptions::default().seed)]
    pub seed: u64,
    /// Print JSON instead of a table.
    #[arg(long)]
    pub json: bool,
    /// Also write uv_layout.png, checker.png and checkerboard renders into this folder.
    #[arg(long, value_name = "DIR")]
    pub pictures: Option<PathBuf>,
}

/// What `--json` prints.
#[derive(Serialize)]
pub struct EvalReport {
    pub mesh: PathBuf,
    pub vertices: usize,
    pub faces: usize,
    pub metrics: Metrics,
}

/// Runs `nuvo eval`: prints the report, writes pictures if asked.
pub fn run(args: &EvalArgs) -> anyhow::Result<()> {
    let report = evaluate_file(args)?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{}", table(&report));
    }
    Ok(())
}

/// Loads and measures the mesh named in `args` (and writes pictures if asked).
pub fn evaluate_file(args: &EvalArgs) -> anyhow::Result<EvalReport> {
    let shown = args.mesh.display();
    // Loader errors already name the file.
    let mesh = load_mesh_with_uv(&args.mesh).context("cannot load the mesh to evaluate")?;
    let opts =
        EvalOptions { views: args.views, resolution: args.resolution, seed: args.seed, ..Default::default() };
    let metrics = evaluate(&mesh, &opts).with_context(|| format!("cannot measure {shown}"))?;
    if let Some(dir) = &args.pictures {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
        let opts = PreviewOptions { seed: args.seed, ..Default::default() };
        write_previews(dir, &mesh, &opts).with_context(|| format!("cannot draw pictures of {shown}"))?;
    }
    Ok(EvalReport {
        mesh: args.mesh.clone(),
        vertices: mesh.positions.len(),
        faces: mesh.triangles.len(),
        metrics,
    })
}

/// The human-readable report.
pub fn table(r: &EvalReport) -> String {
    let (m, uv, o) = (&r.metrics.image, &r.metrics.uv, &r.metrics.options);
    let mut s = format!(
        "{}: {} vertices, {} faces; {} of {} views measured at {}x{} px (seed {})\n",
        r.mesh.display(),
        r.vertices,
        r.faces,
        m.views_used,
        o.views,
        o.resolution,
        o.resolution,
        o.seed
    );
    let rows: [(&str, String); 12] = [
        ("Boundary", format!("{:.4}", m.boundary)),
        ("Stretch", format!("{:.4}", m.stretch)),
        ("Conformal", format!("{:.4}", m.conformal)),
        ("Editability", format!("{:.4}", m.editability)),
        ("charts", uv.charts.to_string()),
        ("UV utilisation", format!("{:.4}", uv.utilisation)),
        ("UV overlap", format!("{:.4} ({} faces)", uv.overlap_fraction, uv.overlapping_faces)),
        ("flipped faces", format!("{:.4} ({} faces)", uv.flipped_fraction, uv.flipped_faces)),
        ("  on mesh creases", format!("{} of them (the surface turns back there)", uv.flipped_on_creases)),
        ("degenerate UV faces", uv.degenerate_uv_faces.to_string()),
        ("degenerate 3-D faces", uv.degenerate_3d_faces.to_string()),
        (
            "texel aspect",
            format!(
                "median {:.3}, 90th percentile {:.3} (1 = square texels on the surface)",
                uv.texel_aspect_median, uv.texel_aspect_p90
            ),
        ),
    ];
    for (name, value) in rows {
        s += &format!("  {name:<22}{value}\n");
    }
    let p = &r.metrics.partuv;
    let square = if p.uv_in_unit_square {
        "[0,1]²".to_string()
    } else {
        format!("the UVs' bounding square, side {:.4}", p.atlas_side)
    };
    s += &format!("PartUV metric set (UVs measured in {square}):\n");
    let rows: [(&str, String); 6] = [
        ("charts", p.charts.to_string()),
        ("seam length", format!("{:.4}", p.seam_length)),
        (
            "angular score",
            format!("{:.4} ({} degenerate faces skipped)", p.angular_score, p.angular_skipped_faces),
        ),
        (
            "area distortion",
            format!(
                "{:.4} (worst chart; {} charts unmeasurable)",
                p.area_distortion, p.area_unmeasured_charts
            ),
        ),
        (
            "overall area dist.",
            format!("{:.4} ({} faces skipped)", p.overall_area_distortion, p.area_skipped_faces),
        ),
        ("packing efficiency", format!("{:.4}", p.packing_efficiency)),
    ];
    for (name, value) in rows {
        s += &format!("  {name:<22}{value}\n");
    }
    s
}
