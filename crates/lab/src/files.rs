//! Writing output files whole or not at all.
//!
//! Every output is first written to a temporary file in the same directory and then renamed over
//! its final name. A rename within one directory is atomic, so a run killed mid-write leaves the
//! previous run's file (or none), never a truncated one beside the previous run's others.
//!
//! A killed run cannot remove its temporary files, so they carry the writer's process id
//! (`.summary.md.<pid>.<random>.md`), and the next write of the same file removes those whose
//! process is gone.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use serde::Serialize;

use crate::error::{LabError, Result};

/// Writes `path` through `write`, atomically: `write` fills a buffered temporary file that
/// replaces `path` only once `write` succeeded and the data reached the disk.
///
/// Errors are the writer's own, or I/O errors without the path: the caller says which file.
pub fn write_atomic<E: From<std::io::Error>>(
    path: &Path,
    write: impl FnOnce(&mut BufWriter<&mut File>) -> std::result::Result<(), E>,
) -> std::result::Result<(), E> {
    let mut tmp = temp_beside(path)?;
    {
        let mut w = BufWriter::new(tmp.as_file_mut());
        write(&mut w)?;
        w.flush()?;
    }
    Ok(persist(tmp, path)?)
}

/// Name of the lock file a run keeps in its output directory (see [`DirLock`]).
pub const LOCK_FILE: &str = ".ferret-lock";

/// One run's claim on an output directory: a second run that asks for the same directory while
/// this one holds it is refused, instead of both computing and the later one's files replacing
/// the earlier one's. An advisory lock on an open file (`flock`), so it ends with the process
/// however that ends and a killed run leaves nothing to clean up; the empty file stays.
#[derive(Debug)]
pub struct DirLock {
    file: Option<File>,
    dir: std::path::PathBuf,
    /// The directory did not exist before: dropped unused, it is removed again.
    created: bool,
    used: bool,
}

impl DirLock {
    /// Creates `dir` if needed and claims it.
    ///
    /// # Errors
    /// [`LabError::Invalid`] when another process holds it; I/O errors creating the directory
    /// or the lock file.
    pub fn acquire(dir: &Path) -> Result<DirLock> {
        let io = |e| LabError::io(format!("locking {}", dir.display()), e);
        let created = !dir.exists();
        std::fs::create_dir_all(dir).map_err(io)?;
        let mut lock = DirLock {
            file: None,
            dir: dir.to_path_buf(),
            created,
            used: false,
        };
        let file = std::fs::OpenOptions::new()
            .create(true)
            .truncate(false)
            .write(true)
            .open(dir.join(LOCK_FILE))
            .map_err(io)?;
        if !try_lock(&file).map_err(io)? {
            // Another run's directory: nothing of it is removed.
            lock.created = false;
            return Err(LabError::invalid(format!(
                "{} is being written by another ferret run; wait for it to finish or choose another output directory",
                dir.display()
            )));
        }
        lock.file = Some(file);
        Ok(lock)
    }

    /// Marks the directory as written to: it stays when the lock is dropped.
    pub fn used(&mut self) {
        self.used = true;
    }
}

impl Drop for DirLock {
    /// A run that failed before writing leaves no directory it created itself.
    fn drop(&mut self) {
        if self.created && !self.used {
            let _ = std::fs::remove_file(self.dir.join(LOCK_FILE));
            // Fails, and leaves it, when anything else is in it.
            let _ = std::fs::remove_dir(&self.dir);
        }
    }
}

/// Takes an exclusive lock on `file` without waiting: `false` when another holds it.
#[cfg(unix)]
fn try_lock(file: &File) -> std::io::Result<bool> {
    use std::os::fd::AsRawFd;
    // SAFETY: flock on a descriptor `file` owns, with no pointers involved.
    if unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) } == 0 {
        return Ok(true);
    }
    let e = std::io::Error::last_os_error();
    if e.kind() == std::io::ErrorKind::WouldBlock {
        Ok(false)
    } else {
        Err(e)
    }
}

#[cfg(not(unix))]
fn try_lock(_: &File) -> std::io::Result<bool> {
    Ok(true)
}

