//! `/v1/jobs`: the job queue's edge. A large CL file is handed over (202 once it is on disk),
//! run in the background, and fetched when it is done.

use super::AppState;
use super::download::{if_range, pumped};
use super::error::{ApiError, ApiQuery};
use super::post::nc_attachment;
use super::refusals::{NotFound, QueueBusy, TooManyDownloads, UploadRefusals};
use super::upload::ClUpload;
use crate::jobs::{self, Job, JobSettings, JobState, Queue};
use crate::post::Settings;
use crate::spool::seal::Diagnostics;
use crate::spool::{Output, lines::LineIndex};
use axum::Json;
use axum::body::Body;
use axum::extract::{Path, Request, State};
use axum::http::{HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use futures_util::StreamExt;
use serde::{Deserialize, Serialize};
use std::sync::Arc;
use tokio_util::io::StreamReader;
use tower::ServiceExt;

/// A job as the API shows it. Times are RFC 3339-free Unix milliseconds, durations seconds.
#[derive(Serialize, utoipa::ToSchema)]
pub struct JobView {
    pub id: String,
    /// `queued`, `running`, `succeeded`, `failed` or `cancelled`.
    pub state: String,
    pub machine: String,
    /// The profile version the job runs with (see `GET /v1/machines/{id}/versions`).
    pub machine_version: Option<i64>,
    /// The version of the machine's tool table the job runs with (`GET
    /// /v1/machines/{id}/tools/versions`); absent when the machine had none or the job brought
    /// its own (`own_tool_table`).
    pub tool_table_version: Option<i64>,
    /// The version of the dialect the job is written in (the one it named, else the profile's
    /// controller), as it was when the job was accepted.
    pub dialect_version: Option<i64>,
    /// The job brought its own `tool_table`.
    pub own_tool_table: bool,
    pub filename: Option<String>,
    pub idempotency_key: Option<String>,
    pub created_ms: i64,
    pub started_ms: Option<i64>,
    pub finished_ms: Option<i64>,
    /// Runs started; more than one: a run was cut off (its replica stopped) or a fault outside
    /// the job ended it (the spool full or failing, the database not answering), and the job ran
    /// again from the start, after a backoff. At most the service's `--job-max-attempts`.
    pub attempts: i64,
    /// Why the last run that did not end went back to the queue, when one did.
    pub last_cause: Option<String>,
    /// A job queued again after such a run: not run before this time (Unix ms).
    pub retry_after_ms: Option<i64>,
    /// The node (replica) that runs or ran it.
    pub node: Option<String>,
    pub progress: JobProgress,
    /// The settings the job was posted with, as they were given (the form's and the API's
    /// names: `mode`, `dialect`, `cycles` …), its own tool table aside: what a link to the job
    /// shows, and what posting again with them repeats.
    #[schema(value_type = Object)]
    pub settings: serde_json::Value,
    /// The engine's summary, when the job succeeded.
    #[schema(value_type = Option<Object>)]
    pub summary: Option<serde_json::Value>,
    pub error: Option<String>,
    /// Where the NC program and the diagnostics are, when there are any.
    pub links: JobLinks,
}

#[derive(Serialize, utoipa::ToSchema)]
pub struct JobProgress {
    pub input_bytes: u64,
    pub bytes_read: u64,
    /// NC motion blocks written so far (the summary's `blocks` once finished).
    pub blocks: u64,
    /// Of the input read (100 when finished successfully).
    pub percent: f64,
    pub nc_bytes: Option<u64>,
}

#[derive(Serialize, utoipa::ToSchema)]
pub struct JobLinks {
    #[serde(rename = "self")]
    pub this: String,
    pub nc: Option<String>,
    pub diagnostics: Option<String>,
    pub preview: Option<String>,
    /// The CL data as uploaded.
    pub input: String,
    /// The NC program's line map (offsets, CL lines, flags), when it has succeeded.
    pub lines: Option<String>,
}

impl From<Job> for JobView {
    fn from(j: Job) -> Self {
        let percent = if j.state == JobState::Succeeded {
            100.0
        } else if j.input_bytes > 0 {
            (j.bytes_read as f64 / j.input_bytes as f64 * 100.0).min(100.0)
        } else {
            0.0
        };
        let base = format!("/v1/jobs/{}", j.id);
        let mut settings = serde_json::to_value(&j.settings).unwrap_or_default();
        if let Some(o) = settings.as_object_mut() {
            o.retain(|k, v| !v.is_null() && !matches!(k.as_str(), "tool_table" | "machine_tools_version" | "dialect_version"));
        }
        JobView {
            settings,
            links: JobLinks {
                nc: (j.state == JobState::Succeeded).then(|| format!("{base}/nc")),
                lines: (j.state == JobState::Succeeded).then(|| format!("{base}/lines")),
                input: format!("{base}/input"),
                diagnostics: matches!(j.state, JobState::Succeeded | JobState::Failed).then(|| format!("{base}/diagnostics")),
                preview: matches!(j.state, JobState::Succeeded | JobState::Failed).then(|| format!("{base}/preview")),
                this: base,
            },
            id: j.id,
            state: j.state.as_str().to_string(),
            machine: j.machine,
            machine_version: j.machine_version,
            tool_table_version: j.settings.machine_tools_version,
            dialect_version: j.settings.dialect_version,
            own_tool_table: j.settings.post.tool_table.is_some(),
            filename: j.filename,
            idempotency_key: j.idempotency_key,
            created_ms: j.created_ms,
            started_ms: j.started_ms,
            finished_ms: j.finished_ms,
            attempts: j.attempts,
            last_cause: j.cause,
            retry_after_ms: j.not_before_ms.filter(|_| j.state == JobState::Queued),
            node: j.owner,
            progress: JobProgress {
                input_bytes: j.input_bytes,
                bytes_read: j.bytes_read,
                blocks: j.blocks,
                percent,
                nc_bytes: j.nc_bytes,
            },
            summary: j.summary,
            error: j.error,
        }
    }
}

#[derive(Serialize, utoipa::ToSchema)]
pub struct JobList {
    pub jobs: Vec<JobView>,
    /// Pass as `offset` for the next page; absent on the last page.
    pub next_offset: Option<u64>,
}

#[derive(Deserialize, utoipa::IntoParams)]
#[serde(deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct ListParams {
    /// Only jobs in this state.
    pub state: Option<String>,
    /// Page size, 1–500 (default 50).
    pub limit: Option<u32>,
    pub offset: Option<u64>,
}

