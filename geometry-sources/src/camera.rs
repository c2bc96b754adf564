//! Cameras and the random rays they shoot, shared by visible-surface mesh sampling and density-field
//! sampling (both follow the paper: "sample random camera rays").
//!
//! Two rigs: random cameras on a sphere around the object (the default; a fresh camera for every
//! ray, so views are spread evenly), or a fixed list of poses read from a JSON file (like the training
//! views of a NeRF). Every camera has a square image; a ray goes through a uniformly random point of
//! it.
//!
//! **Camera file** (JSON, positions in the *input's* coordinates, converted to the canonical frame on
//! load). Either a list of cameras, an object with a default field of view and a list, or a NeRF
//! `transforms.json` (instant-ngp / nerfstudio: `camera_angle_x` in radians and `frames` with 4×4
//! row-major camera-to-world `transform_matrix`, camera looking along its −Z axis):
//!
//! ```json
//! { "fov_degrees": 50,
//!   "cameras": [ { "position": [0, 0, 3], "look_at": [0, 0, 0] },
//!                { "position": [3, 0, 0], "look_at": [0, 0.1, 0], "fov_degrees": 30 } ] }
//! ```

use std::path::{Path, PathBuf};

use glam::Vec3;
use rand::Rng;
use serde::Deserialize;

use crate::coords::V3;
use crate::error::GeometryError;
use crate::frame::{Aabb, Similarity};
use crate::registry::BuildContext;

/// A ray; `dir` has unit length.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    /// Where the ray starts (the camera position).
    pub origin: V3,
    /// Unit direction.
    pub dir: V3,
}

impl Ray {
    /// The point at distance `t` along the ray, `origin + t * dir`.
    pub fn at(&self, t: f32) -> V3 {
        (Vec3::from(self.origin) + t * Vec3::from(self.dir)).to_array()
    }
}

/// A pinhole camera with a square image. Invariant: `forward`, `right`, `up` are orthonormal and
/// `tan_half_fov` is positive and finite.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// Camera centre in the canonical frame.
    pub position: V3,
    forward: V3,
    right: V3,
    up: V3,
    tan_half_fov: f32,
}

impl Camera {
    /// A camera at `position` looking at `target` with a full field of view of `fov_degrees`.
    pub fn look_at(position: V3, target: V3, fov_degrees: f32) -> Result<Camera, String> {
        if !Vec3::from(position).is_finite() || !Vec3::from(target).is_finite() {
            return Err(format!("camera position {position:?} or look-at {target:?} is not finite"));
        }
        if !(fov_degrees > 0.0 && fov_degrees < 179.0) {
            return Err(format!("field of view {fov_degrees}° must be in (0, 179)"));
        }
        let forward = (Vec3::from(target) - Vec3::from(position))
            .try_normalize()
            .ok_or_else(|| format!("camera at {position:?} looks at itself"))?;
        let world_up = if forward.y.abs() < 0.999 { Vec3::Y } else { Vec3::Z };
        let right = forward.cross(world_up).try_normalize().unwrap_or(Vec3::X);
        let up = right.cross(forward);
        Ok(Camera {
            position,
            forward: forward.to_array(),
            right: right.to_array(),
            up: up.to_array(),
            tan_half_fov: (0.5 * fov_degrees).to_radians().tan(),
        })
    }

    /// The ray through image point `(sx, sy)` in `[-1, 1]^2`.
    pub fn ray(&self, sx: f32, sy: f32) -> Ray {
        let t = self.tan_half_fov;
        let forward = Vec3::from(self.forward);
        let d = forward + sx * t * Vec3::from(self.right) + sy * t * Vec3::from(self.up);
        Ray { origin: self.position, dir: d.normalize_or(forward).to_array() }
    }

    /// The ray through a uniformly random image point.
    pub fn random_ray(&self, rng: &mut impl Rng) -> Ray {
        self.ray(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0))
    }
}

fn default_radius() -> f32 {
    3.0
}

fn default_jitter() -> f32 {
    0.05
}

