//! A fleet of simulated robots driving `ferret serve` over real HTTP: the load test behind
//! `ferret bench serve`. Each robot runs its trials to the end against one server (moving to the
//! next replica when a request fails), every write carrying a request id and retried until
//! acknowledged; afterwards every trial is read back, and each acknowledged observation must
//! be stored exactly once. The servers are this crate's own router in the caller's process
//! ([`serve_in_process`]) or `ferret serve` processes ([`Replica::spawn`]).

mod pages;
mod replica;
mod report;
mod robot;
mod work;

use std::sync::Arc;
use std::time::{Duration, Instant};

pub use pages::PagesReport;
pub use replica::{Replica, serve_in_process};
pub use report::{EARLY_FROM, KindLine, LoadReport, TIMED_STARTS};
pub use work::{RobotTrial, robot_trials};

use robot::{Robot, Verified};

/// Why a load test could not run.
#[derive(Debug, thiserror::Error)]
pub enum LoadError {
    /// A file or process could not be used.
    #[error("{what}: {source}")]
    Io {
        /// What was being done.
        what: String,
        /// The system's error.
        #[source]
        source: std::io::Error,
    },
    /// A `ferret serve` process stopped before it listened.
    #[error("ferret serve exited before listening: {log}")]
    ReplicaExited {
        /// What it wrote to its log.
        log: String,
    },
    /// The HTTP client could not be built, or the fleet could not be set up.
    #[error("{0}")]
    Setup(String),
    /// A house gave no trial.
    #[error("house {house}: {message}")]
    House {
        /// The house's name.
        house: String,
        /// What is wrong.
        message: String,
    },
}

impl LoadError {
    fn io(what: impl Into<String>) -> impl FnOnce(std::io::Error) -> LoadError {
        let what = what.into();
        move |source| LoadError::Io { what, source }
    }
}

/// How the fleet drives the servers.
#[derive(Clone, Copy, Debug, Default)]
pub struct FleetSettings {
    /// The robots share one deployment, as a fleet does, instead of one each.
    pub shared_deployment: bool,
    /// Kill (SIGKILL) the first replica this long into the run; its robots carry on against the
    /// others.
    pub kill_first_after: Option<Duration>,
    /// Browser pages watching, page `p` on replica `p % replicas` (see `pages`): they read the
    /// event stream and fetch what the live page fetches.
    pub pages: usize,
    /// Pages that open the event stream and never read it.
    pub stalled_pages: usize,
    /// Robots per home: above 1, each entry of the plans is a home whose trials a team of
    /// this many robots searches together (one trial at a time, every robot asking for its
    /// own containers).
    pub team: usize,
}

/// What a fleet did: each robot's requests and latencies, and what was read back.
pub struct FleetRun {
    robots: Vec<Robot>,
    seconds: f64,
    killed_after: Option<f64>,
    verified: Verified,
    pages: Option<PagesReport>,
    /// The first replica's resident memory, bytes, sampled every half second while robots run.
    rss: Vec<u64>,
}

