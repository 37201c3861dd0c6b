//! The HTTP service over a real socket: every route, streaming order, error paths.

use crate::common;

use common::{Fetch, cfg, server};
use kinepost::http::{Config, openapi_json};
use serde_json::Value;
use std::time::Duration;

fn data(name: &str) -> Vec<u8> {
    std::fs::read(common::data(name)).unwrap()
}

#[tokio::test]
async fn machines_health_metrics_and_docs() {
    let base = server(cfg()).await;
    let c = reqwest::Client::new();
    let list: Vec<Value> = c
        .get(format!("{base}/v1/machines"))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert_eq!(list.len(), 11);
    let one: Value = c
        .get(format!("{base}/v1/machines/htm50200-horizontal"))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert_eq!(one["kinematics"], "head-table");
    assert_eq!(one["rotary"][1]["angle_error"]["range"][1], 40.0);
    let r = c.get(format!("{base}/v1/machines/no-such")).send().await.unwrap();
    assert_eq!(r.status(), 404);
    assert_eq!(r.headers()["content-type"], "application/problem+json");
    assert!(r.headers().contains_key("x-request-id"));
    let p: Value = r.json().await.unwrap();
    assert_eq!(p["type"], "https://kinepost.dev/problems/unknown-machine");
    assert_eq!(
        c.get(format!("{base}/healthz")).send().await.unwrap().text().await.unwrap(),
        "ok"
    );
    assert_eq!(c.get(format!("{base}/readyz")).send().await.unwrap().status(), 200);
    let docs = c.get(format!("{base}/docs/")).send().await.unwrap();
    assert_eq!(docs.status(), 200);
    assert!(
        docs.text().await.unwrap().contains("swagger"),
        "Swagger UI served from the binary"
    );
    // It loads this service's document (it opened on "No API definition provided").
    let init = c.get(format!("{base}/docs/swagger-initializer.js")).send().await.unwrap().text().await.unwrap();
    assert!(init.contains("\"/openapi.json\""), "{init}");
    let m = c.get(format!("{base}/metrics")).send().await.unwrap().text().await.unwrap();
    assert!(
        m.contains("kinepost_http_requests_total{route=\"/v1/machines/{id}\",status=\"404\"} 1"),
        "{m}"
    );
    assert!(m.contains("kinepost_streams_in_flight 0"));
    // The queue's series are there before the first job, at 0.
    assert!(m.contains("kinepost_jobs{state=\"queued\"} 0") && m.contains("kinepost_jobs{state=\"failed\"} 0"), "{m}");
}

#[tokio::test]
async fn metrics_are_valid_openmetrics_with_every_series_from_the_start() {
    let base = server(cfg()).await;
    let c = reqwest::Client::new();
    let r = c.get(format!("{base}/metrics")).send().await.unwrap();
    let ctype = r.headers()["content-type"].to_str().unwrap().to_string();
    assert!(ctype.starts_with("application/openmetrics-text; version=1.0.0"), "{ctype}");
    let m = r.text().await.unwrap();
    check_exposition(&m);
    let mut start = vec![
        "kinepost_cl_points_total 0".to_string(),
        "kinepost_blocks_total 0".into(),
        "kinepost_streams_in_flight 0".into(),
        "kinepost_post_duration_seconds_count 0".into(),
        "kinepost_post_duration_seconds_bucket{le=\"+Inf\"} 0".into(),
    ];
    for st in ["queued", "running", "succeeded", "failed", "cancelled"] {
        start.push(format!("kinepost_jobs{{state=\"{st}\"}} 0"));
    }
    for outcome in ["succeeded", "failed", "cancelled", "retried"] {
        start.push(format!("kinepost_job_duration_seconds_count{{outcome=\"{outcome}\"}} 0"));
        start.push(format!("kinepost_job_duration_seconds_bucket{{le=\"+Inf\",outcome=\"{outcome}\"}} 0"));
    }
    for line in &start {
        assert!(m.lines().any(|l| l == line), "no `{line}` at start in\n{m}");
    }
    // The first scrape is counted once it is answered.
    let m = c.get(format!("{base}/metrics")).text_ok().await;
    check_exposition(&m);
    assert!(m.contains("kinepost_http_requests_total{route=\"/metrics\",status=\"200\"} 1\n"), "{m}");
}

/// An OpenMetrics text exposition: comments (HELP, TYPE, UNIT) and samples, each sample in a
/// family a TYPE line declared before it, ended by one `# EOF`.
fn check_exposition(text: &str) {
    let body = text.strip_suffix("# EOF\n").unwrap_or_else(|| panic!("no final # EOF in\n{text}"));
    let mut families = Vec::new();
    for line in body.lines() {
        if let Some(decl) = line.strip_prefix("# TYPE ") {
            let (name, kind) = decl.split_once(' ').unwrap_or_else(|| panic!("bad `{line}`"));
            assert!(["counter", "gauge", "histogram"].contains(&kind), "`{line}`");
            families.push(name.to_string());
        } else if line.starts_with("# HELP ") || line.starts_with("# UNIT ") {
            continue;
        } else {
            let name = sample_name(line).unwrap_or_else(|| panic!("not a comment or a sample: `{line}`"));
            let family = ["_total", "_bucket", "_sum", "_count"]
                .iter()
                .find_map(|s| name.strip_suffix(s).filter(|f| families.iter().any(|x| x == f)))
                .unwrap_or(name);
            assert!(families.iter().any(|f| f == family), "`{line}` before its # TYPE");
        }
    }
}

/// The metric name of a sample line `name{key="value",…} number`, if the line is one.
fn sample_name(line: &str) -> Option<&str> {
    let end = line.find(|c: char| !(c.is_ascii_alphanumeric() || c == '_' || c == ':'))?;
    let (name, rest) = line.split_at(end);
    if name.is_empty() || name.starts_with(|c: char| c.is_ascii_digit()) {
        return None;
    }
    let rest = match rest.strip_prefix('{') {
        Some(labels) => after_labels(labels)?,
        None => rest,
    };
    let value = rest.strip_prefix(' ')?;
    let number = value.parse::<f64>().is_ok() && !value.contains(|c: char| c.is_ascii_alphabetic() && c != 'e');
    (number || ["+Inf", "-Inf", "NaN"].contains(&value)).then_some(name)
}

/// What follows a label set's closing brace: each label `key="value"` (escapes in the value),
/// separated by commas.
fn after_labels(mut s: &str) -> Option<&str> {
    loop {
        let (key, value) = s.split_once("=\"")?;
        if key.is_empty() || !key.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
            return None;
        }
        let mut chars = value.char_indices();
        let close = loop {
            match chars.next()? {
                (_, '\\') => {
                    chars.next()?;
                }
                (i, '"') => break i,
                _ => {}
            }
        };
        s = &value[close + 1..];
        if let Some(rest) = s.strip_prefix('}') {
            return Some(rest);
        }
        s = s.strip_prefix(',')?;
    }
}

