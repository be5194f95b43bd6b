//! Reading answers: probabilities from the probability prompts, a container from P-DIRECT.
//!
//! **Probabilities.** The prompts ask for a percentage between 1 % and 100 %, so a number is a
//! percentage whether or not it carries `%` ("70" → 0.70, "1" → 0.01); only a bare decimal below
//! one ("0.7") is read as a fraction. Values are clamped to [0.01, 1]. Reasoning some models write
//! between `<think>` and `</think>` is ignored (a percentage in the reasoning is not the answer).
//! Every answer falls in one [`AnswerClass`]; three classes are not answers: no number, several
//! different numbers, and a restatement of the prompt's worked example. The caller re-asks those
//! and then falls back to [`FALLBACK_PROBABILITY`], counting each class.

use std::ops::Range;
use std::sync::LazyLock;

use regex::Regex;
use serde::Serialize;

/// The probability given when an answer cannot be read (and the floor of the clamp).
pub const FALLBACK_PROBABILITY: f64 = 0.01;

static THINK: LazyLock<Regex> =
    LazyLock::new(|| Regex::new(r"(?is)<think>.*?</think>").expect("constant pattern"));
static NUMBER: LazyLock<Regex> = LazyLock::new(|| {
    Regex::new(r"(?i)(\d+(?:\.\d+)?|\.\d+)(\s*(?:%|percent\b|per\s+cent\b))?")
        .expect("constant pattern")
});
static JSON_PERCENT: LazyLock<Regex> =
    LazyLock::new(|| Regex::new(r#""percent"\s*:\s*"?(\d+(?:\.\d+)?)"#).expect("constant pattern"));

/// The answer without `<think>…</think>` blocks (an unclosed `<think>` hides everything after it).
pub fn strip_reasoning(text: &str) -> String {
    masked(text).split('\0').collect::<Vec<_>>().join(" ")
}

/// `text` with reasoning blocks replaced by NUL bytes of the same length, so that byte offsets
/// into the result are offsets into `text`.
fn masked(text: &str) -> String {
    let mut out = text.to_string();
    let blank = |s: &mut String, r: Range<usize>| {
        s.replace_range(r.clone(), &"\0".repeat(r.len()));
    };
    for m in THINK.find_iter(text) {
        blank(&mut out, m.range());
    }
    if let Some(i) = out.to_ascii_lowercase().find("<think>") {
        let end = out.len();
        blank(&mut out, i..end);
    }
    out
}

/// What kind of answer a probability answer is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum AnswerClass {
    /// Structured output: `{"percent": 70}`.
    Json,
    /// Only a number (`70%`, `70`, `**70 %**.`).
    NumberOnly,
    /// One number (or one percentage) within prose.
    NumberInProse,
    /// Several different percentages (or, without any, several different numbers): not an answer.
    SeveralNumbers,
    /// No number at all: not an answer.
    NoNumber,
    /// The worked example's value said about the worked example's object: not an answer.
    ExampleEchoed,
    /// A word answer: Yes or No (P-YESNO), a listed letter (P-CHOICE).
    Word,
    /// Neither Yes nor No, nor a listed letter: not an answer.
    NoWord,
    /// A place the answer left out (P-BATCH): not an answer.
    Missing,
}

impl AnswerClass {
    /// Every class, in report order.
    pub const ALL: [AnswerClass; 9] = [
        Self::Json,
        Self::NumberOnly,
        Self::NumberInProse,
        Self::SeveralNumbers,
        Self::NoNumber,
        Self::ExampleEchoed,
        Self::Word,
        Self::NoWord,
        Self::Missing,
    ];

    /// True for classes that give a probability.
    pub fn usable(self) -> bool {
        matches!(
            self,
            Self::Json | Self::NumberOnly | Self::NumberInProse | Self::Word
        )
    }

    /// The class in words, as in reports (`number-in-prose`).
    pub fn label(self) -> &'static str {
        match self {
            Self::Json => "json",
            Self::NumberOnly => "number-only",
            Self::NumberInProse => "number-in-prose",
            Self::SeveralNumbers => "several-numbers",
            Self::NoNumber => "no-number",
            Self::ExampleEchoed => "example-echoed",
            Self::Word => "word",
            Self::NoWord => "no-word",
            Self::Missing => "missing",
        }
    }
}

