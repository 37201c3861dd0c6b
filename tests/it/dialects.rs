//! Controller dialects: golden programs per dialect (compared within a tolerance;
//! `KINEPOST_UPDATE_GOLDEN=1` rewrites them), and the ISO dialects read back by an independent
//! G-code parser (the `gcode` crate).

use crate::common;

use common::collect::Collect;
use kinepost::post::{self, BlockInfo, Mode, Options, Sink};
use std::path::Path;

/// (dialect, the machine it is shown on)
const CASES: [(&str, &str); 5] = [
    ("fanuc", "spinner-u5-620"),
    ("haas", "haas-umc750"),
    ("siemens", "dmu-nutating-45"),
    ("heidenhain", "dmg-dmc75v"),
    ("linuxcnc", "vmc-4axis-a"),
];

fn program(dialect: &str, machine: &str, mode: Mode, points: usize) -> Collect {
    let lib = common::library();
    let m = lib.get(machine).unwrap().machine.clone();
    let mut cl = Vec::new();
    kinepost::testgen::write_path(&m, points, 11, m.default_tool_length, &mut cl).unwrap();
    let mut o = Options::new(&m);
    o.mode = mode;
    o.dialect = kinepost::nc::dialect(dialect).unwrap();
    let mut sink = Collect::default();
    post::post(&cl[..], &m, &o, &mut sink).unwrap();
    sink
}

/// Splits a line into text and numbers; numbers compare within 2 units of their last decimal
/// place (rounding may differ across platforms' last bits), text exactly.
fn tokens(line: &str) -> Vec<(String, Option<(f64, f64)>)> {
    let mut out = Vec::new();
    let mut rest = line;
    while !rest.is_empty() {
        let start = rest.find(|c: char| c.is_ascii_digit()).unwrap_or(rest.len());
        let (mut text_end, mut num_start) = (start, start);
        if start > 0 && matches!(rest.as_bytes()[start - 1], b'-' | b'+') {
            text_end = start - 1;
            num_start = start - 1;
        }
        if text_end > 0 || num_start == rest.len() {
            out.push((rest[..text_end].to_string(), None));
        }
        if num_start == rest.len() {
            break;
        }
        let tail = &rest[num_start..];
        let len = tail
            .char_indices()
            .skip(1)
            .find(|(_, c)| !(c.is_ascii_digit() || *c == '.'))
            .map_or(tail.len(), |(i, _)| i);
        let num = &tail[..len];
        let dec = num.split('.').nth(1).map_or(0, str::len);
        out.push((
            String::new(),
            num.parse::<f64>().ok().map(|v| (v, 2.0 * 10f64.powi(-(dec as i32)))),
        ));
        rest = &tail[len..];
    }
    out
}

/// Compares a program with `tests/golden/{name}` within output rounding (the version line left
/// out); `KINEPOST_UPDATE_GOLDEN=1` rewrites the file.
fn assert_golden(name: &str, got: &str) {
    let path = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/golden")).join(name);
    // The version line changes with every release: not part of the comparison.
    let strip = |s: &str| {
        s.lines()
            .filter(|l| !l.contains("KINEPOST "))
            .map(str::to_string)
            .collect::<Vec<_>>()
    };
    if std::env::var("KINEPOST_UPDATE_GOLDEN").is_ok() {
        std::fs::write(&path, got).unwrap();
    }
    let want = std::fs::read_to_string(&path).unwrap_or_else(|_| panic!("{name} missing: KINEPOST_UPDATE_GOLDEN=1 writes it"));
    let (g, w) = (strip(got), strip(&want));
    assert_eq!(g.len(), w.len(), "{name}: line count");
    for (i, (a, b)) in g.iter().zip(&w).enumerate() {
        let (ta, tb) = (tokens(a), tokens(b));
        let same = ta.len() == tb.len()
            && ta.iter().zip(&tb).all(|(x, y)| match (&x.1, &y.1) {
                (Some((va, tol)), Some((vb, _))) => (va - vb).abs() <= *tol,
                (None, None) => x.0 == y.0,
                _ => false,
            });
        assert!(same, "{name} line {}: got {a:?}, golden {b:?}", i + 1);
    }
}

#[test]
fn golden_programs_per_dialect() {
    for (d, m) in CASES {
        for mode in [Mode::Joint, Mode::Tcp] {
            let name = format!("{d}-{m}-{}.nc", if mode == Mode::Joint { "joint" } else { "tcp" });
            assert_golden(&name, &program(d, m, mode, 40).nc);
        }
    }
}

/// An ISO program without its tape frame (`%`, `O` number), which the `gcode` crate does not read.
fn tape_body(nc: &str) -> String {
    nc.lines()
        .filter(|l| !l.starts_with(['%', 'O']))
        .map(|l| format!("{l}\n"))
        .collect()
}

#[test]
fn iso_dialects_read_back_with_an_independent_gcode_parser() {
    for (d, m) in [
        ("fanuc", "spinner-u5-620"),
        ("haas", "haas-umc750"),
        ("linuxcnc", "vmc-4axis-a"),
    ] {
        for mode in [Mode::Joint, Mode::Tcp] {
            let p = program(d, m, mode, 120);
            let mut motions = 0;
            let mut modal = [None::<f32>; 6];
            let text = tape_body(&p.nc);
            let prog = gcode::parse(&text).unwrap_or_else(|e| panic!("{d} {m}: the gcode crate rejects our program: {e:?}"));
            for block in &prog.blocks {
                // G53: machine coordinates, not a block of the program's (no joints of ours).
                let g53 = |g: &gcode::GeneralCode| {
                    let n: String = g.to_string()[1..]
                        .chars()
                        .take_while(|c| c.is_ascii_digit() || *c == '.')
                        .collect();
                    n.parse::<f64>() == Ok(53.0)
                };
                if block.codes.iter().any(|c| matches!(c, gcode::Code::General(g) if g53(g))) {
                    modal = [None; 6];
                    continue;
                }
                let mut axis_words = false;
                let mut words: Vec<&gcode::Argument> = Vec::new();
                for c in &block.codes {
                    match c {
                        gcode::Code::General(g) => words.extend(&g.args),
                        gcode::Code::Miscellaneous(x) => words.extend(&x.args),
                        gcode::Code::ToolChange(t) => words.extend(&t.args),
                        _ => {}
                    }
                }
                let mut set = |letter: char, value: &gcode::Value| {
                    if let (Some(k), gcode::Value::Literal(v)) = ("XYZABC".find(letter), value) {
                        modal[k] = Some(*v);
                        axis_words = true;
                    }
                };
                for w in words {
                    set(w.letter, &w.value);
                }
                for w in &block.word_addresses {
                    set(w.letter, &w.value);
                }
                if axis_words {
                    motions += 1;
                    let b = &p.blocks[motions - 1];
                    for (k, want) in b.joints.0.iter().enumerate() {
                        if let Some(want) = want {
                            let got =
                                modal[k].unwrap_or_else(|| panic!("{d}: {} never set", "XYZABC".as_bytes()[k] as char)) as f64;
                            // Output rounding (half a unit in the last place: 3/4 decimals) plus f32.
                            let last = if k < 3 {
                                if m == "haas-umc750" { 1e-4 } else { 1e-3 }
                            } else {
                                1e-4
                            };
                            let tol = 0.5 * last + 1e-9 + 4.0 * f32::EPSILON as f64 * want.abs();
                            assert!((got - want).abs() <= tol, "{d} {m}: {block}: {got} vs {want}");
                        }
                    }
                }
            }
            assert_eq!(motions, p.blocks.len(), "{d} {m} {mode:?}: every motion block parsed");
        }
    }
}

/// Every word of a line as (letter, value): `X+12.500` and `X12.5` alike; `DR+` is ('D', None).
fn words(line: &str) -> Vec<(char, Option<f64>)> {
    line.split_whitespace()
        .filter_map(|w| {
            let mut c = w.chars();
            let l = c.next()?;
            Some((l, c.as_str().parse::<f64>().ok()))
        })
        .collect()
}

