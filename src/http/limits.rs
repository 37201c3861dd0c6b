//! What one client may hold of the service: a post stream's slot, taken before anything is read
//! and given back when the stream ends; a form field's size.

use super::error::ApiError;
use super::{AppState, Metrics};
use axum::extract::multipart::Field;
use axum::extract::{Request, State};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use std::sync::Arc;
use std::sync::atomic::Ordering;

/// A post stream's place among `--max-streams`. It is counted before the check, so concurrent
/// requests cannot all pass it, and uncounted when dropped: the engine's thread holds it (in an
/// `Arc`, the form a request's extensions carry) until the stream has ended, however it ends.
pub(super) struct StreamSlot(Arc<Metrics>);

impl Drop for StreamSlot {
    fn drop(&mut self) {
        self.0.streams.fetch_sub(1, Ordering::AcqRel);
    }
}

/// Streams beyond the limit are refused at once (503 + Retry-After), never queued into memory.
/// The slot travels to the handler in the request's extensions.
pub(super) async fn admit_stream(State(st): State<Arc<AppState>>, mut req: Request, next: Next) -> Response {
    let before = st.metrics.streams.fetch_add(1, Ordering::AcqRel);
    let slot = Arc::new(StreamSlot(st.metrics.clone()));
    if before as usize >= st.config.max_streams {
        return ApiError::Busy(format!("{} post streams running", st.config.max_streams)).into_response();
    }
    req.extensions_mut().insert(slot);
    next.run(req).await
}

/// The most a form's text field may hold: parameters are short, and a field is read whole.
pub(super) const MAX_FIELD: usize = 64 * 1024;

/// A text field, read a chunk at a time and refused (413) once it is longer than [`MAX_FIELD`].
pub(super) async fn read_field(name: &str, mut field: Field<'_>) -> Result<String, ApiError> {
    let mut buf = Vec::new();
    while let Some(chunk) = field.chunk().await.map_err(multipart_error)? {
        if buf.len() + chunk.len() > MAX_FIELD {
            return Err(ApiError::FieldTooLarge {
                field: name.to_string(),
                limit: MAX_FIELD,
            });
        }
        buf.extend_from_slice(&chunk);
    }
    String::from_utf8(buf).map_err(|_| ApiError::BadParameter(format!("{}: not UTF-8 text", crate::text::quote(name))))
}

/// A failed multipart read: over the body limit (413), else malformed (400).
pub(super) fn multipart_error(e: axum::extract::multipart::MultipartError) -> ApiError {
    if e.status() == axum::http::StatusCode::PAYLOAD_TOO_LARGE {
        return ApiError::TooLarge(None);
    }
    ApiError::BadParameter(format!("multipart: {}", e.body_text()))
}
