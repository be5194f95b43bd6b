//! Chat messages as ferret stores and hashes them.
//!
//! A type of our own rather than async-openai's request message: its JSON form is the cache key's
//! input, and it must not change when a library upgrade adds optional fields.

use async_openai::types::chat::{
    ChatCompletionRequestAssistantMessage, ChatCompletionRequestMessage,
    ChatCompletionRequestSystemMessage, ChatCompletionRequestUserMessage,
};
use serde::{Deserialize, Serialize};

/// Who says a message.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum MessageRole {
    /// Instructions and role.
    System,
    /// The question.
    User,
    /// A model's earlier answer (worked examples written as a conversation).
    Assistant,
}

/// One chat message.
#[derive(Clone, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct ChatMessage {
    /// Who says it.
    pub role: MessageRole,
    /// The text.
    pub content: String,
}

impl ChatMessage {
    /// A system message.
    pub fn system(content: impl Into<String>) -> Self {
        Self {
            role: MessageRole::System,
            content: content.into(),
        }
    }

    /// A user message.
    pub fn user(content: impl Into<String>) -> Self {
        Self {
            role: MessageRole::User,
            content: content.into(),
        }
    }

    /// An assistant message.
    pub fn assistant(content: impl Into<String>) -> Self {
        Self {
            role: MessageRole::Assistant,
            content: content.into(),
        }
    }
}

impl From<&ChatMessage> for ChatCompletionRequestMessage {
    fn from(m: &ChatMessage) -> Self {
        let text = m.content.as_str();
        match m.role {
            MessageRole::System => {
                ChatCompletionRequestMessage::System(ChatCompletionRequestSystemMessage::from(text))
            }
            MessageRole::User => {
                ChatCompletionRequestMessage::User(ChatCompletionRequestUserMessage::from(text))
            }
            MessageRole::Assistant => ChatCompletionRequestMessage::Assistant(
                ChatCompletionRequestAssistantMessage::from(text),
            ),
        }
    }
}

/// The messages as one text, for previews and `ferret prompts show`: each message under a
/// `[role]` line.
pub fn transcript(messages: &[ChatMessage]) -> String {
    let mut out = String::new();
    for m in messages {
        let role = match m.role {
            MessageRole::System => "system",
            MessageRole::User => "user",
            MessageRole::Assistant => "assistant",
        };
        if !out.is_empty() {
            out.push('\n');
        }
        out.push('[');
        out.push_str(role);
        out.push_str("]\n");
        out.push_str(&m.content);
        if !m.content.ends_with('\n') {
            out.push('\n');
        }
    }
    out
}

/// A one-line preview of a prompt for error messages: its first `max_chars` characters and, when
/// the prompt is longer, also its last line (where the question is), so a reader can tell which
/// query it was.
pub fn prompt_start(messages: &[ChatMessage], max_chars: usize) -> String {
    let all: String = messages
        .iter()
        .map(|m| m.content.as_str())
        .collect::<Vec<_>>()
        .join("\n");
    let flat = |t: &str| t.split_whitespace().collect::<Vec<_>>().join(" ");
    let head = flat(&all);
    if head.chars().count() <= max_chars {
        return format!("\"{head}\"");
    }
    let start: String = head.chars().take(max_chars).collect();
    let last = all
        .lines()
        .rev()
        .map(flat)
        .find(|l| !l.is_empty())
        .unwrap_or_default();
    let last: String = last.chars().take(2 * max_chars).collect();
    format!("\"{start}…\" (last line: \"{last}\")")
}

/// `text` with control characters (terminal escape sequences, carriage returns, NULs) written as
/// `\u{1b}`-style escapes, for showing what a server sent in a message or on a terminal. Line
/// breaks and tabs are escaped too, so that a reply stays on its line.
pub fn printable(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        // Bidirectional overrides reorder what a terminal shows, like escape sequences.
        if c.is_control() || matches!(c, '\u{202a}'..='\u{202e}' | '\u{2066}'..='\u{2069}') {
            out.extend(c.escape_debug());
        } else {
            out.push(c);
        }
    }
    out
}
