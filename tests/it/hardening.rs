//! What an attack on the service found (issue 30), each answered: connections that send nothing
//! or half a header, uploads that trickle, more streams than allowed at once, huge form fields,
//! CORS for a browser plug-in's profile writes, If-Range, and IK stalling the runtime.

use crate::common;

use common::{Fetch, raw, read_response};
use kinepost::http::Config;
use std::time::{Duration, Instant};
use tokio::io::AsyncWriteExt;

/// A raw `POST /v1/post` head announcing `len` bytes of `ctype`.
fn post_head(path: &str, ctype: &str, len: usize) -> String {
    format!(
        "POST {path} HTTP/1.1\r\nHost: kinepost\r\nContent-Type: {ctype}\r\nContent-Length: {len}\r\nConnection: close\r\n\r\n"
    )
}

fn status(resp: &str) -> u16 {
    resp.split(' ').nth(1).and_then(|s| s.parse().ok()).unwrap_or(0)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn trickling_uploads_lose_their_slots_and_a_fresh_post_gets_in() {
    let base = common::server(Config {
        max_streams: 4,
        min_upload_rate: 1024,
        upload_rate_window: Duration::from_secs(1),
        ..common::cfg()
    })
    .await;
    // Four uploads of a byte every 200 ms, two raw and two as forms, hold every stream slot; a
    // fifth, a job's, is cut off the same way.
    let form_head = "--b\r\nContent-Disposition: form-data; name=\"machine\"\r\n\r\nvmc-3axis\r\n--b\r\nContent-Disposition: form-data; name=\"file\"; filename=\"a.cl\"\r\n\r\nUNITS/MM\n";
    let t0 = Instant::now();
    let mut uploads = Vec::new();
    for i in 0..5 {
        let base = base.clone();
        uploads.push(tokio::spawn(async move {
            let mut s = if i == 4 {
                let head = post_head("/v1/jobs?machine=vmc-3axis", "text/plain", 100_000);
                raw(&base, format!("{head}UNITS/MM\n").as_bytes()).await
            } else if i % 2 == 0 {
                let head = post_head("/v1/post?machine=vmc-3axis", "text/plain", 100_000);
                raw(&base, format!("{head}UNITS/MM\n").as_bytes()).await
            } else {
                let head = post_head("/v1/post", "multipart/form-data; boundary=b", 100_000);
                raw(&base, format!("{head}{form_head}").as_bytes()).await
            };
            let (mut rd, mut wr) = s.split();
            let (resp, ()) = tokio::join!(
                async {
                    let mut rd = tokio::io::AsyncReadExt::take(&mut rd, 1 << 20);
                    let mut out = Vec::new();
                    let _ = tokio::time::timeout(
                        Duration::from_secs(10),
                        tokio::io::AsyncReadExt::read_to_end(&mut rd, &mut out),
                    )
                    .await;
                    String::from_utf8_lossy(&out).into_owned()
                },
                async {
                    let mut w = tokio::io::BufWriter::new(&mut wr);
                    for _ in 0..50 {
                        tokio::time::sleep(Duration::from_millis(200)).await;
                        if w.write_all(b"\n").await.is_err() || w.flush().await.is_err() {
                            break;
                        }
                    }
                }
            );
            resp
        }));
    }
    tokio::time::sleep(Duration::from_millis(300)).await;
    let c = reqwest::Client::new();
    let busy = c
        .post(format!("{base}/v1/post?machine=vmc-3axis"))
        .body("UNITS/MM\nGOTO/1,2,3\n")
        .status_ok()
        .await;
    assert_eq!(busy, 503, "the trickling uploads hold every slot");
    for u in uploads {
        let resp = u.await.unwrap();
        assert_eq!(status(&resp), 408, "{resp}");
        assert!(resp.contains("upload-too-slow") && resp.contains("1024 bytes/s"), "{resp}");
    }
    // One window to notice, and a little for the check: well under the ten seconds allowed.
    assert!(t0.elapsed() < Duration::from_secs(5), "cut off after {:?}", t0.elapsed());
    let nc = c
        .post(format!("{base}/v1/post?machine=vmc-3axis"))
        .body("UNITS/MM\nFEDRAT/500,MMPM\nGOTO/1,2,3\n")
        .send()
        .await
        .unwrap();
    assert_eq!(nc.status(), 200, "the slots were given back");
    assert!(nc.text().await.unwrap().contains("M30"));
}

/// A stream already under way when its upload slows ends with an error record, as any failure
/// after the first byte does.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stream_whose_upload_slows_ends_with_an_error_record() {
    let base = common::server(Config {
        min_upload_rate: 1024,
        upload_rate_window: Duration::from_secs(1),
        ..common::cfg()
    })
    .await;
    let (tx, rx) = tokio::sync::mpsc::channel::<Vec<u8>>(2);
    let body = reqwest::Body::wrap_stream(futures_util::stream::unfold(rx, |mut rx| async move {
        rx.recv().await.map(|b| (Ok::<_, std::io::Error>(b), rx))
    }));
    // The path without its FINI: the engine reads on, waiting for more.
    let cl = String::from_utf8(common::generated("dmg-dmc75v", 2000, 3)).unwrap();
    tx.send(cl.trim_end().trim_end_matches("FINI").as_bytes().to_vec())
        .await
        .unwrap();
    let feeder = tokio::spawn(async move {
        for _ in 0..100 {
            tokio::time::sleep(Duration::from_millis(200)).await;
            if tx.send(b"\n".to_vec()).await.is_err() {
                return;
            }
        }
    });
    let r = reqwest::Client::new()
        .post(format!("{base}/v1/post?machine=dmg-dmc75v"))
        .header("accept", "application/x-ndjson")
        .body(body)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200, "the stream started before the upload slowed");
    let text = tokio::time::timeout(Duration::from_secs(15), r.text())
        .await
        .expect("the stream ends");
    let text = text.unwrap_or_default();
    let last: serde_json::Value = serde_json::from_str(text.trim_end().lines().last().unwrap()).unwrap();
    assert_eq!(last["type"], "error", "{last}");
    assert!(
        last["error"]["detail"].as_str().unwrap().contains("--min-upload-rate"),
        "{last}"
    );
    feeder.abort();
}