/// Where rays come from: the `[geometry.cameras]` table of the `mesh` (visible mode) and `density`
/// sources. All lengths are in the canonical frame, where the object spans `[-1, 1]^3`.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct CameraOptions {
    /// Distance of the random cameras from the centre of the object. Default 3; must exceed the
    /// object's bounding-sphere radius (at most √3) plus the jitter.
    #[serde(default = "default_radius")]
    pub radius: f32,
    /// Random cameras look at a point drawn uniformly from the cube `[-jitter, jitter]^3` around the
    /// centre, so view directions do not all pass through one point. Default 0.05.
    #[serde(default = "default_jitter")]
    pub jitter: f32,
    /// Full field of view in degrees. Default for random cameras: just wide enough to see the sphere
    /// they frame (for meshes the sphere holding 99.5% of the surface area, see [`area_radius`]; for
    /// density grids the grid's bounding sphere); for a camera file: the file's value, else 50.
    pub fov_degrees: Option<f32>,
    /// A camera-pose file (JSON, see the module docs); relative paths resolve against the config's
    /// folder. When set, rays come from these cameras instead of random ones.
    pub file: Option<PathBuf>,
}

impl Default for CameraOptions {
    fn default() -> Self {
        CameraOptions { radius: default_radius(), jitter: default_jitter(), fov_degrees: None, file: None }
    }
}

/// The source of random rays.
#[derive(Clone, Debug)]
pub enum CameraRig {
    /// A fresh camera for every ray, uniformly placed on a sphere of `radius` and looking at the
    /// jittered centre.
    Sphere {
        /// Distance of the cameras from the origin.
        radius: f32,
        /// Half-size of the cube the look-at point is drawn from.
        jitter: f32,
        /// Full field of view.
        fov_degrees: f32,
    },
    /// Rays from a uniformly chosen camera of a fixed list.
    Fixed(Vec<Camera>),
}

impl CameraRig {
    /// Builds the rig described by `opts` for an object that random cameras should keep in view: the
    /// sphere of radius `framed_radius` around the canonical origin (see [`bounding_radius`] and
    /// [`area_radius`]). `to_canonical` converts a camera file's poses; `source` names the source in
    /// errors.
    pub fn from_options(
        opts: &CameraOptions,
        ctx: &BuildContext,
        framed_radius: f32,
        to_canonical: &Similarity,
        source: &str,
    ) -> Result<CameraRig, GeometryError> {
        let bad = |m: String| crate::options::options_error(source, format!("cameras: {m}"));
        if let Some(fov) = opts.fov_degrees
            && !(fov > 0.0 && fov < 179.0)
        {
            return Err(bad(format!("fov_degrees = {fov} must be in (0, 179)")));
        }
        if let Some(file) = &opts.file {
            let cams = load_camera_file(&ctx.resolve(file), to_canonical, opts.fov_degrees)?;
            return Ok(CameraRig::Fixed(cams));
        }
        if !(opts.jitter >= 0.0 && opts.jitter.is_finite()) {
            return Err(bad(format!("jitter = {} must be a finite number >= 0", opts.jitter)));
        }
        let reach = framed_radius + opts.jitter * 3f32.sqrt();
        if !(opts.radius > reach && opts.radius.is_finite()) {
            return Err(bad(format!(
                "radius = {} must exceed the radius of the object's framing sphere plus the jitter ({reach:.3})",
                opts.radius
            )));
        }
        // Half-angle that keeps the whole bounding sphere in view, plus a small margin.
        let auto = 2.0 * (reach / opts.radius).asin().to_degrees() + 4.0;
        Ok(CameraRig::Sphere {
            radius: opts.radius,
            jitter: opts.jitter,
            fov_degrees: opts.fov_degrees.unwrap_or(auto),
        })
    }

    /// One random ray.
    pub fn random_ray(&self, rng: &mut impl Rng) -> Ray {
        match self {
            CameraRig::Sphere { radius, jitter, fov_degrees } => {
                let dir = random_unit_vector(rng);
                let target: V3 = std::array::from_fn(|_| rng.random_range(-1.0..=1.0) * jitter);
                let position = (Vec3::from(target) + *radius * Vec3::from(dir)).to_array();
                let cam = Camera::look_at(position, target, *fov_degrees)
                    .unwrap_or_else(|_| Camera::look_at(position, [0.0; 3], 60.0).unwrap_or(FALLBACK));
                cam.random_ray(rng)
            }
            CameraRig::Fixed(cams) => {
                let i = rng.random_range(0..cams.len().max(1));
                cams.get(i).unwrap_or(&FALLBACK).random_ray(rng)
            }
        }
    }

    /// Short description for logs.
    pub fn describe(&self) -> String {
        match self {
            CameraRig::Sphere { radius, fov_degrees, .. } => {
                format!("random cameras at radius {radius}, fov {fov_degrees:.1}°")
            }
            CameraRig::Fixed(c) => format!("{} cameras from file", c.len()),
        }
    }
}

