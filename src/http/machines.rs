//! `/v1/machines`: the machine library over HTTP. Reads for everyone; writes (create, replace,
//! delete) with the admin bearer token, each a new version in the store, with ETags and
//! `If-Match` so two editors never overwrite each other unknowingly (the routes are
//! [`super::shelf`]'s, for profiles); a mesh body's triangles for the page.

use super::AppState;
use super::error::ApiError;
use super::refusals::{AuthRefusals, BodyRefusals, Conflict, MatchRefusals, NotFound, StoreBusy, StoreFull, TooManyDownloads};
use super::shelf::{self, Document, VersionsDto};
use crate::machines::{Current, Profile, ProfileDoc, Shelf};
use crate::text::quote;
use axum::Json;
use axum::extract::{Path, Request, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::Serialize;
use std::sync::Arc;

/// A machine profile as the API shows it: the profile's own numbers, plus its kinematics kind.
#[derive(Serialize, utoipa::ToSchema)]
pub struct MachineDto {
    pub id: String,
    pub name: String,
    /// `mm` or `inch`.
    pub units: String,
    /// Default NC dialect.
    pub controller: String,
    pub description: String,
    /// table-table, head-head, head-table, 4-axis, 3-axis, 3-rotary/2-linear …
    pub kinematics: String,
    pub linear: Vec<LinearDto>,
    pub rotary: Vec<RotaryDto>,
    pub default_tool_length: f64,
    /// The machine's bodies (`[[body]]`), each on its link, at home: what the collision check
    /// and the machine view use. Empty where the profile gives none.
    pub bodies: Vec<crate::output::model::ModelBody>,
    /// This profile's version: each write over the API makes a new one (`…/versions`).
    pub version: i64,
    /// `file` (the library directory) or `api`.
    pub source: String,
}

#[derive(Serialize, utoipa::ToSchema)]
pub struct LinearDto {
    pub name: String,
    pub min: f64,
    pub max: f64,
    pub max_feed: Option<f64>,
    /// Units/s².
    pub max_accel: Option<f64>,
}

#[derive(Serialize, utoipa::ToSchema)]
pub struct RotaryDto {
    pub name: String,
    /// `table` or `head`.
    pub on: String,
    pub axis: [f64; 3],
    pub pivot: [f64; 3],
    /// Degrees; absent for an unbounded axis.
    pub min: Option<f64>,
    pub max: Option<f64>,
    pub max_feed: Option<f64>,
    /// °/s².
    pub max_accel: Option<f64>,
    pub angle_error: Option<AngleErrorDto>,
    /// NC words that lock and unlock the axis around positioning, if it is clamped.
    pub clamp: Option<Vec<String>>,
}

#[derive(Serialize, utoipa::ToSchema)]
pub struct AngleErrorDto {
    pub coefficients: Vec<f64>,
    pub range: [f64; 2],
}

impl From<&Current> for MachineDto {
    fn from(c: &Current) -> Self {
        let p: &Profile = &c.item;
        let d = &p.doc;
        MachineDto {
            version: c.version,
            source: c.source.as_str().into(),
            id: p.machine.id.clone(),
            name: p.machine.name.clone(),
            units: p.machine.units.as_str().into(),
            controller: p.machine.controller.clone(),
            description: p.machine.description.clone(),
            kinematics: p.machine.kinematics_kind(),
            linear: d
                .linear
                .iter()
                .map(|l| LinearDto {
                    name: l.name.clone(),
                    min: l.min,
                    max: l.max,
                    max_feed: l.max_feed,
                    max_accel: l.max_accel,
                })
                .collect(),
            rotary: d
                .rotary
                .iter()
                .map(|r| RotaryDto {
                    name: r.name.clone(),
                    on: r.on.clone(),
                    axis: r.axis,
                    pivot: r.pivot,
                    min: r.min,
                    max: r.max,
                    max_feed: r.max_feed,
                    max_accel: r.max_accel,
                    angle_error: r.angle_error.as_ref().map(|e| AngleErrorDto {
                        coefficients: e.coefficients.clone(),
                        range: e.range,
                    }),
                    clamp: r.clamp.as_ref().map(|c| c.to_vec()),
                })
                .collect(),
            default_tool_length: p.machine.default_tool_length,
            bodies: crate::output::model::bodies(&p.machine, &p.geometry()),
        }
    }
}

impl Document for Profile {
    type Dto = MachineDto;
    type Doc = ProfileDoc;
    const BODY: &'static str = "profile";
    const NOUN: &'static str = "machine profile";
    fn shelf(st: &AppState) -> &Shelf<Profile> {
        &st.machines
    }
    fn dto(_: &AppState, c: &Current) -> MachineDto {
        MachineDto::from(c)
    }
    fn location(id: &str) -> String {
        format!("/v1/machines/{id}")
    }
    fn invalid(message: String, key: Option<String>) -> ApiError {
        ApiError::BadProfile { message, key }
    }
    fn missing(id: &str) -> ApiError {
        ApiError::UnknownMachine(id.to_string())
    }
    /// The document re-serialized: a profile file's own text is not kept.
    fn served_text(_: &AppState, c: &Current) -> Result<String, ApiError> {
        toml::to_string(&c.item.doc).map_err(|e| ApiError::Internal(e.to_string()))
    }
}

/// Every machine profile, geometry included.
#[utoipa::path(get, path = "/v1/machines", responses((status = 200, description = "Success", body = Vec<MachineDto>)), tag = "machines")]
pub(super) async fn list_machines(State(st): State<Arc<AppState>>) -> Json<Vec<MachineDto>> {
    Json(st.machines.list().iter().map(MachineDto::from).collect())
}

/// One machine profile: JSON, or its TOML exactly as stored with `Accept: application/toml`.
#[utoipa::path(
    get,
    path = "/v1/machines/{id}",
    params(("id" = String, Path, description = "Profile id, e.g. haas-umc750")),
    responses((status = 200, description = "The profile; its TOML as stored with Accept: application/toml",
            content((MachineDto = "application/json"), (String = "application/toml")),
            headers(("ETag" = String, description = "The version, e.g. \"haas-umc750-v3\""))),
        (status = 304, description = "Not modified (If-None-Match)"),
        NotFound, StoreBusy),
    tag = "machines"
)]
pub(super) async fn get_machine(
    State(st): State<Arc<AppState>>,
    Path(id): Path<String>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    shelf::get::<Profile>(&st, &id, &headers).await
}

