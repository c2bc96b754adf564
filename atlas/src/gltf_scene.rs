//! Writing a new UV layer back into the user's own glTF scene.
//!
//! [`write_gltf_with_uvs`] takes the `.gltf`/`.glb` file that
//! [`nuvo_geometry::gltf_io::load_gltf`] merged into one mesh, and a per-corner [`UvLayer`] for that
//! merged mesh, and writes the same scene as a `.glb` whose triangle primitives carry the new UVs
//! as `TEXCOORD_0`. Nothing else of the scene changes.
//!
//! **Preserved.** The JSON is edited as raw JSON, so every property the `gltf` crate does not model
//! survives: scenes, nodes (transforms, names, children, skins, cameras, extras, extensions),
//! meshes (names, weights, extras), materials, textures, samplers, images, skins, animations,
//! cameras, `asset`, `extensionsUsed`/`extensionsRequired`, top-level extras and extensions.
//! Accessors keep their component type, `normalized` flag, name, extras and extensions.
//!
//! **Rewritten**, for each triangle primitive that `load_gltf` reads (the primitives of the mesh
//! instances of the default scene, in its order; see [`nuvo_geometry::gltf_io::GltfScene`]):
//! - a vertex is split where its corners get different UVs: one output vertex per distinct
//!   (input vertex, UV) pair, numbered in the order the output indices first use them; unused input
//!   vertices are dropped;
//! - every vertex attribute (`POSITION`, `NORMAL`, `TANGENT`, `COLOR_n`, `TEXCOORD_n` for `n ≥ 1`,
//!   `JOINTS_n`, `WEIGHTS_n`, custom `_NAME`s; any type and component type; sparse accessors and
//!   accessors without a buffer view resolved) is gathered for the new vertices, and so is every
//!   attribute of every morph target; `min`/`max` are recomputed (always for `POSITION`);
//! - `TEXCOORD_0` is added, or replaces the old one, as float `VEC2` `(u, 1 − v)` (glTF's `v` points
//!   down; [`UvLayer`]'s points up). A morph target's `TEXCOORD_0` displacement belonged to the old
//!   UVs and is dropped (a target left with nothing else gets a zero one);
//! - triangle strips and fans become triangle lists with the same triangles in the same order
//!   and winding (`mode` 4); indices are `u16` when every vertex fits (at most 65 535), else `u32`.
//!
//! Materials are untouched: a texture they map through `TEXCOORD_0` is now sampled with the new
//! UVs (bake a new one); textures on other `texCoord` sets keep working as before. **With a baked
//! base colour** (`base_colour_png`, the input's appearance baked through the new UVs), the
//! rewritten primitives get it instead: each material they use is copied (`NAME (nuvo)`; the
//! original stays for anything else that uses it) with the PNG, embedded, as its
//! `baseColorTexture` on `TEXCOORD_0` and its `baseColorFactor` RGB set to 1 (the factor is in
//! the bake; alpha is kept), primitives without a material get a new one, and their `COLOR_0`,
//! also in the bake, is kept as `_NUVO_BAKED_COLOR_0` so that it is not applied twice.
//!
//! A primitive that assembles no triangle keeps its data and gets an all-zero `TEXCOORD_0`, so that
//! `load_gltf` still finds UVs on every triangle primitive. Point and line primitives, and meshes no
//! node of the scene uses, are left as they are.
//!
//! **Buffers.** The output is one GLB with one binary buffer, whatever the input was (`.gltf` with
//! external or `data:` buffers, or `.glb`). Buffer views still used (by kept accessors or embedded
//! images) are copied into it; accessors, views and buffers no longer referenced are dropped and
//! the rest renumbered. Images stored in buffer views stay embedded, `data:` image URIs stay as they
//! are, and **external image URIs are kept as written and nothing is copied**: they resolve relative
//! to the output's folder, so write the output beside the input or copy the images too.
//!
//! **Refused** (with an error naming the file): a mesh with triangle primitives instanced by more
//! than one node of the scene (one set of vertices cannot carry two different UV layouts; give each
//! node its own copy of the mesh), and files using extensions that store geometry or refer to buffer
//! data in ways this writer would break (`KHR_draco_mesh_compression`, `EXT_meshopt_compression`,
//! `KHR_meshopt_compression`, `EXT_mesh_features`, `EXT_structural_metadata`). Other extensions are
//! kept verbatim; they are assumed not to refer to accessors, buffer views or buffers, except
//! `EXT_mesh_gpu_instancing`, whose accessors are kept and renumbered.
//! [`check_gltf_unwrappable`] makes these checks cheaply (no buffer is read), before training.

use std::collections::{BTreeSet, HashMap};
use std::ops::Range;
use std::path::Path;

use gltf::json::Value;
use nuvo_geometry::gltf_io::{GltfPrimitiveFaces, gltf_mesh_instances, load_gltf_scene, read_gltf_document};
use nuvo_geometry::{GeometryError, TriMesh, UvLayer};
use serde::Serialize;

use crate::error::{AtlasError, write_atomic};

