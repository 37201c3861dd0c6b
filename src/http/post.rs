//! `POST /v1/post`: CL in, NC (or NDJSON blocks) out, streaming both ways.
//!
//! The engine is synchronous; it runs on a blocking thread, reading the request body through a
//! bridge as it arrives and writing into a bounded channel that the response body drains, so
//! memory stays bounded and a client that goes away stops the work. Output is held back until
//! 16 KiB are ready (or the program ends): an error before that still gets its HTTP status.

use super::error::{ApiError, ApiQuery};
use super::{AppState, limits};
use crate::diag::Diagnostic;
use crate::output::{ErrorBody, Header, Record};
use crate::post::{self, BlockInfo, Settings, Sink, Stop, Summary};
use axum::body::Body;
use axum::extract::multipart::Field;
use axum::extract::{FromRequest, Multipart, Request, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use bytes::Bytes;
use futures_util::StreamExt;
use serde::Deserialize;
use std::io::Read;
use std::sync::Arc;
use tokio::sync::{mpsc, oneshot};
use tokio_util::io::{StreamReader, SyncIoBridge};

/// Bytes of output held back before the response starts (so early errors keep their status).
const PRELUDE: usize = 16 * 1024;
/// Chunk size of the streamed output.
const CHUNK: usize = 32 * 1024;
/// Most of an upload read after the engine stopped early (beyond it the connection may reset).
const DRAIN_MAX: u64 = 64 << 20;

/// Query (or multipart form) parameters of `POST /v1/post`.
#[derive(Clone, Debug, Default, Deserialize, utoipa::IntoParams, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct PostParams {
    /// Machine profile id (required).
    pub machine: Option<String>,
    /// NC dialect; default: the profile's controller.
    pub dialect: Option<String>,
    /// `joint` (default) or `tcp`.
    pub mode: Option<String>,
    /// Tool length (gauge line to tip), profile units, one for every tool (a single-tool job);
    /// default per tool: the tool table's, else the CL file's, else the profile's.
    pub tool_length: Option<f64>,
    /// The job's own tool table, as TOML text (`units = "mm"`, `[[tool]] number = 3, length =
    /// 112.5 …`): each tool's length; it replaces the machine's (`/v1/machines/{id}/tools`).
    pub tool_table: Option<String>,
    /// Work offset `x,y,z` in profile units.
    pub work_offset: Option<String>,
    /// Chord tolerance in profile units (default 0.01 mm / 0.0004 in, at most 1 mm / 0.04 in):
    /// also the bound of the FK replay's tip check.
    pub tolerance: Option<f64>,
    pub sequence_numbers: Option<bool>,
    /// Program number (default 1000): 1 to 9999 on fanuc (`O` and four digits), 1 to 99999 on
    /// haas; any on the others, which name the program.
    pub program_number: Option<u32>,
    /// Stop at the first error instead of reporting it and going on.
    pub strict: Option<bool>,
    /// Degrees of orientation the free rotary may use near a singular direction (0: exact).
    pub singular_tolerance: Option<f64>,
    /// Units of the CL when the file does not say: `mm` or `inch`.
    pub cl_units: Option<String>,
    /// Drilling cycles: `expand` (default: moves) or `canned` (the control's canned cycles where
    /// the hole runs along the machine's Z in joint mode; elsewhere still expanded).
    pub cycles: Option<String>,
    /// 3+2 work: `positioning` (default) or `tilted` (a tilted working plane per fixed-axis run:
    /// G68.2/G53.1, G254, CYCLE800, PLANE SPATIAL; joint mode).
    pub planes: Option<String>,
    /// Work coordinate system the program selects: `G54` (default) to `G59` (siemens: `G57`), or
    /// `none`; its origin must be where X Y Z are measured from (joint mode: the profile's
    /// origin; TCP: the part's). heidenhain: none only.
    pub work_coordinates: Option<String>,
    /// Programs of several setups (NX `MSYS` per operation): `transform` (default: every
    /// operation taken into the first's MCS) or `work-offsets` (each distinct MCS in the next
    /// work offset, G55 …).
    pub setups: Option<String>,
    /// Spindle speed (RPM, clockwise, 1 to 200000) for a tool the CL starts no spindle for
    /// before its first move (NX CLSF carries no SPINDL); the CL's SPINDL and SPINDL/OFF win.
    pub spindle_speed: Option<f64>,
    /// Where positioning retracts to: `machine-z` (joint mode's default: the top of Z travel),
    /// `axis:D` (along the tool axis; TCP mode's default is the clearance) or `plane:Z` (along
    /// the tool axis up to z = Z in the part frame); the profile's default where absent.
    pub retract: Option<String>,
    /// A rotary's side the planner keeps to where both IK branches can cut a run: `B-`, `A+`;
    /// the profile's default where absent.
    pub prefer: Option<String>,
    /// How a feed move with rotaries writes F: `inverse-time`, `dpm` or `combined`; the
    /// profile's `[policy] feed_mode`, else inverse time where the control has it.
    pub feed_mode: Option<String>,
    /// Where a bounded rotary may unwind: `retract` (in the cut too) or `rapids` (one inside a
    /// cut is an error); the profile's `[policy] unwind` where absent.
    pub unwind: Option<String>,
    /// Which tool is readied while another cuts: `next` (default: right after each tool change,
    /// the next tool the CL loads; a streamed post, whose CL is read once, readies where the CL
    /// says `SELCTL`; a job's spooled CL is read twice), `cl` (where the CL says `SELCTL`) or
    /// `off`.
    pub preselect: Option<String>,
    /// The smoothing word of each operation: `auto` (default: once the CL says `INTOL`/`OUTTOL`,
    /// each operation's level from its type, else its tolerance), `off`, `rough` or `finish`;
    /// the profile's `[policy] smoothing`, else the dialect's `[smoothing] default`, where
    /// absent.
    pub smoothing: Option<String>,
    /// The collision check against the profile's bodies: `on` (default) or `off`.
    pub collisions: Option<String>,
    /// Bodies closer than this (profile units; default 2 mm / 0.08 in): `near_collision`.
    pub collision_clearance: Option<f64>,
    /// The stock: a box `x0,y0,z0,x1,y1,z1` in the CL's frame and units.
    pub stock: Option<String>,
    /// Fixtures: boxes as the stock's, separated by `;`.
    pub fixtures: Option<String>,
}

