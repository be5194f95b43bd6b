//! The HTTP layer: routes, JSON in and out, the request guards, optional CORS, the OpenAPI
//! document. Handlers parse the body (naming the field a bad body gets wrong) and hand the work
//! to [`Service`] on a blocking thread: planning and SQLite are synchronous, and an LLM
//! strategy blocks on its own runtime.
//!
//! Every request passes the guards in this order: `Host` must name this server (403), a
//! browser's `Origin` must be one allowed for CORS (403), the bearer token must match when one
//! is set (401); then a route that takes a body wants JSON (415) no larger than the limit
//! (413), and other methods on a route are 405 whatever their body. Together
//! they keep a web page the robot's operator happens to open from driving the robot (a form or
//! `text/plain` post, a DNS-rebinding page).

use std::net::{IpAddr, SocketAddr};
use std::sync::Arc;

use std::marker::PhantomData;

use axum::body::Bytes;
use axum::extract::rejection::BytesRejection;
use axum::extract::{DefaultBodyLimit, FromRequest, FromRequestParts, Path, Request, State};
use axum::http::request::Parts;
use axum::http::{HeaderMap, HeaderValue, Method, StatusCode, header};
use axum::middleware::{self, Next};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use axum::{Json, Router};
use serde::de::DeserializeOwned;
use serde_json::{Value, json};
use tower_http::cors::{AllowOrigin, CorsLayer};
use utoipa::OpenApi;
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

use crate::api::{
    AbandonTrial, CreateDeployment, DeploymentState, ErrorBody, ErrorDetail, Observe, SceneDetail,
    SceneSummary, StartTrial, TrialState, UploadScene, WithRequestId,
};
use crate::error::{ApiError, ErrorKind};
use crate::model::{ApiReply, Outcome};
use crate::service::{SceneLimits, Service};

/// Default largest request body, bytes (a scene with hundreds of containers is tens of KB).
pub const DEFAULT_MAX_BODY_BYTES: usize = 1 << 20;

/// How the router guards itself.
#[derive(Clone, Debug)]
pub struct HttpOptions {
    /// When set, every route but `/health` needs `Authorization: Bearer <token>`. An empty
    /// token is refused by [`router`].
    pub token: Option<String>,
    /// Origins allowed to call from a browser; empty = CORS off and every request carrying an
    /// `Origin` refused.
    pub cors_origins: Vec<String>,
    /// The address the server listens on: a request's `Host` must name it (or, for a loopback
    /// address, `localhost`; for an unspecified one, any IP address with its port), or one of
    /// `allowed_hosts`. `None` checks no `Host`.
    pub listen: Option<SocketAddr>,
    /// More names a request's `Host` may give: `name` (any port) or `name:port`.
    pub allowed_hosts: Vec<String>,
    /// Largest request body, bytes (413 past it).
    pub max_body_bytes: usize,
}

impl Default for HttpOptions {
    fn default() -> Self {
        Self {
            token: None,
            cors_origins: Vec::new(),
            listen: None,
            allowed_hosts: Vec::new(),
            max_body_bytes: DEFAULT_MAX_BODY_BYTES,
        }
    }
}

impl HttpOptions {
    /// What [`router`] would refuse, checked without a service (so that a command line can be
    /// refused before anything is opened).
    ///
    /// # Errors
    /// An empty token, a CORS origin that is not a valid header value, an allowed host that is
    /// not a host name; the field names the option.
    pub fn validate(&self) -> Result<(), ApiError> {
        if self.token.as_deref().is_some_and(|t| t.trim().is_empty()) {
            return Err(ApiError::new(
                ErrorKind::Malformed,
                "token",
                "the token is empty: set a non-empty token, or none to run without one",
            ));
        }
        self.origins()?;
        let listen = self
            .listen
            .unwrap_or_else(|| SocketAddr::from(([127, 0, 0, 1], 0)));
        Hosts::new(listen, &self.allowed_hosts)?;
        Ok(())
    }

    fn origins(&self) -> Result<Vec<HeaderValue>, ApiError> {
        self.cors_origins
            .iter()
            .map(|o| {
                HeaderValue::from_str(o)
                    .ok()
                    .filter(|_| !o.trim().is_empty())
                    .ok_or_else(|| {
                        ApiError::new(
                            ErrorKind::Malformed,
                            "cors-origin",
                            format!("{o:?} is not a valid origin"),
                        )
                    })
            })
            .collect()
    }
}

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

