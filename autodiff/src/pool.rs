//! A pool of f32 buffers reused across training steps.
//!
//! Why: a training step allocates the same few hundred buffers (activations, gradients) every time.
//! Returning them to a pool at the end of the step and taking them back at the next means the steady
//! state allocates nothing and resident memory stays flat over 100k steps.
//!
//! Invariant: a [`Buf`] handed out by [`Pool::take`] has exactly the requested length and *unspecified
//! contents* (whatever the previous user left). Every kernel that takes a buffer overwrites all of it.

use std::collections::BTreeMap;

use crate::lines::LineBuf;

/// A pooled buffer: fully initialised floats, of which the first `len` are in use, starting on a
/// cache line ([`crate::lines`]: the AMX tile kernel stores its products' rows into them).
#[derive(Debug, Default)]
pub struct Buf {
    data: LineBuf<f32>,
    len: usize,
}

impl Buf {
    /// The elements in use.
    pub fn as_slice(&self) -> &[f32] {
        &self.data[..self.len]
    }

    /// The elements in use, mutably.
    pub fn as_mut_slice(&mut self) -> &mut [f32] {
        &mut self.data[..self.len]
    }

    /// Number of elements in use.
    pub fn len(&self) -> usize {
        self.len
    }

    /// True when no element is in use.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    fn capacity(&self) -> usize {
        self.data.len()
    }
}

/// Free buffers by capacity. Best fit: [`Pool::take`] reuses the smallest free buffer that holds the
/// request and wastes at most half of itself; otherwise it allocates exactly.
#[derive(Debug, Default)]
pub struct Pool {
    free: BTreeMap<usize, Vec<LineBuf<f32>>>,
    allocations: u64,
    pooled_floats: usize,
}

impl Pool {
    /// A buffer of `len` elements with unspecified contents.
    pub fn take(&mut self, len: usize) -> Buf {
        if len == 0 {
            return Buf::default();
        }
        let found = self
            .free
            .range_mut(len..=len.saturating_mul(2))
            .find_map(|(&cap, list)| list.pop().map(|v| (cap, v)));
        match found {
            Some((cap, data)) => {
                self.pooled_floats -= cap;
                if self.free.get(&cap).is_some_and(Vec::is_empty) {
                    self.free.remove(&cap);
                }
                Buf { data, len }
            }
            None => {
                self.allocations += 1;
                Buf { data: LineBuf::zeroed(len), len }
            }
        }
    }

    /// A buffer of `len` zeros.
    pub fn take_zeroed(&mut self, len: usize) -> Buf {
        let mut b = self.take(len);
        b.as_mut_slice().fill(0.0);
        b
    }

    /// Returns a buffer to the pool.
    pub fn give(&mut self, buf: Buf) {
        let cap = buf.capacity();
        if cap > 0 {
            self.pooled_floats += cap;
            self.free.entry(cap).or_default().push(buf.data);
        }
    }

    /// How many buffers the pool has had to allocate since it was created. Flat across steps in the
    /// steady state; tests use this to prove it.
    pub fn allocations(&self) -> u64 {
        self.allocations
    }

    /// Floats currently held in free buffers.
    pub fn pooled_floats(&self) -> usize {
        self.pooled_floats
    }

    /// Drops every free buffer (e.g. after the batch size changed for good).
    pub fn clear(&mut self) {
        self.free.clear();
        self.pooled_floats = 0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reuses_buffers_of_equal_or_slightly_larger_size() {
        let mut p = Pool::default();
        let a = p.take(100);
        p.give(a);
        let b = p.take(80);
        assert_eq!(b.len(), 80);
        assert_eq!(p.allocations(), 1);
        p.give(b);
        // Too small a request for a 100-float buffer (would waste more than half): allocates.
        let c = p.take(10);
        assert_eq!(p.allocations(), 2);
        p.give(c);
        assert_eq!(p.pooled_floats(), 110);
    }
}
