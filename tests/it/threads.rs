//! A post on two threads writes what it writes on one, byte for byte: the NC, the NDJSON
//! diagnostics, the summary, every call a sink gets (tools, poses of unreachable points), and
//! the same error at the same place when a post fails mid-way (strict mode, the budget, a sink
//! or a reader that fails), without a hang or a thread left behind.

use crate::common;

use kinepost::collide::ToolShape;
use kinepost::diag::Diagnostic;
use kinepost::kinematics::{Machine, Pose};
use kinepost::machines::Library;
use kinepost::output::FileSink;
use kinepost::post::{self, BlockInfo, Budget, Mode, Options, Sink, Summary};
use std::path::{Path, PathBuf};

/// The tests of this file one at a time: the leak check counts the process's threads by name.
use crate::common::TWO_THREAD_POSTS as ONE_AT_A_TIME;

/// Everything a post hands its sink: the NC and NDJSON as the CLI and jobs write them, and the
/// calls those files do not show. `fail_at`: the line at which writing fails (a full disk).
struct Everything {
    files: FileSink<Vec<u8>, Vec<u8>>,
    calls: String,
    lines: usize,
    fail_at: Option<usize>,
}

impl Everything {
    fn new(fail_at: Option<usize>) -> Everything {
        Everything {
            files: FileSink::new(Vec::new(), Some(Vec::new())),
            calls: String::new(),
            lines: 0,
            fail_at,
        }
    }
}

impl Sink for Everything {
    fn line(&mut self, text: &str, block: Option<&BlockInfo>) -> Result<(), kinepost::post::Stop> {
        self.lines += 1;
        if self.fail_at == Some(self.lines) {
            return Err(std::io::Error::other("disk full").into());
        }
        self.files.line(text, block)
    }
    fn diagnostic(&mut self, d: &Diagnostic) -> Result<(), kinepost::post::Stop> {
        self.files.diagnostic(d)
    }
    fn diagnostic_at(&mut self, d: &Diagnostic, pose: &Pose) -> Result<(), kinepost::post::Stop> {
        self.calls += &format!("at {:?} {:?}\n", pose.tip, pose.axis);
        self.files.diagnostic_at(d, pose)
    }
    fn summary(&mut self, s: &Summary) -> Result<(), kinepost::post::Stop> {
        self.files.summary(s)
    }
    fn tool(&mut self, first_block: u64, t: &ToolShape) {
        self.calls += &format!("tool {first_block} {t:?}\n");
    }
}

/// What one post left: the NC, the NDJSON, the other calls, and its result.
#[derive(Debug, PartialEq)]
struct Outcome {
    nc: String,
    ndjson: String,
    calls: String,
    result: String,
}

fn post_with(input: impl std::io::BufRead + Send, m: &Machine, o: &Options, threads: usize, fail_at: Option<usize>) -> Outcome {
    let mut o = o.clone();
    o.threads = threads;
    let mut sink = Everything::new(fail_at);
    let r = post::post(input, m, &o, &mut sink);
    let result = match r {
        Ok(s) => format!("ok {}", serde_json::to_string(&s).unwrap()),
        Err(e) => format!("error {e:?}"),
    };
    let calls = sink.calls;
    let (nc, nd) = sink.files.into_inner().unwrap();
    Outcome {
        nc: String::from_utf8(nc).unwrap(),
        ndjson: String::from_utf8(nd.unwrap()).unwrap(),
        calls,
        result,
    }
}

/// Posts `cl` on one thread and on two; they must agree in everything. Returns the outcome.
fn same(what: &str, cl: &[u8], m: &Machine, o: &Options, fail_at: Option<usize>) -> Outcome {
    let one = post_with(cl, m, o, 1, fail_at);
    let two = post_with(cl, m, o, 2, fail_at);
    if one != two {
        let first = one.nc.lines().zip(two.nc.lines()).position(|(a, b)| a != b);
        panic!(
            "{what}: two threads differ from one (first NC line differing: {first:?}; results {} / {})",
            one.result, two.result
        );
    }
    one
}

fn generated(m: &Machine, points: usize, seed: u64) -> Vec<u8> {
    let mut cl = Vec::new();
    kinepost::testgen::write_path(m, points, seed, m.default_tool_length, &mut cl).unwrap();
    cl
}

