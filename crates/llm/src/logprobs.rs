//! Probabilities from token log-probabilities: the expected percentage a model would have
//! written, rather than the one it happened to write.
//!
//! A small model that answers "10%" to almost every question still ranks holders above
//! non-holders in its token distribution. The expectation is read at the answer's number: the
//! alternatives the server lists for the number's first token, and, along the sampled answer,
//! for each further digit or the token that ends the number.
//!
//! **Method.** Let `S` be the number the model wrote (its digits). Walking the sampled tokens of
//! the number, with `P` the digits sampled so far, the value of an alternative token at a position
//! is:
//! - the sampled token: the expectation at the next position (or `S` once the number has ended);
//! - another run of digits `d`: the number `P·d`, completed with zeros to as many digits as `S`
//!   has (at most two: alternatives to the first digit of "100" are read as tens) — the server
//!   lists only the first token of paths it did not take, so their later digits are unknown;
//! - anything else, after the first digit: the number ends, value `P`.
//!
//! Alternatives at the first position that are not digits (the model could have written a word)
//! are not answers and are left out; probabilities are renormalised over what is left. Values
//! are clamped to 1..=100. Tokenisers that write numbers up to 999 as one token (OpenAI's)
//! need no completion; ones that split digits (Qwen, Gemma, Llama 2) rely on it.

use std::ops::Range;

use serde::{Deserialize, Serialize};

/// One alternative for a token position.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TopLogprob {
    /// The token's text.
    pub token: String,
    /// Its natural-log probability.
    pub logprob: f64,
}

/// One generated token with its alternatives, as OpenAI's `choices[].logprobs.content[]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TokenLogprob {
    /// The token's text.
    pub token: String,
    /// Its natural-log probability (some servers send null for special tokens).
    #[serde(default)]
    pub logprob: Option<f64>,
    /// The most likely tokens at this position, the sampled one usually among them.
    #[serde(default, deserialize_with = "null_as_empty")]
    pub top_logprobs: Vec<TopLogprob>,
}

impl TokenLogprob {
    /// The alternatives listed for this position, with the sampled token added when the server
    /// left it out of its list.
    pub fn alternatives(&self) -> Vec<(&str, f64)> {
        let mut alternatives: Vec<(&str, f64)> = self
            .top_logprobs
            .iter()
            .map(|a| (a.token.as_str(), a.logprob))
            .collect();
        if !alternatives.iter().any(|(t, _)| *t == self.token) {
            alternatives.push((self.token.as_str(), self.logprob.unwrap_or(0.0)));
        }
        alternatives
    }
}

fn null_as_empty<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Vec<TopLogprob>, D::Error> {
    Ok(Option::<Vec<TopLogprob>>::deserialize(d)?.unwrap_or_default())
}

/// Why no expectation could be read.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LogprobIssue {
    /// The tokens do not spell the answer text.
    Misaligned,
    /// The answer's number is not a whole number of digits (a fraction, a decimal).
    NotInteger,
    /// No token holds the number's first digit.
    NoDigits,
}

/// Digits of a token if, leading white space aside, it is only ASCII digits.
fn digits(token: &str) -> Option<&str> {
    let t = token.trim_start();
    (!t.is_empty() && t.bytes().all(|b| b.is_ascii_digit())).then_some(t)
}

/// The number `d` completed with zeros to `width` digits, clamped to 1..=100.
fn completed(d: &str, width: usize) -> f64 {
    let zeros = width.saturating_sub(d.len()).min(2) as i32;
    let v: f64 = d.parse::<f64>().unwrap_or(0.0) * 10f64.powi(zeros);
    v.clamp(1.0, 100.0)
}

/// The expected percentage (1..=100) a model would have written for the number at byte range
/// `number` of `text`, from the `tokens` that produced `text`.
pub fn expected_percentage(
    tokens: &[TokenLogprob],
    text: &str,
    number: Range<usize>,
) -> Result<f64, LogprobIssue> {
    let s = text.get(number.clone()).ok_or(LogprobIssue::Misaligned)?;
    if s.is_empty() || !s.bytes().all(|b| b.is_ascii_digit()) {
        return Err(LogprobIssue::NotInteger);
    }
    // Byte offsets of the tokens in `text`; servers may trim the content's leading white space.
    let k = token_at(tokens, text, number.start)?.ok_or(LogprobIssue::NoDigits)?;
    if digits(&tokens[k].token).is_none() {
        return Err(LogprobIssue::NoDigits);
    }
    let width = if s == "100" { 2 } else { s.len().min(3) };
    Ok(expect_at(tokens, k, k, "", s, width))
}

