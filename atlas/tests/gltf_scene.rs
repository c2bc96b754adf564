//! `write_gltf_with_uvs`: a small two-node, two-mesh scene (interleaved and strided attributes, a
//! normalized u8 colour, a sparse colour, a morph target, a mirroring node, a triangle strip, an
//! unused vertex, an embedded PNG texture, extras), written with a seamed UV layout and read back.

use std::path::{Path, PathBuf};

use gltf::json::{self, validation::Checked::Valid, validation::USize64};
use json::accessor::{ComponentType, Type};
use nuvo_atlas::gltf_scene::{GltfVertexMap, check_gltf_unwrappable, write_gltf_with_uvs};
use nuvo_geometry::gltf_io::load_gltf;
use nuvo_geometry::{TriMesh, UvLayer};
use serde_json::Value;

/// The per-vertex data of the test scene, as the file stores it.
struct Data {
    quad_pos: Vec<[f32; 3]>,
    quad_nrm: Vec<[f32; 3]>,
    quad_col: Vec<[u8; 4]>,
    quad_morph: Vec<[f32; 3]>,
    quad_idx: Vec<u16>,
    grid_pos: Vec<[f32; 3]>,
    grid_nrm: Vec<[f32; 3]>,
    /// After the sparse substitution.
    grid_col: Vec<[f32; 3]>,
    grid_uv1: Vec<[u16; 2]>,
    grid_idx: Vec<u16>,
    strip_pos: Vec<[f32; 3]>,
    strip_nrm: Vec<[f32; 3]>,
    png: Vec<u8>,
}

fn data() -> Data {
    let mut png = Vec::new();
    let img =
        image::RgbImage::from_fn(4, 4, |x, y| image::Rgb(if (x + y) % 2 == 0 { [255; 3] } else { [0; 3] }));
    image::ImageEncoder::write_image(
        image::codecs::png::PngEncoder::new(&mut png),
        img.as_raw(),
        4,
        4,
        image::ExtendedColorType::Rgb8,
    )
    .unwrap();
    let grid_pos: Vec<[f32; 3]> = (0..6)
        .map(|i| [(i % 3) as f32, (i / 3) as f32, 0.0])
        .chain([[5.0, 5.0, 5.0]]) // vertex 6: used by no triangle
        .collect();
    let mut grid_col: Vec<[f32; 3]> = vec![[0.5; 3]; 7];
    grid_col[4] = [1.0, 0.0, 0.0];
    Data {
        quad_pos: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]],
        quad_nrm: vec![[0.0, 0.0, 1.0], [0.0, 0.6, 0.8], [0.6, 0.0, 0.8], [0.8, 0.0, 0.6]],
        quad_col: vec![[255, 0, 0, 255], [0, 255, 0, 255], [0, 0, 255, 255], [255, 255, 0, 128]],
        quad_morph: (0..4).map(|i| [0.0, 0.0, 0.1 * i as f32]).collect(),
        quad_idx: vec![0, 1, 2, 0, 2, 3],
        grid_nrm: (0..7).map(|i| [0.1 * i as f32, 0.0, 1.0]).collect(),
        grid_pos,
        grid_col,
        grid_uv1: (0..7).map(|i| [i * 1000, 65535 - i * 7]).collect(),
        grid_idx: vec![0, 1, 4, 0, 4, 3, 1, 2, 5, 1, 5, 4],
        strip_pos: vec![[0.0, 2.0, 0.0], [1.0, 2.0, 0.0], [0.0, 3.0, 0.0], [1.0, 3.0, 0.0]],
        strip_nrm: (0..4).map(|i| [0.0, 0.2 * i as f32, 1.0]).collect(),
        png,
    }
}

fn le<T: Copy, const N: usize>(v: &[[T; N]], f: impl Fn(T) -> Vec<u8>) -> Vec<u8> {
    v.iter().flat_map(|e| e.iter().flat_map(|&x| f(x)).collect::<Vec<_>>()).collect()
}
fn f32s<const N: usize>(v: &[[f32; N]]) -> Vec<u8> {
    le(v, |x| x.to_le_bytes().to_vec())
}

