//! The rules of ARCHITECTURE.md, kept by reading the source: each "Architecture invariant" there
//! is a test here, so that none of them rots unnoticed. The module rules are checked on resolved
//! paths ([`modules`]): what a `use` or a qualified path names, wherever it is re-exported from.

mod modules;

use modules::{Target, Tree};
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn src() -> PathBuf {
    root().join("src")
}

fn tree() -> &'static Tree {
    static TREE: OnceLock<Tree> = OnceLock::new();
    TREE.get_or_init(|| Tree::load(root()))
}

/// ARCHITECTURE.md's layers, bottom first: a module imports from its own layer and the layers
/// below, never from one above. The binary (`main.rs`, `cli/`) is above them all.
const LAYERS: &[&[&str]] = &[
    &["kinematics", "diag", "text"],
    &["collide", "calib", "testgen"],
    &["cl", "nc", "db"],
    &["machines"],
    &["post"],
    &["output"],
    &["spool"],
    &["jobs"],
    &["http"],
];

/// Violations the tree has today, one entry each, so that this test is green while they are
/// removed; an entry that no longer occurs fails the test too, so the list only shrinks.
const KNOWN: &[&str] = &[
];

/// Functions over the limit today, as `file: fn name`, kept the same way as [`KNOWN`]: the
/// word grep this test replaced did not see a `pub(super) fn`.
const KNOWN_LONG: &[&str] = &[];

/// One resolved dependency of a module on another of the crate.
struct Edge {
    from: usize,
    to: usize,
    line: usize,
    path: String,
}

/// Every dependency between modules of the crate, test code left out (a module's tests may
/// reach it through its callers).
fn edges() -> Vec<Edge> {
    let t = tree();
    let mut out = Vec::new();
    for (from, m) in t.modules.iter().enumerate() {
        if m.test {
            continue;
        }
        for r in m.refs.iter().filter(|r| !r.test) {
            if let Target::Module(to) = t.resolve(from, &r.path) {
                if to != from {
                    out.push(Edge {
                        from,
                        to,
                        line: r.line,
                        path: r.path.join("::"),
                    });
                }
            }
        }
    }
    out
}

fn at(m: usize, line: usize) -> String {
    let file = &tree().modules[m].file;
    format!("{}:{line}", file.strip_prefix(root()).unwrap_or(file).display())
}

/// The violations found, each under its key, against [`KNOWN`]: every one printed, the test
/// failing on a key not known and on a known key not found.
fn judge(found: BTreeMap<String, Vec<String>>, scope: &str) {
    let mut report = String::new();
    for (key, lines) in &found {
        let known = if KNOWN.contains(&key.as_str()) { " (known)" } else { "" };
        report += &format!("{key}{known}\n");
        for l in lines {
            report += &format!("    {l}\n");
        }
    }
    eprint!("{report}");
    let new: Vec<_> = found.keys().filter(|k| !KNOWN.contains(&k.as_str())).collect();
    let gone: Vec<_> = KNOWN.iter().filter(|k| k.starts_with(scope) && !found.contains_key(**k)).collect();
    assert!(new.is_empty(), "violations:\n{report}");
    assert!(gone.is_empty(), "fixed, to remove from KNOWN: {gone:?}");
}

/// For every module, its children's dependencies on each other (anything in one child's subtree
/// using anything in another's) have no circle: each module can be read, and changed, with only
/// the siblings below it in mind.
#[test]
fn no_module_imports_in_a_circle() {
    let t = tree();
    // Each dependency is an arrow between the two children of the pair's nearest common module.
    let mut arrows: BTreeMap<usize, BTreeMap<(usize, usize), Vec<String>>> = BTreeMap::new();
    for e in edges() {
        let (a, b) = (ancestors(e.from), ancestors(e.to));
        let common = a.iter().zip(&b).take_while(|(x, y)| x == y).count();
        if common == 0 || common == a.len() || common == b.len() {
            continue; // another crate, or a module and its own parent or child
        }
        let lines = arrows.entry(a[common - 1]).or_default().entry((a[common], b[common])).or_default();
        lines.push(format!("{}: {}", at(e.from, e.line), e.path));
    }
    let mut found = BTreeMap::new();
    for (parent, graph) in &arrows {
        for scc in circles(graph) {
            let names: Vec<_> = scc.iter().map(|&c| t.modules[c].path.last().unwrap().clone()).collect();
            let key = format!("circle in {}: {}", t.name(*parent), names.join(", "));
            let mut lines = Vec::new();
            for ((x, y), uses) in graph.iter().filter(|((x, y), _)| scc.contains(x) && scc.contains(y)) {
                lines.push(format!("{} → {}: {}", t.name(*x), t.name(*y), uses[0]));
                lines.extend(uses[1..].iter().take(2).map(|u| format!("    {u}")));
            }
            found.insert(key, lines);
        }
    }
    judge(found, "circle");
}

/// The module and its ancestors, the crate's root first.
fn ancestors(mut m: usize) -> Vec<usize> {
    let mut v = vec![m];
    while let Some(p) = tree().modules[m].parent {
        v.push(p);
        m = p;
    }
    v.reverse();
    v
}

