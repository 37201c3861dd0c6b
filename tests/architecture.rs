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

/// The one line of the engine that names clap and utoipa: the derive of the post options'
/// single definition (`post::Settings`), from which the CLI's flags, HTTP's fields and the
/// OpenAPI schema come. Nothing else of either crate is used there.
fn the_options_derive(p: &Path, line: &str) -> bool {
    p.ends_with("post/settings.rs") && line.trim_start().starts_with("#[derive(")
}

fn forbid(folders: &[&str], needles: &[&str], rule: &str) {
    let mut found = Vec::new();
    for f in folders {
        for (p, text) in rust_files(&src().join(f)) {
            for n in needles {
                for l in uses(&text, n).into_iter().filter(|l| !the_options_derive(&p, l)) {
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
            "crate::spool",
            "crate::db",
        ],
        "the engine (cl, nc, post) writes into a Sink: no JSON, schema, HTTP, job or file code",
    );
}

/// The profile loader sits under the engine: a profile's `[policy]` is parsed where it loads
/// (`machines::policy`), not by the post that reads it.
#[test]
fn machines_know_nothing_of_the_engine() {
    forbid(
        &["machines"],
        &["crate::post", "crate::cl", "crate::http", "crate::jobs", "crate::output"],
        "machines loads profiles for the engine and imports nothing from it or above it",
    );
}

#[test]
fn the_job_file_formats_know_neither_edge() {
    forbid(
        &["spool", "db"],
        &["crate::jobs", "crate::http", "axum", "tokio"],
        "spool (the job file formats) and db (the store's tables) sit below the queue and HTTP",
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
            found.extend(
                uses(&text, n)
                    .into_iter()
                    .filter(|l| !the_options_derive(&p, l))
                    .map(|l| format!("{}: {}", p.display(), l.trim())),
            );
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

/// The named fields of each `struct` in `text`, by struct name: the lines of its body (up to the
/// brace that closes it at the struct's indent) that open a field, comments and attributes aside.
fn struct_fields(text: &str) -> Vec<(String, Vec<String>)> {
    let lines: Vec<&str> = text.lines().collect();
    let mut out = Vec::new();
    for (i, l) in lines.iter().enumerate() {
        let t = l.trim_start();
        let Some(rest) = t.split_once("struct ").filter(|(vis, _)| vis.is_empty() || vis.starts_with("pub")).map(|(_, r)| r) else {
            continue;
        };
        if !t.ends_with('{') {
            continue; // a unit or tuple struct
        }
        let name: String = rest.chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect();
        let close = format!("{}}}", &l[..l.len() - t.len()]);
        let mut fields = Vec::new();
        for f in lines[i + 1..].iter().take_while(|x| **x != close) {
            let f = f.trim();
            if f.starts_with("//") || f.starts_with("#[") {
                continue;
            }
            let head = f.split_once(':').map_or("", |(h, _)| h);
            let ident = head.rsplit(' ').next().unwrap_or("");
            let vis = head[..head.len() - ident.len()].trim();
            if !ident.is_empty() && ident.chars().all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_') && (vis.is_empty() || vis.starts_with("pub")) {
                fields.push(f.to_string());
            }
        }
        out.push((name, fields));
    }
    out
}

/// The emitter's state lives with its concepts: the `Emitter` holds what they share and one
/// field per concept, at most 15; a concept's struct keeps its fields private (methods, or a
/// read-only accessor, are how another concept reads it). Only the values handed from one
/// concept to another (an arc block, the look-ahead's findings, a tilted plane) show fields.
#[test]
fn the_emitter_state_lives_with_its_concepts() {
    let emit = src().join("post").join("emit");
    let mod_rs = std::fs::read_to_string(emit.join("mod.rs")).unwrap();
    let structs = struct_fields(&mod_rs);
    let (_, fields) = structs.iter().find(|(n, _)| n == "Emitter").expect("no struct Emitter in src/post/emit/mod.rs");
    assert!(fields.len() >= 5, "the Emitter's fields were not read: {fields:?}");
    assert!(
        fields.len() <= 15,
        "the Emitter has {} fields (at most 15: put the state in the concept that owns it):\n{}",
        fields.len(),
        fields.join("\n")
    );
    let values = ["ArcBlock", "Ahead", "Tilt"];
    let mut found = Vec::new();
    for (p, text) in rust_files(&emit) {
        for (name, fields) in struct_fields(&text) {
            if name == "Emitter" || values.contains(&name.as_str()) {
                continue;
            }
            for f in fields.iter().filter(|f| f.starts_with("pub")) {
                found.push(format!("{}: {name}: {f}", p.display()));
            }
        }
    }
    assert!(found.is_empty(), "a concept's state shown to the other concepts:\n{}", found.join("\n"));
}