impl PostParams {
    pub(super) fn settings(&self) -> Settings {
        Settings {
            machine: self.machine.clone(),
            dialect: self.dialect.clone(),
            mode: self.mode.clone(),
            tool_length: self.tool_length,
            tool_table: self.tool_table.clone(),
            machine_tools_version: None,
            dialect_version: None,
            work_offset: self.work_offset.clone(),
            tolerance: self.tolerance,
            sequence_numbers: self.sequence_numbers,
            program_number: self.program_number,
            strict: self.strict,
            singular_tolerance: self.singular_tolerance,
            cl_units: self.cl_units.clone(),
            cycles: self.cycles.clone(),
            planes: self.planes.clone(),
            work_coordinates: self.work_coordinates.clone(),
            setups: self.setups.clone(),
            spindle_speed: self.spindle_speed,
            retract: self.retract.clone(),
            prefer: self.prefer.clone(),
            feed_mode: self.feed_mode.clone(),
            unwind: self.unwind.clone(),
            preselect: self.preselect.clone(),
            smoothing: self.smoothing.clone(),
            collisions: self.collisions.clone(),
            collision_clearance: self.collision_clearance,
            threads: None, // the server's to choose (`Config::post_threads`), not a request's
            stock: self.stock.clone(),
            fixtures: self.fixtures.clone(),
        }
    }

    /// The machine profile named by `machine` (required).
    pub(super) fn profile(&self, st: &AppState) -> Result<crate::machines::Current, ApiError> {
        let id = self
            .machine
            .as_deref()
            .ok_or_else(|| ApiError::BadParameter("machine: required (e.g. ?machine=haas-umc750)".into()))?;
        st.machines.get(id).map_err(|_| ApiError::UnknownMachine(id.to_string()))
    }

