//! glTF 2.0 / GLB reading (via the `gltf` crate): every triangle primitive of every mesh instance in
//! the scene, with node transforms applied, merged into one [`TriMesh`].
//!
//! Accessors are checked before they are read (element type, component type, stride, sparse
//! storage), because the `gltf` crate's readers trust the file and can panic on inconsistent strides.

use std::path::Path;

use gltf::accessor::{DataType, Dimensions};
use gltf::mesh::Mode;

use crate::error::GeometryError;
use crate::mesh::{TriMesh, UvLayer};

type Mat4 = [[f32; 4]; 4];

/// What one primitive contributed, before merging.
struct Part {
    positions: Vec<[f32; 3]>,
    triangles: Vec<[u32; 3]>,
    uvs: Option<Vec<[f32; 2]>>,
}

/// Names the external buffer files of `document` that cannot be read, as ` (unreadable: a.bin)`,
/// since the glTF crate's error says only what the OS said.
fn unreadable_buffers(document: &gltf::Document, base: &Path) -> String {
    let missing: Vec<String> = document
        .buffers()
        .filter_map(|b| match b.source() {
            gltf::buffer::Source::Uri(uri) if !uri.starts_with("data:") && !base.join(uri).is_file() => {
                Some(uri.to_owned())
            }
            _ => None,
        })
        .collect();
    if missing.is_empty() { String::new() } else { format!(" (unreadable: {})", missing.join(", ")) }
}

/// Reads a `.gltf` (with external or embedded buffers) or `.glb` file.
///
/// - Meshes are instanced through the node hierarchy of the default scene (the first scene when none
///   is marked default; every root node when there are no scenes; every mesh untransformed when there
///   are no nodes). Node transforms are applied; a mirroring transform flips the triangle winding so
///   triangles stay counter-clockwise seen from outside.
/// - Triangle lists, strips and fans are read; point and line primitives are skipped.
/// - `TEXCOORD_0` becomes the [`UvLayer`] (with `v` flipped to the OBJ convention) when *every*
///   triangle primitive has it; otherwise the mesh has no UVs.
/// - Images are never decoded.
pub fn load_gltf(path: &Path) -> Result<TriMesh, GeometryError> {
    load_gltf_scene(path).map(|scene| scene.mesh)
}

/// What [`load_gltf`] read, with the parsed file and where each face of the merged mesh came from,
/// for writers that put data back into the user's own scene.
pub struct GltfScene {
    /// The merged mesh, exactly as [`load_gltf`] returns it.
    pub mesh: TriMesh,
    /// The triangle primitives that make up `mesh`, in merge order: their face and vertex ranges
    /// tile `mesh.triangles` and `mesh.positions` from the start without gaps.
    pub primitives: Vec<GltfPrimitiveFaces>,
    /// The validated document.
    pub document: gltf::Document,
    /// The data of every buffer of `document`, by buffer index.
    pub buffers: Vec<gltf::buffer::Data>,
}

/// Which primitive of which mesh instance a contiguous range of the merged mesh came from.
///
/// Merged vertex `vertices.start + i` is vertex `i` of the primitive (its `POSITION` element `i`,
/// transformed): every element of the primitive's attributes is kept, used or not. Merged face
/// `faces.start + j` is triangle `j` of the primitive as the glTF spec assembles it (lists: indices
/// `3j..3j+3`, trailing indices dropped; strips: `[j, j+1, j+2]`, with the first two swapped for odd
/// `j`; fans: `[0, j+1, j+2]`), with its last two corners swapped when `mirrored`;
/// [`GltfPrimitiveFaces::local_triangle`] undoes the offset and the swap.
#[derive(Clone, Debug, PartialEq)]
pub struct GltfPrimitiveFaces {
    /// Index of the mesh instance in [`gltf_mesh_instances`]' order.
    pub instance: usize,
    /// The node that instances the mesh (`None` for files without nodes).
    pub node: Option<usize>,
    /// The mesh index in the document.
    pub mesh: usize,
    /// The primitive index within the mesh.
    pub primitive: usize,
    /// The primitive's mode (`Triangles`, `TriangleStrip` or `TriangleFan`).
    pub mode: Mode,
    /// The instance's world transform mirrors (negative determinant), so corners 1 and 2 of each
    /// face were swapped.
    pub mirrored: bool,
    /// The faces of the merged mesh this primitive produced.
    pub faces: std::ops::Range<usize>,
    /// The vertices of the merged mesh this primitive produced (its whole `POSITION` accessor).
    pub vertices: std::ops::Range<usize>,
}

