//! Locating the shared test data (`shared/data/` beside the workspace), for tests and benchmarks.
//!
//! Not part of the API: it lives in the crate only so unit tests, integration tests and examples
//! share one rule. A test that needs the data and cannot find it **fails** with a message saying where
//! it looked; it never skips.

use std::path::PathBuf;

/// `$NUVO_DATA` if set, else `<workspace root>/../shared/data`.
pub fn data_dir() -> PathBuf {
    match std::env::var_os("NUVO_DATA") {
        Some(d) => PathBuf::from(d),
        None => PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..").join("..").join("shared").join("data"),
    }
}

/// The path of `rel` inside [`data_dir`]; panics with a clear message when it is missing (test-only).
pub fn data_file(rel: &str) -> PathBuf {
    let p = data_dir().join(rel);
    assert!(
        p.is_file(),
        "test data {} not found; set NUVO_DATA to the folder holding meshes/, density/ and pointclouds/ \
         (default: <workspace>/../shared/data)",
        p.display()
    );
    p
}
