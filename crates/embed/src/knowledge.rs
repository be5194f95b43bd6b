//! A second knowledge source beside a name's word vector: what WordNet says of the name (the
//! nouns above it and its gloss), embedded with the same vectors. A word vector places `vise`
//! near the words it is used with; WordNet says it is a holding device for a workbench, which is
//! the kind of knowledge that says where a thing is kept when no training house had it.
//!
//! Its control reads the same kind of knowledge of another noun, picked by hashing the name
//! ([`WordNet::lemma_for`]): real WordNet vectors with the meaning shuffled away, so that a gain
//! the control also shows is the extra inputs, not WordNet's knowledge.

use crate::wordnet::WordNet;
use crate::{EmbedError, Embeddings, split_name};

/// Which knowledge stands beside the word vectors.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Knowledge {
    /// WordNet's synonyms, hypernyms and gloss of the name.
    WordNet,
    /// The control: the same of a noun picked by hashing the name.
    WordNetShuffled,
}

/// Gloss words that say nothing of a thing.
const STOPWORDS: [&str; 24] = [
    "the",
    "and",
    "for",
    "with",
    "that",
    "used",
    "which",
    "from",
    "into",
    "its",
    "are",
    "any",
    "has",
    "have",
    "usually",
    "often",
    "one",
    "other",
    "especially",
    "such",
    "was",
    "can",
    "may",
    "not",
];

impl Knowledge {
    /// Every source, in the order of reports.
    pub const ALL: [Knowledge; 2] = [Knowledge::WordNet, Knowledge::WordNetShuffled];

    /// Its name on the command line and in ids.
    pub fn name(self) -> &'static str {
        match self {
            Knowledge::WordNet => "wordnet",
            Knowledge::WordNetShuffled => "wordnet-shuffled",
        }
    }

    /// The source a name names.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|k| k.name() == name)
    }

    /// The id of vectors `base` with this knowledge beside them (`glove-6b-50d+wordnet`).
    pub fn id(self, base: &str) -> String {
        format!("{base}+{}", self.name())
    }

    /// An id split into the embeddings' own id and the knowledge beside them.
    ///
    /// # Errors
    /// An id whose part after `+` names no knowledge source.
    pub fn split_id(id: &str) -> Result<(&str, Option<Knowledge>), String> {
        match id.rsplit_once('+') {
            None => Ok((id, None)),
            Some((base, k)) => Self::from_name(k).map(|k| (base, Some(k))).ok_or_else(|| {
                format!(
                    "`{id}`: `{k}` is no knowledge source this ferret knows (wordnet, wordnet-shuffled)"
                )
            }),
        }
    }
}

/// The WordNet lemma of a name: its words joined by `_` (`dining_table`), run together
/// (`countertop`), else its last word, the head of an English compound (`TVStand` → `stand`);
/// the first that is a noun.
pub fn lemma_of(name: &str, wordnet: &WordNet) -> Option<String> {
    let words = split_name(name);
    let last = words.last()?.clone();
    [words.join("_"), words.concat(), last]
        .into_iter()
        .find_map(|w| wordnet.base_forms(&w).into_iter().next())
}

/// `word` and `knowledge` side by side, each unit length and scaled by 1/√2, so that the whole
/// is unit length and a cosine of two such vectors is the mean of the two halves' cosines;
/// zeros where there is no knowledge.
pub fn joined(word: &[f32], knowledge: Option<&[f32]>) -> Vec<f32> {
    let half = std::f32::consts::FRAC_1_SQRT_2;
    let unit = |v: &[f32]| -> Vec<f32> {
        let n = v.iter().map(|x| x * x).sum::<f32>().sqrt();
        v.iter()
            .map(|x| if n > 0.0 { half * x / n } else { 0.0 })
            .collect()
    };
    let mut out = unit(word);
    match knowledge {
        Some(k) => out.extend(unit(k)),
        None => out.extend(std::iter::repeat_n(0.0, word.len())),
    }
    out
}

