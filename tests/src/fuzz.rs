//! A small mutation fuzzer for the input parsers this project owns or wraps: `.npy`, OBJ, glTF/GLB,
//! PLY, XYZ and the TOML experiment config.
//!
//! It starts from valid seed inputs, applies random byte-level and token-level mutations (bit flips,
//! truncation, duplication, splicing in `nan`, `1e38`, `-1`, huge counts, NUL bytes) and feeds each
//! result to the real reader. A reader may return any error, but must not panic: a panic is a
//! finding. Why not cargo-fuzz: it needs a nightly toolchain, and these parsers are cheap enough that a
//! deterministic in-process loop finds the same class of bugs (unchecked indexing, overflowing
//! allocations) on the stable toolchain CI has.
//!
//! Run it for a while with `cargo run --release -p nuvo-tests --example fuzz -- all 180`; findings
//! are written to `tests/fuzz-findings/` and replayed by `tests/tests/fuzz.rs` as regression tests.

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// A parser under test.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Target {
    Npy,
    Obj,
    Glb,
    Gltf,
    Ply,
    Xyz,
    Config,
}

impl Target {
    /// Every target.
    pub const ALL: [Target; 7] =
        [Target::Npy, Target::Obj, Target::Glb, Target::Gltf, Target::Ply, Target::Xyz, Target::Config];

    /// The target's name (also its file extension for findings).
    pub fn name(self) -> &'static str {
        match self {
            Target::Npy => "npy",
            Target::Obj => "obj",
            Target::Glb => "glb",
            Target::Gltf => "gltf",
            Target::Ply => "ply",
            Target::Xyz => "xyz",
            Target::Config => "toml",
        }
    }

    /// The target called `name`.
    pub fn from_name(name: &str) -> Option<Target> {
        Target::ALL.into_iter().find(|t| t.name() == name)
    }

    /// Valid inputs to start mutating from.
    pub fn seeds(self) -> Vec<Vec<u8>> {
        match self {
            Target::Npy => vec![npy_seed("|u1", &[3, 3, 3], 1), npy_seed("<f4", &[2, 3, 4], 4), npy_seed("<f2", &[2, 2, 2], 2)],
            Target::Obj => vec![
                b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nvt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\nf 1/1 2/2 4/3\n".to_vec(),
                b"o a\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//1 4//1\ng b\nf -1 -2 -3\n".to_vec(),
            ],
            Target::Glb => vec![glb_seed()],
            Target::Gltf => vec![gltf_seed()],
            Target::Ply => vec![
                b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n\
                  property float nx\nproperty float ny\nproperty float nz\nend_header\n0 0 0 0 0 1\n1 0 0 0 0 1\n0 1 0 0 0 1\n"
                    .to_vec(),
                ply_binary_seed(),
                b"ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n\
                  property uchar red\nproperty uchar green\nproperty uchar blue\nelement face 1\n\
                  property list uchar int vertex_indices\nend_header\n0 0 0 255 0 0\n1 0 0 0 255 0\n\
                  1 1 0 0 0 255\n0 1 0 9 9 9\n4 0 1 2 3\n"
                    .to_vec(),
            ],
            Target::Xyz => vec![b"0 0 0 0 0 1\n1 0 0 0 0 1\n0 1 0 0 0 1\n".to_vec(), b"# c\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n".to_vec()],
            Target::Config => vec![
                b"seed = 1\n[geometry]\nsource = \"mesh\"\npath = \"a.obj\"\n[model]\ncharts = 2\n[model.texture]\ndepth = 3\n\
                  [training]\nsteps = 10\n[losses.surface]\nweight = 10.0\n[losses.stretch]\narea = \"paper\"\n\
                  [output]\ngutter = 2\n[ablation]\nremove_each = [\"surface\"]\n[[ablation.variants]]\nname = \"x\"\nset = [\"model.charts=1\"]\n"
                    .to_vec(),
            ],
        }
    }

    /// Feeds `bytes` to the reader (through a file in `scratch` where the reader takes paths):
    /// `Ok(true)` when it accepted them, `Ok(false)` when it returned an error; only a panic escapes,
    /// as `Err(message)`.
    pub fn check(self, bytes: &[u8], scratch: &Path) -> Result<bool, String> {
        let path = scratch.join(format!("input.{}", self.name()));
        if self != Target::Npy && self != Target::Config {
            std::fs::write(&path, bytes).map_err(|e| format!("cannot write the scratch file: {e}"))?;
        }
        let outcome = catch_unwind(AssertUnwindSafe(|| match self {
            Target::Npy => nuvo_geometry::npy::parse_npy(bytes).is_ok(),
            Target::Obj | Target::Glb | Target::Gltf => nuvo_geometry::load_mesh(&path).is_ok(),
            // A PLY is read both ways: as points, and as a mesh (a PLY with faces is one).
            Target::Ply => {
                let points = nuvo_geometry::point_cloud::read_points(&path).is_ok();
                nuvo_geometry::load_mesh(&path).is_ok() || points
            }
            Target::Xyz => nuvo_geometry::point_cloud::read_points(&path).is_ok(),
            Target::Config => {
                nuvo_core::config::from_str("fuzz.toml", &String::from_utf8_lossy(bytes)).is_ok()
            }
        }));
        outcome.map_err(|payload| {
            payload
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| payload.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_else(|| "panic".to_owned())
        })
    }
}

