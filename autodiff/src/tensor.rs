//! Owned tensors: parameters, inputs handed to the tape, and results copied out of it.

use serde::{Deserialize, Serialize};

use crate::shape::Shape;

/// An owned 2-D row-major f32 tensor. Invariant: `data.len() == shape.len()`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Tensor {
    shape: Shape,
    data: Vec<f32>,
}

impl Tensor {
    /// A tensor from row-major data.
    ///
    /// # Panics
    /// If `data.len() != rows * cols` (a programming error, not a user-input one).
    pub fn from_vec(rows: usize, cols: usize, data: Vec<f32>) -> Self {
        assert_eq!(
            data.len(),
            rows * cols,
            "Tensor::from_vec: {} values for a {rows}×{cols} tensor",
            data.len()
        );
        Tensor { shape: Shape::new(rows, cols), data }
    }

    /// A tensor of zeros.
    pub fn zeros(rows: usize, cols: usize) -> Self {
        Self::full(rows, cols, 0.0)
    }

    /// A tensor filled with `value`.
    pub fn full(rows: usize, cols: usize, value: f32) -> Self {
        Tensor { shape: Shape::new(rows, cols), data: vec![value; rows * cols] }
    }

    /// A 1×1 tensor.
    pub fn scalar(value: f32) -> Self {
        Self::full(1, 1, value)
    }

    /// A tensor with one row per point, from fixed-size arrays (e.g. `[f32; 3]` positions).
    pub fn from_rows<const N: usize>(rows: &[[f32; N]]) -> Self {
        Tensor { shape: Shape::new(rows.len(), N), data: rows.iter().flatten().copied().collect() }
    }

    /// The shape.
    pub fn shape(&self) -> Shape {
        self.shape
    }

    /// Number of rows.
    pub fn rows(&self) -> usize {
        self.shape.rows
    }

    /// Number of columns.
    pub fn cols(&self) -> usize {
        self.shape.cols
    }

    /// The row-major data.
    pub fn data(&self) -> &[f32] {
        &self.data
    }

    /// The row-major data, mutably.
    pub fn data_mut(&mut self) -> &mut [f32] {
        &mut self.data
    }

    /// Row `r`.
    pub fn row(&self, r: usize) -> &[f32] {
        &self.data[r * self.shape.cols..(r + 1) * self.shape.cols]
    }

    /// Element `(r, c)`.
    pub fn get(&self, r: usize, c: usize) -> f32 {
        self.data[r * self.shape.cols + c]
    }

    /// Consumes the tensor, returning its data.
    pub fn into_vec(self) -> Vec<f32> {
        self.data
    }
}
