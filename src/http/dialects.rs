//! `/v1/dialects`: the NC dialects over HTTP, versioned as the profiles are (a new version per
//! write, ETag `"id-dialect-vN"`, `If-Match`, the admin token). A post names one with
//! `dialect=`; a job records the version it was accepted with and runs with that.

use super::AppState;
use super::error::ApiError;
use super::refusals::{AuthRefusals, BodyRefusals, Conflict, MatchRefusals, NotFound, StoreBusy, StoreFull};
use super::shelf::{self, Document, VersionsDto};
use crate::machines::{Current, Shelf};
use crate::nc::Dialect;
use crate::text::quote;
use axum::Json;
use axum::extract::{Path, Request, State};
use axum::http::{HeaderMap, StatusCode};
use axum::response::Response;
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

impl Document for Dialect {
    type Dto = DialectDto;
    /// Any table: the dialect's loader names what it does not know (`extends` merges first).
    type Doc = toml::Table;
    const BODY: &'static str = "dialect";
    const NOUN: &'static str = "dialect";
    fn shelf(st: &AppState) -> &Shelf<Dialect> {
        &st.machines.dialects
    }
    fn dto(st: &AppState, c: &Current<Dialect>) -> DialectDto {
        dto(st, c)
    }
    fn location(id: &str) -> String {
        format!("/v1/dialects/{id}")
    }
    fn invalid(message: String, _key: Option<String>) -> ApiError {
        ApiError::BadDialect(message)
    }
    fn missing(id: &str) -> ApiError {
        ApiError::NotFound(format!("no dialect {}", quote(id)))
    }
    fn served_text(st: &AppState, c: &Current<Dialect>) -> Result<String, ApiError> {
        crate::machines::dialects::file_text(Some(&st.config.dialects), &c.id).map_err(|e| ApiError::Internal(e.to_string()))
    }
    /// A conflict and a failed precondition in a dialect's words.
    fn refusal(e: crate::machines::Error) -> ApiError {
        use crate::machines::Error as E;
        match e {
            E::Exists { id, version } => ApiError::Conflict(format!("dialect {} exists (version {version}): replace it with PUT", quote(&id))),
            E::Precondition { id, current } => ApiError::PreconditionFailed(format!(
                "dialect {} is at {}: the write was based on another",
                quote(&id),
                current.map_or("no version (deleted or never created)".to_string(), |v| format!("version {v}"))
            )),
            e => shelf::store_refusal::<Dialect>(e),
        }
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
        NotFound, StoreBusy),
    tag = "dialects")]
pub(super) async fn get_dialect(State(st): State<Arc<AppState>>, Path(id): Path<String>, headers: HeaderMap) -> Result<Response, ApiError> {
    shelf::get::<Dialect>(&st, &id, &headers).await
}

/// Adds a dialect (its `id` in the document): validated by the files' loader, templates and all.
#[utoipa::path(post, path = "/v1/dialects",
    request_body(description = "The dialect, as in `dialects/*.toml` (`extends` a built-in and says what differs), or the same document as JSON",
        content((String = "application/toml"), (Object = "application/json"))),
    responses((status = 201, description = "Created", body = DialectDto, headers(("ETag" = String), ("Location" = String))),
        AuthRefusals, BodyRefusals, Conflict, StoreBusy, StoreFull),
    security(("admin" = [])),
    tag = "dialects")]
pub(super) async fn create_dialect(State(st): State<Arc<AppState>>, req: Request) -> Result<Response, ApiError> {
    shelf::create::<Dialect>(&st, req).await
}

/// Replaces (or creates) a dialect; with `If-Match`, only if it is still that version. Posts and
/// jobs submitted from then on use it.
#[utoipa::path(put, path = "/v1/dialects/{id}", params(("id" = String, Path),
        ("If-Match" = Option<String>, Header, description = "The ETag read; the write fails (412) if the dialect changed since")),
    request_body(description = "The dialect (TOML, or the same document as JSON); its `id` must be the path's",
        content((String = "application/toml"), (Object = "application/json"))),
    responses((status = 200, description = "Replaced: a new version", body = DialectDto, headers(("ETag" = String))),
        (status = 201, description = "Created", body = DialectDto, headers(("ETag" = String), ("Location" = String))),
        AuthRefusals, MatchRefusals, BodyRefusals, StoreBusy, StoreFull),
    security(("admin" = [])),
    tag = "dialects")]
pub(super) async fn put_dialect(State(st): State<Arc<AppState>>, Path(id): Path<String>, req: Request) -> Result<Response, ApiError> {
    shelf::put::<Dialect>(&st, &id, req).await
}

/// Deletes a dialect (a version marking the deletion); jobs already queued keep theirs.
#[utoipa::path(delete, path = "/v1/dialects/{id}", params(("id" = String, Path),
        ("If-Match" = Option<String>, Header, description = "Delete only this version")),
    responses((status = 204, description = "Deleted"), AuthRefusals, MatchRefusals, NotFound, StoreBusy, StoreFull),
    security(("admin" = [])),
    tag = "dialects")]
pub(super) async fn delete_dialect(State(st): State<Arc<AppState>>, Path(id): Path<String>, headers: HeaderMap) -> Result<StatusCode, ApiError> {
    shelf::delete::<Dialect>(&st, &id, &headers).await
}

/// A dialect's history: every version, who made it (file or API) and when.
#[utoipa::path(get, path = "/v1/dialects/{id}/versions", params(("id" = String, Path)),
    responses((status = 200, description = "Success", body = VersionsDto), NotFound, StoreBusy),
    tag = "dialects")]
pub(super) async fn list_dialect_versions(State(st): State<Arc<AppState>>, Path(id): Path<String>) -> Result<Json<VersionsDto>, ApiError> {
    shelf::versions::<Dialect>(&st, &id).await
}

/// One version's TOML, exactly as written: what a job that used it ran with.
#[utoipa::path(get, path = "/v1/dialects/{id}/versions/{version}", params(("id" = String, Path), ("version" = i64, Path)),
    responses((status = 200, description = "Success", body = String, content_type = "application/toml"), NotFound),
    tag = "dialects")]
pub(super) async fn get_dialect_version(
    State(st): State<Arc<AppState>>,
    Path((id, version)): Path<(String, String)>,
) -> Result<Response, ApiError> {
    shelf::version::<Dialect>(&st, &id, &version).await
}