/// The same corpus arcs on the same machine, as Fanuc `G2/G3 I J` and as Heidenhain `CC` + `C`:
/// the same arcs, the same ends, the same turning sense, and every `C` block truly on its circle.
#[test]
fn heidenhain_arcs_are_the_iso_arcs_as_cc_and_c() {
    let lib = common::library();
    let m = lib.get("dmg-dmc75v").unwrap().machine.clone();
    let mut total = 0;
    for file in [
        "nx_clsf_mech491_simple_mill_plane_mm.cls",
        "nx_clsf_mech491_simple_mill_plane_zig_mm.cls",
        "creo8_ncl_profilfraesen_profile_mm.ncl",
    ] {
        let cl = std::fs::read(Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data")).join(file)).unwrap();
        let run = |d: &str| {
            let mut o = Options::new(&m);
            o.dialect = kinepost::nc::dialect(d).unwrap();
            let mut sink = Collect::default();
            post::post(&cl[..], &m, &o, &mut sink).unwrap();
            sink.nc
        };
        // ISO: (ccw, end x, end y) of each arc.
        let mut iso = Vec::new();
        let mut g = 0.0;
        for line in run("fanuc").lines() {
            let w = words(line);
            for (l, v) in &w {
                if *l == 'G' && matches!(v, Some(x) if [0.0, 1.0, 2.0, 3.0].contains(x)) {
                    g = v.unwrap();
                }
            }
            let at = |k: char| w.iter().find(|(l, _)| *l == k).and_then(|(_, v)| *v);
            if (g == 2.0 || g == 3.0) && at('X').is_some() {
                iso.push((g == 3.0, at('X').unwrap(), at('Y').unwrap()));
            }
        }
        // Heidenhain: track the position; each C checked against its CC.
        let (mut pos, mut cc) = ([f64::NAN; 2], None::<[f64; 2]>);
        let mut hh = Vec::new();
        for line in run("heidenhain").lines() {
            let toks: Vec<&str> = line.split_whitespace().skip(1).collect();
            let w = words(&toks.join(" "));
            let at = |k: char| w.iter().skip(1).find(|(l, _)| *l == k).and_then(|(_, v)| *v);
            match toks.first() {
                Some(&"CC") => cc = Some([at('X').unwrap(), at('Y').unwrap()]),
                Some(&"C") => {
                    let c = cc.take().expect("a C block follows its CC");
                    let end = [at('X').unwrap_or(pos[0]), at('Y').unwrap_or(pos[1])];
                    let r0 = ((pos[0] - c[0]).powi(2) + (pos[1] - c[1]).powi(2)).sqrt();
                    let r1 = ((end[0] - c[0]).powi(2) + (end[1] - c[1]).powi(2)).sqrt();
                    assert!(
                        (r0 - r1).abs() < 2e-3,
                        "{file}: {line}: radius {r0} at the start, {r1} at the end"
                    );
                    assert!(at('Z').is_none(), "a flat arc names no Z: {line}");
                    let ccw = toks.contains(&"DR+");
                    assert!(ccw || toks.contains(&"DR-"), "{line}");
                    hh.push((ccw, end[0], end[1]));
                    pos = end;
                }
                Some(&"L") => {
                    pos = [at('X').unwrap_or(pos[0]), at('Y').unwrap_or(pos[1])];
                }
                _ => {}
            }
        }
        assert!(!iso.is_empty(), "{file} has arcs");
        assert_eq!(iso.len(), hh.len(), "{file}: every ISO arc is a Heidenhain arc");
        for (a, b) in iso.iter().zip(&hh) {
            assert_eq!(a.0, b.0, "{file}: the same turning sense");
            assert!((a.1 - b.1).abs() < 1e-3 && (a.2 - b.2).abs() < 1e-3, "{file}: {a:?} vs {b:?}");
        }
        total += hh.len();
    }
    assert_eq!(total, 52);
}

/// Holes on the top face (drill, a deeper one, peck, spot with dwell; G98 and G99 returns) and on
/// a face tilted 45° about X, then a cut. Written for these tests.
const HOLES: &str = "PARTNO/CANNED CYCLES
UNITS/MM
LOADTL/1
SPINDL/RPM,3000,CLW
FEDRAT/MMPM,1000
RAPID
GOTO/0,0,50,0,0,1
CYCLE/DRILL,FEDTO,5,MMPM,200,RAPTO,3,RTRCTO,25
GOTO/10,10,0,0,0,1
GOTO/20,10,0,0,0,1
GOTO/30,10,-2,0,0,1
CYCLE/OFF
CYCLE/DEEP,FEDTO,30,STEP,4,MMPM,150,RAPTO,2
GOTO/10,-10,0,0,0,1
GOTO/20,-10,0,0,0,1
CYCLE/OFF
CYCLE/DRILL,FEDTO,3,MMPM,100,RAPTO,2,RTRCTO,20,DWELL,0.5
GOTO/40,0,0,0,0,1
CYCLE/OFF
RAPID
GOTO/0,-60,60,0,-0.70710678,0.70710678
CYCLE/DRILL,FEDTO,8,MMPM,200,RAPTO,3,RTRCTO,15
GOTO/0,-20,10,0,-0.70710678,0.70710678
GOTO/10,-20,10,0,-0.70710678,0.70710678
CYCLE/OFF
RAPID
GOTO/10,-60,60,0,-0.70710678,0.70710678
FEDRAT/MMPM,500
GOTO/10,-30,30,0,-0.70710678,0.70710678
END
FINI
";

fn canned(machine: &str, dialect: Option<&str>, mode: Mode) -> (Collect, post::Summary, Vec<kinepost::diag::Diagnostic>) {
    #[derive(Default)]
    struct WithDiags(Collect, Vec<kinepost::diag::Diagnostic>);
    impl Sink for WithDiags {
        fn line(&mut self, text: &str, b: Option<&BlockInfo>) -> Result<(), kinepost::post::Stop> {
            if let Some(b) = b {
                self.1.extend(b.diagnostics.iter().cloned());
            }
            self.0.line(text, b)
        }
        fn diagnostic(&mut self, d: &kinepost::diag::Diagnostic) -> Result<(), kinepost::post::Stop> {
            self.1.push(d.clone());
            Ok(())
        }
    }
    let lib = common::library();
    let m = lib.get(machine).unwrap().machine.clone();
    let mut o = Options::new(&m);
    o.mode = mode;
    o.canned_cycles = true;
    if let Some(d) = dialect {
        o.dialect = kinepost::nc::dialect(d).unwrap();
    }
    let mut sink = WithDiags::default();
    let s = post::post(HOLES.as_bytes(), &m, &o, &mut sink).unwrap();
    (sink.0, s, sink.1)
}

/// One hole as a control drills it: position, Z of top (where known), R plane, bottom, the level
/// it returns to, feed, peck, dwell (seconds).
#[derive(Clone, Copy, Debug, PartialEq)]
struct DrilledHole {
    x: f64,
    y: f64,
    r: f64,
    bottom: f64,
    back: f64,
    feed: f64,
    peck: f64,
    dwell: f64,
}

/// Random joints from `next` (values in [0, 1)): each linear at `from + span × next` of its
/// travel, bounded rotaries in the middle 70 % of theirs, unbounded ones anywhere.
fn random_joints(
    m: &kinepost::kinematics::Machine,
    (from, span): (f64, f64),
    next: &mut dyn FnMut() -> f64,
) -> kinepost::kinematics::Joints {
    let mut j = kinepost::kinematics::Joints::default();
    for i in 0..3 {
        if let Some(l) = &m.linears[i] {
            j.linear[i] = l.min + (from + span * next()) * (l.max - l.min);
        }
    }
    for (i, r) in m.rotaries.iter().enumerate() {
        j.rotary[i] = match r.limits {
            Some((lo, hi)) => lo + (0.15 + 0.7 * next()) * (hi - lo),
            None => (next() * 2.0 - 1.0) * std::f64::consts::PI,
        };
    }
    j
}

/// The holes of an ISO program: G81/G82/G83 blocks and the X/Y blocks that repeat them.
fn iso_holes(nc: &str, dwell_ms: bool) -> Vec<DrilledHole> {
    let (mut out, mut on, mut z, mut g98) = (Vec::new(), None::<DrilledHole>, f64::NAN, true);
    for line in nc.lines() {
        let w = words(line);
        let at = |k: char| w.iter().find(|(l, _)| *l == k).and_then(|(_, v)| *v);
        let gs: Vec<f64> = w.iter().filter(|(l, _)| *l == 'G').filter_map(|(_, v)| *v).collect();
        if gs.contains(&98.0) {
            g98 = true;
        }
        if gs.contains(&99.0) {
            g98 = false;
        }
        if gs.iter().any(|g| [0.0, 1.0, 80.0].contains(g)) {
            on = None;
        }
        if let Some(&g) = gs.iter().find(|g| [81.0, 82.0, 83.0].contains(*g)) {
            let r = at('R').unwrap();
            on = Some(DrilledHole {
                x: f64::NAN,
                y: f64::NAN,
                r,
                bottom: at('Z').unwrap(),
                back: if g98 { z } else { r },
                feed: at('F').unwrap(),
                peck: if g == 83.0 { at('Q').unwrap() } else { 0.0 },
                dwell: if g == 82.0 {
                    at('P').unwrap() / if dwell_ms { 1000.0 } else { 1.0 }
                } else {
                    0.0
                },
            });
        } else if on.is_none()
            && let Some(v) = at('Z')
        {
            z = v;
        }
        if let Some(h) = on.as_mut()
            && (at('X').is_some() || at('Y').is_some())
        {
            h.x = at('X').unwrap_or(h.x);
            h.y = at('Y').unwrap_or(h.y);
            out.push(*h);
        }
    }
    out
}

/// The holes of a Siemens program: `MCALL CYCLE8x(…)` and the positions that call it.
fn siemens_holes(nc: &str) -> Vec<DrilledHole> {
    let (mut out, mut on, mut feed) = (Vec::new(), None::<DrilledHole>, f64::NAN);
    let (mut x, mut y) = (f64::NAN, f64::NAN);
    for line in nc.lines() {
        if let Some(args) = line.strip_prefix("MCALL CYCLE") {
            let n: u32 = args[..2].parse().unwrap();
            let a: Vec<f64> = args[3..args.len() - 1].split(',').map(|v| v.parse().unwrap_or(0.0)).collect();
            on = Some(DrilledHole {
                x: f64::NAN,
                y: f64::NAN,
                r: a[1] + a[2],
                bottom: a[3],
                back: a[0],
                feed,
                peck: if n == 83 { a[1] - a[5] } else { 0.0 },
                dwell: if n == 82 { a[5] } else { 0.0 },
            });
            continue;
        }
        if line == "MCALL" {
            on = None;
        }
        let w = words(line);
        let at = |k: char| w.iter().find(|(l, _)| *l == k).and_then(|(_, v)| *v);
        feed = at('F').unwrap_or(feed);
        x = at('X').unwrap_or(x);
        y = at('Y').unwrap_or(y);
        if let Some(h) = on.as_mut()
            && (at('X').is_some() || at('Y').is_some())
        {
            (h.x, h.y) = (x, y);
            out.push(*h);
        }
    }
    out
}

/// The holes of a Heidenhain program: `CYCL DEF 200` with its Q parameters, called by `M99`.
fn heidenhain_holes(nc: &str) -> Vec<DrilledHole> {
    let (mut out, mut q) = (Vec::new(), std::collections::HashMap::<u32, f64>::new());
    let (mut x, mut y) = (f64::NAN, f64::NAN);
    for line in nc.lines() {
        if let Some(rest) = line.trim().strip_prefix('Q') {
            let (n, v) = rest.split_once('=').unwrap();
            let v = v.split_whitespace().next().unwrap();
            q.insert(n.parse().unwrap(), v.parse().unwrap());
            continue;
        }
        let toks: Vec<&str> = line.split_whitespace().skip(1).collect();
        if toks.first() != Some(&"L") {
            continue;
        }
        let w = words(&toks[1..].join(" "));
        let at = |k: char| w.iter().find(|(l, _)| *l == k).and_then(|(_, v)| *v);
        x = at('X').unwrap_or(x);
        y = at('Y').unwrap_or(y);
        if toks.contains(&"M99") {
            let top = q[&203];
            out.push(DrilledHole {
                x,
                y,
                r: top + q[&200],
                bottom: top + q[&201],
                back: top + q[&204],
                feed: q[&206],
                peck: if q[&202] < -q[&201] { q[&202] } else { 0.0 },
                dwell: q[&211],
            });
        }
    }
    out
}

fn same_holes(what: &str, got: &[DrilledHole], want: &[DrilledHole]) {
    assert_eq!(got.len(), want.len(), "{what}: {got:?}");
    for (g, w) in got.iter().zip(want) {
        let close = |a: f64, b: f64| (a - b).abs() <= 2e-3;
        let ok = close(g.x, w.x)
            && close(g.y, w.y)
            && close(g.r, w.r)
            && close(g.bottom, w.bottom)
            && close(g.back, w.back)
            && close(g.feed, w.feed)
            && close(g.peck, w.peck)
            && close(g.dwell, w.dwell);
        assert!(ok, "{what}: {g:?}, Fanuc drills {w:?}");
    }
}

/// Canned output on every profile: the ISO, Siemens and Heidenhain programs replayed through
/// `kinepost verify` (its reader expands G81/G82/G83, `MCALL CYCLE81/82/83` and `CYCL DEF 200`
/// with `M99` into the moves a control makes) reach every CL point; holes that run along the
/// machine's Z are cycles, the rest stay moves and say why.
#[test]
fn canned_cycles_reach_every_hole_on_every_profile() {
    use kinepost::post::verify::{VerifyOptions, verify};
    let lib = common::library();
    // Holes drilled as cycles per profile: tables turn the part under a fixed Z spindle (all 8);
    // where a head tilts the tool (head-table, head-head, the 3-rotary machine's inner rotaries)
    // only the 6 top-face holes run along Z.
    for (id, want) in [
        ("spinner-u5-620", 8),
        ("haas-umc750", 8),
        ("mikron-ucp710", 8),
        ("dmu-nutating-45", 8),
        ("vmc-4axis-a", 8),
        ("dmg-dmc75v", 6),
        ("fryer-5x-45", 6),
        ("propeller-3r2l", 6),
    ] {
        let p = lib.get(id).unwrap();
        let m = &p.machine;
        // Siemens' `MCALL CYCLE8x` and Heidenhain's `CYCL DEF 200` … `M99` holes are read back
        // too (not ISO: no `iso_holes`).
        for d in ["fanuc", "haas", "linuxcnc", "siemens", "heidenhain"] {
            let (sink, sum, diags) = canned(id, Some(d), Mode::Joint);
            assert_eq!(sum.errors, 0, "{id} {d}: {diags:?}");
            assert_eq!(sum.canned_holes, want, "{id} {d}");
            if d == "siemens" {
                assert!(sink.nc.contains("MCALL CYCLE8"), "{id}:\n{}", sink.nc);
            } else if d == "heidenhain" {
                assert!(
                    sink.nc.contains("CYCL DEF 200") && sink.nc.contains("M99"),
                    "{id}:\n{}",
                    sink.nc
                );
            } else {
                assert_eq!(iso_holes(&sink.nc, d == "fanuc").len() as u64, want, "{id} {d}:\n{}", sink.nc);
            }
            if want < 8 {
                assert!(
                    diags.iter().any(|x| x.message.contains("does not run along the machine's Z")),
                    "{id}: {diags:?}"
                );
            }
            let vo = VerifyOptions {
                mode: Mode::Joint,
                setup: kinepost::kinematics::Setup::new(sum.tool_length, kinepost::kinematics::Vec3::zeros()),
                tolerance: if m.units == kinepost::kinematics::Units::Mm {
                    0.01
                } else {
                    0.0004
                },
                angle_tolerance_deg: 0.01,
                cl_units: None,
                cl_tool_length: true,
                tool_table: None,
            };
            let r = verify(HOLES.as_bytes(), sink.nc.as_bytes(), m, &vo).unwrap();
            assert!(r.ok && r.matched == 12, "{id} {d}: {r:?}\n{}", sink.nc);
        }
    }
}

/// Siemens and Heidenhain write the same holes as Fanuc (which the test above replays through
/// FK): same positions, levels, feed, peck and dwell. Golden files keep their form.
#[test]
fn every_dialect_drills_the_same_holes() {
    let (fanuc, ..) = canned("spinner-u5-620", Some("fanuc"), Mode::Joint);
    let want = iso_holes(&fanuc.nc, true);
    // The independent parser reads the cycle blocks' words as ours do.
    let text = tape_body(&fanuc.nc);
    let prog = gcode::parse(&text).unwrap_or_else(|e| panic!("the gcode crate rejects our cycles: {e:?}"));
    let g8x: Vec<String> = prog
        .blocks
        .iter()
        .map(|b| b.to_string())
        .filter(|b| b.contains("G81") || b.contains("G82") || b.contains("G83"))
        .collect();
    assert_eq!(g8x.len(), 5, "{g8x:?}");
    assert_eq!(want.len(), 8);
    assert!(want.iter().any(|h| h.peck > 0.0) && want.iter().any(|h| h.dwell > 0.0));
    assert!(
        want.iter().any(|h| h.back > h.r + 1.0) && want.iter().any(|h| h.back == h.r),
        "G98 and G99"
    );
    for d in ["haas", "linuxcnc"] {
        same_holes(
            d,
            &iso_holes(&canned("spinner-u5-620", Some(d), Mode::Joint).0.nc, false),
            &want,
        );
    }
    same_holes(
        "siemens",
        &siemens_holes(&canned("spinner-u5-620", Some("siemens"), Mode::Joint).0.nc),
        &want,
    );
    same_holes(
        "heidenhain",
        &heidenhain_holes(&canned("spinner-u5-620", Some("heidenhain"), Mode::Joint).0.nc),
        &want,
    );
    for d in ["fanuc", "siemens", "heidenhain"] {
        assert_golden(
            &format!("cycles-{d}-spinner-u5-620.nc"),
            &canned("spinner-u5-620", Some(d), Mode::Joint).0.nc,
        );
    }
}

/// A wrong canned cycle is caught: an R plane below the hole's top never reaches the CL point,
/// a moved repeat hole misses its own.
#[test]
fn verify_catches_a_wrong_canned_cycle() {
    use kinepost::post::verify::{VerifyOptions, verify};
    let lib = common::library();
    let m = lib.get("spinner-u5-620").unwrap().machine.clone();
    let (sink, sum, _) = canned("spinner-u5-620", Some("fanuc"), Mode::Joint);
    let vo = VerifyOptions {
        mode: Mode::Joint,
        setup: kinepost::kinematics::Setup::new(sum.tool_length, kinepost::kinematics::Vec3::zeros()),
        tolerance: 0.01,
        angle_tolerance_deg: 0.01,
        cl_units: None,
        cl_tool_length: true,
        tool_table: None,
    };
    let first = iso_holes(&sink.nc, true)[0];
    let r_word = format!("R{:.3}", first.r);
    let low = sink.nc.replacen(&r_word, &format!("R{:.3}", first.r - 4.0), 1);
    assert_ne!(low, sink.nc);
    let r = verify(HOLES.as_bytes(), low.as_bytes(), &m, &vo).unwrap();
    assert!(!r.ok && r.misses[0].cl_line == 9, "{r:?}");
    // The repeat of the first cycle: the line after it holds only X.
    let lines: Vec<&str> = sink.nc.lines().collect();
    let k = lines.iter().position(|l| l.contains("G81")).unwrap() + 1;
    assert!(lines[k].starts_with('X') && !lines[k].contains('Z'), "{}", lines[k]);
    let moved = sink.nc.replacen(lines[k], &lines[k].replace('X', "X1"), 1);
    let r = verify(HOLES.as_bytes(), moved.as_bytes(), &m, &vo).unwrap();
    assert!(!r.ok && r.misses[0].cl_line == 10, "{r:?}");
}

/// TCP mode keeps drilling cycles as moves (controls refuse most cycles under TCP), and says so.
#[test]
fn canned_cycles_in_tcp_mode_stay_moves() {
    let (_, sum, diags) = canned("spinner-u5-620", None, Mode::Tcp);
    assert_eq!(sum.canned_holes, 0);
    assert_eq!(sum.errors, 0);
    assert!(diags.iter().any(|d| d.message.contains("joint mode only")), "{diags:?}");
}

/// Random holes on every profile: tops at random joint positions inside travel (through FK),
/// random depth, R plane, retract and peck. The canned ISO program replays through FK to every
/// hole; on table-table machines every hole is a cycle, wherever the table is turned.
fn random_holes(id: &str, seed: &[f64]) -> Result<(), proptest::test_runner::TestCaseError> {
    use kinepost::kinematics::{Setup, Units, Vec3};
    use kinepost::post::verify::{VerifyOptions, verify};
    use proptest::prelude::*;
    let lib = common::library();
    let p = lib.get(id).unwrap();
    let m = &p.machine;
    let setup = Setup::new(m.default_tool_length, Vec3::zeros());
    let s = if m.units == Units::Mm { 1.0 } else { 1.0 / 25.4 };
    let mut cl = format!(
        "UNITS/{}\nLOADTL/1\nSPINDL/RPM,3000,CLW\nFEDRAT/{},{}\n",
        if m.units == Units::Mm { "MM" } else { "INCHES" },
        if m.units == Units::Mm { "MMPM" } else { "IPM" },
        500.0 * s
    );
    let mut k = 0;
    let mut next = || {
        k += 1;
        seed[(k - 1) % seed.len()]
    };
    let holes = 3;
    for _ in 0..holes {
        let j = random_joints(m, (0.3, 0.4), &mut next);
        let pose = kinepost::kinematics::fk(m, &j, &setup);
        let (t, u) = (pose.tip, pose.axis);
        let (depth, rapto) = ((1.0 + 9.0 * next()) * s, (1.0 + 4.0 * next()) * s);
        let retract = if next() < 0.5 {
            format!(",RTRCTO,{}", rapto + 15.0 * s * next())
        } else {
            String::new()
        };
        let (kind, peck) = if next() < 0.5 {
            ("DEEP", format!(",STEP,{}", (1.0 + 2.0 * next()) * s))
        } else {
            ("DRILL", String::new())
        };
        cl += &format!(
            "CYCLE/{kind},FEDTO,{depth}{peck},{},{},RAPTO,{rapto}{retract}\nGOTO/{},{},{},{},{},{}\nCYCLE/OFF\n",
            if m.units == Units::Mm { "MMPM" } else { "IPM" },
            200.0 * s,
            t.x,
            t.y,
            t.z,
            u.x,
            u.y,
            u.z
        );
    }
    cl += "END\nFINI\n";
    let post_with = |canned: bool| {
        let mut o = Options::new(m);
        o.dialect = kinepost::nc::dialect("fanuc").unwrap();
        o.canned_cycles = canned;
        let mut sink = Collect::default();
        let sum = post::post(cl.as_bytes(), m, &o, &mut sink).unwrap();
        (sink, sum)
    };
    let (_, expanded) = post_with(false);
    // Tops in the middle of travel, start levels a few mm above: all reachable.
    prop_assert_eq!(expanded.errors, 0, "{}", cl);
    let (sink, sum) = post_with(true);
    prop_assert_eq!(sum.errors, 0, "{}\n{}", cl, sink.nc);
    if m.kinematics_kind() == "table-table" {
        prop_assert_eq!(sum.canned_holes, holes as u64, "{}", sink.nc);
    }
    let vo = VerifyOptions {
        mode: Mode::Joint,
        setup,
        tolerance: if m.units == Units::Mm { 0.01 } else { 0.0004 },
        angle_tolerance_deg: 0.01,
        cl_units: None,
        cl_tool_length: true,
        tool_table: None,
    };
    let r = verify(cl.as_bytes(), sink.nc.as_bytes(), m, &vo).unwrap();
    prop_assert!(r.ok && r.matched == holes as u64, "{r:?}\n{cl}\n{}", sink.nc);
    Ok(())
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(24))]
    #[test]
    fn random_holes_drill_as_cycles_on_every_profile(seed in proptest::collection::vec(0.0f64..1.0, 24)) {
        for id in ["spinner-u5-620", "haas-umc750", "mikron-ucp710", "dmu-nutating-45", "dmg-dmc75v", "fryer-5x-45",
                   "htm50200-horizontal", "propeller-3r2l", "vmc-3axis", "vmc-4axis-a"] {
            random_holes(id, &seed)?;
        }
    }
}

