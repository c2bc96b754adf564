//! Writing UV'd meshes for other tools: Wavefront OBJ + MTL, and binary glTF 2.0 (`.glb`).
//!
//! **Frames.** Meshes inside Nuvo live in the canonical frame; writers take the `Similarity` that
//! mapped the input into it (`frame`, as reported by the geometry source) and write
//! `frame.invert(p)`, so outputs line up with the user's original file. Pass
//! [`Similarity::IDENTITY`] for a mesh already in its own coordinates.
//!
//! **UV conventions.** OBJ stores `vt u v` with `v` up, like [`UvLayer`]. glTF puts the texture
//! origin at the top-left, so `TEXCOORD_0 = (u, 1 − v)`; both files show the same texture the same
//! way.
//!
//! **Seams.** OBJ keeps per-corner UV indices (`f v/vt`). glTF has one attribute set per vertex, so
//! the GLB writer emits one vertex per distinct (position index, UV value) pair: vertices on a UV
//! seam are split, others shared. Normals (optional) are area-weighted per *position*, so a seam
//! does not crease the shading.
//!
//! All files are written atomically ([`nuvo_fsio::write_atomic`]).

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use gltf::json;
use json::validation::Checked::Valid;
use json::validation::USize64;
use nuvo_geometry::{Similarity, TriMesh, UvLayer};

use crate::error::AtlasError;
use crate::error::write_atomic;

/// Name of the single material of exported meshes.
pub const MATERIAL_NAME: &str = "nuvo_atlas";

/// Writes `mesh` as OBJ at `path` and its material as `path` with extension `.mtl` beside it. The
/// material's diffuse map (`map_Kd`) is `texture` when given: written relative to the OBJ's folder
/// when it is in that folder, else as given. Errors: no UVs, or an I/O failure naming the file.
pub fn write_obj(
    path: &Path,
    mesh: &TriMesh,
    frame: &Similarity,
    texture: Option<&Path>,
) -> Result<(), AtlasError> {
    let uv = uv_of(mesh, path)?;
    let mtl_path = path.with_extension("mtl");
    let mtl_name = file_name(&mtl_path);
    let map = texture.map(|t| match (t.parent(), path.parent()) {
        (Some(a), Some(b)) if a == b => file_name(t),
        _ => t.display().to_string(),
    });
    write_atomic(&mtl_path, |w| {
        writeln!(
            w,
            "# written by nuvo-atlas\nnewmtl {MATERIAL_NAME}\nKa 1 1 1\nKd 1 1 1\nKs 0 0 0\nd 1\nillum 1"
        )?;
        if let Some(m) = &map {
            writeln!(w, "map_Kd {m}")?;
        }
        Ok(())
    })?;
    write_atomic(path, |w| {
        writeln!(
            w,
            "# written by nuvo-atlas: {} vertices, {} faces",
            mesh.positions.len(),
            mesh.triangles.len()
        )?;
        writeln!(w, "mtllib {mtl_name}\no nuvo")?;
        for &p in &mesh.positions {
            let [x, y, z] = frame.invert(p);
            writeln!(w, "v {x} {y} {z}")?;
        }
        for [u, v] in &uv.coords {
            writeln!(w, "vt {u} {v}")?;
        }
        writeln!(w, "usemtl {MATERIAL_NAME}")?;
        for (t, tu) in mesh.triangles.iter().zip(&uv.triangles) {
            let c = |k: usize| (t[k] as u64 + 1, tu[k] as u64 + 1);
            let [(a, ta), (b, tb), (d, td)] = [c(0), c(1), c(2)];
            writeln!(w, "f {a}/{ta} {b}/{tb} {d}/{td}")?;
        }
        Ok(())
    })
}

/// What goes into a GLB besides positions, UVs and indices.
#[derive(Clone, Copy, Debug, Default)]
pub struct GlbOptions<'a> {
    /// Write a `NORMAL` attribute (area-weighted vertex normals).
    pub normals: bool,
    /// PNG bytes embedded as the base-colour texture of the (double-sided) material.
    pub texture_png: Option<&'a [u8]>,
}