#[tokio::test]
async fn the_served_openapi_document_is_the_checked_in_one() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/openapi/openapi.json");
    let generated = openapi_json();
    if std::env::var("KINEPOST_UPDATE_OPENAPI").is_ok() {
        std::fs::write(path, &generated).unwrap();
    }
    let checked_in = std::fs::read_to_string(path).expect("openapi/openapi.json (KINEPOST_UPDATE_OPENAPI=1 writes it)");
    // OpenAPI 3 requires a description on every response (68 of 130 had none; CI also runs
    // openapi-spec-validator on the file).
    let doc: Value = serde_json::from_str(&generated).unwrap();
    let mut bare = Vec::new();
    for (path, ops) in doc["paths"].as_object().unwrap() {
        for (method, op) in ops.as_object().unwrap() {
            for (status, r) in op["responses"].as_object().into_iter().flatten() {
                if !r["description"].is_string() {
                    bare.push(format!("{method} {path} {status}"));
                }
            }
        }
    }
    assert!(bare.is_empty(), "responses without a description: {bare:?}");
    assert_eq!(
        generated, checked_in,
        "openapi/openapi.json is stale: run with KINEPOST_UPDATE_OPENAPI=1"
    );
    let base = server(cfg()).await;
    let served = reqwest::get(format!("{base}/openapi.json"))
        .await
        .unwrap()
        .text()
        .await
        .unwrap();
    assert_eq!(served, generated);
    let v: Value = serde_json::from_str(&served).unwrap();
    for p in [
        "/v1/post",
        "/v1/machines",
        "/v1/machines/{id}",
        "/healthz",
        "/readyz",
        "/metrics",
    ] {
        assert!(v["paths"][p].is_object(), "{p} documented");
    }
}

#[tokio::test]
async fn post_streams_nc_and_ndjson() {
    let base = server(cfg()).await;
    let c = reqwest::Client::new();
    let cl = data("nx_clsf_mech491_variable_axis_inch_5ax.cls");
    let r = c
        .post(format!("{base}/v1/post?machine=haas-umc750&mode=tcp"))
        .header("content-type", "text/plain")
        .body(cl.clone())
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    assert!(r.headers()["content-disposition"].to_str().unwrap().contains(".nc"));
    let nc = r.text().await.unwrap();
    // The profile's controller is the default dialect: Haas NGC, TCP with G234.
    assert!(
        nc.starts_with("%\nO01000\n") && nc.trim_end().ends_with("M30\n%"),
        "{}",
        &nc[..200]
    );
    assert!(nc.contains("G234 H1") && nc.contains("B-22.2015 C1.0496"));
    // NDJSON: header, blocks with source lines and joints, summary last.
    let r = c
        .post(format!("{base}/v1/post?machine=haas-umc750&mode=tcp"))
        .header("content-type", "application/octet-stream")
        .header("accept", "application/x-ndjson")
        .body(cl)
        .send()
        .await
        .unwrap();
    assert_eq!(r.headers()["content-type"], "application/x-ndjson");
    let lines: Vec<Value> = r
        .text()
        .await
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(lines[0]["type"], "header");
    assert_eq!(lines[0]["machine"], "haas-umc750");
    let blocks: Vec<&Value> = lines
        .iter()
        .filter(|l| l["type"] == "block" && l["source_line"].is_number())
        .collect();
    assert!(blocks.len() > 600);
    assert!(blocks[0]["joints"]["B"].is_number() && blocks[0]["nc"].as_str().unwrap().starts_with("G0"));
    let last = lines.last().unwrap();
    assert_eq!(last["type"], "summary");
    assert_eq!(last["summary"]["cl_points"], 348);
    assert!(last["summary"]["max_tip_deviation"].as_f64().unwrap() < 0.0004);
}

#[tokio::test]
async fn post_as_a_multipart_form() {
    let base = server(cfg()).await;
    let body = format!(
        "--XYZ\r\nContent-Disposition: form-data; name=\"machine\"\r\n\r\nvmc-3axis\r\n--XYZ\r\nContent-Disposition: form-data; name=\"sequence_numbers\"\r\n\r\ntrue\r\n--XYZ\r\nContent-Disposition: form-data; name=\"file\"; filename=\"plate.ncl\"\r\nContent-Type: text/plain\r\n\r\n{}\r\n--XYZ--\r\n",
        String::from_utf8(data("creo8_ncl_profilfraesen_profile_mm.ncl")).unwrap()
    );
    let r = reqwest::Client::new()
        .post(format!("{base}/v1/post"))
        .header("content-type", "multipart/form-data; boundary=XYZ")
        .body(body)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    assert!(r.headers()["content-disposition"].to_str().unwrap().contains("plate.nc"));
    let nc = r.text().await.unwrap();
    assert!(nc.contains("(SOURCE PLATE.NCL)") && nc.contains("N5 "), "{}", &nc[..400]);
}

/// NX's CLSF has no SPINDL: a spindle speed given with the job (query or form field) starts the
/// spindle before the first move; a bad one is refused with the setting named.
#[tokio::test]
async fn a_spindle_speed_for_a_cl_without_one() {
    let base = server(cfg()).await;
    let c = reqwest::Client::new();
    let cl = data("nx_clsf_mech491_simple_mill_plane_mm.cls");
    let post = |q: &str| {
        c.post(format!("{base}/v1/post?machine=vmc-3axis{q}"))
            .header("content-type", "text/plain")
            .body(cl.clone())
    };
    let nc = post("").text_ok().await;
    assert!(!nc.contains(" M3"), "the CL starts no spindle: {nc}");
    let nc = post("&spindle_speed=9000").text_ok().await;
    assert!(nc.contains("\nS9000 M3\nG43 H"), "{nc}");
    let r = post("&spindle_speed=0").send().await.unwrap();
    assert_eq!(r.status(), 400);
    assert!(r.text().await.unwrap().contains("spindle_speed"));
    let body = format!(
        "--XYZ\r\nContent-Disposition: form-data; name=\"machine\"\r\n\r\nvmc-3axis\r\n--XYZ\r\nContent-Disposition: form-data; name=\"spindle_speed\"\r\n\r\n7500\r\n--XYZ\r\nContent-Disposition: form-data; name=\"file\"; filename=\"plane.cls\"\r\nContent-Type: text/plain\r\n\r\n{}\r\n--XYZ--\r\n",
        String::from_utf8(cl.clone()).unwrap()
    );
    let nc = c
        .post(format!("{base}/v1/post"))
        .header("content-type", "multipart/form-data; boundary=XYZ")
        .body(body)
        .text_ok()
        .await;
    assert!(nc.contains("\nS7500 M3\n"), "{nc}");
}

