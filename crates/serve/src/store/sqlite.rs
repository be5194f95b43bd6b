//! The SQLite backend: one file in WAL mode with `synchronous = FULL`, one connection behind a
//! lock, and write transactions that take the file's write lock at once (`IMMEDIATE`), which
//! also serializes every write of the trials of a deployment. The file records its schema
//! version in `PRAGMA user_version`.

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError, Weak};
use std::time::{Duration, Instant};

use rusqlite::config::DbConfig;
use rusqlite::types::{ToSqlOutput, ValueRef};
use rusqlite::{Connection, TransactionBehavior};

use super::SCHEMA_VERSION;
use super::error::StoreError;
use super::value::{Row, Value};

/// Schema migrations, version `i + 1` at index `i`. Version 1 is the schema of the first
/// servers, written with `IF NOT EXISTS` so that it also describes their files.
const MIGRATIONS: [&[&str]; 5] = [
    &["CREATE TABLE IF NOT EXISTS scenes (
        name TEXT PRIMARY KEY, body TEXT NOT NULL);
    CREATE TABLE IF NOT EXISTS deployments (
        id INTEGER PRIMARY KEY AUTOINCREMENT, spec TEXT NOT NULL);
    CREATE TABLE IF NOT EXISTS trials (
        id INTEGER PRIMARY KEY AUTOINCREMENT,
        deployment INTEGER NOT NULL REFERENCES deployments(id),
        k INTEGER NOT NULL, scene TEXT NOT NULL, target TEXT NOT NULL, pose TEXT,
        chosen INTEGER NOT NULL, status TEXT NOT NULL, cost REAL, replays TEXT,
        UNIQUE (deployment, k));
    CREATE TABLE IF NOT EXISTS observations (
        trial INTEGER NOT NULL REFERENCES trials(id), seq INTEGER NOT NULL,
        container TEXT NOT NULL, found INTEGER NOT NULL, objects TEXT NOT NULL,
        travelled REAL, leg REAL NOT NULL,
        PRIMARY KEY (trial, seq));
    CREATE TABLE IF NOT EXISTS requests (
        id TEXT PRIMARY KEY, fingerprint TEXT NOT NULL, status INTEGER NOT NULL, body TEXT NOT NULL);"],
    &[
        "ALTER TABLE trials ADD COLUMN started_after INTEGER NOT NULL DEFAULT 0;
        ALTER TABLE trials ADD COLUMN end_seq INTEGER;",
        super::END_ORDER,
    ],
    // Household tasks: a trial's targets, goal and destination (JSON; NULL for one target).
    &["ALTER TABLE trials ADD COLUMN task TEXT;"],
    // Teams: a trial's robots (JSON; NULL for one robot), who searched each container, and each
    // robot's claim and when it was last heard from.
    &["ALTER TABLE trials ADD COLUMN robots TEXT;
    ALTER TABLE observations ADD COLUMN robot TEXT;
    CREATE TABLE trial_robots (
        trial INTEGER NOT NULL REFERENCES trials(id), robot TEXT NOT NULL,
        claim TEXT, claim_expires_ms INTEGER, heard_ms INTEGER NOT NULL,
        PRIMARY KEY (trial, robot), UNIQUE (trial, claim));"],
    // Robots by name: the robot that named itself when it started a trial alone, and when a
    // trial's robot was last heard from (Unix milliseconds).
    &["ALTER TABLE trials ADD COLUMN robot TEXT;
    ALTER TABLE trials ADD COLUMN heard_ms INTEGER;"],
];

pub(super) struct Sqlite {
    /// Shared with the thread that watches for other processes' commits (a `Weak` there).
    conn: Arc<Mutex<Connection>>,
    pub(super) file: String,
    /// The file, for checks on a connection of their own; `None` in memory.
    path: Option<PathBuf>,
    /// The last whole-file check: when it started and what it found. Held while a check runs,
    /// so checks asked for meanwhile wait and take its answer instead of reading the file again.
    last_check: Mutex<Option<(Instant, Result<(), String>)>>,
    /// The file as opened (device and inode): one put in its place is not this database.
    identity: Option<(u64, u64)>,
}

impl Drop for Sqlite {
    fn drop(&mut self) {
        let Err(lost) = self.check_in_place() else {
            return;
        };
        // Closing the last connection copies the log into the file and deletes the log: into a
        // file emptied underneath, that writes pages into what is no longer a whole database
        // (the next start calls it malformed), and with another file put in its place it
        // deletes the log now beside that one. So the connection closes without it, leaving
        // the file as it was found and the log with the writes since its last copy.
        let conn = self.lock();
        if let Err(e) = conn.set_db_config(DbConfig::SQLITE_DBCONFIG_NO_CKPT_ON_CLOSE, true) {
            tracing::error!("{}: cannot keep closing from writing to it: {e}", self.file);
        }
        tracing::error!(
            "{lost}; closed without writing to it. Its log {}-wal is left as it was; restore the database from a copy",
            self.file
        );
    }
}

/// The device and inode of a file (`None` where the platform has none).
fn identity_of(meta: &std::fs::Metadata) -> Option<(u64, u64)> {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        Some((meta.dev(), meta.ino()))
    }
    #[cfg(not(unix))]
    {
        let _ = meta;
        None
    }
}

impl rusqlite::ToSql for Value {
    fn to_sql(&self) -> rusqlite::Result<ToSqlOutput<'_>> {
        Ok(match self {
            Value::Null => ToSqlOutput::Borrowed(ValueRef::Null),
            Value::Int(v) => ToSqlOutput::Borrowed(ValueRef::Integer(*v)),
            Value::Real(v) => ToSqlOutput::Borrowed(ValueRef::Real(*v)),
            Value::Text(v) => ToSqlOutput::Borrowed(ValueRef::Text(v.as_bytes())),
            Value::Bool(v) => ToSqlOutput::Borrowed(ValueRef::Integer(i64::from(*v))),
        })
    }
}

