//! Checkpoints: every parameter and the optimiser state in one safetensors file.
//!
//! Layout: tensors `param/NAME`, `adam_m/NAME`, `adam_v/NAME` (f32, `[rows, cols]`), and one string
//! metadata entry `nuvo`: a JSON object `{format: "nuvo-checkpoint", version, step, adam_steps,
//! lr_scale, config (the resolved TOML), to_canonical}`. One entry, with fields in a fixed order,
//! because safetensors writes its metadata map in hash order: with several entries, the same state
//! would give different bytes in different processes. safetensors is readable from PyTorch and
//! numpy, so researchers can inspect trained networks directly.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use nuvo_autodiff::Tensor;
use nuvo_geometry::Similarity;
use safetensors::tensor::{Dtype, SafeTensors, TensorView};

use nuvo_fsio::write_bytes_atomic as write_atomic;

/// Identifies our files among other safetensors files.
pub const FORMAT: &str = "nuvo-checkpoint";
/// Bumped whenever the layout changes incompatibly.
pub const VERSION: u32 = 1;

/// Everything needed to continue training or to bake: parameters by name, the optimiser's moments
/// in the same order, and the run's position.
#[derive(Clone, Debug, PartialEq)]
pub struct Checkpoint {
    /// Steps completed.
    pub step: u64,
    /// Learning-rate multiplier after NaN rollbacks (1 normally).
    pub lr_scale: f32,
    /// The resolved experiment config, as TOML.
    pub config_toml: String,
    /// The geometry's input → canonical map, to write outputs in input coordinates.
    pub to_canonical: Similarity,
    /// `(name, value)` of every parameter (sorted by name when loaded).
    pub params: Vec<(String, Tensor)>,
    /// The optimiser's state, its moments in the order of `params`.
    pub adam: AdamState,
    /// Looks in a row at which the atlas had settled (`training.stop_when_settled`; 0 without it).
    pub settled_looks: u32,
}

/// Adam's state: its step count and its first and second moments, one vector per parameter.
#[derive(Clone, Debug, PartialEq)]
pub struct AdamState {
    /// Steps Adam has taken (its bias correction).
    pub steps: u64,
    /// First moments, one vector per parameter.
    pub m: Vec<Vec<f32>>,
    /// Second moments, one vector per parameter.
    pub v: Vec<Vec<f32>>,
}

/// A checkpoint that could not be written or read.
#[derive(Debug, thiserror::Error)]
pub enum CheckpointError {
    #[error("cannot access checkpoint {path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path} is not a usable nuvo checkpoint: {message}")]
    Invalid { path: PathBuf, message: String },
}

/// The `nuvo` metadata entry (field order is the serialised order).
#[derive(serde::Serialize, serde::Deserialize)]
struct Meta {
    format: String,
    version: u32,
    step: u64,
    adam_steps: u64,
    lr_scale: f32,
    config: String,
    to_canonical: Similarity,
    /// Absent when 0, so runs without `stop_when_settled` write the bytes they always did.
    #[serde(default, skip_serializing_if = "is_zero")]
    settled_looks: u32,
}

fn is_zero(n: &u32) -> bool {
    *n == 0
}

/// The metadata key.
const META_KEY: &str = "nuvo";