/// What a fuzzing session did.
#[derive(Debug, Default)]
pub struct Report {
    /// Inputs tried.
    pub runs: u64,
    /// Inputs that made the reader panic, with the panic message.
    pub findings: Vec<(Vec<u8>, String)>,
}

/// Fuzzes `target` until `iterations` inputs were tried or `budget` elapsed, from `seed`
/// (deterministic for a fixed iteration count). Panic messages are silenced while it runs.
pub fn fuzz(target: Target, seed: u64, iterations: u64, budget: Duration, scratch: &Path) -> Report {
    let seeds = target.seeds();
    let mut rng = Rng(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1);
    let mut report = Report::default();
    let started = Instant::now();
    let hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {}));
    while report.runs < iterations && started.elapsed() < budget {
        let mut input = seeds[rng.below(seeds.len())].clone();
        for _ in 0..1 + rng.below(4) {
            mutate(&mut input, &mut rng);
        }
        report.runs += 1;
        if let Err(message) = target.check(&input, scratch) {
            report.findings.push((input, message));
        }
    }
    std::panic::set_hook(hook);
    report
}

/// Files of earlier findings for `target` in `dir` (`*.{ext}`), sorted.
pub fn findings_in(dir: &Path, target: Target) -> Vec<PathBuf> {
    let mut found: Vec<PathBuf> = std::fs::read_dir(dir)
        .into_iter()
        .flatten()
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == target.name()))
        .collect();
    found.sort();
    found
}

/// Tokens that break parsers in interesting ways when spliced into text formats.
const TOKENS: &[&[u8]] = &[
    b"nan",
    b"-inf",
    b"1e38",
    b"-1",
    b"0",
    b"4294967295",
    b"18446744073709551615",
    b"99999999999",
    b"\0",
    b"\n",
    b" ",
    b"/",
    b"//",
    b"f ",
    b"v ",
    b"element vertex 1000000000\n",
    b"property list uchar int vertex_indices\n",
    b"end_header\n",
    b"'shape': (1000000, 1000000, 1000000)",
    b"[",
    b"]",
    b"=",
    b"\"",
    b"{",
    b"}",
];

fn mutate(input: &mut Vec<u8>, rng: &mut Rng) {
    let len = input.len();
    match rng.below(7) {
        0 if len > 0 => {
            let i = rng.below(len);
            input[i] ^= 1 << rng.below(8);
        }
        1 if len > 0 => input.truncate(rng.below(len)),
        2 => {
            let token = TOKENS[rng.below(TOKENS.len())];
            let at = rng.below(len + 1);
            input.splice(at..at, token.iter().copied());
        }
        3 if len > 1 => {
            let (a, b) = (rng.below(len), rng.below(len));
            let (from, to) = (a.min(b), a.max(b));
            input.drain(from..to);
        }
        4 if len > 0 => {
            let from = rng.below(len);
            let to = (from + 1 + rng.below(64)).min(len);
            let chunk = input[from..to].to_vec();
            let at = rng.below(len + 1);
            input.splice(at..at, chunk);
        }
        5 if len > 0 => {
            let i = rng.below(len);
            input[i] = rng.below(256) as u8;
        }
        _ => {
            // Overwrite a little-endian u32 (counts and offsets in binary formats) with an extreme.
            if len >= 4 {
                let i = rng.below(len - 3);
                let v: u32 = [0, 1, u32::MAX, 0x7fff_ffff, 1 << 20][rng.below(5)];
                input[i..i + 4].copy_from_slice(&v.to_le_bytes());
            }
        }
    }
}

