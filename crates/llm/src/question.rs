//! A question as ferret asks it, and the request an endpoint receives for it.
//!
//! The same [`Question`] becomes different requests at different endpoints: the role text may be
//! merged into the first user message ([`SystemRole::Merge`]), a JSON schema may constrain the
//! answer ([`AnswerFormat`]), and token log-probabilities may be requested. The [`Request`] is
//! what is sent and what the response cache keys on, so two endpoints that send the same request
//! to the same server share answers.

use serde::Serialize;
use serde_json::{Value, json};

use crate::config::{AnswerFormat, EndpointConfig, SystemRole};
use crate::message::{ChatMessage, MessageRole};

/// What kind of answer a question expects.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub enum Expect {
    /// A percentage (the probability prompts).
    Probability,
    /// One of these location labels (P-DIRECT).
    Location(Vec<String>),
    /// Yes or No (P-YESNO).
    YesNo,
    /// One of these letters (P-CHOICE).
    Choice(Vec<String>),
    /// Yes or No for each of these places (P-BATCH with `yesno`).
    BatchYesNo(Vec<String>),
    /// A percentage for each of these letters (P-BATCH).
    Batch(Vec<String>),
    /// Anything (a ping).
    Free,
}

/// One question: the messages a prompt template rendered, what it expects, and words that say
/// which question it is (house, target, container, room) for error messages.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct Question {
    /// The rendered prompt.
    pub messages: Vec<ChatMessage>,
    /// The expected answer.
    pub expect: Expect,
    /// Which question this is, in words (`house val-3 (#3), target remote control, sofa in the
    /// living room`).
    pub about: String,
}

impl Question {
    /// A question expecting a percentage.
    pub fn probability(messages: Vec<ChatMessage>, about: impl Into<String>) -> Self {
        Self {
            messages,
            expect: Expect::Probability,
            about: about.into(),
        }
    }

    /// A question whose answer is free text (a ping, a test).
    pub fn free(messages: Vec<ChatMessage>) -> Self {
        Self {
            messages,
            expect: Expect::Free,
            about: "a free-text question".into(),
        }
    }

    /// The same question continued: the model's `answer`, then `reminder` from the user. Used to
    /// re-ask an unusable answer; the continuation is a question of its own in the cache.
    pub fn reask(&self, answer: &str, reminder: &str) -> Self {
        let mut messages = self.messages.clone();
        messages.push(ChatMessage::assistant(answer));
        messages.push(ChatMessage::user(reminder));
        Self {
            messages,
            expect: self.expect.clone(),
            about: format!("{} (asked again)", self.about),
        }
    }
}

/// The format reminder sent with a re-asked probability question.
pub const PROBABILITY_REMINDER: &str =
    "Answer with one percentage between 1% and 100% and nothing else, for example: 40%";
/// The format reminder sent with a re-asked P-YESNO question.
pub const YES_NO_REMINDER: &str = "Answer Yes or No and nothing else.";
/// The format reminder sent with a re-asked P-CHOICE question.
pub const CHOICE_REMINDER: &str =
    "Answer with the letter of one place from the list and nothing else.";
/// The format reminder sent with a re-asked P-BATCH question whose answer left out `missing`
/// (answered Yes or No when `yesno`).
pub fn batch_reminder(missing: &[String], yesno: bool) -> String {
    let (what, example) = if yesno {
        ("Yes or No", "No")
    } else {
        ("a percentage between 1% and 100%", "40%")
    };
    format!(
        "Give {what} for each of these places too, one line each, for example \"{}: {example}\": {}",
        missing.first().map_or("A", String::as_str),
        missing.join(", ")
    )
}

/// The format reminder sent with a re-asked P-DIRECT question.
pub const LOCATION_REMINDER: &str = "Answer with exactly one search location from the list, written exactly as in the list, and nothing else.";

/// The request an endpoint receives: what decides its answer.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Request {
    /// The messages as sent (after [`SystemRole::Merge`]).
    pub messages: Vec<ChatMessage>,
    /// `response_format`, when structured output is asked for.
    pub response_format: Option<Value>,
    /// `top_logprobs` (with `logprobs: true`), when log-probabilities are asked for.
    pub top_logprobs: Option<u8>,
    /// Output tokens the answer needs at least (a percentage per place, P-BATCH): raises an
    /// endpoint's `max_output_tokens` that is lower, never sets a limit where there is none.
    pub min_output_tokens: Option<u32>,
}

/// Output tokens a P-BATCH answer needs per place besides its label (`"A": "40%", ` is 8 tokens
/// in common tokenizers; the rest is room for a model that writes a word or two more).
pub const BATCH_TOKENS_PER_PLACE: u32 = 12;

