//! The `trials` and `observations` tables: a trial's row, its observations one per sequence
//! number, and its end as the next of its deployment's.

use crate::model::{StoredObservation, StoredTrial, TrialStatus};

use super::Final;
use super::conn::{Conn, Reader, Writer};
use super::error::StoreError;
use super::value::{Row, Value};

/// A trial's status and number of observations.
const PROGRESS: &str = "SELECT status, (SELECT count(*) FROM observations WHERE trial = $1)
     FROM trials WHERE id = $1";

const INSERT_OBSERVATION: &str =
    "INSERT INTO observations (trial, seq, container, found, objects, travelled, leg, robot)
     VALUES ($1, $2, $3, $4, $5, $6, $7, $8)";

/// A deployment's trials started after its first `$2` or ended after its first `$3`.
pub(super) const SINCE: &str = "deployment = $1 AND (k > $2 OR end_seq > $3)";

pub(super) const TRIAL_COLUMNS: &str = "id, deployment, k, scene, target, pose, chosen, status, cost, replays, started_after, end_seq, task, robots, robot, heard_ms";

impl Conn<'_> {
    /// A trial's status and observation count from a row of [`PROGRESS`].
    pub(super) fn progress(&self, id: i64, row: &Row) -> Result<(TrialStatus, usize), StoreError> {
        let bad = |what: &str| self.corrupt(format!("trial {id}: {what}"));
        let status = TrialStatus::parse(&self.some_text(row, 0, "trial status")?)
            .ok_or_else(|| bad("status"))?;
        let seen = usize::try_from(self.int(row, 1, "observation count")?)
            .map_err(|_| bad("observation count"))?;
        Ok((status, seen))
    }

    /// Trials from rows of [`TRIAL_COLUMNS`].
    pub(super) fn trials(&self, rows: &[Row]) -> Result<Vec<StoredTrial>, StoreError> {
        let c = self;
        rows.iter()
            .map(|r| {
                let id = c.int(r, 0, "trial id")?;
                let bad = |what: &str| c.corrupt(format!("trial {id}: {what}"));
                let json =
                    |i: usize, what: &str| -> Result<Option<serde_json::Value>, StoreError> {
                        c.text(r, i, what)?
                            .map(|p| serde_json::from_str(&p).map_err(|_| bad(what)))
                            .transpose()
                    };
                Ok(StoredTrial {
                    id,
                    deployment: c.int(r, 1, "trial deployment")?,
                    k: c.int(r, 2, "trial k")?,
                    scene: c.some_text(r, 3, "trial scene")?,
                    target: c.some_text(r, 4, "trial target")?,
                    pose: json(5, "pose")?
                        .map(serde_json::from_value)
                        .transpose()
                        .map_err(|_| bad("pose"))?,
                    chosen: usize::try_from(c.int(r, 6, "trial chosen")?)
                        .map_err(|_| bad("chosen"))?,
                    status: TrialStatus::parse(&c.some_text(r, 7, "trial status")?)
                        .ok_or_else(|| bad("status"))?,
                    cost: c.real(r, 8, "trial cost")?,
                    replays: json(9, "replays")?
                        .map(serde_json::from_value)
                        .transpose()
                        .map_err(|_| bad("replays"))?,
                    started_after: c.int(r, 10, "trial started_after")?,
                    end_seq: match r.get(11) {
                        Some(Value::Null) => None,
                        _ => Some(c.int(r, 11, "trial end_seq")?),
                    },
                    task: json(12, "task")?
                        .map(serde_json::from_value)
                        .transpose()
                        .map_err(|_| bad("task"))?,
                    robots: json(13, "robots")?
                        .map(serde_json::from_value)
                        .transpose()
                        .map_err(|_| bad("robots"))?,
                    robot: c.text(r, 14, "trial robot")?,
                    heard_ms: match r.get(15) {
                        Some(Value::Null) => None,
                        _ => Some(c.int(r, 15, "trial heard_ms")?),
                    },
                })
            })
            .collect()
    }
}

