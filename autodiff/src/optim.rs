//! Adam with per-group learning rates, and the cosine-decay schedule.

use std::collections::BTreeMap;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::params::ParamStore;

/// Adam's hyper-parameters (learning rates are per group, see [`Adam::new`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AdamConfig {
    pub beta1: f32,
    pub beta2: f32,
    pub eps: f32,
}

impl Default for AdamConfig {
    fn default() -> Self {
        AdamConfig { beta1: 0.9, beta2: 0.999, eps: 1e-8 }
    }
}

/// A parameter belongs to a group that has no learning rate.
#[derive(Debug, thiserror::Error)]
#[error("parameter `{param}` is in group `{group}`, which has no learning rate (groups with one: {known})")]
pub struct MissingGroupError {
    pub param: String,
    pub group: String,
    pub known: String,
}

/// The Adam optimiser (Kingma & Ba) with bias correction. Its whole state serialises, so a resumed
/// run continues exactly where it stopped.
///
/// Invariant: `m[i]` and `v[i]` have the length of parameter `i`, and `lr_of[i]` is its group's rate.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Adam {
    pub config: AdamConfig,
    lr_of: Vec<f32>,
    m: Vec<Vec<f32>>,
    v: Vec<Vec<f32>>,
    steps: u64,
}

impl Adam {
    /// An optimiser for every parameter in `params`, each at the base learning rate of its group.
    pub fn new(
        params: &ParamStore,
        config: AdamConfig,
        group_lrs: &BTreeMap<String, f32>,
    ) -> Result<Self, MissingGroupError> {
        let mut lr_of = Vec::with_capacity(params.len());
        for info in &params.infos {
            let lr = group_lrs.get(&info.group).ok_or_else(|| MissingGroupError {
                param: info.name.clone(),
                group: info.group.clone(),
                known: group_lrs.keys().cloned().collect::<Vec<_>>().join(", "),
            })?;
            lr_of.push(*lr);
        }
        let zeros = || params.values.iter().map(|t| vec![0.0; t.data().len()]).collect::<Vec<_>>();
        Ok(Adam { config, lr_of, m: zeros(), v: zeros(), steps: 0 })
    }

    /// Number of steps taken.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// The first and second moment estimates, per parameter in registration order (for checkpoints).
    pub fn moments(&self) -> (&[Vec<f32>], &[Vec<f32>]) {
        (&self.m, &self.v)
    }

    /// Restores a saved state (from [`Adam::moments`] and [`Adam::steps`]). Fails, changing nothing,
    /// if the moments do not match the parameters this optimiser was built for.
    pub fn restore(&mut self, steps: u64, m: Vec<Vec<f32>>, v: Vec<Vec<f32>>) -> Result<(), String> {
        let fits = |x: &[Vec<f32>]| {
            x.len() == self.m.len() && x.iter().zip(&self.m).all(|(a, b)| a.len() == b.len())
        };
        if !fits(&m) || !fits(&v) {
            return Err(format!(
                "optimiser state holds {} tensors whose sizes do not match the model's {}",
                m.len(),
                self.m.len()
            ));
        }
        self.steps = steps;
        self.m = m;
        self.v = v;
        Ok(())
    }

    /// One update of every parameter from its accumulated gradient, each group's learning rate
    /// multiplied by `lr_factor` (the schedule). Parameters are updated in parallel; each update is
    /// elementwise, so the result does not depend on the thread count.
    pub fn step(&mut self, params: &mut ParamStore, lr_factor: f32) {
        self.steps += 1;
        let AdamConfig { beta1, beta2, eps } = self.config;
        let t = self.steps as i32;
        let c1 = 1.0 - beta1.powi(t);
        let c2 = 1.0 - beta2.powi(t);
        params
            .values
            .par_iter_mut()
            .zip(params.grads.par_iter())
            .zip(self.m.par_iter_mut().zip(self.v.par_iter_mut()))
            .zip(self.lr_of.par_iter())
            .for_each(|(((p, g), (m, v)), &lr)| {
                let step = lr * lr_factor / c1;
                let inv_c2 = 1.0 / c2;
                for (((p, &g), m), v) in
                    p.data_mut().iter_mut().zip(g.data()).zip(m.iter_mut()).zip(v.iter_mut())
                {
                    *m = beta1 * *m + (1.0 - beta1) * g;
                    *v = beta2 * *v + (1.0 - beta2) * g * g;
                    *p -= step * *m / ((*v * inv_c2).sqrt() + eps);
                }
            });
    }
}

