//! A service on a real socket (127.0.0.1, an ephemeral port) for tests that talk HTTP to it.

use std::path::Path;
use std::sync::Arc;

use ferret_serve::{HttpOptions, ServeOptions, Service, ServiceOptions, Store};
use ferret_world::GridParams;
use serde_json::Value;

use super::strategies;

pub struct Server {
    pub url: String,
    pub client: reqwest::Client,
    pub handle: tokio::task::JoinHandle<()>,
    pub service: Arc<Service>,
}

impl Drop for Server {
    fn drop(&mut self) {
        self.handle.abort();
    }
}

pub async fn start(db: Option<&Path>, token: Option<&str>) -> Server {
    start_with(
        db,
        token,
        ServiceOptions::default(),
        ServeOptions::default(),
    )
    .await
}

/// A server on 127.0.0.1 with these options, offering the scene `flat`.
pub async fn start_with(
    db: Option<&Path>,
    token: Option<&str>,
    service_options: ServiceOptions,
    serve_options: ServeOptions,
) -> Server {
    start_http(db, service_options, serve_options, |o| {
        o.token = token.map(str::to_string);
    })
    .await
}

/// A server on 127.0.0.1 with these options and HTTP options set by `http`, offering the
/// scene `flat`.
pub async fn start_http(
    db: Option<&Path>,
    service_options: ServiceOptions,
    serve_options: ServeOptions,
    http: impl FnOnce(&mut HttpOptions),
) -> Server {
    // The store waits on its database from blocking threads, as the service runs it.
    let service = tokio::task::block_in_place(|| {
        let store = match db {
            Some(p) => Store::open(p).unwrap(),
            None => super::store(),
        };
        let service =
            Service::with_options(store, GridParams::default(), strategies(), service_options)
                .unwrap();
        service.add_scene("flat", super::flat()).unwrap();
        service
    });
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    let mut options = HttpOptions {
        listen: Some(addr),
        ..HttpOptions::default()
    };
    http(&mut options);
    let service = Arc::new(service);
    let app = ferret_serve::router(service.clone(), &options).unwrap();
    let handle = tokio::spawn(async move {
        ferret_serve::serve(listener, app, serve_options, std::future::pending())
            .await
            .unwrap();
    });
    Server {
        url: format!("http://{addr}"),
        client: reqwest::Client::new(),
        handle,
        service,
    }
}

impl Server {
    pub async fn post(&self, path: &str, body: Value) -> (u16, Value) {
        let r = self
            .client
            .post(format!("{}{path}", self.url))
            .json(&body)
            .send()
            .await
            .unwrap();
        (r.status().as_u16(), r.json().await.unwrap())
    }

    pub async fn post_raw(&self, path: &str, body: &'static str) -> (u16, Value) {
        let r = self
            .client
            .post(format!("{}{path}", self.url))
            .header("content-type", "application/json")
            .body(body)
            .send()
            .await
            .unwrap();
        (r.status().as_u16(), r.json().await.unwrap())
    }

    pub async fn get(&self, path: &str) -> (u16, Value) {
        let r = self
            .client
            .get(format!("{}{path}", self.url))
            .send()
            .await
            .unwrap();
        (r.status().as_u16(), r.json().await.unwrap())
    }
}

/// A replica on the shared PostgreSQL database at `url`, offering the scene `flat`, on
/// 127.0.0.1: its URL and the task serving it.
pub async fn replica(url: &str) -> (String, tokio::task::JoinHandle<()>) {
    let service = tokio::task::block_in_place(|| {
        let service =
            Service::new(super::connect(url), GridParams::default(), strategies()).unwrap();
        service.add_scene("flat", super::flat()).unwrap();
        service
    });
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    let options = HttpOptions {
        listen: Some(addr),
        ..HttpOptions::default()
    };
    let app = ferret_serve::router(Arc::new(service), &options).unwrap();
    let handle = tokio::spawn(async move {
        ferret_serve::serve(
            listener,
            app,
            ServeOptions::default(),
            std::future::pending(),
        )
        .await
        .unwrap();
    });
    (format!("http://{addr}"), handle)
}
