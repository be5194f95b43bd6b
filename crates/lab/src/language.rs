//! Language for the learned likelihood: word vectors of the training houses' names, training the
//! learned part of a prior, and the lazily opened embeddings that give vectors of names a prior
//! file lacks (so a run whose every name is in the file opens no embedding file).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, OnceLock, PoisonError};

use ferret_embed::{EMBEDDINGS_ENV, Embeddings, INSTALL_HINT, WordNet};
use ferret_plan::learned::{self, LearnedSettings, NameVectors};
use ferret_plan::{Embedder, Prior};
use ferret_world::Scene;

use crate::error::{LabError, Result};

pub use ferret_embed::{Knowledge, WORDNET_INSTALL_HINT};

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
    /// One line per word of a name read otherwise than spelt (its base form, a WordNet
    /// hypernym, left out), each word once.
    pub notes: Vec<String>,
    /// The WordNet folder the rule read, if a name needed it.
    pub wordnet: Option<PathBuf>,
}

/// WordNet from `dir`, else from [`ferret_embed::WORDNET_ENV`] or Debian's folder; `None` when
/// none is given or installed. A folder given or named that cannot be read is an error.
pub fn open_wordnet(dir: Option<&Path>) -> Result<Option<WordNet>> {
    let Some(dir) = dir.map(Path::to_path_buf).or_else(WordNet::default_dir) else {
        return Ok(None);
    };
    WordNet::open(&dir)
        .map(Some)
        .map_err(|e| LabError::invalid(format!("WordNet: {e}")))
}

/// WordNet opened when a name first needs it ([`open_wordnet`]'s folder): reading its noun
/// index costs a third of a second and 30 MB, which a run whose every word the vectors know
/// never pays.
#[derive(Debug, Default)]
pub struct LazyWordNet {
    dir: Option<PathBuf>,
    opened: OnceLock<std::result::Result<Option<WordNet>, String>>,
}

impl LazyWordNet {
    /// WordNet from `dir` (else the default folder), not read yet.
    pub fn new(dir: Option<&Path>) -> Self {
        Self {
            dir: dir.map(Path::to_path_buf),
            opened: OnceLock::new(),
        }
    }

    /// WordNet, read at the first call; `None` when none is installed or given.
    pub fn get(&self) -> std::result::Result<Option<&WordNet>, String> {
        self.opened
            .get_or_init(|| open_wordnet(self.dir.as_deref()).map_err(|e| e.to_string()))
            .as_ref()
            .map(Option::as_ref)
            .map_err(Clone::clone)
    }

    /// Whether it has been read.
    pub fn is_open(&self) -> bool {
        self.opened.get().is_some()
    }
}

/// What gives names their vectors: the embeddings, WordNet for words they lack, and a second
/// knowledge source beside them.
#[derive(Clone, Copy)]
pub struct NameSource<'a> {
    /// The word (or sentence) vectors.
    pub embeddings: &'a Embeddings,
    /// WordNet, read when a name first needs it.
    pub wordnet: &'a LazyWordNet,
    /// What stands beside each name's vector, if anything.
    pub knowledge: Option<Knowledge>,
}

impl NameSource<'_> {
    /// The id a prior file records (`glove-6b-50d`, `glove-6b-50d+wordnet`).
    pub fn id(&self) -> String {
        match self.knowledge {
            Some(k) => k.id(self.embeddings.id()),
            None => self.embeddings.id().to_string(),
        }
    }

    /// The length of every vector.
    pub fn dim(&self) -> usize {
        self.embeddings.dim() * if self.knowledge.is_some() { 2 } else { 1 }
    }

    /// The vector of `name` by [`Embeddings::resolve_name`]'s rule, with its knowledge beside
    /// it, and the notes on how it was read; an error for a name with no known word.
    pub fn vector(&self, name: &str) -> std::result::Result<(Vec<f32>, Vec<String>), String> {
        // Without WordNet first: a name whose every word the vectors have reads the same
        // either way, and then WordNet is never read.
        let plain = self.embeddings.resolve_name(name, None);
        let resolved = match plain {
            Ok(r) if r.notes.is_empty() => r,
            other => {
                tracing::debug!(name, without = ?other.map(|r| r.notes), "reading with WordNet");
                self.embeddings
                    .resolve_name(name, self.wordnet.get()?)
                    .map_err(|e| e.to_string())?
            }
        };
        let mut notes: Vec<String> = resolved.notes.iter().map(ToString::to_string).collect();
        let Some(knowledge) = self.knowledge else {
            return Ok((resolved.vector, notes));
        };
        let wordnet = self.wordnet.get()?.ok_or_else(|| {
            format!(
                "{} vectors need WordNet (`{}`, or FERRET_WORDNET)",
                self.id(),
                ferret_embed::WORDNET_INSTALL_HINT
            )
        })?;
        let known = self
            .embeddings
            .knowledge_vector(name, wordnet, knowledge)
            .map_err(|e| e.to_string())?;
        if known.is_none() && knowledge == Knowledge::WordNet {
            notes.push(format!(
                "`{name}`: WordNet has no noun for it; its WordNet half is zeros"
            ));
        }
        Ok((
            ferret_embed::joined(&resolved.vector, known.as_deref()),
            notes,
        ))
    }
}

