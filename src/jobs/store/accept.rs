//! Accepting a job: its input made durable in the spool, then its row committed, the queue's
//! limits counted in the same step. A job is acknowledged only once both exist. When the
//! database's answer is lost (the connection cut at commit), the insert, idempotent on the job id,
//! is asked again; the input is removed only once it is known that no row owns it. A job keeps
//! a digest of its request, so that its Idempotency-Key, given again with another request, is
//! refused rather than answered with a job that is not the one asked for.

use super::{Backend, Job, JobState, Store, now_ms};
use crate::spool::{Paths, sync_dir};
use crate::jobs::Error;
use super::JobSettings;
use sha2::{Digest, Sha256};
use std::time::Duration;
use tokio::io::{AsyncReadExt, AsyncWriteExt};

/// PostgreSQL: job inserts hold this transaction lock, so that the limits are counted and the
/// row inserted as one step across replicas, and so that an insert cut off at commit has ended,
/// one way or the other, before the next attempt asks whether its row is there.
const INSERT_LOCK: i64 = 7_311_000_002;

/// Pauses (ms) before each attempt at the insert, then before each read-only check.
const INSERTS: [u64; 3] = [0, 100, 400];
const CHECKS: [u64; 4] = [0, 200, 500, 1000];

/// One attempt may wait this long (a lock held by a cut-off attempt, a pool without connections).
const ATTEMPT: Duration = Duration::from_secs(5);

/// Who submits what, and the limits the insert keeps.
pub struct Submission {
    pub settings: JobSettings,
    pub machine_version: i64,
    pub client: Option<String>,
    pub filename: Option<String>,
    pub key: Option<String>,
    /// The options' half of the request's digest ([`options_digest`]).
    pub options: String,
    /// Jobs queued at most (the new one not counted).
    pub max_queued: u64,
    /// Jobs queued or running for one client at most; 0: no limit.
    pub max_per_client: u64,
}

/// Why an insert came back without an answer.
enum Failure {
    /// The database refused the statement: nothing was written.
    Refused(sqlx::Error),
    /// The answer was lost every time: the row may or may not be there.
    Unknown(String),
    /// The answer was lost every time, and asking afterwards found no row: nothing was written.
    Lost(String),
}

/// Whether a failed statement may still have taken effect: the connection went away (or the pool
/// had none to give) before the database answered.
fn outcome_unknown(e: &sqlx::Error) -> bool {
    match e {
        // Connection exceptions and the server shutting down.
        sqlx::Error::Database(d) => d.code().is_some_and(|c| c.starts_with("08") || c.starts_with("57P")),
        e => crate::db::connection_gone(e),
    }
}

/// The job row, limits checked in its `WHERE`: no row is inserted when the queue or the client is
/// at its limit, or the idempotency key is taken, or the id exists (an earlier attempt's row).
const INSERT: &str =
    "INSERT INTO jobs (id, state, machine, machine_version, settings, filename, idempotency_key, input_bytes, created_ms, client, request_digest)
    SELECT $1, 'queued', $2, $3, $4, $5, $6, $7, $8, $9, $12
    WHERE (SELECT COUNT(*) FROM jobs WHERE state = 'queued') < $10
      AND (SELECT COUNT(*) FROM jobs WHERE client = $9 AND state IN ('queued', 'running')) < $11
    ON CONFLICT DO NOTHING";

