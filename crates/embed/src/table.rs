//! The word table and the vectors of names.

use std::collections::HashMap;
use std::collections::hash_map::Entry;
use std::path::{Path, PathBuf};
#[cfg(feature = "minilm")]
use std::sync::Arc;

use crate::{EMBEDDINGS_ENV, EmbedError, Matrix, split_name};

/// Embeddings of names: an id, a dimension, and either a word table (one vector per word, a
/// name's vector the mean of its words') or, with the `minilm` feature, a sentence-embedding
/// model run on the name's words.
///
/// A table's vectors are stored row-major in one allocation (400 000 × 50 floats for GloVe 6B
/// 50d, 80 MB) so that a lookup is a hash plus a slice. A model is shared between clones, and so
/// is the cache of the names it has embedded.
#[derive(Clone)]
pub struct Embeddings {
    id: String,
    dim: usize,
    backend: Backend,
}

/// Where the vectors come from.
#[derive(Clone)]
enum Backend {
    /// One vector per word: the word's row in `data` (`dim` floats from `row × dim`).
    Table {
        rows: HashMap<String, usize>,
        data: Vec<f32>,
    },
    /// A sentence-embedding model (all-MiniLM-L6-v2 or another BERT model).
    #[cfg(feature = "minilm")]
    Sentence(Arc<crate::minilm::SentenceModel>),
}

impl std::fmt::Debug for Embeddings {
    // The vectors are far too many to print.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Embeddings")
            .field("id", &self.id)
            .field("dim", &self.dim)
            .field("len", &self.len())
            .finish_non_exhaustive()
    }
}

impl Embeddings {
    /// Opens the folder named by the environment variable [`EMBEDDINGS_ENV`]; an error when it is
    /// unset or empty, saying how to install the embeddings.
    pub fn from_env() -> Result<Self, EmbedError> {
        match std::env::var_os(EMBEDDINGS_ENV) {
            Some(dir) if !dir.is_empty() => Self::open(&PathBuf::from(dir)),
            _ => Err(EmbedError::NotConfigured),
        }
    }

    /// A table from (word, vector) pairs (tests, hand-made tables).
    ///
    /// All vectors must have the same, non-zero length and hold finite values. A word given
    /// twice keeps its first vector (with a warning), as a text table does. No words give an
    /// empty table of dimension 0.
    pub fn from_words(
        id: &str,
        words: impl IntoIterator<Item = (String, Vec<f32>)>,
    ) -> Result<Self, EmbedError> {
        let bad = |what: String| EmbedError::Table {
            id: id.to_owned(),
            what,
        };
        let mut dim = None;
        let mut rows = HashMap::new();
        let mut data = Vec::new();
        let mut duplicates = 0usize;
        for (word, vector) in words {
            match dim {
                None if vector.is_empty() => {
                    return Err(bad(format!("the vector of {word:?} is empty")));
                }
                None => dim = Some(vector.len()),
                Some(d) if d != vector.len() => {
                    return Err(bad(format!(
                        "the vector of {word:?} has {} values, the ones before have {d}",
                        vector.len()
                    )));
                }
                Some(_) => {}
            }
            if vector.iter().any(|v| !v.is_finite()) {
                return Err(bad(format!("the vector of {word:?} is not finite")));
            }
            let next = rows.len();
            match rows.entry(word) {
                Entry::Occupied(_) => duplicates += 1,
                Entry::Vacant(slot) => {
                    slot.insert(next);
                    data.extend_from_slice(&vector);
                }
            }
        }
        if duplicates > 0 {
            tracing::warn!(
                id,
                duplicates,
                "words given more than once keep their first vector"
            );
        }
        Ok(Self {
            id: id.to_owned(),
            dim: dim.unwrap_or(0),
            backend: Backend::Table { rows, data },
        })
    }