/// The strongly connected groups of more than one node, each sorted.
fn circles(graph: &BTreeMap<(usize, usize), Vec<String>>) -> Vec<BTreeSet<usize>> {
    let nodes: BTreeSet<usize> = graph.keys().flat_map(|&(a, b)| [a, b]).collect();
    let reach = |from: usize| {
        let mut seen = BTreeSet::from([from]);
        let mut stack = vec![from];
        while let Some(n) = stack.pop() {
            for &(_, b) in graph.keys().filter(|(a, _)| *a == n) {
                if seen.insert(b) {
                    stack.push(b);
                }
            }
        }
        seen
    };
    let reaches: BTreeMap<usize, BTreeSet<usize>> = nodes.iter().map(|&n| (n, reach(n))).collect();
    let mut out: Vec<BTreeSet<usize>> = Vec::new();
    for &n in &nodes {
        let scc: BTreeSet<usize> = nodes.iter().copied().filter(|m| reaches[&n].contains(m) && reaches[m].contains(&n)).collect();
        if scc.len() > 1 && !out.contains(&scc) {
            out.push(scc);
        }
    }
    out
}

/// The layer of a module of the library (its top-level module's), `None` for the binary's.
fn layer(m: usize) -> Option<usize> {
    let path = &tree().modules[m].path;
    if path[0] != "kinepost" {
        return None;
    }
    let top = path.get(1)?;
    Some(LAYERS.iter().position(|l| l.contains(&top.as_str())).unwrap_or_else(|| panic!("kinepost::{top} is in no layer of LAYERS")))
}

/// Arrows point down only: no module of the library imports from a layer above its own, and
/// every top-level module has its layer.
#[test]
fn nothing_imports_from_a_layer_above() {
    let t = tree();
    for top in t.modules[t.lib].children.values() {
        layer(*top);
    }
    let mut found: BTreeMap<String, Vec<String>> = BTreeMap::new();
    for e in edges() {
        if let (Some(a), Some(b)) = (layer(e.from), layer(e.to)) {
            if a < b {
                let file = &t.modules[e.from].file;
                let file = file.strip_prefix(root()).unwrap_or(file).display();
                let key = format!("layer: {file} → {}", t.modules[e.to].path[1]);
                found.entry(key).or_default().push(format!("{}: {}", at(e.from, e.line), e.path));
            }
        }
    }
    judge(found, "layer");
}

/// The paths (test code included) that modules under `folders` write to an external crate
/// starting with one of `needles` (`std::fs`, `serde_json`).
fn external_uses(folders: &[&str], needles: &[&str]) -> Vec<String> {
    let t = tree();
    let mut found = Vec::new();
    for f in folders {
        let top = t.find(&["kinepost", f]).unwrap_or_else(|| panic!("no module kinepost::{f}"));
        for (m, module) in t.modules.iter().enumerate().filter(|(m, _)| t.within(*m, top)) {
            for r in &module.refs {
                if let Target::External(p) = t.resolve(m, &r.path) {
                    if needles.iter().any(|n| p == *n || p.starts_with(&format!("{n}::"))) {
                        found.push(format!("{}: {p}", at(m, r.line)));
                    }
                }
            }
        }
    }
    found.sort();
    found.dedup();
    found
}

/// The one place the engine names clap and utoipa: the derive on the post options' one
/// definition (`post::Settings`), from which the CLI's flags, HTTP's query and form fields and
/// the OpenAPI schema come, each option's doc comment written once. Those derives generate
/// impls of the crates' traits; nothing in the engine calls them. Only these paths, only there.
const THE_OPTIONS_DERIVE: (&str, &[&str]) = ("src/post/settings.rs:", &["clap::Args", "utoipa::IntoParams", "utoipa::ToSchema"]);

fn the_options_derive(found: &str) -> bool {
    let (file, paths) = THE_OPTIONS_DERIVE;
    found.starts_with(file) && paths.iter().any(|p| found.ends_with(&format!(": {p}")))
}

#[test]
fn kinematics_knows_no_io() {
    let found = external_uses(
        &["kinematics"],
        &["std::fs", "std::io", "std::net", "std::process", "serde", "serde_json", "utoipa", "axum", "tokio"],
    );
    assert!(found.is_empty(), "kinematics is pure: no IO, no serde:\n{}", found.join("\n"));
    // Nothing of the layers above it: `nothing_imports_from_a_layer_above`, kinematics being in
    // the lowest.
    assert_eq!(layer(tree().find(&["kinepost", "kinematics"]).unwrap()), Some(0));
}

#[test]
fn the_engine_knows_no_output_format_http_or_files() {
    let mut found = external_uses(&["cl", "nc", "post"], &["serde_json", "utoipa", "axum", "tokio", "std::fs"]);
    found.retain(|f| !the_options_derive(f));
    assert!(
        found.is_empty(),
        "the engine (cl, nc, post) writes into a Sink: no JSON, schema, HTTP or file code:\n{}",
        found.join("\n")
    );
    // No job, HTTP or output code: those are layers above the engine's.
    let post = layer(tree().find(&["kinepost", "post"]).unwrap());
    for above in ["output", "jobs", "http"] {
        assert!(layer(tree().find(&["kinepost", above]).unwrap()) > post, "{above} above post");
    }
}

