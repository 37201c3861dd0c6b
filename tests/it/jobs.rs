//! The job queue with real processes and a real SQLite store: submit, idempotency, progress,
//! Range/ETag downloads, cancel, delete, and `kill -9` mid-run losing nothing.

use crate::common;

use common::Fetch;

use serde_json::Value;
use std::process::{Child, Command};
use std::time::{Duration, Instant};

#[tokio::test]
async fn a_job_gives_the_same_program_as_a_post_with_range_etag_idempotency_and_paging() {
    let mut cfg = common::cfg();
    cfg.data_dir = std::env::temp_dir().join(format!("kinepost-jobs-a-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&cfg.data_dir);
    let base = common::server(cfg.clone()).await;
    let c = reqwest::Client::new();
    let cl = common::generated("dmg-dmc75v", 2000, 7);

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

    let done = common::wait_job(&c, &base, &id, "succeeded", Duration::from_secs(60)).await;
    assert_eq!(done["progress"]["percent"], 100.0);
    assert_eq!(done["summary"]["cl_points"], 2000);
    assert_eq!(done["attempts"], 1);
    let metrics = c.get(format!("{base}/metrics")).text_ok().await;
    assert!(metrics.contains("kinepost_jobs{state=\"succeeded\"} 1"), "{metrics}");
    assert!(metrics.contains("kinepost_jobs{state=\"queued\"} 0"));
    assert!(
        metrics.contains("kinepost_job_duration_seconds_count{outcome=\"succeeded\"} 1"),
        "{metrics}"
    );
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
        .text_ok()
        .await;
    assert_eq!(
        common::body_lines(&nc),
        common::body_lines(&direct),
        "a job writes what a post streams"
    );

    let r = c.get(&nc_url).header("range", "bytes=0-9").send().await.unwrap();
    assert_eq!(r.status(), 206);
    assert_eq!(r.text().await.unwrap(), &nc[..10]);
    let r = c.get(&nc_url).header("if-none-match", &etag).send().await.unwrap();
    assert_eq!(r.status(), 304);

    let diags = c.get(format!("{base}/v1/jobs/{id}/diagnostics")).text_ok().await;
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
    assert_eq!(c.get(format!("{base}/v1/jobs/0123")).status_ok().await, 404);
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
    let cl = common::generated("haas-umc750", 100_000, 7);
    let mut ids = Vec::new();
    for _ in 0..2 {
        let j: Value = c
            .post(format!("{base}/v1/jobs?machine=haas-umc750"))
            .body(cl.clone())
            .json_ok()
            .await;
        ids.push(j["id"].as_str().unwrap().to_string());
    }
    // The first runs (one worker), the second waits: cancel both.
    common::wait_job(&c, &base, &ids[0], "running", Duration::from_secs(30)).await;
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
    while std::fs::read_dir(&spool)
        .unwrap()
        .any(|e| e.unwrap().file_name().to_string_lossy().ends_with(".tmp"))
    {
        assert!(t0.elapsed() < Duration::from_secs(10), "cancelled job still writing");
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    // A finished job can be removed, files and all.
    let r = c.delete(format!("{base}/v1/jobs/{}", ids[0])).send().await.unwrap();
    assert_eq!(r.status(), 204);
    assert_eq!(c.get(format!("{base}/v1/jobs/{}", ids[0])).status_ok().await, 404);
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
    // Long enough that the 20 ms poll finds it part done: an optimized build posts 250 000
    // points in about a tenth of a second, and the poll missed that.
    let points = if cfg!(debug_assertions) { 250_000 } else { 2_500_000 };
    let big = common::generated("spinner-u5-620", points, 7);
    let small = common::generated("spinner-u5-620", 500, 7);
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
        done.push(common::wait_job(&c, &base, id, "succeeded", Duration::from_secs(300)).await);
    }
    assert_eq!(done[0]["attempts"], 2, "the cut-off run ran again from the start");
    assert_eq!(done[0]["summary"]["cl_points"], points);
    // The program is whole, and reproduces every CL point under the FK.
    let nc = c.get(format!("{base}/v1/jobs/{}/nc", ids[0])).text_ok().await;
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
    assert_eq!(report["matched"], points);
    let _ = std::fs::remove_dir_all(&data);
}

/// FK of a preview point's axis words (joint mode), against the tip and axis it claims.
fn check_point_fk(m: &kinepost::kinematics::Machine, tool_length: f64, axes: &[Value], p: &Value) {
    use kinepost::kinematics::{Joints, Setup, Vec3, fk};
    let mut jt = Joints::default();
    for (a, v) in axes.iter().zip(p["j"].as_array().unwrap()) {
        let v = v.as_f64().unwrap();
        let name = a["name"].as_str().unwrap().chars().next().unwrap();
        match name {
            'X' | 'Y' | 'Z' => jt.linear[(name as u8 - b'X') as usize] = v,
            _ => {
                let i = m.rotaries.iter().position(|r| r.name == name).unwrap();
                jt.rotary[i] = v.to_radians();
            }
        }
    }
    let pose = fk(m, &jt, &Setup::new(tool_length, Vec3::zeros()));
    let v3 = |k: &str| {
        let a = p[k].as_array().unwrap();
        Vec3::new(a[0].as_f64().unwrap(), a[1].as_f64().unwrap(), a[2].as_f64().unwrap())
    };
    // Joints rounded to 1e-4 (mm and degrees) on a lever of up to ~1 m: ~2e-3.
    assert!((pose.tip - v3("tip")).norm() < 5e-3, "tip of {p}: FK {:?}", pose.tip);
    assert!((pose.axis - v3("axis")).norm() < 1e-4, "axis of {p}: FK {:?}", pose.axis);
}

#[tokio::test]
async fn a_preview_draws_the_decimated_path_its_joints_and_every_warning() {
    let base = common::server(common::cfg()).await;
    let c = reqwest::Client::new();
    let lib = common::library();

    // A long path: decimated to the cap, first and last block kept, every point on its joints.
    let cl = common::generated("spinner-u5-620", 30_000, 7);
    let r = c
        .post(format!("{base}/v1/jobs?machine=spinner-u5-620"))
        .body(cl)
        .send()
        .await
        .unwrap();
    let id = r.json::<Value>().await.unwrap()["id"].as_str().unwrap().to_string();
    let r = c.get(format!("{base}/v1/jobs/{id}/preview")).send().await.unwrap();
    assert!(matches!(r.status().as_u16(), 200 | 409), "{}", r.status());
    let done = common::wait_job(&c, &base, &id, "succeeded", Duration::from_secs(120)).await;
    let url = format!("{base}{}", done["links"]["preview"].as_str().unwrap());
    let r = c.get(&url).send().await.unwrap();
    assert_eq!(r.headers()["content-type"], "application/json");
    let etag = r.headers()["etag"].to_str().unwrap().to_string();
    let p: Value = r.json().await.unwrap();
    assert_eq!(c.get(&url).header("if-none-match", etag).status_ok().await, 304);
    let blocks = done["summary"]["blocks"].as_u64().unwrap();
    let pts = p["points"].as_array().unwrap();
    assert_eq!(p["blocks"], blocks);
    assert_eq!(done["progress"]["blocks"], blocks, "progress counts what the summary counts");
    assert!(
        blocks >= 30_000 && pts.len() <= 10_000 && pts.len() >= 2_500,
        "{} of {blocks}",
        pts.len()
    );
    assert!(p["stride"].as_u64().unwrap() >= 4);
    assert_eq!(pts[0]["n"], 1);
    assert_eq!(pts.last().unwrap()["n"], blocks);
    assert!(
        pts.windows(2)
            .all(|w| w[0]["n"].as_u64() < w[1]["n"].as_u64() && w[0]["t"].as_f64() <= w[1]["t"].as_f64())
    );
    let cycle = done["summary"]["cycle_time_s"].as_f64().unwrap();
    assert!((pts.last().unwrap()["t"].as_f64().unwrap() - cycle).abs() < 1e-3 * cycle.max(1.0));
    let prof = lib.get("spinner-u5-620").unwrap();
    let m = &prof.machine;
    let axes = p["axes"].as_array().unwrap();
    let names: String = axes.iter().map(|a| a["name"].as_str().unwrap()).collect();
    assert_eq!(names, "XYZBC");
    for r in &m.rotaries {
        let a = axes.iter().find(|a| a["name"] == r.name.to_string()).unwrap();
        match r.limits {
            Some((lo, hi)) => assert_eq!(a["limits"], serde_json::json!([lo.to_degrees(), hi.to_degrees()])),
            None => assert!(a["limits"].is_null()),
        }
    }
    assert!(pts.iter().any(|q| q["rapid"] == true) && pts.iter().any(|q| q["rapid"] == false));
    let tl = done["summary"]["tool_length"].as_f64().unwrap();
    for q in pts {
        check_point_fk(m, tl, axes, q);
    }
    for mk in p["marks"].as_array().unwrap() {
        check_point_fk(m, tl, axes, mk);
        assert!(mk["cl"].as_str().unwrap().starts_with("GOTO/"), "{mk}");
    }

    // A 5-axis CL file on a 3-axis machine: every unreachable pose is a note at its CL tip,
    // quoting its CL line.
    let cl = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/data/nx_clsf_mech491_variable_axis_inch_5ax.cls"
    ))
    .unwrap();
    let r = c
        .post(format!("{base}/v1/jobs?machine=vmc-3axis"))
        .body(cl.clone())
        .send()
        .await
        .unwrap();
    let id = r.json::<Value>().await.unwrap()["id"].as_str().unwrap().to_string();
    let done = common::wait_job(&c, &base, &id, "succeeded", Duration::from_secs(60)).await;
    let p: Value = common::get_json(&c, &format!("{base}/v1/jobs/{id}/preview")).await;
    let unreachable: Vec<&Value> = p["notes"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|n| n["diagnostic"]["code"] == "unreachable")
        .collect();
    assert_eq!(
        unreachable.len() as u64,
        done["summary"]["counts"]["unreachable"].as_u64().unwrap()
    );
    assert!(!unreachable.is_empty());
    let lines: Vec<&str> = cl.lines().collect();
    for n in unreachable {
        let line = n["diagnostic"]["line"].as_u64().unwrap() as usize;
        assert_eq!(n["cl"].as_str().unwrap(), lines[line - 1].trim_end());
        assert!(n["tip"].is_array() && n["axis"].is_array());
    }
    assert_eq!(p["units"], "mm");
    assert!(p["axes"].as_array().unwrap().iter().all(|a| a["kind"] == "linear"));

    // Unknown, and not finished yet.
    assert_eq!(
        c.get(format!("{base}/v1/jobs/{}/preview", "0".repeat(32))).status_ok().await,
        404
    );
}

