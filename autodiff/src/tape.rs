//! The tape: an arena that records operations as they run and replays them backwards.
//!
//! A training step builds a fresh graph on the same `Tape`: [`Tape::reset`] returns every buffer to
//! the pool, so the next step's identical sequence of operations reuses them. Parameters live in the
//! tape's [`ParamStore`] and survive resets.
//!
//! Shape errors and use of a stale [`Var`] are programming errors and panic with a message that names
//! the op and the shapes; user input never reaches the tape unvalidated.

use crate::bf16::{MatmulPrecision, PackedLeft, Words, take_best_fit};
use crate::ops::Op;
use crate::params::{ParamId, ParamStore};
use crate::pool::{Buf, Pool};
use crate::shape::Shape;
use crate::tensor::Tensor;

/// Handle to a value recorded on a [`Tape`]. Cheap to copy; valid until the next [`Tape::reset`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Var {
    pub(crate) idx: u32,
    pub(crate) generation: u32,
}

impl Var {
    pub(crate) fn index(self) -> usize {
        self.idx as usize
    }
}

pub(crate) struct Node {
    pub op: Op,
    pub shape: Shape,
    pub requires_grad: bool,
}

/// A contiguous run in one of the tape's side arenas (inputs of variadic ops, gather indices,
/// precomputed gradients). Arenas are cleared on reset but keep their capacity.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Span {
    pub start: u32,
    pub len: u32,
}

impl Span {
    pub fn range(self) -> std::ops::Range<usize> {
        self.start as usize..(self.start + self.len) as usize
    }
}

/// The recording arena. See the module docs.
pub struct Tape {
    pub(crate) nodes: Vec<Node>,
    pub(crate) values: Vec<Buf>,
    pub(crate) grads: Vec<Option<Buf>>,
    pub(crate) pool: Pool,
    pub(crate) params: ParamStore,
    param_vars: Vec<Option<Var>>,
    pub(crate) var_arena: Vec<Var>,
    pub(crate) idx_arena: Vec<u32>,
    pub(crate) f32_arena: Vec<f32>,
    /// Factors packed in the forward for the backward's products (the `xᵀ` of a bf16 layer's
    /// weight gradient: [`crate::ops::linear`]), by the index their op records.
    pub(crate) packed: Vec<PackedLeft>,
    /// The buffers of the last graph's packed factors, for the next graph's.
    packed_spare: Vec<Words>,
    /// Bits recorded in the forward for the backward (a ReLU layer's `y > 0`, one an element:
    /// [`crate::ops::linear`]), by the index their op records.
    pub(crate) masks: Vec<Vec<u32>>,
    /// The last graph's masks' buffers, for the next graph's.
    mask_spare: Vec<Vec<u32>>,
    generation: u32,
    backward_done: bool,
    /// What the fused linear layers recorded from now on multiply in (already effective on this
    /// machine: [`MatmulPrecision::effective`]).
    pub(crate) matmul_precision: MatmulPrecision,
}

impl Default for Tape {
    fn default() -> Self {
        Self::new(ParamStore::new())
    }
}

impl Tape {
    /// A tape owning `params`.
    pub fn new(params: ParamStore) -> Self {
        Tape {
            nodes: Vec::new(),
            values: Vec::new(),
            grads: Vec::new(),
            pool: Pool::default(),
            param_vars: vec![None; params.len()],
            params,
            var_arena: Vec::new(),
            idx_arena: Vec::new(),
            f32_arena: Vec::new(),
            packed: Vec::new(),
            packed_spare: Vec::new(),
            masks: Vec::new(),
            mask_spare: Vec::new(),
            generation: 0,
            backward_done: false,
            matmul_precision: MatmulPrecision::F32,
        }
    }

    /// Sets the arithmetic of the fused linear layers recorded from now on
    /// ([`Tape::linear`]); a precision this machine cannot run falls back to f32
    /// ([`MatmulPrecision::effective`]). Returns the precision that will run.
    pub fn set_matmul_precision(&mut self, precision: MatmulPrecision) -> MatmulPrecision {
        self.matmul_precision = precision.effective();
        self.matmul_precision
    }

    /// The arithmetic the fused linear layers run at ([`Tape::set_matmul_precision`]).
    pub fn matmul_precision(&self) -> MatmulPrecision {
        self.matmul_precision
    }