#[test]
fn only_the_binary_knows_the_command_line() {
    let t = tree();
    assert!(!t.modules[t.lib].children.contains_key("cli"), "the library declares the CLI module");
    assert!(t.modules[t.bin].children.contains_key("cli"), "main.rs owns the CLI");
    let tops: Vec<&str> = t.modules[t.lib].children.keys().map(String::as_str).collect();
    let mut found = external_uses(&tops, &["clap"]);
    found.retain(|f| !the_options_derive(f));
    assert!(found.is_empty(), "the command line outside the binary:\n{}", found.join("\n"));
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
/// driver under 400, no function over 150 (from its `fn` to its closing brace, as parsed).
#[test]
fn files_and_functions_stay_readable() {
    let t = tree();
    let mut found = Vec::new();
    for (p, text) in rust_files(&src()) {
        let lines = text.lines().count();
        let limit = if p.ends_with("post/mod.rs") { 400 } else { 1000 };
        if lines > limit {
            found.push(format!("{}: {lines} lines (at most {limit})", p.display()));
        }
    }
    let mut long = BTreeSet::new();
    for m in &t.modules {
        let file = m.file.strip_prefix(root()).unwrap_or(&m.file).display().to_string();
        for (name, first, len) in m.fns.iter().filter(|f| f.2 > 150) {
            let key = format!("{file}: fn {name}");
            if KNOWN_LONG.contains(&key.as_str()) {
                eprintln!("{file}:{first}: fn {name} of {len} lines (known)");
                long.insert(key);
            } else {
                found.push(format!("{file}:{first}: fn {name} of {len} lines"));
            }
        }
    }
    let gone: Vec<_> = KNOWN_LONG.iter().filter(|k| !long.contains(**k)).collect();
    assert!(gone.is_empty(), "short now, to remove from KNOWN_LONG: {gone:?}");
    found.sort();
    found.dedup();
    assert!(found.is_empty(), "hard to read:\n{}", found.join("\n"));
}

/// Inside kinematics the arrows run one way: the model holds what is precomputed from the chain,
/// the solvers read it; neither the model nor the subproblems use a solver or its answers.
#[test]
fn the_kinematics_model_does_not_import_the_solver() {
    let t = tree();
    let k = |name: &str| t.find(&["kinepost", "kinematics", name]).unwrap();
    let solvers = [k("solver"), k("three"), k("solution")];
    let mut found = Vec::new();
    for e in edges() {
        let below = t.within(e.from, k("model")) || t.within(e.from, k("subproblem"));
        if below && solvers.iter().any(|&s| t.within(e.to, s)) {
            found.push(format!("{}: {}", at(e.from, e.line), e.path));
        }
    }
    assert!(found.is_empty(), "the model or subproblems depend on a solver:\n{}", found.join("\n"));
}

/// The resolver itself, on paths whose answer is known: a re-export's home, `super::`, a renamed
/// import, the binary's `kinepost::`, an external crate.
#[test]
fn paths_resolve_to_the_module_that_defines_them() {
    let t = tree();
    let m = |p: &[&str]| t.find(p).unwrap();
    let s = |p: &str| p.split("::").map(String::from).collect::<Vec<_>>();
    let model = m(&["kinepost", "kinematics", "model"]);
    assert_eq!(t.resolve(m(&["kinepost", "post"]), &s("crate::kinematics::Machine")), Target::Module(model));
    assert_eq!(t.resolve(m(&["kinepost", "kinematics", "solver"]), &s("super::model::Machine")), Target::Module(model));
    assert_eq!(t.resolve(m(&["main", "cli"]), &s("kinepost::kinematics::Machine")), Target::Module(model));
    assert_eq!(
        t.resolve(m(&["kinepost", "kinematics"]), &s("std::fs::read")),
        Target::External("std::fs::read".into())
    );
    assert_eq!(t.resolve(m(&["kinepost", "kinematics"]), &s("Vec::new")), Target::Unknown);
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

/// The job file formats (`spool`) and the store's tables (`db`) know neither the queue nor HTTP:
/// their layers are below both, and they use no async runtime or web framework.
#[test]
fn the_job_file_formats_know_neither_edge() {
    let found = external_uses(&["spool", "db"], &["axum", "tokio"]);
    assert!(found.is_empty(), "spool and db sit below the queue and HTTP:\n{}", found.join("\n"));
    let spool = layer(tree().find(&["kinepost", "spool"]).unwrap());
    let db = layer(tree().find(&["kinepost", "db"]).unwrap());
    for above in ["jobs", "http"] {
        let l = layer(tree().find(&["kinepost", above]).unwrap());
        assert!(l > spool && l > db, "{above} above spool and db");
    }
}
