//! The colours of a glTF / GLB file: `COLOR_0` and each primitive's material
//! (`pbrMetallicRoughness.baseColorFactor` and `baseColorTexture`).

use std::collections::HashMap;
use std::path::Path;
use std::sync::Arc;

use gltf::accessor::{DataType, Dimensions};
use gltf::json::texture::WrappingMode;
use gltf::json::validation::Checked;

use super::image_io::{data_uri_bytes, decode_bytes, decode_file, percent_decode};
use super::{ColourImage, LoadedColours, Material, NO_MATERIAL, Rgb, SurfaceColours, finish_surface};
use crate::error::GeometryError;
use crate::gltf_io::{GltfScene, check_accessor, load_gltf_scene};

/// Reads the mesh (exactly [`crate::load_mesh`]'s), its `COLOR_0` and its materials.
pub(super) fn gltf_colours(path: &Path) -> Result<LoadedColours, GeometryError> {
    GeometryError::require_file(path)?;
    let scene = load_gltf_scene(path)?;
    let file = path.display().to_string();
    let mut warnings = Vec::new();
    let vertex_colours = vertex_colours(&scene, &file, &mut warnings);

    let meshes: Vec<gltf::Mesh> = scene.document.meshes().collect();
    let mut face_material = vec![NO_MATERIAL; scene.mesh.triangles.len()];
    let n_materials = scene.document.materials().len();
    let mut used = vec![false; n_materials];
    for pf in &scene.primitives {
        let material = meshes
            .get(pf.mesh)
            .and_then(|m| m.primitives().nth(pf.primitive))
            .and_then(|p| p.material().index())
            .filter(|&m| m < n_materials);
        if let Some(m) = material {
            used[m] = true;
            face_material[pf.faces.clone()].fill(m as u32);
        }
    }

    let root = scene.document.as_json();
    if used.iter().any(|&u| u) && scene.document.extensions_used().any(|e| e == "KHR_texture_transform") {
        warnings.push(format!(
            "{file}: uses KHR_texture_transform, which is ignored: textures are sampled without their transforms"
        ));
    }
    let mut images = ImageCache { path, scene: &scene, decoded: HashMap::new() };
    let materials = root
        .materials
        .iter()
        .enumerate()
        .map(|(i, m)| {
            let name = m.name.clone().unwrap_or_default();
            // The factor is linear light (glTF spec), our colours are sRGB-encoded values.
            let [r, g, b] = {
                let [r, g, b, _] = m.pbr_metallic_roughness.base_color_factor.0;
                [r, g, b].map(super::linear_to_srgb)
            };
            let texture = match (&m.pbr_metallic_roughness.base_color_texture, used[i]) {
                (Some(info), true) => {
                    let what = format!("{file}: material {i} (`{name}`)");
                    if info.tex_coord != 0 {
                        warnings.push(format!(
                            "{what}: its baseColorTexture uses TEXCOORD_{}, but only TEXCOORD_0 is read; the texture is ignored",
                            info.tex_coord
                        ));
                        None
                    } else if scene.mesh.uv.is_none() {
                        warnings.push(format!(
                            "{what} has a baseColorTexture but the mesh has no TEXCOORD_0 on every primitive; the texture is ignored"
                        ));
                        None
                    } else {
                        texture(root, info.index.value(), &what, &mut images, &mut warnings)
                    }
                }
                _ => None,
            };
            Material { name, base_colour: [r, g, b], texture }
        })
        .collect();
    drop(images);
    let surface = SurfaceColours { mesh: scene.mesh, vertex_colours, materials, face_material };
    Ok(finish_surface(surface, warnings))
}

/// `COLOR_0` of every primitive that has a readable one, white for the others; `None` when none
/// has.
fn vertex_colours(scene: &GltfScene, file: &str, warnings: &mut Vec<String>) -> Option<Vec<Rgb>> {
    let meshes: Vec<gltf::Mesh> = scene.document.meshes().collect();
    let mut colours = vec![[1.0; 3]; scene.mesh.positions.len()];
    let mut any = false;
    for pf in &scene.primitives {
        let Some(prim) = meshes.get(pf.mesh).and_then(|m| m.primitives().nth(pf.primitive)) else { continue };
        let Some(acc) = prim.get(&gltf::Semantic::Colors(0)) else { continue };
        match read_colour_0(&prim, &acc, &scene.buffers, pf.vertices.len()) {
            Ok(c) => {
                colours[pf.vertices.clone()].copy_from_slice(&c);
                any = true;
            }
            Err(problem) => warnings.push(format!(
                "{file}: mesh {} primitive {}: {problem}; its vertices are taken as white",
                pf.mesh, pf.primitive
            )),
        }
    }
    any.then_some(colours)
}

