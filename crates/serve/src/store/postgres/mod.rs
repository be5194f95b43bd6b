//! The PostgreSQL backend: a pool of connections (deadpool over tokio-postgres) driven by a
//! small runtime of its own, so that the service's synchronous code (which runs on blocking
//! threads) can wait on it from anywhere. Writes of one deployment's trials serialize on the
//! deployment's row (`SELECT … FOR UPDATE`); request ids in flight are held as session
//! advisory locks on one connection of the replica, so they vanish with a replica that dies.

use std::future::Future;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use deadpool_postgres::{Manager, ManagerConfig, Pool, RecyclingMethod};
use sha2::{Digest, Sha256};
use tokio_postgres::NoTls;
use tokio_postgres::types::ToSql;

mod conn;
mod feed;

use super::SCHEMA_VERSION;
use super::error::StoreError;
use super::value::Value;
pub(super) use conn::Conn;
use conn::{On, Tx, TxState};

/// Schema migrations, version `i + 1` at index `i` (the same versions as SQLite's).
const MIGRATIONS: [&[&str]; 5] = [
    &["CREATE TABLE scenes (name TEXT PRIMARY KEY, body TEXT NOT NULL);
    CREATE TABLE deployments (id BIGSERIAL PRIMARY KEY, spec TEXT NOT NULL);
    CREATE TABLE trials (
        id BIGSERIAL PRIMARY KEY,
        deployment BIGINT NOT NULL REFERENCES deployments(id),
        k BIGINT NOT NULL, scene TEXT NOT NULL, target TEXT NOT NULL, pose TEXT,
        chosen BIGINT NOT NULL, status TEXT NOT NULL, cost DOUBLE PRECISION, replays TEXT,
        UNIQUE (deployment, k));
    CREATE TABLE observations (
        trial BIGINT NOT NULL REFERENCES trials(id), seq BIGINT NOT NULL,
        container TEXT NOT NULL, found BOOLEAN NOT NULL, objects TEXT NOT NULL,
        travelled DOUBLE PRECISION, leg DOUBLE PRECISION NOT NULL,
        PRIMARY KEY (trial, seq));
    CREATE TABLE requests (
        id TEXT PRIMARY KEY, fingerprint TEXT NOT NULL, status BIGINT NOT NULL, body TEXT NOT NULL);"],
    &[
        "ALTER TABLE trials ADD COLUMN started_after BIGINT NOT NULL DEFAULT 0;
        ALTER TABLE trials ADD COLUMN end_seq BIGINT;",
        super::END_ORDER,
    ],
    // Household tasks: a trial's targets, goal and destination (JSON; NULL for one target).
    &["ALTER TABLE trials ADD COLUMN task TEXT;"],
    // Teams: a trial's robots (JSON; NULL for one robot), who searched each container, and each
    // robot's claim and when it was last heard from.
    &["ALTER TABLE trials ADD COLUMN robots TEXT;
    ALTER TABLE observations ADD COLUMN robot TEXT;
    CREATE TABLE trial_robots (
        trial BIGINT NOT NULL REFERENCES trials(id), robot TEXT NOT NULL,
        claim TEXT, claim_expires_ms BIGINT, heard_ms BIGINT NOT NULL,
        PRIMARY KEY (trial, robot), UNIQUE (trial, claim));"],
    // Robots by name: the robot that named itself when it started a trial alone, and when a
    // trial's robot was last heard from (Unix milliseconds).
    &["ALTER TABLE trials ADD COLUMN robot TEXT;
    ALTER TABLE trials ADD COLUMN heard_ms BIGINT;"],
];

/// What a new connection's server process runs first: planning it opens every table of the
/// schema and their indexes (it returns no row).
const WARM: &str =
    "SELECT 1 FROM scenes, deployments, trials, observations, requests, trial_robots LIMIT 0";

/// `e` and what caused it, as one line: the pool's and the driver's errors say only "db error"
/// and keep the server's words (such as "too many connections for role") in their sources.
pub(super) fn with_causes(e: &dyn std::error::Error) -> String {
    let mut line = e.to_string();
    let mut cause = e.source();
    while let Some(c) = cause {
        // The pool's error repeats its source's words in its own.
        let words = c.to_string();
        if !line.ends_with(&words) {
            line.push_str(": ");
            line.push_str(&words);
        }
        cause = c.source();
    }
    line
}

/// The advisory lock every replica takes while it migrates, so two starting at once do not
/// both migrate ("ferret" in ASCII).
const MIGRATION_LOCK: i64 = 0x6665_7272_6574;

/// How a replica uses PostgreSQL.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PostgresOptions {
    /// Connections in the replica's pool: requests that need one beyond this wait.
    pub pool_size: usize,
    /// How long a request waits for a connection (or for one to be made) before it fails
    /// with 503.
    pub wait: Duration,
}

impl Default for PostgresOptions {
    fn default() -> Self {
        Self {
            pool_size: 16,
            wait: Duration::from_secs(10),
        }
    }
}

pub(super) struct Postgres {
    pool: Pool,
    /// Drives the pool's connections; `Option` so that dropping the store (possibly on an
    /// async thread) shuts it down without blocking.
    runtime: Option<tokio::runtime::Runtime>,
    config: tokio_postgres::Config,
    pub(super) db: String,
    /// The session that holds this replica's request claims (advisory locks belong to a
    /// session, so they cannot live on pooled connections). The lock guards only reconnecting:
    /// requests share the session, whose client pipelines their statements.
    claims: Mutex<Option<Arc<ClaimSession>>>,
}

/// The claims session with its two statements prepared once: each request takes and releases
/// a claim, and an unprepared statement costs a round trip of its own every time.
struct ClaimSession {
    client: tokio_postgres::Client,
    lock: tokio_postgres::Statement,
    unlock: tokio_postgres::Statement,
}

impl Drop for Postgres {
    fn drop(&mut self) {
        if let Some(rt) = self.runtime.take() {
            rt.shutdown_background();
        }
    }
}

/// `url` as logs may show it: without its password.
fn describe(config: &tokio_postgres::Config) -> String {
    let host = config
        .get_hosts()
        .first()
        .map(|h| match h {
            tokio_postgres::config::Host::Tcp(h) => h.clone(),
            #[cfg(unix)]
            tokio_postgres::config::Host::Unix(p) => p.display().to_string(),
        })
        .unwrap_or_default();
    let port = config.get_ports().first().copied().unwrap_or(5432);
    format!(
        "postgres://{}@{host}:{port}/{}",
        config.get_user().unwrap_or(""),
        config.get_dbname().unwrap_or("")
    )
}

impl Postgres {
    pub(super) fn connect(url: &str, options: PostgresOptions) -> Result<Postgres, StoreError> {
        let config: tokio_postgres::Config =
            url.parse()
                .map_err(|e: tokio_postgres::Error| StoreError::Unreachable {
                    db: "postgres".into(),
                    what: format!(
                        "not a PostgreSQL URL ({e}); write postgres://user@host:port/database"
                    ),
                })?;
        let db = describe(&config);
        let unreachable = |what: String| StoreError::Unreachable {
            db: db.clone(),
            what,
        };
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(1)
            .thread_name("ferret-postgres")
            .enable_all()
            .build()
            .map_err(|e| unreachable(format!("starting the client's runtime: {e}")))?;
        let manager = Manager::from_config(
            config.clone(),
            NoTls,
            ManagerConfig {
                recycling_method: RecyclingMethod::Fast,
            },
        );
        let pool = Pool::builder(manager)
            .max_size(options.pool_size.max(1))
            .runtime(deadpool_postgres::Runtime::Tokio1)
            .wait_timeout(Some(options.wait))
            .create_timeout(Some(options.wait))
            .build()
            .map_err(|e| unreachable(format!("building the connection pool: {e}")))?;
        let pg = Postgres {
            pool,
            runtime: Some(runtime),
            config,
            db,
            claims: Mutex::new(None),
        };
        pg.migrate()?;
        pg.warm(options.pool_size.max(1));
        Ok(pg)
    }

    /// Opens the pool's connections and the claims session before the first request, each
    /// connection's server process reading the definitions of every table and index: robots
    /// that start at once after a replica starts would otherwise each wait for a connection to
    /// be made and for a new server process to load its catalog, and their first starts were
    /// a fleet's slowest. A connection that cannot be made now is only logged: the pool makes
    /// it when a request needs it.
    fn warm(&self, size: usize) {
        let started = std::time::Instant::now();
        let failures: Vec<String> = self.block_on(async {
            let clients = futures_util::future::join_all((0..size).map(|_| self.pool.get())).await;
            futures_util::future::join_all(clients.into_iter().map(|c| async move {
                match c {
                    Ok(c) => c.batch_execute(WARM).await.err().map(|e| with_causes(&e)),
                    Err(e) => Some(with_causes(&e)),
                }
            }))
            .await
            .into_iter()
            .flatten()
            .collect()
        });
        if let Some(first) = failures.first() {
            tracing::warn!(
                "{}: {} of {size} connections could not be opened now ({first}); the pool opens them when requests need them",
                self.db,
                failures.len()
            );
        }
        match self.claim_session() {
            Err(e) => tracing::warn!(
                "{}: the claims session could not be opened now ({e}); it is opened when a request needs it",
                self.db
            ),
            Ok(_) if failures.is_empty() => tracing::info!(
                "{}: {size} connections and the claims session open in {:.0} ms",
                self.db,
                started.elapsed().as_secs_f64() * 1e3
            ),
            Ok(_) => {}
        }
    }

    fn block_on<F: std::future::Future>(&self, f: F) -> F::Output {
        match &self.runtime {
            Some(rt) => rt.block_on(f),
            // Only while dropping, when nothing runs statements any more.
            None => unreachable!("the PostgreSQL runtime is gone"),
        }
    }

    fn pg(&self, source: tokio_postgres::Error) -> StoreError {
        StoreError::Postgres {
            db: self.db.clone(),
            source,
        }
    }

    fn client(&self) -> Result<deadpool_postgres::Client, StoreError> {
        self.block_on(self.pool.get())
            .map_err(|e| StoreError::Unreachable {
                db: self.db.clone(),
                what: format!("no connection: {e}"),
            })
    }

    pub(super) fn read<T>(
        &self,
        f: impl FnOnce(Conn<'_>) -> Result<T, StoreError>,
    ) -> Result<T, StoreError> {
        let client = self.client()?;
        f(Conn {
            on: On::Client(&client),
            pg: self,
        })
    }

    pub(super) fn write<T, E: From<StoreError>>(
        &self,
        f: impl FnOnce(Conn<'_>) -> Result<T, E>,
    ) -> Result<T, E> {
        self.transaction(f)
    }

    /// Runs `f` in a transaction, committed when it returns `Ok`, rolled back otherwise.
    fn transaction<T, E: From<StoreError>>(
        &self,
        f: impl FnOnce(Conn<'_>) -> Result<T, E>,
    ) -> Result<T, E> {
        let tx = Tx::new(self.client()?);
        let out = f(Conn {
            on: On::Tx(&tx),
            pg: self,
        });
        match out {
            Ok(out) => {
                self.end(tx, "COMMIT")?;
                Ok(out)
            }
            Err(e) => {
                // The error said what went wrong; a failed rollback discards the connection.
                let _ = self.end(tx, "ROLLBACK");
                Err(e)
            }
        }
    }

    /// Ends `tx` with `how` (`COMMIT` or `ROLLBACK`), if it began.
    fn end(&self, tx: Tx, how: &str) -> Result<(), StoreError> {
        if tx.state.get() == TxState::Open {
            self.block_on(tx.client().batch_execute(how))
                .map_err(|e| self.pg(e))?;
        }
        tx.state.set(TxState::Ended);
        Ok(())
    }

    pub(super) fn write_finishing<T, E: From<StoreError>>(
        &self,
        f: impl FnOnce(Conn<'_>) -> Result<(T, Vec<super::Final>), E>,
    ) -> Result<Result<T, super::FinalFailed>, E> {
        let tx = Tx::new(self.client()?);
        let (out, finals) = match f(Conn {
            on: On::Tx(&tx),
            pg: self,
        }) {
            Ok(done) => done,
            Err(e) => {
                let _ = self.end(tx, "ROLLBACK");
                return Err(e);
            }
        };
        let params: Vec<Vec<&(dyn ToSql + Sync)>> = finals
            .iter()
            .map(|last| last.params.iter().map(|v| v as _).collect())
            .collect();
        let client = tx.client();
        let begin = tx.begin();
        // `sent`: the commit went out with them (else, should earlier statements have begun
        // the transaction, it is still open, and dropping it discards the connection).
        let (results, committed, sent) = self.block_on(async {
            let prepared = match futures_util::future::try_join_all(
                finals.iter().map(|last| client.prepare_cached(last.sql)),
            )
            .await
            {
                Ok(p) => p,
                Err(e) => return (vec![Err(e)], Ok(()), false),
            };
            // Sent together with the commit (and the BEGIN, when nothing was sent before):
            // the server runs them in order, and after a failed one the commit rolls the
            // transaction back.
            let statements = futures_util::future::join_all(
                prepared
                    .iter()
                    .zip(&params)
                    .map(|(stmt, params)| client.execute(stmt, params)),
            );
            let (began, results, committed) =
                tokio::join!(begin, statements, client.batch_execute("COMMIT"));
            match began {
                Ok(()) => (results, committed, true),
                Err(e) => (vec![Err(e)], Ok(()), true),
            }
        });
        if sent {
            tx.state.set(TxState::Ended);
        }
        if let Some((index, error)) = results
            .into_iter()
            .enumerate()
            .find_map(|(i, r)| r.err().map(|e| (i, e)))
        {
            return Ok(Err(super::FinalFailed {
                index,
                error: self.pg(error),
            }));
        }
        committed.map_err(|e| self.pg(e))?;
        Ok(Ok(out))
    }

    pub(super) fn schema_version(&self) -> Result<i64, StoreError> {
        self.read(|c| {
            let rows = c.query("SELECT max(version) FROM ferret_schema", &[])?;
            Ok(match rows.first().and_then(|r| r.first()) {
                Some(Value::Int(v)) => *v,
                _ => 0,
            })
        })
    }

    /// Brings the schema to [`SCHEMA_VERSION`] in one transaction under the migration lock, or
    /// refuses a newer one.
    fn migrate(&self) -> Result<(), StoreError> {
        self.transaction(|c| self.migrate_in(&c))
    }

    fn migrate_in(&self, c: &Conn<'_>) -> Result<(), StoreError> {
        c.execute("SELECT pg_advisory_xact_lock($1)", &[MIGRATION_LOCK.into()])?;
        c.execute(
            "CREATE TABLE IF NOT EXISTS ferret_schema (version BIGINT NOT NULL)",
            &[],
        )?;
        let rows = c.query("SELECT max(version) FROM ferret_schema", &[])?;
        let version = match rows.first().and_then(|r| r.first()) {
            Some(Value::Int(v)) => *v,
            _ => 0,
        };
        if version > SCHEMA_VERSION {
            return Err(StoreError::Schema {
                db: self.db.clone(),
                what: format!(
                    "schema version {version} was written by a newer ferret; this one knows versions up to {SCHEMA_VERSION}: upgrade every replica"
                ),
            });
        }
        let from = usize::try_from(version).unwrap_or(0);
        for (i, steps) in MIGRATIONS.iter().enumerate().skip(from) {
            for step in *steps {
                c.batch(step).map_err(|e| StoreError::Schema {
                    db: self.db.clone(),
                    what: format!("migrating to schema version {}: {e}", i + 1),
                })?;
            }
        }
        if version != SCHEMA_VERSION {
            c.execute("DELETE FROM ferret_schema", &[])?;
            c.execute(
                "INSERT INTO ferret_schema (version) VALUES ($1)",
                &[SCHEMA_VERSION.into()],
            )?;
            tracing::info!(
                "{}: schema migrated from version {version} to {SCHEMA_VERSION}",
                self.db
            );
        }
        Ok(())
    }

    /// The two halves of `key`'s advisory lock: the first 8 bytes of its SHA-256, so that every
    /// replica (whatever its build) locks the same number for the same id.
    fn lock_key(key: &str) -> (i32, i32) {
        let h = Sha256::digest(key.as_bytes());
        let half = |i: usize| i32::from_be_bytes([h[i], h[i + 1], h[i + 2], h[i + 3]]);
        (half(0), half(4))
    }

    /// Takes `key`'s advisory lock on the claims session; `None` when another session holds it.
    pub(super) fn claim(&self, key: &str) -> Result<Option<(i32, i32)>, StoreError> {
        let lock = Self::lock_key(key);
        // One retry on a fresh session: the old one may have died with the server's restart.
        for attempt in 0..2 {
            let session = self.claim_session()?;
            match self.block_on(session.client.query_one(&session.lock, &[&lock.0, &lock.1])) {
                Ok(row) => {
                    let took: bool = row.get(0);
                    return Ok(took.then_some(lock));
                }
                Err(e) if attempt == 0 && session.client.is_closed() => {
                    tracing::warn!("{}: the claims session closed ({e}); reconnecting", self.db);
                }
                Err(e) => return Err(self.pg(e)),
            }
        }
        Err(StoreError::Unreachable {
            db: self.db.clone(),
            what: "the claims session cannot be opened".into(),
        })
    }

    /// [`claim`](Self::claim) sent first, `during` run while its answer is on the way.
    pub(super) fn claim_while<T>(
        &self,
        key: &str,
        during: impl FnOnce() -> T,
    ) -> (Result<Option<(i32, i32)>, StoreError>, T) {
        let lock = Self::lock_key(key);
        let Ok(session) = self.claim_session() else {
            let out = during();
            return (self.claim(key), out);
        };
        let params: [&(dyn ToSql + Sync); 2] = [&lock.0, &lock.1];
        let mut asked = std::pin::pin!(session.client.query_one(&session.lock, &params));
        // Polled once here, which sends the statement; its answer is awaited after `during`.
        // (Not spawned: the runtime's one worker drives every connection, and a task per
        // request there slows them all.)
        let sent = asked
            .as_mut()
            .poll(&mut std::task::Context::from_waker(std::task::Waker::noop()));
        let out = during();
        let answer = match sent {
            std::task::Poll::Ready(answer) => answer,
            std::task::Poll::Pending => self.block_on(asked),
        };
        let claimed = match answer {
            Ok(row) => Ok(row.get::<_, bool>(0).then_some(lock)),
            // The session may have died with the server's restart: ask again on a new one.
            Err(_) if session.client.is_closed() => self.claim(key),
            Err(e) => Err(self.pg(e)),
        };
        (claimed, out)
    }

    /// Releases a claim taken by [`claim`](Self::claim). A failure is logged: the lock then
    /// goes with the session.
    pub(super) fn release(&self, lock: (i32, i32)) {
        let session = self
            .claims
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .clone();
        if let Some(session) = session
            && let Err(e) = self.block_on(
                session
                    .client
                    .query_one(&session.unlock, &[&lock.0, &lock.1]),
            )
        {
            tracing::warn!("{}: releasing a request claim: {e}", self.db);
        }
    }

    /// The open claims session, opened (again) when there is none or it closed.
    fn claim_session(&self) -> Result<Arc<ClaimSession>, StoreError> {
        let mut slot = self
            .claims
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if let Some(s) = slot.as_ref()
            && !s.client.is_closed()
        {
            return Ok(s.clone());
        }
        let session = Arc::new(self.session()?);
        *slot = Some(session.clone());
        Ok(session)
    }

    fn session(&self) -> Result<ClaimSession, StoreError> {
        let (client, connection) = self
            .block_on(self.config.connect(NoTls))
            .map_err(|e| self.pg(e))?;
        let db = self.db.clone();
        self.block_on(async move {
            tokio::spawn(async move {
                if let Err(e) = connection.await {
                    tracing::warn!("{db}: claims session: {e}");
                }
            });
        });
        let (lock, unlock) = self
            .block_on(async {
                tokio::try_join!(
                    client.prepare("SELECT pg_try_advisory_lock($1, $2)"),
                    client.prepare("SELECT pg_advisory_unlock($1, $2)"),
                )
            })
            .map_err(|e| self.pg(e))?;
        Ok(ClaimSession {
            client,
            lock,
            unlock,
        })
    }
}
