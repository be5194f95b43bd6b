//! The HTTP layer: routes, JSON in and out, bearer-token check, optional CORS, the OpenAPI
//! document. Handlers parse the body (naming the field a bad body gets wrong) and hand the work
//! to [`Service`] on a blocking thread: planning and SQLite are synchronous, and an LLM
//! strategy blocks on its own runtime.

use std::sync::Arc;

use axum::body::Bytes;
use axum::extract::{Path, Request, State};
use axum::http::{HeaderMap, HeaderValue, Method, StatusCode, header};
use axum::middleware::{self, Next};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use axum::{Json, Router};
use serde::de::DeserializeOwned;
use tower_http::cors::{AllowOrigin, CorsLayer};
use utoipa::OpenApi;

use crate::api::{
    CreateDeployment, DeploymentState, ErrorBody, ErrorDetail, Observe, SceneDetail, SceneSummary,
    StartTrial, TrialState, UploadScene,
};
use crate::error::ApiError;
use crate::service::{Reply, Service};

/// How the router guards itself.
#[derive(Clone, Debug, Default)]
pub struct HttpOptions {
    /// When set, every route but `/health` needs `Authorization: Bearer <token>`.
    pub token: Option<String>,
    /// Origins allowed to call from a browser; empty = CORS off.
    pub cors_origins: Vec<String>,
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let status = StatusCode::from_u16(self.status).unwrap_or(StatusCode::INTERNAL_SERVER_ERROR);
        if status.is_server_error() {
            tracing::warn!(status = self.status, message = %self.message, "request failed");
        }
        let body = ErrorBody {
            error: ErrorDetail {
                status: self.status,
                field: self.field,
                message: self.message,
            },
        };
        (status, Json(body)).into_response()
    }
}

fn reply(r: Result<Reply, ApiError>) -> Response {
    match r {
        Ok((status, body)) => (
            StatusCode::from_u16(status).unwrap_or(StatusCode::OK),
            Json(body),
        )
            .into_response(),
        Err(e) => e.into_response(),
    }
}

/// Parses a JSON body; a failure names the field (`objects[2]`, `pose`).
fn parse<T: DeserializeOwned>(body: &[u8]) -> Result<T, ApiError> {
    let mut de = serde_json::Deserializer::from_slice(body);
    let value: T = serde_path_to_error::deserialize(&mut de).map_err(|e| {
        let path = e.path().to_string();
        let inner = e.into_inner();
        let field = if path == "." { String::new() } else { path };
        ApiError::new(400, field, format!("malformed request: {inner}"))
    })?;
    de.end()
        .map_err(|e| ApiError::new(400, "", format!("malformed request: {e}")))?;
    Ok(value)
}

fn id(raw: &str, what: &str) -> Result<i64, ApiError> {
    raw.parse::<i64>()
        .ok()
        .filter(|v| *v > 0)
        .ok_or_else(|| ApiError::new(404, what, format!("{raw:?} is not a {what} id")))
}

/// Runs a service call on the blocking pool.
async fn blocking(f: impl FnOnce() -> Result<Reply, ApiError> + Send + 'static) -> Response {
    match tokio::task::spawn_blocking(f).await {
        Ok(r) => reply(r),
        Err(e) => ApiError::internal(format!("the request's worker failed: {e}")).into_response(),
    }
}

#[utoipa::path(get, path = "/health", responses((status = 200, description = "The service is up")))]
async fn health() -> Response {
    Json(serde_json::json!({"status": "ok"})).into_response()
}

#[utoipa::path(get, path = "/scenes", responses((status = 200, body = [SceneSummary])))]
async fn list_scenes(State(s): State<Arc<Service>>) -> Response {
    blocking(move || s.list_scenes()).await
}

#[utoipa::path(get, path = "/scenes/{name}", params(("name" = String, Path, description = "Scene name")),
    responses((status = 200, body = SceneDetail), (status = 404, body = ErrorBody)))]
async fn get_scene(State(s): State<Arc<Service>>, Path(name): Path<String>) -> Response {
    blocking(move || s.get_scene(&name)).await
}

#[utoipa::path(post, path = "/scenes", request_body = UploadScene,
    responses((status = 201, body = SceneDetail), (status = 409, body = ErrorBody), (status = 422, body = ErrorBody)))]
async fn upload_scene(State(s): State<Arc<Service>>, body: Bytes) -> Response {
    blocking(move || {
        let req: UploadScene = parse(&body)?;
        s.upload_scene(req, &body)
    })
    .await
}

#[utoipa::path(post, path = "/deployments", request_body = CreateDeployment,
    responses((status = 201, body = DeploymentState), (status = 422, body = ErrorBody)))]
async fn create_deployment(State(s): State<Arc<Service>>, body: Bytes) -> Response {
    blocking(move || {
        let req: CreateDeployment = parse(&body)?;
        s.create_deployment(req, &body)
    })
    .await
}

