//! Token and cost accounting, and answer-parsing counters, per LLM and per strategy.
//!
//! Three views of the same run:
//! - **sent**: HTTP requests made now, with their tokens and cost — what this run spent;
//! - **cache hits**: answers served from the response cache (a count);
//! - **distinct**: each distinct prompt whose answer the run used, counted once with the tokens
//!   and cost it took when it was asked (now or in an earlier run) — what the study as a whole
//!   costs, the paper's table V, and the same whether the cache was cold or warm.
//!
//! Answer parsing (fallbacks) is counted over distinct prompts too, so rates do not depend on how
//! often a trial was replayed.

use std::collections::{BTreeMap, HashSet};
use std::fmt;
use std::io::Write;
use std::sync::Mutex;

use serde::Serialize;

use crate::answer::{AnswerClass, MatchKind};
use crate::client::TokenUsage;

/// What asking one prompt took: its tokens, its price and its time.
#[derive(Clone, Copy, Debug)]
pub struct Spent<'a> {
    /// Tokens sent and received.
    pub usage: &'a TokenUsage,
    /// Price, US dollars.
    pub cost_usd: f64,
    /// Seconds the answer took (0 when not measured).
    pub seconds: f64,
}

/// Token counts and cost of a set of requests.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct TokenCounts {
    /// Requests (or distinct prompts).
    pub requests: u64,
    /// Input tokens.
    pub input_tokens: u64,
    /// Output tokens.
    pub output_tokens: u64,
    /// Input tokens the provider served from its prompt cache (0 when it does not report them).
    pub cached_input_tokens: u64,
    /// USD at the endpoint's prices.
    pub cost_usd: f64,
    /// Seconds the server took to answer (the requests' latencies, summed).
    pub seconds: f64,
}

impl TokenCounts {
    fn add(&mut self, usage: &TokenUsage, cost_usd: f64, seconds: f64) {
        self.requests += 1;
        self.seconds += seconds;
        self.input_tokens += usage.prompt_tokens;
        self.output_tokens += usage.completion_tokens;
        self.cached_input_tokens += usage.cached_tokens.unwrap_or(0);
        self.cost_usd += cost_usd;
    }

    fn merge(&mut self, o: &TokenCounts) {
        self.requests += o.requests;
        self.input_tokens += o.input_tokens;
        self.output_tokens += o.output_tokens;
        self.cached_input_tokens += o.cached_input_tokens;
        self.cost_usd += o.cost_usd;
        self.seconds += o.seconds;
    }

    /// Input plus output tokens.
    pub fn total_tokens(&self) -> u64 {
        self.input_tokens + self.output_tokens
    }
}

/// Whether a probability came from log-probabilities.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LogprobUse {
    /// The endpoint reads probabilities from the text.
    NotWanted,
    /// The expected percentage from the tokens was used.
    Used,
    /// Wanted, but the server sent none or they did not fit the answer: the text was used
    /// (P-YESNO and P-CHOICE: the word, with the endpoint's `word_answer_mass`).
    Missing,
}

/// What became of an answer, for the parsing counters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum AnswerOutcome {
    /// A probability answer.
    Probability {
        /// The class of the first answer.
        class: AnswerClass,
        /// True when the first answer was unusable and the question was asked again.
        reasked: bool,
        /// The probability used, `None` when it fell back to 0.01 after every re-ask.
        value: Option<f64>,
        /// Where the value came from.
        logprobs: LogprobUse,
    },
    /// A P-DIRECT answer and how it matched.
    Direct(MatchKind),
    /// Anything else (a ping).
    Other,
}

