//! `/v1/jobs`: the job queue's edge. A large CL file is handed over (202 once it is on disk),
//! run in the background, and fetched when it is done.

use super::AppState;
use super::error::{ApiError, ApiQuery};
use super::post::{PostParams, nc_attachment, upload, upload_error};
use crate::jobs::{self, Job, Queue, State as JobState};
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
    pub filename: Option<String>,
    pub idempotency_key: Option<String>,
    pub created_ms: i64,
    pub started_ms: Option<i64>,
    pub finished_ms: Option<i64>,
    /// Runs started; more than one: a restart cut a run off and it ran again from the start.
    pub attempts: i64,
    pub progress: JobProgress,
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
        JobView {
            links: JobLinks {
                nc: (j.state == JobState::Succeeded).then(|| format!("{base}/nc")),
                diagnostics: matches!(j.state, JobState::Succeeded | JobState::Failed)
                    .then(|| format!("{base}/diagnostics")),
                this: base,
            },
            id: j.id,
            state: j.state.as_str().to_string(),
            machine: j.machine,
            filename: j.filename,
            idempotency_key: j.idempotency_key,
            created_ms: j.created_ms,
            started_ms: j.started_ms,
            finished_ms: j.finished_ms,
            attempts: j.attempts,
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
            jobs::Error::WrongState { id, state } => ApiError::Conflict(format!("job {id} is {state}")),
            jobs::Error::Upload(m) => upload_error(m),
            e @ (jobs::Error::Db(_) | jobs::Error::Io(_) | jobs::Error::Corrupt(_)) => ApiError::Internal(e.to_string()),
        }
    }
}

fn job_id(id: &str) -> Result<&str, ApiError> {
    if id.len() == 32 && id.bytes().all(|b| b.is_ascii_hexdigit()) {
        Ok(id)
    } else {
        Err(ApiError::NotFound(format!("no job {id}")))
    }
}

/// Submit CL data as a job: the same inputs as `POST /v1/post`. Answers once the input is on disk.
/// An `Idempotency-Key` header (1–200 characters) returns the same job for the same key.
#[utoipa::path(
    post,
    path = "/v1/jobs",
    params(PostParams),
    request_body(content = String, description = "CL data (APT/CLSF text), raw or as the `file` part of multipart/form-data", content_type = "text/plain"),
    responses(
        (status = 202, description = "Accepted: on disk, queued", body = JobView),
        (status = 400, description = "Bad parameter", body = super::error::Problem, content_type = "application/problem+json"),
        (status = 404, description = "Unknown machine", body = super::error::Problem, content_type = "application/problem+json"),
        (status = 413, description = "Upload too large", body = super::error::Problem, content_type = "application/problem+json"),
        (status = 415, description = "Unsupported media type", body = super::error::Problem, content_type = "application/problem+json"),
        (status = 503, description = "Queue full (Retry-After)", body = super::error::Problem, content_type = "application/problem+json"),
    ),
    tag = "jobs"
)]
pub async fn submit(
    State(st): State<Arc<AppState>>,
    ApiQuery(query): ApiQuery<PostParams>,
    req: Request,
) -> Result<Response, ApiError> {
    let q = queue(&st)?.clone();
    let key = req
        .headers()
        .get("idempotency-key")
        .map(|v| v.to_str().map(str::to_string))
        .transpose()
        .map_err(|_| ApiError::BadParameter("Idempotency-Key: expected visible ASCII".into()))?;
    if key.as_ref().is_some_and(|k| k.is_empty() || k.len() > 200) {
        return Err(ApiError::BadParameter("Idempotency-Key: 1 to 200 characters".into()));
    }
    let (params, filename, body) = upload(&st, query, req).await?;
    // Settings are checked now, so a job never fails for a typo hours later.
    let profile = params.profile(&st)?;
    let settings = params.settings();
    settings.profile_options(&profile).map_err(ApiError::BadParameter)?;
    let input = StreamReader::new(body.into_data_stream().map(|r| r.map_err(std::io::Error::other)));
    let (job, _created) = q.submit(settings, filename, key, input).await?;
    let location = format!("/v1/jobs/{}", job.id);
    let mut resp = (StatusCode::ACCEPTED, Json(JobView::from(job))).into_response();
    if let Ok(v) = HeaderValue::from_str(&location) {
        resp.headers_mut().insert(header::LOCATION, v);
    }
    Ok(resp)
}

/// A job: state, progress, timings, and the summary once done.
#[utoipa::path(get, path = "/v1/jobs/{id}", params(("id" = String, Path)),
    responses((status = 200, body = JobView), (status = 404, body = super::error::Problem, content_type = "application/problem+json"),
        (status = 503, body = super::error::Problem, content_type = "application/problem+json")),
    tag = "jobs")]
