//! Buffers that start on a cache line.
//!
//! Why: the AMX tile loads and stores of [`crate::bf16`] move 64-byte rows, and a row that
//! straddles two cache lines costs about twice as long — measured on Emerald Rapids, a 1 KB
//! `TILELOADD` from L1 took ~10 ns aligned and ~20 ns not, and the tile kernel ran 15–20%
//! slower with either its left factor or its output off the line. The allocator gives a
//! `Vec<f32>` 16-byte alignment (large ones sit 16 bytes past a page), so the packed factors
//! and the tape's pooled buffers (the products' outputs) are kept here instead.
//!
//! Invariant: the elements in use are the first `len` of whole 64-byte lines, contiguous and
//! initialised; the buffer's start is 64-byte aligned.

use std::fmt;
use std::ops::{Deref, DerefMut};

/// One cache line of 4-byte elements.
#[derive(Clone, Copy)]
#[repr(C, align(64))]
struct Line<T: Copy>([T; 16]);

/// `len` elements on whole cache lines (module docs).
pub(crate) struct LineBuf<T: Copy> {
    lines: Vec<Line<T>>,
    len: usize,
}

impl<T: Copy + Default> LineBuf<T> {
    /// An empty buffer (no allocation).
    pub(crate) const fn new() -> Self {
        assert!(size_of::<Line<T>>() == 16 * size_of::<T>(), "LineBuf holds 4-byte elements");
        LineBuf { lines: Vec::new(), len: 0 }
    }

    /// `len` default (zero) elements.
    pub(crate) fn zeroed(len: usize) -> Self {
        let mut b = LineBuf::new();
        b.set_zeroed(len);
        b
    }

    /// Makes the buffer `len` default (zero) elements, reusing its allocation.
    pub(crate) fn set_zeroed(&mut self, len: usize) {
        self.lines.clear();
        self.set_len(len);
    }

    /// Makes the buffer `len` elements, reusing its allocation and keeping what it holds: the
    /// first `min(len, old len)` are the old ones, any beyond zero. For a buffer whose every
    /// element the caller writes (no clearing pass over megabytes it is about to fill).
    pub(crate) fn set_len(&mut self, len: usize) {
        self.lines.resize(len.div_ceil(16), Line([T::default(); 16]));
        self.len = len;
    }
}

impl<T: Copy> LineBuf<T> {
    /// How many elements the buffer holds without reallocating.
    pub(crate) fn capacity(&self) -> usize {
        16 * self.lines.capacity()
    }
}

impl<T: Copy + Default> Default for LineBuf<T> {
    fn default() -> Self {
        LineBuf::new()
    }
}

impl<T: Copy> Deref for LineBuf<T> {
    type Target = [T];
    fn deref(&self) -> &[T] {
        // SAFETY: `lines` holds `16 · lines.len() ≥ len` initialised `T`s, contiguous (`Line` is
        // `repr(C)` over `[T; 16]` with no padding: checked in `new`).
        unsafe { std::slice::from_raw_parts(self.lines.as_ptr().cast(), self.len) }
    }
}

impl<T: Copy> DerefMut for LineBuf<T> {
    fn deref_mut(&mut self) -> &mut [T] {
        // SAFETY: as in `deref`, borrowed mutably through `self`.
        unsafe { std::slice::from_raw_parts_mut(self.lines.as_mut_ptr().cast(), self.len) }
    }
}

impl<T: Copy + fmt::Debug> fmt::Debug for LineBuf<T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_list().entries(self.iter()).finish()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn buffers_start_on_cache_lines_and_are_zeroed() {
        let mut w = LineBuf::<u32>::zeroed(1000);
        for len in [1, 16, 17, 4096, 70_000, 3, 0] {
            w.fill(7);
            w.set_zeroed(len);
            assert_eq!(w.len(), len);
            assert!(w.iter().all(|&x| x == 0));
            if len > 0 {
                assert_eq!(w.as_ptr() as usize % 64, 0, "{len} elements");
            }
        }
        let f = LineBuf::<f32>::zeroed(5000 * 256);
        assert_eq!(f.as_ptr() as usize % 64, 0);
        assert_eq!(f.len(), 5000 * 256);
    }
}
