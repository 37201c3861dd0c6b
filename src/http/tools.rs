//! `/v1/machines/{id}/tools`: each machine's standing tool table over HTTP, versioned as the
//! profiles are (a new version per write, ETag `"id-tools-vN"`, `If-Match`, the admin token). A
//! post or job without its own `tool_table` uses the machine's; a job records the version.

use super::AppState;
use super::error::ApiError;
use super::refusals::{AuthRefusals, BodyRefusals, MatchRefusals, NotFound, StoreBusy, StoreFull};
use super::shelf::{self, Document, VersionsDto};
use crate::machines::tools::{ToolTable, ToolTableDoc};
use crate::machines::{Current, Shelf};
use crate::text::quote;
use axum::Json;
use axum::extract::{Path, Request, State};
use axum::http::{HeaderMap, StatusCode};
use axum::response::Response;
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

impl Document for ToolTable {
    type Dto = ToolTableDto;
    type Doc = ToolTableDoc;
    const BODY: &'static str = "tool table";
    const NOUN: &'static str = "tool table";
    fn shelf(st: &AppState) -> &Shelf<ToolTable> {
        &st.machines.tools
    }
    fn dto(_: &AppState, c: &Current<ToolTable>) -> ToolTableDto {
        ToolTableDto::from(c)
    }
    fn location(id: &str) -> String {
        format!("/v1/machines/{id}/tools")
    }
    fn invalid(message: String, key: Option<String>) -> ApiError {
        ApiError::BadToolTable { message, key }
    }
    fn served_text(st: &AppState, c: &Current<ToolTable>) -> Result<String, ApiError> {
        crate::machines::read_text(&crate::machines::tools::table_path(&st.config.machines, &c.id))
            .map_err(|e| ApiError::Internal(e.to_string()))
    }
    /// No table is a machine's that has none, not an unknown machine.
    fn missing(id: &str) -> ApiError {
        ApiError::NotFound(format!("machine {} has no tool table", quote(id)))
    }
    /// The machine must exist: a table for no profile would never be used.
    fn owner(st: &AppState, id: &str) -> Result<(), ApiError> {
        st.machines
            .get(id)
            .map(|_| ())
            .map_err(|_| ApiError::UnknownMachine(id.to_string()))
    }
}

/// A machine's tool table: JSON, or its TOML exactly as stored with `Accept: application/toml`.
#[utoipa::path(get, path = "/v1/machines/{id}/tools",
    params(("id" = String, Path, description = "Profile id, e.g. fryer-5x-45")),
    responses((status = 200, description = "The table; its TOML as stored with Accept: application/toml",
            content((ToolTableDto = "application/json"), (String = "application/toml")),
            headers(("ETag" = String, description = "The version, e.g. \"fryer-5x-45-tools-v2\""))),
        (status = 304, description = "Not modified (If-None-Match)"),
        NotFound, StoreBusy),
    tag = "machines")]
pub(super) async fn get_tools(
    State(st): State<Arc<AppState>>,
    Path(id): Path<String>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    shelf::get::<ToolTable>(&st, &id, &headers).await
}

/// Replaces (or creates) a machine's tool table; with `If-Match`, only if it is still that
/// version. Posts and jobs submitted from then on use it.
#[utoipa::path(put, path = "/v1/machines/{id}/tools", params(("id" = String, Path),
        ("If-Match" = Option<String>, Header, description = "The ETag read; the write fails (412) if the table changed since")),
    request_body(description = "The table (`units`, `[[tool]]` with `number`, `length`, optional `diameter`, `corner_radius`, `holder = { diameter, length }`, `name`), as TOML or the same document as JSON",
        content((String = "application/toml"), (Object = "application/json"))),
    responses((status = 200, description = "Replaced: a new version", body = ToolTableDto, headers(("ETag" = String))),
        (status = 201, description = "Created", body = ToolTableDto, headers(("ETag" = String), ("Location" = String))),
        AuthRefusals, MatchRefusals, BodyRefusals, NotFound, StoreBusy, StoreFull),
    security(("admin" = [])),
    tag = "machines")]
pub(super) async fn put_tools(
    State(st): State<Arc<AppState>>,
    Path(id): Path<String>,
    req: Request,
) -> Result<Response, ApiError> {
    shelf::put::<ToolTable>(&st, &id, req).await
}

/// Deletes a machine's tool table (a version marking the deletion): posts go back to the CL's
/// lengths and the profile's; jobs already queued keep theirs.
#[utoipa::path(delete, path = "/v1/machines/{id}/tools", params(("id" = String, Path),
        ("If-Match" = Option<String>, Header, description = "Delete only this version")),
    responses((status = 204, description = "Deleted"), AuthRefusals, MatchRefusals, NotFound, StoreBusy, StoreFull),
    security(("admin" = [])),
    tag = "machines")]
pub(super) async fn delete_tools(
    State(st): State<Arc<AppState>>,
    Path(id): Path<String>,
    headers: HeaderMap,
) -> Result<StatusCode, ApiError> {
    shelf::delete::<ToolTable>(&st, &id, &headers).await
}

/// A tool table's history: every version, who made it (file or API) and when.
#[utoipa::path(get, path = "/v1/machines/{id}/tools/versions", params(("id" = String, Path)),
    responses((status = 200, description = "Success", body = VersionsDto), NotFound, StoreBusy),
    tag = "machines")]
pub(super) async fn list_tool_versions(
    State(st): State<Arc<AppState>>,
    Path(id): Path<String>,
) -> Result<Json<VersionsDto>, ApiError> {
    shelf::versions::<ToolTable>(&st, &id).await
}

/// One version's TOML, exactly as written: what a job that used it ran with.
#[utoipa::path(get, path = "/v1/machines/{id}/tools/versions/{version}", params(("id" = String, Path), ("version" = i64, Path)),
    responses((status = 200, description = "Success", body = String, content_type = "application/toml"), NotFound),
    tag = "machines")]
pub(super) async fn get_tool_version(
    State(st): State<Arc<AppState>>,
    Path((id, version)): Path<(String, String)>,
) -> Result<Response, ApiError> {
    shelf::version::<ToolTable>(&st, &id, &version).await
}

/// The machine's current table for a post that brings none, as `Settings::profile_options`
/// takes it: the table, and how the header names it.
pub(super) fn standing(st: &AppState, id: &str) -> Option<(Arc<ToolTable>, String)> {
    let c = st.machines.tools.get(id).ok()?;
    Some((c.item, format!("THE MACHINE'S TOOL TABLE V{}", c.version)))
}
