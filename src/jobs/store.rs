//! The job table and the spool directory. One store, two backends through sqlx's `Any` driver
//! (runtime queries only, `$N` parameters that both understand): SQLite in the data directory for
//! one node, PostgreSQL (`KINEPOST_DATABASE_URL`) for replicas sharing a spool directory. The
//! SQL is the same except where the backends differ in kind: claiming (`FOR UPDATE SKIP LOCKED`)
//! and start-up recovery (one node may requeue every running job; replicas go by leases).

mod accept;
mod retry;
mod sweep;

pub use accept::{Submission, options_digest};
pub use retry::MAX_BACKOFF;

use super::Error;
pub use crate::db::Backend;
use crate::post::Summary;
use crate::spool::seal::Diagnostics;
use crate::spool::{Output, Paths, sync_dir};
use serde::{Deserialize, Serialize};
use sqlx::AnyPool;
use sqlx::Row;
use sqlx::any::{AnyPoolOptions, AnyRow};
use std::path::{Path, PathBuf};
use std::time::Duration;

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum JobState {
    Queued,
    Running,
    Succeeded,
    Failed,
    Cancelled,
}

impl JobState {
    pub const ALL: [JobState; 5] = [
        JobState::Queued,
        JobState::Running,
        JobState::Succeeded,
        JobState::Failed,
        JobState::Cancelled,
    ];

    pub fn as_str(self) -> &'static str {
        match self {
            JobState::Queued => "queued",
            JobState::Running => "running",
            JobState::Succeeded => "succeeded",
            JobState::Failed => "failed",
            JobState::Cancelled => "cancelled",
        }
    }

    pub fn parse(s: &str) -> Option<JobState> {
        JobState::ALL.into_iter().find(|x| x.as_str() == s)
    }

    pub fn finished(self) -> bool {
        matches!(self, JobState::Succeeded | JobState::Failed | JobState::Cancelled)
    }
}

impl std::fmt::Display for JobState {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// A job's settings as its row records them: the post's as the request gave them, and what the
/// service chose when it accepted the job, never a request: the versions of the machine's tool
/// table (none: the machine had none, or the job brings its own) and of the dialect (the one
/// named, else the profile's controller) the job runs with. One JSON object, as before the two
/// were apart.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct JobSettings {
    #[serde(flatten)]
    pub post: crate::post::Settings,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub machine_tools_version: Option<i64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dialect_version: Option<i64>,
}

/// A job as stored. Times are Unix milliseconds.
#[derive(Clone, Debug)]
pub struct Job {
    pub id: String,
    pub state: JobState,
    pub machine: String,
    /// The profile version the job was submitted with (and runs with). `None` in rows written
    /// before profiles had versions: those run with the current one.
    pub machine_version: Option<i64>,
    pub settings: JobSettings,
    pub filename: Option<String>,
    pub idempotency_key: Option<String>,
    /// What identifies the request a key was given with (`accept::digest`): the same key with
    /// another request is refused. `None` in rows written before it was kept: the key alone.
    pub request_digest: Option<String>,
    pub input_bytes: u64,
    pub created_ms: i64,
    pub started_ms: Option<i64>,
    pub finished_ms: Option<i64>,
    pub bytes_read: u64,
    pub blocks: u64,
    /// Runs started: more than one means a run was cut off (a replica stopped) or failed for a
    /// cause outside the job, and the job went back to the queue.
    pub attempts: i64,
    /// Why the last run that did not finish went back to the queue (a full spool, the store
    /// not answering, a replica that stopped reporting).
    pub cause: Option<String>,
    /// A job queued again after such a run is not claimed before this time (the backoff).
    pub not_before_ms: Option<i64>,
    /// The node running it (or that ran it last).
    pub owner: Option<String>,
    pub summary: Option<serde_json::Value>,
    pub error: Option<String>,
    pub nc_bytes: Option<u64>,
}

