//! The `density` geometry source: a NeRF-style volume density grid (`.npy`), sampled the way the
//! paper samples a NeRF: cast random camera rays, volume-render each through the density, pool the
//! rendering weights of all rays and resample "surface" points from them (inverse-transform
//! sampling over the normalised weights). Normals are the normalised negative density gradient.
//!
//! ```toml
//! [geometry]
//! source = "density"
//! path = "unruly_bunny.npy"
//! bounds = [[-1, -1, -1], [1, 1, 1]]   # where the first and last grid nodes sit (input coordinates)
//! ```
//!
//! **Canonical frame**: the grid's box (from `bounds`), normalised like any other input (centred,
//! longest half-extent 1), *not* the occupied region: the occupied region depends on a threshold,
//! and fog and floaters reach the box anyway.
//!
//! **Fog and floaters.** Volume rendering samples whatever carries rendering weight. Thin but
//! widespread fog adds up along a ray and, with a sigma_max high enough to make the surface crisp,
//! absorbs most rays before they reach the surface. So densities below `min_density` are treated as
//! empty space; for `uint8` grids it defaults to 3% of sigma_max ([`DEFAULT_MIN_RELATIVE_DENSITY`]),
//! for float grids to 0 (set it for a real NeRF's fog level). Floaters and the fuzzy shell above the
//! threshold are kept: cameras see them, and a NeRF user would see them too (they are a few percent
//! of the samples on the shared grids, more than 3 voxels from the extracted mesh). A threshold also
//! makes most of space exactly empty, which the renderer skips in blocks of 8³ voxels.
//!
//! **Mesh.** The source also hands out a triangle mesh ([`GeometrySource::mesh`]), the surface at
//! `mesh_level` extracted by marching cubes ([`crate::isosurface`]) from the stored values (before the
//! haze threshold), in the same canonical frame as the samples. The outputs bake the atlas onto it
//! when `[output] bake_mesh` is not set. It is extracted once, eagerly, when the source is built:
//! that costs well under a second for the shared 256³ grid on 2 cores (BENCHMARKS.md), while
//! extracting lazily, when the mesh is first asked for, would mean keeping a second copy of the grid
//! (4 bytes a node) alive for the whole run. `extract_mesh = false` skips it.

use std::path::{Path, PathBuf};

use glam::Vec3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::Deserialize;

use crate::camera::{CameraOptions, CameraRig, Ray, bounding_radius};
use crate::coords::V3;
use crate::error::GeometryError;
use crate::frame::{Aabb, Similarity};
use crate::isosurface::{NodeGrid, marching_cubes};
use crate::mesh::TriMesh;
use crate::npy::{Dtype, read_npy};
use crate::options::{options_error, parse_options};
use crate::registry::BuildContext;
use crate::seeding::par_generate;
use crate::source::{GeometrySource, SurfaceSamples};
use crate::volume::DensityGrid;

/// Default `sigma_max` of `uint8` grids: the density at value 255, per unit of input length, for a
/// grid spanning 2 units like the shared test grids (scaled with the grid otherwise). Measured with
/// `examples/sigma_sweep.rs` on `unruly_bunny.npy` and `unruly_vase.npy` (numbers in BENCHMARKS.md):
/// with the default haze threshold, rays stop within about a voxel of the level-12 surface (80th
/// percentile of the sample-to-mesh distance ≈ 1.0 voxel; 800 gives 1.2, 2400 a longer tail).
pub const DEFAULT_SIGMA_MAX: f32 = 1600.0;

/// Default haze threshold of `uint8` grids, as a fraction of sigma_max (≈ value 7.7 of 255, below
/// the shared grids' extraction level 12). Without it the log-normal fog of the shared grids absorbs
/// the rays before they reach the surface at any sigma_max (80th percentile ≥ 4.4 voxels off the
/// mesh): a NeRF user sees that haze as a veil in renderings, not as surface.
pub const DEFAULT_MIN_RELATIVE_DENSITY: f32 = 0.03;

/// Default `mesh_level` of `uint8` grids, in stored units: the level the shared grids' meshes were
/// extracted at (4.7% of full scale). It lies above the default haze threshold (7.65), so the mesh
/// does not wrap haze the sampler ignores, and it is where the sampler's rays stop: with the default
/// sigma_max the samples' median distance to the level-12 mesh is 0.46 voxels (BENCHMARKS.md).
pub const DEFAULT_U8_MESH_LEVEL: f32 = 12.0;

/// Rays cast at construction to check that the cameras see any density at all.
const PROBE_RAYS: usize = 4096;

