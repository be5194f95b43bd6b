//! Serving the router on a TCP listener with the guards a robot's network needs: a deadline for
//! a request's headers and one for its body, an idle timeout for kept-alive connections, and a
//! cap on open connections. At the cap the connection idle the longest is closed to make room, so a client
//! that opens and holds many connections cannot lock a normal one out. A connection is idle only
//! while it has no request in flight and no reply still being written: an event stream open for
//! hours is never timed out nor evicted.
//!
//! Hand-written over hyper because `axum::serve` has no header timeout, idle timeout or cap,
//! and on running out of file descriptors it pauses accepting for a second at a time.

use std::collections::HashMap;
use std::future::Future;
use std::io;
use std::pin::Pin;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::task::{Context, Poll};
use std::time::{Duration, Instant};

use axum::Router;
use hyper::body::{Body, Bytes, Frame, Incoming, SizeHint};
use hyper_util::rt::{TokioIo, TokioTimer};
use tokio::net::TcpListener;
use tokio::sync::{Notify, watch};
use tower::ServiceExt;

/// How connections are guarded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ServeOptions {
    /// Time a client has to send a request's headers once it has connected or its previous
    /// reply was sent.
    pub header_timeout: Duration,
    /// Time a client has to send a request's whole body once its headers are in; past it the
    /// request is answered 408 and the connection closed. Without it, a client that sends part
    /// of a body and stops holds its connection (and, past the cap, everyone's) for good.
    pub body_timeout: Duration,
    /// A kept-alive connection with no request in flight is closed after this long.
    pub idle_timeout: Duration,
    /// Most connections open at once.
    pub max_connections: usize,
}

impl Default for ServeOptions {
    fn default() -> Self {
        Self {
            header_timeout: Duration::from_secs(10),
            body_timeout: Duration::from_secs(10),
            idle_timeout: Duration::from_secs(60),
            max_connections: 256,
        }
    }
}

/// One connection's state, shared between its task and the accept loop.
struct Conn {
    /// Requests in flight.
    busy: AtomicUsize,
    /// When it last became idle (connected, or a reply was sent), ms since the server started.
    idle_since: AtomicU64,
    /// Asks the connection to close (at the cap, or at shutdown).
    close: Notify,
}

struct Registry {
    started: Instant,
    next: AtomicU64,
    conns: Mutex<HashMap<u64, Arc<Conn>>>,
}

