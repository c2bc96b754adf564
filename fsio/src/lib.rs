//! Atomic file writes, for every file the project writes (checkpoints, configs, meshes, images,
//! metrics; `log.jsonl` alone is appended line by line): the
//! bytes go to a temporary file in the destination folder, are flushed to disk, then the file is
//! renamed over the destination. A crash, kill or error mid-write leaves either the old file or none,
//! never a truncated file that looks complete.

use std::io::{BufWriter, Write};
use std::path::Path;

/// Writes `path` atomically with the bytes `fill` produces. On error nothing is left behind (the
/// temporary file is removed); callers attach the path to the error.
pub fn write_atomic(
    path: &Path,
    fill: impl FnOnce(&mut dyn Write) -> std::io::Result<()>,
) -> std::io::Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let mut builder = tempfile::Builder::new();
    builder.prefix(".nuvo-partial-");
    // Temporary files are private (0600) by default; outputs get the usual 0666 & !umask.
    #[cfg(unix)]
    builder.permissions(std::os::unix::fs::PermissionsExt::from_mode(0o666));
    let tmp = builder.tempfile_in(dir)?;
    let mut w = BufWriter::new(tmp);
    fill(&mut w)?;
    let tmp = w.into_inner().map_err(|e| e.into_error())?;
    tmp.as_file().sync_all()?;
    tmp.persist(path).map_err(|e| e.error)?;
    Ok(())
}

/// [`write_atomic`] of a byte slice.
pub fn write_bytes_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    write_atomic(path, |w| w.write_all(bytes))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failed_write_leaves_no_file_and_a_good_one_replaces_atomically() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("out.txt");
        let e = write_atomic(&p, |w| {
            w.write_all(b"half")?;
            Err(std::io::Error::other("disk on fire"))
        })
        .unwrap_err();
        assert!(e.to_string().contains("disk on fire"), "{e}");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0, "partial file left behind");
        write_atomic(&p, |w| w.write_all(b"whole")).unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"whole");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }

    #[test]
    fn a_missing_folder_is_an_error() {
        assert!(write_atomic(Path::new("/nonexistent-nuvo-dir/x.obj"), |_| Ok(())).is_err());
    }

    #[test]
    fn bytes_helper_writes_whole_files() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("b.bin");
        write_bytes_atomic(&p, b"abc").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"abc");
    }
}
