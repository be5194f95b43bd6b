//! `P_S` from an LLM: [`LlmLikelihood`], the likelihood source behind `llm+model/<prompt>/<llm>`.
//!
//! How a prompt is asked and read depends on its [`PromptKind`]:
//! - **percent** (P-CONTEXT-A, P-CONTEXT-B, P-MINIMAL): one question per (target, container
//!   type, room) of a house; the answer's percentage (or the expectation over the number's token
//!   log-probabilities) is the probability of every container of that type in that room.
//! - **yesno** (P-YESNO): one question per (target, container type, room type) naming no house,
//!   so one answer serves every house; P = P(Yes) / (P(Yes) + P(No)) from the first answer
//!   token's log-probabilities.
//! - **choice** (P-CHOICE): one question per house and target listing its places with letters
//!   (asked once more with the list reversed when the template says `orders=2`); the letter's
//!   distribution q is the probability of each place, floored at 0.01 and capped at 0.99. A
//!   house with more places than letters is asked in parts; each part's distribution is scaled
//!   by the part's share of the places, so the total is still 1.
//! - **batch** (P-BATCH): one question per house and target (per part) giving a percentage for
//!   every letter (or, with `yesno`, Yes or No for every place, read as P-YESNO reads its answer;
//!   with `names`, places are named rather than lettered); a place left out is asked again once,
//!   then 0.01.
//!
//! Unusable answers are asked again with a format reminder (up to the endpoint's `max_reasks`),
//! then fall back to 0.01 (for P-CHOICE: every place of the part alike), and are counted.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use ferret_plan::{LikelihoodSource, PlanError, Probability};
use ferret_world::{House, ObjectType};
use futures::future::join_all;

use crate::answer::{
    AnswerClass, FALLBACK_PROBABILITY, WorkedExample, contains_phrase, read_batch,
    read_batch_yes_no, read_label, read_probability, read_yes_no,
};
use crate::client::TokenUsage;
use crate::config::ProbabilityFrom;
use crate::context::{HouseContext, Listing, ListingContext, ProbabilityQuery, QueryPlan};
use crate::error::{LlmError, Result};
use crate::ledger::{AnswerOutcome, LogprobUse, Spent};
use crate::logprobs::{expected_percentage, label_distribution, yes_probability};
use crate::message::ChatMessage;
use crate::prompts::{PromptKind, PromptLibrary};
use crate::question::{
    CHOICE_REMINDER, Expect, PROBABILITY_REMINDER, Question, YES_NO_REMINDER, batch_reminder,
};
use crate::service::{Answer, Llm, LlmService};

/// The largest probability a P-CHOICE place gets: one letter's near certainty says which place
/// is likeliest, not that the target cannot be anywhere else.
pub const CHOICE_CAP: f64 = 0.99;

/// (house name, house index, container count, target).
type MemoKey = (String, usize, usize, ObjectType);

/// What one question asks about, and so how its answer is read.
#[derive(Clone, Debug, PartialEq)]
pub enum Asked {
    /// A target in a container type in a room (percent and yes/no prompts): one probability.
    Query(ProbabilityQuery),
    /// Places of the house's [`Listing`] (indices), lettered `A`, `B`, ... in this order: a
    /// distribution over them (P-CHOICE) or a probability each (P-BATCH).
    Places(Vec<usize>),
}

impl Asked {
    /// The places a listing question names, in the order lettered.
    pub fn places(&self) -> Option<&[usize]> {
        match self {
            Self::Places(p) => Some(p),
            Self::Query(_) => None,
        }
    }
}

/// How each container takes its probability from the answers of a [`QuestionSet`].
#[derive(Clone, Debug, PartialEq)]
pub enum Shape {
    /// Container `i` takes the answer of question `of_container[i]`.
    PerQuery {
        /// The question of each container.
        of_container: Vec<usize>,
    },
    /// Container `i` takes the probability of its place in the listing.
    Listing(Listing),
}

/// The questions for one house and target.
#[derive(Clone, Debug, PartialEq)]
pub struct QuestionSet {
    /// Each question with what it asks about.
    pub questions: Vec<(Question, Asked)>,
    /// How containers take their probabilities from the answers.
    pub shape: Shape,
}