impl Embeddings {
    /// The vector of what WordNet says of `name` ([`Knowledge::WordNet`]) or of the noun its
    /// control picks for it: the mean of the vectors of its synonyms and hypernyms (up to three
    /// steps) and of its gloss's words, each part unit length, the whole unit length. `None`
    /// when WordNet has no noun for it, or the embeddings know none of those words.
    pub fn knowledge_vector(
        &self,
        name: &str,
        wordnet: &WordNet,
        knowledge: Knowledge,
    ) -> Result<Option<Vec<f32>>, EmbedError> {
        let lemma = match knowledge {
            Knowledge::WordNet => lemma_of(name, wordnet),
            Knowledge::WordNetShuffled => wordnet.lemma_for(name).map(str::to_owned),
        };
        let Some(lemma) = lemma else {
            return Ok(None);
        };
        let Some(sense) = wordnet.first_sense(&lemma)? else {
            return Ok(None);
        };
        let phrases: Vec<String> = wordnet
            .related(&lemma)?
            .into_iter()
            .map(|(p, _)| p)
            .collect();
        let definition = sense.gloss.split(['"', ';']).next().unwrap_or("");
        let gloss: Vec<String> = definition
            .split(|c: char| !c.is_ascii_alphabetic())
            .map(str::to_lowercase)
            .filter(|w| w.len() > 2 && !STOPWORDS.contains(&w.as_str()))
            .collect();
        let parts = [
            self.text_vector(phrases.iter().map(String::as_str)),
            self.text_vector(gloss.iter().map(String::as_str)),
        ];
        let mut sum = vec![0f32; self.dim()];
        let mut any = false;
        for part in parts.into_iter().flatten() {
            let n = part.iter().map(|x| x * x).sum::<f32>().sqrt();
            if n > 0.0 {
                any = true;
                sum.iter_mut().zip(&part).for_each(|(s, x)| *s += x / n);
            }
        }
        let n = sum.iter().map(|x| x * x).sum::<f32>().sqrt();
        Ok((any && n > 0.0).then(|| sum.iter().map(|x| x / n).collect()))
    }

    /// The mean vector of texts (words or phrases) the embeddings know, skipping the others.
    fn text_vector<'a>(&self, texts: impl Iterator<Item = &'a str>) -> Option<Vec<f32>> {
        let mut sum = vec![0f32; self.dim()];
        let mut known = 0usize;
        for t in texts {
            let v = if self.is_model() {
                self.embed_name(t)
            } else {
                self.phrase(t)
            };
            if let Some(v) = v {
                sum.iter_mut().zip(&v).for_each(|(s, x)| *s += x);
                known += 1;
            }
        }
        (known > 0).then(|| sum.iter().map(|s| s / known as f32).collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::wordnet::tests::tiny_wordnet;

    fn table() -> Embeddings {
        let words = [
            ("table", vec![1.0, 0.0, 0.0]),
            ("furniture", vec![0.8, 0.6, 0.0]),
            ("holding", vec![0.0, 1.0, 0.0]),
            ("device", vec![0.0, 0.0, 1.0]),
            ("strong", vec![0.0, 0.0, 1.0]),
        ];
        Embeddings::from_words("tiny", words.map(|(w, v)| (w.to_owned(), v))).unwrap()
    }

    #[test]
    fn ids_carry_the_knowledge_and_read_back() {
        assert_eq!(
            Knowledge::WordNet.id("glove-6b-50d"),
            "glove-6b-50d+wordnet"
        );
        assert_eq!(
            Knowledge::split_id("glove-6b-50d+wordnet-shuffled").unwrap(),
            ("glove-6b-50d", Some(Knowledge::WordNetShuffled))
        );
        assert_eq!(Knowledge::split_id("tiny").unwrap(), ("tiny", None));
        assert!(Knowledge::split_id("tiny+cyc").unwrap_err().contains("cyc"));
    }

    #[test]
    fn a_workbench_is_known_by_the_tables_above_it_and_its_gloss() {
        let dir = tempfile::tempdir().unwrap();
        tiny_wordnet(dir.path());
        let wn = WordNet::open(dir.path()).unwrap();
        let t = table();
        let v = t
            .knowledge_vector("Workbench", &wn, Knowledge::WordNet)
            .unwrap()
            .unwrap();
        // Phrases: table and furniture (mean 0.9, 0.3, 0); gloss "a strong worktable": strong.
        let n = (0.9f32 * 0.9 + 0.3 * 0.3).sqrt();
        let want = [0.9 / n, 0.3 / n, 1.0];
        let m = want.iter().map(|x| x * x).sum::<f32>().sqrt();
        for (a, b) in v.iter().zip(want) {
            assert!((a - b / m).abs() < 1e-5, "{v:?}");
        }
        assert_eq!(
            t.knowledge_vector("Xyzzy", &wn, Knowledge::WordNet)
                .unwrap(),
            None
        );
        // The control reads another noun's, the same one every time.
        let a = t
            .knowledge_vector("Workbench", &wn, Knowledge::WordNetShuffled)
            .unwrap();
        let b = t
            .knowledge_vector("Workbench", &wn, Knowledge::WordNetShuffled)
            .unwrap();
        assert_eq!(a, b);
        assert_eq!(lemma_of("WorkBench", &wn).as_deref(), Some("work_bench"));
        assert_eq!(lemma_of("SteelVise", &wn).as_deref(), Some("vise"));
    }

    #[test]
    fn joined_halves_are_unit_length_together() {
        let v = joined(&[3.0, 4.0], Some(&[0.0, 2.0]));
        let n: f32 = v.iter().map(|x| x * x).sum();
        assert!((n - 1.0).abs() < 1e-6, "{v:?}");
        assert_eq!(joined(&[1.0, 0.0], None)[2..], [0.0, 0.0]);
    }
}