/// Vectors by name.
pub type NameVectorsByName = BTreeMap<String, Vec<f32>>;

/// The vectors of `names` from `source`, with the notes on words read otherwise than spelt; an
/// error naming the first name with no known word.
pub fn embed_names<'a>(
    source: &NameSource<'_>,
    names: impl IntoIterator<Item = &'a str>,
) -> Result<(NameVectorsByName, Vec<String>)> {
    let mut vectors = BTreeMap::new();
    let mut notes = Vec::new();
    for name in names {
        if name.is_empty() {
            continue;
        }
        let (vector, said) = source.vector(name).map_err(LabError::invalid)?;
        notes.extend(said);
        vectors.insert(name.to_string(), vector);
    }
    Ok((vectors, notes))
}

/// `prior` (counted on `scenes`) with a learned part trained on the same houses over the names'
/// vectors from `source`.
pub fn train_learned(
    scenes: &[Scene],
    prior: &Prior,
    source: &NameSource<'_>,
    settings: &LearnedSettings,
) -> Result<(Prior, LearnedReport)> {
    let mut names = std::collections::BTreeSet::new();
    for s in scenes {
        names.extend(learned::scene_names(s));
    }
    let (vectors, notes) = embed_names(source, names.iter().map(String::as_str))
        .map_err(|e| LabError::invalid(format!("the training houses: {e}")))?;
    let report = LearnedReport {
        names: vectors.len(),
        notes,
        // Only a WordNet a name needed was read; asking for it here would read it.
        wordnet: if source.wordnet.is_open() {
            source
                .wordnet
                .get()
                .ok()
                .flatten()
                .map(|w| w.dir().to_path_buf())
        } else {
            None
        },
    };
    let refs: Vec<&Scene> = scenes.iter().collect();
    let learned = learned::train(&refs, prior, &source.id(), vectors, settings)?;
    Ok((prior.with_learned(learned), report))
}

/// Vectors of names a prior file lacks, from an embeddings folder opened when the first such
/// name is asked, and kept per name.
pub struct LazyEmbeddings {
    dir: PathBuf,
    expected: String,
    dim: usize,
    opened: OnceLock<std::result::Result<Opened, String>>,
    /// Each name's vector (or why it has none) and the notes on its words, said once.
    cache: Mutex<BTreeMap<String, Resolved>>,
}

/// The embeddings, WordNet when installed, and the knowledge the prior's vectors carry.
type Opened = (Embeddings, LazyWordNet, Option<Knowledge>);

/// A name as the rule resolved it.
type Resolved = (std::result::Result<Vec<f32>, String>, Vec<String>);

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