/// Output tokens a P-BATCH answer over `labels` needs: [`BATCH_TOKENS_PER_PLACE`] per place,
/// plus its label when places are named (a token per 3 characters, generously).
pub fn batch_output_tokens(labels: &[String]) -> u32 {
    let per_place = |l: &String| {
        let name = if l.len() > 1 { l.len().div_ceil(3) } else { 0 };
        BATCH_TOKENS_PER_PLACE + u32::try_from(name).unwrap_or(u32::MAX / 1024)
    };
    labels
        .iter()
        .map(per_place)
        .fold(16u32, u32::saturating_add)
}

impl Request {
    /// A plain text request: these messages, no structured output, no log-probabilities.
    pub fn plain(messages: Vec<ChatMessage>) -> Self {
        Self {
            messages,
            response_format: None,
            top_logprobs: None,
            min_output_tokens: None,
        }
    }

    /// The output-token limit sent with this request under `config`.
    pub fn max_output_tokens(&self, config: &EndpointConfig) -> Option<u32> {
        match (config.max_output_tokens, self.min_output_tokens) {
            (Some(limit), Some(need)) => Some(limit.max(need)),
            (limit, _) => limit,
        }
    }

    /// The request `config`'s endpoint receives for `question`.
    pub fn new(config: &EndpointConfig, question: &Question) -> Self {
        let mut messages = match config.system_role {
            SystemRole::System => question.messages.clone(),
            SystemRole::Merge => merge_system(&question.messages),
        };
        let schema = match &question.expect {
            Expect::Probability => Some(("percent", percent_schema())),
            Expect::Location(labels) => Some(("location", enum_schema("location", labels))),
            Expect::YesNo => Some((
                "answer",
                enum_schema("answer", &["Yes".to_string(), "No".to_string()]),
            )),
            Expect::Choice(labels) => Some(("label", enum_schema("label", labels))),
            Expect::BatchYesNo(labels) => Some(("answers", batch_schema(labels, &["Yes", "No"]))),
            Expect::Batch(labels) => {
                let values: Vec<String> = (1..=100).map(|p| format!("{p}%")).collect();
                Some(("percentages", batch_schema(labels, &values)))
            }
            Expect::Free => None,
        };
        // A model that is not told to write JSON is pushed into it token by token by the
        // grammar, from wherever its own answer would have started: Qwen2.5-Coder-1.5B on
        // llama-server opened with forced spaces and then wrote "100%" where its text answer was
        // "10%". Saying the format in words, after the prompt's own instruction, lets it write
        // the JSON it is constrained to.
        if config.answer_format != AnswerFormat::Text
            && let Some((field, _)) = &schema
            && let Some(last) = messages
                .iter_mut()
                .rev()
                .find(|m| m.role == MessageRole::User)
        {
            last.content
                .push_str(&json_instruction(field, &question.expect));
        }
        let response_format = schema.and_then(|(name, schema)| match config.answer_format {
            AnswerFormat::Text => None,
            AnswerFormat::JsonSchema => Some(json!({
                "type": "json_schema",
                "json_schema": {"name": name, "strict": true, "schema": schema},
            })),
            AnswerFormat::JsonObject => Some(json!({"type": "json_object", "schema": schema})),
        });
        // A ping's answer is never read for a number: asking for logprobs would only slow it.
        let top_logprobs = match question.expect {
            Expect::Free => None,
            _ => config.requested_top_logprobs(),
        };
        let min_output_tokens = match &question.expect {
            Expect::Batch(labels) | Expect::BatchYesNo(labels) => Some(batch_output_tokens(labels)),
            _ => None,
        };
        Self {
            messages,
            response_format,
            top_logprobs,
            min_output_tokens,
        }
    }
}

/// The line appended to the question in JSON answer formats.
pub fn json_instruction(field: &str, expect: &Expect) -> String {
    match (field, expect) {
        ("percent", _) => {
            "\nReply with JSON only: {\"percent\": \"<a percentage from 1% to 100%>\"}".into()
        }
        (_, Expect::YesNo) => {
            "\nReply with JSON only: {\"answer\": \"Yes\"} or {\"answer\": \"No\"}".into()
        }
        (_, Expect::Choice(_)) => {
            "\nReply with JSON only: {\"label\": \"<the letter of one place>\"}".into()
        }
        (_, Expect::BatchYesNo(labels)) => format!(
            "\nReply with JSON only, Yes or No for every place: {{{}}}",
            labels
                .iter()
                .map(|l| format!("\"{l}\": \"<Yes or No>\""))
                .collect::<Vec<_>>()
                .join(", ")
        ),
        (_, Expect::Batch(labels)) => format!(
            "\nReply with JSON only, a percentage from 1% to 100% for every letter: {{{}}}",
            labels
                .iter()
                .map(|l| format!("\"{l}\": \"<percentage>\""))
                .collect::<Vec<_>>()
                .join(", ")
        ),
        _ => format!(
            "\nReply with JSON only: {{\"{field}\": \"<one {field} from the list, written as in the list>\"}}"
        ),
    }
}