/// Profiles with three linears and two rotaries: the machines a tilted plane is written for.
const PLANE_MACHINES: [&str; 7] = [
    "spinner-u5-620",
    "haas-umc750",
    "mikron-ucp710",
    "dmu-nutating-45",
    "dmg-dmc75v",
    "fryer-5x-45",
    "htm50200-horizontal",
];

/// A 3+2 program: `ops` operations, each at a random fixed tool axis (FK of random joints in
/// the middle of travel): approach, a square with a half circle in the plane normal to the axis,
/// and (with `holes`) a drilled hole; rapids between. Returns the CL and the tips of its GOTOs
/// (profile units, W), and how many planes it needs (one per change of tool axis).
fn three_plus_two(
    m: &kinepost::kinematics::Machine,
    seed: &[f64],
    ops: usize,
    holes: bool,
) -> (String, Vec<kinepost::kinematics::Vec3>, u64) {
    use kinepost::kinematics::{Setup, Units, Vec3};
    let s = if m.units == Units::Mm { 1.0 } else { 1.0 / 25.4 };
    let setup = Setup::new(m.default_tool_length, Vec3::zeros());
    let mut k = 0;
    let mut next = || {
        k += 1;
        seed[(k - 1) % seed.len()]
    };
    let mut cl = format!(
        "UNITS/{}\nLOADTL/1\nSPINDL/RPM,3000,CLW\n",
        if m.units == Units::Mm { "MM" } else { "INCHES" }
    );
    let feed = if m.units == Units::Mm { "MMPM" } else { "IPM" };
    let mut tips = Vec::new();
    let (mut planes, mut last_axis) = (0, None);
    for _ in 0..ops {
        let j = random_joints(m, (0.35, 0.3), &mut next);
        let pose = kinepost::kinematics::fk(m, &j, &setup);
        let (t, u) = (pose.tip, pose.axis.normalize());
        // An untilted axis needs no plane.
        if (u - Vec3::z()).norm() > 1e-6 && last_axis.is_none_or(|l: Vec3| (l - u).norm() > 1e-9) {
            planes += 1;
        }
        last_axis = Some(u);
        let e1 = u.cross(&if u.x.abs() < 0.9 { Vec3::x() } else { Vec3::y() }).normalize();
        let e2 = u.cross(&e1);
        let g = |p: Vec3| format!("GOTO/{},{},{},{},{},{}\n", p.x, p.y, p.z, u.x, u.y, u.z);
        let (a, w) = (8.0 * s, 20.0 * s);
        let path = [t + u * w, t, t + e1 * a, t + e1 * a + e2 * a, t + e2 * a, t, t + u * w];
        cl += &format!(
            "RAPID\n{}FEDRAT/{feed},{}\n{}{}",
            g(path[0]),
            400.0 * s,
            g(path[1]),
            g(path[2])
        );
        // Half a circle about the square's far side, counter-clockwise about the tool axis.
        let c = t + e1 * a + e2 * (a / 2.0);
        cl += &format!("CIRCLE/{},{},{},{},{},{},{}\n", c.x, c.y, c.z, u.x, u.y, u.z, a / 2.0);
        cl += &format!("{}{}{}RAPID\n{}", g(path[3]), g(path[4]), g(path[5]), g(path[6]));
        tips.extend_from_slice(&path);
        if holes {
            let h = t + (e1 + e2) * (a / 2.0);
            cl += &format!(
                "CYCLE/DRILL,FEDTO,{},{feed},{},RAPTO,{}\n{}CYCLE/OFF\n",
                3.0 * s,
                150.0 * s,
                2.0 * s,
                g(h)
            );
            tips.push(h);
        }
    }
    cl += "END\nFINI\n";
    (cl, tips, planes)
}

