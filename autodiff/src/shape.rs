//! Shapes of 2-D row-major tensors and the broadcasting rule.

use serde::{Deserialize, Serialize};

/// The shape of a 2-D row-major tensor: `rows` samples (the batch) × `cols` features.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct Shape {
    pub rows: usize,
    pub cols: usize,
}

impl Shape {
    /// A `rows × cols` shape.
    pub const fn new(rows: usize, cols: usize) -> Self {
        Shape { rows, cols }
    }

    /// The 1×1 shape of a scalar.
    pub const SCALAR: Shape = Shape::new(1, 1);

    /// Number of elements.
    pub const fn len(&self) -> usize {
        self.rows * self.cols
    }

    /// True when the tensor has no elements.
    pub const fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The shape both operands broadcast to, or `None` if they are incompatible.
    ///
    /// Each dimension must be equal or 1 in one operand (numpy rules restricted to 2-D): `(r,c)` with
    /// `(1,c)` (a row vector), `(r,1)` (a column vector) or `(1,1)` (a scalar), and `(r,1)` with `(1,c)`
    /// (an outer operation).
    pub fn broadcast(self, other: Shape) -> Option<Shape> {
        fn dim(a: usize, b: usize) -> Option<usize> {
            match (a, b) {
                _ if a == b => Some(a),
                (1, _) => Some(b),
                (_, 1) => Some(a),
                _ => None,
            }
        }
        Some(Shape::new(dim(self.rows, other.rows)?, dim(self.cols, other.cols)?))
    }
}

impl std::fmt::Display for Shape {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}×{}", self.rows, self.cols)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn broadcasting_rules() {
        let s = Shape::new;
        assert_eq!(s(4, 3).broadcast(s(1, 3)), Some(s(4, 3)));
        assert_eq!(s(4, 3).broadcast(s(4, 1)), Some(s(4, 3)));
        assert_eq!(s(1, 1).broadcast(s(4, 3)), Some(s(4, 3)));
        assert_eq!(s(4, 1).broadcast(s(1, 3)), Some(s(4, 3)));
        assert_eq!(s(4, 3).broadcast(s(2, 3)), None);
        assert_eq!(s(4, 3).broadcast(s(4, 2)), None);
    }
}