/// A prompt's worked example, so that an answer restating it is not taken as an answer. Declared
/// in a template by a comment `{# ferret:example percent=90 words=egg,eggs #}`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct WorkedExample {
    /// The example's percentage.
    pub percent: f64,
    /// Words naming the example's object (lower case).
    pub words: Vec<String>,
}

/// A probability answer read.
#[derive(Clone, Debug, PartialEq)]
pub struct ProbabilityReading {
    /// Its class.
    pub class: AnswerClass,
    /// The probability, for usable classes.
    pub probability: Option<f64>,
    /// Byte range of the number in the answer text (what log-probabilities are read at).
    pub number: Option<Range<usize>>,
}

impl ProbabilityReading {
    fn unusable(class: AnswerClass) -> Self {
        Self {
            class,
            probability: None,
            number: None,
        }
    }
}

/// Reads a probability answer (see the module documentation).
pub fn read_probability(answer: &str, example: Option<&WorkedExample>) -> ProbabilityReading {
    let text = masked(answer);
    if let Some(r) = read_json(&text) {
        return r;
    }
    struct Found {
        value: f64,
        percent: bool,
        fraction: bool,
        span: Range<usize>,
        whole: Range<usize>,
    }
    let found: Vec<Found> = NUMBER
        .captures_iter(&text)
        .filter_map(|c| {
            let n = c.get(1)?;
            let value: f64 = n.as_str().parse().ok()?;
            let percent = c.get(2).is_some();
            Some(Found {
                value,
                percent,
                fraction: !percent && n.as_str().contains('.') && value < 1.0,
                span: n.range(),
                whole: c.get(0)?.range(),
            })
        })
        .filter(|f| f.value.is_finite())
        .collect();
    let lower = text.to_lowercase();
    if let Some(ex) = example
        && found.iter().any(|f| f.value == ex.percent)
        && ex.words.iter().any(|w| contains_phrase(&lower, w))
    {
        return ProbabilityReading::unusable(AnswerClass::ExampleEchoed);
    }
    let percents: Vec<&Found> = found.iter().filter(|f| f.percent).collect();
    let pool: Vec<&Found> = if percents.is_empty() {
        found.iter().collect()
    } else {
        percents
    };
    let Some(first) = pool.first() else {
        return ProbabilityReading::unusable(AnswerClass::NoNumber);
    };
    if pool.iter().any(|f| f.value != first.value) {
        return ProbabilityReading::unusable(AnswerClass::SeveralNumbers);
    }
    let p = if first.fraction {
        first.value
    } else {
        first.value / 100.0
    };
    let rest = format!("{}{}", &text[..first.whole.start], &text[first.whole.end..]);
    let only = rest
        .chars()
        .all(|c| c.is_whitespace() || c == '\0' || "\"'`*_.,;:!()[]".contains(c));
    ProbabilityReading {
        class: if only {
            AnswerClass::NumberOnly
        } else {
            AnswerClass::NumberInProse
        },
        probability: Some(p.clamp(FALLBACK_PROBABILITY, 1.0)),
        number: (!first.fraction).then(|| first.span.clone()),
    }
}

/// `{"percent": N}`, possibly in a Markdown code fence.
fn read_json(text: &str) -> Option<ProbabilityReading> {
    let t = text.trim_matches(|c: char| c.is_whitespace() || c == '\0');
    let t = t
        .strip_prefix("```json")
        .or_else(|| t.strip_prefix("```"))
        .map_or(t, |s| s.trim_end().trim_end_matches("```").trim());
    if !t.starts_with('{') {
        return None;
    }
    let value: serde_json::Value = serde_json::from_str(t).ok()?;
    let n = value.get("percent")?;
    let v = n.as_f64().or_else(|| {
        n.as_str()
            .and_then(|s| s.trim().trim_end_matches('%').trim().parse().ok())
    })?;
    let span = JSON_PERCENT.captures(text)?.get(1)?.range();
    v.is_finite().then(|| ProbabilityReading {
        class: AnswerClass::Json,
        probability: Some((v / 100.0).clamp(FALLBACK_PROBABILITY, 1.0)),
        number: Some(span),
    })
}

/// The probability an answer states, when it is usable; see [`read_probability`].
pub fn parse_probability(answer: &str) -> Option<f64> {
    read_probability(answer, None).probability
}

