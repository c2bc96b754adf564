//! What differs between runs' resolved configs, key by key.
//!
//! Each `config.toml` is flattened to `dotted.key = value` leaves (an array is one leaf: a loss's
//! list of charts changes as a whole); a key differs when some run's value, or its absence, is
//! not the same as another's. Comparing values after parsing, not lines, means that formatting
//! and key order never show up as differences.

use std::collections::{BTreeMap, BTreeSet};

/// A config's leaves by dotted key, each value as TOML would write it.
pub type Flat = BTreeMap<String, String>;

/// The leaves of a TOML document.
pub fn flatten(text: &str) -> Result<Flat, toml::de::Error> {
    let table: toml::Table = toml::from_str(text)?;
    let mut out = Flat::new();
    walk("", &toml::Value::Table(table), &mut out);
    Ok(out)
}

fn walk(prefix: &str, value: &toml::Value, out: &mut Flat) {
    match value {
        toml::Value::Table(t) if !t.is_empty() || prefix.is_empty() => {
            for (k, v) in t {
                let key =
                    if prefix.is_empty() { quoted_key(k) } else { format!("{prefix}.{}", quoted_key(k)) };
                walk(&key, v, out);
            }
        }
        leaf => {
            out.insert(prefix.to_owned(), leaf.to_string());
        }
    }
}

/// A key as a TOML path segment: bare when it can be, quoted otherwise (`losses."my.plugin"`).
fn quoted_key(k: &str) -> String {
    let bare = !k.is_empty() && k.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
    if bare { k.to_owned() } else { toml::Value::String(k.to_owned()).to_string() }
}

/// The keys whose values are not the same in every config, in key order, with each config's value
/// (`None` where it lacks the key).
pub fn differences(configs: &[Flat]) -> Vec<(String, Vec<Option<String>>)> {
    let keys: BTreeSet<&String> = configs.iter().flat_map(|c| c.keys()).collect();
    keys.into_iter()
        .filter_map(|key| {
            let values: Vec<Option<String>> = configs.iter().map(|c| c.get(key).cloned()).collect();
            values.iter().any(|v| *v != values[0]).then(|| (key.clone(), values))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn configs_differ_by_value_not_by_formatting_or_order() {
        let a =
            flatten("seed = 3\n[model]\ncharts = 4\nwidth = 128\n[losses.chamfer]\nweight = 1.0\n").unwrap();
        let b = flatten("seed = 3\n[model]\nwidth = 128\ncharts = 8\n[losses]\nchamfer = { weight = 1.0 }\n[losses.\"x.y\"]\nweight = 2\n")
            .unwrap();
        assert_eq!(a["model.charts"], "4");
        assert_eq!(b["losses.\"x.y\".weight"], "2");
        let diff = differences(&[a, b]);
        assert_eq!(
            diff,
            [
                ("losses.\"x.y\".weight".to_owned(), vec![None, Some("2".to_owned())]),
                ("model.charts".to_owned(), vec![Some("4".to_owned()), Some("8".to_owned())]),
            ]
        );
    }

    #[test]
    fn arrays_are_one_value_and_one_config_has_no_differences() {
        let a = flatten("[output]\nviews = [1, 2]\nname = \"a\"\n").unwrap();
        assert_eq!(a["output.views"], "[1, 2]");
        assert_eq!(a["output.name"], "\"a\"");
        assert!(differences(std::slice::from_ref(&a)).is_empty());
        assert!(differences(&[]).is_empty());
    }
}