/// Adds a machine profile: validated by the same loader as the files (errors name the key).
#[utoipa::path(post, path = "/v1/machines",
    request_body(description = "The profile, as in `machines/*.toml`, or the same document as JSON",
        content((String = "application/toml"), (Object = "application/json"))),
    responses((status = 201, description = "Created", body = MachineDto, headers(("ETag" = String), ("Location" = String))),
        AuthRefusals, BodyRefusals, Conflict, StoreBusy, StoreFull),
    security(("admin" = [])),
    tag = "machines")]
pub(super) async fn create_machine(State(st): State<Arc<AppState>>, req: Request) -> Result<Response, ApiError> {
    shelf::create::<Profile>(&st, req).await
}

/// Replaces (or creates) a machine profile; with `If-Match`, only if it is still that version.
#[utoipa::path(put, path = "/v1/machines/{id}", params(("id" = String, Path),
        ("If-Match" = Option<String>, Header, description = "The ETag read; the write fails (412) if the profile changed since")),
    request_body(description = "The profile (TOML, or the same document as JSON); its `id` must be the path's",
        content((String = "application/toml"), (Object = "application/json"))),
    responses((status = 200, description = "Replaced: a new version", body = MachineDto, headers(("ETag" = String))),
        (status = 201, description = "Created", body = MachineDto, headers(("ETag" = String), ("Location" = String))),
        AuthRefusals, MatchRefusals, BodyRefusals, StoreBusy, StoreFull),
    security(("admin" = [])),
    tag = "machines")]
