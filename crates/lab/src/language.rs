//! Language for the learned likelihood: word vectors of the training houses' names, training the
//! learned part of a prior, and the lazily opened embeddings that give vectors of names a prior
//! file lacks (so a run whose every name is in the file opens no embedding file).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, OnceLock};

use ferret_embed::{EMBEDDINGS_ENV, Embeddings, INSTALL_HINT};
use ferret_plan::learned::{self, LearnedSettings, NameVectors};
use ferret_plan::{Embedder, Prior};
use ferret_world::Scene;

use crate::error::{LabError, Result};

/// The embeddings folder a run names, or the one [`EMBEDDINGS_ENV`] names.
pub fn embeddings_dir(given: Option<&Path>) -> Option<PathBuf> {
    given.map(Path::to_path_buf).or_else(|| {
        std::env::var_os(EMBEDDINGS_ENV)
            .filter(|v| !v.is_empty())
            .map(PathBuf::from)
    })
}

/// Opens an embeddings folder, with the command that installs one in the error.
pub fn open_embeddings(dir: &Path) -> Result<Embeddings> {
    Embeddings::open(dir).map_err(|e| {
        LabError::invalid(format!(
            "embeddings {}: {e} (`{INSTALL_HINT}` installs them and prints the folder)",
            dir.display()
        ))
    })
}

/// What training the learned part found and fitted, for the face to print.
#[derive(Clone, Debug)]
pub struct LearnedReport {
    /// Names embedded.
    pub names: usize,
    /// Names none of whose words the embeddings know: they get a zero vector.
    pub unknown: Vec<String>,
}

/// The vectors of `names` from `embeddings` (a zero vector for a name none of whose words it
/// knows), with those names.
pub fn embed_names<'a>(
    embeddings: &Embeddings,
    names: impl IntoIterator<Item = &'a str>,
) -> (BTreeMap<String, Vec<f32>>, Vec<String>) {
    let mut vectors = BTreeMap::new();
    let mut unknown = Vec::new();
    for name in names {
        if name.is_empty() {
            continue;
        }
        let v = embeddings.embed_name(name).unwrap_or_else(|| {
            unknown.push(name.to_string());
            vec![0.0; embeddings.dim()]
        });
        vectors.insert(name.to_string(), v);
    }
    (vectors, unknown)
}

/// `prior` (counted on `scenes`) with a learned part trained on the same houses over the names'
/// vectors from `embeddings`.
pub fn train_learned(
    scenes: &[Scene],
    prior: &Prior,
    embeddings: &Embeddings,
    settings: &LearnedSettings,
) -> Result<(Prior, LearnedReport)> {
    let mut names = std::collections::BTreeSet::new();
    for s in scenes {
        names.extend(learned::scene_names(s));
    }
    let (vectors, unknown) = embed_names(embeddings, names.iter().map(String::as_str));
    if !unknown.is_empty() {
        tracing::debug!(
            "{} name(s) have no known word in {}: {}",
            unknown.len(),
            embeddings.id(),
            unknown.join(", ")
        );
    }
    let report = LearnedReport {
        names: vectors.len(),
        unknown,
    };
    let refs: Vec<&Scene> = scenes.iter().collect();
    let learned = learned::train(&refs, prior, embeddings.id(), vectors, settings)?;
    Ok((prior.with_learned(learned), report))
}

/// Vectors of names a prior file lacks, from an embeddings folder opened when the first such
/// name is asked, and kept per name.
pub struct LazyEmbeddings {
    dir: PathBuf,
    expected: String,
    dim: usize,
    opened: OnceLock<std::result::Result<Embeddings, String>>,
    cache: Mutex<BTreeMap<String, Vec<f32>>>,
}

impl LazyEmbeddings {
    /// Embeddings from `dir`, which must be those `expected` (the learned part's embedding id)
    /// with vectors of `dim` numbers.
    pub fn new(dir: PathBuf, expected: &str, dim: usize) -> Self {
        Self {
            dir,
            expected: expected.to_string(),
            dim,
            opened: OnceLock::new(),
            cache: Mutex::new(BTreeMap::new()),
        }
    }

    /// Whether the folder has been opened (a run whose names are all in the prior file never
    /// opens it).
    pub fn is_open(&self) -> bool {
        self.opened.get().is_some()
    }
}

