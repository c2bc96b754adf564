//! Where an atlas loses the paper's Boundary score: which UV islands and which pieces of the mesh
//! its boundary pixels fall on, over the evaluation's 16 views at 800².
//!
//! ```sh
//! cargo run --release -p nuvo-atlas --example boundary_sources -- RUN/atlas.obj
//! ```
//!
//! Prints the share of the seen pixels and of the boundary pixels on islands and on mesh pieces
//! (faces joined through shared vertex *positions*, so seams do not split a piece) by their face
//! count, and whether each boundary pixel's neighbour sees the same piece (a seam cut through the
//! surface) or another one (a floater or fragment lying on it). Why: on fragmented inputs Boundary
//! is most of what Editability misses, and the fix differs by cause (BENCHMARKS.md, "The generated
//! family").

use std::collections::HashMap;
use std::path::PathBuf;

use nuvo_atlas::load::load_mesh_with_uv;
use nuvo_atlas::metrics::{EvalOptions, boundary_pixels};
use nuvo_atlas::orbit_views;
use nuvo_atlas::render::render;
use nuvo_atlas::uvstats::{Dsu, uv_charts};

const SIZES: [&str; 5] = ["< 10", "10–99", "100–999", "1k–10k", "≥ 10k"];

fn size_class(faces: usize) -> usize {
    match faces {
        0..=9 => 0,
        10..=99 => 1,
        100..=999 => 2,
        1000..=9999 => 3,
        _ => 4,
    }
}

/// Per face, its piece: faces joined through vertices at bit-identical positions.
fn pieces(positions: &[[f32; 3]], triangles: &[[u32; 3]]) -> Vec<u32> {
    let mut id: HashMap<[u32; 3], u32> = HashMap::new();
    let vertex: Vec<u32> = positions
        .iter()
        .map(|p| {
            let next = id.len() as u32;
            *id.entry(p.map(f32::to_bits)).or_insert(next)
        })
        .collect();
    let mut dsu = Dsu::new(id.len());
    for t in triangles {
        dsu.union(vertex[t[0] as usize], vertex[t[1] as usize]);
        dsu.union(vertex[t[0] as usize], vertex[t[2] as usize]);
    }
    triangles.iter().map(|t| dsu.find(vertex[t[0] as usize])).collect()
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let path: PathBuf = std::env::args_os().nth(1).ok_or("usage: boundary_sources ATLAS.obj")?.into();
    let mesh = load_mesh_with_uv(&path)?;
    let uv = mesh.uv.as_ref().ok_or("the mesh has no texture coordinates")?;
    let (island, islands) = uv_charts(&mesh, uv);
    let mut island_faces = vec![0usize; islands];
    for &i in &island {
        island_faces[i as usize] += 1;
    }
    let piece = pieces(&mesh.positions, &mesh.triangles);
    let mut piece_faces: HashMap<u32, usize> = HashMap::new();
    for &p in &piece {
        *piece_faces.entry(p).or_default() += 1;
    }
    let opts = EvalOptions::default();
    let bounds = mesh.bounds().ok_or("the mesh is empty")?;
    let cameras = orbit_views(&bounds, opts.views, opts.seed, opts.resolution, opts.resolution);
    // [by island size, by piece size] × size class.
    let (mut seen, mut boundary) = ([[0usize; 5]; 2], [[0usize; 5]; 2]);
    let (mut same_piece, mut other_piece) = (0usize, 0usize);
    for camera in &cameras {
        let g = render(&mesh, camera)?;
        let class =
            |f: usize| [size_class(island_faces[island[f] as usize]), size_class(piece_faces[&piece[f]])];
        for p in g.pixels.iter().filter_map(|p| p.hit()) {
            for (k, c) in class(p as usize).into_iter().enumerate() {
                seen[k][c] += 1;
            }
        }
        for (i, j) in boundary_pixels(uv, None, &g, &opts.image) {
            let (f, q) = (g.pixels[i].hit().unwrap() as usize, g.pixels[j].hit().unwrap() as usize);
            for (k, c) in class(f).into_iter().enumerate() {
                boundary[k][c] += 1;
            }
            if piece[f] == piece[q] { same_piece += 1 } else { other_piece += 1 }
        }
    }
    let (hits, edges): (usize, usize) = (seen[0].iter().sum(), boundary[0].iter().sum());
    println!(
        "{}: {islands} islands, {} pieces; {hits} pixels seen, {edges} on a boundary (Boundary ≈ {:.4})",
        path.display(),
        piece_faces.len(),
        1.0 - edges as f64 / hits.max(1) as f64
    );
    for (k, by) in ["island", "piece"].iter().enumerate() {
        println!("by {by} size (faces): share of seen pixels, of boundary pixels, boundary rate");
        for c in 0..5 {
            println!(
                "  {:>8}  {:5.1}%  {:5.1}%  {:.3}",
                SIZES[c],
                100.0 * seen[k][c] as f64 / hits.max(1) as f64,
                100.0 * boundary[k][c] as f64 / edges.max(1) as f64,
                boundary[k][c] as f64 / seen[k][c].max(1) as f64
            );
        }
    }
    println!(
        "boundary pixels whose neighbour sees the same piece: {same_piece}; another piece: {other_piece}"
    );
    Ok(())
}
