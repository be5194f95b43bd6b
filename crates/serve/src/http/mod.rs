//! The HTTP layer: routes, JSON in and out, the request guards, optional CORS, the OpenAPI
//! document. Handlers parse the body (naming the field a bad body gets wrong) and hand the work
//! to [`Service`] on a blocking thread: planning and SQLite are synchronous, and an LLM
//! strategy blocks on its own runtime.
//!
//! Every request passes the guards in this order: `Host` must name this server (403), a
//! browser's `Origin` must be one allowed for CORS (403), the bearer token must match when one
//! is set (401); then a route that takes a body wants JSON (415) no larger than the limit
//! (413), and other methods on a route are 405 whatever their body. A CORS preflight passes the
//! Host and Origin checks like any request, then is answered without a token. Together
//! they keep a web page the robot's operator happens to open from driving the robot (a form or
//! `text/plain` post, a DNS-rebinding page).

mod extract;
mod guards;
mod openapi;
mod view;

use std::net::SocketAddr;
use std::sync::Arc;

use axum::Router;
use axum::extract::{DefaultBodyLimit, State};
use axum::http::{HeaderValue, Method, StatusCode, header};
use axum::middleware;
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use tower_http::cors::{AllowOrigin, CorsLayer};
use utoipa::OpenApi;
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

use crate::api::{
    AbandonTrial, ClaimNext, CreateDeployment, DeploymentState, DeploymentSummary, ErrorBody,
    Observe, SceneDetail, SceneMap, SceneSummary, StartTrial, TrialState, TrialView, UploadScene,
};
use crate::error::{ApiError, ErrorKind};
use crate::model::ApiReply;
use crate::service::Service;

use extract::{
    DeploymentId, IDEMPOTENCY_KEY, Id, JsonBody, SceneName, Segment, TrialId, json_response, reply,
};
use guards::{Guards, Hosts, guard};
pub use openapi::{ApiDoc, document};

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
    /// Serve the page and every `GET` route, refuse every write (403): a screen on the wall.
    pub view_only: bool,
}

impl Default for HttpOptions {
    fn default() -> Self {
        Self {
            token: None,
            cors_origins: Vec::new(),
            listen: None,
            allowed_hosts: Vec::new(),
            max_body_bytes: DEFAULT_MAX_BODY_BYTES,
            view_only: false,
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

#[utoipa::path(get, path = "/scenes/{name}/map", params(("name" = String, Path, description = "Scene name")),
    responses((status = 200, description = "The scene's occupancy grid, for drawing", body = SceneMap),
        (status = 404, description = "No scene of that name", body = ErrorBody)))]
async fn get_scene_map(
    State(s): State<Arc<Service>>,
    Segment(name, _): Segment<SceneName>,
) -> Response {
    blocking(move || s.scene_map(&name)).await
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

#[utoipa::path(get, path = "/deployments", responses((status = 200, description = "The newest 1000 deployments, ascending", body = [DeploymentSummary])))]
async fn list_deployments(State(s): State<Arc<Service>>) -> Response {
    blocking(move || s.list_deployments()).await
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

#[utoipa::path(get, path = "/trials/{id}/view", params(("id" = i64, Path, description = "Trial id", minimum = 1)),
    responses((status = 200, description = "The trial with its way so far, what it saw and the likelihood of every container now (the live page's picture)", body = TrialView),
        (status = 404, description = "No trial of that id", body = ErrorBody),
        (status = 503, description = "A strategy could not plan (an LLM endpoint is down); retry later", body = ErrorBody)))]
async fn trial_view(State(s): State<Arc<Service>>, Id(trial, _): Id<TrialId>) -> Response {
    blocking(move || s.trial_view(trial)).await
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

#[utoipa::path(post, path = "/trials/{id}/claims", request_body = ClaimNext,
    operation_id = "claim",
    params(("id" = i64, Path, description = "Trial id", minimum = 1), ("Idempotency-Key" = Option<String>, Header, description = "The request id, as the request_id field (either, or both the same)")),
    responses((status = 200, description = "The team's trial, with the container claimed for the robot that asked in `next` (none while everything left is claimed by its teammates, or once the trial has ended); asking again renews the claim", body = TrialState),
        (status = 404, description = "No such trial", body = ErrorBody),
        (status = 422, description = "The trial has no team, or the robot is not one of its robots", body = ErrorBody),
        (status = 503, description = "A strategy could not plan (an LLM endpoint is down); retry later", body = ErrorBody)))]
async fn claim_container(
    State(s): State<Arc<Service>>,
    Id(trial, _): Id<TrialId>,
    b: JsonBody<ClaimNext>,
) -> Response {
    blocking(move || s.claim_container(trial, b.value, &b.raw)).await
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

/// Every route with its handler, each declared once: the path and method come from the
/// handler's OpenAPI attribute. Returns the router and the OpenAPI document the attributes say.
fn routes() -> (Router<Arc<Service>>, utoipa::openapi::OpenApi) {
    OpenApiRouter::with_openapi(ApiDoc::openapi())
        .routes(routes!(health))
        .routes(routes!(list_scenes, upload_scene))
        .routes(routes!(get_scene))
        .routes(routes!(get_scene_map))
        .routes(routes!(create_deployment, list_deployments))
        .routes(routes!(get_deployment))
        .routes(routes!(start_trial))
        .routes(routes!(get_trial))
        .routes(routes!(post_observation))
        .routes(routes!(claim_container))
        .routes(routes!(abandon_trial))
        .routes(routes!(trial_view))
        .routes(routes!(view::events))
        .split_for_parts()
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
        view_only: options.view_only,
    });
    let doc: Arc<str> = Arc::from(
        document(
            options,
            &service.strategy_names(),
            &service.options().limits,
        )
        .to_string(),
    );
    let mut api = routes().0;
    for (path, content_type, body) in view::PAGE {
        api = api.route(
            path,
            get(move || async move { view::page_file(content_type, body) }),
        );
    }
    let mut app = api
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
        .layer(DefaultBodyLimit::max(options.max_body_bytes));
    // Inside the guards: a preflight from a foreign Host or Origin is refused like any request.
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
    let app = app.layer(middleware::from_fn_with_state(guards, guard));
    Ok(app)
}