fn default_bounds() -> [[f32; 3]; 2] {
    [[-1.0; 3], [1.0; 3]]
}

fn default_step_voxels() -> f32 {
    0.5
}

fn default_rays_per_sample() -> f32 {
    1.0
}

fn default_true() -> bool {
    true
}

/// Options of the `density` source (the `[geometry]` table).
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct DensityOptions {
    /// The grid: a 3-D `.npy` array (`uint8`, `float16` or `float32`), `array[i, j, k]` being the
    /// density at node `(x_i, y_j, z_k)`. Relative paths resolve against the config's folder.
    /// Required.
    pub path: PathBuf,
    /// `[[xmin, ymin, zmin], [xmax, ymax, zmax]]`: where the first and last nodes sit, in the input's
    /// coordinates. Default `[[-1, -1, -1], [1, 1, 1]]`.
    #[serde(default = "default_bounds")]
    pub bounds: [[f32; 3]; 2],
    /// Multiplier from stored values to volume density (per unit of input length). Default:
    /// `DEFAULT_SIGMA_MAX / 255 * (2 / longest side of bounds)` for `uint8` grids (whose values are
    /// fractions of sigma_max), 1 for float grids (assumed to hold densities already).
    pub scale: Option<f32>,
    /// Ray-marching step in voxels (node spacings). Default 0.5.
    #[serde(default = "default_step_voxels")]
    pub step_voxels: f32,
    /// Camera rays rendered per requested sample; the samples are drawn from the pooled weights of
    /// all of them. Default 1.
    #[serde(default = "default_rays_per_sample")]
    pub rays_per_sample: f32,
    /// Densities below this (per unit of input length, after `scale`) are treated as empty space, to
    /// remove haze (see the module docs). Default: 3% of sigma_max for `uint8` grids, 0 for float
    /// grids.
    pub min_density: Option<f32>,
    /// Where rays come from; defaults: random cameras at radius 3 around the grid's box.
    #[serde(default)]
    pub cameras: Option<CameraOptions>,
    /// The level, in stored units (before `scale`), of the surface extracted by marching cubes as
    /// this source's mesh; values at or above it are inside. Default: 12 for `uint8` grids
    /// ([`DEFAULT_U8_MESH_LEVEL`]); for float grids the density at which one voxel of matter absorbs
    /// half the light, `ln 2 / voxel size` (input units) divided by `scale`. Either default is raised
    /// to the haze threshold `min_density` (in stored units) when that is higher, so the mesh never
    /// wraps haze the sampler treats as empty. A level that no cell of the grid straddles is an error.
    pub mesh_level: Option<f32>,
    /// Whether to extract that mesh when the source is built (default true). Set false to save the
    /// time and memory when `[output] bake_mesh` names a mesh anyway, or when per-point UVs suffice.
    #[serde(default = "default_true")]
    pub extract_mesh: bool,
}

/// A rendered ray of the first pass: enough to re-march it identically in the second.
#[derive(Clone, Copy)]
struct RayRecord {
    ray: Ray,
    seed: u64,
    weight: f32,
}

/// A density grid in the canonical frame with its cameras.
pub struct DensitySource {
    path: PathBuf,
    grid: DensityGrid,
    dims: Vec<usize>,
    dtype: Dtype,
    to_canonical: Similarity,
    bounds: Aabb,
    rig: CameraRig,
    step: f32,
    rays_per_sample: f32,
    /// Samples drawn at construction; used only if a batch's rays carry no weight at all.
    fallback: Vec<(V3, V3)>,
    /// The marching-cubes mesh (canonical frame) and its level in stored units, unless
    /// `extract_mesh = false`.
    mesh: Option<(TriMesh, f32)>,
}

impl DensitySource {
    /// The registry builder.
    pub fn build(table: &toml::Table, ctx: &BuildContext) -> Result<Box<dyn GeometrySource>, GeometryError> {
        let opts: DensityOptions = parse_options("density", table)?;
        Ok(Box::new(DensitySource::new(&opts, ctx)?))
    }

