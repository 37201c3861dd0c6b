//! `POST /v1/post`: CL in, NC (or NDJSON blocks) out, streaming both ways.
//!
//! The engine is synchronous; it runs on a blocking thread, reading the request body through a
//! bridge as it arrives and writing into a bounded channel that the response body drains, so
//! memory stays bounded and a client that goes away stops the work. Output is held back until
//! 16 KiB are ready (or the program ends): an error before that still gets its HTTP status.

use super::error::ApiError;
use super::refusals::UploadRefusals;
use super::upload::ClUpload;
use super::{AppState, limits};
use crate::diag::Diagnostic;
use crate::output::{ErrorBody, Header, Record};
use crate::post::{self, BlockInfo, Settings, Sink, Stop, Summary};
use axum::Extension;
use axum::body::Body;
use axum::extract::{FromRequestParts, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use bytes::Bytes;
use futures_util::StreamExt;
use std::io::Read;
use std::sync::Arc;
use tokio::sync::mpsc;
use tokio_util::io::{StreamReader, SyncIoBridge};

/// Bytes of output held back before the response starts (so early errors keep their status).
const PRELUDE: usize = 16 * 1024;
/// Chunk size of the streamed output.
const CHUNK: usize = 32 * 1024;
/// Most of an upload read after the engine stopped early (beyond it the connection may reset).
const DRAIN_MAX: u64 = 64 << 20;

/// The machine profile a post's settings name (`machine`, required).
pub(super) fn profile(st: &AppState, settings: &Settings) -> Result<crate::machines::Current, ApiError> {
    let id = settings
        .machine
        .as_deref()
        .ok_or_else(|| ApiError::BadParameter("machine: required (e.g. ?machine=haas-umc750)".into()))?;
    st.machines.get(id).map_err(|_| ApiError::UnknownMachine(id.to_string()))
}

/// The options `settings` give on the profile `c`, with the machine's standing tool table and
/// the service's dialects (built-in or stored): what a post and a job's submission both check.
pub(super) fn options_on(st: &AppState, settings: &Settings, c: &crate::machines::Current) -> Result<post::Options, ApiError> {
    let standing = super::tools::standing(st, &c.id);
    Ok(settings.profile_options_with(&c.item, standing, &|id| st.machines.dialect(id))?)
}

/// Whether the client wants NDJSON blocks instead of the NC text (`Accept`), refused (406) before
/// the upload is read.
pub struct Negotiated(bool);

impl<S: Send + Sync> FromRequestParts<S> for Negotiated {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut axum::http::request::Parts, _: &S) -> Result<Self, ApiError> {
        wants_ndjson(&parts.headers).map(Negotiated)
    }
}

fn wants_ndjson(h: &HeaderMap) -> Result<bool, ApiError> {
    let Some(a) = h.get(header::ACCEPT).and_then(|v| v.to_str().ok()) else {
        return Ok(false);
    };
    if a.contains("application/x-ndjson") {
        return Ok(true);
    }
    if a.is_empty() || a.contains("text/plain") || a.contains("*/*") || a.contains("text/*") {
        return Ok(false);
    }
    Err(ApiError::NotAcceptable(a.to_string()))
}

enum Msg {
    Data(Bytes),
    /// Failed before anything was sent: the handler answers with this status.
    Fail(ApiError),
}

/// The engine's sink on the blocking thread: NC text or NDJSON lines into the channel.
struct ChannelSink {
    tx: mpsc::Sender<Msg>,
    buf: Vec<u8>,
    ndjson: bool,
    started: bool,
    /// Whose comment syntax the text stream's closing error is written in.
    dialect: Arc<crate::nc::Dialect>,
}

impl ChannelSink {
    /// Sends what is buffered, from `limit` bytes on (all of it with `force`); a response
    /// dropped by now ([`Stop::Gone`]) has lost its client.
    fn send(&mut self, force: bool) -> Result<(), Stop> {
        let limit = if self.started { CHUNK } else { PRELUDE };
        if self.buf.is_empty() || (!force && self.buf.len() < limit) {
            return Ok(());
        }
        let data = Bytes::from(std::mem::replace(&mut self.buf, Vec::with_capacity(CHUNK + 4096)));
        self.started = true;
        self.tx.blocking_send(Msg::Data(data)).map_err(|_| Stop::Gone)
    }

    fn record(&mut self, r: &Record) -> Result<(), Stop> {
        r.write_to(&mut self.buf)?;
        self.send(false)
    }