pub async fn get_job(State(st): State<Arc<AppState>>, Path(id): Path<String>) -> Result<Json<JobView>, ApiError> {
    Ok(Json(queue(&st)?.store.get(job_id(&id)?).await?.into()))
}

/// Jobs, newest first, a page at a time.
#[utoipa::path(get, path = "/v1/jobs", params(ListParams),
    responses((status = 200, body = JobList), (status = 400, body = super::error::Problem, content_type = "application/problem+json"),
        (status = 503, body = super::error::Problem, content_type = "application/problem+json")),
    tag = "jobs")]
pub async fn list_jobs(
    State(st): State<Arc<AppState>>,
    ApiQuery(p): ApiQuery<ListParams>,
) -> Result<Json<JobList>, ApiError> {
    let state = match p.state.as_deref() {
        None | Some("") => None,
        Some(s) => Some(JobState::parse(s).ok_or_else(|| {
            ApiError::BadParameter(format!("state: expected queued, running, succeeded, failed or cancelled, got {s:?}"))
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
        (status = 404, body = super::error::Problem, content_type = "application/problem+json"),
        (status = 503, body = super::error::Problem, content_type = "application/problem+json")),
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
        (status = 404, body = super::error::Problem, content_type = "application/problem+json"),
        (status = 409, description = "Not finished, or failed", body = super::error::Problem, content_type = "application/problem+json"),
        (status = 416, description = "Range not satisfiable"),
        (status = 503, body = super::error::Problem, content_type = "application/problem+json")),
    tag = "jobs")]
pub async fn job_nc(st: State<Arc<AppState>>, Path(id): Path<String>, req: Request) -> Result<Response, ApiError> {
    output(st, id, false, req).await
}

/// The NDJSON diagnostics of a finished job: blocks, diagnostics, then the summary or the error.
#[utoipa::path(get, path = "/v1/jobs/{id}/diagnostics", params(("id" = String, Path)),
    responses((status = 200, description = "One JSON object per line", content_type = "application/x-ndjson"),
        (status = 206, description = "Part of it (Range)", content_type = "application/x-ndjson"),
        (status = 304, description = "Not modified (If-None-Match)"),
        (status = 404, body = super::error::Problem, content_type = "application/problem+json"),
        (status = 409, description = "Not finished", body = super::error::Problem, content_type = "application/problem+json"),
        (status = 416, description = "Range not satisfiable"),
        (status = 503, body = super::error::Problem, content_type = "application/problem+json")),
    tag = "jobs")]
pub async fn job_diagnostics(st: State<Arc<AppState>>, Path(id): Path<String>, req: Request) -> Result<Response, ApiError> {
    output(st, id, true, req).await
}

async fn output(State(st): State<Arc<AppState>>, id: String, diagnostics: bool, req: Request) -> Result<Response, ApiError> {
    let q = queue(&st)?;
    let job = q.store.get(job_id(&id)?).await?;
    let ready = match job.state {
        JobState::Succeeded => true,
        JobState::Failed => diagnostics,
        _ => false,
    };
    if !ready {
        return Err(ApiError::Conflict(format!(
            "job {} is {}: {} only when it has {}",
            job.id,
            job.state,
            if diagnostics { "diagnostics" } else { "the NC program" },
            if diagnostics { "finished" } else { "succeeded" }
        )));
    }
    let path = q.store.output_path(&job.id, diagnostics);
    let len = tokio::fs::metadata(&path)
        .await
        .map_err(|e| ApiError::Internal(format!("job output: {e}")))?
        .len();
    // Outputs never change once published: id, kind and length make a strong validator.
    let etag = format!("\"{}-{}-{len}\"", job.id, if diagnostics { "d" } else { "n" });
    if req
        .headers()
        .get(header::IF_NONE_MATCH)
        .and_then(|v| v.to_str().ok())
        .is_some_and(|v| v.split(',').any(|t| t.trim() == etag || t.trim() == "*"))
    {
        let mut r = StatusCode::NOT_MODIFIED.into_response();
        r.headers_mut().insert(header::ETAG, HeaderValue::from_str(&etag).expect("ascii etag"));
        return Ok(r);
    }
    let mut resp = tower_http::services::ServeFile::new(&path)
        .oneshot(req)
        .await
        .map_err(|e| ApiError::Internal(e.to_string()))?
        .map(Body::new);
    let h = resp.headers_mut();
    h.insert(header::ETAG, HeaderValue::from_str(&etag).expect("ascii etag"));
    h.insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static(if diagnostics { "application/x-ndjson" } else { "text/plain; charset=utf-8" }),
    );
    if !diagnostics {
        h.insert(header::CONTENT_DISPOSITION, nc_attachment(job.filename.as_deref(), &job.id));
    }
    Ok(resp)
}