impl Job {
    /// A job of `machine` in `state`, nothing run or recorded yet.
    pub(super) fn new(id: String, state: JobState, machine: String, created_ms: i64) -> Job {
        Job {
            id,
            state,
            machine,
            machine_version: None,
            settings: JobSettings::default(),
            filename: None,
            idempotency_key: None,
            request_digest: None,
            input_bytes: 0,
            created_ms,
            started_ms: None,
            finished_ms: None,
            bytes_read: 0,
            blocks: 0,
            attempts: 0,
            cause: None,
            not_before_ms: None,
            owner: None,
            summary: None,
            error: None,
            nc_bytes: None,
        }
    }
}

pub struct Store {
    pool: AnyPool,
    backend: Backend,
    spool: PathBuf,
    /// This process, as the owner of the jobs it runs.
    node: String,
    /// A running job whose owner has not reported for this long is taken over.
    lease: Duration,
    startup: tokio::sync::Mutex<Option<sqlx::pool::PoolConnection<sqlx::Any>>>,
}

fn now_ms() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_millis() as i64)
        .unwrap_or(0)
}

fn row_job(r: &AnyRow) -> Result<Job, Error> {
    let state: String = r.try_get("state")?;
    let settings: String = r.try_get("settings")?;
    let summary: Option<String> = r.try_get("summary")?;
    let u = |name: &str| -> Result<u64, Error> { Ok(r.try_get::<i64, _>(name)?.max(0) as u64) };
    Ok(Job {
        id: r.try_get("id")?,
        state: JobState::parse(&state).ok_or_else(|| Error::Corrupt(format!("job state {state:?}")))?,
        machine: r.try_get("machine")?,
        machine_version: r.try_get("machine_version")?,
        settings: serde_json::from_str(&settings).map_err(|e| Error::Corrupt(format!("job settings: {e}")))?,
        filename: r.try_get("filename")?,
        idempotency_key: r.try_get("idempotency_key")?,
        request_digest: r.try_get("request_digest")?,
        input_bytes: u("input_bytes")?,
        created_ms: r.try_get("created_ms")?,
        started_ms: r.try_get("started_ms")?,
        finished_ms: r.try_get("finished_ms")?,
        bytes_read: u("bytes_read")?,
        blocks: u("blocks")?,
        attempts: r.try_get("attempts")?,
        cause: r.try_get("cause")?,
        not_before_ms: r.try_get("not_before_ms")?,
        summary: summary.and_then(|s| serde_json::from_str(&s).ok()),
        error: r.try_get("error")?,
        nc_bytes: r.try_get::<Option<i64>, _>("nc_bytes")?.map(|v| v.max(0) as u64),
        owner: r.try_get("owner")?,
    })
}

/// The store's name in errors: a PostgreSQL URL without its password.
fn redacted(url: &str) -> String {
    match (url.split_once("://"), url.rfind('@')) {
        (Some((scheme, rest)), Some(at)) => {
            let user = rest[..at - scheme.len() - 3].split(':').next().unwrap_or("");
            format!("{scheme}://{user}@{}", &url[at + 1..])
        }
        _ => url.to_string(),
    }
}

fn open_error(named: &str) -> impl Fn(sqlx::Error) -> Error + '_ {
    move |e| Error::Open {
        store: named.to_string(),
        error: e.to_string(),
    }
}

async fn connect_postgres(url: &str) -> Result<AnyPool, sqlx::Error> {
    AnyPoolOptions::new()
        .max_connections(8)
        .acquire_timeout(Duration::from_secs(10))
        // A client gone mid-transaction (a partition, not a closed socket) must not hold the job
        // insert lock for as long as TCP takes to notice.
        .after_connect(|conn, _| {
            Box::pin(async move {
                use sqlx::Executor;
                conn.execute("SET idle_in_transaction_session_timeout = 10000").await?;
                Ok(())
            })
        })
        .connect(url)
        .await
}

