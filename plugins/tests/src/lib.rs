//! Support for the plugin integration tests: building the plugin libraries, and a tiny analytic
//! scene to train on.
//!
//! The plugins are built by running cargo from the test (the way a researcher builds one), in the
//! same workspace and target directory as the tests, so a clean clone needs nothing prepared and an
//! up-to-date tree rebuilds nothing. This cannot deadlock on cargo's build lock: `cargo test` releases
//! it before running test binaries, and within a binary the build runs once ([`plugins`]).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

/// The shared libraries of the example and fixture plugins, by target name (`symmetric_dirichlet`,
/// `misbehaving`, `raw_abi`, `future_abi`, `no_entry`).
pub struct Plugins {
    libraries: BTreeMap<String, PathBuf>,
}

impl Plugins {
    /// The library of target `name`. Panics (failing the test) if it was not built.
    pub fn path(&self, name: &str) -> &Path {
        self.libraries
            .get(name)
            .unwrap_or_else(|| panic!("no plugin library `{name}` in {:?}", self.libraries))
    }
}

/// The plugin libraries, built once per test binary with the profile the tests use.
pub fn plugins() -> &'static Plugins {
    static BUILT: OnceLock<Plugins> = OnceLock::new();
    BUILT.get_or_init(|| build().unwrap_or_else(|e| panic!("building the plugins failed: {e}")))
}

fn build() -> Result<Plugins, String> {
    let workspace = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let mut cmd = Command::new(cargo);
    cmd.current_dir(&workspace).args(["build", "--message-format=json-render-diagnostics"]);
    cmd.args(["-p", "nuvo-loss-symmetric-dirichlet", "-p", "nuvo-plugin-fixtures", "--lib", "--examples"]);
    if !cfg!(debug_assertions) {
        cmd.arg("--release");
    }
    let out = cmd.output().map_err(|e| format!("cannot run cargo: {e}"))?;
    if !out.status.success() {
        return Err(String::from_utf8_lossy(&out.stderr).into_owned());
    }
    let libraries = String::from_utf8_lossy(&out.stdout).lines().filter_map(cdylib_artifact).collect();
    Ok(Plugins { libraries })
}

/// `(target name, shared library)` from one line of cargo's JSON messages, if it reports a cdylib.
fn cdylib_artifact(line: &str) -> Option<(String, PathBuf)> {
    let msg: serde_json::Value = serde_json::from_str(line).ok()?;
    if msg["reason"] != "compiler-artifact" {
        return None;
    }
    let target = &msg["target"];
    target["crate_types"].as_array()?.iter().find(|k| *k == "cdylib")?;
    let file = msg["filenames"]
        .as_array()?
        .iter()
        .filter_map(|f| f.as_str())
        .find(|f| f.ends_with(std::env::consts::DLL_SUFFIX))?;
    Some((target["name"].as_str()?.to_owned(), PathBuf::from(file)))
}

pub use nuvo_geometry::testdata::sphere_sources as sources;

/// A small, fast experiment on the sphere; append `[losses.*]` tables to it.
pub const SMALL: &str = r#"
seed = 7
[geometry]
source = "sphere"
[model]
charts = 2
depth = 3
width = 32
grid_resolution = 16
[training]
steps = 40
batch_3d = 256
batch_uv = 256
checkpoint_every = 20
[optimizer]
lr_mlp = 1e-3
"#;

/// `path` as a TOML string literal (quoted and escaped), for writing configs.
pub fn toml_string(path: &Path) -> String {
    toml::Value::String(path.to_string_lossy().into_owned()).to_string()
}