/// A question answered, re-asks included.
#[derive(Clone, Debug, PartialEq)]
pub struct Resolved {
    /// The first question's cache key (what the ledger counts distinct prompts by).
    pub key: String,
    /// Tokens of every exchange.
    pub usage: TokenUsage,
    /// USD of every exchange.
    pub cost_usd: f64,
    /// Seconds every exchange took when it was asked.
    pub seconds: f64,
    /// True when the first answer was (in part) unusable and the question was asked again.
    pub reasked: bool,
    /// The probability of each thing asked (one for a query; one per place, in the order asked,
    /// for a listing), `None` where no answer could be read.
    pub values: Vec<Option<f64>>,
    /// How the answer was read: what the ledger counts (one per reading).
    pub outcomes: Vec<AnswerOutcome>,
}

/// `P_S` from an LLM asked with one prompt (see the module documentation).
pub struct LlmLikelihood {
    service: Arc<LlmService>,
    llm: Arc<Llm>,
    prompt: String,
    kind: PromptKind,
    /// `<prompt>/<llm>`.
    name: String,
    /// The strategy the answers are counted under.
    strategy: String,
    /// Results per (house name, house index, container count, target): trials and replays on
    /// the same house reuse them without rendering or looking anything up again.
    memo: Mutex<HashMap<MemoKey, Vec<Probability>>>,
    /// The prompt's worked example, read from its template once.
    example: Option<WorkedExample>,
}

impl std::fmt::Debug for LlmLikelihood {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LlmLikelihood")
            .field("name", &self.name)
            .field("kind", &self.kind)
            .field("strategy", &self.strategy)
            .finish()
    }
}

impl Resolved {
    /// Sets the single reading of a per-container question.
    fn one(&mut self, class: AnswerClass, value: Option<f64>, logprobs: LogprobUse) {
        self.values = vec![value];
        self.outcomes = vec![AnswerOutcome::Probability {
            class,
            reasked: self.reasked,
            value,
            logprobs,
        }];
    }
}

impl LlmLikelihood {
    /// A source asking `llm` with `prompt` (a template name or path), counting under `strategy`.
    pub fn new(service: Arc<LlmService>, prompt: &str, llm: &str, strategy: &str) -> Result<Self> {
        let prompt = service.resolve_prompt(prompt)?;
        let llm = service.llm(llm)?;
        let example = service.prompts().example(&prompt);
        let kind = service.prompts().kind(&prompt);
        Ok(Self {
            name: format!("{prompt}/{}", llm.name()),
            service,
            llm,
            prompt,
            kind,
            strategy: strategy.to_string(),
            memo: Mutex::new(HashMap::new()),
            example,
        })
    }

    /// The LLM asked.
    pub fn llm(&self) -> &Arc<Llm> {
        &self.llm
    }

    /// The prompt template's name.
    pub fn prompt(&self) -> &str {
        &self.prompt
    }

    /// How the prompt is asked and read.
    pub fn kind(&self) -> PromptKind {
        self.kind
    }

    /// The messages of every question for `target` in `house`.
    pub fn messages(&self, house: &House, target: &ObjectType) -> Result<Vec<Vec<ChatMessage>>> {
        Ok(self
            .questions(house, target)?
            .questions
            .into_iter()
            .map(|(q, _)| q.messages)
            .collect())
    }

    /// The questions for `target` in `house`.
    pub fn questions(&self, house: &House, target: &ObjectType) -> Result<QuestionSet> {
        question_set(&self.service.prompts(), &self.prompt, house, target)
    }

    /// The prompt's worked example, unless the question is about the example's own object (then
    /// the example's value may well be the answer).
    fn example_for(&self, asked: &Asked) -> Option<WorkedExample> {
        let Asked::Query(query) = asked else {
            return None;
        };
        let example = self.example.clone()?;
        let words = format!(
            "{} {}",
            query.target.words().to_lowercase(),
            query.container.words().to_lowercase()
        );
        (!example.words.iter().any(|w| contains_phrase(&words, w))).then_some(example)
    }

    /// Reads one percentage answer: its class, the probability (from the text, or from the
    /// tokens' log-probabilities when the endpoint says so), and where it came from.
    fn read_percent(
        &self,
        answer: &Answer,
        example: Option<&WorkedExample>,
    ) -> (AnswerClass, Option<f64>, LogprobUse) {
        let r = read_probability(&answer.text, example);
        let Some(p) = r.probability else {
            return (r.class, None, LogprobUse::NotWanted);
        };
        self.percent_from_tokens(answer, r.class, p, r.number)
    }

