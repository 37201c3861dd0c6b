//! One error enum for the HTTP edge, mapped to RFC 9457 problem+json in one `match`.

use axum::http::{HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::Serialize;

#[derive(Debug, thiserror::Error)]
pub enum ApiError {
    #[error("no machine profile {0:?}")]
    UnknownMachine(String),
    #[error("{0}")]
    BadParameter(String),
    #[error("unsupported content type {0:?}: send text/plain, application/octet-stream or multipart/form-data")]
    UnsupportedMediaType(String),
    #[error("not acceptable: {0:?}; this route produces text/plain or application/x-ndjson")]
    NotAcceptable(String),
    /// Strict mode, or a failure before the first byte was sent: the CL line and column.
    #[error("{message}")]
    BadRecord {
        message: String,
        line: Option<u32>,
        column: Option<u32>,
        code: &'static str,
    },
    #[error("upload larger than the limit of {0} bytes")]
    TooLarge(u64),
    #[error("{0}")]
    NotFound(String),
    #[error("{0}")]
    Conflict(String),
    #[error("server busy: {0}")]
    Busy(String),
    #[error("{0}")]
    Internal(String),
}

/// The problem document (RFC 9457) with kinepost's extensions.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct Problem {
    /// A stable URI naming the problem type, e.g. `https://kinepost.dev/problems/unknown-machine`.
    #[serde(rename = "type")]
    pub kind: String,
    pub title: String,
    pub status: u16,
    pub detail: String,
    /// CL line and column of a bad record.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub line: Option<u32>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub column: Option<u32>,
    /// The diagnostic code, for errors that come from the engine.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub code: Option<String>,
}

pub const PROBLEM_BASE: &str = "https://kinepost.dev/problems/";

impl ApiError {
    pub fn problem(&self) -> Problem {
        let (status, slug, title) = match self {
            ApiError::UnknownMachine(_) => (StatusCode::NOT_FOUND, "unknown-machine", "Unknown machine"),
            ApiError::BadParameter(_) => (StatusCode::BAD_REQUEST, "bad-parameter", "Bad parameter"),
            ApiError::UnsupportedMediaType(_) => (
                StatusCode::UNSUPPORTED_MEDIA_TYPE,
                "unsupported-media-type",
                "Unsupported media type",
            ),
            ApiError::NotAcceptable(_) => (StatusCode::NOT_ACCEPTABLE, "not-acceptable", "Not acceptable"),
            ApiError::BadRecord { .. } => (StatusCode::UNPROCESSABLE_ENTITY, "bad-record", "Bad CL record"),
            ApiError::TooLarge(_) => (StatusCode::PAYLOAD_TOO_LARGE, "too-large", "Upload too large"),
            ApiError::NotFound(_) => (StatusCode::NOT_FOUND, "not-found", "Not found"),
            ApiError::Conflict(_) => (StatusCode::CONFLICT, "conflict", "Conflict"),
            ApiError::Busy(_) => (StatusCode::SERVICE_UNAVAILABLE, "busy", "Server busy"),
            ApiError::Internal(_) => (StatusCode::INTERNAL_SERVER_ERROR, "internal", "Internal error"),
        };
        let (line, column, code) = match self {
            ApiError::BadRecord { line, column, code, .. } => (*line, *column, Some(code.to_string())),
            _ => (None, None, None),
        };
        Problem {
            kind: format!("{PROBLEM_BASE}{slug}"),
            title: title.into(),
            status: status.as_u16(),
            detail: self.to_string(),
            line,
            column,
            code,
        }
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let p = self.problem();
        let status = StatusCode::from_u16(p.status).unwrap_or(StatusCode::INTERNAL_SERVER_ERROR);
        let mut r = (status, serde_json::to_string(&p).unwrap_or_default()).into_response();
        r.headers_mut()
            .insert(header::CONTENT_TYPE, HeaderValue::from_static("application/problem+json"));
        if matches!(self, ApiError::Busy(_)) {
            r.headers_mut().insert(header::RETRY_AFTER, HeaderValue::from_static("5"));
        }
        r
    }
}

/// `Json<T>` whose rejections are problem documents like every other error (400, or 415 for a
/// missing JSON content type), not axum's plain text.
pub struct ApiJson<T>(pub T);

impl<T: serde::de::DeserializeOwned, S: Send + Sync> axum::extract::FromRequest<S> for ApiJson<T> {
    type Rejection = ApiError;

    async fn from_request(req: axum::extract::Request, state: &S) -> Result<Self, Self::Rejection> {
        use axum::extract::rejection::JsonRejection;
        match axum::Json::<T>::from_request(req, state).await {
            Ok(axum::Json(v)) => Ok(ApiJson(v)),
            Err(JsonRejection::MissingJsonContentType(_)) => {
                Err(ApiError::UnsupportedMediaType("expected application/json".into()))
            }
            Err(e) => Err(ApiError::BadParameter(e.body_text())),
        }
    }
}

/// `Query<T>` whose rejections are problem documents (400) naming the parameter.
pub struct ApiQuery<T>(pub T);

impl<T: serde::de::DeserializeOwned, S: Send + Sync> axum::extract::FromRequestParts<S> for ApiQuery<T> {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut axum::http::request::Parts, state: &S) -> Result<Self, Self::Rejection> {
        match axum::extract::Query::<T>::from_request_parts(parts, state).await {
            Ok(axum::extract::Query(v)) => Ok(ApiQuery(v)),
            Err(e) => Err(ApiError::BadParameter(e.body_text())),
        }
    }
}