/// `smoothing=` as a query parameter and a form field: each operation's word in the dialect's
/// form; a bad value refused with the setting named.
#[tokio::test]
async fn smoothing_per_operation_as_a_query_and_a_form_field() {
    let base = server(cfg()).await;
    let c = reqwest::Client::new();
    let cl = "UNITS/MM\nTOOL PATH/A,TOOL,EM1\nINTOL/0.1\nOUTTOL/0.1\nLOADTL/1\nSPINDL/8000,CLW\nRAPID\nGOTO/0,0,50,0,0,1\nGOTO/0,0,5\nFEDRAT/1000\nGOTO/10,0,5\nFINI\n";
    let post = |q: &str| {
        c.post(format!("{base}/v1/post?machine=vmc-3axis&dialect=siemens{q}"))
            .header("content-type", "text/plain")
            .body(cl)
    };
    let nc = post("").text_ok().await;
    assert!(nc.contains("\nCYCLE832(0.200, _ROUGH, 1)\n") && nc.contains("\nCYCLE832()\n"), "{nc}");
    let nc = post("&smoothing=finish").text_ok().await;
    assert!(nc.contains("\nCYCLE832(0.200, _FINISH, 1)\n"), "{nc}");
    assert!(!post("&smoothing=off").text_ok().await.contains("CYCLE832"));
    let r = post("&smoothing=medium").send().await.unwrap();
    assert_eq!(r.status(), 400);
    let e = r.text().await.unwrap();
    assert!(e.contains("smoothing") && e.contains("medium"), "{e}");
    let body = format!(
        "--XYZ\r\nContent-Disposition: form-data; name=\"machine\"\r\n\r\nvmc-3axis\r\n--XYZ\r\nContent-Disposition: form-data; name=\"dialect\"\r\n\r\nhaas\r\n--XYZ\r\nContent-Disposition: form-data; name=\"smoothing\"\r\n\r\nfinish\r\n--XYZ\r\nContent-Disposition: form-data; name=\"file\"; filename=\"a.cls\"\r\nContent-Type: text/plain\r\n\r\n{cl}\r\n--XYZ--\r\n"
    );
    let nc = c
        .post(format!("{base}/v1/post"))
        .header("content-type", "multipart/form-data; boundary=XYZ")
        .body(body)
        .text_ok()
        .await;
    assert!(nc.contains("\nG187 P3 E0.200\n"), "{nc}");
}

/// Lenient text/plain answers 200 before the program is read: the outcome is in the text, the
/// blocks with errors marked and a closing comment before the program end.
#[tokio::test]
async fn a_program_with_errors_says_so_in_the_streamed_text() {
    let base = server(cfg()).await;
    let c = reqwest::Client::new();
    let cl = "FEDRAT/500,MMPM\nLOADTL/1\nSPINDL/1000\nGOTO/10,20,30,0,0,1\nGOTO/9000,20,30,0,0,1\nFINI\n";
    let nc = c
        .post(format!("{base}/v1/post?machine=vmc-3axis"))
        .header("content-type", "text/plain")
        .body(cl)
        .text_ok()
        .await;
    assert!(nc.contains("X9000.000 (ERROR LIMIT_VIOLATION)"), "{nc}");
    let close = nc.find("(KINEPOST: ERRORS 1,").expect("closing comment");
    assert!(close < nc.find("M30").unwrap(), "{nc}");
}

#[tokio::test]
async fn drilling_cycles_as_canned_cycles_on_request() {
    let base = server(cfg()).await;
    let c = reqwest::Client::new();
    let post = |q: &'static str| {
        c.post(format!("{base}/v1/post?machine=vmc-3axis{q}"))
            .header("content-type", "text/plain")
            .body(data("creo8_ncl_bohren_drill_mm.ncl"))
    };
    let nc = post("&cycles=canned").text_ok().await;
    assert!(nc.contains("G99 G83 X") && nc.contains("\nG80\n"), "{nc}");
    let nc = post("").text_ok().await;
    assert!(!nc.contains("G83"), "expanded by default: {nc}");
    assert_eq!(post("&cycles=sometimes").status_ok().await, 400);
    let d = c.get(format!("{base}/v1/dialects")).json_ok().await;
    assert!(d[0]["canned_cycles"].as_str().unwrap().contains("G81"), "{d}");
}

/// 3+2 in a tilted working plane on request (`planes=tilted`), in the dialect asked for.
#[tokio::test]
async fn fixed_axis_work_in_a_tilted_plane_on_request() {
    let base = server(cfg()).await;
    let c = reqwest::Client::new();
    let cl = "UNITS/MM\nLOADTL/1\nSPINDL/RPM,3000\nRAPID\nGOTO/10,-20,40,0,-0.5,0.8660254\nFEDRAT/MMPM,300\n\
              GOTO/10,-5,14.019,0,-0.5,0.8660254\nGOTO/30,-5,14.019,0,-0.5,0.8660254\nRAPID\n\
              GOTO/30,-20,40,0,-0.5,0.8660254\nFINI\n";
    let post = |q: &'static str| {
        c.post(format!("{base}/v1/post?machine=spinner-u5-620{q}"))
            .header("content-type", "text/plain")
            .body(cl)
    };
    let nc = post("&planes=tilted").text_ok().await;
    assert!(
        nc.contains("\nG68.2 X0 Y0 Z0 I") && nc.contains("\nG53.1\n") && nc.contains("\nG69\n"),
        "{nc}"
    );
    let nc = post("&planes=tilted&dialect=heidenhain").text_ok().await;
    assert!(nc.contains(" PLANE SPATIAL SPA") && nc.contains(" PLANE RESET STAY"), "{nc}");
    let nc = post("").text_ok().await;
    assert!(!nc.contains("G68.2"), "5-axis positioning by default: {nc}");
    assert_eq!(post("&planes=sideways").status_ok().await, 400);
    let d = c.get(format!("{base}/v1/dialects")).json_ok().await;
    assert!(d[0]["tilted_planes"].as_str().unwrap().contains("G68.2"), "{d}");
}

#[tokio::test]
async fn errors_before_the_first_byte_have_their_status() {
    let base = server(Config {
        max_upload: 2000,
        ..cfg()
    })
    .await;
    let c = reqwest::Client::new();
    let post = |q: &str, ct: &str, body: &'static str| {
        c.post(format!("{base}/v1/post{q}"))
            .header("content-type", ct.to_string())
            .body(body)
            .send()
    };
    let status = |r: reqwest::Response| r.status().as_u16();
    assert_eq!(
        status(post("", "text/plain", "GOTO/1,2,3").await.unwrap()),
        400,
        "machine missing"
    );
    assert_eq!(status(post("?machine=nope", "text/plain", "GOTO/1,2,3").await.unwrap()), 404);
    assert_eq!(
        status(post("?machine=vmc-3axis", "application/json", "{}").await.unwrap()),
        415
    );
    assert_eq!(
        status(
            post("?machine=vmc-3axis&mode=sideways", "text/plain", "GOTO/1,2,3")
                .await
                .unwrap()
        ),
        400
    );
    assert_eq!(
        status(
            post("?machine=vmc-3axis&colour=red", "text/plain", "GOTO/1,2,3")
                .await
                .unwrap()
        ),
        400,
        "unknown parameter"
    );
    let r = c
        .post(format!("{base}/v1/post?machine=vmc-3axis"))
        .header("accept", "image/png")
        .body("GOTO/1,2,3")
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 406);
    let r = post(
        "?machine=vmc-3axis&strict=true",
        "text/plain",
        "UNITS/MM\nGOTO/1,2,3\nGOTO/1,x,3\n",
    )
    .await
    .unwrap();
    assert_eq!(r.status(), 422);
    let p: Value = r.json().await.unwrap();
    assert_eq!((p["line"].as_u64(), p["column"].as_u64()), (Some(3), Some(8)), "{p}");
    let big = "GOTO/1,2,3\n".repeat(300);
    let r = c
        .post(format!("{base}/v1/post?machine=vmc-3axis"))
        .header("content-type", "text/plain")
        .body(big)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 413);
    // It names the limit it hit, never "a limit of 0 bytes".
    let p: Value = r.json().await.unwrap();
    let detail = p["detail"].as_str().unwrap();
    assert!(detail.contains("limit of") && !detail.contains(" 0 bytes"), "{p}");
}