/// The statement in SQLite's numbered form: `$n` becomes `?n`, since SQLite numbers `$n`
/// parameters by where they first appear, not by `n`.
fn numbered(sql: &str) -> String {
    let mut out = String::with_capacity(sql.len());
    let mut chars = sql.chars().peekable();
    while let Some(c) = chars.next() {
        if c == '$' && chars.peek().is_some_and(char::is_ascii_digit) {
            out.push('?');
        } else {
            out.push(c);
        }
    }
    out
}

pub(super) fn execute(
    conn: &Connection,
    s: &Sqlite,
    sql: &str,
    params: &[Value],
) -> Result<u64, StoreError> {
    let mut stmt = conn.prepare_cached(&numbered(sql)).map_err(|e| s.sql(e))?;
    let n = stmt
        .execute(rusqlite::params_from_iter(params))
        .map_err(|e| s.sql(e))?;
    Ok(n as u64)
}

pub(super) fn query(
    conn: &Connection,
    s: &Sqlite,
    sql: &str,
    params: &[Value],
) -> Result<Vec<Row>, StoreError> {
    let mut stmt = conn.prepare_cached(&numbered(sql)).map_err(|e| s.sql(e))?;
    let columns = stmt.column_count();
    let mut rows = stmt
        .query(rusqlite::params_from_iter(params))
        .map_err(|e| s.sql(e))?;
    let mut out = Vec::new();
    while let Some(r) = rows.next().map_err(|e| s.sql(e))? {
        let mut row = Vec::with_capacity(columns);
        for i in 0..columns {
            row.push(match r.get_ref(i).map_err(|e| s.sql(e))? {
                ValueRef::Null => Value::Null,
                ValueRef::Integer(v) => Value::Int(v),
                ValueRef::Real(v) => Value::Real(v),
                ValueRef::Text(t) | ValueRef::Blob(t) => {
                    Value::Text(String::from_utf8_lossy(t).into_owned())
                }
            });
        }
        out.push(row);
    }
    Ok(out)
}

impl Sqlite {
    pub(super) fn open(path: &Path) -> Result<Sqlite, StoreError> {
        let file = path.display().to_string();
        let conn = Connection::open(path).map_err(|source| StoreError::Sql {
            file: file.clone(),
            source,
        })?;
        let mut store = Self::init(conn, file)?;
        store.path = Some(path.to_path_buf());
        store.identity = std::fs::metadata(path).ok().as_ref().and_then(identity_of);
        Ok(store)
    }

    pub(super) fn in_memory() -> Result<Sqlite, StoreError> {
        let conn = Connection::open_in_memory().map_err(|source| StoreError::Sql {
            file: ":memory:".into(),
            source,
        })?;
        Self::init(conn, ":memory:".into())
    }