fn post_planes(
    m: &kinepost::kinematics::Machine,
    cl: &str,
    dialect: &str,
    wo: kinepost::kinematics::Vec3,
    holes: bool,
) -> (Collect, post::Summary) {
    let mut o = Options::new(m);
    o.dialect = kinepost::nc::dialect(dialect).unwrap();
    o.tilted_planes = true;
    o.canned_cycles = holes;
    o.work_offset = wo;
    let mut sink = Collect::default();
    let sum = post::post(cl.as_bytes(), m, &o, &mut sink).unwrap();
    (sink, sum)
}

/// Inside a plane no rotary word may be written (the control owns the rotaries there), and every
/// plane is left before the program ends.
fn no_rotaries_in_planes(nc: &str, m: &kinepost::kinematics::Machine) -> Result<u32, String> {
    let (mut on, mut planes) = (false, 0);
    for l in nc.lines() {
        let code = if l.starts_with("CYCLE800(") {
            l
        } else {
            l.split(['(', ';']).next().unwrap_or("").trim()
        };
        if code.contains("G68.2") || code.contains("G254") || code.starts_with("CYCLE800(0") || code.contains("PLANE SPATIAL") {
            (on, planes) = (true, planes + 1);
            continue;
        }
        if code.contains("G69") || code.contains("G255") || code == "CYCLE800()" || code.contains("PLANE RESET") {
            on = false;
            continue;
        }
        if on
            && words(code)
                .iter()
                .any(|(c, v)| v.is_some() && m.rotaries.iter().any(|r| r.name == *c))
        {
            return Err(format!("a rotary word inside a tilted plane: {l:?}"));
        }
    }
    if on {
        return Err("the program ends inside a tilted plane".into());
    }
    Ok(planes)
}

fn random_planes(id: &str, seed: &[f64]) -> Result<(), proptest::test_runner::TestCaseError> {
    use kinepost::kinematics::{Setup, Units, Vec3};
    use kinepost::post::verify::{VerifyOptions, verify};
    use proptest::prelude::*;
    let lib = common::library();
    let m = &lib.get(id).unwrap().machine;
    let s = if m.units == Units::Mm { 1.0 } else { 1.0 / 25.4 };
    let tol = if m.units == Units::Mm { 0.01 } else { 0.0004 };
    // A work offset moves the part on the table: plane coordinates must not care.
    let wo = Vec3::new(seed[0] - 0.5, seed[1] - 0.5, seed[2] - 0.5) * 40.0 * s;
    let ops = 3;
    let table_table = m.kinematics_kind() == "table-table";
    for d in ["fanuc", "haas", "siemens", "heidenhain"] {
        if d == "haas" && !table_table {
            continue;
        }
        // Every dialect's canned cycles and planes are read back by `verify`.
        let (cl, _, want) = three_plus_two(m, &seed[3..], ops, true);
        let (sink, sum) = post_planes(m, &cl, d, wo, true);
        prop_assert_eq!(sum.errors, 0, "{} {}\n{}\n{}", id, d, cl, sink.nc);
        prop_assert_eq!(sum.tilted_planes, want, "{} {}\n{}", id, d, sink.nc);
        let planes =
            no_rotaries_in_planes(&sink.nc, m).map_err(|e| TestCaseError::fail(format!("{id} {d}: {e}\n{}", sink.nc)))?;
        prop_assert_eq!(planes as u64, want, "{} {}\n{}", id, d, sink.nc);
        let setup = Setup::new(m.default_tool_length, wo);
        let vo = VerifyOptions {
            mode: Mode::Joint,
            setup,
            tolerance: tol,
            angle_tolerance_deg: 0.01,
            cl_units: None,
            cl_tool_length: true,
            tool_table: None,
        };
        let r = verify(cl.as_bytes(), sink.nc.as_bytes(), m, &vo).unwrap();
        prop_assert!(r.ok && r.matched == r.cl_points, "{id} {d}: {r:?}\n{cl}\n{}", sink.nc);
        prop_assert_eq!(sum.canned_holes, ops as u64, "{} {}\n{}", id, d, sink.nc);
    }
    Ok(())
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(12))]
    /// Random 3+2 programs on every 5-axis profile, in every dialect that tilts planes: each
    /// fixed-axis operation becomes one plane, no rotary word is written inside one, the arcs
    /// come out as arcs in the plane, holes as canned cycles in it, and `verify` (plane
    /// coordinates × the plane's frame, as the control computes them) reaches every CL point.
    #[test]
    fn random_three_plus_two_in_tilted_planes(seed in proptest::collection::vec(0.0f64..1.0, 40)) {
        for id in PLANE_MACHINES {
            random_planes(id, &seed)?;
        }
    }
}

/// A fixed-axis run longer than the look-ahead that turns its axis inside a cut: the plane was
/// entered (nothing ahead said otherwise), so the turn is a retract along the tool axis out of
/// the plane, a reposition and a re-approach, with a warning, and the program still verifies.
#[test]
fn a_plane_left_inside_a_cut_is_repositioned_out_of_it() {
    use kinepost::kinematics::{Joints, Setup, Vec3};
    use kinepost::post::verify::{VerifyOptions, verify};
    let lib = common::library();
    let m = &lib.get("spinner-u5-620").unwrap().machine;
    let setup = Setup::new(m.default_tool_length, Vec3::zeros());
    let j = Joints {
        linear: [0.0, 0.0, 100.0],
        rotary: [0.5, 0.3, 0.0],
    };
    let p = kinepost::kinematics::fk(m, &j, &setup);
    let (t, u) = (p.tip, p.axis);
    let e1 = u.cross(&Vec3::x()).normalize();
    let g = |q: Vec3, a: Vec3| format!("GOTO/{},{},{},{},{},{}\n", q.x, q.y, q.z, a.x, a.y, a.z);
    let mut cl = String::from("UNITS/MM\nLOADTL/1\nSPINDL/RPM,3000,CLW\nRAPID\n");
    cl += &g(t + u * 20.0, u);
    cl += "FEDRAT/MMPM,500\n";
    for i in 0..2000 {
        cl += &g(t + e1 * (i as f64 * 0.01), u);
    }
    // The axis now tilts 5° further while cutting on.
    let turned = (u + e1 * 0.0875).normalize();
    cl += &g(t + e1 * 21.0, turned);
    cl += &g(t + e1 * 22.0, turned);
    cl += "END\nFINI\n";
    let (sink, sum) = post_planes(m, &cl, "fanuc", Vec3::zeros(), false);
    assert_eq!(sum.tilted_planes, 1, "{}", sink.nc);
    assert_eq!(sum.errors, 0, "{}", sink.nc);
    assert_eq!(sum.counts.get("branch_change"), Some(&1), "{:?}", sum.counts);
    let after = sink.nc.split("G69").nth(1).expect("the plane is left");
    let before = sink.nc.split("G69").next().unwrap();
    assert!(
        before.lines().rev().nth(1).unwrap().contains("RETRACT REPOSITION"),
        "{}",
        sink.nc
    );
    assert!(after.contains("(REPOSITION)"), "{after}");
    no_rotaries_in_planes(&sink.nc, m).unwrap();
    let vo = VerifyOptions {
        mode: Mode::Joint,
        setup,
        tolerance: 0.01,
        angle_tolerance_deg: 0.01,
        cl_units: None,
        cl_tool_length: true,
        tool_table: None,
    };
    let r = verify(cl.as_bytes(), sink.nc.as_bytes(), m, &vo).unwrap();
    assert!(r.ok && r.matched == 2003, "{r:?}");
}

