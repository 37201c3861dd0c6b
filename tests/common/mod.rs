//! A real kinepost server on an ephemeral loopback port, for integration tests.

use kinepost::http::{AppState, Config, Metrics, app};
use kinepost::machines::Library;
use std::sync::Arc;

pub async fn server(cfg: Config) -> String {
    let library = Library::load_dir(&cfg.machines).unwrap();
    let state = Arc::new(AppState {
        library: library.clone(),
        config: cfg.clone(),
        metrics: Arc::new(Metrics::default()),
        jobs: Some(kinepost::jobs::Queue::start(cfg.jobs(), library.clone()).await.unwrap()),
    });
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    tokio::spawn(async move { axum::serve(listener, app(state)).await.unwrap() });
    format!("http://{addr}")
}

static NEXT: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);

pub fn cfg() -> Config {
    Config {
        machines: concat!(env!("CARGO_MANIFEST_DIR"), "/machines").into(),
        // One data directory per server: each has its own job store.
        data_dir: std::env::temp_dir().join(format!(
            "kinepost-http-{}-{}",
            std::process::id(),
            NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
        )),
        ..Config::default()
    }
}
