//! Writing output files whole or not at all.
//!
//! Every output is first written to a temporary file in the same directory and then renamed over
//! its final name. A rename within one directory is atomic, so a run killed mid-write leaves the
//! previous run's file (or none), never a truncated one beside the previous run's others.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

use anyhow::{Context, Result};
use serde::Serialize;

/// Writes `path` through `write`, atomically: `write` fills a buffered temporary file that
/// replaces `path` only once `write` succeeded and the data reached the disk.
pub fn write_atomic(
    path: &Path,
    write: impl FnOnce(&mut BufWriter<&mut File>) -> Result<()>,
) -> Result<()> {
    let mut tmp = temp_beside(path)?;
    {
        let mut w = BufWriter::new(tmp.as_file_mut());
        write(&mut w).with_context(|| format!("writing {}", path.display()))?;
        w.flush()
            .with_context(|| format!("writing {}", path.display()))?;
    }
    persist(tmp, path)
}

/// Writes `bytes` to `path` atomically.
pub fn write_bytes(path: &Path, bytes: impl AsRef<[u8]>) -> Result<()> {
    write_atomic(path, |w| Ok(w.write_all(bytes.as_ref())?))
}

/// Writes serde rows as CSV to `path` atomically.
pub fn write_csv<T: Serialize>(path: &Path, rows: &[T]) -> Result<()> {
    write_atomic(path, |w| {
        let mut csv = csv::Writer::from_writer(w);
        for r in rows {
            csv.serialize(r)?;
        }
        csv.flush()?;
        Ok(())
    })
}

/// Produces `path` atomically with a writer that only takes a path (picture backends): `draw`
/// writes a temporary path in the same directory with the same extension, so that format
/// detection by extension still works, and that file is then renamed to `path`.
pub fn write_with_path(path: &Path, draw: impl FnOnce(&Path) -> Result<()>) -> Result<()> {
    let tmp = temp_beside(path)?;
    draw(tmp.path()).with_context(|| format!("writing {}", path.display()))?;
    persist(tmp, path)
}

/// A temporary file next to `path` (same directory, so the final rename cannot cross file
/// systems), hidden, and ending in `path`'s extension.
fn temp_beside(path: &Path) -> Result<tempfile::NamedTempFile> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let suffix = path
        .extension()
        .map(|e| format!(".{}", e.to_string_lossy()))
        .unwrap_or_default();
    let prefix = format!(".{name}.");
    let mut builder = tempfile::Builder::new();
    builder.prefix(&prefix).suffix(&suffix);
    // Temporary files are created private (0600); outputs are ordinary files others may read.
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        builder.permissions(std::fs::Permissions::from_mode(0o644));
    }
    builder
        .tempfile_in(dir)
        .with_context(|| format!("creating a temporary file for {}", path.display()))
}

fn persist(tmp: tempfile::NamedTempFile, path: &Path) -> Result<()> {
    tmp.as_file()
        .sync_all()
        .with_context(|| format!("writing {}", path.display()))?;
    tmp.persist(path)
        .map_err(|e| e.error)
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failed_write_keeps_the_previous_file_and_leaves_no_temporary() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("summary.md");
        write_bytes(&path, "first run\n").unwrap();
        let err = write_atomic(&path, |w| {
            w.write_all(b"half of the second")?;
            anyhow::bail!("killed")
        });
        assert!(err.is_err());
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "first run\n");
        let names: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, vec![std::ffi::OsString::from("summary.md")]);
        write_bytes(&path, "second run\n").unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "second run\n");
    }

    #[test]
    fn pictures_get_a_temporary_path_with_their_extension() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("costs.png");
        let mut seen = None;
        write_with_path(&path, |tmp| {
            seen = Some(tmp.to_path_buf());
            std::fs::write(tmp, b"png bytes")?;
            Ok(())
        })
        .unwrap();
        let seen = seen.unwrap();
        assert_eq!(seen.extension().unwrap(), "png");
        assert_eq!(seen.parent(), path.parent());
        assert_ne!(seen, path);
        assert_eq!(std::fs::read(&path).unwrap(), b"png bytes");
        assert!(!seen.exists());
    }
}