impl LazyEmbeddings {
    /// The embeddings (and WordNet, when installed), opened and checked at the first call.
    fn opened(&self) -> std::result::Result<&Opened, String> {
        self.opened
            .get_or_init(|| {
                tracing::info!("opening embeddings {}", self.dir.display());
                let e = open_embeddings(&self.dir).map_err(|e| e.to_string())?;
                let (base, knowledge) = Knowledge::split_id(&self.expected)?;
                if e.id() != base {
                    return Err(format!(
                        "embeddings {} are {}, but the prior's learned part was trained with {base}",
                        self.dir.display(),
                        e.id(),
                    ));
                }
                let dim = e.dim() * if knowledge.is_some() { 2 } else { 1 };
                // Checked once here, not as a wrong-length vector at every name asked.
                if dim != self.dim {
                    return Err(format!(
                        "embeddings {} ({}) have vectors of {} numbers, but the prior's learned part was trained on {}-number vectors: give the embeddings it was trained with",
                        self.dir.display(),
                        self.expected,
                        dim,
                        self.dim
                    ));
                }
                Ok((e, LazyWordNet::new(None), knowledge))
            })
            .as_ref()
            .map_err(Clone::clone)
    }

    fn resolve(&self, name: &str) -> std::result::Result<Resolved, String> {
        // Held while a name is resolved, so that threads asking for the same new name at once
        // resolve it once and say its notes once.
        let mut cache = self.cache.lock().unwrap_or_else(PoisonError::into_inner);
        if let Some(r) = cache.get(name) {
            return Ok(r.clone());
        }
        let (embeddings, wordnet, knowledge) = self.opened()?;
        let source = NameSource {
            embeddings,
            wordnet,
            knowledge: *knowledge,
        };
        let resolved = match source.vector(name) {
            Ok((vector, notes)) => {
                for n in &notes {
                    tracing::warn!("{n}");
                }
                (Ok(vector), notes)
            }
            Err(e) => (Err(e), Vec::new()),
        };
        cache.insert(name.to_string(), resolved.clone());
        Ok(resolved)
    }
}

impl NameVectors for LazyEmbeddings {
    fn vector(&self, name: &str) -> std::result::Result<Vec<f32>, String> {
        self.resolve(name)?.0
    }

    fn notes(&self, name: &str) -> Vec<String> {
        self.resolve(name).map(|r| r.1).unwrap_or_default()
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
    fn a_name_without_a_known_word_is_refused_and_a_skipped_word_noted() {
        let table = table();
        let wordnet = LazyWordNet::default();
        let source = NameSource {
            embeddings: &table,
            wordnet: &wordnet,
            knowledge: None,
        };
        let err = embed_names(&source, ["Fridge", "Zzyzx", ""]).unwrap_err();
        assert!(err.to_string().contains("`Zzyzx`"), "{err}");
        let (vectors, notes) = embed_names(&source, ["Fridge", "ZzyzxSoap", ""]).unwrap();
        assert_eq!(notes.len(), 1, "{notes:?}");
        assert!(
            notes[0].contains("`ZzyzxSoap`") && notes[0].contains("zzyzx"),
            "{notes:?}"
        );
        assert!(vectors["ZzyzxSoap"][1] > 0.9);
        assert!(vectors["Fridge"][0] > 0.99);
        assert!(!vectors.contains_key(""));
    }

    #[test]
    fn wordnet_is_read_only_for_a_word_the_vectors_lack() {
        let table = table();
        let wordnet = LazyWordNet::new(Some(Path::new("/nowhere")));
        let source = NameSource {
            embeddings: &table,
            wordnet: &wordnet,
            knowledge: None,
        };
        let (vectors, notes) = embed_names(&source, ["Fridge", "SoapToilet"]).unwrap();
        assert_eq!((vectors.len(), notes.len()), (2, 0));
        assert!(!wordnet.is_open());
        let err = embed_names(&source, ["ZzyzxSoap"]).unwrap_err().to_string();
        assert!(wordnet.is_open());
        assert!(err.contains("nowhere"), "{err}");
    }

    #[test]
    fn a_lazy_name_is_noted_once_and_a_typo_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("vectors.txt"), "fridge 1 0 0\nsoap 0 1 0\n").unwrap();
        let lazy = LazyEmbeddings::new(dir.path().to_path_buf(), "vectors", 3);
        let err = lazy.vector("Xyzzyblorp").unwrap_err();
        assert!(err.contains("`Xyzzyblorp`"), "{err}");
        assert!(lazy.vector("BlorpSoap").is_ok());
        let notes = lazy.notes("BlorpSoap");
        assert_eq!(notes.len(), 1, "{notes:?}");
        assert!(notes[0].contains("blorp"), "{notes:?}");
        assert!(lazy.notes("Soap").is_empty());
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
