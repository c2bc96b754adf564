//! Tests of the appearance reader: every file is written by the test itself.

use std::io::Cursor;
use std::path::{Path, PathBuf};

use super::*;

fn write(dir: &Path, name: &str, bytes: impl AsRef<[u8]>) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

fn close(a: Rgb, b: Rgb, tol: f32) -> bool {
    (0..3).all(|k| (a[k] - b[k]).abs() <= tol)
}

fn assert_close(a: Rgb, b: Rgb, tol: f32) {
    assert!(close(a, b, tol), "{a:?} != {b:?}");
}

fn surface(loaded: &LoadedColours) -> &SurfaceColours {
    match &loaded.colours {
        Some(Colours::Surface(s)) => s,
        other => panic!("expected surface colours, got {other:?}"),
    }
}

fn points(loaded: &LoadedColours) -> &PointColours {
    match &loaded.colours {
        Some(Colours::Points(p)) => p,
        other => panic!("expected point colours, got {other:?}"),
    }
}

fn u8_colour(c: [u8; 3]) -> Rgb {
    c.map(|x| f32::from(x) / 255.0)
}

/// A 2×2 image: top row red, green; bottom row blue, white.
fn two_by_two() -> image::RgbImage {
    let mut img = image::RgbImage::new(2, 2);
    img.put_pixel(0, 0, image::Rgb([255, 0, 0]));
    img.put_pixel(1, 0, image::Rgb([0, 255, 0]));
    img.put_pixel(0, 1, image::Rgb([0, 0, 255]));
    img.put_pixel(1, 1, image::Rgb([255, 255, 255]));
    img
}

fn png_bytes(img: &image::RgbImage) -> Vec<u8> {
    let mut bytes = Cursor::new(Vec::new());
    img.write_to(&mut bytes, image::ImageFormat::Png).unwrap();
    bytes.into_inner()
}

