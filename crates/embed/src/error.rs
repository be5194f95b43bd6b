//! Errors of the embed crate. Every error about a file names that file; errors about a text table
//! also name the line.

use std::path::PathBuf;

use crate::{EMBEDDINGS_ENV, INSTALL_HINT};

/// Everything that can go wrong finding, reading or building an embeddings table.
#[derive(Debug, thiserror::Error)]
pub enum EmbedError {
    /// A file or folder could not be opened or read.
    #[error("{path}: {source}")]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The cause.
        #[source]
        source: std::io::Error,
    },
    /// The folder holds no embeddings this crate can read.
    #[error(
        "{path}: no embeddings found (looked for {looked_for}); install them with `{}` and pass the folder it prints",
        INSTALL_HINT
    )]
    NotFound {
        /// The folder that was searched.
        path: PathBuf,
        /// What was looked for.
        looked_for: String,
    },
    /// No folder was given and the environment variable is not set.
    #[error(
        "no embeddings folder given and {} is not set; install the embeddings with `{}` and set {} to the folder it prints",
        EMBEDDINGS_ENV,
        INSTALL_HINT,
        EMBEDDINGS_ENV
    )]
    NotConfigured,
    /// The folder holds more than one candidate and it is not clear which one is meant.
    #[error("{path}: {what}")]
    Ambiguous {
        /// The folder.
        path: PathBuf,
        /// The candidates.
        what: String,
    },
    /// An NPY matrix file is malformed or of a kind this crate does not read (dtype, shape).
    #[error("{path}: {what}")]
    Npy {
        /// The `.npy` file.
        path: PathBuf,
        /// What is wrong.
        what: String,
    },
    /// An NPY file is shorter or longer than its header says (typically an interrupted download).
    #[error(
        "{path}: the header says {rows}×{dim} float32 values, so the file should be {expected} bytes, but it is {actual} bytes"
    )]
    NpySize {
        /// The `.npy` file.
        path: PathBuf,
        /// Rows in the header's shape.
        rows: usize,
        /// Columns in the header's shape.
        dim: usize,
        /// Header plus data length in bytes.
        expected: u64,
        /// The file's length in bytes.
        actual: u64,
    },
    /// The parquet reader failed on the word index.
    #[error("{path}: {source}")]
    Parquet {
        /// The `.parquet` file.
        path: PathBuf,
        /// The cause.
        #[source]
        source: parquet::errors::ParquetError,
    },
    /// The word index parsed but does not hold what is expected (one string column, no nulls).
    #[error("{path}: {what}")]
    Index {
        /// The `.parquet` file.
        path: PathBuf,
        /// What is wrong.
        what: String,
    },
    /// The matrix and the word index disagree on the number of words.
    #[error("{matrix} has {rows} rows but {index} has {words} words; they must match one to one")]
    CountMismatch {
        /// The matrix file.
        matrix: PathBuf,
        /// Its rows.
        rows: usize,
        /// The word index file.
        index: PathBuf,
        /// Its words.
        words: usize,
    },
    /// A line of a text table is malformed.
    #[error("{path}, line {line}: {what}")]
    Text {
        /// The text file.
        path: PathBuf,
        /// The 1-based line number.
        line: usize,
        /// What is wrong.
        what: String,
    },
    /// The folder holds a sentence-embedding model (`model.safetensors` with `tokenizer.json` and
    /// `config.json`), but this build cannot run it: the `minilm` feature is off. The variant
    /// exists in every build, so that callers can match on it.
    #[error(
        "{path}: this is a sentence-embedding model (model.safetensors, tokenizer.json, \
         config.json), which this build of ferret-embed cannot run: build with `--features minilm` \
         (`--features ferret-embed/minilm` from a crate that depends on it)"
    )]
    NeedsFeature {
        /// The model's folder.
        path: PathBuf,
    },
    /// A sentence-embedding model's files could not be loaded (a malformed config, tokenizer or
    /// weights file, or a model that is not a BERT model). Only the `minilm` feature makes it.
    #[error("{path}: {what}")]
    Model {
        /// The file at fault (or the model's folder).
        path: PathBuf,
        /// What is wrong.
        what: String,
    },
    /// Words given to [`Embeddings::from_words`](crate::Embeddings::from_words) do not form a
    /// table.
    #[error("table {id:?}: {what}")]
    Table {
        /// The table's id.
        id: String,
        /// What is wrong.
        what: String,
    },
    /// A WordNet dictionary folder is missing or malformed.
    #[error("{path}: {what}")]
    WordNet {
        /// The folder or file at fault.
        path: PathBuf,
        /// What is wrong.
        what: String,
    },
    /// No word of a name is known, so it has no vector ([`Embeddings::resolve_name`](crate::Embeddings::resolve_name)).
    #[error(
        "the name `{name}` has no vector: none of its words ({words:?}) is known to {embeddings} {wordnet}; check its spelling, or name it with words the embeddings know"
    )]
    UnknownName {
        /// The name.
        name: String,
        /// Its words.
        words: Vec<String>,
        /// The embeddings' id.
        embeddings: String,
        /// Whether WordNet was asked, and where it is.
        wordnet: String,
    },
}
