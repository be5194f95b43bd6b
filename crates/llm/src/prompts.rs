//! Prompt templates (minijinja): the seven shipped with ferret and any the user adds by path.
//!
//! A template renders to text. Lines reading exactly `[system]`, `[user]` or `[assistant]` start
//! a message with that role; text before the first such line, or a template without any, is one
//! user message. Templates are rendered with strict undefined variables, so a typo or a
//! probability template used for P-DIRECT fails loudly instead of sending a half-empty prompt.
//!
//! Variables of **probability** templates (`llm+model`), see [`ProbabilityContext`]:
//! `target`, `container`, `room` (words: `remote control`, `sofa`, `living room`), `rooms` (room
//! labels, `bedroom 1` when a type repeats) and `house` (a list of `{room, containers}`).
//!
//! Variables of **direct** templates (`llm-direct`), see [`DirectContext`]: `target`, `rooms`,
//! `room_distances` (`{from, to, metres}`), `robot` (`{room, at, distances: [{room, metres}]}`) and
//! `options` (`{number, label, container, room}`; the answer is matched against `label`).
//!
//! Variables of **listing** templates (P-CHOICE, P-BATCH), see [`ListingContext`]: `target`,
//! `rooms`, `house`, and `options` (`{label, container, room}`, lettered `A`, `B`, ...).
//!
//! **Kinds.** A template says how it is asked and read with a comment `{# ferret:kind K #}`:
//! `percent` (the default: one question per target, container type and room, answered with a
//! percentage), `yesno` (one per target, container type and room *type*, answered Yes or No),
//! `choice` (one per house and target listing every place; the answer is a letter;
//! `orders=2` also asks the list reversed and averages), or `batch` (one per house and target, a
//! percentage per letter; `names` names the places instead, `yesno` asks Yes or No for each). See
//! [`PromptKind`].
//!
//! The filter `article` puts "a" or "an" before a noun (`{{ target | article }}` → `an apple`).

use std::collections::BTreeMap;
use std::path::Path;

use minijinja::{Environment, UndefinedBehavior};
use serde::Serialize;

use crate::answer::WorkedExample;
use crate::context::{
    DirectContext, HouseContext, ListingContext, ProbabilityContext, ProbabilityQuery,
};
use crate::error::{LlmError, Result};
use crate::message::{ChatMessage, MessageRole};

/// P-CONTEXT-A: role and task, the house, a worked example (eggs in the fridge, 90%), the question.
pub const P_CONTEXT_A: &str = "p-context-a";
/// P-CONTEXT-B: the same elements in other words (bread in the pantry, 85%).
pub const P_CONTEXT_B: &str = "p-context-b";
/// P-MINIMAL: only the question, for a typical household.
pub const P_MINIMAL: &str = "p-minimal";
/// P-DIRECT: asks which container to search next (the llm-direct baseline).
pub const P_DIRECT: &str = "p-direct";
/// P-YESNO: "would X be found in or on the Y in the Z?", read as P(Yes) / (P(Yes) + P(No)).
pub const P_YESNO: &str = "p-yesno";
/// P-CHOICE: which lettered place most likely holds X, read from the letter's distribution.
pub const P_CHOICE: &str = "p-choice";
/// P-BATCH: a percentage for every lettered place in one answer.
pub const P_BATCH: &str = "p-batch";

/// Largest template file read, bytes.
pub const MAX_TEMPLATE_BYTES: u64 = 1 << 20;

/// The shipped templates, compiled into the binary.
pub const BUILTIN_TEMPLATES: [(&str, &str); 7] = [
    (P_CONTEXT_A, include_str!("../prompts/p-context-a.j2")),
    (P_CONTEXT_B, include_str!("../prompts/p-context-b.j2")),
    (P_MINIMAL, include_str!("../prompts/p-minimal.j2")),
    (P_DIRECT, include_str!("../prompts/p-direct.j2")),
    (P_YESNO, include_str!("../prompts/p-yesno.j2")),
    (P_CHOICE, include_str!("../prompts/p-choice.j2")),
    (P_BATCH, include_str!("../prompts/p-batch.j2")),
];