/// `path` made absolute with every existing part resolved (symbolic links, `..`), the parts that
/// do not exist yet appended as written: what two paths must be compared as to tell whether one
/// is (or is inside) the other, when one of them is still to be created.
pub fn resolved(path: &Path) -> PathBuf {
    let absolute = std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf());
    let mut existing = absolute.as_path();
    let mut rest: Vec<&std::ffi::OsStr> = Vec::new();
    loop {
        if let Ok(real) = existing.canonicalize() {
            let mut out = real;
            out.extend(rest.iter().rev());
            return out;
        }
        match (existing.parent(), existing.file_name()) {
            (Some(parent), Some(name)) => {
                rest.push(name);
                existing = parent;
            }
            _ => return absolute,
        }
    }
}

/// Writes `bytes` to `path` atomically.
pub fn write_bytes(path: &Path, bytes: impl AsRef<[u8]>) -> Result<()> {
    write_atomic(path, |w| w.write_all(bytes.as_ref()))
        .map_err(|e| LabError::io(format!("writing {}", path.display()), e))
}

/// Serde rows as CSV text.
pub fn csv_bytes<T: Serialize>(rows: &[T]) -> Result<Vec<u8>> {
    let csv_error = |source| LabError::Csv {
        context: "writing CSV rows".into(),
        source,
    };
    let mut csv = csv::Writer::from_writer(Vec::new());
    for r in rows {
        csv.serialize(r).map_err(csv_error)?;
    }
    csv.into_inner().map_err(|e| {
        LabError::io(
            "writing CSV rows",
            std::io::Error::other(e.error().to_string()),
        )
    })
}

/// Writes serde rows as CSV to `path` atomically.
pub fn write_csv<T: Serialize>(path: &Path, rows: &[T]) -> Result<()> {
    write_bytes(path, csv_bytes(rows)?)
}

/// A file written a piece at a time and put in place whole: the same temporary file beside
/// `path` as [`write_atomic`], for output too large to hold in memory first (an evaluation's
/// trials, written as houses finish). Dropped without [`commit`](Self::commit), the temporary
/// file is removed and `path` keeps what it held.
#[derive(Debug)]
pub struct AtomicFile {
    tmp: tempfile::NamedTempFile,
    path: std::path::PathBuf,
}

impl AtomicFile {
    /// Starts writing `path`.
    ///
    /// # Errors
    /// I/O errors creating the temporary file (the caller says which file).
    pub fn create(path: &Path) -> std::io::Result<Self> {
        Ok(Self {
            tmp: temp_beside(path)?,
            path: path.to_path_buf(),
        })
    }

    /// A handle on the temporary file to write through (shares its position).
    ///
    /// # Errors
    /// I/O errors duplicating the handle.
    pub fn handle(&self) -> std::io::Result<File> {
        self.tmp.as_file().try_clone()
    }

    /// Puts the written file in place of `path`, once its data reached the disk. Every writer on
    /// a [`handle`](Self::handle) must have been flushed.
    ///
    /// # Errors
    /// I/O errors syncing or renaming.
    pub fn commit(self) -> std::io::Result<()> {
        persist(self.tmp, &self.path)
    }
}

/// Produces `path` atomically with a writer that only takes a path (picture backends): `draw`
/// writes a temporary path in the same directory with the same extension, so that format
/// detection by extension still works, and that file is then renamed to `path`.
pub fn write_with_path<E: From<std::io::Error>>(
    path: &Path,
    draw: impl FnOnce(&Path) -> std::result::Result<(), E>,
) -> std::result::Result<(), E> {
    let tmp = temp_beside(path)?;
    draw(tmp.path())?;
    Ok(persist(tmp, path)?)
}

/// A temporary file next to `path` (same directory, so the final rename cannot cross file
/// systems), hidden, and ending in `path`'s extension.
fn temp_beside(path: &Path) -> std::io::Result<tempfile::NamedTempFile> {
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
    remove_stale_temporaries(dir, &name, &suffix);
    let prefix = format!(".{name}.{}.", std::process::id());
    let mut builder = tempfile::Builder::new();
    builder.prefix(&prefix).suffix(&suffix);
    // Temporary files are created private (0600); outputs are ordinary files others may read.
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        builder.permissions(std::fs::Permissions::from_mode(0o644));
    }
    builder.tempfile_in(dir)
}