/// An NC program uploaded where CL is meant: 422 with a problem document naming what it looks
/// like and the line, in text and NDJSON alike; a job of it fails with the reason.
#[tokio::test]
async fn g_code_given_as_cl_is_refused_with_422() {
    let base = server(cfg()).await;
    let c = reqwest::Client::new();
    let nc = "%\nO1000\nG21 G90\nG0 X10 Y20 Z30\nG1 Z5 F500\nM30\n%\n";
    for accept in ["text/plain", "application/x-ndjson"] {
        let r = c
            .post(format!("{base}/v1/post?machine=vmc-3axis"))
            .header("content-type", "text/plain")
            .header("accept", accept)
            .body(nc)
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 422, "{accept}");
        assert_eq!(r.headers()["content-type"], "application/problem+json");
        let p: Value = r.json().await.unwrap();
        assert_eq!(p["type"], "https://kinepost.dev/problems/not-cl-data", "{p}");
        assert_eq!((p["code"].as_str(), p["line"].as_u64()), (Some("not_cl"), Some(2)), "{p}");
        assert!(p["detail"].as_str().unwrap().starts_with("this looks like G-code"), "{p}");
    }
    let r = c
        .post(format!("{base}/v1/jobs?machine=vmc-3axis"))
        .header("content-type", "text/plain")
        .body(nc)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 202);
    let id = r.json::<Value>().await.unwrap()["id"].as_str().unwrap().to_string();
    let j = common::wait_finished(&c, &base, &id, std::time::Duration::from_secs(60)).await;
    assert_eq!(j["state"], "failed", "{j}");
    assert!(j["error"].as_str().unwrap().contains("looks like G-code"), "{j}");
}

/// A lathe's program is its own problem (`turning`, saying kinepost posts milling), not "Not CL
/// data": the file is CL, the machine is the wrong kind. A job of it fails with that reason.
#[tokio::test]
async fn a_turning_program_is_refused_as_turning() {
    let base = server(cfg()).await;
    let c = reqwest::Client::new();
    let cl = "UNITS/MM\nMODE/TURN\nLOADTL/1\nFEDRAT/0.1,MMPR\nGOTO/17,0,2\nGOTO/17,0,-190\n";
    for accept in ["text/plain", "application/x-ndjson"] {
        let r = c
            .post(format!("{base}/v1/post?machine=vmc-3axis"))
            .header("content-type", "text/plain")
            .header("accept", accept)
            .body(cl)
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 422, "{accept}");
        let p: Value = r.json().await.unwrap();
        assert_eq!(p["type"], "https://kinepost.dev/problems/turning", "{p}");
        assert!(p["title"].as_str().unwrap().contains("kinepost posts milling"), "{p}");
        assert_eq!((p["code"].as_str(), p["line"].as_u64()), (Some("turning"), Some(2)), "{p}");
    }
    let r = c
        .post(format!("{base}/v1/jobs?machine=vmc-3axis"))
        .header("content-type", "text/plain")
        .body(cl)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 202);
    let id = r.json::<Value>().await.unwrap()["id"].as_str().unwrap().to_string();
    let j = common::wait_finished(&c, &base, &id, std::time::Duration::from_secs(60)).await;
    assert_eq!(j["state"], "failed", "{j}");
    assert!(j["error"].as_str().unwrap().contains("kinepost posts milling"), "{j}");
}

#[tokio::test]
async fn nc_bytes_arrive_before_the_upload_completes() {
    let base = server(cfg()).await;
    // A long upload sent in two halves: the second only after NC bytes have come back.
    let mut cl = String::from("UNITS/MM\nFEDRAT/500,MMPM\n");
    for i in 0..4000 {
        cl.push_str(&format!(
            "GOTO/{:.3},{:.3},10\n",
            (i as f64 * 0.01).sin() * 50.0,
            i as f64 * 0.01
        ));
    }
    let (first, second) = cl.split_at(cl.len() / 2);
    let (first, second) = (first.to_string(), second.to_string());
    let (tx, rx) = tokio::sync::mpsc::channel::<Result<String, std::io::Error>>(2);
    let (got_tx, mut got_rx) = tokio::sync::mpsc::channel::<()>(1);
    tokio::spawn(async move {
        tx.send(Ok(first)).await.unwrap();
        // Hold the rest until the client has seen output.
        tokio::time::timeout(Duration::from_secs(10), got_rx.recv())
            .await
            .expect("NC arrived while the upload was open");
        tx.send(Ok(second)).await.unwrap();
    });
    let stream = futures_util::stream::unfold(rx, |mut rx| async move { rx.recv().await.map(|x| (x, rx)) });
    let mut r = reqwest::Client::new()
        .post(format!("{base}/v1/post?machine=vmc-3axis"))
        .header("content-type", "text/plain")
        .body(reqwest::Body::wrap_stream(stream))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    let mut text = String::new();
    let mut signalled = false;
    while let Some(chunk) = r.chunk().await.unwrap() {
        text.push_str(std::str::from_utf8(&chunk).unwrap());
        if !signalled {
            got_tx.send(()).await.unwrap();
            signalled = true;
        }
    }
    assert!(text.trim_end().ends_with("M30\n%"));
    // All 4000 points made it: the second half was released only after NC output had arrived,
    // so the program streamed while the upload was still open.
    let motions = text.lines().filter(|l| l.contains('X') || l.contains('Y')).count();
    assert!(motions > 3000, "{motions} motion blocks");
}

#[tokio::test]
async fn an_error_after_streaming_began_ends_the_program_explicitly() {
    let base = server(cfg()).await;
    // Enough good points to start the stream (> 16 KiB of NC), then a bad record in strict mode.
    let mut cl = String::from("UNITS/MM\nFEDRAT/500,MMPM\n");
    for i in 0..3000 {
        cl.push_str(&format!(
            "GOTO/{:.3},{:.3},10\n",
            (i as f64 * 0.01).sin() * 50.0,
            i as f64 * 0.01
        ));
    }
    cl.push_str("GOTO/1,oops,3\nGOTO/1,2,3\n");
    let r = reqwest::Client::new()
        .post(format!("{base}/v1/post?machine=vmc-3axis&strict=true"))
        .header("content-type", "text/plain")
        .body(cl.clone())
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200, "streaming had begun");
    let text = r.text().await.unwrap();
    let last = text.trim_end().lines().last().unwrap();
    assert!(last.starts_with("(ERROR:") && last.contains("LINE 3003"), "{last}");
    assert!(!text.contains("M30"), "a failed program never ends as if complete");
    let r = reqwest::Client::new()
        .post(format!("{base}/v1/post?machine=vmc-3axis&strict=true"))
        .header("content-type", "text/plain")
        .header("accept", "application/x-ndjson")
        .body(cl)
        .send()
        .await
        .unwrap();
    let text = r.text().await.unwrap();
    let last: Value = serde_json::from_str(text.trim_end().lines().last().unwrap()).unwrap();
    assert_eq!(last["type"], "error");
    assert_eq!(last["error"]["line"], 3003);
}

