//! Name → constructor registry of losses, with the documentation `nuvo losses` prints.

use std::collections::BTreeMap;

use crate::loss::{Loss, LossError};

/// One documented option of a loss.
#[derive(Clone, Copy, Debug)]
pub struct OptionDoc {
    pub name: &'static str,
    pub default: &'static str,
    pub doc: &'static str,
}

/// What the registry knows about a loss besides how to build it.
#[derive(Clone, Copy, Debug)]
pub struct LossInfo {
    /// Registry name, the key of its `[losses.NAME]` table.
    pub name: &'static str,
    /// One line: what the term does.
    pub summary: &'static str,
    /// The weight used when the config gives none (the paper's, for the paper's losses).
    pub default_weight: f32,
    /// Its options (besides `weight`).
    pub options: &'static [OptionDoc],
}

/// A loss the registry can build by name: what `nuvo losses` says about it, and a constructor from
/// its `[losses.NAME]` table. The paper's losses and an application's own take this one shape, the
/// shape of a run-time plugin (`nuvo_plugin_api::LossPlugin`: associated info and a constructor).
pub trait RegisteredLoss: Loss + Sized + 'static {
    /// Its name, summary, default weight and options.
    const INFO: LossInfo;

    /// The loss with these options (the `[losses.NAME]` table without `weight`).
    fn from_options(options: &toml::Table) -> Result<Self, LossError>;
}

/// Builds a loss from its options table (the `[losses.NAME]` table without `weight`).
type LossBuilder = fn(&toml::Table) -> Result<Box<dyn Loss>, LossError>;

fn build<L: RegisteredLoss>(options: &toml::Table) -> Result<Box<dyn Loss>, LossError> {
    Ok(Box::new(L::from_options(options)?))
}

/// The registry of losses by name.
#[derive(Default)]
pub struct LossRegistry {
    entries: BTreeMap<&'static str, (LossInfo, LossBuilder)>,
}

impl LossRegistry {
    /// An empty registry.
    pub fn new() -> Self {
        Self::default()
    }

    /// A registry with every loss of the paper.
    pub fn with_builtins() -> Self {
        let mut r = Self::new();
        crate::builtin::add_all(&mut r);
        r
    }

    /// Registers (or replaces) loss `L` under `L::INFO.name`.
    pub fn add<L: RegisteredLoss>(&mut self) {
        self.entries.insert(L::INFO.name, (L::INFO, build::<L>));
    }

    /// Everything registered, sorted by name.
    pub fn list(&self) -> impl Iterator<Item = &LossInfo> {
        self.entries.values().map(|(i, _)| i)
    }

    /// What is known about `name`.
    pub fn info(&self, name: &str) -> Option<&LossInfo> {
        self.entries.get(name).map(|(i, _)| i)
    }

    /// Comma-separated registered names, for error messages.
    pub fn names(&self) -> String {
        self.entries.keys().copied().collect::<Vec<_>>().join(", ")
    }

    /// Builds loss `name` from `options`; an unknown name lists the known ones.
    pub fn build(&self, name: &str, options: &toml::Table) -> Result<Box<dyn Loss>, LossError> {
        let (_, build) = self
            .entries
            .get(name)
            .ok_or_else(|| LossError::Unknown { name: name.to_owned(), known: self.names() })?;
        build(options)
    }
}

/// Deserialises a loss's options, turning serde's message into a [`LossError::Options`] naming the
/// loss (serde's own message names the key and lists the valid ones).
pub fn parse_options<T: serde::de::DeserializeOwned>(
    loss: &str,
    options: &toml::Table,
) -> Result<T, LossError> {
    T::deserialize(toml::Value::Table(options.clone()))
        .map_err(|e| LossError::Options { loss: loss.to_owned(), message: e.to_string().trim().to_owned() })
}

/// Rejects any option: for losses that take none.
pub fn no_options(loss: &str, options: &toml::Table) -> Result<(), LossError> {
    match options.keys().next() {
        None => Ok(()),
        Some(k) => Err(LossError::Options {
            loss: loss.to_owned(),
            message: format!("unknown field `{k}`; this loss takes no options besides `weight`"),
        }),
    }
}
