//! What changed, told live to whoever watches (the browser page of `GET /events`): a trial
//! started, searched a container, ended; a deployment was created. The service tells the
//! [`Events`] hub after each write has committed, so a watcher that reads on an event sees what
//! the event announced.
//!
//! On SQLite (one server) the hub hands an event to its watchers at once. On PostgreSQL the
//! event goes out as a `NOTIFY` and every replica's listening session (this one's too) hands it
//! to its own watchers, so a page on one replica sees the trials a robot drives through another.
//! Whatever cannot travel that way (an event too long, a replica gone before it sent its last
//! ones) reaches the other replicas' watchers as a `resync`, never as silence.
//!
//! Memory is bounded whatever the watchers do: every watcher reads the same ring of the last
//! [`RING`] events; one that falls further behind (a client that stops reading) loses the oldest
//! and is told to read everything again (`resync`), rather than the server keeping a queue per
//! watcher. Open streams are capped (`max_streams`); past the cap a watcher is refused.

use std::collections::{BTreeMap, BTreeSet, HashMap, VecDeque};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

use serde::{Deserialize, Serialize};
use tokio::sync::{broadcast, mpsc, watch};

use crate::api::{ObservationInfo, TrialState};
use crate::model::TrialStatus;

/// Events kept for watchers that are behind; older ones are dropped for the slowest.
pub const RING: usize = 1024;

/// Default most event streams open at once.
pub const DEFAULT_MAX_STREAMS: usize = 32;

/// The PostgreSQL channel events travel on between replicas.
pub(crate) const CHANNEL: &str = "ferret_events";

/// What a replica with watchers says on the channel (when its watchers change, then every
/// [`HEARTBEAT`]), with the deployments they watch (`watching\n3,7`, or `watching\n*` for
/// all): replicas publish through the database only the events another replica's watchers
/// want, since notifications cost the database and every replica (a fleet nobody watches pays
/// nothing). A replica's own watchers get its events directly.
pub(crate) const WATCHING: &str = "watching";

/// Longest notification a replica sends: PostgreSQL takes payloads under 8000 bytes. Events
/// published together go in one notification up to it.
pub(crate) const MAX_NOTIFICATION: usize = 7_900;

/// Longest trial event: one that would be longer goes without the way to its next container,
/// then without its observation (a page then reads the trial's picture).
const MAX_EVENT: usize = 7_000;

/// Longest list of deployments a replica says it watches; past it, it says it watches all
/// (more events than its pages want, rather than a word too long for a notification).
const MAX_WATCHING_LIST: usize = 4_000;

/// How often a replica with watchers says so.
pub(crate) const HEARTBEAT: std::time::Duration = std::time::Duration::from_secs(5);

/// How long a replica publishes after it last heard that someone watches.
const LEASE: std::time::Duration = std::time::Duration::from_secs(15);

/// Events a replica that publishes nothing keeps, for a watcher that comes: those of the last
/// [`KEEP_UNHEARD`] go out when it hears of it, so that a page sees every event from the moment
/// it connected, however long the word took to reach the replica.
const KEEP_UNHEARD: std::time::Duration = std::time::Duration::from_secs(2);

/// One event as a stream sends it: its name and its JSON data (one line).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Frame {
    /// `trial`, `deployment` or `resync`.
    pub name: String,
    /// Its data: compact JSON, no newline.
    pub data: String,
    /// The deployment a `trial` event is of (streams of one deployment skip the others').
    pub deployment: Option<i64>,
}

impl Frame {
    /// The frame as one text (name, newline, data), how it travels between replicas.
    pub(crate) fn encode(&self) -> String {
        format!("{}\n{}", self.name, self.data)
    }

    /// A frame from [`Frame::encode`]'s text; `None` for anything else (a stranger's `NOTIFY` on
    /// the channel is ignored, not passed on to pages).
    pub(crate) fn decode(text: &str) -> Option<Frame> {
        let (name, data) = text.split_once('\n')?;
        if !matches!(name, TRIAL | DEPLOYMENT | RESYNC) || data.contains('\n') {
            return None;
        }
        // Read for its deployment only; the rest is checked to be JSON without being kept.
        #[derive(Deserialize)]
        struct Head {
            deployment: Option<i64>,
        }
        let head: Head = serde_json::from_str(data).ok()?;
        if name == RESYNC {
            // Another replica's word that its events were lost on the way: whatever it counted,
            // this replica cannot tell how many of them its watchers wanted.
            return Some(resync_unknown());
        }
        Some(Frame {
            name: name.to_string(),
            data: data.to_string(),
            deployment: (name == TRIAL).then_some(head.deployment).flatten(),
        })
    }
}

