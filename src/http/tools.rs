//! `/v1/machines/{id}/tools`: each machine's standing tool table over HTTP, versioned as the
//! profiles are (a new version per write, ETag `"id-tools-vN"`, `If-Match`, the admin token). A
//! post or job without its own `tool_table` uses the machine's; a job records the version.

use super::AppState;
use super::error::{ApiError, Problem};
use super::machines::{
    VersionsDto, authorize, etag_header, expectation_of, toml_body, toml_response, version_toml, versions_of, wants_toml, written,
};
use crate::machines::Current;
use crate::machines::tools::{ToolTable, ToolTableDoc};
use crate::text::quote;
use axum::Json;
use axum::extract::{Path, Request, State};
use axum::http::{HeaderMap, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::Serialize;
use std::sync::Arc;

/// A machine's tool table as the API shows it.
#[derive(Serialize, utoipa::ToSchema)]
pub struct ToolTableDto {
    pub machine: String,
    /// This table's version: each write makes a new one (`…/tools/versions`).
    pub version: i64,
    /// `file` (`machines/<id>.tools.toml`) or `api`.
    pub source: String,
    /// `mm` or `inch`: every length of the table.
    pub units: String,
    pub tools: Vec<ToolDto>,
}

#[derive(Serialize, utoipa::ToSchema)]
pub struct ToolDto {
    pub number: u32,
    /// Gauge line to tip.
    pub length: f64,
    pub diameter: Option<f64>,
    pub corner_radius: Option<f64>,
    pub holder: Option<HolderDto>,
    pub name: Option<String>,
}

#[derive(Serialize, utoipa::ToSchema)]
pub struct HolderDto {
    pub diameter: f64,
    pub length: f64,
}

impl From<&Current<ToolTable>> for ToolTableDto {
    fn from(c: &Current<ToolTable>) -> Self {
        ToolTableDto {
            machine: c.id.clone(),
            version: c.version,
            source: c.source.as_str().into(),
            units: c.item.units.as_str().into(),
            tools: c
                .item
                .iter()
                .map(|t| ToolDto {
                    number: t.number,
                    length: t.length,
                    diameter: t.diameter,
                    corner_radius: t.corner_radius,
                    holder: t.holder.map(|h| HolderDto {
                        diameter: h.diameter,
                        length: h.length,
                    }),
                    name: t.name.clone(),
                })
                .collect(),
        }
    }
}

/// The machine must exist: a table for no profile would never be used.
fn machine(st: &AppState, id: &str) -> Result<(), ApiError> {
    st.machines
        .get(id)
        .map(|_| ())
        .map_err(|_| ApiError::UnknownMachine(id.to_string()))
}

fn no_table(id: &str) -> ApiError {
    ApiError::NotFound(format!("machine {} has no tool table", quote(id)))
}

/// A machine's tool table: JSON, or its TOML exactly as stored with `Accept: application/toml`.
#[utoipa::path(get, path = "/v1/machines/{id}/tools",
    params(("id" = String, Path, description = "Profile id, e.g. fryer-5x-45")),
    responses((status = 200, description = "The table; its TOML as stored with Accept: application/toml",
            content((ToolTableDto = "application/json"), (String = "application/toml")),
            headers(("ETag" = String, description = "The version, e.g. \"fryer-5x-45-tools-v2\""))),
        (status = 304, description = "Not modified (If-None-Match)"),
        (status = 404, description = "No such machine, or it has no tool table", body = Problem, content_type = "application/problem+json")),
    tag = "machines")]
pub(super) async fn get_tools(
    State(st): State<Arc<AppState>>,
    Path(id): Path<String>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    machine(&st, &id)?;
    let c = st.machines.tools.get(&id).map_err(|_| no_table(&id))?;
    if let Some(r) = super::not_modified(&headers, &c.etag()) {
        return Ok(r);
    }
    let mut r = if wants_toml(&headers) {
        let text = match st.machines.tools.text(&id, c.version).await {
            Ok(t) => t,
            // Files only: no store to hold the text; the file's own words.
            Err(crate::machines::Error::ReadOnly) => {
                crate::machines::read_text(&crate::machines::tools::table_path(&st.config.machines, &id))
                    .map_err(|e| ApiError::Internal(e.to_string()))?
            }
            Err(e) => return Err(e.into()),
        };
        toml_response(StatusCode::OK, text)
    } else {
        Json(ToolTableDto::from(&c)).into_response()
    };
    r.headers_mut().insert(header::ETAG, etag_header(&c));
    Ok(r)
}

