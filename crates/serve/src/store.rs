//! The service's memory: one SQLite file in WAL mode with `synchronous = FULL`, so a row is on
//! disk before the reply that reports it leaves the server. Everything the service knows is
//! derived from these rows (a trial's belief from its observations, a deployment's selector from
//! its finished trials), which is what makes a `kill -9` harmless.

use std::path::Path;
use std::sync::{Mutex, MutexGuard};
use std::time::{Duration, Instant};

use crate::model::{
    DeploymentSpec, Outcome, StoredDeployment, StoredObservation, StoredReply, StoredTrial,
    TrialStatus,
};
use rusqlite::{Connection, OptionalExtension, Transaction, TransactionBehavior, params};

/// Storage failures (the disk, not the request).
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
    /// A stored row does not parse (the file was edited or written by another version).
    #[error("database {file}: {what}")]
    Corrupt {
        /// The database file.
        file: String,
        /// What is wrong.
        what: String,
    },
}

/// How a reply's outcome is stored: as the numbers databases have always held (200, 201), so
/// that a database written by any version answers its retries the same.
fn stored_code(o: Outcome) -> u16 {
    match o {
        Outcome::Done => 200,
        Outcome::Created => 201,
    }
}

fn outcome_of(code: u16) -> Outcome {
    if code == 201 {
        Outcome::Created
    } else {
        Outcome::Done
    }
}

/// The database.
pub struct Store {
    conn: Mutex<Connection>,
    file: String,
    /// The file, for checks on a connection of their own; `None` in memory.
    path: Option<std::path::PathBuf>,
    /// The last whole-file check: when it started and what it found. Held while a check runs,
    /// so checks asked for meanwhile wait and take its answer instead of reading the file again.
    last_check: Mutex<Option<(Instant, Result<(), String>)>>,
}

const SCHEMA: &str = "
CREATE TABLE IF NOT EXISTS scenes (
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
    id TEXT PRIMARY KEY, fingerprint TEXT NOT NULL, status INTEGER NOT NULL, body TEXT NOT NULL);
";

impl Store {
    /// Opens (creating if needed) the database at `path`.
    ///
    /// # Errors
    /// The file cannot be opened or is not a ferret database.
    pub fn open(path: &Path) -> Result<Store, StoreError> {
        let file = path.display().to_string();
        let conn = Connection::open(path).map_err(|source| StoreError::Sql {
            file: file.clone(),
            source,
        })?;
        let mut store = Self::init(conn, file)?;
        store.path = Some(path.to_path_buf());
        Ok(store)
    }

    /// A database in memory (tests, benchmarks).
    ///
    /// # Errors
    /// SQLite cannot allocate it.
    pub fn in_memory() -> Result<Store, StoreError> {
        let conn = Connection::open_in_memory().map_err(|source| StoreError::Sql {
            file: ":memory:".into(),
            source,
        })?;
        Self::init(conn, ":memory:".into())
    }

    fn init(conn: Connection, file: String) -> Result<Store, StoreError> {
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
        conn.execute_batch(SCHEMA).map_err(sql)?;
        Ok(Store {
            conn: Mutex::new(conn),
            file,
            path: None,
            last_check: Mutex::new(None),
        })
    }