#[tokio::test]
async fn twenty_concurrent_posts_admit_exactly_max_streams() {
    let base = common::server(Config {
        max_streams: 4,
        ..common::cfg()
    })
    .await;
    // Each form stops before its file part, so no handler has got far when all twenty ask.
    let first = "--b\r\nContent-Disposition: form-data; name=\"machine\"\r\n\r\nvmc-3axis\r\n";
    let rest = "--b\r\nContent-Disposition: form-data; name=\"file\"; filename=\"a.cl\"\r\n\r\nUNITS/MM\nFEDRAT/500,MMPM\nGOTO/1,2,3\n\r\n--b--\r\n";
    let head = post_head("/v1/post", "multipart/form-data; boundary=b", first.len() + rest.len());
    let start = format!("{head}{first}");
    let socks = futures_util::future::join_all((0..20).map(|_| raw(&base, start.as_bytes()))).await;
    tokio::time::sleep(Duration::from_millis(1000)).await;
    let (mut refused, mut admitted) = (0, 0);
    for mut s in socks {
        if let Some(resp) = read_response(&mut s, Duration::from_millis(100)).await {
            assert_eq!(status(&resp), 503, "{resp}");
            assert!(resp.to_ascii_lowercase().contains("retry-after: 5"), "{resp}");
            refused += 1;
            continue;
        }
        s.write_all(rest.as_bytes()).await.unwrap();
        let resp = read_response(&mut s, Duration::from_secs(10)).await.unwrap();
        assert_eq!(status(&resp), 200, "{resp}");
        assert!(resp.contains("M30"), "{resp}");
        admitted += 1;
    }
    assert_eq!((admitted, refused), (4, 16));
    // Every slot was given back when its stream ended, and the refused ones took none.
    let c = reqwest::Client::new();
    let mut metrics = String::new();
    for _ in 0..20 {
        metrics = c.get(format!("{base}/metrics")).text_ok().await;
        if metrics.contains("kinepost_streams_in_flight 0") {
            break;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    assert!(metrics.contains("kinepost_streams_in_flight 0"), "{metrics}");
}

#[tokio::test]
async fn connections_without_a_request_are_closed_at_their_deadline() {
    let base = common::server(Config {
        header_timeout: Duration::from_millis(500),
        idle_timeout: Duration::from_millis(800),
        ..common::cfg()
    })
    .await;
    let t0 = Instant::now();
    let mut half = raw(&base, b"GET /healthz HTTP/1.1\r\nHost: kine").await;
    let mut silent = raw(&base, b"").await;
    assert_eq!(read_response(&mut half, Duration::from_secs(5)).await.as_deref(), Some(""));
    assert_eq!(read_response(&mut silent, Duration::from_secs(5)).await.as_deref(), Some(""));
    let took = t0.elapsed();
    assert!(
        took >= Duration::from_millis(450) && took < Duration::from_secs(3),
        "{took:?}"
    );

    // A keep-alive connection answers, then is closed once idle for longer than allowed.
    let mut ka = raw(&base, b"GET /healthz HTTP/1.1\r\nHost: kinepost\r\n\r\n").await;
    let t0 = Instant::now();
    let resp = read_response(&mut ka, Duration::from_secs(5)).await.unwrap();
    assert_eq!(status(&resp), 200, "{resp}");
    let took = t0.elapsed();
    assert!(
        took >= Duration::from_millis(700) && took < Duration::from_secs(3),
        "closed after {took:?}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn healthz_answers_with_hundreds_of_idle_sockets_open() {
    let data = std::env::temp_dir().join(format!("kinepost-idle-{}", std::process::id()));
    // Fewer descriptors than idle sockets: without a bound the server could accept no more.
    let (mut child, base) = common::spawn_binary_with_nofile(&data, &[], 256);
    let mut idle = Vec::new();
    for _ in 0..300 {
        idle.push(raw(&base, b"").await);
    }
    tokio::time::sleep(Duration::from_millis(300)).await;
    let c = reqwest::Client::builder().timeout(Duration::from_secs(10)).build().unwrap();
    let t0 = Instant::now();
    let r = c.get(format!("{base}/healthz")).send().await;
    let took = t0.elapsed();
    let _ = child.kill();
    let _ = child.wait();
    let _ = std::fs::remove_dir_all(&data);
    assert_eq!(r.expect("healthz answers").status(), 200);
    assert!(took < Duration::from_secs(2), "healthz took {took:?}");
    drop(idle);
}

#[tokio::test]
async fn a_huge_form_field_is_refused_early_and_no_value_is_echoed_whole() {
    let base = common::server(common::cfg()).await;
    let field = 8 << 20;
    let pre = "--b\r\nContent-Disposition: form-data; name=\"dialect\"\r\n\r\n";
    let post = "\r\n--b\r\nContent-Disposition: form-data; name=\"file\"; filename=\"a.cl\"\r\n\r\nGOTO/1,2,3\n\r\n--b--\r\n";
    let head = post_head(
        "/v1/post?machine=vmc-3axis",
        "multipart/form-data; boundary=b",
        pre.len() + field + post.len(),
    );
    let t0 = Instant::now();
    let mut s = raw(&base, format!("{head}{pre}").as_bytes()).await;
    let (mut rd, mut wr) = s.split();
    let (resp, ()) = tokio::join!(
        async {
            let mut out = Vec::new();
            let _ = tokio::time::timeout(
                Duration::from_secs(20),
                tokio::io::AsyncReadExt::read_to_end(&mut rd, &mut out),
            )
            .await;
            String::from_utf8_lossy(&out).into_owned()
        },
        async {
            let chunk = vec![b'x'; 64 * 1024];
            for _ in 0..field / chunk.len() {
                if wr.write_all(&chunk).await.is_err() {
                    return;
                }
            }
            let _ = wr.write_all(post.as_bytes()).await;
        }
    );
    assert_eq!(status(&resp), 413, "{}", &resp[..resp.len().min(500)]);
    assert!(resp.len() < 2000, "{} bytes answered", resp.len());
    assert!(resp.contains("\\\"dialect\\\"") && resp.contains("65536"), "{resp}");
    assert!(t0.elapsed() < Duration::from_secs(10));

    // Values in the query, the path and JSON bodies are quoted cut short.
    let c = reqwest::Client::new();
    let long = "x".repeat(20_000);
    for (url, want) in [
        (format!("{base}/v1/post?machine={long}"), 404),
        (format!("{base}/v1/post?machine=vmc-3axis&dialect={long}"), 400),
        (format!("{base}/v1/post?machine=vmc-3axis&{long}=1"), 400),
        (format!("{base}/v1/jobs?state={long}"), 400),
    ] {
        let r = c
            .request(
                if url.contains("/v1/jobs") {
                    reqwest::Method::GET
                } else {
                    reqwest::Method::POST
                },
                &url,
            )
            .body("GOTO/1,2,3\n")
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), want, "{url:.60}");
        let text = r.text().await.unwrap();
        assert!(
            text.len() < 1000 && text.contains(&"x".repeat(80)) && !text.contains(&"x".repeat(81)),
            "{text}"
        );
    }
    let r = c.get(format!("{base}/v1/jobs/{}", "y".repeat(20_000))).send().await.unwrap();
    assert_eq!(r.status(), 404);
    assert!(r.text().await.unwrap().len() < 1000);
    for body in [
        serde_json::json!({ "joints": { long.clone(): 1.0 } }),
        serde_json::json!({ "joints": { "X": long.clone() } }),
        serde_json::json!({ "joints": {}, long.clone(): 1 }),
    ] {
        let r = c
            .post(format!("{base}/v1/machines/vmc-3axis/fk"))
            .json(&body)
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 400);
        let text = r.text().await.unwrap();
        assert!(text.len() < 1000, "{text}");
    }
}