    /// `p`, or the expectation over the tokens of the number at `number`, as the endpoint says.
    fn percent_from_tokens(
        &self,
        answer: &Answer,
        class: AnswerClass,
        p: f64,
        number: Option<std::ops::Range<usize>>,
    ) -> (AnswerClass, Option<f64>, LogprobUse) {
        if self.llm.endpoint().config.probability_from == ProbabilityFrom::Text {
            return (class, Some(p), LogprobUse::NotWanted);
        }
        let expected = match (&answer.logprobs, number) {
            (Some(tokens), Some(number)) => expected_percentage(tokens, &answer.text, number).ok(),
            _ => None,
        };
        match expected {
            Some(e) => (
                class,
                Some((e / 100.0).clamp(FALLBACK_PROBABILITY, 1.0)),
                LogprobUse::Used,
            ),
            None => (class, Some(p), LogprobUse::Missing),
        }
    }

    /// Reads one yes/no answer.
    fn read_yes_no(&self, answer: &Answer) -> (AnswerClass, Option<f64>, LogprobUse) {
        match read_yes_no(&answer.text) {
            Some(word) => self.word_probability(answer, &word),
            None => (AnswerClass::NoWord, None, LogprobUse::NotWanted),
        }
    }

    /// P(Yes) at a Yes/No `word` of `answer`: from the tokens' log-probabilities, or the word
    /// with the endpoint's `word_answer_mass` when there are none.
    fn word_probability(
        &self,
        answer: &Answer,
        word: &crate::answer::WordReading,
    ) -> (AnswerClass, Option<f64>, LogprobUse) {
        let from_tokens = answer
            .logprobs
            .as_deref()
            .and_then(|t| yes_probability(t, &answer.text, word.span.start));
        match from_tokens {
            Some(p) => (
                AnswerClass::Word,
                Some(p.clamp(FALLBACK_PROBABILITY, CHOICE_CAP)),
                LogprobUse::Used,
            ),
            None => {
                let m = self.llm.endpoint().config.word_answer_mass;
                let p = if word.index == 0 { m } else { 1.0 - m };
                (AnswerClass::Word, Some(p), LogprobUse::Missing)
            }
        }
    }

    /// Reads one choice answer: the distribution over `labels`.
    fn read_choice(
        &self,
        answer: &Answer,
        labels: &[String],
    ) -> (AnswerClass, Option<Vec<f64>>, LogprobUse) {
        let Some(word) = read_label(&answer.text, labels) else {
            return (AnswerClass::NoWord, None, LogprobUse::NotWanted);
        };
        let from_tokens = answer
            .logprobs
            .as_deref()
            .and_then(|t| label_distribution(t, &answer.text, word.span.start, labels));
        match from_tokens {
            Some(q) => (AnswerClass::Word, Some(q), LogprobUse::Used),
            None => {
                let m = self.llm.endpoint().config.word_answer_mass;
                let n = labels.len();
                let q = (0..n)
                    .map(|i| match (i == word.index, n) {
                        (_, 1) => 1.0,
                        (true, _) => m,
                        (false, _) => (1.0 - m) / (n - 1) as f64,
                    })
                    .collect();
                (AnswerClass::Word, Some(q), LogprobUse::Missing)
            }
        }
    }

