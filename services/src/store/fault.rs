//! Database faults an operator can act on, told apart from bugs: the database is unreachable
//! or overloaded, full, or read-only. The API answers each with its own problem (503/507).
//!
//! Assumption: `sqlx` reports a SQLite error's code as its extended result code in decimal and
//! a PostgreSQL error's code as its SQLSTATE; the backend is told by the error's concrete type.

use super::StoreError;

/// A database condition that is not a bug of ours.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DbFault {
    /// Unreachable, restarting, shutting down, out of connections or locked: retry later.
    Unavailable,
    /// No space left for the write (SQLite `SQLITE_FULL`, PostgreSQL `53100 disk_full`).
    Full,
    /// Writes refused: a read-only file, or a read-only PostgreSQL database/session/standby.
    ReadOnly,
}

impl DbFault {
    /// What to tell the client (no secret, no SQL).
    pub fn describe(self) -> &'static str {
        match self {
            DbFault::Unavailable => "the database is unavailable; retry shortly",
            DbFault::Full => {
                "the database is full (no space left for this write); nothing was stored"
            }
            DbFault::ReadOnly => "the database is read-only; nothing was stored",
        }
    }
}

impl StoreError {
    /// The operational fault behind this error, if it is one (`None`: a bug or bad data).
    pub fn fault(&self) -> Option<DbFault> {
        match self {
            StoreError::Db(e) => sqlx_fault(e),
            StoreError::Migrate(sqlx::migrate::MigrateError::Execute(e)) => sqlx_fault(e),
            _ => None,
        }
    }
}

fn sqlx_fault(e: &sqlx::Error) -> Option<DbFault> {
    match e {
        // Connection refused until the acquire timeout, a pool being shut down, a socket
        // that broke mid-query (server stopped): all say "not now".
        sqlx::Error::PoolTimedOut
        | sqlx::Error::PoolClosed
        | sqlx::Error::Io(_)
        | sqlx::Error::WorkerCrashed => Some(DbFault::Unavailable),
        sqlx::Error::Database(d) => {
            let code = d.code()?;
            if d.try_downcast_ref::<sqlx::postgres::PgDatabaseError>()
                .is_some()
            {
                pg_fault(&code)
            } else {
                code.parse::<u32>().ok().and_then(sqlite_fault)
            }
        }
        _ => None,
    }
}

fn sqlite_fault(extended: u32) -> Option<DbFault> {
    // Primary result code = low byte of the extended code (sqlite3.h).
    match extended & 0xff {
        // SQLITE_FULL
        13 => Some(DbFault::Full),
        // SQLITE_READONLY (and its extended codes: file, directory, recovery, …)
        8 => Some(DbFault::ReadOnly),
        // SQLITE_BUSY / SQLITE_LOCKED after the busy timeout, SQLITE_CANTOPEN
        5 | 6 | 14 => Some(DbFault::Unavailable),
        _ => None,
    }
}

fn pg_fault(sqlstate: &str) -> Option<DbFault> {
    match sqlstate {
        // disk_full
        "53100" => Some(DbFault::Full),
        // read_only_sql_transaction (default_transaction_read_only, a hot standby)
        "25006" => Some(DbFault::ReadOnly),
        // insufficient_resources, out_of_memory, too_many_connections; admin_shutdown,
        // crash_shutdown, cannot_connect_now; serialization_failure, deadlock_detected
        "53000" | "53200" | "53300" | "57P01" | "57P02" | "57P03" | "40001" | "40P01" => {
            Some(DbFault::Unavailable)
        }
        // Class 08: connection exception.
        s if s.starts_with("08") => Some(DbFault::Unavailable),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sqlite_codes() {
        assert_eq!(sqlite_fault(13), Some(DbFault::Full));
        assert_eq!(sqlite_fault(8), Some(DbFault::ReadOnly));
        // SQLITE_READONLY_DBMOVED (1032), SQLITE_BUSY_SNAPSHOT (517)
        assert_eq!(sqlite_fault(1032), Some(DbFault::ReadOnly));
        assert_eq!(sqlite_fault(517), Some(DbFault::Unavailable));
        // SQLITE_CONSTRAINT_UNIQUE (2067) is a bug or a race, not an outage.
        assert_eq!(sqlite_fault(2067), None);
        assert_eq!(sqlite_fault(1), None);
    }

    #[test]
    fn postgres_codes() {
        assert_eq!(pg_fault("53100"), Some(DbFault::Full));
        assert_eq!(pg_fault("25006"), Some(DbFault::ReadOnly));
        assert_eq!(pg_fault("57P01"), Some(DbFault::Unavailable));
        assert_eq!(pg_fault("08006"), Some(DbFault::Unavailable));
        assert_eq!(pg_fault("23505"), None);
        assert_eq!(pg_fault("42P01"), None);
    }

    #[test]
    fn transport_errors_are_unavailable() {
        let e = StoreError::Db(sqlx::Error::PoolTimedOut);
        assert_eq!(e.fault(), Some(DbFault::Unavailable));
        let io = std::io::Error::new(std::io::ErrorKind::ConnectionReset, "reset");
        assert_eq!(
            StoreError::Db(sqlx::Error::Io(io)).fault(),
            Some(DbFault::Unavailable)
        );
        assert_eq!(StoreError::Invalid("x".into()).fault(), None);
        assert_eq!(StoreError::Db(sqlx::Error::RowNotFound).fault(), None);
    }
}
