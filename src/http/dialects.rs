//! `/v1/dialects`: the NC dialects over HTTP, versioned as the profiles are (a new version per
//! write, ETag `"id-dialect-vN"`, `If-Match`, the admin token). A post names one with
//! `dialect=`; a job records the version it was accepted with and runs with that.

use super::AppState;
use super::error::{ApiError, Problem};
use super::machines::{VersionsDto, authorize, etag_header, expectation_of, toml_body, toml_response, version_toml, versions_of, wants_toml, written};
use crate::machines::{Current, Expect};
use crate::nc::Dialect;
use crate::text::quote;
use axum::Json;
use axum::extract::{Path, Request, State};
use axum::http::{HeaderMap, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::Serialize;
use std::sync::Arc;

/// A controller dialect and its words for the things that differ between controls.
#[derive(Serialize, utoipa::ToSchema)]
pub struct DialectDto {
    pub name: String,
    pub title: String,
    /// This dialect's version: each write makes a new one (`…/versions`).
    pub version: i64,
    /// `file` (`dialects/<id>.toml`, or built in) or `api`.
    pub source: String,
    /// `word_address` or `conversational`.
    pub style: String,
    pub tcp_on: String,
    pub tcp_off: String,
    /// The inverse-time feed word, if the control has one.
    pub inverse_time: Option<String>,
    pub tool_change: Vec<String>,
    /// The program events this dialect writes from its own templates.
    pub templates: Vec<String>,
    /// Machines whose profile names this dialect as their controller (their default).
    pub default_for: Vec<String>,
    /// How drilling cycles are written with `cycles=canned`.
    pub canned_cycles: String,
    /// How 3+2 work is written with `planes=tilted`.
    pub tilted_planes: String,
    /// The work coordinate systems a program can select (`work_coordinates`); the first is the
    /// default. Empty: the program selects none (the control's preset).
    pub work_coordinates: Vec<String>,
    pub notes: String,
}

fn dto(st: &AppState, c: &Current<Dialect>) -> DialectDto {
    let d = &c.item;
    DialectDto {
        name: d.name.clone(),
        title: d.title.clone(),
        version: c.version,
        source: c.source.as_str().into(),
        style: match d.style {
            crate::nc::Style::WordAddress => "word_address".into(),
            crate::nc::Style::Conversational => "conversational".into(),
        },
        tcp_on: d.tcp_on.clone(),
        tcp_off: d.tcp_off.clone(),
        inverse_time: d.inverse_time.clone(),
        tool_change: d.tool_change.clone(),
        templates: crate::nc::templates::EVENTS.iter().filter(|e| d.templates.has(e)).map(|e| e.to_string()).collect(),
        default_for: st
            .machines
            .list()
            .iter()
            .filter(|m| m.item.machine.controller == d.name)
            .map(|m| m.item.machine.id.clone())
            .collect(),
        canned_cycles: d.cycles.describe().into(),
        tilted_planes: d.planes.describe().into(),
        work_coordinates: d.work_coordinates.clone(),
        notes: d.notes.clone(),
    }
}

/// The store's errors in a dialect's words (its loader's refusals are 422 `bad-dialect`).
fn dialect_err(e: crate::machines::Error) -> ApiError {
    use crate::machines::Error as E;
    match e {
        E::NotFound(id) => ApiError::NotFound(format!("no dialect {}", quote(&id))),
        E::Parse { .. } | E::Invalid { .. } => ApiError::BadDialect(e.to_string()),
        E::Exists { id, version } => ApiError::Conflict(format!("dialect {} exists (version {version}): replace it with PUT", quote(&id))),
        E::Precondition { id, current } => ApiError::PreconditionFailed(format!(
            "dialect {} is at {}: the write was based on another",
            quote(&id),
            current.map_or("no version (deleted or never created)".to_string(), |v| format!("version {v}"))
        )),
        e => e.into(),
    }
}

/// The NC dialects; a post request may name any, the profile's `controller` is the default.
#[utoipa::path(get, path = "/v1/dialects", responses((status = 200, description = "Success", body = Vec<DialectDto>)), tag = "dialects")]
pub(super) async fn list_dialects(State(st): State<Arc<AppState>>) -> Json<Vec<DialectDto>> {
    let mut all = st.machines.dialects.list();
    // The built-ins first, in their usual order, then the shop's own by id.
    let rank = |id: &str| crate::nc::DIALECTS.iter().position(|b| *b == id).unwrap_or(usize::MAX);
    all.sort_by(|a, b| (rank(&a.id), &a.id).cmp(&(rank(&b.id), &b.id)));
    Json(all.iter().map(|c| dto(&st, c)).collect())
}

/// One dialect: JSON, or its TOML exactly as stored with `Accept: application/toml`.
#[utoipa::path(get, path = "/v1/dialects/{id}",
    params(("id" = String, Path, description = "Dialect id, e.g. fanuc")),
    responses((status = 200, description = "The dialect; its TOML as stored with Accept: application/toml",
            content((DialectDto = "application/json"), (String = "application/toml")),
            headers(("ETag" = String, description = "The version, e.g. \"fanuc-dialect-v1\""))),
        (status = 304, description = "Not modified (If-None-Match)"),
        (status = 404, description = "No such dialect", body = Problem, content_type = "application/problem+json")),
    tag = "dialects")]