/// How answers were read.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct AnswerCounts {
    /// Probability answers used.
    pub probability_answers: u64,
    /// First answers that were structured output (`{"percent": N}`).
    pub class_json: u64,
    /// First answers that were only a number.
    pub class_number_only: u64,
    /// First answers with one number in prose.
    pub class_number_in_prose: u64,
    /// First answers with several different numbers (not an answer).
    pub class_several_numbers: u64,
    /// First answers without a number (not an answer).
    pub class_no_number: u64,
    /// First answers restating the worked example (not an answer).
    pub class_example_echoed: u64,
    /// First answers that were a word: Yes/No, a listed letter.
    pub class_word: u64,
    /// First answers that were no allowed word (not an answer).
    pub class_no_word: u64,
    /// Places a batch answer left out (not an answer).
    pub class_missing: u64,
    /// Questions asked again after an unusable answer.
    pub reasked: u64,
    /// Probability answers still unusable after every re-ask, which fell back to 0.01.
    pub probability_fallbacks: u64,
    /// Probabilities taken from log-probabilities.
    pub logprob_used: u64,
    /// Probabilities that should have come from log-probabilities but came from the text.
    pub logprob_missing: u64,
    /// P-DIRECT answers used.
    pub direct_answers: u64,
    /// Matched exactly.
    pub direct_exact: u64,
    /// Matched ignoring case and punctuation.
    pub direct_case_insensitive: u64,
    /// Matched by containment.
    pub direct_containment: u64,
    /// Unmatched; the nearest container was taken.
    pub direct_fallbacks: u64,
}

impl AnswerCounts {
    fn merge(&mut self, o: &AnswerCounts) {
        self.probability_answers += o.probability_answers;
        self.class_json += o.class_json;
        self.class_number_only += o.class_number_only;
        self.class_number_in_prose += o.class_number_in_prose;
        self.class_several_numbers += o.class_several_numbers;
        self.class_no_number += o.class_no_number;
        self.class_example_echoed += o.class_example_echoed;
        self.class_word += o.class_word;
        self.class_no_word += o.class_no_word;
        self.class_missing += o.class_missing;
        self.reasked += o.reasked;
        self.probability_fallbacks += o.probability_fallbacks;
        self.logprob_used += o.logprob_used;
        self.logprob_missing += o.logprob_missing;
        self.direct_answers += o.direct_answers;
        self.direct_exact += o.direct_exact;
        self.direct_case_insensitive += o.direct_case_insensitive;
        self.direct_containment += o.direct_containment;
        self.direct_fallbacks += o.direct_fallbacks;
    }

    /// First answers of `class`.
    pub fn class(&self, class: AnswerClass) -> u64 {
        match class {
            AnswerClass::Json => self.class_json,
            AnswerClass::NumberOnly => self.class_number_only,
            AnswerClass::NumberInProse => self.class_number_in_prose,
            AnswerClass::SeveralNumbers => self.class_several_numbers,
            AnswerClass::NoNumber => self.class_no_number,
            AnswerClass::ExampleEchoed => self.class_example_echoed,
            AnswerClass::Word => self.class_word,
            AnswerClass::NoWord => self.class_no_word,
            AnswerClass::Missing => self.class_missing,
        }
    }

    fn class_mut(&mut self, class: AnswerClass) -> &mut u64 {
        match class {
            AnswerClass::Json => &mut self.class_json,
            AnswerClass::NumberOnly => &mut self.class_number_only,
            AnswerClass::NumberInProse => &mut self.class_number_in_prose,
            AnswerClass::SeveralNumbers => &mut self.class_several_numbers,
            AnswerClass::NoNumber => &mut self.class_no_number,
            AnswerClass::ExampleEchoed => &mut self.class_example_echoed,
            AnswerClass::Word => &mut self.class_word,
            AnswerClass::NoWord => &mut self.class_no_word,
            AnswerClass::Missing => &mut self.class_missing,
        }
    }

    /// Answers (probability and P-DIRECT) that fell back.
    pub fn fallbacks(&self) -> u64 {
        self.probability_fallbacks + self.direct_fallbacks
    }

    /// Answers of either kind.
    pub fn answers(&self) -> u64 {
        self.probability_answers + self.direct_answers
    }

    /// The share of answers that fell back, `None` without answers.
    pub fn fallback_share(&self) -> Option<f64> {
        let n = self.answers();
        (n > 0).then(|| self.fallbacks() as f64 / n as f64)
    }
}

