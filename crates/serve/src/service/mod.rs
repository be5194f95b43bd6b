//! The service: one [`Service`] over a store and the candidate strategies, with the limits it
//! enforces. What each route does lives with its resource (`scenes`,
//! `deployments`, `trials`); every write goes through
//! `replies` for request-id idempotency, and planning reads its grids from
//! `grids`. Every operation reads what it needs from the store, plans without
//! holding the database, then writes its rows and its reply in one transaction (checking nothing
//! changed in between).
//!
//! Memory is bounded whatever the database holds: uploaded scenes stay in the store and are
//! read when a request needs them, and the grids and distances planning needs are built on
//! demand into a cache of bounded size, a few at a time.

mod deployments;
mod replies;
mod scenes;
mod starts;
mod tasks;
mod teams;
mod trials;

use std::collections::BTreeMap;
use std::sync::{Arc, RwLock};
use std::time::{SystemTime, UNIX_EPOCH};

use ferret_plan::Strategy;
use ferret_world::{GridParams, Scene};
use serde::Serialize;

use crate::api::{SceneSummary, TrialState};
use crate::error::ApiError;
use crate::events::Events;
use crate::grids::Grids;
use crate::model::{ApiReply, Outcome, SceneLimits};
use crate::store::Store;

/// How long a team robot's claim holds without a word from it, by default: a robot drives a
/// few metres and searches a container in well under a minute.
pub const DEFAULT_CLAIM_TTL: std::time::Duration = std::time::Duration::from_secs(60);

/// How the service bounds its work.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ServiceOptions {
    /// Limits on uploaded scenes.
    pub limits: SceneLimits,
    /// Memory the built grids and distances may hold, bytes; the least recently used are
    /// dropped past it (and built again when asked for).
    pub grid_cache_bytes: usize,
    /// Grids built (or searched from a new pose) at once; more requests that need one wait.
    /// One scene's work takes one at a time, so with two or more a heavy scene never holds up
    /// the others.
    pub concurrent_builds: usize,
    /// Searches of open trials kept between requests (see `searches`), at most this many; 0
    /// rebuilds every search from the store. An exact planner's table is up to 8 MiB (16
    /// containers), so this bounds that memory too.
    pub live_searches: usize,
    /// Replay costs each placed scene (a scene seen from one pose) keeps for trials that end
    /// the same way again (see [`ferret_plan::ReplayMemo`]); 0 replays every candidate at
    /// every trial end.
    pub kept_replays: usize,
    /// Candidate sets whose plans' first steps each scene keeps (see
    /// [`ferret_plan::PlanMemo`]; about 500 bytes each), for searches and replays that meet a
    /// set another one solved: the same decisions without solving; 0 solves every time.
    pub kept_plans: usize,
    /// Event streams (`GET /events`, the live page's) open at once, at most.
    pub max_event_streams: usize,
    /// How long a team robot's claim on a container holds without a word from it: past it,
    /// a teammate may be sent there.
    pub claim_ttl: std::time::Duration,
}

impl Default for ServiceOptions {
    fn default() -> Self {
        Self {
            limits: SceneLimits::default(),
            grid_cache_bytes: 256 << 20,
            // At least two, so that one scene's work (which holds one at a time) never holds
            // every other scene's up.
            concurrent_builds: std::thread::available_parallelism().map_or(2, |n| n.get().max(2)),
            live_searches: 64,
            kept_replays: 4096,
            kept_plans: 2048,
            max_event_streams: crate::events::DEFAULT_MAX_STREAMS,
            claim_ttl: DEFAULT_CLAIM_TTL,
        }
    }
}

/// The scenes the service offers.
#[derive(Default)]
pub(crate) struct Scenes {
    /// Given on the command line: loaded for good.
    pub(crate) fixed: BTreeMap<String, (Arc<Scene>, SceneSummary)>,
    /// Uploaded: only what the list shows; the scene is read from the store when needed.
    pub(crate) uploaded: BTreeMap<String, SceneSummary>,
}

/// Trials whose latest state a replica keeps for reads (a few hundred bytes to a few KB each).
const KEPT_STATES: usize = 4096;

/// The most trial starts of one deployment stored in one transaction: enough for a fleet's
/// burst, few enough that one failed statement costs little to redo.
const MAX_STARTS_TOGETHER: usize = 64;

