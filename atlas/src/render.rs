//! A z-buffer software renderer producing, per pixel, the visible triangle, its perspective-correct
//! barycentrics and the depth: everything the image-space metrics and the preview pictures need.
//!
//! Back faces are kept (meshes extracted from NeRFs have untrustworthy winding); the nearest
//! surface wins, ties going to the lower triangle index. Triangles with a vertex closer than the
//! camera's `near` depth are not drawn (no clipping: the orbit cameras of this crate never come that
//! close). The result does not depend on the number of threads.

use nuvo_geometry::TriMesh;
use rayon::prelude::*;

use crate::camera::{Camera, Projector};
use crate::error::AtlasError;
use crate::raster::{Sampling, raster_parallel};

/// The triangle id of a pixel that sees no surface.
pub const NO_HIT: u32 = u32::MAX;

/// What one pixel sees.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pixel {
    /// Index of the visible triangle, or [`NO_HIT`].
    pub tri: u32,
    /// Perspective-correct barycentrics of the visible point, in the triangle's corner order
    /// (`p = Σ bary[k] · corner[k]`). Zero when there is no hit.
    pub bary: [f32; 3],
    /// View-space depth of the visible point; `f32::INFINITY` when there is no hit.
    pub depth: f32,
}

impl Pixel {
    /// The background.
    pub const EMPTY: Pixel = Pixel { tri: NO_HIT, bary: [0.0; 3], depth: f32::INFINITY };

    /// The visible triangle, if any.
    pub fn hit(&self) -> Option<u32> {
        (self.tri != NO_HIT).then_some(self.tri)
    }
}

/// A rendered view: `width × height` pixels, row-major, row 0 at the top.
#[derive(Clone, Debug, PartialEq)]
pub struct GBuffer {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// `width × height` pixels, row-major.
    pub pixels: Vec<Pixel>,
}

impl GBuffer {
    /// The pixel at column `x`, row `y`. Panics when out of range (a caller bug, not user input).
    pub fn get(&self, x: u32, y: u32) -> &Pixel {
        &self.pixels[(y * self.width + x) as usize]
    }

    /// How many pixels see a surface.
    pub fn hit_count(&self) -> usize {
        self.pixels.iter().filter(|p| p.tri != NO_HIT).count()
    }
}