/// Writes `mesh` as binary glTF 2.0 at `path` (module docs for frames, UVs and seams).
pub fn write_glb(
    path: &Path,
    mesh: &TriMesh,
    frame: &Similarity,
    opts: &GlbOptions,
) -> Result<(), AtlasError> {
    let bytes = glb_bytes(mesh, frame, opts).map_err(|e| match e {
        AtlasError::NoUv { .. } => AtlasError::NoUv { what: path.display().to_string() },
        AtlasError::Encode { message, .. } => AtlasError::Encode { path: path.to_path_buf(), message },
        other => other,
    })?;
    write_atomic(path, |w| w.write_all(&bytes))
}

/// The bytes of the GLB [`write_glb`] writes.
pub fn glb_bytes(mesh: &TriMesh, frame: &Similarity, opts: &GlbOptions) -> Result<Vec<u8>, AtlasError> {
    let uv = uv_of(mesh, Path::new("mesh"))?;
    let split = split_seams(mesh, uv);
    let positions: Vec<[f32; 3]> =
        split.vertices.iter().map(|&(p, _)| frame.invert(mesh.positions[p as usize])).collect();
    let texcoords: Vec<[f32; 2]> = split.vertices.iter().map(|&(_, [u, v])| [u, 1.0 - v]).collect();
    let normals = opts.normals.then(|| {
        let per_position = mesh.vertex_normals_or([0.0, 0.0, 1.0]);
        split.vertices.iter().map(|&(p, _)| per_position[p as usize]).collect::<Vec<_>>()
    });

    let mut root = json::Root {
        asset: json::Asset { generator: Some("nuvo-atlas".into()), ..Default::default() },
        ..Default::default()
    };
    let mut bin = Vec::new();
    let (min, max) = bounds(&positions);
    let mut attributes = BTreeMap::new();
    let pos =
        push_accessor(&mut root, &mut bin, &positions, json::accessor::Type::Vec3, Some((min, max)), true);
    attributes.insert(Valid(json::mesh::Semantic::Positions), pos);
    if let Some(n) = &normals {
        let acc = push_accessor(&mut root, &mut bin, n, json::accessor::Type::Vec3, None, true);
        attributes.insert(Valid(json::mesh::Semantic::Normals), acc);
    }
    let tex = push_accessor(&mut root, &mut bin, &texcoords, json::accessor::Type::Vec2, None, true);
    attributes.insert(Valid(json::mesh::Semantic::TexCoords(0)), tex);
    let indices =
        push_accessor(&mut root, &mut bin, &split.triangles, json::accessor::Type::Scalar, None, false);
    let material = push_material(&mut root, &mut bin, opts.texture_png);
    let primitive = json::mesh::Primitive {
        attributes,
        extensions: None,
        extras: Default::default(),
        indices: Some(indices),
        material: Some(material),
        mode: Valid(json::mesh::Mode::Triangles),
        targets: None,
    };
    let mesh_index = root.push(json::Mesh {
        extensions: None,
        extras: Default::default(),
        name: Some("nuvo".into()),
        primitives: vec![primitive],
        weights: None,
    });
    let node = root.push(json::Node { mesh: Some(mesh_index), ..Default::default() });
    let scene = root.push(json::Scene {
        extensions: None,
        extras: Default::default(),
        name: None,
        nodes: vec![node],
    });
    root.scene = Some(scene);
    root.push(json::Buffer {
        byte_length: USize64::from(bin.len()),
        extensions: None,
        extras: Default::default(),
        name: None,
        uri: None,
    });
    let json_bytes = json::serialize::to_vec(&root)
        .map_err(|e| AtlasError::Encode { path: "mesh.glb".into(), message: e.to_string() })?;
    let total = 12 + 8 + json_bytes.len().next_multiple_of(4) + 8 + bin.len();
    let length = u32::try_from(total).map_err(|_| AtlasError::Encode {
        path: "mesh.glb".into(),
        message: format!("{total} bytes exceed the 4 GiB limit of binary glTF"),
    })?;
    let glb = gltf::binary::Glb {
        header: gltf::binary::Header { magic: *b"glTF", version: 2, length },
        json: json_bytes.into(),
        bin: Some(bin.into()),
    };
    glb.to_vec().map_err(|e| AtlasError::Encode { path: "mesh.glb".into(), message: e.to_string() })
}