/// The preview carries what the page needs to run the program on the machine: the chain, the
/// bodies, the tool, the stock, and the bodies each collision names.
#[tokio::test]
async fn a_preview_carries_the_machine_the_tool_the_stock_and_each_collisions_bodies() {
    let base = common::server(common::cfg()).await;
    let c = reqwest::Client::new();
    // tests/it/collide.rs's crash: the tool plunged into the table (line 9), the holder into the
    // table tilted 85° (line 13).
    let cl = "PARTNO/COLLIDE\nUNITS/MM\nLOADTL/1,LENGTH,100\nSPINDL/6000,RPM,CLW\nFEDRAT/500,MMPM\nRAPID\nGOTO/0,0,100,0,0,1\nGOTO/0,0,20,0,0,1\nGOTO/0,0,-5,0,0,1\nRAPID\nGOTO/0,0,100,0,0,1\nRAPID\nGOTO/0,0,100,0.996195,0,0.087156\nGOTO/0,0,6,0.996195,0,0.087156\nSPINDL/OFF\nFINI\n";
    let r = c
        .post(format!("{base}/v1/jobs?machine=spinner-u5-620&stock=-50,-50,0,50,50,40&work_offset=1,2,-3"))
        .body(cl)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 202);
    let id = r.json::<Value>().await.unwrap()["id"].as_str().unwrap().to_string();
    common::wait_job(&c, &base, &id, "succeeded", Duration::from_secs(60)).await;
    let p: Value = common::get_json(&c, &format!("{base}/v1/jobs/{id}/preview")).await;
    let m = &p["machine"];
    assert_eq!(m["id"], "spinner-u5-620");
    assert_eq!(m["kinematics"], "table-table");
    let rot: Vec<&str> = m["rotary"].as_array().unwrap().iter().map(|r| r["name"].as_str().unwrap()).collect();
    assert_eq!(rot, ["B", "C"]);
    for r in m["rotary"].as_array().unwrap() {
        assert_eq!(r["on"], "table");
        let a: Vec<f64> = r["axis"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
        assert!((a.iter().map(|v| v * v).sum::<f64>() - 1.0).abs() < 1e-12, "a unit axis: {a:?}");
    }
    let bodies = m["bodies"].as_array().unwrap();
    let table = bodies.iter().find(|b| b["name"] == "table").expect("the table body");
    assert_eq!(table["on"], "C");
    assert_eq!(table["cylinder"]["radius"], 250.0);
    assert!(bodies.iter().any(|b| b["on"] == "B" && b["box"].is_array()));
    assert_eq!(p["work_offset"], serde_json::json!([1.0, 2.0, -3.0]));
    assert_eq!(p["stock"], serde_json::json!([[-50.0, -50.0, 0.0, 50.0, 50.0, 40.0]]));
    let tools = p["tools"].as_array().unwrap();
    assert_eq!(tools.len(), 1, "{tools:?}");
    assert_eq!(tools[0]["n"], 1);
    assert_eq!(tools[0]["length"], 100.0);
    assert_eq!(tools[0]["diameter"], 10.0, "the default cutter");
    assert_eq!(tools[0]["holder_diameter"], 40.0);
    // Each collision's mark names its bodies and depth, at the CL line the crash is on.
    let marks = p["marks"].as_array().unwrap();
    let contact = |line: u64, a: &str, b: &str| {
        marks.iter().any(|mk| {
            mk["line"] == line
                && mk["contacts"].as_array().is_some_and(|cs| {
                    cs.iter().any(|c| c["code"] == "collision" && c["a"] == a && c["b"] == b && c["depth"].as_f64().unwrap() > 0.0)
                })
        })
    };
    assert!(contact(9, "cutter", "table"), "{marks:#?}");
    assert!(contact(14, "holder", "table"), "{marks:#?}");
    // The machine list carries the bodies too, in the same form.
    let list: Value = common::get_json(&c, &format!("{base}/v1/machines/spinner-u5-620")).await;
    assert_eq!(list["bodies"], m["bodies"]);
}