/// Golden 3+2 programs in each dialect that tilts planes (two operations at different axes,
/// arcs, and on the ISO controls a hole as a canned cycle in the plane); the ISO ones parse
/// with the `gcode` crate, which sees the plane words and each plane block's three axis words.
#[test]
fn golden_tilted_plane_programs() {
    use kinepost::kinematics::Vec3;
    let lib = common::library();
    let seed = [0.21, 0.67, 0.43, 0.88, 0.12, 0.55, 0.31, 0.76, 0.49, 0.05, 0.93];
    for (d, id) in [
        ("fanuc", "spinner-u5-620"),
        ("haas", "haas-umc750"),
        ("siemens", "dmu-nutating-45"),
        ("heidenhain", "dmg-dmc75v"),
    ] {
        let m = &lib.get(id).unwrap().machine;
        let holes = matches!(d, "fanuc" | "haas");
        let (cl, _, want) = three_plus_two(m, &seed, 2, holes);
        let s = if m.units == kinepost::kinematics::Units::Mm {
            1.0
        } else {
            1.0 / 25.4
        };
        let (sink, sum) = post_planes(m, &cl, d, Vec3::new(12.0, -8.0, 5.0) * s, holes);
        assert_eq!(
            (sum.errors, sum.tilted_planes),
            (0, want),
            "{d} {id} {:?}\n{}",
            sum.counts,
            sink.nc
        );
        assert_eq!(want, 2);
        assert_golden(&format!("planes-{d}-{id}.nc"), &sink.nc);
        if holes {
            let text = tape_body(&sink.nc);
            let prog = gcode::parse(&text).unwrap_or_else(|e| panic!("the gcode crate rejects our planes: {e:?}"));
            let shown: Vec<String> = prog.blocks.iter().map(|b| b.to_string()).collect();
            let plane_word = if d == "fanuc" { "G68.2" } else { "G254" };
            assert_eq!(shown.iter().filter(|b| b.contains(plane_word)).count(), 2, "{shown:?}");
            assert!(shown.iter().any(|b| b.contains("G81")), "{shown:?}");
        }
    }
}

/// A program number the control's frame cannot carry (`O` and four digits on fanuc, five on
/// haas; `O0` nowhere) is refused with the range, before anything is written; the dialects that
/// name programs take any.
#[test]
fn program_numbers_are_checked_against_the_dialects_program_frame() {
    let lib = common::library();
    let m = &lib.get("dmg-dmc75v").unwrap().machine;
    let settings = |dialect: &str, n: u32| post::Settings {
        dialect: Some(dialect.into()),
        program_number: Some(n),
        ..Default::default()
    };
    for (dialect, max) in [
        ("fanuc", Some(9999)),
        ("haas", Some(99999)),
        ("siemens", None),
        ("heidenhain", None),
        ("linuxcnc", None),
    ] {
        match max {
            Some(max) => {
                assert!(settings(dialect, max).options(m).is_ok());
                for bad in [0, max + 1, u32::MAX] {
                    let e = settings(dialect, bad).options(m).unwrap_err().message;
                    assert_eq!(e, format!("program_number {bad}: {dialect} takes 1 to {max}"));
                }
            }
            None => assert!(settings(dialect, u32::MAX).options(m).is_ok()),
        }
    }
}

/// The NC of `cl` posted with `settings`, or the settings' error.
fn nc_with(m: &kinepost::kinematics::Machine, cl: &str, settings: post::Settings) -> Result<String, String> {
    let o = settings.options(m)?;
    let mut nc = Vec::new();
    post::post(cl.as_bytes(), m, &o, &mut post::TextSink(&mut nc)).unwrap();
    Ok(String::from_utf8(nc).unwrap())
}

/// The X Y Z words are measured from one origin (joint mode: the profile's; TCP: the part's): the
/// program selects the work coordinate system that holds it (G54 by default) instead of running
/// in whatever the control has active from the last job. Each control takes only its own: a Sinumerik's G58/G59
/// are additive offsets, a TNC selects its preset on the control.
#[test]
fn the_program_selects_its_work_coordinates() {
    let lib = common::library();
    let m = &lib.get("spinner-u5-620").unwrap().machine;
    let cl = "UNITS/MM\nLOADTL/1\nSPINDL/1000\nGOTO/10,20,30,0,0,1\nFINI\n";
    let program = |dialect: &str, wcs: Option<&str>| {
        nc_with(
            m,
            cl,
            post::Settings {
                dialect: Some(dialect.into()),
                work_coordinates: wcs.map(str::to_string),
                ..Default::default()
            },
        )
    };
    // The safe-start line, with the work coordinates last: nothing else moves.
    for (dialect, start) in [
        ("fanuc", "G90 G17 G40 G49 G80"),
        ("haas", "G90 G17 G40 G49 G80"),
        ("linuxcnc", "G90 G17 G40 G49 G80"),
        ("siemens", "G90 G17 G40 G64"),
    ] {
        let nc = program(dialect, None).unwrap();
        assert!(nc.contains(&format!("\n{start} G54\n")), "{dialect}: {nc}");
        let nc = program(dialect, Some("G56")).unwrap();
        assert!(
            nc.contains(&format!("\n{start} G56\n")) && !nc.contains("G54"),
            "{dialect}: {nc}"
        );
        let nc = program(dialect, Some("none")).unwrap();
        assert!(nc.contains(&format!("\n{start}\n")) && !nc.contains("G5"), "{dialect}: {nc}");
    }
    let nc = program("heidenhain", None).unwrap();
    assert!(!nc.contains("G54"), "{nc}");
    assert_eq!(program("heidenhain", Some("none")).unwrap(), nc);
    let refused = |dialect: &str, wcs: &str| program(dialect, Some(wcs)).unwrap_err();
    assert!(refused("heidenhain", "G54").contains("heidenhain selects none"));
    assert!(refused("siemens", "G59").contains("siemens takes G54, G55, G56, G57 or none"));
    assert!(refused("fanuc", "G54.1").contains("fanuc takes G54"));
}

/// A TCP program's X Y Z are the tip: its retracts go the clearance along the tool axis, and
/// cannot name the top of Z. Before a tool change and at the end it leaves the part by machine
/// Z home once compensation is off (`G53 G0 Z0`, as the real NX post for the Haas does), on the
/// controls whose machine Z0 is the top of travel; joint mode goes to the top of Z travel already.
#[test]
fn a_tcp_program_leaves_the_part_by_machine_z_home() {
    let lib = common::library();
    let m = &lib.get("spinner-u5-620").unwrap().machine;
    let cl = "UNITS/MM\nLOADTL/1\nSPINDL/1000\nFEDRAT/500\nGOTO/10,20,30,0,0,1\nGOTO/10,20,0,0,0,1\n\
              LOADTL/2\nGOTO/30,20,30,0,0,1\nGOTO/30,20,0,0,0,1\nFINI\n";
    let program = |dialect: &str, mode: &str| {
        let settings = post::Settings {
            dialect: Some(dialect.into()),
            mode: Some(mode.into()),
            ..Default::default()
        };
        nc_with(m, cl, settings).unwrap()
    };
    for dialect in ["fanuc", "haas"] {
        let nc = program(dialect, "tcp");
        assert_eq!(nc.matches("\nG49\nG53 G0 Z0\n").count(), 2, "{dialect}: {nc}");
        let (up, change, end) = (nc.find("G53").unwrap(), nc.find("T2 M6").unwrap(), nc.rfind("G53").unwrap());
        assert!(
            up < change && end > change && nc[end..].starts_with("G53 G0 Z0\nM30"),
            "{dialect}: {nc}"
        );
        assert!(!program(dialect, "joint").contains("G53"), "{dialect} joint");
    }
    for dialect in ["linuxcnc", "siemens", "heidenhain"] {
        let nc = program(dialect, "tcp");
        assert!(
            !nc.contains("G53") && !nc.contains("SUPA") && !nc.contains("M91"),
            "{dialect}: {nc}"
        );
    }
}

/// APT's `DELAY` is a dwell (seconds, or `REV,n` spindle revolutions): it was an ignored record,
/// so a drill meant to break its chip at the bottom of each peck never stopped there. Each
/// control writes its own dwell (a Haas `P` without a decimal point is milliseconds, a
/// Sinumerik's `G4 S` revolutions), the cycle time counts it, and `verify` reads the program
/// back through it.
#[test]
fn a_delay_is_each_controls_dwell() {
    use kinepost::kinematics::{Setup, Vec3};
    let lib = common::library();
    let m = &lib.get("vmc-3axis").unwrap().machine;
    let cl = "UNITS/MM\nLOADTL/1\nSPINDL/600,RPM,CLW\nRAPID\nGOTO/0,0,5\nFEDRAT/100,MMPM\nGOTO/0,0,-10\n\
              DELAY/1.5\nGOTO/0,0,5\nGOTO/0,0,-10\nDELAY/REV,10\nGOTO/0,0,5\nFINI\n";
    let post = |cl: &str, dialect: &str| {
        let settings = post::Settings {
            dialect: Some(dialect.into()),
            ..Default::default()
        };
        let o = settings.options(m).unwrap();
        let mut nc = Vec::new();
        let s = post::post(cl.as_bytes(), m, &o, &mut post::TextSink(&mut nc)).unwrap();
        (String::from_utf8(nc).unwrap(), s)
    };
    let (_, plain) = post(&cl.replace("DELAY/1.5\n", "").replace("DELAY/REV,10\n", ""), "fanuc");
    for (dialect, first, second) in [
        ("fanuc", "\nG4 P1500\n", "\nG4 P1000\n"),
        ("haas", "\nG4 P1.500\n", "\nG4 P1.000\n"),
        ("linuxcnc", "\nG4 P1.500\n", "\nG4 P1.000\n"),
        ("siemens", "\nG4 F1.500\n", "\nG4 F1.000\n"),
        ("heidenhain", " CYCL DEF 9.1 DWELL 1.500\n", " CYCL DEF 9.1 DWELL 1.000\n"),
    ] {
        let (nc, s) = post(cl, dialect);
        let (a, b) = (nc.find(first), nc.find(second));
        assert!(a.is_some() && b.is_some() && a < b, "{dialect}: {nc}");
        // After the first plunge's block, before the move out.
        assert!(nc[..a.unwrap()].contains("-10."), "{dialect}: {nc}");
        assert!(
            (s.cycle_time_s - plain.cycle_time_s - 2.5).abs() < 1e-9,
            "{dialect}: {} against {}",
            s.cycle_time_s,
            plain.cycle_time_s
        );
        let vo = post::verify::VerifyOptions {
            mode: Mode::Joint,
            setup: Setup::new(m.default_tool_length, Vec3::zeros()),
            tolerance: 0.01,
            angle_tolerance_deg: 0.01,
            cl_units: None,
            cl_tool_length: true,
            tool_table: None,
        };
        let rep = post::verify::verify(cl.as_bytes(), nc.as_bytes(), m, &vo).unwrap();
        assert!(rep.ok, "{dialect}: {rep:?}\n{nc}");
    }
    // Revolutions with the spindle standing: no time to write; a dwell that is no number of
    // seconds is a bad record.
    let (nc, _) = post(&cl.replace("SPINDL/600,RPM,CLW", "SPINDL/OFF"), "fanuc");
    assert!(nc.contains("G4 P1500") && !nc.contains("G4 P1000"), "{nc}");
    let (nc, s) = post(&cl.replace("DELAY/1.5", "DELAY/-1"), "fanuc");
    assert!(
        !nc.contains("G4 P1500") && s.counts.get("bad_record") == Some(&1),
        "{nc} {:?}",
        s.counts
    );
}