/// Everything counted for one (LLM, strategy) pair.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct UsageRow {
    /// The LLM's endpoint name.
    pub llm: String,
    /// The strategy name (`llm+model/p-context-a/gpt-5-mini`), or what else asked (`ping`).
    pub strategy: String,
    /// Requests sent in this run.
    pub sent: TokenCounts,
    /// Answers served from the response cache.
    pub cache_hits: u64,
    /// Distinct prompts whose answers were used, with what they cost when asked.
    pub distinct: TokenCounts,
    /// Answer parsing, over distinct prompts.
    pub answers: AnswerCounts,
    /// How often each probability was used (per mille, so 0.1 % apart), over distinct prompts.
    pub probability_values: BTreeMap<u32, u64>,
}

impl UsageRow {
    /// The most frequent probability and the share of probability answers that gave it.
    pub fn most_common_probability(&self) -> Option<(f64, f64)> {
        let total: u64 = self.probability_values.values().sum();
        let (v, n) = self
            .probability_values
            .iter()
            .max_by(|a, b| a.1.cmp(b.1).then(b.0.cmp(a.0)))?;
        (total > 0).then(|| (f64::from(*v) / 1000.0, *n as f64 / total as f64))
    }

    /// What went wrong with this strategy's answers, if anything went badly: most of them fell
    /// back, or most probabilities are one value (a model that says "10%" to everything plans
    /// like `model/uniform`). `None` when neither holds.
    pub fn warning(&self) -> Option<String> {
        if let Some(share) = self.answers.fallback_share()
            && share > WARN_FALLBACK_SHARE
        {
            return Some(format!(
                "{:.0} % of its {} answers could not be read and fell back ({} for probabilities); it plans like {}",
                100.0 * share,
                self.answers.answers(),
                crate::answer::FALLBACK_PROBABILITY,
                if self.answers.direct_answers > 0 {
                    "optimistic+greedy"
                } else {
                    "model/uniform"
                }
            ));
        }
        if self.answers.probability_answers >= 10
            && let Some((v, share)) = self.most_common_probability()
            && share > WARN_ONE_VALUE_SHARE
        {
            return Some(format!(
                "{:.0} % of its {} probabilities are {:.1} %: the answers barely depend on the question",
                100.0 * share,
                self.answers.probability_answers,
                100.0 * v
            ));
        }
        None
    }
}

/// A strategy whose answers fell back more often than this is flagged.
pub const WARN_FALLBACK_SHARE: f64 = 0.5;
/// A strategy whose probabilities are one value more often than this is flagged.
pub const WARN_ONE_VALUE_SHARE: f64 = 0.8;

#[derive(Debug, Default)]
struct Inner {
    rows: BTreeMap<(String, String), UsageRow>,
    /// (LLM, strategy, prompt key) already counted in a row's `distinct`.
    seen: HashSet<(String, String, String)>,
    /// Distinct prompts per LLM over all strategies: two strategies sharing a prompt (the same
    /// prompt and LLM under two planner limits) spent its tokens once.
    llm_distinct: BTreeMap<String, TokenCounts>,
    llm_seen: HashSet<(String, String)>,
    /// (LLM, prompt key) sent or served from the cache in this run: a later read of the same
    /// answer is neither a request nor a cache hit.
    fetched: HashSet<(String, String)>,
}

/// A thread-safe tally, shared by every LLM of a run.
#[derive(Debug, Default)]
pub struct Ledger {
    inner: Mutex<Inner>,
}

fn row<'a>(
    rows: &'a mut BTreeMap<(String, String), UsageRow>,
    llm: &str,
    strategy: &str,
) -> &'a mut UsageRow {
    rows.entry((llm.to_string(), strategy.to_string()))
        .or_insert_with(|| UsageRow {
            llm: llm.to_string(),
            strategy: strategy.to_string(),
            ..UsageRow::default()
        })
}

