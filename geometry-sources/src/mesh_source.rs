//! The `mesh` geometry source: a triangle mesh file sampled area-uniformly or by visibility.
//!
//! ```toml
//! [geometry]
//! source = "mesh"
//! path = "unruly_vase.obj"     # .obj, .gltf, .glb or .ply (with faces)
//! sampling = "visible"         # or "uniform" (default)
//! normals = "face"             # or "vertex"
//! flip_normals = false         # true for a mesh wound inside out
//! [geometry.cameras]           # visible mode only; see CameraOptions
//! radius = 3.0
//! ```

use std::path::PathBuf;

use serde::Deserialize;

use crate::camera::{CameraOptions, CameraRig, area_radius};
use crate::error::GeometryError;
use crate::frame::{Aabb, Similarity};
use crate::mesh::TriMesh;
use crate::options::{options_error, parse_options};
use crate::registry::BuildContext;
use crate::sampling::uniform::{AreaSampler, sample_uniform};
use crate::sampling::visible::VisibleSampler;
use crate::sampling::{NormalMode, SurfaceNormals};
use crate::source::{GeometrySource, SurfaceSamples};

/// How mesh samples are drawn.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SamplingMode {
    /// Uniform by area over every face: for clean, well-behaved meshes (the paper's default).
    #[default]
    Uniform,
    /// First hits of random camera rays: for meshes extracted from NeRFs, whose hidden interior
    /// geometry must not be sampled.
    Visible,
}

/// Options of the `mesh` source (the `[geometry]` table).
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct MeshOptions {
    /// The mesh file: `.obj`, `.gltf`, `.glb` or `.ply` (with faces). Relative paths resolve
    /// against the config's folder.
    /// Required.
    pub path: PathBuf,
    /// `"uniform"` (default) or `"visible"`.
    #[serde(default)]
    pub sampling: SamplingMode,
    /// `"face"` (default): the triangle's normal; `"vertex"`: interpolated vertex normals.
    #[serde(default)]
    pub normals: NormalMode,
    /// Point every normal the other way (default false): for a mesh wound inside out, whose
    /// triangles are clockwise seen from outside. `nuvo unwrap` sets it when the mesh profile finds
    /// that rays leave the surface through the back of its faces (`nuvo_geometry::profile`).
    #[serde(default)]
    pub flip_normals: bool,
    /// Cameras for `sampling = "visible"` (ignored otherwise). Defaults: random cameras at radius 3.
    #[serde(default)]
    pub cameras: Option<CameraOptions>,
}

enum Sampler {
    Uniform(AreaSampler),
    Visible(Box<VisibleSampler>),
}

/// A mesh in the canonical frame with its sampler. The canonical frame normalises the bounding box of
/// all vertices ([`TriMesh::bounds`], unreferenced ones included, so the handed-out mesh stays inside
/// `[-1, 1]^3`); vertex order, faces and UVs are kept exactly as loaded, so a UV'd mesh written back
/// with the inverse map matches the input.
pub struct MeshSource {
    path: PathBuf,
    mesh: TriMesh,
    /// The vertex positions exactly as loaded, so writers can give them back bit for bit.
    input_positions: Vec<[f32; 3]>,
    to_canonical: Similarity,
    bounds: Aabb,
    normals: SurfaceNormals,
    sampler: Sampler,
}

impl MeshSource {
    /// The registry builder.
    pub fn build(table: &toml::Table, ctx: &BuildContext) -> Result<Box<dyn GeometrySource>, GeometryError> {
        let opts: MeshOptions = parse_options("mesh", table)?;
        Ok(Box::new(MeshSource::new(&opts, ctx)?))
    }

    /// Loads, normalises and prepares the mesh (BVH for visible mode, area table for uniform mode).
    pub fn new(opts: &MeshOptions, ctx: &BuildContext) -> Result<MeshSource, GeometryError> {
        let path = ctx.resolve(&opts.path);
        let mesh = crate::load::load_mesh(&path)?;
        MeshSource::from_mesh(path, mesh, opts, ctx)
    }

    /// Prepares an already loaded mesh (in input coordinates); `path` is only used in messages.
    pub fn from_mesh(
        path: PathBuf,
        mut mesh: TriMesh,
        opts: &MeshOptions,
        ctx: &BuildContext,
    ) -> Result<MeshSource, GeometryError> {
        mesh.validate().map_err(|m| GeometryError::invalid(&path, m))?;
        let raw_bounds =
            mesh.bounds().ok_or_else(|| GeometryError::invalid(&path, "the mesh has no vertices"))?;
        let to_canonical = Similarity::normalizing(&raw_bounds);
        let input_positions = mesh.positions.clone();
        mesh.transform(&to_canonical);
        let bounds = mesh.bounds().unwrap_or(Aabb { min: [-1.0; 3], max: [1.0; 3] });
        // Both modes need positive area: the uniform sampler to draw from, the ray caster to hit.
        let areas = AreaSampler::new(&mesh).map_err(|m| GeometryError::invalid(&path, m))?;
        let normals = SurfaceNormals::new(&mesh, opts.normals);
        let normals = if opts.flip_normals { normals.flipped() } else { normals };
        let sampler = match opts.sampling {
            SamplingMode::Uniform => Sampler::Uniform(areas),
            SamplingMode::Visible => {
                let cam_opts = opts.cameras.clone().unwrap_or_default();
                let rig = CameraRig::from_options(&cam_opts, ctx, area_radius(&mesh), &to_canonical, "mesh")?;
                let vs = VisibleSampler::new(&mesh, rig, &normals).map_err(|m| options_error("mesh", m))?;
                Sampler::Visible(Box::new(vs))
            }
        };
        Ok(MeshSource { path, mesh, input_positions, to_canonical, bounds, normals, sampler })
    }

    /// The visible-mode sampler, when this source uses it.
    pub fn visible_sampler(&self) -> Option<&VisibleSampler> {
        match &self.sampler {
            Sampler::Visible(v) => Some(v),
            Sampler::Uniform(_) => None,
        }
    }
}

impl GeometrySource for MeshSource {
    fn kind(&self) -> &str {
        "mesh"
    }

    fn sample(&self, n: usize, seed: u64) -> SurfaceSamples {
        match &self.sampler {
            Sampler::Uniform(a) => sample_uniform(&self.mesh, a, &self.normals, n, seed),
            Sampler::Visible(v) => v.sample(&self.mesh, &self.normals, n, seed),
        }
    }

    fn bounds(&self) -> Aabb {
        self.bounds
    }

    fn to_canonical(&self) -> Similarity {
        self.to_canonical
    }

    fn mesh(&self) -> Option<&TriMesh> {
        Some(&self.mesh)
    }

    fn input_positions(&self) -> Option<&[[f32; 3]]> {
        Some(&self.input_positions)
    }

    fn file(&self) -> Option<&std::path::Path> {
        Some(&self.path)
    }

    fn describe(&self) -> String {
        let mode = match &self.sampler {
            Sampler::Uniform(_) => "uniform sampling".to_owned(),
            Sampler::Visible(v) => {
                format!("visible sampling, {}, {:.0}% of rays hit", v.rig().describe(), 100.0 * v.hit_rate())
            }
        };
        format!(
            "mesh {}: {} vertices, {} faces, {}{}",
            self.path.display(),
            self.mesh.positions.len(),
            self.mesh.triangles.len(),
            mode,
            if self.mesh.uv.is_some() { ", with UVs" } else { "" }
        )
    }
}