    /// Asks `question` (about `asked`), and asks again with a format reminder while the answer
    /// is unusable, up to the endpoint's `max_reasks`. Every exchange goes through the cache.
    /// Nothing is counted as used here (see `record`).
    pub async fn resolve(&self, question: &Question, asked: &Asked) -> Result<Resolved> {
        let first = self.llm.ask(question, &self.strategy).await?;
        let mut resolved = Resolved {
            key: first.key.clone(),
            usage: first.usage,
            cost_usd: first.cost_usd,
            seconds: first.latency.as_secs_f64(),
            reasked: false,
            values: Vec::new(),
            outcomes: Vec::new(),
        };
        let max_reasks = self.llm.endpoint().config.max_reasks;
        let mut asked_now = question.clone();
        let mut answer = first;
        match (&question.expect, asked) {
            (Expect::Batch(labels) | Expect::BatchYesNo(labels), Asked::Places(_)) => {
                let yesno = matches!(question.expect, Expect::BatchYesNo(_));
                // Letters are one character; a named place is a phrase.
                let names = labels.iter().any(|l| l.chars().count() > 1);
                let first = self.read_batch(&answer, labels, names, yesno);
                let first_classes: Vec<AnswerClass> = first.iter().map(|(c, _)| *c).collect();
                let mut read: Vec<Option<(f64, LogprobUse)>> =
                    first.into_iter().map(|(_, v)| v).collect();
                for _ in 0..max_reasks {
                    let missing: Vec<String> = labels
                        .iter()
                        .zip(&read)
                        .filter(|(_, v)| v.is_none())
                        .map(|(l, _)| l.clone())
                        .collect();
                    if missing.is_empty() {
                        break;
                    }
                    tracing::debug!(source = %self.name, missing = ?missing, "places missing from a batch answer; asking again");
                    resolved.reasked = true;
                    asked_now = asked_now.reask(&answer.text, &batch_reminder(&missing, yesno));
                    answer = self.ask_again(&asked_now, &mut resolved).await?;
                    let again = self.read_batch(&answer, labels, names, yesno);
                    for (slot, (_, v)) in read.iter_mut().zip(again) {
                        if slot.is_none() {
                            *slot = v;
                        }
                    }
                }
                resolved.values = read.iter().map(|v| v.map(|(p, _)| p)).collect();
                resolved.outcomes = read
                    .iter()
                    .zip(first_classes)
                    .map(|(v, class)| AnswerOutcome::Probability {
                        class,
                        reasked: resolved.reasked && !class.usable(),
                        value: v.map(|(p, _)| p),
                        logprobs: v.map_or(LogprobUse::NotWanted, |(_, l)| l),
                    })
                    .collect();
            }
            (Expect::Choice(labels), Asked::Places(places)) => {
                let (class, q, logprobs) = self
                    .read_until_usable(question, answer, &mut resolved, CHOICE_REMINDER, |a| {
                        self.read_choice(a, labels)
                    })
                    .await?;
                let top = q.as_ref().and_then(|q| q.iter().copied().reduce(f64::max));
                resolved.values = match q {
                    Some(q) => q.into_iter().map(Some).collect(),
                    None => vec![None; places.len()],
                };
                resolved.outcomes = vec![AnswerOutcome::Probability {
                    class,
                    reasked: resolved.reasked,
                    value: top,
                    logprobs,
                }];
            }
            (Expect::YesNo, Asked::Query(_)) => {
                let (class, value, logprobs) = self
                    .read_until_usable(question, answer, &mut resolved, YES_NO_REMINDER, |a| {
                        self.read_yes_no(a)
                    })
                    .await?;
                resolved.one(class, value, logprobs);
            }
            _ => {
                let example = self.example_for(asked);
                let (class, value, logprobs) = self
                    .read_until_usable(question, answer, &mut resolved, PROBABILITY_REMINDER, |a| {
                        self.read_percent(a, example.as_ref())
                    })
                    .await?;
                resolved.one(class, value, logprobs);
            }
        }
        Ok(resolved)
    }

    /// Reads `answer` to `question` with `read`, and while it gives nothing usable, asks again
    /// with `reminder` (up to the endpoint's `max_reasks`), counting every exchange in
    /// `resolved`. Returns the first answer's class with the last reading's value.
    async fn read_until_usable<T>(
        &self,
        question: &Question,
        mut answer: Answer,
        resolved: &mut Resolved,
        reminder: &str,
        read: impl Fn(&Answer) -> (AnswerClass, Option<T>, LogprobUse),
    ) -> Result<(AnswerClass, Option<T>, LogprobUse)> {
        let (class, mut value, mut logprobs) = read(&answer);
        let mut asked = question.clone();
        for _ in 0..self.llm.endpoint().config.max_reasks {
            if value.is_some() {
                break;
            }
            tracing::debug!(source = %self.name, answer = %answer.text, "unusable answer; asking again");
            resolved.reasked = true;
            asked = asked.reask(&answer.text, reminder);
            answer = self.ask_again(&asked, resolved).await?;
            (_, value, logprobs) = read(&answer);
        }
        Ok((class, value, logprobs))
    }

    /// Reads a batch answer: per label, the class of what it gives and its probability (`None`
    /// when the place is missing or its value unreadable).
    fn read_batch(
        &self,
        answer: &Answer,
        labels: &[String],
        names: bool,
        yesno: bool,
    ) -> Vec<(AnswerClass, Option<(f64, LogprobUse)>)> {
        if !yesno {
            return read_batch(&answer.text, labels, names)
                .iter()
                .map(|r| {
                    (
                        r.as_ref().map_or(AnswerClass::Missing, |r| r.class),
                        self.batch_value(answer, r.as_ref()),
                    )
                })
                .collect();
        }
        read_batch_yes_no(&answer.text, labels, names)
            .into_iter()
            .map(|r| match r {
                None => (AnswerClass::Missing, None),
                Some(None) => (AnswerClass::NoWord, None),
                Some(Some(word)) => {
                    let (class, p, l) = self.word_probability(answer, &word);
                    (class, p.map(|p| (p, l)))
                }
            })
            .collect()
    }

