//! The job table (SQLite through sqlx, runtime queries only) and the spool directory.

use super::Error;
use crate::post::{Settings, Summary};
use serde::{Deserialize, Serialize};
use sqlx::Row;
use sqlx::sqlite::{SqliteConnectOptions, SqliteJournalMode, SqlitePool, SqlitePoolOptions, SqliteRow, SqliteSynchronous};
use std::path::{Path, PathBuf};
use std::time::Duration;
use tokio::io::AsyncWriteExt;

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum State {
    Queued,
    Running,
    Succeeded,
    Failed,
    Cancelled,
}

impl State {
    pub const ALL: [State; 5] = [State::Queued, State::Running, State::Succeeded, State::Failed, State::Cancelled];

    pub fn as_str(self) -> &'static str {
        match self {
            State::Queued => "queued",
            State::Running => "running",
            State::Succeeded => "succeeded",
            State::Failed => "failed",
            State::Cancelled => "cancelled",
        }
    }

    pub fn parse(s: &str) -> Option<State> {
        State::ALL.into_iter().find(|x| x.as_str() == s)
    }

    pub fn finished(self) -> bool {
        matches!(self, State::Succeeded | State::Failed | State::Cancelled)
    }
}

impl std::fmt::Display for State {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// A job as stored. Times are Unix milliseconds.
#[derive(Clone, Debug)]
pub struct Job {
    pub id: String,
    pub state: State,
    pub machine: String,
    pub settings: Settings,
    pub filename: Option<String>,
    pub idempotency_key: Option<String>,
    pub input_bytes: u64,
    pub created_ms: i64,
    pub started_ms: Option<i64>,
    pub finished_ms: Option<i64>,
    pub bytes_read: u64,
    pub blocks: u64,
    /// Runs started: more than one means a restart cut a run off.
    pub attempts: i64,
    pub summary: Option<serde_json::Value>,
    pub error: Option<String>,
    pub nc_bytes: Option<u64>,
}

/// A job's files in the spool.
pub(super) struct Paths {
    pub input: PathBuf,
    pub nc: PathBuf,
    pub nc_tmp: PathBuf,
    pub diag: PathBuf,
    pub diag_tmp: PathBuf,
}

impl Paths {
    pub fn new(spool: &Path, id: &str) -> Paths {
        Paths {
            input: spool.join(format!("{id}.cl")),
            nc: spool.join(format!("{id}.nc")),
            nc_tmp: spool.join(format!("{id}.nc.tmp")),
            diag: spool.join(format!("{id}.ndjson")),
            diag_tmp: spool.join(format!("{id}.ndjson.tmp")),
        }
    }
}

pub struct Store {
    pool: SqlitePool,
    spool: PathBuf,
}

const SCHEMA: &str = "CREATE TABLE IF NOT EXISTS jobs (
    id TEXT PRIMARY KEY,
    state TEXT NOT NULL,
    machine TEXT NOT NULL,
    settings TEXT NOT NULL,
    filename TEXT,
    idempotency_key TEXT UNIQUE,
    input_bytes INTEGER NOT NULL,
    created_ms INTEGER NOT NULL,
    started_ms INTEGER,
    finished_ms INTEGER,
    bytes_read INTEGER NOT NULL DEFAULT 0,
    blocks INTEGER NOT NULL DEFAULT 0,
    attempts INTEGER NOT NULL DEFAULT 0,
    summary TEXT,
    error TEXT,
    nc_bytes INTEGER
);
CREATE INDEX IF NOT EXISTS jobs_state ON jobs (state, created_ms)";

fn now_ms() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_millis() as i64)
        .unwrap_or(0)
}