    /// Reads and validates the grid, converts it to densities in the canonical frame, and checks that
    /// the cameras see something.
    pub fn new(opts: &DensityOptions, ctx: &BuildContext) -> Result<DensitySource, GeometryError> {
        check_options(opts)?;
        let path = ctx.resolve(&opts.path);
        let arr = read_npy(&path)?;
        let dims: [usize; 3] = match arr.shape[..] {
            [a, b, c] if a >= 2 && b >= 2 && c >= 2 => [a, b, c],
            [_, _, _] => {
                return Err(GeometryError::invalid(
                    &path,
                    format!("grid shape {:?} needs at least 2 nodes along every axis", arr.shape),
                ));
            }
            _ => {
                return Err(GeometryError::invalid(
                    &path,
                    format!(
                        "expected a 3-D density grid, found a {}-D array of shape {:?}",
                        arr.shape.len(),
                        arr.shape
                    ),
                ));
            }
        };
        if let Some(i) = arr.data.iter().position(|v| !v.is_finite()) {
            return Err(GeometryError::invalid(
                &path,
                format!("value {i} (C order) is not finite: {}", arr.data[i]),
            ));
        }
        let [lo, hi] = opts.bounds;
        let raw = Aabb { min: lo, max: hi };
        let to_canonical = Similarity::normalizing(&raw);
        let longest = 2.0 * raw.max_half_extent();
        let scale_value = opts.scale.unwrap_or(match arr.dtype {
            Dtype::U8 => DEFAULT_SIGMA_MAX / 255.0 * (2.0 / longest),
            Dtype::F16 | Dtype::F32 => 1.0,
        });
        // sigma_canonical = sigma_input / s, because canonical lengths are s times input lengths.
        let to_canon_sigma = scale_value / to_canonical.scale;
        let min_density = opts.min_density.unwrap_or(match arr.dtype {
            Dtype::U8 => DEFAULT_MIN_RELATIVE_DENSITY * 255.0 * scale_value,
            Dtype::F16 | Dtype::F32 => 0.0,
        });
        let min_sigma = min_density / to_canonical.scale;
        let data: Vec<f32> = arr
            .data
            .iter()
            .map(|&v| {
                let s = v * to_canon_sigma;
                if s >= min_sigma && s > 0.0 { s } else { 0.0 }
            })
            .collect();
        let grid = DensityGrid::new(dims, data, to_canonical.apply(lo), to_canonical.apply(hi));
        let (cmin, cmax) = grid.bounds();
        let bounds = Aabb { min: cmin, max: cmax };
        // The whole grid box is framed: empty space is skipped cheaply, so misses cost little.
        let rig = CameraRig::from_options(
            &opts.cameras.clone().unwrap_or_default(),
            ctx,
            bounding_radius(&bounds),
            &to_canonical,
            "density",
        )?;
        let step = opts.step_voxels * grid.voxel_size();
        let mut src = DensitySource {
            path,
            grid,
            dims: arr.shape,
            dtype: arr.dtype,
            to_canonical,
            bounds,
            rig,
            step,
            rays_per_sample: opts.rays_per_sample,
            fallback: Vec::new(),
            mesh: None,
        };
        let probe = src.render_and_resample(PROBE_RAYS, PROBE_RAYS, 0x5052_4f42);
        if probe.is_empty() {
            return Err(GeometryError::invalid(
                &src.path,
                format!(
                    "none of {PROBE_RAYS} camera rays ({}) meets any density: the grid is empty, or `scale`, \
                     `min_density` or `bounds` are wrong",
                    src.rig.describe()
                ),
            ));
        }
        src.fallback = probe;
        if opts.extract_mesh {
            let voxel = (0..3).map(|k| (hi[k] - lo[k]) / (dims[k] - 1) as f32).fold(f32::INFINITY, f32::min);
            let level = opts
                .mesh_level
                .unwrap_or_else(|| default_mesh_level(arr.dtype, voxel, scale_value, min_density));
            let grid = NodeGrid { dims, values: &arr.data, min: cmin, max: cmax };
            src.mesh = Some((extract_mesh(&src.path, &grid, level)?, level));
        }
        Ok(src)
    }

    /// The density grid in the canonical frame (densities per canonical unit length).
    pub fn grid(&self) -> &DensityGrid {
        &self.grid
    }

    /// Renders `rays` random rays and draws `n` points from their pooled weights; empty when no ray
    /// carries any weight.
    fn render_and_resample(&self, rays: usize, n: usize, seed: u64) -> Vec<(V3, V3)> {
        let records = par_generate(rays, seed, 0x7261_7973, |rng, count| {
            (0..count)
                .map(|_| {
                    let ray = self.rig.random_ray(rng);
                    let seed = rng.random::<u64>();
                    let mut weight = 0.0f32;
                    self.grid
                        .march(&ray, self.step, &mut ChaCha8Rng::seed_from_u64(seed), |_, w| weight += w);
                    RayRecord { ray, seed, weight }
                })
                .collect()
        });
        let mut cdf = Vec::with_capacity(records.len());
        let mut total = 0.0f64;
        for r in &records {
            total += f64::from(r.weight);
            cdf.push(total);
        }
        if total.is_nan() || total <= 0.0 {
            return Vec::new();
        }
        // Inverse-transform sampling over the pooled weights: a uniform target in [0, total) picks
        // the ray whose cumulative interval holds it, and its offset picks the sample along the ray.
        let mut targets: Vec<f64> = par_generate(n, seed, 0x6472_6177, |rng, count| {
            (0..count).map(|_| rng.random::<f64>() * total).collect()
        });
        targets.sort_by(f64::total_cmp);
        let mut groups: Vec<(usize, Vec<f32>)> = Vec::new();
        for t in targets {
            let r = cdf.partition_point(|&c| c <= t).min(records.len() - 1);
            let local = (t - if r == 0 { 0.0 } else { cdf[r - 1] }) as f32;
            match groups.last_mut() {
                Some((last, v)) if *last == r => v.push(local),
                _ => groups.push((r, vec![local])),
            }
        }
        groups.par_iter().flat_map_iter(|(r, locals)| self.points_along(&records[*r], locals)).collect()
    }

