//! A job's diagnostics, rebuilt from its compact block store as they stream, are byte for byte
//! the NDJSON `kinepost post --diagnostics` writes for the same CL and options (a real server,
//! the real binary); a failed job's are the CLI's plus the error record that ends them; a job run
//! by the version before the block store keeps its NDJSON file, served as it was.

use crate::common;

use common::{Fetch, data};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// A multipart job of a CL file under its own name, so that its header has as many lines as the
/// CLI's (`JOB`, `SOURCE` there; `DATE`, `SOURCE` here): sequence numbers agree.
async fn submit(c: &reqwest::Client, base: &str, path: &Path, query: &str) -> String {
    let name = path.file_name().unwrap().to_str().unwrap();
    let mut body = format!(
        "--XYZ\r\nContent-Disposition: form-data; name=\"file\"; filename=\"{name}\"\r\nContent-Type: text/plain\r\n\r\n"
    )
    .into_bytes();
    body.extend(std::fs::read(path).unwrap());
    body.extend(b"\r\n--XYZ--\r\n");
    let j: Value = c
        .post(format!("{base}/v1/jobs?{query}"))
        .header("content-type", "multipart/form-data; boundary=XYZ")
        .body(body)
        .json_ok()
        .await;
    j["id"].as_str().unwrap().to_string()
}

/// The CLI's NDJSON for the same file and options, and its exit code.
fn cli(input: &Path, args: &[&str], dir: &Path) -> (Vec<u8>, i32) {
    let nd = dir.join("cli.ndjson");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_kinepost"))
        .arg("post")
        .args(args)
        .arg(input)
        .arg("-o")
        .arg(dir.join("cli.nc"))
        .arg("--diagnostics")
        .arg(&nd)
        .output()
        .unwrap();
    (std::fs::read(&nd).unwrap(), out.status.code().unwrap_or(-1))
}

async fn body(c: &reqwest::Client, url: &str) -> Vec<u8> {
    let r = c.get(url).send().await.unwrap();
    assert_eq!(r.status(), 200, "{url}");
    r.bytes().await.unwrap().to_vec()
}

fn spool(cfg: &kinepost::http::Config) -> PathBuf {
    cfg.data_dir.join("spool")
}

/// (file, job query, CLI flags): warnings, errors by the thousand, three axes, TCP, Heidenhain.
const CASES: [(&str, &str, &[&str]); 5] = [
    (
        "nx_clsf_mech491_variable_axis_inch_5ax.cls",
        "machine=haas-umc750&sequence_numbers=true",
        &["--machine", "haas-umc750", "--sequence-numbers"],
    ),
    (
        // On a 3 in riser: at z = 0 on the platter its flat tool is a collision at every block.
        "nx_clsf_mech491_project2_inch_5ax.cls",
        "machine=haas-umc750&work_offset=0,0,3",
        &["--machine", "haas-umc750", "--work-offset", "0,0,3"],
    ),
    (
        "generated/near_singular_jitter.cls",
        "machine=spinner-u5-620&mode=tcp",
        &["--machine", "spinner-u5-620", "--mode", "tcp"],
    ),
    (
        // Another machine's points: out of travel on every block (its collisions not checked).
        "generated/htm_shuffled.cls",
        "machine=dmg-dmc75v&sequence_numbers=true&collisions=off",
        &["--machine", "dmg-dmc75v", "--sequence-numbers", "--collisions", "off"],
    ),
    (
        "creo8_ncl_profilfraesen_profile_mm.ncl",
        "machine=vmc-3axis",
        &["--machine", "vmc-3axis"],
    ),
];

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_jobs_diagnostics_are_the_clis_byte_for_byte() {
    let cfg = common::cfg();
    let base = common::server(cfg.clone()).await;
    let c = reqwest::Client::new();
    let dir = cfg.data_dir.join("cli");
    std::fs::create_dir_all(&dir).unwrap();
    for (file, query, args) in CASES {
        let id = submit(&c, &base, &data(file), query).await;
        let done = common::wait_job(&c, &base, &id, "succeeded", Duration::from_secs(120)).await;
        let served = body(&c, &format!("{base}/v1/jobs/{id}/diagnostics")).await;
        let (want, _) = cli(&data(file), args, &dir);
        assert!(
            served == want,
            "{file}: the job's diagnostics differ from the CLI's ({} and {} bytes)",
            served.len(),
            want.len()
        );
        // The store is a fraction of the NDJSON.
        let store = std::fs::metadata(spool(&cfg).join(format!("{id}.blocks"))).unwrap().len();
        let nc = done["progress"]["nc_bytes"].as_u64().unwrap();
        eprintln!("{file}: NC {nc} B, NDJSON {} B, block store {store} B", want.len());
        assert!(store * 2 < want.len() as u64, "{file}: store {store} B, NDJSON {} B", want.len());
        assert!(!spool(&cfg).join(format!("{id}.ndjson")).exists());
    }
}