    /// The probability of one batch reading, `None` when the place is missing or unreadable.
    fn batch_value(
        &self,
        answer: &Answer,
        reading: Option<&crate::answer::ProbabilityReading>,
    ) -> Option<(f64, LogprobUse)> {
        let r = reading?;
        let p = r.probability?;
        let (_, v, l) = self.percent_from_tokens(answer, r.class, p, r.number.clone());
        v.map(|v| (v, l))
    }

    async fn ask_again(&self, question: &Question, resolved: &mut Resolved) -> Result<Answer> {
        let answer = self.llm.ask(question, &self.strategy).await?;
        resolved.usage.prompt_tokens += answer.usage.prompt_tokens;
        resolved.usage.completion_tokens += answer.usage.completion_tokens;
        resolved.cost_usd += answer.cost_usd;
        resolved.seconds += answer.latency.as_secs_f64();
        Ok(answer)
    }

    /// Counts a resolved question as used (once per distinct prompt).
    fn record(&self, r: &Resolved) {
        if r.values.iter().any(Option::is_none) {
            tracing::debug!(source = %self.name, "unreadable answers; using {FALLBACK_PROBABILITY}");
        }
        self.llm.ledger().record_answers(
            self.llm.name(),
            &self.strategy,
            &r.key,
            Spent {
                usage: &r.usage,
                cost_usd: r.cost_usd,
                seconds: r.seconds,
            },
            &r.outcomes,
        );
    }

    /// The probabilities, asking every question of the house concurrently.
    pub async fn likelihoods_async(
        &self,
        house: &House,
        target: &ObjectType,
    ) -> Result<Vec<Probability>> {
        let set = self.questions(house, target)?;
        let answers = join_all(set.questions.iter().map(|(q, a)| self.resolve(q, a))).await;
        let resolved = answers.into_iter().collect::<Result<Vec<_>>>()?;
        for r in &resolved {
            self.record(r);
        }
        let floor = |v: Option<f64>| {
            Probability::clamped(v.unwrap_or(FALLBACK_PROBABILITY), FALLBACK_PROBABILITY, 1.0)
        };
        match &set.shape {
            Shape::PerQuery { of_container } => {
                let per_query: Vec<Probability> = resolved
                    .iter()
                    .map(|r| floor(r.values.first().copied().flatten()))
                    .collect();
                Ok(of_container.iter().map(|&q| per_query[q]).collect())
            }
            Shape::Listing(listing) => {
                let per_place = match self.kind {
                    PromptKind::Choice { .. } => choice_probabilities(listing, &set, &resolved),
                    _ => {
                        let mut p = vec![FALLBACK_PROBABILITY; listing.places.len()];
                        for ((_, asked), r) in set.questions.iter().zip(&resolved) {
                            if let Asked::Places(places) = asked {
                                for (&place, v) in places.iter().zip(&r.values) {
                                    p[place] = floor(*v).get();
                                }
                            }
                        }
                        p
                    }
                };
                Ok(listing
                    .of_container
                    .iter()
                    .map(|&i| floor(Some(per_place[i])))
                    .collect())
            }
        }
    }
}

