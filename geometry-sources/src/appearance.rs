//! The colour of the input surface, read where the input has it, so a new atlas can carry the
//! appearance over (issue 22): per-vertex colours (OBJ `v x y z r g b`, glTF `COLOR_0`), base-colour
//! textures through the input's own UVs (OBJ + MTL `map_Kd`, glTF `baseColorTexture`), and the
//! colours of a point cloud's points (PLY `red green blue`, `.xyz` with nine columns).
//!
//! **Colours** are sRGB-encoded values in `[0, 1]`: images' and OBJ/PLY/XYZ colours as stored
//! (by convention sRGB), glTF's linear `COLOR_0` and `baseColorFactor` encoded as read.
//!
//! **Nothing lost.** An image that is missing, unreadable or in an unsupported encoding is a
//! *warning* naming the file (the material then has no texture); only geometry that cannot be read
//! is an error, exactly where [`crate::load_mesh`] or the point readers fail.
//!
//! # What is read
//!
//! | input | colours |
//! |---|---|
//! | `.obj` | `v x y z r g b` vertex colours; per face its `usemtl` material from the `mtllib` files: `Kd` (base colour, white without one) and `map_Kd` (texture; `Kd` is then not applied, as exporters write it beside a texture as a fallback) |
//! | `.gltf`, `.glb` | `COLOR_0` (`VEC3`/`VEC4`; float, normalised `ubyte` or `ushort`); per primitive its material's `pbrMetallicRoughness.baseColorFactor` (RGB) and `baseColorTexture` (a `data:` URI, a file next to the `.gltf`, or a buffer view) |
//! | `.ply` | the `vertex` element's `red green blue` (or `r g b`, or `diffuse_red diffuse_green diffuse_blue`): integers `0..=255` (`ushort`: `0..=65535`), `float`/`double` in `[0, 1]` |
//! | `.xyz`, `.txt`, `.pts` | nine columns `x y z nx ny nz r g b` (`0..=255` when any colour value exceeds 1, else `[0, 1]`) |
//! | anything else (`.npy` density grids, ...) | none |
//!
//! The geometry is read by the crate's own readers, so [`SurfaceColours::mesh`] is exactly
//! [`crate::load_mesh`]'s mesh (the OBJ's own vertex order, the glTF scene merged) and
//! [`PointColours::positions`] exactly [`crate::point_cloud::read_points`]' positions.
//!
//! # Conventions
//!
//! - **Vertex colours** are in the mesh's vertex order: an OBJ's `v` lines in file order (even
//!   when the faces use them out of order), a glTF's merged primitives (vertices of primitives
//!   without `COLOR_0` are white; without any `COLOR_0`, there are no vertex colours). OBJ colours
//!   are `0..=255` when any value of the file exceeds 1, else `[0, 1]`. glTF's `COLOR_0` and
//!   `baseColorFactor` are linear light by the glTF spec and are encoded to sRGB as read, so
//!   that every colour here (and the baked texture) is in one encoding.
//! - **Textures** are sampled through the mesh's [`crate::UvLayer`], which is in OBJ's
//!   convention (`v` up) for both formats (the glTF reader already stored `(u, 1 - v)`), so
//!   [`ColourImage::sample`] serves both: bilinear, pixel centres at `((i + 0.5) / w,
//!   1 - (j + 0.5) / h)`, wrapping (`REPEAT`) outside `[0, 1]`. A texture file is looked up
//!   relative to the folder of the OBJ's MTL file (then the OBJ's own folder; a `\` in the name is
//!   also tried as `/`), a glTF image relative to the `.gltf` file.
//! - **The colour of a surface point** ([`SurfaceColours::colour`]) is its interpolated vertex
//!   colour (white without) times its face's material base colour times the material's texture at
//!   the interpolated UV, clamped to `[0, 1]`. Faces without a material (no `usemtl`, an unknown
//!   material name, a glTF primitive without `material`) are white.
//! - **Nothing worth carrying.** [`LoadedColours::colours`] is `None` for a mesh without vertex
//!   colours, without a texture that could be read, and whose faces all have the same base colour
//!   (a single `Kd` or `baseColorFactor` is not appearance); faces without a material count as
//!   white there. Point files are `None` without colour columns or properties.
//!
//! # Warnings
//!
//! Each warning starts with the file it is about and says what is ignored:
//! - only some OBJ `v` lines have colours (vertex colours are ignored), or only some of a PLY
//!   colour triple's properties are present (point colours are ignored);
//! - an `mtllib` that does not exist or cannot be read (its materials are ignored);
//! - `map_Kd` options that change the mapping (`-o`, `-s`, `-t`, `-clamp on`) are not applied (the
//!   file name is the last word of a value that starts with `-`);
//! - a texture that is missing, unreadable, not PNG/JPEG, corrupt or larger than
//!   16384×16384 pixels (the material keeps its base colour);
//! - a texture on a mesh without texture coordinates (the texture is ignored);
//! - glTF: a `baseColorTexture` with `texCoord` other than 0 (the texture is ignored), a file using
//!   `KHR_texture_transform` (transforms are ignored), a sampler that does not repeat (sampled
//!   with `REPEAT` anyway), an unreadable `COLOR_0` (that primitive's vertices are white).
//!
//! Textures of materials no face uses are not decoded (and not warned about).
//!
//! # Colour anywhere in space
//!
//! [`NearestColour`] answers the colour at any point: the surface colour at the nearest point of
//! the mesh's faces with positive area (parry3d), or for a point cloud the inverse-squared-distance
//! weighted mean of the four nearest points' colours (an exact hit takes that point's colour).

