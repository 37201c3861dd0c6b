//! Machine profiles over the API, on a real server and a real store: create, replace and delete
//! with the admin token, ETags and If-Match, versions, loader errors naming the key, jobs running
//! with the version they were submitted with, and the versions surviving a restart.

use crate::common;

use common::Fetch;

use serde_json::Value;
use std::time::Duration;

const TOKEN: &str = "shop-floor-admin-7f3a";

fn spinner_as(id: &str) -> String {
    std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/machines/spinner-u5-620.toml"))
        .unwrap()
        .replace("id = \"spinner-u5-620\"", &format!("id = \"{id}\""))
}

#[tokio::test]
async fn profiles_are_versioned_guarded_and_jobs_keep_their_version() {
    let mut cfg = common::cfg();
    cfg.admin_token = Some(TOKEN.into());
    cfg.workers = 1;
    let base = common::server(cfg.clone()).await;
    let c = reqwest::Client::new();
    let auth = format!("Bearer {TOKEN}");
    let toml_post = |url: String, body: String| {
        c.post(url)
            .header("authorization", &auth)
            .header("content-type", "application/toml")
            .body(body)
    };

    // The shipped profiles are version 1, from their files.
    let list = common::get_json(&c, &format!("{base}/v1/machines")).await;
    assert!(
        list.as_array()
            .unwrap()
            .iter()
            .all(|m| m["version"] == 1 && m["source"] == "file")
    );
    let r = c.get(format!("{base}/v1/machines/spinner-u5-620")).send().await.unwrap();
    assert_eq!(r.headers()["etag"], "\"spinner-u5-620-v1\"");
    let r = c
        .get(format!("{base}/v1/machines/spinner-u5-620"))
        .header("if-none-match", "\"spinner-u5-620-v1\"")
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 304);
    let r = c
        .get(format!("{base}/v1/machines/spinner-u5-620"))
        .header("accept", "application/toml")
        .send()
        .await
        .unwrap();
    assert_eq!(r.headers()["content-type"], "application/toml; charset=utf-8");
    assert_eq!(r.text().await.unwrap(), spinner_as("spinner-u5-620"));

    // No token, a wrong token: 401 with a challenge; nothing written.
    let r = c
        .post(format!("{base}/v1/machines"))
        .header("content-type", "application/toml")
        .body(spinner_as("shop-spinner"))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 401);
    assert!(r.headers()["www-authenticate"].to_str().unwrap().starts_with("Bearer"));
    let r = c
        .post(format!("{base}/v1/machines"))
        .header("authorization", "Bearer guess")
        .header("content-type", "application/toml")
        .body(spinner_as("shop-spinner"))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 401);
    assert_eq!(c.get(format!("{base}/v1/machines/shop-spinner")).status_ok().await, 404);
    // The scheme is case-insensitive: `bearer` writes as `Bearer` does.
    let r = c
        .post(format!("{base}/v1/machines"))
        .header("authorization", format!("bearer {TOKEN}"))
        .header("content-type", "application/toml")
        .body(spinner_as("shop-spinner-lower"))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 201, "{:?}", r.text().await);

    // Create; the same id again is a conflict.
    let r = toml_post(format!("{base}/v1/machines"), spinner_as("shop-spinner"))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 201);
    assert_eq!(r.headers()["location"], "/v1/machines/shop-spinner");
    assert_eq!(r.headers()["etag"], "\"shop-spinner-v1\"");
    let m: Value = r.json().await.unwrap();
    assert_eq!((m["version"].as_i64(), m["source"].as_str()), (Some(1), Some("api")));
    assert_eq!(m["kinematics"], "table-table");
    let r = toml_post(format!("{base}/v1/machines"), spinner_as("shop-spinner"))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 409);

    // The loader's errors, naming the key.
    let bad = spinner_as("bad-one").replace("axis = [0.0, -1.0, 0.0]", "axis = [0.0, 0.0, 0.0]");
    let r = toml_post(format!("{base}/v1/machines"), bad).send().await.unwrap();
    assert_eq!(r.status(), 422);
    assert_eq!(r.headers()["content-type"], "application/problem+json");
    let p: Value = r.json().await.unwrap();
    assert_eq!(p["key"], "rotary[0] (B).axis", "{p}");
    let r = toml_post(
        format!("{base}/v1/machines"),
        spinner_as("bad-two").replace("[tool]", "spindle = 3\n[tool]"),
    )
    .send()
    .await
    .unwrap();
    assert_eq!(r.status(), 422);
    assert!(r.text().await.unwrap().contains("spindle"));
    let r = c
        .post(format!("{base}/v1/machines"))
        .header("authorization", &auth)
        .header("content-type", "text/plain")
        .body(spinner_as("x"))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 415);

    // JSON bodies: the same document; read back as TOML that the loader takes.
    let doc: Value = serde_json::json!({
        "id": "json-vmc", "units": "mm", "controller": "haas",
        "linear": [{"name": "X", "min": -300.0, "max": 300.0}, {"name": "Y", "min": -200.0, "max": 200.0},
                   {"name": "Z", "min": -300.0, "max": 0.0}],
        "tool": {"default_length": 50.0}
    });
    let r = c
        .post(format!("{base}/v1/machines"))
        .header("authorization", &auth)
        .json(&doc)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 201);
    let t = c
        .get(format!("{base}/v1/machines/json-vmc"))
        .header("accept", "application/toml")
        .text_ok()
        .await;
    kinepost::machines::parse_profile(&t, "json-vmc", Some("json-vmc")).unwrap();
    // `If-Match: *`: replace only what exists.
    for (id, want) in [("json-vmc", 200), ("ghost-vmc", 412)] {
        let r = c
            .put(format!("{base}/v1/machines/{id}"))
            .header("authorization", &auth)
            .header("content-type", "application/toml")
            .header("if-match", "*")
            .body(t.replace("\"json-vmc\"", &format!("\"{id}\"")))
            .status_ok()
            .await;
        assert_eq!(r, want, "{id}");
    }

    // Replace: the path's id must be the body's; If-Match guards against lost updates.
    let r = c
        .put(format!("{base}/v1/machines/shop-spinner"))
        .header("authorization", &auth)
        .header("content-type", "application/toml")
        .body(spinner_as("other-id"))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 422);
    assert_eq!(r.json::<Value>().await.unwrap()["key"], "id");
    let v2 = spinner_as("shop-spinner").replace("pivot = [0.0, 0.0, 100.0]", "pivot = [0.0, 0.0, 120.0]");
    let put = |body: String, if_match: &str| {
        c.put(format!("{base}/v1/machines/shop-spinner"))
            .header("authorization", &auth)
            .header("content-type", "application/toml")
            .header("if-match", if_match)
            .body(body)
    };
    let r = put(v2.clone(), "\"shop-spinner-v1\"").send().await.unwrap();
    assert_eq!(r.status(), 200);
    assert_eq!(r.headers()["etag"], "\"shop-spinner-v2\"");
    let r = put(v2.clone(), "\"shop-spinner-v1\"").send().await.unwrap();
    assert_eq!(r.status(), 412, "a stale If-Match loses, it does not overwrite");

    // A job runs with the version it was submitted with. A long job holds the one worker, so the
    // second job starts only after the profile changed again.
    let mut long = Vec::new();
    let lib = common::library();
    let m = &lib.get("spinner-u5-620").unwrap().machine;
    kinepost::testgen::write_path(m, 60_000, 3, m.default_tool_length, &mut long).unwrap();
    let mut short = Vec::new();
    kinepost::testgen::write_path(m, 500, 11, m.default_tool_length, &mut short).unwrap();
    let submit = |machine: &str, body: Vec<u8>| c.post(format!("{base}/v1/jobs?machine={machine}")).body(body).send();
    let blocker: Value = submit("spinner-u5-620", long).await.unwrap().json().await.unwrap();
    let job: Value = submit("shop-spinner", short.clone()).await.unwrap().json().await.unwrap();
    assert_eq!(job["machine_version"], 2);
    let v3 = spinner_as("shop-spinner").replace("pivot = [0.0, 0.0, 100.0]", "pivot = [0.0, 0.0, 80.0]");
    assert_eq!(put(v3, "\"shop-spinner-v2\"").status_ok().await, 200);
    let changed_ms = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_millis() as i64;
    let done = common::wait_job(&c, &base, job["id"].as_str().unwrap(), "succeeded", Duration::from_secs(120)).await;
    assert!(
        done["started_ms"].as_i64().unwrap() >= changed_ms,
        "the job ran after the change: {done}"
    );
    common::wait_job(
        &c,
        &base,
        blocker["id"].as_str().unwrap(),
        "succeeded",
        Duration::from_secs(120),
    )
    .await;
    let job_nc = c
        .get(format!("{base}/v1/jobs/{}/nc", job["id"].as_str().unwrap()))
        .text_ok()
        .await;
    let post = |machine: &'static str| {
        let base = base.clone();
        let (c, short) = (c.clone(), short.clone());
        async move {
            c.post(format!("{base}/v1/post?machine={machine}"))
                .body(short)
                .text_ok()
                .await
        }
    };
    let now_v3 = post("shop-spinner").await;
    assert_ne!(
        common::body_lines(&job_nc),
        common::body_lines(&now_v3),
        "the pivot change moves the program"
    );
    // Version 2's text again (as version 4): the job's program is its program.
    assert_eq!(put(v2.clone(), "\"shop-spinner-v3\"").status_ok().await, 200);
    assert_eq!(common::body_lines(&job_nc), common::body_lines(&post("shop-spinner").await));

    // Delete: a version too; history and old texts stay readable; the id can come back.
    let r = c
        .delete(format!("{base}/v1/machines/shop-spinner"))
        .header("authorization", &auth)
        .header("if-match", "\"shop-spinner-v3\"")
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 412);
    let r = c
        .delete(format!("{base}/v1/machines/shop-spinner"))
        .header("authorization", &auth)
        .header("if-match", "\"shop-spinner-v4\"")
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 204);
    assert_eq!(c.get(format!("{base}/v1/machines/shop-spinner")).status_ok().await, 404);
    let h = common::get_json(&c, &format!("{base}/v1/machines/shop-spinner/versions")).await;
    assert!(h["current"].is_null());
    let vs: Vec<(i64, bool, String)> = h["versions"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| {
            (
                v["version"].as_i64().unwrap(),
                v["deleted"].as_bool().unwrap(),
                v["source"].as_str().unwrap().into(),
            )
        })
        .collect();
    assert_eq!(vs.len(), 5);
    assert!(
        vs.iter()
            .enumerate()
            .all(|(i, v)| v.0 == i as i64 + 1 && v.2 == "api" && v.1 == (i == 4))
    );
    let t = c.get(format!("{base}/v1/machines/shop-spinner/versions/2")).text_ok().await;
    assert_eq!(t, v2);
    assert_eq!(
        c.get(format!("{base}/v1/machines/shop-spinner/versions/5")).status_ok().await,
        404
    );
    let r = toml_post(format!("{base}/v1/machines"), spinner_as("shop-spinner"))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 201);
    assert_eq!(r.headers()["etag"], "\"shop-spinner-v6\"");

    // A restart on the same store serves what the API wrote.
    let again = common::server(cfg.clone()).await;
    let m = common::get_json(&c, &format!("{again}/v1/machines/shop-spinner")).await;
    assert_eq!(m["version"], 6);
    let h = common::get_json(&c, &format!("{again}/v1/machines/shop-spinner/versions")).await;
    assert_eq!(h["versions"].as_array().unwrap().len(), 6);
}

