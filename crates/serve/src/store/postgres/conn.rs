//! Statements on one pooled connection or one transaction: values bound as PostgreSQL's
//! types, rows read back as the store's values.

use std::future::Future;

use bytes::BytesMut;
use tokio_postgres::types::{IsNull, ToSql, Type, to_sql_checked};

use super::Postgres;
use crate::store::error::StoreError;
use crate::store::value::{Row, Value};

impl ToSql for Value {
    fn to_sql(
        &self,
        ty: &Type,
        out: &mut BytesMut,
    ) -> Result<IsNull, Box<dyn std::error::Error + Sync + Send>> {
        match self {
            Value::Null => Ok(IsNull::Yes),
            Value::Int(v) if *ty == Type::INT4 => i32::try_from(*v)?.to_sql(ty, out),
            Value::Int(v) if *ty == Type::FLOAT8 => (*v as f64).to_sql(ty, out),
            Value::Int(v) => v.to_sql(ty, out),
            Value::Real(v) => v.to_sql(ty, out),
            Value::Text(v) => v.to_sql(ty, out),
            Value::Bool(v) => v.to_sql(ty, out),
        }
    }

    fn accepts(_: &Type) -> bool {
        true
    }

    to_sql_checked!();
}

/// What a [`Conn`] runs its statements on.
pub(super) enum On<'a> {
    Client(&'a deadpool_postgres::Client),
    Tx(&'a Tx),
}

impl On<'_> {
    pub(super) fn client(&self) -> &deadpool_postgres::Client {
        match self {
            On::Client(c) => c,
            On::Tx(t) => t.client(),
        }
    }

    /// What to send before the next statements: `BEGIN` for a transaction none of whose
    /// statements was sent yet.
    pub(super) fn begin(&self) -> impl Future<Output = Result<(), tokio_postgres::Error>> + '_ {
        let begin = match self {
            On::Tx(t) => Some(t.begin()),
            On::Client(_) => None,
        };
        async move {
            match begin {
                Some(b) => b.await,
                None => Ok(()),
            }
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum TxState {
    /// Nothing sent yet: the BEGIN goes with the first statements.
    NotBegun,
    Open,
    Ended,
}

/// A transaction on a pooled connection whose `BEGIN` is sent with its first statements, in
/// the same round trip (tokio-postgres's own transaction waits for its `BEGIN` first, a round
/// trip more for every write, each waiting for a core on a busy machine). A transaction
/// dropped open (a panic) discards its connection, and the server rolls it back.
pub(super) struct Tx {
    pub(super) client: Option<deadpool_postgres::Client>,
    pub(super) state: std::cell::Cell<TxState>,
}

impl Tx {
    pub(super) fn new(client: deadpool_postgres::Client) -> Self {
        Self {
            client: Some(client),
            state: std::cell::Cell::new(TxState::NotBegun),
        }
    }

    pub(super) fn client(&self) -> &deadpool_postgres::Client {
        // Present until dropped.
        self.client.as_ref().unwrap_or_else(|| {
            unreachable!("a transaction's connection is kept until it is dropped")
        })
    }

    /// `BEGIN` when it was not sent yet (the transaction counts as open from here), else
    /// nothing; to be polled before the statements it goes with.
    pub(super) fn begin(&self) -> impl Future<Output = Result<(), tokio_postgres::Error>> + '_ {
        let first = self.state.get() == TxState::NotBegun;
        if first {
            self.state.set(TxState::Open);
        }
        async move {
            if first {
                self.client().batch_execute("BEGIN").await
            } else {
                Ok(())
            }
        }
    }
}

impl Drop for Tx {
    fn drop(&mut self) {
        if self.state.get() == TxState::Open
            && let Some(client) = self.client.take()
        {
            drop(deadpool_postgres::Object::take(client));
        }
    }
}

/// A pooled connection, or a transaction on one.
pub(in crate::store) struct Conn<'a> {
    pub(super) on: On<'a>,
    pub(super) pg: &'a Postgres,
}

