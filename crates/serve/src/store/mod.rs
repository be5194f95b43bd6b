//! The service's memory, on one of two backends: an SQLite file (the embedded default: WAL,
//! `synchronous = FULL`) or a PostgreSQL database that several server replicas share. A row is
//! on disk before the reply that reports it leaves the server, and everything the service knows
//! is derived from the rows (a trial's belief from its observations, a deployment's selector from
//! its trials and the order they ended), which is what makes a `kill -9` of any replica harmless.
//!
//! Both backends run the same statements (written in the SQL both speak, `$n` parameters in
//! order) and read rows into the same `Value`s, so the row parsing below exists once; only
//! the schema's column types, its migrations and row locks differ.

mod postgres;
mod sqlite;

use std::path::Path;

use crate::model::{
    DeploymentSpec, Outcome, StoredDeployment, StoredObservation, StoredReply, StoredTrial,
    TrialStatus,
};

pub use postgres::PostgresOptions;

/// The newest schema version this build writes. Version 1 is the schema of the first servers
/// (their SQLite files record no version); version 2 records the order trials started and ended
/// in, for deployments whose trials overlap.
pub const SCHEMA_VERSION: i64 = 2;

/// Version 2 on both backends, once its columns exist: the trials of the first servers, one at a
/// time per deployment, started after every earlier trial ended and ended in the order they
/// started.
const END_ORDER: &str = "
    UPDATE trials SET started_after = (
        SELECT count(*) FROM trials AS t
        WHERE t.deployment = trials.deployment AND t.k < trials.k AND t.status <> 'searching');
    UPDATE trials SET end_seq = (
        SELECT count(*) FROM trials AS t
        WHERE t.deployment = trials.deployment AND t.k <= trials.k AND t.status <> 'searching')
    WHERE status <> 'searching';
    CREATE UNIQUE INDEX trials_end_order ON trials (deployment, end_seq);";

/// Storage failures (the database, not the request).
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    /// SQLite refused.
    #[error("database {file}: {source}")]
    Sql {
        /// The database file.
        file: String,
        /// SQLite's error.
        #[source]
        source: rusqlite::Error,
    },
    /// PostgreSQL refused or could not be reached.
    #[error("database {db}: {}", postgres_detail(source))]
    Postgres {
        /// The database, without its password.
        db: String,
        /// The client's error.
        #[source]
        source: tokio_postgres::Error,
    },
    /// No connection to PostgreSQL could be had (the pool, or the server, is overwhelmed or down).
    #[error("database {db}: {what}")]
    Unreachable {
        /// The database, without its password.
        db: String,
        /// What failed.
        what: String,
    },
    /// A stored row does not parse (the database was edited or written by another version).
    #[error("database {file}: {what}")]
    Corrupt {
        /// The database.
        file: String,
        /// What is wrong.
        what: String,
    },
    /// The SQLite file the server opened was emptied, removed or replaced underneath it: what
    /// it would write now could not be kept.
    #[error("database {file}: {what}; restart the server on a good copy")]
    Lost {
        /// The database file.
        file: String,
        /// What happened to it.
        what: String,
    },
    /// The database's schema is one this build cannot use.
    #[error("database {db}: {what}")]
    Schema {
        /// The database.
        db: String,
        /// What is wrong, and what to do.
        what: String,
    },
}

impl StoreError {
    /// True when a row was refused for a key another row holds.
    pub fn is_duplicate(&self) -> bool {
        match self {
            StoreError::Postgres { source, .. } => {
                source.code() == Some(&tokio_postgres::error::SqlState::UNIQUE_VIOLATION)
            }
            StoreError::Sql { source, .. } => {
                source.sqlite_error_code() == Some(rusqlite::ErrorCode::ConstraintViolation)
            }
            _ => false,
        }
    }

