//! The HTTP service: the engine for CAM plugins (REST), machinists (the web form) and scripts.
//! Only this module knows HTTP, JSON DTOs and status codes. `app()` builds the whole router,
//! testable without a socket; `serve()` binds it and shuts down gracefully, finishing streams
//! in flight.

mod dialects;
mod download;
mod error;
mod jobs;
mod limits;
mod lines;
mod machine_ops;
mod machines;
mod metrics;
mod post;
pub mod refusals;
mod server;
mod shelf;
mod tools;
mod upload;

pub use error::{ApiError, ApiJson, Problem};
pub use metrics::Metrics;
pub use server::{connection_budget, run};

use crate::machines::Library;
use axum::extract::{Path, Request, State};
use axum::http::{HeaderName, HeaderValue, Method, StatusCode, header};
use axum::middleware;
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post as post_route};
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
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
    /// The shop's dialect files beside the built-ins (`--dialects`, `KINEPOST_DIALECTS`).
    pub dialects: PathBuf,
    pub data_dir: PathBuf,
    /// Largest upload accepted (bytes): files are streamed, not buffered, so this can be large.
    pub max_upload: u64,
    /// Longest a non-streaming request may take.
    pub request_timeout: Duration,
    /// Post streams running at once; more are answered 503 with Retry-After.
    pub max_streams: usize,
    /// A new connection must have sent its first request's headers within this.
    pub header_timeout: Duration,
    /// A connection with no request in flight is closed after this (keep-alive).
    pub idle_timeout: Duration,
    /// A response whose client reads nothing for this long is cut off, its connection closed
    /// (zero: never).
    pub write_timeout: Duration,
    /// Downloads (a job's outputs and input, meshes) one client address may have in flight at
    /// once (429 beyond); 0: no limit.
    pub max_downloads_per_client: usize,
    /// Connections open at once; at the limit the one idle longest is closed for a new one.
    pub max_connections: usize,
    /// Bytes a second an upload must average over `upload_rate_window` (0: no minimum); a slower
    /// one fails (408, or an error at the end of a stream already started).
    pub min_upload_rate: u64,
    pub upload_rate_window: Duration,
    /// Origins allowed by CORS (CAM plugins' web views); empty: no CORS headers.
    pub cors_origins: Vec<String>,
    pub log_json: bool,
    /// Jobs run at once (default: one per core).
    pub workers: usize,
    /// Jobs waiting at most; more are answered 503 with Retry-After.
    pub max_queued: u64,
    /// Jobs one client address may have queued or running (429 beyond); 0: no limit.
    pub max_jobs_per_client: u64,
    /// Finished jobs and their files are removed after this long.
    pub job_retention: Duration,
    /// Bearer token that machine-profile writes must carry; `None`: writes are off.
    pub admin_token: Option<String>,
    /// PostgreSQL for replicas sharing one queue; `None`: SQLite in `data_dir`.
    pub database_url: Option<String>,
    /// The spool replicas share; `None`: `data_dir/spool`.
    pub spool_dir: Option<PathBuf>,
    /// A running job whose node stops reporting for this long is taken over (replicas).
    pub job_lease: Duration,
    /// After SIGTERM, how long requests in flight may take before the server stops anyway (a
    /// client trickling an upload must not keep it up for ever; accepted jobs resume on restart).
    pub shutdown_grace: Duration,
    /// What one post (stream or job) may cost: output per CL byte read, and seconds.
    pub post_budget: crate::post::Budget,
    /// Threads a streamed post runs on, and a job's (`post::threads`; see reliability.md for
    /// why one each under load); a job's 0: two where a core is idle (`jobs::Config::threads`).
    pub post_threads: usize,
    pub job_threads: usize,
    /// Runs a job may have when faults outside it (the spool, the store, a replica) end them.
    pub job_max_attempts: u32,
    /// The pause before a job runs again after such a fault, doubled before each next run.
    pub job_retry_backoff: Duration,
}