struct Builder {
    root: json::Root,
    bin: Vec<u8>,
}

impl Builder {
    fn view(
        &mut self,
        bytes: &[u8],
        stride: Option<usize>,
        target: Option<json::buffer::Target>,
    ) -> json::Index<json::buffer::View> {
        self.bin.resize(self.bin.len().next_multiple_of(4), 0);
        let offset = self.bin.len();
        self.bin.extend_from_slice(bytes);
        self.root.push(json::buffer::View {
            buffer: json::Index::new(0),
            byte_length: USize64::from(bytes.len()),
            byte_offset: Some(USize64::from(offset)),
            byte_stride: stride.map(json::buffer::Stride),
            extensions: None,
            extras: Default::default(),
            name: None,
            target: target.map(Valid),
        })
    }

    #[allow(clippy::too_many_arguments)]
    fn accessor(
        &mut self,
        view: Option<json::Index<json::buffer::View>>,
        offset: usize,
        count: usize,
        ct: ComponentType,
        type_: Type,
        normalized: bool,
        bounds: Option<&[[f32; 3]]>,
    ) -> json::Index<json::Accessor> {
        let (min, max) = match bounds {
            Some(p) => {
                let lo: Vec<f32> =
                    (0..3).map(|k| p.iter().map(|q| q[k]).fold(f32::INFINITY, f32::min)).collect();
                let hi: Vec<f32> =
                    (0..3).map(|k| p.iter().map(|q| q[k]).fold(f32::NEG_INFINITY, f32::max)).collect();
                (Some(json::Value::from(lo)), Some(json::Value::from(hi)))
            }
            None => (None, None),
        };
        self.root.push(json::Accessor {
            buffer_view: view,
            byte_offset: (offset > 0).then(|| USize64::from(offset)),
            count: USize64::from(count),
            component_type: Valid(json::accessor::GenericComponentType(ct)),
            extensions: None,
            extras: Default::default(),
            type_: Valid(type_),
            min,
            max,
            name: None,
            normalized,
            sparse: None,
        })
    }

    /// A tightly packed vertex attribute in its own view.
    fn attribute(
        &mut self,
        bytes: &[u8],
        count: usize,
        ct: ComponentType,
        type_: Type,
        normalized: bool,
    ) -> json::Index<json::Accessor> {
        let view = self.view(bytes, None, Some(json::buffer::Target::ArrayBuffer));
        self.accessor(Some(view), 0, count, ct, type_, normalized, None)
    }

    fn indices(&mut self, idx: &[u16]) -> json::Index<json::Accessor> {
        let bytes: Vec<u8> = idx.iter().flat_map(|i| i.to_le_bytes()).collect();
        let view = self.view(&bytes, None, Some(json::buffer::Target::ElementArrayBuffer));
        self.accessor(Some(view), 0, idx.len(), ComponentType::U16, Type::Scalar, false, None)
    }
}

fn primitive(
    attributes: Vec<(json::mesh::Semantic, json::Index<json::Accessor>)>,
    indices: Option<json::Index<json::Accessor>>,
    material: Option<json::Index<json::Material>>,
    mode: json::mesh::Mode,
    targets: Option<Vec<json::mesh::MorphTarget>>,
) -> json::mesh::Primitive {
    json::mesh::Primitive {
        attributes: attributes.into_iter().map(|(s, a)| (Valid(s), a)).collect(),
        extensions: None,
        extras: Default::default(),
        indices,
        material,
        mode: Valid(mode),
        targets,
    }
}