#[tokio::test]
async fn cors_preflight_allows_the_headers_a_plugin_sends() {
    let base = common::server(Config {
        cors_origins: vec!["https://cam.example".into()],
        ..common::cfg()
    })
    .await;
    let c = reqwest::Client::new();
    let r = c
        .request(reqwest::Method::OPTIONS, format!("{base}/v1/machines/my-mill"))
        .header("origin", "https://cam.example")
        .header("access-control-request-method", "PUT")
        .header("access-control-request-headers", "authorization, content-type, if-match")
        .send()
        .await
        .unwrap();
    assert!(r.status().is_success(), "{}", r.status());
    let h = r.headers();
    assert_eq!(h["access-control-allow-origin"], "https://cam.example");
    let allowed = h["access-control-allow-headers"].to_str().unwrap().to_ascii_lowercase();
    for want in ["authorization", "content-type", "if-match"] {
        assert!(allowed.split(',').any(|a| a.trim() == want), "{want} not in {allowed}");
    }
    assert!(h["access-control-allow-methods"].to_str().unwrap().contains("PUT"));
    let r = c
        .get(format!("{base}/v1/machines/vmc-3axis"))
        .header("origin", "https://cam.example")
        .send()
        .await
        .unwrap();
    let exposed = r.headers()["access-control-expose-headers"]
        .to_str()
        .unwrap()
        .to_ascii_lowercase();
    for want in ["etag", "location", "retry-after", "x-request-id", "content-range"] {
        assert!(exposed.contains(want), "{want} not in {exposed}");
    }
}

