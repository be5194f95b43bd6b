//! From HTTP to the service and back: the status of each outcome and failure, JSON bodies
//! (with the request id a body or an `Idempotency-Key` header carries) and path segments
//! parsed with the field they get wrong named.

use std::marker::PhantomData;

use axum::Json;
use axum::body::Bytes;
use axum::extract::rejection::BytesRejection;
use axum::extract::{FromRequest, FromRequestParts, Path, Request};
use axum::http::request::Parts;
use axum::http::{HeaderMap, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::de::DeserializeOwned;

use crate::api::{ErrorBody, ErrorDetail, WithRequestId};
use crate::error::{ApiError, ErrorKind};
use crate::model::{ApiReply, Outcome};

/// The HTTP status of each kind of failure: the one place the service's errors meet HTTP.
fn status_of(kind: ErrorKind) -> StatusCode {
    match kind {
        ErrorKind::Malformed => StatusCode::BAD_REQUEST,
        ErrorKind::Unauthorized => StatusCode::UNAUTHORIZED,
        ErrorKind::Forbidden => StatusCode::FORBIDDEN,
        ErrorKind::NotFound => StatusCode::NOT_FOUND,
        ErrorKind::MethodNotAllowed => StatusCode::METHOD_NOT_ALLOWED,
        ErrorKind::Conflict => StatusCode::CONFLICT,
        ErrorKind::TooLarge => StatusCode::PAYLOAD_TOO_LARGE,
        ErrorKind::UnsupportedMedia => StatusCode::UNSUPPORTED_MEDIA_TYPE,
        ErrorKind::Timeout => StatusCode::REQUEST_TIMEOUT,
        ErrorKind::Invalid => StatusCode::UNPROCESSABLE_ENTITY,
        ErrorKind::Internal => StatusCode::INTERNAL_SERVER_ERROR,
        ErrorKind::Unavailable => StatusCode::SERVICE_UNAVAILABLE,
    }
}

/// The status of a request that worked.
fn status_of_outcome(outcome: Outcome) -> StatusCode {
    match outcome {
        Outcome::Done => StatusCode::OK,
        Outcome::Created => StatusCode::CREATED,
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let status = status_of(self.kind);
        if status.is_server_error() {
            tracing::warn!(status = status.as_u16(), message = %self.message, "request failed");
        }
        let body = ErrorBody {
            error: ErrorDetail {
                status: status.as_u16(),
                field: self.field,
                message: self.message,
            },
        };
        let mut response = (status, Json(body)).into_response();
        // What is down (the database, an LLM endpoint) may be back in a moment: say when to
        // retry, so that a client tells this from a refusal.
        if status == StatusCode::SERVICE_UNAVAILABLE {
            response
                .headers_mut()
                .insert(header::RETRY_AFTER, header::HeaderValue::from_static("1"));
        }
        response
    }
}

pub(super) fn json_response(status: StatusCode, body: String) -> Response {
    (status, [(header::CONTENT_TYPE, "application/json")], body).into_response()
}

pub(super) fn reply(r: Result<ApiReply, ApiError>) -> Response {
    match r {
        Ok(r) => json_response(status_of_outcome(r.outcome), r.body),
        Err(e) => e.into_response(),
    }
}

/// Parses a JSON object body; a failure names the field (`objects[2]`, `pose`).
pub(super) fn parse<T: DeserializeOwned>(body: &[u8]) -> Result<T, ApiError> {
    // serde reads a struct from an array too (`[]` would be a deployment with every default).
    if body.iter().find(|b| !b.is_ascii_whitespace()) != Some(&b'{') {
        return Err(ApiError::new(
            ErrorKind::Malformed,
            "",
            "the body must be a JSON object",
        ));
    }
    let mut de = serde_json::Deserializer::from_slice(body);
    let value: T = serde_path_to_error::deserialize(&mut de).map_err(|e| {
        let path = e.path().to_string();
        let inner = e.into_inner();
        let field = if path == "." { String::new() } else { path };
        ApiError::new(
            ErrorKind::Malformed,
            field,
            format!("malformed request: {inner}"),
        )
    })?;
    de.end()
        .map_err(|e| ApiError::new(ErrorKind::Malformed, "", format!("malformed request: {e}")))?;
    Ok(value)
}

/// The body, or the error axum met reading it (413 past the limit) as a JSON error. A body that
/// is not `application/json` is refused (415) before it is parsed: forms and `text/plain` are
/// what a web page may post to another site without asking.
pub(super) fn body(
    headers: &HeaderMap,
    b: Result<Bytes, BytesRejection>,
) -> Result<Bytes, ApiError> {
    let json = headers
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.split(';').next())
        .is_some_and(|t| t.trim().eq_ignore_ascii_case("application/json"));
    if !json {
        return Err(ApiError::new(
            ErrorKind::UnsupportedMedia,
            "content-type",
            "the body must be JSON, sent as `Content-Type: application/json`",
        ));
    }
    b.map_err(|e| {
        if let Some(timeout) = timed_out(&e) {
            return ApiError::new(ErrorKind::Timeout, "", timeout.to_string());
        }
        let kind = if e.status() == StatusCode::PAYLOAD_TOO_LARGE {
            ErrorKind::TooLarge
        } else {
            ErrorKind::Malformed
        };
        ApiError::new(kind, "", e.body_text())
    })
}