/// The scene as JSON (with extras and names added as raw JSON) and its binary buffer.
/// `shared`: a third node also instances the quad mesh.
fn scene(d: &Data, shared: bool) -> (Value, Vec<u8>) {
    use json::mesh::Semantic::*;
    let mut b = Builder { root: json::Root::default(), bin: Vec::new() };
    b.root.asset = json::Asset { generator: Some("test".into()), ..Default::default() };

    // Quad: POSITION and NORMAL interleaved (stride 24), normalized u8 colours, an old TEXCOORD_0,
    // one morph target.
    let inter: Vec<u8> = d.quad_pos.iter().zip(&d.quad_nrm).flat_map(|(p, n)| f32s(&[*p, *n])).collect();
    let view = b.view(&inter, Some(24), Some(json::buffer::Target::ArrayBuffer));
    let pos = b.accessor(Some(view), 0, 4, ComponentType::F32, Type::Vec3, false, Some(&d.quad_pos));
    let nrm = b.accessor(Some(view), 12, 4, ComponentType::F32, Type::Vec3, false, None);
    let col = b.attribute(&le(&d.quad_col, |x| vec![x]), 4, ComponentType::U8, Type::Vec4, true);
    let old_uv = b.attribute(&f32s(&[[0.9f32, 0.9]; 4]), 4, ComponentType::F32, Type::Vec2, false);
    let morph_view = b.view(&f32s(&d.quad_morph), None, Some(json::buffer::Target::ArrayBuffer));
    let morph =
        b.accessor(Some(morph_view), 0, 4, ComponentType::F32, Type::Vec3, false, Some(&d.quad_morph));
    let idx = b.indices(&d.quad_idx);

    // The embedded texture.
    let png_view = b.view(&d.png, None, None);
    let image = b.root.push(json::Image {
        buffer_view: Some(png_view),
        mime_type: Some(json::image::MimeType("image/png".into())),
        name: Some("checker.png".into()),
        uri: None,
        extensions: None,
        extras: Default::default(),
    });
    let sampler = b.root.push(json::texture::Sampler {
        mag_filter: Some(Valid(json::texture::MagFilter::Nearest)),
        ..Default::default()
    });
    let texture = b.root.push(json::Texture {
        name: Some("CheckerTex".into()),
        sampler: Some(sampler),
        source: image,
        extensions: None,
        extras: Default::default(),
    });
    let material = b.root.push(json::Material {
        name: Some("Checker".into()),
        pbr_metallic_roughness: json::material::PbrMetallicRoughness {
            base_color_texture: Some(json::texture::Info {
                index: texture,
                tex_coord: 0,
                extensions: None,
                extras: Default::default(),
            }),
            ..Default::default()
        },
        ..Default::default()
    });
    let quad = b.root.push(json::Mesh {
        extensions: None,
        extras: Default::default(),
        name: Some("Quad".into()),
        primitives: vec![primitive(
            vec![(Positions, pos), (Normals, nrm), (Colors(0), col), (TexCoords(0), old_uv)],
            Some(idx),
            Some(material),
            json::mesh::Mode::Triangles,
            Some(vec![json::mesh::MorphTarget { positions: Some(morph), normals: None, tangents: None }]),
        )],
        weights: Some(vec![0.5]),
    });

    // Grid: a sparse colour, normalized u16 TEXCOORD_1, an unused vertex; then a triangle strip.
    let gpos = b.attribute(&f32s(&d.grid_pos), 7, ComponentType::F32, Type::Vec3, false);
    b.root.accessors[gpos.value()].min = Some(json::Value::from(vec![0.0, 0.0, 0.0]));
    b.root.accessors[gpos.value()].max = Some(json::Value::from(vec![5.0, 5.0, 5.0]));
    let gnrm = b.attribute(&f32s(&d.grid_nrm), 7, ComponentType::F32, Type::Vec3, false);
    let gcol = b.attribute(&f32s(&[[0.5f32; 3]; 7]), 7, ComponentType::F32, Type::Vec3, false);
    let sparse_idx = b.view(&4u16.to_le_bytes(), None, None);
    let sparse_val = b.view(&f32s(&[d.grid_col[4]]), None, None);
    b.root.accessors[gcol.value()].sparse = Some(json::accessor::sparse::Sparse {
        count: USize64(1),
        indices: json::accessor::sparse::Indices {
            buffer_view: sparse_idx,
            byte_offset: USize64(0),
            component_type: Valid(json::accessor::IndexComponentType(ComponentType::U16)),
            extensions: None,
            extras: Default::default(),
        },
        values: json::accessor::sparse::Values {
            buffer_view: sparse_val,
            byte_offset: USize64(0),
            extensions: None,
            extras: Default::default(),
        },
        extensions: None,
        extras: Default::default(),
    });
    let guv1 =
        b.attribute(&le(&d.grid_uv1, |x| x.to_le_bytes().to_vec()), 7, ComponentType::U16, Type::Vec2, true);
    let gidx = b.indices(&d.grid_idx);
    let spos = b.attribute(&f32s(&d.strip_pos), 4, ComponentType::F32, Type::Vec3, false);
    b.root.accessors[spos.value()].min = Some(json::Value::from(vec![0.0, 2.0, 0.0]));
    b.root.accessors[spos.value()].max = Some(json::Value::from(vec![1.0, 3.0, 0.0]));
    let snrm = b.attribute(&f32s(&d.strip_nrm), 4, ComponentType::F32, Type::Vec3, false);
    let grid = b.root.push(json::Mesh {
        extensions: None,
        extras: Default::default(),
        name: Some("Grid".into()),
        primitives: vec![
            primitive(
                vec![(Positions, gpos), (Normals, gnrm), (Colors(0), gcol), (TexCoords(1), guv1)],
                Some(gidx),
                Some(material),
                json::mesh::Mode::Triangles,
                None,
            ),
            primitive(
                vec![(Positions, spos), (Normals, snrm)],
                None,
                None,
                json::mesh::Mode::TriangleStrip,
                None,
            ),
        ],
        weights: None,
    });

    let h = std::f32::consts::FRAC_1_SQRT_2;
    let quad_node = b.root.push(json::Node {
        mesh: Some(quad),
        name: Some("QuadNode".into()),
        rotation: Some(json::scene::UnitQuaternion([0.0, 0.0, h, h])),
        scale: Some([2.0, 2.0, 2.0]),
        ..Default::default()
    });
    let root_node = b.root.push(json::Node {
        name: Some("Root".into()),
        translation: Some([1.0, 2.0, 3.0]),
        children: Some(vec![quad_node]),
        ..Default::default()
    });
    let grid_node = b.root.push(json::Node {
        mesh: Some(grid),
        name: Some("GridNode".into()),
        scale: Some([-1.0, 1.0, 1.0]),
        translation: Some([0.0, 0.0, -1.0]),
        ..Default::default()
    });
    let mut nodes = vec![root_node, grid_node];
    if shared {
        nodes.push(b.root.push(json::Node {
            mesh: Some(quad),
            name: Some("QuadCopy".into()),
            translation: Some([4.0, 0.0, 0.0]),
            ..Default::default()
        }));
    }
    let s = b.root.push(json::Scene {
        extensions: None,
        extras: Default::default(),
        name: Some("Scene".into()),
        nodes,
    });
    b.root.scene = Some(s);
    b.root.push(json::Buffer {
        byte_length: USize64::from(b.bin.len()),
        extensions: None,
        extras: Default::default(),
        name: Some("geometry".into()),
        uri: None,
    });
    let mut v: Value = serde_json::to_value(&b.root).unwrap();
    v["nodes"][0]["extras"] = serde_json::json!({"tag": 7});
    v["meshes"][1]["extras"] = serde_json::json!({"kind": "grid"});
    v["materials"][0]["extras"] = serde_json::json!({"author": "test"});
    v["accessors"][nrm.value()]["name"] = "QuadNormals".into();
    v["extras"] = serde_json::json!({"scene_extra": true});
    (v, b.bin)
}