fn queue(st: &AppState) -> Result<&Arc<Queue>, ApiError> {
    st.jobs
        .as_ref()
        .ok_or_else(|| ApiError::Busy("the job queue is not running in this process".into()))
}

impl From<jobs::Error> for ApiError {
    fn from(e: jobs::Error) -> Self {
        match e {
            jobs::Error::NotFound(id) => ApiError::NotFound(format!("no job {id}")),
            jobs::Error::Full(n) => ApiError::Busy(format!("the job queue is full ({n} jobs waiting)")),
            e @ jobs::Error::Unconfirmed(_) => ApiError::Busy(e.to_string()),
            e @ jobs::Error::ClientLimit { .. } => ApiError::TooManyRequests(e.to_string()),
            e @ jobs::Error::KeyReused { .. } => ApiError::KeyReused(e.to_string()),
            jobs::Error::WrongState { id, state } => ApiError::Conflict(format!("job {id} is {state}")),
            jobs::Error::Upload(e) => super::limits::upload_error(Some(&e), &e),
            e @ jobs::Error::NoSpace(_) => ApiError::InsufficientStorage(e.to_string()),
            jobs::Error::Machines(m) => m.into(),
            // The database restarting, a lost connection, a pool without one to give: not now.
            e if e.not_now() => ApiError::Busy(format!("the job store is not answering now, retry: {e}")),
            e @ (jobs::Error::Db(_) | jobs::Error::Io(_) | jobs::Error::Corrupt(_) | jobs::Error::Open { .. }) => {
                ApiError::Internal(e.to_string())
            }
        }
    }
}

fn job_id(id: &str) -> Result<&str, ApiError> {
    if id.len() == 32 && id.bytes().all(|b| b.is_ascii_hexdigit()) {
        Ok(id)
    } else {
        Err(ApiError::NotFound(format!("no job {}", crate::text::quote(id))))
    }
}