    fn init(mut conn: Connection, file: String) -> Result<Sqlite, StoreError> {
        let sql = |source| StoreError::Sql {
            file: file.clone(),
            source,
        };
        conn.busy_timeout(Duration::from_secs(10)).map_err(sql)?;
        if file != ":memory:" {
            let mode: String = conn
                .pragma_update_and_check(None, "journal_mode", "WAL", |row| row.get(0))
                .map_err(sql)?;
            if !mode.eq_ignore_ascii_case("wal") {
                return Err(StoreError::Corrupt {
                    file,
                    what: format!("journal mode {mode}, WAL needed"),
                });
            }
        }
        // FULL: a committed row survives a crash of the machine, not only of the process.
        conn.pragma_update(None, "synchronous", "FULL")
            .map_err(sql)?;
        conn.pragma_update(None, "foreign_keys", "ON")
            .map_err(sql)?;
        migrate(&mut conn, &file)?;
        Ok(Sqlite {
            conn: Arc::new(Mutex::new(conn)),
            file,
            path: None,
            last_check: Mutex::new(None),
            identity: None,
        })
    }

    pub(super) fn schema_version(&self) -> Result<i64, StoreError> {
        self.lock()
            .query_row("PRAGMA user_version", [], |r| r.get(0))
            .map_err(|e| self.sql(e))
    }

    /// Whether the file is still the database the server opened: there, the same file, and
    /// beginning with SQLite's header. A file emptied (`truncate`), removed or replaced while the
    /// server runs is still served from the connection's cache and its log, and what is written
    /// then is lost; a stat and a 16-byte read per write see it.
    pub(super) fn check_in_place(&self) -> Result<(), StoreError> {
        let Some(path) = &self.path else {
            return Ok(());
        };
        let lost = |what: String| {
            Err(StoreError::Lost {
                file: self.file.clone(),
                what,
            })
        };
        let meta = match std::fs::metadata(path) {
            Ok(m) => m,
            Err(e) => return lost(format!("the file is gone ({e})")),
        };
        if self.identity.is_some() && identity_of(&meta) != self.identity {
            return lost("another file was put in its place".into());
        }
        let mut header = [0u8; 16];
        let read = std::fs::File::open(path)
            .and_then(|mut f| std::io::Read::read_exact(&mut f, &mut header));
        match read {
            Ok(()) if &header == b"SQLite format 3\0" => Ok(()),
            Ok(()) => lost("its header is not SQLite's any more".into()),
            Err(_) => lost(format!("it was emptied ({} bytes left)", meta.len())),
        }
    }

    pub(super) fn check_file(&self) -> Result<(), StoreError> {
        self.check_in_place()?;
        let Some(path) = &self.path else {
            return Ok(());
        };
        let asked = Instant::now();
        let mut last = self
            .last_check
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        // A check that started after this one was asked for read the file as it is now.
        let result = match &*last {
            Some((started, result)) if *started >= asked => result.clone(),
            _ => {
                let started = Instant::now();
                let result = quick_check(path);
                *last = Some((started, result.clone()));
                result
            }
        };
        result.map_err(|what| StoreError::Corrupt {
            file: self.file.clone(),
            what,
        })
    }

    /// Calls `changed` (from a thread of its own) within `every` of a commit that another
    /// process made to the file, while `watched` says someone looks: a second `ferret serve`
    /// (`--view-only`, say) on the robots' file tells its pages to read again. SQLite's
    /// `data_version` moves only for other connections' commits, and this server has one. Ends
    /// with the store; nothing for a database in memory.
    pub(super) fn watch_others(
        &self,
        every: Duration,
        watched: Arc<dyn Fn() -> bool + Send + Sync>,
        changed: super::Deliver,
    ) {
        if self.path.is_none() {
            return;
        }
        let conn: Weak<Mutex<Connection>> = Arc::downgrade(&self.conn);
        let file = self.file.clone();
        let spawned = std::thread::Builder::new()
            .name("ferret-sqlite-watch".into())
            .spawn(move || {
                let mut last: Option<i64> = None;
                loop {
                    std::thread::sleep(every);
                    let Some(conn) = conn.upgrade() else { return };
                    if !watched() {
                        last = None;
                        continue;
                    }
                    let version = conn
                        .lock()
                        .unwrap_or_else(PoisonError::into_inner)
                        .query_row("PRAGMA data_version", [], |r| r.get::<_, i64>(0));
                    match version {
                        Ok(v) => {
                            if last.is_some_and(|l| l != v) {
                                changed(None);
                            }
                            last = Some(v);
                        }
                        Err(e) => tracing::debug!("{file}: cannot read data_version: {e}"),
                    }
                }
            });
        if let Err(e) = spawned {
            tracing::warn!(
                "{}: cannot watch for other processes' changes: {e}",
                self.file
            );
        }
    }

    pub(super) fn lock(&self) -> MutexGuard<'_, Connection> {
        // A panic while holding the lock cannot leave a half-written transaction (it rolls back
        // on drop), so the connection is still good.
        self.conn
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    pub(super) fn sql(&self, source: rusqlite::Error) -> StoreError {
        StoreError::Sql {
            file: self.file.clone(),
            source,
        }
    }