fn json_response(status: StatusCode, body: String) -> Response {
    (status, [(header::CONTENT_TYPE, "application/json")], body).into_response()
}

fn reply(r: Result<ApiReply, ApiError>) -> Response {
    match r {
        Ok(r) => json_response(status_of_outcome(r.outcome), r.body),
        Err(e) => e.into_response(),
    }
}

/// Parses a JSON object body; a failure names the field (`objects[2]`, `pose`).
fn parse<T: DeserializeOwned>(body: &[u8]) -> Result<T, ApiError> {
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
fn body(headers: &HeaderMap, b: Result<Bytes, BytesRejection>) -> Result<Bytes, ApiError> {
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
struct JsonBody<T> {
    value: T,
    raw: Bytes,
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
const IDEMPOTENCY_KEY: &str = "idempotency-key";

/// A path segment, or 404 for one that is not valid UTF-8 once decoded.
struct Segment<K>(String, PhantomData<K>);

/// A resource id in a path: a positive integer, else 404.
struct Id<K>(i64, PhantomData<K>);

/// What a path segment names, for the field of its errors.
trait Resource {
    const NAME: &'static str;
}

struct SceneName;
struct DeploymentId;
struct TrialId;

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

/// Runs a service call on the blocking pool.
async fn blocking(f: impl FnOnce() -> Result<ApiReply, ApiError> + Send + 'static) -> Response {
    match tokio::task::spawn_blocking(f).await {
        Ok(r) => reply(r),
        Err(e) => ApiError::internal(format!("the request's worker failed: {e}")).into_response(),
    }
}

#[utoipa::path(get, path = "/health", responses(
    (status = 200, description = "The service is up and its database answers"),
    (status = 503, description = "The database cannot be read", body = ErrorBody)))]
async fn health(State(s): State<Arc<Service>>) -> Response {
    blocking(move || s.health()).await
}

#[utoipa::path(get, path = "/scenes", responses((status = 200, body = [SceneSummary])))]
async fn list_scenes(State(s): State<Arc<Service>>) -> Response {
    blocking(move || s.list_scenes()).await
}

#[utoipa::path(get, path = "/scenes/{name}", params(("name" = String, Path, description = "Scene name")),
    responses((status = 200, body = SceneDetail),
        (status = 404, description = "No scene of that name", body = ErrorBody)))]
async fn get_scene(
    State(s): State<Arc<Service>>,
    Segment(name, _): Segment<SceneName>,
) -> Response {
    blocking(move || s.get_scene(&name)).await
}

#[utoipa::path(post, path = "/scenes", request_body = UploadScene, params(("Idempotency-Key" = Option<String>, Header, description = "The request id, as the request_id field (either, or both the same)")), responses(
    (status = 200, description = "The same scene was uploaded before", body = SceneDetail),
    (status = 201, body = SceneDetail),
    (status = 413, description = "The body, or the store of uploaded scenes, is over its limit", body = ErrorBody)))]
async fn upload_scene(State(s): State<Arc<Service>>, b: JsonBody<UploadScene>) -> Response {
    blocking(move || s.upload_scene(b.value, &b.raw)).await
}

#[utoipa::path(post, path = "/deployments", request_body = CreateDeployment, params(("Idempotency-Key" = Option<String>, Header, description = "The request id, as the request_id field (either, or both the same)")),
    responses((status = 201, body = DeploymentState)))]
async fn create_deployment(
    State(s): State<Arc<Service>>,
    b: JsonBody<CreateDeployment>,
) -> Response {
    blocking(move || s.create_deployment(b.value, &b.raw)).await
}

#[utoipa::path(get, path = "/deployments/{id}", params(("id" = i64, Path, description = "Deployment id", minimum = 1)),
    responses((status = 200, body = DeploymentState),
        (status = 404, description = "No deployment of that id", body = ErrorBody)))]
async fn get_deployment(State(s): State<Arc<Service>>, Id(id, _): Id<DeploymentId>) -> Response {
    blocking(move || s.get_deployment(id)).await
}

#[utoipa::path(post, path = "/deployments/{id}/trials", request_body = StartTrial,
    params(("id" = i64, Path, description = "Deployment id", minimum = 1), ("Idempotency-Key" = Option<String>, Header, description = "The request id, as the request_id field (either, or both the same)")),
    responses((status = 201, body = TrialState),
        (status = 404, description = "No such deployment", body = ErrorBody),
        (status = 503, description = "A strategy could not plan (an LLM endpoint is down); retry later", body = ErrorBody)))]
