//! The rule that gives every name a vector or refuses it, and the notes that say which of its
//! words were read otherwise than spelt.
//!
//! A word of a name (after [`split_name`]) is read, in this order:
//! 1. as spelt, if the embeddings have it;
//! 2. as one of its base forms (WordNet's morphy: `noun.exc`, then the regular endings), or
//!    else a plural/singular variant, that the embeddings have;
//! 3. as the nearest WordNet phrase above it whose words the embeddings all have: a synonym of
//!    its first sense, else a hypernym up to [`MAX_HYPERNYM_DEPTH`](crate::MAX_HYPERNYM_DEPTH) steps (`vise` → `holding
//!    device`);
//! 4. otherwise it is left out of the name's vector.
//!
//! A name with no word read by steps 1–3 has no vector and is refused
//! ([`EmbedError::UnknownName`]): a typo never plans on a vector of zeros. Every word read by
//! step 2, 3 or 4 gives a [`WordNote`], for the caller to report.
//!
//! A sentence-embedding model has a vector for any text, so for it the rule only decides what
//! to report and refuse: a word that is neither one whole token of its vocabulary nor a WordNet
//! noun is noted (embedded from its word pieces), and with WordNet at hand a name with no such
//! known word is refused. Without WordNet such names are only noted, since the model's
//! vocabulary alone lacks common nouns (`ladle`, `spatula`).

use crate::wordnet::{WORDNET_INSTALL_HINT, WordNet};
use crate::{EmbedError, Embeddings, split_name};

/// How a word of a name was read when not as spelt.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum WordReading {
    /// Another form of it: `boxes` as `box`.
    Form(String),
    /// A WordNet phrase: a synonym (distance 0) or the hypernym `distance` steps above it.
    Related {
        /// The phrase whose vector stands for the word.
        phrase: String,
        /// Steps up WordNet's tree (0 for a synonym).
        distance: usize,
    },
    /// A sentence model's word pieces, the word being neither a whole token nor a WordNet noun.
    Pieces,
    /// Left out of the name's vector.
    Skipped,
}

/// A word of a name that was not read as spelt.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct WordNote {
    /// The name (`BenchVise`).
    pub name: String,
    /// The word (`vise`).
    pub word: String,
    /// How it was read.
    pub reading: WordReading,
    /// The embeddings' id.
    pub embeddings: String,
}

impl std::fmt::Display for WordNote {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let Self {
            name,
            word,
            embeddings,
            ..
        } = self;
        match &self.reading {
            WordReading::Form(form) => write!(
                f,
                "`{name}`: `{word}` is not in {embeddings}; read as `{form}`"
            ),
            WordReading::Related {
                phrase,
                distance: 0,
            } => write!(
                f,
                "`{name}`: `{word}` is not in {embeddings}; read as its WordNet synonym `{phrase}`"
            ),
            WordReading::Related { phrase, distance } => write!(
                f,
                "`{name}`: `{word}` is not in {embeddings}; read as its WordNet hypernym `{phrase}` ({distance} up)"
            ),
            WordReading::Pieces => write!(
                f,
                "`{name}`: `{word}` is neither a word of {embeddings} nor a WordNet noun; embedded from its word pieces (check its spelling)"
            ),
            WordReading::Skipped => write!(
                f,
                "`{name}`: `{word}` is in neither {embeddings} nor WordNet; left out of the name's vector (check its spelling)"
            ),
        }
    }
}

/// A name's vector and the notes on words read otherwise than spelt.
#[derive(Clone, Debug, PartialEq)]
pub struct NameVector {
    /// Unit length, [`Embeddings::dim`] numbers.
    pub vector: Vec<f32>,
    /// One per word not read as spelt, in the name's word order.
    pub notes: Vec<WordNote>,
}

/// A word's vector, and how it was read when not as spelt.
type ReadWord = (Vec<f32>, Option<WordReading>);