/// A word answer read: which word, and where it stands in the answer text (what the token
/// log-probabilities are read at).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct WordReading {
    /// The index of the word among those allowed (Yes = 0, No = 1; a label's index).
    pub index: usize,
    /// Byte range of the word in the answer text.
    pub span: Range<usize>,
}

static LEADING_WORD: LazyLock<Regex> = LazyLock::new(|| {
    // The first word, past white space, quotes, emphasis, list marks and a JSON object's opening
    // up to its value: `Yes`, `**No**.`, `{"answer": "Yes"}`, `{"label": "C"}`, `C.`, `(C)`.
    Regex::new(r#"^[\s\x00"'`*_(\[{-]*(?:"?[A-Za-z_]+"?\s*:\s*"?)?([A-Za-z]+)"#)
        .expect("constant pattern")
});

/// The first word of `text` (reasoning aside) and its byte range.
fn leading_word(text: &str) -> Option<(String, Range<usize>)> {
    let t = masked(text);
    let c = LEADING_WORD.captures(&t)?;
    let m = c.get(1)?;
    Some((m.as_str().to_string(), m.range()))
}

/// Reads a P-YESNO answer: `Yes` (index 0) or `No` (index 1), in any case, as the answer's first
/// word or the value of a JSON object (`{"answer": "Yes"}`). `None` for anything else.
pub fn read_yes_no(text: &str) -> Option<WordReading> {
    let (word, span) = leading_word(text)?;
    let index = match word.to_ascii_lowercase().as_str() {
        "yes" => 0,
        "no" => 1,
        _ => return None,
    };
    Some(WordReading { index, span })
}

/// Reads a P-CHOICE answer: one of `labels` (capital letters) as the answer's first word, alone
/// or followed by punctuation or a new line (`C`, `C.`, `(C) the sofa`), or as the value of a JSON
/// object (`{"label": "C"}`). `None` for anything else: a letter that starts prose is a word
/// ("I think B", "A sofa"), not an answer.
pub fn read_label(text: &str, labels: &[String]) -> Option<WordReading> {
    let (word, span) = leading_word(text)?;
    let rest = &text[span.end..];
    let prose = rest
        .strip_prefix([' ', '\t'])
        .and_then(|r| r.trim_start_matches([' ', '\t']).chars().next())
        .is_some_and(char::is_alphanumeric);
    if prose {
        return None;
    }
    labels
        .iter()
        .position(|l| *l == word)
        .map(|index| WordReading { index, span })
}

static BATCH_LINE: LazyLock<Regex> = LazyLock::new(|| {
    // `A: 40%`, `- **B** — 5%`, `"C": "70%"`, `D) 20 %`, one per line or in one JSON object.
    Regex::new(r#"(?m)(?:^|[{,])[\s\x00"'`*_•-]*([A-Z])[\s"'`*_]*[:.)=–—-]\s*"?([^",}\n]*)"#)
        .expect("constant pattern")
});

static NAMED_LINE: LazyLock<Regex> = LazyLock::new(|| {
    // `sofa in the living room: Yes`, `- **bed in the bedroom 2**: 40%`, `"fridge in the
    // kitchen": "No"`, one per line or in one JSON object.
    Regex::new(r#"(?m)(?:^|[{,])[\s\x00"'`*_•-]*([^:=\n"{},*]+?)[\s"'`*_]*[:=]\s*"?([^",}\n]*)"#)
        .expect("constant pattern")
});

/// Where a P-BATCH answer gives each of `labels` its value: the byte range of the value in
/// `text` (`None` when the answer leaves the label out; a label written twice counts where it is
/// first written), and whether the answer is one JSON object. `names`: the labels are place
/// names (matched as P-DIRECT answers are) rather than letters.
pub fn batch_entries(
    text: &str,
    labels: &[String],
    names: bool,
) -> (bool, Vec<Option<Range<usize>>>) {
    let t = masked(text);
    let json = {
        let inner = t.trim_matches(|c: char| c.is_whitespace() || c == '\0');
        let inner = inner
            .strip_prefix("```json")
            .or_else(|| inner.strip_prefix("```"))
            .map_or(inner, |s| s.trim_end().trim_end_matches("```").trim());
        serde_json::from_str::<serde_json::Map<String, serde_json::Value>>(inner).is_ok()
    };
    let mut out: Vec<Option<Range<usize>>> = vec![None; labels.len()];
    let pattern: &Regex = if names { &NAMED_LINE } else { &BATCH_LINE };
    for c in pattern.captures_iter(&t) {
        let (Some(label), Some(value)) = (c.get(1), c.get(2)) else {
            continue;
        };
        let found = if names {
            match_location(label.as_str(), labels).map(|(i, _)| i)
        } else {
            labels.iter().position(|l| l == label.as_str())
        };
        if let Some(i) = found
            && out[i].is_none()
        {
            out[i] = Some(value.range());
        }
    }
    (json, out)
}

/// Reads a P-BATCH answer: for each of `labels`, its percentage (as [`read_probability`] reads
/// one answer, the number's range given in the whole text), `None` when the answer leaves the
/// label out. A JSON object's values are of class [`AnswerClass::Json`]; a label written twice
/// is read where it is first written.
pub fn read_batch(text: &str, labels: &[String], names: bool) -> Vec<Option<ProbabilityReading>> {
    let (json, entries) = batch_entries(text, labels, names);
    entries
        .into_iter()
        .map(|range| {
            let range = range?;
            let mut r = read_probability(&text[range.clone()], None);
            if json && r.class.usable() {
                r.class = AnswerClass::Json;
            }
            r.number = r.number.map(|n| n.start + range.start..n.end + range.start);
            Some(r)
        })
        .collect()
}

/// Reads a P-BATCH answer of Yes or No per place: for each of `labels`, the word read (its span
/// in the whole text), `Some(None)` when the place is given something else, `None` when the
/// answer leaves it out.
pub fn read_batch_yes_no(
    text: &str,
    labels: &[String],
    names: bool,
) -> Vec<Option<Option<WordReading>>> {
    let (_, entries) = batch_entries(text, labels, names);
    entries
        .into_iter()
        .map(|range| {
            let range = range?;
            Some(read_yes_no(&text[range.clone()]).map(|w| WordReading {
                index: w.index,
                span: w.span.start + range.start..w.span.end + range.start,
            }))
        })
        .collect()
}

/// How a P-DIRECT answer was matched to the list of search locations.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum MatchKind {
    /// The answer is one of the labels exactly (surrounding white space aside).
    Exact,
    /// Equal ignoring case, white space, quotes, list markers and end punctuation.
    CaseInsensitive,
    /// A label contains the answer or the answer contains a label.
    Containment,
    /// Nothing matched: the nearest container was taken instead.
    Fallback,
}

/// Lower case, white space collapsed, quotes, emphasis, list markers and end punctuation removed.
fn normalise(s: &str) -> String {
    let words: Vec<&str> = s.split_whitespace().collect();
    let mut t = words.join(" ").to_lowercase();
    let junk: &[char] = &[
        '"', '\'', '`', '*', '_', '.', ',', ';', ':', '!', '?', '“', '”', '‘', '’', ' ',
    ];
    loop {
        let before = t.len();
        t = t.trim_matches(junk).to_string();
        for marker in ["- ", "• "] {
            if let Some(rest) = t.strip_prefix(marker) {
                t = rest.to_string();
            }
        }
        if t.len() == before {
            return t;
        }
    }
}

/// Matches a P-DIRECT answer to one of `labels`: exact, then case-insensitive, then containment
/// (the longest label the answer contains; else the first label containing the answer). `None`
/// when nothing matches; the caller falls back to the nearest container and counts it.
pub fn match_location(answer: &str, labels: &[String]) -> Option<(usize, MatchKind)> {
    let mut text = strip_reasoning(answer);
    // Structured output: {"location": "..."}.
    if let Ok(v) = serde_json::from_str::<serde_json::Value>(text.trim())
        && let Some(l) = v.get("location").and_then(|l| l.as_str())
    {
        text = l.to_string();
    }
    let trimmed = text.trim();
    if let Some(i) = labels.iter().position(|l| l == trimmed) {
        return Some((i, MatchKind::Exact));
    }
    let a = normalise(trimmed);
    if a.is_empty() {
        return None;
    }
    let norm: Vec<String> = labels.iter().map(|l| normalise(l)).collect();
    if let Some(i) = norm.iter().position(|l| *l == a) {
        return Some((i, MatchKind::CaseInsensitive));
    }
    let inside = norm
        .iter()
        .enumerate()
        .filter(|(_, l)| !l.is_empty() && contains_phrase(&a, l))
        .max_by(|(i, x), (j, y)| x.len().cmp(&y.len()).then(j.cmp(i)))
        .map(|(i, _)| i);
    if let Some(i) = inside {
        return Some((i, MatchKind::Containment));
    }
    let bare = a.strip_prefix("the ").unwrap_or(&a);
    norm.iter()
        .position(|l| contains_phrase(l, &a) || contains_phrase(l, bare))
        .map(|i| (i, MatchKind::Containment))
}

/// True when `needle` occurs in `hay` on word boundaries (so `bed` is not found in `bedroom` and
/// `countertop 1` not in `countertop 12`).
pub(crate) fn contains_phrase(hay: &str, needle: &str) -> bool {
    let boundary = |c: Option<char>| c.is_none_or(|c| !c.is_alphanumeric());
    hay.match_indices(needle).any(|(i, m)| {
        boundary(hay[..i].chars().next_back()) && boundary(hay[i + m.len()..].chars().next())
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn class(s: &str) -> AnswerClass {
        read_probability(s, None).class
    }

    #[test]
    fn probabilities_as_design_says() {
        assert_eq!(parse_probability("around 70 percent"), Some(0.70));
        assert_eq!(parse_probability("0.7"), Some(0.7));
        assert_eq!(parse_probability("I cannot say"), None);
        assert_eq!(parse_probability("85%"), Some(0.85));
        assert_eq!(parse_probability("Likelihood: 12.5 %."), Some(0.125));
        assert_eq!(parse_probability("70 per cent"), Some(0.7));
        // A percentage wins over bare numbers.
        assert_eq!(
            parse_probability("Between 1 and 100, I'd say 40%"),
            Some(0.4)
        );
        assert_eq!(parse_probability("0%"), Some(0.01));
        assert_eq!(parse_probability("150%"), Some(1.0));
        // A bare number is a percentage: the prompts ask for 1 %–100 %.
        assert_eq!(parse_probability("70"), Some(0.7));
        assert_eq!(parse_probability("1"), Some(0.01));
        assert_eq!(parse_probability("0"), Some(0.01));
        assert_eq!(
            parse_probability("<think>maybe 5%? no</think>60%"),
            Some(0.6)
        );
        assert_eq!(parse_probability("<think>about 5% I guess"), None);
    }

    #[test]
    fn every_class() {
        assert_eq!(class("70%"), AnswerClass::NumberOnly);
        assert_eq!(class(" **70 %**.\n"), AnswerClass::NumberOnly);
        assert_eq!(class("70"), AnswerClass::NumberOnly);
        assert_eq!(
            class("The likelihood is about 30% because remotes live on sofas."),
            AnswerClass::NumberInProse
        );
        // A stray "(1)" in a cut-off explanation is 1 %, not 100 %.
        let r = read_probability("It depends on the number of chances (1) and", None);
        assert_eq!(r.class, AnswerClass::NumberInProse);
        assert_eq!(r.probability, Some(0.01));
        assert_eq!(class("30% or maybe 60%"), AnswerClass::SeveralNumbers);
        assert_eq!(class("somewhere from 3 to 6"), AnswerClass::SeveralNumbers);
        assert_eq!(class("30% (30 percent)"), AnswerClass::NumberInProse);
        assert_eq!(class("I cannot say."), AnswerClass::NoNumber);
        assert_eq!(class(""), AnswerClass::NoNumber);
        assert_eq!(class("{\"percent\": 35}"), AnswerClass::Json);
        let r = read_probability("{ \"percent\": \"35%\" }", None);
        assert_eq!((r.class, r.probability), (AnswerClass::Json, Some(0.35)));
        assert_eq!(
            read_probability("```json\n{\"percent\": 35}\n```", None).probability,
            Some(0.35)
        );
        let egg = WorkedExample {
            percent: 90.0,
            words: vec!["egg".into(), "eggs".into()],
        };
        let r = read_probability(
            "The likelihood of finding an egg in the fridge is 90%.",
            Some(&egg),
        );
        assert_eq!(r.class, AnswerClass::ExampleEchoed);
        assert_eq!(r.probability, None);
        // The example's value about something else is an answer.
        assert_eq!(
            read_probability("90%", Some(&egg)).class,
            AnswerClass::NumberOnly
        );
        for c in AnswerClass::ALL {
            assert_eq!(
                c.usable(),
                matches!(
                    c,
                    AnswerClass::Json
                        | AnswerClass::NumberOnly
                        | AnswerClass::NumberInProse
                        | AnswerClass::Word
                )
            );
        }
    }

    #[test]
    fn number_spans_point_into_the_original_text() {
        let text = "<think>5%?</think> I'd say 70%";
        let r = read_probability(text, None);
        assert_eq!(&text[r.number.clone().unwrap()], "70");
        let json = "{\"percent\": 42}";
        assert_eq!(&json[read_probability(json, None).number.unwrap()], "42");
        let json = "{\"percent\": \"42%\"}";
        assert_eq!(&json[read_probability(json, None).number.unwrap()], "42");
        assert_eq!(read_probability("0.7", None).number, None);
    }

    #[test]
    fn locations_from_structured_output() {
        let l = labels();
        assert_eq!(
            match_location("{\"location\": \"bed in the bedroom\"}", &l),
            Some((3, MatchKind::Exact))
        );
    }

    fn labels() -> Vec<String> {
        [
            "fridge in the kitchen",
            "counter top 1 in the kitchen",
            "counter top 12 in the kitchen",
            "bed in the bedroom",
        ]
        .map(String::from)
        .to_vec()
    }

    #[test]
    fn locations_exact_then_case_then_containment() {
        let l = labels();
        assert_eq!(
            match_location(" fridge in the kitchen\n", &l),
            Some((0, MatchKind::Exact))
        );
        assert_eq!(
            match_location("Fridge in the Kitchen.", &l),
            Some((0, MatchKind::CaseInsensitive))
        );
        assert_eq!(
            match_location("**\"bed in the bedroom\"**", &l),
            Some((3, MatchKind::CaseInsensitive))
        );
        assert_eq!(
            match_location("- bed in the bedroom", &l),
            Some((3, MatchKind::CaseInsensitive))
        );
        assert_eq!(
            match_location(
                "I would search the counter top 12 in the kitchen first.",
                &l
            ),
            Some((2, MatchKind::Containment))
        );
        assert_eq!(
            match_location("counter top 1 in the kitchen, then the fridge", &l),
            Some((1, MatchKind::Containment))
        );
        assert_eq!(
            match_location("the fridge", &l),
            Some((0, MatchKind::Containment))
        );
        assert_eq!(match_location("bed", &l), Some((3, MatchKind::Containment)));
        assert_eq!(match_location("the garage", &l), None);
        assert_eq!(match_location("", &l), None);
    }

    fn letters(n: usize) -> Vec<String> {
        crate::context::LABELS
            .chars()
            .take(n)
            .map(|c| c.to_string())
            .collect()
    }

    #[test]
    fn yes_and_no_are_read_where_they_stand() {
        let r = read_yes_no("Yes").unwrap();
        assert_eq!((r.index, r.span), (0, 0..3));
        assert_eq!(read_yes_no(" no.").unwrap().index, 1);
        assert_eq!(read_yes_no("**YES**, usually").unwrap().index, 0);
        let json = r#"{"answer": "No"}"#;
        let r = read_yes_no(json).unwrap();
        assert_eq!((r.index, &json[r.span.clone()]), (1, "No"));
        assert_eq!(
            read_yes_no("<think>yes or no?</think>No").unwrap().span,
            25..27
        );
        for bad in ["Maybe", "", "It could be yes", "Nope"] {
            assert_eq!(read_yes_no(bad), None, "{bad}");
        }
    }

    #[test]
    fn a_label_is_read_only_at_the_start_of_the_answer() {
        let l = letters(10);
        assert_eq!(read_label("C", &l).unwrap().index, 2);
        assert_eq!(read_label("C.", &l).unwrap().index, 2);
        assert_eq!(read_label(" (D) the sofa", &l).unwrap().index, 3);
        let json = r#"{"label": "J"}"#;
        let r = read_label(json, &l).unwrap();
        assert_eq!((r.index, &json[r.span.clone()]), (9, "J"));
        // Not a listed letter, or a letter inside prose.
        assert_eq!(read_label("K", &l), None);
        assert_eq!(read_label("I think B", &l), None);
        assert_eq!(read_label("The sofa", &l), None);
        assert_eq!(read_label("c", &l), None);
    }

    #[test]
    fn batch_answers_in_lines_or_json() {
        let l = letters(4);
        let r = read_batch("A: 40%\nB: 5%\n- **C** — 70 %\nD) no idea", &l, false);
        let p: Vec<Option<f64>> = r
            .iter()
            .map(|r| r.as_ref().and_then(|r| r.probability))
            .collect();
        assert_eq!(p, [Some(0.4), Some(0.05), Some(0.7), None]);
        assert_eq!(r[0].as_ref().unwrap().class, AnswerClass::NumberOnly);
        assert_eq!(r[3].as_ref().unwrap().class, AnswerClass::NoNumber);
        // The number's range is in the whole answer.
        let text = "A: 40%\nB: 5%";
        let r = read_batch(text, &l, false);
        assert_eq!(&text[r[1].as_ref().unwrap().number.clone().unwrap()], "5");
        // JSON, with a key that is not listed and one left out.
        let json = r#"{"A": "10%", "Z": "90%", "C": "55%"}"#;
        let r = read_batch(json, &l, false);
        assert_eq!(r[0].as_ref().unwrap().class, AnswerClass::Json);
        assert_eq!(r[0].as_ref().unwrap().probability, Some(0.1));
        assert!(r[1].is_none());
        assert_eq!(r[2].as_ref().unwrap().probability, Some(0.55));
        assert_eq!(&json[r[2].as_ref().unwrap().number.clone().unwrap()], "55");
        // The first mention of a letter counts.
        let r = read_batch("A: 10%\nA: 90%", &l, false);
        assert_eq!(r[0].as_ref().unwrap().probability, Some(0.1));
    }

    #[test]
    fn batch_answers_naming_their_places() {
        let names: Vec<String> = [
            "sofa in the living room",
            "bed in the bedroom 1",
            "bed in the bedroom 2",
        ]
        .iter()
        .map(|s| s.to_string())
        .collect();
        let text = "- Sofa in the living room: Yes\nbed in the bedroom 2: no\n**bed in the bedroom 1**: maybe";
        let r = read_batch_yes_no(text, &names, true);
        let sofa = r[0].clone().unwrap().unwrap();
        assert_eq!((sofa.index, &text[sofa.span.clone()]), (0, "Yes"));
        assert_eq!(r[1], Some(None), "maybe is no answer");
        assert_eq!(r[2].clone().unwrap().unwrap().index, 1);
        let json = r#"{"sofa in the living room": "No", "bed in the bedroom 1": "Yes"}"#;
        let r = read_batch_yes_no(json, &names, true);
        assert_eq!(r[0].clone().unwrap().unwrap().index, 1);
        assert_eq!(r[1].clone().unwrap().unwrap().index, 0);
        assert_eq!(r[2], None, "left out");
        let r = read_batch("sofa in the living room: 35%", &names, true);
        assert_eq!(r[0].as_ref().unwrap().probability, Some(0.35));
        assert!(r[1].is_none());
    }

    proptest! {
        #[test]
        fn parsed_probabilities_are_in_range(s in ".{0,40}") {
            if let Some(p) = parse_probability(&s) {
                prop_assert!((FALLBACK_PROBABILITY..=1.0).contains(&p));
            }
        }

        #[test]
        fn any_percentage_is_read_back(n in 0u32..=100, pre in "[a-z ]{0,12}", post in "[a-z ]{0,12}") {
            let p = parse_probability(&format!("{pre}{n}%{post}")).unwrap();
            prop_assert!((p - (f64::from(n) / 100.0).max(FALLBACK_PROBABILITY)).abs() < 1e-12);
        }

        #[test]
        fn every_label_matches_itself(i in 0usize..4) {
            let l = labels();
            prop_assert_eq!(match_location(&l[i], &l), Some((i, MatchKind::Exact)));
            prop_assert_eq!(match_location(&l[i].to_uppercase(), &l), Some((i, MatchKind::CaseInsensitive)));
        }

        #[test]
        fn batch_lines_are_read_back(values in proptest::collection::vec(1u32..=100, 1..26)) {
            let l = letters(values.len());
            let text: String = l.iter().zip(&values).map(|(l, v)| format!("{l}: {v}%\n")).collect();
            let r = read_batch(&text, &l, false);
            for (r, v) in r.iter().zip(&values) {
                let p = r.as_ref().and_then(|r| r.probability);
                prop_assert_eq!(p, Some(f64::from(*v) / 100.0));
            }
        }
    }
}