pub(super) async fn put_machine(
    State(st): State<Arc<AppState>>,
    Path(id): Path<String>,
    req: Request,
) -> Result<Response, ApiError> {
    shelf::put::<Profile>(&st, &id, req).await
}

/// Deletes a machine profile (a version marking the deletion; jobs already queued keep theirs).
#[utoipa::path(delete, path = "/v1/machines/{id}", params(("id" = String, Path),
        ("If-Match" = Option<String>, Header, description = "Delete only this version")),
    responses((status = 204, description = "Deleted"), AuthRefusals, MatchRefusals, NotFound, StoreBusy, StoreFull),
    security(("admin" = [])),
    tag = "machines")]
pub(super) async fn delete_machine(
    State(st): State<Arc<AppState>>,
    Path(id): Path<String>,
    headers: HeaderMap,
) -> Result<StatusCode, ApiError> {
    shelf::delete::<Profile>(&st, &id, &headers).await
}

/// A profile's history: every version, who made it (file or API) and when.
#[utoipa::path(get, path = "/v1/machines/{id}/versions", params(("id" = String, Path)),
    responses((status = 200, description = "Success", body = VersionsDto), NotFound, StoreBusy),
    tag = "machines")]
pub(super) async fn list_versions(
    State(st): State<Arc<AppState>>,
    Path(id): Path<String>,
) -> Result<Json<VersionsDto>, ApiError> {
    shelf::versions::<Profile>(&st, &id).await
}

/// One version's TOML, exactly as written: what a job that used it ran with.
#[utoipa::path(get, path = "/v1/machines/{id}/versions/{version}", params(("id" = String, Path), ("version" = i64, Path)),
    responses((status = 200, description = "Success", body = String, content_type = "application/toml"), NotFound),
    tag = "machines")]
pub(super) async fn get_version(
    State(st): State<Arc<AppState>>,
    Path((id, version)): Path<(String, String)>,
) -> Result<Response, ApiError> {
    shelf::version::<Profile>(&st, &id, &version).await
}

/// A mesh body's triangles, as the check reads them: binary STL, its ETag the file's digest.
#[utoipa::path(get, path = "/v1/machines/{id}/meshes/{file}", params(("id" = String, Path), ("file" = String, Path)),
    responses((status = 200, description = "Binary STL (profile units, the body's link at home)", content_type = "model/stl"),
        (status = 304, description = "Not modified (If-None-Match)"),
        NotFound, TooManyDownloads),
    tag = "machines"
)]
pub(super) async fn get_mesh(
    State(st): State<Arc<AppState>>,
    Path((id, file)): Path<(String, String)>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let c = st.machines.get(&id)?;
    let g = c.item.geometry();
    let mesh = g
        .bodies
        .iter()
        .find_map(|b| match &b.solid {
            crate::collide::Solid::Mesh(m) if m.file == file => Some(m.clone()),
            _ => None,
        })
        .ok_or_else(|| ApiError::NotFound(format!("machine {} has no body with the mesh {}", quote(&id), quote(&file))))?;
    let etag = format!("\"mesh-{:016x}\"", mesh.digest);
    if let Some(r) = super::not_modified(&headers, &etag) {
        return Ok(r);
    }
    // One copy however many download it: the body shares it.
    let bytes = bytes::Bytes::from_owner(mesh.drawn(crate::machines::meshes::to_binary_stl));
    let mut r = (StatusCode::OK, [(header::CONTENT_TYPE, HeaderValue::from_static("model/stl"))], bytes).into_response();
    if let Ok(v) = HeaderValue::from_str(&etag) {
        r.headers_mut().insert(header::ETAG, v);
    }
    Ok(r)
}