    /// The engine failed. Before anything was sent, the handler answers with the error's status;
    /// once streaming, the output ends with an explicit error, never a silent truncation.
    fn fail(&mut self, err: ApiError, body: ErrorBody) {
        if !self.started {
            let _ = self.tx.blocking_send(Msg::Fail(err));
            return;
        }
        if self.ndjson {
            let _ = self.record(&Record::Error { error: body });
        } else {
            let line = self.dialect.comment_line(&format!("ERROR: {err}"));
            self.buf.extend_from_slice(line.as_bytes());
            self.buf.push(b'\n');
        }
        let _ = self.send(true);
    }
}

impl Sink for ChannelSink {
    fn line(&mut self, text: &str, b: Option<&BlockInfo>) -> Result<(), Stop> {
        if self.ndjson {
            return self.record(&Record::line(text, b));
        }
        self.buf.extend_from_slice(text.as_bytes());
        self.buf.push(b'\n');
        self.send(false)
    }

    fn diagnostic(&mut self, d: &Diagnostic) -> Result<(), Stop> {
        if self.ndjson {
            return self.record(&Record::Diagnostic { diagnostic: d });
        }
        Ok(())
    }

    /// The response has been dropped: its client left.
    fn halted(&mut self) -> Option<Stop> {
        self.tx.is_closed().then_some(Stop::Gone)
    }
    fn summary(&mut self, s: &Summary) -> Result<(), Stop> {
        if self.ndjson {
            return self.record(&Record::Summary { summary: s });
        }
        Ok(())
    }
}

fn engine_error(e: post::Error) -> ApiError {
    match e {
        post::Error::Strict(d) => ApiError::BadRecord {
            message: d.to_string(),
            line: d.line,
            column: d.column,
            code: d.code.as_str(),
        },
        post::Error::NotCl(d) if d.code == crate::diag::Code::Turning => ApiError::Turning {
            message: d.message,
            line: d.line,
        },
        post::Error::NotCl(d) => ApiError::NotCl {
            message: d.message,
            line: d.line,
        },
        e @ post::Error::Read(_) => limits::upload_error(e.io(), &e),
        post::Error::Stop(Stop::Budget(why)) => ApiError::OverBudget(why),
        post::Error::Stop(Stop::Io(e)) => ApiError::Internal(e.to_string()),
        // Nobody reads this answer: the client left, or no job is waiting for it.
        e @ post::Error::Stop(Stop::Gone | Stop::Cancelled) => ApiError::Internal(e.to_string()),
        post::Error::Engine(why) => ApiError::Internal(why.to_string()),
    }
}

/// A request refused after its head, its upload not read yet: the upload is read to its end
/// first (at most `DRAIN_MAX`, ten seconds), else closing on unread bytes resets the connection
/// and the client never reads the problem document. On success the body is handed back.
pub(super) async fn refuse_unread<T>(checked: Result<T, ApiError>, body: Body) -> Result<(T, Body), ApiError> {
    use http_body_util::BodyExt;
    let e = match checked {
        Ok(t) => return Ok((t, body)),
        Err(e) => e,
    };
    let mut body = body;
    let mut left = DRAIN_MAX;
    let _ = tokio::time::timeout(std::time::Duration::from_secs(10), async {
        while let Some(Ok(frame)) = body.frame().await {
            left = left.saturating_sub(frame.data_ref().map_or(0, |d| d.len() as u64));
            if left == 0 {
                break;
            }
        }
    })
    .await;
    Err(e)
}

