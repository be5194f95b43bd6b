//! # ferret-serve
//!
//! ferret as a service a real robot calls: it owns the HTTP API (`ferret serve`), the scenes a
//! robot lives in, live deployments and step-by-step trials, and their storage in SQLite or in a
//! PostgreSQL database that several replicas share. It adds no planner, simulator or selector of
//! its own: a trial step is `ferret_plan::Search`, the replays after a trial are
//! `ferret_plan::replay_costs`, and a deployment's choices are `ferret_select::LiveDeployment`'s.
//! The [`service`] (what each route does, without HTTP) keeps its methods with the API's
//! resources in its submodules (scenes, deployments, trial starts, trials, and the stored replies
//! that make writes safe to retry), over the data they share ([`model`]); [`store`] keeps it,
//! one module per table; `selectors` keeps deployments' selectors between requests, `gather`
//! stores together the trial starts that wait for one deployment's lock, `grids` builds and
//! caches what planning needs, and [`http`] only parses, calls and answers. Everything is
//! written to the database before a reply leaves, and every in-memory state is rebuilt from the
//! rows, so a killed server resumes where it stopped; replies to requests carrying a
//! `request_id` are stored too, so a robot can retry safely. See docs/serve.md.
//!
//! A scene served in-process and one trial driven as a robot would drive it over HTTP (the
//! handlers of `ferret serve` call these same methods with the request's JSON):
//!
//! ```
//! use ferret_plan::{PlannerConfig, StrategyRegistry};
//! use ferret_serve::{Service, Store};
//! use ferret_world::{GridParams, generate};
//! use serde_json::{Value, json};
//!
//! let scene = generate::default_scenes(1, 7)?.remove(0);
//! let (house, truth) = (scene.house.clone(), scene.truth.clone());
//! let registry = StrategyRegistry::builtin(None, PlannerConfig::default(), 16);
//! let candidates = vec![registry.build("model/uniform")?, registry.build("optimistic+greedy")?];
//! let service = Service::new(Store::in_memory()?, GridParams::default(), candidates)?;
//! service.add_scene("home", scene)?;
//!
//! let body = |v: Value| v.to_string().into_bytes();
//! let reply = |r: ferret_serve::ApiReply| serde_json::from_str::<Value>(&r.body);
//! let target = truth.target_types().into_iter().next().ok_or("no target")?;
//! let create = body(json!({}));
//! let deployment = reply(service.create_deployment(serde_json::from_slice(&create)?, &create)?)?;
//! let start = body(json!({"scene": "home", "target": target.to_string()}));
//! let id = deployment["id"].as_i64().ok_or("no deployment id")?;
//! let mut trial = reply(service.start_trial(id, serde_json::from_slice(&start)?, &start)?)?;
//! let mut searched = 0;
//! while let Some(container) = trial["next"]["container"].as_str().map(str::to_string) {
//!     // A real robot drives there and looks; the generated ground truth stands in for it.
//!     let c = house.container_index(&container).ok_or("unknown container")?;
//!     let found = truth.holds(c, &target);
//!     let seen = body(json!({"container": container, "found": found}));
//!     let t = trial["trial"].as_i64().ok_or("no trial id")?;
//!     trial = reply(service.record_observation(t, serde_json::from_slice(&seen)?, &seen)?)?;
//!     searched += 1;
//! }
//! assert_eq!(trial["status"], "done", "the target is in some container");
//! assert_eq!(trial["searched"].as_array().map(Vec::len), Some(searched));
//! assert!(trial["cost_m"].as_f64().is_some_and(|m| m > 0.0));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod api;
pub mod error;
pub mod events;
mod gather;
mod grids;
pub mod http;
pub mod load;
pub mod model;
mod recent;
mod searches;
mod selectors;
pub mod server;
pub mod service;
pub mod store;

pub use error::{ApiError, ErrorKind};
pub use http::{ApiDoc, HttpOptions, document, router};
pub use model::SceneLimits;
pub use model::{ApiReply, Outcome};
pub use server::{ServeOptions, serve};
pub use service::{Service, ServiceOptions};
pub use store::{PostgresOptions, Store, is_postgres_url};
