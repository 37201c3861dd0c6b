//! One shelf of versioned documents over HTTP: machine profiles, tool tables and dialects are
//! read, written and deleted the same way (ETags, `If-Match`, the admin token, TOML or the same
//! document as JSON, a history of versions), so the routes of each kind are this module's
//! functions called with the kind, and each kind's file keeps only what is its own: the DTO,
//! where it is read, and its refusals in its own words.
//!
//! The store side is `machines::catalog`'s [`Shelf`]; this is its HTTP face.

use super::AppState;
use super::error::ApiError;
use crate::machines::{Current, Expect, Kind, Shelf};
use crate::text::quote;
use axum::Json;
use axum::extract::Request;
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::Serialize;

/// A kind of versioned document as the API serves it.
pub(super) trait Document: Kind {
    /// How the API shows a current version.
    type Dto: Serialize;
    /// The document as JSON, which a write may send instead of TOML (turned into TOML for the
    /// loader, so that both forms are validated by the files' own loader).
    type Doc: serde::de::DeserializeOwned + Serialize;
    /// What the body of a write is, in its errors (`the profile is not UTF-8`).
    const BODY: &'static str;
    /// What the log calls it.
    const NOUN: &'static str;

    /// This kind's shelf of the live catalog.
    fn shelf(st: &AppState) -> &Shelf<Self>;
    fn dto(st: &AppState, c: &Current<Self>) -> Self::Dto;
    /// Where the current version of `id` is read (a write's `Location`).
    fn location(id: &str) -> String;
    /// A body the loader refused, or that is no document at all: the kind's 422.
    fn invalid(message: String, key: Option<String>) -> ApiError;
    /// The current version's text in a process without a store: the file's own words.
    fn served_text(st: &AppState, c: &Current<Self>) -> Result<String, ApiError>;

    /// Nothing of this kind under `id` (`id` may name a version: `fanuc version 3`).
    fn missing(id: &str) -> ApiError;
    /// The catalog's refusals in this kind's words.
    fn refusal(e: crate::machines::Error) -> ApiError {
        store_refusal::<Self>(e)
    }
    /// What the document belongs to must exist before it is read or written (a tool table's
    /// machine: a table for no profile would never be used).
    fn owner(_st: &AppState, _id: &str) -> Result<(), ApiError> {
        Ok(())
    }
}

/// The catalog's refusals as the API's: `missing` and `invalid` in the kind's words, the rest
/// as every store error is (`ApiError`'s `From`).
pub(super) fn store_refusal<K: Document>(e: crate::machines::Error) -> ApiError {
    match e {
        crate::machines::Error::NotFound(id) => K::missing(&id),
        e => match ApiError::from(e) {
            ApiError::BadProfile { message, key } => K::invalid(message, key),
            e => e,
        },
    }
}

/// The current version: JSON, or its TOML exactly as stored with `Accept: application/toml`;
/// `304` when `If-None-Match` names it.
pub(super) async fn get<K: Document>(st: &AppState, id: &str, headers: &HeaderMap) -> Result<Response, ApiError> {
    K::owner(st, id)?;
    let shelf = K::shelf(st);
    let c = shelf.get(id).map_err(K::refusal)?;
    if let Some(r) = super::not_modified(headers, &c.etag()) {
        return Ok(r);
    }
    let mut r = if wants_toml(headers) {
        let text = match shelf.text(id, c.version).await {
            Ok(t) => t,
            // Files only: no store to hold the text.
            Err(crate::machines::Error::ReadOnly) => K::served_text(st, &c)?,
            Err(e) => return Err(K::refusal(e)),
        };
        toml_response(StatusCode::OK, text)
    } else {
        Json(K::dto(st, &c)).into_response()
    };
    r.headers_mut().insert(header::ETAG, etag_header(&c));
    Ok(r)
}

/// Adds a document whose id is in its body (`POST`): `409` when the id exists.
pub(super) async fn create<K: Document>(st: &AppState, req: Request) -> Result<Response, ApiError> {
    authorize(st, req.headers())?;
    let text = body::<K>(req).await?;
    let (c, _) = K::shelf(st).put(&text, None, Expect::Absent).await.map_err(K::refusal)?;
    tracing::info!(id = %c.id, version = c.version, "{} created", K::NOUN);
    Ok(written(StatusCode::CREATED, st, &c))
}