/// `{"percent": "<1..100>%"}`: one of the strings `1%` … `100%`. Strings with the `%` rather than
/// an integer because constrained decoding otherwise bends the answer: a model about to write
/// "10%" may not write `%` inside an integer, and its next choice is often `0`, so "10%" became
/// 100 for every question (Qwen2.5-Coder-1.5B on llama-cpp-python; see docs/real-models.md).
/// An enum rather than a pattern: llama.cpp's grammar converter compiles enums
/// everywhere.
fn percent_schema() -> Value {
    let values: Vec<String> = (1..=100).map(|p| format!("{p}%")).collect();
    json!({
        "type": "object",
        "properties": {"percent": {"type": "string", "enum": values}},
        "required": ["percent"],
        "additionalProperties": false,
    })
}

/// `{"<field>": <one of the labels>}`.
fn enum_schema(field: &str, labels: &[String]) -> Value {
    json!({
        "type": "object",
        "properties": {field: {"type": "string", "enum": labels}},
        "required": [field],
        "additionalProperties": false,
    })
}

/// `{"A": <one of values>, "B": ...}`: every label required, in order, nothing else.
fn batch_schema<S: Serialize>(labels: &[String], values: &[S]) -> Value {
    let properties: serde_json::Map<String, Value> = labels
        .iter()
        .map(|l| (l.clone(), json!({"type": "string", "enum": values})))
        .collect();
    json!({
        "type": "object",
        "properties": properties,
        "required": labels,
        "additionalProperties": false,
    })
}

