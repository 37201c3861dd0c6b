//! `/v1/machines`: the machine library over HTTP. Reads for everyone; writes (create, replace,
//! delete) with the admin bearer token, each a new version in the store, with ETags and
//! `If-Match` so two editors never overwrite each other unknowingly.

use super::AppState;
use super::error::{ApiError, Problem};
use crate::machines::{Current, Expect, Kind, Profile, ProfileDoc, Shelf};
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

/// Every machine profile, geometry included.
#[utoipa::path(get, path = "/v1/machines", responses((status = 200, description = "Success", body = Vec<MachineDto>)), tag = "machines")]
pub(super) async fn list_machines(State(st): State<Arc<AppState>>) -> Json<Vec<MachineDto>> {
    Json(st.machines.list().iter().map(MachineDto::from).collect())
}

pub(super) fn etag_header<T: Kind>(c: &Current<T>) -> HeaderValue {
    HeaderValue::from_str(&c.etag()).unwrap_or(HeaderValue::from_static("\"\""))
}

pub(super) fn wants_toml(h: &HeaderMap) -> bool {
    h.get(header::ACCEPT)
        .and_then(|v| v.to_str().ok())
        .is_some_and(|a| a.contains("application/toml"))
}

pub(super) fn toml_response(status: StatusCode, text: String) -> Response {
    (status, [(header::CONTENT_TYPE, "application/toml; charset=utf-8")], text).into_response()
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
        (status = 404, description = "Not found", body = Problem, content_type = "application/problem+json")),
    tag = "machines"
)]
pub(super) async fn get_machine(
    State(st): State<Arc<AppState>>,
    Path(id): Path<String>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let c = st.machines.get(&id)?;
    if let Some(r) = super::not_modified(&headers, &c.etag()) {
        return Ok(r);
    }
    let etag = etag_header(&c);
    let mut r = if wants_toml(&headers) {
        toml_response(StatusCode::OK, version_text(&st, &c).await?)
    } else {
        Json(MachineDto::from(&c)).into_response()
    };
    r.headers_mut().insert(header::ETAG, etag);
    Ok(r)
}

/// The stored TOML of the current version (files-only processes: the document re-serialized).
async fn version_text(st: &AppState, c: &Current) -> Result<String, ApiError> {
    match st.machines.text(&c.item.machine.id, c.version).await {
        Ok(t) => Ok(t),
        Err(crate::machines::Error::ReadOnly) => toml::to_string(&c.item.doc).map_err(|e| ApiError::Internal(e.to_string())),
        Err(e) => Err(e.into()),
    }
}

