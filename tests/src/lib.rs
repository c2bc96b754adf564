//! Test helpers shared by the end-to-end suites: a generated corpus of malformed inputs and a small
//! mutation fuzzer for the input parsers.
//!
//! The corpus is written by code, not checked in as blobs, so each case says what is wrong with it
//! and the suites (`nuvo-cli/tests/malformed.rs`, `tests/tests/`) can assert on the error a user
//! sees.

pub mod corpus;
pub mod fuzz;
