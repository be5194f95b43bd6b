//! The live view: the page a browser opens at `/` (three files embedded in the binary, served
//! under a Content-Security-Policy that allows only them) and the event stream it reads
//! (`GET /events`, Server-Sent Events). The page holds no data: it asks for the token and reads
//! everything through the API with it, so serving it needs no token.

use std::convert::Infallible;
use std::sync::Arc;
use std::time::Duration;

use axum::body::Body;
use axum::extract::{RawQuery, State};
use axum::http::{HeaderValue, header};
use axum::response::{IntoResponse, Response};
use bytes::Bytes;
use futures_util::StreamExt;

use crate::error::{ApiError, ErrorKind};
use crate::events::{Frame, HELLO, HelloEvent, TooManyStreams, json_of};
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

/// How often a stream sends a comment, so that proxies and the page see it alive.
const KEEP_ALIVE: Duration = Duration::from_secs(15);

#[utoipa::path(get, path = "/events",
    params(("deployment" = Option<i64>, Query, description = "Only this deployment's trials (and every new deployment)", minimum = 1)),
    responses(
    (status = 200, description = "Server-Sent Events, each one line of JSON data: `hello` first (`HelloEvent`), then `trial` (`TrialEvent`: a trial started, searched a container or ended), `deployment` (`DeploymentEvent`: created) and `resync` (`ResyncEvent`: this stream lost events; read the state again). With replicas on one PostgreSQL, every replica's events. A comment line (`: keep-alive`) every 15 s.", content_type = "text/event-stream"),
    (status = 400, description = "The query is not `deployment=<id>`", body = crate::api::ErrorBody),
    (status = 503, description = "As many event streams are open as the server allows (--max-event-streams); retry later", body = crate::api::ErrorBody)))]
/// The stream is written here rather than with axum's `Sse`, which sends each event as a write
/// of its own: events that arrive together go out together.
pub(super) async fn events(State(s): State<Arc<Service>>, query: RawQuery) -> Response {
    let only = match only_deployment(query.0.as_deref()) {
        Ok(only) => only,
        Err(e) => return e.into_response(),
    };
    let watcher = match s.events().watch(only) {
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
    let hello = format!(
        "event: {HELLO}\ndata: {}\n\n",
        json_of(&HelloEvent {
            shared: s.is_shared()
        })
    );
    let first = futures_util::stream::once(async move { Bytes::from(hello) });
    let rest = futures_util::stream::unfold(
        (
            watcher,
            tokio::time::interval_at(tokio::time::Instant::now() + KEEP_ALIVE, KEEP_ALIVE),
        ),
        |(mut w, mut tick)| async move {
            let frame = tokio::select! {
                f = w.next() => f?,
                _ = tick.tick() => return Some((Bytes::from_static(b": keep-alive\n\n"), (w, tick))),
            };
            // Events that are already waiting go out in the same write: a busy fleet's events
            // cost the server one write per burst rather than one per event.
            let mut text = String::with_capacity(256);
            write_event(&mut text, &frame);
            for _ in 1..MAX_EVENTS_PER_WRITE {
                match w.try_next() {
                    Some(f) => write_event(&mut text, &f),
                    None => break,
                }
            }
            Some((Bytes::from(text), (w, tick)))
        },
    );
    let body = Body::from_stream(first.chain(rest).map(Ok::<_, Infallible>));
    let mut response = body.into_response();
    let h = response.headers_mut();
    h.insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static("text/event-stream"),
    );
    h.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-store"));
    response
}

/// Most events sent in one write.
const MAX_EVENTS_PER_WRITE: usize = 64;

/// `frame` as Server-Sent Events text (its data is one line of JSON).
fn write_event(out: &mut String, frame: &Frame) {
    out.push_str("event: ");
    out.push_str(&frame.name);
    out.push_str("\ndata: ");
    out.push_str(&frame.data);
    out.push_str("\n\n");
}

/// The deployment a stream's query names (`deployment=<id>`), if any.
fn only_deployment(query: Option<&str>) -> Result<Option<i64>, ApiError> {
    let Some(query) = query.filter(|q| !q.is_empty()) else {
        return Ok(None);
    };
    let bad = || {
        ApiError::new(
            ErrorKind::Malformed,
            "deployment",
            format!("{query:?}: the stream takes only `deployment=<id>`, a positive integer"),
        )
    };
    let id = query.strip_prefix("deployment=").ok_or_else(bad)?;
    // Digits only: `+1`, ` 1` and `01x` are not ids.
    if id.is_empty() || !id.bytes().all(|b| b.is_ascii_digit()) {
        return Err(bad());
    }
    match id.parse::<i64>() {
        Ok(id) if id >= 1 => Ok(Some(id)),
        _ => Err(bad()),
    }
}