/// Removes temporary files of `name` left by processes that no longer run, and, of the unnamed
/// kind earlier versions wrote (`.name.<random><suffix>`), those older than an hour. Best effort:
/// a file that cannot be removed is left.
fn remove_stale_temporaries(dir: &Path, name: &str, suffix: &str) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    let prefix = format!(".{name}.");
    for entry in entries.flatten() {
        let file = entry.file_name();
        let Some(rest) = file
            .to_str()
            .and_then(|f| f.strip_prefix(&prefix))
            .and_then(|f| f.strip_suffix(suffix))
        else {
            continue;
        };
        let stale = match rest.split_once('.') {
            Some((pid, random)) if !random.is_empty() => pid
                .parse::<u32>()
                .is_ok_and(|p| p != std::process::id() && !is_running(p)),
            // Earlier versions' name: six random characters, no process id.
            None if rest.len() == 6 => entry
                .metadata()
                .and_then(|m| m.modified())
                .ok()
                .and_then(|t| t.elapsed().ok())
                .is_some_and(|age| age.as_secs() > 3600),
            _ => false,
        };
        if stale {
            let _ = std::fs::remove_file(entry.path());
        }
    }
}

#[cfg(unix)]
fn is_running(pid: u32) -> bool {
    let Ok(pid) = libc::pid_t::try_from(pid) else {
        return false;
    };
    // SAFETY: signal 0 only checks that the process exists; nothing is sent.
    let alive = unsafe { libc::kill(pid, 0) } == 0;
    // EPERM: it exists but belongs to someone else.
    alive || std::io::Error::last_os_error().raw_os_error() == Some(libc::EPERM)
}

#[cfg(not(unix))]
fn is_running(_: u32) -> bool {
    true
}

fn persist(tmp: tempfile::NamedTempFile, path: &Path) -> std::io::Result<()> {
    tmp.as_file().sync_all()?;
    tmp.persist(path).map_err(|e| e.error)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_output_directory_is_one_runs_at_a_time() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("out");
        let mut first = DirLock::acquire(&out).unwrap();
        let e = DirLock::acquire(&out).unwrap_err();
        assert!(e.to_string().contains("another ferret run"), "{e}");
        assert!(
            out.is_dir(),
            "a refused claim removed the holder's directory"
        );
        first.used();
        drop(first);
        let again = DirLock::acquire(&out).unwrap();
        drop(again);
        assert!(out.is_dir(), "a used directory is kept");
        // Claimed and dropped unused: the directory it created is gone again.
        let unused = dir.path().join("unused");
        drop(DirLock::acquire(&unused).unwrap());
        assert!(!unused.exists());
    }

    #[test]
    fn a_failed_write_keeps_the_previous_file_and_leaves_no_temporary() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("summary.md");
        write_bytes(&path, "first run\n").unwrap();
        let err = write_atomic(&path, |w| {
            w.write_all(b"half of the second")?;
            Err(std::io::Error::other("killed"))
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

    /// A process id no process has (above the kernel's limit).
    fn dead_pid() -> u32 {
        let max: u32 = std::fs::read_to_string("/proc/sys/kernel/pid_max")
            .ok()
            .and_then(|s| s.trim().parse().ok())
            .unwrap_or(4_194_304);
        max + 1
    }

    /// A killed eval left `.summary.md.XXXX.md` beside its outputs for good.
    #[cfg(unix)]
    #[test]
    fn temporaries_of_a_killed_writer_are_removed_by_the_next_write() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("summary.md");
        let dead = dir
            .path()
            .join(format!(".summary.md.{}.a1b2c3.md", dead_pid()));
        let ours = dir
            .path()
            .join(format!(".summary.md.{}.d4e5f6.md", std::process::id()));
        let old_style = dir.path().join(".summary.md.Xy12Zq.md");
        let other_file = dir
            .path()
            .join(format!(".trials.csv.{}.a1b2c3.csv", dead_pid()));
        for p in [&dead, &ours, &old_style, &other_file] {
            std::fs::write(p, "partial").unwrap();
        }
        let hour_ago = std::time::SystemTime::now() - std::time::Duration::from_secs(7200);
        std::fs::File::options()
            .write(true)
            .open(&old_style)
            .unwrap()
            .set_modified(hour_ago)
            .unwrap();
        write_bytes(&path, "run\n").unwrap();
        assert!(!dead.exists(), "a dead writer's temporary is removed");
        assert!(!old_style.exists(), "an old unnamed temporary is removed");
        assert!(ours.exists(), "a live writer's temporary is kept");
        assert!(
            other_file.exists(),
            "other outputs' temporaries wait for their own write"
        );
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "run\n");
    }

    #[test]
    fn pictures_get_a_temporary_path_with_their_extension() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("costs.png");
        let mut seen = None;
        write_with_path(&path, |tmp| {
            seen = Some(tmp.to_path_buf());
            std::fs::write(tmp, b"png bytes")?;
            Ok::<(), std::io::Error>(())
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