    /// A multipart text field, by name.
    fn set(&mut self, name: &str, v: String) -> Result<(), ApiError> {
        let bad = |what: &str| ApiError::BadParameter(format!("{name}: {what}"));
        let num = |v: &str| v.trim().parse::<f64>().map_err(|_| bad("expected a number"));
        let flag = |v: &str| match v.trim() {
            "true" | "1" | "on" | "yes" => Ok(true),
            "false" | "0" | "off" | "no" | "" => Ok(false),
            _ => Err(bad("expected true or false")),
        };
        match name {
            "machine" => self.machine = Some(v),
            "dialect" => self.dialect = Some(v).filter(|s| !s.is_empty()),
            "mode" => self.mode = Some(v).filter(|s| !s.is_empty()),
            "tool_length" => self.tool_length = if v.trim().is_empty() { None } else { Some(num(&v)?) },
            "tool_table" => self.tool_table = Some(v).filter(|s| !s.trim().is_empty()),
            "work_offset" => self.work_offset = Some(v).filter(|s| !s.trim().is_empty()),
            "tolerance" => self.tolerance = if v.trim().is_empty() { None } else { Some(num(&v)?) },
            "sequence_numbers" => self.sequence_numbers = Some(flag(&v)?),
            "program_number" => self.program_number = Some(v.trim().parse().map_err(|_| bad("expected a whole number"))?),
            "strict" => self.strict = Some(flag(&v)?),
            "singular_tolerance" => self.singular_tolerance = if v.trim().is_empty() { None } else { Some(num(&v)?) },
            "cl_units" => self.cl_units = Some(v).filter(|s| !s.is_empty()),
            "cycles" => self.cycles = Some(v).filter(|s| !s.is_empty()),
            "planes" => self.planes = Some(v).filter(|s| !s.is_empty()),
            "work_coordinates" => self.work_coordinates = Some(v).filter(|s| !s.is_empty()),
            "setups" => self.setups = Some(v).filter(|s| !s.is_empty()),
            "retract" => self.retract = Some(v).filter(|s| !s.is_empty()),
            "prefer" => self.prefer = Some(v).filter(|s| !s.is_empty()),
            "feed_mode" => self.feed_mode = Some(v).filter(|s| !s.is_empty()),
            "unwind" => self.unwind = Some(v).filter(|s| !s.is_empty()),
            "preselect" => self.preselect = Some(v).filter(|s| !s.is_empty()),
            "smoothing" => self.smoothing = Some(v).filter(|s| !s.is_empty()),
            "collisions" => self.collisions = Some(v).filter(|s| !s.is_empty()),
            "collision_clearance" => self.collision_clearance = if v.trim().is_empty() { None } else { Some(num(&v)?) },
            "stock" => self.stock = Some(v).filter(|s| !s.trim().is_empty()),
            "fixtures" => self.fixtures = Some(v).filter(|s| !s.trim().is_empty()),
            "spindle_speed" => self.spindle_speed = if v.trim().is_empty() { None } else { Some(num(&v)?) },
            other => {
                return Err(ApiError::BadParameter(format!(
                    "unknown form field {}",
                    crate::text::quote(other)
                )));
            }
        }
        Ok(())
    }
}