    /// Re-marches `rec` and returns the sample where the cumulative weight first exceeds each of the
    /// (sorted) `locals`, with its normal.
    fn points_along(&self, rec: &RayRecord, locals: &[f32]) -> Vec<(V3, V3)> {
        let mut out = Vec::with_capacity(locals.len());
        let mut acc = 0.0f32;
        let mut last = None;
        let mut next = 0;
        self.grid.march(&rec.ray, self.step, &mut ChaCha8Rng::seed_from_u64(rec.seed), |t, w| {
            acc += w;
            last = Some(t);
            while next < locals.len() && locals[next] < acc {
                out.push(self.point(&rec.ray, t));
                next += 1;
            }
        });
        // Rounding can leave a target a hair above the re-accumulated total: use the last sample.
        if let Some(t) = last {
            while out.len() < locals.len() {
                out.push(self.point(&rec.ray, t));
            }
        }
        out
    }

    /// The point at `t` on `ray` with the normalised negative density gradient (or, where the
    /// gradient vanishes, the direction back to the camera).
    fn point(&self, ray: &Ray, t: f32) -> (V3, V3) {
        let p = ray.at(t);
        let n = (-Vec3::from(self.grid.gradient(p))).normalize_or(-Vec3::from(ray.dir));
        (p, n.to_array())
    }
}

/// The default `mesh_level` in stored units (see [`DensityOptions::mesh_level`]), for a grid whose
/// smallest node spacing is `voxel` input units, with `scale` and `min_density` resolved.
fn default_mesh_level(dtype: Dtype, voxel: f32, scale: f32, min_density: f32) -> f32 {
    let natural = match dtype {
        Dtype::U8 => DEFAULT_U8_MESH_LEVEL,
        Dtype::F16 | Dtype::F32 => std::f32::consts::LN_2 / voxel / scale,
    };
    natural.max(min_density / scale)
}

/// The marching-cubes mesh of `grid` (stored values, canonical frame) at `level`; an error naming the
/// values' range when the level meets no surface, since the user then gets no mesh to bake onto.
fn extract_mesh(path: &Path, grid: &NodeGrid, level: f32) -> Result<TriMesh, GeometryError> {
    let mesh = marching_cubes(grid, level);
    if mesh.has_area() {
        return Ok(mesh);
    }
    let lo = grid.values.iter().copied().fold(f32::INFINITY, f32::min);
    let hi = grid.values.iter().copied().fold(f32::NEG_INFINITY, f32::max);
    Err(GeometryError::invalid(
        path,
        format!(
            "mesh_level = {level} gives no surface to extract: the grid's values lie in [{lo}, {hi}] and no \
             cell has values on both sides of the level; set `mesh_level` inside that range, or \
             `extract_mesh = false` to train without the grid's own mesh"
        ),
    ))
}

fn check_options(opts: &DensityOptions) -> Result<(), GeometryError> {
    let bad = |m: String| options_error("density", m);
    let [lo, hi] = opts.bounds;
    if !(0..3).all(|k| lo[k].is_finite() && hi[k].is_finite() && lo[k] < hi[k]) {
        return Err(bad(format!("bounds = {:?} must be finite with min < max on every axis", opts.bounds)));
    }
    if let Some(s) = opts.scale
        && !(s > 0.0 && s.is_finite())
    {
        return Err(bad(format!("scale = {s} must be a positive number")));
    }
    if !(opts.step_voxels > 0.0 && opts.step_voxels <= 16.0) {
        return Err(bad(format!("step_voxels = {} must be in (0, 16]", opts.step_voxels)));
    }
    if !(opts.rays_per_sample > 0.0 && opts.rays_per_sample <= 1000.0) {
        return Err(bad(format!("rays_per_sample = {} must be in (0, 1000]", opts.rays_per_sample)));
    }
    if let Some(m) = opts.min_density
        && !(m >= 0.0 && m.is_finite())
    {
        return Err(bad(format!("min_density = {m} must be a finite number >= 0")));
    }
    if let Some(l) = opts.mesh_level
        && !l.is_finite()
    {
        return Err(bad(format!("mesh_level = {l} must be a finite number")));
    }
    Ok(())
}