/// Submit CL data as a job: the same inputs as `POST /v1/post`. Answers once the input is on disk.
#[utoipa::path(
    post,
    path = "/v1/jobs",
    params(Settings, ("Idempotency-Key" = Option<String>, Header, description = "1–200 characters; the same key with the same request (CL input, machine, options) returns the same job, with another request it is refused (422)")),
    request_body(content = String, description = "CL data (APT/CLSF text), raw or as the `file` part of multipart/form-data", content_type = "text/plain"),
    responses(
        (status = 202, description = "Accepted: on disk, queued", body = JobView),
        UploadRefusals,
        (status = 422, description = "The Idempotency-Key is another request's: a job was accepted with it for another CL input, machine or options (type `idempotency-key-reused`)", body = super::error::Problem, content_type = "application/problem+json"),
        (status = 429, description = "This client has its limit of jobs queued or running (Retry-After)", body = super::error::Problem, content_type = "application/problem+json"),
        (status = 507, description = "The spool's disk is full: not accepted (Retry-After)", body = super::error::Problem, content_type = "application/problem+json"),
        (status = 503, description = "Queue full, or the job store not answering now: a database restarting, a lost connection (Retry-After)", body = super::error::Problem, content_type = "application/problem+json"),
    ),
    tag = "jobs"
)]
pub async fn submit(
    State(st): State<Arc<AppState>>,
    headers: axum::http::HeaderMap,
    peer: Option<axum::Extension<axum::extract::ConnectInfo<std::net::SocketAddr>>>,
    ClUpload { params, filename, body }: ClUpload,
) -> Result<Response, ApiError> {
    let q = queue(&st)?.clone();
    let key = headers
        .get("idempotency-key")
        .map(|v| v.to_str().map(str::to_string))
        .transpose()
        .map_err(|_| ApiError::BadParameter("Idempotency-Key: expected visible ASCII".into()))?;
    if key.as_ref().is_some_and(|k| k.is_empty() || k.len() > 200) {
        return Err(ApiError::BadParameter("Idempotency-Key: 1 to 200 characters".into()));
    }
    // The peer address: behind a proxy every client is the proxy (set the limit accordingly).
    let client = peer.map(|c| c.0.0.ip().to_string());
    // Settings are checked now, so a job never fails for a typo hours later.
    let checked = super::post::profile(&st, &params).and_then(|current| {
        super::post::options_on(&st, &params, &current)?;
        let mut settings = JobSettings::default();
        if params.tool_table.is_none() {
            // The machine's table as it is now, whatever is written to it before the job runs.
            settings.machine_tools_version = st.machines.tools.get(&current.id).ok().map(|c| c.version);
        }
        let dialect = params.dialect.clone().unwrap_or_else(|| current.item.machine.controller.clone());
        settings.dialect_version = st.machines.dialects.get(&dialect).ok().map(|c| c.version);
        settings.post = params;
        Ok((current, settings))
    });
    let ((current, settings), body) = super::post::refuse_unread(checked, body).await?;
    let input = StreamReader::new(body.into_data_stream().map(|r| r.map_err(std::io::Error::other)));
    let (job, _created) = q.submit(settings, current.version, filename, key, client, input).await?;
    let location = format!("/v1/jobs/{}", job.id);
    let mut resp = (StatusCode::ACCEPTED, Json(JobView::from(job))).into_response();
    if let Ok(v) = HeaderValue::from_str(&location) {
        resp.headers_mut().insert(header::LOCATION, v);
    }
    Ok(resp)
}

/// A job: state, progress, timings, and the summary once done.
#[utoipa::path(get, path = "/v1/jobs/{id}", params(("id" = String, Path)),
    responses((status = 200, description = "Success", body = JobView), NotFound,
        QueueBusy),
    tag = "jobs")]
pub async fn get_job(State(st): State<Arc<AppState>>, Path(id): Path<String>) -> Result<Json<JobView>, ApiError> {
    Ok(Json(queue(&st)?.store.get(job_id(&id)?).await?.into()))
}

/// Jobs, newest first, a page at a time.
#[utoipa::path(get, path = "/v1/jobs", params(ListParams),
    responses((status = 200, description = "Success", body = JobList), (status = 400, description = "A parameter is malformed: the problem document names it", body = super::error::Problem, content_type = "application/problem+json"),
        QueueBusy),
    tag = "jobs")]
