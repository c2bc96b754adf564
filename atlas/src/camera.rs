//! Pinhole cameras and the seeded set of views the metrics are computed over.
//!
//! Conventions: right-handed world; a camera looks from `eye` towards `target`; image `x` grows to
//! the right and `y` downwards, pixel `(x, y)` has its centre at `(x + 0.5, y + 0.5)`. *Depth* is the
//! view-space distance along the optical axis (not the ray length), positive in front of the camera.

use glam::DVec3;
use nuvo_geometry::Aabb;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

use crate::error::AtlasError;
use crate::geom::to_dvec3;

/// Vertical field of view of [`orbit_views`], in degrees.
pub const DEFAULT_FOV_Y_DEG: f32 = 40.0;
/// Largest image side accepted, far below the rasteriser's coordinate limit.
pub const MAX_IMAGE_SIDE: u32 = 8192;

/// A perspective camera. Invariants (checked by [`Camera::look_at`]): `eye != target`, `up` not
/// parallel to the view direction, `0 < fov_y_deg < 180`, `1 <= width, height <= MAX_IMAGE_SIDE`,
/// `near > 0`. Geometry closer than `near` (in depth) is not drawn.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Camera {
    /// Centre of projection.
    pub eye: [f32; 3],
    /// The point the optical axis goes through (image centre).
    pub target: [f32; 3],
    /// A direction that appears upwards in the image (need not be orthogonal to the view).
    pub up: [f32; 3],
    /// Vertical field of view in degrees.
    pub fov_y_deg: f32,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Near clipping depth.
    pub near: f32,
}

impl Camera {
    /// A camera at `eye` looking at `target` with `up` roughly upwards in the image; `near` is set
    /// to a thousandth of the eye–target distance.
    pub fn look_at(
        eye: [f32; 3],
        target: [f32; 3],
        up: [f32; 3],
        fov_y_deg: f32,
        width: u32,
        height: u32,
    ) -> Result<Self, AtlasError> {
        let d = to_dvec3(target).distance(to_dvec3(eye));
        let cam = Camera { eye, target, up, fov_y_deg, width, height, near: (d * 1e-3) as f32 };
        cam.check()?;
        Ok(cam)
    }

    /// Checks the invariants on the type.
    pub fn check(&self) -> Result<(), AtlasError> {
        let bad = |m: String| Err(AtlasError::invalid("camera", m));
        if !(self.fov_y_deg > 0.0 && self.fov_y_deg < 180.0) {
            return bad(format!("field of view {}° is not in (0, 180)", self.fov_y_deg));
        }
        for (name, s) in [("width", self.width), ("height", self.height)] {
            if s == 0 || s > MAX_IMAGE_SIDE {
                return bad(format!("{name} {s} is not in 1..={MAX_IMAGE_SIDE}"));
            }
        }
        if !(self.near > 0.0 && self.near.is_finite()) {
            return bad(format!("near plane {} must be positive", self.near));
        }
        if self.eye.iter().chain(&self.target).chain(&self.up).any(|c| !c.is_finite()) {
            return bad("eye, target and up must be finite".into());
        }
        match (to_dvec3(self.target) - to_dvec3(self.eye)).try_normalize() {
            None => bad("eye and target coincide".into()),
            Some(f) if f.cross(to_dvec3(self.up)).try_normalize().is_none() => {
                bad("up is parallel to the view direction".into())
            }
            Some(_) => Ok(()),
        }
    }

    /// Projects a world point: `Some([x, y, depth])` in pixels (module conventions) when the point is
    /// at least `near` in front of the camera, else `None`.
    pub fn project(&self, p: [f32; 3]) -> Option<[f32; 3]> {
        Projector::new(self).project(p)
    }
}

/// A camera prepared for projecting many points: its orthonormal frame and focal length.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Projector {
    eye: DVec3,
    right: DVec3,
    up: DVec3,
    forward: DVec3,
    focal_px: f64,
    cx: f64,
    cy: f64,
    near: f64,
}

impl Projector {
    /// Assumes `cam.check()` passed (degenerate frames project nothing rather than NaN).
    pub(crate) fn new(cam: &Camera) -> Self {
        let eye = to_dvec3(cam.eye);
        let forward = (to_dvec3(cam.target) - eye).normalize_or(DVec3::NEG_Z);
        let right = forward.cross(to_dvec3(cam.up)).normalize_or(DVec3::X);
        let up = right.cross(forward);
        let focal_px = 0.5 * cam.height as f64 / (0.5 * (cam.fov_y_deg as f64).to_radians()).tan();
        Projector {
            eye,
            right,
            up,
            forward,
            focal_px,
            cx: 0.5 * cam.width as f64,
            cy: 0.5 * cam.height as f64,
            near: cam.near as f64,
        }
    }

