//! Tool tables over the API, on a real server and store (SQLite; PostgreSQL too with
//! `KINEPOST_TEST_DATABASE_URL`): `/v1/machines/{id}/tools` written with the admin token, each
//! write a version with its ETag and `If-Match`; posts and jobs use the machine's table, or their
//! own `tool_table`, and a job records the version it ran with.

use crate::common;

use common::Fetch;

use serde_json::Value;
use std::time::Duration;

const TOKEN: &str = "tool-crib-admin";
const MACHINE: &str = "fryer-5x-45";

const TABLE: &str = "units = \"inch\"
[[tool]]
number = 1
length = 3.5
diameter = 0.5
[[tool]]
number = 2
length = 6.25
holder = { diameter = 1.5, length = 2.5 }
";

/// Two tools on the fryer (A/C head-head), a short 5-axis cut each, no lengths in the CL.
fn two_tools() -> String {
    let cut = |n: usize, x0: f64| -> String {
        (0..n)
            .map(|i| {
                let t = i as f64 / (n.max(2) - 1) as f64;
                let (a, c) = ((10.0 + 15.0 * t).to_radians(), (90.0 * t).to_radians());
                format!(
                    "GOTO/{:.4},{:.4},-9,{:.6},{:.6},{:.6}\n",
                    x0 + 2.0 * t,
                    1.0 - t,
                    a.sin() * c.cos(),
                    a.sin() * c.sin(),
                    a.cos()
                )
            })
            .collect()
    };
    format!(
        "UNITS/INCHES\nLOADTL/1\nSPINDL/3000\n{}LOADTL/2\nSPINDL/3000\n{}FINI\n",
        cut(8, -3.0),
        cut(8, 1.0)
    )
}


#[tokio::test]
async fn tool_tables_round_trip_on_sqlite() {
    let mut cfg = common::cfg();
    cfg.admin_token = Some(TOKEN.into());
    cfg.workers = 1;
    round_trip(&common::server(cfg).await).await;
}

#[tokio::test]
#[ignore = "needs PostgreSQL: KINEPOST_TEST_DATABASE_URL=postgres://… cargo test -- --ignored"]
async fn tool_tables_round_trip_on_postgres() {
    let Some((url, admin, name)) = common::postgres("tools").await else {
        assert!(std::env::var("KINEPOST_REQUIRE_POSTGRES").is_err(), "KINEPOST_REQUIRE_POSTGRES is set but KINEPOST_TEST_DATABASE_URL is not");
        eprintln!("SKIPPED: set KINEPOST_TEST_DATABASE_URL=postgres://… to run on PostgreSQL");
        return;
    };
    let mut cfg = common::cfg();
    cfg.admin_token = Some(TOKEN.into());
    cfg.workers = 1;
    cfg.database_url = Some(url);
    round_trip(&common::server(cfg).await).await;
    common::drop_postgres(&admin, &name).await;
}

