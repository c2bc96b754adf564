//! A small, strict reader for NumPy `.npy` files holding one numeric array.
//!
//! Written here rather than taken from a crate because the format is tiny (magic, a Python-dict
//! header, raw data) and the checks matter more than the parsing: the declared shape must match the
//! file's actual size *before* anything is allocated (a lying header must not make us reserve
//! gigabytes), and unsupported dtypes must be named. Supported: `uint8`, `float16`, `float32`
//! (little- or big-endian), C or Fortran order; values come back as `f32` in C order.

use std::path::Path;

use crate::error::GeometryError;

/// Element types this reader accepts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Dtype {
    /// `uint8` (`|u1`).
    U8,
    /// `float16` (`<f2` or `>f2`).
    F16,
    /// `float32` (`<f4` or `>f4`).
    F32,
}

impl Dtype {
    fn size(self) -> usize {
        match self {
            Dtype::U8 => 1,
            Dtype::F16 => 2,
            Dtype::F32 => 4,
        }
    }
}

/// An array read from a `.npy` file. Invariant: `data.len()` is the product of `shape`, stored in C
/// order (last index fastest).
#[derive(Clone, Debug, PartialEq)]
pub struct NpyArray {
    /// The array's shape as declared (and checked against the data size).
    pub shape: Vec<usize>,
    /// The element type stored in the file.
    pub dtype: Dtype,
    /// The values converted to `f32`, in C order.
    pub data: Vec<f32>,
}

/// The parsed header dictionary.
struct Header {
    descr: String,
    fortran_order: bool,
    shape: Vec<usize>,
}

/// Reads a `.npy` file.
pub fn read_npy(path: &Path) -> Result<NpyArray, GeometryError> {
    GeometryError::require_file(path)?;
    let bytes = std::fs::read(path).map_err(|e| GeometryError::Io { path: path.to_path_buf(), source: e })?;
    parse_npy(&bytes).map_err(|m| GeometryError::malformed(path, m))
}

/// Parses the bytes of a `.npy` file; the error is a sentence without the file name.
pub fn parse_npy(bytes: &[u8]) -> Result<NpyArray, String> {
    let rest = bytes.strip_prefix(b"\x93NUMPY").ok_or("not a NumPy .npy file (bad magic bytes)")?;
    let (&major, rest) = rest.split_first().ok_or("truncated .npy header")?;
    let (_minor, rest) = rest.split_first().ok_or("truncated .npy header")?;
    let (len, rest) = match major {
        1 => rest.split_first_chunk::<2>().map(|(l, r)| (u16::from_le_bytes(*l) as usize, r)),
        2 | 3 => rest.split_first_chunk::<4>().map(|(l, r)| (u32::from_le_bytes(*l) as usize, r)),
        v => return Err(format!("unsupported .npy format version {v}")),
    }
    .ok_or("truncated .npy header")?;
    if rest.len() < len {
        return Err(format!("the header claims {len} bytes but the file ends after {}", rest.len()));
    }
    let (header, data) = rest.split_at(len);
    let header = std::str::from_utf8(header).map_err(|_| "the .npy header is not text")?;
    let header = parse_header(header)?;
    let dtype = parse_descr(&header.descr)?;
    let count = header
        .shape
        .iter()
        .try_fold(1usize, |acc, &d| acc.checked_mul(d))
        .filter(|c| c.checked_mul(dtype.size()).is_some())
        .ok_or_else(|| format!("shape {:?} is absurdly large", header.shape))?;
    let expected = count * dtype.size();
    if data.len() != expected {
        return Err(format!(
            "the header declares shape {:?} of {} ({expected} bytes of data) but the file holds {} bytes",
            header.shape,
            header.descr,
            data.len()
        ));
    }
    let big_endian = header.descr.starts_with('>');
    let mut values = decode(data, dtype, big_endian);
    if header.fortran_order && header.shape.len() > 1 {
        values = fortran_to_c(&values, &header.shape);
    }
    Ok(NpyArray { shape: header.shape, dtype, data: values })
}

fn parse_descr(descr: &str) -> Result<Dtype, String> {
    let (order, code) = match descr.chars().next() {
        Some(c @ ('<' | '>' | '|' | '=')) => (c, &descr[1..]),
        _ => ('=', descr),
    };
    let dtype = match code {
        "u1" | "B" => Dtype::U8,
        "f2" | "e" => Dtype::F16,
        "f4" | "f" => Dtype::F32,
        _ => {
            return Err(format!(
                "unsupported dtype `{descr}`; supported: uint8 (`|u1`), float16 (`<f2`), float32 (`<f4`)"
            ));
        }
    };
    if order == '=' && cfg!(target_endian = "big") {
        return Err(format!("native-endian dtype `{descr}` on a big-endian machine is not supported"));
    }
    Ok(dtype)
}