    pub(crate) fn project(&self, p: [f32; 3]) -> Option<[f32; 3]> {
        let d = to_dvec3(p) - self.eye;
        let z = d.dot(self.forward);
        if z.is_nan() || z < self.near {
            return None;
        }
        let s = self.focal_px / z;
        Some([(self.cx + s * d.dot(self.right)) as f32, (self.cy - s * d.dot(self.up)) as f32, z as f32])
    }
}

/// `count` cameras at seeded random directions, uniform on the sphere, all looking at the centre of
/// `bounds`. The distance makes the bounding sphere of `bounds` exactly fill the narrower field of
/// view, so any view of the object fits the frame and the object fills most of it. Same
/// `(bounds, count, seed, size)` → same cameras, on every machine (ChaCha8).
pub fn orbit_views(bounds: &Aabb, count: usize, seed: u64, width: u32, height: u32) -> Vec<Camera> {
    let centre = bounds.center();
    let half_diag = to_dvec3(bounds.max).distance(to_dvec3(bounds.min)) * 0.5;
    let radius = if half_diag > 0.0 && half_diag.is_finite() { half_diag } else { 1.0 };
    let half_y = 0.5 * (DEFAULT_FOV_Y_DEG as f64).to_radians();
    let half_x = (half_y.tan() * width as f64 / height.max(1) as f64).atan();
    let distance = radius / half_y.min(half_x).sin();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..count)
        .map(|_| {
            let z: f64 = rng.random_range(-1.0..1.0);
            let phi: f64 = rng.random_range(0.0..std::f64::consts::TAU);
            let r = (1.0 - z * z).max(0.0).sqrt();
            let dir = [r * phi.cos(), r * phi.sin(), z];
            let eye: [f32; 3] = std::array::from_fn(|k| (centre[k] as f64 + distance * dir[k]) as f32);
            let up = if dir[1].abs() > 0.99 { [0.0, 0.0, 1.0] } else { [0.0, 1.0, 0.0] };
            Camera {
                eye,
                target: centre,
                up,
                fov_y_deg: DEFAULT_FOV_Y_DEG,
                width,
                height,
                near: (0.5 * (distance - radius)) as f32,
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn projection_centres_the_target_and_orients_the_image() {
        let cam = Camera::look_at([0.0, 0.0, 5.0], [0.0; 3], [0.0, 1.0, 0.0], 90.0, 100, 100).unwrap();
        assert_eq!(cam.project([0.0, 0.0, 0.0]).unwrap(), [50.0, 50.0, 5.0]);
        // +x is to the right, +y up (smaller row); at depth 5 with 90° fov, x = 5 is the image edge.
        let p = cam.project([5.0, 2.5, 0.0]).unwrap();
        assert!((p[0] - 100.0).abs() < 1e-4 && (p[1] - 25.0).abs() < 1e-4);
        assert!(cam.project([0.0, 0.0, 6.0]).is_none(), "behind the camera");
    }

    #[test]
    fn bad_cameras_are_errors_not_panics() {
        let up = [0.0, 1.0, 0.0];
        assert!(Camera::look_at([0.0; 3], [0.0; 3], up, 40.0, 8, 8).is_err());
        assert!(Camera::look_at([0.0, 5.0, 0.0], [0.0; 3], up, 40.0, 8, 8).is_err());
        assert!(Camera::look_at([0.0, 0.0, 5.0], [0.0; 3], up, 0.0, 8, 8).is_err());
        assert!(Camera::look_at([0.0, 0.0, 5.0], [0.0; 3], up, 40.0, 0, 8).is_err());
    }

    #[test]
    fn orbit_views_are_seeded_and_frame_the_bounding_sphere() {
        let bb = Aabb { min: [-1.0, -2.0, 0.0], max: [3.0, 0.0, 1.0] };
        let a = orbit_views(&bb, 16, 7, 64, 48);
        assert_eq!(a, orbit_views(&bb, 16, 7, 64, 48));
        assert_ne!(a, orbit_views(&bb, 16, 8, 64, 48));
        for cam in &a {
            cam.check().unwrap();
            for corner in 0..8 {
                let p = std::array::from_fn(|k| if corner >> k & 1 == 1 { bb.max[k] } else { bb.min[k] });
                let [x, y, _] = cam.project(p).expect("box corner behind the camera");
                assert!((0.0..=64.0).contains(&x) && (0.0..=48.0).contains(&y), "corner outside: {x} {y}");
            }
        }
    }
}
