//! The live view: the page a browser opens at `/` (three files embedded in the binary, served
//! under a Content-Security-Policy that allows only them) and the event stream it reads
//! (`GET /events`, Server-Sent Events). The page holds no data: it asks for the token and reads
//! everything through the API with it, so serving it needs no token.

use std::convert::Infallible;
use std::sync::Arc;
use std::time::Duration;

use axum::extract::State;
use axum::http::{HeaderValue, header};
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{IntoResponse, Response};
use futures_util::StreamExt;

use crate::error::{ApiError, ErrorKind};
use crate::events::TooManyStreams;
use crate::service::Service;

/// The page's files, with their paths and types.
pub(super) const PAGE: [(&str, &str, &str); 3] = [
    (
        "/",
        "text/html; charset=utf-8",
        include_str!("../../ui/index.html"),
    ),
    (
        "/ui/app.js",
        "text/javascript; charset=utf-8",
        include_str!("../../ui/app.js"),
    ),
    (
        "/ui/app.css",
        "text/css; charset=utf-8",
        include_str!("../../ui/app.css"),
    ),
];

/// Only the page's own files, only its own server to talk to: no inline script or style, no
/// other origin, no frames, no forms posted anywhere.
pub(super) const CSP: &str = "default-src 'none'; script-src 'self'; style-src 'self'; \
    connect-src 'self'; img-src 'self' data:; base-uri 'none'; form-action 'none'; \
    frame-ancestors 'none'";

/// Whether `path` is one of the page's files (served without a token).
pub(super) fn is_page(path: &str) -> bool {
    PAGE.iter().any(|(p, _, _)| *p == path)
}

/// One of the page's files.
pub(super) fn page_file(content_type: &'static str, body: &'static str) -> Response {
    let mut response = ([(header::CONTENT_TYPE, content_type)], body).into_response();
    let h = response.headers_mut();
    h.insert(
        header::CONTENT_SECURITY_POLICY,
        HeaderValue::from_static(CSP),
    );
    h.insert(
        header::X_CONTENT_TYPE_OPTIONS,
        HeaderValue::from_static("nosniff"),
    );
    h.insert(
        header::REFERRER_POLICY,
        HeaderValue::from_static("no-referrer"),
    );
    h.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-cache"));
    response
}

/// How often an idle stream sends a comment, so that proxies and the page see it alive.
const KEEP_ALIVE: Duration = Duration::from_secs(15);

#[utoipa::path(get, path = "/events", responses(
    (status = 200, description = "Server-Sent Events: `hello` first (`{\"shared\": bool}`), then `trial` (a trial started, searched a container or ended: id, deployment, k, scene, target, strategy, status, searched, next, cost_m), `deployment` (`{\"deployment\": id}`, created) and `resync` (`{\"missed\": n}`: this stream fell behind and lost events; read the state again). With replicas on one PostgreSQL, every replica's events.", content_type = "text/event-stream", body = String),
    (status = 503, description = "As many event streams are open as the server allows (--max-event-streams); retry later", body = crate::api::ErrorBody)))]
pub(super) async fn events(State(s): State<Arc<Service>>) -> Response {
    let watcher = match s.events().watch() {
        Ok(w) => w,
        Err(TooManyStreams { max }) => {
            return ApiError::new(
                ErrorKind::Unavailable,
                "",
                format!(
                    "{max} event streams are open, as many as this server allows (--max-event-streams); retry later"
                ),
            )
            .into_response();
        }
    };
    let hello = Event::default()
        .event("hello")
        .data(serde_json::json!({ "shared": s.is_shared() }).to_string());
    let rest = futures_util::stream::unfold(watcher, |mut w| async move {
        let frame = w.next().await?;
        Some((Event::default().event(&frame.name).data(&frame.data), w))
    });
    let stream = futures_util::stream::once(async { hello })
        .chain(rest)
        .map(Ok::<_, Infallible>);
    let mut response = Sse::new(stream)
        .keep_alive(KeepAlive::new().interval(KEEP_ALIVE))
        .into_response();
    response
        .headers_mut()
        .insert(header::CACHE_CONTROL, HeaderValue::from_static("no-store"));
    response
}