#[tokio::test]
async fn if_range_gets_the_part_only_of_the_same_output() {
    let base = common::server(common::cfg()).await;
    let c = reqwest::Client::new();
    let job = c
        .post(format!("{base}/v1/jobs?machine=vmc-3axis"))
        .body("UNITS/MM\nFEDRAT/500,MMPM\nGOTO/1,2,3\nGOTO/4,5,6\n")
        .json_ok()
        .await;
    let id = job["id"].as_str().unwrap();
    common::wait_job(&c, &base, id, "succeeded", Duration::from_secs(30)).await;
    // The diagnostics are rebuilt as they stream, their length unknown: a Range, with any
    // If-Range, gets the whole (200, `Accept-Ranges: none`); the NDJSON file of a job run
    // before the block store is served by range (`tests/it/job_diagnostics.rs`).
    let url = format!("{base}/v1/jobs/{id}/diagnostics");
    let whole = c.get(&url).send().await.unwrap();
    let etag = whole.headers()["etag"].to_str().unwrap().to_string();
    let len = whole.bytes().await.unwrap().len();
    let r = c.get(&url).header("range", "bytes=0-9").header("if-range", &etag).send().await.unwrap();
    assert_eq!(r.status(), 200);
    assert_eq!(r.headers()["accept-ranges"], "none");
    assert_eq!(r.bytes().await.unwrap().len(), len);
    for out in ["nc"] {
        let url = format!("{base}/v1/jobs/{id}/{out}");
        let whole = c.get(&url).send().await.unwrap();
        let etag = whole.headers()["etag"].to_str().unwrap().to_string();
        let modified = whole.headers()["last-modified"].to_str().unwrap().to_string();
        let len = whole.bytes().await.unwrap().len();
        for (if_range, want) in [
            (etag.clone(), 206),
            (modified.clone(), 206),
            ("\"another-output\"".to_string(), 200),
            (format!("W/{etag}"), 200),
            ("Sat, 01 Jan 2000 00:00:00 GMT".to_string(), 200),
        ] {
            let r = c
                .get(&url)
                .header("range", "bytes=0-9")
                .header("if-range", &if_range)
                .send()
                .await
                .unwrap();
            assert_eq!(r.status(), want, "{out} If-Range {if_range}");
            let body = r.bytes().await.unwrap();
            assert_eq!(body.len(), if want == 206 { 10 } else { len }, "{out} If-Range {if_range}");
        }
    }
}

