//! The service's memory, on one of two backends: an SQLite file (the embedded default: WAL,
//! `synchronous = FULL`) or a PostgreSQL database that several server replicas share. A row is
//! on disk before the reply that reports it leaves the server, and everything the service knows
//! is derived from the rows (a trial's belief from its observations, a deployment's selector from
//! its trials and the order they ended), which is what makes a `kill -9` of any replica harmless.
//!
//! Both backends run the same statements (written in the SQL both speak, `$n` parameters in
//! order) and read rows into the same `Value`s, so the row parsing below exists once; only
//! the schema's column types, its migrations and row locks differ.

mod conn;
mod deployments;
mod error;
mod postgres;
mod requests;
mod robots;
mod scenes;
mod sqlite;
mod trials;
mod value;

use std::path::Path;

use conn::Conn;
pub use conn::{Reader, Writer};
pub use deployments::{DeploymentNow, ListedDeployment};
pub use error::StoreError;
pub use postgres::PostgresOptions;
pub use requests::store_reply;
pub use trials::{NewTrial, TrialCounts, TrialEnding};
use value::Value;

/// The newest schema version this build writes. Version 1 is the schema of the first servers
/// (their SQLite files record no version); version 2 records the order trials started and ended
/// in, for deployments whose trials overlap; version 3 a trial's household task; version 4 its
/// team of robots and their claims; version 5 the robot that started a trial alone and when a
/// trial's robot was last heard from.
pub const SCHEMA_VERSION: i64 = 5;

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

enum Backend {
    Sqlite(Box<sqlite::Sqlite>),
    Postgres(Box<postgres::Postgres>),
}

/// The database.
pub struct Store {
    backend: Backend,
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
            Backend::Postgres(p) => p.read(|c| {
                f(&Reader {
                    conn: Conn::Postgres(c),
                })
            }),
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
            Backend::Sqlite(s) => s.write(|c| {
                f(&Writer {
                    conn: Conn::Sqlite(c, s),
                })
            }),
            Backend::Postgres(p) => p.write(|c| {
                f(&Writer {
                    conn: Conn::Postgres(c),
                })
            }),
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
            Backend::Sqlite(s) => s.write_finishing(|c| {
                f(&Writer {
                    conn: Conn::Sqlite(c, s),
                })
            }),
            Backend::Postgres(p) => p.write_finishing(|c| {
                f(&Writer {
                    conn: Conn::Postgres(c),
                })
            }),
        }
    }

    /// Connects this replica to the events every replica publishes: on PostgreSQL, a session
    /// listens on `channel` (calling `deliver` with each notification's text, or `None` after
    /// a lost session came back) and the returned sender's texts go out as notifications, at
    /// most `queue` waiting, packed as `options` says, with what `options.beat` gives every
    /// `options.every`. On SQLite there is no channel (`None`); while `options.beat` says this
    /// server has watchers, a commit another process makes to the file (a second server on
    /// it) calls `deliver(None)` within [`OTHERS_EVERY`].
    ///
    /// # Errors
    /// The PostgreSQL client's runtime is gone.
    pub fn feed(
        &self,
        channel: &'static str,
        queue: usize,
        deliver: Deliver,
        options: FeedOptions,
    ) -> Result<Option<tokio::sync::mpsc::Sender<String>>, StoreError> {
        match &self.backend {
            Backend::Sqlite(s) => {
                let beat = options.beat.clone();
                s.watch_others(
                    OTHERS_EVERY,
                    std::sync::Arc::new(move || beat().is_some()),
                    deliver,
                );
                Ok(None)
            }
            Backend::Postgres(p) => p.feed(channel, queue, deliver, options).map(Some),
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

/// How often a SQLite server with watchers looks for other processes' commits to its file.
pub const OTHERS_EVERY: std::time::Duration = std::time::Duration::from_millis(250);

/// How a replica's notifications are sent ([`Store::feed`]): packed, named after their sender,
/// and with what `beat` gives sent again every `every`.
pub struct FeedOptions {
    /// How often.
    pub every: std::time::Duration,
    /// What to send now, if anything.
    pub beat: std::sync::Arc<dyn Fn() -> Option<String> + Send + Sync>,
    /// The first line of every notification sent: who sent it.
    pub sender: String,
    /// Longest notification: texts sent together go in one notification up to it, after the
    /// sender's line, separated by blank lines.
    pub max_bytes: usize,
    /// What is sent in place of texts the other replicas did not get (one too long for a
    /// notification, or a batch the database refused): it tells them to read everything again.
    pub lost: String,
}

/// What a replica's listener hands on ([`Store::feed`]): a notification's text, or `None` when
/// notifications may have been missed (its session was lost and is back, or another replica
/// left the database without a word: killed, its events of the last moment never sent).
pub type Deliver = std::sync::Arc<dyn Fn(Option<String>) + Send + Sync>;

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
