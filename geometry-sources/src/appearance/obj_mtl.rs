//! The colours of an OBJ file: `v x y z r g b` vertex colours and the `Kd` / `map_Kd` of the MTL
//! files it names.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use super::{
    ColourImage, LoadedColours, Material, NO_MATERIAL, Rgb, SurfaceColours, finish_surface, relative_to,
};
use crate::error::GeometryError;

/// Reads the mesh (exactly [`crate::load_mesh`]'s), its vertex colours and its materials.
pub(super) fn obj_colours(path: &Path) -> Result<LoadedColours, GeometryError> {
    GeometryError::require_file(path)?;
    let read = crate::obj::load_obj_full(path, true)?;
    let (mesh, extra) = (read.mesh, read.appearance);
    let file = path.display();
    let mut warnings = Vec::new();

    let vertex_colours = vertex_colours(&extra.vertex_colours, mesh.positions.len(), |w| {
        warnings.push(format!("{file}: {w}"));
    });

    // Which MTL files exist, for the warnings tobj's errors cannot give (they name no file).
    let mut mtl_dirs: Vec<PathBuf> = Vec::new();
    for name in &extra.mtllibs {
        let mtl = relative_to(path, name);
        if mtl.is_file() {
            mtl_dirs.push(mtl.parent().map(Path::to_path_buf).unwrap_or_default());
        } else {
            warnings.push(format!(
                "{file}: material library `{name}` ({}) does not exist; its materials are ignored",
                mtl.display()
            ));
        }
    }
    let tobj_materials = match extra.materials {
        Some(Ok(m)) => m,
        Some(Err(e)) => {
            if extra.mtllibs.iter().all(|name| relative_to(path, name).is_file()) {
                warnings
                    .push(format!("{file}: cannot read its material libraries ({e}); materials are ignored"));
            }
            Vec::new()
        }
        None => Vec::new(),
    };
    // Textures are looked up next to the MTL files, then next to the OBJ.
    mtl_dirs.push(path.parent().map(Path::to_path_buf).unwrap_or_default());

    let face_material: Vec<u32> = extra
        .face_material
        .iter()
        .map(|m| match m {
            Some(i) if *i < tobj_materials.len() => *i as u32,
            _ => NO_MATERIAL,
        })
        .collect();
    let mut used = vec![false; tobj_materials.len()];
    for &m in &face_material {
        if m != NO_MATERIAL {
            used[m as usize] = true;
        }
    }
    let mut cache: HashMap<PathBuf, Option<Arc<ColourImage>>> = HashMap::new();
    let materials: Vec<Material> = tobj_materials
        .iter()
        .zip(&used)
        .map(|(m, &used)| {
            let texture = match (&m.diffuse_texture, used) {
                (Some(spec), true) => {
                    texture(path, &m.name, spec, &mtl_dirs, mesh.uv.is_some(), &mut cache, &mut warnings)
                }
                _ => None,
            };
            // With a texture, `Kd` is not applied: exporters write it beside `map_Kd` as a
            // fallback (Blender 0.8, photogrammetry tools 0.6), and importers show the texture
            // alone; multiplying would darken the carried-over colours.
            let base_colour = if texture.is_some() { [1.0; 3] } else { m.diffuse.unwrap_or([1.0; 3]) };
            Material { name: m.name.clone(), base_colour, texture }
        })
        .collect();
    let surface = SurfaceColours { mesh, vertex_colours, materials, face_material };
    Ok(finish_surface(surface, warnings))
}

/// The mesh's vertex colours scaled to `[0, 1]` (`0..=255` when any value exceeds 1), when every
/// vertex has one; `warn` hears why they are ignored when only some do.
pub(super) fn vertex_colours(
    raw: &[Option<[f32; 3]>],
    vertices: usize,
    mut warn: impl FnMut(String),
) -> Option<Vec<Rgb>> {
    let with = raw.iter().filter(|c| c.is_some()).count();
    if with == 0 {
        return None;
    }
    if with != raw.len() || raw.len() != vertices {
        warn(format!(
            "{with} of {} vertices have colours (`v x y z r g b`); vertex colours need all of them and are ignored",
            vertices.max(raw.len())
        ));
        return None;
    }
    let colours: Vec<Rgb> = raw.iter().flatten().copied().collect();
    Some(super::scale_colours(colours))
}