/// Writes carry `Authorization: Bearer <KINEPOST_ADMIN_TOKEN>`; without a configured token
/// there are no writes at all.
pub(super) fn authorize(st: &AppState, h: &HeaderMap) -> Result<(), ApiError> {
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

/// `If-Match` → what the write expects (checked in the store's transaction); none: anything.
fn expectation(h: &HeaderMap, id: &str) -> Result<Expect, ApiError> {
    expectation_of::<Profile>(h, id)
}

/// [`expectation`] for a kind's ETags (`"id-v3"`, `"id-tools-v3"`).
pub(super) fn expectation_of<T: Kind>(h: &HeaderMap, id: &str) -> Result<Expect, ApiError> {
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

/// The profile in the body: TOML (`application/toml`), or the same document as JSON.
async fn profile_text(req: Request) -> Result<String, ApiError> {
    toml_body::<ProfileDoc>(req, "profile").await
}

/// A TOML document in the body (`application/toml`), or the same document `D` as JSON, as TOML
/// text for the loader; `what` names it in errors.
pub(super) async fn toml_body<D: serde::de::DeserializeOwned + Serialize>(req: Request, what: &str) -> Result<String, ApiError> {
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
    let text = String::from_utf8(bytes.to_vec()).map_err(|_| ApiError::BadProfile {
        message: format!("the {what} is not UTF-8"),
        key: None,
    })?;
    if !json {
        return Ok(text);
    }
    let doc: D = serde_json::from_str(&text).map_err(|e| ApiError::BadProfile {
        message: format!("request body: {e}"),
        key: None,
    })?;
    // JSON that TOML cannot hold (a null, an array of mixed tables) is the client's to fix.
    toml::to_string(&doc).map_err(|e| ApiError::BadProfile {
        message: format!("request body: the {what} as TOML: {e}"),
        key: None,
    })
}

/// A version just written (a profile, a tool table): its document, its ETag, where it is read.
pub(super) fn written<T: Kind>(status: StatusCode, c: &Current<T>, body: impl Serialize, location: &str) -> Response {
    let mut r = (status, Json(body)).into_response();
    r.headers_mut().insert(header::ETAG, etag_header(c));
    if let Ok(v) = HeaderValue::from_str(location) {
        r.headers_mut().insert(header::LOCATION, v);
    }
    r
}

/// [`written`] for a machine profile.
fn profile_written(status: StatusCode, c: &Current) -> Response {
    written(status, c, MachineDto::from(c), &format!("/v1/machines/{}", c.item.machine.id))
}

/// Adds a machine profile: validated by the same loader as the files (errors name the key).
#[utoipa::path(post, path = "/v1/machines",
    request_body(description = "The profile, as in `machines/*.toml`, or the same document as JSON",
        content((String = "application/toml"), (Object = "application/json"))),
    responses((status = 201, description = "Created", body = MachineDto, headers(("ETag" = String), ("Location" = String))),
        (status = 401, description = "No admin token given", body = Problem, content_type = "application/problem+json"),
        (status = 403, description = "Writes are off (no admin token configured)", body = Problem, content_type = "application/problem+json"),
        (status = 409, description = "The id exists", body = Problem, content_type = "application/problem+json"),
        (status = 413, description = "The body or a field is too large", body = Problem, content_type = "application/problem+json"),
        (status = 415, description = "Unsupported content type", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "Invalid profile: `key` names what to fix", body = Problem, content_type = "application/problem+json"),
        (status = 507, description = "The store's disk is full: nothing written (Retry-After)", body = Problem, content_type = "application/problem+json")),
    security(("admin" = [])),
    tag = "machines")]
pub(super) async fn create_machine(State(st): State<Arc<AppState>>, req: Request) -> Result<Response, ApiError> {
    authorize(&st, req.headers())?;
    let text = profile_text(req).await?;
    let (c, _) = st.machines.put(&text, None, Expect::Absent).await?;
    tracing::info!(machine = %c.item.machine.id, version = c.version, "machine profile created");
    Ok(profile_written(StatusCode::CREATED, &c))
}

/// Replaces (or creates) a machine profile; with `If-Match`, only if it is still that version.
#[utoipa::path(put, path = "/v1/machines/{id}", params(("id" = String, Path),
        ("If-Match" = Option<String>, Header, description = "The ETag read; the write fails (412) if the profile changed since")),
    request_body(description = "The profile (TOML, or the same document as JSON); its `id` must be the path's",
        content((String = "application/toml"), (Object = "application/json"))),
    responses((status = 200, description = "Replaced: a new version", body = MachineDto, headers(("ETag" = String))),
        (status = 201, description = "Created", body = MachineDto, headers(("ETag" = String), ("Location" = String))),
        (status = 401, description = "No admin token given", body = Problem, content_type = "application/problem+json"),
        (status = 403, description = "The admin token is wrong", body = Problem, content_type = "application/problem+json"),
        (status = 412, description = "If-Match names another version", body = Problem, content_type = "application/problem+json"),
        (status = 413, description = "The body or a field is too large", body = Problem, content_type = "application/problem+json"),
        (status = 415, description = "Unsupported content type", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "Read and refused: the problem document says why", body = Problem, content_type = "application/problem+json"),
        (status = 507, description = "The store's disk is full: nothing written (Retry-After)", body = Problem, content_type = "application/problem+json")),
    security(("admin" = [])),
    tag = "machines")]
pub(super) async fn put_machine(
    State(st): State<Arc<AppState>>,
    Path(id): Path<String>,
    req: Request,
) -> Result<Response, ApiError> {
    authorize(&st, req.headers())?;
    let expect = expectation(req.headers(), &id)?;
    let text = profile_text(req).await?;
    let (c, created) = st.machines.put(&text, Some(&id), expect).await?;
    tracing::info!(machine = %id, version = c.version, "machine profile written");
    Ok(profile_written(if created { StatusCode::CREATED } else { StatusCode::OK }, &c))
}