/// The messages with every system message's text moved to the top of the first user message
/// (or into a user message of its own when there is none).
fn merge_system(messages: &[ChatMessage]) -> Vec<ChatMessage> {
    let role: Vec<&str> = messages
        .iter()
        .filter(|m| m.role == MessageRole::System)
        .map(|m| m.content.trim_end())
        .collect();
    let mut out: Vec<ChatMessage> = messages
        .iter()
        .filter(|m| m.role != MessageRole::System)
        .cloned()
        .collect();
    if role.is_empty() {
        return out;
    }
    let role = role.join("\n\n");
    match out.iter_mut().find(|m| m.role == MessageRole::User) {
        Some(first) => first.content = format!("{role}\n\n{}", first.content),
        None => out.insert(0, ChatMessage::user(role)),
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn q() -> Question {
        Question::probability(
            vec![
                ChatMessage::system("You help a robot."),
                ChatMessage::user("How likely?"),
            ],
            "test",
        )
    }

    #[test]
    fn merge_moves_the_role_into_the_first_user_message() {
        let mut c = EndpointConfig::new("http://x/v1", "m");
        assert_eq!(Request::new(&c, &q()).messages, q().messages);
        c.system_role = SystemRole::Merge;
        let r = Request::new(&c, &q());
        assert_eq!(
            r.messages,
            vec![ChatMessage::user("You help a robot.\n\nHow likely?")]
        );
        let only_system = Question::probability(vec![ChatMessage::system("Role.")], "t");
        assert_eq!(
            Request::new(&c, &only_system).messages,
            vec![ChatMessage::user("Role.")]
        );
    }

    #[test]
    fn formats_follow_the_endpoint() {
        let mut c = EndpointConfig::new("http://x/v1", "m");
        let r = Request::new(&c, &q());
        assert_eq!((r.response_format, r.top_logprobs), (None, None));
        c.answer_format = AnswerFormat::JsonSchema;
        c.probability_from = crate::config::ProbabilityFrom::Logprobs;
        let r = Request::new(&c, &q());
        let f = r.response_format.unwrap();
        assert_eq!(f["type"], "json_schema");
        assert_eq!(f["json_schema"]["strict"], true);
        let e = &f["json_schema"]["schema"]["properties"]["percent"]["enum"];
        assert_eq!(e.as_array().map(Vec::len), Some(100));
        assert_eq!(e[0], "1%");
        assert_eq!(e[99], "100%");
        assert_eq!(r.top_logprobs, Some(20));
        c.answer_format = AnswerFormat::JsonObject;
        let labels = vec!["sofa in the living room".to_string()];
        let direct = Question {
            expect: Expect::Location(labels),
            ..q()
        };
        let f = Request::new(&c, &direct).response_format.unwrap();
        assert_eq!(f["type"], "json_object");
        assert_eq!(
            f["schema"]["properties"]["location"]["enum"][0],
            "sofa in the living room"
        );
        let ping = Question {
            expect: Expect::Free,
            ..q()
        };
        let r = Request::new(&c, &ping);
        assert_eq!((r.response_format, r.top_logprobs), (None, None));
    }

    #[test]
    fn json_formats_say_the_format_in_words_and_text_does_not() {
        let mut c = EndpointConfig::new("http://x/v1", "m");
        assert_eq!(Request::new(&c, &q()).messages, q().messages);
        for format in [AnswerFormat::JsonSchema, AnswerFormat::JsonObject] {
            c.answer_format = format;
            let r = Request::new(&c, &q());
            assert_eq!(r.messages[0], q().messages[0], "the role text is untouched");
            assert!(
                r.messages[1]
                    .content
                    .starts_with("How likely?\nReply with JSON only: {\"percent\"")
            );
            let direct = Question {
                expect: Expect::Location(vec!["bed in the bedroom".into()]),
                ..q()
            };
            let m = Request::new(&c, &direct).messages;
            assert!(m[1].content.contains("{\"location\":"), "{}", m[1].content);
            // A ping is never constrained, so it is not told to write JSON.
            let ping = Question {
                expect: Expect::Free,
                ..q()
            };
            assert_eq!(Request::new(&c, &ping).messages, q().messages);
        }
    }

    #[test]
    fn reask_appends_the_answer_and_the_reminder() {
        let again = q().reask("I am not sure", PROBABILITY_REMINDER);
        assert_eq!(again.messages.len(), 4);
        assert_eq!(again.messages[2], ChatMessage::assistant("I am not sure"));
        assert_eq!(again.messages[3].content, PROBABILITY_REMINDER);
        assert_eq!(again.expect, Expect::Probability);
    }

    #[test]
    fn yes_no_choice_and_batch_schemas() {
        let mut c = EndpointConfig::new("http://x/v1", "m");
        c.answer_format = AnswerFormat::JsonSchema;
        let yes_no = Question {
            expect: Expect::YesNo,
            ..q()
        };
        let r = Request::new(&c, &yes_no);
        let f = r.response_format.unwrap();
        assert_eq!(
            f["json_schema"]["schema"]["properties"]["answer"]["enum"],
            json!(["Yes", "No"])
        );
        assert!(r.messages[1].content.contains("{\"answer\": \"Yes\"}"));
        let letters: Vec<String> = ["A", "B", "C"].iter().map(|s| s.to_string()).collect();
        let choice = Question {
            expect: Expect::Choice(letters.clone()),
            ..q()
        };
        let f = Request::new(&c, &choice).response_format.unwrap();
        assert_eq!(
            f["json_schema"]["schema"]["properties"]["label"]["enum"],
            json!(["A", "B", "C"])
        );
        let batch = Question {
            expect: Expect::Batch(letters.clone()),
            ..q()
        };
        let r = Request::new(&c, &batch);
        let schema = &r.response_format.as_ref().unwrap()["json_schema"]["schema"];
        assert_eq!(schema["required"], json!(["A", "B", "C"]));
        assert_eq!(schema["additionalProperties"], false);
        assert_eq!(
            schema["properties"]["C"]["enum"].as_array().map(Vec::len),
            Some(100)
        );
        assert!(
            r.messages[1].content.ends_with(
                "{\"A\": \"<percentage>\", \"B\": \"<percentage>\", \"C\": \"<percentage>\"}"
            ),
            "{}",
            r.messages[1].content
        );
    }

    #[test]
    fn a_batch_answer_raises_a_low_output_limit_and_nothing_else_does() {
        let mut c = EndpointConfig::new("http://x/v1", "m");
        let letters: Vec<String> = crate::context::LABELS
            .chars()
            .take(20)
            .map(|c| c.to_string())
            .collect();
        let batch = Question {
            expect: Expect::Batch(letters),
            ..q()
        };
        // No limit set: none is sent.
        assert_eq!(Request::new(&c, &batch).max_output_tokens(&c), None);
        c.max_output_tokens = Some(48);
        let need = 16 + 20 * BATCH_TOKENS_PER_PLACE;
        assert_eq!(Request::new(&c, &batch).max_output_tokens(&c), Some(need));
        assert_eq!(Request::new(&c, &q()).max_output_tokens(&c), Some(48));
        c.max_output_tokens = Some(4000);
        assert_eq!(Request::new(&c, &batch).max_output_tokens(&c), Some(4000));
        // Named places need room for their names too.
        c.max_output_tokens = Some(48);
        let named = Question {
            expect: Expect::BatchYesNo(vec!["sofa in the living room".into(); 20]),
            ..q()
        };
        let limit = Request::new(&c, &named).max_output_tokens(&c).unwrap();
        assert_eq!(limit, need + 20 * 8, "23 characters: 8 more tokens each");
    }
}