impl Store {
    /// Streams the input to the spool (fsynced, then renamed into place) and commits the job's
    /// row. Returns the job and `true`, or the job an idempotency key already named and `false`.
    pub(in crate::jobs) async fn insert(
        &self,
        s: Submission,
        input: impl tokio::io::AsyncRead + Unpin,
    ) -> Result<(Job, bool), Error> {
        let id = uuid::Uuid::new_v4().simple().to_string();
        let p = Paths::new(&self.spool, &id, 0);
        let (n, input_digest) = self.spool_input(&id, &p, input).await?;
        let machine = s.settings.post.machine.clone().unwrap_or_default();
        let job = Job {
            machine_version: Some(s.machine_version),
            settings: s.settings.clone(),
            filename: s.filename.clone(),
            idempotency_key: s.key.clone(),
            request_digest: Some(format!("{}:{input_digest}", s.options)),
            input_bytes: n,
            ..Job::new(id, JobState::Queued, machine, now_ms())
        };
        match self.commit_row(&job, &s).await {
            Ok(true) if tokio::fs::try_exists(&p.input).await.unwrap_or(false) => Ok((job, true)),
            Ok(true) => {
                // The input went (removed from outside): a job without it must not stay.
                let _ = sqlx::query("DELETE FROM jobs WHERE id = $1 AND state = 'queued'")
                    .bind(&job.id)
                    .execute(&self.pool)
                    .await;
                Err(Error::Unconfirmed(format!(
                    "the input of job {} is gone from the spool",
                    job.id
                )))
            }
            Ok(false) => {
                let _ = tokio::fs::remove_file(&p.input).await;
                // Two submissions with one key raced: the first one's job is the answer, if it was
                // the same request.
                if let Some(k) = &s.key
                    && let Some(j) = self.by_key(k).await?
                {
                    return same_request(j, &s.options, &input_digest).map(|j| (j, false));
                }
                Err(self.refusal(&s).await?)
            }
            Err(Failure::Refused(e)) => {
                let _ = tokio::fs::remove_file(&p.input).await;
                Err(if crate::db::disk_full(&e) {
                    Error::NoSpace(e.to_string())
                } else {
                    e.into()
                })
            }
            Err(Failure::Lost(why)) => {
                let _ = tokio::fs::remove_file(&p.input).await;
                Err(Error::Unconfirmed(why))
            }
            Err(Failure::Unknown(why)) => {
                tracing::warn!(job = %job.id, error = %why, "the job store did not answer; the input stays until it is known whether the row is there");
                let (pool, backend, input, id) = (self.pool.clone(), self.backend, p.input.clone(), job.id.clone());
                tokio::spawn(async move { settle(&pool, backend, &id, &input).await });
                Err(Error::Unconfirmed(why))
            }
        }
    }

    /// A submission whose key names `job`: that job, when the request is the one it was
    /// accepted with. Its input is read to the end for its digest (the upload's bounds hold),
    /// written nowhere.
    pub(in crate::jobs) async fn resubmitted(
        &self,
        job: Job,
        options: &str,
        input: impl tokio::io::AsyncRead + Unpin,
    ) -> Result<Job, Error> {
        if job.request_digest.is_none() {
            return Ok(job);
        }
        let (_, input_digest) = hashed_copy(input, &mut tokio::io::sink())
            .await
            .map_err(Error::Upload)?;
        same_request(job, options, &input_digest)
    }

    /// The upload, under a temporary name carrying this node (so that a sweep knows whose it
    /// is), fsynced and renamed to the job's input; its length and digest. A full disk is
    /// `NoSpace`: nothing accepted.
    async fn spool_input(&self, id: &str, p: &Paths, input: impl tokio::io::AsyncRead + Unpin) -> Result<(u64, String), Error> {
        let tmp = self.spool.join(super::sweep::upload_name(id, &self.node));
        let copied = async {
            let mut f = tokio::fs::File::create(&tmp).await?;
            let n = hashed_copy(input, &mut f).await?;
            f.flush().await?;
            f.sync_all().await?;
            Ok::<_, std::io::Error>(n)
        }
        .await;
        let n = match copied {
            Ok(n) => n,
            Err(e) => {
                let _ = tokio::fs::remove_file(&tmp).await;
                if e.kind() == std::io::ErrorKind::StorageFull || e.kind() == std::io::ErrorKind::QuotaExceeded {
                    return Err(Error::NoSpace(e.to_string()));
                }
                return Err(Error::Upload(e));
            }
        };
        tokio::fs::rename(&tmp, &p.input).await?;
        sync_dir(&self.spool)?;
        Ok(n)
    }

