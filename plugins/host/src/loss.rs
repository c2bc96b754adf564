//! A plugin instance as a [`Loss`]: the engine sees it as a custom op whose value and
//! vector-Jacobian product the plugin computes.
//!
//! The failure policy is on [`PluginLoss`].

use std::ffi::c_void;
use std::sync::{Mutex, PoisonError};

use nuvo_autodiff::{Tape, Var};
use nuvo_losses::{Loss, LossError, StepContext};
use nuvo_plugin_api::abi::{
    PluginString, RawInputs, RawMatrix, RawOutputs, SLOTS, STATUS_BAD_OPTIONS, STATUS_ERROR, STATUS_OK,
    STATUS_PANIC, Status, take_plugin_string,
};
use nuvo_plugin_api::{Dims, Quantity};

use crate::buffers::GradientBuffers;
use crate::error::PluginError;
use crate::gather::{dims, gather};
use crate::library::LoadedPlugin;

/// Longest message kept from a plugin, in bytes.
const MAX_MESSAGE: usize = 64 * 1024;

/// One instance of a plugin loss. `Send + Sync`: every call goes through a mutex, and through the
/// library's call lock.
///
/// Failures: an error status, a panic, a changed or overrun gradient buffer, an unknown status, or a
/// non-finite gradient next to a finite value make [`Loss::evaluate`] return
/// [`LossError::Evaluation`] naming the plugin and its path; `Trainer::step` returns it and the
/// trainer stays usable. After a panic the instance is poisoned and never called again (its state may
/// be broken): later evaluations fail with the original panic message. A non-finite *value* is
/// recorded as is, with zero gradients, so the trainer skips the step and names the term, as for any
/// loss.
#[derive(Debug)]
pub struct PluginLoss {
    plugin: &'static LoadedPlugin,
    instance: Mutex<Instance>,
}

/// The plugin's opaque instance, and why it must not be called again, if it must not.
#[derive(Debug)]
struct Instance {
    ptr: *mut c_void,
    poisoned: Option<String>,
}

// SAFETY: the ABI requires instances to be movable between threads (plugins built with the safe layer
// must be `Send`); the `Mutex` around `Instance` and the library's call lock ensure one call at a time.
unsafe impl Send for Instance {}

impl PluginLoss {
    /// Creates an instance of `plugin` from the options table (sent as TOML text).
    pub(crate) fn create(plugin: &'static LoadedPlugin, options: &toml::Table) -> Result<Self, PluginError> {
        let path = || plugin.info.path.clone();
        let text = toml::to_string(options).map_err(|e| PluginError::Options {
            path: path(),
            message: format!("cannot encode the options: {e}"),
        })?;
        let mut ptr = std::ptr::null_mut();
        let mut error = PluginString::null();
        let status = {
            let _one_call = plugin.lock_calls();
            // SAFETY: `create` is the plugin's (checked non-null); the text and out-pointers are valid for
            // the call.
            unsafe { (plugin.functions.create)(text.as_ptr(), text.len(), &mut ptr, &mut error) }
        };
        let message = take_message(plugin, error);
        match status {
            STATUS_OK if !ptr.is_null() => {
                Ok(PluginLoss { plugin, instance: Mutex::new(Instance { ptr, poisoned: None }) })
            }
            STATUS_OK => Err(PluginError::Create {
                path: path(),
                message: "it reported success but returned no instance".into(),
            }),
            STATUS_BAD_OPTIONS => Err(PluginError::Options {
                path: path(),
                message: message.unwrap_or_else(|| "it rejected its options without saying why".into()),
            }),
            other => Err(PluginError::Create { path: path(), message: describe_failure(other, message) }),
        }
    }

    /// An evaluation failure, naming the plugin and its path.
    fn failure(&self, message: impl std::fmt::Display) -> LossError {
        let info = &self.plugin.info;
        LossError::Evaluation {
            loss: info.name.clone(),
            message: format!("plugin {}: {message}", info.path.display()),
        }
    }