#[tokio::test]
async fn finished_jobs_expire_with_their_files() {
    let mut cfg = common::cfg();
    cfg.job_retention = Duration::from_secs(1);
    let base = common::server(cfg.clone()).await;
    let c = reqwest::Client::new();
    let r = c
        .post(format!("{base}/v1/jobs?machine=dmg-dmc75v"))
        .body(common::generated("dmg-dmc75v", 200, 7))
        .send()
        .await
        .unwrap();
    let id = r.json::<Value>().await.unwrap()["id"].as_str().unwrap().to_string();
    common::wait_job(&c, &base, &id, "succeeded", Duration::from_secs(60)).await;
    let spool = cfg.data_dir.join("spool");
    let files = || -> usize {
        std::fs::read_dir(&spool)
            .unwrap()
            .flatten()
            .filter(|e| e.file_name().to_string_lossy().starts_with(&id))
            .count()
    };
    assert_eq!(files(), 5, "input, NC, NDJSON, preview, line map");
    let t0 = Instant::now();
    while c.get(format!("{base}/v1/jobs/{id}")).status_ok().await != 404 {
        assert!(t0.elapsed() < Duration::from_secs(10), "the job outlived its retention");
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    assert_eq!(files(), 0, "its files went with it");
    assert_eq!(c.get(format!("{base}/v1/jobs/{id}/nc")).status_ok().await, 404);
}

#[tokio::test]
async fn one_client_cannot_fill_the_queue() {
    let mut cfg = common::cfg();
    cfg.max_jobs_per_client = 2;
    cfg.workers = 1;
    let base = common::server(cfg).await;
    let c = reqwest::Client::new();
    let submit = |points: usize| {
        c.post(format!("{base}/v1/jobs?machine=dmg-dmc75v"))
            .body(common::generated("dmg-dmc75v", points, 7))
            .send()
    };
    let long: Value = submit(200_000).await.unwrap().json().await.unwrap();
    let second = submit(100).await.unwrap();
    assert_eq!(second.status(), 202);
    let r = submit(100).await.unwrap();
    assert_eq!(r.status(), 429);
    assert_eq!(r.headers()["retry-after"], "5");
    let p: Value = r.json().await.unwrap();
    assert!(p["detail"].as_str().unwrap().contains("127.0.0.1 has 2 jobs"), "{p}");
    // Room again once one of them is gone.
    let id = long["id"].as_str().unwrap();
    assert_eq!(c.delete(format!("{base}/v1/jobs/{id}")).status_ok().await, 200);
    assert_eq!(submit(100).await.unwrap().status(), 202);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn limits_hold_under_concurrent_submissions() {
    // Nothing drains (no workers): the limits alone decide.
    let mut cfg = common::cfg();
    (cfg.workers, cfg.max_queued) = (0, 5);
    let base = common::server(cfg.clone()).await;
    common::limit_holds(&[base], &[cfg.data_dir.join("spool")], 5, 503).await;

    let mut cfg = common::cfg();
    (cfg.workers, cfg.max_jobs_per_client) = (0, 3);
    let base = common::server(cfg.clone()).await;
    common::limit_holds(&[base], &[cfg.data_dir.join("spool")], 3, 429).await;
}

#[tokio::test]
async fn start_up_sweeps_the_spool_of_what_no_job_owns() {
    use sqlx::{ConnectOptions, Connection};
    let data = std::env::temp_dir().join(format!("kinepost-jobs-sweep-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&data);
    let (server, base) = start(&data);
    let c = reqwest::Client::new();
    let j: Value = c
        .post(format!("{base}/v1/jobs?machine=dmg-dmc75v"))
        .body(common::generated("dmg-dmc75v", 200, 7))
        .json_ok()
        .await;
    let id = j["id"].as_str().unwrap().to_string();
    common::wait_job(&c, &base, &id, "succeeded", Duration::from_secs(60)).await;
    let own = common::node_of(&c, &base).await;
    drop(server); // kill -9

    // What killed processes leave: uploads (this node's, another's, an old version's), a run's
    // temporaries, an input whose row never committed, outputs whose row was deleted; fresh and
    // old. One node on its own spool removes all of it at start-up.
    let spool = data.join("spool");
    let (fresh, old) = (Duration::ZERO, Duration::from_secs(7200));
    let (a, b) = ("a".repeat(32), "b".repeat(32));
    let planted = [
        (format!("{a}.{own}.cl.tmp"), fresh),
        (format!("{a}.replica-x-12345678.cl.tmp"), fresh),
        (format!("{b}.replica-x-12345678.cl.tmp"), old),
        (format!("{b}.cl.tmp"), fresh),
        (format!("{a}.cl"), fresh),
        (format!("{b}.cl"), old),
        (format!("{a}.nc"), fresh),
        (format!("{a}.ndjson"), fresh),
        (format!("{a}.blocks"), fresh),
        (format!("{a}.nc.partial"), fresh),
        (format!("{a}.preview.json"), fresh),
        (format!("{a}.nc.1.tmp"), fresh),
        (format!("{id}.ndjson.3.tmp"), fresh),
        (format!("{id}.blocks.3.tmp"), fresh),
    ];
    for (name, age) in &planted {
        common::plant(&spool, name, *age);
    }
    common::plant(&spool, "notes.txt", fresh);
    // A damaged row still owns its input.
    let e = "e".repeat(32);
    let mut db = sqlx::sqlite::SqliteConnectOptions::new()
        .filename(data.join("jobs.sqlite"))
        .connect()
        .await
        .unwrap();
    sqlx::raw_sql(sqlx::AssertSqlSafe(format!(
        "INSERT INTO jobs (id, state, machine, settings, input_bytes, created_ms, attempts) VALUES ('{e}', 'failed', 'x', '{{}}', 1, 0, 'x')"
    )))
    .execute(&mut db)
    .await
    .unwrap();
    db.close().await.unwrap();
    common::plant(&spool, &format!("{e}.cl"), fresh);
    let (_server, base) = start(&data);
    // Answering at all means start-up (recovery, the sweep) is done.
    assert_eq!(c.get(format!("{base}/v1/jobs/{id}/nc")).status_ok().await, 200);
    let mut kept: Vec<String> = ["cl", "nc", "blocks", "preview.json", "lines"]
        .iter()
        .map(|x| format!("{id}.{x}"))
        .chain(["notes.txt".to_string(), format!("{e}.cl")])
        .collect();
    kept.sort();
    assert_eq!(common::spool_names(&spool), kept);
    let _ = std::fs::remove_dir_all(&data);
}

/// A row the store cannot read (damaged, or from another version) is listed as a failed job
/// naming why, never a 500 for every page; a queued one does not stop the workers.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_damaged_row_is_a_failed_job_not_a_broken_listing() {
    use sqlx::{ConnectOptions, Connection};
    let mut cfg = common::cfg();
    cfg.workers = 1;
    let base = common::server(cfg.clone()).await;
    let c = reqwest::Client::new();
    let submit = || async {
        let j: Value = c
            .post(format!("{base}/v1/jobs?machine=dmg-dmc75v"))
            .body(common::generated("dmg-dmc75v", 100, 7))
            .json_ok()
            .await;
        j["id"].as_str().unwrap().to_string()
    };
    let (a, b) = (submit().await, submit().await);
    common::wait_job(&c, &base, &b, "succeeded", Duration::from_secs(60)).await;

    let mut db = sqlx::sqlite::SqliteConnectOptions::new()
        .filename(cfg.data_dir.join("jobs.sqlite"))
        .connect()
        .await
        .unwrap();
    let d = "d".repeat(32);
    for sql in [
        format!("UPDATE jobs SET settings = '{{broken' WHERE id = '{a}'"),
        format!("UPDATE jobs SET created_ms = 'yesterday' WHERE id = '{b}'"),
        format!(
            "INSERT INTO jobs (id, state, machine, settings, input_bytes, created_ms) VALUES ('{d}', 'queued', 'dmg-dmc75v', 'not json', 1, 0)"
        ),
    ] {
        sqlx::raw_sql(sqlx::AssertSqlSafe(sql)).execute(&mut db).await.unwrap();
    }
    db.close().await.unwrap();
    // The damaged queued row is failed by the worker that takes it; the next job still runs.
    let e = submit().await;
    common::wait_job(&c, &base, &e, "succeeded", Duration::from_secs(60)).await;

    let r = c.get(format!("{base}/v1/jobs")).send().await.unwrap();
    assert_eq!(r.status(), 200);
    let list: Value = r.json().await.unwrap();
    let jobs = list["jobs"].as_array().unwrap();
    assert_eq!(jobs.len(), 4, "{list}");
    for id in [&a, &d] {
        let j = jobs.iter().find(|j| j["id"] == id.as_str()).unwrap();
        assert_eq!(j["state"], "failed", "{j}");
        assert!(j["error"].as_str().unwrap().contains("cannot be read"), "{j}");
        let one = c.get(format!("{base}/v1/jobs/{id}")).send().await.unwrap();
        assert_eq!(one.status(), 200);
        assert_eq!(one.json::<Value>().await.unwrap()["state"], "failed");
    }
    assert!(jobs.iter().any(|j| j["id"] == b.as_str()));
    // A damaged job can be removed.
    assert_eq!(c.delete(format!("{base}/v1/jobs/{a}")).status_ok().await, 204);
    assert_eq!(c.get(format!("{base}/v1/jobs/{a}")).status_ok().await, 404);
}

/// Every line of an NDJSON body, parsed (a line cut short fails the test).
fn ndjson(text: &str) -> Vec<Value> {
    text.lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{e}: {l:.80}")))
        .collect()
}

/// A failed job's diagnostics always end with its error record: as the engine wrote it, and
/// when the store (or an older version's NDJSON file) was cut short or lost, with the record
/// after its last whole one.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_failed_jobs_diagnostics_end_with_its_error_even_when_cut_short() {
    let cfg = common::cfg();
    let base = common::server(cfg.clone()).await;
    let c = reqwest::Client::new();
    let mut cl = String::from("FEDRAT/1000\n");
    for i in 0..3000 {
        cl.push_str(&format!(
            "GOTO/{:.4},{:.4},-5\n",
            (i as f64 * 0.01).sin() * 50.0,
            i as f64 * 0.01
        ));
    }
    cl.push_str("GOTO/1,oops,3\nGOTO/1,2,3\n");
    let j: Value = c
        .post(format!("{base}/v1/jobs?machine=vmc-3axis&strict=true"))
        .body(cl)
        .json_ok()
        .await;
    let id = j["id"].as_str().unwrap().to_string();
    let failed = common::wait_job(&c, &base, &id, "failed", Duration::from_secs(60)).await;
    let url = format!("{base}/v1/jobs/{id}/diagnostics");
    let whole = c.get(&url).text_ok().await;
    let records = ndjson(&whole);
    assert_eq!(records.last().unwrap()["type"], "error");
    assert_eq!(records.last().unwrap()["error"]["line"], 3002);

    // The block store cut mid-event, the error and part of a block gone (a crash, a full disk):
    // served up to its last whole record, then the job's error.
    let spool = cfg.data_dir.join("spool");
    let store = spool.join(format!("{id}.blocks"));
    let full = std::fs::read(&store).unwrap();
    // The error's line, its event's kind and length (at most 3 bytes), a few of the block's.
    let cut = full.len() - (whole.lines().last().unwrap().len() + 1) - 5;
    std::fs::write(&store, &full[..cut]).unwrap();
    let r = c.get(&url).send().await.unwrap();
    assert_eq!(r.status(), 200);
    let mended = ndjson(&r.text().await.unwrap());
    assert_eq!(mended.len(), records.len() - 1, "the cut block is dropped, the error added");
    assert_eq!(mended.last().unwrap()["type"], "error");
    assert_eq!(mended.last().unwrap()["error"]["detail"], failed["error"]);
    assert_eq!(mended[..mended.len() - 1], records[..records.len() - 2]);
    // Lost altogether: the error record alone.
    std::fs::remove_file(&store).unwrap();
    let r = c.get(&url).send().await.unwrap();
    assert_eq!(r.status(), 200);
    let alone = ndjson(&r.text().await.unwrap());
    assert_eq!(alone.len(), 1);
    assert_eq!(alone[0]["type"], "error");

    // The NDJSON file a version before the block store left, cut mid-record: mended the same.
    let file = spool.join(format!("{id}.ndjson"));
    let cut = whole.len() - whole.lines().last().unwrap().len() - 40;
    std::fs::write(&file, &whole.as_bytes()[..cut]).unwrap();
    let mended = ndjson(&c.get(&url).text_ok().await);
    assert_eq!(mended.len(), records.len() - 1);
    assert_eq!(mended.last().unwrap()["error"]["detail"], failed["error"]);
}

/// An Idempotency-Key names one request: given again with the same CL, machine and options it is
/// that job (however the query is ordered, whatever was written to the machine's tool table
/// since); with another input, machine, option or dialect it is a 422 naming the job, never that
/// job as if it were the answer. Rows from before the digest was kept answer by the key alone.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_idempotency_key_given_with_another_request_is_refused() {
    use sqlx::{ConnectOptions, Connection};
    const TOKEN: &str = "crib";
    let mut cfg = common::cfg();
    cfg.workers = 0;
    cfg.admin_token = Some(TOKEN.into());
    let base = common::server(cfg.clone()).await;
    let c = reqwest::Client::new();
    let cl = common::generated("dmg-dmc75v", 200, 3);
    let submit = |key: &'static str, query: &'static str, body: Vec<u8>| {
        let c = c.clone();
        let url = format!("{base}/v1/jobs?{query}");
        async move {
            let r = c.post(url).header("idempotency-key", key).body(body).send().await.unwrap();
            let status = r.status().as_u16();
            (status, r.json::<Value>().await.unwrap())
        }
    };
    let first = "machine=dmg-dmc75v&sequence_numbers=true";
    let (status, j) = submit("k1", first, cl.clone()).await;
    assert_eq!(status, 202, "{j}");
    let id = j["id"].as_str().unwrap().to_string();
    for query in [first, "sequence_numbers=true&machine=dmg-dmc75v"] {
        let (status, j) = submit("k1", query, cl.clone()).await;
        assert_eq!((status, j["id"].as_str()), (202, Some(id.as_str())), "{query}: {j}");
    }

    let other_cl = common::generated("dmg-dmc75v", 200, 4);
    for (query, body, what) in [
        (first, other_cl.clone(), "another CL input"),
        ("machine=dmg-dmc75v", cl.clone(), "other options"),
        ("machine=dmg-dmc75v&sequence_numbers=true&dialect=fanuc", cl.clone(), "other options"),
        ("machine=haas-umc750&sequence_numbers=true", cl.clone(), "other options"),
        ("machine=haas-umc750", other_cl.clone(), "another CL input and other options"),
    ] {
        let (status, p) = submit("k1", query, body).await;
        assert_eq!(status, 422, "{query}: {p}");
        assert_eq!(p["type"], "https://kinepost.dev/problems/idempotency-key-reused", "{p}");
        assert_eq!(p["title"], "Idempotency-Key reused with another request");
        let detail = p["detail"].as_str().unwrap();
        assert!(detail.contains(&id) && detail.contains(what), "{query}: {detail}");
    }

    // The machine's tool table written since: a version resolved by the service, not asked for.
    let r = c
        .put(format!("{base}/v1/machines/dmg-dmc75v/tools"))
        .header("authorization", format!("Bearer {TOKEN}"))
        .header("content-type", "application/toml")
        .body("units = \"mm\"\n[[tool]]\nnumber = 1\nlength = 120\ndiameter = 10\n")
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 201, "{}", r.text().await.unwrap());
    let (status, j) = submit("k1", first, cl.clone()).await;
    assert_eq!((status, j["id"].as_str()), (202, Some(id.as_str())), "{j}");
    assert_eq!(j["tool_table_version"], Value::Null, "the job keeps what it was accepted with");

    // Two submissions racing with one new key and two inputs: one job, one refusal.
    let (a, b) = tokio::join!(submit("k2", first, cl.clone()), submit("k2", first, other_cl.clone()));
    let mut statuses = [a.0, b.0];
    statuses.sort();
    assert_eq!(statuses, [202, 422], "{} / {}", a.1, b.1);

    // A row written before the digest was kept: the key alone, as then.
    let mut db = sqlx::sqlite::SqliteConnectOptions::new()
        .filename(cfg.data_dir.join("jobs.sqlite"))
        .connect()
        .await
        .unwrap();
    sqlx::query("UPDATE jobs SET request_digest = NULL WHERE id = $1")
        .bind(&id)
        .execute(&mut db)
        .await
        .unwrap();
    db.close().await.unwrap();
    let (status, j) = submit("k1", "machine=haas-umc750", other_cl).await;
    assert_eq!((status, j["id"].as_str()), (202, Some(id.as_str())), "{j}");
}
