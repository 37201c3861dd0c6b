//! What an attack on the service found (issue 30), each answered: more streams than allowed at
//! once.

mod common;

use common::{Fetch, raw, read_response};
use kinepost::http::Config;
use std::time::Duration;
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