/// Deployments whose selectors a replica keeps between requests. A selector holds its
/// deployment's costs (8 bytes per candidate and trial): 1 024 deployments of 2 000 trials of
/// 3 candidates are 48 MiB.
const KEPT_SELECTORS: usize = 1024;

/// The service: what each route does, without HTTP. Its methods live with their resource:
/// scenes, deployments, trials; request-id replies and the grid cache have modules of their own.
pub struct Service {
    pub(crate) store: Store,
    pub(crate) candidates: Vec<Arc<dyn Strategy>>,
    pub(crate) options: ServiceOptions,
    pub(crate) scenes: RwLock<Scenes>,
    pub(crate) grids: Grids,
    /// Open trials' searches kept between requests.
    pub(crate) searches: crate::searches::Searches,
    /// Deployments' selectors kept between requests.
    pub(crate) selectors: crate::selectors::Selectors,
    /// Trial starts waiting for their deployment's lock on this replica, made together.
    pub(crate) starts: crate::gather::Gather<i64, starts::StartJob, starts::Gathered>,
    /// Request ids being run on this replica now.
    pub(crate) in_flight: std::sync::Mutex<std::collections::HashSet<String>>,
    /// Deployments' specs read so far: a spec never changes once stored, and every request of
    /// a trial needs its deployment's.
    pub(crate) specs:
        std::sync::Mutex<std::collections::HashMap<i64, crate::model::DeploymentSpec>>,
    /// What changed, for the pages watching.
    pub(crate) events: Arc<Events>,
    /// Trials' states as their last writes answered them.
    pub(crate) recent: crate::recent::RecentStates,
    /// What each candidate said of each scene's names (strategy, line), by scene.
    pub(crate) language:
        std::sync::Mutex<std::collections::HashMap<String, Arc<scenes::SceneLanguage>>>,
}

impl std::fmt::Debug for Service {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Service")
            .field("candidates", &self.candidates.len())
            .field("options", &self.options)
            .finish_non_exhaustive()
    }
}

/// A reply of `value` as JSON.
pub(crate) fn json<T: Serialize>(outcome: Outcome, value: &T) -> Result<ApiReply, ApiError> {
    serde_json::to_string(value)
        .map(|body| ApiReply { outcome, body })
        .map_err(|e| ApiError::internal(format!("serializing a reply: {e}")))
}

impl Service {
    /// How many trial starts this replica stored together with other starts of their
    /// deployment (robots of a fleet starting at once) since it started.
    pub fn starts_made_together(&self) -> u64 {
        self.starts.together()
    }

    /// A service over `store`, offering `candidates` (strategies built by the caller, the same
    /// registry as `ferret eval`), planning on grids with `grid`, with the default limits.
    ///
    /// # Errors
    /// See [`Service::with_options`].
    pub fn new(
        store: Store,
        grid: GridParams,
        candidates: Vec<Arc<dyn Strategy>>,
    ) -> Result<Service, ApiError> {
        Self::with_options(store, grid, candidates, ServiceOptions::default())
    }

    /// A service with `options`. Scenes uploaded earlier are listed from the store without
    /// being loaded, so start-up takes the same time whatever the store holds.
    ///
    /// # Errors
    /// No candidates, a candidate that needs the ground truth (the oracle), options of zero,
    /// or a store that cannot be read.
    pub fn with_options(
        store: Store,
        grid: GridParams,
        candidates: Vec<Arc<dyn Strategy>>,
        options: ServiceOptions,
    ) -> Result<Service, ApiError> {
        if candidates.is_empty() {
            return Err(ApiError::internal("no candidate strategies"));
        }
        if let Some(s) = candidates.iter().find(|s| s.needs_ground_truth()) {
            return Err(ApiError::internal(format!(
                "{} reads the ground truth, which a robot does not have; it cannot be a candidate",
                s.name()
            )));
        }
        if options.concurrent_builds == 0 {
            return Err(ApiError::internal(
                "concurrent grid builds must be at least 1",
            ));
        }
        let uploaded = store
            .read(|r| r.scene_summaries())?
            .into_iter()
            .map(|(name, rooms, containers)| {
                let s = SceneSummary {
                    name: name.clone(),
                    rooms,
                    containers,
                    has_map: false,
                };
                (name, s)
            })
            .collect();
        let events = Arc::new(Events::new(options.max_event_streams));
        let hub = events.clone();
        let deliver: crate::store::Deliver = Arc::new(move |text: Option<String>| match text {
            Some(text) => hub.hear(&text),
            None => hub.resync_all(),
        });
        let watched = events.clone();
        let feed = crate::store::FeedOptions {
            every: crate::events::HEARTBEAT,
            sender: events.replica().to_string(),
            max_bytes: crate::events::MAX_NOTIFICATION,
            lost: crate::events::lost_word(),
            beat: Arc::new(move || watched.watching_word()),
        };
        if let Some(outbox) =
            store.feed(crate::events::CHANNEL, crate::events::RING, deliver, feed)?
        {
            events.route_through(outbox);
        }
        Ok(Service {
            language: std::sync::Mutex::default(),
            events,
            recent: crate::recent::RecentStates::new(KEPT_STATES),
            store,
            candidates,
            options,
            scenes: RwLock::new(Scenes {
                fixed: BTreeMap::new(),
                uploaded,
            }),
            grids: Grids::new(
                grid,
                options.grid_cache_bytes,
                options.concurrent_builds,
                (options.kept_replays, options.kept_plans),
            ),
            in_flight: std::sync::Mutex::default(),
            specs: std::sync::Mutex::default(),
            searches: crate::searches::Searches::new(options.live_searches),
            selectors: crate::selectors::Selectors::new(KEPT_SELECTORS),
            starts: crate::gather::Gather::new(MAX_STARTS_TOGETHER),
        })
    }

