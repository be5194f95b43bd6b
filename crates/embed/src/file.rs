//! Opening the files of an embeddings folder through the world's input guard: only regular
//! files are read, so a FIFO named like a matrix is refused at once instead of blocking the
//! command (and a server's shutdown) for good.

use std::fs::File;
use std::path::Path;

use crate::EmbedError;

/// Opens `path` for reading if it is a regular file; anything else is an [`EmbedError::Io`]
/// naming the file and what it is (a FIFO, a device, a directory).
pub(crate) fn open(path: &Path) -> Result<File, EmbedError> {
    ferret_world::input::open_file(path).map_err(|source| EmbedError::Io {
        path: path.to_owned(),
        source,
    })
}

/// The whole of the regular file at `path`.
#[cfg(feature = "minilm")]
pub(crate) fn read(path: &Path) -> Result<Vec<u8>, EmbedError> {
    use std::io::Read;
    let mut bytes = Vec::new();
    open(path)?
        .read_to_end(&mut bytes)
        .map_err(|source| EmbedError::Io {
            path: path.to_owned(),
            source,
        })?;
    Ok(bytes)
}