fn row_job(r: &SqliteRow) -> Result<Job, Error> {
    let state: String = r.try_get("state")?;
    let settings: String = r.try_get("settings")?;
    let summary: Option<String> = r.try_get("summary")?;
    let u = |name: &str| -> Result<u64, Error> { Ok(r.try_get::<i64, _>(name)?.max(0) as u64) };
    Ok(Job {
        id: r.try_get("id")?,
        state: State::parse(&state).ok_or_else(|| Error::Corrupt(format!("job state {state:?}")))?,
        machine: r.try_get("machine")?,
        settings: serde_json::from_str(&settings).map_err(|e| Error::Corrupt(format!("job settings: {e}")))?,
        filename: r.try_get("filename")?,
        idempotency_key: r.try_get("idempotency_key")?,
        input_bytes: u("input_bytes")?,
        created_ms: r.try_get("created_ms")?,
        started_ms: r.try_get("started_ms")?,
        finished_ms: r.try_get("finished_ms")?,
        bytes_read: u("bytes_read")?,
        blocks: u("blocks")?,
        attempts: r.try_get("attempts")?,
        summary: summary.and_then(|s| serde_json::from_str(&s).ok()),
        error: r.try_get("error")?,
        nc_bytes: r.try_get::<Option<i64>, _>("nc_bytes")?.map(|v| v.max(0) as u64),
    })
}

/// Makes a rename or a new file durable: the directory entry itself is fsynced.
fn sync_dir(dir: &Path) -> std::io::Result<()> {
    #[cfg(unix)]
    std::fs::File::open(dir)?.sync_all()?;
    let _ = dir;
    Ok(())
}

impl Store {
    pub async fn open(data_dir: &Path) -> Result<Store, Error> {
        let spool = data_dir.join("spool");
        tokio::fs::create_dir_all(&spool).await?;
        let opts = SqliteConnectOptions::new()
            .filename(data_dir.join("jobs.sqlite"))
            .create_if_missing(true)
            .journal_mode(SqliteJournalMode::Wal)
            .synchronous(SqliteSynchronous::Full)
            .busy_timeout(Duration::from_secs(10));
        let pool = SqlitePoolOptions::new().max_connections(4).connect_with(opts).await?;
        for stmt in SCHEMA.split(';') {
            sqlx::query(stmt).execute(&pool).await?;
        }
        Ok(Store { pool, spool })
    }

    pub fn spool(&self) -> &Path {
        &self.spool
    }

    /// Jobs cut off mid-run go back to the queue; stale temporary files go.
    pub async fn recover(&self) -> Result<u64, Error> {
        let n = sqlx::query(
            "UPDATE jobs SET state = 'queued', started_ms = NULL, bytes_read = 0, blocks = 0 WHERE state = 'running'",
        )
        .execute(&self.pool)
        .await?
        .rows_affected();
        let mut dir = tokio::fs::read_dir(&self.spool).await?;
        while let Some(e) = dir.next_entry().await? {
            if e.file_name().to_string_lossy().ends_with(".tmp") {
                let _ = tokio::fs::remove_file(e.path()).await;
            }
        }
        Ok(n)
    }

    pub async fn by_key(&self, key: &str) -> Result<Option<Job>, Error> {
        let r = sqlx::query("SELECT * FROM jobs WHERE idempotency_key = ?")
            .bind(key)
            .fetch_optional(&self.pool)
            .await?;
        r.as_ref().map(row_job).transpose()
    }

    pub async fn get(&self, id: &str) -> Result<Job, Error> {
        let r = sqlx::query("SELECT * FROM jobs WHERE id = ?")
            .bind(id)
            .fetch_optional(&self.pool)
            .await?;
        match r {
            Some(r) => row_job(&r),
            None => Err(Error::NotFound(id.to_string())),
        }
    }

    /// Newest first.
    pub async fn list(&self, state: Option<State>, limit: u32, offset: u64) -> Result<Vec<Job>, Error> {
        let rows = sqlx::query(
            "SELECT * FROM jobs WHERE (?1 IS NULL OR state = ?1) ORDER BY created_ms DESC, id LIMIT ?2 OFFSET ?3",
        )
        .bind(state.map(State::as_str))
        .bind(limit as i64)
        .bind(offset.min(i64::MAX as u64) as i64)
        .fetch_all(&self.pool)
        .await?;
        rows.iter().map(row_job).collect()
    }