impl Config {
    /// The job queue's part of the settings.
    pub fn jobs(&self) -> crate::jobs::Config {
        crate::jobs::Config {
            data_dir: self.data_dir.clone(),
            workers: self.workers,
            max_queued: self.max_queued,
            max_per_client: self.max_jobs_per_client,
            retention: self.job_retention,
            database_url: self.database_url.clone(),
            spool_dir: self.spool_dir.clone(),
            lease: self.job_lease,
            budget: self.post_budget,
            threads: self.job_threads,
            max_attempts: self.job_max_attempts,
            retry_backoff: self.job_retry_backoff,
        }
    }
}

impl Default for Config {
    fn default() -> Self {
        Config {
            bind: "127.0.0.1:8080".into(),
            machines: crate::machines::default_dir(),
            dialects: crate::machines::dialects::default_dir(),
            data_dir: PathBuf::from("data"),
            max_upload: 4 << 30,
            request_timeout: Duration::from_secs(30),
            max_streams: 64,
            header_timeout: Duration::from_secs(30),
            idle_timeout: Duration::from_secs(60),
            write_timeout: Duration::from_secs(30),
            max_downloads_per_client: 8,
            max_connections: 4096,
            min_upload_rate: 1024,
            upload_rate_window: Duration::from_secs(30),
            cors_origins: Vec::new(),
            log_json: false,
            workers: std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1),
            max_queued: 1000,
            max_jobs_per_client: 100,
            job_retention: Duration::from_secs(7 * 24 * 3600),
            admin_token: None,
            database_url: None,
            spool_dir: None,
            job_lease: Duration::from_secs(30),
            shutdown_grace: Duration::from_secs(60),
            post_budget: crate::post::Budget::default(),
            post_threads: 1,
            job_threads: 0,
            job_max_attempts: 5,
            job_retry_backoff: Duration::from_secs(2),
        }
    }
}

pub struct AppState {
    /// The live machine library (profile files, then API versions).
    pub machines: Arc<crate::machines::Catalog>,
    pub config: Config,
    pub metrics: Arc<Metrics>,
    /// The job queue; `None` where a process serves posts only (benches).
    pub jobs: Option<Arc<crate::jobs::Queue>>,
}

#[derive(OpenApi)]
#[openapi(
    info(title = "kinepost", description = "5-axis CNC postprocessor: CL data in, verified NC out, for any machine profile."),
    paths(post::post_cl, machines::list_machines, machines::get_machine, machines::create_machine, machines::put_machine,
        machines::delete_machine, machines::list_versions, machines::get_version, machines::get_mesh, tools::get_tools, tools::put_tools,
        tools::delete_tools, tools::list_tool_versions, tools::get_tool_version, dialects::list_dialects,
        dialects::get_dialect, dialects::create_dialect, dialects::put_dialect, dialects::delete_dialect, dialects::list_dialect_versions, dialects::get_dialect_version, machine_ops::fk_route, machine_ops::ik_route,
        machine_ops::validate_pose, machine_ops::angle_error_fit, machine_ops::calibrate, healthz, readyz, metrics::metrics_route,
        jobs::submit, jobs::list_jobs, jobs::get_job, jobs::delete_job, jobs::job_nc, jobs::job_diagnostics, jobs::job_preview,
        jobs::job_input, jobs::job_lines),
    components(schemas(Problem, machines::MachineDto, machines::LinearDto, machines::RotaryDto, machines::AngleErrorDto,
        shelf::VersionsDto, shelf::VersionDto, tools::ToolTableDto, tools::ToolDto, tools::HolderDto, dialects::DialectDto, crate::post::Settings, machine_ops::FkRequest,
        machine_ops::PoseDto, machine_ops::PoseRequest, machine_ops::ReachDto, machine_ops::AngleFitRequest, machine_ops::FitDto,
        machine_ops::AngleFitResponse, machine_ops::MeasurementDto, machine_ops::CalibrateRequest, machine_ops::CalibrateResponse,
        jobs::JobView, jobs::JobProgress, jobs::JobLinks, jobs::JobList)),
    modifiers(&AdminToken),
    tags((name = "post", description = "Post-processing"), (name = "machines", description = "Machine profiles"), (name = "dialects", description = "NC dialects: the built-ins and the shop's own"), (name = "jobs", description = "Background jobs for large toolpaths"), (name = "ops", description = "Health and metrics"))
)]
pub struct ApiDoc;

