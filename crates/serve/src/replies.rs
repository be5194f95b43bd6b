//! Request ids: a write that carries a `request_id` stores its reply in the same transaction as
//! its rows, so a retry gets the very bytes of the first reply and a reuse of the id for another
//! request is refused.

use sha2::{Digest, Sha256};

use crate::api::MAX_REQUEST_ID;
use crate::error::{ApiError, ErrorKind};
use crate::model::{ApiReply, StoredReply};
use crate::service::Service;
use crate::store::{Reader, Writer};

impl Service {
    /// Runs a write operation with request-id idempotency: a stored reply for the same id and
    /// body is returned as it was; the same id with another body is a 409.
    pub(crate) fn idempotent(
        &self,
        request_id: Option<&str>,
        route: &str,
        body: &[u8],
        op: impl FnOnce(&Writer<'_>) -> Result<ApiReply, ApiError>,
    ) -> Result<ApiReply, ApiError> {
        if let Some(id) = request_id
            && (id.is_empty() || id.chars().count() > MAX_REQUEST_ID)
        {
            return Err(ApiError::new(
                ErrorKind::Malformed,
                "request_id",
                format!("must have 1 to {MAX_REQUEST_ID} characters"),
            ));
        }
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

    /// The stored reply to this request, read before planning so a retry costs no planning.
    pub(crate) fn earlier_reply(
        &self,
        request_id: Option<&str>,
        route: &str,
        body: &[u8],
    ) -> Result<Option<ApiReply>, ApiError> {
        if request_id.is_none() {
            return Ok(None);
        }
        self.store
            .read(|r| Ok(stored_reply(r, request_id, route, body)))?
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

/// The stored reply to `request_id` when it was this request (route and body); a 409 when the
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
            ErrorKind::Conflict,
            "request_id",
            format!("{id:?} was used for another request"),
        ));
    }
    Ok(Some(ApiReply {
        outcome: stored.outcome,
        body: stored.body,
    }))
}
