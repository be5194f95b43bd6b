//! The `scenes` table: scene texts by name.

use super::conn::{Conn, Reader, Writer};
use super::error::StoreError;
use super::value::Value;

impl Writer<'_> {
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
}

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
}