/// The machinist runs the NC, not the diagnostics: in every dialect's comment syntax a block with
/// an error says `ERROR` and its code, an error with no block (a point skipped) is a comment line
/// where it happened, and the program closes with the count before its end.
#[test]
fn a_program_with_errors_says_so_in_its_own_text() {
    let lib = common::library();
    let m = &lib.get("vmc-3axis").unwrap().machine;
    // Line 5 is far outside X travel; line 6 tilts the tool (no solution on three axes).
    // (FEDRAT in mm a minute says the units: a program with no feed at all is an error too.)
    let bad = "FEDRAT/500,MMPM\nLOADTL/1\nSPINDL/1000\nGOTO/10,20,30,0,0,1\nGOTO/9000,20,30,0,0,1\nGOTO/10,20,30,0.5,0,0.866\nGOTO/10,25,30,0,0,1\nFINI\n";
    let good = "FEDRAT/500,MMPM\nLOADTL/1\nSPINDL/1000\nGOTO/10,20,30,0,0,1\nGOTO/10,25,30,0,0,1\nFINI\n";
    for d in ["fanuc", "haas", "linuxcnc", "siemens", "heidenhain"] {
        let s = |cl: &str| {
            let settings = post::Settings {
                dialect: Some(d.into()),
                ..Default::default()
            };
            nc_with(m, cl, settings).unwrap()
        };
        let nc = s(bad);
        let lines: Vec<&str> = nc.lines().collect();
        let flagged = lines
            .iter()
            .find(|l| l.contains("X9000.000") || l.contains("X+9000.000"))
            .unwrap_or_else(|| panic!("{d}: no block for line 5:\n{nc}"));
        assert!(flagged.contains("ERROR LIMIT_VIOLATION"), "{d}: {flagged}");
        assert!(
            lines.iter().any(|l| l.contains("ERROR UNREACHABLE CL LINE 6")),
            "{d}: the skipped point is not in the text:\n{nc}"
        );
        let close = lines
            .iter()
            .position(|l| l.contains("KINEPOST: ERRORS 2,"))
            .unwrap_or_else(|| panic!("{d}:\n{nc}"));
        assert!(lines[close].contains("NOT FIT TO RUN AS IS"), "{d}: {}", lines[close]);
        let end = lines
            .iter()
            .rposition(|l| l.contains("M30") || l.contains("M2") || l.contains("END PGM"))
            .unwrap();
        assert!(close < end, "{d}: the closing comment comes before the program end");
        let nc = s(good);
        assert!(!nc.contains("ERROR "), "{d}:\n{nc}");
        assert!(nc.contains("KINEPOST: ERRORS 0, WARNINGS "), "{d}:\n{nc}");
    }
}

/// Program flow in every dialect, where the CL puts it: `STOP` and `OPSTOP` are the program stop
/// and the optional stop, and the spindle and coolant they halt start again before the next move
/// unless the CL restarts them itself (the operator presses cycle start, not the spindle and
/// coolant buttons); `SELCTL` readies the next tool; `OPSKIP` marks the blocks between with the block delete `/` (told, not
/// written, on a conversational control); `AUXFUN` and `PREFUN` pass their code through, told,
/// and a program end, a coordinate-changing G code or an M code the control does not know
/// (LinuxCNC's are data) is an error, not written; `CUTCOM` starts
/// compensation on the next move and `CUTCOM/OFF` ends it on the move after it (G41 D…/G40,
/// Siemens' G41 with the tool's D1, Heidenhain's RL/R0).
#[test]
fn program_flow_in_every_dialect() {
    let lib = common::library();
    let cl = "UNITS/MM\nLOADTL/1\nSPINDL/5000,CLW\nCOOLNT/ON\nFEDRAT/500,MMPM\nGOTO/0,0,20,0,0,1\n\
              SELCTL/2\nSTOP\nGOTO/20,0,20,0,0,1\nOPSTOP\nSPINDL/6000,CLW\nGOTO/30,0,20,0,0,1\n\
              OPSKIP/ON\nGOTO/40,0,20,0,0,1\nOPSKIP/OFF\nAUXFUN/19\nPREFUN/64\nAUXFUN/30\nPREFUN/91\nGOTO/50,0,20,0,0,1\n\
              CUTCOM/LEFT,7\nGOTO/60,10,20,0,0,1\nGOTO/70,10,20,0,0,1\nCUTCOM/OFF\nGOTO/80,0,20,0,0,1\nEND\n";
    for (d, machine) in CASES {
        let m = lib.get(machine).unwrap().machine.clone();
        let mut o = Options::new(&m);
        o.dialect = kinepost::nc::dialect(d).unwrap();
        let conv = o.dialect.style == kinepost::nc::Style::Conversational;
        let mut sink = Collect::default();
        post::post(cl.as_bytes(), &m, &o, &mut sink).unwrap();
        let lines: Vec<&str> = sink.nc.lines().collect();
        let at = |w: &str| {
            lines
                .iter()
                .position(|l| l.split_whitespace().any(|t| t == w))
                .unwrap_or_else(|| panic!("{d}: no {w}:\n{}", sink.nc))
        };
        let (stop, opt) = (at("M0"), at("M1"));
        assert!(stop < opt, "{d}");
        let between = &lines[stop..opt].join("\n");
        assert!(between.contains("S5000") && between.contains("M3") && between.contains("M8"), "{d}: {between}");
        let after = &lines[opt..].join("\n");
        assert_eq!(after.matches("S6000").count(), 1, "{d}: the CL's own SPINDL only: {after}");
        assert!(!after.contains("S5000") && after.contains("M8"), "{d}: {after}");
        let line_of = |needle: &str| -> Vec<Option<u32>> {
            sink.diags.iter().filter(|x| x.message.contains(needle)).map(|x| x.line).collect()
        };
        assert_eq!(line_of("the stop halts"), [Some(8), Some(8), Some(10)], "{d}: {:?}", sink.diags);
        let skipped: Vec<&&str> = lines.iter().filter(|l| l.starts_with('/')).collect();
        if conv {
            assert!(skipped.is_empty() && line_of("block delete is not written") == [Some(13)], "{d}");
        } else {
            assert_eq!(skipped.len(), 1, "{d}: the one block between OPSKIP/ON and OFF: {skipped:?}");
            assert!(skipped[0].contains('X'), "{d}: the move to X40 mm: {skipped:?}");
        }
        assert!(lines.contains(&"M19") || lines.iter().any(|l| l.ends_with(" M19")), "{d}");
        assert_eq!(line_of("M30 not written"), [Some(18)], "{d}");
        assert_eq!(line_of("G91 not written"), [Some(19)], "{d}");
        assert_eq!(line_of("G64 not written").len(), conv as usize, "{d}: G64 passes on word address");
        let preselect = if conv { "TOOL DEF 2" } else { "T2" };
        assert!(lines.iter().any(|l| l.ends_with(preselect)), "{d}: SELCTL/2 readies tool 2");
        let (on, off) = if conv { ("RL", "R0") } else { ("G41", "G40") };
        assert_eq!(sink.lines_with(on), [22], "{d}: compensation on the move after CUTCOM/LEFT:\n{}", sink.nc);
        assert_eq!(sink.lines_with(off), [25], "{d}: and off on the move after CUTCOM/OFF:\n{}", sink.nc);
        let d_word = lines.iter().any(|l| l.split_whitespace().any(|t| t == "D7"));
        assert_eq!(d_word, !matches!(d, "siemens" | "heidenhain"), "{d}: the CL's register where the control has one");
        assert_golden(&format!("flow-{d}-{machine}.nc"), &sink.nc);
    }
}

/// LinuxCNC stops on an M code it does not know (its interpreter, `rs274`, says "Unknown m
/// code"): its codes are data, an `AUXFUN` outside them is an error and not written, and a
/// profile's clamp words outside them (the Haas UMC-750's M10–M13) are told once and not
/// written. Fanuc and Haas controls take the builder's own codes.
#[test]
fn codes_linuxcnc_does_not_know_are_not_written() {
    let lib = common::library();
    let p = lib.get("haas-umc750").unwrap();
    let cl = "UNITS/MM\nLOADTL/1\nFEDRAT/500,MMPM\nGOTO/0,0,20,0,0,1\nAUXFUN/77\nAUXFUN/101\n\
              RAPID\nGOTO/0,0,20,0,0.5,0.8660254\nGOTO/10,0,20,0,0.5,0.8660254\nEND\n";
    for (d, known) in [("linuxcnc", false), ("haas", true)] {
        let s = post::Settings { dialect: Some(d.into()), ..Default::default() };
        let o = s.profile_options(&p, None).unwrap();
        let mut sink = Collect::default();
        post::post(cl.as_bytes(), &p.machine, &o, &mut sink).unwrap();
        let has = |w: &str| sink.nc.lines().any(|l| !l.starts_with('(') && l.split_whitespace().any(|t| t == w));
        assert_eq!(has("M77"), known, "{d}:\n{}", sink.nc);
        assert!(has("M101"), "{d}: a user code passes");
        assert_eq!(has("M13") && has("M12"), known, "{d}: clamp words:\n{}", sink.nc);
        let refused = sink.diags.iter().any(|x| x.line == Some(5) && x.severity == kinepost::diag::Severity::Error);
        assert_eq!(refused, !known, "{d}: {:?}", sink.diags);
        let told = sink.diags.iter().filter(|x| x.code == kinepost::diag::Code::UnknownWord).count();
        assert_eq!(told, if known { 0 } else { 2 }, "{d}: once per clamped rotary: {:?}", sink.diags);
    }
}

/// Every CL hole cycle kind the reader knows: (the `CYCLE/` record's kind words and values
/// after `FEDTO`, whether it is only ever the control's cycle, whether the spindle turns CCW).
const HOLE_KINDS: [(&str, &str, bool, bool); 19] = [
    ("DRILL", "", false, false),
    ("DRILL", ",DWELL,0.5", false, false),
    ("FACE", ",DWELL,0.5", false, false),
    ("CSINK", "", false, false),
    ("DEEP", ",STEP,2", false, false),
    ("DEEP2", ",1STPECK,2", false, false),
    ("PECK", ",STEP,2", false, false),
    ("DRILL,DEEP", ",STEP,2", false, false),
    ("BRKCHP", ",STEP,2", false, false),
    ("TAP", "", true, false),
    ("RGDTAP", "", true, false),
    ("TAP,LEFT", "", true, true),
    ("RGDTAP", "", true, true),
    ("BORE", "", false, false),
    ("BORE", ",DWELL,0.5", false, false),
    ("REAM", "", false, false),
    ("BORE,DRAG", "", true, false),
    ("BORE,NODRAG", ",SHIFT,0.2", true, false),
    ("BORE,BACK", "", true, false),
];

