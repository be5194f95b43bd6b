//! What a fleet's run measured: requests, latencies by kind of reply, and what was read back.

use serde::Serialize;

use super::FleetRun;
use super::robot::Reply;

/// Trials a robot runs before its early starts are timed, and how many are timed at each end.
pub const EARLY_FROM: usize = 10;
/// See [`EARLY_FROM`].
pub const TIMED_STARTS: usize = 20;

/// Latencies of one kind of reply.
#[derive(Clone, Debug, Serialize)]
pub struct KindLine {
    /// `start`, `step`, `end` or `claim`.
    pub reply: &'static str,
    /// Replies of this kind.
    pub count: usize,
    /// Median, milliseconds.
    pub p50_ms: f64,
    /// 99th percentile, milliseconds.
    pub p99_ms: f64,
    /// Slowest, milliseconds.
    pub max_ms: f64,
}

/// The measured part of a load test.
#[derive(Clone, Debug, Serialize)]
pub struct LoadReport {
    /// Requests made (each counted once, however often it was sent).
    pub requests: usize,
    /// Attempts beyond the first of a request (a replica down, a request id in flight).
    pub retries: usize,
    /// Trial starts answered 409 (then retried).
    pub refused_starts: usize,
    /// Requests given up on, and trials that could not be read back.
    pub errors: usize,
    /// From the first robot's start to the last robot's end.
    pub seconds: f64,
    /// `requests / seconds`.
    pub requests_per_second: f64,
    /// Median of every reply carrying a next container (or ending a trial), milliseconds.
    pub next_p50_ms: f64,
    /// Its 99th percentile.
    pub next_p99_ms: f64,
    /// Its slowest.
    pub next_max_ms: f64,
    /// The same per kind of reply: a trial's start, an observation that leaves it searching,
    /// the observation that ends it (which replays every candidate).
    pub by_reply: Vec<KindLine>,
    /// When the first replica was killed, seconds into the run.
    pub killed_after_s: Option<f64>,
    /// Acknowledged observations read back.
    pub verified_observations: usize,
    /// Acknowledged observations missing from their trial.
    pub lost_observations: usize,
    /// Stored observations beyond the acknowledged ones (a write counted twice).
    pub duplicated_observations: usize,
    /// Deployments whose stored trials are not the ones their robot started.
    pub mismatched_deployments: usize,
    /// Team runs: replies in which two robots of a trial held one container, and robots sent
    /// to a container a teammate had searched; `None` for robots alone.
    pub double_claims: Option<usize>,
    /// Median start of each robot's trials 11–30 and of its last 20, when it ran 60 or more:
    /// whether a start costs more as its deployment's history grows.
    pub start_early_p50_ms: Option<f64>,
    /// See [`start_early_p50_ms`](Self::start_early_p50_ms).
    pub start_late_p50_ms: Option<f64>,
    /// What the watching pages did, when there were any.
    pub pages: Option<super::PagesReport>,
    /// The first replica process's resident memory, MiB, sampled every half second from a
    /// quarter into the run (once the grids of the scenes in use are built): the first sample,
    /// the largest and the last (`ferret serve` processes only).
    pub server_rss_mib: Option<[f64; 3]>,
}

impl LoadReport {
    /// True when nothing failed: no error, no observation lost or stored twice, every
    /// deployment holding the trials its robot started.
    pub fn is_clean(&self) -> bool {
        self.errors == 0
            && self.lost_observations == 0
            && self.duplicated_observations == 0
            && self.mismatched_deployments == 0
            && self.double_claims.unwrap_or(0) == 0
    }
}

/// The value at quantile `q` of sorted `ms` (NaN when empty).
fn quantile(ms: &[f64], q: f64) -> f64 {
    ms.get(((ms.len() as f64 - 1.0) * q).round() as usize)
        .copied()
        .unwrap_or(f64::NAN)
}

impl FleetRun {
    /// What the run measured; `trials` is how many each robot was given.
    pub fn report(&self, trials: usize) -> LoadReport {
        let robots = &self.robots;
        let sorted = |kind: Option<Reply>| {
            let mut ms: Vec<f64> = robots
                .iter()
                .flat_map(|r| r.latencies.iter())
                .filter(|(k, _)| kind.is_none_or(|kind| *k == kind))
                .map(|(_, d)| d.as_secs_f64() * 1e3)
                .collect();
            ms.sort_by(f64::total_cmp);
            ms
        };
        let ms = sorted(None);
        let by_reply = [
            (Reply::Start, "start"),
            (Reply::Step, "step"),
            (Reply::End, "end"),
            (Reply::Claim, "claim"),
        ]
        .into_iter()
        .map(|(kind, name)| {
            let ms = sorted(Some(kind));
            KindLine {
                reply: name,
                count: ms.len(),
                p50_ms: quantile(&ms, 0.5),
                p99_ms: quantile(&ms, 0.99),
                max_ms: ms.last().copied().unwrap_or(f64::NAN),
            }
        })
        .collect();
        let by_history = |late: bool| {
            let mut ms: Vec<f64> = robots
                .iter()
                .flat_map(|r| {
                    let n = r.starts.len();
                    let from = if late {
                        n.saturating_sub(TIMED_STARTS)
                    } else {
                        EARLY_FROM
                    };
                    r.starts.iter().skip(from).take(TIMED_STARTS)
                })
                .map(|d| d.as_secs_f64() * 1e3)
                .collect();
            ms.sort_by(f64::total_cmp);
            (trials >= 3 * TIMED_STARTS).then(|| quantile(&ms, 0.5))
        };
        let requests: usize = robots.iter().map(|r| r.requests).sum();
        let v = &self.verified;
        LoadReport {
            requests,
            retries: robots.iter().map(|r| r.retries).sum(),
            refused_starts: robots.iter().map(|r| r.refused_starts).sum(),
            errors: robots.iter().map(|r| r.errors).sum::<usize>() + v.errors,
            seconds: self.seconds,
            requests_per_second: requests as f64 / self.seconds,
            next_p50_ms: quantile(&ms, 0.5),
            next_p99_ms: quantile(&ms, 0.99),
            next_max_ms: ms.last().copied().unwrap_or(f64::NAN),
            by_reply,
            killed_after_s: self.killed_after,
            verified_observations: v.observations,
            lost_observations: v.lost,
            duplicated_observations: v.duplicated,
            mismatched_deployments: v.mismatched,
            double_claims: robots
                .iter()
                .any(|r| r.team_id.is_some())
                .then(|| robots.iter().map(|r| r.double_claims).sum()),
            start_early_p50_ms: by_history(false),
            start_late_p50_ms: by_history(true),
            pages: self.pages.clone(),
            server_rss_mib: {
                let mib = |b: u64| b as f64 / (1024.0 * 1024.0);
                // From a quarter into the run: by then the grids of the scenes in use are
                // built, and what grows after is what the run keeps.
                let rest = &self.rss[self.rss.len() / 4..];
                match (rest.first(), rest.iter().max(), rest.last()) {
                    (Some(&first), Some(&max), Some(&last)) => {
                        Some([mib(first), mib(max), mib(last)])
                    }
                    _ => None,
                }
            },
        }
    }
}
