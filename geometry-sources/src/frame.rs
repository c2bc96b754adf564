//! Bounding boxes and the similarity transform into the canonical frame.

use serde::{Deserialize, Serialize};

/// An axis-aligned bounding box. Invariant once built from points: `min <= max` componentwise.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Aabb {
    /// Smallest coordinate on each axis.
    pub min: [f32; 3],
    /// Largest coordinate on each axis.
    pub max: [f32; 3],
}

impl Aabb {
    /// The bounding box of `points`, or `None` when there are none.
    pub fn from_points<'a>(points: impl IntoIterator<Item = &'a [f32; 3]>) -> Option<Self> {
        let mut it = points.into_iter();
        let first = *it.next()?;
        let mut bb = Aabb { min: first, max: first };
        for p in it {
            bb.min = std::array::from_fn(|k| bb.min[k].min(p[k]));
            bb.max = std::array::from_fn(|k| bb.max[k].max(p[k]));
        }
        Some(bb)
    }

    /// The centre of the box.
    pub fn center(&self) -> [f32; 3] {
        std::array::from_fn(|k| 0.5 * (self.min[k] + self.max[k]))
    }

    /// Half of the longest side.
    pub fn max_half_extent(&self) -> f32 {
        (0..3).map(|k| 0.5 * (self.max[k] - self.min[k])).fold(0.0, f32::max)
    }
}

/// `p ↦ (p - center) * scale`: the map from input coordinates into the canonical frame.
/// Invariant: `scale > 0` and finite.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Similarity {
    /// The input point that maps to the origin.
    pub center: [f32; 3],
    /// The uniform scale applied after centring.
    pub scale: f32,
}

impl Similarity {
    /// The identity map.
    pub const IDENTITY: Similarity = Similarity { center: [0.0; 3], scale: 1.0 };

    /// The map that sends `bounds` into `[-1, 1]^3`, centred, longest half-extent 1. A degenerate box
    /// (a single point) gets scale 1 so the map stays invertible.
    pub fn normalizing(bounds: &Aabb) -> Self {
        let half = bounds.max_half_extent();
        let scale = if half > 0.0 && half.is_finite() { 1.0 / half } else { 1.0 };
        Similarity { center: bounds.center(), scale }
    }

    /// Input coordinates → canonical frame.
    pub fn apply(&self, p: [f32; 3]) -> [f32; 3] {
        std::array::from_fn(|k| (p[k] - self.center[k]) * self.scale)
    }

    /// Canonical frame → input coordinates.
    pub fn invert(&self, p: [f32; 3]) -> [f32; 3] {
        std::array::from_fn(|k| p[k] / self.scale + self.center[k])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normalizing_maps_box_into_unit_cube_and_back() {
        let bb = Aabb { min: [1.0, 2.0, 3.0], max: [3.0, 3.0, 4.0] };
        let s = Similarity::normalizing(&bb);
        assert_eq!(s.apply([3.0, 2.5, 3.5]), [1.0, 0.0, 0.0]);
        assert_eq!(s.apply([1.0, 2.5, 3.5]), [-1.0, 0.0, 0.0]);
        let p = [2.2, 2.7, 3.1];
        let q = s.invert(s.apply(p));
        for k in 0..3 {
            assert!((p[k] - q[k]).abs() < 1e-6);
        }
    }
}
