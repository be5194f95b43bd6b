//! The response cache: one SQLite file holding every answer ever received, keyed by what
//! determines the answer.
//!
//! **Key.** SHA-256 of a canonical JSON of: the model name, the server (`base_url` without
//! trailing slashes, or the endpoint's `cache_id`), temperature, seed, output-token limit,
//! reasoning effort and the messages. The server is part of the key because model names are not
//! global: `llama3.2:3b` on one Ollama and the same name on another machine may be different
//! quantisations, and `gpt-oss-120b` on a local vLLM is not a provider's build of it. Reusing an
//! answer from a different server would silently mix models; asking again after a server moves
//! only costs tokens. Endpoints that do serve the same weights at several addresses share answers
//! by setting the same `cache_id`. The endpoint's *name*, timeout, concurrency, retry and price
//! settings are not in the key: they do not change the answer.
//!
//! **Durability.** WAL journal, `synchronous = FULL` and a busy timeout: several ferret processes
//! may share one file, and an answer is committed before the caller sees it, so a crash loses
//! nothing that was used. When two runs ask the same prompt at once, the first answer stored wins
//! and both use it ([`ResponseCache::put`] returns the stored entry).
//!
//! API keys are never stored: the key is neither in the hash input nor in any column.

use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use rusqlite::{Connection, OptionalExtension, TransactionBehavior, params};
use serde::Serialize;
use sha2::{Digest, Sha256};

use crate::client::TokenUsage;
use crate::config::EndpointConfig;
use crate::error::CacheError;
use crate::logprobs::TokenLogprob;
use crate::message::ChatMessage;
use crate::question::Request;

/// Where `ferret` keeps the cache unless told otherwise (`--llm-cache`).
pub const DEFAULT_CACHE_PATH: &str = "ferret-llm-cache.sqlite";

/// Schema version in `PRAGMA user_version`. Version 2 added the `logprobs` column; version 1
/// files are upgraded in place (their entries keep their keys and answers).
const SCHEMA_VERSION: i64 = 2;

/// How long a writer waits for another process's lock before failing.
const BUSY_TIMEOUT: Duration = Duration::from_secs(60);

#[derive(Serialize)]
struct KeyInput<'a> {
    /// Bumped if the key's recipe ever changes, so old entries are not misread.
    v: u32,
    model: &'a str,
    server: &'a str,
    temperature: Option<f32>,
    seed: Option<i64>,
    max_output_tokens: Option<u32>,
    reasoning_effort: Option<&'a async_openai::types::chat::ReasoningEffort>,
    messages: &'a [ChatMessage],
    // Left out when absent, so that keys of plain text requests are what they were before
    // structured output and log-probabilities existed.
    #[serde(skip_serializing_if = "Option::is_none")]
    response_format: Option<&'a serde_json::Value>,
    #[serde(skip_serializing_if = "Option::is_none")]
    top_logprobs: Option<u8>,
}

/// The cache key of `request` sent to an endpoint with settings `config`: 64 hex digits.
pub fn cache_key(config: &EndpointConfig, request: &Request) -> String {
    let base = config.normalized_base_url();
    let input = KeyInput {
        v: 1,
        model: &config.model,
        server: config.cache_id.as_deref().unwrap_or(&base),
        temperature: config.temperature,
        seed: config.seed,
        max_output_tokens: request.max_output_tokens(config),
        reasoning_effort: config.reasoning_effort.as_ref(),
        messages: &request.messages,
        response_format: request.response_format.as_ref(),
        top_logprobs: request.top_logprobs,
    };
    // Serialising plain structs, strings and numbers cannot fail.
    let json = serde_json::to_vec(&input).unwrap_or_default();
    format!("{:x}", Sha256::digest(&json))
}