/// For each vertex of the GLB that [`glb_bytes`] writes for `mesh`, the index of the mesh vertex it
/// copies: a vertex on a UV seam appears once per UV it has, so this is how a user carries per-vertex
/// data of their own mesh over to the GLB (`nuvo unwrap` writes it as `vertex_map.json`).
pub fn glb_vertex_map(mesh: &TriMesh) -> Result<Vec<u32>, AtlasError> {
    let uv = uv_of(mesh, Path::new("mesh"))?;
    Ok(split_seams(mesh, uv).vertices.iter().map(|&(p, _)| p).collect())
}

/// The mesh re-indexed for per-vertex attributes: one vertex per distinct (position, UV) pair.
struct SplitMesh {
    /// (original position index, UV) of each output vertex, in first-use order.
    vertices: Vec<(u32, [f32; 2])>,
    triangles: Vec<u32>,
}

fn split_seams(mesh: &TriMesh, uv: &UvLayer) -> SplitMesh {
    let mut index: HashMap<(u32, [u32; 2]), u32> = HashMap::new();
    let mut vertices = Vec::new();
    let mut triangles = Vec::with_capacity(mesh.triangles.len() * 3);
    for (t, tu) in mesh.triangles.iter().zip(&uv.triangles) {
        for k in 0..3 {
            let c = uv.coords[tu[k] as usize];
            let i = *index.entry((t[k], c.map(f32::to_bits))).or_insert_with(|| {
                vertices.push((t[k], c));
                vertices.len() as u32 - 1
            });
            triangles.push(i);
        }
    }
    SplitMesh { vertices, triangles }
}

/// Plain-old-data that can be appended to the binary chunk little-endian.
trait Pod: Copy {
    const COMPONENT: json::accessor::ComponentType;
    fn extend_le(&self, out: &mut Vec<u8>);
}

impl<const N: usize> Pod for [f32; N] {
    const COMPONENT: json::accessor::ComponentType = json::accessor::ComponentType::F32;
    fn extend_le(&self, out: &mut Vec<u8>) {
        self.iter().for_each(|x| out.extend_from_slice(&x.to_le_bytes()));
    }
}

impl Pod for u32 {
    const COMPONENT: json::accessor::ComponentType = json::accessor::ComponentType::U32;
    fn extend_le(&self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.to_le_bytes());
    }
}

/// Appends `data` as a new buffer view + accessor (`vertex_data`: ARRAY_BUFFER, else
/// ELEMENT_ARRAY_BUFFER) and returns the accessor.
fn push_accessor<T: Pod>(
    root: &mut json::Root,
    bin: &mut Vec<u8>,
    data: &[T],
    type_: json::accessor::Type,
    min_max: Option<([f32; 3], [f32; 3])>,
    vertex_data: bool,
) -> json::Index<json::Accessor> {
    let offset = bin.len();
    data.iter().for_each(|d| d.extend_le(bin));
    let target = if vertex_data {
        json::buffer::Target::ArrayBuffer
    } else {
        json::buffer::Target::ElementArrayBuffer
    };
    let view = push_view(root, offset, bin.len() - offset, Some(target));
    root.push(json::Accessor {
        buffer_view: Some(view),
        byte_offset: None,
        count: USize64::from(data.len()),
        component_type: Valid(json::accessor::GenericComponentType(T::COMPONENT)),
        extensions: None,
        extras: Default::default(),
        type_: Valid(type_),
        min: min_max.map(|(lo, _)| json::Value::from(lo.to_vec())),
        max: min_max.map(|(_, hi)| json::Value::from(hi.to_vec())),
        name: None,
        normalized: false,
        sparse: None,
    })
}

fn push_view(
    root: &mut json::Root,
    offset: usize,
    length: usize,
    target: Option<json::buffer::Target>,
) -> json::Index<json::buffer::View> {
    root.push(json::buffer::View {
        buffer: json::Index::new(0),
        byte_length: USize64::from(length),
        byte_offset: Some(USize64::from(offset)),
        byte_stride: None,
        extensions: None,
        extras: Default::default(),
        name: None,
        target: target.map(Valid),
    })
}