fn profile_options(lib: &Library, id: &str, mode: Mode) -> Options {
    let p = lib.get(id).unwrap();
    let mut o = post::Settings::default().profile_options(&p, None).unwrap();
    o.mode = mode;
    o
}

/// Threads of this process named `name`, once they had a moment to exit: a scope's join
/// returns when a thread's closure ends, a moment before the thread itself is gone.
fn threads_named(name: &str) -> usize {
    let count = || {
        std::fs::read_dir("/proc/self/task")
            .map(|d| {
                d.filter_map(|t| std::fs::read_to_string(t.ok()?.path().join("comm")).ok())
                    .filter(|c| c.trim() == name)
                    .count()
            })
            .unwrap_or(0)
    };
    for _ in 0..200 {
        if count() == 0 {
            return 0;
        }
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    count()
}

#[test]
fn generated_paths_on_every_profile_in_both_modes() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let lib = common::library();
    for p in lib.iter() {
        let m = &p.machine;
        // Long enough for several planner commits and several batches (the three-rotary IK
        // is slow in a debug build: fewer there).
        let points = if m.rotaries.len() > 2 { 400 } else { 2500 };
        let cl = generated(m, points, 7);
        for mode in [Mode::Joint, Mode::Tcp] {
            let o = profile_options(&lib, &m.id, mode);
            let out = same(&format!("{} {mode:?}", m.id), &cl, m, &o, None);
            assert!(out.result.starts_with("ok"), "{}: {}", m.id, out.result);
            assert!(out.nc.lines().count() > points, "{}", m.id);
        }
    }
    assert_eq!(threads_named("kinepost-read"), 0, "a reading thread left running");
}

fn corpus() -> Vec<PathBuf> {
    let dir = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data"));
    let mut files = Vec::new();
    for d in [dir.to_path_buf(), dir.join("generated")] {
        for e in std::fs::read_dir(d).unwrap() {
            let p = e.unwrap().path();
            if matches!(p.extension().and_then(|x| x.to_str()), Some("cls" | "ncl")) {
                files.push(p);
            }
        }
    }
    files.sort();
    files
}

/// Every corpus file on machines of each kind (table-table, head-table, head-head; most files
/// unreachable somewhere: errors, repositions, tool changes), in both modes, and with canned
/// cycles and tilted planes (their look-ahead).
#[test]
fn corpus_files_on_each_kind_of_machine_in_both_modes() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let lib = common::library();
    let files = corpus();
    assert!(files.len() >= 8, "{files:?}");
    let mut errors = 0;
    for f in &files {
        let cl = std::fs::read(f).unwrap();
        for id in ["spinner-u5-620", "dmg-dmc75v", "fryer-5x-45", "vmc-3axis"] {
            let p = lib.get(id).unwrap();
            for mode in [Mode::Joint, Mode::Tcp] {
                let mut o = profile_options(&lib, &p.machine.id, mode);
                let what = format!("{} on {} {mode:?}", f.display(), p.machine.id);
                let out = same(&what, &cl, &p.machine, &o, None);
                errors += out.ndjson.matches("\"severity\":\"error\"").count();
                if mode == Mode::Joint {
                    (o.canned_cycles, o.tilted_planes) = (true, true);
                    same(&format!("{what}, cycles and planes"), &cl, &p.machine, &o, None);
                }
            }
        }
    }
    assert!(errors > 0, "the corpus on foreign machines has errors to compare too");
}

/// A generated path with malformed records, a zero tool axis and poses no machine reaches.
fn damaged(m: &Machine) -> Vec<u8> {
    let text = String::from_utf8(generated(m, 3000, 3)).unwrap();
    let mut out = String::new();
    for (k, line) in text.lines().enumerate() {
        out += line;
        out.push('\n');
        match k % 700 {
            100 => out += "GOTO/1.0,2.0,abc,0,0,1\n",
            200 => out += "GOTO/0,0,0,0,0,0\n",
            300 => out += "GOTO/99999,99999,99999,0,0,1\n",
            400 => out += "FEDRAT/\n",
            500 => out += "GOTO/10,10,10,1,0,0\n",
            _ => {}
        }
    }
    out.into_bytes()
}