impl Registry {
    fn now_ms(&self) -> u64 {
        u64::try_from(self.started.elapsed().as_millis()).unwrap_or(u64::MAX)
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, HashMap<u64, Arc<Conn>>> {
        self.conns
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// Closes the connection idle the longest; false when every connection is busy.
    fn evict_idlest(&self) -> bool {
        let conns = self.lock();
        let idlest = conns
            .values()
            .filter(|c| c.busy.load(Ordering::SeqCst) == 0)
            .min_by_key(|c| c.idle_since.load(Ordering::SeqCst));
        match idlest {
            Some(c) => {
                // Marked busy so that the next eviction picks another while this one closes.
                c.busy.fetch_add(1, Ordering::SeqCst);
                c.close.notify_one();
                true
            }
            None => false,
        }
    }
}

/// Marks a request in flight on its connection until dropped (also when the request is
/// cancelled).
struct InFlight {
    conn: Arc<Conn>,
    registry: Arc<Registry>,
}

impl Drop for InFlight {
    fn drop(&mut self) {
        self.conn
            .idle_since
            .store(self.registry.now_ms(), Ordering::SeqCst);
        self.conn.busy.fetch_sub(1, Ordering::SeqCst);
    }
}

/// Serves `app` on `listener` until `shutdown` completes, then lets requests in flight finish
/// (for at most `header_timeout`) and closes every connection.
///
/// # Errors
/// Only a failure of the listener that is not about one connection.
pub async fn serve(
    listener: TcpListener,
    app: Router,
    options: ServeOptions,
    shutdown: impl Future<Output = ()>,
) -> io::Result<()> {
    let registry = Arc::new(Registry {
        started: Instant::now(),
        next: AtomicU64::new(0),
        conns: Mutex::new(HashMap::new()),
    });
    let (stop_tx, stop_rx) = watch::channel(false);
    let mut tasks = tokio::task::JoinSet::new();
    tokio::pin!(shutdown);
    loop {
        let accepted = tokio::select! {
            () = &mut shutdown => break,
            accepted = listener.accept() => accepted,
        };
        // Reap finished connection tasks so the set does not grow.
        while tasks.try_join_next().is_some() {}
        let (stream, _) = match accepted {
            Ok(s) => s,
            Err(e) if is_out_of_descriptors(&e) => {
                // Room is made by closing an idle connection; the pending one is accepted next.
                if !registry.evict_idlest() {
                    tracing::warn!("out of file descriptors with every connection busy");
                }
                tokio::time::sleep(Duration::from_millis(5)).await;
                continue;
            }
            // The client went away before we took it (ECONNABORTED and the like).
            Err(e) => {
                tracing::debug!("accept failed: {e}");
                continue;
            }
        };
        if registry.lock().len() >= options.max_connections && !registry.evict_idlest() {
            tracing::warn!(
                max = options.max_connections,
                "connection cap reached with every connection busy; refusing one"
            );
            drop(stream);
            continue;
        }
        let _ = stream.set_nodelay(true);
        let id = registry.next.fetch_add(1, Ordering::SeqCst);
        let conn = Arc::new(Conn {
            busy: AtomicUsize::new(0),
            idle_since: AtomicU64::new(registry.now_ms()),
            close: Notify::new(),
        });
        registry.lock().insert(id, conn.clone());
        tasks.spawn(connection(
            stream,
            app.clone(),
            options,
            conn,
            registry.clone(),
            id,
            stop_rx.clone(),
        ));
    }
    let _ = stop_tx.send(true);
    let drain = async { while tasks.join_next().await.is_some() {} };
    if tokio::time::timeout(options.header_timeout, drain)
        .await
        .is_err()
    {
        tasks.abort_all();
    }
    Ok(())
}

fn is_out_of_descriptors(e: &io::Error) -> bool {
    #[cfg(unix)]
    {
        matches!(e.raw_os_error(), Some(libc::EMFILE | libc::ENFILE))
    }
    #[cfg(not(unix))]
    {
        let _ = e;
        false
    }
}

async fn connection(
    stream: tokio::net::TcpStream,
    app: Router,
    options: ServeOptions,
    conn: Arc<Conn>,
    registry: Arc<Registry>,
    id: u64,
    mut stop: watch::Receiver<bool>,
) {
    let service = {
        let (conn, registry) = (conn.clone(), registry.clone());
        hyper::service::service_fn(move |req: hyper::Request<Incoming>| {
            conn.busy.fetch_add(1, Ordering::SeqCst);
            let guard = InFlight {
                conn: conn.clone(),
                registry: registry.clone(),
            };
            let app = app.clone();
            let body_timeout = options.body_timeout;
            async move {
                let req = req.map(|b| axum::body::Body::new(Deadline::new(b, body_timeout)));
                // The request stays in flight until its reply's body has been sent, not just its
                // headers: an event stream is a reply that lasts for hours, and a connection
                // writing one is neither idle (to be timed out) nor the idlest (to be evicted).
                let reply = app.oneshot(req).await;
                reply.map(|r| {
                    r.map(|body| {
                        axum::body::Body::new(Sending {
                            inner: body,
                            _in_flight: guard,
                        })
                    })
                })
            }
        })
    };
    let mut builder = hyper::server::conn::http1::Builder::new();
    builder
        .timer(TokioTimer::new())
        .header_read_timeout(options.header_timeout)
        .keep_alive(true);
    let served = builder.serve_connection(TokioIo::new(stream), service);
    tokio::pin!(served);
    let mut closing = false;
    loop {
        let idle_for = Duration::from_millis(
            registry
                .now_ms()
                .saturating_sub(conn.idle_since.load(Ordering::SeqCst)),
        );
        let idle_left = options.idle_timeout.saturating_sub(idle_for);
        tokio::select! {
            _ = served.as_mut() => break,
            () = conn.close.notified(), if !closing => {
                closing = true;
                served.as_mut().graceful_shutdown();
            }
            _ = stop.changed(), if !closing => {
                closing = true;
                served.as_mut().graceful_shutdown();
            }
            () = tokio::time::sleep(idle_left), if !closing => {
                let still_idle = conn.busy.load(Ordering::SeqCst) == 0
                    && registry.now_ms().saturating_sub(conn.idle_since.load(Ordering::SeqCst))
                        >= u64::try_from(options.idle_timeout.as_millis()).unwrap_or(u64::MAX);
                if still_idle {
                    closing = true;
                    served.as_mut().graceful_shutdown();
                }
            }
            // A connection asked to close that does not finish its reply in time is dropped.
            () = tokio::time::sleep(options.header_timeout), if closing => break,
        }
    }
    registry.lock().remove(&id);
}

/// A reply's body that keeps its request in flight until it has been sent (or dropped).
struct Sending {
    inner: axum::body::Body,
    _in_flight: InFlight,
}

impl Body for Sending {
    type Data = Bytes;
    type Error = axum::Error;

    fn poll_frame(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
    ) -> Poll<Option<Result<Frame<Bytes>, Self::Error>>> {
        Pin::new(&mut self.get_mut().inner).poll_frame(cx)
    }

    fn is_end_stream(&self) -> bool {
        self.inner.is_end_stream()
    }

    fn size_hint(&self) -> SizeHint {
        self.inner.size_hint()
    }
}

/// The error a request body gives when it has not arrived by its deadline.
#[derive(Debug, thiserror::Error)]
#[error("the request body did not arrive within {0:?}")]
pub struct BodyTimeout(pub Duration);

/// A request body that fails with [`BodyTimeout`] when it has not ended by a deadline, however
/// slowly its bytes trickle in.
struct Deadline {
    inner: Incoming,
    limit: Duration,
    /// Boxed: `Sleep` is not `Unpin`, and a body is polled through `Pin<&mut Self>`.
    deadline: Pin<Box<tokio::time::Sleep>>,
}

impl Deadline {
    fn new(inner: Incoming, limit: Duration) -> Self {
        Self {
            inner,
            limit,
            deadline: Box::pin(tokio::time::sleep(limit)),
        }
    }
}

impl Body for Deadline {
    type Data = Bytes;
    type Error = Box<dyn std::error::Error + Send + Sync>;

    fn poll_frame(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
    ) -> Poll<Option<Result<Frame<Bytes>, Self::Error>>> {
        let this = self.get_mut();
        match Pin::new(&mut this.inner).poll_frame(cx) {
            Poll::Ready(frame) => Poll::Ready(frame.map(|f| f.map_err(Into::into))),
            Poll::Pending => match this.deadline.as_mut().poll(cx) {
                Poll::Ready(()) => Poll::Ready(Some(Err(Box::new(BodyTimeout(this.limit))))),
                Poll::Pending => Poll::Pending,
            },
        }
    }

    fn is_end_stream(&self) -> bool {
        self.inner.is_end_stream()
    }

    fn size_hint(&self) -> SizeHint {
        self.inner.size_hint()
    }
}