    /// True when the failure is the database being out of reach (or shutting down) rather than
    /// a fault in its data: a request may be retried, here or on another replica.
    pub fn is_unavailable(&self) -> bool {
        match self {
            StoreError::Unreachable { .. } | StoreError::Lost { .. } => true,
            StoreError::Postgres { source, .. } => {
                use tokio_postgres::error::SqlState;
                source.is_closed()
                    || match source.code() {
                        None => true,
                        // The transaction lost a race; it may simply be run again.
                        Some(c) => {
                            *c == SqlState::T_R_SERIALIZATION_FAILURE
                                || *c == SqlState::T_R_DEADLOCK_DETECTED
                                || *c == SqlState::ADMIN_SHUTDOWN
                                || *c == SqlState::CANNOT_CONNECT_NOW
                        }
                    }
            }
            StoreError::Sql { source, .. } => matches!(
                source.sqlite_error_code(),
                Some(rusqlite::ErrorCode::DatabaseBusy | rusqlite::ErrorCode::DatabaseLocked)
            ),
            _ => false,
        }
    }
}

/// What PostgreSQL said: the server's message and code when it answered, else the client's.
fn postgres_detail(e: &tokio_postgres::Error) -> String {
    match e.as_db_error() {
        Some(db) => format!("{} ({})", db.message(), db.code().code()),
        None => e.to_string(),
    }
}

/// A value of a row or a statement parameter, whichever backend holds it.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum Value {
    Null,
    Int(i64),
    Real(f64),
    Text(String),
    Bool(bool),
}

impl From<i64> for Value {
    fn from(v: i64) -> Self {
        Value::Int(v)
    }
}
impl From<f64> for Value {
    fn from(v: f64) -> Self {
        Value::Real(v)
    }
}
impl From<bool> for Value {
    fn from(v: bool) -> Self {
        Value::Bool(v)
    }
}
impl From<&str> for Value {
    fn from(v: &str) -> Self {
        Value::Text(v.to_string())
    }
}
impl From<String> for Value {
    fn from(v: String) -> Self {
        Value::Text(v)
    }
}
impl<T: Into<Value>> From<Option<T>> for Value {
    fn from(v: Option<T>) -> Self {
        v.map_or(Value::Null, Into::into)
    }
}

/// One row, read whole.
pub(crate) type Row = Vec<Value>;

/// How a reply's outcome is stored: as the numbers databases have always held (200, 201), so
/// that a database written by any version answers its retries the same.
fn stored_code(o: Outcome) -> i64 {
    match o {
        Outcome::Done => 200,
        Outcome::Created => 201,
    }
}

fn outcome_of(code: i64) -> Outcome {
    if code == 201 {
        Outcome::Created
    } else {
        Outcome::Done
    }
}

enum Backend {
    Sqlite(Box<sqlite::Sqlite>),
    Postgres(Box<postgres::Postgres>),
}

/// The database.
pub struct Store {
    backend: Backend,
}

/// A connection (or a transaction on one) of either backend.
enum Conn<'a> {
    Sqlite(&'a rusqlite::Connection, &'a sqlite::Sqlite),
    Postgres(postgres::Conn<'a>),
}

impl Store {
    /// Opens (creating if needed) the SQLite database at `path`, migrating an older schema.
    ///
    /// # Errors
    /// The file cannot be opened, is not a ferret database, or has a newer schema.
    pub fn open(path: &Path) -> Result<Store, StoreError> {
        Ok(Store {
            backend: Backend::Sqlite(Box::new(sqlite::Sqlite::open(path)?)),
        })
    }

    /// A database in memory (tests, benchmarks).
    ///
    /// # Errors
    /// SQLite cannot allocate it.
    pub fn in_memory() -> Result<Store, StoreError> {
        Ok(Store {
            backend: Backend::Sqlite(Box::new(sqlite::Sqlite::in_memory()?)),
        })
    }

    /// Connects to the PostgreSQL database at `url` (`postgres://user@host:port/db`), creating
    /// or migrating its schema (one replica at a time: the migration holds a lock).
    ///
    /// # Errors
    /// The URL does not parse, the server cannot be reached, or its schema is newer.
    pub fn connect(url: &str, options: PostgresOptions) -> Result<Store, StoreError> {
        Ok(Store {
            backend: Backend::Postgres(Box::new(postgres::Postgres::connect(url, options)?)),
        })
    }

