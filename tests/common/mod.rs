//! A real kinepost server on an ephemeral loopback port, for integration tests.
#![allow(dead_code)] // each test crate uses part of it

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

/// The real binary serving `data` on an ephemeral loopback port: the child and its base URL,
/// its log drained in the background.
pub fn spawn_binary(data: &std::path::Path, extra: &[&str]) -> (std::process::Child, String) {
    use std::io::{BufRead, BufReader};
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_kinepost"))
        .args(["serve", "--bind", "127.0.0.1:0", "--data-dir", data.to_str().unwrap()])
        .args(extra)
        .env("KINEPOST_MACHINES", concat!(env!("CARGO_MANIFEST_DIR"), "/machines"))
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut err = BufReader::new(child.stderr.take().unwrap());
    let mut line = String::new();
    let addr = loop {
        line.clear();
        assert!(err.read_line(&mut line).unwrap() > 0, "server exited early");
        if let Some(rest) = line.split("listening on ").nth(1) {
            break rest.split_whitespace().next().unwrap().to_string();
        }
    };
    std::thread::spawn(move || for _ in err.lines() {});
    (child, addr)
}

/// GET a JSON document.
pub async fn get_json(c: &reqwest::Client, url: &str) -> serde_json::Value {
    c.get(url).send().await.unwrap().json().await.unwrap()
}
