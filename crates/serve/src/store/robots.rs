//! The `trial_robots` table: a team trial's robots, each with the container it claimed (no two
//! robots of a trial hold the same one: the table's unique key says so whatever a replica
//! plans) and when it was last heard from.

use crate::model::StoredRobot;

use super::Final;
use super::conn::{Reader, Writer};
use super::error::StoreError;

impl Reader<'_> {
    /// A team trial's robots that have called, in no particular order.
    ///
    /// # Errors
    /// The database refuses, or a row does not parse.
    pub fn trial_robots(&self, trial: i64) -> Result<Vec<StoredRobot>, StoreError> {
        let c = &self.conn;
        c.query(
            "SELECT robot, claim, claim_expires_ms, heard_ms FROM trial_robots WHERE trial = $1",
            &[trial.into()],
        )?
        .iter()
        .map(|r| {
            let claim = match c.text(r, 1, "robot claim")? {
                Some(container) => Some((container, c.int(r, 2, "robot claim expiry")?)),
                None => None,
            };
            Ok(StoredRobot {
                robot: c.some_text(r, 0, "robot id")?,
                claim,
                heard_ms: c.int(r, 3, "robot heard")?,
            })
        })
        .collect()
    }
}

impl Writer<'_> {
    /// A statement that lets go of every claim of `trial` (it has ended), to run with the
    /// commit after [`claim_last`](Self::claim_last)'s.
    pub fn release_claims_last(&self, trial: i64) -> Final {
        Final {
            sql: "UPDATE trial_robots SET claim = NULL, claim_expires_ms = NULL WHERE trial = $1",
            params: vec![trial.into()],
        }
    }

    /// Statements that let go of the claims of `trial` that lapsed by `now_ms` and of any claim
    /// on `searched` (a container just searched), then record that `robot` was heard from at
    /// `now_ms`, holding `claim` (a container and when it lapses) or nothing: to run with the
    /// commit, in this order, so that the claim taken never meets one let go.
    pub fn claim_last(
        &self,
        (trial, robot): (i64, &str),
        now_ms: i64,
        searched: Option<&str>,
        claim: Option<(&str, i64)>,
    ) -> Vec<Final> {
        let mut statements = vec![Final {
            sql: "UPDATE trial_robots SET claim = NULL, claim_expires_ms = NULL
                 WHERE trial = $1 AND (claim_expires_ms <= $2 OR claim = $3 OR robot = $4)",
            params: vec![trial.into(), now_ms.into(), searched.into(), robot.into()],
        }];
        statements.push(Final {
            sql: "INSERT INTO trial_robots (trial, robot, claim, claim_expires_ms, heard_ms)
                 VALUES ($1, $2, $3, $4, $5)
                 ON CONFLICT (trial, robot) DO UPDATE SET claim = excluded.claim,
                     claim_expires_ms = excluded.claim_expires_ms, heard_ms = excluded.heard_ms",
            params: vec![
                trial.into(),
                robot.into(),
                claim.map(|c| c.0).into(),
                claim.map(|c| c.1).into(),
                now_ms.into(),
            ],
        });
        statements
    }
}
