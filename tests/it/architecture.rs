//! The rules of ARCHITECTURE.md, kept by reading the source: each "Architecture invariant" there
//! is a test here, so that none of them rots unnoticed.

use std::path::{Path, PathBuf};

fn src() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("src")
}

/// Every `.rs` file under `dir`, with its text.
fn rust_files(dir: &Path) -> Vec<(PathBuf, String)> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else if p.extension().is_some_and(|x| x == "rs") {
                let text = std::fs::read_to_string(&p).unwrap();
                out.push((p, text));
            }
        }
    }
    assert!(!out.is_empty(), "no Rust files under {}", dir.display());
    out
}

/// Code lines (comments dropped) of `text` that use `needle`.
fn uses<'a>(text: &'a str, needle: &str) -> Vec<&'a str> {
    text.lines()
        .filter(|l| !l.trim_start().starts_with("//"))
        .filter(|l| l.contains(needle))
        .collect()
}

fn forbid(folders: &[&str], needles: &[&str], rule: &str) {
    let mut found = Vec::new();
    for f in folders {
        for (p, text) in rust_files(&src().join(f)) {
            for n in needles {
                for l in uses(&text, n) {
                    found.push(format!("{}: {}", p.display(), l.trim()));
                }
            }
        }
    }
    assert!(found.is_empty(), "{rule}:\n{}", found.join("\n"));
}

#[test]
fn kinematics_knows_no_io() {
    forbid(
        &["kinematics"],
        &[
            "std::fs",
            "std::io",
            "serde_json",
            "utoipa",
            "axum",
            "tokio",
            "crate::post",
            "crate::cl",
            "crate::nc",
            "crate::machines",
        ],
        "kinematics is pure: no IO and no layer above it",
    );
}

#[test]
fn the_engine_knows_no_output_format_http_or_files() {
    forbid(
        &["cl", "nc", "post"],
        &[
            "serde_json",
            "utoipa",
            "axum",
            "tokio",
            "std::fs",
            "crate::http",
            "crate::jobs",
            "crate::output",
        ],
        "the engine (cl, nc, post) writes into a Sink: no JSON, schema, HTTP, job or file code",
    );
}

#[test]
fn only_the_binary_knows_the_command_line() {
    let lib = std::fs::read_to_string(src().join("lib.rs")).unwrap();
    assert!(uses(&lib, "mod cli").is_empty(), "the library declares the CLI module");
    let main = std::fs::read_to_string(src().join("main.rs")).unwrap();
    assert!(!uses(&main, "mod cli;").is_empty(), "main.rs owns the CLI");
    let mut found = Vec::new();
    for (p, text) in rust_files(&src()) {
        if p.starts_with(src().join("cli")) || p.ends_with("main.rs") {
            continue;
        }
        for n in ["crate::cli", "kinepost::cli", "clap::"] {
            found.extend(uses(&text, n).into_iter().map(|l| format!("{}: {}", p.display(), l.trim())));
        }
    }
    assert!(found.is_empty(), "the command line outside the binary:\n{}", found.join("\n"));
}

#[test]
fn a_post_option_is_validated_in_one_place() {
    let settings = src().join("post").join("settings.rs");
    let mut found = Vec::new();
    for (p, text) in rust_files(&src()) {
        if p == settings {
            continue;
        }
        // Options come from `Settings::options`: nothing else builds them or validates a setting.
        for n in ["Options::new(", "Options {", "impl Settings", "fn options("] {
            for l in uses(&text, n) {
                if !l.contains("IkOptions") && !l.contains("VerifyOptions") && !l.contains("PoolOptions") {
                    found.push(format!("{}: {}", p.display(), l.trim()));
                }
            }
        }
    }
    assert!(
        found.is_empty(),
        "post options built outside post/settings.rs:\n{}",
        found.join("\n")
    );
}

/// Files a newcomer can read: none over 1 000 lines (vendored web files aside), the pipeline
/// driver under 400, no function over 150.
#[test]
fn files_and_functions_stay_readable() {
    let mut found = Vec::new();
    for (p, text) in rust_files(&src()) {
        let lines: Vec<&str> = text.lines().collect();
        let limit = if p.ends_with("post/mod.rs") { 400 } else { 1000 };
        if lines.len() > limit {
            found.push(format!("{}: {} lines (at most {limit})", p.display(), lines.len()));
        }
        for (i, l) in lines.iter().enumerate() {
            let t = l.trim_start();
            let indent = l.len() - t.len();
            let is_fn = t.starts_with("fn ") || (t.starts_with("pub") && t.contains(" fn ") && t.find(" fn ") < t.find('('));
            if !is_fn || t.ends_with(';') {
                continue;
            }
            let close = format!("{}}}", " ".repeat(indent));
            let end = lines[i..].iter().position(|x| *x == close).map_or(lines.len(), |k| i + k);
            if end - i + 1 > 150 {
                found.push(format!("{}:{}: fn of {} lines: {}", p.display(), i + 1, end - i + 1, t));
            }
        }
    }
    assert!(found.is_empty(), "hard to read:\n{}", found.join("\n"));
}

/// Inside kinematics the arrows run one way: the model holds what is precomputed from the chain,
/// the IK (solver) reads it; neither the model nor the subproblems import the solver.
#[test]
fn the_kinematics_model_does_not_import_the_solver() {
    let k = src().join("kinematics");
    let mut found = Vec::new();
    for (p, text) in rust_files(&k) {
        let name = p.strip_prefix(&k).unwrap().to_string_lossy().to_string();
        if name.starts_with("model") || name == "subproblem.rs" {
            found.extend(uses(&text, "solver").into_iter().map(|l| format!("{name}: {}", l.trim())));
        }
    }
    assert!(
        found.is_empty(),
        "the model or subproblems depend on the solver:\n{}",
        found.join("\n")
    );
}