/// SQLite in `path`: checked before use (a damaged file is refused at start-up, naming it, not
/// found by a request), then WAL and fsync on every commit; writers wait rather than fail.
async fn connect_sqlite(path: &Path) -> Result<AnyPool, Error> {
    use sqlx::Connection;
    let named = |e: String| Error::Open {
        store: path.display().to_string(),
        error: e,
    };
    let url = format!("sqlite://{}?mode=rwc", path.display());
    if path.exists() {
        let check = async {
            let mut c = sqlx::AnyConnection::connect(&url).await?;
            let rows: Vec<String> = sqlx::query_scalar("PRAGMA quick_check").fetch_all(&mut c).await?;
            c.close().await?;
            Ok::<_, sqlx::Error>(rows)
        };
        match tokio::time::timeout(Duration::from_secs(10), check).await {
            Ok(Ok(rows)) if rows == ["ok"] => {}
            Ok(Ok(rows)) => return Err(named(format!("damaged: {}", rows.join("; ")))),
            Ok(Err(e)) => return Err(named(e.to_string())),
            Err(_) => return Err(named("no answer to a check in 10 s".into())),
        }
    }
    AnyPoolOptions::new()
        .max_connections(4)
        .acquire_timeout(Duration::from_secs(10))
        .after_connect(|conn, _| {
            Box::pin(async move {
                use sqlx::Executor;
                conn.execute("PRAGMA journal_mode = WAL").await?;
                conn.execute("PRAGMA synchronous = FULL").await?;
                conn.execute("PRAGMA busy_timeout = 10000").await?;
                Ok(())
            })
        })
        .connect(&url)
        .await
        .map_err(|e| named(e.to_string()))
}

/// This node's name as the owner of its runs and uploads: kept in the data directory, so that a
/// restarted process knows what its predecessor left in a shared spool. One process per data
/// directory.
fn node_name(data_dir: &Path) -> std::io::Result<String> {
    let path = data_dir.join("node");
    let ok = |s: &str| !s.is_empty() && s.len() <= 80 && s.bytes().all(|b| b.is_ascii_alphanumeric() || b"-_.".contains(&b));
    if let Ok(s) = std::fs::read_to_string(&path)
        && ok(s.trim())
    {
        return Ok(s.trim().to_string());
    }
    let host: String = std::env::var("HOSTNAME")
        .unwrap_or_default()
        .chars()
        .filter(|c| c.is_ascii_alphanumeric() || "-_.".contains(*c))
        .take(60)
        .collect();
    let host = if host.is_empty() { "node".to_string() } else { host };
    let node = format!("{host}-{}", &uuid::Uuid::new_v4().simple().to_string()[..8]);
    let tmp = data_dir.join("node.tmp");
    std::fs::write(&tmp, &node)?;
    std::fs::File::open(&tmp)?.sync_all()?;
    std::fs::rename(&tmp, &path)?;
    sync_dir(data_dir)?;
    Ok(node)
}

/// A row read for display: one that cannot be decoded (damaged, or written by another version)
/// is shown as a failed job with its id and the reason, never an error for a whole listing.
fn row_shown(r: &AnyRow) -> Job {
    row_job(r).unwrap_or_else(|e| {
        let id: String = r.try_get("id").unwrap_or_default();
        tracing::warn!(job = %id, error = %e, "a job's stored row cannot be read");
        let error = format!("this job's stored row cannot be read ({e}); DELETE /v1/jobs/{id} removes it");
        let (machine, created_ms) = (
            r.try_get("machine").unwrap_or_default(),
            r.try_get("created_ms").unwrap_or_default(),
        );
        Job {
            error: Some(error),
            idempotency_key: r.try_get("idempotency_key").unwrap_or_default(),
            ..Job::new(id, JobState::Failed, machine, created_ms)
        }
    })
}