/// Writes the scene as `.gltf` + external `.bin`, or as `.glb`.
fn write_input(dir: &Path, name: &str, glb: bool, shared: bool) -> PathBuf {
    let d = data();
    let (mut v, bin) = scene(&d, shared);
    if glb {
        let path = dir.join(format!("{name}.glb"));
        let json = serde_json::to_vec(&v).unwrap();
        let out = gltf::binary::Glb {
            header: gltf::binary::Header { magic: *b"glTF", version: 2, length: 0 },
            json: json.into(),
            bin: Some(bin.into()),
        };
        std::fs::write(&path, out.to_vec().unwrap()).unwrap();
        path
    } else {
        let path = dir.join(format!("{name}.gltf"));
        std::fs::write(dir.join(format!("{name}.bin")), &bin).unwrap();
        v["buffers"][0]["uri"] = format!("{name}.bin").into();
        std::fs::write(&path, serde_json::to_vec_pretty(&v).unwrap()).unwrap();
        path
    }
}

/// A per-corner UV layout of `mesh`: one UV per vertex, except on faces 1 and 3 (the quad's second
/// triangle, the grid's second), shifted by half the atlas: a seam along their edges.
fn seamed_layout(mesh: &TriMesh) -> UvLayer {
    let mut uv = UvLayer::default();
    for (f, t) in mesh.triangles.iter().enumerate() {
        let shift = if f == 1 || f == 3 { 0.5 } else { 0.0 };
        let mut tri = [0; 3];
        for k in 0..3 {
            let v = t[k] as f32;
            uv.coords.push([0.02 * v + shift, 0.9 - 0.03 * v]);
            tri[k] = uv.coords.len() as u32 - 1;
        }
        uv.triangles.push(tri);
    }
    uv
}