/// The event every stream starts with.
pub const HELLO: &str = "hello";
/// A trial started, searched a container, or ended ([`TrialEvent`]).
pub const TRIAL: &str = "trial";
/// A deployment was created ([`DeploymentEvent`]).
pub const DEPLOYMENT: &str = "deployment";
/// The stream lost events: read the state again ([`ResyncEvent`]).
pub const RESYNC: &str = "resync";

/// The first event of every stream.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct HelloEvent {
    /// Whether the stream carries the events of every replica (replicas sharing one
    /// PostgreSQL) rather than this server's only.
    pub shared: bool,
}

/// A deployment was created.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct DeploymentEvent {
    /// Its id.
    pub deployment: i64,
}

/// The stream fell behind and lost events, or the replica lost the events of others: read the
/// state again.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct ResyncEvent {
    /// How many events this stream lost; null when the replica cannot tell (it lost its
    /// listening session, and with it other replicas' events).
    pub missed: Option<u64>,
}

/// Every kind of event a stream sends, with the name of its data's schema in the OpenAPI
/// document: what the document's description of `GET /events` is made from.
pub const EVENT_SCHEMAS: [(&str, &str); 4] = [
    (HELLO, "HelloEvent"),
    (TRIAL, "TrialEvent"),
    (DEPLOYMENT, "DeploymentEvent"),
    (RESYNC, "ResyncEvent"),
];

/// A trial as its event tells it: enough for a page's list of trials, not its whole state.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct TrialEvent {
    /// Its id.
    pub trial: i64,
    /// Its deployment.
    pub deployment: i64,
    /// 1-based position in the deployment.
    pub k: i64,
    /// The scene's name.
    pub scene: String,
    /// The target.
    pub target: String,
    /// The strategy chosen for it.
    pub strategy: String,
    /// Where it stands.
    pub status: TrialStatus,
    /// Containers searched so far.
    pub searched: usize,
    /// The container to search next, while searching.
    pub next: Option<String>,
    /// Map distance travelled so far (its cost once ended), metres.
    pub cost_m: f64,
    /// The way to the next container (cell centres), while searching: with `observed`, a page
    /// that shows the trial follows it without asking for its picture again.
    pub next_path: Option<Vec<[f64; 2]>>,
    /// The observation this event reports, when it reports one.
    pub observed: Option<ObservationInfo>,
    /// Whose trial it is: the robot that started it alone and named itself, or a team's
    /// robots joined by `,`.
    pub robot: Option<String>,
}

impl TrialEvent {
    /// The event of a trial now in `t`, after `observed` when it reports an observation.
    pub fn new(t: &TrialState, observed: Option<ObservationInfo>) -> Self {
        TrialEvent {
            trial: t.trial,
            deployment: t.deployment,
            k: t.k,
            scene: t.scene.clone(),
            target: t.target.clone(),
            strategy: t.strategy.clone(),
            status: t.status,
            searched: t.searched.len(),
            next: t.next.as_ref().map(|n| n.container.clone()),
            cost_m: t.cost_m,
            next_path: t.next.as_ref().map(|n| n.path.clone()),
            observed,
            robot: crate::model::whose(
                t.robot.as_deref(),
                t.robots.iter().flatten().map(|r| r.id.as_str()),
            ),
        }
    }
}

/// An event's data as a stream sends it: one line of JSON. Its types hold numbers, strings and
/// options only, which always serialize.
pub(crate) fn json_of(event: &impl Serialize) -> String {
    serde_json::to_string(event).unwrap_or_default()
}

/// Another replica's watchers: until when (ms on the hub's clock) and which deployments they
/// watch (`None`: all).
type Lease = (u64, Option<BTreeSet<i64>>);