/// The index of the token holding byte `at` of `text`, when `tokens` spell `text` (or spell it
/// after a prefix, as some servers send the tokens of a reasoning block too).
fn token_at(tokens: &[TokenLogprob], text: &str, at: usize) -> Result<Option<usize>, LogprobIssue> {
    let joined: String = tokens.iter().map(|t| t.token.as_str()).collect();
    let shift = if joined == text {
        0usize
    } else if let Some(i) = joined.find(text).filter(|_| !text.is_empty()) {
        i
    } else {
        return Err(LogprobIssue::Misaligned);
    };
    let start = at + shift;
    let mut offset = 0usize;
    for (i, t) in tokens.iter().enumerate() {
        let end = offset + t.token.len();
        if start >= offset && start < end {
            return Ok(Some(i));
        }
        offset = end;
    }
    Ok(None)
}

/// A token as a word: white space, quotes, emphasis and end punctuation removed (`" Yes"`,
/// `"C."`, `"**No"` → `Yes`, `C`, `No`).
fn token_word(token: &str) -> &str {
    token.trim_matches(|c: char| c.is_whitespace() || "\"'`*_.,:;!?()[]{}".contains(c))
}

/// The probabilities of the alternatives at token `k` (the sampled token included when the
/// server left it out of its list), summed per word by `word_of` (which returns `None` for
/// tokens that are none of the words), and the mass of every alternative listed.
fn word_masses(
    tok: &TokenLogprob,
    words: usize,
    word_of: impl Fn(&str) -> Option<usize>,
) -> (Vec<f64>, f64) {
    let alternatives = tok.alternatives();
    let mut mass = vec![0.0; words];
    let mut listed = 0.0;
    for (t, lp) in alternatives {
        if lp.is_nan() {
            continue;
        }
        let p = lp.min(0.0).exp();
        listed += p;
        if let Some(w) = word_of(token_word(t)) {
            mass[w] += p;
        }
    }
    (mass, listed)
}

/// P(Yes) / (P(Yes) + P(No)) at the answer word that starts at byte `at` of `text`, from the
/// alternatives the server listed for that token (any case: `Yes`, ` yes`, `YES`). `None` when
/// the tokens do not spell the text or list neither word.
pub fn yes_probability(tokens: &[TokenLogprob], text: &str, at: usize) -> Option<f64> {
    let k = token_at(tokens, text, at).ok()??;
    let (mass, _) = word_masses(&tokens[k], 2, |w| match w.to_ascii_lowercase().as_str() {
        "yes" => Some(0),
        "no" => Some(1),
        _ => None,
    });
    let total = mass[0] + mass[1];
    (total > 0.0).then(|| mass[0] / total)
}

/// The distribution over `labels` at the answer's label that starts at byte `at` of `text`:
/// the probability of each label among the alternatives the server listed for that token, the
/// mass it listed for no token at all spread evenly over the labels it left out, normalised over
/// the labels. `None` when the tokens do not spell the text or list no label.
pub fn label_distribution(
    tokens: &[TokenLogprob],
    text: &str,
    at: usize,
    labels: &[String],
) -> Option<Vec<f64>> {
    let k = token_at(tokens, text, at).ok()??;
    let (mut mass, listed) = word_masses(&tokens[k], labels.len(), |w| {
        labels.iter().position(|l| l == w)
    });
    if mass.iter().all(|&m| m <= 0.0) {
        return None;
    }
    let unlisted = (1.0 - listed).max(0.0);
    let left_out = mass.iter().filter(|&&m| m <= 0.0).count();
    if left_out > 0 {
        let share = unlisted / left_out as f64;
        for m in mass.iter_mut().filter(|m| **m <= 0.0) {
            *m = share;
        }
    }
    let total: f64 = mass.iter().sum();
    Some(mass.iter().map(|m| m / total).collect())
}

