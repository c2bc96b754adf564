//! The `point_cloud` geometry source: stored surface points (PLY or plain text), sampled by drawing
//! random points of the cloud (with replacement). Normals come from the file or are estimated
//! ([`crate::normals`]).
//!
//! ```toml
//! [geometry]
//! source = "point_cloud"
//! path = "stanford-bunny_200k.ply"   # .ply (ASCII or binary) or .xyz/.txt/.pts
//! normals = "auto"                    # "auto" (default), "file" or "estimate"
//! neighbors = 16
//! ```

use std::path::PathBuf;

use glam::Vec3;
use rand::Rng;
use serde::Deserialize;

use crate::coords::{V3, coordinate_problem};
use crate::error::GeometryError;
use crate::frame::{Aabb, Similarity};
use crate::load::dotted;
use crate::options::{options_error, parse_options};
use crate::ply::{PointSet, read_ply};
use crate::registry::BuildContext;
use crate::seeding::par_generate;
use crate::source::{GeometrySource, SurfaceSamples};

/// Point-cloud extensions (lower case).
pub const POINT_CLOUD_EXTENSIONS: &[&str] = &["ply", "xyz", "txt", "pts"];

/// Where point normals come from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum NormalSource {
    /// The file's normals when it has them, estimated otherwise.
    #[default]
    Auto,
    /// The file's normals; an error when the file has none.
    File,
    /// Always estimated, ignoring any normals in the file.
    Estimate,
}

fn default_neighbors() -> usize {
    16
}

/// Options of the `point_cloud` source (the `[geometry]` table).
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct PointCloudOptions {
    /// The point file: `.ply` (ASCII or binary; `vertex` element with `x y z` and optionally
    /// `nx ny nz`) or plain text `.xyz`/`.txt`/`.pts` (`x y z [nx ny nz [r g b]]` per line). Relative paths
    /// resolve against the config's folder. Required.
    pub path: PathBuf,
    /// `"auto"` (default), `"file"` or `"estimate"`; see [`NormalSource`].
    #[serde(default)]
    pub normals: NormalSource,
    /// Neighbours (including the point) used to estimate a normal. Default 16; at least 3.
    #[serde(default = "default_neighbors")]
    pub neighbors: usize,
}

/// A point cloud with unit normals in the canonical frame.
pub struct PointCloudSource {
    path: PathBuf,
    positions: Vec<V3>,
    normals: Vec<V3>,
    estimated: bool,
    to_canonical: Similarity,
    bounds: Aabb,
}

impl PointCloudSource {
    /// The registry builder.
    pub fn build(table: &toml::Table, ctx: &BuildContext) -> Result<Box<dyn GeometrySource>, GeometryError> {
        let opts: PointCloudOptions = parse_options("point_cloud", table)?;
        Ok(Box::new(PointCloudSource::new(&opts, ctx)?))
    }

    /// Reads, validates and normalises the cloud, estimating normals when needed.
    pub fn new(opts: &PointCloudOptions, ctx: &BuildContext) -> Result<PointCloudSource, GeometryError> {
        if opts.neighbors < 3 || opts.neighbors > 256 {
            return Err(options_error(
                "point_cloud",
                format!("neighbors = {} must be in 3..=256", opts.neighbors),
            ));
        }
        let path = ctx.resolve(&opts.path);
        let set = read_points(&path)?;
        PointCloudSource::from_points(path, set, opts)
    }

    /// Prepares points already read (in input coordinates); `path` is only used in messages.
    pub fn from_points(
        path: PathBuf,
        set: PointSet,
        opts: &PointCloudOptions,
    ) -> Result<PointCloudSource, GeometryError> {
        let PointSet { mut positions, normals } = set;
        if positions.is_empty() {
            return Err(GeometryError::invalid(&path, "the file holds no points"));
        }
        for (i, p) in positions.iter().enumerate() {
            if let Some(problem) = coordinate_problem(*p) {
                return Err(GeometryError::invalid(&path, format!("point {} has {problem}: {p:?}", i + 1)));
            }
        }
        let raw = Aabb::from_points(&positions).ok_or_else(|| GeometryError::invalid(&path, "no points"))?;
        let to_canonical = Similarity::normalizing(&raw);
        for p in &mut positions {
            *p = to_canonical.apply(*p);
        }
        let use_file = match (opts.normals, &normals) {
            (NormalSource::Estimate, _) | (NormalSource::Auto, None) => false,
            (NormalSource::File | NormalSource::Auto, Some(_)) => true,
            (NormalSource::File, None) => {
                return Err(GeometryError::invalid(
                    &path,
                    "normals = \"file\" but the file has no normals (nx ny nz)",
                ));
            }
        };
        let (normals, estimated) = match normals {
            Some(ns) if use_file => (unit_file_normals(&path, ns)?, false),
            _ => (crate::normals::estimate_normals(&positions, opts.neighbors), true),
        };
        let bounds = Aabb::from_points(&positions).unwrap_or(Aabb { min: [-1.0; 3], max: [1.0; 3] });
        Ok(PointCloudSource { path, positions, normals, estimated, to_canonical, bounds })
    }

    /// The points in the canonical frame.
    pub fn positions(&self) -> &[V3] {
        &self.positions
    }

    /// Their unit normals (from the file or estimated).
    pub fn normals(&self) -> &[V3] {
        &self.normals
    }
}

/// Reads a point file by extension.
pub fn read_points(path: &std::path::Path) -> Result<PointSet, GeometryError> {
    GeometryError::require_file(path)?;
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).unwrap_or_default();
    match ext.as_str() {
        "ply" => read_ply(path),
        "xyz" | "txt" | "pts" => crate::xyz::read_xyz(path),
        _ => Err(GeometryError::invalid(
            path,
            format!(
                "unsupported point-cloud extension `.{ext}`; supported: {}",
                dotted(POINT_CLOUD_EXTENSIONS)
            ),
        )),
    }
}

/// Normalises file normals (a similarity does not change directions); zero or non-finite ones are
/// errors.
fn unit_file_normals(path: &std::path::Path, normals: Vec<V3>) -> Result<Vec<V3>, GeometryError> {
    normals
        .into_iter()
        .enumerate()
        .map(|(i, n)| {
            Vec3::from(n).try_normalize().map(V3::from).ok_or_else(|| {
                GeometryError::invalid(
                    path,
                    format!("point {} has an unusable normal {n:?}; set normals = \"estimate\" to ignore the file's", i + 1),
                )
            })
        })
        .collect()
}

impl GeometrySource for PointCloudSource {
    fn kind(&self) -> &str {
        "point_cloud"
    }

    fn sample(&self, n: usize, seed: u64) -> SurfaceSamples {
        let idx = par_generate(n, seed, 0x706f_696e, |rng, count| {
            (0..count).map(|_| rng.random_range(0..self.positions.len())).collect()
        });
        SurfaceSamples {
            positions: idx.iter().map(|&i| self.positions[i]).collect(),
            normals: idx.iter().map(|&i| self.normals[i]).collect(),
        }
    }

    fn bounds(&self) -> Aabb {
        self.bounds
    }

    fn to_canonical(&self) -> Similarity {
        self.to_canonical
    }

    fn file(&self) -> Option<&std::path::Path> {
        Some(&self.path)
    }

    fn describe(&self) -> String {
        format!(
            "point cloud {}: {} points, {} normals",
            self.path.display(),
            self.positions.len(),
            if self.estimated { "estimated" } else { "file" }
        )
    }
}