pub async fn list_jobs(State(st): State<Arc<AppState>>, ApiQuery(p): ApiQuery<ListParams>) -> Result<Json<JobList>, ApiError> {
    let state = match p.state.as_deref() {
        None | Some("") => None,
        Some(s) => Some(JobState::parse(s).ok_or_else(|| {
            ApiError::BadParameter(format!(
                "state: expected queued, running, succeeded, failed or cancelled, got {}",
                crate::text::quote(s)
            ))
        })?),
    };
    let limit = p.limit.unwrap_or(50);
    if !(1..=500).contains(&limit) {
        return Err(ApiError::BadParameter("limit: 1 to 500".into()));
    }
    let offset = p.offset.unwrap_or(0);
    let jobs = queue(&st)?.store.list(state, limit + 1, offset).await?;
    let more = jobs.len() > limit as usize;
    Ok(Json(JobList {
        jobs: jobs.into_iter().take(limit as usize).map(JobView::from).collect(),
        next_offset: more.then(|| offset + limit as u64),
    }))
}

/// Cancels a queued or running job; removes a finished one and its files.
#[utoipa::path(delete, path = "/v1/jobs/{id}", params(("id" = String, Path)),
    responses((status = 200, description = "Cancelled", body = JobView), (status = 204, description = "Finished job removed"),
        NotFound,
        QueueBusy),
    tag = "jobs")]
pub async fn delete_job(State(st): State<Arc<AppState>>, Path(id): Path<String>) -> Result<Response, ApiError> {
    let q = queue(&st)?;
    let id = job_id(&id)?;
    match q.cancel(id).await {
        Ok(j) => Ok(Json(JobView::from(j)).into_response()),
        Err(jobs::Error::WrongState { .. }) => {
            q.store.delete(id).await?;
            Ok(StatusCode::NO_CONTENT.into_response())
        }
        Err(e) => Err(e.into()),
    }
}

/// The NC program of a succeeded job (Range requests, ETag).
#[utoipa::path(get, path = "/v1/jobs/{id}/nc", params(("id" = String, Path)),
    responses((status = 200, description = "The NC program", content_type = "text/plain"),
        (status = 206, description = "Part of it (Range)", content_type = "text/plain"),
        (status = 304, description = "Not modified (If-None-Match)"),
        NotFound,
        (status = 409, description = "Not finished, or failed", body = super::error::Problem, content_type = "application/problem+json"),
        (status = 416, description = "Range not satisfiable"),
        QueueBusy, TooManyDownloads),
    tag = "jobs")]
pub async fn job_nc(st: State<Arc<AppState>>, Path(id): Path<String>, req: Request) -> Result<Response, ApiError> {
    output(st, id, Output::Nc, req).await
}

/// The NDJSON diagnostics of a finished job: blocks, diagnostics, then the summary or the error.
/// The same bytes as `kinepost post --diagnostics` writes for the same CL and options (a failed
/// job's end with its error record), rebuilt from the job's compact store as they stream: a
/// Range gets the whole (200, `Accept-Ranges: none`), except for a job run by a version before
/// that store, whose NDJSON file is served as it is.
#[utoipa::path(get, path = "/v1/jobs/{id}/diagnostics", params(("id" = String, Path)),
    responses((status = 200, description = "One JSON object per line", content_type = "application/x-ndjson"),
        (status = 206, description = "Part of it (Range; only a job run before the compact store)", content_type = "application/x-ndjson"),
        (status = 304, description = "Not modified (If-None-Match)"),
        NotFound,
        (status = 409, description = "Not finished", body = super::error::Problem, content_type = "application/problem+json"),
        (status = 416, description = "Range not satisfiable"),
        QueueBusy, TooManyDownloads),
    tag = "jobs")]
pub async fn job_diagnostics(st: State<Arc<AppState>>, Path(id): Path<String>, req: Request) -> Result<Response, ApiError> {
    output(st, id, Output::Diagnostics, req).await
}

/// A decimated picture of a finished job for display: the path (tool tip and axis, rapid or
/// feed), every axis word against block number and time with the profile's limits, and every
/// block with a warning, an error, an unwind or a branch change, quoting its NC and CL lines.
/// At most 10 000 points (every `stride`-th block, plus the first, the last and each change
/// between rapid and feed) and 5 000 marks.
#[utoipa::path(get, path = "/v1/jobs/{id}/preview", params(("id" = String, Path)),
    responses((status = 200, description = "The preview", body = crate::output::preview::Preview),
        (status = 304, description = "Not modified (If-None-Match)"),
        (status = 404, description = "No such job, or a job finished before previews existed", body = super::error::Problem, content_type = "application/problem+json"),
        (status = 409, description = "Not finished", body = super::error::Problem, content_type = "application/problem+json"),
        QueueBusy),
    tag = "jobs")]