/// Cosine decay from factor 1 to `final_factor` over `total_steps`, after an optional linear warm-up.
/// Multiply each group's base learning rate by [`CosineSchedule::factor`].
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CosineSchedule {
    pub total_steps: u64,
    #[serde(default)]
    pub warmup_steps: u64,
    #[serde(default)]
    pub final_factor: f32,
}

impl CosineSchedule {
    /// The learning-rate factor at `step` (0-based): ramps linearly over the warm-up, then follows
    /// `final + (1 − final)·½(1 + cos(π·progress))`, and stays at `final_factor` past the end.
    pub fn factor(&self, step: u64) -> f32 {
        if step < self.warmup_steps {
            return (step + 1) as f32 / self.warmup_steps as f32;
        }
        let span = self.total_steps.saturating_sub(self.warmup_steps).max(1);
        let progress = ((step - self.warmup_steps) as f32 / span as f32).min(1.0);
        let cos = 0.5 * (1.0 + (std::f32::consts::PI * progress).cos());
        self.final_factor + (1.0 - self.final_factor) * cos
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Tensor;

    #[test]
    fn schedule_shape() {
        let s = CosineSchedule { total_steps: 100, warmup_steps: 0, final_factor: 0.1 };
        assert_eq!(s.factor(0), 1.0);
        assert!((s.factor(50) - 0.55).abs() < 1e-6);
        assert!((s.factor(100) - 0.1).abs() < 1e-6);
        assert!((s.factor(1000) - 0.1).abs() < 1e-6);
        let w = CosineSchedule { total_steps: 100, warmup_steps: 10, final_factor: 0.0 };
        assert!((w.factor(0) - 0.1).abs() < 1e-6);
        assert!((w.factor(9) - 1.0).abs() < 1e-6);
    }

    #[test]
    fn first_adam_step_moves_each_group_by_its_learning_rate() {
        // With bias correction the first step is lr·g/(|g| + eps) ≈ lr·sign(g).
        let mut p = ParamStore::new();
        let a = p.add("a", "mlp", Tensor::from_vec(1, 2, vec![1.0, 1.0]));
        let b = p.add("b", "sigma", Tensor::scalar(0.0));
        p.grads[a.index()] = Tensor::from_vec(1, 2, vec![0.5, -2.0]);
        p.grads[b.index()] = Tensor::scalar(3.0);
        let lrs = BTreeMap::from([("mlp".to_owned(), 1e-2), ("sigma".to_owned(), 0.1)]);
        let mut adam = Adam::new(&p, AdamConfig::default(), &lrs).unwrap();
        adam.step(&mut p, 1.0);
        let av = p.value(a).data();
        assert!((av[0] - 0.99).abs() < 1e-6 && (av[1] - 1.01).abs() < 1e-6, "{av:?}");
        assert!((p.value(b).data()[0] + 0.1).abs() < 1e-6);
    }

    #[test]
    fn missing_group_is_an_error_naming_it() {
        let mut p = ParamStore::new();
        p.add("grid.0", "grid", Tensor::scalar(0.0));
        let e =
            Adam::new(&p, AdamConfig::default(), &BTreeMap::from([("mlp".to_owned(), 1e-4)])).unwrap_err();
        assert!(e.to_string().contains("`grid`"), "{e}");
    }
}
