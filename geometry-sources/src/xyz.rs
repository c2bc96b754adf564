//! Plain-text point files (`.xyz`, `.txt`, `.pts`): one point per line as `x y z`,
//! `x y z nx ny nz` or `x y z nx ny nz r g b`, separated by spaces, tabs or commas; `#` starts a
//! comment; every data line must have the same number of columns. The colours of nine-column files
//! are read by the appearance reader ([`crate::appearance`]); [`read_xyz`] keeps their normals.

use std::path::Path;

use crate::coords::V3;
use crate::error::GeometryError;
use crate::ply::PointSet;

/// Reads a plain-text point file; errors name the file and the line.
pub fn read_xyz(path: &Path) -> Result<PointSet, GeometryError> {
    read_xyz_colours(path).map(|(set, _)| set)
}

/// [`read_xyz`] with the colour columns of a nine-column file, as written (unscaled).
pub(crate) fn read_xyz_colours(path: &Path) -> Result<(PointSet, Option<Vec<V3>>), GeometryError> {
    let bytes = std::fs::read(path).map_err(|e| GeometryError::Io { path: path.to_path_buf(), source: e })?;
    let text =
        std::str::from_utf8(&bytes).map_err(|e| GeometryError::malformed(path, format!("not text: {e}")))?;
    let mut set = PointSet::default();
    let mut normals = Vec::new();
    let mut colours = Vec::new();
    let mut columns = None;
    for (i, line) in text.lines().enumerate() {
        let line = line.split('#').next().unwrap_or("");
        let fields: Vec<&str> =
            line.split(|c: char| c.is_whitespace() || c == ',').filter(|f| !f.is_empty()).collect();
        if fields.is_empty() {
            continue;
        }
        let bad = |m: String| GeometryError::malformed(path, format!("line {}: {m}", i + 1));
        let values: Vec<f32> = fields
            .iter()
            .map(|f| f.parse::<f32>().map_err(|_| bad(format!("`{f}` is not a number"))))
            .collect::<Result<_, _>>()?;
        if ![3, 6, 9].contains(&values.len()) {
            return Err(bad(format!(
                "expected 3 (x y z), 6 (x y z nx ny nz) or 9 (x y z nx ny nz r g b) numbers, found {}",
                values.len()
            )));
        }
        match columns {
            None => columns = Some(values.len()),
            Some(c) if c != values.len() => {
                return Err(bad(format!("{} numbers, but earlier lines have {c}", values.len())));
            }
            _ => {}
        }
        set.positions.push([values[0], values[1], values[2]]);
        if values.len() >= 6 {
            normals.push([values[3], values[4], values[5]]);
        }
        if values.len() == 9 {
            colours.push([values[6], values[7], values[8]]);
        }
    }
    if columns >= Some(6) {
        set.normals = Some(normals);
    }
    Ok((set, (columns == Some(9)).then_some(colours)))
}