/// A valid camera used only if a construction that cannot fail does (keeps sampling panic-free).
const FALLBACK: Camera = Camera {
    position: [0.0, 0.0, 3.0],
    forward: [0.0, 0.0, -1.0],
    right: [1.0, 0.0, 0.0],
    up: [0.0, 1.0, 0.0],
    tan_half_fov: 0.6,
};

/// Radius of the sphere around the origin that contains `bounds`.
pub fn bounding_radius(bounds: &Aabb) -> f32 {
    Vec3::from_array(std::array::from_fn(|k| bounds.min[k].abs().max(bounds.max[k].abs()))).length()
}

/// Radius of the sphere around the origin holding 99.5% of the surface area of `mesh` (by triangle,
/// counting a triangle at its farthest corner). Random cameras frame this sphere: NeRF meshes have
/// floaters and fog fragments out to the corners of their box, and framing the whole box would waste
/// most rays on empty background (on `unruly_vase.obj`, 93% of rays missed). Floaters outside it are
/// still seen, from cameras on their side.
pub fn area_radius(mesh: &crate::mesh::TriMesh) -> f32 {
    let mut r: Vec<(f32, f32)> = (0..mesh.triangles.len())
        .map(|f| {
            (mesh.corners(f).iter().map(|&c| Vec3::from(c).length()).fold(0.0, f32::max), mesh.face_area(f))
        })
        .filter(|&(_, a)| a > 0.0 && a.is_finite())
        .collect();
    let total: f64 = r.iter().map(|&(_, a)| f64::from(a)).sum();
    r.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut acc = 0.0f64;
    for &(d, a) in &r {
        acc += f64::from(a);
        if acc >= 0.995 * total {
            return d;
        }
    }
    r.last().map_or(1.0, |&(d, _)| d)
}

