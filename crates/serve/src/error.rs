//! The service's error: what kind of failure, the request field at fault and a message. The
//! HTTP layer turns the kind into a status; nothing else here knows about HTTP.

use crate::store::StoreError;

/// What kind of failure an [`ApiError`] is. The first ones are the request's fault and name its
/// field; [`Internal`](ErrorKind::Internal) and [`Unavailable`](ErrorKind::Unavailable) are the
/// server's own trouble (the database, an LLM endpoint), never the request's.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ErrorKind {
    /// The request cannot be read: malformed JSON, a missing or mistyped field.
    Malformed,
    /// The request lacks the credentials the server asks for.
    Unauthorized,
    /// The request comes from a host or origin the server does not serve.
    Forbidden,
    /// What the request names does not exist.
    NotFound,
    /// The route does not take the request's method.
    MethodNotAllowed,
    /// The request conflicts with the state (an open trial, a reused request id, a taken name).
    Conflict,
    /// The request, or what it would store, is over a limit.
    TooLarge,
    /// The body is not JSON.
    UnsupportedMedia,
    /// The request's body did not arrive in time.
    Timeout,
    /// A value the service cannot use.
    Invalid,
    /// The server failed where it should not have.
    Internal,
    /// Something the service depends on is down for now (an LLM endpoint, the database).
    Unavailable,
}

/// An error reply: its kind, the field at fault and what is wrong.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{field}: {message}")]
pub struct ApiError {
    /// What kind of failure.
    pub kind: ErrorKind,
    /// The field, e.g. `container` or `scene.containers[2].pose`; empty for the whole request.
    pub field: String,
    /// What is wrong.
    pub message: String,
}

impl ApiError {
    /// An error of a kind, with its field and message.
    pub fn new(kind: ErrorKind, field: impl Into<String>, message: impl Into<String>) -> Self {
        Self {
            kind,
            field: field.into(),
            message: message.into(),
        }
    }

    /// The request cannot be read.
    pub fn malformed(field: impl Into<String>, message: impl Into<String>) -> Self {
        Self::new(ErrorKind::Malformed, field, message)
    }

    /// What the request names does not exist.
    pub fn not_found(field: impl Into<String>, message: impl Into<String>) -> Self {
        Self::new(ErrorKind::NotFound, field, message)
    }

    /// The request conflicts with the state.
    pub fn conflict(field: impl Into<String>, message: impl Into<String>) -> Self {
        Self::new(ErrorKind::Conflict, field, message)
    }

    /// The request, or what it would store, is over a limit.
    pub fn too_large(field: impl Into<String>, message: impl Into<String>) -> Self {
        Self::new(ErrorKind::TooLarge, field, message)
    }

    /// A value the service cannot use.
    pub fn invalid(field: impl Into<String>, message: impl Into<String>) -> Self {
        Self::new(ErrorKind::Invalid, field, message)
    }

    /// Something the service depends on is down for now.
    pub fn unavailable(field: impl Into<String>, message: impl Into<String>) -> Self {
        Self::new(ErrorKind::Unavailable, field, message)
    }

    /// Something the server should not have run into.
    pub fn internal(message: impl Into<String>) -> Self {
        Self::new(ErrorKind::Internal, "", message)
    }
}

impl From<StoreError> for ApiError {
    fn from(e: StoreError) -> Self {
        if e.is_unavailable() {
            // The database is out of reach or busy for now: the request may be retried, here
            // or on another replica.
            tracing::warn!("{e}");
            Self::unavailable("", e.to_string())
        } else {
            Self::internal(e.to_string())
        }
    }
}

/// A planning failure as the service reports it.
pub(crate) fn plan_error(e: ferret_plan::PlanError) -> ApiError {
    // Planning errors come from strategies (an LLM endpoint down, a policy failing), not from
    // the request: the request was valid and may be retried.
    ApiError::new(ErrorKind::Unavailable, "", e.to_string())
}