    /// Replays at trial ends answered from kept replay costs (see
    /// [`ServiceOptions::kept_replays`]) instead of simulated, counted over the scenes whose
    /// grids are still cached.
    pub fn replays_reused(&self) -> u64 {
        self.grids.replays_reused()
    }

    /// Planner decisions taken from plans kept in the scenes now cached instead of solved.
    pub fn plans_reused(&self) -> u64 {
        self.grids.plans_reused()
    }

    /// True when the store is PostgreSQL, which other replicas may share (their events reach
    /// this replica's watchers).
    pub fn is_shared(&self) -> bool {
        self.store.is_shared()
    }

    /// The hub of live events (`GET /events`).
    pub fn events(&self) -> &Events {
        &self.events
    }

    /// What a write that committed made of a trial (after recording `observed`, if it did):
    /// kept for reads of it, and told to the pages watching.
    pub(crate) fn told(&self, state: TrialState, observed: Option<crate::api::ObservationInfo>) {
        if self.events.wanted() {
            self.events.trial(&state, observed);
        }
        self.recent.keep(Arc::new(state));
    }

    /// The limits it enforces.
    pub fn options(&self) -> &ServiceOptions {
        &self.options
    }

    /// Bytes the cached grids and distances hold now (at most
    /// [`ServiceOptions::grid_cache_bytes`]).
    pub fn grid_cache_bytes(&self) -> usize {
        self.grids.cached_bytes()
    }

    /// Whole grids with their distance matrices built so far: what a scene costs the first time
    /// it is used (or again after the cache dropped it), for monitoring.
    pub fn grids_built(&self) -> u64 {
        self.grids.built()
    }

    /// Open trials whose search is kept between requests now (at most
    /// [`ServiceOptions::live_searches`]).
    pub fn live_searches(&self) -> usize {
        self.searches.len()
    }

    /// The scenes with a grid in the cache, each once, sorted.
    pub fn cached_grids(&self) -> Vec<String> {
        self.grids.cached_scenes()
    }

    /// The candidates' names, in order.
    pub fn strategy_names(&self) -> Vec<String> {
        self.candidates
            .iter()
            .map(|s| s.name().to_string())
            .collect()
    }

    /// `GET /health`: done when the store answers and its file reads whole, else unavailable.
    pub fn health(&self) -> Result<ApiReply, ApiError> {
        match self
            .store
            .read(|r| r.check())
            .and_then(|()| self.store.check_file())
        {
            Ok(()) => Ok(ApiReply {
                outcome: Outcome::Done,
                body: r#"{"status":"ok"}"#.to_string(),
            }),
            Err(e) => {
                tracing::error!("health check: {e}");
                Err(ApiError::unavailable(
                    "",
                    "the database cannot be read; see the server's log",
                ))
            }
        }
    }
}

/// Milliseconds since the Unix epoch, on this replica's clock (replicas sharing a database
/// must agree on the time to well within a claim's time).
pub(super) fn now_ms() -> i64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| i64::try_from(d.as_millis()).unwrap_or(i64::MAX))
}