async fn round_trip(base: &str) {
    let c = reqwest::Client::new();
    let url = format!("{base}/v1/machines/{MACHINE}/tools");
    let auth = format!("Bearer {TOKEN}");
    let put = |body: &str, if_match: Option<&str>| {
        let mut r = c
            .put(&url)
            .header("authorization", &auth)
            .header("content-type", "application/toml")
            .body(body.to_string());
        if let Some(m) = if_match {
            r = r.header("if-match", m);
        }
        r.send()
    };

    // None yet; writes need the token; a table for no machine is refused.
    assert_eq!(c.get(&url).status_ok().await, 404);
    let r = c
        .put(&url)
        .header("content-type", "application/toml")
        .body(TABLE)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 401);
    let r = c
        .put(format!("{base}/v1/machines/no-such-machine/tools"))
        .header("authorization", &auth)
        .header("content-type", "application/toml")
        .body(TABLE)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 404);

    // Created: version 1, its ETag; read back as JSON, as the TOML written, and 304.
    let r = put(TABLE, None).await.unwrap();
    assert_eq!(r.status(), 201);
    assert_eq!(r.headers()["etag"], format!("\"{MACHINE}-tools-v1\""));
    let t: Value = r.json().await.unwrap();
    assert_eq!((t["version"].as_i64(), t["units"].as_str()), (Some(1), Some("inch")));
    assert_eq!(t["tools"][1]["holder"]["diameter"], 1.5);
    let r = c.get(&url).header("accept", "application/toml").send().await.unwrap();
    assert_eq!(r.headers()["etag"], format!("\"{MACHINE}-tools-v1\""));
    assert_eq!(r.text().await.unwrap(), TABLE);
    let r = c
        .get(&url)
        .header("if-none-match", format!("\"{MACHINE}-tools-v1\""))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 304);

    // Replaced only from the version read: a stale If-Match (or a profile's ETag) is 412.
    let v2 = TABLE.replace("length = 6.25", "length = 6.0");
    for stale in [format!("\"{MACHINE}-tools-v7\""), format!("\"{MACHINE}-v1\"")] {
        assert_eq!(put(&v2, Some(&stale)).await.unwrap().status(), 412, "{stale}");
    }
    let r = put(&v2, Some(&format!("\"{MACHINE}-tools-v1\""))).await.unwrap();
    assert_eq!(r.status(), 200);
    assert_eq!(r.headers()["etag"], format!("\"{MACHINE}-tools-v2\""));
    // A bad table: 422 naming the entry, nothing written.
    let r = put(&TABLE.replace("length = 3.5", "length = -3.5"), None).await.unwrap();
    assert_eq!(r.status(), 422);
    let p: Value = r.json().await.unwrap();
    assert_eq!((p["key"].as_str(), p["title"].as_str()), (Some("tool[0] (T1).length"), Some("Invalid tool table")), "{p}");
    let vs = common::get_json(&c, &format!("{url}/versions")).await;
    assert_eq!(vs["current"], 2, "{vs}");
    assert_eq!(c.get(format!("{url}/versions/1")).text_ok().await, TABLE);

    // A post without a table of its own uses the machine's, and says which version.
    let post = |q: &str| {
        c.post(format!("{base}/v1/post?machine={MACHINE}&dialect=fanuc{q}"))
            .header("content-type", "text/plain")
            .body(two_tools())
            .send()
    };
    let nc = post("").await.unwrap().text().await.unwrap();
    assert!(nc.contains("(TOOL 2 LENGTH 6.0000 FROM THE TOOL TABLE)"), "{nc}");
    assert!(nc.contains("THE MACHINE'S TOOL TABLE V2"), "{nc}");
    // Its own (a query parameter here, a form field below) replaces the machine's.
    let q = format!(
        "&tool_table={}",
        TABLE
            .replace('\n', "%0A")
            .replace(' ', "%20")
            .replace('"', "%22")
            .replace('=', "%3D")
    );
    let nc = post(&q).await.unwrap().text().await.unwrap();
    assert!(
        nc.contains("(TOOL 2 LENGTH 6.2500 FROM THE TOOL TABLE)") && nc.contains("THE JOB'S TOOL TABLE"),
        "{nc}"
    );
    let form = format!(
        "--XYZ\r\nContent-Disposition: form-data; name=\"machine\"\r\n\r\n{MACHINE}\r\n--XYZ\r\nContent-Disposition: form-data; name=\"tool_table\"\r\n\r\n{}\r\n--XYZ\r\nContent-Disposition: form-data; name=\"file\"; filename=\"two.cls\"\r\n\r\n{}\r\n--XYZ--\r\n",
        TABLE.replace("6.25", "7.5"),
        two_tools()
    );
    let r = c
        .post(format!("{base}/v1/post"))
        .header("content-type", "multipart/form-data; boundary=XYZ")
        .body(form)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    assert!(r.text().await.unwrap().contains("TOOL 2 LENGTH 7.5000 FROM THE TOOL TABLE"));
    // A bad one of the job's own: 400 naming the entry, before anything is written.
    let r = post("&tool_table=units%3D%22inch%22%0A%5B%5Btool%5D%5D%0Anumber%3D0%0Alength%3D1")
        .await
        .unwrap();
    assert_eq!(r.status(), 400);
    assert!(r.text().await.unwrap().contains("tool[0].number"));

    // A job records the machine's table version it was submitted with, and runs with it.
    let submit = |q: &str| {
        c.post(format!("{base}/v1/jobs?machine={MACHINE}&dialect=fanuc{q}"))
            .header("content-type", "text/plain")
            .body(two_tools())
            .send()
    };
    let job: Value = submit("").await.unwrap().json().await.unwrap();
    assert_eq!(
        (job["tool_table_version"].as_i64(), job["own_tool_table"].as_bool()),
        (Some(2), Some(false)),
        "{job}"
    );
    let r = put(TABLE, None).await.unwrap();
    assert_eq!(
        r.status(),
        200,
        "version 3, after the job was submitted: {:?}",
        r.text().await
    );
    let id = job["id"].as_str().unwrap();
    let done = common::wait_job(&c, base, id, "succeeded", Duration::from_secs(60)).await;
    assert_eq!(done["state"], "succeeded", "{done}");
    let nc = c.get(format!("{base}/v1/jobs/{id}/nc")).text_ok().await;
    assert!(
        nc.contains("(TOOL 2 LENGTH 6.0000 FROM THE TOOL TABLE)") && nc.contains("V2"),
        "{nc}"
    );
    let job: Value = submit(&q).await.unwrap().json().await.unwrap();
    assert_eq!(
        (job["tool_table_version"].as_i64(), job["own_tool_table"].as_bool()),
        (None, Some(true)),
        "{job}"
    );

    // Deleted: a version of its own; posts go back to the profile's length.
    let r = c
        .delete(&url)
        .header("authorization", &auth)
        .header("if-match", format!("\"{MACHINE}-tools-v2\""))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 412);
    let r = c.delete(&url).header("authorization", &auth).send().await.unwrap();
    assert_eq!(r.status(), 204);
    assert_eq!(c.get(&url).status_ok().await, 404);
    let vs = common::get_json(&c, &format!("{url}/versions")).await;
    let deleted: Vec<bool> = vs["versions"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v["deleted"].as_bool().unwrap())
        .collect();
    assert_eq!(deleted, [false, false, false, true], "{vs}");
    let nc = post("").await.unwrap().text().await.unwrap();
    assert!(!nc.contains("TOOL TABLE") && nc.contains("UNTIL THE CL SETS ONE"), "{nc}");
}
