//! The database both the job queue and the machine catalog keep their rows in: SQLite in the
//! data directory (one node) or PostgreSQL (replicas), one pool shared by the two. Here is what
//! both need to know of it: which backend it is, its tables ([`schema`]), and which of its
//! errors mean "not now" or "no room" rather than "no".

pub mod schema;

/// Which database the store is on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Backend {
    Sqlite,
    Postgres,
}

/// Whether a database error is its disk being full: SQLite's `SQLITE_FULL`, PostgreSQL's
/// `disk_full`, or the OS's `ENOSPC`/`EDQUOT`.
pub fn disk_full(e: &sqlx::Error) -> bool {
    match e {
        sqlx::Error::Database(d) => d
            .code()
            .is_some_and(|c| c == "53100" || c.parse::<i32>().is_ok_and(|n| n & 0xff == 13)),
        sqlx::Error::Io(e) => matches!(e.kind(), std::io::ErrorKind::StorageFull | std::io::ErrorKind::QuotaExceeded),
        _ => false,
    }
}

/// A database error that means "not now", not "no": the connection went (reset, closed, the
/// server shut down or restarting: PostgreSQL's class 08 and 57P01–57P03), the pool had no
/// connection to give in time, too many clients, or the server asks for the transaction again
/// (serialization failure, deadlock; SQLite busy or locked). The same request asked again later
/// may well succeed, so the service answers 503 with `Retry-After` and a job's run goes back to
/// the queue, where any other error is the request's or the job's own. PostgreSQL's codes are
/// always five characters, SQLite's are its numeric (extended) result codes: the two never meet.
pub fn not_now(e: &sqlx::Error) -> bool {
    match e {
        sqlx::Error::Database(d) => d.code().is_some_and(|c| {
            c.starts_with("08")
                || matches!(
                    c.as_ref(),
                    "57P01" | "57P02" | "57P03" | "40001" | "40P01" | "53300" | "5" | "6" | "261" | "262" | "517" | "773"
                )
        }),
        e => connection_gone(e),
    }
}

/// The connection, not the statement, failed: the link (IO, TLS, the protocol), or the pool had
/// none to give. Whether the statement ran is then unknown.
pub fn connection_gone(e: &sqlx::Error) -> bool {
    matches!(
        e,
        sqlx::Error::Io(_)
            | sqlx::Error::Tls(_)
            | sqlx::Error::Protocol(_)
            | sqlx::Error::PoolTimedOut
            | sqlx::Error::PoolClosed
            | sqlx::Error::WorkerCrashed
    )
}