    /// Inserts the row, asking again where an answer was lost: `true` when the row is there
    /// (inserted now or by an attempt whose answer was lost), `false` when the insert refused it
    /// (a limit, or the key taken); `Lost` when the answers were lost and no row is there.
    async fn commit_row(&self, job: &Job, s: &Submission) -> Result<bool, Failure> {
        let mut why = String::new();
        for pause in INSERTS {
            tokio::time::sleep(Duration::from_millis(pause)).await;
            match tokio::time::timeout(ATTEMPT, self.insert_once(job, s)).await {
                Ok(Ok(there)) => return Ok(there),
                Ok(Err(e)) if !outcome_unknown(&e) => return Err(Failure::Refused(e)),
                Ok(Err(e)) => why = e.to_string(),
                Err(_) => why = format!("no answer in {ATTEMPT:?}"),
            }
        }
        // Writing keeps failing: find out, without writing, whether one of the attempts landed.
        for pause in CHECKS {
            tokio::time::sleep(Duration::from_millis(pause)).await;
            match tokio::time::timeout(ATTEMPT, row_there(&self.pool, self.backend, &job.id)).await {
                Ok(Ok(true)) => return Ok(true),
                Ok(Ok(false)) => return Err(Failure::Lost(why)),
                _ => {}
            }
        }
        Err(Failure::Unknown(why))
    }

    /// One attempt: the conditional insert and, when it inserted nothing, whether the id is
    /// there (PostgreSQL: both under the insert lock, in one transaction).
    async fn insert_once(&self, job: &Job, s: &Submission) -> Result<bool, sqlx::Error> {
        let per_client = match (&s.client, s.max_per_client) {
            (Some(_), n) if n > 0 => n.min(i64::MAX as u64) as i64,
            _ => i64::MAX,
        };
        let insert = sqlx::query(INSERT)
            .bind(&job.id)
            .bind(&job.machine)
            .bind(job.machine_version)
            .bind(serde_json::to_string(&job.settings).unwrap_or_default())
            .bind(&job.filename)
            .bind(&job.idempotency_key)
            .bind(job.input_bytes.min(i64::MAX as u64) as i64)
            .bind(job.created_ms)
            .bind(&s.client)
            .bind(s.max_queued.min(i64::MAX as u64) as i64)
            .bind(per_client)
            .bind(&job.request_digest);
        let exists = sqlx::query_scalar::<_, i64>("SELECT COUNT(*) FROM jobs WHERE id = $1").bind(&job.id);
        match self.backend {
            Backend::Sqlite => {
                // One statement: SQLite runs one writer at a time, counts included.
                if insert.execute(&self.pool).await?.rows_affected() == 1 {
                    return Ok(true);
                }
                Ok(exists.fetch_one(&self.pool).await? > 0)
            }
            Backend::Postgres => {
                let mut tx = self.pool.begin().await?;
                sqlx::query("SELECT pg_advisory_xact_lock($1)")
                    .bind(INSERT_LOCK)
                    .execute(&mut *tx)
                    .await?;
                let there = insert.execute(&mut *tx).await?.rows_affected() == 1 || exists.fetch_one(&mut *tx).await? > 0;
                tx.commit().await?;
                Ok(there)
            }
        }
    }

    /// Why a row was not inserted (its key was not taken): the full queue or the client's limit.
    /// Counted again after the refusal, so a job may have ended since: with room in the queue it
    /// was the client's limit, whatever the client's count is now.
    async fn refusal(&self, s: &Submission) -> Result<Error, Error> {
        let waiting = self.count(JobState::Queued).await?;
        if let Some(c) = &s.client
            && s.max_per_client > 0
            && waiting < s.max_queued
        {
            let active = self.active_for(c).await?;
            return Ok(Error::ClientLimit {
                client: c.clone(),
                active: active.max(s.max_per_client),
            });
        }
        Ok(Error::Full(waiting.max(s.max_queued)))
    }
}

