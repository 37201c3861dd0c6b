//! The HTTP service: the engine for CAM plugins (REST), machinists (the web form) and scripts.
//! Only this module knows HTTP, JSON DTOs and status codes. `app()` builds the whole router,
//! testable without a socket; `serve()` binds it and shuts down gracefully, finishing streams
//! in flight.

mod error;
mod jobs;
mod machine_ops;
mod post;

pub use error::{ApiError, ApiJson, Problem};
pub use post::PostParams;

use crate::machines::{Library, Profile};
use axum::Json;
use axum::extract::{MatchedPath, Path, Request, State};
use axum::http::{HeaderName, HeaderValue, StatusCode, header};
use axum::middleware::{self, Next};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post as post_route};
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tower_http::cors::{AllowOrigin, CorsLayer};
use tower_http::request_id::{MakeRequestId, PropagateRequestIdLayer, RequestId, SetRequestIdLayer};
use tower_http::trace::TraceLayer;
use utoipa::OpenApi;

/// Service settings (CLI flags with environment equivalents).
#[derive(Clone, Debug)]
pub struct Config {
    pub bind: String,
    pub machines: PathBuf,
    pub data_dir: PathBuf,
    /// Largest upload accepted (bytes): files are streamed, not buffered, so this can be large.
    pub max_upload: u64,
    /// Longest a non-streaming request may take.
    pub request_timeout: Duration,
    /// Post streams running at once; more are answered 503 with Retry-After.
    pub max_streams: usize,
    /// Origins allowed by CORS (CAM plugins' web views); empty: no CORS headers.
    pub cors_origins: Vec<String>,
    pub log_json: bool,
    /// Jobs run at once (default: one per core).
    pub workers: usize,
    /// Jobs waiting at most; more are answered 503 with Retry-After.
    pub max_queued: u64,
    /// Finished jobs and their files are removed after this long.
    pub job_retention: Duration,
}

impl Config {
    /// The job queue's part of the settings.
    pub fn jobs(&self) -> crate::jobs::Config {
        crate::jobs::Config {
            data_dir: self.data_dir.clone(),
            workers: self.workers,
            max_queued: self.max_queued,
            retention: self.job_retention,
        }
    }
}

impl Default for Config {
    fn default() -> Self {
        Config {
            bind: "127.0.0.1:8080".into(),
            machines: crate::machines::default_dir(),
            data_dir: PathBuf::from("data"),
            max_upload: 4 << 30,
            request_timeout: Duration::from_secs(30),
            max_streams: 64,
            cors_origins: Vec::new(),
            log_json: false,
            workers: std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1),
            max_queued: 1000,
            job_retention: Duration::from_secs(7 * 24 * 3600),
        }
    }
}

/// Counters for `/metrics`, rendered in the Prometheus text format.
#[derive(Default)]
pub struct Metrics {
    requests: Mutex<BTreeMap<(String, u16), u64>>,
    pub streams: AtomicU64,
    cl_points: AtomicU64,
    blocks: AtomicU64,
    posts: AtomicU64,
    /// Sum of post durations in microseconds, and the count per duration bucket (seconds).
    post_micros: AtomicU64,
    buckets: [AtomicU64; 8],
}

const BUCKETS: [f64; 8] = [0.01, 0.05, 0.1, 0.5, 1.0, 5.0, 30.0, 300.0];

impl Metrics {
    fn record_request(&self, route: &str, status: u16) {
        if let Ok(mut m) = self.requests.lock() {
            *m.entry((route.to_string(), status)).or_default() += 1;
        }
    }

    pub fn record_post(&self, s: &crate::post::Summary, secs: f64) {
        self.cl_points.fetch_add(s.cl_points, Ordering::Relaxed);
        self.blocks.fetch_add(s.blocks, Ordering::Relaxed);
        self.posts.fetch_add(1, Ordering::Relaxed);
        self.post_micros.fetch_add((secs * 1e6) as u64, Ordering::Relaxed);
        for (b, limit) in self.buckets.iter().zip(BUCKETS) {
            if secs <= limit {
                b.fetch_add(1, Ordering::Relaxed);
            }
        }
    }