/// Replaces (or creates) the document `id` (`PUT`); with `If-Match`, only if it is still that
/// version.
pub(super) async fn put<K: Document>(st: &AppState, id: &str, req: Request) -> Result<Response, ApiError> {
    authorize(st, req.headers())?;
    K::owner(st, id)?;
    let expect = expectation::<K>(req.headers(), id)?;
    let text = body::<K>(req).await?;
    let (c, created) = K::shelf(st).put(&text, Some(id), expect).await.map_err(K::refusal)?;
    tracing::info!(id = %id, version = c.version, "{} written", K::NOUN);
    Ok(written(if created { StatusCode::CREATED } else { StatusCode::OK }, st, &c))
}

/// Deletes the document `id`: a version marking the deletion (jobs already queued keep theirs).
pub(super) async fn delete<K: Document>(st: &AppState, id: &str, headers: &HeaderMap) -> Result<StatusCode, ApiError> {
    authorize(st, headers)?;
    let expect = expectation::<K>(headers, id)?;
    let v = K::shelf(st).delete(id, expect).await.map_err(K::refusal)?;
    tracing::info!(id = %id, version = v, "{} deleted", K::NOUN);
    Ok(StatusCode::NO_CONTENT)
}

/// The history of `id`: every version, who made it (file or API) and when.
pub(super) async fn versions<K: Document>(st: &AppState, id: &str) -> Result<Json<VersionsDto>, ApiError> {
    let shelf = K::shelf(st);
    let versions = match shelf.versions(id).await {
        Err(crate::machines::Error::ReadOnly) => Vec::new(),
        r => r.map_err(K::refusal)?,
    };
    let current = shelf.get(id).ok();
    if versions.is_empty() && current.is_none() {
        return Err(K::refusal(crate::machines::Error::NotFound(id.to_string())));
    }
    Ok(Json(VersionsDto {
        id: id.to_string(),
        current: current.map(|c| c.version),
        versions: versions
            .into_iter()
            .map(|v| VersionDto {
                version: v.version,
                source: v.source.as_str().into(),
                created_ms: v.created_ms,
                deleted: v.deleted,
            })
            .collect(),
    }))
}

/// One version's TOML, exactly as written: what a job that used it ran with. Any version that
/// cannot be given (a path's `version` no number, a deletion, no store) is not found.
pub(super) async fn version<K: Document>(st: &AppState, id: &str, version: &str) -> Result<Response, ApiError> {
    let v: i64 = version
        .parse()
        .map_err(|_| ApiError::NotFound(format!("no version {} of {}", quote(version), quote(id))))?;
    match K::shelf(st).text(id, v).await {
        Ok(t) => Ok(toml_response(StatusCode::OK, t)),
        Err(crate::machines::Error::ReadOnly) => Err(ApiError::NotFound("no version store in this process".into())),
        Err(e) => Err(ApiError::NotFound(e.to_string())),
    }
}

#[derive(Serialize, utoipa::ToSchema)]
pub struct VersionDto {
    pub version: i64,
    /// `file` or `api`.
    pub source: String,
    pub created_ms: i64,
    /// This version deleted the profile.
    pub deleted: bool,
}

#[derive(Serialize, utoipa::ToSchema)]
pub struct VersionsDto {
    pub id: String,
    /// The version served now; absent when the profile is deleted.
    pub current: Option<i64>,
    /// Oldest first.
    pub versions: Vec<VersionDto>,
}

fn etag_header<T: Kind>(c: &Current<T>) -> HeaderValue {
    HeaderValue::from_str(&c.etag()).unwrap_or(HeaderValue::from_static("\"\""))
}

fn wants_toml(h: &HeaderMap) -> bool {
    h.get(header::ACCEPT)
        .and_then(|v| v.to_str().ok())
        .is_some_and(|a| a.contains("application/toml"))
}

fn toml_response(status: StatusCode, text: String) -> Response {
    (status, [(header::CONTENT_TYPE, "application/toml; charset=utf-8")], text).into_response()
}

