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

/// Why an upload's bytes stopped coming, as its reader (the engine, the spool) gets it: inside
/// the I/O error it reads, through the layers between (body, multipart, bridge), and told by
/// its type where the request's answer is made, never by its words.
#[derive(Clone, Debug, thiserror::Error)]
pub(super) enum Cut {
    /// Slower than `--min-upload-rate` (408).
    #[error("upload slower than the minimum of {rate} bytes/s over {secs} s (--min-upload-rate)")]
    TooSlow { rate: u64, secs: f64 },
    /// Over the body limit (413).
    #[error("{}", ApiError::TooLarge(None))]
    TooLarge,
    /// A form that broke off (400): multipart's words.
    #[error("multipart: {0}")]
    Form(String),
}

impl Cut {
    /// A failed read of a multipart form: the pace or the limit where either cut it.
    pub(super) fn of_multipart(e: axum::extract::multipart::MultipartError) -> Cut {
        if let Some(cut) = cut_in(&e) {
            return cut;
        }
        if e.status() == axum::http::StatusCode::PAYLOAD_TOO_LARGE {
            return Cut::TooLarge;
        }
        Cut::Form(e.body_text())
    }
}

impl From<Cut> for ApiError {
    fn from(c: Cut) -> ApiError {
        match c {
            c @ Cut::TooSlow { .. } => ApiError::UploadTooSlow(c.to_string()),
            Cut::TooLarge => ApiError::TooLarge(None),
            c @ Cut::Form(_) => ApiError::BadParameter(c.to_string()),
        }
    }
}

/// Where an error's chain of causes says how the upload was cut: a [`Cut`], or the body
/// limit's own error. An I/O error's cause is what it wraps (its `source` skips that).
fn cut_in(e: &(dyn std::error::Error + 'static)) -> Option<Cut> {
    fn next<'a>(e: &&'a (dyn std::error::Error + 'static)) -> Option<&'a (dyn std::error::Error + 'static)> {
        match e.downcast_ref::<std::io::Error>() {
            Some(io) => io.get_ref().map(|inner| inner as &(dyn std::error::Error + 'static)),
            None => e.source(),
        }
    }
    std::iter::successors(Some(e), next).find_map(|e| match e.downcast_ref::<Cut>() {
        Some(c) => Some(c.clone()),
        None => e.is::<http_body_util::LengthLimitError>().then_some(Cut::TooLarge),
    })
}

/// A failed read of an upload (the engine's or the spool's, `io` where an I/O error is what
/// failed; `e` the whole error): too slow (408), over the body limit (413), else a broken
/// upload (400) in `e`'s words.
pub(super) fn upload_error(io: Option<&std::io::Error>, e: &dyn std::fmt::Display) -> ApiError {
    match io.and_then(|io| cut_in(io)) {
        Some(c @ (Cut::TooSlow { .. } | Cut::TooLarge)) => c.into(),
        Some(Cut::Form(_)) | None => ApiError::BadParameter(format!("reading the upload: {e}")),
    }
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
        Box::new(Cut::TooSlow {
            rate,
            secs: window.as_secs_f64(),
        })
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
    Cut::of_multipart(e).into()
}