/// The hub: publishes events and hands out streams of them.
pub struct Events {
    ring: broadcast::Sender<Arc<Frame>>,
    /// When the hub was made: the clock of `others`.
    started: std::time::Instant,
    /// Other replicas with watchers, until when (ms after `started`) and which
    /// deployments they watch (`None`: all).
    others: Mutex<HashMap<String, Lease>>,
    /// What this replica's watchers watch, and the way to the other replicas.
    watching: Arc<Watching>,
    /// Replicas on PostgreSQL: the events of the last [`KEEP_UNHEARD`] that no other replica wanted,
    /// with when and their deployment.
    unheard: Mutex<VecDeque<(u64, Option<i64>, String)>>,
    /// This replica's name on the channel: what it hears from itself it has delivered already.
    replica: String,
    open: Arc<AtomicUsize>,
    max_streams: AtomicUsize,
    closed: watch::Sender<bool>,
}

impl std::fmt::Debug for Events {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Events")
            .field("open", &self.open.load(Ordering::Relaxed))
            .finish_non_exhaustive()
    }
}

impl Default for Events {
    fn default() -> Self {
        Self::new(DEFAULT_MAX_STREAMS)
    }
}

/// Refused: as many streams are open as allowed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TooManyStreams {
    /// The cap.
    pub max: usize,
}

impl Events {
    /// A hub handing events straight to its watchers, with at most `max_streams` open.
    pub fn new(max_streams: usize) -> Self {
        let (ring, _) = broadcast::channel(RING);
        let (closed, _) = watch::channel(false);
        Self {
            ring,
            started: std::time::Instant::now(),
            others: Mutex::default(),
            watching: Arc::default(),
            unheard: Mutex::default(),
            replica: format!(
                "{}-{:x}",
                std::process::id(),
                std::time::SystemTime::now()
                    .duration_since(std::time::UNIX_EPOCH)
                    .map_or(0, |d| d.as_nanos())
            ),
            open: Arc::new(AtomicUsize::new(0)),
            max_streams: AtomicUsize::new(max_streams),
            closed,
        }
    }

    /// From now on, events for the other replicas go to the database (`outbox`), and theirs
    /// come through [`Events::hear`] from this replica's listener. Set once, when the service
    /// is made; a second call changes nothing.
    pub(crate) fn route_through(&self, outbox: mpsc::Sender<String>) {
        let _ = self.watching.outbox.set(outbox);
    }

    /// Where events for the other replicas go: `None` on one server (SQLite).
    fn outbox(&self) -> Option<&mpsc::Sender<String>> {
        self.watching.outbox.get()
    }

    /// Tells every watcher `frame` (from the listener, or directly on one server).
    pub(crate) fn deliver(&self, frame: Frame) {
        // No watcher is not an error: nobody is looking.
        let _ = self.ring.send(Arc::new(frame));
    }

    fn now_ms(&self) -> u64 {
        u64::try_from(self.started.elapsed().as_millis()).unwrap_or(u64::MAX)
    }

    /// Whether this replica has watchers.
    pub(crate) fn watched_here(&self) -> bool {
        self.ring.receiver_count() > 0
    }

    /// This replica's name on the channel: every notification it sends begins with it.
    pub(crate) fn replica(&self) -> &str {
        &self.replica
    }

    /// A notification heard on the channel: `<sender>\n` then frames (or [`WATCHING`])
    /// separated by blank lines. What this replica sent itself is skipped (its watchers had
    /// it at once), and what is not ours ignored.
    pub(crate) fn hear(&self, payload: &str) {
        let Some((sender, blocks)) = payload.split_once('\n') else {
            return;
        };
        if sender == self.replica {
            return;
        }
        for block in blocks.split("\n\n") {
            if let Some(which) = block
                .strip_prefix(WATCHING)
                .and_then(|r| r.strip_prefix('\n'))
            {
                let wanted = (which != "*").then(|| {
                    which
                        .split(',')
                        .filter_map(|d| d.parse::<i64>().ok())
                        .collect()
                });
                self.heard_watching(sender, wanted);
            } else if let Some(frame) = Frame::decode(block) {
                self.deliver(frame);
            } else {
                tracing::debug!("ignored a notification that is not an event");
            }
        }
    }

    /// Replica `sender` watches the deployments `wanted` (`None`: all): publish their events
    /// through the database for a while, beginning with those kept meanwhile.
    pub(crate) fn heard_watching(&self, sender: &str, wanted: Option<BTreeSet<i64>>) {
        let lease = u64::try_from(LEASE.as_millis()).unwrap_or(u64::MAX);
        // Held throughout, as `publish` holds it from its choice to its keeping: an event
        // published meanwhile is either sent by it or found here, never left kept.
        let mut unheard = lock(&self.unheard);
        let now = self.now_ms();
        lock(&self.others).insert(sender.to_string(), (now.saturating_add(lease), wanted));
        let (send, keep): (Vec<_>, Vec<_>) = unheard
            .drain(..)
            .partition(|(_, d, _)| self.others_want(*d, now));
        unheard.extend(keep);
        if let Some(outbox) = self.outbox() {
            for (_, _, text) in send {
                let _ = outbox.try_send(text);
            }
        }
    }