/// Whether the client wants NDJSON blocks instead of the NC text.
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
    params(PostParams),
    request_body(content = String, description = "CL data (APT/CLSF text), raw or as the `file` part of multipart/form-data", content_type = "text/plain"),
    responses(
        (status = 200, description = "The NC program (text/plain), or one JSON object per line (application/x-ndjson): header, block…, summary, and error on failure", content_type = "text/plain"),
        (status = 400, description = "Bad parameter", body = super::error::Problem, content_type = "application/problem+json"),
        (status = 404, description = "Unknown machine", body = super::error::Problem, content_type = "application/problem+json"),
        (status = 408, description = "Upload slower than --min-upload-rate (once the program has begun, it ends with the error instead)", body = super::error::Problem, content_type = "application/problem+json"),
        (status = 413, description = "Upload too large, or a form field over 64 KiB", body = super::error::Problem, content_type = "application/problem+json"),
        (status = 415, description = "Unsupported media type", body = super::error::Problem, content_type = "application/problem+json"),
        (status = 422, description = "Bad CL record (strict mode) with line and column, input that is no CL data (`not-cl-data`: an NC program, nothing recognisable), a lathe's program (`turning`: kinepost posts milling), or over the server's bound on output or time before the first byte (`over-budget`)", body = super::error::Problem, content_type = "application/problem+json"),
        (status = 503, description = "--max-streams post streams running (Retry-After)", body = super::error::Problem, content_type = "application/problem+json"),
    ),
    tag = "post"
)]
pub async fn post_cl(
    State(st): State<Arc<AppState>>,
    ApiQuery(query): ApiQuery<PostParams>,
    mut req: Request,
) -> Result<Response, ApiError> {
    let ndjson = wants_ndjson(req.headers())?;
    let slot = req.extensions_mut().remove::<Arc<limits::StreamSlot>>();
    let (params, filename, body) = upload(&st, query, req).await?;
    let checked = params.profile(&st).and_then(|c| {
        let standing = super::tools::standing(&st, &c.id);
        let opts = params.settings().profile_options_with(&c.item, standing, &|id| st.machines.dialect(id));
        Ok((c.item, opts.map_err(ApiError::BadParameter)?))
    });
    let ((profile, mut opts), body) = refuse_unread(checked, body).await?;
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

/// The CL upload of `/v1/post` and `/v1/jobs`: a raw body with query parameters, or a multipart
/// form whose fields come before its `file` part.
pub(super) async fn upload(
    st: &Arc<AppState>,
    query: PostParams,
    req: Request,
) -> Result<(PostParams, Option<String>, Body), ApiError> {
    let ctype = req
        .headers()
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .unwrap_or("text/plain")
        .to_ascii_lowercase();
    if ctype.starts_with("multipart/form-data") {
        multipart_body(st, query, req).await
    } else if ctype.starts_with("text/plain") || ctype.starts_with("application/octet-stream") || ctype.is_empty() {
        Ok((query, None, req.into_body()))
    } else {
        Err(ApiError::UnsupportedMediaType(ctype))
    }
}

/// Reads form fields up to the file part, then hands the file's bytes over as a body stream fed
/// by a task that owns the form (fields after the file are not read).
async fn multipart_body(
    st: &Arc<AppState>,
    query: PostParams,
    req: Request,
) -> Result<(PostParams, Option<String>, Body), ApiError> {
    let mp = Multipart::from_request(req, st)
        .await
        .map_err(|e| ApiError::BadParameter(format!("multipart: {e}")))?;
    let (ptx, prx) = oneshot::channel::<FormHead>();
    let (btx, brx) = mpsc::channel::<Result<Bytes, std::io::Error>>(8);
    tokio::spawn(read_form(mp, query, ptx, btx));
    let (params, fname) = prx.await.map_err(|_| ApiError::Internal("multipart reader ended".into()))??;
    let stream = futures_util::stream::unfold(brx, |mut rx| async move { rx.recv().await.map(|item| (item, rx)) });
    Ok((params, fname, Body::from_stream(stream)))
}

/// What a form says before its file: the parameters and the file's name, or why it is refused.
type FormHead = Result<(PostParams, Option<String>), ApiError>;

/// The form task: text fields into `params` until the file part, then `params` and the file's
/// name to `ptx` and its bytes to `btx`. A form that fails before its file says so on `ptx`.
async fn read_form(
    mut mp: Multipart,
    mut params: PostParams,
    ptx: oneshot::Sender<FormHead>,
    btx: mpsc::Sender<Result<Bytes, std::io::Error>>,
) {
    let failure = loop {
        let field = match mp.next_field().await {
            Ok(Some(field)) => field,
            Ok(None) => break ApiError::BadParameter("multipart: no file part (name it \"file\")".into()),
            Err(e) => break limits::multipart_error(e),
        };
        let name = field.name().unwrap_or("").to_string();
        if field.file_name().is_some() || name == "file" {
            let fname = field.file_name().map(str::to_string);
            let _ = ptx.send(Ok((params, fname)));
            return stream_file(field, btx).await;
        }
        let set = limits::read_field(&name, field).await.and_then(|v| params.set(&name, v));
        if let Err(e) = set {
            break e;
        }
    };
    let _ = ptx.send(Err(failure));
}

/// The file part's bytes into the body channel until the part ends, the upload breaks (the
/// error goes on to the engine) or the handler is gone.
async fn stream_file(mut field: Field<'_>, btx: mpsc::Sender<Result<Bytes, std::io::Error>>) {
    loop {
        match field.chunk().await {
            Ok(Some(b)) => {
                if btx.send(Ok(b)).await.is_err() {
                    return;
                }
            }
            Ok(None) => return,
            Err(e) => {
                let cut = limits::Cut::of_multipart(e);
                let _ = btx.send(Err(std::io::Error::other(cut))).await;
                return;
            }
        }
    }
}