fn corners(m: &TriMesh) -> Vec<([f32; 3], [f32; 2])> {
    let uv = m.uv.as_ref();
    (0..m.triangles.len())
        .flat_map(|f| (0..3).map(move |k| (f, k)))
        .map(|(f, k)| {
            let p = m.positions[m.triangles[f][k] as usize];
            (p, uv.map_or([f32::NAN; 2], |uv| uv.coords[uv.triangles[f][k] as usize]))
        })
        .collect()
}

fn output_json(bytes: &[u8]) -> Value {
    let glb = gltf::binary::Glb::from_slice(bytes).unwrap();
    serde_json::from_slice(&glb.json).unwrap()
}

/// The triangles of a strip, as the glTF spec assembles them.
fn strip_triangles(n: usize) -> Vec<[u32; 3]> {
    (0..n - 2)
        .map(|j| j as u32)
        .map(|j| if j % 2 == 0 { [j, j + 1, j + 2] } else { [j + 1, j, j + 2] })
        .collect()
}

fn write_and_check(glb_input: bool) {
    let dir = tempfile::tempdir().unwrap();
    let input = write_input(dir.path(), "scene", glb_input, false);
    let d = data();
    let in_mesh = load_gltf(&input).unwrap();
    assert_eq!(in_mesh.triangles.len(), 2 + 4 + 2);
    let uv = seamed_layout(&in_mesh);
    check_gltf_unwrappable(&input).unwrap();
    let out_dir = dir.path().join("out");
    std::fs::create_dir(&out_dir).unwrap();
    let output = out_dir.join("unwrapped.glb");
    let map = write_gltf_with_uvs(&input, &uv, &output, None).unwrap();
    let bytes = std::fs::read(&output).unwrap();

    // (a) Same faces, same corner positions, the given UVs.
    let out_mesh = load_gltf(&output).unwrap();
    assert_eq!(out_mesh.triangles.len(), in_mesh.triangles.len());
    let want: Vec<([f32; 3], [f32; 2])> = corners(&in_mesh)
        .into_iter()
        .enumerate()
        .map(|(c, (p, _))| (p, uv.coords[uv.triangles[c / 3][c % 3] as usize]))
        .collect();
    let got = corners(&out_mesh);
    for (c, (g, w)) in got.iter().zip(&want).enumerate() {
        assert_eq!(g.0, w.0, "corner {c}: position");
        assert!(
            (g.1[0] - w.1[0]).abs() < 1e-6 && (g.1[1] - w.1[1]).abs() < 1e-6,
            "corner {c}: {g:?} vs {w:?}"
        );
    }

    // (b) Everything but the geometry is kept; old accessors and views are gone.
    let gltf = gltf::Gltf::from_slice(&bytes).expect("the output validates");
    let blob = gltf.blob.as_deref().unwrap();
    let out = output_json(&bytes);
    let (inp, _) = scene(&d, false);
    for key in ["nodes", "scenes", "scene", "materials", "textures", "samplers", "asset", "extras"] {
        assert_eq!(out[key], inp[key], "{key}");
    }
    for (mo, mi) in out["meshes"].as_array().unwrap().iter().zip(inp["meshes"].as_array().unwrap()) {
        for key in ["name", "weights", "extras"] {
            assert_eq!(mo[key], mi[key], "mesh {key}");
        }
        for (po, pi) in mo["primitives"].as_array().unwrap().iter().zip(mi["primitives"].as_array().unwrap())
        {
            assert_eq!(po["material"], pi["material"]);
            let keys = |p: &Value| {
                let mut k: Vec<String> = p["attributes"].as_object().unwrap().keys().cloned().collect();
                k.push("TEXCOORD_0".into());
                k.sort();
                k.dedup();
                k
            };
            assert_eq!(keys(po), keys(pi));
        }
    }
    assert_eq!(out["meshes"].as_array().unwrap().len(), 2);
    let mut image = out["images"][0].clone();
    image.as_object_mut().unwrap().remove("bufferView");
    let mut image_in = inp["images"][0].clone();
    image_in.as_object_mut().unwrap().remove("bufferView");
    assert_eq!(image, image_in);
    let gltf::image::Source::View { view, mime_type } = gltf.images().next().unwrap().source() else {
        panic!("the image is no longer embedded")
    };
    assert_eq!(mime_type, "image/png");
    assert_eq!(&blob[view.offset()..view.offset() + view.length()], &d.png[..]);
    // quad: POSITION NORMAL COLOR_0 TEXCOORD_0 target indices; grid: POSITION NORMAL COLOR_0
    // TEXCOORD_1 TEXCOORD_0 indices; strip: POSITION NORMAL TEXCOORD_0 indices.
    assert_eq!(gltf.accessors().len(), 16);
    assert_eq!(gltf.views().len(), 17);
    assert_eq!(out["buffers"].as_array().unwrap().len(), 1);
    assert_eq!(out["buffers"][0]["name"], "geometry");
    assert!(out["buffers"][0].get("uri").is_none());
    let quad_acc = &gltf.meshes().next().unwrap().primitives().next().unwrap();
    let nrm = quad_acc.get(&gltf::Semantic::Normals).unwrap();
    assert_eq!(nrm.name(), Some("QuadNormals"));
    let col = quad_acc.get(&gltf::Semantic::Colors(0)).unwrap();
    assert!(col.normalized());
    assert_eq!(col.data_type(), gltf::accessor::DataType::U8);

    // (c) + (d) Attributes follow their vertices; the vertex map says where each came from.
    let mut seen_prims = Vec::new();
    for mesh in gltf.meshes() {
        for prim in mesh.primitives() {
            seen_prims.push((mesh.index(), prim.index()));
            assert_eq!(prim.mode(), gltf::mesh::Mode::Triangles);
            let r = prim.reader(|_| Some(blob));
            let idx: Vec<u32> = r.read_indices().unwrap().into_u32().collect();
            assert!(matches!(r.read_indices().unwrap(), gltf::mesh::util::ReadIndices::U16(_)));
            let entry = map
                .primitives
                .iter()
                .find(|p| (p.mesh, p.primitive) == (mesh.index(), prim.index()))
                .unwrap();
            let src = &entry.source_vertices;
            let n_out = r.read_positions().unwrap().count();
            assert_eq!(src.len(), n_out);
            // First-use order.
            let mut next = 0;
            for &i in &idx {
                assert!(i <= next);
                next = next.max(i + 1);
            }
            assert_eq!(next as usize, n_out);
            let in_tris: Vec<[u32; 3]> = match (mesh.index(), prim.index()) {
                (0, 0) => d.quad_idx.chunks(3).map(|c| [c[0], c[1], c[2]].map(u32::from)).collect(),
                (1, 0) => d.grid_idx.chunks(3).map(|c| [c[0], c[1], c[2]].map(u32::from)).collect(),
                _ => strip_triangles(4),
            };
            let out_tris: Vec<[u32; 3]> =
                idx.chunks(3).map(|c| [c[0], c[1], c[2]].map(|i| src[i as usize])).collect();
            assert_eq!(out_tris, in_tris, "mesh {} primitive {}", mesh.index(), prim.index());
            let nrm: Vec<[f32; 3]> = r.read_normals().unwrap().collect();
            let pos: Vec<[f32; 3]> = r.read_positions().unwrap().collect();
            let (in_pos, in_nrm) = match (mesh.index(), prim.index()) {
                (0, 0) => (&d.quad_pos, &d.quad_nrm),
                (1, 0) => (&d.grid_pos, &d.grid_nrm),
                _ => (&d.strip_pos, &d.strip_nrm),
            };
            for (v, &s) in src.iter().enumerate() {
                assert_eq!(pos[v], in_pos[s as usize]);
                assert_eq!(nrm[v], in_nrm[s as usize]);
            }
            match mesh.index() {
                0 => {
                    assert_eq!(n_out, 6, "two vertices of the quad sit on the seam");
                    let col: Vec<[u8; 4]> = r.read_colors(0).unwrap().into_rgba_u8().collect();
                    let morph: Vec<[f32; 3]> =
                        r.read_morph_targets().next().unwrap().0.expect("morph positions").collect();
                    for (v, &s) in src.iter().enumerate() {
                        assert_eq!(col[v], d.quad_col[s as usize]);
                        assert_eq!(morph[v], d.quad_morph[s as usize]);
                    }
                    let target = prim.morph_targets().next().unwrap().positions().unwrap();
                    assert!(target.min().is_some() && target.max().is_some());
                }
                _ if prim.index() == 0 => {
                    assert_eq!(n_out, 8, "6 used vertices, two split, the unused one dropped");
                    let col: Vec<[f32; 3]> = r.read_colors(0).unwrap().into_rgb_f32().collect();
                    let gltf::mesh::util::ReadTexCoords::U16(uv1) = r.read_tex_coords(1).unwrap() else {
                        panic!("TEXCOORD_1 changed type")
                    };
                    let uv1: Vec<[u16; 2]> = uv1.collect();
                    for (v, &s) in src.iter().enumerate() {
                        assert_eq!(col[v], d.grid_col[s as usize], "sparse colour of vertex {s}");
                        assert_eq!(uv1[v], d.grid_uv1[s as usize]);
                    }
                    let acc = prim.get(&gltf::Semantic::Positions).unwrap();
                    let max: Vec<f64> =
                        acc.max().unwrap().as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect();
                    assert_eq!(max, [2.0, 1.0, 0.0], "bounds recomputed without the unused vertex");
                }
                _ => assert_eq!(n_out, 4),
            }
        }
    }
    assert_eq!(seen_prims, [(0, 0), (1, 0), (1, 1)]);
    let ranges: Vec<_> = map.primitives.iter().map(|p| p.faces.clone()).collect();
    assert_eq!(ranges, [0..2, 2..6, 6..8]);
    assert_eq!(map.primitives.iter().map(|p| p.node).collect::<Vec<_>>(), [Some(0), Some(2), Some(2)]);
    // The flat map: output merged vertex -> input merged vertex.
    assert_eq!(map.merged.len(), out_mesh.positions.len());
    for (v, &s) in map.merged.iter().enumerate() {
        assert_eq!(out_mesh.positions[v], in_mesh.positions[s as usize]);
    }
    for (f, (to, ti)) in out_mesh.triangles.iter().zip(&in_mesh.triangles).enumerate() {
        assert_eq!(to.map(|v| map.merged[v as usize]), *ti, "face {f}");
    }
    let json = serde_json::to_value(&map).unwrap();
    assert_eq!(json["primitives"][0]["source_vertices"].as_array().unwrap().len(), 6);
    assert!(json["merged"].is_array());
}