#[test]
fn inputs_with_errors_and_strict_mode_stop_at_the_same_place() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let lib = common::library();
    for id in ["spinner-u5-620", "dmg-dmc75v", "haas-umc750", "vmc-3axis"] {
        let m = &lib.get(id).unwrap().machine;
        let cl = damaged(m);
        for mode in [Mode::Joint, Mode::Tcp] {
            let mut o = profile_options(&lib, id, mode);
            let out = same(&format!("{id} {mode:?} damaged"), &cl, m, &o, None);
            assert!(out.ndjson.contains("\"severity\":\"error\""), "{id}: errors expected");
            o.strict = true;
            let out = same(&format!("{id} {mode:?} damaged, strict"), &cl, m, &o, None);
            assert!(out.result.starts_with("error Strict"), "{id}: {}", out.result);
        }
    }
    // Input that is no CL is refused the same way.
    let m = &lib.get("spinner-u5-620").unwrap().machine;
    let o = profile_options(&lib, "spinner-u5-620", Mode::Joint);
    let out = same("NC input", b"G0 X1 Y2\nG1 X3\n".repeat(40).as_slice(), m, &o, None);
    assert!(out.result.starts_with("error NotCl"), "{}", out.result);
    assert_eq!(threads_named("kinepost-read"), 0, "a reading thread left running");
}

/// A reader that fails after `left` bytes (a dropped upload).
struct Failing<'a> {
    data: &'a [u8],
    left: usize,
}

impl std::io::Read for Failing<'_> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        if self.left == 0 {
            return Err(std::io::Error::other("connection reset"));
        }
        let n = buf.len().min(self.left).min(self.data.len());
        buf[..n].copy_from_slice(&self.data[..n]);
        (self.data, self.left) = (&self.data[n..], self.left - n);
        Ok(n)
    }
}

#[test]
fn posts_failing_mid_way_fail_the_same_and_leave_no_thread() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let lib = common::library();
    let m = &lib.get("spinner-u5-620").unwrap().machine;
    // Long enough that the reading half is far ahead, blocked on a full queue, when the
    // emitting half stops.
    let cl = generated(m, 30_000, 11);
    let mut o = profile_options(&lib, "spinner-u5-620", Mode::Joint);
    // The sink fails (a full disk) early, mid-way, near the end.
    for at in [3, 5000, 25_000] {
        let t = std::time::Instant::now();
        let out = same(&format!("sink failing at line {at}"), &cl, m, &o, Some(at));
        assert!(out.result.contains("disk full"), "{}", out.result);
        assert!(t.elapsed().as_secs() < 60, "a failed post took {:?}", t.elapsed());
    }
    // The budget: the output bound mid-way.
    o.budget = Budget {
        floor_blocks: 12_000,
        blocks_per_byte: 0,
        seconds: f64::INFINITY,
    };
    let out = same("output bound", &cl, m, &o, None);
    assert!(out.result.starts_with("error Stop(Budget"), "{}", out.result);
    o.budget = Budget::default();
    // The reader fails mid-way.
    for left in [100_000, 1_500_000] {
        let one = post_with(std::io::BufReader::new(Failing { data: &cl, left }), m, &o, 1, None);
        let two = post_with(std::io::BufReader::new(Failing { data: &cl, left }), m, &o, 2, None);
        assert_eq!(one, two, "reader failing after {left} bytes");
        assert!(one.result.contains("connection reset"), "{}", one.result);
    }
    assert_eq!(threads_named("kinepost-read"), 0, "a reading thread left running");
}

/// Each edge chooses a post's threads (the CLI's `--threads`, the server's configuration): a
/// request cannot; every choice is checked by the one function.
#[test]
fn threads_are_one_or_two() {
    let with = post::threads;
    assert_eq!(with(None), Ok(1));
    assert_eq!(with(Some(1)), Ok(1));
    assert_eq!(with(Some(2)), Ok(2));
    for bad in [0, 3, 64] {
        let e = with(Some(bad)).unwrap_err();
        assert!(e.contains("threads") && e.contains("1 or 2"), "{e}");
    }
}