    /// Opens what `db` names: a `postgres://` or `postgresql://` URL, or an SQLite file path.
    ///
    /// # Errors
    /// See [`Store::open`] and [`Store::connect`].
    pub fn open_any(db: &str, options: PostgresOptions) -> Result<Store, StoreError> {
        if is_postgres_url(db) {
            Self::connect(db, options)
        } else {
            Self::open(Path::new(db))
        }
    }

    /// The database as logs and messages name it (a PostgreSQL URL without its password).
    pub fn describe(&self) -> String {
        match &self.backend {
            Backend::Sqlite(s) => s.file.clone(),
            Backend::Postgres(p) => p.db.clone(),
        }
    }

    /// True on PostgreSQL (several replicas may share it).
    pub fn is_shared(&self) -> bool {
        matches!(self.backend, Backend::Postgres(_))
    }

    /// The schema version the database records.
    ///
    /// # Errors
    /// The database cannot be read.
    pub fn schema_version(&self) -> Result<i64, StoreError> {
        match &self.backend {
            Backend::Sqlite(s) => s.schema_version(),
            Backend::Postgres(p) => p.schema_version(),
        }
    }

    /// Reads every page of an SQLite file on a connection of its own, so damage is seen
    /// wherever it is; PostgreSQL checks its own pages, so there this passes.
    ///
    /// # Errors
    /// [`StoreError::Corrupt`] with SQLite's first finding, or [`StoreError::Sql`].
    pub fn check_file(&self) -> Result<(), StoreError> {
        match &self.backend {
            Backend::Sqlite(s) => s.check_file(),
            Backend::Postgres(_) => Ok(()),
        }
    }