/// Where the vertices of the written file came from.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct GltfVertexMap {
    /// One entry per rewritten triangle primitive, in `load_gltf`'s merge order.
    pub primitives: Vec<PrimitiveVertexMap>,
    /// For the merged mesh `load_gltf` reads from the output: output vertex → vertex of the merged
    /// mesh `load_gltf` reads from the input. Faces are the same, in the same order, in both.
    pub merged: Vec<u32>,
}

/// The vertex map of one rewritten primitive.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PrimitiveVertexMap {
    /// The mesh index (unchanged in the output).
    pub mesh: usize,
    /// The primitive index within the mesh (unchanged in the output).
    pub primitive: usize,
    /// The node instancing the mesh (`None` for files without nodes).
    pub node: Option<usize>,
    /// The faces of the merged mesh this primitive holds.
    pub faces: Range<usize>,
    /// For each output vertex of the primitive, the input vertex (element of the input's attribute
    /// accessors) it copies.
    pub source_vertices: Vec<u32>,
}

/// Extensions whose data this writer cannot carry over.
const REFUSED_EXTENSIONS: [&str; 5] = [
    "KHR_draco_mesh_compression",
    "EXT_meshopt_compression",
    "KHR_meshopt_compression",
    "EXT_mesh_features",
    "EXT_structural_metadata",
];

/// Checks, without reading any buffer, that [`write_gltf_with_uvs`] can write UVs into `input`:
/// the file parses and validates as `load_gltf` requires, no mesh with triangle primitives is
/// instanced by more than one node, and no refused extension is used (module docs).
pub fn check_gltf_unwrappable(input: &Path) -> Result<(), AtlasError> {
    let (document, _) = read_gltf_document(input)?;
    check_document(input, &document)
}

fn check_document(path: &Path, document: &gltf::Document) -> Result<(), AtlasError> {
    if let Some(ext) = document.extensions_used().find(|e| REFUSED_EXTENSIONS.contains(e)) {
        return Err(refused(
            path,
            format!(
                "the file uses the extension {ext}, whose data cannot be carried over when \
                 TEXCOORD_0 is rewritten; export the scene without it"
            ),
        ));
    }
    let instances = gltf_mesh_instances(document).map_err(|m| GeometryError::malformed(path, m))?;
    let mut users: HashMap<usize, Vec<Option<usize>>> = HashMap::new();
    for i in &instances {
        users.entry(i.mesh).or_default().push(i.node);
    }
    for mesh in document.meshes() {
        let Some(nodes) = users.get(&mesh.index()) else { continue };
        let triangles = mesh.primitives().any(|p| {
            use gltf::mesh::Mode::*;
            matches!(p.mode(), Triangles | TriangleStrip | TriangleFan)
        });
        if nodes.len() > 1 && triangles {
            let named = |n: &Option<usize>| match n.and_then(|n| document.nodes().nth(n)) {
                Some(node) => match node.name() {
                    Some(name) => format!("{} ({name:?})", node.index()),
                    None => node.index().to_string(),
                },
                None => "?".into(),
            };
            let list: Vec<String> = nodes.iter().map(named).collect();
            return Err(refused(
                path,
                format!(
                    "mesh {}{} is used by {} nodes of the scene ({}); one set of vertices cannot \
                     carry a different UV layout for each use. Give each node its own copy of the \
                     mesh (in Blender: Object > Relations > Make Single User > Object & Data)",
                    mesh.index(),
                    mesh.name().map(|n| format!(" ({n:?})")).unwrap_or_default(),
                    nodes.len(),
                    list.join(", ")
                ),
            ));
        }
    }
    Ok(())
}

fn refused(path: &Path, message: String) -> AtlasError {
    AtlasError::invalid("glTF scene", format!("{}: {message}", path.display()))
}

fn malformed(path: &Path, message: impl Into<String>) -> AtlasError {
    AtlasError::Geometry(GeometryError::malformed(path, message))
}

/// Writes `input`'s scene to `output` (a `.glb`) with `uv` as `TEXCOORD_0`; see the module docs
/// for what is kept, rewritten and refused. `uv` is a per-corner layer of the mesh
/// [`nuvo_geometry::gltf_io::load_gltf`] reads from `input` (`v` up). Returns where each output
/// vertex came from. The output is written atomically.
///
/// `base_colour_png`: PNG bytes of a base-colour texture baked through `uv` (module docs).
pub fn write_gltf_with_uvs(
    input: &Path,
    uv: &UvLayer,
    output: &Path,
    base_colour_png: Option<&[u8]>,
) -> Result<GltfVertexMap, AtlasError> {
    let scene = load_gltf_scene(input)?;
    check_document(input, &scene.document)?;
    check_uv(input, &scene.mesh, uv)?;
    let json = raw_json(input, &scene.document)?;
    let mut writer = Writer {
        path: input,
        old_accessors: json.get("accessors").and_then(Value::as_array).map_or(0, Vec::len),
        old_views: json.get("bufferViews").and_then(Value::as_array).map_or(0, Vec::len),
        json,
        buffers: &scene.buffers,
        dense: HashMap::new(),
        new_accessors: Vec::new(),
        new_views: Vec::new(),
    };
    let mut map = GltfVertexMap::default();
    for prim in &scene.primitives {
        let source_vertices = writer.rewrite_primitive(prim, &scene.mesh, uv)?;
        map.merged.extend(source_vertices.iter().map(|&v| v + prim.vertices.start as u32));
        map.primitives.push(PrimitiveVertexMap {
            mesh: prim.mesh,
            primitive: prim.primitive,
            node: prim.node,
            faces: prim.faces.clone(),
            source_vertices,
        });
    }
    if let Some(png) = base_colour_png {
        writer.use_base_colour(png, &scene.primitives);
    }
    let (json, bin) = writer.finish()?;
    let bytes = glb(output, &json, bin)?;
    write_atomic(output, |w| w.write_all(&bytes))?;
    Ok(map)
}

