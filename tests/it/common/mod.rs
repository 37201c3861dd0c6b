//! A real kinepost server on an ephemeral loopback port, for integration tests.
#![allow(dead_code)] // not every helper is used by every run's configuration

pub mod collect;
pub mod stl;
pub mod verify;

use kinepost::http::{AppState, Config, Metrics, app};
use kinepost::kinematics::Machine;
use kinepost::machines::Library;
use kinepost::post::{self, Settings, Summary};
use std::path::PathBuf;
use std::sync::{Arc, OnceLock};

/// The shipped `machines/` directory, loaded once for the whole binary: most tests read it as
/// it is (a test that changes a profile loads a directory of its own).
pub fn library() -> &'static Library {
    static LIBRARY: OnceLock<Library> = OnceLock::new();
    LIBRARY.get_or_init(|| Library::load_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/machines").as_ref()).unwrap())
}

/// A shipped profile's machine.
pub fn machine(id: &str) -> Machine {
    library().get(id).unwrap().machine.clone()
}

/// A file of the corpus, `tests/data/<name>`.
pub fn data(name: &str) -> PathBuf {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data")).join(name)
}

/// The options a user gets on machine `m` giving no setting: `Settings::default()` validated, the
/// path the CLI and the service take.
pub fn defaults(m: &Machine) -> post::Options {
    Settings::default().options(m).unwrap()
}

/// `cl` posted on the shipped profile `id` as the CLI and the service post it: `settings`
/// through [`Settings::profile_options`] (the profile's clamps, policy and bodies).
pub fn post_with(id: &str, settings: &Settings, cl: &[u8]) -> (collect::Collect, Summary) {
    let p = library().get(id).unwrap();
    let o = settings.profile_options(&p, None).unwrap();
    let mut sink = collect::Collect::default();
    let summary = post::post(cl, &p.machine, &o, &mut sink).unwrap();
    (sink, summary)
}

pub async fn server(cfg: Config) -> String {
    let library = Library::load_dir(&cfg.machines).unwrap().with_dialects(&cfg.dialects).unwrap();
    let (queue, machines) = kinepost::jobs::Queue::start(cfg.jobs(), &library).await.unwrap();
    let metrics = Arc::new(Metrics::default());
    let m = metrics.clone();
    queue.observe(Box::new(move |outcome, secs| m.record_job(outcome, secs)));
    let state = Arc::new(AppState {
        machines,
        config: cfg.clone(),
        metrics,
        jobs: Some(queue),
    });
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    tokio::spawn(async move { kinepost::http::run(listener, app(state), &cfg, std::future::pending()).await });
    format!("http://{addr}")
}

/// Posts on two threads, one at a time in this binary: `threads.rs`'s leak check counts the
/// process's threads by name, and another test's two-thread post beside it would be counted.
pub static TWO_THREAD_POSTS: std::sync::Mutex<()> = std::sync::Mutex::new(());

static NEXT: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);

/// This test process's directory for its servers' data, removed when the process exits (the
/// servers live as long as the process: a run left hundreds of these behind).
fn scratch() -> std::path::PathBuf {
    static ONCE: std::sync::Once = std::sync::Once::new();
    extern "C" fn remove() {
        let _ = std::fs::remove_dir_all(std::env::temp_dir().join(format!("kinepost-http-{}", std::process::id())));
    }
    ONCE.call_once(|| {
        // SAFETY: registers a plain function with no captures to run at exit.
        unsafe { libc::atexit(remove) };
    });
    std::env::temp_dir().join(format!("kinepost-http-{}", std::process::id()))
}

pub fn cfg() -> Config {
    Config {
        machines: concat!(env!("CARGO_MANIFEST_DIR"), "/machines").into(),
        // One data directory per server: each has its own job store.
        data_dir: scratch().join(NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed).to_string()),
        ..Config::default()
    }
}

/// The real binary serving `data` on an ephemeral loopback port: the child and its base URL,
/// its log drained in the background.
pub fn spawn_binary(data: &std::path::Path, extra: &[&str]) -> (std::process::Child, String) {
    spawn_serving(std::process::Command::new(env!("CARGO_BIN_EXE_kinepost")), data, extra)
}