impl GltfPrimitiveFaces {
    /// Merged face `f` (in `self.faces`) as primitive-local vertex indices in the winding the file
    /// itself assembles, i.e. with the mirror swap undone. Corner `k` of the result is corner
    /// [`GltfPrimitiveFaces::merged_corner`]`(k)` of the merged face.
    pub fn local_triangle(&self, mesh: &TriMesh, f: usize) -> [u32; 3] {
        let base = self.vertices.start as u32;
        let t = mesh.triangles[f];
        [0, 1, 2].map(|k| t[self.merged_corner(k)] - base)
    }

    /// Which corner of the merged face holds corner `k` of the file's triangle (`k` itself, or the
    /// last two exchanged when `mirrored`).
    pub fn merged_corner(&self, k: usize) -> usize {
        if self.mirrored && k > 0 { 3 - k } else { k }
    }
}

/// One instance of a mesh in the scene, in the order [`load_gltf`] merges them.
#[derive(Clone, Debug, PartialEq)]
pub struct GltfMeshInstance {
    /// The node that instances the mesh (`None` for files without nodes, where every mesh is
    /// taken once, untransformed).
    pub node: Option<usize>,
    /// The mesh index in the document.
    pub mesh: usize,
    /// The world transform (column-major, `matrix[column][row]`).
    pub matrix: [[f32; 4]; 4],
}

impl GltfMeshInstance {
    /// The transform mirrors (negative determinant), so [`load_gltf`] swaps each face's winding.
    pub fn mirrored(&self) -> bool {
        det3(&self.matrix) < 0.0
    }
}

/// Parses and validates a `.gltf` or `.glb` file the way [`load_gltf`] does, without loading its
/// buffers or reading any geometry. Returns the document and the GLB binary chunk, if any.
pub fn read_gltf_document(path: &Path) -> Result<(gltf::Document, Option<Vec<u8>>), GeometryError> {
    let bad = |m: String| GeometryError::malformed(path, m);
    let bytes = std::fs::read(path).map_err(|e| GeometryError::Io { path: path.to_path_buf(), source: e })?;
    let not_gltf = |e: gltf::Error| bad(format!("not a valid glTF/GLB file: {e}"));
    // Parse, check what the crate's validator itself indexes unchecked, then validate.
    let unchecked = gltf::Gltf::from_slice_without_validation(&bytes).map_err(not_gltf)?;
    check_position_accessors(unchecked.document.as_json()).map_err(bad)?;
    let document = gltf::Document::from_json(unchecked.document.into_json()).map_err(not_gltf)?;
    Ok((document, unchecked.blob))
}

/// Every mesh instance of `document`'s scene, in [`load_gltf`]'s order (its docs say which
/// scene and nodes). Errors (a cycle in the node hierarchy) are sentences without the file name.
pub fn gltf_mesh_instances(document: &gltf::Document) -> Result<Vec<GltfMeshInstance>, String> {
    Ok(mesh_instances(document)?
        .into_iter()
        .map(|(node, mesh, matrix)| GltfMeshInstance { node, mesh: mesh.index(), matrix })
        .collect())
}

/// [`load_gltf`] with the parsed file and the origin of every face: see [`GltfScene`]. Fails
/// exactly where [`load_gltf`] fails, with the same errors.
pub fn load_gltf_scene(path: &Path) -> Result<GltfScene, GeometryError> {
    let bad = |m: String| GeometryError::malformed(path, m);
    let (document, blob) = read_gltf_document(path)?;
    let base = path.parent().unwrap_or(Path::new("."));
    let buffers = gltf::import_buffers(&document, Some(base), blob).map_err(|e| {
        bad(format!("cannot load the glTF buffers: {e}{}", unreadable_buffers(&document, base)))
    })?;
    let mut parts = Vec::new();
    let mut primitives = Vec::new();
    let (mut faces, mut vertices) = (0, 0);
    for (instance, (node, mesh, matrix)) in mesh_instances(&document).map_err(bad)?.into_iter().enumerate() {
        for (p, prim) in mesh.primitives().enumerate() {
            let what = format!("mesh {} primitive {p}", mesh.index());
            if let Some(part) =
                read_primitive(&prim, &buffers, &matrix).map_err(|m| bad(format!("{what}: {m}")))?
            {
                let (nf, nv) = (part.triangles.len(), part.positions.len());
                primitives.push(GltfPrimitiveFaces {
                    instance,
                    node,
                    mesh: mesh.index(),
                    primitive: p,
                    mode: prim.mode(),
                    mirrored: det3(&matrix) < 0.0,
                    faces: faces..faces + nf,
                    vertices: vertices..vertices + nv,
                });
                (faces, vertices) = (faces + nf, vertices + nv);
                parts.push(part);
            }
        }
    }
    let mesh = merge(parts);
    if mesh.triangles.is_empty() {
        return Err(GeometryError::invalid(path, "the file has no triangle primitives"));
    }
    mesh.validate().map_err(|m| GeometryError::invalid(path, m))?;
    Ok(GltfScene { mesh, primitives, document, buffers })
}