    pub async fn count(&self, state: State) -> Result<u64, Error> {
        let n: i64 = sqlx::query_scalar("SELECT COUNT(*) FROM jobs WHERE state = ?")
            .bind(state.as_str())
            .fetch_one(&self.pool)
            .await?;
        Ok(n.max(0) as u64)
    }

    pub(super) async fn insert(
        &self,
        settings: Settings,
        filename: Option<String>,
        key: Option<String>,
        mut input: impl tokio::io::AsyncRead + Unpin,
    ) -> Result<(Job, bool), Error> {
        let id = uuid::Uuid::new_v4().simple().to_string();
        let p = Paths::new(&self.spool, &id);
        let tmp = self.spool.join(format!("{id}.cl.tmp"));
        let copied = async {
            let mut f = tokio::fs::File::create(&tmp).await?;
            let n = tokio::io::copy(&mut input, &mut f).await?;
            f.flush().await?;
            f.sync_all().await?;
            Ok::<u64, std::io::Error>(n)
        }
        .await;
        let n = match copied {
            Ok(n) => n,
            Err(e) => {
                let _ = tokio::fs::remove_file(&tmp).await;
                return Err(Error::Upload(e.to_string()));
            }
        };
        tokio::fs::rename(&tmp, &p.input).await?;
        sync_dir(&self.spool)?;
        let machine = settings.machine.clone().unwrap_or_default();
        let res = sqlx::query(
            "INSERT INTO jobs (id, state, machine, settings, filename, idempotency_key, input_bytes, created_ms)
             VALUES (?, 'queued', ?, ?, ?, ?, ?, ?)",
        )
        .bind(&id)
        .bind(&machine)
        .bind(serde_json::to_string(&settings).unwrap_or_default())
        .bind(&filename)
        .bind(&key)
        .bind(n.min(i64::MAX as u64) as i64)
        .bind(now_ms())
        .execute(&self.pool)
        .await;
        match res {
            Ok(_) => Ok((self.get(&id).await?, true)),
            Err(e) => {
                let _ = tokio::fs::remove_file(&p.input).await;
                // Two submissions with one key raced: the first one's job is the answer.
                if let Some(k) = &key
                    && let Some(j) = self.by_key(k).await?
                {
                    return Ok((j, false));
                }
                Err(e.into())
            }
        }
    }

    /// Takes the oldest queued job; SQLite serializes writers, so two workers never get one job.
    pub(super) async fn claim(&self) -> Result<Option<Job>, Error> {
        let r = sqlx::query(
            "UPDATE jobs SET state = 'running', started_ms = ?, attempts = attempts + 1, bytes_read = 0, blocks = 0
             WHERE id = (SELECT id FROM jobs WHERE state = 'queued' ORDER BY created_ms, id LIMIT 1) AND state = 'queued'
             RETURNING *",
        )
        .bind(now_ms())
        .fetch_optional(&self.pool)
        .await?;
        r.as_ref().map(row_job).transpose()
    }

    /// Records progress; `false` when the job is no longer running (cancelled).
    pub(super) async fn progress(&self, id: &str, bytes: u64, blocks: u64) -> Result<bool, Error> {
        let n = sqlx::query("UPDATE jobs SET bytes_read = ?, blocks = ? WHERE id = ? AND state = 'running'")
            .bind(bytes as i64)
            .bind(blocks as i64)
            .bind(id)
            .execute(&self.pool)
            .await?
            .rows_affected();
        Ok(n > 0)
    }