/// Renders `mesh` (any frame: the camera is in the same one) from `camera`. Fails only on an invalid
/// camera or mesh. Cost: one pass over the vertices and one over the triangles, parallel over row
/// bands.
pub fn render(mesh: &TriMesh, camera: &Camera) -> Result<GBuffer, AtlasError> {
    camera.check()?;
    mesh.validate().map_err(|m| AtlasError::invalid("mesh", m))?;
    let proj = Projector::new(camera);
    // [x, y, 1/depth] per vertex, or None when in front of the near plane.
    let screen: Vec<Option<[f32; 3]>> =
        mesh.positions.par_iter().map(|&p| proj.project(p).map(|[x, y, z]| [x, y, 1.0 / z])).collect();
    let mut pixels = vec![Pixel::EMPTY; camera.width as usize * camera.height as usize];
    let corners = |i: usize| {
        let t = mesh.triangles[i];
        Some([screen[t[0] as usize]?, screen[t[1] as usize]?, screen[t[2] as usize]?])
    };
    raster_parallel(
        camera.width,
        camera.height,
        &mut pixels,
        mesh.triangles.len(),
        Sampling::Snapped,
        |i| corners(i).map(|c| c.map(|q| [q[0], q[1]])),
        |px, i, l| {
            let Some(c) = corners(i) else { return };
            let w = [l[0] * c[0][2], l[1] * c[1][2], l[2] * c[2][2]];
            let inv_depth = w[0] + w[1] + w[2];
            let depth = 1.0 / inv_depth;
            if depth < px.depth && inv_depth > 0.0 {
                *px = Pixel { tri: i as u32, bary: w.map(|x| x * depth), depth };
            }
        },
    );
    Ok(GBuffer { width: camera.width, height: camera.height, pixels })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square(z: f32, half: f32) -> TriMesh {
        TriMesh {
            positions: vec![[-half, -half, z], [half, -half, z], [half, half, z], [-half, half, z]],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
            uv: None,
        }
    }

    /// 90° fov at distance 5 from z = 0 over 100 px: 1 world unit = 10 px at z = 0.
    fn front_camera() -> Camera {
        Camera::look_at([0.0, 0.0, 5.0], [0.0; 3], [0.0, 1.0, 0.0], 90.0, 100, 100).unwrap()
    }

    #[test]
    fn a_known_square_covers_the_expected_pixels_at_the_expected_depth() {
        let g = render(&square(0.0, 2.0), &front_camera()).unwrap();
        // [-2, 2]^2 at 10 px/unit → pixels 30..70 in x and y, exactly 40 x 40, no gaps or overlaps.
        assert_eq!(g.hit_count(), 1600);
        for y in 0..100 {
            for x in 0..100 {
                let p = g.get(x, y);
                let inside = (30..70).contains(&x) && (30..70).contains(&y);
                assert_eq!(p.hit().is_some(), inside, "pixel {x},{y}");
                if inside {
                    assert!((p.depth - 5.0).abs() < 1e-5);
                }
            }
        }
    }

    #[test]
    fn a_known_triangle_covers_its_half_of_the_square() {
        // (-2,-2), (2,-2), (-2,2) → pixels (30,70), (70,70), (30,30): the lower-left half of the
        // square 30..70, hypotenuse on the pixel-centre diagonal x = y.
        let m = TriMesh {
            positions: vec![[-2.0, -2.0, 0.0], [2.0, -2.0, 0.0], [-2.0, 2.0, 0.0]],
            triangles: vec![[0, 1, 2]],
            uv: None,
        };
        let g = render(&m, &front_camera()).unwrap();
        let mut diagonal = 0;
        for y in 0..100u32 {
            for x in 0..100u32 {
                let p = g.get(x, y);
                let in_square = (30..70).contains(&x) && (30..70).contains(&y);
                if in_square && y > x {
                    assert_eq!(p.tri, 0, "pixel {x},{y} strictly inside is not covered");
                    assert!((p.depth - 5.0).abs() < 1e-5);
                } else if in_square && x == y {
                    diagonal += p.hit().is_some() as usize; // on the edge: owned by one side
                } else {
                    assert!(p.hit().is_none(), "pixel {x},{y} outside is covered");
                }
            }
        }
        assert!(diagonal == 0 || diagonal == 40, "the edge rule must treat the whole edge alike");
        assert_eq!(g.hit_count(), 780 + diagonal);
    }

    #[test]
    fn the_nearer_surface_wins_whatever_the_order_and_winding() {
        let far = square(0.0, 2.0);
        let mut near = square(1.0, 1.0);
        near.triangles = vec![[0, 2, 1], [0, 3, 2]]; // back-facing: still drawn
        for near_first in [false, true] {
            let (a, b) = if near_first { (&near, &far) } else { (&far, &near) };
            let mut m = a.clone();
            m.positions.extend(&b.positions);
            m.triangles.extend(b.triangles.iter().map(|t| t.map(|v| v + 4)));
            let g = render(&m, &front_camera()).unwrap();
            let near_ids = if near_first { [0, 1] } else { [2, 3] };
            let c = g.get(50, 50);
            assert!(near_ids.contains(&c.tri), "centre sees triangle {}", c.tri);
            assert!((c.depth - 4.0).abs() < 1e-5);
            let edge = g.get(32, 50);
            assert!(!near_ids.contains(&edge.tri) && (edge.depth - 5.0).abs() < 1e-5);
        }
    }

    #[test]
    fn barycentrics_are_perspective_correct() {
        // A slanted triangle: the interpolated point must lie on each pixel's ray.
        let m = TriMesh {
            positions: vec![[-3.0, -2.0, -4.0], [3.0, -1.0, 2.0], [0.0, 3.0, -1.0]],
            triangles: vec![[0, 1, 2]],
            uv: None,
        };
        let cam = front_camera();
        let g = render(&m, &cam).unwrap();
        assert!(g.hit_count() > 500);
        for y in 0..100 {
            for x in 0..100 {
                let p = g.get(x, y);
                if p.hit().is_none() {
                    continue;
                }
                let q: [f32; 3] =
                    std::array::from_fn(|k| (0..3).map(|c| p.bary[c] * m.positions[c][k]).sum());
                let [sx, sy, d] = cam.project(q).unwrap();
                assert!((sx - x as f32 - 0.5).abs() < 0.02 && (sy - y as f32 - 0.5).abs() < 0.02);
                assert!((d - p.depth).abs() < 1e-4 * d);
            }
        }
    }

    #[test]
    fn geometry_behind_the_near_plane_is_not_drawn() {
        let g = render(&square(6.0, 2.0), &front_camera()).unwrap();
        assert_eq!(g.hit_count(), 0);
    }
}
