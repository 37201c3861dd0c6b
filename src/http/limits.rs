//! What one client may hold of the service: a post stream's slot, taken before anything is read
//! and given back when the stream ends; its downloads in flight; an upload's pace; a form
//! field's size.

use super::error::ApiError;
use super::{AppState, Metrics};
use axum::body::Body;
use axum::extract::multipart::Field;
use axum::extract::{Request, State};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use bytes::Bytes;
use futures_util::StreamExt;
use std::sync::Arc;
use std::time::Duration;

/// A post stream's place among `--max-streams`. It is counted before the check, so concurrent
/// requests cannot all pass it, and uncounted when dropped: the engine's thread holds it (in an
/// `Arc`, the form a request's extensions carry) until the stream has ended, however it ends.
pub(super) struct StreamSlot(Arc<Metrics>);

impl Drop for StreamSlot {
    fn drop(&mut self) {
        self.0.stream_ended();
    }
}

/// Streams beyond the limit are refused at once (503 + Retry-After), never queued into memory.
/// The slot travels to the handler in the request's extensions.
pub(super) async fn admit_stream(State(st): State<Arc<AppState>>, mut req: Request, next: Next) -> Response {
    let before = st.metrics.stream_started();
    let slot = Arc::new(StreamSlot(st.metrics.clone()));
    if before as usize >= st.config.max_streams {
        return ApiError::Busy(format!("{} post streams running", st.config.max_streams)).into_response();
    }
    req.extensions_mut().insert(slot);
    next.run(req).await
}

/// The downloads in flight by client address: one client's stalled downloads hold their files
/// and buffers until the write deadline cuts them, so their number is bounded per client.
#[derive(Default)]
pub struct Downloads(std::sync::Mutex<std::collections::HashMap<std::net::IpAddr, usize>>);

impl Downloads {
    fn lock(&self) -> std::sync::MutexGuard<'_, std::collections::HashMap<std::net::IpAddr, usize>> {
        self.0.lock().unwrap_or_else(|p| p.into_inner())
    }
}

/// A download's place among its client's, given back when its body is dropped (sent or cut).
struct DownloadSlot(Arc<AppState>, std::net::IpAddr);

impl Drop for DownloadSlot {
    fn drop(&mut self) {
        let mut m = self.0.metrics.downloads.lock();
        if let Some(n) = m.get_mut(&self.1) {
            *n -= 1;
            if *n == 0 {
                m.remove(&self.1);
            }
        }
    }
}

/// Download routes: a client with `--max-downloads-per-client` in flight is answered 429 (with
/// Retry-After); a slot is held until the response's body is sent or dropped.
pub(super) async fn admit_download(State(st): State<Arc<AppState>>, req: Request, next: Next) -> Response {
    let limit = st.config.max_downloads_per_client;
    let Some(ip) = req
        .extensions()
        .get::<axum::extract::ConnectInfo<std::net::SocketAddr>>()
        .map(|c| c.0.ip())
    else {
        return next.run(req).await;
    };
    if limit == 0 {
        return next.run(req).await;
    }
    {
        let mut m = st.metrics.downloads.lock();
        let n = m.entry(ip).or_default();
        if *n >= limit {
            return ApiError::TooManyRequests(format!(
                "this client has {limit} downloads in flight (--max-downloads-per-client)"
            ))
            .into_response();
        }
        *n += 1;
    }
    let slot = DownloadSlot(st.clone(), ip);
    next.run(req).await.map(|b| {
        Body::new(http_body_util::BodyExt::map_frame(b, move |f| {
            let _ = &slot;
            f
        }))
    })
}

/// What every too-slow upload's message starts with, however many layers it passed through.
const TOO_SLOW: &str = "upload slower than the minimum of";

/// The upload error text names a client that sent too slowly: its message from there on.
pub(super) fn too_slow(text: &str) -> Option<&str> {
    text.find(TOO_SLOW).map(|i| &text[i..])
}

/// An error whose chain of sources says the upload was too slow, as the error the client gets.
pub(super) fn too_slow_in(e: &(dyn std::error::Error + 'static)) -> Option<ApiError> {
    std::iter::successors(Some(e), |e| e.source())
        .find_map(|e| too_slow(&e.to_string()).map(|m| ApiError::UploadTooSlow(m.to_string())))
}

/// Upload routes: a body that arrives slower than `--min-upload-rate` (bytes a second, averaged
/// over `--upload-rate-window`) fails, so that trickling clients cannot hold slots for ever.
pub(super) async fn min_upload_rate(State(st): State<Arc<AppState>>, req: Request, next: Next) -> Response {
    let (rate, window) = (st.config.min_upload_rate, st.config.upload_rate_window);
    if rate == 0 || window.is_zero() {
        return next.run(req).await;
    }
    next.run(req.map(|b| metered(b, rate, window))).await
}

/// The body, failing once a window of time spent waiting for the client has brought fewer than
/// `rate × window` bytes. Only time the server waits counts: while it does not read (its output
/// is backed up), the client is not slow.
fn metered(body: Body, rate: u64, window: Duration) -> Body {
    let need = rate as f64 * window.as_secs_f64();
    let meter = Meter {
        stream: body.into_data_stream(),
        waited: Duration::ZERO,
        bytes: 0,
    };
    let slow = move || -> axum::BoxError {
        format!(
            "{TOO_SLOW} {rate} bytes/s over {} s (--min-upload-rate)",
            window.as_secs_f64()
        )
        .into()
    };
    Body::from_stream(futures_util::stream::unfold(Some(meter), move |m| async move {
        let mut m = m?;
        loop {
            let t0 = tokio::time::Instant::now();
            let next = tokio::time::timeout(window.saturating_sub(m.waited), m.stream.next()).await;
            m.waited += t0.elapsed();
            let chunk = match next {
                Ok(Some(Ok(b))) => Some(b),
                Ok(Some(Err(e))) => return Some((Err(axum::BoxError::from(e)), None)),
                Ok(None) => return None,
                Err(_) => None,
            };
            m.bytes += chunk.as_ref().map_or(0, |b| b.len() as u64);
            if m.waited >= window {
                if (m.bytes as f64) < need {
                    return Some((Err(slow()), None));
                }
                m.waited = Duration::ZERO;
                m.bytes = 0;
            }
            if let Some(b) = chunk {
                return Some((Ok::<Bytes, axum::BoxError>(b), Some(m)));
            }
        }
    }))
}

struct Meter {
    stream: axum::body::BodyDataStream,
    /// Time spent waiting for the client in this window.
    waited: Duration,
    /// Bytes it sent in this window.
    bytes: u64,
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

/// A failed multipart read: too slow (408), over the body limit (413), else malformed (400).
pub(super) fn multipart_error(e: axum::extract::multipart::MultipartError) -> ApiError {
    if let Some(slow) = too_slow_in(&e) {
        return slow;
    }
    if e.status() == axum::http::StatusCode::PAYLOAD_TOO_LARGE {
        return ApiError::TooLarge(None);
    }
    ApiError::BadParameter(format!("multipart: {}", e.body_text()))
}