/// One stored answer.
#[derive(Clone, Debug, PartialEq)]
pub struct CachedReply {
    /// The cache key.
    pub key: String,
    /// The endpoint's name when it was asked (informative; not part of the key).
    pub endpoint: String,
    /// The model.
    pub model: String,
    /// The server part of the key (base URL or cache id).
    pub server: String,
    /// The prompt.
    pub messages: Vec<ChatMessage>,
    /// The answer text.
    pub reply: String,
    /// Token counts reported with it.
    pub usage: TokenUsage,
    /// Latency of the request that produced it.
    pub latency: Duration,
    /// When it was stored, seconds since the Unix epoch.
    pub created_unix: i64,
    /// Token log-probabilities of the answer, when they were asked for and sent.
    pub logprobs: Option<Vec<TokenLogprob>>,
}

/// The response cache file. Safe to share between threads (one connection behind a mutex) and
/// between processes (SQLite locking).
#[derive(Debug)]
pub struct ResponseCache {
    file: PathBuf,
    conn: Mutex<Connection>,
}

impl ResponseCache {
    /// Opens (creating if needed, parent directories included) the cache at `file`.
    pub fn open(file: &Path) -> Result<Self, CacheError> {
        let sql = |source| CacheError::Sqlite {
            file: file.to_path_buf(),
            source,
        };
        if let Some(dir) = file.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(|e| {
                sql(rusqlite::Error::SqliteFailure(
                    rusqlite::ffi::Error::new(rusqlite::ffi::SQLITE_CANTOPEN),
                    Some(format!("cannot create {}: {e}", dir.display())),
                ))
            })?;
        }
        let mut conn = Connection::open(file).map_err(sql)?;
        conn.busy_timeout(BUSY_TIMEOUT).map_err(sql)?;
        let mode = switch_to_wal(&conn, BUSY_TIMEOUT).map_err(sql)?;
        if !mode.eq_ignore_ascii_case("wal") {
            tracing::warn!(file = %file.display(), mode, "response cache is not in WAL mode (file system without shared memory?)");
        }
        conn.pragma_update(None, "synchronous", "FULL")
            .map_err(sql)?;
        // IMMEDIATE takes the write lock before reading the version, so two processes opening
        // an old cache at once cannot both migrate it, and the busy timeout applies to the wait.
        let tx = conn
            .transaction_with_behavior(TransactionBehavior::Immediate)
            .map_err(sql)?;
        let version: i64 = tx
            .pragma_query_value(None, "user_version", |row| row.get(0))
            .map_err(sql)?;
        if version > SCHEMA_VERSION {
            return Err(CacheError::Version {
                file: file.to_path_buf(),
                found: version,
                expected: SCHEMA_VERSION,
            });
        }
        tx.execute_batch(
            "CREATE TABLE IF NOT EXISTS responses (
                key               TEXT PRIMARY KEY,
                endpoint          TEXT NOT NULL,
                model             TEXT NOT NULL,
                server            TEXT NOT NULL,
                messages          TEXT NOT NULL,
                reply             TEXT NOT NULL,
                prompt_tokens     INTEGER NOT NULL,
                completion_tokens INTEGER NOT NULL,
                cached_tokens     INTEGER,
                latency_ms        INTEGER NOT NULL,
                created_unix      INTEGER NOT NULL,
                logprobs          TEXT
            );",
        )
        .map_err(sql)?;
        if version == 1 {
            tx.execute_batch("ALTER TABLE responses ADD COLUMN logprobs TEXT;")
                .map_err(sql)?;
        }
        tx.pragma_update(None, "user_version", SCHEMA_VERSION)
            .map_err(sql)?;
        tx.commit().map_err(sql)?;
        Ok(Self {
            file: file.to_path_buf(),
            conn: Mutex::new(conn),
        })
    }

    /// The cache file.
    pub fn path(&self) -> &Path {
        &self.file
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Connection> {
        // A panic while holding the lock cannot leave SQLite inconsistent (statements are atomic),
        // so a poisoned lock is still usable.
        self.conn.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// The stored answer for `key`, if any.
    pub fn get(&self, key: &str) -> Result<Option<CachedReply>, CacheError> {
        let conn = self.lock();
        let row = conn
            .query_row(
                "SELECT key, endpoint, model, server, messages, reply, prompt_tokens, completion_tokens,
                        cached_tokens, latency_ms, created_unix, logprobs
                 FROM responses WHERE key = ?1",
                [key],
                |r| {
                    Ok((
                        r.get::<_, String>(0)?,
                        r.get::<_, String>(1)?,
                        r.get::<_, String>(2)?,
                        r.get::<_, String>(3)?,
                        r.get::<_, String>(4)?,
                        r.get::<_, String>(5)?,
                        r.get::<_, i64>(6)?,
                        r.get::<_, i64>(7)?,
                        r.get::<_, Option<i64>>(8)?,
                        r.get::<_, i64>(9)?,
                        r.get::<_, i64>(10)?,
                        r.get::<_, Option<String>>(11)?,
                    ))
                },
            )
            .optional()
            .map_err(|source| CacheError::Sqlite { file: self.file.clone(), source })?;
        let Some((
            key,
            endpoint,
            model,
            server,
            messages,
            reply,
            pt,
            ct,
            cached,
            latency_ms,
            created_unix,
            logprobs,
        )) = row
        else {
            return Ok(None);
        };
        let messages: Vec<ChatMessage> =
            serde_json::from_str(&messages).map_err(|e| CacheError::Corrupt {
                file: self.file.clone(),
                key: key.clone(),
                message: format!("messages are not JSON: {e}"),
            })?;
        let logprobs = match logprobs {
            None => None,
            Some(text) => Some(
                serde_json::from_str(&text).map_err(|e| CacheError::Corrupt {
                    file: self.file.clone(),
                    key: key.clone(),
                    message: format!("logprobs are not JSON: {e}"),
                })?,
            ),
        };
        let n = |v: i64| u64::try_from(v).unwrap_or(0);
        Ok(Some(CachedReply {
            logprobs,
            key,
            endpoint,
            model,
            server,
            messages,
            reply,
            usage: TokenUsage {
                prompt_tokens: n(pt),
                completion_tokens: n(ct),
                cached_tokens: cached.map(n),
            },
            latency: Duration::from_millis(n(latency_ms)),
            created_unix,
        }))
    }

    /// Stores `entry` unless an answer for its key is already there, and returns the stored one:
    /// the answer every run must use, so that replays see what deployment saw.
    pub fn put(&self, entry: &CachedReply) -> Result<CachedReply, CacheError> {
        let sql = |source| CacheError::Sqlite {
            file: self.file.clone(),
            source,
        };
        let messages = serde_json::to_string(&entry.messages).map_err(|e| CacheError::Corrupt {
            file: self.file.clone(),
            key: entry.key.clone(),
            message: e.to_string(),
        })?;
        let logprobs = match &entry.logprobs {
            None => None,
            Some(l) => Some(serde_json::to_string(l).map_err(|e| CacheError::Corrupt {
                file: self.file.clone(),
                key: entry.key.clone(),
                message: e.to_string(),
            })?),
        };
        let clamp = |v: u64| i64::try_from(v).unwrap_or(i64::MAX);
        {
            let conn = self.lock();
            conn.execute(
                "INSERT OR IGNORE INTO responses
                    (key, endpoint, model, server, messages, reply, prompt_tokens, completion_tokens,
                     cached_tokens, latency_ms, created_unix, logprobs)
                 VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11, ?12)",
                params![
                    entry.key,
                    entry.endpoint,
                    entry.model,
                    entry.server,
                    messages,
                    entry.reply,
                    clamp(entry.usage.prompt_tokens),
                    clamp(entry.usage.completion_tokens),
                    entry.usage.cached_tokens.map(clamp),
                    clamp(entry.latency.as_millis() as u64),
                    entry.created_unix,
                    logprobs,
                ],
            )
            .map_err(sql)?;
        }
        self.get(&entry.key)?.ok_or_else(|| CacheError::Corrupt {
            file: self.file.clone(),
            key: entry.key.clone(),
            message: "entry vanished right after it was written".into(),
        })
    }

    /// Every stored key, in key order.
    pub fn keys(&self) -> Result<Vec<String>, CacheError> {
        let conn = self.lock();
        let sql = |source| CacheError::Sqlite {
            file: self.file.clone(),
            source,
        };
        let mut stmt = conn
            .prepare("SELECT key FROM responses ORDER BY key")
            .map_err(sql)?;
        let keys = stmt
            .query_map([], |r| r.get::<_, String>(0))
            .map_err(sql)?
            .collect::<rusqlite::Result<Vec<String>>>()
            .map_err(sql)?;
        Ok(keys)
    }

    /// Copies every answer of `other` that this cache lacks (insert-or-ignore by key), as
    /// merging the caches of an evaluation's shards does. An answer of `other` that differs from
    /// the one stored here under the same key (reply or log-probabilities; two shards asked an
    /// endpoint that does not answer deterministically) is not copied but returned in
    /// [`CacheMerge::conflicts`]: the trials of the two shards then used different answers, which
    /// one machine never does, and whoever merges must know.
    pub fn merge_from(&self, other: &ResponseCache) -> Result<CacheMerge, CacheError> {
        let mut merge = CacheMerge::default();
        for key in other.keys()? {
            let Some(entry) = other.get(&key)? else {
                continue;
            };
            let before = self.get(&key)?;
            let stored = match before {
                Some(b) => {
                    merge.present += 1;
                    b
                }
                None => {
                    merge.added += 1;
                    self.put(&entry)?
                }
            };
            if stored.reply != entry.reply || stored.logprobs != entry.logprobs {
                merge.conflicts.push(CacheConflict {
                    key,
                    model: entry.model.clone(),
                    prompt: entry
                        .messages
                        .last()
                        .map(|m| m.content.clone())
                        .unwrap_or_default(),
                    kept: stored.reply,
                    other: entry.reply,
                    other_file: other.file.clone(),
                });
            }
        }
        Ok(merge)
    }

    /// Number of stored answers.
    pub fn len(&self) -> Result<u64, CacheError> {
        let conn = self.lock();
        conn.query_row("SELECT COUNT(*) FROM responses", [], |r| r.get::<_, i64>(0))
            .map(|n| u64::try_from(n).unwrap_or(0))
            .map_err(|source| CacheError::Sqlite {
                file: self.file.clone(),
                source,
            })
    }

    /// True when nothing is stored.
    pub fn is_empty(&self) -> Result<bool, CacheError> {
        self.len().map(|n| n == 0)
    }

    /// SQLite's own consistency check; `Ok(())` when the file is sound.
    pub fn integrity_check(&self) -> Result<(), CacheError> {
        let conn = self.lock();
        let result: String = conn
            .query_row("PRAGMA integrity_check", [], |r| r.get(0))
            .map_err(|source| CacheError::Sqlite {
                file: self.file.clone(),
                source,
            })?;
        if result == "ok" {
            Ok(())
        } else {
            Err(CacheError::Corrupt {
                file: self.file.clone(),
                key: String::new(),
                message: result,
            })
        }
    }
}