/// The expectation at token position `j` with digits `prefix` sampled so far (`k` is the
/// number's first position).
fn expect_at(
    tokens: &[TokenLogprob],
    k: usize,
    j: usize,
    prefix: &str,
    sampled_number: &str,
    width: usize,
) -> f64 {
    let ended = || {
        if prefix.is_empty() {
            completed(sampled_number, width)
        } else {
            completed(prefix, prefix.len())
        }
    };
    let Some(tok) = tokens.get(j) else {
        return ended();
    };
    let sampled_digits = digits(&tok.token);
    let alternatives = tok.alternatives();
    let mut mass = 0.0;
    let mut sum = 0.0;
    for (t, lp) in alternatives {
        if lp.is_nan() {
            continue;
        }
        let p = lp.min(0.0).exp();
        let value = if t == tok.token {
            match sampled_digits {
                Some(d) => {
                    let next = format!("{prefix}{d}");
                    if next.len() > 4 {
                        completed(&next, next.len())
                    } else {
                        expect_at(tokens, k, j + 1, &next, sampled_number, width)
                    }
                }
                None => ended(),
            }
        } else {
            match digits(t) {
                Some(d) => {
                    let next = format!("{prefix}{d}");
                    if j == k {
                        completed(&next, width)
                    } else {
                        completed(&next, next.len())
                    }
                }
                // Not an answer at the first position; the end of the number after it.
                None if j == k => continue,
                None => ended(),
            }
        };
        mass += p;
        sum += p * value;
    }
    if mass > 0.0 { sum / mass } else { ended() }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tok(token: &str, alts: &[(&str, f64)]) -> TokenLogprob {
        let lp = alts.iter().find(|(t, _)| *t == token).map(|(_, p)| p.ln());
        TokenLogprob {
            token: token.into(),
            logprob: lp,
            top_logprobs: alts
                .iter()
                .map(|(t, p)| TopLogprob {
                    token: (*t).into(),
                    logprob: p.ln(),
                })
                .collect(),
        }
    }

    #[test]
    fn whole_number_tokens_average_directly() {
        // OpenAI-style: "70" is one token; alternatives are whole percentages.
        let t = vec![
            tok("70", &[("70", 0.5), ("80", 0.3), ("The", 0.2)]),
            tok("%", &[("%", 1.0)]),
        ];
        let e = expected_percentage(&t, "70%", 0..2).unwrap();
        // "The" is not an answer: renormalised over 0.8.
        assert!((e - (0.5 * 70.0 + 0.3 * 80.0) / 0.8).abs() < 1e-9, "{e}");
    }

    #[test]
    fn split_digits_follow_the_sampled_path() {
        // Qwen-style: "7", "0", "%". First position 7 (0.6) or 2 (0.4 → 20); second position
        // after "7": "0" (0.5 → 70), "5" (0.25 → 75), "%" (0.25 → 7).
        let t = vec![
            tok("7", &[("7", 0.6), ("2", 0.4)]),
            tok("0", &[("0", 0.5), ("5", 0.25), ("%", 0.25)]),
            tok("%", &[("%", 1.0)]),
        ];
        let after7 = 0.5 * 70.0 + 0.25 * 75.0 + 0.25 * 7.0;
        let e = expected_percentage(&t, "70%", 0..2).unwrap();
        assert!((e - (0.6 * after7 + 0.4 * 20.0)).abs() < 1e-9, "{e}");
    }

    #[test]
    fn hundred_reads_first_digit_alternatives_as_tens() {
        let t = vec![
            tok("1", &[("1", 0.5), ("9", 0.5)]),
            tok("0", &[("0", 1.0)]),
            tok("0", &[("0", 0.8), ("%", 0.2)]),
            tok("%", &[("%", 1.0)]),
        ];
        let e = expected_percentage(&t, "100%", 0..3).unwrap();
        // "1" path: 0.8·100 + 0.2·10 = 82; "9" → 90.
        assert!((e - (0.5 * 82.0 + 0.5 * 90.0)).abs() < 1e-9, "{e}");
    }

    #[test]
    fn json_answers_and_leading_space() {
        let text = "{\"percent\": 40}";
        let t = vec![
            tok("{\"", &[("{\"", 1.0)]),
            tok("percent", &[("percent", 1.0)]),
            tok("\":", &[("\":", 1.0)]),
            tok(" 4", &[(" 4", 0.5), (" 1", 0.5)]),
            tok("0", &[("0", 1.0)]),
            tok("}", &[("}", 1.0)]),
        ];
        let e = expected_percentage(&t, text, 12..14).unwrap();
        assert!((e - 25.0).abs() < 1e-9, "{e}");
    }

    #[test]
    fn refuses_what_it_cannot_read() {
        let t = vec![tok("0", &[("0", 1.0)]), tok(".7", &[(".7", 1.0)])];
        assert_eq!(
            expected_percentage(&t, "0.7", 0..3),
            Err(LogprobIssue::NotInteger)
        );
        let t = vec![tok("seventy", &[("seventy", 1.0)])];
        assert_eq!(
            expected_percentage(&t, "70", 0..2),
            Err(LogprobIssue::Misaligned)
        );
        // Server trimmed the leading space of the content: still aligned.
        let t = vec![tok(" 5", &[(" 5", 1.0)]), tok("%", &[("%", 1.0)])];
        assert_eq!(expected_percentage(&t, "5%", 0..1), Ok(5.0));
    }

    #[test]
    fn replies_deserialize_with_nulls() {
        let v: Vec<TokenLogprob> = serde_json::from_str(
            r#"[{"token":"7","logprob":-0.1,"bytes":null,"top_logprobs":[{"token":"7","logprob":-0.1,"bytes":null}]},
                {"token":"%","logprob":null,"top_logprobs":null}]"#,
        )
        .unwrap();
        assert_eq!(v.len(), 2);
        assert!(v[1].top_logprobs.is_empty());
    }

    #[test]
    fn yes_probability_from_the_answer_token() {
        let t = vec![tok(
            "Yes",
            &[("Yes", 0.6), ("No", 0.2), (" yes", 0.1), ("Maybe", 0.05)],
        )];
        let p = yes_probability(&t, "Yes", 0).unwrap();
        assert!((p - 0.7 / 0.9).abs() < 1e-12, "{p}");
        // In a JSON answer, at the word's token.
        let t = vec![
            tok("{\"", &[("{\"", 1.0)]),
            tok("answer", &[("answer", 1.0)]),
            tok("\":", &[("\":", 1.0)]),
            tok(" \"", &[(" \"", 1.0)]),
            tok("No", &[("No", 0.75), ("Yes", 0.25)]),
            tok("\"}", &[("\"}", 1.0)]),
        ];
        let text = "{\"answer\": \"No\"}";
        let p = yes_probability(&t, text, 12).unwrap();
        assert!((p - 0.25).abs() < 1e-12, "{p}");
        // Tokens that do not spell the answer are not read.
        assert_eq!(yes_probability(&t, "Yes", 0), None);
    }

    #[test]
    fn label_distribution_spreads_unlisted_mass_over_unlisted_letters() {
        let labels: Vec<String> = ["A", "B", "C", "D"].iter().map(|s| s.to_string()).collect();
        // A 0.5, C 0.3 (as " C" and "C."), "The" 0.1: 0.1 is unlisted, shared by B and D.
        let t = vec![tok(
            "A",
            &[("A", 0.5), (" C", 0.2), ("C.", 0.1), ("The", 0.1)],
        )];
        let q = label_distribution(&t, "A", 0, &labels).unwrap();
        let want = [0.5, 0.05, 0.3, 0.05].map(|x| x / 0.9);
        for (a, b) in q.iter().zip(want) {
            assert!((a - b).abs() < 1e-12, "{q:?}");
        }
        // Every letter listed: nothing is spread.
        let t = vec![tok("B", &[("A", 0.1), ("B", 0.6), ("C", 0.2), ("D", 0.1)])];
        let q = label_distribution(&t, "B", 0, &labels).unwrap();
        assert!((q[1] - 0.6).abs() < 1e-12, "{q:?}");
        // No letter among the alternatives.
        let t = vec![tok("Hmm", &[("Hmm", 1.0)])];
        assert_eq!(label_distribution(&t, "Hmm", 0, &labels), None);
    }

    proptest::proptest! {
        #[test]
        fn expectation_stays_in_range(ps in proptest::collection::vec(0.001f64..1.0, 1..6), d in 1u32..=100) {
            let s = d.to_string();
            let alts: Vec<(String, f64)> = ps.iter().enumerate().map(|(i, p)| ((i + 1).to_string(), *p)).collect();
            let mut t: Vec<TokenLogprob> = Vec::new();
            for ch in s.chars() {
                let c = ch.to_string();
                let mut a: Vec<(&str, f64)> = alts.iter().map(|(x, p)| (x.as_str(), *p)).collect();
                a.push((c.as_str(), 0.5));
                t.push(tok(&c, &a));
            }
            t.push(tok("%", &[("%", 1.0)]));
            let text = format!("{s}%");
            let e = expected_percentage(&t, &text, 0..s.len()).unwrap();
            proptest::prop_assert!((1.0..=100.0).contains(&e), "{}", e);
        }

        #[test]
        fn label_distributions_are_distributions(
            ps in proptest::collection::vec(0.0001f64..0.3, 1..6),
            n in 1usize..26,
        ) {
            let labels: Vec<String> = crate::context::LABELS.chars().take(n).map(|c| c.to_string()).collect();
            let alts: Vec<(String, f64)> = ps.iter().enumerate().map(|(i, p)| (labels[i % n].clone(), *p)).collect();
            let a: Vec<(&str, f64)> = alts.iter().map(|(x, p)| (x.as_str(), *p)).collect();
            let t = vec![tok(&labels[0], &a)];
            let q = label_distribution(&t, &labels[0], 0, &labels).unwrap();
            proptest::prop_assert_eq!(q.len(), n);
            proptest::prop_assert!(q.iter().all(|&x| (0.0..=1.0).contains(&x)));
            proptest::prop_assert!((q.iter().sum::<f64>() - 1.0).abs() < 1e-9);
        }
    }
}