/// One hole at (10, 20, 0) down the part's Z (line 7 is its GOTO): a tap's feed per revolution
/// is its pitch, 1.25.
fn one_hole(kind: &str, extra: &str, ccw: bool) -> String {
    let feed = if kind.contains("TAP") { "MMPR,1.25" } else { "MMPM,120" };
    format!(
        "UNITS/MM\nLOADTL/1\nSPINDL/RPM,800,{}\nRAPID\nGOTO/10,20,40,0,0,1\nCYCLE/{kind},FEDTO,12,{feed},RAPTO,3,RTRCTO,15{extra}\nGOTO/10,20,0\nCYCLE/OFF\nGOTO/10,20,40\nEND\nFINI\n",
        if ccw { "CCLW" } else { "CLW" }
    )
}

fn post_cl(machine: &str, dialect: &str, mode: Mode, canned: bool, cl: &str) -> (Collect, post::Summary) {
    let lib = common::library();
    let m = lib.get(machine).unwrap().machine.clone();
    let mut o = Options::new(&m);
    o.mode = mode;
    o.canned_cycles = canned;
    o.dialect = kinepost::nc::dialect(dialect).unwrap();
    let mut sink = Collect::default();
    let s = post::post(cl.as_bytes(), &m, &o, &mut sink).unwrap();
    (sink, s)
}

/// Every CL cycle kind × dialect × mode × canned or not: the control's own cycle, or an error
/// naming the hole's line; a tap or a bore that stops or orients the spindle never enters the
/// hole as moves (a rapid out of a tap snaps it, a turning bar drawn out marks the wall), and a
/// bore written as moves comes out at the feed.
#[test]
fn every_hole_cycle_is_the_controls_cycle_or_an_error() {
    use kinepost::diag::{Code, Severity};
    for (kind, extra, canned_only, ccw) in HOLE_KINDS {
        let cl = one_hole(kind, extra, ccw);
        for d in ["fanuc", "haas", "linuxcnc", "siemens", "heidenhain"] {
            for mode in [Mode::Joint, Mode::Tcp] {
                for canned in [false, true] {
                    let (sink, sum) = post_cl("spinner-u5-620", d, mode, canned, &cl);
                    let what = format!("{kind}{extra} {d} {mode:?} canned {canned}:\n{}", sink.nc);
                    let below: Vec<usize> = (0..sink.blocks.len()).filter(|&i| sink.blocks[i].tip[2] < -1e-6).collect();
                    if sum.canned_holes == 1 {
                        // The cycle's call is the one block at the bottom.
                        assert_eq!(below.len(), 1, "{what}");
                        assert_eq!(sum.errors, 0, "{what}");
                        continue;
                    }
                    if canned_only {
                        let refused = sink.diags.iter().find(|x| x.code == Code::CycleRefused);
                        let r = refused.unwrap_or_else(|| panic!("no cycle_refused: {what}"));
                        assert_eq!((r.severity, r.line), (Severity::Error, Some(7)), "{what}");
                        assert!(sink.nc.contains("ERROR CYCLE_REFUSED CL LINE 7"), "{what}");
                        assert!(below.is_empty(), "a block in the hole: {what}");
                        continue;
                    }
                    // Written as moves: to the bottom and out; a bore's way out at the feed.
                    assert!(!below.is_empty(), "{what}");
                    let bottom = below
                        .iter()
                        .copied()
                        .max_by(|a, b| sink.blocks[*b].tip[2].total_cmp(&sink.blocks[*a].tip[2]))
                        .unwrap();
                    let out = &sink.blocks[bottom + 1];
                    let bore = kind.starts_with("BORE") || kind == "REAM";
                    assert_eq!(out.rapid, !bore, "{what}");
                }
            }
        }
    }
}

/// Every hole kind in one program, each at its own point (10 mm apart along X), right-hand ones
/// first, then the spindle turned CCW for the left-hand taps.
fn all_holes() -> String {
    let mut cl = String::from("UNITS/MM\nLOADTL/1\nSPINDL/RPM,800,CLW\nRAPID\nGOTO/0,0,40,0,0,1\n");
    let mut x = 0;
    for ccw in [false, true] {
        if ccw {
            cl += "SPINDL/RPM,800,CCLW\n";
        }
        for (kind, extra, _, left) in HOLE_KINDS {
            if left != ccw {
                continue;
            }
            let feed = if kind.contains("TAP") { "MMPR,1.25" } else { "MMPM,120" };
            x += 10;
            cl += &format!("CYCLE/{kind},FEDTO,12,{feed},RAPTO,3,RTRCTO,15{extra}\nGOTO/{x},20,0\nCYCLE/OFF\n");
        }
    }
    cl + "END\nFINI\n"
}

/// Each dialect's form of every hole cycle (golden files, `KINEPOST_UPDATE_GOLDEN=1`), read back
/// by `verify` to every hole's top and bottom; what a control has no cycle for is an error at
/// its line. The forms and the manuals they follow: docs/dialects.md.
#[test]
fn golden_hole_cycles_per_dialect() {
    use kinepost::kinematics::{Setup, Vec3};
    use kinepost::post::verify::{VerifyOptions, verify};
    let lib = common::library();
    let m = lib.get("vmc-3axis").unwrap().machine.clone();
    let cl = all_holes();
    for d in ["fanuc", "haas", "linuxcnc", "siemens", "heidenhain"] {
        let (sink, sum) = post_cl("vmc-3axis", d, Mode::Joint, true, &cl);
        assert_golden(&format!("holes-{d}-vmc-3axis.nc"), &sink.nc);
        // Back boring nowhere; a fine bore not on LinuxCNC (its G76 threads).
        let refused = if d == "linuxcnc" { 2 } else { 1 };
        assert_eq!(sum.errors, refused, "{d}\n{}", sink.nc);
        assert_eq!(sum.canned_holes, HOLE_KINDS.len() as u64 - refused, "{d}\n{}", sink.nc);
        let vo = VerifyOptions {
            mode: Mode::Joint,
            setup: Setup::new(m.default_tool_length, Vec3::zeros()),
            tolerance: 0.01,
            angle_tolerance_deg: 0.01,
            cl_units: None,
            cl_tool_length: true,
            tool_table: None,
        };
        // Every hole's top is on its cycle's way in, but those refused: never reached.
        let r = verify(cl.as_bytes(), sink.nc.as_bytes(), &m, &vo).unwrap();
        let refused_at: Vec<u32> = sink
            .diags
            .iter()
            .filter(|x| x.code == kinepost::diag::Code::CycleRefused)
            .filter_map(|x| x.line)
            .collect();
        assert_eq!(refused_at.len() as u64, refused, "{d}");
        assert_eq!(r.matched, r.cl_points - refused, "{d}: {r:?}\n{}", sink.nc);
        assert!(
            r.misses.iter().all(|x| refused_at.contains(&x.cl_line)),
            "{d}: {r:?}\n{}",
            sink.nc
        );
    }
}

/// One canned hole on vmc-3axis in `dialect`: the cycle's line (the block at the hole's
/// bottom), the summary and the diagnostics; the CYCLE record is line 6.
fn one_canned(dialect: &str, cycle: &str) -> (String, post::Summary, Collect) {
    let cl =
        format!("UNITS/MM\nLOADTL/1\nSPINDL/RPM,800,CLW\nRAPID\nGOTO/10,20,40,0,0,1\n{cycle}\nGOTO/10,20,0\nCYCLE/OFF\nEND\n");
    let (sink, sum) = post_cl("vmc-3axis", dialect, Mode::Joint, true, &cl);
    let call = sink
        .texts
        .iter()
        .zip(&sink.blocks)
        .find(|(_, b)| b.tip[2] < -1e-6)
        .map(|(t, _)| t.clone());
    (call.unwrap_or_else(|| panic!("no cycle: {}", sink.nc)), sum, sink)
}

/// The error a value out of range gets: `word_range`, at the CYCLE's hole (line 7).
fn range_error(sink: &Collect, says: &str) {
    let d = sink.diags.iter().find(|d| d.code == kinepost::diag::Code::WordRange);
    let d = d.unwrap_or_else(|| panic!("no word_range: {:?}\n{}", sink.diags, sink.nc));
    assert_eq!((d.severity, d.line), (kinepost::diag::Severity::Error, Some(7)), "{d}");
    assert!(d.message.contains(says), "{d}");
    assert!(sink.nc.contains("ERROR WORD_RANGE CL LINE 7"), "{}", sink.nc);
}

/// A cycle's feed of 1e300 was written `F0.0` (the integer it rounds to wrapped): an error, and
/// the control's largest feed written.
#[test]
fn a_cycle_feed_beyond_the_control_is_an_error_not_f0() {
    let (call, sum, sink) = one_canned("fanuc", "CYCLE/DRILL,FEDTO,5,MMPM,1e300,RAPTO,3");
    assert!(call.ends_with("F999000.0"), "{call}");
    assert_eq!(sum.errors, 1);
    range_error(&sink, "feed");
}

/// A peck of 1e-7 was written `Q0.000`, a peck the control refuses or loops on: an error, and
/// the smallest peck the word holds written.
#[test]
fn a_peck_that_rounds_to_nothing_is_an_error_not_q0() {
    let (call, sum, sink) = one_canned("fanuc", "CYCLE/DEEP,FEDTO,5,STEP,1e-7,MMPM,100,RAPTO,3");
    assert!(call.contains(" Q0.001 "), "{call}");
    assert_eq!(sum.errors, 1);
    range_error(&sink, "peck");
}

/// A peck of 1e300 was written `Q0.000`: a peck deeper than the hole is one plunge to its
/// bottom, written as the hole's depth.
#[test]
fn a_peck_deeper_than_the_hole_is_the_holes_depth() {
    let (call, sum, _) = one_canned("fanuc", "CYCLE/DEEP,FEDTO,5,STEP,1e300,MMPM,100,RAPTO,3");
    assert!(call.contains(" Q5.000 "), "{call}");
    assert_eq!(sum.errors, 0);
}

/// A dwell of 1e300 s was written `P9223372036854775807` (milliseconds, saturated): an error,
/// and the control's longest dwell written.
#[test]
fn a_cycle_dwell_beyond_the_control_is_an_error() {
    let (call, sum, sink) = one_canned("fanuc", "CYCLE/DRILL,FEDTO,5,MMPM,100,RAPTO,3,DWELL,1e300");
    assert!(call.contains(" P99999999 "), "{call}");
    assert_eq!(sum.errors, 1);
    range_error(&sink, "dwell");
}

/// `RAPTO,-50` rapided 50 mm below the hole's top (into the part) and the estimate read −0.3
/// min: an error at the CYCLE's line, the R plane at the top, the time positive.
#[test]
fn an_r_plane_below_the_holes_top_is_an_error() {
    let (call, sum, sink) = one_canned("fanuc", "CYCLE/DRILL,FEDTO,5,MMPM,100,RAPTO,-50,RTRCTO,10");
    assert!(call.contains(" R0.000 "), "{call}");
    assert!(sum.cycle_time_s > 0.0, "{}", sum.cycle_time_s);
    let d = sink
        .diags
        .iter()
        .find(|d| d.message.contains("RAPTO"))
        .unwrap_or_else(|| panic!("{:?}", sink.diags));
    assert_eq!((d.severity, d.line), (kinepost::diag::Severity::Error, Some(6)), "{d}");
    assert!(sink.nc.contains("CL LINE 6"), "{}", sink.nc);
    // Written as moves, the same: no rapid below the top before the feed.
    let (sink, _) = post_cl(
        "vmc-3axis",
        "fanuc",
        Mode::Joint,
        false,
        "UNITS/MM\nFEDRAT/MMPM,100\nRAPID\nGOTO/10,20,40,0,0,1\nCYCLE/DRILL,FEDTO,5,MMPM,100,RAPTO,-50\nGOTO/10,20,0\nCYCLE/OFF\nEND\n",
    );
    assert!(sink.blocks.iter().all(|b| !b.rapid || b.tip[2] >= -1e-6), "{}", sink.nc);
}