#[utoipa::path(get, path = "/deployments/{id}", params(("id" = i64, Path, description = "Deployment id")),
    responses((status = 200, body = DeploymentState), (status = 404, body = ErrorBody)))]
async fn get_deployment(State(s): State<Arc<Service>>, Path(raw): Path<String>) -> Response {
    blocking(move || s.get_deployment(id(&raw, "deployment")?)).await
}

#[utoipa::path(post, path = "/deployments/{id}/trials", request_body = StartTrial,
    params(("id" = i64, Path, description = "Deployment id")),
    responses((status = 201, body = TrialState), (status = 404, body = ErrorBody),
        (status = 409, body = ErrorBody), (status = 422, body = ErrorBody)))]
async fn start_trial(
    State(s): State<Arc<Service>>,
    Path(raw): Path<String>,
    body: Bytes,
) -> Response {
    blocking(move || {
        let d = id(&raw, "deployment")?;
        let req: StartTrial = parse(&body)?;
        s.start_trial(d, req, &body)
    })
    .await
}

#[utoipa::path(get, path = "/trials/{id}", params(("id" = i64, Path, description = "Trial id")),
    responses((status = 200, body = TrialState), (status = 404, body = ErrorBody)))]
async fn get_trial(State(s): State<Arc<Service>>, Path(raw): Path<String>) -> Response {
    blocking(move || s.get_trial(id(&raw, "trial")?)).await
}

#[utoipa::path(post, path = "/trials/{id}/observations", request_body = Observe,
    params(("id" = i64, Path, description = "Trial id")),
    responses((status = 200, body = TrialState), (status = 404, body = ErrorBody),
        (status = 409, body = ErrorBody), (status = 422, body = ErrorBody)))]
async fn observe(State(s): State<Arc<Service>>, Path(raw): Path<String>, body: Bytes) -> Response {
    blocking(move || {
        let t = id(&raw, "trial")?;
        let req: Observe = parse(&body)?;
        s.observe(t, req, &body)
    })
    .await
}

/// The OpenAPI document.
#[derive(OpenApi)]
#[openapi(
    info(
        title = "ferret serve",
        description = "LLM-informed object search for a real robot: scenes, deployments with strategy selection, trials step by step. See docs/serve.md."
    ),
    paths(
        health,
        list_scenes,
        get_scene,
        upload_scene,
        create_deployment,
        get_deployment,
        start_trial,
        get_trial,
        observe
    ),
    components(schemas(ErrorBody, ErrorDetail))
)]
pub struct ApiDoc;

async fn openapi() -> Response {
    Json(ApiDoc::openapi()).into_response()
}

async fn not_found() -> Response {
    ApiError::new(404, "", "no such route; see /openapi.json").into_response()
}

async fn method_not_allowed() -> Response {
    ApiError::new(
        405,
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

async fn check_token(
    State(token): State<Option<Arc<str>>>,
    headers: HeaderMap,
    req: Request,
    next: Next,
) -> Response {
    if let Some(token) = token
        && req.uri().path() != "/health"
    {
        let given = headers
            .get(header::AUTHORIZATION)
            .and_then(|v| v.to_str().ok())
            .and_then(|v| v.strip_prefix("Bearer "));
        if !given.is_some_and(|g| same(g.as_bytes(), token.as_bytes())) {
            return ApiError::new(
                401,
                "authorization",
                "a valid `Authorization: Bearer <token>` header is required",
            )
            .into_response();
        }
    }
    next.run(req).await
}

/// The service's router.
///
/// # Errors
/// A CORS origin that is not a valid header value.
pub fn router(service: Arc<Service>, options: &HttpOptions) -> Result<Router, ApiError> {
    let token: Option<Arc<str>> = options.token.as_deref().map(Arc::from);
    let mut app = Router::new()
        .route("/health", get(health))
        .route("/openapi.json", get(openapi))
        .route("/scenes", get(list_scenes).post(upload_scene))
        .route("/scenes/{name}", get(get_scene))
        .route("/deployments", post(create_deployment))
        .route("/deployments/{id}", get(get_deployment))
        .route("/deployments/{id}/trials", post(start_trial))
        .route("/trials/{id}", get(get_trial))
        .route("/trials/{id}/observations", post(observe))
        .fallback(not_found)
        .method_not_allowed_fallback(method_not_allowed)
        .with_state(service)
        .layer(middleware::from_fn_with_state(token, check_token));
    if !options.cors_origins.is_empty() {
        let origins = options
            .cors_origins
            .iter()
            .map(|o| {
                HeaderValue::from_str(o).map_err(|_| {
                    ApiError::new(400, "cors-origin", format!("{o:?} is not a valid origin"))
                })
            })
            .collect::<Result<Vec<_>, _>>()?;
        app = app.layer(
            CorsLayer::new()
                .allow_origin(AllowOrigin::list(origins))
                .allow_methods([Method::GET, Method::POST])
                .allow_headers([header::AUTHORIZATION, header::CONTENT_TYPE]),
        );
    }
    Ok(app)
}