/// The bearer token that machine-profile writes carry (`KINEPOST_ADMIN_TOKEN`).
struct AdminToken;

impl utoipa::Modify for AdminToken {
    fn modify(&self, api: &mut utoipa::openapi::OpenApi) {
        use utoipa::openapi::security::{Http, HttpAuthScheme, SecurityScheme};
        api.components
            .get_or_insert_with(Default::default)
            .add_security_scheme("admin", SecurityScheme::Http(Http::new(HttpAuthScheme::Bearer)));
    }
}

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
    // The pace is metered inside the length limit, so that the limit's error reaches the
    // multipart reader as its own type (413, not 400).
    let streams = tower::ServiceBuilder::new()
        .layer(middleware::map_response_with_state(state.clone(), bare_problem))
        .layer(middleware::from_fn_with_state(state.clone(), limits::min_upload_rate))
        .layer(axum::extract::DefaultBodyLimit::disable())
        .layer(tower_http::limit::RequestBodyLimitLayer::new(
            state.config.max_upload.min(usize::MAX as u64) as usize,
        ));
    // A client's downloads in flight are counted until each body is sent or dropped.
    let download = middleware::from_fn_with_state(state.clone(), limits::admit_download);
    // Streams are neither compressed (CompressionLayer holds them back) nor timed out.
    let streaming = axum::Router::new()
        .route(
            "/v1/post",
            post_route(post::post_cl)
                .layer(streams.clone())
                .layer(middleware::from_fn_with_state(state.clone(), limits::admit_stream)),
        )
        .route(
            "/v1/jobs",
            post_route(jobs::submit).layer(streams.clone()).get(jobs::list_jobs),
        )
        .route("/v1/jobs/{id}", get(jobs::get_job).delete(jobs::delete_job))
        .route("/v1/jobs/{id}/nc", get(jobs::job_nc).layer(download.clone()))
        .route(
            "/v1/jobs/{id}/diagnostics",
            get(jobs::job_diagnostics).layer(download.clone()),
        )
        .route("/v1/jobs/{id}/input", get(jobs::job_input).layer(download.clone()))
        .route("/v1/jobs/{id}/lines", get(jobs::job_lines).layer(download.clone()));
    let api = axum::Router::new()
        .route("/v1/machines", get(machines::list_machines).post(machines::create_machine))
        .route("/v1/dialects", get(dialects::list_dialects).post(dialects::create_dialect))
        .route(
            "/v1/dialects/{id}",
            get(dialects::get_dialect).put(dialects::put_dialect).delete(dialects::delete_dialect),
        )
        .route("/v1/dialects/{id}/versions", get(dialects::list_dialect_versions))
        .route("/v1/dialects/{id}/versions/{version}", get(dialects::get_dialect_version))
        .route(
            "/v1/machines/{id}",
            get(machines::get_machine)
                .put(machines::put_machine)
                .delete(machines::delete_machine),
        )
        .route("/v1/machines/{id}/versions", get(machines::list_versions))
        .route("/v1/machines/{id}/versions/{version}", get(machines::get_version))
        .route(
            "/v1/machines/{id}/meshes/{file}",
            get(machines::get_mesh).layer(download.clone()),
        )
        .route(
            "/v1/machines/{id}/tools",
            get(tools::get_tools).put(tools::put_tools).delete(tools::delete_tools),
        )
        .route("/v1/machines/{id}/tools/versions", get(tools::list_tool_versions))
        .route("/v1/machines/{id}/tools/versions/{version}", get(tools::get_tool_version))
        .route("/v1/machines/{id}/fk", post_route(machine_ops::fk_route))
        .route("/v1/machines/{id}/ik", post_route(machine_ops::ik_route))
        .route("/v1/machines/{id}/validate-pose", post_route(machine_ops::validate_pose))
        .route("/v1/machines/{id}/angle-error-fit", post_route(machine_ops::angle_error_fit))
        .route("/v1/machines/{id}/calibrate", post_route(machine_ops::calibrate))
        // A preview is a few MB of JSON read whole: compressed, unlike the streams.
        .route("/v1/jobs/{id}/preview", get(jobs::job_preview))
        .route("/healthz", get(healthz))
        .route("/readyz", get(readyz))
        .route("/metrics", get(metrics::metrics_route))
        .route(
            "/openapi.json",
            get(|| async { ([(header::CONTENT_TYPE, "application/json")], openapi_json()) }),
        )
        .route("/", get(|| async { static_file("index.html") }))
        .route("/machine-check.html", get(|| async { static_file("machine-check.html") }))
        .route("/static/{file}", get(|Path(f): Path<String>| async move { static_file(&f) }))
        .route(
            "/static/vendor/three/{file}",
            get(|Path(f): Path<String>| async move { vendor_file(&f) }),
        );
    let cors = if state.config.cors_origins.is_empty() {
        CorsLayer::new()
    } else {
        let origins: Vec<HeaderValue> = state
            .config
            .cors_origins
            .iter()
            .filter_map(|o| HeaderValue::from_str(o).ok())
            .collect();
        // Listed, not `*`: a wildcard does not cover Authorization (Fetch standard), and a
        // browser would keep a plug-in's profile writes from being sent.
        CorsLayer::new()
            .allow_origin(AllowOrigin::list(origins))
            .allow_methods([Method::GET, Method::HEAD, Method::POST, Method::PUT, Method::DELETE])
            .allow_headers(CORS_REQUEST_HEADERS.map(HeaderName::from_static))
            .expose_headers(CORS_EXPOSED_HEADERS.map(HeaderName::from_static))
            .max_age(Duration::from_secs(600))
    };
    // Debug builds: a refusal the document does not list for its route is a bug (`refusals`).
    #[cfg(debug_assertions)]
    let (streaming, api) = (
        streaming.route_layer(middleware::from_fn(refusals::undocumented_refusal)),
        api.route_layer(middleware::from_fn(refusals::undocumented_refusal)),
    );
    let api = api
        // The UI loads the document this service serves at /openapi.json (its own route).
        .merge(utoipa_swagger_ui::SwaggerUi::new("/docs").config(utoipa_swagger_ui::Config::new(["/openapi.json"])))
        .layer(tower_http::compression::CompressionLayer::new())
        .layer(tower_http::timeout::TimeoutLayer::with_status_code(
            StatusCode::REQUEST_TIMEOUT,
            state.config.request_timeout,
        ))
        .layer(middleware::map_response_with_state(state.clone(), bare_problem));
    streaming
        .merge(api)
        .layer(middleware::from_fn_with_state(state.clone(), metrics::count_requests))
        .layer(cors)
        .layer(TraceLayer::new_for_http().make_span_with(|req: &Request| {
            let id = req.headers().get("x-request-id").and_then(|v| v.to_str().ok()).unwrap_or("-");
            tracing::info_span!("request", method = %req.method(), uri = %req.uri().path(), request_id = %id)
        }))
        .layer(PropagateRequestIdLayer::new(x_request_id.clone()))
        .layer(SetRequestIdLayer::new(x_request_id, Counter::default()))
        .with_state(state)
}

