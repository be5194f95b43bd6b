//! # ferret-serve
//!
//! ferret as a service a real robot calls: it owns the HTTP API (`ferret serve`), the scenes a
//! robot lives in, live deployments and step-by-step trials, and their storage in SQLite or in a
//! PostgreSQL database that several replicas share. It adds no planner, simulator or selector of
//! its own: a trial step is `ferret_plan::Search`, the replays after a trial are
//! `ferret_plan::replay_costs`, and a deployment's choices are `ferret_select::LiveDeployment`'s.
//! The modules follow the API's resources (`scenes`, `deployments`, `trials`) around the data
//! they share ([`model`]); [`store`] keeps it, `replies` makes writes safe to retry,
//! `selectors` keeps deployments' selectors between requests, `gather` stores together the
//! trial starts that wait for one deployment's lock, `grids` builds and caches what planning
//! needs, and [`http`] only parses, calls and answers. Everything is written to the database
//! before a reply leaves, and every in-memory state is rebuilt from the rows, so a killed server
//! resumes where it stopped; replies to requests carrying a `request_id` are stored too, so a
//! robot can retry safely. See docs/serve.md.

pub mod api;
mod deployments;
pub mod error;
mod gather;
mod grids;
pub mod http;
pub mod model;
mod replies;
mod scenes;
mod searches;
mod selectors;
pub mod server;
pub mod service;
pub mod store;
mod trials;

pub use error::{ApiError, ErrorKind};
pub use http::{ApiDoc, HttpOptions, document, router};
pub use model::{ApiReply, Outcome};
pub use server::{ServeOptions, serve};
pub use service::{SceneLimits, Service, ServiceOptions};
pub use store::{PostgresOptions, Store, is_postgres_url};
