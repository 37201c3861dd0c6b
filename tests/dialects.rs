//! Controller dialects: golden programs per dialect (compared within a tolerance;
//! `KINEPOST_UPDATE_GOLDEN=1` rewrites them), and the ISO dialects read back by an independent
//! G-code parser (the `gcode` crate).

use kinepost::machines::Library;
use kinepost::post::{self, BlockInfo, Mode, Options, Sink};
use std::path::Path;

#[derive(Default)]
struct Collect {
    nc: String,
    blocks: Vec<BlockInfo>,
}

impl Sink for Collect {
    fn line(&mut self, text: &str, b: Option<&BlockInfo>) -> std::io::Result<()> {
        self.nc.push_str(text);
        self.nc.push('\n');
        if let Some(b) = b {
            self.blocks.push(b.clone());
        }
        Ok(())
    }
}

/// (dialect, the machine it is shown on)
const CASES: [(&str, &str); 5] = [
    ("fanuc", "spinner-u5-620"),
    ("haas", "haas-umc750"),
    ("siemens", "dmu-nutating-45"),
    ("heidenhain", "dmg-dmc75v"),
    ("linuxcnc", "vmc-4axis-a"),
];

fn program(dialect: &str, machine: &str, mode: Mode, points: usize) -> Collect {
    let lib = Library::load_dir(Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/machines"))).unwrap();
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

#[test]
fn golden_programs_per_dialect() {
    let update = std::env::var("KINEPOST_UPDATE_GOLDEN").is_ok();
    for (d, m) in CASES {
        for mode in [Mode::Joint, Mode::Tcp] {
            let name = format!("{d}-{m}-{}.nc", if mode == Mode::Joint { "joint" } else { "tcp" });
            let path = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/golden")).join(&name);
            let got = program(d, m, mode, 40).nc;
            // The version line changes with every release: not part of the comparison.
            let strip = |s: &str| {
                s.lines()
                    .filter(|l| !l.contains("KINEPOST "))
                    .map(str::to_string)
                    .collect::<Vec<_>>()
            };
            if update {
                std::fs::write(&path, &got).unwrap();
            }
            let want =
                std::fs::read_to_string(&path).unwrap_or_else(|_| panic!("{name} missing: KINEPOST_UPDATE_GOLDEN=1 writes it"));
            let (g, w) = (strip(&got), strip(&want));
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
    }
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
            let text: String =
                p.nc.lines()
                    .filter(|l| !l.starts_with('%') && !l.starts_with('O'))
                    .map(|l| format!("{l}\n"))
                    .collect();
            let prog = gcode::parse(&text).unwrap_or_else(|e| panic!("{d} {m}: the gcode crate rejects our program: {e:?}"));
            for block in &prog.blocks {
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
    let lib = Library::load_dir(Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/machines"))).unwrap();
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