/// One primitive's `COLOR_0` as RGB, after checking the accessor as [`crate::gltf_io`] does.
fn read_colour_0(
    prim: &gltf::Primitive,
    acc: &gltf::Accessor,
    buffers: &[gltf::buffer::Data],
    vertices: usize,
) -> Result<Vec<Rgb>, String> {
    let dims = match acc.dimensions() {
        d @ (Dimensions::Vec3 | Dimensions::Vec4) => d,
        other => return Err(format!("COLOR_0 accessor {} is {other:?}; expected VEC3 or VEC4", acc.index())),
    };
    check_accessor(acc, "COLOR_0", dims, &[DataType::F32, DataType::U8, DataType::U16])?;
    let reader = prim.reader(|b| buffers.get(b.index()).map(|d| &d.0[..]));
    let colours: Vec<Rgb> = reader.read_colors(0).ok_or("COLOR_0 data is missing")?.into_rgb_f32().collect();
    if colours.len() != vertices {
        return Err(format!("COLOR_0 has {} entries but there are {vertices} vertices", colours.len()));
    }
    // COLOR_0 is linear light (glTF spec); our colours are sRGB-encoded values.
    let encode = |x: f32| if x.is_finite() { super::linear_to_srgb(x.clamp(0.0, 1.0)) } else { 0.0 };
    Ok(colours.into_iter().map(|c| c.map(encode)).collect())
}

/// Decoded images by index (`None`: could not be used, already warned about).
struct ImageCache<'a> {
    path: &'a Path,
    scene: &'a GltfScene,
    decoded: HashMap<usize, Option<Arc<ColourImage>>>,
}

/// The decoded image of texture `t`, or `None` with a warning (prefixed `what`).
fn texture(
    root: &gltf::json::Root,
    t: usize,
    what: &str,
    images: &mut ImageCache,
    warnings: &mut Vec<String>,
) -> Option<Arc<ColourImage>> {
    let Some(tex) = root.textures.get(t) else {
        warnings.push(format!("{what}: texture {t} does not exist"));
        return None;
    };
    let sampler = tex.sampler.and_then(|s| root.samplers.get(s.value()));
    if let Some(s) = sampler {
        let wraps = [s.wrap_s, s.wrap_t];
        if wraps.iter().any(|w| !matches!(w, Checked::Valid(WrappingMode::Repeat))) {
            warnings.push(format!(
                "{what}: texture {t}'s sampler does not repeat (wrapS/wrapT); it is sampled with REPEAT"
            ));
        }
    }
    let i = tex.source.value();
    if !images.decoded.contains_key(&i) {
        let decoded = match decode_image(root, i, images.path, images.scene) {
            Ok(img) => Some(Arc::new(img)),
            Err(problem) => {
                warnings.push(format!("{what}: image {i}: {problem}; the material keeps its base colour"));
                None
            }
        };
        images.decoded.insert(i, decoded);
    }
    images.decoded[&i].clone()
}

/// Decodes image `i` from a `data:` URI, a file next to the glTF, or a buffer view.
fn decode_image(
    root: &gltf::json::Root,
    i: usize,
    path: &Path,
    scene: &GltfScene,
) -> Result<ColourImage, String> {
    let image = root.images.get(i).ok_or_else(|| format!("image {i} does not exist"))?;
    let origin = format!("{} image {i}", path.display());
    if let Some(v) = image.buffer_view {
        let view = root
            .buffer_views
            .get(v.value())
            .ok_or_else(|| format!("buffer view {} does not exist", v.value()))?;
        let buffer = scene
            .buffers
            .get(view.buffer.value())
            .ok_or_else(|| format!("buffer {} does not exist", view.buffer.value()))?;
        let start = view.byte_offset.map_or(0, |o| o.0);
        let bytes = usize::try_from(start)
            .ok()
            .zip(usize::try_from(view.byte_length.0).ok())
            .and_then(|(s, n)| buffer.0.get(s..s.checked_add(n)?))
            .ok_or_else(|| format!("buffer view {} lies outside its buffer", v.value()))?;
        return decode_bytes(bytes, origin);
    }
    let uri = image.uri.as_deref().ok_or("has neither a uri nor a bufferView")?;
    if let Some(bytes) = data_uri_bytes(uri) {
        return decode_bytes(&bytes?, origin);
    }
    if uri.contains(':') {
        return Err(format!("the URI `{uri}` is not a relative path or a data URI"));
    }
    let name = percent_decode(uri).ok_or_else(|| format!("the URI `{uri}` has a malformed %-escape"))?;
    let file = super::relative_to(path, &name);
    decode_file(&file).map_err(|problem| format!("`{}`: {problem}", file.display()))
}