    pub fn render(&self) -> String {
        use std::fmt::Write;
        let mut o = String::new();
        o.push_str("# HELP kinepost_http_requests_total HTTP requests by route and status.\n# TYPE kinepost_http_requests_total counter\n");
        if let Ok(m) = self.requests.lock() {
            for ((route, status), n) in m.iter() {
                let _ = writeln!(o, "kinepost_http_requests_total{{route=\"{route}\",status=\"{status}\"}} {n}");
            }
        }
        let g = |o: &mut String, name: &str, kind: &str, help: &str, v: u64| {
            let _ = writeln!(o, "# HELP {name} {help}\n# TYPE {name} {kind}\n{name} {v}");
        };
        g(
            &mut o,
            "kinepost_cl_points_total",
            "counter",
            "CL points post-processed.",
            self.cl_points.load(Ordering::Relaxed),
        );
        g(
            &mut o,
            "kinepost_blocks_total",
            "counter",
            "NC blocks written.",
            self.blocks.load(Ordering::Relaxed),
        );
        g(
            &mut o,
            "kinepost_streams_in_flight",
            "gauge",
            "Post streams running now.",
            self.streams.load(Ordering::Relaxed),
        );
        o.push_str("# HELP kinepost_post_duration_seconds Duration of completed posts.\n# TYPE kinepost_post_duration_seconds histogram\n");
        for (b, limit) in self.buckets.iter().zip(BUCKETS) {
            let _ = writeln!(
                o,
                "kinepost_post_duration_seconds_bucket{{le=\"{limit}\"}} {}",
                b.load(Ordering::Relaxed)
            );
        }
        let n = self.posts.load(Ordering::Relaxed);
        let _ = writeln!(o, "kinepost_post_duration_seconds_bucket{{le=\"+Inf\"}} {n}");
        let _ = writeln!(
            o,
            "kinepost_post_duration_seconds_sum {}",
            self.post_micros.load(Ordering::Relaxed) as f64 / 1e6
        );
        let _ = writeln!(o, "kinepost_post_duration_seconds_count {n}");
        o
    }
}

pub struct AppState {
    pub library: Library,
    pub config: Config,
    pub metrics: Arc<Metrics>,
    /// The job queue; `None` where a process serves posts only (benches).
    pub jobs: Option<Arc<crate::jobs::Queue>>,
}

#[derive(OpenApi)]
#[openapi(
    info(title = "kinepost", description = "5-axis CNC postprocessor: CL data in, verified NC out, for any machine profile."),
    paths(post::post_cl, list_machines, get_machine, list_dialects, machine_ops::fk_route, machine_ops::ik_route,
        machine_ops::validate_pose, machine_ops::angle_error_fit, machine_ops::calibrate, healthz, readyz, metrics_route,
        jobs::submit, jobs::list_jobs, jobs::get_job, jobs::delete_job, jobs::job_nc, jobs::job_diagnostics),
    components(schemas(Problem, MachineDto, LinearDto, RotaryDto, AngleErrorDto, DialectDto, PostParams, machine_ops::FkRequest,
        machine_ops::PoseDto, machine_ops::PoseRequest, machine_ops::ReachDto, machine_ops::AngleFitRequest, machine_ops::FitDto,
        machine_ops::AngleFitResponse, machine_ops::MeasurementDto, machine_ops::CalibrateRequest, machine_ops::CalibrateResponse,
        jobs::JobView, jobs::JobProgress, jobs::JobLinks, jobs::JobList)),
    tags((name = "post", description = "Post-processing"), (name = "machines", description = "Machine profiles"), (name = "jobs", description = "Background jobs for large toolpaths"), (name = "ops", description = "Health and metrics"))
)]
pub struct ApiDoc;

/// The OpenAPI document as served and as checked in (`openapi/openapi.json`).
pub fn openapi_json() -> String {
    ApiDoc::openapi().to_pretty_json().unwrap_or_default()
}

/// Request ids: a process-wide counter (unique per server run, cheap, no RNG needed).
#[derive(Clone, Default)]
struct Counter(Arc<AtomicU64>);

impl MakeRequestId for Counter {
    fn make_request_id<B>(&mut self, _: &axum::http::Request<B>) -> Option<RequestId> {
        let n = self.0.fetch_add(1, Ordering::Relaxed);
        HeaderValue::from_str(&format!("kp-{n:x}")).ok().map(RequestId::new)
    }
}