    /// Calls the plugin's `evaluate`; returns its status and message.
    fn call(
        &self,
        instance: *mut c_void,
        inputs: &RawInputs,
        outputs: &mut RawOutputs,
    ) -> (Status, Option<String>) {
        let mut error = PluginString::null();
        let status = {
            let _one_call = self.plugin.lock_calls();
            // SAFETY: `instance` is live (destroyed only on drop) and locked; `inputs` points at tape values
            // of exactly the declared shapes and `outputs` at distinct, exactly shaped buffers, all alive and
            // unchanged for the call.
            unsafe { (self.plugin.functions.evaluate)(instance, inputs, outputs, &mut error) }
        };
        (status, take_message(self.plugin, error))
    }
}

/// Copies and frees a message from `plugin`.
fn take_message(plugin: &LoadedPlugin, message: PluginString) -> Option<String> {
    // SAFETY: `message` is null or was just written by this plugin, and is taken exactly once.
    unsafe { take_plugin_string(message, plugin.functions.free_string, MAX_MESSAGE) }
}

/// A failed status and its message, as one phrase.
fn describe_failure(status: Status, message: Option<String>) -> String {
    let message = message.unwrap_or_else(|| "no message".into());
    match status {
        STATUS_PANIC => format!("it panicked: {message}"),
        STATUS_ERROR => message,
        other => format!("it returned the unknown status {other} ({message})"),
    }
}

/// The inputs struct pointing at the tape values of `vars`. Fails (a bug in nuvo, not the plugin) if
/// a value does not have the shape the ABI promises.
fn raw_inputs(
    tape: &Tape,
    vars: &[Option<Var>; SLOTS],
    dims: Dims,
    epsilon: f32,
) -> Result<RawInputs, String> {
    let mut inputs = RawInputs {
        charts: dims.charts,
        batch_3d: dims.batch_3d,
        batch_uv: dims.batch_uv,
        epsilon,
        quantities: [RawMatrix::EMPTY; SLOTS],
    };
    for (slot, var) in vars.iter().enumerate() {
        let (Some(var), Some(q)) = (var, Quantity::from_slot(slot)) else { continue };
        let (rows, cols) = q.shape(dims);
        let values = tape.value(*var);
        if values.len() != rows * cols {
            return Err(format!("internal error: `{q}` has {} values, expected {rows}×{cols}", values.len()));
        }
        inputs.quantities[slot] = RawMatrix { data: values.as_ptr(), rows, cols };
    }
    Ok(inputs)
}

impl Loss for PluginLoss {
    fn evaluate(&self, ctx: &mut StepContext<'_>) -> Result<Var, LossError> {
        let mut instance = self.instance.lock().unwrap_or_else(PoisonError::into_inner);
        if let Some(why) = &instance.poisoned {
            return Err(self.failure(format!("not called again after it panicked ({why})")));
        }
        let reads = self.plugin.info.reads;
        let dims = dims(ctx);
        let vars = gather(ctx, reads);
        let inputs = raw_inputs(ctx.tape, &vars, dims, ctx.data().epsilon).map_err(|m| self.failure(m))?;
        let mut buffers = GradientBuffers::new(reads, dims);
        let mut outputs = buffers.raw_outputs();
        let (status, message) = self.call(instance.ptr, &inputs, &mut outputs);
        if status != STATUS_OK {
            let description = describe_failure(status, message);
            if status == STATUS_PANIC {
                instance.poisoned = Some(description.clone());
            }
            return Err(self.failure(description));
        }
        buffers.check_untouched(&outputs).map_err(|m| self.failure(m))?;
        if outputs.value.is_finite() {
            buffers.check_finite().map_err(|m| self.failure(m))?;
        } else {
            buffers.zero();
        }
        let (wrt, grads): (Vec<Var>, Vec<&[f32]>) =
            buffers.differentiable().filter_map(|q| Some((vars[q.slot()]?, buffers.gradient(q)))).unzip();
        Ok(ctx.tape.custom_scalar(&wrt, outputs.value, &grads))
    }
}

impl Drop for PluginLoss {
    fn drop(&mut self) {
        let instance = self.instance.get_mut().unwrap_or_else(PoisonError::into_inner);
        let _one_call = self.plugin.lock_calls();
        // SAFETY: the instance came from this plugin's `create` and is destroyed exactly once, here, after
        // its last use; the library is never unloaded.
        unsafe { (self.plugin.functions.destroy)(instance.ptr) };
    }
}