/// IK runs on the blocking pool: however long it takes, the runtime answers health checks. Slow
/// IK needs a rotary with a long travel and angle error (its windings listed turn by turn); where
/// the loader refuses such travel, the longest it takes stands in.
#[tokio::test(flavor = "multi_thread", worker_threads = 1)]
async fn healthz_answers_while_ik_computes() {
    const TOKEN: &str = "hardening-admin";
    let base = common::server(Config {
        admin_token: Some(TOKEN.into()),
        ..common::cfg()
    })
    .await;
    let c = reqwest::Client::new();
    let haas = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/machines/haas-umc750.toml")).unwrap();
    let mut created = false;
    for travel in ["1e9", "99999.999"] {
        let profile = haas.replace("id = \"haas-umc750\"", "id = \"long-c\"").replace(
            "max_accel = 600.0  # deg/s2",
            &format!(
                "max_accel = 600.0\nmin = -{travel}\nmax = {travel}\n[rotary.angle_error]\ncoefficients = [0.0, 0.001, 0.0]\nrange = [-180.0, 180.0]"
            ),
        );
        let r = c
            .post(format!("{base}/v1/machines"))
            .header("authorization", format!("Bearer {TOKEN}"))
            .header("content-type", "application/toml")
            .body(profile)
            .send()
            .await
            .unwrap();
        if r.status() == 201 {
            created = true;
            break;
        }
        assert_eq!(r.status(), 422, "{}", r.text().await.unwrap());
    }
    assert!(created);
    let pose = serde_json::json!({ "tip": [1.0, 2.0, 3.0], "axis": [0.3, 0.2, 0.9] });
    // Timed from before the calls: on a runtime thread busy with IK, the test's own timer would
    // fire late too.
    let t0 = Instant::now();
    let calls: Vec<_> = (0..3)
        .map(|_| {
            let req = c.post(format!("{base}/v1/machines/long-c/ik")).json(&pose);
            tokio::spawn(async move { req.send().await.unwrap().status() })
        })
        .collect();
    tokio::time::sleep(Duration::from_millis(200)).await;
    assert_eq!(c.get(format!("{base}/healthz")).status_ok().await, 200);
    let took = t0.elapsed();
    for call in calls {
        assert_eq!(call.await.unwrap(), 200);
    }
    assert!(
        took < Duration::from_millis(2200),
        "healthz answered {took:?} after the IK calls went out"
    );
}