#[tokio::test]
async fn busy_cors_gzip_and_the_web_page() {
    let base = server(Config {
        max_streams: 0,
        cors_origins: vec!["https://cam.example".into()],
        ..cfg()
    })
    .await;
    let c = reqwest::Client::new();
    let r = c
        .post(format!("{base}/v1/post?machine=vmc-3axis"))
        .header("content-type", "text/plain")
        .body("GOTO/1,2,3")
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 503);
    assert_eq!(r.headers()["retry-after"], "5");
    let r = c
        .get(format!("{base}/v1/machines"))
        .header("origin", "https://cam.example")
        .header("accept-encoding", "gzip")
        .send()
        .await
        .unwrap();
    assert_eq!(r.headers()["access-control-allow-origin"], "https://cam.example");
    assert_eq!(
        r.headers()["content-encoding"],
        "gzip",
        "non-streaming responses are compressed"
    );
    let r = c
        .get(format!("{base}/v1/machines"))
        .header("origin", "https://evil.example")
        .send()
        .await
        .unwrap();
    assert!(!r.headers().contains_key("access-control-allow-origin"));
    let page = c.get(format!("{base}/")).send().await.unwrap();
    assert!(page.headers()["content-type"].to_str().unwrap().starts_with("text/html"));
    let html = page.text().await.unwrap();
    assert!(html.contains("/static/app.js"));
    assert_eq!(c.get(format!("{base}/static/app.js")).send().await.unwrap().status(), 200);
    // Every module the page imports is served here, as JavaScript: nothing from the internet.
    let map_start = html.find(r#"<script type="importmap">"#).expect("import map") + 25;
    let map_end = map_start + html[map_start..].find("</script>").unwrap();
    let map: serde_json::Value = serde_json::from_str(&html[map_start..map_end]).unwrap();
    let mut urls: Vec<String> = map["imports"]
        .as_object()
        .unwrap()
        .values()
        .map(|v| v.as_str().unwrap().to_string())
        .collect();
    urls.extend(
        [
            "/static/view.js",
            "/static/kin.js",
            "/static/machine3d.js",
            "/static/simulate.js",
            "/static/check.js",
            "/static/vendor/three/three.core.js",
            "/static/vendor/three/LICENSE",
        ]
        .map(String::from),
    );
    for u in &urls {
        assert!(u.starts_with("/static/"), "{u}");
        let r = c.get(format!("{base}{u}")).send().await.unwrap();
        assert_eq!(r.status(), 200, "{u}");
        let ct = r.headers()["content-type"].to_str().unwrap().to_string();
        let body = r.text().await.unwrap();
        assert!(
            u.ends_with("LICENSE") && body.contains("MIT License") || ct.starts_with("text/javascript"),
            "{u}: {ct}"
        );
    }
    assert!(!html.contains("http://") && !html.contains("https://"));
    // The machine check page, linked from the form, loads the same modules.
    assert!(html.contains("/machine-check.html"));
    let check = c.get(format!("{base}/machine-check.html")).send().await.unwrap();
    assert!(check.headers()["content-type"].to_str().unwrap().starts_with("text/html"));
    let check = check.text().await.unwrap();
    assert!(check.contains("/static/check.js") && check.contains(r#"<script type="importmap">"#));
    assert!(!check.contains("http://") && !check.contains("https://"));
    assert_eq!(
        c.get(format!("{base}/static/secret.toml")).send().await.unwrap().status(),
        404
    );
}

#[tokio::test]
async fn fk_ik_reachability_and_fits_over_http() {
    let base = server(cfg()).await;
    let c = reqwest::Client::new();
    // A JSON body over the limit is too large (413), not a bad parameter (it was 400).
    let huge = format!("{{\"joints\": {{\"X\": 1}}, \"pad\": \"{}\"}}", "x".repeat(3 << 20));
    let r = c
        .post(format!("{base}/v1/machines/spinner-u5-620/fk"))
        .header("content-type", "application/json")
        .body(huge)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 413);
    let post = |path: String, body: Value| c.post(format!("{base}{path}")).json(&body).send();
    // FK then IK: the words come back among the solutions.
    let pose: Value = post(
        "/v1/machines/spinner-u5-620/fk".into(),
        serde_json::json!({"joints": {"X": 10, "Y": 20, "Z": 30, "B": 30, "C": 45}}),
    )
    .await
    .unwrap()
    .json()
    .await
    .unwrap();
    let ik: Value = post(
        "/v1/machines/spinner-u5-620/ik".into(),
        serde_json::json!({"tip": pose["tip"], "axis": pose["axis"]}),
    )
    .await
    .unwrap()
    .json()
    .await
    .unwrap();
    assert!(
        ik["solutions"]
            .as_array()
            .unwrap()
            .iter()
            .any(|s| (s["B"].as_f64().unwrap() - 30.0).abs() < 1e-9 && (s["C"].as_f64().unwrap() - 45.0).abs() < 1e-9)
    );
    // Reachability: a tilted tool on a 3-axis machine misses by its tilt.
    let v: Value = post(
        "/v1/machines/vmc-3axis/validate-pose".into(),
        serde_json::json!({"tip": [0, 0, 0], "axis": [0, 0.5, 0.8660254037844386]}),
    )
    .await
    .unwrap()
    .json()
    .await
    .unwrap();
    assert_eq!(v["reachable"], false);
    assert!((v["miss_deg"].as_f64().unwrap() - 30.0).abs() < 1e-6);
    let r = post(
        "/v1/machines/spinner-u5-620/fk".into(),
        serde_json::json!({"joints": {"Q": 1}}),
    )
    .await
    .unwrap();
    assert_eq!(r.status(), 400);
    // Angle error: the HTM50200 paper's polynomial back from its samples, as a profile to apply.
    let paper = [0.1808, -2.95e-2, 2.3e-3, -7e-5, -8e-7];
    let samples: Vec<[f64; 2]> = (0..=40)
        .map(|t| [t as f64, paper.iter().rev().fold(0.0, |a, k| a * t as f64 + k)])
        .collect();
    let fit: Value = post(
        "/v1/machines/htm50200-horizontal/angle-error-fit".into(),
        serde_json::json!({"axis": "B", "samples": samples}),
    )
    .await
    .unwrap()
    .json()
    .await
    .unwrap();
    assert_eq!(fit["proposed"]["degree"], 4);
    assert_eq!(fit["fits"].as_array().unwrap().len(), 4);
    let toml_text = fit["proposed_profile"].as_str().unwrap();
    let prof = kinepost::machines::parse_profile(toml_text, "proposed", Some("htm50200-horizontal"))
        .expect("the proposal is a valid profile");
    assert!(prof.machine.rotaries.iter().any(|r| r.angle_error.is_some()));
    // Calibration: a machine whose A pivot sits 0.003 in off in y: recovered from test cuts.
    let lib = common::library();
    let nominal = lib.get("fryer-5x-45").unwrap();
    let shifted = std::fs::read_to_string(cfg().machines.join("fryer-5x-45.toml"))
        .unwrap()
        .replace("pivot = [-0.002, -0.001, 5.0]", "pivot = [-0.002, 0.002, 5.0]");
    let truth = kinepost::machines::parse_profile(&shifted, "truth", None).unwrap();
    let setup = kinepost::kinematics::Setup::new(3.0, kinepost::kinematics::Vec3::zeros());
    let mut meas = Vec::new();
    for cdeg in [0.0, 90.0, 180.0, -90.0] {
        for adeg in [0.0, 45.0, 90.0] {
            let words = serde_json::json!({"X": 1.0, "Y": -0.5, "Z": -2.0, "A": adeg, "C": cdeg});
            let mut j = kinepost::kinematics::Joints {
                linear: [1.0, -0.5, -2.0],
                ..Default::default()
            };
            j.rotary[nominal.machine.rotary_index('A').unwrap()] = f64::to_radians(adeg);
            j.rotary[nominal.machine.rotary_index('C').unwrap()] = f64::to_radians(cdeg);
            let d = kinepost::calib::simulated_deviation(&nominal.machine, &truth.machine, &setup, &j);
            meas.push(serde_json::json!({"joints": words, "deviation": [d.x, d.y, d.z]}));
        }
    }
    let cal: Value = post(
        "/v1/machines/fryer-5x-45/calibrate".into(),
        serde_json::json!({"measurements": meas, "tool_length": 3.0}),
    )
    .await
    .unwrap()
    .json()
    .await
    .unwrap();
    assert!(
        cal["rms"].as_f64().unwrap() < 1e-9 && cal["rms_before"].as_f64().unwrap() > 1e-3,
        "{cal}"
    );
    assert!(
        (cal["offsets"]["A"][1].as_f64().unwrap() - 0.003).abs() < 1e-8,
        "{}",
        cal["offsets"]
    );
    assert!(cal["proposed_profile"].as_str().unwrap().contains("0.002"));
}

/// A post over the server's budget (blocks per CL byte beyond a floor) ends where the bound
/// falls, saying so in each form: the NDJSON stream's error record, the text's error comment
/// without a program end, and a job that fails with the reason.
#[tokio::test]
async fn a_post_over_the_servers_budget_ends_saying_so() {
    let budget = kinepost::post::Budget {
        floor_blocks: 300,
        blocks_per_byte: 0,
        seconds: f64::INFINITY,
    };
    let base = server(Config { post_budget: budget, ..cfg() }).await;
    let c = reqwest::Client::new();
    let cl = common::generated("spinner-u5-620", 2000, 3);
    let post = |accept: &'static str| {
        c.post(format!("{base}/v1/post?machine=spinner-u5-620"))
            .header("content-type", "text/plain")
            .header("accept", accept)
            .body(cl.clone())
            .send()
    };
    let nd = post("application/x-ndjson").await.unwrap().text().await.unwrap();
    let last: serde_json::Value = serde_json::from_str(nd.lines().last().unwrap()).unwrap();
    assert_eq!(last["error"]["code"], "over_budget", "{last}");
    assert!(last["error"]["detail"].as_str().unwrap().contains("output bound"), "{last}");
    assert!(nd.lines().count() < 700, "stopped near the bound: {} records", nd.lines().count());
    let text = post("text/plain").await.unwrap().text().await.unwrap();
    assert!(text.trim_end().ends_with(')') && text.contains("(ERROR: OUTPUT BOUND"), "{text}");
    assert!(!text.contains("M30"), "no program end after the bound");
    let r = c
        .post(format!("{base}/v1/jobs?machine=spinner-u5-620"))
        .header("content-type", "text/plain")
        .body(cl.clone())
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 202);
    let id = r.json::<serde_json::Value>().await.unwrap()["id"].as_str().unwrap().to_string();
    let j = common::wait_finished(&c, &base, &id, std::time::Duration::from_secs(60)).await;
    assert_eq!(j["state"], "failed", "{j}");
    assert!(j["error"].as_str().unwrap().contains("output bound"), "{j}");
}

