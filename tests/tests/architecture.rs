//! ARCHITECTURE.md as a checked contract: its list of which project crates each crate depends on
//! must be what the workspace's `Cargo.toml` files say, and the list's order must be a layering
//! (every crate after all it depends on), so no import runs back up unnoticed.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_path_buf()
}

fn read_toml(path: &Path) -> toml::Table {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    text.parse().unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Every workspace member's package name and the project crates its `[dependencies]` name.
fn workspace_dependencies() -> BTreeMap<String, BTreeSet<String>> {
    let root = root();
    let members = read_toml(&root.join("Cargo.toml"))["workspace"]["members"].as_array().unwrap().clone();
    let manifests: Vec<toml::Table> =
        members.iter().map(|m| read_toml(&root.join(m.as_str().unwrap()).join("Cargo.toml"))).collect();
    let names: BTreeSet<String> =
        manifests.iter().map(|m| m["package"]["name"].as_str().unwrap().to_owned()).collect();
    manifests
        .iter()
        .map(|m| {
            let deps = m.get("dependencies").and_then(toml::Value::as_table);
            let ours =
                deps.into_iter().flat_map(|d| d.keys()).filter(|k| names.contains(*k)).cloned().collect();
            (m["package"]["name"].as_str().unwrap().to_owned(), ours)
        })
        .collect()
}

/// The list between the `dependencies` markers, in its order: `` - `crate`: `dep`, `dep` `` (or `—`).
fn documented_dependencies() -> Vec<(String, BTreeSet<String>)> {
    let text = std::fs::read_to_string(root().join("ARCHITECTURE.md")).unwrap();
    let begin =
        text.find("<!-- dependencies: begin -->").expect("ARCHITECTURE.md has the list's begin marker");
    let end = text.find("<!-- dependencies: end -->").expect("ARCHITECTURE.md has the list's end marker");
    let unquote = |s: &str| s.trim().trim_matches('`').to_owned();
    text[begin..end]
        .lines()
        .filter_map(|l| l.strip_prefix("- "))
        .map(|l| {
            let (name, deps) = l.split_once(':').unwrap_or_else(|| panic!("not `- crate: deps`: {l}"));
            let deps = deps.trim();
            let deps = if deps == "—" { BTreeSet::new() } else { deps.split(',').map(unquote).collect() };
            (unquote(name), deps)
        })
        .collect()
}

#[test]
fn the_documented_dependencies_are_the_manifests_and_a_layering() {
    let documented = documented_dependencies();
    let actual = workspace_dependencies();
    let listed: BTreeMap<String, BTreeSet<String>> = documented.iter().cloned().collect();
    assert_eq!(listed.len(), documented.len(), "a crate is listed twice in ARCHITECTURE.md");
    for (name, deps) in &actual {
        let doc = listed.get(name).unwrap_or_else(|| panic!("ARCHITECTURE.md does not list `{name}`"));
        assert_eq!(
            doc, deps,
            "`{name}`'s project dependencies: ARCHITECTURE.md says {doc:?}, Cargo.toml {deps:?}"
        );
    }
    for name in listed.keys() {
        assert!(actual.contains_key(name), "ARCHITECTURE.md lists `{name}`, which is not a workspace member");
    }
    let mut seen = BTreeSet::new();
    for (name, deps) in &documented {
        for d in deps {
            assert!(
                seen.contains(d),
                "`{name}` depends on `{d}`, listed after it: the layering runs back up"
            );
        }
        seen.insert(name.clone());
    }
}