/// The whole service as a router: every route, every layer.
pub fn app(state: Arc<AppState>) -> axum::Router {
    let x_request_id = HeaderName::from_static("x-request-id");
    let streams = tower::ServiceBuilder::new()
        .layer(axum::extract::DefaultBodyLimit::disable())
        .layer(tower_http::limit::RequestBodyLimitLayer::new(
            state.config.max_upload.min(usize::MAX as u64) as usize,
        ));
    // Streams are neither compressed (CompressionLayer holds them back) nor timed out.
    let streaming = axum::Router::new().route(
        "/v1/post",
        post_route(post::post_cl)
            .layer(streams.clone())
            .layer(middleware::from_fn_with_state(state.clone(), admit_stream)),
    )
    .route("/v1/jobs", post_route(jobs::submit).layer(streams.clone()).get(jobs::list_jobs))
    .route("/v1/jobs/{id}", get(jobs::get_job).delete(jobs::delete_job))
    .route("/v1/jobs/{id}/nc", get(jobs::job_nc))
    .route("/v1/jobs/{id}/diagnostics", get(jobs::job_diagnostics));
    let api = axum::Router::new()
        .route("/v1/machines", get(list_machines))
        .route("/v1/dialects", get(list_dialects))
        .route("/v1/machines/{id}", get(get_machine))
        .route("/v1/machines/{id}/fk", post_route(machine_ops::fk_route))
        .route("/v1/machines/{id}/ik", post_route(machine_ops::ik_route))
        .route("/v1/machines/{id}/validate-pose", post_route(machine_ops::validate_pose))
        .route("/v1/machines/{id}/angle-error-fit", post_route(machine_ops::angle_error_fit))
        .route("/v1/machines/{id}/calibrate", post_route(machine_ops::calibrate))
        .route("/healthz", get(healthz))
        .route("/readyz", get(readyz))
        .route("/metrics", get(metrics_route))
        .route(
            "/openapi.json",
            get(|| async { ([(header::CONTENT_TYPE, "application/json")], openapi_json()) }),
        )
        .route("/", get(|| async { static_file("index.html") }))
        .route("/static/{file}", get(|Path(f): Path<String>| async move { static_file(&f) }));
    let cors = if state.config.cors_origins.is_empty() {
        CorsLayer::new()
    } else {
        let origins: Vec<HeaderValue> = state
            .config
            .cors_origins
            .iter()
            .filter_map(|o| HeaderValue::from_str(o).ok())
            .collect();
        CorsLayer::new()
            .allow_origin(AllowOrigin::list(origins))
            .allow_methods(tower_http::cors::Any)
            .allow_headers(tower_http::cors::Any)
    };
    let api = api
        .merge(utoipa_swagger_ui::SwaggerUi::new("/docs"))
        .layer(tower_http::compression::CompressionLayer::new())
        .layer(tower_http::timeout::TimeoutLayer::with_status_code(
            StatusCode::REQUEST_TIMEOUT,
            state.config.request_timeout,
        ));
    streaming
        .merge(api)
        .layer(middleware::from_fn_with_state(state.clone(), count_requests))
        .layer(cors)
        .layer(TraceLayer::new_for_http().make_span_with(|req: &Request| {
            let id = req.headers().get("x-request-id").and_then(|v| v.to_str().ok()).unwrap_or("-");
            tracing::info_span!("request", method = %req.method(), uri = %req.uri().path(), request_id = %id)
        }))
        .layer(PropagateRequestIdLayer::new(x_request_id.clone()))
        .layer(SetRequestIdLayer::new(x_request_id, Counter::default()))
        .with_state(state)
}

/// The web form's files, compiled into the binary: nothing to deploy, nothing fetched.
fn static_file(name: &str) -> Response {
    let (body, ctype): (&'static str, &str) = match name {
        "index.html" => (include_str!("web/index.html"), "text/html; charset=utf-8"),
        "app.js" => (include_str!("web/app.js"), "text/javascript; charset=utf-8"),
        "style.css" => (include_str!("web/style.css"), "text/css; charset=utf-8"),
        _ => return (StatusCode::NOT_FOUND, "not found").into_response(),
    };
    ([(header::CONTENT_TYPE, ctype), (header::CACHE_CONTROL, "no-cache")], body).into_response()
}

/// Requests by route and status, for `/metrics`.
async fn count_requests(State(st): State<Arc<AppState>>, req: Request, next: Next) -> Response {
    let route = req
        .extensions()
        .get::<MatchedPath>()
        .map_or("unmatched".to_string(), |p| p.as_str().to_string());
    let resp = next.run(req).await;
    st.metrics.record_request(&route, resp.status().as_u16());
    resp
}