/// A uniformly distributed unit vector.
pub(crate) fn random_unit_vector(rng: &mut impl Rng) -> V3 {
    let z: f32 = rng.random_range(-1.0..=1.0);
    let phi = rng.random_range(0.0..std::f32::consts::TAU);
    let r = (1.0 - z * z).max(0.0).sqrt();
    [r * phi.cos(), r * phi.sin(), z]
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct PoseEntry {
    position: V3,
    look_at: V3,
    fov_degrees: Option<f32>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct PoseList {
    fov_degrees: Option<f32>,
    cameras: Vec<PoseEntry>,
}

#[derive(Deserialize)]
struct NerfFrame {
    transform_matrix: [[f32; 4]; 4],
}

#[derive(Deserialize)]
struct NerfTransforms {
    camera_angle_x: Option<f32>,
    frames: Vec<NerfFrame>,
}

/// Reads a camera file (see the module docs) and converts its poses to the canonical frame.
/// `fov_override` replaces every field of view in the file.
pub fn load_camera_file(
    path: &Path,
    to_canonical: &Similarity,
    fov_override: Option<f32>,
) -> Result<Vec<Camera>, GeometryError> {
    let text =
        std::fs::read_to_string(path).map_err(|e| GeometryError::Io { path: path.into(), source: e })?;
    let bad = |m: String| GeometryError::malformed(path, m);
    let value: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| bad(format!("not valid JSON: {e}")))?;
    let poses: Vec<(V3, V3, f32)> = if value.is_array() || value.get("cameras").is_some() {
        let list: PoseList = if value.is_array() {
            PoseList {
                fov_degrees: None,
                cameras: serde_json::from_value(value).map_err(|e| bad(e.to_string()))?,
            }
        } else {
            serde_json::from_value(value).map_err(|e| bad(e.to_string()))?
        };
        let default_fov = list.fov_degrees.unwrap_or(50.0);
        list.cameras
            .into_iter()
            .map(|c| (c.position, c.look_at, c.fov_degrees.unwrap_or(default_fov)))
            .collect()
    } else if value.get("frames").is_some() {
        let nerf: NerfTransforms = serde_json::from_value(value).map_err(|e| bad(e.to_string()))?;
        let fov = nerf.camera_angle_x.map(|a| a.to_degrees()).unwrap_or(50.0);
        nerf.frames
            .iter()
            .map(|f| {
                let m = &f.transform_matrix;
                let pos = [m[0][3], m[1][3], m[2][3]];
                (pos, (Vec3::from(pos) + Vec3::new(-m[0][2], -m[1][2], -m[2][2])).to_array(), fov)
            })
            .collect()
    } else {
        return Err(bad(
            "expected a list of cameras, an object with `cameras`, or a NeRF transforms file with \
                        `frames`"
                .into(),
        ));
    };
    if poses.is_empty() {
        return Err(GeometryError::invalid(path, "the camera file lists no cameras"));
    }
    poses
        .into_iter()
        .enumerate()
        .map(|(i, (p, t, fov))| {
            let fov = fov_override.unwrap_or(fov);
            Camera::look_at(to_canonical.apply(p), to_canonical.apply(t), fov)
                .map_err(|m| GeometryError::invalid(path, format!("camera {}: {m}", i + 1)))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn rays_stay_within_the_field_of_view() {
        let cam = Camera::look_at([0.0, 0.0, 3.0], [0.0; 3], 60.0).unwrap();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let limit = (30f32.to_radians().tan() * 2f32.sqrt()).atan().cos();
        for _ in 0..1000 {
            let r = cam.random_ray(&mut rng);
            assert!((Vec3::from(r.dir).length() - 1.0).abs() < 1e-5);
            assert!(Vec3::from(r.dir).dot(Vec3::NEG_Z) >= limit - 1e-5);
        }
    }

    #[test]
    fn sphere_rig_rays_point_at_the_object() {
        let bounds = Aabb { min: [-1.0; 3], max: [1.0; 3] };
        let ctx = BuildContext { base_dir: ".".into() };
        let framed = bounding_radius(&bounds);
        let rig =
            CameraRig::from_options(&CameraOptions::default(), &ctx, framed, &Similarity::IDENTITY, "t")
                .unwrap();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        for _ in 0..100 {
            let r = rig.random_ray(&mut rng);
            assert!((Vec3::from(r.origin).length() - 3.0).abs() < 0.2);
            // Pointing inwards: the centre is in front of the camera.
            assert!(Vec3::from(r.dir).dot(Vec3::from(r.origin)) < 0.0);
        }
        let too_close = CameraOptions { radius: 1.5, ..Default::default() };
        let e = CameraRig::from_options(&too_close, &ctx, framed, &Similarity::IDENTITY, "t").unwrap_err();
        assert!(e.to_string().contains("radius"), "{e}");
    }

    #[test]
    fn camera_file_formats_and_errors() {
        let dir = tempfile::tempdir().unwrap();
        let sim = Similarity { center: [10.0, 0.0, 0.0], scale: 0.5 };
        let list = dir.path().join("list.json");
        std::fs::write(&list, r#"[{"position": [10, 0, 6], "look_at": [10, 0, 0]}]"#).unwrap();
        let cams = load_camera_file(&list, &sim, None).unwrap();
        assert_eq!(cams[0].position, [0.0, 0.0, 3.0]);
        assert!((Vec3::from(cams[0].forward).dot(Vec3::NEG_Z) - 1.0).abs() < 1e-6);

        let obj = dir.path().join("obj.json");
        std::fs::write(
            &obj,
            r#"{"fov_degrees": 30, "cameras": [{"position": [1,2,3], "look_at": [0,0,0]}]}"#,
        )
        .unwrap();
        assert!(
            (load_camera_file(&obj, &Similarity::IDENTITY, None).unwrap()[0].tan_half_fov
                - 15f32.to_radians().tan())
            .abs()
                < 1e-6
        );

        let nerf = dir.path().join("transforms.json");
        std::fs::write(
            &nerf,
            r#"{"camera_angle_x": 0.7, "frames": [{"file_path": "a.png",
                "transform_matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,4],[0,0,0,1]]}]}"#,
        )
        .unwrap();
        let c = load_camera_file(&nerf, &Similarity::IDENTITY, None).unwrap()[0];
        assert_eq!(c.position, [0.0, 0.0, 4.0]);
        assert!((Vec3::from(c.forward).dot(Vec3::NEG_Z) - 1.0).abs() < 1e-6);

        for (name, text, needle) in [
            ("typo.json", r#"[{"positon": [1,2,3], "look_at": [0,0,0]}]"#, "positon"),
            ("empty.json", "[]", "no cameras"),
            ("self.json", r#"[{"position": [1,1,1], "look_at": [1,1,1]}]"#, "camera 1"),
            ("garbage.json", "{{{", "JSON"),
            ("other.json", r#"{"foo": 1}"#, "expected a list"),
        ] {
            let p = dir.path().join(name);
            std::fs::write(&p, text).unwrap();
            let e = load_camera_file(&p, &Similarity::IDENTITY, None).unwrap_err().to_string();
            assert!(e.contains(name) && e.contains(needle), "{name}: {e}");
        }
    }
}