/// [`spawn_binary`] with at most `nofile` open files (`ulimit -n`, soft and hard).
pub fn spawn_binary_with_nofile(data: &std::path::Path, extra: &[&str], nofile: u32) -> (std::process::Child, String) {
    let mut sh = std::process::Command::new("sh");
    sh.args([
        "-c",
        &format!("ulimit -n {nofile} && exec \"$0\" \"$@\""),
        env!("CARGO_BIN_EXE_kinepost"),
    ]);
    spawn_serving(sh, data, extra)
}

fn spawn_serving(mut cmd: std::process::Command, data: &std::path::Path, extra: &[&str]) -> (std::process::Child, String) {
    use std::io::{BufRead, BufReader};
    let mut child = cmd
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
            // A text line (`… listening on http://… machines=10`) or a JSON one (`…","machines"…`).
            break rest.split(|c: char| c.is_whitespace() || c == '"').next().unwrap().to_string();
        }
    };
    std::thread::spawn(move || for _ in err.lines() {});
    (child, addr)
}

/// GET a JSON document.
pub async fn get_json(c: &reqwest::Client, url: &str) -> serde_json::Value {
    c.get(url).send().await.unwrap().json().await.unwrap()
}

/// A generated 5-axis path (`testgen`) for a shipped profile, as CL bytes.
pub fn generated(machine: &str, points: usize, seed: u64) -> Vec<u8> {
    let p = library().get(machine).unwrap();
    let m = &p.machine;
    let mut out = Vec::new();
    kinepost::testgen::write_path(m, points, seed, m.default_tool_length, &mut out).unwrap();
    out
}

/// NC without the lines that name the run (date, job id, source): what two runs share.
pub fn body_lines(nc: &str) -> Vec<&str> {
    nc.lines()
        .filter(|l| !(l.contains("DATE ") || l.contains("JOB ") || l.contains("SOURCE ")))
        .collect()
}

/// Polls a job until its state is `want`; ending in another state, or `limit` passing, fails.
pub async fn wait_job(c: &reqwest::Client, base: &str, id: &str, want: &str, limit: std::time::Duration) -> serde_json::Value {
    let j = poll_job(c, base, id, limit, |s| {
        s == want || matches!(s, "succeeded" | "failed" | "cancelled")
    })
    .await;
    assert_eq!(j["state"], want, "job ended otherwise: {j}");
    j
}

/// Polls a job until it has ended, in whatever state.
pub async fn wait_finished(c: &reqwest::Client, base: &str, id: &str, limit: std::time::Duration) -> serde_json::Value {
    poll_job(c, base, id, limit, |s| !matches!(s, "queued" | "running")).await
}

async fn poll_job(
    c: &reqwest::Client,
    base: &str,
    id: &str,
    limit: std::time::Duration,
    done: impl Fn(&str) -> bool,
) -> serde_json::Value {
    let t0 = std::time::Instant::now();
    loop {
        let j = get_json(c, &format!("{base}/v1/jobs/{id}")).await;
        if done(j["state"].as_str().unwrap_or_default()) {
            return j;
        }
        assert!(t0.elapsed() < limit, "job still {} after {limit:?}: {j}", j["state"]);
        tokio::time::sleep(std::time::Duration::from_millis(50)).await;
    }
}

/// Send and read in one step, failing the test on a transport error: the chain every test wrote.
#[allow(async_fn_in_trait)] // test helpers: awaited in place, never spawned
pub trait Fetch {
    async fn status_ok(self) -> reqwest::StatusCode;
    async fn text_ok(self) -> String;
    async fn json_ok(self) -> serde_json::Value;
}

impl Fetch for reqwest::RequestBuilder {
    async fn status_ok(self) -> reqwest::StatusCode {
        self.send().await.unwrap().status()
    }
    async fn text_ok(self) -> String {
        self.send().await.unwrap().text().await.unwrap()
    }
    async fn json_ok(self) -> serde_json::Value {
        self.send().await.unwrap().json().await.unwrap()
    }
}

/// A request written by hand on its own connection, for what a client library will not do
/// (send half a header, stop mid-body): the socket, after `bytes` are written.
pub async fn raw(base: &str, bytes: &[u8]) -> tokio::net::TcpStream {
    use tokio::io::AsyncWriteExt;
    let mut s = tokio::net::TcpStream::connect(base.trim_start_matches("http://"))
        .await
        .unwrap();
    s.write_all(bytes).await.unwrap();
    s
}

