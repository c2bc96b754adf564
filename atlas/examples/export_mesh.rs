//! Writes a UV'd mesh as OBJ + MTL + checkerboard PNG and as a textured GLB, for checking the
//! files in other tools (Blender, trimesh).
//!
//! ```sh
//! cargo run --release -p nuvo-atlas --example export_mesh -- /work/shared/data/meshes/spot.obj /tmp/out
//! ```

use std::path::PathBuf;

use nuvo_atlas::export::{GlbOptions, write_glb, write_obj};
use nuvo_atlas::load::load_mesh_with_uv;
use nuvo_atlas::pictures::{checkerboard, png_bytes, write_png};
use nuvo_geometry::Similarity;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let (Some(mesh), Some(dir)) = (args.next(), args.next()) else {
        return Err("usage: export_mesh MESH.obj OUT_DIR".into());
    };
    let dir = PathBuf::from(dir);
    std::fs::create_dir_all(&dir)?;
    let mesh = load_mesh_with_uv(mesh.as_ref())?;
    let texture = checkerboard(1024, 8)?;
    let png = dir.join("atlas.png");
    write_png(&png, &texture)?;
    write_obj(&dir.join("mesh.obj"), &mesh, &Similarity::IDENTITY, Some(&png))?;
    let bytes = png_bytes(&texture)?;
    write_glb(
        &dir.join("mesh.glb"),
        &mesh,
        &Similarity::IDENTITY,
        &GlbOptions { normals: true, texture_png: Some(&bytes) },
    )?;
    println!("wrote {}/{{mesh.obj, mesh.mtl, atlas.png, mesh.glb}}", dir.display());
    Ok(())
}