/// Runs one robot per entry of `plans` against the servers at `urls` (robot `r` starts on
/// `urls[r % len]`), then reads every trial back from a server still up. `replicas` are the
/// processes behind `urls`, in order, for [`FleetSettings::kill_first_after`]; `on_trial` is
/// called as each trial ends.
///
/// # Errors
/// The HTTP client cannot be built, the shared deployment cannot be created, or a replica
/// cannot be killed.
pub fn drive(
    runtime: &tokio::runtime::Runtime,
    urls: Vec<String>,
    plans: Vec<Vec<RobotTrial>>,
    settings: FleetSettings,
    replicas: &mut [Replica],
    on_trial: Arc<dyn Fn() + Send + Sync>,
) -> Result<FleetRun, LoadError> {
    if urls.is_empty() {
        return Err(LoadError::Setup("no server to drive".into()));
    }
    runtime.block_on(async {
        let client = reqwest::Client::builder()
            .timeout(Duration::from_secs(60))
            .build()
            .map_err(|e| LoadError::Setup(format!("the HTTP client: {e}")))?;
        let urls = Arc::new(urls);
        let shared =
            if settings.shared_deployment {
                let mut creator = Robot::new(client.clone(), urls.clone(), usize::MAX);
                let created = creator.post("/deployments", serde_json::json!({})).await;
                Some(created.and_then(|d| d["id"].as_i64()).ok_or_else(|| {
                    LoadError::Setup("the shared deployment was not created".into())
                })?)
            } else {
                None
            };
        let (stop_pages, stopped) = tokio::sync::watch::channel(false);
        let counts = Arc::new(pages::Counts::default());
        let mut watchers = Vec::new();
        for p in 0..settings.pages + settings.stalled_pages {
            let url = urls[p % urls.len()].clone();
            let (counts, stopped) = (counts.clone(), stopped.clone());
            watchers.push(if p < settings.pages {
                tokio::spawn(pages::page(client.clone(), url, counts, stopped))
            } else {
                tokio::spawn(pages::stalled_page(url, counts, stopped))
            });
        }
        if !watchers.is_empty() {
            // The pages are open before the first robot starts, as they would be.
            tokio::time::sleep(Duration::from_millis(300)).await;
        }
        let sampler = replicas.first().map(|r| {
            let pid = r.pid();
            let stopped = stopped.clone();
            tokio::spawn(async move {
                let mut samples = Vec::new();
                while !*stopped.borrow() {
                    if let Some(b) = replica::resident_bytes(pid) {
                        samples.push(b);
                    }
                    tokio::time::sleep(Duration::from_millis(500)).await;
                }
                samples
            })
        });
        let started = Instant::now();
        let team = settings.team.max(1);
        let tasks: Vec<_> = plans
            .into_iter()
            .enumerate()
            .map(|(h, trials)| {
                let (client, urls, on_trial) = (client.clone(), urls.clone(), on_trial.clone());
                tokio::spawn(async move {
                    if team == 1 {
                        let mut robot = Robot::new(client, urls, h);
                        robot.run(trials, on_trial.as_ref(), shared).await;
                        return vec![robot];
                    }
                    // Robot m of home h starts on replica h·team + m (mod replicas): a team's
                    // robots talk to different replicas.
                    let mut members: Vec<Robot> = (0..team)
                        .map(|m| Robot::new(client.clone(), urls.clone(), h * team + m))
                        .collect();
                    Robot::run_home(&mut members, trials, on_trial.as_ref(), shared).await;
                    members
                })
            })
            .collect();
        let mut killed_after = None;
        if let Some(after) = settings.kill_first_after {
            tokio::time::sleep(after).await;
            if let Some(first) = replicas.first_mut() {
                first.kill().map_err(LoadError::io("killing replica 0"))?;
                killed_after = Some(started.elapsed().as_secs_f64());
            }
        }
        let mut robots = Vec::new();
        for t in tasks {
            robots.extend(
                t.await
                    .map_err(|e| LoadError::Setup(format!("a robot failed: {e}")))?,
            );
        }
        let seconds = started.elapsed().as_secs_f64();
        let _ = stop_pages.send(true);
        for w in watchers {
            let _ = w.await;
        }
        let rss = match sampler {
            Some(s) => s.await.unwrap_or_default(),
            None => Vec::new(),
        };
        let pages = (settings.pages + settings.stalled_pages > 0)
            .then(|| counts.report(settings.pages, settings.stalled_pages));
        // Read every trial back from a replica that is still up.
        let alive = usize::from(killed_after.is_some()).min(urls.len() - 1);
        let check = Robot::new(client.clone(), Arc::new(urls[alive..].to_vec()), 0);
        let mut verified = Verified::default();
        for robot in &robots {
            check.verify(robot, shared.is_some(), &mut verified).await;
        }
        Ok(FleetRun {
            robots,
            seconds,
            killed_after,
            verified,
            pages,
            rss,
        })
    })
}