/// Request headers the API reads, which a browser may send cross-origin.
const CORS_REQUEST_HEADERS: [&str; 9] = [
    "authorization",
    "content-type",
    "if-match",
    "if-none-match",
    "if-range",
    "range",
    "idempotency-key",
    "x-request-id",
    "accept",
];

/// Response headers a cross-origin script may read (beyond the CORS-safelisted ones).
const CORS_EXPOSED_HEADERS: [&str; 8] = [
    "etag",
    "location",
    "retry-after",
    "x-request-id",
    "content-range",
    "content-disposition",
    "accept-ranges",
    "www-authenticate",
];

/// The web form's files, compiled into the binary: nothing to deploy, nothing fetched.
fn static_file(name: &str) -> Response {
    let (body, ctype): (&'static str, &str) = match name {
        "index.html" => (include_str!("web/index.html"), "text/html; charset=utf-8"),
        "app.js" => (include_str!("web/app.js"), "text/javascript; charset=utf-8"),
        "style.css" => (include_str!("web/style.css"), "text/css; charset=utf-8"),
        "view.js" => (include_str!("web/view.js"), "text/javascript; charset=utf-8"),
        "ncview.js" => (include_str!("web/ncview.js"), "text/javascript; charset=utf-8"),
        "kin.js" => (include_str!("web/kin.js"), "text/javascript; charset=utf-8"),
        "machine3d.js" => (include_str!("web/machine3d.js"), "text/javascript; charset=utf-8"),
        "viewport.js" => (include_str!("web/viewport.js"), "text/javascript; charset=utf-8"),
        "simulate.js" => (include_str!("web/simulate.js"), "text/javascript; charset=utf-8"),
        "check.js" => (include_str!("web/check.js"), "text/javascript; charset=utf-8"),
        "machine-check.html" => (include_str!("web/machine-check.html"), "text/html; charset=utf-8"),
        _ => return (StatusCode::NOT_FOUND, "not found").into_response(),
    };
    ([(header::CONTENT_TYPE, ctype), (header::CACHE_CONTROL, "no-cache")], body).into_response()
}

