//! # ferret-serve
//!
//! ferret as a service a real robot calls: it owns the HTTP API (`ferret serve`), the scenes a
//! robot lives in, live deployments and step-by-step trials, and their storage in SQLite. It
//! adds no planner, simulator or selector of its own: a trial step is `ferret_plan::Search`, the
//! replay after a trial is `ferret_plan::replay_costs`, selection is
//! `ferret_select::LiveDeployment`, the same pieces `ferret deploy` drives. Everything is
//! written to the database before a reply leaves, and every in-memory state is rebuilt from the
//! rows, so a killed server resumes where it stopped; replies to requests carrying a
//! `request_id` are stored too, so a robot can retry safely. See docs/serve.md.

pub mod api;
pub mod error;
pub mod http;
pub mod server;
pub mod service;
pub mod store;

pub use error::{ApiError, ErrorKind};
pub use http::{ApiDoc, HttpOptions, document, router};
pub use server::{ServeOptions, serve};
pub use service::{Outcome, Reply, SceneLimits, Service, ServiceOptions};
pub use store::Store;
