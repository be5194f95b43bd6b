//! One simulated robot: a deployment and its trials, run to the end over HTTP, then read back.

use std::time::Instant;

use super::RobotTrial;

/// What a reply answered, for latencies by kind.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Reply {
    /// A trial's start.
    Start,
    /// An observation that leaves the trial searching.
    Step,
    /// The observation that ends it.
    End,
}

/// What was read back after the run.
#[derive(Default)]
pub(super) struct Verified {
    pub(super) observations: usize,
    pub(super) lost: usize,
    pub(super) duplicated: usize,
    pub(super) mismatched: usize,
    pub(super) errors: usize,
}

/// One simulated robot: a deployment and its trials, run to the end against its replica (and
/// the next one when a request to it fails).
pub(super) struct Robot {
    pub(super) client: reqwest::Client,
    pub(super) urls: std::sync::Arc<Vec<String>>,
    /// The replica it talks to now.
    pub(super) at: usize,
    pub(super) id: usize,
    /// Writes so far, for request ids.
    pub(super) writes: usize,
    pub(super) latencies: Vec<(Reply, std::time::Duration)>,
    /// Each trial's start, in order.
    pub(super) starts: Vec<std::time::Duration>,
    pub(super) requests: usize,
    pub(super) retries: usize,
    /// Starts answered 409.
    pub(super) refused_starts: usize,
    pub(super) errors: usize,
    pub(super) deployment: Option<i64>,
    /// Per trial started: its id and the containers whose observation was acknowledged.
    pub(super) acked: Vec<(i64, Vec<String>)>,
}

/// What makes this run's request ids its own: a database may hold earlier runs' replies.
fn run_tag() -> &'static str {
    static TAG: std::sync::OnceLock<String> = std::sync::OnceLock::new();
    TAG.get_or_init(|| {
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos());
        format!("bench-{}-{nanos:x}", std::process::id())
    })
}

/// Attempts of one request before the robot gives up on it (about a minute with the pauses).
const ATTEMPTS: u32 = 60;

impl Robot {
    pub(super) fn new(
        client: reqwest::Client,
        urls: std::sync::Arc<Vec<String>>,
        id: usize,
    ) -> Self {
        let at = id % urls.len().max(1);
        Self {
            client,
            urls,
            at,
            id,
            writes: 0,
            latencies: Vec::new(),
            starts: Vec::new(),
            requests: 0,
            retries: 0,
            refused_starts: 0,
            errors: 0,
            deployment: None,
            acked: Vec::new(),
        }
    }

    /// POSTs `body` with a request id of its own until a replica acknowledges it; `None` when
    /// refused (4xx other than 409) or out of attempts.
    pub(super) async fn post(
        &mut self,
        path: &str,
        mut body: serde_json::Value,
    ) -> Option<serde_json::Value> {
        self.writes += 1;
        body["request_id"] = format!("{}-robot-{}-{}", run_tag(), self.id, self.writes).into();
        self.requests += 1;
        for attempt in 0..ATTEMPTS {
            if attempt > 0 {
                self.retries += 1;
                // Another replica, after a pause that grows to half a second.
                self.at = (self.at + 1) % self.urls.len();
                tokio::time::sleep(std::time::Duration::from_millis(
                    (20 * u64::from(attempt)).min(500),
                ))
                .await;
            }
            let t = Instant::now();
            let sent = self
                .client
                .post(format!("{}{path}", self.urls[self.at]))
                .json(&body)
                .send()
                .await;
            let Ok(reply) = sent else { continue };
            let status = reply.status();
            let Ok(value) = reply.json::<serde_json::Value>().await else {
                continue;
            };
            if status.is_success() {
                let kind = if value["status"] == "searching" {
                    if path.ends_with("/trials") {
                        Reply::Start
                    } else {
                        Reply::Step
                    }
                } else {
                    Reply::End
                };
                self.latencies.push((kind, t.elapsed()));
                return Some(value);
            }
            // 409: the same request in flight (on a replica that may have died) or the
            // deployment busy; 5xx: the replica or its database in trouble. Both pass.
            if status.as_u16() == 409 || status.is_server_error() {
                if status.as_u16() == 409 && path.ends_with("/trials") {
                    self.refused_starts += 1;
                }
                continue;
            }
            tracing::warn!(%path, reply = %value, "request refused");
            return None;
        }
        tracing::warn!(%path, "no replica acknowledged the request");
        None
    }