    /// Publishes the outputs (rename, then the row), unless the job was cancelled meanwhile.
    pub(super) async fn succeed(&self, id: &str, s: &Summary) -> Result<(), Error> {
        if self.get(id).await?.state != State::Running {
            self.remove_outputs(id);
            return Ok(());
        }
        let p = Paths::new(&self.spool, id);
        tokio::fs::rename(&p.nc_tmp, &p.nc).await?;
        tokio::fs::rename(&p.diag_tmp, &p.diag).await?;
        sync_dir(&self.spool)?;
        let nc_bytes = tokio::fs::metadata(&p.nc).await?.len();
        sqlx::query(
            "UPDATE jobs SET state = 'succeeded', finished_ms = ?, summary = ?, nc_bytes = ? WHERE id = ? AND state = 'running'",
        )
        .bind(now_ms())
        .bind(serde_json::to_string(s).unwrap_or_default())
        .bind(nc_bytes as i64)
        .bind(id)
        .execute(&self.pool)
        .await?;
        Ok(())
    }

    /// A failed job keeps its diagnostics (ending with the error), never its partial program.
    pub(super) async fn fail(&self, id: &str, msg: &str) -> Result<(), Error> {
        let p = Paths::new(&self.spool, id);
        let _ = tokio::fs::remove_file(&p.nc_tmp).await;
        let _ = tokio::fs::rename(&p.diag_tmp, &p.diag).await;
        sqlx::query("UPDATE jobs SET state = 'failed', finished_ms = ?, error = ? WHERE id = ? AND state = 'running'")
            .bind(now_ms())
            .bind(msg)
            .bind(id)
            .execute(&self.pool)
            .await?;
        Ok(())
    }

    pub(super) async fn cancel(&self, id: &str) -> Result<Job, Error> {
        let n = sqlx::query(
            "UPDATE jobs SET state = 'cancelled', finished_ms = ? WHERE id = ? AND state IN ('queued', 'running')",
        )
        .bind(now_ms())
        .bind(id)
        .execute(&self.pool)
        .await?
        .rows_affected();
        let j = self.get(id).await?;
        if n == 0 {
            return Err(Error::WrongState {
                id: id.to_string(),
                state: j.state,
            });
        }
        Ok(j)
    }

    /// Removes a finished job and its files.
    pub async fn delete(&self, id: &str) -> Result<(), Error> {
        let j = self.get(id).await?;
        if !j.state.finished() {
            return Err(Error::WrongState {
                id: id.to_string(),
                state: j.state,
            });
        }
        sqlx::query("DELETE FROM jobs WHERE id = ?").bind(id).execute(&self.pool).await?;
        self.remove_files(id);
        Ok(())
    }

    pub(super) fn remove_outputs(&self, id: &str) {
        let p = Paths::new(&self.spool, id);
        for f in [&p.nc_tmp, &p.diag_tmp] {
            let _ = std::fs::remove_file(f);
        }
    }

    fn remove_files(&self, id: &str) {
        let p = Paths::new(&self.spool, id);
        for f in [&p.input, &p.nc, &p.nc_tmp, &p.diag, &p.diag_tmp] {
            let _ = std::fs::remove_file(f);
        }
    }

    /// Removes jobs finished longer ago than `retention`, files first.
    pub(super) async fn expire(&self, retention: Duration) -> Result<u64, Error> {
        let cutoff = now_ms() - retention.as_millis().min(i64::MAX as u128) as i64;
        let ids: Vec<String> = sqlx::query_scalar(
            "SELECT id FROM jobs WHERE state IN ('succeeded', 'failed', 'cancelled') AND finished_ms < ?",
        )
        .bind(cutoff)
        .fetch_all(&self.pool)
        .await?;
        for id in &ids {
            self.remove_files(id);
            sqlx::query("DELETE FROM jobs WHERE id = ?").bind(id).execute(&self.pool).await?;
        }
        Ok(ids.len() as u64)
    }

    /// Where a finished job's output lives (the NC program or the NDJSON diagnostics).
    pub fn output_path(&self, id: &str, diagnostics: bool) -> PathBuf {
        let p = Paths::new(&self.spool, id);
        if diagnostics { p.diag } else { p.nc }
    }
}