    /// Whether another replica's watchers want an event of `deployment` (`None`: not a
    /// trial's) now. Called with `unheard` held (the lock order is `unheard`, then `others`).
    fn others_want(&self, deployment: Option<i64>, now: u64) -> bool {
        lock(&self.others).values().any(|(until, wanted)| {
            *until > now
                && match (wanted, deployment) {
                    (None, _) | (_, None) => true,
                    (Some(ids), Some(d)) => ids.contains(&d),
                }
        })
    }

    /// What this replica says on the channel about its watchers now, if it has any.
    pub(crate) fn watching_word(&self) -> Option<String> {
        self.watching.word()
    }

    /// Publishes `frame`: to this replica's watchers, and on PostgreSQL to the other replicas'
    /// through the database while one of them has watchers (else it is kept a moment, for a
    /// watcher on its way).
    /// Never waits: when the database falls behind by a whole ring, the event is dropped
    /// (watchers see it in the next state they read).
    pub(crate) fn publish(&self, frame: Frame) {
        let Some(outbox) = self.outbox() else {
            self.deliver(frame);
            return;
        };
        let text = frame.encode();
        let deployment = frame.deployment;
        if self.watched_here() {
            self.deliver(frame);
        }
        let mut unheard = lock(&self.unheard);
        let now = self.now_ms();
        if self.others_want(deployment, now) {
            if outbox.try_send(text).is_err() {
                tracing::warn!("event dropped: the database is behind on notifications");
            }
            return;
        }
        let keep = u64::try_from(KEEP_UNHEARD.as_millis()).unwrap_or(u64::MAX);
        while unheard
            .front()
            .is_some_and(|(at, _, _)| now.saturating_sub(*at) > keep)
            || unheard.len() >= RING
        {
            unheard.pop_front();
        }
        unheard.push_back((now, deployment, text));
    }

    /// Whether an event is worth making: through the database always (when nobody watches it
    /// is kept a moment, for a watcher on its way), else only while this replica has a
    /// watcher.
    pub(crate) fn wanted(&self) -> bool {
        self.outbox().is_some() || self.watched_here()
    }

    /// Publishes a trial's state after a write (that recorded `observed`, if any).
    pub(crate) fn trial(&self, state: &TrialState, observed: Option<ObservationInfo>) {
        let mut event = TrialEvent::new(state, observed);
        let mut data = serde_json::to_string(&event);
        if data.as_ref().is_ok_and(|d| d.len() > MAX_EVENT) {
            event.next_path = None;
            data = serde_json::to_string(&event);
        }
        if data.as_ref().is_ok_and(|d| d.len() > MAX_EVENT) {
            event.observed = None;
            data = serde_json::to_string(&event);
        }
        match data {
            Ok(data) if data.len() <= MAX_EVENT => self.publish(Frame {
                name: TRIAL.into(),
                data,
                deployment: Some(state.deployment),
            }),
            // Names are bounded where they come in, so this is a safeguard: every watcher reads
            // again rather than one missing the trial's change.
            _ => self.publish(resync_unknown()),
        }
    }

    /// Publishes a new deployment.
    pub(crate) fn deployment(&self, id: i64) {
        self.publish(Frame {
            name: DEPLOYMENT.into(),
            data: json_of(&DeploymentEvent { deployment: id }),
            deployment: None,
        });
    }

    /// Every watcher told to read everything again (the listener lost its session, and with it
    /// the events meanwhile).
    pub(crate) fn resync_all(&self) {
        self.deliver(resync_unknown());
    }

    /// Streams open now.
    pub fn open_streams(&self) -> usize {
        self.open.load(Ordering::SeqCst)
    }

    /// Ends every stream (the server is stopping) and refuses new ones.
    pub fn close(&self) {
        let _ = self.closed.send(true);
    }