use std::num::NonZero;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::error::GeometryError;
use crate::frame::Similarity;
use crate::mesh::TriMesh;
use crate::raycast::RayCaster;

mod gltf_colours;
mod image_io;
mod obj_mtl;
#[cfg(test)]
mod tests;

/// An RGB colour, each channel in `[0, 1]`.
pub type Rgb = [f32; 3];

/// A decoded image, row 0 at the top (as image files store it).
#[derive(Clone, Debug, PartialEq)]
pub struct ColourImage {
    /// Where it came from (a file path, or `file.glb image 2` for an embedded one), for messages.
    pub origin: String,
    /// Width in pixels (≥ 1).
    pub width: u32,
    /// Height in pixels (≥ 1).
    pub height: u32,
    /// Row-major RGB, 8 bits per channel (alpha dropped).
    pub pixels: Vec<[u8; 3]>,
}

impl ColourImage {
    /// Bilinear lookup at texture coordinate `uv` in the OBJ convention (`v` up: `v = 0` is the
    /// bottom row), wrapping around (`REPEAT`, the default of glTF and OBJ) outside `[0, 1]`.
    ///
    /// Pixel `(i, j)` (column `i`, row `j` from the top) has its centre at
    /// `((i + 0.5) / width, 1 - (j + 0.5) / height)`, where the lookup returns it exactly. A
    /// non-finite coordinate counts as 0; an image whose `pixels` do not fill `width × height`
    /// reads as white where they are missing.
    pub fn sample(&self, uv: [f32; 2]) -> Rgb {
        let (w, h) = (i64::from(self.width.max(1)), i64::from(self.height.max(1)));
        let finite = |x: f32| if x.is_finite() { f64::from(x) } else { 0.0 };
        // Continuous pixel coordinates with pixel centres on integers, rows counted from the top.
        let x = finite(uv[0]) * w as f64 - 0.5;
        let y = (1.0 - finite(uv[1])) * h as f64 - 0.5;
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = ((x - x0) as f32, (y - y0) as f32);
        let (x0, y0) = (x0 as i64, y0 as i64);
        let texel = |i: i64, j: i64| -> [f32; 3] {
            let (i, j) = (i.rem_euclid(w), j.rem_euclid(h));
            let p = self.pixels.get((j * w + i) as usize).copied().unwrap_or([255; 3]);
            p.map(|c| f32::from(c) / 255.0)
        };
        let (a, b) = (texel(x0, y0), texel(x0 + 1, y0));
        let (c, d) = (texel(x0, y0 + 1), texel(x0 + 1, y0 + 1));
        std::array::from_fn(|k| {
            let top = a[k] + (b[k] - a[k]) * fx;
            let bottom = c[k] + (d[k] - c[k]) * fx;
            top + (bottom - top) * fy
        })
    }
}

