//! `nuvo-autodiff`: a small reverse-mode automatic differentiation engine over 2-D f32 tensors.
//!
//! Written for Nuvo's workload: many MLPs evaluated on batches of a few thousand points, with losses
//! built from elementwise arithmetic, reductions, gathers and grid lookups. The split follows
//! candle-core: [`Tensor`] is plain owned data; [`Tape`] records operations on [`Var`] handles and runs
//! them backwards; [`nn`] and [`optim`] build models and train them on top.
//!
//! ```
//! use nuvo_autodiff::{Tape, Tensor, ParamStore};
//! let mut params = ParamStore::new();
//! let w = params.add("w", "mlp", Tensor::from_vec(2, 1, vec![0.5, -1.0]));
//! let mut tape = Tape::new(params);
//! let x = tape.input(&Tensor::from_vec(3, 2, vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0]));
//! let wv = tape.param(w);
//! let y = tape.matmul(x, wv);
//! let loss = tape.mean_all(y);
//! tape.backward(loss);
//! assert_eq!(tape.params().grad(w).data(), &[3.0, 4.0]);
//! ```
//!
//! Invariants worth knowing:
//! - Gradients of parameters accumulate in the [`ParamStore`] until `zero_grads`.
//! - Buffers are pooled: after the first step of a fixed-shape loop, steps allocate almost nothing.
//! - Every kernel is deterministic whatever the thread count (see the `kernels` module).

mod bf16;
pub mod gradcheck;
mod kernels;
mod lines;
pub mod nn;
mod ops;
pub mod optim;
mod params;
mod pool;
mod shape;
mod tape;
mod tensor;

pub use bf16::{Bf16Kernel, MatmulPrecision, bf16_kernel, bf16_matmul_available};
pub use ops::Activation;
pub use params::{ParamId, ParamInfo, ParamStore};
pub use pool::Pool;
pub use shape::Shape;
pub use tape::{Tape, Var};
pub use tensor::Tensor;

/// Output width of [`Tape::posenc`].
pub use ops::posenc_width;
