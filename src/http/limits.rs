//! What one client may hold of the service: a post stream's slot, taken before anything is read
//! and given back when the stream ends.

use super::error::ApiError;
use super::{AppState, Metrics};
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