    pub(super) fn write<T, E: From<StoreError>>(
        &self,
        f: impl FnOnce(&Connection) -> Result<T, E>,
    ) -> Result<T, E> {
        self.check_in_place()?;
        let mut conn = self.lock();
        // IMMEDIATE: a second process on the same file waits for the write lock (busy timeout)
        // instead of failing when a read turns into a write.
        let tx = conn
            .transaction_with_behavior(TransactionBehavior::Immediate)
            .map_err(|e| self.sql(e))?;
        let out = f(&tx)?;
        tx.commit().map_err(|e| self.sql(e))?;
        Ok(out)
    }
}

impl Sqlite {
    pub(super) fn write_finishing<T, E: From<StoreError>>(
        &self,
        f: impl FnOnce(&Connection) -> Result<(T, Vec<super::Final>), E>,
    ) -> Result<Result<T, super::FinalFailed>, E> {
        self.check_in_place()?;
        let mut conn = self.lock();
        let tx = conn
            .transaction_with_behavior(TransactionBehavior::Immediate)
            .map_err(|e| self.sql(e))?;
        let (out, finals) = f(&tx)?;
        for (index, last) in finals.iter().enumerate() {
            if let Err(error) = query(&tx, self, last.sql, &last.params) {
                // Dropping the transaction rolls it back.
                return Ok(Err(super::FinalFailed { index, error }));
            }
        }
        tx.commit().map_err(|e| self.sql(e))?;
        Ok(Ok(out))
    }
}

/// Reads every page of the file on a connection of its own (`PRAGMA quick_check`: b-tree
/// structure, cell layout, free list, not index contents), so that damage is seen wherever it
/// is: the service's connection keeps the pages it has read in its cache, and reading a row or
/// two sees only those.
fn quick_check(path: &Path) -> Result<(), String> {
    use rusqlite::OpenFlags;
    let conn = Connection::open_with_flags(
        path,
        OpenFlags::SQLITE_OPEN_READ_ONLY | OpenFlags::SQLITE_OPEN_NO_MUTEX,
    )
    .map_err(|e| format!("cannot open for checking: {e}"))?;
    conn.busy_timeout(Duration::from_secs(10))
        .map_err(|e| e.to_string())?;
    let finding: String = conn
        .query_row("PRAGMA quick_check(1)", [], |r| r.get(0))
        .map_err(|e| format!("reading the file: {e}"))?;
    if finding == "ok" {
        Ok(())
    } else {
        Err(format!("the file is damaged: {finding}"))
    }
}

/// Brings the file's schema to [`SCHEMA_VERSION`] in one transaction, or refuses a newer one.
fn migrate(conn: &mut Connection, file: &str) -> Result<(), StoreError> {
    let sql = |source| StoreError::Sql {
        file: file.to_string(),
        source,
    };
    let tx = conn
        .transaction_with_behavior(TransactionBehavior::Immediate)
        .map_err(sql)?;
    let recorded: i64 = tx
        .query_row("PRAGMA user_version", [], |r| r.get(0))
        .map_err(sql)?;
    // The first servers recorded no version: their files have the tables of version 1.
    let legacy: bool = tx
        .query_row(
            "SELECT count(*) > 0 FROM sqlite_master WHERE type = 'table' AND name = 'trials'",
            [],
            |r| r.get(0),
        )
        .map_err(sql)?;
    let version = if recorded == 0 && legacy { 1 } else { recorded };
    if version > SCHEMA_VERSION {
        return Err(StoreError::Schema {
            db: file.to_string(),
            what: format!(
                "schema version {version} was written by a newer ferret; this one knows versions up to {SCHEMA_VERSION}: upgrade ferret, or give another --db"
            ),
        });
    }
    let from = usize::try_from(version).unwrap_or(0);
    for (i, steps) in MIGRATIONS.iter().enumerate().skip(from) {
        for step in *steps {
            tx.execute_batch(step)
                .map_err(|source| StoreError::Schema {
                    db: file.to_string(),
                    what: format!("migrating to schema version {}: {source}", i + 1),
                })?;
        }
    }
    if version != SCHEMA_VERSION || recorded != SCHEMA_VERSION {
        tx.pragma_update(None, "user_version", SCHEMA_VERSION)
            .map_err(sql)?;
        if version != SCHEMA_VERSION {
            tracing::info!("{file}: schema migrated from version {version} to {SCHEMA_VERSION}");
        }
    }
    tx.commit().map_err(sql)
}