#[tokio::test]
async fn writes_are_off_without_a_token_and_files_version_at_start_up() {
    // A library directory of our own, and one store across "restarts".
    let dir = std::env::temp_dir().join(format!("kinepost-lib-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    for id in ["spinner-u5-620", "haas-umc750"] {
        std::fs::copy(
            format!("{}/machines/{id}.toml", env!("CARGO_MANIFEST_DIR")),
            dir.join(format!("{id}.toml")),
        )
        .unwrap();
    }
    let mut cfg = common::cfg();
    cfg.machines = dir.clone();
    let base = common::server(cfg.clone()).await;
    let c = reqwest::Client::new();
    let r = c
        .post(format!("{base}/v1/machines"))
        .header("authorization", "Bearer anything")
        .header("content-type", "application/toml")
        .body(spinner_as("new-one"))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 403, "no admin token configured: no writes");
    assert_eq!(c.delete(format!("{base}/v1/machines/haas-umc750")).status_ok().await, 403);

    // A changed file is a new version at the next start; an API change is never overwritten.
    let path = dir.join("spinner-u5-620.toml");
    let changed = std::fs::read_to_string(&path)
        .unwrap()
        .replace("d = 100 (chosen)", "d = 100, remeasured");
    std::fs::write(&path, &changed).unwrap();
    let mut admin = cfg.clone();
    admin.admin_token = Some(TOKEN.into());
    let base = common::server(admin.clone()).await;
    let m = common::get_json(&c, &format!("{base}/v1/machines/spinner-u5-620")).await;
    assert_eq!((m["version"].as_i64(), m["source"].as_str()), (Some(2), Some("file")));
    assert!(m["description"].as_str().unwrap().contains("remeasured"));
    let haas = std::fs::read_to_string(dir.join("haas-umc750.toml")).unwrap();
    let r = c
        .put(format!("{base}/v1/machines/haas-umc750"))
        .header("authorization", format!("Bearer {TOKEN}"))
        .header("content-type", "application/toml")
        .body(haas.replace("default_length = ", "default_length = 1"))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    std::fs::write(
        dir.join("haas-umc750.toml"),
        haas.replace("description = \"", "description = \"file edit: "),
    )
    .unwrap();
    let base = common::server(admin).await;
    let m = common::get_json(&c, &format!("{base}/v1/machines/haas-umc750")).await;
    assert_eq!((m["version"].as_i64(), m["source"].as_str()), (Some(2), Some("api")));
    assert!(!m["description"].as_str().unwrap().contains("file edit"));
    let _ = std::fs::remove_dir_all(&dir);
}

