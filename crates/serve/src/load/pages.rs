//! Browser pages watching the fleet, as the live page behaves (crates/serve/ui/app.js). Each
//! reads `GET /events` on its replica (only the deployment it shows, once it shows one) and
//! fetches only what it shows: a trial's picture when it starts watching the trial (the events
//! then carry each step; it reads the picture again after a gap, and once the trial is done
//! for its replays), its deployment when one
//! of the deployment's trials ends (at most every 500 ms), the list of deployments when one is
//! created, everything again on `resync`. A stalled page opens the stream and never reads it:
//! a client that stopped reading. Pages never poll.
//!
//! This is a model of the page's request pattern for the load test, not a second page: the
//! browser tests drive the real one.

use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use serde::Serialize;
use tokio::sync::watch;

/// What the pages did.
#[derive(Clone, Debug, Default, Serialize)]
pub struct PagesReport {
    /// Pages that read their stream.
    pub pages: usize,
    /// Pages that opened their stream and never read it.
    pub stalled_pages: usize,
    /// Events the reading pages received, in all.
    pub events: usize,
    /// `resync` events among them (a page fell behind).
    pub resyncs: usize,
    /// Requests the pages made besides their streams.
    pub fetches: usize,
    /// Streams that could not be opened or broke.
    pub stream_errors: usize,
}

/// Counters the pages share.
#[derive(Default)]
pub(super) struct Counts {
    events: AtomicUsize,
    resyncs: AtomicUsize,
    fetches: AtomicUsize,
    stream_errors: AtomicUsize,
}

impl Counts {
    pub(super) fn report(&self, pages: usize, stalled_pages: usize) -> PagesReport {
        PagesReport {
            pages,
            stalled_pages,
            events: self.events.load(Ordering::Relaxed),
            resyncs: self.resyncs.load(Ordering::Relaxed),
            fetches: self.fetches.load(Ordering::Relaxed),
            stream_errors: self.stream_errors.load(Ordering::Relaxed),
        }
    }
}

/// The least time between two fetches of a deployment, as the page waits.
const DEPLOYMENT_EVERY: Duration = Duration::from_millis(500);

/// One event of a stream: its name and data.
fn parse(block: &str) -> Option<(String, serde_json::Value)> {
    let (mut name, mut data) = (None, String::new());
    for line in block.lines() {
        if let Some(v) = line.strip_prefix("event:") {
            name = Some(v.trim().to_string());
        } else if let Some(v) = line.strip_prefix("data:") {
            data.push_str(v.trim());
        }
    }
    Some((name?, serde_json::from_str(&data).ok()?))
}

