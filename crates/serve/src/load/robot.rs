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
    /// A team robot's claim of its next container.
    Claim,
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
    /// Its id in its team's trials, when it is one of a team.
    pub(super) team_id: Option<String>,
    /// Replies of team trials in which two robots held one container, and observations of a
    /// container a teammate had searched already (a robot sent where another went).
    pub(super) double_claims: usize,
}

/// How a write ended.
pub(super) enum Posted {
    /// Acknowledged.
    Done(serde_json::Value),
    /// Answered 409 with an error that stays (a container already searched, a trial ended).
    Conflict(serde_json::Value),
    /// Refused, or out of attempts.
    Failed,
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
            team_id: None,
            double_claims: 0,
        }
    }

    /// POSTs `body` with a request id of its own until a replica acknowledges it; `None` when
    /// refused (4xx other than 409) or out of attempts.
    pub(super) async fn post(
        &mut self,
        path: &str,
        body: serde_json::Value,
    ) -> Option<serde_json::Value> {
        match self.post_until(path, body, false).await {
            Posted::Done(v) => Some(v),
            Posted::Conflict(_) | Posted::Failed => None,
        }
    }

    /// [`post`](Self::post); with `team`, a 409 about the container or the trial (searched by
    /// a teammate, ended) is an answer, not a request to retry.
    pub(super) async fn post_until(
        &mut self,
        path: &str,
        mut body: serde_json::Value,
        team: bool,
    ) -> Posted {
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
                let kind = if path.ends_with("/claims") {
                    Reply::Claim
                } else if value["status"] == "searching" {
                    if path.ends_with("/trials") {
                        Reply::Start
                    } else {
                        Reply::Step
                    }
                } else {
                    Reply::End
                };
                self.latencies.push((kind, t.elapsed()));
                return Posted::Done(value);
            }
            if team
                && status.as_u16() == 409
                && matches!(
                    value["error"]["field"].as_str(),
                    Some("container" | "trial")
                )
            {
                return Posted::Conflict(value);
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
            return Posted::Failed;
        }
        tracing::warn!(%path, "no replica acknowledged the request");
        Posted::Failed
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
        if let Some(id) = robot.deployment {
            self.verify_deployment(id, robot, shared, out).await;
        }
        self.verify_observations(robot, out).await;
    }

    /// `robot`'s deployment holds its trials exactly (or, shared, among others in its order).
    async fn verify_deployment(&self, id: i64, robot: &Robot, shared: bool, out: &mut Verified) {
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
    }

    /// Each observation acknowledged to `robot` is stored once in its trial (for a robot of
    /// a team: among the containers the trial says it searched).
    async fn verify_observations(&self, robot: &Robot, out: &mut Verified) {
        for (trial, acked) in &robot.acked {
            let Some(t) = self.get(&format!("/trials/{trial}")).await else {
                out.errors += 1;
                continue;
            };
            let theirs = match &robot.team_id {
                Some(me) => t["robots"]
                    .as_array()
                    .and_then(|rs| rs.iter().find(|r| r["id"] == me.as_str()))
                    .map(|r| r["searched"].clone())
                    .unwrap_or_default(),
                None => t["searched"].clone(),
            };
            let searched: Vec<String> = theirs
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

impl Robot {
    /// Runs `trials` as a home of `members` robots searching each together: the first starts
    /// each trial (in a deployment of its own, or in `shared`) naming the team, then every
    /// member claims, searches and reports until the trial ends; the next trial starts once
    /// every member is done.
    pub(super) async fn run_home(
        members: &mut [Robot],
        trials: Vec<RobotTrial>,
        on_trial: &(dyn Fn() + Send + Sync),
        shared: Option<i64>,
    ) {
        use serde_json::json;
        let team: Vec<serde_json::Value> = (0..members.len())
            .map(|m| json!({"id": format!("r{m}")}))
            .collect();
        for (m, robot) in members.iter_mut().enumerate() {
            robot.team_id = Some(format!("r{m}"));
        }
        let Some(leader) = members.first_mut() else {
            return;
        };
        let id = match shared {
            Some(id) => id,
            None => {
                let created = leader.post("/deployments", json!({})).await;
                leader.latencies.clear();
                match created.and_then(|d| d["id"].as_i64()) {
                    Some(id) => id,
                    None => {
                        leader.errors += 1;
                        return;
                    }
                }
            }
        };
        leader.deployment = Some(id);
        for t in trials {
            let Some(leader) = members.first_mut() else {
                return;
            };
            let mut start = json!({"scene": t.scene, "target": t.target, "robots": team});
            if let Some(pose) = t.pose {
                start["pose"] = json!(pose);
            }
            let Some(reply) = leader
                .post(&format!("/deployments/{id}/trials"), start)
                .await
            else {
                leader.errors += 1;
                break;
            };
            if let Some((_, took)) = leader.latencies.last() {
                leader.starts.push(*took);
            }
            let trial = reply["trial"].as_i64().unwrap_or_default();
            let searches = members
                .iter_mut()
                .map(|m| m.team_search(trial, &t.target, &t.contents));
            futures_util::future::join_all(searches).await;
            on_trial();
        }
    }

    /// This robot's part of team trial `trial`: claims, searches and reports until it ends.
    async fn team_search(
        &mut self,
        trial: i64,
        target: &str,
        contents: &std::collections::HashMap<String, Vec<String>>,
    ) {
        use serde_json::json;
        let me = self.team_id.clone().unwrap_or_default();
        self.acked.push((trial, Vec::new()));
        let claim = format!("/trials/{trial}/claims");
        let observe = format!("/trials/{trial}/observations");
        let mut reply = match self.post_until(&claim, json!({"robot": me}), true).await {
            Posted::Done(v) => v,
            Posted::Conflict(_) => return,
            Posted::Failed => {
                self.errors += 1;
                return;
            }
        };
        // A robot with nothing left to claim waits for its teammates, at most about a minute.
        let mut waits = 0;
        while reply["status"] == "searching" && waits < 3000 {
            self.double_claims += shared_claims(&reply);
            let posted = match reply["next"]["container"].as_str() {
                Some(next) => {
                    let seen = contents.get(next).cloned().unwrap_or_default();
                    let found = seen.iter().any(|s| s == target);
                    let body =
                        json!({"robot": me, "container": next, "found": found, "objects": seen});
                    let next = next.to_string();
                    match self.post_until(&observe, body, true).await {
                        Posted::Done(v) => {
                            if let Some((_, acked)) = self.acked.last_mut() {
                                acked.push(next);
                            }
                            Posted::Done(v)
                        }
                        Posted::Conflict(v) if v["error"]["field"] == "container" => {
                            // Sent where a teammate had been: ask anew.
                            self.double_claims += 1;
                            self.post_until(&claim, json!({"robot": me}), true).await
                        }
                        other => other,
                    }
                }
                None => {
                    waits += 1;
                    tokio::time::sleep(std::time::Duration::from_millis(20)).await;
                    self.post_until(&claim, json!({"robot": me}), true).await
                }
            };
            reply = match posted {
                Posted::Done(v) => v,
                Posted::Conflict(_) => return,
                Posted::Failed => {
                    self.errors += 1;
                    return;
                }
            };
        }
    }
}

/// Containers two robots of a reply's team hold at once.
fn shared_claims(reply: &serde_json::Value) -> usize {
    let claims: Vec<&str> = reply["robots"]
        .as_array()
        .into_iter()
        .flatten()
        .filter_map(|r| r["claim"].as_str())
        .collect();
    let distinct: std::collections::BTreeSet<&str> = claims.iter().copied().collect();
    claims.len() - distinct.len()
}

#[cfg(test)]
mod tests {
    use super::shared_claims;
    use serde_json::json;

    /// What the fleet counts as a double claim: a container held by two robots of one reply.
    #[test]
    fn a_container_held_by_two_robots_is_counted() {
        let reply = |claims: [Option<&str>; 3]| json!({"robots": claims.iter().map(|c| json!({"claim": c})).collect::<Vec<_>>()});
        assert_eq!(shared_claims(&reply([Some("bed"), Some("sofa"), None])), 0);
        assert_eq!(shared_claims(&reply([Some("bed"), Some("bed"), None])), 1);
        assert_eq!(
            shared_claims(&reply([Some("bed"), Some("bed"), Some("bed")])),
            2
        );
        assert_eq!(shared_claims(&reply([None, None, None])), 0);
        assert_eq!(shared_claims(&json!({"status": "done"})), 0);
    }
}
