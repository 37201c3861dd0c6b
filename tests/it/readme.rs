//! The curl examples of the README and of `docs/*.md` (and the `sed` lines that prepare their
//! files), run as written against a live server (only the address and the repository paths are
//! substituted), so the documentation cannot drift from the service.

use crate::common;

use std::path::Path;

const ROOT: &str = env!("CARGO_MANIFEST_DIR");

/// The pages in the order their examples run: the README, then `docs/*.md` sorted by name.
fn pages() -> Vec<(String, String)> {
    let mut docs: Vec<_> = std::fs::read_dir(Path::new(ROOT).join("docs"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "md"))
        .collect();
    docs.sort();
    let mut pages = vec![Path::new(ROOT).join("README.md")];
    pages.extend(docs);
    pages
        .iter()
        .map(|p| {
            let name = p.strip_prefix(ROOT).unwrap().display().to_string();
            (name, std::fs::read_to_string(p).unwrap())
        })
        .collect()
}

fn examples(page: &str) -> Vec<&str> {
    page.lines()
        .filter(|l| l.starts_with("curl ") || l.starts_with("sed "))
        .collect()
}

/// Whether an example's URL (`localhost:8080/…`) is `route`, a `{param}` matching any segment.
fn calls(example: &str, route: &str) -> bool {
    let Some(at) = example.find("localhost:8080/") else {
        return false;
    };
    let url = &example[at + "localhost:8080".len()..];
    // A quoted URL ends at its quote (a `$(…)` in it may hold spaces), a bare one at a space.
    let end = match example[..at].chars().last() {
        Some(q @ ('\'' | '"')) => url.find(q),
        _ => url.find(char::is_whitespace),
    };
    let path = url[..end.unwrap_or(url.len())].split('?').next().unwrap();
    let (got, want): (Vec<_>, Vec<_>) = (path.split('/').collect(), route.split('/').collect());
    got.len() == want.len() && got.iter().zip(&want).all(|(g, w)| w.starts_with('{') || g == w)
}

/// Every route of the OpenAPI document has an example somewhere in the pages.
#[test]
fn every_route_has_an_example() {
    let doc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(Path::new(ROOT).join("openapi/openapi.json")).unwrap()).unwrap();
    let pages = pages();
    let all: Vec<&str> = pages.iter().flat_map(|(_, text)| examples(text)).collect();
    let missing: Vec<&String> = doc["paths"]
        .as_object()
        .unwrap()
        .keys()
        .filter(|route| !all.iter().any(|ex| calls(ex, route)))
        .collect();
    assert!(
        missing.is_empty(),
        "routes without a curl example in README.md or docs/: {missing:?}"
    );
}

/// A page's examples run in a directory of their own, in order, so that they may use the files
/// the page's earlier examples wrote (never another page's).
async fn run_page(addr: &str, dir: &Path, page: &str) {
    std::fs::create_dir_all(dir).unwrap();
    let data = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/");
    for ex in examples(page) {
        let cmd = ex
            .replace("localhost:8080", addr)
            .replace("@tests/data/", &format!("@{data}"))
            .replace(" machines/", concat!(" ", env!("CARGO_MANIFEST_DIR"), "/machines/"));
        let (cmd2, dir2) = (cmd.clone(), dir.to_path_buf());
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
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_curl_example_in_the_docs_works() {
    let pages = pages();
    let count: usize = pages.iter().map(|(_, text)| examples(text).len()).sum();
    assert!(count >= 30, "README.md and docs/ have curl examples for each route: {count}");
    let mut cfg = common::cfg();
    cfg.admin_token = Some("change-me".into()); // as docs/http-api.md starts it
    let base = common::server(cfg).await;
    let addr = base.trim_start_matches("http://").to_string();
    let root = std::env::temp_dir().join(format!("kinepost-readme-{}", std::process::id()));
    for (name, text) in &pages {
        run_page(&addr, &root.join(name.replace('/', "_")), text).await;
    }
    // The README's headline: a CL file posted with the spindle speed, the NC back, spindle on.
    let nc = std::fs::read_to_string(root.join("README.md").join("part.nc")).unwrap();
    assert!(nc.trim_end().ends_with("M30\n%"));
    assert!(
        nc.lines().any(|l| l.starts_with('S') && l.contains(" M3")),
        "the headline's program starts the spindle"
    );
    std::fs::remove_dir_all(&root).ok();
}