impl Store {
    /// Opens (and creates) the store: PostgreSQL when `database_url` is given, else SQLite in
    /// `data_dir`. The spool is `spool` (shared between replicas) or `data_dir/spool`.
    pub async fn open(
        data_dir: &Path,
        database_url: Option<&str>,
        spool: Option<&Path>,
        lease: Duration,
    ) -> Result<Store, Error> {
        sqlx::any::install_default_drivers();
        let spool = spool.map_or_else(|| data_dir.join("spool"), Path::to_path_buf);
        tokio::fs::create_dir_all(&spool).await?;
        tokio::fs::create_dir_all(data_dir).await?;
        let node = node_name(data_dir)?;
        let (pool, backend, named) = match database_url {
            Some(url) if url.starts_with("postgres:") || url.starts_with("postgresql:") => {
                let named = redacted(url);
                (
                    connect_postgres(url).await.map_err(open_error(&named))?,
                    Backend::Postgres,
                    named,
                )
            }
            Some(url) => return Err(Error::Corrupt(format!("database URL {url:?}: expected postgres://…"))),
            None => {
                let path = data_dir.join("jobs.sqlite");
                let named = path.display().to_string();
                (connect_sqlite(&path).await?, Backend::Sqlite, named)
            }
        };
        // Replicas starting together would race on CREATE TABLE (PostgreSQL's catalog is not
        // IF-NOT-EXISTS-safe under concurrency) and on seeding the machine catalog: one at a
        // time, under an advisory lock held until `started()`.
        let startup = match backend {
            Backend::Postgres => {
                let mut conn = pool.acquire().await?;
                sqlx::query("SELECT pg_advisory_lock(7311000001)").execute(&mut *conn).await?;
                Some(conn)
            }
            Backend::Sqlite => None,
        };
        crate::db::schema::jobs(&pool, backend).await.map_err(open_error(&named))?;
        let store = Store {
            pool,
            backend,
            spool,
            node,
            lease,
            startup: tokio::sync::Mutex::new(startup),
        };
        store.check().await.map_err(|e| Error::Open {
            store: named,
            error: e.to_string(),
        })?;
        Ok(store)
    }

    /// A cheap read of the job table: the store answers (readiness, start-up).
    pub async fn check(&self) -> Result<u64, Error> {
        self.count(JobState::Queued).await
    }

    /// Start-up is over (schema, recovery, catalog seeding): the next replica may start.
    pub async fn started(&self) {
        if let Some(mut conn) = self.startup.lock().await.take() {
            let _ = sqlx::query("SELECT pg_advisory_unlock(7311000001)").execute(&mut *conn).await;
        }
    }

    /// The connection pool, shared with the machine catalog (one store).
    pub fn pool(&self) -> &AnyPool {
        &self.pool
    }

    pub fn backend(&self) -> Backend {
        self.backend
    }

    /// This process's name as a job owner.
    pub fn node(&self) -> &str {
        &self.node
    }

    pub fn spool(&self) -> &Path {
        &self.spool
    }

    /// One node: every job found running was cut off by this node's end; they go back to the
    /// queue (their temporaries go with the start-up sweep). Replicas share the store: nothing is
    /// taken from a live peer here; a dead peer's jobs are taken over by lease in `claim`.
    pub async fn recover(&self) -> Result<u64, Error> {
        if self.backend != Backend::Sqlite {
            return Ok(0);
        }
        let n = sqlx::query(
            "UPDATE jobs SET state = 'queued', started_ms = NULL, bytes_read = 0, blocks = 0,
                 cause = 'its run was cut off by a restart of this node' WHERE state = 'running'",
        )
        .execute(&self.pool)
        .await?
        .rows_affected();
        Ok(n)
    }

    pub async fn by_key(&self, key: &str) -> Result<Option<Job>, Error> {
        let r = sqlx::query("SELECT * FROM jobs WHERE idempotency_key = $1")
            .bind(key)
            .fetch_optional(&self.pool)
            .await?;
        Ok(r.as_ref().map(row_shown))
    }

    pub async fn get(&self, id: &str) -> Result<Job, Error> {
        let r = sqlx::query("SELECT * FROM jobs WHERE id = $1")
            .bind(id)
            .fetch_optional(&self.pool)
            .await?;
        match r {
            Some(r) => Ok(row_shown(&r)),
            None => Err(Error::NotFound(id.to_string())),
        }
    }

    /// Newest first.
    pub async fn list(&self, state: Option<JobState>, limit: u32, offset: u64) -> Result<Vec<Job>, Error> {
        let offset = offset.min(i64::MAX as u64) as i64;
        let rows = match state {
            Some(st) => {
                sqlx::query("SELECT * FROM jobs WHERE state = $1 ORDER BY created_ms DESC, id LIMIT $2 OFFSET $3")
                    .bind(st.as_str())
                    .bind(limit as i64)
                    .bind(offset)
                    .fetch_all(&self.pool)
                    .await?
            }
            None => {
                sqlx::query("SELECT * FROM jobs ORDER BY created_ms DESC, id LIMIT $1 OFFSET $2")
                    .bind(limit as i64)
                    .bind(offset)
                    .fetch_all(&self.pool)
                    .await?
            }
        };
        Ok(rows.iter().map(row_shown).collect())
    }