/// Post-process the CL in the request body (raw, or the `file` part of a multipart form).
#[utoipa::path(
    post,
    path = "/v1/post",
    params(Settings),
    request_body(content = String, description = "CL data (APT/CLSF text), raw or as the `file` part of multipart/form-data", content_type = "text/plain"),
    responses(
        (status = 200, description = "The NC program (text/plain), or one JSON object per line (application/x-ndjson): header, block…, summary, and error on failure", content_type = "text/plain"),
        UploadRefusals,
        (status = 406, description = "Accept names neither text/plain nor application/x-ndjson", body = super::error::Problem, content_type = "application/problem+json"),
        (status = 422, description = "Bad CL record (strict mode) with line and column, input that is no CL data (`not-cl-data`: an NC program, nothing recognisable), a lathe's program (`turning`: kinepost posts milling), or over the server's bound on output or time before the first byte (`over-budget`)", body = super::error::Problem, content_type = "application/problem+json"),
        (status = 503, description = "--max-streams post streams running (Retry-After)", body = super::error::Problem, content_type = "application/problem+json"),
    ),
    tag = "post"
)]
pub async fn post_cl(
    State(st): State<Arc<AppState>>,
    Negotiated(ndjson): Negotiated,
    slot: Option<Extension<Arc<limits::StreamSlot>>>,
    ClUpload { params, filename, body }: ClUpload,
) -> Result<Response, ApiError> {
    // Held until the stream ends (the one in the request's extensions went with the request).
    let slot = slot.map(|Extension(s)| s);
    let checked = profile(&st, &params).and_then(|c| Ok((options_on(&st, &params, &c)?, c.item)));
    let ((mut opts, profile), body) = refuse_unread(checked, body).await?;
    opts.budget = st.config.post_budget;
    opts.threads = st.config.post_threads;
    opts.header.push(format!("DATE {} UTC", crate::output::utc_now()));
    if let Some(f) = &filename {
        opts.header.push(format!("SOURCE {f}"));
    }
    let (tx, mut rx) = mpsc::channel::<Msg>(8);
    let reader = SyncIoBridge::new(StreamReader::new(
        body.into_data_stream().map(|r| r.map_err(std::io::Error::other)),
    ));
    let with_header = ndjson;
    let metrics = st.metrics.clone();
    tokio::task::spawn_blocking(move || {
        let _slot = slot;
        let mut sink = ChannelSink {
            tx,
            buf: Vec::with_capacity(PRELUDE + 4096),
            ndjson,
            started: false,
            dialect: opts.dialect.clone(),
        };
        if with_header {
            let h = Header {
                machine: &profile.machine.id,
                units: profile.machine.units.as_str(),
                mode: opts.mode,
                dialect: &opts.dialect.name,
                tolerance: opts.tolerance,
            };
            let _ = sink.record(&Record::Header(h));
        }
        let mut input = std::io::BufReader::with_capacity(64 * 1024, reader);
        let t0 = std::time::Instant::now();
        match post::post(&mut input, &profile.machine, &opts, &mut sink) {
            Ok(s) => {
                metrics.record_post(&s, t0.elapsed().as_secs_f64());
                let _ = sink.send(true);
            }
            Err(e) => {
                let body = ErrorBody::from_engine(&e);
                sink.fail(engine_error(e), body);
            }
        }
        // The response ends whole; then the upload the engine stopped reading (strict mode, a
        // budget) is read to its end, else closing on unread bytes resets the connection and
        // the client can lose the response's last records.
        drop(sink);
        let _ = std::io::copy(&mut (&mut input).take(DRAIN_MAX), &mut std::io::sink());
    });
    let first = match rx.recv().await {
        Some(Msg::Fail(e)) => return Err(e),
        Some(Msg::Data(b)) => b,
        None => Bytes::new(),
    };
    let rest = futures_util::stream::unfold(rx, |mut rx| async move {
        match rx.recv().await {
            Some(Msg::Data(b)) => Some((Ok::<Bytes, std::io::Error>(b), rx)),
            Some(Msg::Fail(e)) => Some((Err(std::io::Error::other(e)), rx)),
            None => None,
        }
    });
    let stream = futures_util::stream::once(async move { Ok::<Bytes, std::io::Error>(first) }).chain(rest);
    let mut resp = Response::new(Body::from_stream(stream));
    *resp.status_mut() = StatusCode::OK;
    let h = resp.headers_mut();
    if ndjson {
        h.insert(header::CONTENT_TYPE, HeaderValue::from_static("application/x-ndjson"));
    } else {
        h.insert(header::CONTENT_TYPE, HeaderValue::from_static("text/plain; charset=utf-8"));
        h.insert(header::CONTENT_DISPOSITION, nc_attachment(filename.as_deref(), "program"));
    }
    Ok(resp.into_response())
}

/// `Content-Disposition` for an NC download named after the uploaded file: its stem, reduced to
/// characters safe in a header and a file name, else `fallback`.
pub(super) fn nc_attachment(upload: Option<&str>, fallback: &str) -> HeaderValue {
    let safe: String = upload
        .and_then(|f| std::path::Path::new(f).file_stem())
        .and_then(|s| s.to_str())
        .unwrap_or("")
        .chars()
        .filter(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.'))
        .take(64)
        .collect();
    let stem = if safe.is_empty() { fallback } else { &safe };
    HeaderValue::from_str(&format!("attachment; filename=\"{stem}.nc\"")).unwrap_or(HeaderValue::from_static("attachment"))
}