/// A GET of `path` on a socket whose receive buffer is small, which is then never read: a client
/// that stalls a download (issue 51).
async fn stalled_get(base: &str, path: &str) -> tokio::net::TcpStream {
    let sock = tokio::net::TcpSocket::new_v4().unwrap();
    sock.set_recv_buffer_size(4096).unwrap();
    let mut s = sock
        .connect(base.trim_start_matches("http://").parse().unwrap())
        .await
        .unwrap();
    s.write_all(format!("GET {path} HTTP/1.1\r\nHost: kinepost\r\n\r\n").as_bytes())
        .await
        .unwrap();
    s
}

/// A succeeded job whose diagnostics are many megabytes (more than socket buffers hold): its id
/// and the diagnostics' length.
async fn big_job(c: &reqwest::Client, base: &str) -> (String, usize) {
    let job = c
        .post(format!("{base}/v1/jobs?machine=dmg-dmc75v"))
        .body(common::generated("dmg-dmc75v", 40_000, 5))
        .json_ok()
        .await;
    let id = job["id"].as_str().unwrap().to_string();
    common::wait_job(c, base, &id, "succeeded", Duration::from_secs(120)).await;
    let len = c
        .get(format!("{base}/v1/jobs/{id}/diagnostics"))
        .send()
        .await
        .unwrap()
        .bytes()
        .await
        .unwrap()
        .len();
    assert!(len > 8 << 20, "diagnostics of {len} bytes fit in socket buffers");
    (id, len)
}

/// Issue 51, 1: clients that ask for a job's diagnostics and never read held a blocking thread
/// each until the pool was full, and then no post could start (while `/healthz` said 200); and
/// nothing ever ended their responses. Here the pool has 6 threads and 12 clients stall: a post
/// is served at once, and every stalled download is cut at the write deadline.
#[test]
fn stalled_downloads_hold_no_thread_and_are_cut_at_the_write_deadline() {
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .max_blocking_threads(6)
        .enable_all()
        .build()
        .unwrap();
    rt.block_on(async {
        let base = common::server(Config {
            write_timeout: Duration::from_secs(3),
            max_downloads_per_client: 0,
            workers: 1,
            ..common::cfg()
        })
        .await;
        let c = reqwest::Client::builder().timeout(Duration::from_secs(10)).build().unwrap();
        let (id, len) = big_job(&c, &base).await;
        let path = format!("/v1/jobs/{id}/diagnostics");
        let mut stalled = Vec::new();
        for _ in 0..12 {
            stalled.push(stalled_get(&base, &path).await);
        }
        tokio::time::sleep(Duration::from_millis(500)).await;
        let t0 = Instant::now();
        let r = c
            .post(format!("{base}/v1/post?machine=vmc-3axis"))
            .body("UNITS/MM\nFEDRAT/500,MMPM\nGOTO/1,2,3\n")
            .send()
            .await
            .expect("a post is served beside stalled downloads");
        assert_eq!(r.status(), 200);
        assert!(r.text().await.unwrap().contains("M30"));
        // Before the write deadline: the stalled downloads still hold whatever they hold.
        assert!(t0.elapsed() < Duration::from_secs(2), "the post took {:?}", t0.elapsed());
        // Each fills its socket's buffers (about 3 MB, rebuilt as they stream), waits three
        // seconds and is cut; reading it earlier would let it go on.
        tokio::time::sleep(Duration::from_secs(7)).await;
        // Each was cut: what it gets when it reads at last is short of the whole.
        for mut s in stalled {
            let mut got = 0usize;
            let mut buf = vec![0u8; 1 << 16];
            loop {
                match tokio::time::timeout(Duration::from_secs(5), tokio::io::AsyncReadExt::read(&mut s, &mut buf)).await {
                    Ok(Ok(0)) | Ok(Err(_)) => break,
                    Ok(Ok(n)) => got += n,
                    Err(_) => panic!("a stalled download still open after its write deadline ({got} of {len} bytes read)"),
                }
            }
            assert!(got < len, "a stalled download got the whole ({got} of {len} bytes)");
        }
    });
}