    pub async fn count(&self, state: JobState) -> Result<u64, Error> {
        let n: i64 = sqlx::query_scalar("SELECT COUNT(*) FROM jobs WHERE state = $1")
            .bind(state.as_str())
            .fetch_one(&self.pool)
            .await?;
        Ok(n.max(0) as u64)
    }

    /// Takes the oldest queued job, or a running one whose owner stopped reporting (a replica
    /// that died). SQLite serializes writers; PostgreSQL skips rows another replica is claiming,
    /// so two workers never get one job. A row that cannot be read is failed, naming why, and
    /// the next one taken: it would otherwise be claimed again and again. So is a job whose runs
    /// were cut off more than `max_attempts` times (each took its replica down, perhaps).
    pub(super) async fn claim(&self, max_attempts: i64) -> Result<Option<Job>, Error> {
        loop {
            let Some(r) = self.claim_row().await? else { return Ok(None) };
            match row_job(&r) {
                Ok(j) if j.attempts > max_attempts => {
                    let cause = j.cause.as_deref().unwrap_or("cut off");
                    let why = format!("run {} times without an end, not run again: {cause}", j.attempts - 1);
                    tracing::error!(job = %j.id, error = %why, "a job's runs keep being cut off: failed");
                    sqlx::query(
                        "UPDATE jobs SET state = 'failed', finished_ms = $1, error = $2 WHERE id = $3 AND state = 'running' AND owner = $4",
                    )
                    .bind(now_ms())
                    .bind(&why)
                    .bind(&j.id)
                    .bind(&self.node)
                    .execute(&self.pool)
                    .await?;
                }
                Ok(j) => {
                    if j.attempts > 1 {
                        // A run before this one that did not end (its replica killed, or cut off
                        // by a restart) left its temporaries: they are not this run's.
                        self.remove_outputs(&Job {
                            attempts: j.attempts - 1,
                            ..j.clone()
                        });
                    }
                    return Ok(Some(j));
                }
                Err(e) => {
                    let id: String = r.try_get("id")?;
                    tracing::error!(job = %id, error = %e, "a claimed job's row cannot be read: failed");
                    sqlx::query("UPDATE jobs SET state = 'failed', finished_ms = $1, error = $2 WHERE id = $3")
                        .bind(now_ms())
                        .bind(format!("this job's stored row cannot be read ({e})"))
                        .bind(&id)
                        .execute(&self.pool)
                        .await?;
                }
            }
        }
    }

    async fn claim_row(&self) -> Result<Option<AnyRow>, Error> {
        let lock = match self.backend {
            Backend::Sqlite => "",
            Backend::Postgres => "FOR UPDATE SKIP LOCKED",
        };
        let now = now_ms();
        let stale = now - self.lease.as_millis().min(i64::MAX as u128) as i64;
        // A job queued again after a fault waits out its backoff; a run taken over says whose.
        let sql = format!(
            "UPDATE jobs SET state = 'running', started_ms = $1, heartbeat_ms = $1, owner = $2, attempts = attempts + 1,
                 bytes_read = 0, blocks = 0, not_before_ms = NULL,
                 cause = CASE WHEN state = 'running'
                              THEN 'its run on ' || COALESCE(owner, 'another node') || ' stopped reporting (the lease ran out)'
                              ELSE cause END
             WHERE id = (SELECT id FROM jobs
                         WHERE (state = 'queued' AND (not_before_ms IS NULL OR not_before_ms <= $1))
                            OR (state = 'running' AND heartbeat_ms < $3)
                         ORDER BY created_ms, id LIMIT 1 {lock})
               AND ((state = 'queued' AND (not_before_ms IS NULL OR not_before_ms <= $1))
                    OR (state = 'running' AND heartbeat_ms < $3))
             RETURNING *"
        );
        let r = sqlx::query(sqlx::AssertSqlSafe(sql))
            .bind(now)
            .bind(&self.node)
            .bind(stale)
            .fetch_optional(&self.pool)
            .await?;
        Ok(r)
    }