    /// Reads every page of the file from disk on a connection of its own (`PRAGMA quick_check`:
    /// b-tree structure, cell layout, free list, not index contents), so that damage is seen
    /// wherever it is: the service's connection keeps the pages it has read in its cache, and
    /// reading a row or two sees only those. Takes time linear in the file's size; does not hold
    /// up the service's connection. A database in memory has no file and always passes.
    ///
    /// # Errors
    /// [`StoreError::Corrupt`] with SQLite's first finding, or [`StoreError::Sql`] when the file
    /// cannot be opened or read.
    pub fn check_file(&self) -> Result<(), StoreError> {
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
                let result = self.quick_check(path);
                *last = Some((started, result.clone()));
                result
            }
        };
        result.map_err(|what| self.corrupt(what))
    }

    fn quick_check(&self, path: &Path) -> Result<(), String> {
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

    fn lock(&self) -> MutexGuard<'_, Connection> {
        // A panic while holding the lock cannot leave a half-written transaction (it rolls back
        // on drop), so the connection is still good.
        self.conn
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    fn sql(&self, source: rusqlite::Error) -> StoreError {
        StoreError::Sql {
            file: self.file.clone(),
            source,
        }
    }

    fn corrupt(&self, what: String) -> StoreError {
        StoreError::Corrupt {
            file: self.file.clone(),
            what,
        }
    }

    /// Reads with the connection.
    pub fn read<T>(
        &self,
        f: impl FnOnce(&Reader<'_>) -> Result<T, StoreError>,
    ) -> Result<T, StoreError> {
        let conn = self.lock();
        f(&Reader {
            conn: &conn,
            store: self,
        })
    }

    /// Runs `f` in one transaction, committed when it returns `Ok`, rolled back otherwise.
    pub fn write<T, E: From<StoreError>>(
        &self,
        f: impl FnOnce(&Writer<'_>) -> Result<T, E>,
    ) -> Result<T, E> {
        let mut conn = self.lock();
        // IMMEDIATE: a second process on the same file waits for the write lock (busy timeout)
        // instead of failing when a read turns into a write.
        let tx = conn
            .transaction_with_behavior(TransactionBehavior::Immediate)
            .map_err(|e| self.sql(e))?;
        let out = f(&Writer {
            tx: &tx,
            store: self,
        })?;
        tx.commit().map_err(|e| self.sql(e))?;
        Ok(out)
    }
}

/// Read access inside [`Store::read`] (also available to writers).
pub struct Reader<'a> {
    conn: &'a Connection,
    store: &'a Store,
}

/// Write access inside [`Store::write`].
pub struct Writer<'a> {
    tx: &'a Transaction<'a>,
    store: &'a Store,
}

impl Writer<'_> {
    /// Reads inside the transaction.
    pub fn reader(&self) -> Reader<'_> {
        Reader {
            conn: self.tx,
            store: self.store,
        }
    }

    /// Stores a scene's text under its name.
    pub fn insert_scene(&self, name: &str, body: &str) -> Result<(), StoreError> {
        self.tx
            .execute(
                "INSERT INTO scenes (name, body) VALUES (?1, ?2)",
                params![name, body],
            )
            .map_err(|e| self.store.sql(e))?;
        Ok(())
    }

    /// Stores a new deployment; returns its id.
    pub fn insert_deployment(&self, spec: &DeploymentSpec) -> Result<i64, StoreError> {
        let json = serde_json::to_string(spec).map_err(|e| self.store.corrupt(e.to_string()))?;
        self.tx
            .execute("INSERT INTO deployments (spec) VALUES (?1)", params![json])
            .map_err(|e| self.store.sql(e))?;
        Ok(self.tx.last_insert_rowid())
    }

    /// Stores a new trial (status searching); returns its id.
    pub fn insert_trial(
        &self,
        deployment: i64,
        k: i64,
        scene: &str,
        target: &str,
        pose: Option<[f64; 3]>,
        chosen: usize,
    ) -> Result<i64, StoreError> {
        let pose = pose.map(|p| serde_json::json!(p).to_string());
        self.tx
            .execute(
                "INSERT INTO trials (deployment, k, scene, target, pose, chosen, status)
                 VALUES (?1, ?2, ?3, ?4, ?5, ?6, 'searching')",
                params![deployment, k, scene, target, pose, chosen as i64],
            )
            .map_err(|e| self.store.sql(e))?;
        Ok(self.tx.last_insert_rowid())
    }

    /// Appends an observation as number `seq` (0-based) of `trial`.
    pub fn insert_observation(
        &self,
        trial: i64,
        seq: usize,
        o: &StoredObservation,
    ) -> Result<(), StoreError> {
        let objects = serde_json::json!(o.objects).to_string();
        self.tx
            .execute(
                "INSERT INTO observations (trial, seq, container, found, objects, travelled, leg)
                 VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7)",
                params![
                    trial,
                    seq as i64,
                    o.container,
                    o.found,
                    objects,
                    o.travelled,
                    o.leg
                ],
            )
            .map_err(|e| self.store.sql(e))?;
        Ok(())
    }

    /// Ends a trial.
    pub fn end_trial(
        &self,
        trial: i64,
        status: TrialStatus,
        cost: f64,
        replays: Option<&[f64]>,
    ) -> Result<(), StoreError> {
        let replays = replays.map(|r| serde_json::json!(r).to_string());
        self.tx
            .execute(
                "UPDATE trials SET status = ?2, cost = ?3, replays = ?4 WHERE id = ?1",
                params![trial, status.as_str(), cost, replays],
            )
            .map_err(|e| self.store.sql(e))?;
        Ok(())
    }

    /// Stores the reply to a request id.
    pub fn insert_reply(&self, id: &str, reply: &StoredReply) -> Result<(), StoreError> {
        self.tx
            .execute(
                "INSERT INTO requests (id, fingerprint, status, body) VALUES (?1, ?2, ?3, ?4)",
                params![
                    id,
                    reply.fingerprint,
                    stored_code(reply.outcome),
                    reply.body
                ],
            )
            .map_err(|e| self.store.sql(e))?;
        Ok(())
    }
}