impl Ledger {
    /// An empty ledger.
    pub fn new() -> Self {
        Self::default()
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Inner> {
        self.inner.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Counts a request for prompt `key` sent to `llm` on behalf of `strategy`, answered in
    /// `seconds`.
    pub fn record_sent(
        &self,
        llm: &str,
        strategy: &str,
        key: &str,
        usage: &TokenUsage,
        cost_usd: f64,
        seconds: f64,
    ) {
        let mut inner = self.lock();
        inner.fetched.insert((llm.to_string(), key.to_string()));
        row(&mut inner.rows, llm, strategy)
            .sent
            .add(usage, cost_usd, seconds);
    }

    /// Counts an answer to prompt `key` served from the cache — once per run: reading again an
    /// answer this run already sent for or fetched (prefetched questions read by trials, replays)
    /// is not another hit.
    pub fn record_cache_hit(&self, llm: &str, strategy: &str, key: &str) {
        let mut inner = self.lock();
        if inner.fetched.insert((llm.to_string(), key.to_string())) {
            row(&mut inner.rows, llm, strategy).cache_hits += 1;
        }
    }

    /// Counts the use of the answer to prompt `key` — once per (LLM, strategy, prompt), however
    /// often it is used: its tokens and cost, and how it was read.
    pub fn record_answer(
        &self,
        llm: &str,
        strategy: &str,
        key: &str,
        usage: &TokenUsage,
        cost_usd: f64,
        outcome: AnswerOutcome,
    ) {
        let spent = Spent {
            usage,
            cost_usd,
            seconds: 0.0,
        };
        self.record_answers(llm, strategy, key, spent, &[outcome]);
    }

    /// Like [`Self::record_answer`], with the seconds the answer took when it was asked, for an
    /// answer that may give several readings (a percentage per place, P-BATCH): what it
    /// [`Spent`] once, each reading as an answer of its own.
    pub fn record_answers(
        &self,
        llm: &str,
        strategy: &str,
        key: &str,
        spent: Spent<'_>,
        outcomes: &[AnswerOutcome],
    ) {
        let Spent {
            usage,
            cost_usd,
            seconds,
        } = spent;
        let mut inner = self.lock();
        if !inner
            .seen
            .insert((llm.to_string(), strategy.to_string(), key.to_string()))
        {
            return;
        }
        if inner.llm_seen.insert((llm.to_string(), key.to_string())) {
            inner
                .llm_distinct
                .entry(llm.to_string())
                .or_default()
                .add(usage, cost_usd, seconds);
        }
        let r = row(&mut inner.rows, llm, strategy);
        r.distinct.add(usage, cost_usd, seconds);
        for &outcome in outcomes {
            count_outcome(r, outcome);
        }
    }

    /// A snapshot of every row.
    pub fn report(&self) -> TokenReport {
        let inner = self.lock();
        TokenReport {
            rows: inner.rows.values().cloned().collect(),
            llm_distinct: inner.llm_distinct.clone(),
        }
    }
}

fn count_outcome(r: &mut UsageRow, outcome: AnswerOutcome) {
    if let AnswerOutcome::Probability { value: Some(v), .. } = outcome {
        *r.probability_values
            .entry((v * 1000.0).round() as u32)
            .or_default() += 1;
    }
    let a = &mut r.answers;
    match outcome {
        AnswerOutcome::Probability {
            class,
            reasked,
            value,
            logprobs,
        } => {
            a.probability_answers += 1;
            *a.class_mut(class) += 1;
            a.reasked += u64::from(reasked);
            a.probability_fallbacks += u64::from(value.is_none());
            match logprobs {
                LogprobUse::Used => a.logprob_used += 1,
                LogprobUse::Missing => a.logprob_missing += 1,
                LogprobUse::NotWanted => {}
            }
        }
        AnswerOutcome::Direct(kind) => {
            a.direct_answers += 1;
            match kind {
                MatchKind::Exact => a.direct_exact += 1,
                MatchKind::CaseInsensitive => a.direct_case_insensitive += 1,
                MatchKind::Containment => a.direct_containment += 1,
                MatchKind::Fallback => a.direct_fallbacks += 1,
            }
        }
        AnswerOutcome::Other => {}
    }
}

/// A snapshot of a [`Ledger`]: rows sorted by LLM, then strategy.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct TokenReport {
    /// One row per (LLM, strategy).
    pub rows: Vec<UsageRow>,
    /// Distinct prompts per LLM over all its strategies, each counted once.
    pub llm_distinct: BTreeMap<String, TokenCounts>,
}

/// The header of `tokens.csv`.
pub const TOKENS_CSV_HEADER: [&str; 33] = [
    "llm",
    "strategy",
    "requests",
    "input_tokens",
    "output_tokens",
    "cached_input_tokens",
    "cost_usd",
    "cache_hits",
    "distinct_prompts",
    "distinct_input_tokens",
    "distinct_output_tokens",
    "distinct_cost_usd",
    "probability_answers",
    "probability_fallbacks",
    "direct_answers",
    "direct_case_insensitive",
    "direct_containment",
    "direct_fallbacks",
    "class_json",
    "class_number_only",
    "class_number_in_prose",
    "class_several_numbers",
    "class_no_number",
    "class_example_echoed",
    "reasked",
    "logprob_used",
    "logprob_missing",
    "warning",
    "class_word",
    "class_no_word",
    "class_missing",
    "seconds",
    "distinct_seconds",
];

impl TokenReport {
    /// One row per LLM over all its strategies (`strategy` = `*`): the paper's table V. Requests,
    /// cache hits and answer counts are summed; `distinct` counts a prompt shared by several
    /// strategies once.
    pub fn per_llm(&self) -> Vec<UsageRow> {
        let mut by: BTreeMap<&str, UsageRow> = BTreeMap::new();
        for r in &self.rows {
            let t = by.entry(&r.llm).or_insert_with(|| UsageRow {
                llm: r.llm.clone(),
                strategy: "*".into(),
                ..UsageRow::default()
            });
            t.sent.merge(&r.sent);
            t.cache_hits += r.cache_hits;
            t.answers.merge(&r.answers);
        }
        for (llm, row) in by.iter_mut() {
            row.distinct = self.llm_distinct.get(*llm).copied().unwrap_or_default();
        }
        by.into_values().collect()
    }

