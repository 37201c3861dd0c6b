//! Every table of the store, for both databases: the jobs' (`jobs`) and the machine catalog's
//! versions (`machine_versions`, `tool_table_versions`, `dialect_versions`). The SQL is the
//! same for SQLite and PostgreSQL (types both read: `TEXT`, `BIGINT`); only the question of
//! which columns a table already has is asked of each in its own words. Tables are made at
//! start-up, one replica at a time (the job store's advisory lock), and a table made by an
//! older version gets the columns added since.

use super::Backend;
use sqlx::AnyPool;

/// The job table and its index, as made today.
const JOBS: &str = "CREATE TABLE IF NOT EXISTS jobs (
    id TEXT PRIMARY KEY,
    state TEXT NOT NULL,
    machine TEXT NOT NULL,
    machine_version BIGINT,
    settings TEXT NOT NULL,
    filename TEXT,
    idempotency_key TEXT UNIQUE,
    input_bytes BIGINT NOT NULL,
    created_ms BIGINT NOT NULL,
    started_ms BIGINT,
    finished_ms BIGINT,
    bytes_read BIGINT NOT NULL DEFAULT 0,
    blocks BIGINT NOT NULL DEFAULT 0,
    attempts BIGINT NOT NULL DEFAULT 0,
    summary TEXT,
    error TEXT,
    nc_bytes BIGINT,
    owner TEXT,
    heartbeat_ms BIGINT,
    client TEXT,
    cause TEXT,
    not_before_ms BIGINT,
    request_digest TEXT
);
CREATE INDEX IF NOT EXISTS jobs_state ON jobs (state, created_ms)";

/// Columns added after the first release of the table, for stores made before them.
const JOBS_ADDED: [(&str, &str); 7] = [
    ("machine_version", "BIGINT"),
    ("owner", "TEXT"),
    ("heartbeat_ms", "BIGINT"),
    ("client", "TEXT"),
    ("cause", "TEXT"),
    ("not_before_ms", "BIGINT"),
    ("request_digest", "TEXT"),
];

/// The job table, and the columns added since its first release.
pub async fn jobs(pool: &AnyPool, backend: Backend) -> Result<(), sqlx::Error> {
    for stmt in JOBS.split(';') {
        sqlx::query(stmt).execute(pool).await?;
    }
    for (col, ty) in JOBS_ADDED {
        let has: i64 = match backend {
            Backend::Sqlite => {
                sqlx::query_scalar("SELECT COUNT(*) FROM pragma_table_info('jobs') WHERE name = $1")
                    .bind(col)
                    .fetch_one(pool)
                    .await?
            }
            Backend::Postgres => {
                sqlx::query_scalar(
                    "SELECT COUNT(*) FROM information_schema.columns WHERE table_name = 'jobs' AND column_name = $1",
                )
                .bind(col)
                .fetch_one(pool)
                .await?
            }
        };
        if has == 0 {
            sqlx::query(sqlx::AssertSqlSafe(format!("ALTER TABLE jobs ADD COLUMN {col} {ty}")))
                .execute(pool)
                .await?;
        }
    }
    Ok(())
}

/// A catalog shelf's table of versions (`table`: a constant of the shelf's kind, never input):
/// every kind has the same columns.
pub async fn versions(pool: &AnyPool, table: &str) -> Result<(), sqlx::Error> {
    let sql = format!(
        "CREATE TABLE IF NOT EXISTS {table} (
    id TEXT NOT NULL,
    version BIGINT NOT NULL,
    toml TEXT,
    source TEXT NOT NULL,
    created_ms BIGINT NOT NULL,
    PRIMARY KEY (id, version)
)"
    );
    sqlx::query(sqlx::AssertSqlSafe(sql)).execute(pool).await?;
    Ok(())
}
