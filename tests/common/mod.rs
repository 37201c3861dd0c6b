//! A real kinepost server on an ephemeral loopback port, for integration tests.

use kinepost::http::{AppState, Config, Metrics, app};
use kinepost::machines::Library;
use std::sync::Arc;

pub async fn server(cfg: Config) -> String {
    let library = Library::load_dir(&cfg.machines).unwrap();
    let state = Arc::new(AppState {
        library,
        config: cfg,
        metrics: Arc::new(Metrics::default()),
    });
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    tokio::spawn(async move { axum::serve(listener, app(state)).await.unwrap() });
    format!("http://{addr}")
}

pub fn cfg() -> Config {
    Config {
        machines: concat!(env!("CARGO_MANIFEST_DIR"), "/machines").into(),
        data_dir: std::env::temp_dir().join(format!("kinepost-http-{}", std::process::id())),
        ..Config::default()
    }
}