/// How a probability template is asked and read, declared in it by `{# ferret:kind K #}`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum PromptKind {
    /// One question per (target, container type, room); the answer is a percentage.
    Percent,
    /// One question per (target, container type, room type), naming no house; the answer is Yes
    /// or No, read from the first token's log-probabilities.
    YesNo,
    /// One question per house and target listing its places with letters; the answer is a
    /// letter, read from the first token's log-probabilities. `orders` is 1 (as listed) or 2
    /// (also reversed, averaged).
    Choice {
        /// Orders the list is asked in.
        orders: u8,
    },
    /// One question per house and target; the answer gives a percentage (or, with `yesno`, Yes
    /// or No) for every place.
    Batch {
        /// Places are named (`sofa in the living room`) rather than lettered, and the answer
        /// names each place before its value.
        names: bool,
        /// Each place is answered Yes or No, read as P-YESNO reads its answer (at that word's
        /// token), rather than with a percentage.
        yesno: bool,
    },
}

impl PromptKind {
    /// True for kinds asking one question per house and target about a listing of places.
    pub fn is_listing(self) -> bool {
        matches!(self, Self::Choice { .. } | Self::Batch { .. })
    }
}

static KIND: std::sync::LazyLock<regex::Regex> = std::sync::LazyLock::new(|| {
    regex::Regex::new(r"\{#-?\s*ferret:kind\s+([a-z]+)([^#]*)").expect("constant pattern")
});

/// The kind a template declares; `Percent` when it declares none.
fn declared_kind(name: &str, source: &str) -> Result<PromptKind> {
    let Some(c) = KIND.captures(source) else {
        return Ok(PromptKind::Percent);
    };
    let bad = |message: String| LlmError::Prompt {
        name: name.to_string(),
        message,
    };
    let kind = c.get(1).map_or("", |k| k.as_str());
    let (mut orders, mut names, mut yesno) = (1, false, false);
    for option in c.get(2).map_or("", |o| o.as_str()).split_whitespace() {
        match (kind, option) {
            ("batch", "names") => names = true,
            ("batch", "yesno") => yesno = true,
            ("choice", o) if o.starts_with("orders=") => match o["orders=".len()..].parse() {
                Ok(n @ 1..=2) => orders = n,
                _ => return Err(bad(format!("ferret:kind {o}: orders must be 1 or 2"))),
            },
            (_, o) => {
                return Err(bad(format!(
                    "ferret:kind {kind} has no option `{o}` (choice: orders=1|2; batch: names, yesno)"
                )));
            }
        }
    }
    match kind {
        "percent" => Ok(PromptKind::Percent),
        "yesno" => Ok(PromptKind::YesNo),
        "choice" => Ok(PromptKind::Choice { orders }),
        "batch" => Ok(PromptKind::Batch { names, yesno }),
        other => Err(bad(format!(
            "ferret:kind {other}: expected percent, yesno, choice or batch"
        ))),
    }
}

static EXAMPLE: std::sync::LazyLock<regex::Regex> = std::sync::LazyLock::new(|| {
    regex::Regex::new(
        r"\{#-?\s*ferret:example\s+percent=(\d+(?:\.\d+)?)\s+words=([^\s#-]+(?:-[^\s#-]+)*)",
    )
    .expect("constant pattern")
});

/// Named prompt templates.
#[derive(Debug)]
pub struct PromptLibrary {
    env: Environment<'static>,
    sources: BTreeMap<String, String>,
}

impl Default for PromptLibrary {
    fn default() -> Self {
        Self::new()
    }
}

/// "a" or "an" before `noun` (by its first letter; good enough for object names).
fn article(noun: String) -> String {
    let an = noun
        .trim_start()
        .chars()
        .next()
        .is_some_and(|c| "aeiouAEIOU".contains(c));
    format!("{} {noun}", if an { "an" } else { "a" })
}

impl PromptLibrary {
    /// A library holding the four shipped templates.
    pub fn new() -> Self {
        let mut env = Environment::new();
        env.set_undefined_behavior(UndefinedBehavior::Strict);
        env.set_trim_blocks(true);
        env.set_lstrip_blocks(true);
        env.add_filter("article", article);
        let mut lib = Self {
            env,
            sources: BTreeMap::new(),
        };
        for (name, source) in BUILTIN_TEMPLATES {
            // The shipped templates are tested; a syntax error in one is a build defect.
            if let Err(e) = lib.add_template(name, source.to_string()) {
                tracing::error!("shipped prompt {name} does not compile: {e}");
            }
        }
        lib
    }

    /// Adds (or replaces) a template under `name`.
    pub fn add_template(&mut self, name: &str, source: String) -> Result<()> {
        declared_kind(name, &source)?;
        self.env
            .add_template_owned(name.to_string(), source.clone())
            .map_err(|e| LlmError::Prompt {
                name: name.to_string(),
                message: template_error(&e),
            })?;
        self.sources.insert(name.to_string(), source);
        Ok(())
    }