    /// The row for (`llm`, `strategy`), if anything was counted.
    pub fn row(&self, llm: &str, strategy: &str) -> Option<&UsageRow> {
        self.rows
            .iter()
            .find(|r| r.llm == llm && r.strategy == strategy)
    }

    /// Writes `tokens.csv`: [`TOKENS_CSV_HEADER`], one line per (LLM, strategy).
    pub fn write_csv<W: Write>(&self, out: W) -> csv::Result<()> {
        let mut w = csv::Writer::from_writer(out);
        w.write_record(TOKENS_CSV_HEADER)?;
        for r in &self.rows {
            let n = |v: u64| v.to_string();
            let usd = |v: f64| format!("{v:.6}");
            w.write_record([
                r.llm.clone(),
                r.strategy.clone(),
                n(r.sent.requests),
                n(r.sent.input_tokens),
                n(r.sent.output_tokens),
                n(r.sent.cached_input_tokens),
                usd(r.sent.cost_usd),
                n(r.cache_hits),
                n(r.distinct.requests),
                n(r.distinct.input_tokens),
                n(r.distinct.output_tokens),
                usd(r.distinct.cost_usd),
                n(r.answers.probability_answers),
                n(r.answers.probability_fallbacks),
                n(r.answers.direct_answers),
                n(r.answers.direct_case_insensitive),
                n(r.answers.direct_containment),
                n(r.answers.direct_fallbacks),
                n(r.answers.class_json),
                n(r.answers.class_number_only),
                n(r.answers.class_number_in_prose),
                n(r.answers.class_several_numbers),
                n(r.answers.class_no_number),
                n(r.answers.class_example_echoed),
                n(r.answers.reasked),
                n(r.answers.logprob_used),
                n(r.answers.logprob_missing),
                r.warning().unwrap_or_default(),
                n(r.answers.class_word),
                n(r.answers.class_no_word),
                n(r.answers.class_missing),
                format!("{:.3}", r.sent.seconds),
                format!("{:.3}", r.distinct.seconds),
            ])?;
        }
        w.flush()?;
        Ok(())
    }
}

/// A plain-text table like the paper's table V, one line per LLM: the tokens and cost of the
/// distinct prompts used, then requests sent now, cache hits and answer fallbacks.
impl fmt::Display for TokenReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "{:<20} {:>12} {:>10} {:>12} {:>10} {:>9} {:>10} {:>10}",
            "LLM",
            "input tok",
            "output tok",
            "total tok",
            "cost USD",
            "requests",
            "cache hits",
            "fallbacks"
        )?;
        for r in self.per_llm() {
            writeln!(
                f,
                "{:<20} {:>12} {:>10} {:>12} {:>10.4} {:>9} {:>10} {:>10}",
                r.llm,
                r.distinct.input_tokens,
                r.distinct.output_tokens,
                r.distinct.total_tokens(),
                r.distinct.cost_usd,
                r.sent.requests,
                r.cache_hits,
                r.answers.fallbacks(),
            )?;
        }
        // The same columns per strategy, so prompts of one LLM can be compared (paper table V
        // gives only the per-LLM totals).
        // "prompts" and "seconds" are over the distinct prompts used, whenever they were asked:
        // what the strategy costs, whether its answers came from the cache or not.
        writeln!(
            f,
            "\n{:<40} {:>8} {:>12} {:>10} {:>10} {:>9} {:>9} {:>10} {:>10}",
            "strategy",
            "prompts",
            "input tok",
            "output tok",
            "cost USD",
            "seconds",
            "requests",
            "cache hits",
            "fallbacks"
        )?;
        for r in &self.rows {
            writeln!(
                f,
                "{:<40} {:>8} {:>12} {:>10} {:>10.4} {:>9.1} {:>9} {:>10} {:>10}",
                r.strategy,
                r.distinct.requests,
                r.distinct.input_tokens,
                r.distinct.output_tokens,
                r.distinct.cost_usd,
                r.distinct.seconds,
                r.sent.requests,
                r.cache_hits,
                r.answers.fallbacks(),
            )?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn prob(class: AnswerClass, value: Option<f64>) -> AnswerOutcome {
        AnswerOutcome::Probability {
            class,
            reasked: !class.usable(),
            value,
            logprobs: LogprobUse::NotWanted,
        }
    }

    #[test]
    fn tallies_per_llm_and_strategy_and_writes_csv() {
        let l = Ledger::new();
        let (m, d) = ("llm+model/p-minimal/g", "llm-direct/p-direct/g");
        let u = TokenUsage {
            prompt_tokens: 100,
            completion_tokens: 3,
            cached_tokens: Some(40),
        };
        l.record_sent("g", m, "k1", &u, 0.5, 1.5);
        l.record_sent("g", m, "k2", &u, 0.5, 1.5);
        l.record_answer(
            "g",
            m,
            "k1",
            &u,
            0.5,
            prob(AnswerClass::NumberOnly, Some(0.3)),
        );
        l.record_answer("g", m, "k2", &u, 0.5, prob(AnswerClass::NoNumber, None));
        // Reading again an answer sent in this run is not a cache hit, nor a second use.
        l.record_cache_hit("g", m, "k2");
        l.record_answer("g", m, "k2", &u, 0.5, prob(AnswerClass::NoNumber, None));
        // An answer first served from the cache is one hit, however often it is read.
        l.record_cache_hit("g", d, "k3");
        l.record_cache_hit("g", d, "k3");
        l.record_answer(
            "g",
            d,
            "k3",
            &u,
            0.5,
            AnswerOutcome::Direct(MatchKind::Fallback),
        );
        l.record_answer(
            "g",
            d,
            "k4",
            &u,
            0.5,
            AnswerOutcome::Direct(MatchKind::Exact),
        );
        let r = l.report();
        let row_m = r.row("g", m).unwrap();
        assert_eq!(
            row_m.sent,
            TokenCounts {
                requests: 2,
                input_tokens: 200,
                output_tokens: 6,
                cached_input_tokens: 80,
                cost_usd: 1.0,
                seconds: 3.0,
            }
        );
        assert_eq!(row_m.distinct.requests, 2);
        assert_eq!(row_m.cache_hits, 0);
        let a = row_m.answers;
        assert_eq!(
            (
                a.probability_answers,
                a.probability_fallbacks,
                a.class_number_only,
                a.class_no_number,
                a.reasked
            ),
            (2, 1, 1, 1, 1)
        );
        assert_eq!(row_m.most_common_probability(), Some((0.3, 1.0)));
        let row_d = r.row("g", d).unwrap();
        assert_eq!(row_d.cache_hits, 1);
        assert_eq!(
            (
                row_d.answers.direct_answers,
                row_d.answers.direct_fallbacks,
                row_d.answers.direct_exact
            ),
            (2, 1, 1)
        );
        let t = &r.per_llm()[0];
        assert_eq!(
            (t.distinct.input_tokens, t.sent.requests, t.cache_hits),
            (400, 2, 1)
        );
        let mut csv = Vec::new();
        r.write_csv(&mut csv).unwrap();
        let csv = String::from_utf8(csv).unwrap();
        let lines: Vec<&str> = csv.lines().collect();
        assert_eq!(lines.len(), 3);
        assert_eq!(lines[0], TOKENS_CSV_HEADER.join(","));
        assert_eq!(
            lines[1],
            "g,llm+model/p-minimal/g,2,200,6,80,1.000000,0,2,200,6,1.000000,2,1,0,0,0,0,0,1,0,0,1,0,1,0,0,,0,0,0,3.000,0.000"
        );
        let table = r.to_string();
        assert!(table.lines().nth(1).unwrap().starts_with("g "), "{table}");
        assert!(table.contains(" 400 "), "{table}");
        // A prompt shared by two strategies counts once per LLM.
        l.record_answer(
            "g",
            "llm+model/p-minimal/g/exact",
            "k1",
            &u,
            0.5,
            prob(AnswerClass::NumberOnly, Some(0.3)),
        );
        let r = l.report();
        assert_eq!(
            r.row("g", "llm+model/p-minimal/g/exact")
                .unwrap()
                .distinct
                .requests,
            1
        );
        assert_eq!(r.per_llm()[0].distinct.requests, 4);
    }

    #[test]
    fn warns_when_answers_fall_back_or_collapse_to_one_value() {
        let u = TokenUsage::default();
        let l = Ledger::new();
        for i in 0..20 {
            let (class, v) = if i < 11 {
                (AnswerClass::NoNumber, None)
            } else {
                (AnswerClass::NumberOnly, Some(0.5))
            };
            l.record_answer("g", "a", &format!("k{i}"), &u, 0.0, prob(class, v));
        }
        for i in 0..20 {
            let v = if i < 17 { 0.1 } else { 0.05 * f64::from(i) };
            l.record_answer(
                "g",
                "b",
                &format!("k{i}"),
                &u,
                0.0,
                prob(AnswerClass::NumberOnly, Some(v)),
            );
        }
        for i in 0..20 {
            l.record_answer(
                "g",
                "c",
                &format!("k{i}"),
                &u,
                0.0,
                prob(AnswerClass::NumberOnly, Some(0.01 * f64::from(i + 1))),
            );
        }
        let r = l.report();
        let a = r.row("g", "a").unwrap().warning().unwrap();
        assert!(a.contains("55 %") && a.contains("model/uniform"), "{a}");
        let b = r.row("g", "b").unwrap().warning().unwrap();
        assert!(b.contains("85 %") && b.contains("10.0 %"), "{b}");
        assert_eq!(r.row("g", "c").unwrap().warning(), None);
    }
}
