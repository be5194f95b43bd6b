//! The guards every request passes before its route: `Host`, a browser's `Origin`, the bearer
//! token.

use std::net::{IpAddr, SocketAddr};
use std::sync::Arc;

use axum::extract::{Request, State};
use axum::http::{HeaderMap, Method, header};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};

use crate::error::{ApiError, ErrorKind};

/// Equal-time comparison, so the token cannot be guessed byte by byte from response times.
/// (Hand-written: one loop, not worth a dependency.)
pub(super) fn same(a: &[u8], b: &[u8]) -> bool {
    a.len() == b.len() && a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

/// The `Host` values a request may carry.
#[derive(Debug, Default)]
pub(super) struct Hosts {
    /// Any IP address with this port (listening on an unspecified address).
    any_ip_on: Option<u16>,
    /// Addresses with their port.
    ips: Vec<(IpAddr, u16)>,
    /// Names, with a port or any.
    names: Vec<(String, Option<u16>)>,
}

impl Hosts {
    pub(super) fn new(listen: SocketAddr, allowed: &[String]) -> Result<Hosts, ApiError> {
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
pub(super) struct Guards {
    pub(super) token: Option<Arc<str>>,
    pub(super) origins: Vec<String>,
    pub(super) hosts: Option<Hosts>,
    pub(super) max_body_bytes: usize,
    pub(super) view_only: bool,
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
        // The page the server itself serves is of the server's own origin: its requests name
        // the Host checked above (so not a DNS-rebinding page's).
        let own_origin = |o: &str| {
            self.hosts.is_some()
                && host
                    .and_then(|h| h.to_str().ok())
                    .zip(o.strip_prefix("http://"))
                    .is_some_and(|(h, rest)| rest.eq_ignore_ascii_case(h))
        };
        if let Some(origin) = headers.get(header::ORIGIN)
            && !origin.to_str().is_ok_and(|o| {
                own_origin(o) || self.origins.iter().any(|a| a.eq_ignore_ascii_case(o))
            })
        {
            return Err(ApiError::new(
                ErrorKind::Forbidden,
                "origin",
                "requests from browser pages are refused unless their origin is allowed (--cors-origin)",
            ));
        }
        // A browser's CORS preflight carries no credentials (it cannot): past the Host and
        // Origin checks above, the CORS layer inside answers it.
        let preflight = *req.method() == Method::OPTIONS
            && !self.origins.is_empty()
            && headers.contains_key(header::ORIGIN)
            && headers.contains_key(header::ACCESS_CONTROL_REQUEST_METHOD);
        if preflight {
            return Ok(());
        }
        if let Some(token) = &self.token
            && req.uri().path() != "/health"
            && !super::view::is_page(req.uri().path())
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
        if self.view_only && !matches!(*req.method(), Method::GET | Method::HEAD) {
            return Err(ApiError::new(
                ErrorKind::Forbidden,
                "",
                "this server is view-only (--view-only): it serves the page and GET routes, no writes",
            ));
        }
        Ok(())
    }
}

pub(super) async fn guard(State(guards): State<Arc<Guards>>, req: Request, next: Next) -> Response {
    match guards.check(&req) {
        Ok(()) => next.run(req).await,
        Err(e) => e.into_response(),
    }
}
