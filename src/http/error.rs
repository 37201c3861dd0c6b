//! One error enum for the HTTP edge, mapped to RFC 9457 problem+json in one `match`.

use crate::text::quote;
use axum::http::{HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::Serialize;

#[derive(Debug, thiserror::Error)]
pub enum ApiError {
    #[error("no machine profile {}", quote(.0))]
    UnknownMachine(String),
    #[error("{0}")]
    BadParameter(String),
    /// A post setting refused: the problem names its field.
    #[error("{0}")]
    BadSetting(#[from] crate::post::SettingError),
    #[error("unsupported content type {}: send text/plain, application/octet-stream or multipart/form-data", quote(.0))]
    UnsupportedMediaType(String),
    #[error("not acceptable: {}; this route produces text/plain or application/x-ndjson", quote(.0))]
    NotAcceptable(String),
    /// Strict mode, or a failure before the first byte was sent: the CL line and column.
    #[error("{message}")]
    BadRecord {
        message: String,
        line: Option<u32>,
        column: Option<u32>,
        code: &'static str,
    },
    /// The upload is no CL data (an NC program, nothing recognisable): the line it is told by.
    #[error("{message}")]
    NotCl { message: String, line: Option<u32> },
    /// The upload is a lathe's program (code `turning`): CL data, but kinepost posts milling.
    /// Its own problem, so that a client tells "wrong file" from "wrong kind of machine".
    #[error("{message}")]
    Turning { message: String, line: Option<u32> },
    /// The limit in bytes where the handler knows it (else the service's `--max-upload`).
    #[error("upload larger than {}", .0.map_or("the service's limit (--max-upload)".to_string(), |n| format!("the limit of {n} bytes")))]
    TooLarge(Option<u64>),
    /// A form's text field longer than the service reads for one.
    #[error("form field {} is longer than the limit of {limit} bytes", quote(.field))]
    FieldTooLarge { field: String, limit: usize },
    /// The client sent its upload slower than `--min-upload-rate`.
    #[error("{0}")]
    UploadTooSlow(String),
    /// A non-streaming request over `--request-timeout`.
    #[error("{0}")]
    Timeout(String),
    #[error("{0}")]
    NotFound(String),
    #[error("{0}")]
    Conflict(String),
    #[error("server busy: {0}")]
    Busy(String),
    #[error("{0}")]
    Internal(String),
    /// A profile the loader rejects; `key` names what to fix when the loader knows it.
    #[error("{message}")]
    BadProfile { message: String, key: Option<String> },
    /// A tool table the loader refused: `key` names the entry to fix.
    #[error("{message}")]
    BadToolTable { message: String, key: Option<String> },
    /// A dialect its loader refused (a key, a template and its line).
    #[error("{0}")]
    BadDialect(String),
    #[error("{0}")]
    Unauthorized(String),
    #[error("{0}")]
    Forbidden(String),
    /// `If-Match` names another version than the current one.
    #[error("{0}")]
    PreconditionFailed(String),
    /// A per-client limit (jobs queued or running).
    #[error("{0}")]
    TooManyRequests(String),
    /// The server's disk is full: the request was not accepted (retry later or elsewhere).
    #[error("{0}")]
    InsufficientStorage(String),
    /// An Idempotency-Key already given with another request (`POST /v1/jobs`).
    #[error("{0}")]
    KeyReused(String),
    /// The post went over the server's bound on output per CL byte or on time.
    #[error("{0}")]
    OverBudget(String),
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
    /// The profile key to fix (`rotary[0].axis`), for an invalid machine profile.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub key: Option<String>,
    /// The request's field to fix (`feed_mode`), for a post setting refused.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub field: Option<String>,
}

pub const PROBLEM_BASE: &str = "https://kinepost.dev/problems/";

impl ApiError {
    pub fn problem(&self) -> Problem {
        let (status, slug, title) = match self {
            ApiError::UnknownMachine(_) => (StatusCode::NOT_FOUND, "unknown-machine", "Unknown machine"),
            ApiError::BadParameter(_) | ApiError::BadSetting(_) => (StatusCode::BAD_REQUEST, "bad-parameter", "Bad parameter"),
            ApiError::UnsupportedMediaType(_) => (
                StatusCode::UNSUPPORTED_MEDIA_TYPE,
                "unsupported-media-type",
                "Unsupported media type",
            ),
            ApiError::NotAcceptable(_) => (StatusCode::NOT_ACCEPTABLE, "not-acceptable", "Not acceptable"),
            ApiError::BadRecord { .. } => (StatusCode::UNPROCESSABLE_ENTITY, "bad-record", "Bad CL record"),
            ApiError::NotCl { .. } => (StatusCode::UNPROCESSABLE_ENTITY, "not-cl-data", "Not CL data"),
            ApiError::Turning { .. } => (StatusCode::UNPROCESSABLE_ENTITY, "turning", "A turning program: kinepost posts milling"),
            ApiError::TooLarge(_) => (StatusCode::PAYLOAD_TOO_LARGE, "too-large", "Upload too large"),
            ApiError::FieldTooLarge { .. } => (StatusCode::PAYLOAD_TOO_LARGE, "field-too-large", "Form field too large"),
            ApiError::UploadTooSlow(_) => (StatusCode::REQUEST_TIMEOUT, "upload-too-slow", "Upload too slow"),
            ApiError::Timeout(_) => (StatusCode::REQUEST_TIMEOUT, "request-timeout", "Request timed out"),
            ApiError::NotFound(_) => (StatusCode::NOT_FOUND, "not-found", "Not found"),
            ApiError::Conflict(_) => (StatusCode::CONFLICT, "conflict", "Conflict"),
            ApiError::Busy(_) => (StatusCode::SERVICE_UNAVAILABLE, "busy", "Server busy"),
            ApiError::Internal(_) => (StatusCode::INTERNAL_SERVER_ERROR, "internal", "Internal error"),
            ApiError::BadProfile { .. } => (StatusCode::UNPROCESSABLE_ENTITY, "bad-profile", "Invalid machine profile"),
            ApiError::BadToolTable { .. } => (StatusCode::UNPROCESSABLE_ENTITY, "bad-tool-table", "Invalid tool table"),
            ApiError::BadDialect(_) => (StatusCode::UNPROCESSABLE_ENTITY, "bad-dialect", "Invalid dialect"),
            ApiError::Unauthorized(_) => (StatusCode::UNAUTHORIZED, "unauthorized", "Unauthorized"),
            ApiError::Forbidden(_) => (StatusCode::FORBIDDEN, "forbidden", "Forbidden"),
            ApiError::PreconditionFailed(_) => (StatusCode::PRECONDITION_FAILED, "precondition-failed", "Precondition failed"),
            ApiError::TooManyRequests(_) => (StatusCode::TOO_MANY_REQUESTS, "too-many-requests", "Too many requests"),
            ApiError::InsufficientStorage(_) => (
                StatusCode::INSUFFICIENT_STORAGE,
                "insufficient-storage",
                "Insufficient storage",
            ),
            ApiError::OverBudget(_) => (StatusCode::UNPROCESSABLE_ENTITY, "over-budget", "Post over its bound"),
            ApiError::KeyReused(_) => (
                StatusCode::UNPROCESSABLE_ENTITY,
                "idempotency-key-reused",
                "Idempotency-Key reused with another request",
            ),
        };
        let (line, column, code) = match self {
            ApiError::BadRecord { line, column, code, .. } => (*line, *column, Some(code.to_string())),
            ApiError::NotCl { line, .. } => (*line, None, Some(crate::diag::Code::NotCl.as_str().to_string())),
            ApiError::Turning { line, .. } => (*line, None, Some(crate::diag::Code::Turning.as_str().to_string())),
            _ => (None, None, None),
        };
        let key = match self {
            ApiError::BadProfile { key, .. } | ApiError::BadToolTable { key, .. } => key.clone(),
            _ => None,
        };
        Problem {
            kind: format!("{PROBLEM_BASE}{slug}"),
            title: title.into(),
            status: status.as_u16(),
            detail: self.to_string(),
            line,
            column,
            code,
            key,
            field: match self {
                ApiError::BadSetting(e) => Some(e.field.to_string()),
                _ => None,
            },
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
        if matches!(
            self,
            ApiError::Busy(_) | ApiError::InsufficientStorage(_) | ApiError::TooManyRequests(_)
        ) {
            r.headers_mut().insert(header::RETRY_AFTER, HeaderValue::from_static("5"));
        }
        if matches!(self, ApiError::Unauthorized(_)) {
            r.headers_mut().insert(
                header::WWW_AUTHENTICATE,
                HeaderValue::from_static("Bearer realm=\"kinepost\""),
            );
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
            // Over axum's body limit for JSON (2 MiB): too large, not malformed.
            Err(e) if e.status() == StatusCode::PAYLOAD_TOO_LARGE => Err(ApiError::TooLarge(Some(2 << 20))),
            Err(e) => Err(ApiError::BadParameter(clip_quoted(&e.body_text()))),
        }
    }
}

/// A parser's message (serde's) with each value it quotes, and each word longer than a value is
/// quoted (a map key or an unknown parameter in a path), cut as [`quote`] cuts it, and at most
/// `LIMIT` characters in all: serde echoes what it met whole, and that comes from the client.
fn clip_quoted(msg: &str) -> String {
    const LIMIT: usize = 600;
    let keep = crate::text::QUOTED;
    let mut out = String::new();
    let mut open: Option<char> = None;
    // Characters of the current quoted value or word, and whether the last one was a backslash.
    let (mut run, mut escaped) = (0, false);
    let mut written = 0;
    for c in msg.chars() {
        if written == LIMIT {
            out.push('…');
            return out;
        }
        let ends = match open {
            Some(q) => c == q && !escaped,
            None => c.is_whitespace() || c == '"' || c == '`',
        };
        escaped = open.is_some() && c == '\\' && !escaped;
        if ends {
            if run > keep {
                out.push('…');
            }
            out.push(c);
            written += 1;
            run = 0;
            open = match open {
                Some(_) => None,
                None => (c == '"' || c == '`').then_some(c),
            };
        } else {
            if run < keep {
                out.push(c);
                written += 1;
            }
            run += 1;
        }
    }
    if run > keep {
        out.push('…');
    }
    out
}

/// `Query<T>` whose rejections are problem documents (400) naming the parameter.
pub struct ApiQuery<T>(pub T);

impl<T: serde::de::DeserializeOwned, S: Send + Sync> axum::extract::FromRequestParts<S> for ApiQuery<T> {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut axum::http::request::Parts, state: &S) -> Result<Self, Self::Rejection> {
        match axum::extract::Query::<T>::from_request_parts(parts, state).await {
            Ok(axum::extract::Query(v)) => Ok(ApiQuery(v)),
            Err(e) => Err(ApiError::BadParameter(clip_quoted(&e.body_text()))),
        }
    }
}

impl From<crate::machines::Error> for ApiError {
    fn from(e: crate::machines::Error) -> Self {
        use crate::machines::Error as E;
        match e {
            E::NotFound(id) => ApiError::UnknownMachine(id),
            E::Invalid { ref key, .. } => ApiError::BadProfile {
                key: (!key.is_empty()).then(|| key.clone()),
                message: e.to_string(),
            },
            E::Parse { .. } => ApiError::BadProfile {
                key: None,
                message: e.to_string(),
            },
            E::Exists { .. } => ApiError::Conflict(e.to_string()),
            E::Precondition { .. } => ApiError::PreconditionFailed(e.to_string()),
            E::ReadOnly => ApiError::Forbidden(e.to_string()),
            E::NoSpace(_) => ApiError::InsufficientStorage(e.to_string()),
            E::Unavailable(_) => ApiError::Busy(e.to_string()),
            E::Io { .. } | E::Store(_) => ApiError::Internal(e.to_string()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::clip_quoted;

    #[test]
    fn quoted_values_in_parser_messages_are_cut() {
        let long = "x".repeat(10_000);
        let m = clip_quoted(&format!("unknown field `{long}`, expected one of `machine`"));
        assert_eq!(m, format!("unknown field `{}…`, expected one of `machine`", "x".repeat(80)));
        let m = clip_quoted(&format!(
            "invalid type: string \"a\\\"{long}\", expected f64 at line 1 column 9"
        ));
        assert!(m.len() < 200 && m.ends_with("expected f64 at line 1 column 9"), "{m}");
        let m = clip_quoted(&format!("query string: joints.{long}: invalid"));
        assert_eq!(m, format!("query string: joints.{}… invalid", "x".repeat(73)));
    }
}
