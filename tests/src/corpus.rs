//! Malformed inputs for every file the CLI reads: geometry (OBJ, glTF/GLB, PLY, XYZ, NPY), experiment
//! configs (TOML) and loss plugins.
//!
//! [`write()`] creates the files in a folder and returns one [`Case`] per input, each with the config
//! that makes `nuvo train` read it and the words its error must contain. Invariant: every case is
//! wrong in exactly one way that a user could plausibly produce (a typo, a half-written download, a
//! broken exporter), and none of them may make the CLI panic, hang or leave complete-looking output.

use std::path::{Path, PathBuf};

use nuvo_geometry::npy::write_npy_bytes;

/// Which reader a case exercises.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// A triangle mesh (`nuvo train` with `source = "mesh"`, and `nuvo eval`).
    Mesh,
    /// A point cloud (`source = "point_cloud"`).
    PointCloud,
    /// A density grid (`source = "density"`).
    Density,
    /// The experiment config itself.
    Config,
    /// A loss plugin named by the config.
    Plugin,
}

/// One malformed input.
#[derive(Clone, Debug)]
pub struct Case {
    /// Short name, unique in the corpus (also the file's stem).
    pub name: String,
    pub kind: Kind,
    /// The malformed file (for configs: the config itself).
    pub input: PathBuf,
    /// A config that makes `nuvo train` read `input`.
    pub config: PathBuf,
    /// Lower-case words the error must contain (besides the file's name), e.g. `["nan"]`.
    pub expect: Vec<&'static str>,
}

/// Small, fast training settings appended to every generated config.
const TINY: &str = "[model]\ncharts = 1\ndepth = 2\nwidth = 8\ngrid_resolution = 4\n\
                    [training]\nsteps = 2\nbatch_3d = 16\nbatch_uv = 16\n\
                    [output]\neval_views = 1\neval_resolution = 16\nrenders = 0\natlas_resolution = 64\ngutter = 1\n";

/// A valid one-triangle-pair mesh, for configs whose fault is elsewhere.
const GOOD_OBJ: &str = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 3 4\nf 1 2 5\nf 1 5 4\n";

/// Writes the corpus into `dir` (which must exist) and returns its cases.
pub fn write(dir: &Path) -> Vec<Case> {
    let mut w = Writer { dir: dir.to_owned(), cases: Vec::new() };
    w.meshes();
    w.gltf();
    w.point_clouds();
    w.densities();
    w.configs();
    w.plugins();
    w.cases
}

struct Writer {
    dir: PathBuf,
    cases: Vec<Case>,
}

impl Writer {
    fn file(&self, name: &str, bytes: &[u8]) -> PathBuf {
        let p = self.dir.join(name);
        std::fs::write(&p, bytes).expect("the corpus folder is writable");
        p
    }