impl Writer<'_> {
    /// Stores trial `t` under id `id` (from [`lock_deployment_since`]), as a statement run
    /// with the commit.
    ///
    /// [`lock_deployment_since`]: Self::lock_deployment_since
    pub fn insert_trial_last(&self, id: i64, t: &NewTrial<'_>) -> Final {
        let pose = t.pose.map(|p| serde_json::json!(p).to_string());
        let task = t
            .task
            .map(|task| serde_json::to_value(task).unwrap_or_default().to_string());
        let robots = t
            .robots
            .map(|r| serde_json::to_value(r).unwrap_or_default().to_string());
        Final {
            sql: "INSERT INTO trials (id, deployment, k, scene, target, pose, chosen, status, started_after, task, robots, robot, heard_ms)
                 VALUES ($1, $2, $3, $4, $5, $6, $7, 'searching', $8, $9, $10, $11, $12)",
            params: vec![
                id.into(),
                t.deployment.into(),
                t.k.into(),
                t.scene.into(),
                t.target.into(),
                pose.into(),
                (t.chosen as i64).into(),
                t.started_after.into(),
                task.into(),
                robots.into(),
                t.robot.into(),
                t.heard_ms.into(),
            ],
        }
    }

    /// Locks trial `id` until the transaction ends, so that one observation per sequence
    /// number is recorded without holding its deployment (an observation that leaves the trial
    /// searching changes nothing a deployment's other trials depend on), and reads its status
    /// and number of observations under the lock, in one round trip. `None` when there is no
    /// such trial.
    ///
    /// # Errors
    /// The database refuses, or the row does not parse.
    pub fn lock_trial_progress(&self, id: i64) -> Result<Option<(TrialStatus, usize)>, StoreError> {
        let lock = match &self.conn {
            Conn::Sqlite(..) => "SELECT id FROM trials WHERE id = $1",
            Conn::Postgres(_) => "SELECT id FROM trials WHERE id = $1 FOR UPDATE",
        };
        let answers = self
            .conn
            .query_all(&[(lock, &[id.into()]), (PROGRESS, &[id.into()])])?;
        match answers.as_slice() {
            [_, progress] => match progress.first() {
                Some(row) => Ok(Some(self.conn.progress(id, row)?)),
                None => Ok(None),
            },
            _ => Ok(None),
        }
    }

    /// Statements that record that `trial`'s robot was heard from at `heard_ms`, store
    /// observation `seq` of it (unless `observation` is `None`) and, when `end` says how, end the trial as the next of `deployment`'s trials to end,
    /// taking the deployment's lock for that: to run with the commit, so that the deployment
    /// is held for no round trip at all. Take the trial's lock first
    /// ([`lock_trial_progress`](Self::lock_trial_progress)): a transaction taking both takes
    /// the trial's first, so two never wait for each other.
    pub fn record_and_end_last(
        &self,
        (trial, deployment): (i64, i64),
        heard_ms: i64,
        observation: Option<(usize, &StoredObservation)>,
        end: Option<TrialEnding<'_>>,
    ) -> Vec<Final> {
        // The trial's row is locked already (it was read under the lock), so this costs no wait.
        let mut statements = vec![Final {
            sql: "UPDATE trials SET heard_ms = $2 WHERE id = $1",
            params: vec![trial.into(), heard_ms.into()],
        }];
        if let Some((seq, o)) = observation {
            statements.push(Final {
                sql: INSERT_OBSERVATION,
                params: vec![
                    trial.into(),
                    (seq as i64).into(),
                    o.container.as_str().into(),
                    o.found.into(),
                    serde_json::json!(o.objects).to_string().into(),
                    o.travelled.into(),
                    o.leg.into(),
                    o.robot.clone().into(),
                ],
            });
        }
        if let Some(e) = &end {
            statements.push(Final {
                sql: self.lock_deployment_sql(),
                params: vec![deployment.into()],
            });
            statements.push(Final {
                sql: "UPDATE trials SET status = $2, cost = $3, replays = $4,
                     end_seq = (SELECT coalesce(max(end_seq), 0) + 1 FROM trials
                                WHERE deployment = $5)
                 WHERE id = $1",
                params: vec![
                    trial.into(),
                    e.status.as_str().into(),
                    e.cost.into(),
                    e.replays.map(|r| serde_json::json!(r).to_string()).into(),
                    deployment.into(),
                ],
            });
        }
        statements
    }
}

/// How many trials of a deployment started, ended, and are open.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TrialCounts {
    /// Trials started.
    pub started: usize,
    /// Trials ended (done or exhausted).
    pub ended: usize,
    /// Trials still searching.
    pub open: usize,
}

/// How a trial ends, for [`Writer::record_and_end_last`].
#[derive(Clone, Copy, Debug)]
pub struct TrialEnding<'a> {
    /// Done, exhausted or abandoned.
    pub status: TrialStatus,
    /// Its cost, metres.
    pub cost: f64,
    /// Every candidate's replay cost, when done.
    pub replays: Option<&'a [f64]>,
}