/// The body deadline of the connection loop, when that is why the body could not be read.
fn timed_out(e: &BytesRejection) -> Option<&crate::server::BodyTimeout> {
    let mut cause: Option<&(dyn std::error::Error + 'static)> = Some(e);
    while let Some(c) = cause {
        if let Some(t) = c.downcast_ref::<crate::server::BodyTimeout>() {
            return Some(t);
        }
        cause = c.source();
    }
    None
}

/// A JSON object body with its raw bytes (a request id's fingerprint is taken over the bytes the
/// robot sent). Refused in this order: not `application/json` (415), unreadable or over the
/// limit (400, 413, 408), not a JSON object of the route's fields (400, naming the field).
pub(super) struct JsonBody<T> {
    pub(super) value: T,
    pub(super) raw: Bytes,
}

impl<S: Send + Sync, T: DeserializeOwned + WithRequestId> FromRequest<S> for JsonBody<T> {
    type Rejection = ApiError;

    async fn from_request(req: Request, state: &S) -> Result<Self, ApiError> {
        let headers = req.headers().clone();
        let raw = body(&headers, Bytes::from_request(req, state).await)?;
        let mut value: T = parse(&raw)?;
        if let Some(key) = idempotency_key(&headers)? {
            let id = value.request_id_mut();
            match id {
                Some(given) if *given != key => {
                    return Err(ApiError::new(
                        ErrorKind::Malformed,
                        "request_id",
                        "the body's request_id and the Idempotency-Key header differ; give one, or both the same",
                    ));
                }
                _ => *id = Some(key),
            }
        }
        Ok(Self { value, raw })
    }
}

/// The `Idempotency-Key` header's key: a structured-field string (`"abc"`, the draft's form) or a
/// bare value, taken as written. Two such headers, or one that is not text, are refused.
fn idempotency_key(headers: &HeaderMap) -> Result<Option<String>, ApiError> {
    let mut all = headers.get_all(IDEMPOTENCY_KEY).iter();
    let Some(value) = all.next() else {
        return Ok(None);
    };
    let bad = |message: &str| ApiError::new(ErrorKind::Malformed, IDEMPOTENCY_KEY, message);
    if all.next().is_some() {
        return Err(bad("given twice"));
    }
    let text = value
        .to_str()
        .map_err(|_| bad("not visible ASCII text"))?
        .trim();
    let key = match text.strip_prefix('"').and_then(|t| t.strip_suffix('"')) {
        Some(inner) => inner.replace("\\\"", "\"").replace("\\\\", "\\"),
        None => text.to_string(),
    };
    Ok(Some(key))
}

/// The header of the IETF Idempotency-Key draft.
pub(super) const IDEMPOTENCY_KEY: &str = "idempotency-key";

/// A path segment, or 404 for one that is not valid UTF-8 once decoded.
pub(super) struct Segment<K>(pub(super) String, pub(super) PhantomData<K>);

/// A resource id in a path: a positive integer, else 404.
pub(super) struct Id<K>(pub(super) i64, pub(super) PhantomData<K>);

/// What a path segment names, for the field of its errors.
trait Resource {
    const NAME: &'static str;
}

pub(super) struct SceneName;
pub(super) struct DeploymentId;
pub(super) struct TrialId;

impl Resource for SceneName {
    const NAME: &'static str = "scene";
}
impl Resource for DeploymentId {
    const NAME: &'static str = "deployment";
}
impl Resource for TrialId {
    const NAME: &'static str = "trial";
}

impl<S: Send + Sync, K: Resource> FromRequestParts<S> for Segment<K> {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, state: &S) -> Result<Self, ApiError> {
        Path::<String>::from_request_parts(parts, state)
            .await
            .map(|Path(s)| Segment(s, PhantomData))
            .map_err(|e| ApiError::new(ErrorKind::NotFound, K::NAME, e.body_text()))
    }
}

impl<S: Send + Sync, K: Resource> FromRequestParts<S> for Id<K> {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, state: &S) -> Result<Self, ApiError> {
        let Segment(raw, _) = Segment::<K>::from_request_parts(parts, state).await?;
        raw.parse::<i64>()
            .ok()
            .filter(|v| *v > 0)
            .map(|id| Id(id, PhantomData))
            .ok_or_else(|| {
                ApiError::new(
                    ErrorKind::NotFound,
                    K::NAME,
                    format!("{raw:?} is not a {} id", K::NAME),
                )
            })
    }
}
