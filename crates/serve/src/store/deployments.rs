//! The `deployments` table: a deployment's spec, and the lock its trials' starts and ends
//! take.

use crate::model::{DeploymentSpec, StoredDeployment, StoredTrial};

use super::conn::{Conn, Reader, Writer};
use super::error::StoreError;
use super::trials::{SINCE, TRIAL_COLUMNS};
use super::value::Value;

impl Writer<'_> {
    pub(super) fn lock_deployment_sql(&self) -> &'static str {
        match &self.conn {
            Conn::Sqlite(..) => "SELECT id FROM deployments WHERE id = $1",
            Conn::Postgres(_) => "SELECT id FROM deployments WHERE id = $1 FOR UPDATE",
        }
    }

    /// Locks deployment `id` until the transaction ends, so that the trials of one deployment
    /// are started and ended by one replica at a time (on SQLite, every write transaction
    /// already holds the whole file), and then reads, under the lock, its trials that started
    /// after its first `started` or ended after its first `ended` (as
    /// [`Reader::trials_since`]), in one round trip: what a trial's start holds the deployment
    /// for is kept short, since every start and end of the deployment waits for it. Takes the
    /// ids of `new_trials` trials (at least one) to start. `None` when there is no such
    /// deployment.
    ///
    /// # Errors
    /// The database refuses, or a row does not parse.
    pub fn lock_deployment_since(
        &self,
        id: i64,
        (started, ended): (usize, usize),
        new_trials: usize,
    ) -> Result<Option<DeploymentNow>, StoreError> {
        let count = |n: usize| Value::from(i64::try_from(n).unwrap_or(i64::MAX));
        let since = format!("SELECT {TRIAL_COLUMNS} FROM trials WHERE {SINCE} ORDER BY k");
        // The new trials' ids, taken with the lock so that the trials and the replies naming
        // them can go with the commit. (SQLite writes one transaction at a time: the ids after
        // the largest are free.)
        let next_ids = match &self.conn {
            Conn::Sqlite(..) => {
                "WITH RECURSIVE n(i) AS (SELECT 1 UNION ALL SELECT i + 1 FROM n WHERE i < $1)
                 SELECT (SELECT coalesce(max(id), 0) FROM trials) + i FROM n ORDER BY i"
            }
            Conn::Postgres(_) => {
                "SELECT nextval(pg_get_serial_sequence('trials', 'id'))
                 FROM generate_series(1, $1::bigint)"
            }
        };
        let answers = self.conn.query_all(&[
            (next_ids, &[count(new_trials)]),
            (self.lock_deployment_sql(), &[id.into()]),
            (&since, &[id.into(), count(started), count(ended)]),
        ])?;
        match answers.as_slice() {
            [next, locked, rows] if !locked.is_empty() => {
                let next_trials = next
                    .iter()
                    .map(|row| self.conn.int(row, 0, "next trial id"))
                    .collect::<Result<Vec<_>, _>>()?;
                if next_trials.len() != new_trials {
                    return Err(self.conn.corrupt(format!(
                        "{} trial ids where {new_trials} were asked for",
                        next_trials.len()
                    )));
                }
                Ok(Some(DeploymentNow {
                    since: self.conn.trials(rows)?,
                    next_trials,
                }))
            }
            _ => Ok(None),
        }
    }

    /// Stores a new deployment; returns its id.
    ///
    /// # Errors
    /// The database refuses.
    pub fn insert_deployment(&self, spec: &DeploymentSpec) -> Result<i64, StoreError> {
        let json = serde_json::to_string(spec).map_err(|e| self.conn.corrupt(e.to_string()))?;
        let row = self
            .conn
            .query_opt(
                "INSERT INTO deployments (spec) VALUES ($1) RETURNING id",
                &[json.into()],
            )?
            .ok_or_else(|| self.conn.corrupt("a new deployment has no id".into()))?;
        self.conn.int(&row, 0, "deployment id")
    }
}

/// A deployment as a trial's start finds it under its lock.
#[derive(Clone, Debug)]
pub struct DeploymentNow {
    /// Its trials started or ended since what the caller knew.
    pub since: Vec<StoredTrial>,
    /// The ids the new trials will have, in order.
    pub next_trials: Vec<i64>,
}

impl Reader<'_> {
    /// A deployment by id.
    ///
    /// # Errors
    /// The database refuses, or the stored spec does not parse.
    pub fn deployment(&self, id: i64) -> Result<Option<StoredDeployment>, StoreError> {
        let Some(row) = self
            .conn
            .query_opt("SELECT spec FROM deployments WHERE id = $1", &[id.into()])?
        else {
            return Ok(None);
        };
        let spec = self.conn.some_text(&row, 0, "deployment spec")?;
        serde_json::from_str(&spec)
            .map(|spec| Some(StoredDeployment { id, spec }))
            .map_err(|e| self.conn.corrupt(format!("deployment {id}: {e}")))
    }

    /// Every deployment id.
    ///
    /// # Errors
    /// The database refuses.
    pub fn deployment_ids(&self) -> Result<Vec<i64>, StoreError> {
        self.conn
            .query("SELECT id FROM deployments ORDER BY id", &[])?
            .iter()
            .map(|r| self.conn.int(r, 0, "deployment id"))
            .collect()
    }

    /// The newest `limit` deployments, ascending, each with how many trials it started and its
    /// trials still searching (in the order they started).
    ///
    /// # Errors
    /// The database refuses, or a row does not parse.
    pub fn listed_deployments(&self, limit: usize) -> Result<Vec<ListedDeployment>, StoreError> {
        let c = &self.conn;
        let limit = i64::try_from(limit).unwrap_or(i64::MAX);
        let mut listed: Vec<ListedDeployment> = c
            .query(
                "SELECT d.id, d.spec, (SELECT count(*) FROM trials AS t WHERE t.deployment = d.id)
                 FROM deployments AS d ORDER BY d.id DESC LIMIT $1",
                &[limit.into()],
            )?
            .iter()
            .map(|r| {
                let spec = c.some_text(r, 1, "deployment spec")?;
                Ok(ListedDeployment {
                    id: c.int(r, 0, "deployment id")?,
                    spec: serde_json::from_str(&spec)
                        .map_err(|e| c.corrupt(format!("deployment spec: {e}")))?,
                    trials: usize::try_from(c.int(r, 2, "trial count")?).unwrap_or(0),
                    open: Vec::new(),
                })
            })
            .collect::<Result<_, StoreError>>()?;
        listed.reverse();
        let Some(first) = listed.first().map(|d| d.id) else {
            return Ok(listed);
        };
        for r in c.query(
            "SELECT deployment, id FROM trials WHERE deployment >= $1 AND end_seq IS NULL
             ORDER BY deployment, k",
            &[first.into()],
        )? {
            let (deployment, trial) = (c.int(&r, 0, "deployment id")?, c.int(&r, 1, "trial id")?);
            if let Ok(i) = listed.binary_search_by_key(&deployment, |d| d.id) {
                listed[i].open.push(trial);
            }
        }
        Ok(listed)
    }
}

/// A deployment as the list of deployments shows it.
#[derive(Debug, Clone, PartialEq)]
pub struct ListedDeployment {
    /// Its id.
    pub id: i64,
    /// How it was created.
    pub spec: DeploymentSpec,
    /// Trials it started.
    pub trials: usize,
    /// Its trials still searching, in the order they started.
    pub open: Vec<i64>,
}