pub async fn job_preview(st: State<Arc<AppState>>, Path(id): Path<String>, req: Request) -> Result<Response, ApiError> {
    output(st, id, Output::Preview, req).await
}

/// The CL data the job was posted with, as it was uploaded (Range requests, ETag): what a viewer
/// shows beside the NC. Every job has it until it is removed.
#[utoipa::path(get, path = "/v1/jobs/{id}/input", params(("id" = String, Path)),
    responses((status = 200, description = "The CL data", content_type = "text/plain"),
        (status = 206, description = "Part of it (Range)", content_type = "text/plain"),
        (status = 304, description = "Not modified (If-None-Match)"),
        NotFound,
        (status = 416, description = "Range not satisfiable"),
        QueueBusy, TooManyDownloads),
    tag = "jobs")]
pub async fn job_input(st: State<Arc<AppState>>, Path(id): Path<String>, req: Request) -> Result<Response, ApiError> {
    output(st, id, Output::Input, req).await
}

/// The line map of a succeeded job's NC program (Range requests, ETag): 16 bytes per NC line,
/// four little-endian unsigned 32-bit integers — the line's byte offset in the NC (low 32 bits,
/// then high), the CL line it came from (0: none), and flags (1 error, 2 warning, 4 unwind,
/// 8 branch change, 16 tool change). A viewer reads any line of the NC by its offsets with a
/// Range request and links it to its CL line (`…/input`).
#[utoipa::path(get, path = "/v1/jobs/{id}/lines", params(("id" = String, Path)),
    responses((status = 200, description = "The line map", content_type = "application/octet-stream"),
        (status = 206, description = "Part of it (Range)", content_type = "application/octet-stream"),
        (status = 304, description = "Not modified (If-None-Match)"),
        (status = 404, description = "No such job, or a job finished before line maps existed", body = super::error::Problem, content_type = "application/problem+json"),
        (status = 409, description = "Not finished, or failed", body = super::error::Problem, content_type = "application/problem+json"),
        (status = 416, description = "Range not satisfiable"),
        QueueBusy, TooManyDownloads),
    tag = "jobs")]
pub async fn job_lines(st: State<Arc<AppState>>, Path(id): Path<String>, req: Request) -> Result<Response, ApiError> {
    output(st, id, Output::Lines, req).await
}

async fn output(State(st): State<Arc<AppState>>, id: String, what: Output, req: Request) -> Result<Response, ApiError> {
    let q = queue(&st)?;
    let job = q.store.get(job_id(&id)?).await?;
    let name = match what {
        Output::Nc => "the NC program",
        Output::Diagnostics => "diagnostics",
        Output::Preview => "a preview",
        Output::Lines => "a line map",
        Output::Input => "its input",
    };
    let only_succeeded = matches!(what, Output::Nc | Output::Lines);
    let ready = match job.state {
        _ if what == Output::Input => true,
        JobState::Succeeded => true,
        JobState::Failed => !only_succeeded,
        _ => false,
    };
    if !ready {
        return Err(ApiError::Conflict(format!(
            "job {} is {}: {name} only when it has {}",
            job.id,
            job.state,
            if only_succeeded { "succeeded" } else { "finished" }
        )));
    }
    if what == Output::Diagnostics {
        return diagnostics(q, &job, req).await;
    }
    let path = q.store.output_path(&job.id, what);
    if what == Output::Lines
        && let Some((store, modified)) = compact_lines(&path).await?
    {
        return super::lines::serve(&job, store, modified, req).await;
    }
    serve_file(&job, &path, what, req).await
}

/// A line map stored compactly, and when it was written; `None`: a file of the fixed-size
/// entries (a job run before the compact store), or none at all (served as files are).
async fn compact_lines(path: &std::path::Path) -> Result<Option<(LineIndex, Option<std::time::SystemTime>)>, ApiError> {
    let path = path.to_path_buf();
    let opened = tokio::task::spawn_blocking(move || -> std::io::Result<_> {
        let modified = std::fs::metadata(&path)?.modified().ok();
        Ok(LineIndex::open(&path)?.map(|s| (s, modified)))
    });
    match opened.await.map_err(|e| ApiError::Internal(e.to_string()))? {
        Ok(found) => Ok(found),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
        Err(e) => Err(ApiError::Internal(format!("job line map: {e}"))),
    }
}