pub(super) async fn get_dialect(State(st): State<Arc<AppState>>, Path(id): Path<String>, headers: HeaderMap) -> Result<Response, ApiError> {
    let c = st.machines.dialects.get(&id).map_err(dialect_err)?;
    if let Some(r) = super::not_modified(&headers, &c.etag()) {
        return Ok(r);
    }
    let mut r = if wants_toml(&headers) {
        let text = match st.machines.dialects.text(&id, c.version).await {
            Ok(t) => t,
            // Files only: no store to hold the text; the file's own words.
            Err(crate::machines::Error::ReadOnly) => {
                crate::machines::dialects::file_text(Some(&st.config.dialects), &id).map_err(|e| ApiError::Internal(e.to_string()))?
            }
            Err(e) => return Err(dialect_err(e)),
        };
        toml_response(StatusCode::OK, text)
    } else {
        Json(dto(&st, &c)).into_response()
    };
    r.headers_mut().insert(header::ETAG, etag_header(&c));
    Ok(r)
}

async fn dialect_text(req: Request) -> Result<String, ApiError> {
    toml_body::<toml::Table>(req, "dialect").await.map_err(|e| match e {
        ApiError::BadProfile { message, .. } => ApiError::BadDialect(message),
        e => e,
    })
}

/// Adds a dialect (its `id` in the document): validated by the files' loader, templates and all.
#[utoipa::path(post, path = "/v1/dialects",
    request_body(description = "The dialect, as in `dialects/*.toml` (`extends` a built-in and says what differs), or the same document as JSON",
        content((String = "application/toml"), (Object = "application/json"))),
    responses((status = 201, description = "Created", body = DialectDto, headers(("ETag" = String), ("Location" = String))),
        (status = 401, description = "No admin token given", body = Problem, content_type = "application/problem+json"),
        (status = 403, description = "Writes are off (no admin token configured)", body = Problem, content_type = "application/problem+json"),
        (status = 409, description = "The id exists", body = Problem, content_type = "application/problem+json"),
        (status = 413, description = "The body is too large", body = Problem, content_type = "application/problem+json"),
        (status = 415, description = "Unsupported content type", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "Invalid dialect: the key, or the template and its line", body = Problem, content_type = "application/problem+json"),
        (status = 507, description = "The store's disk is full: nothing written (Retry-After)", body = Problem, content_type = "application/problem+json")),
    security(("admin" = [])),
    tag = "dialects")]
pub(super) async fn create_dialect(State(st): State<Arc<AppState>>, req: Request) -> Result<Response, ApiError> {
    authorize(&st, req.headers())?;
    let text = dialect_text(req).await?;
    let (c, _) = st.machines.dialects.put(&text, None, Expect::Absent).await.map_err(dialect_err)?;
    tracing::info!(dialect = %c.id, version = c.version, "dialect created");
    Ok(written(StatusCode::CREATED, &c, dto(&st, &c), &format!("/v1/dialects/{}", c.id)))
}