/// Replaces (or creates) a machine's tool table; with `If-Match`, only if it is still that
/// version. Posts and jobs submitted from then on use it.
#[utoipa::path(put, path = "/v1/machines/{id}/tools", params(("id" = String, Path),
        ("If-Match" = Option<String>, Header, description = "The ETag read; the write fails (412) if the table changed since")),
    request_body(description = "The table (`units`, `[[tool]]` with `number`, `length`, optional `diameter`, `corner_radius`, `holder = { diameter, length }`, `name`), as TOML or the same document as JSON",
        content((String = "application/toml"), (Object = "application/json"))),
    responses((status = 200, description = "Replaced: a new version", body = ToolTableDto, headers(("ETag" = String))),
        (status = 201, description = "Created", body = ToolTableDto, headers(("ETag" = String), ("Location" = String))),
        (status = 401, description = "No admin token given", body = Problem, content_type = "application/problem+json"),
        (status = 403, description = "The admin token is wrong", body = Problem, content_type = "application/problem+json"),
        (status = 404, description = "No such machine", body = Problem, content_type = "application/problem+json"),
        (status = 412, description = "If-Match names another version", body = Problem, content_type = "application/problem+json"),
        (status = 413, description = "The body or a field is too large", body = Problem, content_type = "application/problem+json"),
        (status = 415, description = "Unsupported content type", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "Invalid table: `key` names the entry to fix", body = Problem, content_type = "application/problem+json"),
        (status = 507, description = "The store's disk is full: nothing written (Retry-After)", body = Problem, content_type = "application/problem+json")),
    security(("admin" = [])),
    tag = "machines")]
pub(super) async fn put_tools(
    State(st): State<Arc<AppState>>,
    Path(id): Path<String>,
    req: Request,
) -> Result<Response, ApiError> {
    authorize(&st, req.headers())?;
    machine(&st, &id)?;
    let expect = expectation_of::<ToolTable>(req.headers(), &id)?;
    // The loader's refusals are the table's, not a profile's.
    let table_err = |e: ApiError| match e {
        ApiError::BadProfile { message, key } => ApiError::BadToolTable { message, key },
        e => e,
    };
    let text = toml_body::<ToolTableDoc>(req, "tool table").await.map_err(table_err)?;
    let (c, created) = st.machines.tools.put(&text, Some(&id), expect).await.map_err(|e| table_err(e.into()))?;
    tracing::info!(machine = %id, version = c.version, "tool table written");
    let status = if created { StatusCode::CREATED } else { StatusCode::OK };
    Ok(written(status, &c, ToolTableDto::from(&c), &format!("/v1/machines/{id}/tools")))
}

/// Deletes a machine's tool table (a version marking the deletion): posts go back to the CL's
/// lengths and the profile's; jobs already queued keep theirs.
#[utoipa::path(delete, path = "/v1/machines/{id}/tools", params(("id" = String, Path),
        ("If-Match" = Option<String>, Header, description = "Delete only this version")),
    responses((status = 204, description = "Deleted"),
        (status = 401, description = "No admin token given", body = Problem, content_type = "application/problem+json"),
        (status = 403, description = "The admin token is wrong", body = Problem, content_type = "application/problem+json"),
        (status = 404, description = "Not found", body = Problem, content_type = "application/problem+json"),
        (status = 412, description = "If-Match names another version", body = Problem, content_type = "application/problem+json"),
        (status = 507, description = "The store's disk is full: nothing written (Retry-After)", body = Problem, content_type = "application/problem+json")),
    security(("admin" = [])),
    tag = "machines")]
pub(super) async fn delete_tools(
    State(st): State<Arc<AppState>>,
    Path(id): Path<String>,
    headers: HeaderMap,
) -> Result<StatusCode, ApiError> {
    authorize(&st, &headers)?;
    let expect = expectation_of::<ToolTable>(&headers, &id)?;
    let v = match st.machines.tools.delete(&id, expect).await {
        Err(crate::machines::Error::NotFound(_)) => return Err(no_table(&id)),
        r => r?,
    };
    tracing::info!(machine = %id, version = v, "tool table deleted");
    Ok(StatusCode::NO_CONTENT)
}

/// A tool table's history: every version, who made it (file or API) and when.
#[utoipa::path(get, path = "/v1/machines/{id}/tools/versions", params(("id" = String, Path)),
    responses((status = 200, description = "Success", body = VersionsDto), (status = 404, description = "Not found", body = Problem, content_type = "application/problem+json")),
    tag = "machines")]
pub(super) async fn list_tool_versions(
    State(st): State<Arc<AppState>>,
    Path(id): Path<String>,
) -> Result<Json<VersionsDto>, ApiError> {
    versions_of(&st.machines.tools, id.clone())
        .await?
        .map(Json)
        .ok_or_else(|| no_table(&id))
}

/// One version's TOML, exactly as written: what a job that used it ran with.
#[utoipa::path(get, path = "/v1/machines/{id}/tools/versions/{version}", params(("id" = String, Path), ("version" = i64, Path)),
    responses((status = 200, description = "Success", body = String, content_type = "application/toml"),
        (status = 404, description = "No such version, or a deletion", body = Problem, content_type = "application/problem+json")),
    tag = "machines")]
pub(super) async fn get_tool_version(
    State(st): State<Arc<AppState>>,
    Path((id, version)): Path<(String, String)>,
) -> Result<Response, ApiError> {
    version_toml(&st.machines.tools, &id, &version).await
}

/// The machine's current table for a post that brings none, as `Settings::profile_options`
/// takes it: the table, and how the header names it.
pub(super) fn standing(st: &AppState, id: &str) -> Option<(Arc<ToolTable>, String)> {
    let c = st.machines.tools.get(id).ok()?;
    Some((c.item, format!("THE MACHINE'S TOOL TABLE V{}", c.version)))
}