    /// Records progress and renews this node's lease; `false` when the job is no longer this
    /// node's to run (cancelled, or taken over).
    pub(super) async fn progress(&self, id: &str, bytes: u64, blocks: u64) -> Result<bool, Error> {
        let n = sqlx::query(
            "UPDATE jobs SET bytes_read = $1, blocks = $2, heartbeat_ms = $3 WHERE id = $4 AND state = 'running' AND owner = $5",
        )
        .bind(bytes as i64)
        .bind(blocks as i64)
        .bind(now_ms())
        .bind(id)
        .bind(&self.node)
        .execute(&self.pool)
        .await?
        .rows_affected();
        Ok(n > 0)
    }

    fn still_mine(&self, j: &Job) -> bool {
        j.state == JobState::Running && j.owner.as_deref() == Some(self.node.as_str())
    }

    /// Publishes one run's outputs (rename, then the row), unless the job was cancelled or taken
    /// over meanwhile.
    pub(super) async fn succeed(&self, job: &Job, s: &Summary) -> Result<(), Error> {
        let id = &job.id;
        if !self.still_mine(&self.get(id).await?) {
            self.remove_outputs(job);
            return Ok(());
        }
        let p = Paths::new(&self.spool, id, job.attempts);
        for (tmp, published) in [
            (&p.nc_tmp, &p.nc),
            (&p.blocks_tmp, &p.blocks),
            (&p.preview_tmp, &p.preview),
            (&p.lines_tmp, &p.lines),
        ] {
            // Asked again after the store did not answer: what this run renamed stays renamed.
            if !tokio::fs::try_exists(tmp).await? && tokio::fs::try_exists(published).await? {
                continue;
            }
            tokio::fs::rename(tmp, published).await?;
        }
        sync_dir(&self.spool)?;
        let nc_bytes = tokio::fs::metadata(&p.nc).await?.len();
        sqlx::query(
            "UPDATE jobs SET state = 'succeeded', finished_ms = $1, summary = $2, nc_bytes = $3
             WHERE id = $4 AND state = 'running' AND owner = $5",
        )
        .bind(now_ms())
        .bind(serde_json::to_string(s).unwrap_or_default())
        .bind(nc_bytes as i64)
        .bind(id)
        .bind(&self.node)
        .execute(&self.pool)
        .await?;
        Ok(())
    }

    /// A failed job keeps its diagnostics (ending with the error) and its preview (up to where it
    /// stopped), never its partial program.
    pub(super) async fn fail(&self, job: &Job, msg: &str) -> Result<(), Error> {
        let id = &job.id;
        if !self.still_mine(&self.get(id).await?) {
            self.remove_outputs(job);
            return Ok(());
        }
        let p = Paths::new(&self.spool, id, job.attempts);
        // The partial NC stays only as the text its diagnostics point into.
        let _ = tokio::fs::rename(&p.nc_tmp, &p.nc_partial).await;
        let _ = tokio::fs::remove_file(&p.lines_tmp).await;
        let _ = tokio::fs::rename(&p.blocks_tmp, &p.blocks).await;
        let _ = tokio::fs::rename(&p.preview_tmp, &p.preview).await;
        // Before the row says failed, so that its diagnostics are never read unclosed.
        let (diag, message) = (p.blocks.clone(), msg.to_string());
        match tokio::task::spawn_blocking(move || crate::spool::seal::close(&diag, &message)).await {
            Ok(Ok(())) => {}
            Ok(Err(e)) => tracing::warn!(job = %id, error = %e, "closing a failed job's diagnostics (served mended)"),
            Err(e) => tracing::warn!(job = %id, error = %e, "closing a failed job's diagnostics (served mended)"),
        }
        sqlx::query(
            "UPDATE jobs SET state = 'failed', finished_ms = $1, error = $2 WHERE id = $3 AND state = 'running' AND owner = $4",
        )
        .bind(now_ms())
        .bind(msg)
        .bind(id)
        .bind(&self.node)
        .execute(&self.pool)
        .await?;
        Ok(())
    }

