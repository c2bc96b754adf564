//! The colour of the input surface, read where the input has it, so a new atlas can carry the
//! appearance over (issue 22): per-vertex colours (OBJ `v x y z r g b`, glTF `COLOR_0`), base-colour
//! textures through the input's own UVs (OBJ + MTL `map_Kd`, glTF `baseColorTexture`), and the
//! colours of a point cloud's points (PLY `red green blue`, `.xyz` with nine columns).
//!
//! **Colours** are the file's encoded values (sRGB for images and, by convention, for vertex
//! colours) scaled to `[0, 1]`; nothing here converts to linear light.
//!
//! **Nothing lost.** An image that is missing, unreadable or in an unsupported encoding is a
//! *warning* naming the file (the material then has no texture); only geometry that cannot be read
//! is an error, exactly where [`crate::load_mesh`] or the point readers fail.
//!
//! INTERFACE STUB: the bodies are filled in by the appearance work (issue 22).

use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::error::GeometryError;
use crate::frame::Similarity;
use crate::mesh::TriMesh;

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
    pub fn sample(&self, uv: [f32; 2]) -> Rgb {
        let _ = uv;
        unimplemented!("interface stub")
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
    pub fn colour(&self, face: usize, bary: [f32; 3]) -> Rgb {
        let _ = (face, bary);
        unimplemented!("interface stub")
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
    let _ = path;
    unimplemented!("interface stub")
}

/// The colour of the nearest surface point (a mesh) or of the nearest points (a point cloud) to any
/// point in space, for baking colour onto geometry other than the coloured file's own faces.
pub struct NearestColour {
    _private: (),
}

impl NearestColour {
    /// Indexes `colours` for queries in the frame `to_frame` maps input coordinates to (e.g. a
    /// source's `to_canonical`).
    pub fn new(colours: &Colours, to_frame: &Similarity) -> NearestColour {
        let _ = (colours, to_frame);
        unimplemented!("interface stub")
    }

    /// The colour at the surface point nearest `p` (in the frame given to [`NearestColour::new`]).
    pub fn colour_at(&self, p: [f32; 3]) -> Rgb {
        let _ = p;
        unimplemented!("interface stub")
    }
}

/// The path an OBJ's `mtllib` or `map_Kd` names, relative to the OBJ's folder.
#[allow(dead_code)]
fn relative_to(file: &Path, name: &str) -> PathBuf {
    file.parent().unwrap_or(Path::new(".")).join(name)
}