fn base64(bytes: &[u8]) -> String {
    const ALPHABET: &[u8] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::new();
    for chunk in bytes.chunks(3) {
        let b = [chunk[0], *chunk.get(1).unwrap_or(&0), *chunk.get(2).unwrap_or(&0)];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for k in 0..4 {
            if k <= chunk.len() {
                out.push(ALPHABET[((n >> (18 - 6 * k)) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

// ---------------------------------------------------------------- ColourImage::sample

fn image(width: u32, height: u32, pixels: Vec<[u8; 3]>) -> ColourImage {
    ColourImage { origin: "test".into(), width, height, pixels }
}

#[test]
fn sampling_at_pixel_centres_returns_the_pixels() {
    let img = image(3, 2, vec![[10, 20, 30], [40, 50, 60], [70, 80, 90], [1, 2, 3], [4, 5, 6], [7, 8, 9]]);
    for j in 0..2 {
        for i in 0..3 {
            let uv = [(i as f32 + 0.5) / 3.0, 1.0 - (j as f32 + 0.5) / 2.0];
            assert_close(img.sample(uv), u8_colour(img.pixels[j * 3 + i]), 1e-6);
        }
    }
}

#[test]
fn sampling_between_pixels_is_bilinear() {
    let img = image(2, 1, vec![[0, 0, 0], [255, 255, 255]]);
    // Halfway between the two pixel centres (u = 0.25 and 0.75).
    assert_close(img.sample([0.5, 0.5]), [0.5; 3], 1e-6);
    assert_close(img.sample([0.375, 0.5]), [0.25; 3], 1e-6);
    // 2×2: the middle of the image averages all four.
    let img = image(2, 2, vec![[255, 0, 0], [0, 255, 0], [0, 0, 255], [255, 255, 255]]);
    assert_close(img.sample([0.5, 0.5]), [0.5; 3], 1e-6);
    // v up: v = 0.75 is the top row's centre.
    assert_close(img.sample([0.5, 0.75]), [0.5, 0.5, 0.0], 1e-6);
}

#[test]
fn sampling_wraps_around() {
    let img = image(2, 2, vec![[255, 0, 0], [0, 255, 0], [0, 0, 255], [255, 255, 255]]);
    for (u, v) in [(0.25, 0.75), (0.75, 0.25), (0.75, 0.75)] {
        for (du, dv) in [(1.0, 0.0), (-1.0, 0.0), (0.0, 3.0), (-2.0, -5.0)] {
            assert_close(img.sample([u + du, v + dv]), img.sample([u, v]), 1e-5);
        }
    }
    // At u = 0 the left and right columns blend (REPEAT, not clamp).
    let stripe = image(2, 1, vec![[0, 0, 0], [255, 255, 255]]);
    assert_close(stripe.sample([0.0, 0.5]), [0.5; 3], 1e-6);
    assert_close(stripe.sample([1.0, 0.5]), [0.5; 3], 1e-6);
    assert_close(stripe.sample([f32::NAN, 0.5]), [0.5; 3], 1e-6);
}

// ---------------------------------------------------------------- OBJ

#[test]
fn obj_vertex_colours_follow_the_file_vertex_order() {
    let dir = tempfile::tempdir().unwrap();
    // The faces use vertex 3 first and never use vertex 5 (as in obj.rs's order test).
    let unit = "v 0 0 0 1 0 0\nv 1 0 0 0 1 0\nv 1 1 0 0 0 1\nv 0 1 0 0.5 0.5 0.5\nv 9 9 9 0.25 0 1\nf 3 4 1\nf 3 -4 -5\n";
    let bytes = "v 0 0 0 255 0 0\nv 1 0 0 0 255 0\nv 1 1 0 0 0 255\nv 0 1 0 51 51 51\nv 9 9 9 0 0 0\nf 3 4 1\nf 3 -4 -5\n";
    for (name, text, want) in [
        ("unit.obj", unit, [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.5; 3], [0.25, 0.0, 1.0]]),
        ("bytes.obj", bytes, [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.2; 3], [0.0; 3]]),
    ] {
        let p = write(dir.path(), name, text);
        let loaded = load_colours(&p).unwrap();
        assert!(loaded.warnings.is_empty(), "{:?}", loaded.warnings);
        let s = surface(&loaded);
        assert_eq!(s.mesh, crate::load_mesh(&p).unwrap());
        let vc = s.vertex_colours.as_ref().unwrap();
        assert_eq!(vc.len(), 5);
        for (got, want) in vc.iter().zip(want) {
            assert_close(*got, want, 1e-6);
        }
        // Face 0 is vertices 3, 4, 1 of the file: its first corner is blue.
        assert_close(s.colour(0, [1.0, 0.0, 0.0]), [0.0, 0.0, 1.0], 1e-6);
        assert_close(s.colour(0, [0.0, 0.0, 1.0]), [1.0, 0.0, 0.0], 1e-6);
        assert_close(s.colour(0, [0.5, 0.0, 0.5]), [0.5, 0.0, 0.5], 1e-6);
        assert_eq!(s.face_material, vec![NO_MATERIAL; 2]);
    }
}

#[test]
fn obj_with_colours_on_only_some_vertices_warns_and_ignores_them() {
    let dir = tempfile::tempdir().unwrap();
    let p = write(dir.path(), "some.obj", "v 0 0 0 1 0 0\nv 1 0 0 0 1 0\nv 0 1 0 0 0 1\nv 5 5 5\nf 1 2 3\n");
    let loaded = load_colours(&p).unwrap();
    assert_eq!(loaded.colours, None);
    assert_eq!(loaded.warnings.len(), 1, "{:?}", loaded.warnings);
    assert!(loaded.warnings[0].contains("some.obj") && loaded.warnings[0].contains("3 of 4"));
}

/// A unit quad (two triangles) with UVs spanning [0, 1]², using material `mat`, and its MTL.
fn textured_quad(dir: &Path, name: &str, mtl: &str) -> PathBuf {
    write(dir, &format!("{name}.mtl"), mtl);
    write(
        dir,
        &format!("{name}.obj"),
        format!(
            "mtllib {name}.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nusemtl mat\nf 1/1 2/2 3/3\nf 1/1 3/3 4/4\n"
        ),
    )
}

#[test]
fn obj_texture_is_sampled_through_the_uvs() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir(dir.path().join("tex")).unwrap();
    two_by_two().save(dir.path().join("tex/colours.png")).unwrap();
    let p = textured_quad(dir.path(), "quad", "newmtl mat\nKd 1 1 1\nmap_Kd tex/colours.png\n");
    let loaded = load_colours(&p).unwrap();
    assert!(loaded.warnings.is_empty(), "{:?}", loaded.warnings);
    let s = surface(&loaded);
    assert_eq!(s.mesh, crate::load_mesh(&p).unwrap());
    assert_eq!(s.face_material, vec![0, 0]);
    let tex = s.materials[0].texture.as_ref().unwrap();
    assert_eq!((tex.width, tex.height), (2, 2));
    assert!(tex.origin.ends_with("colours.png"), "{}", tex.origin);
    // Face 0 has UVs (0,0), (1,0), (1,1): bary (0.25, 0.5, 0.25) is uv (0.75, 0.25), the centre of
    // the bottom-right pixel (white); (0.25, 0.0, 0.75) is uv (0.75, 0.75), top-right (green).
    assert_close(s.colour(0, [0.25, 0.5, 0.25]), [1.0; 3], 1e-5);
    assert_close(s.colour(0, [0.25, 0.0, 0.75]), [0.0, 1.0, 0.0], 1e-5);
    // Face 1 has UVs (0,0), (1,1), (0,1): uv (0.25, 0.75) is top-left (red).
    assert_close(s.colour(1, [0.25, 0.25, 0.5]), [1.0, 0.0, 0.0], 1e-5);

    // Kd is not applied over a texture (exporters write it as a fallback); options before the
    // name are skipped (scale warned about).
    let p = textured_quad(
        dir.path(),
        "dark",
        "newmtl mat\nKd 0.5 0.5 0.5\nmap_Kd -s 1 1 1 -bm 1 tex/colours.png\n",
    );
    let loaded = load_colours(&p).unwrap();
    assert_eq!(loaded.warnings.len(), 1, "{:?}", loaded.warnings);
    assert!(loaded.warnings[0].contains("-s 1 1 1"), "{:?}", loaded.warnings);
    assert_close(surface(&loaded).colour(0, [0.25, 0.5, 0.25]), [1.0; 3], 1e-5);
}

#[test]
fn obj_jpeg_texture_decodes() {
    let dir = tempfile::tempdir().unwrap();
    let img = image::RgbImage::from_pixel(8, 8, image::Rgb([200, 100, 50]));
    img.save(dir.path().join("flat.jpg")).unwrap();
    let p = textured_quad(dir.path(), "jpeg", "newmtl mat\nmap_Kd flat.jpg\n");
    let loaded = load_colours(&p).unwrap();
    assert!(loaded.warnings.is_empty(), "{:?}", loaded.warnings);
    assert_close(surface(&loaded).colour(1, [0.3, 0.3, 0.4]), u8_colour([200, 100, 50]), 3.0 / 255.0);
}

#[test]
fn a_16_bit_grey_alpha_texture_becomes_rgb() {
    let dir = tempfile::tempdir().unwrap();
    let img = image::ImageBuffer::<image::LumaA<u16>, _>::from_pixel(4, 4, image::LumaA([65535 / 5, 100]));
    img.save(dir.path().join("grey.png")).unwrap();
    let p = textured_quad(dir.path(), "grey", "newmtl mat\nmap_Kd grey.png\n");
    let loaded = load_colours(&p).unwrap();
    assert!(loaded.warnings.is_empty(), "{:?}", loaded.warnings);
    assert_close(surface(&loaded).colour(0, [0.2, 0.3, 0.5]), [0.2; 3], 1.0 / 255.0);
}

#[test]
fn missing_or_corrupt_textures_are_warnings() {
    let dir = tempfile::tempdir().unwrap();
    let p = textured_quad(dir.path(), "missing", "newmtl mat\nKd 0.5 0.5 0.5\nmap_Kd gone.png\n");
    let loaded = load_colours(&p).unwrap();
    assert_eq!(loaded.colours, None, "one base colour and no texture carry nothing");
    assert_eq!(loaded.warnings.len(), 1, "{:?}", loaded.warnings);
    let w = &loaded.warnings[0];
    assert!(w.contains("missing.obj") && w.contains("gone.png") && w.contains("does not exist"), "{w}");

    write(dir.path(), "corrupt.png", b"\x89PNG\r\n\x1a\nnot really a png at all");
    write(dir.path(), "text.png", b"hello");
    for name in ["corrupt.png", "text.png"] {
        let p = textured_quad(dir.path(), "bad", &format!("newmtl mat\nmap_Kd {name}\n"));
        let loaded = load_colours(&p).unwrap();
        assert_eq!(loaded.colours, None);
        assert_eq!(loaded.warnings.len(), 1, "{:?}", loaded.warnings);
        assert!(loaded.warnings[0].contains(name), "{:?}", loaded.warnings);
    }

    // With vertex colours the surface still carries colour; the material keeps its base colour.
    write(dir.path(), "vc.mtl", "newmtl mat\nKd 0.5 0.5 0.5\nmap_Kd gone.png\n");
    let p = write(
        dir.path(),
        "vc.obj",
        "mtllib vc.mtl\nv 0 0 0 1 1 1\nv 1 0 0 1 1 1\nv 0 1 0 1 1 1\nvt 0 0\nusemtl mat\nf 1/1 2/1 3/1\n",
    );
    let loaded = load_colours(&p).unwrap();
    assert_eq!(loaded.warnings.len(), 1);
    let s = surface(&loaded);
    assert_eq!(s.materials[0].texture, None);
    assert_close(s.colour(0, [1.0 / 3.0; 3]), [0.5; 3], 1e-6);
}

#[test]
fn a_missing_mtl_file_is_a_warning() {
    let dir = tempfile::tempdir().unwrap();
    let p = write(
        dir.path(),
        "nomtl.obj",
        "mtllib nowhere.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl red\nf 1 2 3\n",
    );
    let loaded = load_colours(&p).unwrap();
    assert_eq!(loaded.colours, None);
    assert_eq!(loaded.warnings.len(), 1, "{:?}", loaded.warnings);
    assert!(loaded.warnings[0].contains("nowhere.mtl"), "{:?}", loaded.warnings);
}

#[test]
fn a_texture_without_uvs_is_dropped_with_a_warning() {
    let dir = tempfile::tempdir().unwrap();
    two_by_two().save(dir.path().join("t.png")).unwrap();
    write(dir.path(), "nouv.mtl", "newmtl mat\nmap_Kd t.png\n");
    let p =
        write(dir.path(), "nouv.obj", "mtllib nouv.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl mat\nf 1 2 3\n");
    let loaded = load_colours(&p).unwrap();
    assert_eq!(loaded.colours, None);
    assert!(loaded.warnings[0].contains("no texture coordinates"), "{:?}", loaded.warnings);
}

#[test]
fn several_material_colours_are_colour_and_one_is_not() {
    let dir = tempfile::tempdir().unwrap();
    write(dir.path(), "two.mtl", "newmtl red\nKd 1 0 0\nnewmtl blue\nKd 0 0 1\n");
    let two =
        "mtllib two.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nusemtl red\nf 1 2 3\nusemtl blue\nf 1 3 4\n";
    let p = write(dir.path(), "two.obj", two);
    let loaded = load_colours(&p).unwrap();
    assert!(loaded.warnings.is_empty(), "{:?}", loaded.warnings);
    let s = surface(&loaded);
    assert_eq!(s.materials.len(), 2);
    assert_eq!(s.face_material, vec![0, 1]);
    assert_eq!(s.colour(0, [0.2, 0.3, 0.5]), [1.0, 0.0, 0.0]);
    assert_eq!(s.colour(1, [0.2, 0.3, 0.5]), [0.0, 0.0, 1.0]);

    let one = two.replace("usemtl blue", "usemtl red");
    let p = write(dir.path(), "one.obj", one);
    assert_eq!(load_colours(&p).unwrap(), LoadedColours { colours: None, warnings: vec![] });

    // One material on some faces and none on the others: two colours (white counts).
    let partial = "mtllib two.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3\nusemtl red\nf 1 3 4\n";
    let p = write(dir.path(), "partial.obj", partial);
    let s = load_colours(&p).unwrap();
    let s = surface(&s);
    assert_eq!(s.colour(0, [1.0, 0.0, 0.0]), [1.0; 3]);
    assert_eq!(s.colour(1, [1.0, 0.0, 0.0]), [1.0, 0.0, 0.0]);
}

// ---------------------------------------------------------------- glTF

fn f32_bytes(values: &[f32]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

/// Two primitives of one mesh, each one triangle: the first with COLOR_0 (float VEC3), the second
/// with COLOR_0 as normalised unsigned bytes (VEC4) when `second_coloured`.
fn gltf_with_colours(second_coloured: bool) -> String {
    let positions = f32_bytes(&[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0]);
    let colours = f32_bytes(&[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]);
    let bytes_colours: Vec<u8> = vec![255, 0, 0, 255, 0, 255, 0, 255, 51, 51, 51, 255];
    let mut buffer = positions.clone();
    buffer.extend(&colours);
    buffer.extend(&bytes_colours);
    let second = if second_coloured { r#", "COLOR_0": 2"# } else { "" };
    format!(
        r#"{{"asset": {{"version": "2.0"}},
  "buffers": [{{"uri": "data:application/octet-stream;base64,{}", "byteLength": {}}}],
  "bufferViews": [{{"buffer": 0, "byteLength": 36}}, {{"buffer": 0, "byteOffset": 36, "byteLength": 36}},
                  {{"buffer": 0, "byteOffset": 72, "byteLength": 12}}],
  "accessors": [
    {{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0,0,0], "max": [1,1,0]}},
    {{"bufferView": 1, "componentType": 5126, "count": 3, "type": "VEC3"}},
    {{"bufferView": 2, "componentType": 5121, "normalized": true, "count": 3, "type": "VEC4"}}],
  "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0, "COLOR_0": 1}}}},
                             {{"attributes": {{"POSITION": 0{second}}}}}]}}],
  "nodes": [{{"mesh": 0}}], "scenes": [{{"nodes": [0]}}]}}"#,
        base64(&buffer),
        buffer.len()
    )
}