fn decode(data: &[u8], dtype: Dtype, big: bool) -> Vec<f32> {
    match dtype {
        Dtype::U8 => data.iter().map(|&b| f32::from(b)).collect(),
        Dtype::F16 => data
            .chunks_exact(2)
            .map(|c| {
                let bits =
                    if big { u16::from_be_bytes([c[0], c[1]]) } else { u16::from_le_bytes([c[0], c[1]]) };
                half::f16::from_bits(bits).to_f32()
            })
            .collect(),
        Dtype::F32 => data
            .chunks_exact(4)
            .map(|c| {
                let b = [c[0], c[1], c[2], c[3]];
                if big { f32::from_be_bytes(b) } else { f32::from_le_bytes(b) }
            })
            .collect(),
    }
}

/// Reorders Fortran-order (first index fastest) values into C order.
fn fortran_to_c(values: &[f32], shape: &[usize]) -> Vec<f32> {
    let mut out = vec![0.0; values.len()];
    let mut idx = vec![0usize; shape.len()];
    for v in &mut out {
        // Fortran offset of the current C-order multi-index.
        let mut off = 0;
        for d in (0..shape.len()).rev() {
            off = off * shape[d] + idx[d];
        }
        *v = values[off];
        for d in (0..shape.len()).rev() {
            idx[d] += 1;
            if idx[d] < shape[d] {
                break;
            }
            idx[d] = 0;
        }
    }
    out
}

/// Parses `{'descr': '<f4', 'fortran_order': False, 'shape': (2, 3), }`.
fn parse_header(text: &str) -> Result<Header, String> {
    let bad = |why: &str| format!("malformed .npy header ({why}): {}", text.trim());
    let body =
        text.trim().strip_prefix('{').and_then(|t| t.strip_suffix('}')).ok_or_else(|| bad("not a dict"))?;
    let mut p = Tokens { s: body.as_bytes(), i: 0 };
    let (mut descr, mut fortran, mut shape) = (None, None, None);
    loop {
        p.skip_ws();
        if p.done() {
            break;
        }
        let key = p.string().ok_or_else(|| bad("expected a quoted key"))?;
        p.expect(b':').ok_or_else(|| bad("expected `:`"))?;
        match key.as_str() {
            "descr" => descr = Some(p.string().ok_or_else(|| bad("descr must be a string"))?),
            "fortran_order" => {
                fortran = Some(p.boolean().ok_or_else(|| bad("fortran_order must be True/False"))?)
            }
            "shape" => shape = Some(p.tuple().ok_or_else(|| bad("shape must be a tuple of integers"))?),
            other => return Err(bad(&format!("unknown key `{other}`"))),
        }
        p.skip_ws();
        if !p.done() {
            p.expect(b',').ok_or_else(|| bad("expected `,`"))?;
        }
    }
    Ok(Header {
        descr: descr.ok_or_else(|| bad("no descr"))?,
        fortran_order: fortran.ok_or_else(|| bad("no fortran_order"))?,
        shape: shape.ok_or_else(|| bad("no shape"))?,
    })
}

struct Tokens<'a> {
    s: &'a [u8],
    i: usize,
}

impl Tokens<'_> {
    fn skip_ws(&mut self) {
        while self.s.get(self.i).is_some_and(|c| c.is_ascii_whitespace()) {
            self.i += 1;
        }
    }

    fn done(&self) -> bool {
        self.i >= self.s.len()
    }

    fn expect(&mut self, c: u8) -> Option<()> {
        self.skip_ws();
        (self.s.get(self.i) == Some(&c)).then(|| self.i += 1)
    }

    fn string(&mut self) -> Option<String> {
        self.skip_ws();
        let q = *self.s.get(self.i).filter(|&&c| c == b'\'' || c == b'"')?;
        let start = self.i + 1;
        let len = self.s.get(start..)?.iter().position(|&c| c == q)?;
        self.i = start + len + 1;
        String::from_utf8(self.s[start..start + len].to_vec()).ok()
    }

    fn boolean(&mut self) -> Option<bool> {
        self.skip_ws();
        for (word, v) in [(&b"True"[..], true), (&b"False"[..], false)] {
            if self.s.get(self.i..self.i + word.len()) == Some(word) {
                self.i += word.len();
                return Some(v);
            }
        }
        None
    }

    fn tuple(&mut self) -> Option<Vec<usize>> {
        self.expect(b'(')?;
        let mut out = Vec::new();
        loop {
            self.skip_ws();
            if self.s.get(self.i) == Some(&b')') {
                self.i += 1;
                return Some(out);
            }
            let start = self.i;
            while self.s.get(self.i).is_some_and(u8::is_ascii_digit) {
                self.i += 1;
            }
            out.push(std::str::from_utf8(&self.s[start..self.i]).ok()?.parse().ok()?);
            self.skip_ws();
            match self.s.get(self.i) {
                Some(b',') => self.i += 1,
                Some(b')') => {}
                _ => return None,
            }
        }
    }
}