/// A page that reads its stream until `stop`.
pub(super) async fn page(
    client: reqwest::Client,
    url: String,
    counts: Arc<Counts>,
    mut stop: watch::Receiver<bool>,
) {
    let fetch = |path: String| {
        let (client, url, counts) = (client.clone(), url.clone(), counts.clone());
        async move {
            counts.fetches.fetch_add(1, Ordering::Relaxed);
            if let Ok(r) = client.get(format!("{url}{path}")).send().await {
                let _ = r.bytes().await;
            }
        }
    };
    let open = |query: String| {
        let (client, url, counts) = (client.clone(), url.clone(), counts.clone());
        async move {
            match client.get(format!("{url}/events{query}")).send().await {
                Ok(r) if r.status().is_success() => Some(r),
                _ => {
                    counts.stream_errors.fetch_add(1, Ordering::Relaxed);
                    None
                }
            }
        }
    };
    let Some(mut stream) = open(String::new()).await else {
        return;
    };
    // What the page loads first.
    fetch("/scenes".into()).await;
    fetch("/deployments".into()).await;
    let mut buffer = String::new();
    // The page shows the first deployment it hears of, and watches its newest trial.
    let (mut selected, mut watched): (Option<i64>, Option<i64>) = (None, None);
    let mut last_deployment_fetch: Option<Instant> = None;
    let mut deployment_due = false;
    let mut scenes_seen = std::collections::BTreeSet::new();
    // Steps of the watched trial its page has drawn.
    let mut seen_steps: Option<u64> = None;
    loop {
        let chunk = tokio::select! {
            c = stream.chunk() => c,
            _ = stop.wait_for(|s| *s) => return,
        };
        let chunk = match chunk {
            Ok(Some(c)) => c,
            _ => {
                counts.stream_errors.fetch_add(1, Ordering::Relaxed);
                return;
            }
        };
        buffer.push_str(&String::from_utf8_lossy(&chunk));
        // Events that came in one read are coalesced, as the page coalesces them.
        let (mut view, mut list) = (false, false);
        while let Some(end) = buffer.find("\n\n") {
            let block: String = buffer.drain(..end + 2).collect();
            let Some((name, data)) = parse(&block) else {
                continue; // a keep-alive comment
            };
            counts.events.fetch_add(1, Ordering::Relaxed);
            match name.as_str() {
                "trial" => {
                    let (Some(t), Some(d)) = (data["trial"].as_i64(), data["deployment"].as_i64())
                    else {
                        continue;
                    };
                    if selected.is_none() {
                        // The page shows this deployment: from now on its stream carries only
                        // this deployment's trials (the page opens it again with the filter).
                        selected = Some(d);
                        let Some(filtered) = open(format!("?deployment={d}")).await else {
                            return;
                        };
                        stream = filtered;
                        buffer.clear();
                        watched = (data["status"] == "searching").then_some(t);
                        view = watched.is_some();
                        seen_steps = data["searched"].as_u64();
                        break;
                    }
                    if selected != Some(d) {
                        continue;
                    }
                    let searching = data["status"] == "searching";
                    let steps = data["searched"].as_u64();
                    if searching && steps == Some(0) && watched != Some(t) {
                        watched = Some(t);
                        if let Some(scene) = data["scene"].as_str()
                            && scenes_seen.insert(scene.to_string())
                        {
                            fetch(format!("/scenes/{scene}")).await;
                        }
                        view = true;
                        seen_steps = Some(0);
                    } else if watched == Some(t) {
                        // The events carry each step (the observation, the way to the next
                        // container): the picture is read again only after a gap, and at the
                        // end for the other strategies' replays, which no event carries.
                        if steps != seen_steps.map(|n| n + 1) || data["status"] == "done" {
                            view = true;
                        }
                        seen_steps = steps;
                    }
                    deployment_due |= !searching;
                }
                "deployment" => list = true,
                "resync" => {
                    counts.resyncs.fetch_add(1, Ordering::Relaxed);
                    (view, list, deployment_due) = (true, true, true);
                }
                _ => {}
            }
        }
        if view && let Some(t) = watched {
            fetch(format!("/trials/{t}/view")).await;
        }
        if deployment_due
            && let Some(d) = selected
            && last_deployment_fetch.is_none_or(|at| at.elapsed() >= DEPLOYMENT_EVERY)
        {
            last_deployment_fetch = Some(Instant::now());
            deployment_due = false;
            fetch(format!("/deployments/{d}")).await;
        }
        if list {
            fetch("/deployments".into()).await;
        }
    }
}

/// A page that opens its stream and then never reads it, until `stop`.
pub(super) async fn stalled_page(
    url: String,
    counts: Arc<Counts>,
    mut stop: watch::Receiver<bool>,
) {
    use tokio::io::AsyncWriteExt;
    let Some(authority) = url.strip_prefix("http://") else {
        counts.stream_errors.fetch_add(1, Ordering::Relaxed);
        return;
    };
    // A bare socket with a small receive buffer, so that the server's writes back up soon.
    let Ok(addr) = authority.parse::<std::net::SocketAddr>() else {
        counts.stream_errors.fetch_add(1, Ordering::Relaxed);
        return;
    };
    let socket = match addr {
        std::net::SocketAddr::V4(_) => tokio::net::TcpSocket::new_v4(),
        std::net::SocketAddr::V6(_) => tokio::net::TcpSocket::new_v6(),
    };
    let Ok(socket) = socket else {
        counts.stream_errors.fetch_add(1, Ordering::Relaxed);
        return;
    };
    let _ = socket.set_recv_buffer_size(4096);
    let Ok(mut conn) = socket.connect(addr).await else {
        counts.stream_errors.fetch_add(1, Ordering::Relaxed);
        return;
    };
    let request = format!("GET /events HTTP/1.1\r\nHost: {authority}\r\n\r\n");
    if conn.write_all(request.as_bytes()).await.is_err() {
        counts.stream_errors.fetch_add(1, Ordering::Relaxed);
        return;
    }
    let _ = stop.wait_for(|s| *s).await;
    drop(conn);
}