async fn start_trial(
    State(s): State<Arc<Service>>,
    Id(deployment, _): Id<DeploymentId>,
    b: JsonBody<StartTrial>,
) -> Response {
    blocking(move || s.start_trial(deployment, b.value, &b.raw)).await
}

#[utoipa::path(get, path = "/trials/{id}", params(("id" = i64, Path, description = "Trial id", minimum = 1)),
    responses((status = 200, body = TrialState),
        (status = 404, description = "No trial of that id", body = ErrorBody),
        (status = 503, description = "A strategy could not plan (an LLM endpoint is down); retry later", body = ErrorBody)))]
async fn get_trial(State(s): State<Arc<Service>>, Id(trial, _): Id<TrialId>) -> Response {
    blocking(move || s.get_trial(trial)).await
}

#[utoipa::path(post, path = "/trials/{id}/observations", request_body = Observe,
    operation_id = "observe",
    params(("id" = i64, Path, description = "Trial id", minimum = 1), ("Idempotency-Key" = Option<String>, Header, description = "The request id, as the request_id field (either, or both the same)")),
    responses((status = 200, body = TrialState),
        (status = 404, description = "No such trial", body = ErrorBody),
        (status = 503, description = "A strategy could not plan (an LLM endpoint is down); retry later", body = ErrorBody)))]
async fn post_observation(
    State(s): State<Arc<Service>>,
    Id(trial, _): Id<TrialId>,
    b: JsonBody<Observe>,
) -> Response {
    blocking(move || s.record_observation(trial, b.value, &b.raw)).await
}

#[utoipa::path(post, path = "/trials/{id}/abandon", request_body = AbandonTrial,
    operation_id = "abandon",
    params(("id" = i64, Path, description = "Trial id", minimum = 1), ("Idempotency-Key" = Option<String>, Header, description = "The request id, as the request_id field (either, or both the same)")),
    responses((status = 200, description = "The trial ended as abandoned; selection learns nothing from it", body = TrialState),
        (status = 404, description = "No such trial", body = ErrorBody),
        (status = 409, description = "The trial has ended already", body = ErrorBody)))]
async fn abandon_trial(
    State(s): State<Arc<Service>>,
    Id(trial, _): Id<TrialId>,
    b: JsonBody<AbandonTrial>,
) -> Response {
    blocking(move || s.abandon_trial(trial, b.value, &b.raw)).await
}

/// The OpenAPI document as derived from the types; [`document`] adds what the derive cannot say.
#[derive(OpenApi)]
#[openapi(
    info(
        title = "ferret serve",
        description = "LLM-informed object search for a real robot: scenes, deployments with strategy selection, trials step by step. See docs/serve.md."
    ),
    components(schemas(ErrorBody, ErrorDetail))
)]
pub struct ApiDoc;

/// Statuses every route may answer besides its own, and why.
const COMMON_STATUSES: [(u16, &str); 3] = [
    (
        403,
        "The Host header names another server, or a browser Origin is not allowed",
    ),
    (500, "The server's own failure (its database)"),
    (
        503,
        "The database is out of reach or busy for now: retry, here or on another replica",
    ),
];

/// Statuses of every route that takes a body.
const BODY_STATUSES: [(u16, &str); 6] = [
    (
        400,
        "Malformed JSON, not an object, a missing or mistyped field",
    ),
    (
        409,
        "The same request id is still in flight (retry later), or a conflicting state",
    ),
    (
        408,
        "The body did not arrive within the server's body timeout",
    ),
    (413, "The body is larger than the server's limit"),
    (415, "The body is not application/json"),
    (
        422,
        "A value the server cannot use (named in `field`), or a request id used before with another body",
    ),
];

/// Every route with its handler, each declared once: the path and method come from the
/// handler's OpenAPI attribute. Returns the router and the OpenAPI document the attributes say.
fn routes() -> (Router<Arc<Service>>, utoipa::openapi::OpenApi) {
    OpenApiRouter::with_openapi(ApiDoc::openapi())
        .routes(routes!(health))
        .routes(routes!(list_scenes, upload_scene))
        .routes(routes!(get_scene))
        .routes(routes!(create_deployment))
        .routes(routes!(get_deployment))
        .routes(routes!(start_trial))
        .routes(routes!(get_trial))
        .routes(routes!(post_observation))
        .routes(routes!(abandon_trial))
        .split_for_parts()
}