#[test]
fn gltf_color_0_becomes_vertex_colours() {
    let dir = tempfile::tempdir().unwrap();
    let p = write(dir.path(), "coloured.gltf", gltf_with_colours(true));
    let loaded = load_colours(&p).unwrap();
    assert!(loaded.warnings.is_empty(), "{:?}", loaded.warnings);
    let s = surface(&loaded);
    assert_eq!(s.mesh, crate::load_mesh(&p).unwrap());
    let vc = s.vertex_colours.as_ref().unwrap();
    let want =
        [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [SRGB_0_2; 3]];
    assert_eq!(vc.len(), 6);
    for (got, want) in vc.iter().zip(want) {
        assert_close(*got, want, 1e-6);
    }
    assert_close(s.colour(0, [0.5, 0.5, 0.0]), [0.5, 0.5, 0.0], 1e-6);
    assert_close(s.colour(1, [0.0, 0.0, 1.0]), [SRGB_0_2; 3], 1e-6);

    // A primitive without COLOR_0 is white.
    let p = write(dir.path(), "half.gltf", gltf_with_colours(false));
    let loaded = load_colours(&p).unwrap();
    let vc = surface(&loaded).vertex_colours.clone().unwrap();
    assert_eq!(&vc[3..], &[[1.0; 3]; 3]);
    assert_close(vc[1], [0.0, 1.0, 0.0], 0.0);
}

