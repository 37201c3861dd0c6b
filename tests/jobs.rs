//! The job queue with real processes and a real SQLite store: submit, idempotency, progress,
//! Range/ETag downloads, cancel, delete, and `kill -9` mid-run losing nothing.

mod common;

use serde_json::Value;
use std::process::{Child, Command};
use std::time::{Duration, Instant};

fn generated(machine: &str, points: usize) -> String {
    let lib = kinepost::machines::Library::load_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/machines").as_ref()).unwrap();
    let p = lib.get(machine).unwrap();
    let mut out = Vec::new();
    kinepost::testgen::write_path(&p.machine, points, 7, p.machine.default_tool_length, &mut out).unwrap();
    String::from_utf8(out).unwrap()
}

async fn wait_for(c: &reqwest::Client, base: &str, id: &str, want: &str, limit: Duration) -> Value {
    let t0 = Instant::now();
    loop {
        let j: Value = common::get_json(&c, &format!("{base}/v1/jobs/{id}")).await;
        if j["state"] == want {
            return j;
        }
        assert!(
            !(j["state"] == "failed" || j["state"] == "cancelled") || want == j["state"],
            "job ended {j}"
        );
        assert!(t0.elapsed() < limit, "job still {} after {limit:?}: {j}", j["state"]);
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

/// NC without the lines that name the run (date, job id, source).
fn body_lines(nc: &str) -> Vec<&str> {
    nc.lines()
        .filter(|l| !(l.contains("DATE ") || l.contains("JOB ") || l.contains("SOURCE ")))
        .collect()
}

#[tokio::test]
async fn a_job_gives_the_same_program_as_a_post_with_range_etag_idempotency_and_paging() {
    let mut cfg = common::cfg();
    cfg.data_dir = std::env::temp_dir().join(format!("kinepost-jobs-a-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&cfg.data_dir);
    let base = common::server(cfg.clone()).await;
    let c = reqwest::Client::new();
    let cl = generated("dmg-dmc75v", 2000);

    let submit = |key: &'static str| {
        c.post(format!("{base}/v1/jobs?machine=dmg-dmc75v&sequence_numbers=true"))
            .header("content-type", "text/plain")
            .header("idempotency-key", key)
            .body(cl.clone())
            .send()
    };
    let r = submit("part-17").await.unwrap();
    assert_eq!(r.status(), 202);
    let loc = r.headers()["location"].to_str().unwrap().to_string();
    let j: Value = r.json().await.unwrap();
    let id = j["id"].as_str().unwrap().to_string();
    assert_eq!(loc, format!("/v1/jobs/{id}"));
    assert_eq!(j["progress"]["input_bytes"], cl.len() as u64);
    // The same key is the same job, not a second run.
    let again: Value = submit("part-17").await.unwrap().json().await.unwrap();
    assert_eq!(again["id"], id.as_str());

    let done = wait_for(&c, &base, &id, "succeeded", Duration::from_secs(60)).await;
    assert_eq!(done["progress"]["percent"], 100.0);
    assert_eq!(done["summary"]["cl_points"], 2000);
    assert_eq!(done["attempts"], 1);
    let nc_url = format!("{base}{}", done["links"]["nc"].as_str().unwrap());
    let r = c.get(&nc_url).send().await.unwrap();
    assert_eq!(r.status(), 200);
    let etag = r.headers()["etag"].to_str().unwrap().to_string();
    let nc = r.text().await.unwrap();
    assert_eq!(done["progress"]["nc_bytes"], nc.len() as u64);
    let direct = c
        .post(format!("{base}/v1/post?machine=dmg-dmc75v&sequence_numbers=true"))
        .header("content-type", "text/plain")
        .body(cl.clone())
        .send()
        .await
        .unwrap()
        .text()
        .await
        .unwrap();
    assert_eq!(body_lines(&nc), body_lines(&direct), "a job writes what a post streams");

    let r = c.get(&nc_url).header("range", "bytes=0-9").send().await.unwrap();
    assert_eq!(r.status(), 206);
    assert_eq!(r.text().await.unwrap(), &nc[..10]);
    let r = c.get(&nc_url).header("if-none-match", &etag).send().await.unwrap();
    assert_eq!(r.status(), 304);

    let diags = c
        .get(format!("{base}/v1/jobs/{id}/diagnostics"))
        .send()
        .await
        .unwrap()
        .text()
        .await
        .unwrap();
    let last: Value = serde_json::from_str(diags.lines().last().unwrap()).unwrap();
    assert_eq!(last["type"], "summary");
    assert!(diags.lines().filter(|l| l.contains("\"type\":\"block\"")).count() >= 2000);

    // Paging and the state filter.
    for k in ["p1", "p2"] {
        assert_eq!(submit(k).await.unwrap().status(), 202);
    }
    let page: Value = common::get_json(&c, &format!("{base}/v1/jobs?limit=2")).await;
    assert_eq!(page["jobs"].as_array().unwrap().len(), 2);
    assert_eq!(page["next_offset"], 2);
    let page: Value = common::get_json(&c, &format!("{base}/v1/jobs?limit=2&offset=2")).await;
    assert_eq!(page["jobs"][0]["id"], id.as_str(), "newest first");
    assert!(page["next_offset"].is_null());
    let r = c.get(format!("{base}/v1/jobs?state=done")).send().await.unwrap();
    assert_eq!(r.status(), 400);

    // Bad settings are refused at the door, not hours later.
    let r = c
        .post(format!("{base}/v1/jobs?machine=no-such"))
        .body("GOTO/1,2,3\n")
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 404);
    let r = c
        .post(format!("{base}/v1/jobs?machine=dmg-dmc75v&mode=sideways"))
        .body("GOTO/1,2,3\n")
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 400);
    assert_eq!(c.get(format!("{base}/v1/jobs/0123")).send().await.unwrap().status(), 404);
    let _ = std::fs::remove_dir_all(&cfg.data_dir);
}

#[tokio::test]
async fn cancel_stops_a_job_and_nothing_half_done_is_served() {
    let mut cfg = common::cfg();
    cfg.data_dir = std::env::temp_dir().join(format!("kinepost-jobs-c-{}", std::process::id()));
    cfg.workers = 1;
    let _ = std::fs::remove_dir_all(&cfg.data_dir);
    let base = common::server(cfg.clone()).await;
    let c = reqwest::Client::new();
    let cl = generated("haas-umc750", 100_000);
    let mut ids = Vec::new();
    for _ in 0..2 {
        let j: Value = c
            .post(format!("{base}/v1/jobs?machine=haas-umc750"))
            .body(cl.clone())
            .send()
            .await
            .unwrap()
            .json()
            .await
            .unwrap();
        ids.push(j["id"].as_str().unwrap().to_string());
    }
    // The first runs (one worker), the second waits: cancel both.
    wait_for(&c, &base, &ids[0], "running", Duration::from_secs(30)).await;
    for id in &ids {
        let r = c.delete(format!("{base}/v1/jobs/{id}")).send().await.unwrap();
        assert_eq!(r.status(), 200);
        let j: Value = r.json().await.unwrap();
        assert_eq!(j["state"], "cancelled");
        let r = c.get(format!("{base}/v1/jobs/{id}/nc")).send().await.unwrap();
        assert_eq!(r.status(), 409);
        assert_eq!(r.headers()["content-type"], "application/problem+json");
    }
    // The running one stops promptly: its temporary outputs go.
    let t0 = Instant::now();
    let spool = cfg.data_dir.join("spool");
    while std::fs::read_dir(&spool).unwrap().any(|e| e.unwrap().file_name().to_string_lossy().ends_with(".tmp")) {
        assert!(t0.elapsed() < Duration::from_secs(10), "cancelled job still writing");
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    // A finished job can be removed, files and all.
    let r = c.delete(format!("{base}/v1/jobs/{}", ids[0])).send().await.unwrap();
    assert_eq!(r.status(), 204);
    assert_eq!(c.get(format!("{base}/v1/jobs/{}", ids[0])).send().await.unwrap().status(), 404);
    assert!(!spool.join(format!("{}.cl", ids[0])).exists());
    let _ = std::fs::remove_dir_all(&cfg.data_dir);
}

/// The server process, killed however the test ends (a panicking test must not leave it behind).
struct Server(Child);

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn start(data: &std::path::Path) -> (Server, String) {
    let (child, addr) = common::spawn_binary(data, &["--workers", "1"]);
    (Server(child), addr)
}

#[tokio::test]
async fn kill_9_mid_run_loses_no_accepted_job_and_the_output_verifies() {
    let data = std::env::temp_dir().join(format!("kinepost-jobs-k-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&data);
    let (mut child, base) = start(&data);
    let c = reqwest::Client::new();
    let big = generated("spinner-u5-620", 250_000);
    let small = generated("spinner-u5-620", 500);
    let mut ids = Vec::new();
    for cl in [&big, &small, &small] {
        let r = c
            .post(format!("{base}/v1/jobs?machine=spinner-u5-620"))
            .body(cl.clone())
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 202);
        ids.push(r.json::<Value>().await.unwrap()["id"].as_str().unwrap().to_string());
    }
    // Kill while the big one is part done and the others wait.
    let t0 = Instant::now();
    loop {
        let j: Value = common::get_json(&c, &format!("{base}/v1/jobs/{}", ids[0])).await;
        let read = j["progress"]["bytes_read"].as_u64().unwrap();
        if j["state"] == "running" && read > 0 {
            assert!(read < big.len() as u64, "killed mid-run: {j}");
            break;
        }
        assert!(j["state"] == "queued" || j["state"] == "running", "{j}");
        assert!(t0.elapsed() < Duration::from_secs(30));
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    child.0.kill().unwrap(); // SIGKILL
    child.0.wait().unwrap();

    let (_child, base) = start(&data);
    let mut done = Vec::new();
    for id in &ids {
        done.push(wait_for(&c, &base, id, "succeeded", Duration::from_secs(300)).await);
    }
    assert_eq!(done[0]["attempts"], 2, "the cut-off run ran again from the start");
    assert_eq!(done[0]["summary"]["cl_points"], 250_000);
    // The program is whole, and reproduces every CL point under the FK.
    let nc = c
        .get(format!("{base}/v1/jobs/{}/nc", ids[0]))
        .send()
        .await
        .unwrap()
        .text()
        .await
        .unwrap();
    assert!(nc.trim_end().ends_with("M30\n%"));
    std::fs::write(data.join("big.cl"), &big).unwrap();
    std::fs::write(data.join("big.nc"), &nc).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_kinepost"))
        .args(["verify", "--machine", "spinner-u5-620", "--cl"])
        .arg(data.join("big.cl"))
        .arg("--nc")
        .arg(data.join("big.nc"))
        .env("KINEPOST_MACHINES", concat!(env!("CARGO_MANIFEST_DIR"), "/machines"))
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let report: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(report["matched"], 250_000);
    let _ = std::fs::remove_dir_all(&data);
}