    /// A new watcher's stream: every event, or with `only` a deployment's id, that
    /// deployment's trials and the other events (new deployments, resync).
    ///
    /// # Errors
    /// [`TooManyStreams`] when the cap is reached.
    pub fn watch(&self, only: Option<i64>) -> Result<Watcher, TooManyStreams> {
        let max = self.max_streams.load(Ordering::SeqCst);
        let taken = self
            .open
            .fetch_update(Ordering::SeqCst, Ordering::SeqCst, |n| {
                (n < max && !*self.closed.borrow()).then_some(n + 1)
            });
        if taken.is_err() {
            return Err(TooManyStreams { max });
        }
        *lock(&self.watching.here).entry(only).or_default() += 1;
        let watcher = Watcher {
            only,
            ring: self.ring.subscribe(),
            closed: self.closed.subscribe(),
            _slot: Slot {
                open: self.open.clone(),
                watching: self.watching.clone(),
                only,
            },
        };
        self.watching.say();
        Ok(watcher)
    }
}

/// A stream's place under the cap and among what this replica watches, given back when the
/// stream ends however it ends.
#[derive(Debug)]
struct Slot {
    open: Arc<AtomicUsize>,
    watching: Arc<Watching>,
    only: Option<i64>,
}

impl Drop for Slot {
    fn drop(&mut self) {
        self.open.fetch_sub(1, Ordering::SeqCst);
        {
            let mut here = lock(&self.watching.here);
            if let Some(n) = here.get_mut(&self.only) {
                *n -= 1;
                if *n == 0 {
                    here.remove(&self.only);
                }
            }
        }
        // A page that moved to one deployment's stream narrows what others send at once.
        self.watching.say();
    }
}

/// What this replica's watchers watch, and what it last said of it on the channel.
#[derive(Debug, Default)]
struct Watching {
    /// How many watch each deployment (`None`: all).
    here: Mutex<BTreeMap<Option<i64>, usize>>,
    /// What this replica last said.
    said: Mutex<Option<String>>,
    /// Where to say it, and where events for the other replicas go (replicas on PostgreSQL).
    outbox: std::sync::OnceLock<mpsc::Sender<String>>,
}

impl Watching {
    /// What to say now: [`WATCHING`] with the deployments watched, if any watcher is open.
    fn word(&self) -> Option<String> {
        let here = lock(&self.here);
        if here.is_empty() {
            return None;
        }
        let which = if here.contains_key(&None) {
            "*".to_string()
        } else {
            let ids: Vec<String> = here.keys().flatten().map(i64::to_string).collect();
            let list = ids.join(",");
            if list.len() > MAX_WATCHING_LIST {
                "*".to_string()
            } else {
                list
            }
        };
        Some(format!("{WATCHING}\n{which}"))
    }

    /// Says what the watchers watch, when that changed (nothing once none is left: the
    /// others' leases run out).
    fn say(&self) {
        let word = self.word();
        let mut said = lock(&self.said);
        if *said == word {
            return;
        }
        match (&word, self.outbox.get()) {
            (Some(w), Some(outbox)) => {
                if outbox.try_send(w.clone()).is_ok() {
                    *said = word;
                }
            }
            (None, _) => *said = None,
            (Some(_), None) => {}
        }
    }
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// One watcher's events.
#[derive(Debug)]
pub struct Watcher {
    only: Option<i64>,
    ring: broadcast::Receiver<Arc<Frame>>,
    closed: watch::Receiver<bool>,
    _slot: Slot,
}

impl Watcher {
    /// The next event; `resync` when the watcher fell behind the ring, `None` once the hub is
    /// closed.
    pub async fn next(&mut self) -> Option<Arc<Frame>> {
        loop {
            if *self.closed.borrow() {
                return None;
            }
            let frame = tokio::select! {
                got = self.ring.recv() => match got {
                    Ok(frame) => frame,
                    Err(broadcast::error::RecvError::Lagged(missed)) => resync(missed),
                    Err(broadcast::error::RecvError::Closed) => return None,
                },
                _ = self.closed.wait_for(|c| *c) => return None,
            };
            if self.wants(&frame) {
                return Some(frame);
            }
        }
    }

    /// An event already waiting, without waiting for one (`resync` when the watcher fell
    /// behind; `None` when none is waiting or the hub is closed).
    pub fn try_next(&mut self) -> Option<Arc<Frame>> {
        loop {
            if *self.closed.borrow() {
                return None;
            }
            let frame = match self.ring.try_recv() {
                Ok(frame) => frame,
                Err(broadcast::error::TryRecvError::Lagged(missed)) => resync(missed),
                Err(_) => return None,
            };
            if self.wants(&frame) {
                return Some(frame);
            }
        }
    }