/// gltf-json's validator looks up each primitive's POSITION accessor without a bounds check (and
/// panics on a bad index), so that one index is checked before validation.
fn check_position_accessors(root: &gltf::json::Root) -> Result<(), String> {
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, prim) in mesh.primitives.iter().enumerate() {
            let key = gltf::json::validation::Checked::Valid(gltf::Semantic::Positions);
            if let Some(idx) = prim.attributes.get(&key)
                && idx.value() >= root.accessors.len()
            {
                return Err(format!(
                    "mesh {m} primitive {p}: POSITION refers to accessor {} but there are only {}",
                    idx.value(),
                    root.accessors.len()
                ));
            }
        }
    }
    Ok(())
}

/// A mesh instance: (node, mesh, world matrix).
type Instance<'a> = (Option<usize>, gltf::Mesh<'a>, Mat4);

/// Every mesh instance to read, following the scene graph.
fn mesh_instances(doc: &gltf::Document) -> Result<Vec<Instance<'_>>, String> {
    let roots: Vec<gltf::Node> = match doc.default_scene().or_else(|| doc.scenes().next()) {
        Some(scene) => scene.nodes().collect(),
        None if doc.nodes().len() > 0 => {
            let mut is_child = vec![false; doc.nodes().len()];
            for n in doc.nodes() {
                for c in n.children() {
                    if let Some(f) = is_child.get_mut(c.index()) {
                        *f = true;
                    }
                }
            }
            doc.nodes().filter(|n| !is_child.get(n.index()).copied().unwrap_or(true)).collect()
        }
        None => return Ok(doc.meshes().map(|m| (None, m, IDENTITY)).collect()),
    };
    let mut out = Vec::new();
    // Depth-first walk with an explicit stack; a node graph deeper than the node count has a cycle.
    let max_depth = doc.nodes().len();
    // Pushed in reverse so instances come out in document order.
    let mut stack: Vec<(gltf::Node, Mat4, usize)> =
        roots.into_iter().rev().map(|n| (n, IDENTITY, 0)).collect();
    while let Some((node, parent, depth)) = stack.pop() {
        if depth > max_depth {
            return Err("the node hierarchy contains a cycle".into());
        }
        let world = mat_mul(&parent, &node.transform().matrix());
        if let Some(mesh) = node.mesh() {
            out.push((Some(node.index()), mesh, world));
        }
        let children: Vec<gltf::Node> = node.children().collect();
        stack.extend(children.into_iter().rev().map(|c| (c, world, depth + 1)));
    }
    Ok(out)
}

const IDENTITY: Mat4 =
    [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]];

/// Product of two column-major matrices (`m[column][row]`, glTF's layout).
fn mat_mul(a: &Mat4, b: &Mat4) -> Mat4 {
    std::array::from_fn(|c| std::array::from_fn(|r| (0..4).map(|k| a[k][r] * b[c][k]).sum()))
}

fn transform_point(m: &Mat4, p: [f32; 3]) -> [f32; 3] {
    std::array::from_fn(|r| m[0][r] * p[0] + m[1][r] * p[1] + m[2][r] * p[2] + m[3][r])
}

fn det3(m: &Mat4) -> f32 {
    m[0][0] * (m[1][1] * m[2][2] - m[2][1] * m[1][2]) - m[1][0] * (m[0][1] * m[2][2] - m[2][1] * m[0][2])
        + m[2][0] * (m[0][1] * m[1][2] - m[1][1] * m[0][2])
}

/// Checks that `acc` can be read as `dims` with one of `types` without trusting the file.
pub(crate) fn check_accessor(
    acc: &gltf::Accessor,
    what: &str,
    dims: Dimensions,
    types: &[DataType],
) -> Result<(), String> {
    if acc.dimensions() != dims || !types.contains(&acc.data_type()) {
        return Err(format!(
            "{what} accessor {} is {:?} {:?}; expected {dims:?} of {types:?}",
            acc.index(),
            acc.dimensions(),
            acc.data_type()
        ));
    }
    if acc.sparse().is_some() {
        return Err(format!("{what} accessor {} is sparse, which is not supported", acc.index()));
    }
    let Some(view) = acc.view() else {
        return Err(format!("{what} accessor {} has no buffer view", acc.index()));
    };
    let stride = view.stride().unwrap_or(acc.size());
    if stride < acc.size() {
        return Err(format!(
            "{what} accessor {}: byte stride {stride} is smaller than its element size {}",
            acc.index(),
            acc.size()
        ));
    }
    let needed = acc
        .count()
        .checked_sub(1)
        .and_then(|c| c.checked_mul(stride))
        .and_then(|b| b.checked_add(acc.offset() + acc.size()));
    match needed {
        Some(n) if n <= view.length() => Ok(()),
        _ => Err(format!(
            "{what} accessor {}: {} elements of {} bytes do not fit its {}-byte buffer view",
            acc.index(),
            acc.count(),
            acc.size(),
            view.length()
        )),
    }
}

