//! README's curl examples (and the `sed` lines that prepare their files), run as written against
//! a live server (only the address and the repository paths are substituted), so the
//! documentation cannot drift from the service.

mod common;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_curl_example_in_the_readme_works() {
    let readme = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/README.md")).unwrap();
    let examples: Vec<&str> = readme
        .lines()
        .filter(|l| l.starts_with("curl ") || l.starts_with("sed "))
        .collect();
    assert!(examples.len() >= 8, "README has curl examples for each route: {examples:?}");
    let mut cfg = common::cfg();
    cfg.admin_token = Some("change-me".into()); // as the README starts it
    let base = common::server(cfg).await;
    let addr = base.trim_start_matches("http://").to_string();
    let dir = std::env::temp_dir().join(format!("kinepost-readme-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let data = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/");
    for ex in examples {
        let cmd = ex
            .replace("localhost:8080", &addr)
            .replace("@tests/data/", &format!("@{data}"))
            .replace(" machines/", concat!(" ", env!("CARGO_MANIFEST_DIR"), "/machines/"));
        let (cmd2, dir2) = (cmd.clone(), dir.clone());
        let out = tokio::task::spawn_blocking(move || {
            std::process::Command::new("sh")
                .arg("-c")
                .arg(&cmd2)
                .current_dir(&dir2)
                .output()
        })
        .await
        .unwrap()
        .expect("curl runs (install curl)");
        assert!(out.status.success(), "{cmd}\n{}", String::from_utf8_lossy(&out.stderr));
    }
    let nc = std::fs::read_to_string(dir.join("part.nc")).unwrap();
    assert!(nc.trim_end().ends_with("M30\n%"));
    std::fs::remove_dir_all(&dir).ok();
}