/// A finished job's diagnostics: rebuilt from its block store as they stream, or the NDJSON
/// file of a job run before the store (mended where a failed job's does not end with its error).
async fn diagnostics(q: &Queue, job: &Job, req: Request) -> Result<Response, ApiError> {
    match q.store.diagnostics(job).await? {
        Diagnostics::Whole(path) => serve_file(job, &path, Output::Diagnostics, req).await,
        Diagnostics::Mended { path, keep, tail } => mended(&path, keep, tail).await,
        Diagnostics::Rebuilt { store, nc, end, len } => {
            // The store never changes once the job has finished: its length is a validator.
            let etag = format!("\"{}-b-{len}\"", job.id);
            if let Some(r) = super::not_modified(req.headers(), &etag) {
                return Ok(r);
            }
            let reader = tokio::task::spawn_blocking(move || crate::spool::blocks::rebuild(&store, &nc, end))
                .await
                .map_err(|e| ApiError::Internal(e.to_string()))?
                .map_err(|e| ApiError::Internal(format!("job diagnostics: {e}")))?;
            let mut resp = Response::new(pumped(reader));
            let h = resp.headers_mut();
            h.insert(header::ETAG, HeaderValue::from_str(&etag).expect("ascii etag"));
            h.insert(header::CONTENT_TYPE, HeaderValue::from_static("application/x-ndjson"));
            // Made as it streams, its length unknown: a Range gets the whole (200).
            h.insert(header::ACCEPT_RANGES, HeaderValue::from_static("none"));
            Ok(resp)
        }
    }
}

/// A published output file (Range with If-Range, ETag).
async fn serve_file(job: &Job, path: &std::path::Path, what: Output, req: Request) -> Result<Response, ApiError> {
    let (tag, ctype) = match what {
        Output::Nc => ("n", "text/plain; charset=utf-8"),
        Output::Diagnostics => ("d", "application/x-ndjson"),
        Output::Preview => ("p", "application/json"),
        Output::Lines => ("l", "application/octet-stream"),
        Output::Input => ("i", "text/plain"),
    };
    let (len, modified) = match tokio::fs::metadata(path).await {
        Ok(m) => (m.len(), m.modified().ok()),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound && what != Output::Nc && what != Output::Diagnostics => {
            let why = match what {
                Output::Preview => "no preview (it finished before previews were made)",
                Output::Lines => "no line map (it finished before line maps were made)",
                _ => "no input left",
            };
            return Err(ApiError::NotFound(format!("job {} has {why}", job.id)));
        }
        Err(e) => return Err(ApiError::Internal(format!("job output: {e}"))),
    };
    // Outputs never change once published: id, kind and length make a strong validator.
    let etag = format!("\"{}-{tag}-{len}\"", job.id);
    if let Some(r) = super::not_modified(req.headers(), &etag) {
        return Ok(r);
    }
    let req = if_range(req, &etag, modified);
    let mut resp = tower_http::services::ServeFile::new(path)
        .oneshot(req)
        .await
        .map_err(|e| ApiError::Internal(e.to_string()))?
        .map(Body::new);
    let h = resp.headers_mut();
    h.insert(header::ETAG, HeaderValue::from_str(&etag).expect("ascii etag"));
    h.insert(header::CONTENT_TYPE, HeaderValue::from_static(ctype));
    if what == Output::Nc {
        h.insert(header::CONTENT_DISPOSITION, nc_attachment(job.filename.as_deref(), &job.id));
    }
    Ok(resp)
}

/// A failed job's diagnostics whose file does not end with the error record: its complete lines,
/// then the record, whole (no ranges: this body is made, not a file).
async fn mended(path: &std::path::Path, keep: u64, tail: Vec<u8>) -> Result<Response, ApiError> {
    use tokio::io::AsyncReadExt;
    let body = if keep == 0 {
        Body::from(tail)
    } else {
        let f = tokio::fs::File::open(path)
            .await
            .map_err(|e| ApiError::Internal(format!("job output: {e}")))?;
        Body::from_stream(tokio_util::io::ReaderStream::new(
            f.take(keep).chain(std::io::Cursor::new(tail)),
        ))
    };
    Ok(([(header::CONTENT_TYPE, "application/x-ndjson")], body).into_response())
}