impl NameVectors for LazyEmbeddings {
    fn vector(&self, name: &str) -> std::result::Result<Vec<f32>, String> {
        if let Ok(cache) = self.cache.lock()
            && let Some(v) = cache.get(name)
        {
            return Ok(v.clone());
        }
        let embeddings = self
            .opened
            .get_or_init(|| {
                tracing::info!("opening embeddings {}", self.dir.display());
                let e = open_embeddings(&self.dir).map_err(|e| e.to_string())?;
                if e.id() != self.expected {
                    return Err(format!(
                        "embeddings {} are {}, but the prior's learned part was trained with {}",
                        self.dir.display(),
                        e.id(),
                        self.expected
                    ));
                }
                // Checked once here, not as a wrong-length vector at every name asked.
                if e.dim() != self.dim {
                    return Err(format!(
                        "embeddings {} ({}) have vectors of {} numbers, but the prior's learned part was trained on {}-number vectors: give the embeddings it was trained with",
                        self.dir.display(),
                        e.id(),
                        e.dim(),
                        self.dim
                    ));
                }
                Ok(e)
            })
            .as_ref()
            .map_err(Clone::clone)?;
        let v = embeddings
            .embed_name(name)
            .unwrap_or_else(|| vec![0.0; embeddings.dim()]);
        if let Ok(mut cache) = self.cache.lock() {
            cache.insert(name.to_string(), v.clone());
        }
        Ok(v)
    }
}

/// `prior` with lazily opened embeddings from `dir` (or [`EMBEDDINGS_ENV`]) for names its learned
/// part lacks; unchanged without a learned part or a folder.
pub fn with_embeddings(prior: Arc<Prior>, dir: Option<&Path>) -> Arc<Prior> {
    match (prior.learned(), embeddings_dir(dir)) {
        (Some(learned), Some(dir)) if prior.embedder().is_none() => {
            let lazy = LazyEmbeddings::new(dir, &learned.embedding, learned.dim);
            Arc::new(prior.with_embedder(Embedder(Arc::new(lazy))))
        }
        _ => prior,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A tiny table where kitchen things share a direction and bathroom things another.
    fn table() -> Embeddings {
        let words = [
            ("fridge", [1.0, 0.0, 0.0]),
            ("kitchen", [0.9, 0.1, 0.0]),
            ("egg", [0.8, 0.0, 0.2]),
            ("toilet", [0.0, 1.0, 0.0]),
            ("bathroom", [0.1, 0.9, 0.0]),
            ("soap", [0.0, 0.8, 0.2]),
        ];
        Embeddings::from_words(
            "tiny",
            words.iter().map(|(w, v)| (w.to_string(), v.to_vec())),
        )
        .unwrap()
    }

    #[test]
    fn names_without_a_known_word_get_zeros_and_are_reported() {
        let (vectors, unknown) = embed_names(&table(), ["Fridge", "Zzyzx", ""]);
        assert_eq!(unknown, ["Zzyzx"]);
        assert_eq!(vectors["Zzyzx"], vec![0.0; 3]);
        assert!(vectors["Fridge"][0] > 0.99);
        assert!(!vectors.contains_key(""));
    }

    #[test]
    fn the_embeddings_folder_is_opened_only_for_a_name_the_file_lacks() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("vectors.txt"), "fridge 1 0 0\nsoap 0 1 0\n").unwrap();
        let lazy = LazyEmbeddings::new(dir.path().to_path_buf(), "vectors", 3);
        assert!(!lazy.is_open());
        let v = lazy.vector("Soap").unwrap();
        assert!(lazy.is_open());
        assert!((v[1] - 1.0).abs() < 1e-6, "{v:?}");
        let other = LazyEmbeddings::new(dir.path().to_path_buf(), "glove-6b-50d", 3);
        let err = other.vector("Soap").unwrap_err();
        assert!(err.contains("glove-6b-50d"), "{err}");
        let missing = LazyEmbeddings::new(dir.path().join("nowhere"), "vectors", 3);
        let err = missing.vector("Soap").unwrap_err();
        assert!(
            err.contains("nowhere") && err.contains(INSTALL_HINT),
            "{err}"
        );
        // Embeddings of the right name but another length (a 49-column matrix for a 50-number
        // prior) were taken, and every name then failed on its own.
        let narrower = LazyEmbeddings::new(dir.path().to_path_buf(), "vectors", 4);
        let err = narrower.vector("Soap").unwrap_err();
        assert!(
            err.contains("vectors of 3 numbers") && err.contains("4-number"),
            "{err}"
        );
    }
}
