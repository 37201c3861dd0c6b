//! Graceful shutdown with the real binary: SIGTERM during a post stream lets it finish.

use crate::common;

use std::process::Command;
use std::time::Duration;

#[tokio::test]
async fn sigterm_finishes_the_stream_in_flight_then_exits() {
    let data = std::env::temp_dir().join(format!("kinepost-shutdown-{}", std::process::id()));
    let (mut child, addr) = common::spawn_binary(&data, &[]);

    let mut cl = String::from("UNITS/MM\nFEDRAT/500,MMPM\n");
    for i in 0..3000 {
        cl.push_str(&format!(
            "GOTO/{:.3},{:.3},10\n",
            (i as f64 * 0.01).cos() * 40.0,
            i as f64 * 0.02
        ));
    }
    let (a, b) = cl.split_at(cl.len() / 2);
    let (a, b) = (a.to_string(), b.to_string());
    let (tx, rx) = tokio::sync::mpsc::channel::<Result<String, std::io::Error>>(2);
    let pid = child.id();
    tokio::spawn(async move {
        tx.send(Ok(a)).await.unwrap();
        tokio::time::sleep(Duration::from_millis(300)).await;
        // Shut down while the upload is half done.
        Command::new("kill").args(["-TERM", &pid.to_string()]).status().unwrap();
        tokio::time::sleep(Duration::from_millis(300)).await;
        tx.send(Ok(b)).await.unwrap();
    });
    let body = reqwest::Body::wrap_stream(futures_util::stream::unfold(rx, |mut rx| async move {
        rx.recv().await.map(|x| (x, rx))
    }));
    let r = reqwest::Client::new()
        .post(format!("{addr}/v1/post?machine=vmc-3axis"))
        .header("content-type", "text/plain")
        .body(body)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    let text = r.text().await.unwrap();
    assert!(text.trim_end().ends_with("M30\n%"), "the stream in flight finished");
    assert!(
        text.lines().filter(|l| l.contains('Y')).count() > 2900,
        "all points, including those sent after SIGTERM"
    );
    let status = tokio::task::spawn_blocking(move || child.wait()).await.unwrap().unwrap();
    assert!(status.success(), "exits cleanly after the stream: {status}");
    let _ = std::fs::remove_dir_all(&data);
}

/// A client that never finishes its upload cannot keep the server up: after SIGTERM it gets the
/// grace (here 1 s), then the server stops and exits cleanly.
#[tokio::test]
async fn a_trickling_upload_does_not_outlive_the_shutdown_grace() {
    let data = std::env::temp_dir().join(format!("kinepost-grace-{}", std::process::id()));
    let (mut child, addr) = common::spawn_binary(&data, &["--shutdown-grace", "1"]);
    let (tx, rx) = tokio::sync::mpsc::channel::<Result<String, std::io::Error>>(1);
    tx.send(Ok("UNITS/MM\nGOTO/1,2,3\n".into())).await.unwrap();
    let body = reqwest::Body::wrap_stream(futures_util::stream::unfold(rx, |mut rx| async move {
        rx.recv().await.map(|x| (x, rx))
    }));
    let upload = tokio::spawn(
        reqwest::Client::new()
            .post(format!("{addr}/v1/post?machine=vmc-3axis"))
            .header("content-type", "text/plain")
            .body(body)
            .send(),
    );
    tokio::time::sleep(Duration::from_millis(300)).await;
    Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .unwrap();
    // Generous: a server waiting for the upload would never exit; one that honours the grace
    // exits about a second after the signal.
    let exited = tokio::task::spawn_blocking(move || {
        for _ in 0..300 {
            if let Some(s) = child.try_wait().unwrap() {
                return Some(s);
            }
            std::thread::sleep(Duration::from_millis(100));
        }
        let _ = child.kill();
        None
    })
    .await
    .unwrap();
    let status = exited.expect("still running 30 s after SIGTERM with a 1 s grace");
    assert!(status.success(), "{status}");
    drop(tx); // the upload was never finished
    let _ = upload.await;
    let _ = std::fs::remove_dir_all(&data);
}