    /// Runs `trials` in a deployment of its own, or in `shared`.
    pub(super) async fn run(
        &mut self,
        trials: Vec<RobotTrial>,
        on_trial: &(dyn Fn() + Send + Sync),
        shared: Option<i64>,
    ) {
        use serde_json::json;
        let id = match shared {
            Some(id) => id,
            None => {
                let created = self.post("/deployments", json!({})).await;
                // The latencies that count are those of replies carrying a next container.
                self.latencies.clear();
                match created.and_then(|d| d["id"].as_i64()) {
                    Some(id) => id,
                    None => {
                        self.errors += 1;
                        return;
                    }
                }
            }
        };
        self.deployment = Some(id);
        for RobotTrial {
            scene,
            target,
            pose,
            contents,
        } in trials
        {
            let mut start = json!({"scene": scene, "target": target});
            if let Some(pose) = pose {
                start["pose"] = json!(pose);
            }
            let Some(mut reply) = self.post(&format!("/deployments/{id}/trials"), start).await
            else {
                self.errors += 1;
                break;
            };
            if let Some((_, took)) = self.latencies.last() {
                self.starts.push(*took);
            }
            let trial = reply["trial"].as_i64().unwrap_or_default();
            self.acked.push((trial, Vec::new()));
            while reply["status"] == "searching" {
                let next = reply["next"]["container"]
                    .as_str()
                    .unwrap_or_default()
                    .to_string();
                let seen = contents.get(&next).cloned().unwrap_or_default();
                let found = seen.contains(&target);
                match self
                    .post(
                        &format!("/trials/{trial}/observations"),
                        json!({"container": next, "found": found, "objects": seen}),
                    )
                    .await
                {
                    Some(r) => {
                        if let Some((_, acked)) = self.acked.last_mut() {
                            acked.push(next);
                        }
                        reply = r;
                    }
                    None => {
                        self.errors += 1;
                        break;
                    }
                }
            }
            on_trial();
        }
    }

    async fn get(&self, path: &str) -> Option<serde_json::Value> {
        for attempt in 0..ATTEMPTS {
            if attempt > 0 {
                tokio::time::sleep(std::time::Duration::from_millis(100)).await;
            }
            let url = &self.urls[attempt as usize % self.urls.len()];
            if let Ok(r) = self.client.get(format!("{url}{path}")).send().await
                && r.status().is_success()
                && let Ok(v) = r.json().await
            {
                return Some(v);
            }
        }
        None
    }

    /// Reads `robot`'s deployment and trials back: its trials exactly, each acknowledged
    /// observation once.
    pub(super) async fn verify(&self, robot: &Robot, shared: bool, out: &mut Verified) {
        let Some(id) = robot.deployment else { return };
        match self.get(&format!("/deployments/{id}")).await {
            Some(dep) => {
                let stored: Vec<i64> = dep["trials"]
                    .as_array()
                    .map(|t| t.iter().filter_map(|t| t["trial"].as_i64()).collect())
                    .unwrap_or_default();
                let started: Vec<i64> = robot.acked.iter().map(|(t, _)| *t).collect();
                // A shared deployment holds every robot's trials: this robot's must be among
                // them, in its order.
                let mismatched = if shared {
                    let mine: Vec<i64> = stored
                        .iter()
                        .copied()
                        .filter(|t| started.contains(t))
                        .collect();
                    mine != started
                } else {
                    stored != started
                };
                if mismatched {
                    out.mismatched += 1;
                }
            }
            None => out.errors += 1,
        }
        for (trial, acked) in &robot.acked {
            let Some(t) = self.get(&format!("/trials/{trial}")).await else {
                out.errors += 1;
                continue;
            };
            let searched: Vec<String> = t["searched"]
                .as_array()
                .map(|s| {
                    s.iter()
                        .filter_map(|c| c.as_str().map(str::to_string))
                        .collect()
                })
                .unwrap_or_default();
            out.observations += acked.len();
            out.lost += acked.iter().filter(|c| !searched.contains(c)).count();
            out.duplicated += searched
                .len()
                .saturating_sub(searched.iter().filter(|c| acked.contains(c)).count())
                + acked
                    .iter()
                    .map(|c| {
                        searched
                            .iter()
                            .filter(|s| *s == c)
                            .count()
                            .saturating_sub(1)
                    })
                    .sum::<usize>();
        }
    }
}