    /// The parameters.
    pub fn params(&self) -> &ParamStore {
        &self.params
    }

    /// The parameters, mutably (optimiser steps, loading checkpoints, adding parameters).
    pub fn params_mut(&mut self) -> &mut ParamStore {
        &mut self.params
    }

    /// Gives the parameters back, consuming the tape.
    pub fn into_params(self) -> ParamStore {
        self.params
    }

    /// Forgets the recorded graph, returning all buffers to the pool. Every [`Var`] from before is
    /// invalid afterwards. Parameters and their gradients are untouched.
    pub fn reset(&mut self) {
        for b in self.values.drain(..) {
            self.pool.give(b);
        }
        for b in self.grads.drain(..).flatten() {
            self.pool.give(b);
        }
        self.nodes.clear();
        self.var_arena.clear();
        self.idx_arena.clear();
        self.f32_arena.clear();
        self.packed_spare.extend(self.packed.drain(..).map(PackedLeft::into_words));
        self.mask_spare.append(&mut self.masks);
        self.param_vars.clear();
        self.generation = self.generation.wrapping_add(1);
        self.backward_done = false;
    }

    /// Number of recorded nodes.
    pub fn len(&self) -> usize {
        self.nodes.len()
    }

    /// True when nothing is recorded.
    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }

    /// The buffer pool (for memory statistics).
    pub fn pool(&self) -> &Pool {
        &self.pool
    }

    // ----- leaves -------------------------------------------------------------------------------

    /// A constant input (no gradient), copied into a pooled buffer.
    pub fn input(&mut self, t: &Tensor) -> Var {
        self.input_with(t.shape(), |d| d.copy_from_slice(t.data()))
    }

    /// A constant input written directly into its pooled buffer by `fill` (which must write every
    /// element): per-step data without an intermediate allocation.
    pub fn input_with(&mut self, shape: Shape, fill: impl FnOnce(&mut [f32])) -> Var {
        let mut buf = self.pool.take(shape.len());
        fill(buf.as_mut_slice());
        self.push_node(Op::Leaf, shape, buf, false)
    }

    /// A constant filled with one value.
    pub fn constant(&mut self, shape: Shape, value: f32) -> Var {
        self.input_with(shape, |d| d.fill(value))
    }

    /// A leaf whose gradient is kept after [`Tape::backward`] (read it with [`Tape::grad`]). Used for
    /// gradients with respect to data (gradient checks, plugin inputs).
    pub fn leaf(&mut self, t: &Tensor) -> Var {
        let mut buf = self.pool.take(t.data().len());
        buf.as_mut_slice().copy_from_slice(t.data());
        self.push_node(Op::Leaf, t.shape(), buf, true)
    }

    /// The node of parameter `id` (one per parameter per graph; its gradient accumulates straight into
    /// the [`ParamStore`]).
    pub fn param(&mut self, id: ParamId) -> Var {
        if self.param_vars.len() < self.params.len() {
            self.param_vars.resize(self.params.len(), None);
        }
        if let Some(v) = self.param_vars[id.index()] {
            return v;
        }
        let shape = self.params.value(id).shape();
        let v = self.push_node(Op::Param(id), shape, Buf::default(), true);
        self.param_vars[id.index()] = Some(v);
        v
    }

    // ----- reading --------------------------------------------------------------------------------

    fn check(&self, v: Var) {
        assert!(
            v.generation == self.generation && v.index() < self.nodes.len(),
            "stale Var: it was recorded before the last Tape::reset"
        );
    }

    /// The shape of `v`.
    pub fn shape(&self, v: Var) -> Shape {
        self.check(v);
        self.nodes[v.index()].shape
    }

    /// The value of `v`, row-major.
    pub fn value(&self, v: Var) -> &[f32] {
        self.check(v);
        self.reader().value(v)
    }

    /// The value of `v` copied into an owned tensor.
    pub fn to_tensor(&self, v: Var) -> Tensor {
        let s = self.shape(v);
        Tensor::from_vec(s.rows, s.cols, self.value(v).to_vec())
    }

    /// The value of a 1×1 `v`.
    ///
    /// # Panics
    /// If `v` is not 1×1.
    pub fn scalar(&self, v: Var) -> f32 {
        assert_eq!(self.shape(v), Shape::SCALAR, "Tape::scalar of a {} value", self.shape(v));
        self.value(v)[0]
    }

    /// Whether gradients flow into `v`.
    pub fn requires_grad(&self, v: Var) -> bool {
        self.check(v);
        self.nodes[v.index()].requires_grad
    }

    /// The gradient of a [`Tape::leaf`] after [`Tape::backward`]; `None` if nothing flowed into it.
    pub fn grad(&self, v: Var) -> Option<&[f32]> {
        self.check(v);
        self.grads.get(v.index()).and_then(|g| g.as_ref()).map(Buf::as_slice)
    }

    pub(crate) fn reader(&self) -> Reader<'_> {
        Reader {
            nodes: &self.nodes,
            values: &self.values,
            param_values: &self.params.values,
            var_arena: &self.var_arena,
            idx_arena: &self.idx_arena,
            f32_arena: &self.f32_arena,
            packed: &self.packed,
            masks: &self.masks,
        }
    }

    // ----- recording ------------------------------------------------------------------------------

    pub(crate) fn push_node(&mut self, op: Op, shape: Shape, value: Buf, requires_grad: bool) -> Var {
        debug_assert!(matches!(op, Op::Param(_)) || value.len() == shape.len());
        self.nodes.push(Node { op, shape, requires_grad });
        self.values.push(value);
        Var { idx: (self.nodes.len() - 1) as u32, generation: self.generation }
    }

    /// Records an op whose output buffer `out` was computed by the caller; `inputs` decide whether
    /// gradients flow.
    pub(crate) fn push(&mut self, op: Op, shape: Shape, out: Buf, inputs: &[Var]) -> Var {
        let rg = inputs.iter().any(|&v| {
            self.check(v);
            self.nodes[v.index()].requires_grad
        });
        self.push_node(op, shape, out, rg)
    }

    /// Stores `vars` in the side arena (for variadic ops).
    pub(crate) fn store_vars(&mut self, vars: &[Var]) -> Span {
        let start = self.var_arena.len() as u32;
        self.var_arena.extend_from_slice(vars);
        Span { start, len: vars.len() as u32 }
    }

    /// Stores indices in the side arena (for gathers).
    pub(crate) fn store_indices(&mut self, idx: &[u32]) -> Span {
        let start = self.idx_arena.len() as u32;
        self.idx_arena.extend_from_slice(idx);
        Span { start, len: idx.len() as u32 }
    }

    /// Stores floats in the side arena (for precomputed gradients).
    pub(crate) fn store_floats(&mut self, values: &[f32]) -> Span {
        let start = self.f32_arena.len() as u32;
        self.f32_arena.extend_from_slice(values);
        Span { start, len: values.len() as u32 }
    }

    /// A buffer for a factor of `len` words packed in the forward ([`Tape::packed`]): the
    /// smallest spare one that holds them, else the largest, else a new one.
    pub(crate) fn packed_words(&mut self, len: usize) -> Words {
        take_best_fit(&mut self.packed_spare, len)
    }

    /// Keeps a factor packed in the forward for the backward; its index for the op to record.
    pub(crate) fn keep_packed(&mut self, packed: PackedLeft) -> u32 {
        self.packed.push(packed);
        (self.packed.len() - 1) as u32
    }

    /// `len` words for a mask recorded in the forward ([`Tape::masks`]), in a buffer the last
    /// graph's masks left when one is spare (their contents are overwritten).
    pub(crate) fn mask_words(&mut self, len: usize) -> Vec<u32> {
        let mut words = self.mask_spare.pop().unwrap_or_default();
        words.resize(len, 0);
        words
    }

    /// Keeps a mask recorded in the forward for the backward; its index for the op to record.
    pub(crate) fn keep_mask(&mut self, mask: Vec<u32>) -> u32 {
        self.masks.push(mask);
        (self.masks.len() - 1) as u32
    }

    /// A pooled buffer for an op's output.
    pub(crate) fn alloc(&mut self, shape: Shape) -> Buf {
        self.pool.take(shape.len())
    }

    // ----- backward -------------------------------------------------------------------------------

    /// Accumulates d`loss`/d(parameter) into every parameter's gradient, and d`loss`/d(leaf) for
    /// [`Tape::leaf`] nodes.
    ///
    /// # Panics
    /// If `loss` is not 1×1, or `backward` already ran on this graph.
    pub fn backward(&mut self, loss: Var) {
        self.check(loss);
        assert_eq!(
            self.shape(loss),
            Shape::SCALAR,
            "backward from a {} value; it must be 1×1",
            self.shape(loss)
        );
        assert!(!self.backward_done, "backward called twice on one graph; call Tape::reset between steps");
        self.backward_done = true;
        if !self.nodes[loss.index()].requires_grad {
            return;
        }
        self.grads.resize_with(self.nodes.len(), || None);
        let mut seed = self.pool.take(1);
        seed.as_mut_slice()[0] = 1.0;
        self.grads[loss.index()] = Some(seed);
        for i in (0..=loss.index()).rev() {
            let node = &self.nodes[i];
            if !node.requires_grad || node.op.is_leaf() {
                continue;
            }
            let Some(mut g) = self.grads[i].take() else { continue };
            let reader = Reader {
                nodes: &self.nodes,
                values: &self.values,
                param_values: &self.params.values,
                var_arena: &self.var_arena,
                idx_arena: &self.idx_arena,
                f32_arena: &self.f32_arena,
                packed: &self.packed,
                masks: &self.masks,
            };
            let mut sink = GradSink {
                nodes: &self.nodes,
                grads: &mut self.grads[..i],
                param_grads: &mut self.params.grads,
                pool: &mut self.pool,
            };
            crate::ops::backward(&node.op, &reader, &mut sink, self.values[i].as_slice(), g.as_mut_slice());
            self.pool.give(g);
        }
    }
}

