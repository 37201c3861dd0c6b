//! The statuses each family of routes refuses with, as types the OpenAPI document is derived
//! from (`responses(…, Refusals)` in a route's `#[utoipa::path]`): written once per family,
//! not copied into every route, so that what is documented is what the family's code answers.
//! Every refusal is a problem document ([`Problem`], `application/problem+json`); which
//! `ApiError` gives which status stays the one `match` of `error.rs`.
//!
//! `tests/it/http.rs` provokes each refusal on each route it is documented for, and each status a
//! route answers must be documented for it. A server fault (500) is no route's contract and is
//! documented nowhere.

use super::error::Problem;
use utoipa::IntoResponses;

/// A write's admin token (`authorize`).
#[derive(IntoResponses)]
pub enum AuthRefusals {
    #[response(status = 401, description = "No admin token given, or not the admin token (WWW-Authenticate)", content_type = "application/problem+json")]
    Unauthorized(Problem),
    #[response(status = 403, description = "Writes are off: no admin token configured, or no version store in this process", content_type = "application/problem+json")]
    Forbidden(Problem),
}

/// A write's document in the body: TOML, or the same document as JSON, read by the files' loader.
#[derive(IntoResponses)]
pub enum BodyRefusals {
    #[response(status = 413, description = "The body is over 1 MiB", content_type = "application/problem+json")]
    TooLarge(Problem),
    #[response(status = 415, description = "Not application/toml or application/json", content_type = "application/problem+json")]
    UnsupportedMediaType(Problem),
    #[response(status = 422, description = "Invalid: the problem document says why (`key` names what to fix; a dialect: the key, or the template and its line)", content_type = "application/problem+json")]
    Invalid(Problem),
}

/// A write under `If-Match` (`PUT`, `DELETE`).
#[derive(IntoResponses)]
pub enum MatchRefusals {
    #[response(status = 400, description = "If-Match is not visible ASCII", content_type = "application/problem+json")]
    BadParameter(Problem),
    #[response(status = 412, description = "If-Match names another version, or is no ETag of this document", content_type = "application/problem+json")]
    PreconditionFailed(Problem),
}

/// A create (`POST`, the id in the body) of an id that exists.
#[derive(IntoResponses)]
#[response(status = 409, description = "The id exists: replace it with PUT", content_type = "application/problem+json")]
pub struct Conflict(pub Problem);

/// What the path names is not there.
#[derive(IntoResponses)]
#[response(status = 404, description = "Not found: the problem document says what", content_type = "application/problem+json")]
pub struct NotFound(pub Problem);

/// The store of versions did not answer now (a database restarting, a lost connection).
#[derive(IntoResponses)]
#[response(status = 503, description = "The store is not answering now: nothing written (Retry-After)", content_type = "application/problem+json")]
pub struct StoreBusy(pub Problem);

/// The store's disk is full.
#[derive(IntoResponses)]
#[response(status = 507, description = "The store's disk is full: nothing written (Retry-After)", content_type = "application/problem+json")]
pub struct StoreFull(pub Problem);

/// A job's routes: the queue must be running in this process and its store answering.
#[derive(IntoResponses)]
#[response(status = 503, description = "The job store is not answering now, or this process runs no job queue (Retry-After)", content_type = "application/problem+json")]
pub struct QueueBusy(pub Problem);

/// A download (a job's outputs and input, a mesh) beyond the client's downloads in flight
/// (`--max-downloads-per-client`, `limits::admit_download`).
#[derive(IntoResponses)]
#[response(status = 429, description = "This client has its limit of downloads in flight (Retry-After)", content_type = "application/problem+json")]
pub struct TooManyDownloads(pub Problem);

/// A computation on one machine with a JSON request (FK, IK, reach, the fits).
#[derive(IntoResponses)]
pub enum MachineOpRefusals {
    #[response(status = 400, description = "A parameter is malformed: the problem document names it", content_type = "application/problem+json")]
    BadParameter(Problem),
    #[response(status = 404, description = "No such machine", content_type = "application/problem+json")]
    UnknownMachine(Problem),
    #[response(status = 413, description = "The JSON body is over 2 MiB", content_type = "application/problem+json")]
    TooLarge(Problem),
    #[response(status = 415, description = "Not application/json", content_type = "application/problem+json")]
    UnsupportedMediaType(Problem),
}

/// A CL upload (`POST /v1/post`, `POST /v1/jobs`, [`super::upload::ClUpload`]): the body raw or
/// as a form, its parameters, its machine.
#[derive(IntoResponses)]
pub enum UploadRefusals {
    #[response(status = 400, description = "Bad parameter, or a malformed form: the problem document names it", content_type = "application/problem+json")]
    BadParameter(Problem),
    #[response(status = 404, description = "Unknown machine", content_type = "application/problem+json")]
    UnknownMachine(Problem),
    #[response(status = 408, description = "Upload slower than --min-upload-rate: a job is not accepted; a post stream that has begun ends with the error instead", content_type = "application/problem+json")]
    UploadTooSlow(Problem),
    #[response(status = 413, description = "Upload too large, or a form field over 64 KiB", content_type = "application/problem+json")]
    TooLarge(Problem),
    #[response(status = 415, description = "Not text/plain, application/octet-stream or multipart/form-data", content_type = "application/problem+json")]
    UnsupportedMediaType(Problem),
}

/// The error statuses the OpenAPI document lists for each operation, by method (lower case)
/// and path as the router names it (`/v1/machines/{id}`).
fn listed() -> &'static std::collections::HashMap<(String, String), Vec<u16>> {
    static LISTED: std::sync::OnceLock<std::collections::HashMap<(String, String), Vec<u16>>> = std::sync::OnceLock::new();
    LISTED.get_or_init(|| {
        let doc: serde_json::Value = serde_json::from_str(&super::openapi_json()).unwrap_or_default();
        let mut map = std::collections::HashMap::new();
        for (path, ops) in doc["paths"].as_object().into_iter().flatten() {
            for (method, op) in ops.as_object().into_iter().flatten() {
                let statuses = op["responses"].as_object().into_iter().flatten().filter_map(|(s, _)| s.parse().ok()).collect();
                map.insert((method.clone(), path.clone()), statuses);
            }
        }
        map
    })
}

/// Debug builds (every test): a route that refuses with a status its OpenAPI responses do not
/// list fails where it answers, so the document cannot drift from the code again. A server
/// fault (500) is no contract; routes the document leaves out (the page's files) are not
/// checked, nor what the layers outside the routes answer (the request timeout's 408).
#[cfg(debug_assertions)]
pub(super) async fn undocumented_refusal(
    matched: Option<axum::extract::MatchedPath>,
    req: axum::extract::Request,
    next: axum::middleware::Next,
) -> axum::response::Response {
    let method = req.method().as_str().to_ascii_lowercase();
    let resp = next.run(req).await;
    let status = resp.status();
    let refused = status.is_client_error() || (status.is_server_error() && status.as_u16() != 500);
    if let Some(path) = matched.filter(|_| refused)
        && let Some(statuses) = listed().get(&(method.clone(), path.as_str().to_string()))
    {
        assert!(
            statuses.contains(&status.as_u16()),
            "{} {} answered {status}, which its OpenAPI responses do not list ({statuses:?}): add it to the route's refusals",
            method.to_ascii_uppercase(),
            path.as_str(),
        );
    }
    resp
}