/// The texture a `map_Kd` line names, decoded, or `None` with a warning.
fn texture(
    obj: &Path,
    material: &str,
    spec: &str,
    dirs: &[PathBuf],
    has_uv: bool,
    cache: &mut HashMap<PathBuf, Option<Arc<ColourImage>>>,
    warnings: &mut Vec<String>,
) -> Option<Arc<ColourImage>> {
    let file = obj.display();
    let (name, options) = split_map_options(spec);
    if !options.is_empty() {
        warnings.push(format!(
            "{file}: material `{material}`: the options {} of `map_Kd {spec}` are ignored",
            options.join(" ")
        ));
    }
    if !has_uv {
        warnings.push(format!(
            "{file}: material `{material}` has the texture `{name}` but the mesh has no texture coordinates; the texture is ignored"
        ));
        return None;
    }
    // The first folder where the file exists (also trying `\` as a folder separator), else the
    // MTL's own folder, for the message.
    let candidates: Vec<PathBuf> = dirs
        .iter()
        .flat_map(|d| {
            let mut c = vec![d.join(name)];
            if name.contains('\\') {
                c.push(d.join(name.replace('\\', "/")));
            }
            c
        })
        .collect();
    let chosen = candidates.iter().find(|p| p.is_file()).unwrap_or(&candidates[0]).clone();
    cache
        .entry(chosen.clone())
        .or_insert_with(|| match super::image_io::decode_file(&chosen) {
            Ok(img) => Some(Arc::new(img)),
            Err(problem) => {
                warnings.push(format!(
                    "{file}: texture `{name}` ({}) of material `{material}`: {problem}; the material keeps its base colour",
                    chosen.display()
                ));
                None
            }
        })
        .clone()
}

/// Splits a `map_Kd` value into the file name and the options before it that change the mapping
/// (`-o`, `-s`, `-t`, `-clamp on`), which are not applied. Options are recognised only when the
/// value starts with `-`; then the last word is the file name. Without options the whole value is
/// the name (so names with spaces work).
fn split_map_options(spec: &str) -> (&str, Vec<String>) {
    let spec = spec.trim();
    if !spec.starts_with('-') {
        return (spec, Vec::new());
    }
    let words: Vec<&str> = spec.split_whitespace().collect();
    let name = words.last().copied().unwrap_or(spec);
    let mut ignored = Vec::new();
    let mut i = 0;
    while i + 1 < words.len() {
        let w = words[i];
        // Arguments run until the next option (or the file name).
        let args: Vec<&str> = words[i + 1..words.len() - 1]
            .iter()
            .take_while(|a| !a.starts_with('-') || a.parse::<f32>().is_ok())
            .copied()
            .collect();
        let changes_mapping = match w {
            "-o" | "-s" | "-t" => true,
            "-clamp" => args.first() == Some(&"on"),
            _ => false,
        };
        if changes_mapping {
            ignored.push(std::iter::once(w).chain(args.iter().copied()).collect::<Vec<_>>().join(" "));
        }
        i += 1 + args.len();
    }
    (name, ignored)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn map_options_precede_the_file_name() {
        assert_eq!(split_map_options("tex.png"), ("tex.png", vec![]));
        assert_eq!(split_map_options("my tex.png"), ("my tex.png", vec![]));
        assert_eq!(split_map_options("-bm 0.5 tex.png"), ("tex.png", vec![]));
        assert_eq!(
            split_map_options("-s 2 2 1 -o -0.5 0 0 -blendu off tex.png"),
            ("tex.png", vec!["-s 2 2 1".to_owned(), "-o -0.5 0 0".to_owned()])
        );
        assert_eq!(split_map_options("-clamp on tex.png"), ("tex.png", vec!["-clamp on".to_owned()]));
        assert_eq!(split_map_options("-clamp off tex.png"), ("tex.png", vec![]));
    }
}