    /// A table from a row-major matrix and the word of each row (the package format).
    pub(crate) fn from_matrix(
        id: String,
        matrix: Matrix,
        words: Vec<String>,
    ) -> Result<Self, EmbedError> {
        if let Some(at) = matrix.data.iter().position(|v| !v.is_finite()) {
            let (row, col) = (at / matrix.cols.max(1), at % matrix.cols.max(1));
            return Err(EmbedError::Table {
                id,
                what: format!(
                    "row {row} (the word {:?}), value {}: {} is not a finite number",
                    words.get(row).map_or("", String::as_str),
                    col + 1,
                    matrix.data[at]
                ),
            });
        }
        let mut rows = HashMap::with_capacity(words.len());
        let mut duplicates = 0usize;
        for (row, word) in words.into_iter().enumerate() {
            // Keep the first row of a repeated word, like a text table does.
            if let Entry::Vacant(slot) = rows.entry(word) {
                slot.insert(row);
            } else {
                duplicates += 1;
            }
        }
        if duplicates > 0 {
            tracing::warn!(
                id,
                duplicates,
                "words listed more than once keep their first row"
            );
        }
        Ok(Self {
            id,
            dim: matrix.cols,
            backend: Backend::Table {
                rows,
                data: matrix.data,
            },
        })
    }

    /// Embeddings computed by a sentence-embedding model.
    #[cfg(feature = "minilm")]
    pub(crate) fn from_model(id: String, model: crate::minilm::SentenceModel) -> Self {
        Self {
            id,
            dim: model.dim(),
            backend: Backend::Sentence(Arc::new(model)),
        }
    }

    /// Whether the vectors come from a sentence-embedding model rather than a word table.
    pub fn is_model(&self) -> bool {
        match &self.backend {
            Backend::Table { .. } => false,
            #[cfg(feature = "minilm")]
            Backend::Sentence(_) => true,
        }
    }

    /// The table's id, e.g. `glove-6b-50d` for the GloVe package, `all-minilm-l6-v2` for that
    /// model, or a text table's header id or file stem; meant for fingerprints and reports.
    pub fn id(&self) -> &str {
        &self.id
    }

    /// The length of every vector.
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// The number of distinct words; for a model, the size of its tokenizer's vocabulary (word
    /// pieces, 30 522 for all-MiniLM-L6-v2), although any word can be embedded.
    pub fn len(&self) -> usize {
        match &self.backend {
            Backend::Table { rows, .. } => rows.len(),
            #[cfg(feature = "minilm")]
            Backend::Sentence(model) => model.vocab_size(),
        }
    }

    /// Whether the table holds no word (only possible through [`Self::from_words`]).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The vector of a word, exactly as spelt (GloVe's words are lowercase).
    ///
    /// Always `None` for a sentence-embedding model: it has no stored vector per word (its
    /// vectors are computed, and a word alone is embedded by [`Self::embed_name`]).
    pub fn word(&self, w: &str) -> Option<&[f32]> {
        match &self.backend {
            Backend::Table { rows, data } => {
                let row = *rows.get(w)?;
                data.get(row * self.dim..(row + 1) * self.dim)
            }
            #[cfg(feature = "minilm")]
            Backend::Sentence(_) => None,
        }
    }

    /// The vector of a word, trying simple English plural/singular variants when the word itself
    /// is missing: `-ies` → `-y`, `-es` → `` after s, x, z, ch and sh, `-s` → ``, and otherwise
    /// `+s`. Small hand-made tables often hold one form only.
    fn word_or_variant(&self, w: &str) -> Option<&[f32]> {
        self.word_form(w).map(|(_, v)| v)
    }

    /// [`Self::word_or_variant`] with the form found (`None` when it is the word as spelt).
    pub(crate) fn word_form(&self, w: &str) -> Option<(Option<String>, &[f32])> {
        if let Some(v) = self.word(w) {
            return Some((None, v));
        }
        let mut variants = Vec::with_capacity(2);
        if let Some(stem) = w.strip_suffix("ies") {
            variants.push(format!("{stem}y"));
        }
        if let Some(stem) = w.strip_suffix("es")
            && ["s", "x", "z", "ch", "sh"]
                .iter()
                .any(|e| stem.ends_with(e))
        {
            variants.push(stem.to_owned());
        }
        match w.strip_suffix('s') {
            // `ss` is not a plural (`glass`), and a one-letter stem is not a word worth trying.
            Some(stem) if stem.chars().count() > 1 && !stem.ends_with('s') => {
                variants.push(stem.to_owned());
            }
            Some(_) => {}
            None => variants.push(format!("{w}s")),
        }
        variants.into_iter().find_map(|v| {
            let found = self.word(&v)?;
            tracing::trace!(word = w, variant = %v, "using a plural/singular variant");
            Some((Some(v), found))
        })
    }