/// Streams beyond the limit are refused at once (503 + Retry-After), never queued into memory.
async fn admit_stream(State(st): State<Arc<AppState>>, req: Request, next: Next) -> Response {
    if st.metrics.streams.load(Ordering::Relaxed) as usize >= st.config.max_streams {
        return ApiError::Busy(format!("{} post streams running", st.config.max_streams)).into_response();
    }
    next.run(req).await
}

/// A machine profile as the API shows it: the profile's own numbers, plus its kinematics kind.
#[derive(Serialize, utoipa::ToSchema)]
pub struct MachineDto {
    pub id: String,
    pub name: String,
    /// `mm` or `inch`.
    pub units: String,
    /// Default NC dialect.
    pub controller: String,
    pub description: String,
    /// table-table, head-head, head-table, 4-axis, 3-axis, 3-rotary/2-linear …
    pub kinematics: String,
    pub linear: Vec<LinearDto>,
    pub rotary: Vec<RotaryDto>,
    pub default_tool_length: f64,
}

#[derive(Serialize, utoipa::ToSchema)]
pub struct LinearDto {
    pub name: String,
    pub min: f64,
    pub max: f64,
    pub max_feed: Option<f64>,
}

#[derive(Serialize, utoipa::ToSchema)]
pub struct RotaryDto {
    pub name: String,
    /// `table` or `head`.
    pub on: String,
    pub axis: [f64; 3],
    pub pivot: [f64; 3],
    /// Degrees; absent for an unbounded axis.
    pub min: Option<f64>,
    pub max: Option<f64>,
    pub max_feed: Option<f64>,
    pub angle_error: Option<AngleErrorDto>,
    /// NC words that lock and unlock the axis around positioning, if it is clamped.
    pub clamp: Option<Vec<String>>,
}

#[derive(Serialize, utoipa::ToSchema)]
pub struct AngleErrorDto {
    pub coefficients: Vec<f64>,
    pub range: [f64; 2],
}

impl From<&Profile> for MachineDto {
    fn from(p: &Profile) -> Self {
        let d = &p.doc;
        MachineDto {
            id: p.machine.id.clone(),
            name: p.machine.name.clone(),
            units: p.machine.units.as_str().into(),
            controller: p.machine.controller.clone(),
            description: p.machine.description.clone(),
            kinematics: p.machine.kinematics_kind(),
            linear: d
                .linear
                .iter()
                .map(|l| LinearDto {
                    name: l.name.clone(),
                    min: l.min,
                    max: l.max,
                    max_feed: l.max_feed,
                })
                .collect(),
            rotary: d
                .rotary
                .iter()
                .map(|r| RotaryDto {
                    name: r.name.clone(),
                    on: r.on.clone(),
                    axis: r.axis,
                    pivot: r.pivot,
                    min: r.min,
                    max: r.max,
                    max_feed: r.max_feed,
                    angle_error: r.angle_error.as_ref().map(|e| AngleErrorDto {
                        coefficients: e.coefficients.clone(),
                        range: e.range,
                    }),
                    clamp: r.clamp.as_ref().map(|c| c.to_vec()),
                })
                .collect(),
            default_tool_length: p.machine.default_tool_length,
        }
    }
}

/// Every machine profile, geometry included.
#[utoipa::path(get, path = "/v1/machines", responses((status = 200, body = Vec<MachineDto>)), tag = "machines")]
async fn list_machines(State(st): State<Arc<AppState>>) -> Json<Vec<MachineDto>> {
    Json(st.library.iter().map(|p| MachineDto::from(p.as_ref())).collect())
}

/// One machine profile.
#[utoipa::path(
    get,
    path = "/v1/machines/{id}",
    params(("id" = String, Path, description = "Profile id, e.g. haas-umc750")),
    responses((status = 200, body = MachineDto), (status = 404, body = Problem, content_type = "application/problem+json")),
    tag = "machines"
)]
async fn get_machine(State(st): State<Arc<AppState>>, Path(id): Path<String>) -> Result<Json<MachineDto>, ApiError> {
    let p = st.library.get(&id).map_err(|_| ApiError::UnknownMachine(id))?;
    Ok(Json(MachineDto::from(p.as_ref())))
}

/// A controller dialect and its words for the things that differ between controls.
#[derive(Serialize, utoipa::ToSchema)]
pub struct DialectDto {
    pub name: String,
    pub title: String,
    /// `word_address` or `conversational`.
    pub style: String,
    pub tcp_on: String,
    pub tcp_off: String,
    /// The inverse-time feed word, if the control has one.
    pub inverse_time: Option<String>,
    pub tool_change: Vec<String>,
    /// Machines whose profile names this dialect as their controller (their default).
    pub default_for: Vec<String>,
    pub notes: String,
}