/// The single double-sided material, textured with the embedded PNG when given.
fn push_material(
    root: &mut json::Root,
    bin: &mut Vec<u8>,
    png: Option<&[u8]>,
) -> json::Index<json::Material> {
    let base_color_texture = png.map(|png| {
        while !bin.len().is_multiple_of(4) {
            bin.push(0);
        }
        let offset = bin.len();
        bin.extend_from_slice(png);
        let view = push_view(root, offset, png.len(), None);
        let image = root.push(json::Image {
            buffer_view: Some(view),
            mime_type: Some(json::image::MimeType("image/png".into())),
            name: None,
            uri: None,
            extensions: None,
            extras: Default::default(),
        });
        let sampler = root.push(json::texture::Sampler {
            mag_filter: Some(Valid(json::texture::MagFilter::Linear)),
            min_filter: Some(Valid(json::texture::MinFilter::LinearMipmapLinear)),
            wrap_s: Valid(json::texture::WrappingMode::ClampToEdge),
            wrap_t: Valid(json::texture::WrappingMode::ClampToEdge),
            ..Default::default()
        });
        let texture = root.push(json::Texture {
            name: None,
            sampler: Some(sampler),
            source: image,
            extensions: None,
            extras: Default::default(),
        });
        json::texture::Info { index: texture, tex_coord: 0, extensions: None, extras: Default::default() }
    });
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    root.push(json::Material {
        name: Some(MATERIAL_NAME.into()),
        double_sided: true,
        pbr_metallic_roughness: json::material::PbrMetallicRoughness {
            base_color_texture,
            metallic_factor: json::material::StrengthFactor(0.0),
            ..Default::default()
        },
        ..Default::default()
    })
}

fn bounds(points: &[[f32; 3]]) -> ([f32; 3], [f32; 3]) {
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for p in points {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    if points.is_empty() { ([0.0; 3], [0.0; 3]) } else { (lo, hi) }
}

/// The UV layer of a valid mesh (indices in range), naming `path` in the errors.
fn uv_of<'a>(mesh: &'a TriMesh, path: &Path) -> Result<&'a UvLayer, AtlasError> {
    mesh.validate().map_err(|m| AtlasError::invalid("mesh", format!("{}: {m}", path.display())))?;
    mesh.uv.as_ref().ok_or_else(|| AtlasError::NoUv { what: path.display().to_string() })
}