/// Issue 51, 1: one client's downloads in flight are bounded (429 beyond), and its slots come
/// back when they end.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_clients_downloads_in_flight_are_bounded() {
    let base = common::server(Config {
        max_downloads_per_client: 2,
        write_timeout: Duration::from_secs(60),
        ..common::cfg()
    })
    .await;
    let c = reqwest::Client::builder().timeout(Duration::from_secs(10)).build().unwrap();
    let (id, _) = big_job(&c, &base).await;
    let a = stalled_get(&base, &format!("/v1/jobs/{id}/diagnostics")).await;
    let b = stalled_get(&base, &format!("/v1/jobs/{id}/diagnostics")).await;
    tokio::time::sleep(Duration::from_millis(300)).await;
    let r = c.get(format!("{base}/v1/jobs/{id}/input")).send().await.unwrap();
    assert_eq!(r.status(), 429, "a third download in flight");
    assert!(r.headers().contains_key("retry-after"));
    assert!(r.text().await.unwrap().contains("--max-downloads-per-client"));
    drop((a, b));
    tokio::time::sleep(Duration::from_millis(500)).await;
    assert_eq!(c.get(format!("{base}/v1/jobs/{id}/input")).status_ok().await, 200);
}

/// Issue 51, 1: `/readyz` says whether a post could be served now: not while every post stream
/// is taken (`/healthz` answered 200 throughout while none could be).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn readyz_is_503_while_no_post_could_be_served() {
    let base = common::server(Config {
        max_streams: 1,
        ..common::cfg()
    })
    .await;
    let c = reqwest::Client::new();
    assert_eq!(c.get(format!("{base}/readyz")).status_ok().await, 200);
    let head = post_head("/v1/post?machine=vmc-3axis", "text/plain", 100_000);
    let held = raw(&base, format!("{head}UNITS/MM\n").as_bytes()).await;
    tokio::time::sleep(Duration::from_millis(300)).await;
    let r = c.get(format!("{base}/readyz")).send().await.unwrap();
    assert_eq!(r.status(), 503);
    assert!(r.text().await.unwrap().contains("--max-streams"));
    assert_eq!(c.get(format!("{base}/healthz")).status_ok().await, 200);
    drop(held);
    let mut ready = 0;
    for _ in 0..40 {
        ready = c.get(format!("{base}/readyz")).status_ok().await.as_u16();
        if ready == 200 {
            break;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    assert_eq!(ready, 200, "ready again once the stream has ended");
}

/// Issue 51, 5: a post whose client left went on for about 65 s, the engine noticing only at its
/// next write, which a long collision check held back. Here the table is a mesh of 100 000
/// triangles (a six-point path takes minutes to check in a debug build): the engine looks
/// between the check's samples, and its stream slot (held by its thread) is free within 2 s.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_post_whose_client_left_stops_within_a_second() {
    let dir = std::env::temp_dir().join(format!("kinepost-gone-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let spinner = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/machines/spinner-u5-620.toml")).unwrap();
    let table = "cylinder = { from = [0.0, 0.0, -60.0], to = [0.0, 0.0, 0.0], radius = 250.0 }";
    assert!(spinner.contains(table));
    std::fs::write(dir.join("spinner-mesh.toml"), spinner.replacen(table, "mesh = \"table.stl\"", 1).replace("id = \"spinner-u5-620\"", "id = \"spinner-mesh\"")).unwrap();
    // Small triangles strewn over the table: no bound lets the check skip them.
    let mut seed = 1u64;
    let mut rnd = |lo: f64, hi: f64| {
        seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        lo + (hi - lo) * ((seed >> 11) as f64 / (1u64 << 53) as f64)
    };
    let tris: Vec<[[f64; 3]; 3]> = (0..100_000)
        .map(|_| {
            let (x, y, z) = (rnd(-250.0, 250.0), rnd(-250.0, 250.0), rnd(-60.0, 0.0));
            [[x, y, z], [x + 3.0, y, z], [x, y + 3.0, z]]
        })
        .collect();
    std::fs::write(dir.join("table.stl"), common::stl::binary(&tris)).unwrap();
    let base = common::server(Config {
        machines: dir.clone(),
        ..common::cfg()
    })
    .await;
    let cl = common::generated("spinner-u5-620", 6, 1);
    let c = reqwest::Client::new();
    let gone = c
        .post(format!("{base}/v1/post?machine=spinner-mesh"))
        .body(cl)
        .timeout(Duration::from_secs(1))
        .send()
        .await;
    assert!(gone.is_err(), "the post answered within a second: the test needs a slower one");
    let t0 = Instant::now();
    let mut metrics = String::new();
    while t0.elapsed() < Duration::from_secs(10) {
        metrics = c.get(format!("{base}/metrics")).text_ok().await;
        if metrics.contains("kinepost_streams_in_flight 0") {
            break;
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    let took = t0.elapsed();
    let _ = std::fs::remove_dir_all(&dir);
    assert!(metrics.contains("kinepost_streams_in_flight 0"), "the engine runs on");
    assert!(took < Duration::from_secs(2), "the engine stopped {took:?} after its client left");
}

/// The resident memory of process `pid`, in MB.
fn rss_mb(pid: u32) -> f64 {
    let s = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap();
    let kb: f64 = s.lines().find(|l| l.starts_with("VmRSS:")).unwrap().split_whitespace().nth(1).unwrap().parse().unwrap();
    kb / 1024.0
}

/// Issue 51, 3: each download of a mesh made its own binary STL (10 MB for 200 000 triangles):
/// 150 unread GETs took the server from 544 to 1 612 MB. Now every download shares one copy.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn unread_mesh_downloads_share_one_copy() {
    let dir = std::env::temp_dir().join(format!("kinepost-meshes-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(dir.join("machines")).unwrap();
    let spinner = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/machines/spinner-u5-620.toml")).unwrap();
    let table = "cylinder = { from = [0.0, 0.0, -60.0], to = [0.0, 0.0, 0.0], radius = 250.0 }";
    std::fs::write(
        dir.join("machines/spinner-mesh.toml"),
        spinner.replacen(table, "mesh = \"table.stl\"", 1).replace("id = \"spinner-u5-620\"", "id = \"spinner-mesh\""),
    )
    .unwrap();
    let tris: Vec<[[f64; 3]; 3]> = (0..200_000)
        .map(|i| {
            let (x, y) = ((i % 400) as f64 - 200.0, (i / 400) as f64 * 0.8 - 200.0);
            [[x, y, -60.0], [x + 1.0, y, -30.0], [x, y + 1.0, 0.0]]
        })
        .collect();
    std::fs::write(dir.join("machines/table.stl"), common::stl::binary(&tris)).unwrap();
    let machines = dir.join("machines");
    let (mut child, base) = common::spawn_binary(
        &dir.join("data"),
        &["--machines", machines.to_str().unwrap(), "--max-downloads-per-client", "0"],
    );
    let path = "/v1/machines/spinner-mesh/meshes/table.stl";
    // One read whole: the copy made, and the size of one.
    let c = reqwest::Client::new();
    let whole = c.get(format!("{base}{path}")).send().await.unwrap().bytes().await.unwrap();
    assert_eq!(whole.len(), 84 + 50 * 200_000);
    let before = rss_mb(child.id());
    let mut unread = Vec::new();
    for _ in 0..150 {
        unread.push(stalled_get(&base, path).await);
    }
    // Until every one has its response (counted as its body starts), or the memory shows.
    let t0 = Instant::now();
    let counted = "kinepost_http_requests_total{route=\"/v1/machines/{id}/meshes/{file}\",status=\"200\"} 151";
    while t0.elapsed() < Duration::from_secs(120) && rss_mb(child.id()) - before < 150.0 {
        if c.get(format!("{base}/metrics")).text_ok().await.contains(counted) {
            break;
        }
        tokio::time::sleep(Duration::from_millis(250)).await;
    }
    tokio::time::sleep(Duration::from_millis(500)).await;
    let after = rss_mb(child.id());
    let _ = child.kill();
    let _ = child.wait();
    let _ = std::fs::remove_dir_all(&dir);
    drop(unread);
    eprintln!("150 unread mesh downloads: {before:.0} MB -> {after:.0} MB");
    // A copy each would be 1.5 GB; hyper's buffers of each response, which share the bytes,
    // are all that grows.
    assert!(after - before < 150.0, "150 unread mesh downloads: {before:.0} MB -> {after:.0} MB");
}