    fn wants(&self, frame: &Frame) -> bool {
        self.only.is_none() || frame.deployment.is_none() || frame.deployment == self.only
    }
}

/// The event telling every watcher that events were lost, how many unknown.
fn resync_unknown() -> Frame {
    Frame {
        name: RESYNC.into(),
        data: json_of(&ResyncEvent { missed: None }),
        deployment: None,
    }
}

/// What a replica sends the others in place of events they did not get: a `resync`.
pub(crate) fn lost_word() -> String {
    resync_unknown().encode()
}

/// The event telling a watcher that it lost `missed` events.
fn resync(missed: u64) -> Arc<Frame> {
    Arc::new(Frame {
        name: RESYNC.into(),
        data: json_of(&ResyncEvent {
            missed: Some(missed),
        }),
        deployment: None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(i: usize) -> Frame {
        Frame {
            name: "deployment".into(),
            data: format!("{{\"deployment\":{i}}}"),
            deployment: None,
        }
    }

    #[tokio::test]
    async fn a_watcher_that_stops_reading_is_told_to_resync_and_costs_no_more_than_the_ring() {
        let events = Events::new(4);
        let mut slow = events.watch(None).expect("a slot");
        let mut live = events.watch(None).expect("a slot");
        for i in 0..10 * RING {
            events.publish(frame(i));
            if i % RING == 0 {
                // A watcher that reads keeps up whatever the other does.
                while let Ok(Some(f)) =
                    tokio::time::timeout(std::time::Duration::from_millis(1), live.next()).await
                {
                    assert_eq!(f.name, "deployment");
                }
            }
        }
        // The ring holds at most RING events, whoever is behind.
        assert!(events.ring.len() <= RING);
        let first = slow.next().await.expect("an event");
        assert_eq!(first.name, "resync");
        let missed: serde_json::Value = serde_json::from_str(&first.data).expect("json");
        assert_eq!(missed["missed"], 10 * RING - RING);
        // Then the newest RING events, in order.
        let next = slow.next().await.expect("an event");
        assert_eq!(*next, frame(10 * RING - RING));
    }

    #[tokio::test]
    async fn streams_past_the_cap_are_refused_and_a_closed_one_frees_its_slot() {
        let events = Events::new(2);
        let a = events.watch(None).expect("first");
        let _b = events.watch(None).expect("second");
        assert_eq!(events.watch(None).unwrap_err(), TooManyStreams { max: 2 });
        assert_eq!(events.open_streams(), 2);
        drop(a);
        assert_eq!(events.open_streams(), 1);
        let mut c = events.watch(None).expect("a freed slot");
        events.close();
        assert!(c.next().await.is_none(), "a closed hub ends its streams");
        assert!(events.watch(None).is_err(), "and opens none");
    }

    /// 450 pages on deployments with long ids made a list too long for one notification: it was
    /// dropped, and the other replicas sent this one nothing.
    #[test]
    fn a_replica_watching_too_many_deployments_to_list_says_it_watches_all() {
        let events = Events::new(500);
        let watchers: Vec<Watcher> = (0..450)
            .map(|i| events.watch(Some(i64::MAX - i)).expect("a slot"))
            .collect();
        let word = events.watching_word().expect("watchers");
        assert_eq!(word, format!("{WATCHING}\n*"));
        drop(watchers);
        let few: Vec<Watcher> = (1..=3)
            .map(|i| events.watch(Some(i64::MAX - i)).expect("a slot"))
            .collect();
        let word = events.watching_word().expect("watchers");
        assert!(word.ends_with(&format!(",{}", i64::MAX - 1)), "{word}");
        assert!(word.len() + events.replica().len() < MAX_NOTIFICATION);
        drop(few);
    }

    #[test]
    fn only_our_own_frames_pass_between_replicas() {
        let f = Frame {
            name: "trial".into(),
            data: r#"{"trial":1,"deployment":7}"#.into(),
            deployment: Some(7),
        };
        assert_eq!(Frame::decode(&f.encode()), Some(f));
        assert_eq!(
            Frame::decode("resync\n{\"missed\":3}"),
            Some(resync_unknown()),
            "another replica's lost events: how many of them this one's pages wanted is unknown"
        );
        for stranger in [
            "hello",
            "trial\nnot json",
            "resync\nnot json",
            "script\n{}",
            "trial\n{}\n{}",
        ] {
            assert_eq!(Frame::decode(stranger), None, "{stranger:?}");
        }
    }

    #[tokio::test]
    async fn a_stream_of_one_deployment_skips_the_trials_of_others_only() {
        let events = Events::new(4);
        let mut one = events.watch(Some(2)).expect("a slot");
        let mut all = events.watch(None).expect("a slot");
        let trial = |d: i64| Frame {
            name: "trial".into(),
            data: format!("{{\"deployment\":{d}}}"),
            deployment: Some(d),
        };
        for f in [trial(1), trial(2), frame(3), trial(3), trial(2)] {
            events.publish(f);
        }
        let mut got = Vec::new();
        while let Some(f) = one.try_next() {
            got.push(f.data.clone());
        }
        assert_eq!(
            got,
            [
                r#"{"deployment":2}"#,
                r#"{"deployment":3}"#,
                r#"{"deployment":2}"#
            ],
            "its trials and the new deployment"
        );
        let mut n = 0;
        while all.try_next().is_some() {
            n += 1;
        }
        assert_eq!(n, 5);
    }

    #[tokio::test]
    async fn replicas_publish_through_the_database_only_what_another_replica_watches() {
        let events = Events::new(4);
        let (outbox, mut sent) = mpsc::channel(64);
        events.route_through(outbox);
        let mut sent_now = || {
            let mut v = Vec::new();
            while let Ok(t) = sent.try_recv() {
                v.push(t);
            }
            v
        };
        let trial = |d: i64| Frame {
            name: "trial".into(),
            data: format!("{{\"deployment\":{d}}}"),
            deployment: Some(d),
        };
        events.publish(trial(1));
        events.publish(trial(2));
        events.publish(frame(3));
        assert!(sent_now().is_empty(), "nobody watches: nothing sent");
        // Another replica's page on deployment 2: what was kept for it goes out first, then
        // what it wants as it comes (new deployments always), nothing else.
        events.heard_watching("other", Some([2].into()));
        events.publish(trial(1));
        events.publish(trial(2));
        events.publish(frame(4));
        assert_eq!(
            sent_now(),
            [trial(2), frame(3), trial(2), frame(4)].map(|f| f.encode())
        );
        // A page of every deployment: the events of deployment 1 kept meanwhile, then the new.
        events.hear(&format!("third\n{WATCHING}\n*"));
        events.publish(trial(1));
        assert_eq!(
            sent_now(),
            [trial(1).encode(), trial(1).encode(), trial(1).encode()]
        );

        // A page here says what it watches, once per change, and gets this replica's events at
        // once, not through the database.
        let events = Events::new(4);
        let (outbox, mut sent) = mpsc::channel(64);
        events.route_through(outbox);
        let mut a = events.watch(Some(7)).expect("a slot");
        let b = events.watch(Some(7)).expect("a slot");
        let c = events.watch(Some(3)).expect("a slot");
        events.publish(trial(7));
        let mut got = Vec::new();
        while let Ok(t) = sent.try_recv() {
            got.push(t);
        }
        assert_eq!(got, [format!("{WATCHING}\n7"), format!("{WATCHING}\n3,7")]);
        assert_eq!(a.try_next().as_deref(), Some(&trial(7)));
        drop((b, c));
        assert_eq!(events.watching_word(), Some(format!("{WATCHING}\n7")));
        assert_eq!(
            sent.try_recv().ok(),
            Some(format!("{WATCHING}\n7")),
            "a closed stream narrows what others send at once"
        );
        // What it hears: another replica's events; its own notifications and strangers' skipped.
        let other = |blocks: &[String]| format!("other\n{}", blocks.join("\n\n"));
        events.hear(&other(&[trial(7).encode(), frame(6).encode()]));
        assert_eq!(a.try_next().as_deref(), Some(&trial(7)));
        assert_eq!(a.try_next().as_deref(), Some(&frame(6)));
        events.hear(&format!("{}\n{}", events.replica(), trial(7).encode()));
        events.hear("other\nnot an event");
        assert!(a.try_next().is_none(), "its own and strangers' skipped");
        drop(a);
        assert_eq!(events.watching_word(), None, "no watcher left");
    }
}