fn file_name(p: &Path) -> String {
    p.file_name().map_or_else(|| p.display().to_string(), |n| n.to_string_lossy().into_owned())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testmesh::{grid, with_uv_per_corner};

    /// A plane with a seam (left half's UVs shifted), in a canonical frame with a non-trivial map back.
    fn seamed() -> (TriMesh, Similarity) {
        let m = grid(4, |p| [(p[0] + 1.0) * 0.25, (p[1] + 1.0) * 0.5]);
        let m = with_uv_per_corner(&m, |f, _, uv| {
            if m.corners(f).iter().all(|c| c[0] <= 0.0) { [uv[0] + 0.5, uv[1]] } else { uv }
        });
        (m, Similarity { center: [10.0, -3.0, 0.5], scale: 0.25 })
    }

    /// Per-corner (position, uv) of a mesh, for comparing meshes indexed differently.
    fn corners(m: &TriMesh) -> Vec<([f32; 3], [f32; 2])> {
        let uv = m.uv.as_ref().unwrap();
        (0..m.triangles.len())
            .flat_map(|f| (0..3).map(move |k| (f, k)))
            .map(|(f, k)| (m.positions[m.triangles[f][k] as usize], uv.coords[uv.triangles[f][k] as usize]))
            .collect()
    }

    #[test]
    fn obj_round_trips_through_our_reader_in_input_coordinates() {
        let (m, frame) = seamed();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.obj");
        write_obj(&path, &m, &frame, Some(&dir.path().join("atlas.png"))).unwrap();
        let back = nuvo_geometry::obj::load_obj(&path).unwrap();
        assert_eq!(back.triangles.len(), m.triangles.len());
        let want: Vec<_> = corners(&m).into_iter().map(|(p, uv)| (frame.invert(p), uv)).collect();
        assert_eq!(corners(&back), want);
        let mtl = std::fs::read_to_string(dir.path().join("out.mtl")).unwrap();
        assert!(mtl.contains("map_Kd atlas.png"), "{mtl}");
        assert!(std::fs::read_to_string(&path).unwrap().contains("mtllib out.mtl"));
    }

    #[test]
    fn glb_round_trips_through_the_gltf_crate_with_seams_split() {
        let (m, frame) = seamed();
        let png = [0x89u8, b'P', b'N', b'G', 1, 2, 3]; // opaque bytes: the reader does not decode them
        let opts = GlbOptions { normals: true, texture_png: Some(&png) };
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.glb");
        write_glb(&path, &m, &frame, &opts).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let gltf = gltf::Gltf::from_slice(&bytes).expect("valid glTF");
        let blob = gltf.blob.as_deref().expect("binary chunk");
        let prim = gltf.meshes().next().unwrap().primitives().next().unwrap();
        let reader = prim.reader(|_| Some(blob));
        let pos: Vec<[f32; 3]> = reader.read_positions().unwrap().collect();
        let tex: Vec<[f32; 2]> = reader.read_tex_coords(0).unwrap().into_f32().collect();
        let nrm: Vec<[f32; 3]> = reader.read_normals().unwrap().collect();
        let idx: Vec<u32> = reader.read_indices().unwrap().into_u32().collect();
        assert_eq!(idx.len(), m.triangles.len() * 3);
        let got: Vec<_> =
            idx.iter().map(|&i| (pos[i as usize], [tex[i as usize][0], 1.0 - tex[i as usize][1]])).collect();
        let want: Vec<_> = corners(&m).into_iter().map(|(p, uv)| (frame.invert(p), uv)).collect();
        for (g, w) in got.iter().zip(&want) {
            assert_eq!(g.0, w.0);
            assert!((g.1[0] - w.1[0]).abs() < 1e-6 && (g.1[1] - w.1[1]).abs() < 1e-6, "{g:?} vs {w:?}");
        }
        // 25 positions; the 5 on the seam column x = 0 carry two UVs each.
        assert_eq!(pos.len(), 30);
        assert!(nrm.iter().all(|n| (n[2].abs() - 1.0).abs() < 1e-6));
        let image = gltf.images().next().expect("embedded texture");
        let gltf::image::Source::View { view, mime_type } = image.source() else { panic!("not embedded") };
        assert_eq!(mime_type, "image/png");
        assert_eq!(&blob[view.offset()..view.offset() + view.length()], &png);
        assert!(gltf.materials().next().unwrap().double_sided());
    }

    #[test]
    fn the_vertex_map_names_the_mesh_vertex_of_every_glb_vertex() {
        let (m, frame) = seamed();
        let map = glb_vertex_map(&m).unwrap();
        let glb = glb_bytes(&m, &frame, &GlbOptions::default()).unwrap();
        let (doc, buffers, _) = gltf::import_slice(&glb).unwrap();
        let prim = doc.meshes().next().unwrap().primitives().next().unwrap();
        let reader = prim.reader(|b| Some(&buffers[b.index()]));
        let positions: Vec<[f32; 3]> = reader.read_positions().unwrap().collect();
        assert_eq!(map.len(), positions.len());
        assert!(map.len() > m.positions.len(), "the fixture has a seam");
        for (k, &v) in map.iter().enumerate() {
            let want = frame.invert(m.positions[v as usize]);
            assert_eq!(positions[k], want, "GLB vertex {k} is mesh vertex {v}");
        }
    }

    #[test]
    fn meshes_without_uvs_are_refused_naming_the_file() {
        let (mut m, frame) = seamed();
        m.uv = None;
        let dir = tempfile::tempdir().unwrap();
        let e = write_glb(&dir.path().join("x.glb"), &m, &frame, &GlbOptions::default()).unwrap_err();
        assert!(e.to_string().contains("x.glb"), "{e}");
        let e = write_obj(&dir.path().join("y.obj"), &m, &frame, None).unwrap_err();
        assert!(e.to_string().contains("y.obj"), "{e}");
    }
}
