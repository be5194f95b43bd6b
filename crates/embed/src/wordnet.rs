//! WordNet's nouns, read from the database files of Debian's `wordnet-base` package (Princeton
//! WordNet 3.0): base forms of inflected words, the words of a noun's first sense (its synonyms),
//! the nouns above it (hypernyms, nearest first) and its gloss.
//!
//! Written here rather than taken from the `wordnet-db` crate, which parses all four parts of
//! speech eagerly (0.9 s and 197 MB peak on this project's 2-core machine) where a run needs a
//! few noun lookups, and which stops the process on a malformed line instead of naming it: this
//! reader keeps only the noun index in memory (about 80 000 lemmas), reads a synset's line from
//! `data.noun` when it is asked, and answers a malformed line with the file and line.

use std::collections::{BTreeSet, HashMap, VecDeque};
use std::io::{BufRead, BufReader, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use crate::EmbedError;

/// The environment variable naming a WordNet dictionary folder (one holding `index.noun`,
/// `data.noun` and `noun.exc`).
pub const WORDNET_ENV: &str = "FERRET_WORDNET";

/// Where Debian's `wordnet-base` puts the dictionary, used when [`WORDNET_ENV`] is unset.
pub const WORDNET_DEFAULT_DIR: &str = "/usr/share/wordnet";

/// What installs WordNet, quoted in error messages.
pub const WORDNET_INSTALL_HINT: &str = "scripts/embeddings.sh install wordnet";

/// How far up the hypernym tree a substitute is looked for: past three steps WordNet's nouns
/// are abstractions (`instrumentality`, `artifact`, `whole`) that say nothing of where a thing is
/// kept.
pub const MAX_HYPERNYM_DEPTH: usize = 3;

/// Morphy's detachment rules for nouns (WordNet's `morphy(7WN)`), tried in this order.
const NOUN_SUFFIXES: [(&str, &str); 8] = [
    ("s", ""),
    ("ses", "s"),
    ("xes", "x"),
    ("zes", "z"),
    ("ches", "ch"),
    ("shes", "sh"),
    ("men", "man"),
    ("ies", "y"),
];

/// One noun synset as read from `data.noun`.
#[derive(Clone, Debug, PartialEq)]
pub struct Synset {
    /// Its words, as phrases (`bench vise`: WordNet's underscores become spaces), in file order.
    pub words: Vec<String>,
    /// Byte offsets of its hypernyms (plain and instance) in `data.noun`.
    pub hypernyms: Vec<u64>,
    /// Its gloss: the definition, with any examples.
    pub gloss: String,
}

/// The nouns of a WordNet dictionary folder.
#[derive(Debug)]
pub struct WordNet {
    dir: PathBuf,
    data: PathBuf,
    /// Lemma (lowercase, `_` between words) → offsets of its senses in `data.noun`, most
    /// frequent first.
    senses: HashMap<String, Vec<u64>>,
    /// Irregular inflection → base forms (`noun.exc`).
    exceptions: HashMap<String, Vec<String>>,
    /// Every lemma in the index's (sorted) order, for [`Self::lemma_for`].
    lemmas: Vec<String>,
}

impl WordNet {
    /// The folder [`WORDNET_ENV`] names, else [`WORDNET_DEFAULT_DIR`] when it holds a noun
    /// index; `None` when neither gives one.
    pub fn default_dir() -> Option<PathBuf> {
        match std::env::var_os(WORDNET_ENV) {
            Some(dir) if !dir.is_empty() => Some(PathBuf::from(dir)),
            _ => {
                let dir = PathBuf::from(WORDNET_DEFAULT_DIR);
                dir.join("index.noun").is_file().then_some(dir)
            }
        }
    }

    /// Reads the noun index and exceptions of a dictionary folder.
    pub fn open(dir: &Path) -> Result<Self, EmbedError> {
        let index = dir.join("index.noun");
        let data = dir.join("data.noun");
        if !index.is_file() || !data.is_file() {
            return Err(EmbedError::WordNet {
                path: dir.to_owned(),
                what: format!(
                    "no WordNet dictionary here (index.noun and data.noun): `{WORDNET_INSTALL_HINT}` installs Debian's wordnet-base, or set {WORDNET_ENV}"
                ),
            });
        }
        let mut senses = HashMap::new();
        let mut lemmas = Vec::new();
        for_lines(&index, |line_no, line| {
            // The licence header's lines start with spaces.
            if line.starts_with(' ') || line.is_empty() {
                return Ok(());
            }
            let (lemma, offsets) = parse_index_line(line).map_err(|what| EmbedError::Text {
                path: index.clone(),
                line: line_no,
                what,
            })?;
            lemmas.push(lemma.clone());
            senses.insert(lemma, offsets);
            Ok(())
        })?;
        let mut exceptions: HashMap<String, Vec<String>> = HashMap::new();
        let exc = dir.join("noun.exc");
        // The exception list is optional: without it only the regular rules give base forms.
        if exc.is_file() {
            for_lines(&exc, |_, line| {
                let mut words = line.split_whitespace();
                if let Some(inflected) = words.next() {
                    exceptions
                        .entry(inflected.to_owned())
                        .or_default()
                        .extend(words.map(str::to_owned));
                }
                Ok(())
            })?;
        }
        tracing::debug!(dir = %dir.display(), lemmas = senses.len(), "read WordNet's nouns");
        Ok(Self {
            dir: dir.to_owned(),
            data,
            senses,
            exceptions,
            lemmas,
        })
    }

    /// A noun lemma picked by `key` alone (a hash into the index's sorted lemmas): what a
    /// shuffled control reads instead of the name's own sense — real WordNet knowledge, of
    /// another noun.
    pub fn lemma_for(&self, key: &str) -> Option<&str> {
        if self.lemmas.is_empty() {
            return None;
        }
        // FNV-1a: fixed across platforms and releases, unlike the standard library's hasher.
        let h = key.bytes().fold(0xcbf2_9ce4_8422_2325_u64, |h, b| {
            (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
        });
        self.lemmas
            .get((h % self.lemmas.len() as u64) as usize)
            .map(String::as_str)
    }

    /// The folder it was read from.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Number of noun lemmas.
    pub fn len(&self) -> usize {
        self.senses.len()
    }

    /// Whether it holds no noun.
    pub fn is_empty(&self) -> bool {
        self.senses.is_empty()
    }

    /// Whether `lemma` (lowercase, words joined by `_` or spaces) is a noun.
    pub fn is_noun(&self, lemma: &str) -> bool {
        self.senses.contains_key(&lemma.replace(' ', "_"))
    }

    /// The noun lemmas `word` is a form of, as morphy finds them: the word itself if it is a
    /// noun, its irregular base forms (`noun.exc`), then the regular detachments (`boxes` →
    /// `box`, `shelves` only through the exception list).
    pub fn base_forms(&self, word: &str) -> Vec<String> {
        let word = word.to_lowercase();
        let mut forms = Vec::new();
        let push = |w: String, forms: &mut Vec<String>| {
            if self.senses.contains_key(&w) && !forms.contains(&w) {
                forms.push(w);
            }
        };
        push(word.clone(), &mut forms);
        for base in self.exceptions.get(&word).into_iter().flatten() {
            push(base.clone(), &mut forms);
        }
        for (suffix, replacement) in NOUN_SUFFIXES {
            if let Some(stem) = word.strip_suffix(suffix)
                && !stem.is_empty()
            {
                push(format!("{stem}{replacement}"), &mut forms);
            }
        }
        forms
    }

    /// The first (most frequent) sense of the noun `lemma`, if it is one.
    pub fn first_sense(&self, lemma: &str) -> Result<Option<Synset>, EmbedError> {
        match self
            .senses
            .get(&lemma.replace(' ', "_"))
            .and_then(|s| s.first())
        {
            Some(&offset) => self.synset(offset).map(Some),
            None => Ok(None),
        }
    }

    /// Phrases for `word` nearest first: the other words of its first sense, then the words of
    /// the synsets above it, breadth first, up to [`MAX_HYPERNYM_DEPTH`] steps. Each phrase
    /// comes with its distance (0 for a synonym).
    pub fn related(&self, word: &str) -> Result<Vec<(String, usize)>, EmbedError> {
        let mut out = Vec::new();
        let Some(lemma) = self.base_forms(word).into_iter().next() else {
            return Ok(out);
        };
        let Some(&first) = self.senses.get(&lemma).and_then(|s| s.first()) else {
            return Ok(out);
        };
        let own = lemma.replace('_', " ");
        let mut seen_words = BTreeSet::from([own]);
        let mut seen = BTreeSet::from([first]);
        let mut queue = VecDeque::from([(first, 0usize)]);
        while let Some((offset, depth)) = queue.pop_front() {
            let synset = self.synset(offset)?;
            for w in &synset.words {
                if seen_words.insert(w.clone()) {
                    out.push((w.clone(), depth));
                }
            }
            if depth < MAX_HYPERNYM_DEPTH {
                for &h in &synset.hypernyms {
                    if seen.insert(h) {
                        queue.push_back((h, depth + 1));
                    }
                }
            }
        }
        Ok(out)
    }

    /// The synset at `offset` in `data.noun`.
    pub fn synset(&self, offset: u64) -> Result<Synset, EmbedError> {
        let io = |source| EmbedError::Io {
            path: self.data.clone(),
            source,
        };
        let mut file = crate::file::open(&self.data)?;
        file.seek(SeekFrom::Start(offset)).map_err(io)?;
        // A synset's line is a few hundred bytes; the longest in WordNet 3.0 is under 12 kB.
        let mut line = Vec::new();
        BufReader::new(file.take(1 << 16))
            .read_until(b'\n', &mut line)
            .map_err(io)?;
        let bad = |what: String| EmbedError::WordNet {
            path: self.data.clone(),
            what: format!("the synset at byte {offset}: {what}"),
        };
        let line = std::str::from_utf8(&line)
            .map_err(|_| bad("not UTF-8 text".to_owned()))?
            .trim_end();
        parse_data_line(line, offset).map_err(bad)
    }
}

/// Calls `f` with every line of a text file (numbered from 1), naming the file in errors.
fn for_lines(
    path: &Path,
    mut f: impl FnMut(usize, &str) -> Result<(), EmbedError>,
) -> Result<(), EmbedError> {
    let io = |source| EmbedError::Io {
        path: path.to_owned(),
        source,
    };
    let mut reader = BufReader::new(crate::file::open(path)?);
    let mut buf = Vec::new();
    let mut line_no = 0;
    loop {
        buf.clear();
        if reader.read_until(b'\n', &mut buf).map_err(io)? == 0 {
            return Ok(());
        }
        line_no += 1;
        let line = std::str::from_utf8(&buf).map_err(|_| EmbedError::Text {
            path: path.to_owned(),
            line: line_no,
            what: "not UTF-8 text".to_owned(),
        })?;
        f(line_no, line.trim_end_matches(['\n', '\r']))?;
    }
}

/// `lemma pos synset_cnt p_cnt [ptr_symbol…] sense_cnt tagsense_cnt offset…`
fn parse_index_line(line: &str) -> Result<(String, Vec<u64>), String> {
    let fields: Vec<&str> = line.split_whitespace().collect();
    let number = |i: usize, what: &str| -> Result<usize, String> {
        fields
            .get(i)
            .ok_or_else(|| format!("ends before its {what}"))?
            .parse::<usize>()
            .map_err(|_| format!("its {what} `{}` is not a number", fields[i]))
    };
    let lemma = fields.first().ok_or("an empty line")?;
    let synsets = number(2, "synset count")?;
    let pointers = number(3, "pointer count")?;
    let first = 4 + pointers + 2;
    if fields.len() != first + synsets {
        return Err(format!(
            "{} fields, where {synsets} synsets and {pointers} pointer kinds make {}",
            fields.len(),
            first + synsets
        ));
    }
    let offsets = fields[first..]
        .iter()
        .map(|f| {
            f.parse::<u64>()
                .map_err(|_| format!("the synset offset `{f}` is not a number"))
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok((lemma.to_lowercase(), offsets))
}

/// `offset lex_filenum ss_type w_cnt (word lex_id)… p_cnt (symbol offset pos src/dst)… | gloss`
fn parse_data_line(line: &str, offset: u64) -> Result<Synset, String> {
    let (head, gloss) = line.split_once(" | ").unwrap_or((line, ""));
    let fields: Vec<&str> = head.split_whitespace().collect();
    let field = |i: usize| fields.get(i).copied().ok_or("the line ends early");
    let at: u64 = field(0)?
        .parse()
        .map_err(|_| "no offset at the line's start (is the offset right?)".to_owned())?;
    if at != offset {
        return Err(format!(
            "the line there is synset {at}: the index and data.noun are of different releases"
        ));
    }
    let words = usize::from_str_radix(field(3)?, 16).map_err(|_| "a bad word count")?;
    let mut out = Vec::with_capacity(words);
    for i in 0..words {
        out.push(clean_word(field(4 + 2 * i)?));
    }
    let p = 4 + 2 * words;
    let pointers: usize = field(p)?.parse().map_err(|_| "a bad pointer count")?;
    let mut hypernyms = Vec::new();
    for i in 0..pointers {
        let symbol = field(p + 1 + 4 * i)?;
        let target = field(p + 2 + 4 * i)?;
        if symbol == "@" || symbol == "@i" {
            hypernyms.push(
                target
                    .parse()
                    .map_err(|_| format!("the pointer target `{target}` is not a number"))?,
            );
        }
    }
    Ok(Synset {
        words: out,
        hypernyms,
        gloss: gloss.trim().to_owned(),
    })
}

/// A synset word as a phrase: `bench_vise` → `bench vise`, `armoire(p)` → `armoire` (adjective
/// markers), lowercase.
fn clean_word(w: &str) -> String {
    let w = w.split('(').next().unwrap_or(w);
    w.replace('_', " ").to_lowercase()
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A tiny dictionary in WordNet's format: workbench → worktable → table → furniture, vise →
    /// holding device, and `shelves` → `shelf` by the exception list. Offsets are the real byte
    /// positions of each line, as WordNet's are.
    pub(crate) fn tiny_wordnet(dir: &Path) {
        let synsets: [(&str, &[&str], &[&str], &str); 7] = [
            (
                "furniture",
                &["furniture", "piece_of_furniture"],
                &[],
                "furnishings",
            ),
            ("table", &["table"], &["furniture"], "a piece of furniture"),
            (
                "worktable",
                &["worktable", "work_table"],
                &["table"],
                "a table for work",
            ),
            (
                "workbench",
                &["workbench", "work_bench", "bench"],
                &["worktable"],
                "a strong worktable",
            ),
            ("holding", &["holding_device"], &[], "a device for holding"),
            (
                "vise",
                &["vise", "bench_vise"],
                &["holding"],
                "a holding device",
            ),
            ("shelf", &["shelf"], &["furniture"], "a support"),
        ];
        // Every field is fixed-width, so a first pass with zero offsets gives every line's
        // length, and the second writes the same lines with the real offsets.
        let header = "  1 This is a licence line.\n";
        let write = |offsets: &HashMap<&str, usize>| {
            let mut data = String::from(header);
            let mut at = HashMap::new();
            for (key, words, hyper, gloss) in synsets.iter() {
                at.insert(*key, data.len());
                let ws: Vec<String> = words.iter().map(|w| format!("{w} 0")).collect();
                let ptrs: String = hyper
                    .iter()
                    .map(|h| format!(" @ {:08} n 0000", offsets.get(h).copied().unwrap_or(0)))
                    .collect();
                data.push_str(&format!(
                    "{:08} 06 n {:02x} {} {:03}{ptrs} | {gloss}\n",
                    offsets.get(key).copied().unwrap_or(0),
                    words.len(),
                    ws.join(" "),
                    hyper.len()
                ));
            }
            (data, at)
        };
        let (_, offsets) = write(&HashMap::new());
        let (data, again) = write(&offsets);
        assert_eq!(offsets, again);
        std::fs::write(dir.join("data.noun"), data).unwrap();
        let mut index = String::from(header);
        let mut lemmas: Vec<(String, usize)> = Vec::new();
        for (key, words, _, _) in synsets.iter() {
            for w in words.iter() {
                lemmas.push((w.to_string(), offsets[key]));
            }
        }
        lemmas.sort();
        lemmas.dedup_by(|a, b| a.0 == b.0);
        for (lemma, offset) in lemmas {
            index.push_str(&format!("{lemma} n 1 1 @ 1 0 {offset:08}\n"));
        }
        std::fs::write(dir.join("index.noun"), index).unwrap();
        std::fs::write(dir.join("noun.exc"), "shelves shelf\n").unwrap();
    }

    #[test]
    fn hypernyms_are_found_nearest_first_and_synonyms_before_them() {
        let dir = tempfile::tempdir().unwrap();
        tiny_wordnet(dir.path());
        let wn = WordNet::open(dir.path()).unwrap();
        assert!(wn.is_noun("bench vise"));
        let related = wn.related("Workbenches").unwrap();
        let words: Vec<&str> = related.iter().map(|(w, _)| w.as_str()).collect();
        assert_eq!(
            words,
            [
                "work bench",
                "bench",
                "worktable",
                "work table",
                "table",
                "furniture",
                "piece of furniture"
            ]
        );
        assert_eq!(related[2].1, 1);
        assert_eq!(related[5].1, 3);
        assert!(wn.related("xyzzy").unwrap().is_empty());
    }

    #[test]
    fn base_forms_follow_the_rules_and_the_exception_list() {
        let dir = tempfile::tempdir().unwrap();
        tiny_wordnet(dir.path());
        std::fs::write(
            dir.path().join("index.noun"),
            format!(
                "{}box n 1 0 1 0 00000028\n",
                std::fs::read_to_string(dir.path().join("index.noun")).unwrap()
            ),
        )
        .unwrap();
        let wn = WordNet::open(dir.path()).unwrap();
        assert_eq!(wn.base_forms("Boxes"), ["box"]);
        assert_eq!(wn.base_forms("shelves"), ["shelf"]);
        assert_eq!(wn.base_forms("table"), ["table"]);
        assert!(wn.base_forms("tables").contains(&"table".to_owned()));
        assert!(wn.base_forms("s").is_empty());
    }

    #[test]
    fn a_malformed_file_is_named_with_its_line() {
        let dir = tempfile::tempdir().unwrap();
        tiny_wordnet(dir.path());
        let index = dir.path().join("index.noun");
        let text = std::fs::read_to_string(&index).unwrap();
        std::fs::write(&index, format!("{text}lamp n 2 0 1 0 00000001\n")).unwrap();
        let err = WordNet::open(dir.path()).unwrap_err().to_string();
        let lines = text.lines().count() + 1;
        assert!(
            err.contains("index.noun") && err.contains(&format!("line {lines}")),
            "{err}"
        );
        // An offset into the middle of a line names the data file and the offset.
        std::fs::write(&index, format!("{text}lamp n 1 0 1 0 00000003\n")).unwrap();
        let wn = WordNet::open(dir.path()).unwrap();
        let err = wn.related("lamp").unwrap_err().to_string();
        assert!(err.contains("data.noun") && err.contains("byte 3"), "{err}");
        let missing = WordNet::open(&dir.path().join("nowhere")).unwrap_err();
        assert!(
            missing.to_string().contains(WORDNET_INSTALL_HINT),
            "{missing}"
        );
    }

    /// The real dictionary, when Debian's package is installed.
    #[test]
    fn real_wordnet_knows_a_workbench_is_a_worktable() {
        let Some(dir) = WordNet::default_dir() else {
            eprintln!(
                "skipped: no WordNet ({WORDNET_INSTALL_HINT} installs it, or set {WORDNET_ENV})"
            );
            return;
        };
        let wn = WordNet::open(&dir).unwrap();
        assert!(wn.len() > 80_000, "{} noun lemmas", wn.len());
        let related = wn.related("workbench").unwrap();
        assert!(
            related.iter().any(|(w, d)| w == "worktable" && *d == 1),
            "{related:?}"
        );
        assert_eq!(wn.base_forms("shelves"), ["shelf"]);
        let gloss = wn.first_sense("armoire").unwrap().unwrap().gloss;
        assert!(gloss.contains("wardrobe"), "{gloss}");
    }
}