/// A tap's feed is its pitch times the speed (the CL's feed per revolution is the pitch, a
/// feed per minute over the speed gives it), its hand the record's or the spindle's; a tap with
/// no speed turning, or a left-hand one with the spindle turning clockwise, is an error.
#[test]
fn a_taps_feed_is_its_pitch_times_the_speed_and_its_hand_the_spindles() {
    let tap = |d: &str, spindle: &str, cycle: &str| {
        let cl = format!(
            "UNITS/MM\nLOADTL/1\n{spindle}\nRAPID\nGOTO/10,20,40,0,0,1\n{cycle},FEDTO,12,RAPTO,3\nGOTO/10,20,0\nCYCLE/OFF\nEND\n"
        );
        post_cl("vmc-3axis", d, Mode::Joint, false, &cl)
    };
    let (cw, ccw) = ("SPINDL/RPM,800,CLW", "SPINDL/RPM,800,CCLW");
    // (dialect, rigid right-hand, rigid left-hand, floating right, floating left): words each holds.
    let cases: [(&str, [&[&str]; 4]); 5] = [
        (
            "fanuc",
            [
                &["M29 S800", "G84 ", "F1000.0"],
                &["M29 S800", "G74 ", "F1000.0"],
                &["G84 ", "F1000.0"],
                &["G74 ", "F1000.0"],
            ],
        ),
        (
            "haas",
            [
                &["G84 ", "F1000.0"],
                &["G74 ", "F1000.0"],
                &["G84 ", "F1000.0"],
                &["G74 ", "F1000.0"],
            ],
        ),
        (
            "linuxcnc",
            [
                &["G33.1 Z-12.000 K1.2500"],
                &["M4", "G33.1 Z-12.000 K1.2500"],
                &["G84 ", "F1000.0"],
                &["G74 ", "F1000.0"],
            ],
        ),
        (
            "siemens",
            [
                &["CYCLE84(", ",3,,1.2500,0,800,800)"],
                &["CYCLE84(", ",4,,-1.2500,0,800,800)"],
                &["F1000.0", "CYCLE840(", ",4,3,1)"],
                &["F1000.0", "CYCLE840(", ",3,4,1)"],
            ],
        ),
        (
            "heidenhain",
            [
                &["CYCL DEF 207", "Q239=+1.2500"],
                &["CYCL DEF 207", "Q239=-1.2500"],
                &["CYCL DEF 206", "Q206=+1000.0"],
                &["M4", "CYCL DEF 206", "Q206=+1000.0"],
            ],
        ),
    ];
    for (d, [rigid, rigid_left, float, float_left]) in cases {
        for (spindle, cycle, want) in [
            (cw, "CYCLE/RGDTAP,MMPR,1.25", rigid),
            (cw, "CYCLE/RGDTAP,MMPM,1000", rigid),
            (ccw, "CYCLE/RGDTAP,MMPR,1.25", rigid_left),
            (cw, "CYCLE/TAP,MMPR,1.25", float),
            (ccw, "CYCLE/TAP,LEFT,MMPR,1.25", float_left),
            (ccw, "CYCLE/TAP,MMPR,1.25", float_left),
        ] {
            let (sink, sum) = tap(d, spindle, cycle);
            assert_eq!((sum.errors, sum.canned_holes), (0, 1), "{d} {cycle}\n{}", sink.nc);
            for w in want {
                assert!(sink.nc.contains(w), "{d} {spindle} {cycle}: no {w:?}\n{}", sink.nc);
            }
        }
        for (spindle, cycle, says) in [
            (
                cw,
                "CYCLE/TAP,LEFT,MMPR,1.25",
                "left-hand tap with the spindle turning clockwise",
            ),
            ("SPINDL/OFF", "CYCLE/RGDTAP,MMPR,1.25", "no spindle speed"),
            (cw, "CYCLE/TAP", "no feed"),
        ] {
            let (sink, sum) = tap(d, spindle, cycle);
            let r = sink.diags.iter().find(|x| x.code == kinepost::diag::Code::CycleRefused);
            let r = r.unwrap_or_else(|| panic!("{d} {cycle}: {:?}\n{}", sink.diags, sink.nc));
            assert!(r.message.contains(says) && r.line == Some(7), "{d} {cycle}: {r}");
            assert_eq!(sum.canned_holes, 0, "{d} {cycle}");
            assert!(
                sink.blocks.iter().all(|b| b.tip[2] >= -1e-6),
                "{d} {cycle}: into the hole\n{}",
                sink.nc
            );
        }
    }
}

/// Two operations, the CAM's tolerance band 0.1+0.1 (a roughing) and 0.005+0.005 (a finish),
/// with two tools and then one: the CL's words change at each `TOOL PATH`.
fn two_operations(intol: bool) -> String {
    let tol = |t: &str| if intol { format!("INTOL/{t}\nOUTTOL/{t}\n") } else { String::new() };
    let op = |name: &str, t: &str, tool: u32, x: u32| {
        format!(
            "TOOL PATH/{name},TOOL,EM{tool}\n{}LOADTL/{tool}\nSPINDL/8000,CLW\nRAPID\nGOTO/0,0,50,0,0,1\nGOTO/0,0,5\nFEDRAT/1000\nGOTO/{x},0,5\nGOTO/{x},{x},5\nRAPID\nGOTO/{x},{x},50\n",
            tol(t)
        )
    };
    format!("UNITS/MM\n{}{}FINI\n", op("POCKET_A", "0.1", 1, 10), op("WALLS_B", "0.005", 2, 20))
}

fn post_smoothing(dialect: &str, smoothing: post::Smoothing, cl: &str) -> String {
    let lib = common::library();
    let m = lib.get("vmc-3axis").unwrap().machine.clone();
    let mut o = Options::new(&m);
    o.dialect = kinepost::nc::dialect(dialect).unwrap();
    o.smoothing = smoothing;
    let mut sink = Collect::default();
    let s = post::post(cl.as_bytes(), &m, &o, &mut sink).unwrap();
    assert_eq!(s.errors, 0, "{dialect}:\n{}", sink.nc);
    sink.nc
}

/// `smoothing` `auto`: each operation's word from its INTOL+OUTTOL, after its OPERATION line
/// and before its first feed move, each dialect's form and level; cancelled before the tool
/// change and at the end. A CL that says no tolerance, and `off`, post as before smoothing
/// existed (the dialect's `blend` only); `finish` forces the level, at the job's tolerance
/// where the CL says none.
#[test]
fn smoothing_per_operation_on_every_dialect() {
    use post::Smoothing;
    let cl = two_operations(true);
    // Each dialect: the first operation's lines, the second's, the cancel.
    type Lines = &'static [&'static str];
    let forms: [(&str, Lines, Lines, Lines); 5] = [
        ("haas", &["G187 P1 E0.200"], &["G187 P3 E0.010"], &["G187"]),
        ("siemens", &["CYCLE832(0.200, _ROUGH, 1)"], &["CYCLE832(0.010, _FINISH, 1)"], &["CYCLE832()"]),
        ("fanuc", &["G05.1 Q1 R1 (TOL 0.200)"], &["G05.1 Q1 R10 (TOL 0.010)"], &["G05.1 Q0"]),
        (
            "heidenhain",
            &["CYCL DEF 32.0 TOLERANCE", "CYCL DEF 32.1 T0.200", "CYCL DEF 32.2 HSC-MODE:1"],
            &["CYCL DEF 32.0 TOLERANCE", "CYCL DEF 32.1 T0.010", "CYCL DEF 32.2 HSC-MODE:0"],
            &["CYCL DEF 32.0 TOLERANCE", "CYCL DEF 32.1"],
        ),
        ("linuxcnc", &["G64 P0.200"], &["G64 P0.010"], &["G64"]),
    ];
    for (d, first, second, off) in forms {
        let nc = post_smoothing(d, Smoothing::Auto, &cl);
        // Heidenhain numbers every line: compare the words after the number.
        let lines: Vec<&str> = nc
            .lines()
            .map(|l| if d == "heidenhain" { l.split_once(' ').map_or(l, |(_, w)| w) } else { l })
            .collect();
        let at = |want: &[&str], from: usize| {
            (from..lines.len())
                .find(|&i| lines[i..].starts_with(want))
                .unwrap_or_else(|| panic!("{d}: {want:?} after line {from}:\n{nc}"))
        };
        let is_feed = |l: &str| l.contains("G1 ") || l.contains(" F1000");
        let a = lines.iter().position(|l| l.contains("OPERATION POCKET_A")).unwrap();
        let b = lines.iter().position(|l| l.contains("OPERATION WALLS_B")).unwrap();
        let rough = at(first, a);
        let finish = at(second, b);
        assert!(rough < b, "{d}: the roughing word in its own operation:\n{nc}");
        // Each before its operation's first feed move, none of which comes earlier.
        let first_feed = |from: usize| (from..lines.len()).find(|&i| is_feed(lines[i])).unwrap();
        assert_eq!(first_feed(a), rough + first.len(), "{d}: right before the first feed move:\n{nc}");
        assert_eq!(first_feed(b), finish + second.len(), "{d}: right before the first feed move:\n{nc}");
        // Cancelled before the second tool's change and at the end.
        let change = (b..lines.len()).find(|&i| lines[i].contains("M6") || lines[i].starts_with("TOOL CALL 2")).unwrap();
        let cancel = at(off, b);
        assert!(cancel < change, "{d}: cancelled before the tool change:\n{nc}");
        assert!(at(off, finish + second.len()) > finish, "{d}: cancelled at the end:\n{nc}");
        // No INTOL/OUTTOL, and off: the program without smoothing, byte for byte.
        let plain = post_smoothing(d, Smoothing::Off, &two_operations(false));
        assert_eq!(post_smoothing(d, Smoothing::Auto, &two_operations(false)), plain, "{d}: auto without INTOL");
        let off_nc = post_smoothing(d, Smoothing::Off, &cl);
        assert!(!off_nc.contains(first[0]) && !off_nc.contains(second[0]), "{d}: off writes none:\n{off_nc}");
    }
    // finish: every operation the finish level; the job's tolerance where the CL says none.
    let nc = post_smoothing("siemens", Smoothing::Finish, &two_operations(false));
    assert_eq!(nc.matches("CYCLE832(0.010, _FINISH, 1)").count(), 2, "{nc}");
    let nc = post_smoothing("haas", Smoothing::Rough, &cl);
    assert!(nc.contains("G187 P1 E0.200") && nc.contains("G187 P1 E0.010"), "{nc}");
}