/// The OpenAPI document this server serves: the derived one, plus what the service enforces
/// and the derive cannot say (the scene schema with this server's limits, the strategies it
/// offers, unique items, patterns of array items, every status a route can answer, the token).
pub fn document(options: &HttpOptions, strategies: &[String], limits: &SceneLimits) -> Value {
    let mut doc = serde_json::to_value(routes().1).unwrap_or_default();
    let error_ref =
        json!({"application/json": {"schema": {"$ref": "#/components/schemas/ErrorBody"}}});
    if let Some(schemas) = doc
        .pointer_mut("/components/schemas")
        .and_then(Value::as_object_mut)
    {
        schemas.insert("Scene".into(), crate::api::scene_schema(limits));
    }
    if let Some(scene) = doc.pointer_mut("/components/schemas/UploadScene/properties/scene") {
        *scene = json!({
            "$ref": "#/components/schemas/Scene",
            "description": "The scene, as in a scene file (version 1, without `map`)."
        });
    }
    if let Some(s) = doc.pointer_mut("/components/schemas/CreateDeployment/properties/strategies") {
        s["uniqueItems"] = json!(true);
        s["items"] = json!({"type": "string", "enum": strategies});
    }
    if let Some(items) = doc.pointer_mut("/components/schemas/Observe/properties/objects/items") {
        *items = json!({"type": "string", "pattern": crate::api::TYPE_NAME_PATTERN});
    }
    if let Some(pose) = doc.pointer_mut("/components/schemas/StartTrial/properties/pose") {
        *pose = json!({
            "type": ["array", "null"],
            "items": {"type": "number"},
            "minItems": 3,
            "maxItems": 3,
            "description": "The robot's pose `[x, y, yaw°]` in the map frame, yaw within ±360°; default: the scene's start."
        });
    }
    let paths: Vec<(String, String)> = doc
        .pointer("/paths")
        .and_then(Value::as_object)
        .map(|paths| {
            paths
                .iter()
                .flat_map(|(path, ops)| {
                    ops.as_object()
                        .into_iter()
                        .flat_map(|o| o.keys())
                        .map(move |method| (path.clone(), method.clone()))
                })
                .collect()
        })
        .unwrap_or_default();
    for (path, method) in paths {
        let Some(op) = doc
            .pointer_mut(&format!("/paths/{}/{method}", path.replace('/', "~1")))
            .and_then(Value::as_object_mut)
        else {
            continue;
        };
        let mut all: Vec<(u16, &str)> = Vec::new();
        if op.contains_key("requestBody") {
            all.extend(BODY_STATUSES);
        }
        all.extend(COMMON_STATUSES);
        if options.token.is_some() && path != "/health" {
            all.push((401, "The bearer token is missing or wrong"));
            op.insert("security".into(), json!([{"bearer": []}]));
        }
        let responses = op
            .entry("responses")
            .or_insert_with(|| json!({}))
            .as_object_mut();
        if let Some(responses) = responses {
            // A route's own description of a status (in its attribute) comes first.
            for (status, description) in all {
                responses
                    .entry(status.to_string())
                    .or_insert_with(|| json!({"description": description, "content": error_ref}));
            }
        }
    }
    for (path, method, status, links) in links() {
        if let Some(response) = doc.pointer_mut(&format!(
            "/paths/{}/{method}/responses/{status}",
            path.replace('/', "~1")
        )) {
            response["links"] = links;
        }
    }
    if options.token.is_some() {
        doc["components"]["securitySchemes"] =
            json!({"bearer": {"type": "http", "scheme": "bearer"}});
    }
    doc
}

/// How the objects one route creates are reached by the others (OpenAPI links), so that a client
/// generator or a contract tester can follow a deployment to its trials and their observations.
fn links() -> Vec<(&'static str, &'static str, u16, Value)> {
    let to = |operation: &str, parameter: &str, from: &str| json!({"operationId": operation, "parameters": {parameter: format!("$response.body#/{from}")}});
    let trial = || {
        json!({
            "GetTrial": to("get_trial", "id", "trial"),
            "Observe": to("observe", "id", "trial"),
            "Abandon": to("abandon", "id", "trial"),
        })
    };
    vec![
        (
            "/scenes",
            "post",
            201,
            json!({"GetScene": to("get_scene", "name", "name")}),
        ),
        (
            "/deployments",
            "post",
            201,
            json!({
                "GetDeployment": to("get_deployment", "id", "id"),
                "StartTrial": to("start_trial", "id", "id"),
            }),
        ),
        ("/deployments/{id}/trials", "post", 201, trial()),
        ("/trials/{id}/observations", "post", 200, trial()),
    ]
}