impl Conn<'_> {
    pub(in crate::store) fn reborrow(&self) -> Conn<'_> {
        Conn {
            on: match &self.on {
                On::Client(c) => On::Client(c),
                On::Tx(t) => On::Tx(t),
            },
            pg: self.pg,
        }
    }

    pub(in crate::store) fn db(&self) -> &str {
        &self.pg.db
    }

    pub(super) fn batch(&self, sql: &str) -> Result<(), tokio_postgres::Error> {
        let c = self.on.client();
        self.pg.block_on(async {
            let (began, done) = tokio::join!(self.on.begin(), c.batch_execute(sql));
            began.and(done)
        })
    }

    pub(in crate::store) fn execute(&self, sql: &str, params: &[Value]) -> Result<u64, StoreError> {
        let params: Vec<&(dyn ToSql + Sync)> = params.iter().map(|p| p as _).collect();
        let pg = self.pg;
        let c = self.on.client();
        pg.block_on(async {
            let stmt = c.prepare_cached(sql).await?;
            let (began, done) = tokio::join!(self.on.begin(), c.execute(&stmt, &params));
            began.and(done)
        })
        .map_err(|e| pg.pg(e))
    }

    pub(in crate::store) fn query(
        &self,
        sql: &str,
        params: &[Value],
    ) -> Result<Vec<Row>, StoreError> {
        let params: Vec<&(dyn ToSql + Sync)> = params.iter().map(|p| p as _).collect();
        let pg = self.pg;
        let rows = pg
            .block_on(async {
                let c = self.on.client();
                let stmt = c.prepare_cached(sql).await?;
                let (began, rows) = tokio::join!(self.on.begin(), c.query(&stmt, &params));
                began.and(rows)
            })
            .map_err(|e| pg.pg(e))?;
        rows.iter().map(|r| row(pg, r)).collect()
    }

    /// Runs `statements` in order, sent together (pipelined): the server gets them in one
    /// round trip and runs each after the one before, so every statement sees what the ones
    /// before it did (a lock taken by the first is held when the second reads).
    pub(in crate::store) fn query_all(
        &self,
        statements: &[(&str, &[Value])],
    ) -> Result<Vec<Vec<Row>>, StoreError> {
        let pg = self.pg;
        let params: Vec<Vec<&(dyn ToSql + Sync)>> = statements
            .iter()
            .map(|(_, p)| p.iter().map(|v| v as _).collect())
            .collect();
        let answers = pg
            .block_on(async {
                // Prepared first (a round trip only for a statement new to this connection),
                // so that none is sent before an earlier one still waiting for its
                // preparation: the order they run in is the order given.
                let c = self.on.client();
                let prepared = futures_util::future::try_join_all(
                    statements.iter().map(|(sql, _)| c.prepare_cached(sql)),
                )
                .await?;
                let (began, answers) = tokio::join!(
                    self.on.begin(),
                    futures_util::future::try_join_all(
                        prepared
                            .iter()
                            .zip(&params)
                            .map(|(stmt, params)| c.query(stmt, params)),
                    )
                );
                began.and(answers)
            })
            .map_err(|e| pg.pg(e))?;
        answers
            .iter()
            .map(|rows| rows.iter().map(|r| row(pg, r)).collect())
            .collect()
    }
}

pub(super) fn row(pg: &Postgres, r: &tokio_postgres::Row) -> Result<Row, StoreError> {
    let err = |e| pg.pg(e);
    (0..r.len())
        .map(|i| {
            let ty = r.columns()[i].type_();
            Ok(if *ty == Type::INT8 {
                r.try_get::<_, Option<i64>>(i).map_err(err)?.into()
            } else if *ty == Type::INT4 {
                r.try_get::<_, Option<i32>>(i)
                    .map_err(err)?
                    .map(i64::from)
                    .into()
            } else if *ty == Type::FLOAT8 {
                r.try_get::<_, Option<f64>>(i).map_err(err)?.into()
            } else if *ty == Type::BOOL {
                r.try_get::<_, Option<bool>>(i).map_err(err)?.into()
            } else if *ty == Type::TEXT || *ty == Type::VARCHAR || *ty == Type::NAME {
                r.try_get::<_, Option<String>>(i).map_err(err)?.into()
            } else if *ty == Type::VOID {
                Value::Null
            } else {
                return Err(StoreError::Corrupt {
                    file: pg.db.clone(),
                    what: format!(
                        "column {} has type {ty}, which ferret does not read",
                        r.columns()[i].name()
                    ),
                });
            })
        })
        .collect()
}
