//! Deserialising a source's options table into its typed, documented options struct.

use serde::de::DeserializeOwned;

use crate::error::GeometryError;

/// Deserialises `table` into `T`. Options structs use `#[serde(deny_unknown_fields)]`, so a typo'd key
/// is an error naming the key and listing the valid ones; the error names the source too.
pub fn parse_options<T: DeserializeOwned>(
    source_name: &str,
    table: &toml::Table,
) -> Result<T, GeometryError> {
    T::deserialize(toml::Value::Table(table.clone())).map_err(|e| GeometryError::Options {
        source_name: source_name.to_owned(),
        message: e.to_string().trim().to_owned(),
    })
}

/// An options error for `source_name` with `message`.
pub(crate) fn options_error(source_name: &str, message: impl Into<String>) -> GeometryError {
    GeometryError::Options { source_name: source_name.to_owned(), message: message.into() }
}