    /// A case whose input is read as the geometry of `source`.
    fn geometry(&mut self, kind: Kind, file: &str, bytes: &[u8], expect: &[&'static str]) {
        let input = self.file(file, bytes);
        let source = match kind {
            Kind::Mesh => "mesh",
            Kind::PointCloud => "point_cloud",
            Kind::Density => "density",
            _ => unreachable!("geometry cases only"),
        };
        let extra = if kind == Kind::Density { "bounds = [[-1, -1, -1], [1, 1, 1]]\n" } else { "" };
        let stem = file.replace('.', "_");
        let config = self.file(
            &format!("{stem}.toml"),
            format!("[geometry]\nsource = \"{source}\"\npath = {input:?}\n{extra}{TINY}").as_bytes(),
        );
        self.cases.push(Case { name: stem, kind, input, config, expect: expect.to_vec() });
    }

    /// A config case: `body` is the whole config (the geometry defaults to a good mesh).
    fn config(&mut self, name: &str, body: &str, expect: &[&'static str]) {
        let config = self.file(&format!("{name}.toml"), body.as_bytes());
        self.cases.push(Case {
            name: name.to_owned(),
            kind: Kind::Config,
            input: config.clone(),
            config,
            expect: expect.to_vec(),
        });
    }

    fn meshes(&mut self) {
        let m = Kind::Mesh;
        self.geometry(m, "empty.obj", b"", &["no"]);
        self.geometry(m, "garbage.obj", &garbage(4096, 1), &[]);
        self.geometry(m, "nul.obj", b"v 0 0 0\nv 1 0 0\nv 0\0 1 0\nf 1 2 3\n", &[]);
        self.geometry(m, "truncated.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2", &[]);
        self.geometry(m, "nan.obj", b"v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n", &["finite"]);
        self.geometry(m, "inf.obj", b"v 0 0 0\nv inf 0 0\nv 0 1 0\nf 1 2 3\n", &["finite"]);
        self.geometry(
            m,
            "huge.obj",
            b"v 0 0 0\nv 1e38 0 0\nv 0 -1e38 0\nv 0 0 1e38\nf 1 2 3\nf 1 2 4\n",
            &[],
        );
        self.geometry(m, "index_out_of_range.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n", &[]);
        self.geometry(m, "index_zero.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", &[]);
        self.geometry(m, "index_negative.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf -1 -2 -7\n", &[]);
        self.geometry(m, "no_faces.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\n", &["face"]);
        self.geometry(m, "degenerate.obj", b"v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\nf 1 1 2\n", &["degenerate"]);
    }

    fn gltf(&mut self) {
        let m = Kind::Mesh;
        self.geometry(m, "empty.glb", b"", &[]);
        self.geometry(m, "garbage.glb", &garbage(2048, 2), &[]);
        let mut truncated = b"glTF".to_vec();
        truncated.extend_from_slice(&2u32.to_le_bytes());
        truncated.extend_from_slice(&4000u32.to_le_bytes());
        truncated.extend_from_slice(&[0u8; 20]);
        self.geometry(m, "truncated.glb", &truncated, &[]);
        self.geometry(m, "empty.gltf", b"", &[]);
        self.geometry(m, "not_json.gltf", b"{\"asset\": {\"version\": \"2.0\"", &[]);
        let no_mesh = br#"{"asset":{"version":"2.0"},"scenes":[{"nodes":[]}],"scene":0}"#;
        self.geometry(m, "no_mesh.gltf", no_mesh, &[]);
        let missing_buffer = br#"{"asset":{"version":"2.0"},"buffers":[{"uri":"missing.bin","byteLength":36}],
            "bufferViews":[{"buffer":0,"byteLength":36}],
            "accessors":[{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}],
            "meshes":[{"primitives":[{"attributes":{"POSITION":0}}]}],"nodes":[{"mesh":0}],"scenes":[{"nodes":[0]}],"scene":0}"#;
        self.geometry(m, "missing_buffer.gltf", missing_buffer, &["missing.bin"]);
    }

    fn point_clouds(&mut self) {
        let p = Kind::PointCloud;
        self.geometry(p, "empty.ply", b"", &[]);
        self.geometry(p, "garbage.ply", &garbage(1024, 3), &[]);
        let lying = b"ply\nformat ascii 1.0\nelement vertex 100\nproperty float x\nproperty float y\n\
                      property float z\nend_header\n0 0 0\n1 0 0\n0 1 0\n";
        self.geometry(p, "header_lies.ply", lying, &[]);
        let mut bin = b"ply\nformat binary_little_endian 1.0\nelement vertex 50\nproperty float x\n\
                        property float y\nproperty float z\nend_header\n"
            .to_vec();
        bin.extend_from_slice(&[0u8; 30]);
        self.geometry(p, "truncated_binary.ply", &bin, &[]);
        let nan = b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
                    property float z\nend_header\n0 0 0\nnan 0 0\n0 1 0\n";
        self.geometry(p, "nan.ply", nan, &["line 9"]);
        let no_xyz = b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float a\nend_header\n1\n2\n";
        self.geometry(p, "no_positions.ply", no_xyz, &[]);
        self.geometry(p, "empty.xyz", b"", &[]);
        self.geometry(p, "garbage.xyz", b"1 2 3\nfour five six\n", &["line 2"]);
    }

    fn densities(&mut self) {
        let d = Kind::Density;
        self.geometry(d, "empty.npy", b"", &[]);
        self.geometry(d, "garbage.npy", &garbage(512, 4), &[]);
        self.geometry(d, "two_d.npy", &npy("<f4", &[4, 4], 4 * 16), &["3-d"]);
        self.geometry(d, "complex_dtype.npy", &npy("<c8", &[2, 2, 2], 8 * 8), &["dtype"]);
        self.geometry(d, "absurd_shape.npy", &npy("|u1", &[100_000, 100_000, 100_000], 64), &[]);
        self.geometry(d, "truncated.npy", &npy("<f4", &[8, 8, 8], 100), &[]);
        let mut nan = npy("<f4", &[2, 2, 2], 0);
        for k in 0..8 {
            nan.extend_from_slice(&(if k == 3 { f32::NAN } else { 1.0f32 }).to_le_bytes());
        }
        self.geometry(d, "nan.npy", &nan, &["finite"]);
    }

    fn configs(&mut self) {
        let mesh = self.file("good.obj", GOOD_OBJ.as_bytes());
        let g = format!("[geometry]\nsource = \"mesh\"\npath = {mesh:?}\n");
        let dir = self.dir.clone();
        self.config("syntax_error", &format!("{g}[model\ncharts = 2\n"), &["toml"]);
        self.config("unknown_key", &format!("{g}[model]\nchrats = 2\n"), &["chrats", "charts", "line"]);
        self.config("wrong_type", &format!("{g}[training]\nsteps = \"many\"\n"), &["training.steps"]);
        self.config("unknown_loss", &format!("{g}[losses.cycle3d]\n"), &["cycle3d", "cycle_3d"]);
        self.config(
            "unknown_source",
            "[geometry]\nsource = \"meshh\"\npath = \"x.obj\"\n",
            &["meshh", "point_cloud"],
        );
        self.config("negative_size", &format!("{g}[training]\nbatch_3d = -5\n"), &["batch_3d"]);
        self.config("zero_charts", &format!("{g}[model]\ncharts = 0\n"), &["model.charts", "at least 1"]);
        let missing = dir.join("does_not_exist.obj");
        self.config(
            "missing_file",
            &format!("[geometry]\nsource = \"mesh\"\npath = {missing:?}\n"),
            &["does_not_exist.obj"],
        );
        self.config(
            "directory_as_file",
            &format!("[geometry]\nsource = \"mesh\"\npath = {dir:?}\n"),
            &["directory"],
        );
        self.config("missing_geometry", "seed = 1\n", &["missing field `geometry`"]);
        self.config("nan_rate", &format!("{g}[optimizer]\nlr_mlp = nan\n"), &["lr_mlp"]);
    }

    fn plugins(&mut self) {
        let mesh = self.dir.join("good.obj");
        let text_lib = self.file("not_a_library.so", b"this is a text file, not a shared library\n");
        let g = format!("[geometry]\nsource = \"mesh\"\npath = {mesh:?}\n{TINY}");
        for (name, lib) in
            [("plugin_not_a_library", text_lib), ("plugin_missing", self.dir.join("libnope.so"))]
        {
            let config = self
                .file(&format!("{name}.toml"), format!("{g}[losses.mine]\nplugin = {lib:?}\n").as_bytes());
            self.cases.push(Case {
                name: name.to_owned(),
                kind: Kind::Plugin,
                input: lib,
                config,
                expect: vec![],
            });
        }
    }
}

/// `n` deterministic pseudo-random bytes, NULs included.
fn garbage(n: usize, seed: u64) -> Vec<u8> {
    let mut state = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    (0..n)
        .map(|_| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 24) as u8
        })
        .collect()
}

/// A `.npy` file of `descr` and `shape` whose data are `data_bytes` zero bytes (fewer or more than
/// the shape needs, to make truncated and absurd files).
fn npy(descr: &str, shape: &[usize], data_bytes: usize) -> Vec<u8> {
    write_npy_bytes(shape, descr, &vec![0; data_bytes], false)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_unique_and_files_exist() {
        let dir = tempfile::tempdir().unwrap();
        let cases = write(dir.path());
        let mut names: Vec<&str> = cases.iter().map(|c| c.name.as_str()).collect();
        names.sort();
        let n = names.len();
        names.dedup();
        assert_eq!(names.len(), n);
        assert!(n >= 40, "{n} cases");
        for c in &cases {
            assert!(c.config.is_file(), "{}", c.name);
        }
    }

    #[test]
    fn npy_headers_are_aligned() {
        let b = npy("<f4", &[2, 3, 4], 0);
        assert_eq!(b.len() % 64, 0);
        assert_eq!(&b[..6], b"\x93NUMPY");
    }
}