    pub(super) async fn cancel(&self, id: &str) -> Result<Job, Error> {
        let n =
            sqlx::query("UPDATE jobs SET state = 'cancelled', finished_ms = $1 WHERE id = $2 AND state IN ('queued', 'running')")
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
        // Files first: on a full disk the row's delete needs the room they hold (a job that
        // failed filling the disk would otherwise pin it). A row left by a failed delete lists
        // a job with no outputs, and the next delete removes it.
        self.remove_files(id);
        sqlx::query("DELETE FROM jobs WHERE id = $1")
            .bind(id)
            .execute(&self.pool)
            .await?;
        Ok(())
    }

    /// One run's temporaries.
    pub(super) fn remove_outputs(&self, job: &Job) {
        let p = Paths::new(&self.spool, &job.id, job.attempts);
        for f in [&p.nc_tmp, &p.blocks_tmp, &p.preview_tmp, &p.lines_tmp] {
            let _ = std::fs::remove_file(f);
        }
    }

    /// Every file of a job: input, outputs, any run's temporaries.
    fn remove_files(&self, id: &str) {
        let prefix = format!("{id}.");
        if let Ok(dir) = std::fs::read_dir(&self.spool) {
            for e in dir.flatten() {
                if e.file_name().to_string_lossy().starts_with(&prefix) {
                    let _ = std::fs::remove_file(e.path());
                }
            }
        }
    }

    /// Removes jobs finished longer ago than `retention`, files first.
    pub(super) async fn expire(&self, retention: Duration) -> Result<u64, Error> {
        let cutoff = now_ms() - retention.as_millis().min(i64::MAX as u128) as i64;
        let ids: Vec<String> =
            sqlx::query_scalar("SELECT id FROM jobs WHERE state IN ('succeeded', 'failed', 'cancelled') AND finished_ms < $1")
                .bind(cutoff)
                .fetch_all(&self.pool)
                .await?;
        for id in &ids {
            self.remove_files(id);
            sqlx::query("DELETE FROM jobs WHERE id = $1")
                .bind(id)
                .execute(&self.pool)
                .await?;
        }
        Ok(ids.len() as u64)
    }

    /// A client's jobs still queued or running.
    pub async fn active_for(&self, client: &str) -> Result<u64, Error> {
        let n: i64 = sqlx::query_scalar("SELECT COUNT(*) FROM jobs WHERE client = $1 AND state IN ('queued', 'running')")
            .bind(client)
            .fetch_one(&self.pool)
            .await?;
        Ok(n.max(0) as u64)
    }

    /// Jobs by state, for `/metrics`.
    pub async fn counts(&self) -> Result<Vec<(JobState, u64)>, Error> {
        let rows = sqlx::query("SELECT state, COUNT(*) FROM jobs GROUP BY state")
            .fetch_all(&self.pool)
            .await?;
        let mut out = Vec::new();
        for r in rows {
            let st: String = r.try_get(0)?;
            let n: i64 = r.try_get(1)?;
            if let Some(st) = JobState::parse(&st) {
                out.push((st, n.max(0) as u64));
            }
        }
        Ok(out)
    }

    /// How a finished job's diagnostics are served: rebuilt from its block store, or its NDJSON
    /// file where a version before the store ran it; a failed job's end with its error record.
    pub async fn diagnostics(&self, job: &Job) -> Result<Diagnostics, Error> {
        let p = Paths::new(self.spool(), &job.id, 0);
        let failed = (job.state == JobState::Failed).then(|| job.error.clone().unwrap_or_else(|| "the job failed".into()));
        let read = tokio::task::spawn_blocking(move || crate::spool::seal::locate(p, failed));
        Ok(read.await.map_err(std::io::Error::other)??)
    }

    /// Where a finished job's output lives.
    pub fn output_path(&self, id: &str, o: Output) -> PathBuf {
        Paths::new(&self.spool, id, 0).output(o)
    }
}