    /// Reads with a connection.
    ///
    /// # Errors
    /// What `f` returns, or no connection to be had.
    pub fn read<T>(
        &self,
        f: impl FnOnce(&Reader<'_>) -> Result<T, StoreError>,
    ) -> Result<T, StoreError> {
        match &self.backend {
            Backend::Sqlite(s) => {
                let conn = s.lock();
                f(&Reader {
                    conn: Conn::Sqlite(&conn, s),
                })
            }
            Backend::Postgres(p) => p.read(|conn| f(&Reader { conn })),
        }
    }

    /// Runs `f` in one transaction, committed when it returns `Ok`, rolled back otherwise.
    ///
    /// # Errors
    /// What `f` returns, or the transaction failing to begin or commit.
    pub fn write<T, E: From<StoreError>>(
        &self,
        f: impl FnOnce(&Writer<'_>) -> Result<T, E>,
    ) -> Result<T, E> {
        match &self.backend {
            Backend::Sqlite(s) => s.write(|conn| f(&Writer { conn })),
            Backend::Postgres(p) => p.write(|conn| f(&Writer { conn })),
        }
    }

    /// Replaces the body of request `id`'s stored reply, in a transaction of its own (one
    /// round trip on PostgreSQL). Used for a reply that completes one stored before (a trial
    /// start's plan): losing it to a crash of the database only means that a retry plans again,
    /// to the same reply, so on PostgreSQL it does not wait for its commit to reach the disk
    /// (`synchronous_commit` off for this transaction alone).
    ///
    /// # Errors
    /// The database refuses, or cannot be reached.
    pub fn replace_reply(&self, id: &str, body: &str) -> Result<(), StoreError> {
        const SQL: &str = "UPDATE requests SET body = $2 WHERE id = $1";
        let params = vec![request_key(id).as_ref().into(), body.into()];
        match &self.backend {
            Backend::Sqlite(s) => s.write(|conn| conn.execute(SQL, &params).map(drop)),
            Backend::Postgres(p) => {
                let finals = vec![
                    Final {
                        sql: "SET LOCAL synchronous_commit TO OFF",
                        params: Vec::new(),
                    },
                    Final { sql: SQL, params },
                ];
                p.write_finishing(|_| Ok::<_, StoreError>(((), finals)))?
                    .map_err(|failed| failed.error)
            }
        }
    }

    /// Like [`write`](Self::write), with statements `f` gives to run last: they are sent with
    /// the commit (on PostgreSQL in one round trip, so that locks they take are held no longer
    /// than the server takes to run them). When one of them fails the transaction is rolled
    /// back and the inner error says which.
    ///
    /// # Errors
    /// What `f` returns, or the transaction failing to begin or commit.
    pub fn write_finishing<T, E: From<StoreError>>(
        &self,
        f: impl FnOnce(&Writer<'_>) -> Result<(T, Vec<Final>), E>,
    ) -> Result<Result<T, FinalFailed>, E> {
        match &self.backend {
            Backend::Sqlite(s) => s.write_finishing(|conn| f(&Writer { conn })),
            Backend::Postgres(p) => p.write_finishing(|conn| f(&Writer { conn })),
        }
    }

    /// Claims `key` for one request across every replica of the database while the returned
    /// guard lives: `None` when another replica holds it. On SQLite (one server per file) there
    /// is nothing to claim across processes and this always succeeds.
    ///
    /// # Errors
    /// The database cannot be reached.
    pub fn claim(&self, key: &str) -> Result<Option<Claim<'_>>, StoreError> {
        match &self.backend {
            Backend::Sqlite(_) => Ok(Some(Claim { held: None })),
            Backend::Postgres(p) => Ok(p.claim(key)?.map(|k| Claim { held: Some((p, k)) })),
        }
    }

    /// [`claim`](Self::claim), with `during` run while the claim is asked for (on PostgreSQL
    /// the claim's round trip and the statements `during` runs overlap): for what is safe to
    /// do before the claim is known, such as looking up a stored reply whose absence is checked
    /// again when the reply is stored.
    ///
    /// # Errors
    /// As [`claim`](Self::claim), beside what `during` returns.
    pub fn claim_while<T>(
        &self,
        key: &str,
        during: impl FnOnce() -> T,
    ) -> (Result<Option<Claim<'_>>, StoreError>, T) {
        match &self.backend {
            Backend::Sqlite(_) => (Ok(Some(Claim { held: None })), during()),
            Backend::Postgres(p) => {
                let (claimed, out) = p.claim_while(key, during);
                (
                    claimed.map(|k| k.map(|k| Claim { held: Some((p, k)) })),
                    out,
                )
            }
        }
    }
}

/// A request key held across replicas; released when dropped (or when the replica holding it
/// dies, since the lock belongs to its database session).
pub struct Claim<'a> {
    held: Option<(&'a postgres::Postgres, (i32, i32))>,
}

impl Drop for Claim<'_> {
    fn drop(&mut self) {
        if let Some((p, key)) = self.held.take() {
            p.release(key);
        }
    }
}

/// True when `db` is a PostgreSQL URL rather than a file path.
pub fn is_postgres_url(db: &str) -> bool {
    db.starts_with("postgres://") || db.starts_with("postgresql://")
}

impl Conn<'_> {
    fn execute(&self, sql: &str, params: &[Value]) -> Result<u64, StoreError> {
        match self {
            Conn::Sqlite(c, s) => sqlite::execute(c, s, sql, params),
            Conn::Postgres(c) => c.execute(sql, params),
        }
    }

    fn query(&self, sql: &str, params: &[Value]) -> Result<Vec<Row>, StoreError> {
        match self {
            Conn::Sqlite(c, s) => sqlite::query(c, s, sql, params),
            Conn::Postgres(c) => c.query(sql, params),
        }
    }

    /// A trial's status and observation count from a row of [`PROGRESS`].
    fn progress(&self, id: i64, row: &Row) -> Result<(TrialStatus, usize), StoreError> {
        let bad = |what: &str| self.corrupt(format!("trial {id}: {what}"));
        let status = TrialStatus::parse(&self.some_text(row, 0, "trial status")?)
            .ok_or_else(|| bad("status"))?;
        let seen = usize::try_from(self.int(row, 1, "observation count")?)
            .map_err(|_| bad("observation count"))?;
        Ok((status, seen))
    }