/// Linear 0.2 and 0.5 in sRGB encoding (IEC 61966-2-1: 1.055 x^(1/2.4) − 0.055), as glTF's
/// linear `COLOR_0` and `baseColorFactor` are read.
const SRGB_0_2: f32 = 0.484_529_2;
const SRGB_0_5: f32 = 0.735_357;

/// A triangle with TEXCOORD_0 whose material has `baseColorFactor` and the texture `image` (a JSON
/// object), with `extra` appended to the buffer (for a GLB's image) and `tex_coord`.
fn textured_gltf(
    image: &str,
    factor: [f32; 3],
    tex_coord: u32,
    buffer_uri: Option<&str>,
    extra: usize,
) -> String {
    let positions = f32_bytes(&[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0]);
    // glTF's v points down: these are OBJ-convention uvs (0.75, 0.25), (0.25, 0.75), (0.75, 0.75).
    let uvs = f32_bytes(&[0.75, 0.75, 0.25, 0.25, 0.75, 0.25]);
    let mut buffer = positions;
    buffer.extend(&uvs);
    let uri = match buffer_uri {
        Some(uri) => format!(r#""uri": "{uri}", "#),
        None => format!(r#""uri": "data:application/octet-stream;base64,{}", "#, base64(&buffer)),
    };
    format!(
        r#"{{"asset": {{"version": "2.0"}},
  "buffers": [{{{uri}"byteLength": {}}}],
  "bufferViews": [{{"buffer": 0, "byteLength": 36}}, {{"buffer": 0, "byteOffset": 36, "byteLength": 24}}{}],
  "accessors": [
    {{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0,0,0], "max": [1,1,0]}},
    {{"bufferView": 1, "componentType": 5126, "count": 3, "type": "VEC2"}}],
  "images": [{image}],
  "textures": [{{"source": 0}}],
  "materials": [{{"name": "painted", "pbrMetallicRoughness": {{"baseColorFactor": [{}, {}, {}, 1],
                  "baseColorTexture": {{"index": 0, "texCoord": {tex_coord}}}}}}}],
  "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0, "TEXCOORD_0": 1}}, "material": 0}}]}}],
  "nodes": [{{"mesh": 0}}], "scenes": [{{"nodes": [0]}}]}}"#,
        60 + extra,
        if extra > 0 {
            format!(r#", {{"buffer": 0, "byteOffset": 60, "byteLength": {extra}}}"#)
        } else {
            String::new()
        },
        factor[0],
        factor[1],
        factor[2],
    )
}