fn check_uv(path: &Path, mesh: &TriMesh, uv: &UvLayer) -> Result<(), AtlasError> {
    let bad = |m: String| AtlasError::invalid("UV layer", format!("for {}: {m}", path.display()));
    if uv.triangles.len() != mesh.triangles.len() {
        return Err(bad(format!(
            "it has {} faces but the file's merged mesh has {}",
            uv.triangles.len(),
            mesh.triangles.len()
        )));
    }
    if let Some(i) = uv.coords.iter().position(|c| c.iter().any(|x| !x.is_finite())) {
        return Err(bad(format!("coordinate {i} is not finite: {:?}", uv.coords[i])));
    }
    if let Some(f) = uv.triangles.iter().position(|t| t.iter().any(|&i| i as usize >= uv.coords.len())) {
        return Err(bad(format!(
            "face {f} refers to coordinate {:?} but there are {}",
            uv.triangles[f],
            uv.coords.len()
        )));
    }
    Ok(())
}

/// The file's JSON as raw JSON (so that nothing the `gltf` crate does not model is lost), checked
/// against the validated `document` it must describe.
fn raw_json(path: &Path, document: &gltf::Document) -> Result<Value, AtlasError> {
    let bytes = std::fs::read(path).map_err(|e| GeometryError::Io { path: path.to_path_buf(), source: e })?;
    let json_bytes = if bytes.starts_with(b"glTF") {
        gltf::binary::Glb::from_slice(&bytes)
            .map_err(|e| malformed(path, format!("not a valid GLB file: {e}")))?
            .json
            .into_owned()
    } else {
        bytes
    };
    let json: Value = gltf::json::deserialize::from_slice(&json_bytes)
        .map_err(|e| malformed(path, format!("not valid glTF JSON: {e}")))?;
    let len = |key: &str| json.get(key).and_then(Value::as_array).map_or(0, Vec::len);
    if !json.is_object()
        || len("accessors") != document.accessors().len()
        || len("bufferViews") != document.views().len()
        || len("meshes") != document.meshes().len()
        || document.meshes().any(|m| {
            let prims = json["meshes"][m.index()].get("primitives").and_then(Value::as_array);
            prims.map_or(0, Vec::len) != m.primitives().len()
        })
    {
        return Err(malformed(path, "the file changed while it was being read"));
    }
    Ok(json)
}

/// An accessor's elements, tightly packed (sparse substitutions applied).
struct Dense {
    component: u64,
    type_: String,
    elem: usize,
    count: usize,
    bytes: Vec<u8>,
}

/// Where a buffer view of the output gets its bytes.
enum ViewData {
    /// The bytes of an input view (index into the input's `bufferViews`).
    Old(usize),
    /// New bytes.
    New(Vec<u8>),
}

struct Writer<'a> {
    path: &'a Path,
    json: Value,
    buffers: &'a [gltf::buffer::Data],
    old_accessors: usize,
    old_views: usize,
    dense: HashMap<usize, std::rc::Rc<Dense>>,
    /// Accessors numbered from `old_accessors` on, pointing at views numbered from `old_views` on.
    new_accessors: Vec<Value>,
    new_views: Vec<(Value, Vec<u8>)>,
}

const ARRAY_BUFFER: u64 = 34962;
const ELEMENT_ARRAY_BUFFER: u64 = 34963;
const F32: u64 = 5126;

fn component_size(component: u64) -> Option<usize> {
    match component {
        5120 | 5121 => Some(1),
        5122 | 5123 => Some(2),
        5125 | 5126 => Some(4),
        _ => None,
    }
}

/// (columns, rows) of an accessor type; matrices are stored column by column.
fn shape(type_: &str) -> Option<(usize, usize)> {
    Some(match type_ {
        "SCALAR" => (1, 1),
        "VEC2" => (1, 2),
        "VEC3" => (1, 3),
        "VEC4" => (1, 4),
        "MAT2" => (2, 2),
        "MAT3" => (3, 3),
        "MAT4" => (4, 4),
        _ => return None,
    })
}