impl GeometrySource for DensitySource {
    fn kind(&self) -> &str {
        "density"
    }

    fn sample(&self, n: usize, seed: u64) -> SurfaceSamples {
        if n == 0 {
            return SurfaceSamples::default();
        }
        let rays = ((n as f64 * f64::from(self.rays_per_sample)).ceil() as usize).max(1);
        let mut pairs = self.render_and_resample(rays, n, seed);
        if pairs.len() < n {
            // No ray of this batch met any density (possible only for tiny batches of a sparse
            // field): fall back to the construction-time samples.
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            while pairs.len() < n {
                pairs.push(self.fallback[rng.random_range(0..self.fallback.len())]);
            }
        }
        let (positions, normals) = pairs.into_iter().unzip();
        SurfaceSamples { positions, normals }
    }

    fn bounds(&self) -> Aabb {
        self.bounds
    }

    fn to_canonical(&self) -> Similarity {
        self.to_canonical
    }

    fn mesh(&self) -> Option<&TriMesh> {
        self.mesh.as_ref().map(|(m, _)| m)
    }

    fn describe(&self) -> String {
        let mesh = match &self.mesh {
            Some((m, level)) => format!(
                "marching-cubes mesh at level {level}: {} vertices, {} faces",
                m.positions.len(),
                m.triangles.len()
            ),
            None => "no mesh (extract_mesh = false)".to_owned(),
        };
        format!(
            "density {}: {:?} {:?} grid, step {:.4}, {}, {mesh}",
            self.path.display(),
            self.dims,
            self.dtype,
            self.step,
            self.rig.describe()
        )
    }
}

/// A density grid's node bounds from the JSON header beside it (`NAME.json` with `bounds_min` and
/// `bounds_max`, as the shared grids have), if there is one: what the `bounds` option should be.
/// A header that is not JSON or has malformed corners is an error naming it.
pub fn header_bounds(grid: &Path) -> Result<Option<[[f32; 3]; 2]>, GeometryError> {
    let header = grid.with_extension("json");
    let Ok(text) = std::fs::read_to_string(&header) else { return Ok(None) };
    let bad = |m: &str| GeometryError::malformed(&header, format!("the grid's header {m}"));
    let json: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| bad(&format!("is not JSON: {e}")))?;
    let corner = |key: &str| -> Result<Option<[f32; 3]>, GeometryError> {
        let Some(v) = json.get(key) else { return Ok(None) };
        let a: Vec<f32> = v
            .as_array()
            .filter(|a| a.len() == 3)
            .and_then(|a| a.iter().map(|x| x.as_f64().map(|x| x as f32)).collect())
            .ok_or_else(|| bad(&format!("has a `{key}` that is not three numbers")))?;
        Ok(Some([a[0], a[1], a[2]]))
    };
    match (corner("bounds_min")?, corner("bounds_max")?) {
        (Some(lo), Some(hi)) => Ok(Some([lo, hi])),
        _ => Ok(None),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_bounds_come_from_the_json_beside_the_grid() {
        let dir = tempfile::tempdir().unwrap();
        let grid = dir.path().join("g.npy");
        assert_eq!(header_bounds(&grid).unwrap(), None);
        let header = dir.path().join("g.json");
        std::fs::write(&header, r#"{"bounds_min": [-1, -2, -1], "bounds_max": [1, 2, 1.5]}"#).unwrap();
        assert_eq!(header_bounds(&grid).unwrap(), Some([[-1.0, -2.0, -1.0], [1.0, 2.0, 1.5]]));
        std::fs::write(&header, r#"{"level": 12}"#).unwrap();
        assert_eq!(header_bounds(&grid).unwrap(), None);
        std::fs::write(&header, r#"{"bounds_min": [0, 0], "bounds_max": [1, 1, 1]}"#).unwrap();
        let e = header_bounds(&grid).unwrap_err().to_string();
        assert!(e.contains("g.json") && e.contains("`bounds_min`"), "{e}");
        std::fs::write(&header, "not json").unwrap();
        assert!(header_bounds(&grid).unwrap_err().to_string().contains("is not JSON"));
    }
}