impl Embeddings {
    /// The vector of `name` by the rule of this module, with `wordnet` for base forms and
    /// hypernyms when given; [`EmbedError::UnknownName`] when the name has no known word.
    pub fn resolve_name(
        &self,
        name: &str,
        wordnet: Option<&WordNet>,
    ) -> Result<NameVector, EmbedError> {
        let words = split_name(name);
        let note = |word: &str, reading| WordNote {
            name: name.to_owned(),
            word: word.to_owned(),
            reading,
            embeddings: self.id().to_owned(),
        };
        let unknown = |words: Vec<String>| EmbedError::UnknownName {
            name: name.to_owned(),
            embeddings: self.id().to_owned(),
            words,
            wordnet: wordnet.map_or_else(
                || {
                    format!(
                        "without WordNet (`{WORDNET_INSTALL_HINT}` adds base forms and hypernyms)"
                    )
                },
                |w| format!("nor WordNet ({})", w.dir().display()),
            ),
        };
        if self.is_model() {
            let mut notes = Vec::new();
            for w in &words {
                let known = self.whole_token(w) == Some(true)
                    || wordnet.is_some_and(|wn| !wn.base_forms(w).is_empty());
                if !known {
                    notes.push(note(w, WordReading::Pieces));
                }
            }
            if words.is_empty() || (wordnet.is_some() && notes.len() == words.len()) {
                return Err(unknown(words));
            }
            let vector = self
                .embed_name(name)
                .ok_or_else(|| unknown(words.clone()))?;
            return Ok(NameVector { vector, notes });
        }
        let mut sum = vec![0f64; self.dim()];
        let mut known = 0usize;
        let mut notes = Vec::new();
        let add = |v: &[f32], sum: &mut Vec<f64>| {
            for (s, x) in sum.iter_mut().zip(v) {
                *s += f64::from(*x);
            }
        };
        for w in &words {
            match self.read_word(w, wordnet)? {
                Some((vector, reading)) => {
                    add(&vector, &mut sum);
                    known += 1;
                    if let Some(r) = reading {
                        notes.push(note(w, r));
                    }
                }
                None => notes.push(note(w, WordReading::Skipped)),
            }
        }
        let norm = sum.iter().map(|s| s * s).sum::<f64>().sqrt();
        if known == 0 || norm == 0.0 || !norm.is_finite() {
            return Err(unknown(words));
        }
        Ok(NameVector {
            vector: sum.iter().map(|s| (s / norm) as f32).collect(),
            notes,
        })
    }

    /// One word's vector by steps 1–3 of the rule, and how it was read when not as spelt.
    fn read_word(
        &self,
        word: &str,
        wordnet: Option<&WordNet>,
    ) -> Result<Option<ReadWord>, EmbedError> {
        if let Some(v) = self.word(word) {
            return Ok(Some((v.to_vec(), None)));
        }
        if let Some(wn) = wordnet {
            for form in wn.base_forms(word) {
                if form != word
                    && let Some(v) = self.word(&form)
                {
                    return Ok(Some((v.to_vec(), Some(WordReading::Form(form)))));
                }
            }
        }
        if let Some((Some(form), v)) = self.word_form(word) {
            return Ok(Some((v.to_vec(), Some(WordReading::Form(form)))));
        }
        let Some(wn) = wordnet else {
            return Ok(None);
        };
        for (phrase, distance) in wn.related(word)? {
            if let Some(v) = self.phrase(&phrase) {
                return Ok(Some((v, Some(WordReading::Related { phrase, distance }))));
            }
        }
        Ok(None)
    }