/// One material of a mesh file: its base colour (OBJ `Kd`, glTF `baseColorFactor`'s RGB) times
/// its texture, when it has one that could be read.
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    /// The material's name in the file (may be empty).
    pub name: String,
    /// Multiplies the texture (or is the colour, without one).
    pub base_colour: Rgb,
    /// The decoded base-colour texture, sampled through the mesh's own UVs.
    pub texture: Option<Arc<ColourImage>>,
}

/// The colour of a mesh file's surface.
///
/// Invariants: `mesh` is exactly what [`crate::load_mesh`] returns for the file (input coordinates,
/// the file's vertex and face order, its UVs); `vertex_colours`, when present, has one entry per
/// vertex of `mesh`; `face_material` has one entry per face, each `< materials.len()` or
/// [`NO_MATERIAL`]; a material with a texture implies `mesh.uv` is present.
#[derive(Clone, Debug, PartialEq)]
pub struct SurfaceColours {
    /// The file's mesh.
    pub mesh: TriMesh,
    /// Per-vertex colours, when the file has them.
    pub vertex_colours: Option<Vec<Rgb>>,
    /// The materials the faces use.
    pub materials: Vec<Material>,
    /// Per face, its material, or [`NO_MATERIAL`].
    pub face_material: Vec<u32>,
}

/// `face_material` of a face without a material (white).
pub const NO_MATERIAL: u32 = u32::MAX;

impl SurfaceColours {
    /// The colour at barycentrics `bary` of face `face`: vertex colours interpolated, times the
    /// face's material (its base colour times its texture at the interpolated UV). White where the
    /// file says nothing.
    ///
    /// Panics when `face` is not a face of [`SurfaceColours::mesh`].
    pub fn colour(&self, face: usize, bary: [f32; 3]) -> Rgb {
        let corners = self.mesh.triangles[face];
        let mut colour = match &self.vertex_colours {
            Some(vc) => std::array::from_fn(|k| (0..3).map(|c| bary[c] * vc[corners[c] as usize][k]).sum()),
            None => [1.0; 3],
        };
        let material = self.face_material.get(face).and_then(|&m| self.materials.get(m as usize));
        if let Some(material) = material {
            colour = std::array::from_fn(|k| colour[k] * material.base_colour[k]);
            if let (Some(texture), Some(uv)) = (&material.texture, &self.mesh.uv) {
                let t = uv.triangles[face].map(|i| uv.coords[i as usize]);
                let at = std::array::from_fn(|k| (0..3).map(|c| bary[c] * t[c][k]).sum());
                let texel = texture.sample(at);
                colour = std::array::from_fn(|k| colour[k] * texel[k]);
            }
        }
        colour.map(unit)
    }
}

/// Coloured points (a point cloud's).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PointColours {
    /// Positions as stored (input coordinates).
    pub positions: Vec<[f32; 3]>,
    /// One colour per point.
    pub colours: Vec<Rgb>,
}

/// Colour that an input carries.
#[derive(Clone, Debug, PartialEq)]
pub enum Colours {
    /// A mesh with vertex colours, textures or several material colours.
    Surface(SurfaceColours),
    /// A point cloud with per-point colours.
    Points(PointColours),
}

/// What [`load_colours`] found: the colours (`None` when the file carries none: no vertex or point
/// colours, no texture that could be read, and at most one material colour), and warnings about
/// what could not be used (each names the file and the problem).
#[derive(Clone, Debug, PartialEq)]
pub struct LoadedColours {
    /// The colours, if the file has any.
    pub colours: Option<Colours>,
    /// What could not be used and why (missing or unreadable images, unsupported encodings, ...).
    pub warnings: Vec<String>,
}

