//! Writing output files whole or not at all (see [`ferret_lab::files`]), with the file named in
//! every error.

use std::path::Path;

use anyhow::{Context, Result};
use serde::Serialize;

/// Writes `bytes` to `path` atomically.
pub fn write_bytes(path: &Path, bytes: impl AsRef<[u8]>) -> Result<()> {
    Ok(ferret_lab::files::write_bytes(path, bytes)?)
}

/// Writes serde rows as CSV to `path` atomically.
pub fn write_csv<T: Serialize>(path: &Path, rows: &[T]) -> Result<()> {
    Ok(ferret_lab::files::write_csv(path, rows)?)
}

/// Produces `path` atomically with a writer that only takes a path (picture backends).
pub fn write_with_path(path: &Path, draw: impl FnOnce(&Path) -> Result<()>) -> Result<()> {
    ferret_lab::files::write_with_path(path, |p| draw(p).map_err(Failure::Inner))
        .map_err(Failure::into_anyhow)
        .with_context(|| format!("writing {}", path.display()))
}

/// The writer's own error or the file system's.
enum Failure {
    Inner(anyhow::Error),
    Io(std::io::Error),
}

impl From<std::io::Error> for Failure {
    fn from(e: std::io::Error) -> Self {
        Self::Io(e)
    }
}

impl Failure {
    fn into_anyhow(self) -> anyhow::Error {
        match self {
            Self::Inner(e) => e,
            Self::Io(e) => e.into(),
        }
    }
}