/// What the server sends on `s` within `limit`, up to its closing the connection: `None` if it
/// neither closed nor sent a complete response head in that time.
pub async fn read_response(s: &mut tokio::net::TcpStream, limit: std::time::Duration) -> Option<String> {
    use tokio::io::AsyncReadExt;
    let deadline = tokio::time::Instant::now() + limit;
    let mut got = Vec::new();
    let mut buf = [0u8; 8192];
    loop {
        match tokio::time::timeout_at(deadline, s.read(&mut buf)).await {
            Ok(Ok(0)) | Ok(Err(_)) => return Some(String::from_utf8_lossy(&got).into_owned()),
            Ok(Ok(n)) => got.extend_from_slice(&buf[..n]),
            Err(_) => {
                let head_done = got.windows(4).any(|w| w == b"\r\n\r\n");
                return head_done.then(|| String::from_utf8_lossy(&got).into_owned());
            }
        }
    }
}

/// Thirty submissions at once, spread over `bases` (replicas of one queue), where the limit lets
/// `allowed` in and nothing drains: exactly `allowed` accepted, every other one refused with
/// `status` and Retry-After, and no input of a refused one left in the spools.
pub async fn limit_holds(bases: &[String], spools: &[std::path::PathBuf], allowed: usize, status: u16) {
    let c = reqwest::Client::new();
    let cl = generated("dmg-dmc75v", 2000, 3);
    let sends = (0..30).map(|k| {
        c.post(format!("{}/v1/jobs?machine=dmg-dmc75v", bases[k % bases.len()]))
            .body(cl.clone())
            .send()
    });
    let (mut accepted, mut refused) = (0, 0);
    for r in futures_util::future::join_all(sends).await {
        let r = r.unwrap();
        match r.status().as_u16() {
            202 => accepted += 1,
            s if s == status => {
                assert_eq!(r.headers()["retry-after"], "5");
                refused += 1;
            }
            s => panic!("{s}: {}", r.text().await.unwrap()),
        }
    }
    assert_eq!((accepted, refused), (allowed, 30 - allowed), "accepted, refused ({status})");
    let jobs = get_json(&c, &format!("{}/v1/jobs?limit=100", bases[0])).await;
    assert_eq!(jobs["jobs"].as_array().unwrap().len(), allowed);
    let inputs: usize = spools
        .iter()
        .map(|s| {
            std::fs::read_dir(s)
                .unwrap()
                .flatten()
                .filter(|e| e.file_name().to_string_lossy().contains(".cl"))
                .count()
        })
        .sum();
    assert_eq!(inputs, allowed, "spool inputs");
}

/// Writes a spool file last modified `age` ago.
pub fn plant(spool: &std::path::Path, name: &str, age: std::time::Duration) {
    let path = spool.join(name);
    std::fs::write(&path, b"left behind").unwrap();
    let f = std::fs::File::options().write(true).open(&path).unwrap();
    f.set_modified(std::time::SystemTime::now() - age).unwrap();
}

/// The names in a spool, sorted.
pub fn spool_names(spool: &std::path::Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(spool)
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

/// The node a server names in `/readyz` (its jobs' owner).
pub async fn node_of(c: &reqwest::Client, base: &str) -> String {
    let t = c.get(format!("{base}/readyz")).send().await.unwrap().text().await.unwrap();
    t.rsplit_once("node ").unwrap().1.trim().to_string()
}

/// A fresh PostgreSQL database for one test, when the environment names a server.
pub async fn postgres(what: &str) -> Option<(String, String, String)> {
    use sqlx::Connection;
    let admin = std::env::var("KINEPOST_TEST_DATABASE_URL").ok().filter(|u| !u.is_empty())?;
    let name = format!("kinepost_{what}_{}", std::process::id());
    let mut c = sqlx::PgConnection::connect(&admin)
        .await
        .expect("connect to KINEPOST_TEST_DATABASE_URL");
    for q in [format!("DROP DATABASE IF EXISTS {name}"), format!("CREATE DATABASE {name}")] {
        sqlx::raw_sql(sqlx::AssertSqlSafe(q)).execute(&mut c).await.unwrap();
    }
    let base = admin.rsplit_once('/').map_or(admin.as_str(), |(b, _)| b);
    Some((format!("{base}/{name}"), admin, name))
}

pub async fn drop_postgres(admin: &str, name: &str) {
    use sqlx::Connection;
    if let Ok(mut c) = sqlx::PgConnection::connect(admin).await {
        let _ = sqlx::raw_sql(sqlx::AssertSqlSafe(format!("DROP DATABASE IF EXISTS {name} WITH (FORCE)")))
            .execute(&mut c)
            .await;
    }
}