    /// Adds the template in file `path` under `name`.
    pub fn add_file(&mut self, name: &str, path: &Path) -> Result<()> {
        let source = ferret_world::input::read_text(path, MAX_TEMPLATE_BYTES).map_err(|e| {
            LlmError::Prompt {
                name: name.to_string(),
                message: format!("cannot read {}: {e}", path.display()),
            }
        })?;
        self.add_template(name, source)
    }

    /// The template a strategy names: a known name, or else a path to a template file
    /// (`prompts/mine.j2`), loaded under that path as its name. Returns the name to render.
    pub fn resolve(&mut self, name_or_path: &str) -> Result<String> {
        if self.sources.contains_key(name_or_path) {
            return Ok(name_or_path.to_string());
        }
        let path = Path::new(name_or_path);
        if path.is_file() {
            self.add_file(name_or_path, path)?;
            return Ok(name_or_path.to_string());
        }
        Err(LlmError::Prompt {
            name: name_or_path.to_string(),
            message: format!(
                "no such prompt (known: {}) and no such template file",
                self.names().join(", ")
            ),
        })
    }

    /// True when a template is called `name`.
    pub fn contains(&self, name: &str) -> bool {
        self.sources.contains_key(name)
    }

    /// Template names, sorted.
    pub fn names(&self) -> Vec<String> {
        self.sources.keys().cloned().collect()
    }

    /// A template's source text.
    pub fn source(&self, name: &str) -> Option<&str> {
        self.sources.get(name).map(String::as_str)
    }

    /// The worked example template `name` declares with a comment
    /// `{# ferret:example percent=90 words=egg,eggs #}`, if it declares one: answers restating
    /// it are not taken as answers.
    pub fn example(&self, name: &str) -> Option<WorkedExample> {
        let c = EXAMPLE.captures(self.sources.get(name)?)?;
        Some(WorkedExample {
            percent: c.get(1)?.as_str().parse().ok()?,
            words: c
                .get(2)?
                .as_str()
                .split(',')
                .map(|w| w.trim().to_lowercase())
                .filter(|w| !w.is_empty())
                .collect(),
        })
    }

    /// How template `name` is asked and read (`Percent` for an unknown name).
    pub fn kind(&self, name: &str) -> PromptKind {
        self.sources
            .get(name)
            .and_then(|s| declared_kind(name, s).ok())
            .unwrap_or(PromptKind::Percent)
    }

    /// Renders template `name` with `ctx` into messages.
    pub fn render<S: Serialize>(&self, name: &str, ctx: &S) -> Result<Vec<ChatMessage>> {
        let err = |message: String| LlmError::Prompt {
            name: name.to_string(),
            message,
        };
        let template = self
            .env
            .get_template(name)
            .map_err(|e| err(template_error(&e)))?;
        let text = template.render(ctx).map_err(|e| err(template_error(&e)))?;
        let messages = split_messages(&text);
        if messages.is_empty() {
            return Err(err("renders to an empty prompt".into()));
        }
        Ok(messages)
    }

    /// The messages asking `query` with template `name` in a house described by `house`.
    pub fn probability_messages(
        &self,
        name: &str,
        house: &HouseContext,
        query: &ProbabilityQuery,
    ) -> Result<Vec<ChatMessage>> {
        self.render(name, &ProbabilityContext::new(house, query))
    }

    /// The messages of listing template `name` (P-CHOICE, P-BATCH) for `ctx`.
    pub fn listing_messages(&self, name: &str, ctx: &ListingContext) -> Result<Vec<ChatMessage>> {
        self.render(name, ctx)
    }

    /// The messages asking where to search next with template `name`.
    pub fn direct_messages(&self, name: &str, ctx: &DirectContext) -> Result<Vec<ChatMessage>> {
        self.render(name, ctx)
    }
}

/// minijinja's message with its cause chain (where the undefined variable is, etc.).
fn template_error(e: &minijinja::Error) -> String {
    ferret_world::error_chain(e)
}

