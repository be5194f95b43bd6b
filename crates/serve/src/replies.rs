//! Request ids, as the IETF Idempotency-Key draft has them: a write that carries a
//! `request_id` stores its reply in the same transaction as its rows, so a retry after it
//! completed gets the very bytes of the first reply; a retry while the first is still in flight
//! (on this replica or another) gets 409; the same id with another body gets 422.

use sha2::{Digest, Sha256};

use crate::api::MAX_REQUEST_ID;
use crate::error::{ApiError, ErrorKind};
use crate::model::{ApiReply, StoredReply};
use crate::service::Service;
use crate::store::{Claim, Reader, Writer};

/// How a write with a request id begins: answered from the stored reply, or claimed.
pub(crate) enum Begun<'a> {
    /// The request completed before; this is its reply.
    Replied(ApiReply),
    /// The request is new (or failed before): run it while holding this.
    Fresh(RequestClaim<'a>),
}

/// A request id in flight, on this replica and (on PostgreSQL) every other; released when
/// dropped.
pub(crate) struct RequestClaim<'a> {
    service: &'a Service,
    id: Option<String>,
    _shared: Option<Claim<'a>>,
}

impl Drop for RequestClaim<'_> {
    fn drop(&mut self) {
        if let Some(id) = self.id.take() {
            self.service
                .in_flight
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .remove(&id);
        }
    }
}

impl Service {
    /// Begins a write: the stored reply when this request completed before, else a claim on
    /// its id held until the write ends. Read before planning, so a retry costs no planning.
    ///
    /// # Errors
    /// 400 for an id of the wrong length, 409 while the same id is in flight, 422 when the id
    /// was used for another request.
    pub(crate) fn begin(
        &self,
        request_id: Option<&str>,
        route: &str,
        body: &[u8],
    ) -> Result<Begun<'_>, ApiError> {
        let Some(id) = request_id else {
            return Ok(Begun::Fresh(RequestClaim {
                service: self,
                id: None,
                _shared: None,
            }));
        };
        if id.is_empty() || id.chars().count() > MAX_REQUEST_ID {
            return Err(ApiError::new(
                ErrorKind::Malformed,
                "request_id",
                format!("must have 1 to {MAX_REQUEST_ID} characters"),
            ));
        }
        let in_flight = || {
            ApiError::new(
                ErrorKind::Conflict,
                "request_id",
                format!("{id:?} is in flight; retry when it has completed"),
            )
        };
        if !self
            .in_flight
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .insert(id.to_string())
        {
            return Err(in_flight());
        }
        // From here the id is ours on this replica: dropping the claim gives it back.
        let mut claim = RequestClaim {
            service: self,
            id: Some(id.to_string()),
            _shared: None,
        };
        match self.store.claim(id)? {
            Some(shared) => claim._shared = Some(shared),
            None => return Err(in_flight()),
        }
        match self
            .store
            .read(|r| Ok(stored_reply(r, request_id, route, body)))??
        {
            Some(reply) => Ok(Begun::Replied(reply)),
            None => Ok(Begun::Fresh(claim)),
        }
    }

    /// Runs a write operation with request-id idempotency, under the claim [`begin`] took: a
    /// stored reply for the same id and body is returned as it was (a claim lost with a
    /// restarted database cannot make it run twice); the same id with another body is a 422.
    ///
    /// [`begin`]: Service::begin
    pub(crate) fn idempotent(
        &self,
        request_id: Option<&str>,
        route: &str,
        body: &[u8],
        op: impl FnOnce(&Writer<'_>) -> Result<ApiReply, ApiError>,
    ) -> Result<ApiReply, ApiError> {
        self.store.write(|w| {
            if let Some(reply) = stored_reply(&w.reader(), request_id, route, body)? {
                return Ok(reply);
            }
            let reply = op(w)?;
            if let Some(id) = request_id {
                w.insert_reply(
                    id,
                    &StoredReply {
                        fingerprint: fingerprint(route, body),
                        outcome: reply.outcome,
                        body: reply.body.clone(),
                    },
                )?;
            }
            Ok(reply)
        })
    }
}
/// What tells a retried request from another one under the same id: route and body.
fn fingerprint(route: &str, body: &[u8]) -> String {
    let mut h = Sha256::new();
    h.update(route.as_bytes());
    h.update([0]);
    h.update(body);
    format!("{:x}", h.finalize())
}

/// The stored reply to `request_id` when it was this request (route and body); a 422 when the
/// id was used for another one.
fn stored_reply(
    r: &Reader<'_>,
    request_id: Option<&str>,
    route: &str,
    body: &[u8],
) -> Result<Option<ApiReply>, ApiError> {
    let Some(id) = request_id else {
        return Ok(None);
    };
    let Some(stored) = r.reply(id)? else {
        return Ok(None);
    };
    if stored.fingerprint != fingerprint(route, body) {
        return Err(ApiError::new(
            ErrorKind::Invalid,
            "request_id",
            format!("{id:?} was used for another request (another route or body)"),
        ));
    }
    Ok(Some(ApiReply {
        outcome: stored.outcome,
        body: stored.body,
    }))
}
