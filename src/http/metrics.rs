//! `/metrics`: the service's counters in a `prometheus-client` registry, served as OpenMetrics
//! text. Every series whose labels are known beforehand exists from the start, at 0: a series
//! that appears only with its first event breaks alerts (`rate`, `absent`) and dashboards.

use super::AppState;
use crate::jobs::JobState;
use axum::extract::{MatchedPath, Request, State};
use axum::http::header;
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use prometheus_client::encoding::EncodeLabelSet;
use prometheus_client::encoding::text::{encode_eof, encode_registry};
use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::family::Family;
use prometheus_client::metrics::gauge::Gauge;
use prometheus_client::metrics::histogram::Histogram;
use prometheus_client::registry::{Registry, Unit};
use std::sync::Arc;

/// What Prometheus asks for first in its `Accept` header, and what the encoder writes.
pub const CONTENT_TYPE: &str = "application/openmetrics-text; version=1.0.0; charset=utf-8";

/// Upper bounds (seconds) of the duration histograms' buckets: from a short stream to a long job.
const BUCKETS: [f64; 10] = [0.01, 0.05, 0.1, 0.5, 1.0, 5.0, 30.0, 300.0, 1800.0, 7200.0];

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct RequestLabels {
    route: String,
    status: u16,
}

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct OutcomeLabel {
    outcome: &'static str,
}

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct StateLabel {
    state: &'static str,
}

fn duration_histogram() -> Histogram {
    Histogram::new(BUCKETS)
}

/// The service's metrics. The registry holds clones of the handles below (they share their
/// values), so recording goes through the fields and encoding through the registry.
pub struct Metrics {
    registry: Registry,
    requests: Family<RequestLabels, Counter>,
    streams: Gauge,
    cl_points: Counter,
    blocks: Counter,
    posts: Histogram,
    /// Job run durations by outcome (succeeded, failed, cancelled; retried: a fault outside the
    /// job ended the run and it was queued again).
    job_runs: Family<OutcomeLabel, Histogram, fn() -> Histogram>,
    /// Downloads in flight by client, for `--max-downloads-per-client`.
    pub(super) downloads: Downloads,
}

impl Default for Metrics {
    fn default() -> Self {
        let m = Metrics {
            registry: Registry::default(),
            requests: Family::default(),
            streams: Gauge::default(),
            cl_points: Counter::default(),
            blocks: Counter::default(),
            posts: duration_histogram(),
            job_runs: Family::new_with_constructor(duration_histogram),
            downloads: Downloads::default(),
        };
        for st in JobState::ALL.into_iter().filter(|s| s.finished()) {
            let _ = m.job_runs.get_or_create(&OutcomeLabel { outcome: st.as_str() });
        }
        let _ = m.job_runs.get_or_create(&OutcomeLabel { outcome: "retried" });
        m.registered()
    }
}

impl Metrics {
    /// Registers every handle under its exposed name (the encoder adds `_total` to counters and
    /// the unit to the histograms' names).
    fn registered(mut self) -> Self {
        let r = &mut self.registry;
        r.register(
            "kinepost_http_requests",
            "HTTP requests by route and status",
            self.requests.clone(),
        );
        r.register("kinepost_cl_points", "CL points post-processed", self.cl_points.clone());
        r.register("kinepost_blocks", "NC blocks written", self.blocks.clone());
        r.register("kinepost_streams_in_flight", "Post streams running now", self.streams.clone());
        r.register_with_unit(
            "kinepost_post_duration",
            "Duration of completed posts",
            Unit::Seconds,
            self.posts.clone(),
        );
        r.register_with_unit(
            "kinepost_job_duration",
            "Job runs ended on this node, by outcome",
            Unit::Seconds,
            self.job_runs.clone(),
        );
        self
    }

    fn record_request(&self, route: &str, status: u16) {
        let labels = RequestLabels {
            route: route.to_string(),
            status,
        };
        self.requests.get_or_create(&labels).inc();
    }

    pub fn record_post(&self, s: &crate::post::Summary, secs: f64) {
        self.cl_points.inc_by(s.cl_points);
        self.blocks.inc_by(s.blocks);
        self.posts.observe(secs.max(0.0));
    }

    /// A job run ended (`outcome`: its state), after `secs` of running.
    pub fn record_job(&self, outcome: &'static str, secs: f64) {
        self.job_runs.get_or_create(&OutcomeLabel { outcome }).observe(secs.max(0.0));
    }

    /// A post stream started: the number running before it (the admission check's count).
    pub(super) fn stream_started(&self) -> u64 {
        self.streams.inc().max(0) as u64
    }

    pub(super) fn stream_ended(&self) {
        self.streams.dec();
    }

    /// Post streams running now.
    pub(super) fn streams_running(&self) -> u64 {
        self.streams.get().max(0) as u64
    }

    /// The OpenMetrics text; `jobs`: jobs by state in the store (the queue depth), when it
    /// answered. Their gauge is built for this scrape, every state included at 0, so that a
    /// store that did not answer shows no stale depth and concurrent scrapes share nothing.
    pub fn render(&self, jobs: Option<&[(JobState, u64)]>) -> String {
        let mut o = String::new();
        // Writing into a String cannot fail.
        let _ = encode_registry(&mut o, &self.registry);
        if let Some(jobs) = jobs {
            let by_state = Family::<StateLabel, Gauge>::default();
            for st in JobState::ALL {
                let n = jobs.iter().find(|(s, _)| *s == st).map_or(0, |(_, n)| *n);
                by_state.get_or_create(&StateLabel { state: st.as_str() }).set(n as i64);
            }
            let mut r = Registry::default();
            r.register(
                "kinepost_jobs",
                "Jobs in the store by state (queued: the queue depth; all replicas)",
                by_state,
            );
            let _ = encode_registry(&mut o, &r);
        }
        let _ = encode_eof(&mut o);
        o
    }
}

/// Requests by route and status, for `/metrics`.
pub(super) async fn count_requests(State(st): State<Arc<AppState>>, req: Request, next: Next) -> Response {
    let route = req
        .extensions()
        .get::<MatchedPath>()
        .map_or("unmatched".to_string(), |p| p.as_str().to_string());
    let resp = next.run(req).await;
    st.metrics.record_request(&route, resp.status().as_u16());
    resp
}

/// Prometheus metrics.
#[utoipa::path(get, path = "/metrics", responses((status = 200, description = "OpenMetrics text format (Prometheus scrapes it)", content_type = "application/openmetrics-text")), tag = "ops")]
pub(super) async fn metrics_route(State(st): State<Arc<AppState>>) -> impl IntoResponse {
    let jobs = match &st.jobs {
        Some(q) => q.store.counts().await.ok(),
        None => None,
    };
    ([(header::CONTENT_TYPE, CONTENT_TYPE)], st.metrics.render(jobs.as_deref()))
}

/// The downloads in flight by client address: one client's stalled downloads hold their files
/// and buffers until the write deadline cuts them, so their number is bounded per client.
#[derive(Default)]
pub struct Downloads(std::sync::Mutex<std::collections::HashMap<std::net::IpAddr, usize>>);

impl Downloads {
    pub(super) fn lock(&self) -> std::sync::MutexGuard<'_, std::collections::HashMap<std::net::IpAddr, usize>> {
        self.0.lock().unwrap_or_else(|p| p.into_inner())
    }
}
