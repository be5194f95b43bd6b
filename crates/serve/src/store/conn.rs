//! What both backends share below the tables: a row's values, a connection of either backend
//! with the row parsing that exists once for both, and the read and write handles
//! [`Store`](super::Store) lends.

use super::error::StoreError;
use super::value::{Row, Value};
use super::{postgres, sqlite};

/// A connection (or a transaction on one) of either backend.
pub(super) enum Conn<'a> {
    Sqlite(&'a rusqlite::Connection, &'a sqlite::Sqlite),
    Postgres(postgres::Conn<'a>),
}

impl Conn<'_> {
    pub(super) fn execute(&self, sql: &str, params: &[Value]) -> Result<u64, StoreError> {
        match self {
            Conn::Sqlite(c, s) => sqlite::execute(c, s, sql, params),
            Conn::Postgres(c) => c.execute(sql, params),
        }
    }

    pub(super) fn query(&self, sql: &str, params: &[Value]) -> Result<Vec<Row>, StoreError> {
        match self {
            Conn::Sqlite(c, s) => sqlite::query(c, s, sql, params),
            Conn::Postgres(c) => c.query(sql, params),
        }
    }

    /// Runs `statements` in order; on PostgreSQL they are sent at once (one round trip).
    pub(super) fn query_all(
        &self,
        statements: &[(&str, &[Value])],
    ) -> Result<Vec<Vec<Row>>, StoreError> {
        match self {
            Conn::Sqlite(c, s) => statements
                .iter()
                .map(|(sql, params)| sqlite::query(c, s, sql, params))
                .collect(),
            Conn::Postgres(c) => c.query_all(statements),
        }
    }

    pub(super) fn query_opt(&self, sql: &str, params: &[Value]) -> Result<Option<Row>, StoreError> {
        Ok(self.query(sql, params)?.into_iter().next())
    }

    pub(super) fn corrupt(&self, what: String) -> StoreError {
        let file = match self {
            Conn::Sqlite(_, s) => s.file.clone(),
            Conn::Postgres(c) => c.db().to_string(),
        };
        StoreError::Corrupt { file, what }
    }

    /// The value at `i` of `row`, or a corrupt-row error naming `what`.
    pub(super) fn int(&self, row: &Row, i: usize, what: &str) -> Result<i64, StoreError> {
        match row.get(i) {
            Some(Value::Int(v)) => Ok(*v),
            other => Err(self.corrupt(format!("{what}: expected an integer, found {other:?}"))),
        }
    }

    pub(super) fn real(&self, row: &Row, i: usize, what: &str) -> Result<Option<f64>, StoreError> {
        match row.get(i) {
            Some(Value::Real(v)) => Ok(Some(*v)),
            // SQLite hands back a whole REAL as an integer when it was stored as one.
            Some(Value::Int(v)) => Ok(Some(*v as f64)),
            Some(Value::Null) => Ok(None),
            other => Err(self.corrupt(format!("{what}: expected a number, found {other:?}"))),
        }
    }

    pub(super) fn text(
        &self,
        row: &Row,
        i: usize,
        what: &str,
    ) -> Result<Option<String>, StoreError> {
        match row.get(i) {
            Some(Value::Text(v)) => Ok(Some(v.clone())),
            Some(Value::Null) => Ok(None),
            other => Err(self.corrupt(format!("{what}: expected text, found {other:?}"))),
        }
    }

    pub(super) fn some_text(&self, row: &Row, i: usize, what: &str) -> Result<String, StoreError> {
        self.text(row, i, what)?
            .ok_or_else(|| self.corrupt(format!("{what}: missing")))
    }

    pub(super) fn bool(&self, row: &Row, i: usize, what: &str) -> Result<bool, StoreError> {
        match row.get(i) {
            Some(Value::Bool(v)) => Ok(*v),
            Some(Value::Int(v)) => Ok(*v != 0),
            other => Err(self.corrupt(format!("{what}: expected a boolean, found {other:?}"))),
        }
    }
}

/// Read access inside [`Store::read`](super::Store::read) (also available to writers).
pub struct Reader<'a> {
    pub(super) conn: Conn<'a>,
}

/// Write access inside [`Store::write`](super::Store::write).
pub struct Writer<'a> {
    pub(super) conn: Conn<'a>,
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
}

impl Reader<'_> {
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
            "trial_robots",
        ] {
            self.conn.query(
                &format!("SELECT count(*) FROM (SELECT * FROM {table} LIMIT 1) AS one"),
                &[],
            )?;
        }
        Ok(())
    }
}