/// The rebuilt body has a strong ETag (304 on If-None-Match); it is made as it streams, its
/// length unknown, so a Range gets the whole body (200, `Accept-Ranges: none`).
#[tokio::test]
async fn the_rebuilt_body_has_an_etag_and_answers_a_range_whole() {
    let cfg = common::cfg();
    let base = common::server(cfg.clone()).await;
    let c = reqwest::Client::new();
    let (file, query, _) = CASES[0];
    let id = submit(&c, &base, &data(file), query).await;
    common::wait_job(&c, &base, &id, "succeeded", Duration::from_secs(60)).await;
    let url = format!("{base}/v1/jobs/{id}/diagnostics");
    let r = c.get(&url).send().await.unwrap();
    let etag = r.headers()["etag"].to_str().unwrap().to_string();
    assert_eq!(r.headers()["content-type"], "application/x-ndjson");
    let whole = r.bytes().await.unwrap();
    let r = c.get(&url).header("if-none-match", &etag).send().await.unwrap();
    assert_eq!(r.status(), 304);
    let r = c.get(&url).header("range", "bytes=0-9").send().await.unwrap();
    assert_eq!(r.status(), 200);
    assert_eq!(r.headers()["accept-ranges"], "none");
    assert_eq!(r.bytes().await.unwrap(), whole);
}

/// A failed job's diagnostics are the CLI's up to where it stopped, then the error record (the
/// CLI puts its error in the program and on stderr instead); a cancelled job has none.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_failed_jobs_diagnostics_are_the_clis_and_its_error_a_cancelled_has_none() {
    let cfg = common::cfg();
    let base = common::server(cfg.clone()).await;
    let c = reqwest::Client::new();
    let dir = cfg.data_dir.join("cli");
    std::fs::create_dir_all(&dir).unwrap();
    // A bad record half way (past the reader's look-ahead): strict mode stops there.
    let cl = String::from_utf8(common::generated("spinner-u5-620", 10_000, 3)).unwrap();
    let mut lines: Vec<&str> = cl.lines().collect();
    lines.insert(lines.len() / 2, "GOTO/1,oops,3");
    let file = dir.join("broken.cls");
    std::fs::write(&file, lines.join("\n") + "\n").unwrap();
    let id = submit(&c, &base, &file, "machine=spinner-u5-620&strict=true").await;
    let failed = common::wait_job(&c, &base, &id, "failed", Duration::from_secs(60)).await;
    let served = body(&c, &format!("{base}/v1/jobs/{id}/diagnostics")).await;
    let (want, code) = cli(&file, &["--machine", "spinner-u5-620", "--strict"], &dir);
    assert!(want.len() > 100_000, "{} bytes before the error", want.len());
    assert_eq!(code, 2, "the CLI refuses it too");
    assert!(served.starts_with(&want), "the job's records before its error are the CLI's");
    let rest: Vec<&[u8]> = served[want.len()..].split_inclusive(|&b| b == b'\n').collect();
    assert_eq!(rest.len(), 1, "one record more: the error");
    let error: Value = serde_json::from_slice(rest[0]).unwrap();
    assert_eq!(error["type"], "error");
    assert_eq!(error["error"]["detail"], failed["error"]);
    assert!(error["error"]["line"].as_u64().is_some(), "{error}");
    // Its partial program is its diagnostics' text, never served as a program.
    assert_eq!(c.get(format!("{base}/v1/jobs/{id}/nc")).status_ok().await, 409);
    assert!(spool(&cfg).join(format!("{id}.nc.partial")).exists());
    assert!(!spool(&cfg).join(format!("{id}.nc")).exists());

    // Cancelled while queued: nothing to serve, nothing left in the spool but its input.
    let mut cfg2 = common::cfg();
    cfg2.workers = 0;
    let base2 = common::server(cfg2.clone()).await;
    let id = submit(&c, &base2, &data(CASES[1].0), CASES[1].1).await;
    assert_eq!(c.delete(format!("{base2}/v1/jobs/{id}")).status_ok().await, 200);
    assert_eq!(c.get(format!("{base2}/v1/jobs/{id}/diagnostics")).status_ok().await, 409);
    assert_eq!(common::spool_names(&spool(&cfg2)), vec![format!("{id}.cl")]);
}

/// A job directory written by the version before the block store has `<id>.ndjson` beside the
/// NC: after the upgrade it is served as it was, Range and ETag included; a failed job's file
/// cut short is mended after its last whole line.
#[tokio::test]
async fn a_job_run_before_the_block_store_is_served_from_its_ndjson() {
    let cfg = common::cfg();
    let base = common::server(cfg.clone()).await;
    let c = reqwest::Client::new();
    let dir = cfg.data_dir.join("cli");
    std::fs::create_dir_all(&dir).unwrap();
    let (file, query, args) = CASES[0];
    let id = submit(&c, &base, &data(file), query).await;
    common::wait_job(&c, &base, &id, "succeeded", Duration::from_secs(60)).await;
    // What the previous version left: its NDJSON (the CLI's bytes), no block store.
    let (old, _) = cli(&data(file), args, &dir);
    std::fs::write(spool(&cfg).join(format!("{id}.ndjson")), &old).unwrap();
    std::fs::remove_file(spool(&cfg).join(format!("{id}.blocks"))).unwrap();
    let url = format!("{base}/v1/jobs/{id}/diagnostics");
    let r = c.get(&url).send().await.unwrap();
    assert_eq!(r.headers()["etag"].to_str().unwrap(), format!("\"{id}-d-{}\"", old.len()));
    assert_eq!(r.bytes().await.unwrap(), old);
    let r = c.get(&url).header("range", "bytes=10-19").send().await.unwrap();
    assert_eq!(r.status(), 206);
    assert_eq!(r.bytes().await.unwrap(), old[10..20]);
}