/// A request over `--request-timeout` is 408 with a problem document naming the limit, as every
/// error (it was an empty body): here a JSON body that never ends.
#[tokio::test]
async fn a_request_over_its_time_is_a_problem_document() {
    use futures_util::StreamExt;
    let base = server(Config {
        request_timeout: Duration::from_millis(300),
        ..cfg()
    })
    .await;
    let body = futures_util::stream::once(async { Ok::<_, std::io::Error>(bytes::Bytes::from_static(b"{")) })
        .chain(futures_util::stream::pending());
    let r = reqwest::Client::new()
        .post(format!("{base}/v1/machines/spinner-u5-620/fk"))
        .header("content-type", "application/json")
        .body(reqwest::Body::wrap_stream(body))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 408);
    assert_eq!(r.headers()["content-type"], "application/problem+json");
    let p: Value = r.json().await.unwrap();
    assert!(p["detail"].as_str().unwrap().contains("--request-timeout"), "{p}");
}

/// The collision check's fields: validated where every post option is, a bad one a 400 naming it.
#[tokio::test]
async fn collision_fields_are_taken_and_checked() {
    let base = server(cfg()).await;
    let c = reqwest::Client::new();
    let cl = "UNITS/MM\nLOADTL/1\nSPINDL/1000\nGOTO/10,20,30,0,0,1\nFINI\n";
    let post = |q: &str| {
        c.post(format!("{base}/v1/post?machine=vmc-3axis{q}"))
            .header("content-type", "text/plain")
            .body(cl)
    };
    let nc = post("&stock=0,0,0,50,50,20&collision_clearance=3&collisions=on").text_ok().await;
    assert!(nc.contains("M30"), "{nc}");
    post("&collisions=off").text_ok().await;
    for (q, key) in [("&collisions=maybe", "collisions"), ("&stock=1,2,3", "stock"), ("&collision_clearance=-1", "collision_clearance")] {
        let r = post(q).send().await.unwrap();
        assert_eq!(r.status(), 400, "{q}");
        assert!(r.text().await.unwrap().contains(key), "{q}");
    }
}