/// What [`ResponseCache::merge_from`] did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CacheMerge {
    /// Answers copied.
    pub added: u64,
    /// Keys already stored (the same answer, or a conflict).
    pub present: u64,
    /// Keys stored with a different answer.
    pub conflicts: Vec<CacheConflict>,
}

/// One key answered differently by two caches.
#[derive(Clone, Debug, PartialEq)]
pub struct CacheConflict {
    /// The cache key.
    pub key: String,
    /// The model asked.
    pub model: String,
    /// The last message of the prompt.
    pub prompt: String,
    /// The answer kept (the one stored first).
    pub kept: String,
    /// The answer not copied.
    pub other: String,
    /// The cache it came from.
    pub other_file: PathBuf,
}

impl std::fmt::Display for CacheConflict {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "key {} ({}): kept {:?}, {} answered {:?} to {:?}",
            self.key,
            self.model,
            self.kept,
            self.other_file.display(),
            self.other,
            self.prompt
        )
    }
}

/// Seconds since the Unix epoch, now.
pub(crate) fn now_unix() -> i64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| i64::try_from(d.as_secs()).unwrap_or(i64::MAX))
}

/// Puts a database file in WAL mode and returns the journal mode it ended in.
///
/// Switching a new file's journal mode takes an exclusive lock, and when several processes open
/// the same new file at once SQLite reports `SQLITE_BUSY` at once for the ones that would
/// deadlock instead of calling the busy handler; so the switch is retried here until `patience`
/// runs out.
///
/// # Errors
/// Any SQLite error, or `SQLITE_BUSY` still after `patience`.
fn switch_to_wal(conn: &Connection, patience: Duration) -> rusqlite::Result<String> {
    let deadline = std::time::Instant::now() + patience;
    let mut pause = Duration::from_millis(1);
    loop {
        match conn.pragma_update_and_check(None, "journal_mode", "WAL", |row| row.get(0)) {
            Err(rusqlite::Error::SqliteFailure(e, _))
                if e.code == rusqlite::ErrorCode::DatabaseBusy
                    && std::time::Instant::now() < deadline =>
            {
                std::thread::sleep(pause);
                pause = (pause * 2).min(Duration::from_millis(50));
            }
            other => return other,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::EndpointConfig;

    fn entry(key: &str, reply: &str) -> CachedReply {
        CachedReply {
            key: key.into(),
            endpoint: "e".into(),
            model: "m".into(),
            server: "http://x".into(),
            messages: vec![ChatMessage::user("q")],
            reply: reply.into(),
            usage: TokenUsage {
                prompt_tokens: 5,
                completion_tokens: 1,
                cached_tokens: None,
            },
            latency: Duration::from_millis(12),
            created_unix: 1,
            logprobs: None,
        }
    }

    fn req(messages: &[ChatMessage]) -> Request {
        Request {
            min_output_tokens: None,
            messages: messages.to_vec(),
            response_format: None,
            top_logprobs: None,
        }
    }

    #[test]
    fn key_depends_on_answer_relevant_settings_only() {
        let m = [ChatMessage::user("where is the remote?")];
        let base = EndpointConfig::new("http://h:8000/v1", "m");
        let k = cache_key(&base, &req(&m));
        assert_eq!(k.len(), 64);
        // The recipe of plain text requests is unchanged since schema 1 (this is the SHA-256 of the
        // JSON that version wrote, computed outside ferret): old caches stay valid.
        assert_eq!(
            k,
            "e9aa9e16c4fb4026191408c87f0d8a6942a93764d384051e97c14e3cafa34f6d"
        );
        let mut same = base.clone();
        same.base_url = "http://h:8000/v1/".into();
        same.concurrency = 9;
        same.timeout_secs = 3.0;
        same.price_input_per_mtok = 1.0;
        assert_eq!(cache_key(&same, &req(&m)), k);
        for change in [
            |c: &mut EndpointConfig| c.model = "n".into(),
            |c: &mut EndpointConfig| c.base_url = "http://other:8000/v1".into(),
            |c: &mut EndpointConfig| c.temperature = Some(0.0),
            |c: &mut EndpointConfig| c.seed = Some(1),
            |c: &mut EndpointConfig| c.max_output_tokens = Some(10),
            |c: &mut EndpointConfig| {
                c.reasoning_effort = Some(async_openai::types::chat::ReasoningEffort::Low)
            },
        ] {
            let mut c = base.clone();
            change(&mut c);
            assert_ne!(cache_key(&c, &req(&m)), k);
        }
        assert_ne!(
            cache_key(&base, &req(&[ChatMessage::user("where is the remote")])),
            k
        );
        assert_ne!(
            cache_key(&base, &req(&[ChatMessage::system("where is the remote?")])),
            k
        );
        let mut with_format = req(&m);
        with_format.response_format = Some(serde_json::json!({"type": "json_object"}));
        assert_ne!(cache_key(&base, &with_format), k);
        let mut with_logprobs = req(&m);
        with_logprobs.top_logprobs = Some(20);
        assert_ne!(cache_key(&base, &with_logprobs), k);
        // A shared cache id stands for the server.
        let mut a = base.clone();
        a.cache_id = Some("gpt-oss-120b-bf16".into());
        let mut b = a.clone();
        b.base_url = "http://elsewhere/v1".into();
        assert_eq!(cache_key(&a, &req(&m)), cache_key(&b, &req(&m)));
    }

    #[test]
    fn first_answer_stored_wins_and_survives_reopening() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("sub/cache.sqlite");
        let cache = ResponseCache::open(&path).unwrap();
        assert!(cache.is_empty().unwrap());
        assert_eq!(cache.put(&entry("k", "70%")).unwrap().reply, "70%");
        assert_eq!(cache.put(&entry("k", "20%")).unwrap().reply, "70%");
        drop(cache);
        let cache = ResponseCache::open(&path).unwrap();
        let got = cache.get("k").unwrap().unwrap();
        assert_eq!(got, entry("k", "70%"));
        assert_eq!(cache.get("other").unwrap(), None);
        assert_eq!(cache.len().unwrap(), 1);
        cache.integrity_check().unwrap();
    }

    #[test]
    fn logprobs_round_trip_and_version_1_files_upgrade() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("v1.sqlite");
        // A file as schema 1 wrote it.
        let conn = Connection::open(&path).unwrap();
        conn.execute_batch(
            "CREATE TABLE responses (key TEXT PRIMARY KEY, endpoint TEXT NOT NULL, model TEXT NOT NULL,
                server TEXT NOT NULL, messages TEXT NOT NULL, reply TEXT NOT NULL,
                prompt_tokens INTEGER NOT NULL, completion_tokens INTEGER NOT NULL,
                cached_tokens INTEGER, latency_ms INTEGER NOT NULL, created_unix INTEGER NOT NULL);
             INSERT INTO responses VALUES ('old', 'e', 'm', 's', '[]', '40%', 1, 1, NULL, 5, 1);
             PRAGMA user_version = 1;",
        )
        .unwrap();
        drop(conn);
        let cache = ResponseCache::open(&path).unwrap();
        let old = cache.get("old").unwrap().unwrap();
        assert_eq!((old.reply.as_str(), old.logprobs), ("40%", None));
        let mut e = entry("new", "70%");
        e.logprobs = Some(vec![TokenLogprob {
            token: "70".into(),
            logprob: Some(-0.2),
            top_logprobs: vec![],
        }]);
        assert_eq!(cache.put(&e).unwrap(), e);
        drop(cache);
        let conn = Connection::open(&path).unwrap();
        let v: i64 = conn
            .pragma_query_value(None, "user_version", |r| r.get(0))
            .unwrap();
        assert_eq!(v, 2);
    }

    #[test]
    fn refuses_newer_schema() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("c.sqlite");
        let conn = Connection::open(&path).unwrap();
        conn.pragma_update(None, "user_version", 7).unwrap();
        drop(conn);
        let e = ResponseCache::open(&path).unwrap_err();
        assert!(matches!(e, CacheError::Version { found: 7, .. }), "{e}");
    }

    #[test]
    fn merge_copies_missing_answers_and_reports_conflicts() {
        let dir = tempfile::tempdir().unwrap();
        let a = ResponseCache::open(&dir.path().join("a.sqlite")).unwrap();
        let b = ResponseCache::open(&dir.path().join("b.sqlite")).unwrap();
        a.put(&entry("k1", "70")).unwrap();
        a.put(&entry("k2", "20")).unwrap();
        b.put(&entry("k2", "20")).unwrap();
        b.put(&entry("k3", "5")).unwrap();
        b.put(&entry("k1", "80")).unwrap();
        let m = a.merge_from(&b).unwrap();
        assert_eq!((m.added, m.present), (1, 2));
        assert_eq!(m.conflicts.len(), 1);
        let c = &m.conflicts[0];
        assert_eq!(
            (c.key.as_str(), c.kept.as_str(), c.other.as_str()),
            ("k1", "70", "80")
        );
        assert!(c.to_string().contains("b.sqlite"), "{c}");
        assert_eq!(a.len().unwrap(), 3);
        assert_eq!(a.get("k1").unwrap().unwrap().reply, "70");
        assert_eq!(a.keys().unwrap(), ["k1", "k2", "k3"]);
    }
}
