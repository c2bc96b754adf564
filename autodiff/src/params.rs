//! Trainable parameters, kept outside the tape so they survive [`crate::Tape::reset`].

use serde::{Deserialize, Serialize};

use crate::tensor::Tensor;

/// Handle to a parameter in a [`ParamStore`]. Stable for the store's lifetime.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub struct ParamId(pub(crate) u32);

impl ParamId {
    /// Position of the parameter in its store (registration order).
    pub fn index(self) -> usize {
        self.0 as usize
    }
}

/// One named parameter and the optimiser group it belongs to.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ParamInfo {
    /// Unique name, e.g. `texture.2.layer3.w`; checkpoints match parameters by name.
    pub name: String,
    /// Optimiser group, e.g. `mlp`, `sigma`, `grid`: groups get their own learning rate.
    pub group: String,
}

/// Every trainable tensor of a model, with its gradient.
///
/// Invariant: `values[i]`, `grads[i]` and `infos[i]` describe parameter `i`, and `grads[i]` has the
/// shape of `values[i]`. Gradients accumulate across `backward` calls until [`ParamStore::zero_grads`].
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct ParamStore {
    pub(crate) infos: Vec<ParamInfo>,
    pub(crate) values: Vec<Tensor>,
    #[serde(skip)]
    pub(crate) grads: Vec<Tensor>,
}

impl ParamStore {
    /// An empty store.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds a parameter with initial `value`. Names must be unique.
    ///
    /// # Panics
    /// If `name` is already taken (a model-construction bug).
    pub fn add(&mut self, name: impl Into<String>, group: impl Into<String>, value: Tensor) -> ParamId {
        let name = name.into();
        assert!(self.find(&name).is_none(), "parameter `{name}` registered twice");
        self.grads.push(Tensor::zeros(value.rows(), value.cols()));
        self.values.push(value);
        self.infos.push(ParamInfo { name, group: group.into() });
        ParamId((self.values.len() - 1) as u32)
    }

    /// Number of parameters (tensors).
    pub fn len(&self) -> usize {
        self.values.len()
    }

    /// True when there are no parameters.
    pub fn is_empty(&self) -> bool {
        self.values.is_empty()
    }

    /// Total number of scalar parameters.
    pub fn numel(&self) -> usize {
        self.values.iter().map(|t| t.data().len()).sum()
    }

    /// All parameter ids in registration order.
    pub fn ids(&self) -> impl Iterator<Item = ParamId> + use<> {
        (0..self.values.len() as u32).map(ParamId)
    }

    /// The id of the parameter called `name`.
    pub fn find(&self, name: &str) -> Option<ParamId> {
        self.infos.iter().position(|i| i.name == name).map(|i| ParamId(i as u32))
    }

    /// Name and group of a parameter.
    pub fn info(&self, id: ParamId) -> &ParamInfo {
        &self.infos[id.index()]
    }

    /// The value of a parameter.
    pub fn value(&self, id: ParamId) -> &Tensor {
        &self.values[id.index()]
    }

    /// The value of a parameter, mutably (initialisation, loading, optimiser steps).
    pub fn value_mut(&mut self, id: ParamId) -> &mut Tensor {
        &mut self.values[id.index()]
    }

    /// The accumulated gradient of a parameter.
    pub fn grad(&self, id: ParamId) -> &Tensor {
        &self.grads[id.index()]
    }

    /// Value and gradient together, for optimisers.
    pub fn value_and_grad_mut(&mut self, id: ParamId) -> (&mut Tensor, &Tensor) {
        (&mut self.values[id.index()], &self.grads[id.index()])
    }

    /// Sets every gradient to zero (before each step's `backward`).
    pub fn zero_grads(&mut self) {
        for g in &mut self.grads {
            g.data_mut().fill(0.0);
        }
    }

    /// True when every value and gradient is finite. The trainer checks this before an optimiser step.
    pub fn all_finite(&self) -> bool {
        self.values.iter().chain(&self.grads).all(|t| t.data().iter().all(|v| v.is_finite()))
    }

    /// Rebuilds gradient buffers after deserialisation (they are not stored).
    pub fn restore_grads(&mut self) {
        self.grads = self.values.iter().map(|v| Tensor::zeros(v.rows(), v.cols())).collect();
    }
}