/// three.js, vendored from npm (see `web/vendor/three/README`): the page's 3D view loads it by
/// an import map, so nothing is fetched from the internet. It changes only with a release.
fn vendor_file(name: &str) -> Response {
    let body: &'static str = match name {
        "three.module.js" => include_str!("web/vendor/three/three.module.js"),
        "three.core.js" => include_str!("web/vendor/three/three.core.js"),
        "OrbitControls.js" => include_str!("web/vendor/three/OrbitControls.js"),
        "LICENSE" => include_str!("web/vendor/three/LICENSE"),
        _ => return (StatusCode::NOT_FOUND, "not found").into_response(),
    };
    let ctype = if name == "LICENSE" {
        "text/plain; charset=utf-8"
    } else {
        "text/javascript; charset=utf-8"
    };
    (
        [
            (header::CONTENT_TYPE, ctype),
            (header::CACHE_CONTROL, "public, max-age=86400"),
        ],
        body,
    )
        .into_response()
}

/// `304 Not Modified`, carrying the ETag, when `If-None-Match` names `etag` (or `*`): for every
/// route whose representations never change under one ETag.
fn not_modified(headers: &axum::http::HeaderMap, etag: &str) -> Option<Response> {
    let hit = headers
        .get(header::IF_NONE_MATCH)
        .and_then(|v| v.to_str().ok())
        .is_some_and(|v| v.split(',').any(|t| t.trim() == etag || t.trim() == "*"));
    let etag = HeaderValue::from_str(etag).ok()?;
    hit.then(|| (StatusCode::NOT_MODIFIED, [(header::ETAG, etag)]).into_response())
}

/// The layers that answer on their own (the body limit's 413 in text/plain, the request
/// timeout's empty 408) answer, as every error, with a problem document naming the limit.
async fn bare_problem<B>(State(st): State<Arc<AppState>>, resp: axum::http::Response<B>) -> Response
where
    B: axum::body::HttpBody<Data = bytes::Bytes> + Send + 'static,
    B::Error: Into<axum::BoxError>,
{
    let is_problem = resp
        .headers()
        .get(header::CONTENT_TYPE)
        .is_some_and(|v| v.as_bytes().starts_with(b"application/problem+json"));
    if is_problem {
        return resp.map(axum::body::Body::new);
    }
    match resp.status() {
        StatusCode::PAYLOAD_TOO_LARGE => error::ApiError::TooLarge(Some(st.config.max_upload)).into_response(),
        StatusCode::REQUEST_TIMEOUT => error::ApiError::Timeout(format!(
            "the request took longer than {:?} (--request-timeout)",
            st.config.request_timeout
        ))
        .into_response(),
        _ => resp.map(axum::body::Body::new),
    }
}


/// Alive.
#[utoipa::path(get, path = "/healthz", responses((status = 200, description = "ok")), tag = "ops")]
async fn healthz() -> &'static str {
    "ok"
}