/// xorshift64: deterministic, dependency-free.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }

    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

fn npy_seed(descr: &str, shape: &[usize], item: usize) -> Vec<u8> {
    let n: usize = shape.iter().product();
    let data: Vec<u8> = (0..n * item).map(|i| (i * 37 % 251) as u8).collect();
    nuvo_geometry::npy::write_npy_bytes(shape, descr, &data, false)
}

fn ply_binary_seed() -> Vec<u8> {
    let mut out =
        b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
                    property float z\nend_header\n"
            .to_vec();
    for p in [[0f32, 0., 0.], [1., 0., 0.], [0., 1., 0.]] {
        for c in p {
            out.extend_from_slice(&c.to_le_bytes());
        }
    }
    out
}

/// Three positions and one triangle, as a buffer for the glTF seeds.
fn triangle_buffer() -> Vec<u8> {
    let mut b = Vec::new();
    for c in [0f32, 0., 0., 1., 0., 0., 0., 1., 0.] {
        b.extend_from_slice(&c.to_le_bytes());
    }
    for i in [0u16, 1, 2, 0] {
        b.extend_from_slice(&i.to_le_bytes());
    }
    b
}

fn gltf_json(buffer_uri: Option<&str>) -> String {
    let uri = buffer_uri.map(|u| format!("\"uri\":\"{u}\",")).unwrap_or_default();
    format!(
        r#"{{"asset":{{"version":"2.0"}},"buffers":[{{{uri}"byteLength":44}}],
"bufferViews":[{{"buffer":0,"byteOffset":0,"byteLength":36}},{{"buffer":0,"byteOffset":36,"byteLength":6}}],
"accessors":[{{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}},
{{"bufferView":1,"componentType":5123,"count":3,"type":"SCALAR"}}],
"meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}},"indices":1}}]}}],
"nodes":[{{"mesh":0,"scale":[2,2,2]}}],"scenes":[{{"nodes":[0]}}],"scene":0}}"#
    )
}

fn gltf_seed() -> Vec<u8> {
    const B64: &[u8] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let data = triangle_buffer();
    let mut enc = String::new();
    for chunk in data.chunks(3) {
        let n = chunk.iter().enumerate().fold(0u32, |acc, (i, &b)| acc | (b as u32) << (16 - 8 * i));
        for k in 0..4 {
            enc.push(if k <= chunk.len() { B64[(n >> (18 - 6 * k)) as usize & 63] as char } else { '=' });
        }
    }
    gltf_json(Some(&format!("data:application/octet-stream;base64,{enc}"))).into_bytes()
}

fn glb_seed() -> Vec<u8> {
    let mut json = gltf_json(None).into_bytes();
    while !json.len().is_multiple_of(4) {
        json.push(b' ');
    }
    let bin = triangle_buffer();
    let total = 12 + 8 + json.len() + 8 + bin.len();
    let mut out = b"glTF".to_vec();
    for v in [2u32, total as u32, json.len() as u32, 0x4E4F_534A] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out.extend_from_slice(&json);
    for v in [bin.len() as u32, 0x004E_4942] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out.extend_from_slice(&bin);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_seed_is_read_without_error() {
        let dir = tempfile::tempdir().unwrap();
        for t in Target::ALL {
            for (k, s) in t.seeds().iter().enumerate() {
                let path = dir.path().join(format!("seed{k}.{}", t.name()));
                std::fs::write(&path, s).unwrap();
                let ok = match t {
                    Target::Npy => nuvo_geometry::npy::parse_npy(s).map(drop).map_err(|e| e.to_string()),
                    Target::Obj | Target::Glb | Target::Gltf => {
                        nuvo_geometry::load_mesh(&path).map(drop).map_err(|e| e.to_string())
                    }
                    Target::Ply | Target::Xyz => {
                        nuvo_geometry::point_cloud::read_points(&path).map(drop).map_err(|e| e.to_string())
                    }
                    Target::Config => {
                        nuvo_core::config::from_str("seed.toml", std::str::from_utf8(s).unwrap())
                            .map(drop)
                            .map_err(|e| e.to_string())
                    }
                };
                assert!(ok.is_ok(), "seed {k} of {}: {ok:?}", t.name());
            }
        }
    }
}
