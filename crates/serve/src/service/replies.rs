//! Request ids, as the IETF Idempotency-Key draft has them: a write that carries a
//! `request_id` stores its reply in the same transaction as its rows, so a retry after it
//! completed gets the very bytes of the first reply; a retry while the first is still in flight
//! (on this replica or another) gets 409; the same id with another body gets 422.

use sha2::{Digest, Sha256};

use super::Service;
use crate::api::MAX_REQUEST_ID;
use crate::error::{ApiError, ErrorKind};
use crate::model::{ApiReply, StoredReply};
use crate::store::{Claim, Final, FinalFailed, Reader, Writer, store_reply};

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
    /// Set when [`complete`](RequestClaim::complete) rolled its write back for a reply stored
    /// meanwhile.
    rolled_back: std::cell::Cell<bool>,
}

/// A request's id and fingerprint, to store its reply from another request's write.
#[derive(Clone, Debug)]
pub(crate) struct ReplyTo {
    id: String,
    fingerprint: String,
}

impl ReplyTo {
    /// The reply to request `id`, sent to `route` with `body`.
    pub(crate) fn new(id: &str, route: &str, body: &[u8]) -> Self {
        Self {
            id: id.to_string(),
            fingerprint: fingerprint(route, body),
        }
    }

    /// The statement storing `reply` as this request's, to run with the commit; it fails as
    /// [`store_reply`]'s does when the request has a reply already.
    pub(crate) fn store(&self, reply: &ApiReply) -> Final {
        store_reply(
            &self.id,
            &StoredReply {
                fingerprint: self.fingerprint.clone(),
                outcome: reply.outcome,
                body: reply.body.clone(),
            },
        )
    }
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
                rolled_back: Default::default(),
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
            rolled_back: Default::default(),
        };
        // The stored reply is looked up while the claim is asked for. Should another replica
        // store it between the two (and let go of the id), this request runs again, and
        // storing its reply, which finds the first, rolls it back and answers with that.
        let (claimed, stored) = self.store.claim_while(id, || {
            self.store
                .read(|r| Ok(stored_reply(r, request_id, route, body)))
        });
        match claimed? {
            Some(shared) => claim._shared = Some(shared),
            None => return Err(in_flight()),
        }
        match stored?? {
            Some(reply) => Ok(Begun::Replied(reply)),
            None => Ok(Begun::Fresh(claim)),
        }
    }
}