/// Byte offsets of the components of one element, and the element's size: matrix columns start on
/// 4-byte boundaries (glTF 2.0, "Data Alignment").
fn layout(type_: &str, component: u64) -> Option<(Vec<usize>, usize)> {
    let (cols, rows) = shape(type_)?;
    let c = component_size(component)?;
    let column = if cols > 1 { (rows * c).next_multiple_of(4) } else { rows * c };
    let offsets = (0..cols).flat_map(|j| (0..rows).map(move |r| j * column + r * c)).collect();
    Some((offsets, cols * column))
}

fn read_component(bytes: &[u8], component: u64) -> f64 {
    match component {
        5120 => bytes[0] as i8 as f64,
        5121 => bytes[0] as f64,
        5122 => i16::from_le_bytes([bytes[0], bytes[1]]) as f64,
        5123 => u16::from_le_bytes([bytes[0], bytes[1]]) as f64,
        5125 => u32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]) as f64,
        _ => f32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]) as f64,
    }
}

fn usize_of(v: Option<&Value>) -> Option<usize> {
    v.and_then(Value::as_u64).and_then(|x| usize::try_from(x).ok())
}

impl Writer<'_> {
    fn bad(&self, message: String) -> AtlasError {
        malformed(self.path, message)
    }

    /// The bytes of input buffer view `v` and its stride (`None` when absent).
    fn view_bytes(&self, v: usize) -> Result<(&[u8], Option<usize>), AtlasError> {
        let view = self.json["bufferViews"]
            .get(v)
            .filter(|v| v.is_object())
            .ok_or_else(|| self.bad(format!("buffer view {v} does not exist")))?;
        let buffer = usize_of(view.get("buffer"));
        let data = buffer.and_then(|b| self.buffers.get(b)).ok_or_else(|| {
            self.bad(format!(
                "buffer view {v} refers to buffer {:?}, which does not exist",
                view.get("buffer")
            ))
        })?;
        let offset = usize_of(view.get("byteOffset")).unwrap_or(0);
        let length = usize_of(view.get("byteLength")).unwrap_or(0);
        let bytes = offset.checked_add(length).and_then(|end| data.0.get(offset..end)).ok_or_else(|| {
            self.bad(format!(
                "buffer view {v} ({length} bytes at offset {offset}) does not fit its {}-byte buffer",
                data.0.len()
            ))
        })?;
        Ok((bytes, usize_of(view.get("byteStride"))))
    }

    /// Accessor `a` of the input, resolved (cached: primitives often share accessors).
    fn dense(&mut self, a: usize) -> Result<std::rc::Rc<Dense>, AtlasError> {
        if let Some(d) = self.dense.get(&a) {
            return Ok(d.clone());
        }
        let d = std::rc::Rc::new(self.resolve(a)?);
        self.dense.insert(a, d.clone());
        Ok(d)
    }

    fn resolve(&self, a: usize) -> Result<Dense, AtlasError> {
        let acc = self.json["accessors"]
            .get(a)
            .filter(|v| v.is_object())
            .ok_or_else(|| self.bad(format!("accessor {a} does not exist")))?;
        let what = |m: String| self.bad(format!("accessor {a}: {m}"));
        let component = acc.get("componentType").and_then(Value::as_u64).unwrap_or(0);
        let type_ = acc.get("type").and_then(Value::as_str).unwrap_or("").to_owned();
        let (_, elem) = layout(&type_, component)
            .ok_or_else(|| what(format!("unknown type {type_:?} or component type {component}")))?;
        let count = usize_of(acc.get("count")).ok_or_else(|| what("has no valid count".into()))?;
        let mut bytes = count
            .checked_mul(elem)
            .filter(|&n| n <= u32::MAX as usize)
            .map(|n| vec![0u8; n])
            .ok_or_else(|| what(format!("{count} elements are too many")))?;
        if let Some(v) = usize_of(acc.get("bufferView")) {
            let (view, stride) = self.view_bytes(v)?;
            let stride = stride.unwrap_or(elem);
            let offset = usize_of(acc.get("byteOffset")).unwrap_or(0);
            let fits = count == 0
                || (count - 1)
                    .checked_mul(stride)
                    .and_then(|x| x.checked_add(offset + elem))
                    .is_some_and(|end| end <= view.len() && stride >= elem);
            if !fits {
                return Err(what(format!(
                    "{count} elements of {elem} bytes (stride {stride}, offset {offset}) do not fit \
                     its {}-byte buffer view",
                    view.len()
                )));
            }
            for (i, out) in bytes.chunks_exact_mut(elem).enumerate() {
                let at = offset + i * stride;
                out.copy_from_slice(&view[at..at + elem]);
            }
        }
        if let Some(sparse) = acc.get("sparse") {
            let n = usize_of(sparse.get("count")).ok_or_else(|| what("sparse count is missing".into()))?;
            let part = |key: &str| -> Result<&[u8], AtlasError> {
                let p = sparse.get(key).ok_or_else(|| what(format!("sparse {key} are missing")))?;
                let v = usize_of(p.get("bufferView"))
                    .ok_or_else(|| what(format!("sparse {key} have no buffer view")))?;
                let (view, _) = self.view_bytes(v)?;
                let offset = usize_of(p.get("byteOffset")).unwrap_or(0);
                view.get(offset..).ok_or_else(|| what(format!("sparse {key} start beyond their buffer view")))
            };
            let idx_bytes = part("indices")?;
            let val_bytes = part("values")?;
            let ic = sparse["indices"].get("componentType").and_then(Value::as_u64).unwrap_or(0);
            let isz = match ic {
                5121 => 1,
                5123 => 2,
                5125 => 4,
                _ => {
                    return Err(what(format!("sparse index component type {ic} is not an unsigned integer")));
                }
            };
            if idx_bytes.len() < n * isz || val_bytes.len() < n * elem {
                return Err(what(format!("{n} sparse entries do not fit their buffer views")));
            }
            for k in 0..n {
                let i = read_component(&idx_bytes[k * isz..], ic) as usize;
                if i >= count {
                    return Err(what(format!("sparse index {i} is out of range for {count} elements")));
                }
                bytes[i * elem..(i + 1) * elem].copy_from_slice(&val_bytes[k * elem..(k + 1) * elem]);
            }
        }
        Ok(Dense { component, type_, elem, count, bytes })
    }

    /// Adds a new buffer view holding `bytes` and returns its (final-numbering-space) index.
    fn push_view(&mut self, bytes: Vec<u8>, target: u64, stride: Option<usize>) -> usize {
        let mut view: Value =
            [("byteLength", Value::from(bytes.len())), ("target", Value::from(target))].into_iter().collect();
        if let Some(s) = stride {
            view["byteStride"] = s.into();
        }
        self.new_views.push((view, bytes));
        self.old_views + self.new_views.len() - 1
    }

    fn push_accessor(&mut self, acc: Value) -> usize {
        self.new_accessors.push(acc);
        self.old_accessors + self.new_accessors.len() - 1
    }

    /// A new vertex accessor with the elements `vertices` of input accessor `a`: same type,
    /// component type, `normalized`, name, extras and extensions; `min`/`max` recomputed when the
    /// input had them or `bounds` is set.
    fn gather(&mut self, a: usize, vertices: &[u32], bounds: bool, what: &str) -> Result<usize, AtlasError> {
        let d = self.dense(a)?;
        if let Some(&v) = vertices.iter().find(|&&v| v as usize >= d.count) {
            return Err(self.bad(format!(
                "{what}: accessor {a} has {} elements but the primitive uses vertex {v}",
                d.count
            )));
        }
        // Vertex attribute elements start on 4-byte boundaries (glTF 2.0, "Data Alignment").
        let stride = d.elem.next_multiple_of(4);
        let mut bytes = vec![0u8; vertices.len() * stride];
        for (out, &v) in bytes.chunks_exact_mut(stride).zip(vertices) {
            let v = v as usize;
            out[..d.elem].copy_from_slice(&d.bytes[v * d.elem..(v + 1) * d.elem]);
        }
        let mut acc = self.json["accessors"][a].clone();
        let had_bounds = acc.get("min").is_some() || acc.get("max").is_some();
        let obj = acc.as_object_mut().expect("resolved accessors are objects");
        for key in ["bufferView", "byteOffset", "sparse", "min", "max"] {
            obj.remove(key);
        }
        if had_bounds || bounds {
            let (offsets, _) = layout(&d.type_, d.component).expect("resolved accessors have a layout");
            let mut lo = vec![f64::INFINITY; offsets.len()];
            let mut hi = vec![f64::NEG_INFINITY; offsets.len()];
            for e in bytes.chunks_exact(stride) {
                for (k, &o) in offsets.iter().enumerate() {
                    let x = read_component(&e[o..], d.component);
                    lo[k] = lo[k].min(x);
                    hi[k] = hi[k].max(x);
                }
            }
            let number = |x: f64| if d.component == F32 { Value::from(x) } else { Value::from(x as i64) };
            obj.insert("min".into(), lo.into_iter().map(number).collect());
            obj.insert("max".into(), hi.into_iter().map(number).collect());
        }
        obj.insert("count".into(), vertices.len().into());
        let view = self.push_view(bytes, ARRAY_BUFFER, (stride != d.elem).then_some(stride));
        acc["bufferView"] = view.into();
        Ok(self.push_accessor(acc))
    }

    fn push_texcoords(&mut self, uvs: &[[f32; 2]]) -> usize {
        let bytes: Vec<u8> = uvs.iter().flatten().flat_map(|x| x.to_le_bytes()).collect();
        let view = self.push_view(bytes, ARRAY_BUFFER, None);
        self.push_accessor(
            [
                ("bufferView", Value::from(view)),
                ("componentType", F32.into()),
                ("count", uvs.len().into()),
                ("type", "VEC2".into()),
            ]
            .into_iter()
            .collect(),
        )
    }

    fn push_indices(&mut self, indices: &[u32], vertices: usize) -> usize {
        // 65 535 is the primitive-restart value of u16 indices, which glTF forbids.
        let (component, bytes): (u64, Vec<u8>) = if vertices <= 65_535 {
            (5123, indices.iter().flat_map(|&i| (i as u16).to_le_bytes()).collect())
        } else {
            (5125, indices.iter().flat_map(|&i| i.to_le_bytes()).collect())
        };
        let view = self.push_view(bytes, ELEMENT_ARRAY_BUFFER, None);
        self.push_accessor(
            [
                ("bufferView", Value::from(view)),
                ("componentType", component.into()),
                ("count", indices.len().into()),
                ("type", "SCALAR".into()),
            ]
            .into_iter()
            .collect(),
        )
    }

    /// Gives the rewritten primitives with triangles (`primitives`) the baked base colour `png`
    /// (module docs): an embedded image, a texture, and per material used a copy showing it.
    fn use_base_colour(&mut self, png: &[u8], primitives: &[GltfPrimitiveFaces]) {
        let view = self.old_views + self.new_views.len();
        self.new_views.push(([("byteLength", Value::from(png.len()))].into_iter().collect(), png.to_vec()));
        fn push(json: &mut Value, key: &str, item: Value) -> usize {
            let list = &mut json[key];
            if !list.is_array() {
                *list = Value::Array(Vec::new());
            }
            let list = list.as_array_mut().expect("made an array");
            list.push(item);
            list.len() - 1
        }
        let image = push(
            &mut self.json,
            "images",
            [
                ("bufferView", Value::from(view)),
                ("mimeType", "image/png".into()),
                ("name", "nuvo baked colour".into()),
            ]
            .into_iter()
            .collect(),
        );
        // Linear, mip-mapped, clamped: the bake fills the gutters, so every level reads surface colour.
        let sampler = push(
            &mut self.json,
            "samplers",
            [("magFilter", 9729u64), ("minFilter", 9987), ("wrapS", 33071), ("wrapT", 33071)]
                .into_iter()
                .map(|(k, v)| (k, Value::from(v)))
                .collect(),
        );
        let texture = push(
            &mut self.json,
            "textures",
            [("sampler", sampler), ("source", image)].into_iter().map(|(k, v)| (k, Value::from(v))).collect(),
        );
        let mut copies: HashMap<Option<u64>, usize> = HashMap::new();
        for prim in primitives.iter().filter(|p| !p.faces.is_empty()) {
            let json_prim = &self.json["meshes"][prim.mesh]["primitives"][prim.primitive];
            let original = json_prim.get("material").and_then(Value::as_u64);
            let copy = match copies.get(&original) {
                Some(&c) => c,
                None => {
                    let mut m = original
                        .and_then(|m| self.json["materials"].get(m as usize))
                        .filter(|m| m.is_object())
                        .cloned()
                        .unwrap_or_else(|| Value::Object(Default::default()));
                    let name = m.get("name").and_then(Value::as_str).unwrap_or("material").to_owned();
                    m["name"] = format!("{name} (nuvo)").into();
                    let pbr = &mut m["pbrMetallicRoughness"];
                    if !pbr.is_object() {
                        *pbr = Value::Object(Default::default());
                    }
                    let alpha = pbr
                        .get("baseColorFactor")
                        .and_then(|f| f.get(3))
                        .and_then(Value::as_f64)
                        .unwrap_or(1.0);
                    pbr["baseColorFactor"] = Value::from(vec![1.0, 1.0, 1.0, alpha]);
                    pbr["baseColorTexture"] = [("index", Value::from(texture))].into_iter().collect();
                    let c = push(&mut self.json, "materials", m);
                    copies.insert(original, c);
                    c
                }
            };
            let out = &mut self.json["meshes"][prim.mesh]["primitives"][prim.primitive];
            out["material"] = copy.into();
            if let Some(attributes) = out.get_mut("attributes").and_then(Value::as_object_mut)
                && let Some(colour) = attributes.remove("COLOR_0")
            {
                attributes.insert("_NUVO_BAKED_COLOR_0".into(), colour);
            }
        }
    }

    /// Rewrites one primitive (module docs) and returns, per output vertex, its input vertex.
    fn rewrite_primitive(
        &mut self,
        prim: &GltfPrimitiveFaces,
        mesh: &TriMesh,
        uv: &UvLayer,
    ) -> Result<Vec<u32>, AtlasError> {
        let what = format!("mesh {} primitive {}", prim.mesh, prim.primitive);
        let json_prim = self.json["meshes"][prim.mesh]["primitives"][prim.primitive].clone();
        let attributes = json_prim
            .get("attributes")
            .and_then(Value::as_object)
            .ok_or_else(|| self.bad(format!("{what} has no attributes")))?
            .clone();
        let mut out = json_prim.clone();
        if prim.faces.is_empty() {
            // No triangle: keep the data, give load_gltf a TEXCOORD_0 to find.
            let n = prim.vertices.len();
            let tex = self.push_texcoords(&vec![[0.0, 0.0]; n]);
            out["attributes"]["TEXCOORD_0"] = tex.into();
            self.json["meshes"][prim.mesh]["primitives"][prim.primitive] = out;
            return Ok((0..n as u32).collect());
        }

        // Split vertices: one per distinct (input vertex, UV), in first-use order.
        let mut ids: HashMap<(u32, [u32; 2]), u32> = HashMap::new();
        let mut sources = Vec::new();
        let mut uvs = Vec::new();
        let mut indices = Vec::with_capacity(prim.faces.len() * 3);
        for f in prim.faces.clone() {
            let local = prim.local_triangle(mesh, f);
            for (k, &v) in local.iter().enumerate() {
                let [u, w] = uv.coords[uv.triangles[f][prim.merged_corner(k)] as usize];
                let id = *ids.entry((v, [u, w].map(f32::to_bits))).or_insert_with(|| {
                    sources.push(v);
                    uvs.push([u, 1.0 - w]);
                    sources.len() as u32 - 1
                });
                indices.push(id);
            }
        }

        let mut new_attributes = gltf::json::Value::Object(Default::default());
        for (name, acc) in &attributes {
            if name == "TEXCOORD_0" {
                continue;
            }
            let a = usize_of(Some(acc)).ok_or_else(|| self.bad(format!("{what}: attribute {name}")))?;
            new_attributes[name.as_str()] =
                self.gather(a, &sources, name == "POSITION", &format!("{what} attribute {name}"))?.into();
        }
        new_attributes["TEXCOORD_0"] = self.push_texcoords(&uvs).into();
        out["attributes"] = new_attributes;

        if let Some(targets) = json_prim.get("targets").and_then(Value::as_array) {
            let mut new_targets = Vec::with_capacity(targets.len());
            for (t, target) in targets.iter().enumerate() {
                let target = target
                    .as_object()
                    .ok_or_else(|| self.bad(format!("{what}: morph target {t} is not an object")))?;
                let mut new_target = gltf::json::Value::Object(Default::default());
                for (name, acc) in target {
                    if name == "TEXCOORD_0" {
                        continue;
                    }
                    let a = usize_of(Some(acc))
                        .ok_or_else(|| self.bad(format!("{what}: morph target {t} attribute {name}")))?;
                    let label = format!("{what} morph target {t} attribute {name}");
                    new_target[name.as_str()] = self.gather(a, &sources, name == "POSITION", &label)?.into();
                }
                if new_target.as_object().is_some_and(|o| o.is_empty()) {
                    new_target["TEXCOORD_0"] = self.push_texcoords(&vec![[0.0, 0.0]; sources.len()]).into();
                }
                new_targets.push(new_target);
            }
            out["targets"] = Value::Array(new_targets);
        }
        out["indices"] = self.push_indices(&indices, sources.len()).into();
        if out.get("mode").is_some() {
            out["mode"] = 4.into();
        }
        self.json["meshes"][prim.mesh]["primitives"][prim.primitive] = out;
        Ok(sources)
    }

    /// Drops what is no longer referenced, renumbers, and packs every kept view into one buffer.
    fn finish(mut self) -> Result<(Value, Vec<u8>), AtlasError> {
        // Accessors: old and new, keep the referenced ones.
        let mut accessors: Vec<Value> = match self.json.get_mut("accessors").map(Value::take) {
            Some(Value::Array(a)) => a,
            _ => Vec::new(),
        };
        accessors.append(&mut self.new_accessors);
        let mut used = BTreeSet::new();
        for_each_accessor_ref(&mut self.json, &mut |r| {
            used.insert(r.as_u64().unwrap_or(u64::MAX));
        });
        let map = renumber(&used, accessors.len());
        for_each_accessor_ref(&mut self.json, &mut |r| {
            *r = r.as_u64().and_then(|i| map.get(&i)).map_or(Value::Null, |&i| i.into());
        });
        if let Some(missing) = used.iter().find(|&&i| !map.contains_key(&i)) {
            return Err(self.bad(format!("a reference to accessor {missing}, which does not exist")));
        }
        let accessors: Vec<Value> = accessors
            .into_iter()
            .enumerate()
            .filter(|(i, _)| used.contains(&(*i as u64)))
            .map(|(_, a)| a)
            .collect();
        self.json["accessors"] = Value::Array(accessors);

        // Buffer views: referenced by kept accessors (and their sparse parts) and by images.
        // (The input views stay in the JSON until the end: `view_bytes` reads them.)
        let old_views = self.json.get("bufferViews").and_then(Value::as_array).cloned().unwrap_or_default();
        let mut views: Vec<(Value, ViewData)> =
            old_views.into_iter().enumerate().map(|(i, v)| (v, ViewData::Old(i))).collect();
        views.extend(std::mem::take(&mut self.new_views).into_iter().map(|(v, b)| (v, ViewData::New(b))));
        let mut used = BTreeSet::new();
        for_each_view_ref(&mut self.json, &mut |r| {
            used.insert(r.as_u64().unwrap_or(u64::MAX));
        });
        let map = renumber(&used, views.len());
        if let Some(missing) = used.iter().find(|&&i| !map.contains_key(&i)) {
            return Err(self.bad(format!("a reference to buffer view {missing}, which does not exist")));
        }
        for_each_view_ref(&mut self.json, &mut |r| {
            *r = r.as_u64().and_then(|i| map.get(&i)).map_or(Value::Null, |&i| i.into());
        });
        let mut bin = Vec::new();
        let mut kept = Vec::new();
        for (i, (mut view, data)) in views.into_iter().enumerate() {
            if !used.contains(&(i as u64)) {
                continue;
            }
            let bytes = match &data {
                ViewData::Old(v) => self.view_bytes(*v)?.0,
                ViewData::New(b) => &b[..],
            };
            bin.resize(bin.len().next_multiple_of(4), 0);
            view["buffer"] = 0.into();
            view["byteOffset"] = bin.len().into();
            view["byteLength"] = bytes.len().into();
            bin.extend_from_slice(bytes);
            kept.push(view);
        }
        self.json["bufferViews"] = Value::Array(kept);

        // One buffer: the GLB's binary chunk (keeping the first buffer's name, extras, extensions).
        let mut buffer = match self.json.get("buffers").and_then(|b| b.get(0)) {
            Some(Value::Object(b)) => Value::Object(b.clone()),
            _ => Value::Object(Default::default()),
        };
        if let Some(b) = buffer.as_object_mut() {
            b.remove("uri");
        }
        buffer["byteLength"] = bin.len().into();
        self.json["buffers"] = Value::Array(vec![buffer]);
        for key in ["accessors", "bufferViews"] {
            if self.json[key].as_array().is_some_and(Vec::is_empty) {
                self.json.as_object_mut().expect("checked object").remove(key);
            }
        }
        Ok((self.json, bin))
    }
}

