//! Two `kinepost serve` replicas on one real PostgreSQL and one shared spool: a batch runs with
//! no job run twice, idempotency and cancel work across replicas, a replica killed mid-job has
//! its job taken over, and a profile written on one is served by the other.
//!
//! Needs a PostgreSQL server: `KINEPOST_TEST_DATABASE_URL=postgres://user@host/db` (any database
//! the user may create databases from; each run makes and drops its own). Without it the test
//! says it is skipped, unless `KINEPOST_REQUIRE_POSTGRES=1` (CI), where it fails.

mod common;

use common::Fetch;

use serde_json::Value;
use sqlx::Connection;
use std::process::Child;
use std::time::{Duration, Instant};

const TOKEN: &str = "replica-admin";

/// A fresh database on the test server, dropped by `Drop`.
struct TestDb {
    admin: String,
    name: String,
    url: String,
}

impl TestDb {
    async fn create() -> Option<TestDb> {
        let admin = match std::env::var("KINEPOST_TEST_DATABASE_URL") {
            Ok(u) if !u.is_empty() => u,
            _ => {
                assert!(
                    std::env::var("KINEPOST_REQUIRE_POSTGRES").is_err(),
                    "KINEPOST_REQUIRE_POSTGRES is set but KINEPOST_TEST_DATABASE_URL is not"
                );
                eprintln!("SKIPPED: set KINEPOST_TEST_DATABASE_URL=postgres://… to run the replica tests");
                return None;
            }
        };
        // One database per test: tests of this file run at once in one process.
        static NEXT: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
        let name = format!(
            "kinepost_test_{}_{}",
            std::process::id(),
            NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
        );
        let mut c = sqlx::PgConnection::connect(&admin)
            .await
            .expect("connect to KINEPOST_TEST_DATABASE_URL");
        sqlx::raw_sql(sqlx::AssertSqlSafe(format!("DROP DATABASE IF EXISTS {name}")))
            .execute(&mut c)
            .await
            .unwrap();
        sqlx::raw_sql(sqlx::AssertSqlSafe(format!("CREATE DATABASE {name}")))
            .execute(&mut c)
            .await
            .unwrap();
        let base = admin.rsplit_once('/').map_or(admin.as_str(), |(b, _)| b);
        let url = format!("{base}/{name}");
        Some(TestDb { admin, name, url })
    }
}

impl Drop for TestDb {
    fn drop(&mut self) {
        let (admin, name) = (self.admin.clone(), self.name.clone());
        let _ = std::thread::spawn(move || {
            tokio::runtime::Runtime::new().unwrap().block_on(async {
                if let Ok(mut c) = sqlx::PgConnection::connect(&admin).await {
                    let _ = sqlx::raw_sql(sqlx::AssertSqlSafe(format!("DROP DATABASE IF EXISTS {name} WITH (FORCE)")))
                        .execute(&mut c)
                        .await;
                }
            })
        })
        .join();
    }
}

struct Replica {
    child: Child,
    base: String,
}

