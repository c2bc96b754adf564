//! Decoding texture images (PNG, JPEG) into [`ColourImage`]s, and the small URI helpers glTF
//! images need (base64 `data:` URIs, percent-encoded relative paths).

use std::io::{BufRead, Cursor, Seek};
use std::path::Path;

use image::{ImageReader, Limits};

use super::ColourImage;

/// The largest width and height accepted; larger images are refused before decoding.
pub(crate) const MAX_SIDE: u32 = 16384;

/// Decodes the image file at `path`; the error is a sentence without the file name.
pub(crate) fn decode_file(path: &Path) -> Result<ColourImage, String> {
    let open = || -> Result<ImageReader<std::io::BufReader<std::fs::File>>, String> {
        let reader = ImageReader::open(path).map_err(|e| match e.kind() {
            std::io::ErrorKind::NotFound => "the file does not exist".to_owned(),
            _ => format!("cannot open it: {e}"),
        })?;
        reader.with_guessed_format().map_err(|e| format!("cannot read it: {e}"))
    };
    if path.is_dir() {
        return Err("is a directory, not an image".into());
    }
    decode(open, path.display().to_string())
}

/// Decodes an image held in memory; `origin` names it in the result.
pub(crate) fn decode_bytes(bytes: &[u8], origin: String) -> Result<ColourImage, String> {
    let open = || -> Result<ImageReader<Cursor<&[u8]>>, String> {
        ImageReader::new(Cursor::new(bytes)).with_guessed_format().map_err(|e| format!("cannot read it: {e}"))
    };
    decode(open, origin)
}

/// Reads the header (refusing unknown formats and oversized images), then decodes to RGB8.
fn decode<R: BufRead + Seek>(
    open: impl Fn() -> Result<ImageReader<R>, String>,
    origin: String,
) -> Result<ColourImage, String> {
    let reader = open()?;
    if reader.format().is_none() {
        return Err("not a PNG or JPEG image (unrecognised or unsupported format)".into());
    }
    let (width, height) = reader.into_dimensions().map_err(|e| format!("cannot decode it: {e}"))?;
    if width > MAX_SIDE || height > MAX_SIDE {
        return Err(format!("{width}×{height} pixels is larger than the {MAX_SIDE}×{MAX_SIDE} accepted"));
    }
    if width == 0 || height == 0 {
        return Err(format!("the image is empty ({width}×{height} pixels)"));
    }
    let mut reader = open()?;
    let mut limits = Limits::default();
    limits.max_image_width = Some(MAX_SIDE);
    limits.max_image_height = Some(MAX_SIDE);
    // Room for the largest accepted image in 16-bit RGBA, which the decoder may produce first.
    limits.max_alloc = Some(u64::from(MAX_SIDE) * u64::from(MAX_SIDE) * 8 + (1 << 20));
    reader.limits(limits);
    let rgb = reader.decode().map_err(|e| format!("cannot decode it: {e}"))?.into_rgb8();
    let (width, height) = rgb.dimensions();
    let pixels = rgb.into_raw().chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
    Ok(ColourImage { origin, width, height, pixels })
}

/// The bytes of a `data:[<media type>][;base64],<data>` URI; `None` when `uri` is not one.
pub(crate) fn data_uri_bytes(uri: &str) -> Option<Result<Vec<u8>, String>> {
    let rest = uri.strip_prefix("data:")?;
    let Some((meta, data)) = rest.split_once(',') else {
        return Some(Err("the data URI has no `,` before its data".into()));
    };
    if !meta.ends_with(";base64") {
        return Some(Err("the data URI is not base64-encoded, which is not supported".into()));
    }
    Some(base64_decode(data).ok_or_else(|| "the data URI is not valid base64".into()))
}

/// Decodes standard (or URL-safe) base64, ignoring whitespace; padding is optional and bits left
/// over in the last symbol are dropped. The `base64` crate decodes (the one gltf decodes its own
/// buffer URIs with); only whitespace and the URL-safe alphabet are mapped first.
pub(crate) fn base64_decode(text: &str) -> Option<Vec<u8>> {
    let standard: Vec<u8> = text
        .bytes()
        .filter(|b| !b.is_ascii_whitespace())
        .map(|b| match b {
            b'-' => b'+',
            b'_' => b'/',
            b => b,
        })
        .collect();
    base64::decode_config(standard, base64::STANDARD.decode_allow_trailing_bits(true)).ok()
}

/// Undoes `%XX` escapes of a relative URI; `None` when an escape is malformed or the result is not
/// UTF-8.
pub(crate) fn percent_decode(uri: &str) -> Option<String> {
    let bytes = uri.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i] == b'%' {
            let hex = std::str::from_utf8(bytes.get(i + 1..i + 3)?).ok()?;
            out.push(u8::from_str_radix(hex, 16).ok()?);
            i += 3;
        } else {
            out.push(bytes[i]);
            i += 1;
        }
    }
    String::from_utf8(out).ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_round_trips_known_strings() {
        assert_eq!(base64_decode("aGVsbG8=").unwrap(), b"hello");
        assert_eq!(base64_decode("aGVsbG8").unwrap(), b"hello");
        assert_eq!(base64_decode("aGVs bG8h").unwrap(), b"hello!");
        assert_eq!(base64_decode("").unwrap(), b"");
        assert!(base64_decode("a").is_none());
        assert!(base64_decode("aGV*").is_none());
        assert!(base64_decode("aG==VsbG8").is_none());
        assert_eq!(data_uri_bytes("data:image/png;base64,aGk=").unwrap().unwrap(), b"hi");
        assert!(data_uri_bytes("data:image/png,hi").unwrap().is_err());
        assert!(data_uri_bytes("tex.png").is_none());
    }

    #[test]
    fn percent_escapes_are_undone() {
        assert_eq!(percent_decode("my%20tex.png").unwrap(), "my tex.png");
        assert_eq!(percent_decode("plain.png").unwrap(), "plain.png");
        assert!(percent_decode("bad%2").is_none());
        assert!(percent_decode("bad%zz").is_none());
    }
}