/// A trial to store.
#[derive(Clone, Copy, Debug)]
pub struct NewTrial<'a> {
    /// Its deployment.
    pub deployment: i64,
    /// 1-based position in the deployment.
    pub k: i64,
    /// The scene's name.
    pub scene: &'a str,
    /// The target type (for a task, its targets' label).
    pub target: &'a str,
    /// The robot's pose at the start, when given.
    pub pose: Option<[f64; 3]>,
    /// Index of the chosen strategy.
    pub chosen: usize,
    /// How many of the deployment's trials had ended when it started.
    pub started_after: i64,
    /// The household task, for a trial of one.
    pub task: Option<&'a crate::model::TaskBody>,
    /// The team, for a trial searched by several robots.
    pub robots: Option<&'a [crate::model::TeamRobot]>,
    /// The robot that started it alone and named itself.
    pub robot: Option<&'a str>,
    /// When it started (Unix milliseconds): its robot's first message.
    pub heard_ms: i64,
}

impl Reader<'_> {
    fn trials_where(&self, clause: &str, keys: &[Value]) -> Result<Vec<StoredTrial>, StoreError> {
        let rows = self.conn.query(
            &format!("SELECT {TRIAL_COLUMNS} FROM trials WHERE {clause} ORDER BY k"),
            keys,
        )?;
        self.conn.trials(&rows)
    }

    /// A deployment's trials, in order.
    ///
    /// # Errors
    /// The database refuses, or a row does not parse.
    pub fn trials_of(&self, deployment: i64) -> Result<Vec<StoredTrial>, StoreError> {
        self.trials_where("deployment = $1", &[deployment.into()])
    }

    /// The trials of a deployment that started after its first `started` or ended after its
    /// first `ended` (in order of start): what happened since a state made from those, read in
    /// one statement so that it continues that state consistently. Both halves are index range
    /// scans, so a long history costs nothing here.
    ///
    /// # Errors
    /// The database refuses, or a row does not parse.
    pub fn trials_since(
        &self,
        deployment: i64,
        started: usize,
        ended: usize,
    ) -> Result<Vec<StoredTrial>, StoreError> {
        let count = |n: usize| i64::try_from(n).unwrap_or(i64::MAX);
        self.trials_where(
            SINCE,
            &[
                deployment.into(),
                count(started).into(),
                count(ended).into(),
            ],
        )
    }

    /// The first trial of a deployment still searching, if any.
    ///
    /// # Errors
    /// The database refuses.
    pub fn open_trial(&self, deployment: i64) -> Result<Option<i64>, StoreError> {
        let c = &self.conn;
        c.query_opt(
            "SELECT id FROM trials WHERE deployment = $1 AND end_seq IS NULL ORDER BY k LIMIT 1",
            &[deployment.into()],
        )?
        .map(|row| c.int(&row, 0, "trial id"))
        .transpose()
    }

    /// A trial by id.
    ///
    /// # Errors
    /// The database refuses, or the row does not parse.
    pub fn trial(&self, id: i64) -> Result<Option<StoredTrial>, StoreError> {
        Ok(self
            .trials_where("id = $1", &[id.into()])?
            .into_iter()
            .next())
    }

    /// A trial's observations, in order.
    ///
    /// # Errors
    /// The database refuses, or a row does not parse.
    pub fn observations(&self, trial: i64) -> Result<Vec<StoredObservation>, StoreError> {
        let c = &self.conn;
        c.query(
            "SELECT container, found, objects, travelled, leg, robot FROM observations
             WHERE trial = $1 ORDER BY seq",
            &[trial.into()],
        )?
        .iter()
        .map(|r| {
            let objects = c.some_text(r, 2, "observation objects")?;
            Ok(StoredObservation {
                container: c.some_text(r, 0, "observation container")?,
                found: c.bool(r, 1, "observation found")?,
                objects: serde_json::from_str(&objects)
                    .map_err(|_| c.corrupt(format!("trial {trial}: objects")))?,
                travelled: c.real(r, 3, "observation travelled")?,
                leg: c
                    .real(r, 4, "observation leg")?
                    .ok_or_else(|| c.corrupt(format!("trial {trial}: leg")))?,
                robot: c.text(r, 5, "observation robot")?,
            })
        })
        .collect()
    }
}