/// Reads the colours of any supported input: meshes (`.obj` + its MTL files, `.gltf`, `.glb`) and
/// point clouds (`.ply`, `.xyz`, `.txt`, `.pts`). Other extensions (e.g. a density grid `.npy`) have
/// no colour: `Ok` with `colours: None`. Errors only where the geometry itself cannot be read.
pub fn load_colours(path: &Path) -> Result<LoadedColours, GeometryError> {
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).unwrap_or_default();
    match ext.as_str() {
        "obj" => obj_mtl::obj_colours(path),
        "gltf" | "glb" => gltf_colours::gltf_colours(path),
        "ply" if crate::ply::declares_faces(path) => ply_mesh_colours(path),
        "ply" | "xyz" | "txt" | "pts" => point_colours(path, &ext),
        _ => Ok(LoadedColours { colours: None, warnings: Vec::new() }),
    }
}

/// The vertex colours of a PLY mesh (a PLY with faces).
fn ply_mesh_colours(path: &Path) -> Result<LoadedColours, GeometryError> {
    let (mesh, colours, warning) = crate::ply::read_ply_mesh_coloured(path)?;
    let warnings = warning.map(|w| format!("{}: {w}", path.display())).into_iter().collect();
    let face_material = vec![NO_MATERIAL; mesh.triangles.len()];
    let vertex_colours = colours.map(|c| c.into_iter().map(|c| c.map(unit)).collect());
    Ok(finish_surface(
        SurfaceColours { mesh, vertex_colours, materials: Vec::new(), face_material },
        warnings,
    ))
}

/// The colours of a point file (`ext` is `ply`, or a plain-text extension).
fn point_colours(path: &Path, ext: &str) -> Result<LoadedColours, GeometryError> {
    GeometryError::require_file(path)?;
    let mut warnings = Vec::new();
    let (positions, colours) = if ext == "ply" {
        let (positions, colours, warning) = crate::ply::read_ply_colours(path)?;
        warnings.extend(warning.map(|w| format!("{}: {w}", path.display())));
        (positions, colours.map(|c| c.into_iter().map(|c| c.map(unit)).collect()))
    } else {
        let (set, colours) = crate::xyz::read_xyz_colours(path)?;
        (set.positions, colours.map(scale_colours))
    };
    let colours = colours.map(|colours| Colours::Points(PointColours { positions, colours }));
    Ok(LoadedColours { colours, warnings })
}

/// Colours written either in `[0, 1]` or, when any value exceeds 1, in `0..=255`, scaled to
/// `[0, 1]` (clamped; non-finite values become 0).
fn scale_colours(mut colours: Vec<Rgb>) -> Vec<Rgb> {
    let max = if colours.iter().flatten().any(|&v| v > 1.0) { 255.0 } else { 1.0 };
    for c in &mut colours {
        *c = c.map(|v| unit(v / max));
    }
    colours
}

/// `x` clamped to `[0, 1]`, 0 when not a number.
fn unit(x: f32) -> f32 {
    if x.is_nan() { 0.0 } else { x.clamp(0.0, 1.0) }
}

/// Wraps a mesh's colours up, `None` when they carry nothing (see [`LoadedColours::colours`]).
fn finish_surface(surface: SurfaceColours, warnings: Vec<String>) -> LoadedColours {
    let face_base = |&m: &u32| surface.materials.get(m as usize).map_or([1.0; 3], |m| m.base_colour);
    let textured = surface
        .face_material
        .iter()
        .any(|&m| surface.materials.get(m as usize).is_some_and(|m| m.texture.is_some()));
    let first = surface.face_material.first().map(face_base);
    let several_colours = surface.face_material.iter().any(|m| Some(face_base(m)) != first);
    let carries = surface.vertex_colours.is_some() || textured || several_colours;
    LoadedColours { colours: carries.then_some(Colours::Surface(surface)), warnings }
}

/// The colour of the nearest surface point (a mesh) or of the nearest points (a point cloud) to any
/// point in space, for baking colour onto geometry other than the coloured file's own faces.
///
/// It is `Send + Sync`: build it once and query it from many threads.
pub struct NearestColour {
    index: NearestIndex,
}