#[test]
fn gltf_with_external_buffer_gets_uvs_and_keeps_everything_else() {
    write_and_check(false);
}

#[test]
fn glb_gets_uvs_and_keeps_everything_else() {
    write_and_check(true);
}

#[test]
fn rewriting_is_idempotent_on_its_own_output() {
    let dir = tempfile::tempdir().unwrap();
    let input = write_input(dir.path(), "scene", true, false);
    let uv = seamed_layout(&load_gltf(&input).unwrap());
    let first = dir.path().join("first.glb");
    write_gltf_with_uvs(&input, &uv, &first, None).unwrap();
    // The output's merged mesh has its own vertex numbering; give it the same per-corner UVs.
    let again = load_gltf(&first).unwrap().uv.unwrap();
    let second = dir.path().join("second.glb");
    let map: GltfVertexMap = write_gltf_with_uvs(&first, &again, &second, None).unwrap();
    assert_eq!(std::fs::read(&first).unwrap(), std::fs::read(&second).unwrap());
    for p in &map.primitives {
        assert!(p.source_vertices.iter().enumerate().all(|(i, &s)| i as u32 == s));
    }
}

#[test]
fn a_mesh_used_by_two_nodes_is_refused_naming_file_mesh_and_nodes() {
    let dir = tempfile::tempdir().unwrap();
    for glb in [false, true] {
        let input = write_input(dir.path(), "shared", glb, true);
        let e = check_gltf_unwrappable(&input).unwrap_err().to_string();
        let name = input.file_name().unwrap().to_str().unwrap();
        for part in [name, "mesh 0", "\"Quad\"", "\"QuadNode\"", "\"QuadCopy\"", "2 nodes"] {
            assert!(e.contains(part), "{part:?} not in: {e}");
        }
        let mesh = load_gltf(&input).unwrap();
        let output = dir.path().join("out.glb");
        let e2 = write_gltf_with_uvs(&input, &seamed_layout(&mesh), &output, None).unwrap_err().to_string();
        assert_eq!(e, e2);
        assert!(!output.exists());
    }
}