/// Read access to values during backward (shared, so kernels can hold many at once).
#[derive(Clone, Copy)]
pub(crate) struct Reader<'a> {
    nodes: &'a [Node],
    values: &'a [Buf],
    param_values: &'a [Tensor],
    pub var_arena: &'a [Var],
    pub idx_arena: &'a [u32],
    pub f32_arena: &'a [f32],
    pub packed: &'a [PackedLeft],
    pub masks: &'a [Vec<u32>],
}

impl<'a> Reader<'a> {
    pub fn value(&self, v: Var) -> &'a [f32] {
        match self.nodes[v.index()].op {
            Op::Param(id) => self.param_values[id.index()].data(),
            _ => self.values[v.index()].as_slice(),
        }
    }

    pub fn shape(&self, v: Var) -> Shape {
        self.nodes[v.index()].shape
    }

    pub fn vars(&self, s: Span) -> &'a [Var] {
        &self.var_arena[s.range()]
    }
}

/// Write access to gradients during backward.
pub(crate) struct GradSink<'a> {
    nodes: &'a [Node],
    grads: &'a mut [Option<Buf>],
    param_grads: &'a mut [Tensor],
    pool: &'a mut Pool,
}

impl GradSink<'_> {
    /// Whether gradient must flow into `v`.
    pub fn needs(&self, v: Var) -> bool {
        self.nodes[v.index()].requires_grad
    }

    /// The gradient buffer of `v` and whether it is *fresh*. A fresh buffer has unspecified contents
    /// and the caller must overwrite every element; otherwise the caller adds to it.
    pub fn slot(&mut self, v: Var) -> (&mut [f32], bool) {
        if let Op::Param(id) = self.nodes[v.index()].op {
            return (self.param_grads[id.index()].data_mut(), false);
        }
        let len = self.nodes[v.index()].shape.len();
        let slot = &mut self.grads[v.index()];
        let fresh = slot.is_none();
        if fresh {
            *slot = Some(self.pool.take(len));
        }
        (slot.as_mut().map(Buf::as_mut_slice).unwrap_or_default(), fresh)
    }

    /// The gradient buffer of `v`, zero-filled if fresh: for kernels that write only part of it or
    /// scatter into it.
    pub fn slot_zeroed(&mut self, v: Var) -> &mut [f32] {
        let (dst, fresh) = self.slot(v);
        if fresh {
            dst.fill(0.0);
        }
        dst
    }

    /// Adds `src` (same shape as `v`) into `v`'s gradient.
    pub fn add(&mut self, v: Var, src: &[f32]) {
        let (dst, fresh) = self.slot(v);
        if fresh {
            dst.copy_from_slice(src);
        } else {
            crate::kernels::update1(dst, src, |d, s| d + s);
        }
    }
}