/// The shelves' routes (profiles, tool tables, dialects), the machine computations and the
/// uploads: each refusal provoked, and each status the route answers is one its OpenAPI
/// responses list. (Debug builds also check every refusal of every test as it is answered.)
#[tokio::test]
async fn every_refusal_a_route_answers_is_documented_for_it() {
    let doc: Value = serde_json::from_str(&openapi_json()).unwrap();
    const TOKEN: &str = "documented-admin";
    let base = server(Config {
        admin_token: Some(TOKEN.into()),
        ..cfg()
    })
    .await;
    let off = server(cfg()).await;
    let c = reqwest::Client::new();
    let profile = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/machines/vmc-3axis.toml")).unwrap();
    let spare = profile.replace("id = \"vmc-3axis\"", "id = \"spare\"");
    let table = "units = \"mm\"\n[[tool]]\nnumber = 1\nlength = 100.0\n";
    let dialect = "id = \"shop\"\nextends = \"fanuc\"\n";
    let bad = "id = \"spare\"\nthis is = [ not toml";
    let big = "#".repeat((1 << 20) + 1);
    let auth = format!("Bearer {TOKEN}");
    // (method, the route as documented, the request's path, Authorization, If-Match, content type, body, the status)
    type Case<'a> = (&'a str, String, String, Option<&'a str>, Option<&'a [u8]>, &'a str, String, u16);
    let a = Some(auth.as_str());
    let mut cases: Vec<Case> = Vec::new();
    for (one, id, create, body, kind) in [
        ("/v1/machines/{id}", "vmc-3axis", Some("/v1/machines"), spare.clone(), "machine"),
        ("/v1/machines/{id}/tools", "vmc-3axis", None, table.to_string(), "tools"),
        ("/v1/dialects/{id}", "fanuc", Some("/v1/dialects"), dialect.to_string(), "dialect"),
    ] {
        let at = |id: &str| one.replace("{id}", id);
        let toml = "application/toml";
        cases.extend([
            ("get", one.to_string(), at("nope"), None, None, toml, String::new(), 404),
            ("get", format!("{one}/versions"), at("nope") + "/versions", None, None, toml, String::new(), 404),
            ("get", format!("{one}/versions/{{version}}"), at(id) + "/versions/x", None, None, toml, String::new(), 404),
            ("get", format!("{one}/versions/{{version}}"), at(id) + "/versions/99", None, None, toml, String::new(), 404),
            ("put", one.to_string(), at(id), None, None, toml, body.clone(), 401),
            ("put", one.to_string(), at(id), Some("Bearer not-the-token"), None, toml, body.clone(), 401),
            ("delete", one.to_string(), at(id), None, None, toml, String::new(), 401),
            ("delete", one.to_string(), at(id), Some("Bearer not-the-token"), None, toml, String::new(), 401),
            ("put", one.to_string(), at(id), a, Some(b"\"nope-v1\"".as_slice()), toml, body.clone(), 412),
            ("put", one.to_string(), at(id), a, Some(b"\xff".as_slice()), toml, body.clone(), 400),
            ("put", one.to_string(), at(id), a, None, "image/png", body.clone(), 415),
            ("put", one.to_string(), at(id), a, None, toml, big.clone(), 413),
            ("put", one.to_string(), at(id), a, None, toml, bad.to_string(), 422),
            ("delete", one.to_string(), at(id), a, Some(b"\"nope-v1\"".as_slice()), toml, String::new(), 412),
            ("delete", one.to_string(), at(id), a, Some(b"\xff".as_slice()), toml, String::new(), 400),
            ("delete", one.to_string(), at("nope"), a, None, toml, String::new(), 404),
        ]);
        if kind == "tools" {
            // A table for no machine, and a machine without a table.
            cases.push(("put", one.to_string(), at("nope"), a, None, toml, body.clone(), 404));
            cases.push(("get", one.to_string(), at(id), None, None, toml, String::new(), 404));
            cases.push(("delete", one.to_string(), at(id), a, None, toml, String::new(), 404));
        }
        if let Some(create) = create {
            cases.extend([
                ("post", create.to_string(), create.to_string(), None, None, toml, body.clone(), 401),
                ("post", create.to_string(), create.to_string(), a, None, "text/html", body.clone(), 415),
                ("post", create.to_string(), create.to_string(), a, None, toml, big.clone(), 413),
                ("post", create.to_string(), create.to_string(), a, None, toml, bad.to_string(), 422),
                ("post", create.to_string(), create.to_string(), a, None, toml, body.clone(), 201),
                ("post", create.to_string(), create.to_string(), a, None, toml, body.clone(), 409),
            ]);
        }
    }
    for op in ["fk", "ik", "validate-pose", "angle-error-fit", "calibrate"] {
        let route = format!("/v1/machines/{{id}}/{op}");
        let json = "application/json";
        cases.extend([
            ("post", route.clone(), format!("/v1/machines/vmc-3axis/{op}"), None, None, "text/plain", "{}".to_string(), 415),
            ("post", route.clone(), format!("/v1/machines/vmc-3axis/{op}"), None, None, json, "{".to_string(), 400),
        ]);
    }
    let fk = r#"{"joints": {"X": 0}}"#.to_string();
    cases.push(("post", "/v1/machines/{id}/fk".to_string(), "/v1/machines/nope/fk".into(), None, None, "application/json", fk, 404));
    let unreachable = r#"{"tip": [0, 0, 0], "axis": [1, 0, 0]}"#.to_string();
    cases.push(("post", "/v1/machines/{id}/ik".to_string(), "/v1/machines/vmc-3axis/ik".into(), None, None, "application/json", unreachable, 422));
    for route in ["/v1/post", "/v1/jobs"] {
        cases.extend([
            ("post", route.to_string(), format!("{route}?machine=nope"), None, None, "text/plain", "GOTO/1,2,3".to_string(), 404),
            ("post", route.to_string(), format!("{route}?machine=vmc-3axis&colour=red"), None, None, "text/plain", "GOTO/1,2,3".to_string(), 400),
            ("post", route.to_string(), format!("{route}?machine=vmc-3axis"), None, None, "application/json", "{}".to_string(), 415),
        ]);
    }
    let mut seen = std::collections::BTreeMap::<String, std::collections::BTreeSet<u16>>::new();
    for (method, route, path, authorization, if_match, ctype, body, want) in cases {
        let method_ = reqwest::Method::from_bytes(method.to_ascii_uppercase().as_bytes()).unwrap();
        let mut rq = c.request(method_, format!("{base}{path}")).header("content-type", ctype).body(body.clone());
        if let Some(v) = authorization {
            rq = rq.header("authorization", v);
        }
        if let Some(v) = if_match {
            rq = rq.header("if-match", reqwest::header::HeaderValue::from_bytes(v).unwrap());
        }
        let got = rq.send().await.unwrap().status().as_u16();
        assert_eq!(got, want, "{method} {path}");
        if got >= 400 {
            let listed = &doc["paths"][&route][method]["responses"];
            assert!(listed.is_object(), "{method} {route} is documented");
            assert!(listed[got.to_string()].is_object(), "{method} {route} answers {got}, which its OpenAPI responses do not list: {listed}");
            seen.entry(format!("{method} {route}")).or_default().insert(got);
        }
    }
    // Writes with no admin token configured are off.
    const WRITES: [(&str, &str); 8] = [
        ("post", "/v1/machines"),
        ("put", "/v1/machines/{id}"),
        ("delete", "/v1/machines/{id}"),
        ("put", "/v1/machines/{id}/tools"),
        ("delete", "/v1/machines/{id}/tools"),
        ("post", "/v1/dialects"),
        ("put", "/v1/dialects/{id}"),
        ("delete", "/v1/dialects/{id}"),
    ];
    for (method, route) in WRITES {
        let path = route.replace("{id}", if route.starts_with("/v1/dialects") { "fanuc" } else { "vmc-3axis" });
        let m = reqwest::Method::from_bytes(method.to_ascii_uppercase().as_bytes()).unwrap();
        let got = c
            .request(m, format!("{off}{path}"))
            .header("authorization", "Bearer anything")
            .header("content-type", "application/toml")
            .body(table)
            .send()
            .await
            .unwrap()
            .status()
            .as_u16();
        assert_eq!(got, 403, "{method} {path} with writes off");
        assert!(doc["paths"][route][method]["responses"]["403"].is_object(), "{method} {route} lists 403");
        seen.entry(format!("{method} {route}")).or_default().insert(got);
    }
    // Every write of the three shelves was refused for its token both ways, its version or id,
    // and (with a body) its document; every read for what is not there.
    for (method, route) in WRITES {
        let want: &[u16] = match method {
            "post" => &[401, 403, 409, 413, 415, 422],
            "put" => &[400, 401, 403, 412, 413, 415, 422],
            _ => &[400, 401, 403, 404, 412],
        };
        let got = &seen[&format!("{method} {route}")];
        assert!(want.iter().all(|s| got.contains(s)), "{method} {route}: {got:?}");
    }
    assert_eq!(seen.keys().filter(|r| r.starts_with("get")).count(), 9, "{seen:?}");
}