/// Old index → new index of the `used` indices below `len`, in order.
fn renumber(used: &BTreeSet<u64>, len: usize) -> HashMap<u64, usize> {
    used.iter().filter(|&&i| i < len as u64).enumerate().map(|(new, &old)| (old, new)).collect()
}

/// Calls `f` on every JSON value that is an accessor index.
fn for_each_accessor_ref(json: &mut Value, f: &mut dyn FnMut(&mut Value)) {
    let each = |v: Option<&mut Value>, f: &mut dyn FnMut(&mut Value)| {
        if let Some(v) = v {
            f(v);
        }
    };
    for mesh in array_mut(json, "meshes") {
        for prim in array_mut(mesh, "primitives") {
            each(prim.get_mut("indices"), f);
            if let Some(Value::Object(attributes)) = prim.get_mut("attributes") {
                attributes.values_mut().for_each(&mut *f);
            }
            for target in array_mut(prim, "targets") {
                if let Value::Object(t) = target {
                    t.values_mut().for_each(&mut *f);
                }
            }
        }
    }
    for skin in array_mut(json, "skins") {
        each(skin.get_mut("inverseBindMatrices"), f);
    }
    for animation in array_mut(json, "animations") {
        for sampler in array_mut(animation, "samplers") {
            each(sampler.get_mut("input"), f);
            each(sampler.get_mut("output"), f);
        }
    }
    for node in array_mut(json, "nodes") {
        let attributes = node
            .get_mut("extensions")
            .and_then(|e| e.get_mut("EXT_mesh_gpu_instancing"))
            .and_then(|e| e.get_mut("attributes"));
        if let Some(Value::Object(attributes)) = attributes {
            attributes.values_mut().for_each(&mut *f);
        }
    }
}