/// Splits rendered text at `[system]` / `[user]` / `[assistant]` lines.
fn split_messages(text: &str) -> Vec<ChatMessage> {
    let mut out = Vec::new();
    let mut role = MessageRole::User;
    let mut buf: Vec<&str> = Vec::new();
    let mut flush = |role: MessageRole, buf: &mut Vec<&str>| {
        let content = buf.join("\n").trim().to_string();
        if !content.is_empty() {
            out.push(ChatMessage { role, content });
        }
        buf.clear();
    };
    for line in text.lines() {
        let next = match line.trim() {
            "[system]" => Some(MessageRole::System),
            "[user]" => Some(MessageRole::User),
            "[assistant]" => Some(MessageRole::Assistant),
            _ => None,
        };
        match next {
            Some(r) => {
                flush(role, &mut buf);
                role = r;
            }
            None => buf.push(line),
        }
    }
    flush(role, &mut buf);
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::context::tests::{small_house, straight_distances};
    use crate::context::{DirectContext, QueryPlan};
    use crate::message::transcript;
    use ferret_world::{ObjectType, Place};

    #[test]
    fn shipped_templates_all_compile() {
        let lib = PromptLibrary::new();
        assert_eq!(
            lib.names(),
            [
                "p-batch",
                "p-choice",
                "p-context-a",
                "p-context-b",
                "p-direct",
                "p-minimal",
                "p-yesno"
            ]
        );
        assert_eq!(lib.kind(P_CONTEXT_A), PromptKind::Percent);
        assert_eq!(lib.kind(P_MINIMAL), PromptKind::Percent);
        assert_eq!(lib.kind(P_YESNO), PromptKind::YesNo);
        assert_eq!(lib.kind(P_CHOICE), PromptKind::Choice { orders: 2 });
        assert_eq!(
            lib.kind(P_BATCH),
            PromptKind::Batch {
                names: false,
                yesno: false
            }
        );
    }

    #[test]
    fn context_a_holds_every_element() {
        let house = small_house();
        let ctx = HouseContext::new(&house);
        let plan = QueryPlan::new(&house, &ObjectType::new("RemoteControl"));
        let lib = PromptLibrary::new();
        let m = lib
            .probability_messages(P_CONTEXT_A, &ctx, &plan.queries[4])
            .unwrap();
        assert_eq!(m.len(), 2);
        assert_eq!(m[0].role, MessageRole::System);
        assert!(m[0].content.contains("robot"));
        let u = &m[1].content;
        assert!(
            u.contains("The home has these rooms: kitchen, bedroom 1, bedroom 2."),
            "{u}"
        );
        assert!(
            u.contains(
                "The kitchen contains: fridge, counter top (2).\nThe bedroom 1 contains: bed.\n"
            ),
            "{u}"
        );
        assert!(
            u.contains("eggs in the fridge in the kitchen?\nAnswer: 90%"),
            "{u}"
        );
        assert!(
            u.ends_with("What is the likelihood that I find a remote control in the dresser in the bedroom 2?\nAnswer with a percentage between 1% and 100% only."),
            "{u}"
        );
    }

    #[test]
    fn context_b_and_minimal() {
        let house = small_house();
        let ctx = HouseContext::new(&house);
        let plan = QueryPlan::new(&house, &ObjectType::new("Apple"));
        let lib = PromptLibrary::new();
        let b = transcript(
            &lib.probability_messages(P_CONTEXT_B, &ctx, &plan.queries[0])
                .unwrap(),
        );
        assert!(
            b.contains("- In the kitchen: fridge, counter top (2)"),
            "{b}"
        );
        assert!(
            b.contains("85%") && b.contains("an apple is in the fridge in the kitchen?"),
            "{b}"
        );
        let m = lib
            .probability_messages(P_MINIMAL, &ctx, &plan.queries[0])
            .unwrap();
        assert_eq!(
            m,
            [ChatMessage::user(
                "In a typical household, what is the likelihood of finding an apple in the fridge in the kitchen? Answer with a percentage only."
            )]
        );
    }

    #[test]
    fn direct_lists_rooms_distances_robot_and_options() {
        let house = small_house();
        let ctx = HouseContext::new(&house);
        let d = straight_distances(&house);
        let (dc, _) = DirectContext::new(
            &house,
            &ctx,
            &d,
            &ObjectType::new("CellPhone"),
            Place::Start,
            &[0, 1, 2, 3, 4, 5],
        )
        .unwrap();
        let lib = PromptLibrary::new();
        let m = lib.direct_messages(P_DIRECT, &dc).unwrap();
        let u = &m[1].content;
        assert!(u.contains("- kitchen to bedroom 1: 4.0 m\n"), "{u}");
        assert!(u.contains("The robot is in the kitchen."), "{u}");
        assert!(
            u.contains("- counter top 2 in the kitchen\n- bed in the bedroom 1\n"),
            "{u}"
        );
        assert!(u.contains("Object to find: cell phone\n"), "{u}");
        assert!(u.ends_with("and nothing else."), "{u}");
        // A probability template lacks P-DIRECT's variables: strict rendering refuses it.
        let e = lib.render(P_CONTEXT_A, &dc).unwrap_err().to_string();
        assert!(e.contains("p-context-a"), "{e}");
    }

    #[test]
    fn worked_examples_are_declared() {
        let lib = PromptLibrary::new();
        let a = lib.example(P_CONTEXT_A).unwrap();
        assert_eq!(a.percent, 90.0);
        assert!(a.words.contains(&"eggs".to_string()), "{a:?}");
        let b = lib.example(P_CONTEXT_B).unwrap();
        assert_eq!(b.percent, 85.0);
        assert!(b.words.contains(&"bread".to_string()), "{b:?}");
        assert_eq!(lib.example(P_MINIMAL), None);
    }

    #[test]
    fn user_templates_by_path_and_markers() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("mine.j2");
        std::fs::write(
            &path,
            "[system]\nBe brief.\n[user]\nIs {{ target | article }} in the {{ container }}?\n",
        )
        .unwrap();
        let mut lib = PromptLibrary::new();
        let name = lib.resolve(path.to_str().unwrap()).unwrap();
        let house = small_house();
        let ctx = HouseContext::new(&house);
        let plan = QueryPlan::new(&house, &ObjectType::new("Egg"));
        let m = lib
            .probability_messages(&name, &ctx, &plan.queries[0])
            .unwrap();
        assert_eq!(
            m,
            [
                ChatMessage::system("Be brief."),
                ChatMessage::user("Is an egg in the fridge?")
            ]
        );
        assert!(
            lib.resolve("p-nonexistent")
                .unwrap_err()
                .to_string()
                .contains("p-context-a")
        );
        assert!(lib.add_template("bad", "{% if %}".into()).is_err());
    }

    #[test]
    fn yes_no_choice_and_batch_render() {
        let house = small_house();
        let ctx = HouseContext::new(&house);
        let lib = PromptLibrary::new();
        let plan = QueryPlan::by_room_type(&house, &ObjectType::new("RemoteControl"));
        let m = lib
            .probability_messages(P_YESNO, &ctx, &plan.queries[2])
            .unwrap();
        assert_eq!(
            m,
            [ChatMessage::user(
                "In a typical home, would a remote control be found in or on the bed in the bedroom? Answer Yes or No."
            )]
        );
        let listing = crate::context::Listing::new(&house, &ctx);
        let l = ListingContext::new(&ctx, &listing, &[0, 1, 2, 3, 4], &ObjectType::new("Apple"));
        for name in [P_CHOICE, P_BATCH] {
            let m = lib.listing_messages(name, &l).unwrap();
            let u = &m[1].content;
            assert!(
                u.starts_with("Places in the home:\nA. fridge in the kitchen\nB. counter top in the kitchen\nC. bed in the bedroom 1\n"),
                "{u}"
            );
            assert!(u.contains("an apple"), "{u}");
        }
        // The listing comes before the target: the same prefix for every target of a house.
        let other = ListingContext::new(&ctx, &listing, &[0, 1, 2, 3, 4], &ObjectType::new("Book"));
        let a = &lib.listing_messages(P_CHOICE, &l).unwrap()[1].content;
        let b = &lib.listing_messages(P_CHOICE, &other).unwrap()[1].content;
        let common = a.chars().zip(b.chars()).take_while(|(x, y)| x == y).count();
        assert!(common > a.find("E. dresser").unwrap(), "{common}");
        // A listing template lacks the probability variables: strict rendering refuses it.
        assert!(
            lib.probability_messages(P_CHOICE, &ctx, &plan.queries[0])
                .is_err()
        );
    }

    #[test]
    fn declared_kinds_are_checked() {
        let mut lib = PromptLibrary::new();
        lib.add_template("mine", "{# ferret:kind choice #}\n{{ target }}".into())
            .unwrap();
        assert_eq!(lib.kind("mine"), PromptKind::Choice { orders: 1 });
        let e = lib
            .add_template("bad", "{# ferret:kind guess #}".into())
            .unwrap_err()
            .to_string();
        assert!(e.contains("guess") && e.contains("yesno"), "{e}");
        let e = lib
            .add_template("bad", "{# ferret:kind choice orders=3 #}".into())
            .unwrap_err()
            .to_string();
        assert!(e.contains("orders=3"), "{e}");
        assert_eq!(lib.kind("no-such-template"), PromptKind::Percent);
    }
}