/// A version just written: its document, its ETag, where it is read.
fn written<K: Document>(status: StatusCode, st: &AppState, c: &Current<K>) -> Response {
    let mut r = (status, Json(K::dto(st, c))).into_response();
    r.headers_mut().insert(header::ETAG, etag_header(c));
    if let Ok(v) = HeaderValue::from_str(&K::location(&c.id)) {
        r.headers_mut().insert(header::LOCATION, v);
    }
    r
}

/// Writes carry `Authorization: Bearer <KINEPOST_ADMIN_TOKEN>`; without a configured token
/// there are no writes at all (403). A missing or wrong token is the same 401.
fn authorize(st: &AppState, h: &HeaderMap) -> Result<(), ApiError> {
    let Some(want) = st.config.admin_token.as_deref() else {
        return Err(ApiError::Forbidden(
            "machine profile writes are off: start the service with KINEPOST_ADMIN_TOKEN set".into(),
        ));
    };
    let got = h
        .get(header::AUTHORIZATION)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.trim().split_once(' '))
        // The scheme is case-insensitive (RFC 9110 §11.1): `bearer` is `Bearer`.
        .filter(|(scheme, _)| scheme.eq_ignore_ascii_case("bearer"))
        .map(|(_, t)| t.trim());
    match got {
        Some(t) if constant_time_eq(t.as_bytes(), want.as_bytes()) => Ok(()),
        Some(_) => Err(ApiError::Unauthorized("the bearer token is not the admin token".into())),
        None => Err(ApiError::Unauthorized(
            "writes need Authorization: Bearer <admin token>".into(),
        )),
    }
}

/// Compares without an early exit, so timing tells nothing about how much of a guess matched.
fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    let mut diff = a.len() ^ b.len();
    for (i, x) in a.iter().enumerate() {
        diff |= (*x ^ b.get(i % b.len().max(1)).copied().unwrap_or(0)) as usize;
    }
    diff == 0
}

/// `If-Match` → what the write expects (checked in the store's transaction), for the kind's
/// ETags (`"id-v3"`, `"id-tools-v3"`: the two never stand for each other); none: anything.
fn expectation<T: Kind>(h: &HeaderMap, id: &str) -> Result<Expect, ApiError> {
    let Some(v) = h.get(header::IF_MATCH) else {
        return Ok(Expect::Any);
    };
    let v = v
        .to_str()
        .map_err(|_| ApiError::BadParameter("If-Match: expected an ETag".into()))?
        .trim();
    if v == "*" {
        return Ok(Expect::Present);
    }
    let version = v
        .strip_prefix(&format!("\"{id}{}", T::ETAG))
        .and_then(|r| r.strip_suffix('"'))
        .and_then(|n| n.parse::<i64>().ok())
        .ok_or_else(|| ApiError::PreconditionFailed(format!("If-Match {}: not an ETag of {} {}", quote(v), T::WHAT, quote(id))))?;
    Ok(Expect::Version(version))
}

/// The document in the body: TOML (`application/toml`), or the same document as JSON, as TOML
/// text for the loader.
async fn body<K: Document>(req: Request) -> Result<String, ApiError> {
    let what = K::BODY;
    let ctype = req
        .headers()
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .unwrap_or("")
        .to_ascii_lowercase();
    let json = ctype.starts_with("application/json");
    if !(json || ctype.starts_with("application/toml") || ctype.starts_with("text/toml")) {
        return Err(ApiError::UnsupportedMediaType(format!(
            "{ctype}: send the {what} as application/toml or application/json"
        )));
    }
    let bytes = axum::body::to_bytes(req.into_body(), 1 << 20)
        .await
        .map_err(|_| ApiError::TooLarge(Some(1 << 20)))?;
    let text = String::from_utf8(bytes.to_vec()).map_err(|_| K::invalid(format!("the {what} is not UTF-8"), None))?;
    if !json {
        return Ok(text);
    }
    let doc: K::Doc = serde_json::from_str(&text).map_err(|e| K::invalid(format!("request body: {e}"), None))?;
    // JSON that TOML cannot hold (a null, an array of mixed tables) is the client's to fix.
    toml::to_string(&doc).map_err(|e| K::invalid(format!("request body: the {what} as TOML: {e}"), None))
}