impl Reader<'_> {
    /// Every stored scene: `(name, body)`.
    pub fn scenes(&self) -> Result<Vec<(String, String)>, StoreError> {
        let mut stmt = self
            .conn
            .prepare("SELECT name, body FROM scenes ORDER BY name")
            .map_err(|e| self.store.sql(e))?;
        let rows = stmt
            .query_map([], |r| Ok((r.get(0)?, r.get(1)?)))
            .map_err(|e| self.store.sql(e))?;
        rows.collect::<Result<_, _>>()
            .map_err(|e| self.store.sql(e))
    }

    /// Every stored scene's name with its numbers of rooms and containers, counted by SQLite
    /// without loading the scenes (0 for a body that is not JSON).
    pub fn scene_summaries(&self) -> Result<Vec<(String, usize, usize)>, StoreError> {
        let mut stmt = self
            .conn
            .prepare(
                "SELECT name,
                    CASE WHEN json_valid(body) THEN json_array_length(body, '$.rooms') END,
                    CASE WHEN json_valid(body) THEN json_array_length(body, '$.containers') END
                 FROM scenes ORDER BY name",
            )
            .map_err(|e| self.store.sql(e))?;
        let rows = stmt
            .query_map([], |r| {
                Ok((
                    r.get::<_, String>(0)?,
                    r.get::<_, Option<i64>>(1)?,
                    r.get::<_, Option<i64>>(2)?,
                ))
            })
            .map_err(|e| self.store.sql(e))?;
        let count = |n: Option<i64>| n.and_then(|n| usize::try_from(n).ok()).unwrap_or(0);
        rows.map(|r| r.map(|(name, rooms, containers)| (name, count(rooms), count(containers))))
            .collect::<Result<_, _>>()
            .map_err(|e| self.store.sql(e))
    }

    /// A stored scene's body.
    pub fn scene(&self, name: &str) -> Result<Option<String>, StoreError> {
        self.conn
            .query_row("SELECT body FROM scenes WHERE name = ?1", [name], |r| {
                r.get(0)
            })
            .optional()
            .map_err(|e| self.store.sql(e))
    }

    /// How many scenes are stored.
    pub fn scene_count(&self) -> Result<usize, StoreError> {
        let n: i64 = self
            .conn
            .query_row("SELECT count(*) FROM scenes", [], |r| r.get(0))
            .map_err(|e| self.store.sql(e))?;
        Ok(usize::try_from(n).unwrap_or(usize::MAX))
    }

    /// Reads the schema and a row of every table: a damaged file fails here as it would on
    /// every route. Cheap, for health checks.
    pub fn check(&self) -> Result<(), StoreError> {
        for table in [
            "scenes",
            "deployments",
            "trials",
            "observations",
            "requests",
        ] {
            self.conn
                .query_row(
                    &format!("SELECT count(*) FROM (SELECT * FROM {table} LIMIT 1)"),
                    [],
                    |r| r.get::<_, i64>(0),
                )
                .map_err(|e| self.store.sql(e))?;
        }
        Ok(())
    }

    /// A deployment by id.
    pub fn deployment(&self, id: i64) -> Result<Option<StoredDeployment>, StoreError> {
        let spec: Option<String> = self
            .conn
            .query_row("SELECT spec FROM deployments WHERE id = ?1", [id], |r| {
                r.get(0)
            })
            .optional()
            .map_err(|e| self.store.sql(e))?;
        spec.map(|s| {
            serde_json::from_str(&s)
                .map(|spec| StoredDeployment { id, spec })
                .map_err(|e| self.store.corrupt(format!("deployment {id}: {e}")))
        })
        .transpose()
    }

    /// Every deployment id.
    pub fn deployment_ids(&self) -> Result<Vec<i64>, StoreError> {
        let mut stmt = self
            .conn
            .prepare("SELECT id FROM deployments ORDER BY id")
            .map_err(|e| self.store.sql(e))?;
        let rows = stmt
            .query_map([], |r| r.get(0))
            .map_err(|e| self.store.sql(e))?;
        rows.collect::<Result<_, _>>()
            .map_err(|e| self.store.sql(e))
    }

    fn trials_where(&self, clause: &str, key: i64) -> Result<Vec<StoredTrial>, StoreError> {
        let mut stmt = self
            .conn
            .prepare(&format!(
                "SELECT id, deployment, k, scene, target, pose, chosen, status, cost, replays
                 FROM trials WHERE {clause} ORDER BY k"
            ))
            .map_err(|e| self.store.sql(e))?;
        let rows = stmt
            .query_map([key], |r| {
                Ok((
                    r.get::<_, i64>(0)?,
                    r.get::<_, i64>(1)?,
                    r.get::<_, i64>(2)?,
                    r.get::<_, String>(3)?,
                    r.get::<_, String>(4)?,
                    r.get::<_, Option<String>>(5)?,
                    r.get::<_, i64>(6)?,
                    r.get::<_, String>(7)?,
                    r.get::<_, Option<f64>>(8)?,
                    r.get::<_, Option<String>>(9)?,
                ))
            })
            .map_err(|e| self.store.sql(e))?;
        let mut out = Vec::new();
        for row in rows {
            let (id, deployment, k, scene, target, pose, chosen, status, cost, replays) =
                row.map_err(|e| self.store.sql(e))?;
            let bad = |what: &str| self.store.corrupt(format!("trial {id}: {what}"));
            out.push(StoredTrial {
                id,
                deployment,
                k,
                scene,
                target,
                pose: pose
                    .map(|p| serde_json::from_str(&p))
                    .transpose()
                    .map_err(|_| bad("pose"))?,
                chosen: usize::try_from(chosen).map_err(|_| bad("chosen"))?,
                status: TrialStatus::parse(&status).ok_or_else(|| bad("status"))?,
                cost,
                replays: replays
                    .map(|p| serde_json::from_str(&p))
                    .transpose()
                    .map_err(|_| bad("replays"))?,
            });
        }
        Ok(out)
    }

    /// A deployment's trials, in order.
    pub fn trials_of(&self, deployment: i64) -> Result<Vec<StoredTrial>, StoreError> {
        self.trials_where("deployment = ?1", deployment)
    }

    /// A trial by id.
    pub fn trial(&self, id: i64) -> Result<Option<StoredTrial>, StoreError> {
        Ok(self.trials_where("id = ?1", id)?.into_iter().next())
    }

    /// A trial's observations, in order.
    pub fn observations(&self, trial: i64) -> Result<Vec<StoredObservation>, StoreError> {
        let mut stmt = self
            .conn
            .prepare(
                "SELECT container, found, objects, travelled, leg FROM observations
                 WHERE trial = ?1 ORDER BY seq",
            )
            .map_err(|e| self.store.sql(e))?;
        let rows = stmt
            .query_map([trial], |r| {
                Ok((
                    r.get::<_, String>(0)?,
                    r.get::<_, bool>(1)?,
                    r.get::<_, String>(2)?,
                    r.get::<_, Option<f64>>(3)?,
                    r.get::<_, f64>(4)?,
                ))
            })
            .map_err(|e| self.store.sql(e))?;
        let mut out = Vec::new();
        for row in rows {
            let (container, found, objects, travelled, leg) = row.map_err(|e| self.store.sql(e))?;
            out.push(StoredObservation {
                container,
                found,
                objects: serde_json::from_str(&objects)
                    .map_err(|_| self.store.corrupt(format!("trial {trial}: objects")))?,
                travelled,
                leg,
            });
        }
        Ok(out)
    }

    /// The stored reply to request `id`.
    pub fn reply(&self, id: &str) -> Result<Option<StoredReply>, StoreError> {
        self.conn
            .query_row(
                "SELECT fingerprint, status, body FROM requests WHERE id = ?1",
                [id],
                |r| {
                    Ok(StoredReply {
                        fingerprint: r.get(0)?,
                        outcome: outcome_of(r.get(1)?),
                        body: r.get(2)?,
                    })
                },
            )
            .optional()
            .map_err(|e| self.store.sql(e))
    }
}
