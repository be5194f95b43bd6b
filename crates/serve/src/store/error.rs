//! Storage failures, on either backend.

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