/// Reads one primitive in world coordinates; `None` for non-triangle primitives.
fn read_primitive(
    prim: &gltf::Primitive,
    buffers: &[gltf::buffer::Data],
    matrix: &Mat4,
) -> Result<Option<Part>, String> {
    let mode = prim.mode();
    if !matches!(mode, Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan) {
        return Ok(None);
    }
    let reader = prim.reader(|b| buffers.get(b.index()).map(|d| &d.0[..]));
    let pos_acc = prim.get(&gltf::Semantic::Positions).ok_or("has no POSITION attribute")?;
    check_accessor(&pos_acc, "POSITION", Dimensions::Vec3, &[DataType::F32])?;
    let positions: Vec<[f32; 3]> = reader.read_positions().ok_or("POSITION data is missing")?.collect();
    if positions.len() != pos_acc.count() {
        return Err(format!(
            "POSITION accessor claims {} vertices but its buffer holds {}",
            pos_acc.count(),
            positions.len()
        ));
    }
    let positions: Vec<[f32; 3]> = positions.into_iter().map(|p| transform_point(matrix, p)).collect();
    let indices: Vec<u32> = match prim.indices() {
        Some(acc) => {
            check_accessor(&acc, "index", Dimensions::Scalar, &[DataType::U8, DataType::U16, DataType::U32])?;
            let idx: Vec<u32> = reader.read_indices().ok_or("index data is missing")?.into_u32().collect();
            if idx.len() != acc.count() {
                return Err(format!(
                    "index accessor claims {} indices but its buffer holds {}",
                    acc.count(),
                    idx.len()
                ));
            }
            idx
        }
        None => (0..positions.len() as u32).collect(),
    };
    if let Some(&bad) = indices.iter().find(|&&i| i as usize >= positions.len()) {
        return Err(format!("index {bad} is out of range for {} vertices", positions.len()));
    }
    let mut triangles = assemble(mode, &indices);
    if det3(matrix) < 0.0 {
        for t in &mut triangles {
            t.swap(1, 2);
        }
    }
    let uvs = match prim.get(&gltf::Semantic::TexCoords(0)) {
        Some(acc) => {
            check_accessor(
                &acc,
                "TEXCOORD_0",
                Dimensions::Vec2,
                &[DataType::F32, DataType::U8, DataType::U16],
            )?;
            let uv: Vec<[f32; 2]> = reader
                .read_tex_coords(0)
                .ok_or("TEXCOORD_0 data is missing")?
                .into_f32()
                .map(|[u, v]| [u, 1.0 - v])
                .collect();
            if uv.len() != positions.len() {
                return Err(format!(
                    "TEXCOORD_0 has {} entries but there are {} vertices",
                    uv.len(),
                    positions.len()
                ));
            }
            Some(uv)
        }
        None => None,
    };
    Ok(Some(Part { positions, triangles, uvs }))
}

/// Triangles from a list, strip or fan of vertex indices (strip winding alternates as the spec says).
fn assemble(mode: Mode, idx: &[u32]) -> Vec<[u32; 3]> {
    match mode {
        Mode::TriangleStrip => {
            (2..idx.len())
                .map(|i| {
                    if i % 2 == 0 {
                        [idx[i - 2], idx[i - 1], idx[i]]
                    } else {
                        [idx[i - 1], idx[i - 2], idx[i]]
                    }
                })
                .collect()
        }
        Mode::TriangleFan => (2..idx.len()).map(|i| [idx[0], idx[i - 1], idx[i]]).collect(),
        _ => idx.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
    }
}

/// Concatenates parts; UVs survive only when every part has them.
fn merge(parts: Vec<Part>) -> TriMesh {
    let all_uv = !parts.is_empty() && parts.iter().all(|p| p.uvs.is_some());
    let mut mesh = TriMesh::default();
    let mut uv = UvLayer::default();
    for part in parts {
        let base = mesh.positions.len() as u32;
        mesh.triangles.extend(part.triangles.iter().map(|t| t.map(|i| i + base)));
        mesh.positions.extend(part.positions);
        if let (true, Some(coords)) = (all_uv, part.uvs) {
            uv.triangles.extend(part.triangles.iter().map(|t| t.map(|i| i + base)));
            uv.coords.extend(coords);
        }
    }
    if all_uv {
        mesh.uv = Some(uv);
    }
    mesh
}