/// Replaces (or creates) a dialect; with `If-Match`, only if it is still that version. Posts and
/// jobs submitted from then on use it.
#[utoipa::path(put, path = "/v1/dialects/{id}", params(("id" = String, Path),
        ("If-Match" = Option<String>, Header, description = "The ETag read; the write fails (412) if the dialect changed since")),
    request_body(description = "The dialect (TOML, or the same document as JSON); its `id` must be the path's",
        content((String = "application/toml"), (Object = "application/json"))),
    responses((status = 200, description = "Replaced: a new version", body = DialectDto, headers(("ETag" = String))),
        (status = 201, description = "Created", body = DialectDto, headers(("ETag" = String), ("Location" = String))),
        (status = 401, description = "No admin token given", body = Problem, content_type = "application/problem+json"),
        (status = 403, description = "The admin token is wrong", body = Problem, content_type = "application/problem+json"),
        (status = 412, description = "If-Match names another version", body = Problem, content_type = "application/problem+json"),
        (status = 413, description = "The body is too large", body = Problem, content_type = "application/problem+json"),
        (status = 415, description = "Unsupported content type", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "Invalid dialect: the key, or the template and its line", body = Problem, content_type = "application/problem+json"),
        (status = 507, description = "The store's disk is full: nothing written (Retry-After)", body = Problem, content_type = "application/problem+json")),
    security(("admin" = [])),
    tag = "dialects")]
pub(super) async fn put_dialect(State(st): State<Arc<AppState>>, Path(id): Path<String>, req: Request) -> Result<Response, ApiError> {
    authorize(&st, req.headers())?;
    let expect = expectation_of::<Dialect>(req.headers(), &id)?;
    let text = dialect_text(req).await?;
    let (c, created) = st.machines.dialects.put(&text, Some(&id), expect).await.map_err(dialect_err)?;
    tracing::info!(dialect = %id, version = c.version, "dialect written");
    let status = if created { StatusCode::CREATED } else { StatusCode::OK };
    Ok(written(status, &c, dto(&st, &c), &format!("/v1/dialects/{id}")))
}

/// Deletes a dialect (a version marking the deletion); jobs already queued keep theirs.
#[utoipa::path(delete, path = "/v1/dialects/{id}", params(("id" = String, Path),
        ("If-Match" = Option<String>, Header, description = "Delete only this version")),
    responses((status = 204, description = "Deleted"),
        (status = 401, description = "No admin token given", body = Problem, content_type = "application/problem+json"),
        (status = 403, description = "The admin token is wrong", body = Problem, content_type = "application/problem+json"),
        (status = 404, description = "Not found", body = Problem, content_type = "application/problem+json"),
        (status = 412, description = "If-Match names another version", body = Problem, content_type = "application/problem+json"),
        (status = 507, description = "The store's disk is full: nothing written (Retry-After)", body = Problem, content_type = "application/problem+json")),
    security(("admin" = [])),
    tag = "dialects")]
pub(super) async fn delete_dialect(State(st): State<Arc<AppState>>, Path(id): Path<String>, headers: HeaderMap) -> Result<StatusCode, ApiError> {
    authorize(&st, &headers)?;
    let expect = expectation_of::<Dialect>(&headers, &id)?;
    let v = st.machines.dialects.delete(&id, expect).await.map_err(dialect_err)?;
    tracing::info!(dialect = %id, version = v, "dialect deleted");
    Ok(StatusCode::NO_CONTENT)
}

/// A dialect's history: every version, who made it (file or API) and when.
#[utoipa::path(get, path = "/v1/dialects/{id}/versions", params(("id" = String, Path)),
    responses((status = 200, description = "Success", body = VersionsDto), (status = 404, description = "Not found", body = Problem, content_type = "application/problem+json")),
    tag = "dialects")]
pub(super) async fn list_dialect_versions(State(st): State<Arc<AppState>>, Path(id): Path<String>) -> Result<Json<VersionsDto>, ApiError> {
    versions_of(&st.machines.dialects, id.clone())
        .await?
        .map(Json)
        .ok_or_else(|| ApiError::NotFound(format!("no dialect {}", quote(&id))))
}

/// One version's TOML, exactly as written: what a job that used it ran with.
#[utoipa::path(get, path = "/v1/dialects/{id}/versions/{version}", params(("id" = String, Path), ("version" = i64, Path)),
    responses((status = 200, description = "Success", body = String, content_type = "application/toml"),
        (status = 404, description = "No such version, or a deletion", body = Problem, content_type = "application/problem+json")),
    tag = "dialects")]
pub(super) async fn get_dialect_version(
    State(st): State<Arc<AppState>>,
    Path((id, version)): Path<(String, String)>,
) -> Result<Response, ApiError> {
    version_toml(&st.machines.dialects, &id, &version).await
}