/// The options of a request as the client gave them, hashed: the machine, the options, its own
/// tool table, the dialect it named; not what the service resolved (the versions of the tool
/// table and the dialect, the threads), so that the same request asked again after a profile or
/// table was written is still the same request. Canonical: keys sorted, absent options left out
/// (an option a later version adds does not change the digest of a request without it).
pub fn options_digest(settings: &JobSettings) -> String {
    let given: std::collections::BTreeMap<String, serde_json::Value> = match serde_json::to_value(settings) {
        Ok(serde_json::Value::Object(o)) => o
            .into_iter()
            .filter(|(k, v)| !v.is_null() && !matches!(k.as_str(), "machine_tools_version" | "dialect_version" | "threads"))
            .collect(),
        _ => Default::default(),
    };
    hex(&Sha256::digest(serde_json::to_string(&given).unwrap_or_default()))
}

/// `job`, when it was accepted with this request (`<options>:<input>`, as [`Store::insert`]
/// keeps it), else the refusal saying what differs.
fn same_request(job: Job, options: &str, input: &str) -> Result<Job, Error> {
    let Some((o, i)) = job.request_digest.as_deref().and_then(|d| d.split_once(':')) else {
        return Ok(job);
    };
    let what = match (o == options, i == input) {
        (true, true) => return Ok(job),
        (true, false) => "another CL input",
        (false, true) => "other options (machine, settings, tool table or dialect)",
        (false, false) => "another CL input and other options",
    };
    Err(Error::KeyReused {
        key: job.idempotency_key.unwrap_or_default(),
        job: job.id,
        what,
    })
}

/// Copies `input` to `out`: the bytes copied and their SHA-256.
async fn hashed_copy(
    mut input: impl tokio::io::AsyncRead + Unpin,
    out: &mut (impl tokio::io::AsyncWrite + Unpin),
) -> std::io::Result<(u64, String)> {
    let (mut hash, mut n) = (Sha256::new(), 0u64);
    let mut buf = vec![0u8; 64 << 10];
    loop {
        let got = input.read(&mut buf).await?;
        if got == 0 {
            return Ok((n, hex(&hash.finalize())));
        }
        hash.update(&buf[..got]);
        out.write_all(&buf[..got]).await?;
        n += got as u64;
    }
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// Whether a job's row is there, asked so that an insert cut off at commit has ended first
/// (PostgreSQL: under the insert lock).
async fn row_there(pool: &sqlx::AnyPool, backend: Backend, id: &str) -> Result<bool, sqlx::Error> {
    let q = sqlx::query_scalar::<_, i64>("SELECT COUNT(*) FROM jobs WHERE id = $1").bind(id);
    match backend {
        Backend::Sqlite => Ok(q.fetch_one(pool).await? > 0),
        Backend::Postgres => {
            let mut tx = pool.begin().await?;
            sqlx::query("SELECT pg_advisory_xact_lock($1)")
                .bind(INSERT_LOCK)
                .execute(&mut *tx)
                .await?;
            let n = q.fetch_one(&mut *tx).await?;
            tx.commit().await?;
            Ok(n > 0)
        }
    }
}

/// After a 503 whose insert may have landed: once the database answers, the input goes if no row
/// owns it. A row that is there keeps it (a client repeating its key gets that job).
async fn settle(pool: &sqlx::AnyPool, backend: Backend, id: &str, input: &std::path::Path) {
    for _ in 0..600 {
        match tokio::time::timeout(ATTEMPT, row_there(pool, backend, id)).await {
            Ok(Ok(false)) => {
                let _ = tokio::fs::remove_file(input).await;
                return;
            }
            Ok(Ok(true)) => {
                tracing::warn!(job = %id, "a job answered 503 was stored after all: it runs");
                return;
            }
            _ => tokio::time::sleep(Duration::from_secs(1)).await,
        }
    }
    tracing::error!(job = %id, "the job store never answered; the spool sweep removes the input if no row owns it");
}