#[test]
fn missing_corrupt_or_mismatched_inputs_are_errors_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let output = dir.path().join("out.glb");
    let uv = UvLayer { coords: vec![[0.0; 2]], triangles: vec![[0; 3]] };
    let missing = dir.path().join("missing.glb");
    let corrupt = dir.path().join("corrupt.glb");
    std::fs::write(&corrupt, b"glTF\x02\0\0\0 this is not a GLB").unwrap();
    let truncated = write_input(dir.path(), "nobin", false, false);
    std::fs::remove_file(dir.path().join("nobin.bin")).unwrap();
    for path in [&missing, &corrupt] {
        let e = check_gltf_unwrappable(path).unwrap_err().to_string();
        assert!(e.contains(path.to_str().unwrap()), "{e}");
    }
    for path in [&missing, &corrupt, &truncated] {
        let e = write_gltf_with_uvs(path, &uv, &output, None).unwrap_err().to_string();
        assert!(e.contains(path.to_str().unwrap()), "{e}");
        assert!(!output.exists());
    }
    // A UV layer for another mesh.
    let good = write_input(dir.path(), "good", true, false);
    let e = write_gltf_with_uvs(&good, &uv, &output, None).unwrap_err().to_string();
    assert!(e.contains("good.glb") && e.contains("1 faces") && e.contains('8'), "{e}");
    assert!(!output.exists());
}

#[test]
fn extensions_that_store_geometry_are_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let (mut v, bin) = scene(&data(), false);
    v["extensionsUsed"] = serde_json::json!(["KHR_materials_unlit", "KHR_draco_mesh_compression"]);
    let path = dir.path().join("draco.gltf");
    std::fs::write(dir.path().join("draco.bin"), &bin).unwrap();
    v["buffers"][0]["uri"] = "draco.bin".into();
    std::fs::write(&path, serde_json::to_vec(&v).unwrap()).unwrap();
    let e = check_gltf_unwrappable(&path).unwrap_err().to_string();
    assert!(e.contains("draco.gltf") && e.contains("KHR_draco_mesh_compression"), "{e}");
}