/// The questions template `prompt` of `prompts` asks for `target` in `house`, as its kind says
/// (see the module documentation).
pub fn question_set(
    prompts: &PromptLibrary,
    prompt: &str,
    house: &House,
    target: &ObjectType,
) -> Result<QuestionSet> {
    let kind = prompts.kind(prompt);
    let ctx = HouseContext::new(house);
    let about = |what: String| format!("house {} (#{}): {what}", house.name, house.index);
    match kind {
        PromptKind::Percent | PromptKind::YesNo => {
            let plan = if kind == PromptKind::YesNo {
                QueryPlan::by_room_type(house, target)
            } else {
                QueryPlan::with_context(house, &ctx, target)
            };
            let questions = plan
                .queries
                .iter()
                .map(|q| {
                    let messages = prompts.probability_messages(prompt, &ctx, q)?;
                    let question = if kind == PromptKind::YesNo {
                        Question {
                            messages,
                            expect: Expect::YesNo,
                            about: about(q.describe()),
                        }
                    } else {
                        Question::probability(messages, about(q.describe()))
                    };
                    Ok((question, Asked::Query(q.clone())))
                })
                .collect::<Result<Vec<_>>>()?;
            Ok(QuestionSet {
                questions,
                shape: Shape::PerQuery {
                    of_container: plan.of_container,
                },
            })
        }
        PromptKind::Choice { orders } => {
            let listing = Listing::new(house, &ctx);
            let mut questions = Vec::new();
            for (i, part) in listing.parts.iter().enumerate() {
                for order in 0..orders {
                    let places: Vec<usize> = if order == 0 {
                        part.clone()
                    } else {
                        part.iter().rev().copied().collect()
                    };
                    let lctx = ListingContext::new(&ctx, &listing, &places, target);
                    let messages = prompts.listing_messages(prompt, &lctx)?;
                    let question = Question {
                        messages,
                        expect: Expect::Choice(lctx.labels()),
                        about: about(format!(
                            "where is {} most likely (places {}{})",
                            target.words(),
                            part_words(i, listing.parts.len()),
                            if order == 0 { "" } else { ", reversed" }
                        )),
                    };
                    questions.push((question, Asked::Places(places)));
                }
            }
            Ok(QuestionSet {
                questions,
                shape: Shape::Listing(listing),
            })
        }
        PromptKind::Batch { names, yesno } => {
            let listing = Listing::new(house, &ctx);
            let mut questions = Vec::new();
            for (i, part) in listing.parts.iter().enumerate() {
                let lctx = ListingContext::labelled(&ctx, &listing, part, target, names);
                let messages = prompts.listing_messages(prompt, &lctx)?;
                let question = Question {
                    messages,
                    expect: if yesno {
                        Expect::BatchYesNo(lctx.labels())
                    } else {
                        Expect::Batch(lctx.labels())
                    },
                    about: about(format!(
                        "likelihood of {} at every place ({})",
                        target.words(),
                        part_words(i, listing.parts.len())
                    )),
                };
                questions.push((question, Asked::Places(part.clone())));
            }
            Ok(QuestionSet {
                questions,
                shape: Shape::Listing(listing),
            })
        }
    }
}

/// "all places" or "part 2 of 3".
fn part_words(i: usize, parts: usize) -> String {
    if parts == 1 {
        "all places".into()
    } else {
        format!("part {} of {parts}", i + 1)
    }
}

/// P-CHOICE's probability per place: per part, the mean over the orders asked of each place's
/// share of the letter distribution (an unreadable order left out; a part without any readable
/// order spread evenly), times the part's share of all places; floored at 0.01, capped at
/// [`CHOICE_CAP`].
fn choice_probabilities(listing: &Listing, set: &QuestionSet, resolved: &[Resolved]) -> Vec<f64> {
    let readable = |r: &Resolved| -> Option<Vec<f64>> { r.values.iter().copied().collect() };
    let total = listing.places.len().max(1) as f64;
    let mut sum = vec![0.0; listing.places.len()];
    let mut orders = vec![0usize; listing.places.len()];
    for ((_, asked), r) in set.questions.iter().zip(resolved) {
        let Asked::Places(places) = asked else {
            continue;
        };
        let Some(q) = readable(r) else {
            continue;
        };
        for (&place, v) in places.iter().zip(&q) {
            sum[place] += v;
            orders[place] += 1;
        }
    }
    let mut p = vec![0.0; listing.places.len()];
    for part in &listing.parts {
        let share = part.len() as f64 / total;
        for &place in part {
            let q = if orders[place] == 0 {
                1.0 / part.len() as f64
            } else {
                sum[place] / orders[place] as f64
            };
            p[place] = (q * share).clamp(FALLBACK_PROBABILITY, CHOICE_CAP);
        }
    }
    p
}

fn likelihood_error(source: &str, e: LlmError) -> PlanError {
    PlanError::Likelihood {
        source_name: source.to_string(),
        error: Box::new(e),
    }
}

impl LikelihoodSource for LlmLikelihood {
    fn name(&self) -> &str {
        &self.name
    }

    fn likelihoods(
        &self,
        house: &House,
        target: &ObjectType,
    ) -> std::result::Result<Vec<Probability>, PlanError> {
        let key = (
            house.name.clone(),
            house.index,
            house.containers.len(),
            target.clone(),
        );
        if let Some(p) = self
            .memo
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .get(&key)
        {
            return Ok(p.clone());
        }
        let p = self
            .service
            .block_on(self.likelihoods_async(house, target))
            .map_err(|e| likelihood_error(&self.name, e))?;
        self.memo
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .insert(key, p.clone());
        Ok(p)
    }
}