    /// Trials from rows of [`TRIAL_COLUMNS`].
    fn trials(&self, rows: &[Row]) -> Result<Vec<StoredTrial>, StoreError> {
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
                })
            })
            .collect()
    }

    /// Runs `statements` in order; on PostgreSQL they are sent at once (one round trip).
    fn query_all(&self, statements: &[(&str, &[Value])]) -> Result<Vec<Vec<Row>>, StoreError> {
        match self {
            Conn::Sqlite(c, s) => statements
                .iter()
                .map(|(sql, params)| sqlite::query(c, s, sql, params))
                .collect(),
            Conn::Postgres(c) => c.query_all(statements),
        }
    }

    fn query_opt(&self, sql: &str, params: &[Value]) -> Result<Option<Row>, StoreError> {
        Ok(self.query(sql, params)?.into_iter().next())
    }

    fn corrupt(&self, what: String) -> StoreError {
        let file = match self {
            Conn::Sqlite(_, s) => s.file.clone(),
            Conn::Postgres(c) => c.db().to_string(),
        };
        StoreError::Corrupt { file, what }
    }

    /// The value at `i` of `row`, or a corrupt-row error naming `what`.
    fn int(&self, row: &Row, i: usize, what: &str) -> Result<i64, StoreError> {
        match row.get(i) {
            Some(Value::Int(v)) => Ok(*v),
            other => Err(self.corrupt(format!("{what}: expected an integer, found {other:?}"))),
        }
    }

    fn real(&self, row: &Row, i: usize, what: &str) -> Result<Option<f64>, StoreError> {
        match row.get(i) {
            Some(Value::Real(v)) => Ok(Some(*v)),
            // SQLite hands back a whole REAL as an integer when it was stored as one.
            Some(Value::Int(v)) => Ok(Some(*v as f64)),
            Some(Value::Null) => Ok(None),
            other => Err(self.corrupt(format!("{what}: expected a number, found {other:?}"))),
        }
    }

    fn text(&self, row: &Row, i: usize, what: &str) -> Result<Option<String>, StoreError> {
        match row.get(i) {
            Some(Value::Text(v)) => Ok(Some(v.clone())),
            Some(Value::Null) => Ok(None),
            other => Err(self.corrupt(format!("{what}: expected text, found {other:?}"))),
        }
    }

    fn some_text(&self, row: &Row, i: usize, what: &str) -> Result<String, StoreError> {
        self.text(row, i, what)?
            .ok_or_else(|| self.corrupt(format!("{what}: missing")))
    }

    fn bool(&self, row: &Row, i: usize, what: &str) -> Result<bool, StoreError> {
        match row.get(i) {
            Some(Value::Bool(v)) => Ok(*v),
            Some(Value::Int(v)) => Ok(*v != 0),
            other => Err(self.corrupt(format!("{what}: expected a boolean, found {other:?}"))),
        }
    }
}

/// Read access inside [`Store::read`] (also available to writers).
pub struct Reader<'a> {
    conn: Conn<'a>,
}

/// Write access inside [`Store::write`].
pub struct Writer<'a> {
    conn: Conn<'a>,
}