/// The NC dialects; a post request may name any, the profile's `controller` is the default.
#[utoipa::path(get, path = "/v1/dialects", responses((status = 200, body = Vec<DialectDto>)), tag = "post")]
async fn list_dialects(State(st): State<Arc<AppState>>) -> Json<Vec<DialectDto>> {
    Json(
        crate::nc::ALL
            .iter()
            .map(|d| DialectDto {
                name: d.name.into(),
                title: d.title.into(),
                style: match d.style {
                    crate::nc::Style::WordAddress => "word_address".into(),
                    crate::nc::Style::Conversational => "conversational".into(),
                },
                tcp_on: d.tcp_on.into(),
                tcp_off: d.tcp_off.into(),
                inverse_time: d.inverse_time.map(str::to_string),
                tool_change: d.tool_change.iter().map(|s| s.to_string()).collect(),
                default_for: st
                    .library
                    .iter()
                    .filter(|p| p.machine.controller == d.name)
                    .map(|p| p.machine.id.clone())
                    .collect(),
                notes: d.notes.into(),
            })
            .collect(),
    )
}

/// Alive.
#[utoipa::path(get, path = "/healthz", responses((status = 200, description = "ok")), tag = "ops")]
async fn healthz() -> &'static str {
    "ok"
}

/// Ready: machines loaded and the data directory writable.
#[utoipa::path(get, path = "/readyz", responses((status = 200, description = "ready"), (status = 503, body = Problem, content_type = "application/problem+json")), tag = "ops")]
async fn readyz(State(st): State<Arc<AppState>>) -> Result<Response, ApiError> {
    if st.library.is_empty() {
        return Err(ApiError::Busy("no machine profiles loaded".into()));
    }
    let probe = st.config.data_dir.join(".readyz");
    std::fs::create_dir_all(&st.config.data_dir)
        .and_then(|_| std::fs::write(&probe, b"ok"))
        .and_then(|_| std::fs::remove_file(&probe))
        .map_err(|e| ApiError::Busy(format!("data directory {} not writable: {e}", st.config.data_dir.display())))?;
    Ok((StatusCode::OK, format!("ready: {} machines", st.library.len())).into_response())
}

/// Prometheus metrics.
#[utoipa::path(get, path = "/metrics", responses((status = 200, description = "Prometheus text format", content_type = "text/plain")), tag = "ops")]
async fn metrics_route(State(st): State<Arc<AppState>>) -> impl IntoResponse {
    ([(header::CONTENT_TYPE, "text/plain; version=0.0.4")], st.metrics.render())
}

/// Loads the library and binds; runs until SIGINT/SIGTERM, then lets streams in flight finish.
pub async fn serve(cfg: Config) -> Result<(), String> {
    let library = Library::load_dir(&cfg.machines).map_err(|e| e.to_string())?;
    std::fs::create_dir_all(&cfg.data_dir).map_err(|e| format!("{}: {e}", cfg.data_dir.display()))?;
    let listener = tokio::net::TcpListener::bind(&cfg.bind)
        .await
        .map_err(|e| format!("bind {}: {e}", cfg.bind))?;
    let addr = listener.local_addr().map_err(|e| e.to_string())?;
    tracing::info!(%addr, machines = library.len(), "kinepost listening");
    eprintln!("kinepost: listening on http://{addr} ({} machines)", library.len());
    let queue = crate::jobs::Queue::start(cfg.jobs(), library.clone())
        .await
        .map_err(|e| format!("job queue in {}: {e}", cfg.data_dir.display()))?;
    let state = Arc::new(AppState {
        library,
        config: cfg,
        metrics: Arc::new(Metrics::default()),
        jobs: Some(queue),
    });
    axum::serve(listener, app(state))
        .with_graceful_shutdown(shutdown_signal())
        .await
        .map_err(|e| e.to_string())
}

async fn shutdown_signal() {
    let ctrl_c = async {
        let _ = tokio::signal::ctrl_c().await;
    };
    #[cfg(unix)]
    let term = async {
        if let Ok(mut s) = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            s.recv().await;
        }
    };
    #[cfg(not(unix))]
    let term = std::future::pending::<()>();
    tokio::select! { _ = ctrl_c => {}, _ = term => {} }
    tracing::info!("shutting down: finishing streams in flight");
}