impl Drop for Replica {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn replica(db: &TestDb, spool: &std::path::Path, tag: &str) -> Replica {
    let data = std::env::temp_dir().join(format!("kinepost-replica-{}-{tag}", std::process::id()));
    let _ = std::fs::remove_dir_all(&data);
    let spool = spool.to_str().unwrap().to_string();
    let (child, addr) = common::spawn_binary(
        &data,
        &[
            "--database-url",
            &db.url,
            "--spool-dir",
            &spool,
            "--workers",
            "2",
            "--job-lease-secs",
            "2",
            "--admin-token",
            TOKEN,
        ],
    );
    Replica { child, base: addr }
}

/// The replica's node name, as its jobs show it.
async fn node_of(c: &reqwest::Client, base: &str) -> String {
    let t = c.get(format!("{base}/readyz")).text_ok().await;
    t.rsplit_once("node ").unwrap().1.trim().to_string()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn two_replicas_share_one_queue_and_take_over_a_dead_ones_job() {
    let Some(db) = TestDb::create().await else { return };
    let spool = std::env::temp_dir().join(format!("kinepost-shared-spool-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&spool);
    let a = replica(&db, &spool, "a");
    let b = replica(&db, &spool, "b");
    let c = reqwest::Client::new();

    // A batch submitted to both: every job once, by either replica.
    let mut ids = Vec::new();
    for k in 0..24u64 {
        let base = if k % 2 == 0 { &a.base } else { &b.base };
        let r = c
            .post(format!("{base}/v1/jobs?machine=dmg-dmc75v"))
            .body(common::generated("dmg-dmc75v", 3000, k))
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 202);
        ids.push(r.json::<Value>().await.unwrap()["id"].as_str().unwrap().to_string());
    }
    let mut nodes = std::collections::BTreeSet::new();
    for id in &ids {
        let j = common::wait_finished(&c, &b.base, id, Duration::from_secs(180)).await;
        assert_eq!(j["state"], "succeeded", "{j}");
        assert_eq!(j["attempts"], 1, "no job runs twice: {j}");
        nodes.insert(j["node"].as_str().unwrap().to_string());
    }
    assert_eq!(nodes.len(), 2, "both replicas worked: {nodes:?}");
    // Outputs are on the shared spool: any replica serves any job, as a post would write it.
    let direct = c
        .post(format!("{}/v1/post?machine=dmg-dmc75v", a.base))
        .body(common::generated("dmg-dmc75v", 3000, 5))
        .text_ok()
        .await;
    for base in [&a.base, &b.base] {
        let nc = c.get(format!("{base}/v1/jobs/{}/nc", ids[5])).text_ok().await;
        assert_eq!(common::body_lines(&nc), common::body_lines(&direct));
    }

    // Idempotency and cancel across replicas.
    let mut same = Vec::new();
    for base in [&a.base, &b.base] {
        let j: Value = c
            .post(format!("{base}/v1/jobs?machine=dmg-dmc75v"))
            .header("idempotency-key", "op-40")
            .body(common::generated("dmg-dmc75v", 100, 1))
            .json_ok()
            .await;
        same.push(j["id"].as_str().unwrap().to_string());
    }
    assert_eq!(same[0], same[1]);
    let long: Value = c
        .post(format!("{}/v1/jobs?machine=dmg-dmc75v", a.base))
        .body(common::generated("dmg-dmc75v", 400_000, 9))
        .json_ok()
        .await;
    let long_id = long["id"].as_str().unwrap().to_string();
    let r = c.delete(format!("{}/v1/jobs/{long_id}", b.base)).send().await.unwrap();
    assert_eq!(r.status(), 200);
    let j = common::wait_finished(&c, &a.base, &long_id, Duration::from_secs(30)).await;
    assert_eq!(j["state"], "cancelled");

    // A profile written on one replica is served by the other.
    let toml = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/machines/dmg-dmc75v.toml"))
        .unwrap()
        .replace("id = \"dmg-dmc75v\"", "id = \"shop-dmg\"");
    let r = c
        .post(format!("{}/v1/machines", a.base))
        .header("authorization", format!("Bearer {TOKEN}"))
        .header("content-type", "application/toml")
        .body(toml)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 201);
    let t0 = Instant::now();
    while c.get(format!("{}/v1/machines/shop-dmg", b.base)).status_ok().await != 200 {
        assert!(t0.elapsed() < Duration::from_secs(10), "replica b never saw the profile");
        tokio::time::sleep(Duration::from_millis(100)).await;
    }

    // kill -9 a replica mid-job: the other takes the job over once the lease runs out.
    let mut a = a;
    let victim: Value = c
        .post(format!("{}/v1/jobs?machine=dmg-dmc75v", a.base))
        .body(common::generated("dmg-dmc75v", 150_000, 4))
        .json_ok()
        .await;
    let victim_id = victim["id"].as_str().unwrap().to_string();
    // Wait until a runs it (b may get it first: then there is nothing to kill for this check).
    let t0 = Instant::now();
    let first = loop {
        let j = common::get_json(&c, &format!("{}/v1/jobs/{victim_id}", b.base)).await;
        if j["state"] == "running" && j["progress"]["blocks"].as_u64().unwrap_or(0) > 0 {
            break j;
        }
        assert!(t0.elapsed() < Duration::from_secs(60), "{j}");
        tokio::time::sleep(Duration::from_millis(20)).await;
    };
    let runner = first["node"].as_str().unwrap().to_string();
    let node_a = node_of(&c, &a.base).await;
    let mut b = b;
    let (killed, survivor) = if runner == node_a { (&mut a, &b) } else { (&mut b, &a) };
    killed.child.kill().unwrap();
    killed.child.wait().unwrap();
    let j = common::wait_finished(&c, &survivor.base, &victim_id, Duration::from_secs(180)).await;
    assert_eq!(j["state"], "succeeded", "{j}");
    assert_eq!(j["attempts"], 2, "taken over after the kill: {j}");
    assert_ne!(j["node"].as_str().unwrap(), runner);
    let nc = c.get(format!("{}/v1/jobs/{victim_id}/nc", survivor.base)).text_ok().await;
    let direct = c
        .post(format!("{}/v1/post?machine=dmg-dmc75v", survivor.base))
        .body(common::generated("dmg-dmc75v", 150_000, 4))
        .text_ok()
        .await;
    assert_eq!(
        common::body_lines(&nc),
        common::body_lines(&direct),
        "the taken-over job's program is whole"
    );
    let _ = std::fs::remove_dir_all(&spool);
}
