//! Load on the HTTP service, loopback only, bounded in time: CONCURRENCY clients post a mid-size
//! 5-axis file (generated, 5000 points) for SECONDS, every tenth request a job submission of the
//! same file to the real job queue (SQLite in a temporary directory).
//! `cargo bench --bench load [-- CONC SECS ROUNDS]`. ROUNDS rounds (default 2): prints throughput, p50/p99 latency and
//! RSS after each (stable memory: the second round ends where the first did), then waits for
//! every job and counts how they ended (all must succeed).

use kinepost::http::{AppState, Config, Metrics, app};
use kinepost::machines::Library;
use std::sync::Arc;
use std::time::{Duration, Instant};

fn rss_kb() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmRSS:"))
                .and_then(|l| l.split_whitespace().nth(1)?.parse().ok())
        })
        .unwrap_or(0)
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).filter(|a| !a.starts_with("--")).collect();
    let conc: usize = args.first().and_then(|a| a.parse().ok()).unwrap_or(32);
    let secs: u64 = args.get(1).and_then(|a| a.parse().ok()).unwrap_or(10);
    let rounds: u32 = args.get(2).and_then(|a| a.parse().ok()).unwrap_or(2);
    let rt = tokio::runtime::Builder::new_multi_thread().enable_all().build().unwrap();
    rt.block_on(async move {
        let machines = std::path::PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/machines"));
        let library = Library::load_dir(&machines).unwrap();
        let m = library.get("haas-umc750").unwrap().machine.clone();
        let mut cl = Vec::new();
        kinepost::testgen::write_path(&m, 5000, 3, m.default_tool_length, &mut cl).unwrap();
        let cl = bytes::Bytes::from(cl);
        let data_dir = std::env::temp_dir().join(format!("kinepost-load-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&data_dir);
        // Every client is 127.0.0.1 here: the per-client job limit would count all 32 as one.
        let cfg = Config { machines, data_dir: data_dir.clone(), max_streams: conc * 2, max_jobs_per_client: 0, ..Config::default() };
        let (queue, machines) = kinepost::jobs::Queue::start(cfg.jobs(), &library).await.unwrap();
        let state = Arc::new(AppState { machines, config: cfg.clone(), metrics: Arc::new(Metrics::default()), jobs: Some(queue) });
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        let base = format!("http://{}", listener.local_addr().unwrap());
        let url = format!("{base}/v1/post?machine=haas-umc750&mode=tcp");
        let jobs_url = format!("{base}/v1/jobs?machine=haas-umc750&mode=tcp");
        let mut job_ids: Vec<String> = Vec::new();
        // The service's own accept loop: its deadlines, upload pace and connection bound in force.
        tokio::spawn(async move { kinepost::http::run(listener, app(state), &cfg, std::future::pending()).await });
        let rss0 = rss_kb();
        for round in 1..=rounds {
            let deadline = Instant::now() + Duration::from_secs(secs);
            let client = reqwest::Client::new();
            let t0 = Instant::now();
            let mut tasks = Vec::new();
            for _ in 0..conc {
                let (client, url, jobs_url, cl) = (client.clone(), url.clone(), jobs_url.clone(), cl.clone());
                tasks.push(tokio::spawn(async move {
                    let (mut lat, mut errors, mut bytes, mut ids) = (Vec::new(), 0u64, 0u64, Vec::new());
                    let mut i = 0u64;
                    while Instant::now() < deadline {
                        i += 1;
                        if i % 10 == 0 {
                            match client.post(&jobs_url).header("content-type", "text/plain").body(cl.clone()).send().await {
                                Ok(r) if r.status() == 202 => match r.json::<serde_json::Value>().await {
                                    Ok(j) => ids.push(j["id"].as_str().unwrap_or_default().to_string()),
                                    Err(_) => errors += 1,
                                },
                                Ok(r) => {
                                    let st = r.status();
                                    eprintln!("job submission: {st} {}", r.text().await.unwrap_or_default());
                                    errors += 1
                                }
                                Err(e) => {
                                    eprintln!("job submission: {e}");
                                    errors += 1
                                }
                            }
                            continue;
                        }
                        let t = Instant::now();
                        match client.post(&url).header("content-type", "text/plain").body(cl.clone()).send().await {
                            Ok(r) if r.status() == 200 => match r.bytes().await {
                                Ok(b) if b.ends_with(b"M30\n%\n") => {
                                    bytes += b.len() as u64;
                                    lat.push(t.elapsed().as_secs_f64());
                                }
                                _ => errors += 1,
                            },
                            Ok(r) => {
                                eprintln!("post: {}", r.status());
                                errors += 1
                            }
                            Err(e) => {
                                eprintln!("post: {e}");
                                errors += 1
                            }
                        }
                    }
                    (lat, errors, bytes, ids)
                }));
            }
            let (mut lat, mut errors, mut bytes) = (Vec::new(), 0, 0);
            let mut submitted = 0;
            for t in tasks {
                let (l, e, b, ids) = t.await.unwrap();
                lat.extend(l);
                errors += e;
                bytes += b;
                submitted += ids.len();
                job_ids.extend(ids);
            }
            let wall = t0.elapsed().as_secs_f64();
            lat.sort_by(f64::total_cmp);
            let q = |p: f64| lat.get(((lat.len() as f64 - 1.0) * p) as usize).copied().unwrap_or(0.0) * 1000.0;
            println!(
                "round {round}: {conc} clients, {wall:.1} s: {} posts of 5000 CL points and {submitted} jobs submitted, {errors} errors; {:.1} posts/s, {:.2} M CL points/s, {:.1} MB/s of NC; latency p50 {:.0} ms, p99 {:.0} ms; RSS {rss0} kB before any load, {} kB after this round",
                lat.len(),
                lat.len() as f64 / wall,
                lat.len() as f64 * 5000.0 / wall / 1e6,
                bytes as f64 / wall / 1e6,
                q(0.5),
                q(0.99),
                rss_kb(),
            );
        }
        // Every job submitted runs to success.
        let client = reqwest::Client::new();
        let t0 = Instant::now();
        let mut ended = std::collections::BTreeMap::<String, u64>::new();
        for id in &job_ids {
            loop {
                let j: serde_json::Value = client.get(format!("{base}/v1/jobs/{id}")).send().await.unwrap().json().await.unwrap();
                let st = j["state"].as_str().unwrap_or_default().to_string();
                if st != "queued" && st != "running" {
                    *ended.entry(st).or_default() += 1;
                    break;
                }
                tokio::time::sleep(Duration::from_millis(50)).await;
            }
        }
        println!(
            "jobs: {} submitted, ended {ended:?} ({:.1} s after the load); RSS {} kB",
            job_ids.len(),
            t0.elapsed().as_secs_f64(),
            rss_kb()
        );
        let _ = std::fs::remove_dir_all(&data_dir);
    });
}
