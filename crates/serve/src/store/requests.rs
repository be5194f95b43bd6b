//! The `requests` table: the stored reply to each request id, which makes a write safe to
//! retry.

use crate::model::{Outcome, StoredReply};

use super::conn::{Conn, Reader};
use super::error::StoreError;
use super::{Backend, Final, Store};

impl Store {
    /// Replaces the body of request `id`'s stored reply, in a transaction of its own (one
    /// round trip on PostgreSQL). Used for a reply that completes one stored before (a trial
    /// start's plan): losing it to a crash of the database only means that a retry plans again,
    /// to the same reply, so on PostgreSQL it does not wait for its commit to reach the disk
    /// (`synchronous_commit` off for this transaction alone).
    ///
    /// # Errors
    /// The database refuses, or cannot be reached.
    pub fn replace_reply(&self, id: &str, body: &str) -> Result<(), StoreError> {
        const SQL: &str = "UPDATE requests SET body = $2 WHERE id = $1";
        let params = vec![request_key(id).as_ref().into(), body.into()];
        match &self.backend {
            Backend::Sqlite(s) => s.write(|c| Conn::Sqlite(c, s).execute(SQL, &params).map(drop)),
            Backend::Postgres(p) => {
                let finals = vec![
                    Final {
                        sql: "SET LOCAL synchronous_commit TO OFF",
                        params: Vec::new(),
                    },
                    Final { sql: SQL, params },
                ];
                p.write_finishing(|_| Ok::<_, StoreError>(((), finals)))?
                    .map_err(|failed| failed.error)
            }
        }
    }
}

/// How a request id is stored: as given, unless it holds NUL, which PostgreSQL text cannot.
/// Such an id is stored as the hex of its bytes behind 201 `~`: longer than any id the API
/// takes (200 characters), so it never equals an id stored as given.
fn request_key(id: &str) -> std::borrow::Cow<'_, str> {
    if !id.contains('\0') {
        return std::borrow::Cow::Borrowed(id);
    }
    let mut key = "~".repeat(201);
    for b in id.bytes() {
        key.push_str(&format!("{b:02x}"));
    }
    std::borrow::Cow::Owned(key)
}

/// How a reply's outcome is stored: as the numbers databases have always held (200, 201), so
/// that a database written by any version answers its retries the same.
fn stored_code(o: Outcome) -> i64 {
    match o {
        Outcome::Done => 200,
        Outcome::Created => 201,
    }
}

fn outcome_of(code: i64) -> Outcome {
    if code == 201 {
        Outcome::Created
    } else {
        Outcome::Done
    }
}

/// The reply to request `id`, stored as the last statement of its write: a second reply to the
/// same id is refused ([`StoreError::is_duplicate`]), rolling back the write it ended.
pub fn store_reply(id: &str, reply: &StoredReply) -> Final {
    Final {
        sql: "INSERT INTO requests (id, fingerprint, status, body) VALUES ($1, $2, $3, $4)",
        params: vec![
            request_key(id).as_ref().into(),
            reply.fingerprint.as_str().into(),
            stored_code(reply.outcome).into(),
            reply.body.as_str().into(),
        ],
    }
}

impl Reader<'_> {
    /// The stored reply to request `id`.
    ///
    /// # Errors
    /// The database refuses.
    pub fn reply(&self, id: &str) -> Result<Option<StoredReply>, StoreError> {
        let c = &self.conn;
        c.query_opt(
            "SELECT fingerprint, status, body FROM requests WHERE id = $1",
            &[request_key(id).as_ref().into()],
        )?
        .map(|r| {
            Ok(StoredReply {
                fingerprint: c.some_text(&r, 0, "request fingerprint")?,
                outcome: outcome_of(c.int(&r, 1, "request status")?),
                body: c.some_text(&r, 2, "request body")?,
            })
        })
        .transpose()
    }
}