/// Deletes a machine profile (a version marking the deletion; jobs already queued keep theirs).
#[utoipa::path(delete, path = "/v1/machines/{id}", params(("id" = String, Path),
        ("If-Match" = Option<String>, Header, description = "Delete only this version")),
    responses((status = 204, description = "Deleted"),
        (status = 401, description = "No admin token given", body = Problem, content_type = "application/problem+json"),
        (status = 403, description = "The admin token is wrong", body = Problem, content_type = "application/problem+json"),
        (status = 404, description = "Not found", body = Problem, content_type = "application/problem+json"),
        (status = 412, description = "If-Match names another version", body = Problem, content_type = "application/problem+json"),
        (status = 507, description = "The store's disk is full: nothing written (Retry-After)", body = Problem, content_type = "application/problem+json")),
    security(("admin" = [])),
    tag = "machines")]
pub(super) async fn delete_machine(
    State(st): State<Arc<AppState>>,
    Path(id): Path<String>,
    headers: HeaderMap,
) -> Result<StatusCode, ApiError> {
    authorize(&st, &headers)?;
    let expect = expectation(&headers, &id)?;
    let v = st.machines.delete(&id, expect).await?;
    tracing::info!(machine = %id, version = v, "machine profile deleted");
    Ok(StatusCode::NO_CONTENT)
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

/// A profile's history: every version, who made it (file or API) and when.
#[utoipa::path(get, path = "/v1/machines/{id}/versions", params(("id" = String, Path)),
    responses((status = 200, description = "Success", body = VersionsDto), (status = 404, description = "Not found", body = Problem, content_type = "application/problem+json")),
    tag = "machines")]
pub(super) async fn list_versions(
    State(st): State<Arc<AppState>>,
    Path(id): Path<String>,
) -> Result<Json<VersionsDto>, ApiError> {
    versions_of(&st.machines, id.clone()).await?.map(Json).ok_or(ApiError::UnknownMachine(id))
}

/// A shelf's history of `id`; `None` when it never had one.
pub(super) async fn versions_of<T: Kind>(shelf: &Shelf<T>, id: String) -> Result<Option<VersionsDto>, ApiError> {
    let versions = match shelf.versions(&id).await {
        Err(crate::machines::Error::ReadOnly) => Vec::new(),
        r => r?,
    };
    let current = shelf.get(&id).ok();
    if versions.is_empty() && current.is_none() {
        return Ok(None);
    }
    Ok(Some(VersionsDto {
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
        id,
    }))
}

/// One version's TOML, exactly as written: what a job that used it ran with.
#[utoipa::path(get, path = "/v1/machines/{id}/versions/{version}", params(("id" = String, Path), ("version" = i64, Path)),
    responses((status = 200, description = "Success", body = String, content_type = "application/toml"),
        (status = 404, description = "No such version, or a deletion", body = Problem, content_type = "application/problem+json")),
    tag = "machines")]
pub(super) async fn get_version(
    State(st): State<Arc<AppState>>,
    Path((id, version)): Path<(String, String)>,
) -> Result<Response, ApiError> {
    version_toml(&st.machines, &id, &version).await
}

/// One version's TOML of a shelf, by the path's `version`.
pub(super) async fn version_toml<T: Kind>(shelf: &Shelf<T>, id: &str, version: &str) -> Result<Response, ApiError> {
    let v: i64 = version
        .parse()
        .map_err(|_| ApiError::NotFound(format!("no version {} of {}", quote(version), quote(id))))?;
    match shelf.text(id, v).await {
        Ok(t) => Ok(toml_response(StatusCode::OK, t)),
        Err(crate::machines::Error::ReadOnly) => Err(ApiError::NotFound("no version store in this process".into())),
        Err(e) => Err(ApiError::NotFound(e.to_string())),
    }
}

/// A mesh body's triangles, as the check reads them: binary STL, its ETag the file's digest.
#[utoipa::path(get, path = "/v1/machines/{id}/meshes/{file}", params(("id" = String, Path), ("file" = String, Path)),
    responses((status = 200, description = "Binary STL (profile units, the body's link at home)", content_type = "model/stl"),
        (status = 304, description = "Not modified (If-None-Match)"),
        (status = 404, description = "No such machine, or no body of it with this mesh", body = Problem, content_type = "application/problem+json")),
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