    /// For a sentence-embedding model, whether its tokenizer has `word` as one whole token;
    /// `None` for a word table.
    pub(crate) fn whole_token(&self, word: &str) -> Option<bool> {
        match &self.backend {
            Backend::Table { .. } => {
                let _ = word;
                None
            }
            #[cfg(feature = "minilm")]
            Backend::Sentence(model) => Some(model.whole_token(word)),
        }
    }

    /// The vector of a type name, of length [`Self::dim`] and unit L2 norm.
    ///
    /// For a word table: its words ([`split_name`]), each looked up in lowercase (with a
    /// plural/singular variant when the word itself is missing), averaged and L2-normalised.
    /// Unknown words are skipped (logged at debug level), so `FooLamp` is `lamp`'s direction.
    /// `None` when no word is known, or when the known words' vectors cancel out exactly (a zero
    /// vector has no direction).
    ///
    /// For a sentence-embedding model: its words joined by spaces (`CounterTop` → `counter
    /// top`), tokenized without padding, run through the model, mean-pooled over the tokens and
    /// L2-normalised, as sentence-transformers does for all-MiniLM-L6-v2. Every word has a vector
    /// (unknown words are split into word pieces); `None` only when the name has no words, or if
    /// the model fails (logged as a warning). The same name always gives the same vector: vectors
    /// are cached per text, and the computation does not depend on the number of threads.
    pub fn embed_name(&self, name: &str) -> Option<Vec<f32>> {
        #[cfg(feature = "minilm")]
        if let Backend::Sentence(model) = &self.backend {
            return model.embed_name(name);
        }
        let mut sum = vec![0f64; self.dim];
        let mut known = 0usize;
        for word in split_name(name) {
            let Some(v) = self.word_or_variant(&word) else {
                tracing::debug!(name, word, table = %self.id, "word not in the table, skipped");
                continue;
            };
            // Sum in f64: names are short, but this keeps the result independent of word order
            // up to the final rounding.
            for (s, x) in sum.iter_mut().zip(v) {
                *s += f64::from(*x);
            }
            known += 1;
        }
        if known == 0 {
            return None;
        }
        // The mean's direction is the sum's, so normalising the sum is the same as normalising
        // the average.
        let norm = sum.iter().map(|s| s * s).sum::<f64>().sqrt();
        if norm == 0.0 || !norm.is_finite() {
            tracing::debug!(name, "the words' vectors sum to zero; no direction");
            return None;
        }
        Some(sum.iter().map(|s| (s / norm) as f32).collect())
    }
}

/// The cosine similarity of two vectors of the same length; 0 when either is zero or the
/// lengths differ.
pub fn cosine(a: &[f32], b: &[f32]) -> f32 {
    if a.len() != b.len() {
        return 0.0;
    }
    let (mut ab, mut aa, mut bb) = (0f64, 0f64, 0f64);
    for (x, y) in a.iter().zip(b) {
        let (x, y) = (f64::from(*x), f64::from(*y));
        ab += x * y;
        aa += x * x;
        bb += y * y;
    }
    if aa == 0.0 || bb == 0.0 {
        return 0.0;
    }
    (ab / (aa.sqrt() * bb.sqrt())) as f32
}

/// A table from a text file: its header id, else its file stem.
pub(crate) fn from_text(path: &Path) -> Result<Embeddings, EmbedError> {
    let table = crate::text::read_text(path)?;
    let id = table.id.unwrap_or_else(|| {
        path.file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "vectors".to_owned())
    });
    // The reader has checked the lengths and numbers, which is all `from_words` checks.
    Embeddings::from_words(&id, table.words)
}
