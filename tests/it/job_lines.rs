//! A job's line map, stored compactly and rebuilt as it streams, answers `GET
//! /v1/jobs/{id}/lines` exactly as the file of fixed-size entries a version before it left
//! (which is still served): the same bytes, whole or by Range, the same ETag, statuses and
//! range headers; and its entries agree with the NC they index.

use crate::common;

use common::Fetch;
use serde_json::Value;
use std::time::Duration;

/// A server and a succeeded job of a generated spinner path: (config, base URL, client, id).
async fn job(points: usize, seed: u64) -> (kinepost::http::Config, String, reqwest::Client, String) {
    let cfg = common::cfg();
    let base = common::server(cfg.clone()).await;
    let c = reqwest::Client::new();
    let j: Value = c
        .post(format!("{base}/v1/jobs?machine=spinner-u5-620"))
        .body(common::generated("spinner-u5-620", points, seed))
        .json_ok()
        .await;
    let id = j["id"].as_str().unwrap().to_string();
    common::wait_job(&c, &base, &id, "succeeded", Duration::from_secs(120)).await;
    (cfg, base, c, id)
}

/// What a client sees of one request: status, the headers that say what the bytes are, bytes.
async fn seen(c: &reqwest::Client, url: &str, headers: &[(&str, &str)]) -> (u16, Vec<(String, String)>, Vec<u8>) {
    let mut req = c.get(url);
    for (k, v) in headers {
        req = req.header(*k, *v);
    }
    let r = req.send().await.unwrap();
    let status = r.status().as_u16();
    let keep = ["etag", "content-range", "content-length", "accept-ranges", "content-type"];
    let h = keep
        .iter()
        .filter_map(|k| r.headers().get(*k).map(|v| (k.to_string(), v.to_str().unwrap().to_string())))
        .collect();
    (status, h, r.bytes().await.unwrap().to_vec())
}

/// The requests compared: whole, ranges within, across and at the ends of entries, suffix and
/// open ranges, past the end, malformed, multipart, If-Range matching and not, If-None-Match.
fn requests(len: u64, etag: &str) -> Vec<Vec<(&'static str, String)>> {
    let r = |s: String| vec![("range", s)];
    vec![
        vec![],
        r("bytes=0-15".into()),
        r("bytes=0-0".into()),
        r(format!("bytes=16-{}", 16 * 1000 - 1)),
        r(format!("bytes=7-{}", len / 2 + 3)),
        r(format!("bytes={}-", len - 40)),
        r("bytes=-33".into()),
        r(format!("bytes={}-{}", len - 1, len + 100)),
        r(format!("bytes={}-", len)),
        r("bytes=5-2".into()),
        r("lines=0-4".into()),
        r("bytes=0-15,32-47".into()),
        vec![("range", "bytes=100-200".into()), ("if-range", etag.to_string())],
        vec![("range", "bytes=100-200".into()), ("if-range", "\"other\"".into())],
        vec![("if-none-match", etag.to_string())],
    ]
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_compact_line_map_is_served_as_the_fixed_size_file_was() {
    let (cfg, base, c, id) = job(20_000, 3).await;
    let url = format!("{base}/v1/jobs/{id}/lines");
    let (status, _, whole) = seen(&c, &url, &[]).await;
    assert_eq!(status, 200);
    let file = cfg.data_dir.join("spool").join(format!("{id}.lines"));
    let stored = std::fs::metadata(&file).unwrap().len();
    assert!(
        stored * 8 < whole.len() as u64,
        "{stored} bytes stored for {} served",
        whole.len()
    );

    // The entries index the NC: each line's offset, and the NC's length after the last.
    let nc = c
        .get(format!("{base}/v1/jobs/{id}/nc"))
        .send()
        .await
        .unwrap()
        .bytes()
        .await
        .unwrap();
    let offsets: Vec<u64> = whole
        .chunks(16)
        .map(|e| {
            u32::from_le_bytes(e[0..4].try_into().unwrap()) as u64
                | (u32::from_le_bytes(e[4..8].try_into().unwrap()) as u64) << 32
        })
        .collect();
    let starts: Vec<u64> = std::iter::once(0)
        .chain(nc.iter().enumerate().filter(|(_, b)| **b == b'\n').map(|(i, _)| i as u64 + 1))
        .take_while(|&o| o < nc.len() as u64)
        .collect();
    assert_eq!(offsets, starts);
    assert!(whole.chunks(16).filter(|e| e[8..12] != [0; 4]).count() > 19_000, "CL lines");

    // Every request answered alike by the compact store and by the old file of its bytes.
    let len = whole.len() as u64;
    let etag = format!("\"{id}-l-{len}\"");
    let mut compact = Vec::new();
    for h in requests(len, &etag) {
        let h: Vec<(&str, &str)> = h.iter().map(|(k, v)| (*k, v.as_str())).collect();
        compact.push(seen(&c, &url, &h).await);
    }
    assert_eq!(compact[0].1.iter().find(|(k, _)| k == "etag").unwrap().1, etag);
    assert_eq!(compact[4].2, whole[7..len as usize / 2 + 4]);
    std::fs::write(&file, &whole).unwrap();
    for (h, want) in requests(len, &etag).into_iter().zip(compact) {
        let hh: Vec<(&str, &str)> = h.iter().map(|(k, v)| (*k, v.as_str())).collect();
        let got = seen(&c, &url, &hh).await;
        assert_eq!(got.0, want.0, "{h:?}");
        assert_eq!(got.1, want.1, "{h:?}");
        assert!(got.2 == want.2, "{h:?}: {} and {} bytes", got.2.len(), want.2.len());
    }
}

/// Random ranges of a bigger map, each the whole's bytes.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn random_ranges_are_the_wholes_bytes() {
    let (_, base, c, id) = job(60_000, 11).await;
    let url = format!("{base}/v1/jobs/{id}/lines");
    let (_, _, whole) = seen(&c, &url, &[]).await;
    let len = whole.len() as u64;
    let mut x = 99u64;
    for _ in 0..60 {
        x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        let a = (x >> 20) % len;
        let b = (a + (x >> 45) % 200_000).min(len - 1);
        let (status, h, body) = seen(&c, &url, &[("range", &format!("bytes={a}-{b}"))]).await;
        assert_eq!(status, 206);
        assert!(h.contains(&("content-range".into(), format!("bytes {a}-{b}/{len}"))));
        assert!(body == whole[a as usize..=b as usize], "{a}-{b}");
    }
}
