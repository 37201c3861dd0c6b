//! `GET /v1/jobs/{id}/lines` for a job whose line map is stored compactly (`spool::lines`): the
//! fixed-size entries rebuilt as they stream, answered as a file of them would be (the same
//! ETag, Range and If-Range, validators, 416s), so a viewer cannot tell which format a job left.

use super::download::{if_range, pumped};
use super::error::ApiError;
use crate::jobs::Job;
use crate::spool::lines::LineIndex;
use axum::body::Body;
use axum::extract::Request;
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use httpdate::HttpDate;
use std::time::SystemTime;

/// Serves the map of `store`, a job's compact line map last modified at `modified`.
pub(super) async fn serve(job: &Job, store: LineIndex, modified: Option<SystemTime>, req: Request) -> Result<Response, ApiError> {
    let len = store.len();
    // The fixed-size file's ETag: its length, which the store keeps.
    let etag = format!("\"{}-l-{len}\"", job.id);
    let modified = modified.map(HttpDate::from);
    if let Some(r) = super::not_modified(req.headers(), &etag) {
        return Ok(r);
    }
    let mut resp = match precondition(req.headers(), &etag, modified) {
        Some(StatusCode::NOT_MODIFIED) => dated(with_status(Response::new(Body::empty()), StatusCode::NOT_MODIFIED), modified),
        Some(status) => with_status(Response::new(Body::empty()), status),
        None => ranged(store, modified, if_range(req, &etag, modified.map(SystemTime::from))).await?,
    };
    // As the file's answers have them, whatever their status.
    let h = resp.headers_mut();
    h.insert(header::ETAG, HeaderValue::from_str(&etag).expect("ascii etag"));
    h.insert(header::CONTENT_TYPE, HeaderValue::from_static("application/octet-stream"));
    Ok(resp)
}

/// The whole map, the one range asked for, or a 416.
async fn ranged(store: LineIndex, modified: Option<HttpDate>, req: Request) -> Result<Response, ApiError> {
    let len = store.len();
    let range = req.headers().get(header::RANGE).and_then(|v| v.to_str().ok());
    let (status, start, end) = match range.map(|r| parse_range(r, len)) {
        None => (StatusCode::OK, 0, len),
        Some(Ok((a, b))) => (StatusCode::PARTIAL_CONTENT, a, b + 1),
        Some(Err(body)) => return Ok(dated(unsatisfiable(len, body), modified)),
    };
    let reader = tokio::task::spawn_blocking(move || store.range(start, end))
        .await
        .map_err(|e| ApiError::Internal(e.to_string()))?
        .map_err(|e| ApiError::Internal(format!("job line map: {e}")))?;
    let mut resp = dated(with_status(Response::new(pumped(reader)), status), modified);
    let h = resp.headers_mut();
    h.insert(header::ACCEPT_RANGES, HeaderValue::from_static("bytes"));
    h.insert(header::CONTENT_LENGTH, HeaderValue::from(end - start));
    if status == StatusCode::PARTIAL_CONTENT {
        let r = format!("bytes {start}-{}/{len}", end - 1);
        h.insert(header::CONTENT_RANGE, HeaderValue::from_str(&r).expect("ascii range"));
    }
    Ok(resp)
}

/// One range, inclusive, as the file server reads the header; `Err`: a 416, with the body it
/// gives one (a multipart request is refused in words, an unsatisfiable one with none).
fn parse_range(header: &str, len: u64) -> Result<(u64, u64), &'static str> {
    let parsed = http_range_header::parse_range_header(header).map_err(|_| "")?;
    if parsed.ranges.len() > 1 {
        return Err("Cannot serve multipart range requests");
    }
    let r = parsed.validate(len).map_err(|_| "")?.pop().ok_or("")?;
    Ok((*r.start(), *r.end()))
}

fn unsatisfiable(len: u64, body: &'static str) -> Response {
    let mut resp = (StatusCode::RANGE_NOT_SATISFIABLE, body).into_response();
    let h = resp.headers_mut();
    h.remove(header::CONTENT_TYPE);
    h.insert(header::ACCEPT_RANGES, HeaderValue::from_static("bytes"));
    h.insert(
        header::CONTENT_RANGE,
        HeaderValue::from_str(&format!("bytes */{len}")).expect("ascii range"),
    );
    resp
}

/// RFC 9110 §13.2.2, after If-None-Match: If-Match (strong) or else If-Unmodified-Since fails
/// with 412; If-Modified-Since, where no If-None-Match was sent, answers 304.
fn precondition(h: &HeaderMap, etag: &str, modified: Option<HttpDate>) -> Option<StatusCode> {
    let date = |name| {
        h.get(name)
            .and_then(|v| v.to_str().ok())
            .and_then(|v| v.parse::<HttpDate>().ok())
    };
    if let Some(m) = h.get(header::IF_MATCH).and_then(|v| v.to_str().ok()) {
        if !m.split(',').any(|t| t.trim() == etag || t.trim() == "*") {
            return Some(StatusCode::PRECONDITION_FAILED);
        }
    } else if let (Some(since), Some(m)) = (date(header::IF_UNMODIFIED_SINCE), modified)
        && since < m
    {
        return Some(StatusCode::PRECONDITION_FAILED);
    }
    if !h.contains_key(header::IF_NONE_MATCH)
        && let (Some(since), Some(m)) = (date(header::IF_MODIFIED_SINCE), modified)
        && since >= m
    {
        return Some(StatusCode::NOT_MODIFIED);
    }
    None
}

fn with_status(mut resp: Response, status: StatusCode) -> Response {
    *resp.status_mut() = status;
    resp
}

fn dated(mut resp: Response, modified: Option<HttpDate>) -> Response {
    if let Some(m) = modified {
        resp.headers_mut().insert(
            header::LAST_MODIFIED,
            HeaderValue::from_str(&m.to_string()).expect("http date"),
        );
    }
    resp
}