/// Every post option is taken by the CLI, the query and the form alike, and each gives the same
/// program. The options are listed from their one definition (`post::Settings`), so an option
/// added there without a sample here fails, and so does one an edge does not take.
#[tokio::test]
async fn every_post_option_is_taken_by_the_cli_the_query_and_the_form_alike() {
    const MACHINE: &str = "haas-umc750";
    let samples: &[(&str, &str)] = &[
        ("dialect", "fanuc"),
        ("mode", "tcp"),
        ("tool_length", "4"),
        ("tool_table", "units = \"inch\"\n[[tool]]\nnumber = 1\nlength = 4.5\n"),
        ("work_offset", "0.1,0.1,0.1"),
        ("tolerance", "0.001"),
        ("sequence_numbers", "true"),
        ("program_number", "1234"),
        ("strict", "true"),
        ("singular_tolerance", "0.5"),
        ("cl_units", "inch"),
        ("cycles", "canned"),
        ("planes", "tilted"),
        ("work_coordinates", "G55"),
        ("setups", "work-offsets"),
        ("spindle_speed", "5000"),
        ("retract", "axis:1"),
        ("prefer", "B-"),
        ("feed_mode", "combined"),
        ("unwind", "rapids"),
        ("preselect", "off"),
        ("smoothing", "finish"),
        ("collisions", "off"),
        ("collision_clearance", "0.05"),
        ("stock", "-5,-5,-5,5,5,5"),
        ("fixtures", "20,20,0,21,21,1;-21,-21,0,-20,-20,1"),
    ];
    let Value::Object(defined) = serde_json::to_value(kinepost::post::Settings::default()).unwrap() else {
        panic!("the post options serialize as an object");
    };
    for name in defined.keys().filter(|k| *k != "machine") {
        assert!(samples.iter().any(|(k, _)| k == name), "post option {name}: give it a sample here");
    }
    let base = server(cfg()).await;
    let c = reqwest::Client::new();
    let dir = std::env::temp_dir().join(format!("kinepost-options-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let cl_path = dir.join("path.cls");
    let cl = common::generated(MACHINE, 40, 3);
    std::fs::write(&cl_path, &cl).unwrap();
    // What two runs of the same program share: the words, not the comments naming the run.
    let words = |nc: &str| -> Vec<String> {
        common::body_lines(nc).into_iter().filter(|l| !l.starts_with('(')).map(str::to_string).collect()
    };
    let plain = words(
        &c.post(format!("{base}/v1/post?machine={MACHINE}"))
            .header("content-type", "text/plain")
            .body(cl.clone())
            .text_ok()
            .await,
    );
    let mut unchanged = Vec::new();
    for (name, value) in samples {
        let flag = format!("--{}", name.replace('_', "-"));
        let out = dir.join("out.nc");
        let mut cli = std::process::Command::new(env!("CARGO_BIN_EXE_kinepost"));
        cli.args(["post", "--machine", MACHINE, "-o"]).arg(&out);
        match *name {
            "tool_table" => {
                let table = dir.join("tools.toml");
                std::fs::write(&table, value).unwrap();
                cli.arg(&flag).arg(&table);
            }
            "sequence_numbers" | "strict" => {
                cli.arg(&flag);
            }
            _ => {
                cli.arg(&flag).arg(value);
            }
        }
        let run = cli.arg(&cl_path).output().unwrap();
        let stderr = String::from_utf8_lossy(&run.stderr);
        assert_ne!(run.status.code(), Some(2), "{flag} {value}: the CLI refused it: {stderr}");
        let by_cli = std::fs::read_to_string(&out).unwrap();
        let by_query = c
            .post(format!("{base}/v1/post?{}", serde_urlencoded::to_string([("machine", MACHINE), (name, value)]).unwrap()))
            .header("content-type", "text/plain")
            .body(cl.clone())
            .text_ok()
            .await;
        let mut form = String::new();
        for (k, v) in [("machine", MACHINE), (name, value)] {
            form += &format!("--XYZ\r\nContent-Disposition: form-data; name=\"{k}\"\r\n\r\n{v}\r\n");
        }
        form += &format!(
            "--XYZ\r\nContent-Disposition: form-data; name=\"file\"; filename=\"path.cls\"\r\nContent-Type: text/plain\r\n\r\n{}\r\n--XYZ--\r\n",
            String::from_utf8(cl.clone()).unwrap()
        );
        let by_form = c
            .post(format!("{base}/v1/post"))
            .header("content-type", "multipart/form-data; boundary=XYZ")
            .body(form)
            .text_ok()
            .await;
        assert_eq!(words(&by_query), words(&by_cli), "{name}={value}: the query's program is not the CLI's");
        assert_eq!(words(&by_form), words(&by_cli), "{name}={value}: the form's program is not the CLI's");
        if words(&by_cli) == plain {
            unchanged.push(*name);
        }
    }
    // A generated path has no holes, no second tool, no rapids to unwind at: those options leave
    // it as it was. The rest must each have written another program, the same by every edge.
    assert!(unchanged.len() <= 14, "options that changed nothing: {unchanged:?}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// A setting refused names its field in the problem document, as the query and the form give it.
#[tokio::test]
async fn a_refused_setting_is_named_in_the_problem() {
    let base = server(cfg()).await;
    let c = reqwest::Client::new();
    let r = c
        .post(format!("{base}/v1/post?machine=haas-umc750&unwind=never"))
        .header("content-type", "text/plain")
        .body("UNITS/MM\nGOTO/0,0,0\nFINI\n")
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 400);
    let p: Value = r.json().await.unwrap();
    assert_eq!(p["field"], "unwind", "{p}");
    assert!(p["detail"].as_str().unwrap().contains("never"), "{p}");
    let form = "--XYZ\r\nContent-Disposition: form-data; name=\"machine\"\r\n\r\nhaas-umc750\r\n--XYZ\r\nContent-Disposition: form-data; name=\"feed_mode\"\r\n\r\nslow\r\n--XYZ\r\nContent-Disposition: form-data; name=\"file\"; filename=\"a.cls\"\r\nContent-Type: text/plain\r\n\r\nGOTO/0,0,0\r\n--XYZ--\r\n";
    let r = c
        .post(format!("{base}/v1/jobs"))
        .header("content-type", "multipart/form-data; boundary=XYZ")
        .body(form)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 400);
    let p: Value = r.json().await.unwrap();
    assert_eq!(p["field"], "feed_mode", "{p}");
    // An unknown field, in the query or the form, is refused.
    let r = c.post(format!("{base}/v1/post?machine=haas-umc750&feed=1")).body("GOTO/0,0,0\n").send().await.unwrap();
    assert_eq!(r.status(), 400);
    let form = form.replace("feed_mode", "feed");
    let r = c
        .post(format!("{base}/v1/post"))
        .header("content-type", "multipart/form-data; boundary=XYZ")
        .body(form)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 400);
    assert!(r.text().await.unwrap().contains("unknown form field"));
}