impl Writer<'_> {
    /// Reads inside the transaction.
    pub fn reader(&self) -> Reader<'_> {
        Reader {
            conn: match &self.conn {
                Conn::Sqlite(c, s) => Conn::Sqlite(c, s),
                Conn::Postgres(c) => Conn::Postgres(c.reborrow()),
            },
        }
    }

    fn lock_deployment_sql(&self) -> &'static str {
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

    /// Stores trial `t` under id `id` (from [`lock_deployment_since`]), as a statement run
    /// with the commit.
    ///
    /// [`lock_deployment_since`]: Self::lock_deployment_since
    pub fn insert_trial_last(&self, id: i64, t: &NewTrial<'_>) -> Final {
        let pose = t.pose.map(|p| serde_json::json!(p).to_string());
        Final {
            sql: "INSERT INTO trials (id, deployment, k, scene, target, pose, chosen, status, started_after)
                 VALUES ($1, $2, $3, $4, $5, $6, $7, 'searching', $8)",
            params: vec![
                id.into(),
                t.deployment.into(),
                t.k.into(),
                t.scene.into(),
                t.target.into(),
                pose.into(),
                (t.chosen as i64).into(),
                t.started_after.into(),
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

    /// Statements that store observation `seq` of `trial` (unless `observation` is `None`)
    /// and, when `end` says how, end the trial as the next of `deployment`'s trials to end,
    /// taking the deployment's lock for that: to run with the commit, so that the deployment
    /// is held for no round trip at all. Take the trial's lock first
    /// ([`lock_trial_progress`](Self::lock_trial_progress)): a transaction taking both takes
    /// the trial's first, so two never wait for each other.
    pub fn record_and_end_last(
        &self,
        (trial, deployment): (i64, i64),
        observation: Option<(usize, &StoredObservation)>,
        end: Option<TrialEnding<'_>>,
    ) -> Vec<Final> {
        let mut statements = Vec::new();
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

    /// Stores a scene's text under its name.
    ///
    /// # Errors
    /// The database refuses (a taken name).
    pub fn insert_scene(&self, name: &str, body: &str) -> Result<(), StoreError> {
        self.conn.execute(
            "INSERT INTO scenes (name, body) VALUES ($1, $2)",
            &[name.into(), body.into()],
        )?;
        Ok(())
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

/// How a request id is stored: as given, unless it holds NUL, which PostgreSQL text cannot.
/// Such an id is stored as the hex of its bytes behind 201 `~`: longer than any id the API
/// takes (200 characters), so it never equals an id stored as given.
fn request_key(id: &str) -> std::borrow::Cow<'_, str> {
    if !id.contains('\0') {
        return std::borrow::Cow::Borrowed(id);
    }
    let mut key = "~".repeat(201);
    for b in id.bytes() {
        key.push_str(&format!("{b:02x}"));
    }
    std::borrow::Cow::Owned(key)
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

/// A deployment as a trial's start finds it under its lock.
#[derive(Clone, Debug)]
pub struct DeploymentNow {
    /// Its trials started or ended since what the caller knew.
    pub since: Vec<StoredTrial>,
    /// The ids the new trials will have, in order.
    pub next_trials: Vec<i64>,
}

/// A statement a write runs last, with its commit ([`Store::write_finishing`]).
#[derive(Clone, Debug)]
pub struct Final {
    sql: &'static str,
    params: Vec<Value>,
}

/// The final statement that failed, the transaction rolled back.
#[derive(Debug)]
pub struct FinalFailed {
    /// Its place among the final statements.
    pub index: usize,
    /// What the database said.
    pub error: StoreError,
}

/// The reply to request `id`, stored as the last statement of its write: a second reply to the
/// same id is refused ([`StoreError::is_duplicate`]), rolling back the write it ended.
pub fn store_reply(id: &str, reply: &StoredReply) -> Final {
    Final {
        sql: "INSERT INTO requests (id, fingerprint, status, body) VALUES ($1, $2, $3, $4)",
        params: vec![
            request_key(id).as_ref().into(),
            reply.fingerprint.as_str().into(),
            stored_code(reply.outcome).into(),
            reply.body.as_str().into(),
        ],
    }
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
    /// The target type.
    pub target: &'a str,
    /// The robot's pose at the start, when given.
    pub pose: Option<[f64; 3]>,
    /// Index of the chosen strategy.
    pub chosen: usize,
    /// How many of the deployment's trials had ended when it started.
    pub started_after: i64,
}

/// A trial's status and number of observations.
const PROGRESS: &str = "SELECT status, (SELECT count(*) FROM observations WHERE trial = $1)
     FROM trials WHERE id = $1";

const INSERT_OBSERVATION: &str =
    "INSERT INTO observations (trial, seq, container, found, objects, travelled, leg)
     VALUES ($1, $2, $3, $4, $5, $6, $7)";

/// A deployment's trials started after its first `$2` or ended after its first `$3`.
const SINCE: &str = "deployment = $1 AND (k > $2 OR end_seq > $3)";

const TRIAL_COLUMNS: &str =
    "id, deployment, k, scene, target, pose, chosen, status, cost, replays, started_after, end_seq";

impl Reader<'_> {
    /// Every stored scene: `(name, body)`.
    ///
    /// # Errors
    /// The database refuses.
    pub fn scenes(&self) -> Result<Vec<(String, String)>, StoreError> {
        self.conn
            .query("SELECT name, body FROM scenes ORDER BY name", &[])?
            .iter()
            .map(|r| {
                Ok((
                    self.conn.some_text(r, 0, "scene name")?,
                    self.conn.some_text(r, 1, "scene body")?,
                ))
            })
            .collect()
    }

    /// Every stored scene's name with its numbers of rooms and containers, counted by the
    /// database without loading the scenes (0 for a body that is not JSON).
    ///
    /// # Errors
    /// The database refuses.
    pub fn scene_summaries(&self) -> Result<Vec<(String, usize, usize)>, StoreError> {
        let sql = match &self.conn {
            Conn::Sqlite(..) => {
                "SELECT name,
                    CASE WHEN json_valid(body) THEN json_array_length(body, '$.rooms') END,
                    CASE WHEN json_valid(body) THEN json_array_length(body, '$.containers') END
                 FROM scenes ORDER BY name"
            }
            // Uploaded bodies were parsed before they were stored, so the cast cannot fail.
            Conn::Postgres(_) => {
                "SELECT name,
                    json_array_length((body::json) -> 'rooms')::bigint,
                    json_array_length((body::json) -> 'containers')::bigint
                 FROM scenes ORDER BY name"
            }
        };
        let count = |v: Option<&Value>| match v {
            Some(Value::Int(n)) => usize::try_from(*n).unwrap_or(0),
            _ => 0,
        };
        self.conn
            .query(sql, &[])?
            .iter()
            .map(|r| {
                Ok((
                    self.conn.some_text(r, 0, "scene name")?,
                    count(r.get(1)),
                    count(r.get(2)),
                ))
            })
            .collect()
    }

    /// A stored scene's body.
    ///
    /// # Errors
    /// The database refuses.
    pub fn scene(&self, name: &str) -> Result<Option<String>, StoreError> {
        // Stored names are printable ASCII; PostgreSQL cannot even compare text holding NUL.
        if name.contains('\0') {
            return Ok(None);
        }
        self.conn
            .query_opt("SELECT body FROM scenes WHERE name = $1", &[name.into()])?
            .map(|r| self.conn.some_text(&r, 0, "scene body"))
            .transpose()
    }

    /// How many scenes are stored.
    ///
    /// # Errors
    /// The database refuses.
    pub fn scene_count(&self) -> Result<usize, StoreError> {
        let row = self.conn.query_opt("SELECT count(*) FROM scenes", &[])?;
        let n = row.map_or(Ok(0), |r| self.conn.int(&r, 0, "scene count"))?;
        Ok(usize::try_from(n).unwrap_or(usize::MAX))
    }

    /// Reads the schema and a row of every table: a damaged database fails here as it would on
    /// every route. Cheap, for health checks.
    ///
    /// # Errors
    /// The database refuses.
    pub fn check(&self) -> Result<(), StoreError> {
        for table in [
            "scenes",
            "deployments",
            "trials",
            "observations",
            "requests",
        ] {
            self.conn.query(
                &format!("SELECT count(*) FROM (SELECT * FROM {table} LIMIT 1) AS one"),
                &[],
            )?;
        }
        Ok(())
    }

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
            "SELECT container, found, objects, travelled, leg FROM observations
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
            })
        })
        .collect()
    }

    /// The stored reply to request `id`.
    ///
    /// # Errors
    /// The database refuses.
    pub fn reply(&self, id: &str) -> Result<Option<StoredReply>, StoreError> {
        let c = &self.conn;
        c.query_opt(
            "SELECT fingerprint, status, body FROM requests WHERE id = $1",
            &[request_key(id).as_ref().into()],
        )?
        .map(|r| {
            Ok(StoredReply {
                fingerprint: c.some_text(&r, 0, "request fingerprint")?,
                outcome: outcome_of(c.int(&r, 1, "request status")?),
                body: c.some_text(&r, 2, "request body")?,
            })
        })
        .transpose()
    }
}