#[test]
fn gltf_embedded_texture_is_sampled_in_the_obj_convention() {
    let dir = tempfile::tempdir().unwrap();
    let png = png_bytes(&two_by_two());
    let image = format!(r#"{{"uri": "data:image/png;base64,{}"}}"#, base64(&png));
    let p = write(dir.path(), "textured.gltf", textured_gltf(&image, [1.0, 0.5, 1.0], 0, None, 0));
    let loaded = load_colours(&p).unwrap();
    assert!(loaded.warnings.is_empty(), "{:?}", loaded.warnings);
    let s = surface(&loaded);
    assert_eq!(s.mesh, crate::load_mesh(&p).unwrap());
    assert_eq!(s.vertex_colours, None);
    assert_eq!(s.materials[0].name, "painted");
    assert_close(s.materials[0].base_colour, [1.0, SRGB_0_5, 1.0], 1e-6);
    // Corner 0: uv (0.75, 0.25) bottom-right (white); corner 1: (0.25, 0.75) top-left (red);
    // corner 2: (0.75, 0.75) top-right (green); times the factor.
    assert_close(s.colour(0, [1.0, 0.0, 0.0]), [1.0, SRGB_0_5, 1.0], 1e-5);
    assert_close(s.colour(0, [0.0, 1.0, 0.0]), [1.0, 0.0, 0.0], 1e-5);
    assert_close(s.colour(0, [0.0, 0.0, 1.0]), [0.0, SRGB_0_5, 0.0], 1e-5);

    // An external image next to the file, and a missing one (a warning naming it).
    two_by_two().save(dir.path().join("my tex.png")).unwrap();
    let p =
        write(dir.path(), "external.gltf", textured_gltf(r#"{"uri": "my%20tex.png"}"#, [1.0; 3], 0, None, 0));
    let loaded = load_colours(&p).unwrap();
    assert!(loaded.warnings.is_empty(), "{:?}", loaded.warnings);
    assert_close(surface(&loaded).colour(0, [0.0, 1.0, 0.0]), [1.0, 0.0, 0.0], 1e-5);
    let p = write(dir.path(), "lost.gltf", textured_gltf(r#"{"uri": "lost.png"}"#, [1.0; 3], 0, None, 0));
    let loaded = load_colours(&p).unwrap();
    assert_eq!(loaded.colours, None);
    assert!(loaded.warnings[0].contains("lost.png"), "{:?}", loaded.warnings);

    // texCoord 1 is not read: the texture is dropped with a warning.
    let p = write(dir.path(), "tc1.gltf", textured_gltf(&image, [1.0; 3], 1, None, 0));
    let loaded = load_colours(&p).unwrap();
    assert_eq!(loaded.colours, None);
    assert!(loaded.warnings[0].contains("TEXCOORD_1"), "{:?}", loaded.warnings);
}

/// A GLB holding `json` and the binary chunk `bin`.
fn glb(json: &str, bin: &[u8]) -> Vec<u8> {
    let mut json = json.as_bytes().to_vec();
    while !json.len().is_multiple_of(4) {
        json.push(b' ');
    }
    let mut bin = bin.to_vec();
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let total = 12 + 8 + json.len() + 8 + bin.len();
    let mut out = Vec::new();
    out.extend(b"glTF");
    out.extend(2u32.to_le_bytes());
    out.extend((total as u32).to_le_bytes());
    out.extend((json.len() as u32).to_le_bytes());
    out.extend(b"JSON");
    out.extend(json);
    out.extend((bin.len() as u32).to_le_bytes());
    out.extend(b"BIN\0");
    out.extend(bin);
    out
}

#[test]
fn glb_texture_in_a_buffer_view_decodes() {
    let dir = tempfile::tempdir().unwrap();
    let png = png_bytes(&two_by_two());
    let json =
        textured_gltf(r#"{"bufferView": 2, "mimeType": "image/png"}"#, [1.0; 3], 0, Some(""), png.len());
    let json = json.replace(r#""uri": "", "#, "");
    let mut bin = f32_bytes(&[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0]);
    bin.extend(f32_bytes(&[0.75, 0.75, 0.25, 0.25, 0.75, 0.25]));
    bin.extend(&png);
    let p = write(dir.path(), "model.glb", glb(&json, &bin));
    let loaded = load_colours(&p).unwrap();
    assert!(loaded.warnings.is_empty(), "{:?}", loaded.warnings);
    let s = surface(&loaded);
    assert_eq!(s.mesh, crate::load_mesh(&p).unwrap());
    assert!(s.materials[0].texture.as_ref().unwrap().origin.ends_with("model.glb image 0"));
    assert_close(s.colour(0, [0.0, 0.0, 1.0]), [0.0, 1.0, 0.0], 1e-5);

    // A corrupt embedded image is a warning, not an error.
    let mut bad = bin.clone();
    let n = bad.len();
    bad[n - 40..].fill(7);
    let p = write(dir.path(), "corrupt.glb", glb(&json, &bad));
    let loaded = load_colours(&p).unwrap();
    assert_eq!(loaded.colours, None);
    assert!(loaded.warnings[0].contains("corrupt.glb") && loaded.warnings[0].contains("image 0"));
}

// ---------------------------------------------------------------- points

#[test]
fn ply_red_green_blue_are_point_colours() {
    let dir = tempfile::tempdir().unwrap();
    let header =
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n";
    let p = write(
        dir.path(),
        "c.ply",
        format!(
            "{header}property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n0 0 0 255 0 0\n1 0 0 0 51 0\n0 1 0 0 0 255\n"
        ),
    );
    let loaded = load_colours(&p).unwrap();
    assert!(loaded.warnings.is_empty());
    let pc = points(&loaded);
    assert_eq!(pc.positions, crate::point_cloud::read_points(&p).unwrap().positions);
    assert_eq!(pc.colours, vec![[1.0, 0.0, 0.0], [0.0, 0.2, 0.0], [0.0, 0.0, 1.0]]);

    let p = write(
        dir.path(),
        "f.ply",
        format!(
            "{header}property float r\nproperty float g\nproperty float b\nend_header\n0 0 0 0.5 0.25 1\n1 0 0 0 0 0\n0 1 0 1 1 1\n"
        ),
    );
    assert_eq!(points(&load_colours(&p).unwrap()).colours[0], [0.5, 0.25, 1.0]);

    let p = write(dir.path(), "plain.ply", format!("{header}end_header\n0 0 0\n1 0 0\n0 1 0\n"));
    assert_eq!(load_colours(&p).unwrap(), LoadedColours { colours: None, warnings: vec![] });
    let p = write(
        dir.path(),
        "red.ply",
        format!("{header}property uchar red\nend_header\n0 0 0 1\n1 0 0 2\n0 1 0 3\n"),
    );
    let loaded = load_colours(&p).unwrap();
    assert_eq!(loaded.colours, None);
    assert!(loaded.warnings[0].contains("red.ply"), "{:?}", loaded.warnings);
}

#[test]
fn xyz_with_nine_columns_has_colours_and_normals() {
    let dir = tempfile::tempdir().unwrap();
    let p = write(dir.path(), "c.xyz", "0 0 0 0 0 1 255 0 0\n1 0 0 0 0 1 0 51 0\n");
    let loaded = load_colours(&p).unwrap();
    let pc = points(&loaded);
    assert_eq!(pc.positions, vec![[0.0; 3], [1.0, 0.0, 0.0]]);
    assert_eq!(pc.colours, vec![[1.0, 0.0, 0.0], [0.0, 0.2, 0.0]]);
    let set = crate::xyz::read_xyz(&p).unwrap();
    assert_eq!(set.normals, Some(vec![[0.0, 0.0, 1.0]; 2]));
    let p = write(dir.path(), "u.txt", "0 0 0 0 0 1 1 0.5 0\n");
    assert_eq!(points(&load_colours(&p).unwrap()).colours, vec![[1.0, 0.5, 0.0]]);
    let p = write(dir.path(), "n.xyz", "0 0 0 0 0 1\n");
    assert_eq!(load_colours(&p).unwrap().colours, None);
}

#[test]
fn other_inputs_have_no_colour_and_broken_geometry_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let p = write(dir.path(), "grid.npy", b"\x93NUMPY");
    assert_eq!(load_colours(&p).unwrap(), LoadedColours { colours: None, warnings: vec![] });
    let p = write(dir.path(), "broken.obj", "");
    assert!(load_colours(&p).unwrap_err().to_string().contains("broken.obj"));
    assert!(load_colours(&dir.path().join("absent.ply")).is_err());
}

// ---------------------------------------------------------------- NearestColour

#[test]
fn nearest_colour_is_sync() {
    fn sync<T: Send + Sync>() {}
    sync::<NearestColour>();
    sync::<Colours>();
}

#[test]
fn nearest_surface_colour_is_the_colour_of_the_face_below() {
    // Two triangles side by side in z = 0, red and blue through two materials.
    let mesh = TriMesh {
        positions: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [2.0, 0.0, 0.0], [2.0, 1.0, 0.0]],
        triangles: vec![[0, 1, 2], [1, 3, 4], [0, 0, 1]],
        uv: None,
    };
    let material = |name: &str, c: Rgb| Material { name: name.into(), base_colour: c, texture: None };
    let colours = Colours::Surface(SurfaceColours {
        mesh,
        vertex_colours: None,
        materials: vec![material("red", [1.0, 0.0, 0.0]), material("blue", [0.0, 0.0, 1.0])],
        face_material: vec![0, 1, 1],
    });
    let frame = Similarity { center: [1.0, 0.5, 0.0], scale: 2.0 };
    let nearest = NearestColour::new(&colours, &frame);
    // Above the first face (input (0.8, 0.3, 0.5)) and above the second ((1.6, 0.3, -0.2)).
    assert_eq!(nearest.colour_at(frame.apply([0.8, 0.3, 0.5])), [1.0, 0.0, 0.0]);
    assert_eq!(nearest.colour_at(frame.apply([1.6, 0.3, -0.2])), [0.0, 0.0, 1.0]);
    // Beyond the far edge the nearest point is still on the blue face.
    assert_eq!(nearest.colour_at(frame.apply([3.0, 0.2, 0.0])), [0.0, 0.0, 1.0]);

    // With vertex colours the barycentrics come through: a gradient along x.
    let Colours::Surface(mut s) = colours else { unreachable!() };
    s.materials.clear();
    s.face_material = vec![NO_MATERIAL; 3];
    s.vertex_colours = Some(vec![[0.0; 3], [0.5; 3], [0.5; 3], [1.0; 3], [1.0; 3]]);
    let nearest = NearestColour::new(&Colours::Surface(s), &Similarity::IDENTITY);
    assert_close(nearest.colour_at([1.5, 0.25, 1.0]), [0.75; 3], 1e-5);
    assert_close(nearest.colour_at([0.9, 0.5, -1.0]), [0.45; 3], 1e-5);
}

#[test]
fn nearest_point_colour_is_exact_on_a_point_and_weighted_between() {
    let colours = Colours::Points(PointColours {
        positions: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0], [5.0, 5.0, 5.0]],
        colours: vec![[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 1.0, 1.0], [0.0; 3]],
    });
    let frame = Similarity { center: [0.5, 0.5, 0.0], scale: 3.0 };
    let nearest = NearestColour::new(&colours, &frame);
    assert_eq!(nearest.colour_at(frame.apply([1.0, 0.0, 0.0])), [0.0, 1.0, 0.0]);
    assert_eq!(nearest.colour_at(frame.apply([0.0, 1.0, 0.0])), [0.0, 0.0, 1.0]);
    // The centre of the square is equally far from its four corners: their mean.
    assert_close(nearest.colour_at(frame.apply([0.5, 0.5, 0.0])), [0.5, 0.5, 0.5], 1e-5);
    // Close to a corner, that corner dominates.
    let c = nearest.colour_at(frame.apply([0.01, 0.0, 0.0]));
    assert!(c[0] > 0.99 && c[1] < 0.01, "{c:?}");
    assert_eq!(
        NearestColour::new(&Colours::Points(PointColours::default()), &frame).colour_at([0.0; 3]),
        [1.0; 3]
    );
}

#[test]
fn a_ply_mesh_has_surface_colours_and_a_ply_without_faces_point_colours() {
    let dir = tempfile::tempdir().unwrap();
    let header = |faces: usize| {
        format!(
            "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n\
             property uchar red\nproperty uchar green\nproperty uchar blue\nelement face {faces}\n\
             property list uchar int vertex_indices\nend_header\n0 0 0 255 0 0\n1 0 0 0 255 0\n0 1 0 0 0 255\n"
        )
    };
    let mesh = write(dir.path(), "mesh.ply", format!("{}3 0 1 2\n", header(1)));
    let loaded = load_colours(&mesh).unwrap();
    let s = surface(&loaded);
    assert_eq!(s.mesh, crate::load_mesh(&mesh).unwrap());
    assert_close(s.colour(0, [0.5, 0.5, 0.0]), [0.5, 0.5, 0.0], 1e-6);
    let cloud = write(dir.path(), "cloud.ply", header(0));
    match load_colours(&cloud).unwrap().colours {
        Some(Colours::Points(p)) => assert_eq!(p.colours[2], [0.0, 0.0, 1.0]),
        other => panic!("{other:?}"),
    }
}