    /// The mean of a phrase's word vectors, when the embeddings have every word of it.
    pub(crate) fn phrase(&self, phrase: &str) -> Option<Vec<f32>> {
        let words: Vec<&str> = phrase.split([' ', '-']).filter(|w| !w.is_empty()).collect();
        let mut sum = vec![0f32; self.dim()];
        for w in &words {
            for (s, x) in sum.iter_mut().zip(self.word(w)?) {
                *s += x;
            }
        }
        if words.is_empty() {
            return None;
        }
        Some(sum.iter().map(|s| s / words.len() as f32).collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::wordnet::tests::tiny_wordnet;

    fn table() -> Embeddings {
        let words = [
            ("table", vec![1.0, 0.0, 0.0]),
            ("holding", vec![0.0, 1.0, 0.0]),
            ("device", vec![0.0, 0.0, 1.0]),
            ("lamp", vec![0.6, 0.8, 0.0]),
            ("shelf", vec![0.0, 0.6, 0.8]),
        ];
        Embeddings::from_words("tiny", words.map(|(w, v)| (w.to_owned(), v))).unwrap()
    }

    #[test]
    fn known_words_give_no_notes() {
        let r = table().resolve_name("TableLamp", None).unwrap();
        assert!(r.notes.is_empty());
        let n = (1.6f32 * 1.6 + 0.8 * 0.8).sqrt();
        assert!((r.vector[0] - 1.6 / n).abs() < 1e-6, "{:?}", r.vector);
    }

    #[test]
    fn a_name_with_no_known_word_is_refused_and_says_which() {
        let err = table().resolve_name("Xyzzyblorp", None).unwrap_err();
        let text = err.to_string();
        assert!(
            text.contains("`Xyzzyblorp`") && text.contains("xyzzyblorp") && text.contains("tiny"),
            "{text}"
        );
        assert!(text.contains(WORDNET_INSTALL_HINT), "{text}");
        assert!(table().resolve_name("", None).is_err());
        assert!(table().resolve_name("42", None).is_err());
    }

    #[test]
    fn an_unknown_word_beside_a_known_one_is_skipped_with_a_note() {
        let r = table().resolve_name("XyzzyLamp", None).unwrap();
        assert_eq!(r.notes.len(), 1);
        assert_eq!(r.notes[0].reading, WordReading::Skipped);
        assert_eq!(r.notes[0].word, "xyzzy");
        assert!(r.notes[0].to_string().contains("`XyzzyLamp`"));
        assert!((r.vector[0] - 0.6).abs() < 1e-6, "{:?}", r.vector);
    }

    #[test]
    fn wordnet_reads_base_forms_and_hypernyms_and_says_so() {
        let dir = tempfile::tempdir().unwrap();
        tiny_wordnet(dir.path());
        let wn = WordNet::open(dir.path()).unwrap();
        let t = table();
        // `workbench` is not in the table: its first hypernym with known words is `table`
        // (worktable and work table are not), two steps up.
        let r = t.resolve_name("Workbench", Some(&wn)).unwrap();
        assert_eq!(
            r.notes[0].reading,
            WordReading::Related {
                phrase: "table".into(),
                distance: 2
            }
        );
        assert!((r.vector[0] - 1.0).abs() < 1e-6);
        let r = t.resolve_name("Vise", Some(&wn)).unwrap();
        assert_eq!(
            r.notes[0].reading,
            WordReading::Related {
                phrase: "holding device".into(),
                distance: 1
            }
        );
        let h = std::f32::consts::FRAC_1_SQRT_2;
        assert!((r.vector[1] - h).abs() < 1e-6 && (r.vector[2] - h).abs() < 1e-6);
        let r = t.resolve_name("Shelves", Some(&wn)).unwrap();
        assert_eq!(r.notes[0].reading, WordReading::Form("shelf".into()));
        // Without WordNet, neither is known.
        assert!(t.resolve_name("Vise", None).is_err());
        let err = t.resolve_name("Xyzzy", Some(&wn)).unwrap_err().to_string();
        assert!(err.contains("nor WordNet"), "{err}");
    }

    #[test]
    fn the_rule_agrees_with_embed_name_where_every_word_is_known() {
        let t = table();
        for name in ["Table", "TableLamp", "ShelfLamp", "HoldingDevice", "Lamps"] {
            let r = t.resolve_name(name, None).unwrap();
            let old = t.embed_name(name).unwrap();
            assert!(
                r.vector.iter().zip(&old).all(|(a, b)| (a - b).abs() < 1e-6),
                "{name}"
            );
        }
    }
}