fn le_bytes(values: &[f32]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

impl Checkpoint {
    /// Writes the checkpoint atomically.
    pub fn save(&self, path: &Path) -> Result<(), CheckpointError> {
        let invalid = |m: String| CheckpointError::Invalid { path: path.to_owned(), message: m };
        let AdamState { steps: adam_steps, m, v } = &self.adam;
        let mut blobs: Vec<(String, Vec<usize>, Vec<u8>)> = Vec::with_capacity(3 * self.params.len());
        for (k, (name, t)) in self.params.iter().enumerate() {
            let shape = vec![t.rows(), t.cols()];
            blobs.push((format!("param/{name}"), shape.clone(), le_bytes(t.data())));
            blobs.push((format!("adam_m/{name}"), shape.clone(), le_bytes(&m[k])));
            blobs.push((format!("adam_v/{name}"), shape, le_bytes(&v[k])));
        }
        let views = blobs
            .iter()
            .map(|(n, s, b)| {
                Ok((
                    n.clone(),
                    TensorView::new(Dtype::F32, s.clone(), b).map_err(|e| invalid(e.to_string()))?,
                ))
            })
            .collect::<Result<Vec<_>, CheckpointError>>()?;
        let meta = Meta {
            format: FORMAT.to_owned(),
            version: VERSION,
            step: self.step,
            adam_steps: *adam_steps,
            lr_scale: self.lr_scale,
            config: self.config_toml.clone(),
            to_canonical: self.to_canonical,
            settled_looks: self.settled_looks,
        };
        let json = serde_json::to_string(&meta).map_err(|e| invalid(e.to_string()))?;
        let metadata = HashMap::from([(META_KEY.to_owned(), json)]);
        let bytes = safetensors::serialize(views, Some(metadata)).map_err(|e| invalid(e.to_string()))?;
        write_atomic(path, &bytes).map_err(|source| CheckpointError::Io { path: path.to_owned(), source })
    }

    /// Reads and checks a checkpoint written by [`Checkpoint::save`].
    pub fn load(path: &Path) -> Result<Self, CheckpointError> {
        let bytes =
            std::fs::read(path).map_err(|source| CheckpointError::Io { path: path.to_owned(), source })?;
        let invalid = |m: String| CheckpointError::Invalid { path: path.to_owned(), message: m };
        let st =
            SafeTensors::deserialize(&bytes).map_err(|e| invalid(format!("not a safetensors file ({e})")))?;
        let (_, meta) = SafeTensors::read_metadata(&bytes).map_err(|e| invalid(e.to_string()))?;
        let entry = meta
            .metadata()
            .as_ref()
            .and_then(|m| m.get(META_KEY))
            .ok_or_else(|| invalid(format!("metadata `{META_KEY}` is missing")))?;
        let meta: Meta =
            serde_json::from_str(entry).map_err(|e| invalid(format!("metadata `{META_KEY}`: {e}")))?;
        if meta.format != FORMAT {
            return Err(invalid(format!("its format is `{}`, not `{FORMAT}`", meta.format)));
        }
        if meta.version != VERSION {
            return Err(invalid(format!(
                "it is format version {}; this build of nuvo reads version {VERSION}",
                meta.version
            )));
        }
        let read = |name: &str| -> Result<Tensor, CheckpointError> {
            let t = st.tensor(name).map_err(|e| invalid(format!("tensor `{name}`: {e}")))?;
            let (shape, data) = (t.shape(), t.data());
            if t.dtype() != Dtype::F32 || shape.len() != 2 || data.len() != 4 * shape[0] * shape[1] {
                return Err(invalid(format!("tensor `{name}` is not a 2-D f32 tensor")));
            }
            let values = data.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect();
            Ok(Tensor::from_vec(shape[0], shape[1], values))
        };
        // Parameters come back sorted by name; restoring matches them to the model by name.
        let mut names: Vec<String> =
            st.names().into_iter().filter_map(|n| n.strip_prefix("param/")).map(str::to_owned).collect();
        names.sort();
        let mut params = Vec::with_capacity(names.len());
        let (mut m, mut v) = (Vec::with_capacity(names.len()), Vec::with_capacity(names.len()));
        for name in names {
            params.push((name.clone(), read(&format!("param/{name}"))?));
            m.push(read(&format!("adam_m/{name}"))?.into_vec());
            v.push(read(&format!("adam_v/{name}"))?.into_vec());
        }
        Ok(Checkpoint {
            step: meta.step,
            lr_scale: meta.lr_scale,
            config_toml: meta.config,
            to_canonical: meta.to_canonical,
            params,
            adam: AdamState { steps: meta.adam_steps, m, v },
            settled_looks: meta.settled_looks,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Checkpoint {
        Checkpoint {
            step: 42,
            lr_scale: 0.5,
            config_toml: "seed = 3\n".into(),
            to_canonical: Similarity { center: [1.0, 2.0, 3.0], scale: 0.25 },
            params: vec![
                ("a.w".into(), Tensor::from_vec(2, 2, vec![1.0, -2.0, 3.5, f32::MIN_POSITIVE])),
                ("b".into(), Tensor::scalar(7.0)),
            ],
            adam: AdamState {
                steps: 41,
                m: vec![vec![0.1, 0.2, 0.3, 0.4], vec![0.5]],
                v: vec![vec![1.0, 2.0, 3.0, 4.0], vec![5.0]],
            },
            settled_looks: 1,
        }
    }

    #[test]
    fn round_trip_is_exact() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("c.safetensors");
        let c = sample();
        c.save(&p).unwrap();
        assert_eq!(Checkpoint::load(&p).unwrap(), c);
    }

    #[test]
    fn garbage_and_foreign_files_are_clear_errors() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("junk.safetensors");
        std::fs::write(&p, b"definitely not a checkpoint").unwrap();
        let e = Checkpoint::load(&p).unwrap_err().to_string();
        assert!(e.contains("junk.safetensors") && e.contains("not a safetensors file"), "{e}");
        let e = Checkpoint::load(&dir.path().join("missing")).unwrap_err().to_string();
        assert!(e.contains("missing"), "{e}");
        // A valid safetensors file that is not ours.
        let data = le_bytes(&[1.0]);
        let view = TensorView::new(Dtype::F32, vec![1, 1], &data).unwrap();
        let bytes = safetensors::serialize([("x", view)], None).unwrap();
        std::fs::write(&p, bytes).unwrap();
        let e = Checkpoint::load(&p).unwrap_err().to_string();
        assert!(e.contains("metadata"), "{e}");
    }

    #[test]
    fn the_same_checkpoint_always_gives_the_same_bytes() {
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (dir.path().join("a"), dir.path().join("b"));
        sample().save(&a).unwrap();
        sample().save(&b).unwrap();
        assert_eq!(std::fs::read(a).unwrap(), std::fs::read(b).unwrap());
    }

    #[test]
    fn truncated_file_is_an_error_not_a_panic() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("c.safetensors");
        sample().save(&p).unwrap();
        let bytes = std::fs::read(&p).unwrap();
        for cut in [0, 8, bytes.len() / 2, bytes.len() - 1] {
            std::fs::write(&p, &bytes[..cut]).unwrap();
            assert!(Checkpoint::load(&p).is_err());
        }
    }
}