/// Serialises an array as `.npy` version 1.0 (for tests and tools that write grids).
pub fn write_npy_bytes(shape: &[usize], descr: &str, data: &[u8], fortran: bool) -> Vec<u8> {
    let dims: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
    let tuple = if dims.len() == 1 { format!("({},)", dims[0]) } else { format!("({})", dims.join(", ")) };
    let order = if fortran { "True" } else { "False" };
    let mut header = format!("{{'descr': '{descr}', 'fortran_order': {order}, 'shape': {tuple}, }}");
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut out = b"\x93NUMPY\x01\x00".to_vec();
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    out.extend_from_slice(data);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_all_supported_dtypes_and_orders() {
        let u8s = write_npy_bytes(&[2, 3], "|u1", &[0, 1, 2, 3, 4, 5], false);
        assert_eq!(parse_npy(&u8s).unwrap().data, vec![0.0, 1.0, 2.0, 3.0, 4.0, 5.0]);
        let f32s: Vec<u8> = [1.5f32, -2.0].iter().flat_map(|v| v.to_le_bytes()).collect();
        let a = parse_npy(&write_npy_bytes(&[2], "<f4", &f32s, false)).unwrap();
        assert_eq!((a.shape, a.dtype, a.data), (vec![2], Dtype::F32, vec![1.5, -2.0]));
        let be: Vec<u8> = [1.5f32, -2.0].iter().flat_map(|v| v.to_be_bytes()).collect();
        assert_eq!(parse_npy(&write_npy_bytes(&[2], ">f4", &be, false)).unwrap().data, vec![1.5, -2.0]);
        let f16s: Vec<u8> =
            [0.5f32, 3.0].iter().flat_map(|v| half::f16::from_f32(*v).to_bits().to_le_bytes()).collect();
        assert_eq!(parse_npy(&write_npy_bytes(&[2], "<f2", &f16s, false)).unwrap().data, vec![0.5, 3.0]);
        // Fortran order: first index fastest. Element [i, j] of a 2×3 array is 10 i + j.
        let fortran = [0u8, 10, 1, 11, 2, 12];
        let a = parse_npy(&write_npy_bytes(&[2, 3], "|u1", &fortran, true)).unwrap();
        assert_eq!(a.data, vec![0.0, 1.0, 2.0, 10.0, 11.0, 12.0]);
    }

    #[test]
    fn rejects_lies_and_unsupported_input() {
        let cases: Vec<(Vec<u8>, &str)> = vec![
            (b"PK\x03\x04".to_vec(), "magic"),
            (b"\x93NUMPY\x01\x00\xff\xff{".to_vec(), "claims"),
            (write_npy_bytes(&[4, 4], "|u1", &[0; 15], false), "holds 15 bytes"),
            (write_npy_bytes(&[4, 4], "|u1", &[0; 17], false), "holds 17 bytes"),
            (write_npy_bytes(&[1 << 40, 1 << 40], "<f4", &[0; 8], false), "absurdly"),
            (write_npy_bytes(&[4_000_000_000, 4], "<f4", &[0; 8], false), "declares"),
            (write_npy_bytes(&[2], "<i8", &[0; 16], false), "unsupported dtype"),
            (write_npy_bytes(&[2], "<c8", &[0; 16], false), "unsupported dtype"),
            (b"\x93NUMPY\x01\x00\x08\x00{'a': 1}".to_vec(), "malformed"),
            (b"\x93NUMPY\x09\x00".to_vec(), "version"),
        ];
        for (bytes, needle) in cases {
            let e = parse_npy(&bytes).unwrap_err();
            assert!(e.contains(needle), "{needle}: {e}");
        }
    }
}