async fn not_found() -> Response {
    ApiError::new(ErrorKind::NotFound, "", "no such route; see /openapi.json").into_response()
}

async fn method_not_allowed() -> Response {
    ApiError::new(
        ErrorKind::MethodNotAllowed,
        "",
        "this route does not take that method; see /openapi.json",
    )
    .into_response()
}

/// Equal-time comparison, so the token cannot be guessed byte by byte from response times.
/// (Hand-written: one loop, not worth a dependency.)
fn same(a: &[u8], b: &[u8]) -> bool {
    a.len() == b.len() && a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

/// The `Host` values a request may carry.
#[derive(Debug, Default)]
struct Hosts {
    /// Any IP address with this port (listening on an unspecified address).
    any_ip_on: Option<u16>,
    /// Addresses with their port.
    ips: Vec<(IpAddr, u16)>,
    /// Names, with a port or any.
    names: Vec<(String, Option<u16>)>,
}

impl Hosts {
    fn new(listen: SocketAddr, allowed: &[String]) -> Result<Hosts, ApiError> {
        let mut hosts = Hosts::default();
        let port = listen.port();
        if listen.ip().is_unspecified() {
            hosts.any_ip_on = Some(port);
        } else {
            hosts.ips.push((listen.ip(), port));
        }
        if listen.ip().is_loopback() || listen.ip().is_unspecified() {
            hosts.names.push(("localhost".into(), Some(port)));
        }
        for a in allowed {
            let bad = || {
                ApiError::new(
                    ErrorKind::Malformed,
                    "allow-host",
                    format!("{a:?} is not a host name or host:port"),
                )
            };
            let (host, port) = split_host(a).ok_or_else(bad)?;
            match host.parse::<IpAddr>() {
                Ok(ip) => hosts.ips.push((ip, port.unwrap_or(listen.port()))),
                Err(_) if !host.is_empty() => {
                    hosts.names.push((host.to_ascii_lowercase(), port));
                }
                Err(_) => return Err(bad()),
            }
        }
        Ok(hosts)
    }

    fn allows(&self, value: &str) -> bool {
        let Some((host, port)) = split_host(value) else {
            return false;
        };
        let port = port.unwrap_or(80);
        match host.parse::<IpAddr>() {
            Ok(ip) => {
                self.any_ip_on == Some(port) || self.ips.iter().any(|&(i, p)| i == ip && p == port)
            }
            Err(_) => self.names.iter().any(|(n, p)| {
                // One trailing dot is the same name written fully qualified (`localhost.`);
                // more are no name at all.
                n.eq_ignore_ascii_case(host.strip_suffix('.').unwrap_or(&host))
                    && p.is_none_or(|p| p == port)
            }),
        }
    }
}

/// `host`, `host:port`, `[v6]:port` → host (without brackets) and port.
fn split_host(value: &str) -> Option<(String, Option<u16>)> {
    if value.contains('@') {
        return None;
    }
    let authority: axum::http::uri::Authority = value.parse().ok()?;
    let host = authority.host();
    let host = host
        .strip_prefix('[')
        .and_then(|h| h.strip_suffix(']'))
        .unwrap_or(host);
    Some((host.to_string(), authority.port_u16()))
}

/// What the guards check.
struct Guards {
    token: Option<Arc<str>>,
    origins: Vec<String>,
    hosts: Option<Hosts>,
    max_body_bytes: usize,
}

impl Guards {
    fn check(&self, req: &Request) -> Result<(), ApiError> {
        let headers: &HeaderMap = req.headers();
        // RFC 9112 §3.2: an HTTP/1.1 request has exactly one Host; a target in absolute form
        // names the host itself, which must then be the one the Host header names.
        let mut hosts_given = headers.get_all(header::HOST).iter();
        let host = hosts_given.next();
        let bad_host = |message: &str| Err(ApiError::new(ErrorKind::Malformed, "host", message));
        if hosts_given.next().is_some() {
            return bad_host("more than one Host header");
        }
        if host.is_none() && req.version() == axum::http::Version::HTTP_11 {
            return bad_host("an HTTP/1.1 request needs a Host header");
        }
        if let Some(target) = req.uri().authority()
            && req.version() <= axum::http::Version::HTTP_11
            && !host.is_some_and(|h| {
                h.as_bytes()
                    .eq_ignore_ascii_case(target.as_str().as_bytes())
            })
        {
            return bad_host("the request target names another host than the Host header");
        }
        // A declared body past the limit is refused before it is waited for.
        if let Some(length) = headers.get(header::CONTENT_LENGTH)
            && length
                .to_str()
                .ok()
                .and_then(|l| l.parse::<u64>().ok())
                .is_some_and(|l| l > self.max_body_bytes as u64)
        {
            return Err(ApiError::new(
                ErrorKind::TooLarge,
                "",
                format!(
                    "the body is declared larger than the server's limit of {} bytes",
                    self.max_body_bytes
                ),
            ));
        }
        if let Some(hosts) = &self.hosts
            && let Some(host) = host
            && !host.to_str().is_ok_and(|h| hosts.allows(h))
        {
            return Err(ApiError::new(
                ErrorKind::Forbidden,
                "host",
                "the Host header names another server (start the server with --allow-host for names it is reached by)",
            ));
        }
        if let Some(origin) = headers.get(header::ORIGIN)
            && !origin
                .to_str()
                .is_ok_and(|o| self.origins.iter().any(|a| a.eq_ignore_ascii_case(o)))
        {
            return Err(ApiError::new(
                ErrorKind::Forbidden,
                "origin",
                "requests from browser pages are refused unless their origin is allowed (--cors-origin)",
            ));
        }
        if let Some(token) = &self.token
            && req.uri().path() != "/health"
        {
            let given = headers
                .get(header::AUTHORIZATION)
                .and_then(|v| v.to_str().ok())
                .and_then(|v| v.trim_start().split_once(' '))
                .filter(|(scheme, _)| scheme.eq_ignore_ascii_case("bearer"))
                .map(|(_, t)| t.trim());
            if !given.is_some_and(|g| same(g.as_bytes(), token.as_bytes())) {
                return Err(ApiError::new(
                    ErrorKind::Unauthorized,
                    "authorization",
                    "a valid `Authorization: Bearer <token>` header is required",
                ));
            }
        }
        Ok(())
    }
}

async fn guard(State(guards): State<Arc<Guards>>, req: Request, next: Next) -> Response {
    match guards.check(&req) {
        Ok(()) => next.run(req).await,
        Err(e) => e.into_response(),
    }
}

/// The service's router.
///
/// # Errors
/// An empty token, a CORS origin that is not a valid header value, an allowed host that is not
/// a host name.
pub fn router(service: Arc<Service>, options: &HttpOptions) -> Result<Router, ApiError> {
    options.validate()?;
    let hosts = options
        .listen
        .map(|l| Hosts::new(l, &options.allowed_hosts))
        .transpose()?;
    let guards = Arc::new(Guards {
        token: options.token.as_deref().map(Arc::from),
        origins: options.cors_origins.clone(),
        hosts,
        max_body_bytes: options.max_body_bytes,
    });
    let doc: Arc<str> = Arc::from(
        document(
            options,
            &service.strategy_names(),
            &service.options().limits,
        )
        .to_string(),
    );
    let mut app = routes()
        .0
        .route(
            "/openapi.json",
            get(move || {
                let doc = doc.clone();
                async move { json_response(StatusCode::OK, doc.to_string()) }
            }),
        )
        .fallback(not_found)
        .method_not_allowed_fallback(method_not_allowed)
        .with_state(service)
        .layer(DefaultBodyLimit::max(options.max_body_bytes))
        .layer(middleware::from_fn_with_state(guards, guard));
    if !options.cors_origins.is_empty() {
        let origins = options.origins()?;
        app = app.layer(
            CorsLayer::new()
                .allow_origin(AllowOrigin::list(origins))
                .allow_methods([Method::GET, Method::POST])
                .allow_headers([
                    header::AUTHORIZATION,
                    header::CONTENT_TYPE,
                    header::HeaderName::from_static(IDEMPOTENCY_KEY),
                ]),
        );
    }
    Ok(app)
}
