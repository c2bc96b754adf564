//! Row-major matrix views over the host's buffers, so plugin code never touches raw pointers.

/// A read-only row-major `rows × cols` view. Invariant: `data.len() == rows · cols`.
#[derive(Clone, Copy, Debug)]
pub struct Matrix<'a> {
    data: &'a [f32],
    rows: usize,
    cols: usize,
}

/// A writable row-major `rows × cols` view. Invariant: `data.len() == rows · cols`.
#[derive(Debug)]
pub struct MatrixMut<'a> {
    data: &'a mut [f32],
    rows: usize,
    cols: usize,
}

impl<'a> Matrix<'a> {
    /// A view of `data` as `rows × cols`; `None` if the length does not match.
    pub fn new(data: &'a [f32], rows: usize, cols: usize) -> Option<Self> {
        (rows.checked_mul(cols) == Some(data.len())).then_some(Matrix { data, rows, cols })
    }

    /// Rows.
    pub fn rows(&self) -> usize {
        self.rows
    }

    /// Columns.
    pub fn cols(&self) -> usize {
        self.cols
    }

    /// All elements, row after row.
    pub fn data(&self) -> &'a [f32] {
        self.data
    }

    /// Row `r`. Panics if `r ≥ rows` (inside a plugin, the panic becomes an error status).
    pub fn row(&self, r: usize) -> &'a [f32] {
        &self.data[r * self.cols..(r + 1) * self.cols]
    }

    /// The rows, in order.
    pub fn iter_rows(&self) -> impl Iterator<Item = &'a [f32]> + use<'a> {
        let (data, cols) = (self.data, self.cols);
        (0..self.rows).map(move |r| &data[r * cols..(r + 1) * cols])
    }

    /// Rows `start .. start + count` as a matrix. Panics if they are out of range.
    pub fn rows_range(&self, start: usize, count: usize) -> Matrix<'a> {
        Matrix {
            data: &self.data[start * self.cols..(start + count) * self.cols],
            rows: count,
            cols: self.cols,
        }
    }
}

impl<'a> MatrixMut<'a> {
    /// A writable view of `data` as `rows × cols`; `None` if the length does not match.
    pub fn new(data: &'a mut [f32], rows: usize, cols: usize) -> Option<Self> {
        (rows.checked_mul(cols) == Some(data.len())).then_some(MatrixMut { data, rows, cols })
    }

    /// Rows.
    pub fn rows(&self) -> usize {
        self.rows
    }

    /// Columns.
    pub fn cols(&self) -> usize {
        self.cols
    }

    /// All elements, row after row.
    pub fn data_mut(&mut self) -> &mut [f32] {
        self.data
    }

    /// Row `r`. Panics if `r ≥ rows` (inside a plugin, the panic becomes an error status).
    pub fn row_mut(&mut self, r: usize) -> &mut [f32] {
        &mut self.data[r * self.cols..(r + 1) * self.cols]
    }

    /// A read-only view of the same elements.
    pub fn as_matrix(&self) -> Matrix<'_> {
        Matrix { data: self.data, rows: self.rows, cols: self.cols }
    }
}