impl RequestClaim<'_> {
    /// What storing this request's reply takes, for a write that stores the replies of several
    /// requests at once (gathered trial starts); `None` without a request id.
    pub(crate) fn reply_to(&self, route: &str, body: &[u8]) -> Option<ReplyTo> {
        self.id.as_deref().map(|id| ReplyTo::new(id, route, body))
    }

    /// Whether the last [`complete`](Self::complete) committed its own write (false when it
    /// answered with a reply stored meanwhile, its write rolled back): what it wrote may be
    /// remembered only then.
    pub(crate) fn wrote(&self) -> bool {
        !self.rolled_back.get()
    }

    /// Replaces the reply stored by [`complete`](Self::complete) by `reply` (a reply that could
    /// only be finished once the write was committed); nothing without a request id.
    ///
    /// # Errors
    /// The database refuses.
    pub(crate) fn replace(&self, reply: &ApiReply) -> Result<(), ApiError> {
        let Some(id) = self.id.as_deref() else {
            return Ok(());
        };
        Ok(self.service.store.replace_reply(id, &reply.body)?)
    }

    /// Runs a write operation with request-id idempotency, under this claim. [`Service::begin`]
    /// found no reply stored, and the claim keeps every other run of the id out, so the reply
    /// is not looked up again before the operation; storing it is what checks. Should the id
    /// have a reply all the same (a claim lost with its database session while another
    /// replica ran the id), the operation is rolled back and the stored reply returned as it
    /// was, or a 422 when it answered another body.
    pub(crate) fn complete(
        &self,
        route: &str,
        body: &[u8],
        op: impl FnOnce(&Writer<'_>) -> Result<ApiReply, ApiError>,
    ) -> Result<ApiReply, ApiError> {
        self.complete_with(route, body, |w| Ok((op(w)?, Vec::new())))
    }

    /// [`complete`](Self::complete) for an operation that ends with statements to run with the
    /// commit (see [`Store::write_finishing`](crate::store::Store::write_finishing)); the reply
    /// is stored last among them.
    pub(crate) fn complete_with(
        &self,
        route: &str,
        body: &[u8],
        op: impl FnOnce(&Writer<'_>) -> Result<(ApiReply, Vec<Final>), ApiError>,
    ) -> Result<ApiReply, ApiError> {
        let request_id = self.id.as_deref();
        self.rolled_back.set(false);
        // Where the reply is among the final statements.
        let reply_at = std::cell::Cell::new(None);
        let done = self.service.store.write_finishing(|w| {
            let (reply, mut finals) = op(w)?;
            if let Some(to) = self.reply_to(route, body) {
                reply_at.set(Some(finals.len()));
                finals.push(to.store(&reply));
            }
            Ok::<_, ApiError>((reply, finals))
        })?;
        match done {
            Ok(reply) => Ok(reply),
            // The id has a reply already: the write is rolled back and that reply returned.
            Err(FinalFailed { index, error })
                if error.is_duplicate() && reply_at.get() == Some(index) =>
            {
                self.rolled_back.set(true);
                self.service
                    .store
                    .read(|r| Ok(stored_reply(r, request_id, route, body)))??
                    .ok_or_else(|| ApiError::internal("a request id's stored reply vanished"))
            }
            Err(FinalFailed { error, .. }) => Err(error.into()),
        }
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

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use ferret_plan::strategy::GreedyStrategy;
    use ferret_world::GridParams;

    use super::*;
    use crate::model::Outcome;
    use crate::store::{Store, StoreError};

    fn service() -> Service {
        let store = Store::in_memory().unwrap();
        Service::new(store, GridParams::default(), vec![Arc::new(GreedyStrategy)]).unwrap()
    }

    /// A claim that finds its id answered when it stores its reply (another replica ran the id
    /// after this one's claim was lost) rolls its own write back and answers as the stored
    /// reply does: byte for byte for the same body, 422 for another.
    #[test]
    fn a_reply_stored_meanwhile_rolls_the_write_back_and_is_returned() {
        let s = service();
        let (route, body) = ("POST /scenes", br#"{"a":1}"#.as_slice());
        let earlier = StoredReply {
            fingerprint: fingerprint(route, body),
            outcome: Outcome::Created,
            body: "the first run's reply".into(),
        };
        s.store
            .write_finishing(|_| Ok::<_, StoreError>(((), vec![store_reply("r1", &earlier)])))
            .unwrap()
            .unwrap();
        let claim = || RequestClaim {
            service: &s,
            id: Some("r1".into()),
            _shared: None,
            rolled_back: Default::default(),
        };
        let write = |w: &Writer<'_>| -> Result<ApiReply, ApiError> {
            w.insert_scene("written", "{}")?;
            Ok(ApiReply {
                outcome: Outcome::Created,
                body: "a second run's reply".into(),
            })
        };
        let answered = claim();
        let reply = answered.complete(route, body, write).unwrap();
        assert!(!answered.wrote());
        assert_eq!(reply.body, earlier.body);
        assert_eq!(reply.outcome, Outcome::Created);
        let err = claim().complete(route, b"{}", write).unwrap_err();
        assert_eq!(err.kind, crate::error::ErrorKind::Invalid, "{err:?}");
        assert_eq!(s.store.read(|r| r.scene("written")).unwrap(), None);
        // A fresh id runs the write and stores its reply.
        let fresh = RequestClaim {
            service: &s,
            id: Some("r2".into()),
            _shared: None,
            rolled_back: Default::default(),
        };
        let reply = fresh.complete(route, body, write).unwrap();
        assert!(fresh.wrote());
        assert_eq!(reply.body, "a second run's reply");
        assert!(s.store.read(|r| r.scene("written")).unwrap().is_some());
        assert_eq!(
            s.store.read(|r| r.reply("r2")).unwrap().unwrap().body,
            reply.body
        );
    }
}