/// What [`NearestColour`] searches.
enum NearestIndex {
    /// The faces with positive area, in the query frame, and the colours to evaluate there.
    Surface { caster: Box<RayCaster>, colours: Box<SurfaceColours> },
    /// The points with finite coordinates (`tree` is `None` without any) and their colours, in
    /// the tree's item order.
    Points { tree: Option<kiddo::ImmutableKdTree<f32, 3>>, colours: Vec<Rgb> },
}

/// How many points [`NearestColour`] averages for a point cloud.
const POINT_NEIGHBOURS: usize = 4;

impl NearestColour {
    /// Indexes `colours` for queries in the frame `to_frame` maps input coordinates to (e.g. a
    /// source's `to_canonical`).
    pub fn new(colours: &Colours, to_frame: &Similarity) -> NearestColour {
        let index = match colours {
            Colours::Surface(surface) => {
                let mut mesh = surface.mesh.clone();
                mesh.uv = None;
                mesh.transform(to_frame);
                NearestIndex::Surface {
                    caster: Box::new(RayCaster::build(&mesh)),
                    colours: Box::new(surface.clone()),
                }
            }
            Colours::Points(points) => {
                let (positions, colours): (Vec<[f32; 3]>, Vec<Rgb>) = points
                    .positions
                    .iter()
                    .zip(&points.colours)
                    .map(|(p, c)| (to_frame.apply(*p), *c))
                    .filter(|(p, _)| p.iter().all(|x| x.is_finite()))
                    .unzip();
                let tree =
                    (!positions.is_empty()).then(|| kiddo::ImmutableKdTree::new_from_slice(&positions));
                NearestIndex::Points { tree, colours }
            }
        };
        NearestColour { index }
    }

    /// The colour at the surface point nearest `p` (in the frame given to [`NearestColour::new`]).
    ///
    /// White when there is nothing to ask (no face with positive area, no point with finite
    /// coordinates) or `p` is not finite.
    pub fn colour_at(&self, p: [f32; 3]) -> Rgb {
        if !p.iter().all(|x| x.is_finite()) {
            return [1.0; 3];
        }
        match &self.index {
            NearestIndex::Surface { caster, colours } => match caster.nearest(p) {
                Some((face, bary)) => colours.colour(face as usize, bary),
                None => [1.0; 3],
            },
            NearestIndex::Points { tree: Some(tree), colours } => {
                let near =
                    tree.nearest_n::<kiddo::SquaredEuclidean>(&p, NonZero::new(POINT_NEIGHBOURS).unwrap());
                if let Some(hit) = near.iter().find(|n| n.distance == 0.0) {
                    return colours[hit.item as usize];
                }
                let mut sum = [0.0f64; 3];
                let mut weights = 0.0f64;
                for n in &near {
                    let w = 1.0 / f64::from(n.distance);
                    let c = colours[n.item as usize];
                    for k in 0..3 {
                        sum[k] += w * f64::from(c[k]);
                    }
                    weights += w;
                }
                if weights > 0.0 && weights.is_finite() {
                    sum.map(|s| unit((s / weights) as f32))
                } else {
                    near.first().map_or([1.0; 3], |n| colours[n.item as usize])
                }
            }
            _ => [1.0; 3],
        }
    }
}

/// The path an OBJ's `mtllib` (or a glTF's image URI) names, relative to the file's folder.
fn relative_to(file: &Path, name: &str) -> PathBuf {
    file.parent().unwrap_or(Path::new(".")).join(name)
}

/// The sRGB encoding of a linear-light value in `[0, 1]` (IEC 61966-2-1).
pub(crate) fn linear_to_srgb(x: f32) -> f32 {
    match x {
        x if x <= 0.003_130_8 => 12.92 * x,
        // Exact at 1, so white stays white (the formula gives 1 − 6e-8 in f32).
        x if x >= 1.0 => 1.0,
        x => 1.055 * x.powf(1.0 / 2.4) - 0.055,
    }
}