/// A profile whose table is an STL mesh `file` (the shipped spinner's kinematics, no other body).
fn spinner_mesh_as(id: &str, file: &str) -> String {
    let text = spinner_as(id);
    let cut = text.find("\n# Geometry for the collision check").or_else(|| text.find("\n[[body]]")).unwrap_or(text.len());
    format!("{}\n[[body]]\nname = \"table mesh\"\non = \"C\"\nmesh = {file:?}\n", &text[..cut])
}

#[tokio::test]
async fn mesh_bodies_come_from_the_library_directory_and_are_served_for_the_page() {
    let dir = std::env::temp_dir().join(format!("kinepost-mesh-lib-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let stl = common::stl::binary(&common::stl::box_triangles([-300.0, -300.0, -60.0], [300.0, 300.0, 0.0]));
    std::fs::write(dir.join("table.stl"), &stl).unwrap();
    std::fs::write(dir.join("spinner-mesh.toml"), spinner_mesh_as("spinner-mesh", "table.stl")).unwrap();
    let mut cfg = common::cfg();
    cfg.machines = dir.clone();
    cfg.admin_token = Some(TOKEN.into());
    let base = common::server(cfg).await;
    let c = reqwest::Client::new();

    // The profile's body names its mesh; the page fetches the triangles.
    let m = common::get_json(&c, &format!("{base}/v1/machines/spinner-mesh")).await;
    let body = &m["bodies"][0];
    assert_eq!(body["mesh"]["file"], "table.stl", "{m}");
    assert_eq!(body["mesh"]["triangles"], 12);
    assert_eq!(body["mesh"]["bounds"], serde_json::json!([-300.0, -300.0, -60.0, 300.0, 300.0, 0.0]));
    let r = c.get(format!("{base}/v1/machines/spinner-mesh/meshes/table.stl")).send().await.unwrap();
    assert_eq!(r.status(), 200);
    assert_eq!(r.headers()["content-type"], "model/stl");
    let etag = r.headers()["etag"].to_str().unwrap().to_string();
    let bytes = r.bytes().await.unwrap();
    assert_eq!(bytes.len(), 84 + 12 * 50);
    assert_eq!(&bytes[12 + 84..84 + 50 - 2], &stl[12 + 84..84 + 50 - 2], "the first triangle's vertices");
    let r = c.get(format!("{base}/v1/machines/spinner-mesh/meshes/table.stl")).header("if-none-match", &etag).send().await.unwrap();
    assert_eq!(r.status(), 304);
    for url in ["spinner-mesh/meshes/other.stl", "spinner-u5-620/meshes/table.stl", "nobody/meshes/table.stl"] {
        assert_eq!(c.get(format!("{base}/v1/machines/{url}")).status_ok().await, 404, "{url}");
    }

    // Over the API: a mesh is a file the operator put in the library directory; none is uploaded.
    let post = |body: String| {
        c.post(format!("{base}/v1/machines"))
            .header("authorization", format!("Bearer {TOKEN}"))
            .header("content-type", "application/toml")
            .body(body)
    };
    for (file, why) in [("missing.stl", "missing.stl"), ("../table.stl", "beside the profile")] {
        let r = post(spinner_mesh_as("api-mesh", file)).send().await.unwrap();
        assert_eq!(r.status(), 422, "{file}");
        let p: Value = r.json().await.unwrap();
        assert_eq!(p["key"], "body[0].mesh", "{p}");
        assert!(p["detail"].as_str().unwrap_or_default().contains(why), "{p}");
    }
    assert_eq!(post(spinner_mesh_as("api-mesh", "table.stl")).status_ok().await, 201);
    let m = common::get_json(&c, &format!("{base}/v1/machines/api-mesh")).await;
    assert_eq!(m["bodies"][0]["mesh"]["triangles"], 12, "{m}");
    let _ = std::fs::remove_dir_all(&dir);
}
