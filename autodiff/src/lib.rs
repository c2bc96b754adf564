//! Placeholder: the engine lands in the next commits.