/// Calls `f` on every JSON value that is a buffer view index.
fn for_each_view_ref(json: &mut Value, f: &mut dyn FnMut(&mut Value)) {
    for acc in array_mut(json, "accessors") {
        if let Some(v) = acc.get_mut("bufferView") {
            f(v);
        }
        if let Some(sparse) = acc.get_mut("sparse") {
            for key in ["indices", "values"] {
                if let Some(v) = sparse.get_mut(key).and_then(|p| p.get_mut("bufferView")) {
                    f(v);
                }
            }
        }
    }
    for image in array_mut(json, "images") {
        if let Some(v) = image.get_mut("bufferView") {
            f(v);
        }
    }
}

fn array_mut<'v>(json: &'v mut Value, key: &str) -> impl Iterator<Item = &'v mut Value> {
    json.get_mut(key).and_then(Value::as_array_mut).into_iter().flatten()
}

/// The GLB bytes of `json` with binary chunk `bin`.
fn glb(output: &Path, json: &Value, bin: Vec<u8>) -> Result<Vec<u8>, AtlasError> {
    let encode = |message: String| AtlasError::Encode { path: output.to_path_buf(), message };
    let json_bytes = gltf::json::serialize::to_vec(json).map_err(|e| encode(e.to_string()))?;
    let total = 12 + 8 + json_bytes.len().next_multiple_of(4) + 8 + bin.len().next_multiple_of(4);
    let length = u32::try_from(total)
        .map_err(|_| encode(format!("{total} bytes exceed the 4 GiB limit of binary glTF")))?;
    let glb = gltf::binary::Glb {
        header: gltf::binary::Header { magic: *b"glTF", version: 2, length },
        json: json_bytes.into(),
        bin: Some(bin.into()),
    };
    glb.to_vec().map_err(|e| encode(e.to_string()))
}