/// Ready: machines loaded, the data directory writable, the job store answering, and a post
/// could be served now (a stream slot free, a blocking thread to run it on).
#[utoipa::path(get, path = "/readyz", responses((status = 200, description = "ready"), (status = 503, description = "Not ready or overloaded: retry later", body = Problem, content_type = "application/problem+json")), tag = "ops")]
async fn readyz(State(st): State<Arc<AppState>>) -> Result<Response, ApiError> {
    if st.machines.is_empty() {
        return Err(ApiError::Busy("no machine profiles loaded".into()));
    }
    if st.metrics.streams_running() >= st.config.max_streams as u64 {
        return Err(ApiError::Busy(format!(
            "every post stream is running ({}, --max-streams)",
            st.config.max_streams
        )));
    }
    // A post runs on the blocking pool: when every thread of it is held, no post starts
    // however idle the runtime is (and `/healthz` answers at once).
    let probe = tokio::task::spawn_blocking(|| ());
    if tokio::time::timeout(Duration::from_secs(1), probe).await.is_err() {
        return Err(ApiError::Busy("no thread free to run a post within 1 s".into()));
    }
    let probe = st.config.data_dir.join(".readyz");
    std::fs::create_dir_all(&st.config.data_dir)
        .and_then(|_| std::fs::write(&probe, b"ok"))
        .and_then(|_| std::fs::remove_file(&probe))
        .map_err(|e| ApiError::Busy(format!("data directory {} not writable: {e}", st.config.data_dir.display())))?;
    if let Some(q) = &st.jobs {
        match tokio::time::timeout(Duration::from_secs(3), q.store.check()).await {
            Ok(Ok(_)) => {}
            Ok(Err(e)) => return Err(ApiError::Busy(e.to_string())),
            Err(_) => return Err(ApiError::Busy("the job store did not answer in 3 s".into())),
        }
    }
    let node = st
        .jobs
        .as_ref()
        .map_or(String::new(), |q| format!(", node {}", q.store.node()));
    Ok((StatusCode::OK, format!("ready: {} machines{node}", st.machines.len())).into_response())
}

/// Loads the library and binds; runs until SIGINT/SIGTERM, then lets streams in flight finish.
pub async fn serve(mut cfg: Config) -> Result<(), String> {
    let library = Library::load_dir(&cfg.machines)
        .and_then(|l| l.with_dialects(&cfg.dialects))
        .map_err(|e| e.to_string())?;
    std::fs::create_dir_all(&cfg.data_dir).map_err(|e| format!("{}: {e}", cfg.data_dir.display()))?;
    let fit = connection_budget(cfg.max_connections);
    if fit < cfg.max_connections {
        tracing::warn!(
            max_connections = fit,
            "fewer connections than --max-connections fit the open-file limit (ulimit -n)"
        );
        cfg.max_connections = fit;
    }
    // The store is opened and checked before the port: a damaged store stops the start.
    let (queue, machines) = crate::jobs::Queue::start(cfg.jobs(), &library)
        .await
        .map_err(|e| format!("job queue in {}: {e}", cfg.data_dir.display()))?;
    let listener = tokio::net::TcpListener::bind(&cfg.bind)
        .await
        .map_err(|e| format!("bind {}: {e}", cfg.bind))?;
    let addr = listener.local_addr().map_err(|e| e.to_string())?;
    // One line, in the log's own format (a plain line broke a JSON log).
    tracing::info!(machines = library.len(), "kinepost listening on http://{addr}");
    let metrics = Arc::new(Metrics::default());
    let m = metrics.clone();
    queue.observe(Box::new(move |outcome, secs| m.record_job(outcome, secs)));
    let grace = cfg.shutdown_grace;
    let state = Arc::new(AppState {
        machines,
        config: cfg.clone(),
        metrics,
        jobs: Some(queue),
    });
    let (stopping, mut stop) = tokio::sync::watch::channel(false);
    let server = run(listener, app(state), &cfg, async move {
        shutdown_signal().await;
        let _ = stopping.send(true);
    });
    let deadline = async move {
        if stop.wait_for(|s| *s).await.is_ok() {
            tokio::time::sleep(grace).await;
            tracing::warn!(?grace, "shutdown grace over: stopping with requests still in flight");
        } else {
            std::future::pending::<()>().await;
        }
    };
    tokio::select! {
        () = server => Ok(()),
        () = deadline => Ok(()),
    }
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
