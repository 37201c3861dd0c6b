//! The engine end to end: real CL files, generated paths on every profile in both modes, the real
//! NX post's program as a golden reference, strict mode, diagnostics that keep going.

use crate::common;

use common::collect::Collect;
use common::{data, defaults, machine};
use kinepost::cl::{Event, Reader};
use kinepost::diag::{Code, Diagnostic, Severity};
use kinepost::kinematics::{Joints, Machine, Setup, Units, Vec3, angle_between, fk};
use kinepost::nc::read::NcReader;
use kinepost::post::{self, BlockInfo, Mode, Options, Sink, Summary};
use std::path::Path;

fn run(m: &Machine, cl: &[u8], o: &Options) -> (Collect, Summary) {
    let mut sink = Collect::default();
    let s = post::post(cl, m, o, &mut sink).unwrap();
    (sink, s)
}

/// The profile's defaults in `mode`, written as word address (what `NcReader` and `verify` read).
fn fanuc(m: &Machine, mode: Mode) -> Options {
    let mut o = post::Settings { dialect: Some("fanuc".into()), ..Default::default() }.options(m).unwrap();
    o.mode = mode;
    o
}

/// A tip the machine reaches: the controlled point at mid travel, rotaries at zero.
fn mid_travel_tip(m: &Machine, setup: &Setup) -> Vec3 {
    let mut j = Joints::default();
    for (i, l) in m.linears.iter().enumerate() {
        if let Some(l) = l {
            j.linear[i] = 0.5 * (l.min + l.max);
        }
    }
    fk(m, &j, setup).tip
}

/// `d` turned by `rad` about `e`.
fn tilt(d: Vec3, e: Vec3, rad: f64) -> Vec3 {
    nalgebra::Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(e), rad) * d
}

#[test]
fn every_copied_corpus_file_reads_without_error_or_unknown_record_diagnostics() {
    let mut n = 0;
    for e in std::fs::read_dir(data("")).unwrap() {
        let p = e.unwrap().path();
        if !matches!(p.extension().and_then(|x| x.to_str()), Some("cls" | "ncl")) {
            continue;
        }
        let f = std::io::BufReader::new(std::fs::File::open(&p).unwrap());
        let (mut records, mut errors) = (0, Vec::new());
        for ev in Reader::new(f) {
            match ev.unwrap() {
                Event::Statement(_) => records += 1,
                Event::Diagnostic(d) if d.severity == Severity::Error => errors.push(d),
                // NX's listing around the CLSF (header, line count) is no unknown record: a
                // warning on every file teaches the shop floor to read past warnings.
                Event::Diagnostic(d) if d.code == Code::UnknownRecord => errors.push(d),
                Event::Diagnostic(_) => {}
            }
        }
        assert!(records > 10, "{}", p.display());
        assert!(errors.is_empty(), "{}: {errors:?}", p.display());
        n += 1;
    }
    assert_eq!(n, 8);
}

/// Where a TCP block's tip really is (machine-model.md, TCP mode): the control places the
/// linears for tip X Y Z at the rotary words taken as the angles (its kinematics are nominal), and
/// the axes stand at the words plus their angle error.
fn tcp_real_tip(m: &Machine, words: &Joints, setup: &Setup) -> Vec3 {
    let p = Vec3::from(words.linear);
    let q = kinepost::kinematics::controlled_point(m, &words.rotary, &p, setup);
    fk(
        m,
        &Joints {
            linear: q.into(),
            rotary: words.rotary,
        },
        setup,
    )
    .tip
}

/// The CL points of a generated path, and the NC read back and replayed through FK: each CL
/// point is reproduced, in order, by a block (an independent check of what the text says, beside
/// the engine's own FK replay).
fn replay_matches(m: &Machine, cl: &str, nc: &str, mode: Mode, setup: &Setup, tol: f64) {
    let mut pts = Vec::new();
    for ev in Reader::new(cl.as_bytes()) {
        if let Event::Statement(s) = ev.unwrap()
            && let kinepost::cl::Record::Goto { p, axis: Some(a) } = s.record
        {
            pts.push((Vec3::from(p), Vec3::from(a).normalize()));
        }
    }
    let mut r = NcReader::new(nc.as_bytes(), m.units);
    let mut k = 0;
    while let Some(b) = r.next_block().unwrap() {
        if k == pts.len() {
            break;
        }
        let mut j = Joints::default();
        for i in 0..3 {
            j.linear[i] = b.axes[i].unwrap_or(0.0);
        }
        for (i, rot) in m.rotaries.iter().enumerate() {
            j.rotary[i] = b.axes[3 + (rot.name as u8 - b'A') as usize].unwrap_or(0.0).to_radians();
        }
        let pose = fk(m, &j, setup);
        let tip = if mode == Mode::Tcp {
            tcp_real_tip(m, &j, setup)
        } else {
            pose.tip
        };
        if (tip - pts[k].0).norm() <= tol && angle_between(&pose.axis, &pts[k].1).to_degrees() <= 0.01 {
            k += 1;
        }
    }
    assert_eq!(
        k,
        pts.len(),
        "{}: only {k} of {} CL points reproduced in order",
        m.id,
        pts.len()
    );
}

#[test]
fn generated_paths_on_every_profile_post_clean_in_joint_and_tcp_mode() {
    let lib = common::library();
    for p in lib.iter() {
        let m = &p.machine;
        let n = if m.rotaries.len() == 3 { 60 } else { 150 };
        let mut cl = Vec::new();
        kinepost::testgen::write_path(m, n, 7, m.default_tool_length, &mut cl).unwrap();
        let cl_text = String::from_utf8(cl.clone()).unwrap();
        for mode in [Mode::Joint, Mode::Tcp] {
            // The engine under test; word address so the replay below can read it (every dialect
            // is checked by tests/it/dialects.rs and, in CI, by the shared verifier).
            let o = fanuc(m, mode);
            let (sink, s) = run(m, &cl, &o);
            let errors: Vec<_> = sink.diags.iter().filter(|d| d.severity == Severity::Error).collect();
            assert!(errors.is_empty(), "{} {mode:?}: {errors:?}", m.id);
            assert_eq!(s.cl_points, n as u64, "{} {mode:?}", m.id);
            assert!(
                s.max_tip_deviation <= o.tolerance,
                "{} {mode:?}: FK replay {}",
                m.id,
                s.max_tip_deviation
            );
            assert!(
                s.max_axis_deviation_deg <= 0.01,
                "{} {mode:?}: {}",
                m.id,
                s.max_axis_deviation_deg
            );
            let setup = Setup::new(m.default_tool_length, Vec3::zeros());
            replay_matches(m, &cl_text, &sink.nc, mode, &setup, o.tolerance);
            // And the motion between blocks stays on the CL segments (joint mode: the
            // linearization), by the same check `kinepost verify` runs.
            let vo = kinepost::post::verify::VerifyOptions {
                mode,
                setup,
                tolerance: o.tolerance,
                angle_tolerance_deg: 0.01,
                cl_units: None,
                cl_tool_length: true,
                tool_table: None,
            };
            let r = kinepost::post::verify::verify(cl_text.as_bytes(), sink.nc.as_bytes(), m, &vo).unwrap();
            assert!(r.ok, "{} {mode:?}: {r:?}", m.id);
        }
    }
}

/// The real NX post (HAAS_UMC750_5AXIS_MILL_IN) on the same CL file: X Y Z agree to 0.0001 in,
/// C travel is NX's optimum, and no step is larger than NX's.
#[test]
fn nx_variable_axis_against_the_real_nx_post() {
    let m = machine("haas-umc750");
    let cl = std::fs::read(data("nx_clsf_mech491_variable_axis_inch_5ax.cls")).unwrap();
    let mut o = defaults(&m);
    o.mode = Mode::Tcp;
    let (sink, s) = run(&m, &cl, &o);
    assert_eq!(s.errors, 0);
    assert_eq!(s.cl_points, 348);
    let golden = std::fs::read_to_string(data("golden/nx_post_HAAS_UMC750_variable_axis.nc")).unwrap();
    let read = |t: &str| {
        let mut r = NcReader::new(t.as_bytes(), Units::Inch);
        let mut v = Vec::new();
        while let Some(b) = r.next_block().unwrap() {
            v.push(b);
        }
        v
    };
    let (g, k) = (read(&golden), read(&sink.nc));
    // Every golden block's X Y Z appears, in order, in ours.
    let mut j = 0;
    for gb in &g {
        let (Some(gx), Some(gy), Some(gz)) = (gb.axes[0], gb.axes[1], gb.axes[2]) else {
            continue;
        };
        let want = [gx, gy, gz];
        while j < k.len() && !(0..3).all(|i| (k[j].axes[i].unwrap_or(f64::NAN) - want[i]).abs() <= 1e-4 + 1e-9) {
            j += 1;
        }
        assert!(j < k.len(), "golden line {} ({want:?}) not found in order", gb.line);
    }
    let travel = |blocks: &[kinepost::nc::read::NcBlock]| {
        let (mut t, mut step, mut prev) = (0.0f64, 0.0f64, None::<f64>);
        for b in blocks {
            if let Some(c) = b.axes[5] {
                if let Some(p) = prev {
                    let d: f64 = (c - p).abs();
                    t += d;
                    if !b.rapid {
                        step = step.max(d);
                    }
                }
                prev = Some(c);
            }
        }
        (t, step)
    };
    let (nx_t, nx_step) = travel(&g);
    let (kp_t, kp_step) = travel(&k);
    assert!((nx_t - 3856.568).abs() < 0.01, "{nx_t}");
    assert!(kp_t <= nx_t + 0.01, "C travel {kp_t} vs NX {nx_t}");
    assert!(kp_step <= nx_step, "largest C step {kp_step} vs NX {nx_step}");
    let c = s.axes.get(&'C').unwrap();
    assert!((c.travel.unwrap() - kp_t).abs() < 0.01, "summary agrees with the program");
}

#[test]
fn mm_cl_on_an_inch_machine_is_converted() {
    // NX's own post wrote X-10.7283 for the CL's -272.5 mm.
    let m = machine("haas-umc750");
    let cl = std::fs::read(data("nx_clsf_mech491_simple_mill_plane_mm.cls")).unwrap();
    let (sink, s) = run(&m, &cl, &defaults(&m));
    assert_eq!(s.cl_units, "mm");
    assert!(sink.nc.contains("X-10.7283"), "{}", &sink.nc[..600.min(sink.nc.len())]);
    assert!(sink.nc.contains("G20"));
}

#[test]
fn bad_records_are_diagnostics_with_line_and_column_and_the_rest_goes_on() {
    let m = machine("spinner-u5-620");
    let cl = "UNITS/MM\nFEDRAT/500,MMPM\nGOTO/0,0,50,0,0,1\nGOTO/1,2,abc\nGOTO/10,0,50,0,0,1\nFROBNICATE/1\nGOTO/20,0,50,0,0,1\n";
    let (sink, s) = run(&m, cl.as_bytes(), &defaults(&m));
    let bad = sink.first(Code::BadRecord);
    assert_eq!((bad.line, bad.column), (Some(4), Some(10)), "{bad}");
    assert!(bad.message.contains("expected a finite number"), "{bad}");
    let unknown = sink.first(Code::UnknownRecord);
    assert_eq!(unknown.severity, Severity::Warning);
    assert_eq!(s.cl_points, 3, "the good records all went through");
    assert!(sink.nc.trim_end().ends_with("M30\n%") || sink.nc.trim_end().ends_with('%'));
}

/// Moves the CAM system did not give a feed are written at rapid, and the post says so once;
/// FROM positions at rapid even with a feed in force; a bad tool number changes no tool; a
/// negative drilling depth positions the hole only, with a warning.
#[test]
fn feedless_moves_from_bad_tools_and_negative_depths_are_told() {
    let m = machine("spinner-u5-620");
    let cl = "UNITS/MM\nLOADTL/3\nGOTO/0,0,50\nGOTO/0,0,40\nGOTO/0,0,30\nFEDRAT/500,MMPM\n\
              GOTO/0,0,20\nFROM/0,0,60\nGOTO/0,0,55\nLOADTL/4.5\nCYCLE/DRILL,-5,MMPM,100\nGOTO/5,5,0\nCYCLE/OFF\n";
    let (sink, _) = run(&m, cl.as_bytes(), &defaults(&m));
    let no_feed: Vec<_> = sink.diags.iter().filter(|d| d.code == Code::NoFeed).collect();
    assert_eq!(no_feed.len(), 1, "{:?}", sink.diags);
    assert_eq!((no_feed[0].line, no_feed[0].severity), (Some(4), Severity::Warning));
    let lines: Vec<&str> = sink.nc.lines().collect();
    let at = |z: &str| {
        lines
            .iter()
            .position(|l| l.contains(z))
            .unwrap_or_else(|| panic!("{z} in\n{}", sink.nc))
    };
    let has = |l: &str, w: &str| l.split_whitespace().any(|x| x == w);
    // Z40 and Z30 before any FEDRAT: rapid (G0 stays modal from the first move, no G1 before).
    assert!(!lines[..at("Z30.")].iter().any(|l| has(l, "G1")), "{}", sink.nc);
    assert!(has(lines[at("Z20.")], "G1"), "{}", sink.nc);
    assert!(has(lines[at("Z60.")], "G0"), "FROM positions at rapid:\n{}", sink.nc);
    assert!(has(lines[at("Z55.")], "G1"), "{}", sink.nc);
    let tool = sink
        .diags
        .iter()
        .find(|d| d.line == Some(10))
        .expect("bad tool number reported");
    assert_eq!(
        (tool.code, tool.severity, tool.column),
        (Code::BadRecord, Severity::Error, Some(8))
    );
    let tools: Vec<_> = lines.iter().filter(|l| has(l, "M6")).collect();
    assert_eq!(tools, [&"T3 M6"], "{}", sink.nc);
    let depth = sink
        .diags
        .iter()
        .find(|d| d.line == Some(11))
        .expect("negative depth reported");
    assert_eq!(depth.severity, Severity::Warning);
    assert!(depth.message.contains("negative"), "{depth}");
    assert!(!sink.nc.contains("Z-5."), "no hole drilled upward or downward:\n{}", sink.nc);
}

/// A feed per revolution on a stopped spindle is no feed per minute of 0 (an alarm on the
/// control) but the per-minute reading, with a warning.
#[test]
fn a_feed_per_revolution_at_s0_is_not_f0() {
    let m = machine("spinner-u5-620");
    let cl = "UNITS/MM\nSPINDL/0,RPM\nFEDRAT/0.2,MMPR\nGOTO/1,2,3\nGOTO/5,0,0\n";
    let (sink, _) = run(&m, cl.as_bytes(), &defaults(&m));
    // Fed to the first point from the clearance over it, then on to the next: F0.2 per minute.
    assert!(sink.nc.contains("G1 Z3.000 F0.2\nX5.000 Y0.000 Z0.000\n"), "{}", sink.nc);
    assert!(
        sink.diags
            .iter()
            .any(|d| d.code == Code::FeedClamped && d.message.contains("no spindle speed"))
    );
}

/// A file that moves nothing (a wrong upload) still makes a program, but never a silent one.
#[test]
fn a_file_without_motion_is_told() {
    let m = machine("spinner-u5-620");
    let (sink, s) = run(&m, b"PARTNO/EMPTY\nUNITS/MM\nFINI\n", &defaults(&m));
    let d = sink.first(Code::NoMotion);
    assert_eq!((d.severity, s.cl_points), (Severity::Warning, 0));
    let (sink, _) = run(&m, b"UNITS/MM\nGOTO/1,2,3\n", &defaults(&m));
    assert!(!sink.diags.iter().any(|d| d.code == Code::NoMotion));
}

/// Input that is no CL (an NC program uploaded instead of its CL, an empty or binary file) is
/// refused before a byte is written, saying what it looks like and where; CL with NC-looking
/// lines among its records is CL, and a malformed CL record is CL all the same.
#[test]
fn input_that_is_no_cl_is_refused_saying_what_it_looks_like() {
    let m = machine("vmc-3axis");
    let refused = |cl: &str| {
        let mut sink = Collect::default();
        match post::post(cl.as_bytes(), &m, &defaults(&m), &mut sink) {
            Err(post::Error::NotCl(d)) => {
                assert!(sink.nc.is_empty() && sink.diags.is_empty(), "{cl:?}: {}", sink.nc);
                assert_eq!((d.code, d.severity), (Code::NotCl, Severity::Error));
                d
            }
            other => panic!("{cl:?}: {other:?}\n{}", sink.nc),
        }
    };
    let d = refused("%\nO1000 (PART)\nG21 G90\nG0 X1 Y2 Z3\nG1 X5 F500\nM30\n%\n");
    assert_eq!(d.line, Some(2), "{d}");
    assert!(
        d.message
            .starts_with("this looks like G-code (\"O1000 (PART)\" at line 2), not CL data"),
        "{d}"
    );
    // A long program is told after a few blocks, not read to its end.
    let long = "G1 X1 Y2 F100\n".repeat(100_000);
    assert!(refused(&long).message.contains("G-code"));
    let d = refused("0 BEGIN PGM 1 MM\n1 TOOL CALL 1 Z S3000\n2 L X+10 Y+5 R0 FMAX\n3 END PGM 1 MM\n");
    assert!(d.message.contains("Heidenhain conversational"), "{d}");
    let d = refused("");
    assert!(d.message.contains("empty"), "{d}");
    let d = refused("\u{1}\u{2}PNG\n");
    assert!(
        d.message
            .starts_with("nothing in the input is CL data (line 1: unknown record"),
        "{d}"
    );
    let utf16: Vec<u8> = [0xFF, 0xFE]
        .into_iter()
        .chain("GOTO/1,2,3\n".bytes().flat_map(|b| [b, 0]))
        .collect();
    let d = refused(&String::from_utf8_lossy(&utf16));
    assert!(d.message.contains("nothing in the input is CL data"), "{d}");
    // CL that carries NC-looking lines, and CL whose only record is malformed: posted.
    let (sink, s) = run(&m, b"G0 X1 Y2\nUNITS/MM\nGOTO/1,2,3\nM30\n", &defaults(&m));
    assert_eq!(s.cl_points, 1);
    assert_eq!(sink.diags.iter().filter(|d| d.code == Code::UnknownRecord).count(), 2);
    let (sink, _) = run(&m, b"GOTO/1,x,3\n", &defaults(&m));
    assert!(sink.diags.iter().any(|d| d.code == Code::BadRecord));
}

/// A words-by-CL-line view of a program: the motion blocks, keyed by the CL line each ends.
#[derive(Default)]
struct ByLine(std::collections::BTreeMap<u32, String>);

impl Sink for ByLine {
    fn line(&mut self, text: &str, b: Option<&BlockInfo>) -> Result<(), kinepost::post::Stop> {
        if let Some(l) = b.and_then(|b| b.source_line) {
            self.0.insert(l, text.to_string());
        }
        Ok(())
    }
}

/// An explicit UNITS applies from its line on, wherever it sits: the same file with
/// `UNITS/INCHES` at statement 100 or at statement 5 000 writes the same words for the points
/// before the one and after the other. (Within the units look-ahead a later record once scaled
/// the points before it, beyond it not: programs 25.4× apart.)
#[test]
fn units_apply_from_their_line_wherever_they_sit() {
    let m = machine("vmc-3axis");
    let o = defaults(&m);
    let file = |at: usize| {
        let mut lines = vec!["FEDRAT/20".to_string()];
        lines.extend((0..6000).map(|i| {
            let t = f64::from(i) * 0.01;
            format!(
                "GOTO/{:.4},{:.4},{:.4}",
                2.0 + t.sin(),
                2.0 + t.cos(),
                1.0 + 0.5 * (0.3 * t).sin()
            )
        }));
        lines.insert(at - 1, "UNITS/INCHES".into());
        lines.join("\n")
    };
    let post = |at: usize| {
        let mut sink = ByLine::default();
        let s = post::post(file(at).as_bytes(), &m, &o, &mut sink).unwrap();
        assert_eq!((s.errors, s.counts.get("units_changed")), (0, Some(&1)), "{at}");
        sink.0
    };
    let (early, late) = (post(100), post(5000));
    let mut compared = 0;
    for (line, words) in &early {
        // Between the two records the files differ; the first block after each writes its F.
        if *line < 100 || *line > 5001 {
            assert_eq!(Some(words), late.get(line), "CL line {line}");
            compared += 1;
        }
    }
    assert!(compared > 1000, "{compared}");
    // Before the record, mm (the profile's, assumed); after it, inch.
    assert!(early[&2].contains("Z1.000"), "{}", early[&2]);
    assert_ne!(early[&4000], late[&4000]);
}

/// A UNITS record after motion that changes the units is a warning naming its line; one before
/// motion decides the units of everything, silently, and one that changes nothing says nothing.
#[test]
fn a_units_change_after_motion_is_told_with_its_line() {
    let m = machine("vmc-3axis");
    let o = defaults(&m);
    let (sink, s) = run(
        &m,
        b"UNITS/MM\nFEDRAT/100\nGOTO/1,2,3\nGOTO/2,2,3\nUNITS/INCHES\nGOTO/1,2,3\n",
        &o,
    );
    let d = sink.only(Code::UnitsChanged);
    assert_eq!((d.severity, d.line), (Severity::Warning, Some(5)), "{d}");
    assert!(d.message.contains("from mm to inch") && d.message.contains("line 5"), "{d}");
    assert_eq!((s.cl_units.as_str(), s.cl_units_source.as_str()), ("mm", "UNITS record"));
    assert!(sink.nc.contains("X25.400 Y50.800 Z76.200"), "{}", sink.nc);
    let (sink, s) = run(&m, b"FEDRAT/4\nUNITS/INCHES\nGOTO/1,2,3\nGOTO/2,2,3\n", &o);
    assert!(
        !sink
            .diags
            .iter()
            .any(|d| matches!(d.code, Code::UnitsChanged | Code::UnitsAssumed))
    );
    assert_eq!(s.cl_units, "inch");
    // No units before the motion: assumed (told), and a later record in the same units is no change.
    let (sink, _) = run(&m, b"FEDRAT/100\nGOTO/1,2,3\nUNITS/MM\nGOTO/2,2,3\n", &o);
    assert!(!sink.diags.iter().any(|d| d.code == Code::UnitsChanged));
    sink.only(Code::UnitsAssumed);
}

/// The tool tilting about a tip that stands still: the tip's path gives no time, so each block
/// takes the machine axes' path (units and degrees) at F: inverse time 1/t on a control that has
/// it (not F1000000), F itself on one that has not.
#[test]
fn a_turn_about_a_standing_tip_takes_the_machine_axes_time() {
    // Tilted one way, then the other about the same tip (from vertical, the free rotary is
    // turned while positioning, and the turn would be B alone).
    let cl =
        "UNITS/MM\nFEDRAT/1000,MMPM\nGOTO/0,0,50,0.5,0,0.8660254\nGOTO/0,0,50,0,0.5,0.8660254\nGOTO/10,0,50,0,0.5,0.8660254\n";
    for id in ["spinner-u5-620", "dmg-dmc75v"] {
        let m = machine(id);
        let (sink, _) = run(&m, cl.as_bytes(), &defaults(&m));
        let turning: Vec<_> = sink
            .blocks
            .windows(2)
            .filter(|w| !w[1].rapid && w[0].tip == w[1].tip)
            .collect();
        assert!(turning.len() >= 10, "{id}: {}", sink.nc);
        for w in turning {
            let (a, b) = (&w[0].joints.0, &w[1].joints.0);
            let len = (0..6)
                .map(|k| match (a[k], b[k]) {
                    (Some(x), Some(y)) => (y - x) * (y - x),
                    _ => 0.0,
                })
                .sum::<f64>()
                .sqrt();
            let want = len / 1000.0 * 60.0;
            assert!(
                (w[1].time_s - want).abs() <= 1e-9 + 1e-6 * want,
                "{id}: {} s, want {want} s",
                w[1].time_s
            );
        }
        let feeds: Vec<f64> = sink
            .nc
            .lines()
            .flat_map(|l| l.split_whitespace())
            .filter_map(|w| w.strip_prefix('F').and_then(|v| v.parse().ok()))
            .collect();
        // Inverse time: a few per minute (it was 1 000 000); heidenhain, F along the axes: F1000.
        assert!(feeds.iter().all(|&f| f <= 1000.0 + 1e-9), "{id}: {feeds:?}");
    }
}

/// The tool leaves the part before a tool change and before the end (joint: to the top of Z;
/// TCP: the clearance along the tool axis). After the change the machine is not where the last
/// tool left off: the next move (here a feed, the CL file gives no RAPID) positions as a
/// rotary-turning rapid does (retract, turn, over the point, down to the clearance along the
/// tool axis), never a feed interpolated from the old tool's last block; the feed point itself
/// is reached at feed (it was reached at rapid: a plunge onto the part, the shared verifier's
/// `motion_kind`).
#[test]
fn the_first_move_after_a_tool_change_positions_at_rapid() {
    let m = machine("spinner-u5-620");
    let cl = "UNITS/MM\nLOADTL/1\nFEDRAT/500,MMPM\nGOTO/0,0,50,0.5,0,0.8660254\nGOTO/10,0,40,0.5,0,0.8660254\n\
              LOADTL/2\nGOTO/0,0,50,0,0,1\nGOTO/10,0,40,0,0,1\n";
    for mode in [Mode::Joint, Mode::Tcp] {
        let mut o = defaults(&m);
        o.mode = mode;
        let (sink, _) = run(&m, cl.as_bytes(), &o);
        let lines: Vec<&str> = sink.nc.lines().collect();
        let has = |l: &str, w: &str| l.split_whitespace().any(|x| x == w);
        let t2 = lines.iter().position(|l| has(l, "M6") && l.starts_with("T2")).expect("T2 M6");
        // Up and away before the change and before the end, in the orientation the tool has.
        let end = lines.iter().position(|l| has(l, "M30")).expect("M30");
        for at in [t2, end] {
            // (TCP: then machine Z home, once TCP is off.)
            let up = lines[..at].iter().rposition(|l| l.starts_with("G53 G0 Z0"));
            assert_eq!(up.is_some(), mode == Mode::Tcp, "{mode:?}:\n{}", sink.nc);
            let last = lines[..at]
                .iter()
                .rev()
                .find(|l| (l.contains(" Z") || l.starts_with('Z')) && !l.starts_with("G53"))
                .unwrap();
            assert!(last.contains("RETRACT") && has(last, "G0"), "{mode:?}: {last}\n{}", sink.nc);
            if mode == Mode::Joint {
                let zmax = m.linears[2].as_ref().unwrap().max;
                assert!(last.contains(&format!("Z{zmax:.3}")), "{last}");
            }
        }
        let moves: Vec<&str> = lines[t2..]
            .iter()
            .copied()
            .filter(|l| l.split_whitespace().any(|w| w.len() > 1 && "XYZBC".contains(&w[..1])))
            .collect();
        let cut = moves.iter().position(|l| has(l, "G1")).expect("the cut");
        assert!(cut >= 2, "{mode:?}: positioning before the cut:\n{}", sink.nc);
        assert!(has(moves[0], "G0") && moves[0].contains("RETRACT"), "{mode:?}:\n{}", sink.nc);
        assert!(
            !moves[..cut].iter().any(|l| has(l, "G93") || has(l, "G1")),
            "{mode:?}:\n{}",
            sink.nc
        );
        // Positioning ends at the clearance over the CL point (50 mm along the vertical axis);
        // the point is fed to, then the cut goes on.
        assert!(moves[cut - 1].contains("Z100.000"), "{mode:?}:\n{}", sink.nc);
        assert!(
            moves[cut].contains("Z50.000") && !moves[cut].contains('X'),
            "{mode:?}:\n{}",
            sink.nc
        );
        assert!(
            moves[cut + 1].contains("X10.000") && moves[cut + 1].contains("Z40.000"),
            "{mode:?}:\n{}",
            sink.nc
        );
    }
}

/// The program's first move comes from home: the rotaries turn with the tool at the top of Z
/// travel, over the point, and the tool then comes straight down, at rapid to the clearance
/// along the tool axis and at feed onto the point (a feed point: it may lie on the part);
/// nothing turns on the way down.
#[test]
fn the_first_move_turns_the_rotaries_at_the_top_then_comes_down() {
    let m = machine("spinner-u5-620");
    let zmax = m.linears[2].as_ref().unwrap().max;
    let cl = "UNITS/MM\nFEDRAT/500,MMPM\nGOTO/0,0,50,0.5,0,0.8660254\nGOTO/10,0,40,0.5,0,0.8660254\n";
    let o = defaults(&m);
    let (sink, _) = run(&m, cl.as_bytes(), &o);
    let [over, near, down] = [&sink.blocks[0], &sink.blocks[1], &sink.blocks[2]];
    assert!(over.rapid && near.rapid && !down.rapid, "{}", sink.nc);
    assert_eq!(over.joints.0[2], Some(zmax), "{}", sink.nc);
    for b in [near, down] {
        for k in [0, 1, 3, 4, 5] {
            let (a, w) = (over.joints.0[k].unwrap_or(0.0), b.joints.0[k].unwrap_or(0.0));
            assert!((a - w).abs() < 1e-9, "only Z moves on the way down:\n{}", sink.nc);
        }
    }
    let along = Vec3::from(near.tip) - Vec3::from(down.tip);
    assert!(
        (along - Vec3::new(0.5, 0.0, 0.8660254) * o.clearance).norm() < 1e-6,
        "{along:?}"
    );
    assert!((down.tip[2] - 50.0).abs() < 1e-9 && down.joints.0[4].is_some_and(|b| (b - 30.0).abs() < 1e-6));
}

#[test]
fn strict_mode_fails_cleanly_at_the_first_error() {
    let m = machine("spinner-u5-620");
    let cl = "UNITS/MM\nGOTO/0,0,50\nGOTO/1,2\nGOTO/3,4,5\n";
    let mut o = defaults(&m);
    o.strict = true;
    let mut sink = Collect::default();
    match post::post(cl.as_bytes(), &m, &o, &mut sink) {
        Err(post::Error::Strict(d)) => {
            assert_eq!(d.line, Some(3));
            assert!(d.message.contains("expected 3 values"), "{d}");
        }
        other => panic!("{other:?}"),
    }
    assert!(!sink.nc.contains("M30"), "a failed program never ends as if complete");
}

/// A tilting axis whose travel leaves out 0 (B from 5° to 120°): the branch within travel is
/// taken, though the other one turns C less. (Candidates were once judged with their rotary words
/// set to 0, which made every candidate on such a machine "outside travel".)
#[test]
fn a_travel_that_leaves_out_zero_still_tells_the_branches_apart() {
    let text = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/machines/haas-umc750.toml"))
        .unwrap()
        .replace("min = -35.0", "min = 5.0");
    let m = kinepost::machines::parse_profile(&text, "b-from-5.toml", None)
        .unwrap()
        .machine;
    let setup = Setup::new(m.default_tool_length, Vec3::zeros());
    let b = m.rotary_index('B').unwrap();
    let c = m.rotary_index('C').unwrap();
    let mut cl = String::from("UNITS/INCHES\nFEDRAT/20,IPM\n");
    for k in 0..5 {
        // The pose of B = +30°, C = 170°: the other branch is B = −30°, C = −10°.
        let mut j = Joints {
            linear: [1.0 + k as f64 * 0.1, 2.0, 3.0],
            rotary: [0.0; 3],
        };
        j.rotary[b] = 30f64.to_radians();
        j.rotary[c] = 170f64.to_radians();
        let p = fk(&m, &j, &setup);
        cl += &format!(
            "GOTO/{},{},{},{},{},{}\n",
            p.tip.x, p.tip.y, p.tip.z, p.axis.x, p.axis.y, p.axis.z
        );
    }
    let (sink, s) = run(&m, cl.as_bytes(), &defaults(&m));
    assert_eq!(s.errors, 0, "{:?}\n{}", sink.diags, sink.nc);
    for blk in &sink.blocks {
        let bw = blk.joints.0[4].unwrap();
        assert!((bw - 30.0).abs() < 1e-3, "B{bw} in {}", sink.nc);
    }
}

#[test]
fn unreachable_poses_name_the_line_and_limits_name_the_axis() {
    let m = machine("vmc-3axis");
    let cl = "UNITS/MM\nFEDRAT/500,MMPM\nGOTO/0,0,50,0,0,1\nGOTO/0,0,50,0,0.5,0.866025\nGOTO/0,0,40,0,0,1\nGOTO/900,0,40,0,0,1\n";
    let (sink, s) = run(&m, cl.as_bytes(), &defaults(&m));
    let u = sink.first(Code::Unreachable);
    assert_eq!(u.line, Some(4));
    assert!(u.message.contains("30.0"), "{u}");
    let l = sink.first(Code::LimitViolation);
    assert_eq!(l.line, Some(6));
    assert!(l.message.starts_with("X = 900"), "{l}");
    assert_eq!(s.errors, 2);
}

#[test]
fn a_bounded_rotary_unwinds_with_a_marked_retract() {
    // dmg-dmc75v's C is bounded to ±360°: three turns of C must unwind.
    let m = machine("dmg-dmc75v");
    let mut cl = String::from("UNITS/MM\nFEDRAT/800,MMPM\n");
    let setup = Setup::new(m.default_tool_length, Vec3::zeros());
    for k in 0..=360 {
        let c = (k as f64 * 3.0).to_radians();
        let j = Joints {
            linear: [20.0, 0.0, 0.0],
            rotary: [c, (-30f64).to_radians(), 0.0],
        };
        let p = fk(&m, &j, &setup);
        cl.push_str(&format!(
            "GOTO/{:.6},{:.6},{:.6},{:.9},{:.9},{:.9}\n",
            p.tip.x, p.tip.y, p.tip.z, p.axis.x, p.axis.y, p.axis.z
        ));
    }
    let (sink, s) = run(&m, cl.as_bytes(), &defaults(&m));
    assert_eq!(s.errors, 0, "{:?}", sink.diags);
    assert!(s.counts.get("unwind").copied().unwrap_or(0) >= 1, "{:?}", s.counts);
    assert!(sink.nc.contains("UNWIND"));
    let c = s.axes.get(&'C').unwrap();
    assert!(c.min >= -360.0 - 1e-9 && c.max <= 360.0 + 1e-9, "C within travel: {c:?}");
    // The shop's policy unwind=rapids: the same unwind, still retracted, is an error.
    let mut o = defaults(&m);
    o.unwind = kinepost::post::Unwind::AtRapids;
    let (strict, s2) = run(&m, cl.as_bytes(), &o);
    assert!(s2.errors >= 1 && strict.nc.contains("UNWIND") && strict.nc.contains("ERROR UNWIND"), "{}", strict.nc);
    assert_eq!(strict.blocks.len(), sink.blocks.len(), "the same motion");
    let bad = kinepost::post::Settings { unwind: Some("never".into()), ..Default::default() };
    assert!(bad.options(&m).unwrap_err().message.starts_with("unwind"));
}

/// `turns` of a 30°-tilted tool axis swept about Z around a rising circle: every GOTO turns C by
/// 5°, so the table winds on and each segment is subdivided.
fn spiral(turns: usize) -> String {
    let mut cl = String::from("UNITS/MM\nSPINDL/8000,CLW\nFEDRAT/1000,MMPM\n");
    for k in 0..=turns * 72 {
        let (a, t) = ((k as f64 * 5.0).to_radians(), 30f64.to_radians());
        cl += &format!(
            "GOTO/{:.4},{:.4},{:.4},{:.6},{:.6},{:.6}\n",
            50.0 * a.cos(),
            50.0 * a.sin(),
            10.0 + k as f64 * 0.01,
            t.sin() * a.cos(),
            t.sin() * a.sin(),
            t.cos()
        );
    }
    cl
}

/// A post stops at its budget (blocks per CL byte read beyond a floor, seconds) with an error
/// saying which, and writes nothing more; within it, nothing changes.
#[test]
fn a_post_stops_at_its_output_and_time_budget() {
    use kinepost::post::Budget;
    let m = machine("spinner-u5-620");
    let cl = spiral(4);
    let mut o = defaults(&m);
    let (_, whole) = run(&m, cl.as_bytes(), &o);
    assert!(whole.blocks > 1000, "{}", whole.blocks);
    let post_with = |b: Budget| {
        let mut o = o.clone();
        o.budget = b;
        let mut sink = Collect::default();
        (post::post(cl.as_bytes(), &m, &o, &mut sink), sink)
    };
    let tight = Budget { floor_blocks: 500, blocks_per_byte: 0, seconds: f64::INFINITY };
    let (r, sink) = post_with(tight);
    let Err(post::Error::Stop(post::Stop::Budget(why))) = r else { panic!("{r:?}") };
    assert!(why.contains("output bound") && why.contains("500"), "{why}");
    let written = sink.nc.lines().filter(|l| l.starts_with('X') || l.starts_with("G")).count();
    assert!((500..520).contains(&written), "stops at the bound: {written} lines");
    // One block a byte is far more than this path needs (about one block in ten bytes).
    let per_byte = Budget { floor_blocks: 500, blocks_per_byte: 1, seconds: f64::INFINITY };
    let (r, _) = post_with(per_byte);
    assert_eq!(r.unwrap().blocks, whole.blocks);
    let (r, _) = post_with(Budget { seconds: 0.0, ..Budget::default() });
    let Err(post::Error::Stop(post::Stop::Budget(why))) = r else { panic!("{r:?}") };
    assert!(why.contains("time bound"), "{why}");
    o.budget = Budget::new(0, 0.0).unwrap();
    assert_eq!(run(&m, cl.as_bytes(), &o).1.blocks, whole.blocks, "0: no bound");
    assert!(Budget::new(8, f64::NAN).is_err() && Budget::new(8, -1.0).is_err());
}

/// A table with far more turns of travel than the planner lists windings (LinuxCNC's ±99 999°)
/// winds on from where it stands: it once started at the lower limit (C−99 653°) and unwound
/// back there after eight turns.
#[test]
fn a_long_travel_table_winds_on_from_where_it_stands() {
    let text = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/machines/spinner-u5-620.toml"))
        .unwrap()
        .replace("max_feed = 18000.0", "min = -99999.0\nmax = 99999.0\nmax_feed = 18000.0");
    let m = kinepost::machines::parse_profile(&text, "spinner-u5-620.toml", None)
        .unwrap()
        .machine;
    let c = m.rotary_index('C').unwrap();
    assert!(m.rotaries[c].limits.is_some());
    let (sink, s) = run(&m, spiral(20).as_bytes(), &defaults(&m));
    assert_eq!((s.errors, s.warnings), (0, 0), "{:?}", sink.diags);
    let travel = s.axes.get(&'C').unwrap();
    assert!(travel.max - travel.min < 7200.0 + 360.0, "twenty turns, no unwind: {travel:?}");
    assert!(travel.min.abs().min(travel.max.abs()) < 360.0, "starts near 0: {travel:?}");
}

#[test]
fn verify_replays_any_program_and_names_the_cl_lines_it_misses() {
    use kinepost::post::verify::{VerifyOptions, verify};
    let m = machine("haas-umc750");
    let cl = std::fs::read(data("nx_clsf_mech491_variable_axis_inch_5ax.cls")).unwrap();
    let mut o = defaults(&m);
    o.mode = Mode::Tcp;
    let (sink, _) = run(&m, &cl, &o);
    let vo = VerifyOptions {
        mode: Mode::Tcp,
        setup: Setup::new(3.0, Vec3::zeros()),
        tolerance: 0.0004,
        angle_tolerance_deg: 0.01,
        cl_units: None,
        cl_tool_length: true,
        tool_table: None,
    };
    let ours = verify(&cl[..], sink.nc.as_bytes(), &m, &vo).unwrap();
    assert!(ours.ok && ours.matched == 348, "{ours:?}");
    // The real NX post's program verifies too (a second opinion on the check itself).
    let golden = std::fs::read(data("golden/nx_post_HAAS_UMC750_variable_axis.nc")).unwrap();
    let nx = verify(&cl[..], &golden[..], &m, &vo).unwrap();
    assert!(nx.ok, "{nx:?}");
    // Tamper with one B word: that CL point is missed and named.
    let bad = sink.nc.replacen("B-20.8330", "B-20.8630", 1);
    assert_ne!(bad, sink.nc);
    let r = verify(&cl[..], bad.as_bytes(), &m, &vo).unwrap();
    assert!(!r.ok);
    assert_eq!(r.matched, 347);
    assert_eq!(r.misses[0].cl_line, 26, "{:?}", r.misses);
}

#[test]
fn a_singular_tolerance_holds_the_free_rotary_within_its_bound_and_reports_what_it_saved() {
    use kinepost::post::verify::{VerifyOptions, verify};
    let m = machine("haas-umc750");
    let cl = std::fs::read(data("nx_clsf_mech491_variable_axis_inch_5ax.cls")).unwrap();
    let mut o = defaults(&m);
    o.mode = Mode::Tcp;
    let (_, exact) = run(&m, &cl, &o);
    o.singular_tolerance = 0.5f64.to_radians();
    let (sink, held) = run(&m, &cl, &o);
    let (ce, ch) = (exact.axes[&'C'].travel.unwrap(), held.axes[&'C'].travel.unwrap());
    assert!(ch < ce - 100.0, "C travel {ch} vs exact {ce}");
    assert!(
        (held.smoothing_travel_saved_deg - (ce - ch)).abs() < 0.5,
        "reported {} vs {}",
        held.smoothing_travel_saved_deg,
        ce - ch
    );
    assert!(held.smoothing_max_deviation_deg <= 0.5 + 1e-6 && held.smoothing_max_deviation_deg > 0.4);
    assert!(held.smoothed_blocks > 0 && held.errors == 0);
    assert!(
        sink.diags
            .iter()
            .any(|d| d.code == Code::Singular && d.message.contains("held"))
    );
    // Tips stay exact; orientation within the stated bound.
    let vo = VerifyOptions {
        mode: Mode::Tcp,
        setup: Setup::new(3.0, Vec3::zeros()),
        tolerance: 0.0004,
        angle_tolerance_deg: 0.5 + 1e-3,
        cl_units: None,
        cl_tool_length: true,
        tool_table: None,
    };
    assert!(verify(&cl[..], sink.nc.as_bytes(), &m, &vo).unwrap().ok);
}

/// NX CLSF arcs turn clockwise about their CIRCLE axis: the real NX post writes this lead-in as
/// `G03 X-10.4331 Y6.4961 I.2953 J0.0` (counter-clockwise about +Z) for an axis of (0,0,-1).
/// Word-address output writes that arc; where arcs are linearized (the conversational dialect,
/// for now) the chords must run that quarter, not the other three.
#[test]
fn nx_arcs_turn_the_way_the_nx_post_cuts_them() {
    let m = machine("haas-umc750");
    let cl = std::fs::read(data("nx_clsf_mech491_simple_mill_plane_mm.cls")).unwrap();
    let mut o = fanuc(&m, Mode::Joint);
    let (sink, _) = run(&m, &cl, &o);
    assert!(
        sink.nc.contains("G3 X-10.4331 Y6.4961 Z3.9370 I0.2953 J0.0000"),
        "{}",
        &sink.nc[..800]
    );
    // Heidenhain: the same arc as CC + C. From X-10.7283 Y6.7913 (180° about the centre) to
    // X-10.4331 Y6.4961 (270°) counter-clockwise (DR+): through the lower-left quarter, as NX cut.
    o.dialect = kinepost::nc::dialect("heidenhain").unwrap();
    let (sink, _) = run(&m, &cl, &o);
    let lines: Vec<&str> = sink.nc.lines().collect();
    let k = lines
        .iter()
        .position(|l| l.ends_with(" CC X-10.4331 Y+6.7913"))
        .expect("the centre");
    assert!(lines[k - 1].contains("Z+3.9370"), "{}", lines[k - 1]);
    let xy = lines[..k].iter().rev().find(|l| l.contains(" X")).unwrap();
    assert!(xy.contains("X-10.7283 Y+6.7913"), "{xy}");
    assert!(lines[k + 1].ends_with(" C X-10.4331 Y+6.4961 DR+"), "{}", lines[k + 1]);
}

#[test]
fn the_nc_reader_knows_g2_from_g20() {
    let nc = "%\nG21\nG0 X1 Y2 Z3\nG2 X2 Y3 I1 J0\nG20\nG1 X1\n%\n";
    let mut r = NcReader::new(nc.as_bytes(), Units::Mm);
    let a = r.next_block().unwrap().unwrap();
    assert_eq!((a.units, a.rapid), (Units::Mm, true));
    let b = r.next_block().unwrap().unwrap();
    assert_eq!((b.units, b.rapid), (Units::Mm, false), "G2 is an arc, not inch");
    let c = r.next_block().unwrap().unwrap();
    assert_eq!(c.units, Units::Inch, "G20 is inch");
}

/// Canned cycles read as the moves a control makes: position at the current level, rapid to R,
/// feed to Z, back to the initial level (G98) or R (G99); repeats drill at each new X Y; G80 ends.
#[test]
fn the_nc_reader_expands_canned_cycles() {
    let nc = "G0 X0 Y0 Z50\nG98 G81 X10 Y5 Z-5 R2 F100\nX20\nG99 G83 X30 Z-8 R1 Q2\nG80\nG0 Z60\n";
    let mut r = NcReader::new(nc.as_bytes(), Units::Mm);
    let mut got = Vec::new();
    while let Some(b) = r.next_block().unwrap() {
        got.push((b.axes[0].unwrap(), b.axes[1].unwrap(), b.axes[2].unwrap(), b.rapid));
    }
    #[rustfmt::skip]
    let want = [
        (0.0, 0.0, 50.0, true),
        (10.0, 5.0, 50.0, true), (10.0, 5.0, 2.0, true), (10.0, 5.0, -5.0, false), (10.0, 5.0, 50.0, true),
        (20.0, 5.0, 50.0, true), (20.0, 5.0, 2.0, true), (20.0, 5.0, -5.0, false), (20.0, 5.0, 50.0, true),
        (30.0, 5.0, 50.0, true), (30.0, 5.0, 1.0, true), (30.0, 5.0, -8.0, false), (30.0, 5.0, 1.0, true),
        (30.0, 5.0, 60.0, true),
    ];
    assert_eq!(got, want);
}

/// The three golden programs of the real NX post (HAAS_UMC750_5AXIS_MILL_IN) against kinepost's,
/// Haas dialect: every golden motion block's X Y Z appears in order within 0.0001 in, and every
/// golden arc as an arc of the same sense with the same I J.
#[test]
fn haas_dialect_matches_the_nx_golden_programs() {
    let m = machine("haas-umc750");
    for (cl, golden, mode) in [
        (
            "nx_clsf_mech491_variable_axis_inch_5ax.cls",
            "nx_post_HAAS_UMC750_variable_axis.nc",
            Mode::Tcp,
        ),
        (
            "nx_clsf_mech491_simple_mill_plane_mm.cls",
            "nx_post_HAAS_UMC750_simple_mill_plane.nc",
            Mode::Joint,
        ),
        (
            "nx_clsf_mech491_simple_mill_plane_zig_mm.cls",
            "nx_post_HAAS_UMC750_simple_mill_plane_zig.nc",
            Mode::Joint,
        ),
    ] {
        let mut o = defaults(&m);
        o.mode = mode;
        assert_eq!(o.dialect.name, "haas", "the profile's controller is the default");
        let (sink, s) = run(&m, &std::fs::read(data(cl)).unwrap(), &o);
        assert_eq!(s.errors, 0, "{cl}");
        let gold = std::fs::read_to_string(data(&format!("golden/{golden}"))).unwrap();
        let read = |t: &str| {
            let mut r = NcReader::new(t.as_bytes(), Units::Inch);
            let mut v = Vec::new();
            while let Some(b) = r
                .next_block()
                .unwrap_or_else(|e| panic!("{golden}: {e}: {}", &t[..300.min(t.len())]))
            {
                v.push(b);
            }
            v
        };
        let (g, k) = (read(&gold), read(&sink.nc));
        let mut j = 0;
        let mut matched = 0;
        for gb in &g {
            let (Some(x), Some(y), Some(z)) = (gb.axes[0], gb.axes[1], gb.axes[2]) else {
                continue;
            };
            while j < k.len()
                && !k[j].axes[..3]
                    .iter()
                    .zip([x, y, z])
                    .all(|(a, b)| a.is_some_and(|a| (a - b).abs() <= 1e-4 + 1e-9))
            {
                j += 1;
            }
            assert!(j < k.len(), "{golden} line {}: X{x} Y{y} Z{z} not found in order", gb.line);
            matched += 1;
        }
        assert!(matched > 30, "{golden}: {matched} blocks compared");
        // Arcs: same sense, same end point and centre offsets.
        let words = |line: &str, l: char| -> Option<f64> {
            let i = line.find(l)?;
            let rest = &line[i + 1..];
            let end = rest
                .find(|c: char| !(c.is_ascii_digit() || c == '.' || c == '-'))
                .unwrap_or(rest.len());
            rest[..end].parse().ok()
        };
        let arcs: Vec<&str> = gold.lines().filter(|l| l.contains("G02") || l.contains("G03")).collect();
        for ga in &arcs {
            let ccw = ga.contains("G03");
            let want = ['X', 'Y', 'I', 'J'].map(|l| words(ga, l));
            let found = sink.nc.lines().any(|l| {
                (l.contains(if ccw { "G3 " } else { "G2 " }))
                    && ['X', 'Y', 'I', 'J'].iter().zip(want).all(|(c, w)| match (words(l, *c), w) {
                        (Some(a), Some(b)) => (a - b).abs() <= 1e-4 + 1e-9,
                        (_, None) => true,
                        (None, Some(_)) => false,
                    })
            });
            assert!(found, "{golden}: arc {ga:?} not written the same way");
        }
        if golden.contains("plane") {
            assert!(!arcs.is_empty());
        }
    }
}

#[test]
fn rapids_that_turn_rotaries_retract_first_and_turn_alone() {
    let m = machine("spinner-u5-620");
    let (s30, c30) = (30f64.to_radians().sin(), 30f64.to_radians().cos());
    let cl = format!(
        "UNITS/MM\nFEDRAT/500,MMPM\nGOTO/0,0,10,0,0,1\nGOTO/10,0,10,0,0,1\nRAPID\nGOTO/20,5,30,{s30},0,{c30}\nGOTO/25,5,28,{s30},0,{c30}\n"
    );
    let mut o = fanuc(&m, Mode::Joint);
    let (sink, s) = run(&m, cl.as_bytes(), &o);
    assert_eq!(s.errors, 0);
    let lines: Vec<&str> = sink.nc.lines().collect();
    let i = lines
        .iter()
        .position(|l| l.contains("(RETRACT Z)"))
        .expect("retract before turning");
    assert!(
        lines[i].starts_with("G0 Z460.000"),
        "machine Z to the top of travel: {}",
        lines[i]
    );
    let turn = lines[i + 1];
    let code = turn.split('(').next().unwrap();
    assert!(
        turn.contains("ROTARY REPOSITION")
            && code.contains('B')
            && !code.contains('X')
            && !code.contains('Y')
            && !code.contains('Z'),
        "rotaries alone: {turn}"
    );
    assert!(
        lines[i + 2].contains('X') && !lines[i + 2].contains('Z'),
        "then X Y at the top: {}",
        lines[i + 2]
    );
    assert!(lines[i + 3].starts_with('Z'), "then down: {}", lines[i + 3]);
    // TCP mode: lift along the tool axis, turn at clearance.
    o.mode = Mode::Tcp;
    let (sink, _) = run(&m, cl.as_bytes(), &o);
    assert!(sink.nc.contains("(RETRACT)") && sink.nc.contains("(ROTARY REPOSITION)"));
}

/// Two rapids in a row that each turn the rotaries climbed to the top of Z twice: the second
/// starts at a CL rapid point in the air, lifts along the tool axis, turns there and comes down,
/// and both rapid points are still reached.
#[test]
fn consecutive_rapids_that_turn_rotaries_climb_to_the_top_of_z_once() {
    let m = machine("spinner-u5-620");
    let (s30, c30) = (30f64.to_radians().sin(), 30f64.to_radians().cos());
    let cl = format!(
        "UNITS/MM\nFEDRAT/500,MMPM\nGOTO/0,0,10,0,0,1\nGOTO/10,0,10,0,0,1\nRAPID\nGOTO/20,5,60,{s30},0,{c30}\n\
         RAPID\nGOTO/20,5,60,0,{s30},{c30}\nGOTO/25,5,58,0,{s30},{c30}\n"
    );
    let o = fanuc(&m, Mode::Joint);
    let (sink, s) = run(&m, cl.as_bytes(), &o);
    assert_eq!(s.errors, 0, "{:?}", sink.diags);
    let climbs = sink.nc.lines().filter(|l| l.contains("(RETRACT Z)")).count();
    assert_eq!(climbs, 1, "one climb to the top of Z:\n{}", sink.nc);
    let lift = sink.nc.lines().position(|l| l.contains("(RETRACT)")).expect("a lift along the tool axis");
    let turn = sink.nc.lines().nth(lift + 1).unwrap();
    assert!(turn.contains("ROTARY REPOSITION") && turn.contains('C'), "turned at clearance: {turn}");
    replay_matches(&m, &cl, &sink.nc, Mode::Joint, &Setup::new(m.default_tool_length, Vec3::zeros()), 1e-3);
    // A cut between them: the next rotary rapid climbs again.
    let cut = cl.replace("\nRAPID\nGOTO/20,5,60,0,", &format!("\nGOTO/21,5,60,{s30},0,{c30}\nRAPID\nGOTO/20,5,60,0,"));
    let (sink, _) = run(&m, cut.as_bytes(), &o);
    assert_eq!(sink.nc.lines().filter(|l| l.contains("(RETRACT Z)")).count(), 2, "{}", sink.nc);
}

#[test]
fn clamped_rotaries_unlock_before_they_turn_and_lock_after_positioning() {
    let lib = common::library();
    let p = lib.get("haas-umc750").unwrap();
    let mut o = defaults(&p.machine);
    o.mode = Mode::Tcp;
    o.clamps = p.clamps();
    let (sink, _) = run(
        &p.machine,
        &std::fs::read(data("nx_clsf_mech491_variable_axis_inch_5ax.cls")).unwrap(),
        &o,
    );
    let lines: Vec<&str> = sink.nc.lines().collect();
    let first_rotary = lines.iter().position(|l| l.contains('B') && l.starts_with("G0")).unwrap();
    let unlock_b = lines.iter().position(|l| l.starts_with("M13")).expect("B unlocked");
    let unlock_c = lines.iter().position(|l| l.starts_with("M11")).expect("C unlocked");
    assert!(
        unlock_b < first_rotary && unlock_c < first_rotary,
        "unlocked before the first move that turns them"
    );
    let end = lines.iter().position(|l| l.starts_with("M30")).unwrap();
    assert!(
        lines[..end].iter().rev().take(7).any(|l| l.starts_with("M12")) && lines[..end].iter().any(|l| l.starts_with("M10")),
        "locked at the end"
    );
    // A 3-axis program on the same machine never unlocks.
    let (sink, _) = run(
        &p.machine,
        &std::fs::read(data("nx_clsf_mech491_simple_mill_plane_mm.cls")).unwrap(),
        &Options {
            clamps: p.clamps(),
            ..defaults(&p.machine)
        },
    );
    assert!(!sink.nc.contains("UNLOCK"));
}

/// A segment whose axis sweeps through the singular direction symmetrically (a lead angle from
/// −20° to +20°, common in CAM output) has its subdivision midpoint exactly on it, where the free
/// rotary takes the interpolated angle: the linears must follow that angle. They were computed
/// for the first rotary's angle, a block 35 mm off its pose on spinner-u5-620 (caught only by the
/// self-verification).
#[test]
fn a_segment_through_the_singular_direction_keeps_every_block_on_its_pose() {
    let lib = common::library();
    let mut checked = 0;
    for p in lib.iter() {
        let m = &p.machine;
        let Some(s1) = kinepost::kinematics::singular_direction(m) else {
            continue;
        };
        let setup = Setup::new(m.default_tool_length, Vec3::zeros());
        let tip = mid_travel_tip(m, &setup);
        let reachable = |a: Vec3| {
            let pose = kinepost::kinematics::Pose { tip, axis: a };
            kinepost::kinematics::ik(m, &pose, &setup, &Default::default()).is_ok()
        };
        // Either sense of the rotary's line, a plane through it in which both tilts are
        // orientations the machine reaches.
        let Some((d, e)) = [s1, -s1]
            .into_iter()
            .flat_map(|d| [Vec3::x(), Vec3::y(), Vec3::z()].map(|w| (d, d.cross(&w))))
            .filter_map(|(d, e)| Some((d, e.try_normalize(1e-9)?)))
            .find(|&(d, e)| reachable(tilt(d, e, -20f64.to_radians())) && reachable(tilt(d, e, 20f64.to_radians())))
        else {
            panic!("{}: no reachable tilt about {s1:?}", m.id)
        };
        let (a1, a2) = (tilt(d, e, -20f64.to_radians()), tilt(d, e, 20f64.to_radians()));
        let cl = format!(
            "UNITS/{}\nFEDRAT/500\nGOTO/{},{},{},{},{},{}\nGOTO/{},{},{},{},{},{}\n",
            if m.units == Units::Inch { "INCHES" } else { "MM" },
            tip.x,
            tip.y,
            tip.z,
            a1.x,
            a1.y,
            a1.z,
            tip.x + 1.0,
            tip.y,
            tip.z,
            a2.x,
            a2.y,
            a2.z,
        );
        let o = defaults(m);
        let (sink, s) = run(m, cl.as_bytes(), &o);
        let bad: Vec<_> = sink
            .diags
            .iter()
            .filter(|d| d.code == Code::VerifyDeviation || d.code == Code::Unreachable)
            .collect();
        assert!(bad.is_empty(), "{}: {bad:?}\n{}", m.id, sink.nc);
        assert!(
            s.max_tip_deviation <= o.tolerance,
            "{}: {}\n{}",
            m.id,
            s.max_tip_deviation,
            sink.nc
        );
        assert!(
            s.inserted_blocks > 0,
            "{}: the segment is subdivided through the midpoint",
            m.id
        );
        checked += 1;
    }
    assert!(checked >= 4, "{checked} two-rotary profiles");
}

/// Inverse time is 1/min: a long move's value is small, and one decimal (F0.1 for 0.149) was a
/// third off its time. Every G93 F now carries the block's time to the word's last digit; a feed
/// that rounds to F0 (an alarm) is the smallest F, with a warning.
#[test]
fn inverse_time_keeps_its_precision_and_no_feed_word_is_zero() {
    /// Each written line with its block.
    #[derive(Default)]
    struct Lines(Vec<(String, Option<BlockInfo>)>, Vec<Diagnostic>);
    impl Sink for Lines {
        fn line(&mut self, text: &str, b: Option<&BlockInfo>) -> Result<(), kinepost::post::Stop> {
            self.1.extend(b.iter().flat_map(|b| b.diagnostics.iter().cloned()));
            self.0.push((text.to_string(), b.cloned()));
            Ok(())
        }
        fn diagnostic(&mut self, _: &Diagnostic) -> Result<(), kinepost::post::Stop> {
            Ok(())
        }
    }
    let m = machine("spinner-u5-620");
    let cl = "UNITS/MM\nFEDRAT/1,MMPM\nGOTO/0,0,50,0,0,1\nGOTO/200,0,50,0.5,0,0.8660254\n\
              FEDRAT/0.01,MMPM\nGOTO/210,0,50,0.5,0,0.8660254\n";
    let mut sink = Lines::default();
    post::post(cl.as_bytes(), &m, &defaults(&m), &mut sink).unwrap();
    let (mut inverse, mut per_min) = (0, 0);
    let mut g93 = false;
    for (text, b) in &sink.0 {
        g93 = (g93 || text.contains("G93")) && !text.contains("G94");
        let Some(f) = text
            .split_whitespace()
            .find_map(|w| w.strip_prefix('F').and_then(|v| v.parse::<f64>().ok()))
        else {
            continue;
        };
        assert!(f > 0.0, "{text}");
        let b = b.as_ref().unwrap();
        if g93 {
            // 1/min to the word's three decimals; most of these moves take minutes (F < 1).
            let want = 60.0 / b.time_s;
            assert!((f - want).abs() <= 0.0005 + 1e-12, "{text}: 1/min is {want}");
            inverse += (want < 1.0) as usize;
        } else {
            per_min += 1;
        }
    }
    assert!(inverse >= 2 && per_min >= 1, "{:?}", sink.0);
    // FEDRAT/0.01 mm/min: F0.0 before, now F0.1 with the warning that says so.
    let clamped: Vec<_> = sink.1.iter().filter(|d| d.code == Code::FeedClamped).collect();
    assert!(clamped.len() == 1 && clamped[0].line == Some(6), "{clamped:?}");
    assert!(sink.0.iter().any(|(t, _)| t.ends_with("F0.1")), "{:?}", sink.0);
}

/// A CL point 10⁵× outside travel (a typo) is a limit error; the segments to and from it are
/// written straight, not followed to the tolerance (2¹⁴ leaves that cannot converge, each a
/// reposition: 98 000 blocks for this file).
#[test]
fn a_point_far_outside_travel_is_one_error_not_a_flood_of_blocks() {
    let m = machine("spinner-u5-620");
    let cl = "UNITS/MM\nFEDRAT/1000,MMPM\nGOTO/0,0,50,0,0.5,0.8660254\nGOTO/10,0,50,0,0.5,0.8660254\n\
              GOTO/1e8,0,50,0.5,0,0.8660254\nGOTO/20,0,50,0,-0.5,0.8660254\n";
    let (sink, s) = run(&m, cl.as_bytes(), &defaults(&m));
    assert!(s.blocks < 100, "{} blocks", s.blocks);
    let limits: Vec<_> = sink.diags.iter().filter(|d| d.code == Code::LimitViolation).collect();
    assert!(limits.len() == 1 && limits[0].line == Some(5), "{limits:?}");
}

/// A surface speed is turned into RPM at the cutter's diameter (a mill's S word is RPM): it was
/// written as S300 for 300 ft/min, an eighth of the speed a ½-inch cutter needs. A lathe tool
/// (refused now, see below) or no diameter: written as S with a warning, as before.
#[test]
fn surface_speed_becomes_rpm_at_the_cutters_diameter() {
    let s_words = |nc: &str| -> Vec<String> {
        nc.lines()
            .filter(|l| !l.starts_with('('))
            .flat_map(|l| l.split_whitespace())
            .filter(|w| w.starts_with('S') && w[1..].parse::<f64>().is_ok())
            .map(str::to_string)
            .collect()
    };
    let motion = "GOTO/0,0,1,0,0,1\nGOTO/1,0,1,0,0,1\n";
    let m = machine("haas-umc750");
    let cases = [
        // 300 ft/min at Ø0.5 in: 300·12/(π·0.5) = 2291.8.
        (
            "UNITS/INCHES\nCUTTER/0.5\nSPINDL/300,SFM,CLW\nFEDRAT/20,IPM\n",
            "S2292",
            Severity::Info,
        ),
        // 200 m/min at Ø10 mm: 200 000/(π·10) = 6366.2; the CL in mm, the machine in inch.
        (
            "UNITS/MM\nTLDATA/MILL,10,0,50\nSPINDL/200,SMM\nFEDRAT/500,MMPM\n",
            "S6366",
            Severity::Info,
        ),
        // (A lathe tool's program is refused: `a_turning_program_is_refused_never_milled`.)
        ("UNITS/MM\nSPINDL/120,SFM\nFEDRAT/500,MMPM\n", "S120", Severity::Warning),
    ];
    for (head, want, sev) in cases {
        let cl = format!("{head}{motion}");
        let (sink, _) = run(&m, cl.as_bytes(), &defaults(&m));
        assert_eq!(s_words(&sink.nc), vec![want.to_string()], "{cl}\n{}", sink.nc);
        let d: Vec<_> = sink.diags.iter().filter(|d| d.code == Code::SurfaceSpeed).collect();
        assert!(d.len() == 1 && d[0].severity == sev, "{cl}: {d:?}");
    }
    // A feed per revolution goes with the converted speed: 0.01 in/rev at 2292 RPM.
    let cl = format!("UNITS/INCHES\nCUTTER/0.5\nSPINDL/300,SFM\nFEDRAT/0.01,IPR\n{motion}");
    let (sink, _) = run(&m, cl.as_bytes(), &defaults(&m));
    assert!(sink.nc.contains("F22.92"), "{}", sink.nc);
}

/// A path passing microradians from the singular direction: the exact free rotary chases the
/// azimuth of an all but vertical axis to and fro, and linearization stopped 14 halvings deep at
/// 0.98 of the tolerance, over once the words were rounded (`kinepost verify` failed kinepost's
/// own output). However fine the tolerance, one segment makes at most 2¹⁴ blocks, with a warning.
#[test]
fn linearization_follows_a_near_singular_swing_and_is_bounded() {
    let m = machine("spinner-u5-620");
    let cl = std::fs::read_to_string(data("generated/near_singular_jitter.cls")).unwrap();
    let o = defaults(&m);
    let (sink, s) = run(&m, cl.as_bytes(), &o);
    assert_eq!(s.errors, 0, "{:?}", sink.diags);
    let vo = kinepost::post::verify::VerifyOptions {
        mode: Mode::Joint,
        setup: Setup::new(m.default_tool_length, Vec3::zeros()),
        tolerance: o.tolerance,
        angle_tolerance_deg: 0.01,
        cl_units: None,
        cl_tool_length: true,
        tool_table: None,
    };
    let r = kinepost::post::verify::verify(cl.as_bytes(), sink.nc.as_bytes(), &m, &vo).unwrap();
    assert!(r.ok, "{r:?}");
    // Where the interpolated rotaries miss the orientation by less than a word says, they are
    // the midpoint: C no longer chases the azimuth to and fro (15 branch changes before).
    let chases: Vec<_> = sink.diags.iter().filter(|d| d.code == Code::BranchChange).collect();
    assert!(chases.is_empty(), "{chases:?}");
    // A quarter turn of B at a tolerance of 1e-7 mm wants 40 000 blocks: 2^14, told.
    let mut o = defaults(&m);
    o.tolerance = 1e-7;
    let cl = "UNITS/MM\nFEDRAT/500,MMPM\nGOTO/100,0,50,0,0,1\nGOTO/100,0,50,1,0,0\n";
    let (sink, s) = run(&m, cl.as_bytes(), &o);
    assert!(s.blocks <= (1 << 14) + 100, "{} blocks", s.blocks);
    let told: Vec<_> = sink
        .diags
        .iter()
        .filter(|d| d.code == Code::Linearized && d.severity == Severity::Warning)
        .collect();
    assert_eq!(told.len(), 1, "{told:?}");
}

/// Where a two-rotary profile meets its singular direction: a tip at mid travel, the direction
/// (`±s1`) the tool reaches there and at `reach` radians from it, two unit vectors across it.
struct SingularFrame {
    base: Vec3,
    d: Vec3,
    e1: Vec3,
    e2: Vec3,
}

fn singular_frame(m: &Machine, setup: &Setup, reach: f64) -> Option<SingularFrame> {
    let s1 = kinepost::kinematics::singular_direction(m)?;
    let base = mid_travel_tip(m, setup);
    let reachable = |a: Vec3| {
        let pose = kinepost::kinematics::Pose { tip: base, axis: a };
        kinepost::kinematics::ik(m, &pose, setup, &Default::default())
            .is_ok_and(|sols| sols.iter().any(|s| kinepost::kinematics::reachable_within_limits(m, s)))
    };
    let perp = |d: Vec3| {
        [Vec3::x(), Vec3::y(), Vec3::z()]
            .into_iter()
            .find_map(|w| d.cross(&w).try_normalize(1e-6))
            .unwrap()
    };
    // htm50200-horizontal reaches its singular direction (±X) only with a work offset.
    let d = [s1, -s1]
        .into_iter()
        .find(|&d| reachable(tilt(d, perp(d), reach)) && reachable(d))?;
    Some(SingularFrame {
        base,
        d,
        e1: perp(d),
        e2: d.cross(&perp(d)),
    })
}

/// A random path about a reachable tip whose tool axis stays within a few degrees of a
/// two-rotary profile's singular direction: exactly on it, symmetric about it, jittered by
/// microradians to degrees. What fuzzing found there (a midpoint 35 mm off its pose, the free
/// rotary chasing the azimuth until linearization gave up): every block reproduces its pose, the
/// motion between blocks stays on the CL segments, joint and TCP mode.
fn near_singular_path(id: &str, seed: &[f64]) -> Result<bool, proptest::test_runner::TestCaseError> {
    use proptest::prelude::*;
    let m = machine(id);
    let setup = Setup::new(m.default_tool_length, Vec3::zeros());
    let Some(SingularFrame { base, d, e1, e2, .. }) = singular_frame(&m, &setup, 0.03) else {
        return Ok(false);
    };
    let scale = if m.units == Units::Mm { 1.0 } else { 1.0 / 25.4 };
    let mut cl = format!(
        "UNITS/{}\nFEDRAT/{}\n",
        if m.units == Units::Mm { "MM" } else { "INCHES" },
        500.0 * scale
    );
    let mut k = 0;
    let mut next = || {
        k += 1;
        seed[(k - 1) % seed.len()]
    };
    let n = 12;
    let (mut r, mut phi) = (0.0, 0.0);
    for _ in 0..n {
        let tip = base + Vec3::new(next() - 0.5, next() - 0.5, next() - 0.5) * (40.0 * scale);
        if next() < 0.4 {
            // The mirror of the last axis: the segment's midpoint is exactly singular.
            phi += std::f64::consts::PI;
        } else {
            // Distance from the singular direction: exactly on it, microradians, or degrees.
            r = match (next() * 4.0) as u32 {
                0 => 0.0,
                1 => 1e-6 * next(),
                2 => 1e-3 * next(),
                _ => 0.05 * next(),
            };
            phi = 6.3 * next();
        }
        let e = e1 * phi.cos() + e2 * phi.sin();
        let a = tilt(d, e, r);
        cl += &format!("GOTO/{},{},{},{:.12},{:.12},{:.12}\n", tip.x, tip.y, tip.z, a.x, a.y, a.z);
    }
    for (_, s, _) in post_and_verify(&m, &cl)? {
        prop_assert_eq!(s.cl_points, n as u64);
    }
    Ok(true)
}

type PathCheck = fn(&str, &[f64]) -> Result<bool, proptest::test_runner::TestCaseError>;

/// `check` on every shipped profile; it says whether the profile could take its path (a
/// two-rotary chain that reaches its singular direction), and at least five must.
fn on_two_rotary_profiles(check: PathCheck, seed: &[f64]) -> Result<(), proptest::test_runner::TestCaseError> {
    let lib = common::library();
    let mut exercised = 0;
    for p in lib.iter() {
        exercised += check(&p.machine.id, seed)? as u32;
    }
    proptest::prop_assert!(exercised >= 5, "{exercised} profiles");
    Ok(())
}

/// What `kinepost verify` is given for a program posted with `o`: its mode and tolerance, the
/// profile's tool length until the CL sets one, no work offset.
fn verify_options(m: &Machine, o: &Options) -> kinepost::post::verify::VerifyOptions {
    kinepost::post::verify::VerifyOptions {
        mode: o.mode,
        setup: Setup::new(m.default_tool_length, Vec3::zeros()),
        tolerance: o.tolerance,
        angle_tolerance_deg: 0.01,
        cl_units: None,
        cl_tool_length: true,
        tool_table: None,
    }
}

/// `cl` posted on `m` in joint and TCP mode (word address), each program replayed through
/// `verify`: no error diagnostic, every check passed. Returns mode, summary and report.
fn post_and_verify(
    m: &Machine,
    cl: &str,
) -> Result<Vec<(Mode, Summary, kinepost::post::verify::Report)>, proptest::test_runner::TestCaseError> {
    use proptest::prelude::*;
    let mut out = Vec::new();
    for mode in [Mode::Joint, Mode::Tcp] {
        let o = fanuc(m, mode);
        let (sink, s) = run(m, cl.as_bytes(), &o);
        let errors: Vec<_> = sink.diags.iter().filter(|d| d.severity == Severity::Error).collect();
        prop_assert!(errors.is_empty(), "{} {mode:?}: {errors:?}\n{cl}", m.id);
        let r = kinepost::post::verify::verify(cl.as_bytes(), sink.nc.as_bytes(), m, &verify_options(m, &o)).unwrap();
        prop_assert!(r.ok, "{} {mode:?}: {r:?}\n{cl}\n{}", m.id, sink.nc);
        out.push((mode, s, r));
    }
    Ok(out)
}

/// A cut that tilts onto the singular direction and leaves it toward another azimuth (a vertical
/// stretch between two tilted ones), on every two-rotary profile, joint and TCP: the free rotary
/// turns at the singular point, tip standing, where any angle of it holds the CL orientation;
/// every block between CL points keeps the tool axis on the CL arc. It turned during the cut
/// after the point: 0.7° off the arc for a 2° step on spinner-u5-620, 31° for a 90° tilt.
fn leaving_the_singular_direction(id: &str, seed: &[f64]) -> Result<bool, proptest::test_runner::TestCaseError> {
    use proptest::prelude::*;
    let m = machine(id);
    let setup = Setup::new(m.default_tool_length, Vec3::zeros());
    let (step_in, step_out) = ((0.5 + 4.5 * seed[0]).to_radians(), (0.5 + 14.5 * seed[1]).to_radians());
    let Some(SingularFrame { base, d, e1, e2 }) = singular_frame(&m, &setup, 3.0 * step_out.max(step_in)) else {
        return Ok(false);
    };
    let (phi_in, phi_out) = (6.3 * seed[2], 6.3 * seed[3]);
    let scale = if m.units == Units::Mm { 1.0 } else { 1.0 / 25.4 };
    let mut cl = format!(
        "UNITS/{}\nFEDRAT/{}\n",
        if m.units == Units::Mm { "MM" } else { "INCHES" },
        500.0 * scale
    );
    let dir = |phi: f64| e1 * phi.cos() + e2 * phi.sin();
    let mut goto = |k: f64, a: Vec3| {
        let tip = base + (e1 * (seed[4] - 0.5) + e2 * (seed[5] - 0.5)) * (8.0 * k * scale);
        cl += &format!("GOTO/{},{},{},{:.12},{:.12},{:.12}\n", tip.x, tip.y, tip.z, a.x, a.y, a.z);
    };
    for k in 0..=3 {
        goto(k as f64 - 3.0, tilt(d, dir(phi_in), (3 - k) as f64 * step_in));
    }
    for k in 1..=3 {
        goto(k as f64, tilt(d, dir(phi_out), k as f64 * step_out));
    }
    for (mode, s, r) in post_and_verify(&m, &cl)? {
        prop_assert!(s.max_singular_deviation_deg < 1e-9, "{id} {mode:?}: {s:?}\n{cl}");
        prop_assert_eq!(r.matched, 7);
        // Rotary words of 4 decimals leave the axis within 1e-4° of its pose.
        prop_assert!(r.max_axis_off_arc_deg < 1e-3, "{id} {mode:?}: {r:?}\n{cl}");
    }
    Ok(true)
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(32))]
    #[test]
    fn paths_about_the_singular_direction_post_clean_on_every_two_rotary_profile(
        seed in proptest::collection::vec(0.0f64..1.0, 64)
    ) {
        on_two_rotary_profiles(near_singular_path, &seed)?;
    }

    #[test]
    fn a_cut_leaving_the_singular_direction_turns_the_free_rotary_at_it(
        seed in proptest::collection::vec(0.0f64..1.0, 6)
    ) {
        on_two_rotary_profiles(leaving_the_singular_direction, &seed)?;
    }
}

/// One feed segment tilting a nutating table's tool axis by 60°, nowhere near its singular
/// direction: the exact midpoints leave the joint interpolation by degrees, which is no swing of
/// a free rotary. Taken for one, the interpolated rotaries were held: 1.3° off the CL arc (a
/// CATIA file's 90° tilt: 31°), reported as a singular deviation.
#[test]
fn a_long_tilt_on_a_nutating_table_keeps_its_orientation() {
    let m = machine("dmu-nutating-45");
    let ax = |t: f64| {
        let (t, az) = (t.to_radians(), 30f64.to_radians());
        (t.sin() * az.cos(), t.sin() * az.sin(), t.cos())
    };
    let ((a, b, c), (i, j, k)) = (ax(10.0), ax(70.0));
    let cl = format!("UNITS/MM\nFEDRAT/500\nGOTO/0,0,20,{a},{b},{c}\nGOTO/20,0,20,{i},{j},{k}\n");
    for (mode, s, r) in post_and_verify(&m, &cl).unwrap() {
        assert_eq!(s.max_singular_deviation_deg, 0.0, "{mode:?}");
        assert!(r.max_axis_off_arc_deg < 1e-3, "{mode:?}: {r:?}");
        // The segment was checked at all: every cut's first one was exempt (its start's match, a
        // rapid, counted as a block between).
        if mode == Mode::Joint {
            assert!(r.max_off_segment > 0.0 && r.max_nonlinear > 0.0, "{r:?}");
        }
    }
}

/// The propeller machine (three rotaries, two linears) facing a plane through X = 0: the chain
/// flips there, and no feed block may turn a rotary further than the step limit (10°). Joint
/// mode repositioned; TCP mode wrote the flip as one G1 turning C 180° while cutting.
#[test]
fn no_feed_block_turns_a_rotary_past_the_step_limit() {
    let m = machine("propeller-3r2l");
    let cl = std::fs::read(data("nx_clsf_mech491_simple_mill_plane_mm.cls")).unwrap();
    for mode in [Mode::Joint, Mode::Tcp] {
        let mut o = defaults(&m);
        o.mode = mode;
        let (sink, _) = run(&m, &cl, &o);
        let mut repositions = 0;
        for w in sink.blocks.windows(2) {
            if w[1].rapid || w[0].rapid {
                repositions += w[1].rapid as u32;
                continue;
            }
            for k in 3..6 {
                if let (Some(a), Some(b)) = (w[0].joints.0[k], w[1].joints.0[k]) {
                    assert!(
                        (b - a).abs() <= 10.0 + 1e-6,
                        "{mode:?}: {a} -> {b} at line {:?}",
                        w[1].source_line
                    );
                }
            }
        }
        assert!(repositions > 0, "{mode:?}");
    }
}

/// Blocks inserted between two points within travel can leave it (a long segment with large
/// turns on htm50200-horizontal: the table sweeps the tip around its axis): each such block is a
/// limit error naming the axis, as the shared verifier finds them; none was reported before.
/// Checked against the profile's travel block by block, independently of the engine's own check.
#[test]
fn inserted_blocks_outside_travel_are_limit_errors() {
    let m = machine("htm50200-horizontal");
    let cl = std::fs::read(data("generated/htm_shuffled.cls")).unwrap();
    let (sink, _) = run(&m, &cl, &fanuc(&m, Mode::Joint));
    // The engine's slack: 1e-6 units, 1e-9 rad (B 90.0009° is outside [−15°, 90°]).
    let outside = |b: &BlockInfo| {
        let w = &b.joints.0;
        m.linears.iter().enumerate().any(|(i, l)| {
            l.as_ref()
                .is_some_and(|l| w[i].is_some_and(|v| v < l.min - 1e-6 || v > l.max + 1e-6))
        }) || m.rotaries.iter().any(|r| {
            let k = 3 + (r.name as u8 - b'A') as usize;
            r.limits
                .is_some_and(|(lo, hi)| w[k].is_some_and(|v| v.to_radians() < lo - 1e-9 || v.to_radians() > hi + 1e-9))
        })
    };
    let mut n = 0;
    for b in &sink.blocks {
        let told = b.diagnostics.iter().any(|d| d.code == Code::LimitViolation);
        assert_eq!(told, outside(b), "{:?}", b);
        n += told as u32;
    }
    let errs = sink.diags.iter().filter(|d| d.code == Code::LimitViolation).count();
    assert!(
        n >= 50,
        "{n} blocks outside travel, {errs} errors, {} blocks",
        sink.blocks.len()
    );
}

/// A cut that starts with the tool along the singular direction and tilts away (common CAM
/// output): the machine positions onto the first point with the free rotary already where the
/// cut needs it, so the cut turns only the tilt and the tool axis stays on the CL orientation.
/// It held C at 0 and turned it 90° during the cut, the axis up to 11.4° off.
#[test]
fn a_cut_from_the_singular_direction_turns_its_free_rotary_while_positioning() {
    for id in ["spinner-u5-620", "haas-umc750", "dmg-dmc75v"] {
        let m = machine(id);
        let s = if m.units == Units::Mm { 1.0 } else { 1.0 / 25.4 };
        let cl = format!(
            "UNITS/{}\nFEDRAT/{}\nGOTO/0,0,{},0,0,1\nGOTO/{},0,{},0,0.5,0.8660254\n",
            if m.units == Units::Mm { "MM" } else { "INCHES" },
            500.0 * s,
            50.0 * s,
            10.0 * s,
            50.0 * s
        );
        for tilted_planes in [false, true] {
            let mut o = defaults(&m);
            o.tilted_planes = tilted_planes;
            let (sink, sum) = run(&m, cl.as_bytes(), &o);
            assert!(
                sum.max_singular_deviation_deg < 1e-6,
                "{id}: {}\n{}",
                sum.max_singular_deviation_deg,
                sink.nc
            );
            // The free rotary does not move after the approach: no unwind of a bounded table
            // to another winding of the same angle either (dmg-dmc75v positioned C at +90° for a
            // cut the planner put at −270°, then retracted and turned it a full circle).
            let c = |b: &BlockInfo| b.joints.0[5];
            let feed: Vec<_> = sink.blocks.iter().filter(|b| !b.rapid).collect();
            assert!(feed.iter().all(|b| c(b) == c(feed[0])), "{id}: {}", sink.nc);
            assert_eq!(sum.errors, 0, "{id}: {:?}", sink.diags);
            let moved = |d: &&Diagnostic| matches!(d.code, Code::Unwind | Code::BranchChange) || d.message.contains("turned");
            assert!(!sink.diags.iter().any(|d| moved(&d)), "{id}: {:?}\n{}", sink.diags, sink.nc);
        }
    }
}

/// The CL sets the tool length (`LOADTL/n,LENGTH,l`; NX's `TLDATA`), here two tools' on head
/// machines, where it moves every X Y Z: the program is cut for each and says so where it takes
/// effect (its header is out before the CL is read and only knew the profile's), and `verify`
/// follows the CL as `post` does, also reading Siemens 840D (`TRAORI`, `TRAFOOF`). It failed
/// kinepost's own programs: by 0.3 in on fryer-5x-45 (the profile's 3 in for the CL's 100 mm),
/// and at `TRAORI`, the first line of every Siemens TCP program.
#[test]
fn the_cls_tool_lengths_are_stated_and_verify_follows_them() {
    for id in ["fryer-5x-45", "dmg-dmc75v"] {
        let m = machine(id);
        let (l1, l2) = (1.3 * m.default_tool_length, 1.1 * m.default_tool_length);
        let mut out = Vec::new();
        kinepost::testgen::write_path(&m, 120, 7, l1, &mut out).unwrap();
        let text = String::from_utf8(out).unwrap();
        let gotos = text.lines().filter(|l| l.starts_with("GOTO")).count();
        let mut cl = String::new();
        let mut seen = 0;
        for line in text.lines() {
            if line.starts_with("GOTO") {
                seen += 1;
                if seen == gotos / 2 {
                    cl += &format!("LOADTL/2,LENGTH,{l2}\n");
                }
            }
            cl += line;
            cl.push('\n');
        }
        let said = |l: f64| format!("TOOL LENGTH {l:.*} FROM THE CL", if m.units == Units::Mm { 3 } else { 4 });
        for dialect in [kinepost::nc::dialect("fanuc").unwrap(), kinepost::nc::dialect("siemens").unwrap()] {
            for mode in [Mode::Joint, Mode::Tcp] {
                let mut o = fanuc(&m, mode);
                o.dialect = dialect.clone();
                let (sink, s) = run(&m, cl.as_bytes(), &o);
                assert!(sink.nc.contains("UNTIL THE CL SETS ONE"), "{id}: {}", sink.nc);
                assert!(
                    sink.nc.contains(&said(l1)) && sink.nc.contains(&said(l2)),
                    "{id}: {}",
                    sink.nc
                );
                assert_eq!(s.tool_length, l2);
                let verify = |cl_tool_length: bool| {
                    let vo = kinepost::post::verify::VerifyOptions {
                        cl_tool_length,
                        tool_table: None,
                        ..verify_options(&m, &o)
                    };
                    kinepost::post::verify::verify(cl.as_bytes(), sink.nc.as_bytes(), &m, &vo).unwrap()
                };
                let r = verify(true);
                assert!(r.ok && r.matched == gotos as u64, "{id} {} {mode:?}: {r:?}", dialect.name);
                // The profile's length throughout is another program (joint mode: TCP X Y Z are
                // the tip whatever the length).
                if mode == Mode::Joint {
                    assert!(!verify(false).ok, "{id} {}", dialect.name);
                }
            }
        }
        // The job fixes the length: the CL's are told, not followed.
        let mut o = fanuc(&m, Mode::Joint);
        o.tool_length = Some(m.default_tool_length);
        let (sink, s) = run(&m, cl.as_bytes(), &o);
        assert!(
            !sink.nc.contains("UNTIL THE CL") && !sink.nc.contains("FROM THE CL"),
            "{}",
            sink.nc
        );
        assert_eq!(s.tool_length, m.default_tool_length);
        let told = sink.diags.iter().filter(|d| d.code == Code::ToolLength).count();
        assert_eq!(told, 2, "{:?}", sink.diags);
    }
}

/// `verify` reads Heidenhain conversational (the default of dmg-dmc75v and mikron-ucp710): `L`
/// blocks with `FMAX` rapid for their block only, `C` arcs, `FUNCTION TCPM`. It failed at the
/// first `C+…` word ("C without a value"). What it does not read is named with its line.
#[test]
fn verify_reads_heidenhain_conversational() {
    for id in ["dmg-dmc75v", "mikron-ucp710"] {
        let m = machine(id);
        for file in [
            "nx_clsf_mech491_variable_axis_inch_5ax.cls",
            "nx_clsf_mech491_simple_mill_plane_mm.cls",
        ] {
            let cl = std::fs::read(data(file)).unwrap();
            for mode in [Mode::Joint, Mode::Tcp] {
                let mut o = defaults(&m);
                o.mode = mode;
                o.dialect = kinepost::nc::dialect("heidenhain").unwrap();
                let (sink, s) = run(&m, &cl, &o);
                let r = kinepost::post::verify::verify(&cl[..], sink.nc.as_bytes(), &m, &verify_options(&m, &o)).unwrap();
                assert!(r.ok && r.matched == s.cl_points, "{id} {file} {mode:?}: {r:?}");
                assert!(r.max_axis_off_arc_deg <= s.max_singular_deviation_deg + 0.01, "{r:?} {s:?}");
            }
        }
    }
    let m = machine("dmg-dmc75v");
    let o = fanuc(&m, Mode::Joint);
    let polar = "0 BEGIN PGM 1 MM\n1 L X+0 Y+0 Z+50 FMAX\n2 LP PR+10 PA+30 F500\n3 END PGM 1 MM\n";
    let cl = "UNITS/MM\nGOTO/0,0,50\n";
    let e = kinepost::post::verify::verify(cl.as_bytes(), polar.as_bytes(), &m, &verify_options(&m, &o))
        .unwrap_err()
        .to_string();
    assert!(e.contains("NC line 3") && e.contains("LP"), "{e}");
}

/// A load of the tool already in the spindle (CATIA writes `LOADTL/1` then `LOADTL/1,1`) writes
/// no second change: it stopped the spindle, retracted and changed tool 1 for tool 1. A tool that
/// comes back after another is changed as any.
#[test]
fn loading_the_tool_in_the_spindle_again_changes_nothing() {
    let m = machine("spinner-u5-620");
    let changes = |tools: &[u32]| {
        let mut cl = String::from("UNITS/MM\nFEDRAT/500\n");
        for (k, t) in tools.iter().enumerate() {
            cl += &format!("LOADTL/{t}\nGOTO/{},0,10,0,0,1\n", 10 * k);
        }
        let (sink, s) = run(&m, cl.as_bytes(), &fanuc(&m, Mode::Joint));
        assert_eq!(s.errors, 0, "{:?}", sink.diags);
        let told = sink
            .diags
            .iter()
            .filter(|d| d.message.contains("in the spindle already"))
            .count();
        (sink.nc.lines().filter(|l| l.contains(" M6")).count(), told)
    };
    assert_eq!(changes(&[1, 1]), (1, 1));
    assert_eq!(changes(&[1, 2, 1]), (3, 0));
    assert_eq!(changes(&[3, 3, 3, 4]), (2, 2));
}

/// A singular point stands at the free angle held from the point before it, not the IK's: where
/// that puts a linear outside travel, the point is a limit error. The planner judged travel at
/// the IK's angle and the emitter checked only points the planner found outside, so the block
/// went out told as "within 1% of its travel" (mikron-ucp710, fuzzed: C held at 666°, Y -277 of
/// ±275). Here spinner-u5-620: C held at 90° turns X 270 of the part into machine Y 270 of ±260.
#[test]
fn a_singular_point_outside_travel_at_its_held_angle_is_a_limit_error() {
    let m = machine("spinner-u5-620");
    let cl = "UNITS/MM\nRAPID\nGOTO/250,0,50,0,0.5,0.8660254\nFEDRAT/500\nGOTO/270,0,50,0,0,1\n";
    let (sink, s) = run(&m, cl.as_bytes(), &fanuc(&m, Mode::Joint));
    let last = sink
        .blocks
        .iter()
        .rev()
        .find(|b| b.source_line == Some(5) && !b.rapid)
        .expect("the vertical point's block");
    let y = last.joints.0[1].unwrap();
    assert!(y.abs() > 260.0, "held C puts Y out of travel: {y}\n{}", sink.nc);
    assert!(
        last.diagnostics
            .iter()
            .any(|d| d.code == Code::LimitViolation && d.severity == Severity::Error && d.message.starts_with("Y = ")),
        "{:?}",
        last.diagnostics
    );
    assert!(
        !sink.diags.iter().any(|d| d.code == Code::NearLimit && d.line == Some(5)),
        "{:?}",
        sink.diags
    );
    assert!(s.errors > 0);
}

/// The propeller machine (no X: the rotaries place the tip too) on flat work. An arc's chords
/// held the rotaries of the arc's end while Y and Z moved (9.6 mm off the pose: every chord of
/// the NX facing file's arcs), and a singular point (the tool along the A axis, A free) took the
/// first of its roots, C a half turn from the planned one, with the planned B: the tool 180° off.
/// Every chord end and every singular point is now an exact solution on the planned root.
#[test]
fn the_propeller_machine_places_the_tip_with_its_rotaries() {
    let m = machine("propeller-3r2l");
    let facing = std::fs::read_to_string(data("nx_clsf_mech491_simple_mill_plane_mm.cls")).unwrap();
    let (_, s, _) = &post_and_verify(&m, &facing).unwrap()[0];
    assert!(s.counts.get("arc_linearized").is_some_and(|&n| n > 0), "{s:?}");
    // A tool along −X: C turns it onto ±Y, A's axis, on two roots; the cut stays on one.
    let cl = "UNITS/MM\nLOADTL/1\nFEDRAT/500,MMPM\nGOTO/-0.5,0,-50,-1,0,0\nGOTO/-0.5,0,0,-1,0,0\nGOTO/-0.5,0,40,-1,0,0\n";
    for (mode, s, _) in post_and_verify(&m, cl).unwrap() {
        assert!(s.max_tip_deviation < 1e-3, "{mode:?}: {s:?}");
    }
}

/// A retract, approach or re-approach along the tool axis stops where the travel ends (told as a
/// `near_limit` warning): fryer-5x-45's Z ends 1 in over the NX facing file's clearance point,
/// and in TCP mode every approach and retract went there, a limit error on a program that was
/// otherwise within travel. The words as written stay within it too, rounding included.
#[test]
fn retracts_along_the_tool_axis_stay_within_travel() {
    let m = machine("fryer-5x-45");
    let cl = std::fs::read(data("nx_clsf_mech491_simple_mill_plane_mm.cls")).unwrap();
    let (sink, s) = run(&m, &cl, &fanuc(&m, Mode::Tcp));
    assert_eq!(s.errors, 0, "{:?}", sink.diags);
    let z = m.linears[2].as_ref().unwrap();
    let top = sink.blocks.iter().filter_map(|b| b.joints.0[2]).fold(f64::MIN, f64::max);
    assert!(
        top <= z.max + 1e-6 && top > z.max - 1e-3,
        "highest Z {top}, travel ends at {}",
        z.max
    );
    let told = sink
        .diags
        .iter()
        .filter(|d| d.code == Code::NearLimit && d.message.contains("shortened"))
        .count();
    assert!(told >= 2, "{:?}", sink.diags);
    tcp_words_within_travel(&m, &sink.nc, s.tool_length);
    // A retract shortened to the travel's end exactly: the rounded tip words put dmg-dmc75v's X
    // 0.0005 mm past -375 at the project file's second tool (1.5 in long).
    let m = machine("dmg-dmc75v");
    let cl = std::fs::read_to_string(data("nx_clsf_mech491_project2_inch_5ax.cls")).unwrap();
    let (sink, _) = run(&m, cl.as_bytes(), &fanuc(&m, Mode::Tcp));
    let from = sink.nc.find("T2 M6").expect("tool 2");
    let to = from + sink.nc[from..].find("T1 M6").expect("tool 1 again");
    tcp_words_within_travel(&m, &sink.nc[from..to], 1.5 * 25.4);
}

/// Every block of a TCP program (X Y Z the tip, as written and rounded) puts the machine's axes
/// within travel, for a tool `length` long.
fn tcp_words_within_travel(m: &Machine, nc: &str, length: f64) {
    let setup = Setup::new(length, Vec3::zeros());
    let mut r = NcReader::new(nc.as_bytes(), m.units);
    let mut n = 0;
    while let Some(b) = r.next_block().unwrap() {
        let (Some(x), Some(y), Some(z)) = (b.axes[0], b.axes[1], b.axes[2]) else {
            continue;
        };
        let mut words = [0.0; 3];
        for (i, rot) in m.rotaries.iter().enumerate() {
            words[i] = b.axes[3 + (rot.name as u8 - b'A') as usize].unwrap_or(0.0).to_radians();
        }
        let cp = kinepost::kinematics::controlled_point(m, &m.actual_angles(&words), &Vec3::new(x, y, z), &setup);
        let j = Joints {
            linear: cp.into(),
            rotary: words,
        };
        assert!(
            kinepost::kinematics::limit_violation(m, &j, 1e-9).is_none(),
            "{b:?}: machine at {cp:?}"
        );
        n += 1;
    }
    assert!(n > 30, "{n} blocks read");
}

/// A drilling cycle with no feed anywhere (CATIA's tapping demo: `CYCLE/TAP,50.786017,1.0`, no
/// FEDRAT) drives the tool into the part at rapid: an error at each hole's line, no longer a
/// warning, and a strict run refuses the program.
#[test]
fn a_drilling_cycle_without_a_feed_is_an_error() {
    let m = machine("vmc-3axis");
    let cl = "UNITS/MM\nRAPID\nGOTO/10,20,5\nCYCLE/TAP,20,1\nGOTO/10,20,0\nCYCLE/OFF\n";
    let (sink, s) = run(&m, cl.as_bytes(), &defaults(&m));
    let d = sink.first(Code::NoFeed);
    assert_eq!((d.severity, d.line), (Severity::Error, Some(5)), "{d}");
    assert!(d.message.starts_with("tapping cycle without a feed"), "{d}");
    assert!(s.errors >= 1);
    refused_in_strict_mode(&m, cl, Code::NoFeed);
}

/// A strict run of `cl` fails on its first `code` diagnostic.
fn refused_in_strict_mode(m: &Machine, cl: &str, code: Code) {
    let mut o = defaults(m);
    o.strict = true;
    let r = post::post(cl.as_bytes(), m, &o, &mut Collect::default());
    assert!(matches!(r, Err(post::Error::Strict(ref d)) if d.code == code), "{r:?}");
}

/// CATIA's tap demo starts the spindle at 0.398 RPM: the NC says S0, a tool that does not turn
/// fed into the part. An error naming the line, and strict mode refuses the program.
#[test]
fn a_spindle_speed_that_rounds_to_zero_is_an_error() {
    let m = machine("vmc-3axis");
    let cl = "UNITS/MM\nSPINDL/    0.3980,RPM,CLW\nFEDRAT/100,MMPM\nGOTO/10,20,5\nGOTO/10,20,0\n";
    let (sink, s) = run(&m, cl.as_bytes(), &defaults(&m));
    let d = sink.first(Code::SpindleSpeed);
    assert_eq!((d.severity, d.line), (Severity::Error, Some(2)), "{d}");
    assert!(d.message.contains("0.398") && d.message.contains("S0"), "{d}");
    assert_eq!(s.errors, 1);
    refused_in_strict_mode(&m, cl, Code::SpindleSpeed);
    // 0.5 RPM and up is a turning spindle, written S1: no diagnostic.
    let ok = cl.replace("0.3980", "0.5");
    let (sink, _) = run(&m, ok.as_bytes(), &defaults(&m));
    assert!(!sink.diags.iter().any(|d| d.code == Code::SpindleSpeed));
    // A surface speed with no cutter to convert it is written as S: the same rule.
    let sfm = cl.replace("0.3980,RPM,CLW", "0.2,SFM,CLW");
    let (sink, _) = run(&m, sfm.as_bytes(), &defaults(&m));
    assert!(
        sink.diags
            .iter()
            .any(|d| d.code == Code::SpindleSpeed && d.line == Some(2) && d.severity == Severity::Error),
        "{:?}",
        sink.diags
    );
}

/// NX's CLSF listings carry no SPINDL (the real post takes the speed from the operation): the NC
/// fed a tool that does not turn into the part without a word. Told once at the first cut until
/// a spindle starts; rapids alone say nothing.
#[test]
fn a_cut_with_the_spindle_standing_is_told_once() {
    let m = machine("vmc-3axis");
    let stopped = |cl: &str| {
        let (sink, _) = run(&m, cl.as_bytes(), &defaults(&m));
        sink.diags
            .into_iter()
            .filter(|d| d.code == Code::SpindleStopped)
            .map(|d| (d.severity, d.line))
            .collect::<Vec<_>>()
    };
    let cut = "UNITS/MM\nLOADTL/1\nGOTO/10,20,5\nFEDRAT/100,MMPM\nGOTO/10,20,0\nGOTO/30,20,0\n";
    assert_eq!(stopped(cut), [(Severity::Warning, Some(5))]);
    assert_eq!(stopped("UNITS/MM\nLOADTL/1\nGOTO/10,20,5\nRAPID\nGOTO/10,20,9\n"), []);
    let on = cut.replace("LOADTL/1\n", "LOADTL/1\nSPINDL/1000,RPM,CLW\n");
    assert_eq!(stopped(&on), []);
    // Stopped by the CL in the middle, started again: one warning, at the cut after the stop.
    let off = format!("{on}SPINDL/OFF\nGOTO/40,20,0\nGOTO/50,20,0\nSPINDL/900,RPM\nGOTO/60,20,0\n");
    assert_eq!(stopped(&off), [(Severity::Warning, Some(9))]);
    // A drilling cycle cuts too.
    let mut o = defaults(&m);
    o.canned_cycles = true;
    let cl = "UNITS/MM\nLOADTL/1\nGOTO/0,0,20\nCYCLE/DRILL,5,MMPM,100\nGOTO/5,5,0\nCYCLE/OFF\n";
    let (sink, _) = run(&m, cl.as_bytes(), &o);
    assert!(sink.nc.contains("G81"), "{}", sink.nc);
    assert!(
        sink.diags.iter().any(|d| d.code == Code::SpindleStopped && d.line == Some(5)),
        "{:?}",
        sink.diags
    );
}

/// M6 stops the spindle on every control, but APT's SPINDL is modal: where the CL does not say
/// it again after a tool change, the spindle starts again (same speed and direction) before the
/// new tool's first move, with an info naming the change; where it does, nothing is added.
#[test]
fn a_tool_change_restarts_the_spindle_the_cl_left_on() {
    let m = machine("vmc-3axis");
    let cl = "UNITS/MM\nLOADTL/1\nSPINDL/1000,RPM,CCLW\nFEDRAT/100,MMPM\nGOTO/10,20,5\nGOTO/10,20,0\n\
              LOADTL/2\nGOTO/30,20,5\nGOTO/30,20,0\n";
    let (sink, _) = run(&m, cl.as_bytes(), &defaults(&m));
    let after = &sink.nc[sink.nc.find("T2 M6").expect("a tool change")..];
    let (s, g43) = (after.find("S1000 M4").expect("a restart"), after.find("G43 H2").unwrap());
    assert!(s < g43 && g43 < after.find("G0").unwrap(), "{after}");
    let info = sink.only(Code::SpindleStopped);
    assert_eq!((info.severity, info.line), (Severity::Info, Some(7)));
    // Said again by the CL: written once, as the CL says it.
    let restated = cl.replace("LOADTL/2\n", "LOADTL/2\nSPINDL/2000,RPM,CLW\n");
    let (sink, _) = run(&m, restated.as_bytes(), &defaults(&m));
    assert_eq!(
        sink.nc.matches(" M4").count() + sink.nc.matches(" M3").count(),
        2,
        "{}",
        sink.nc
    );
    assert!(sink.nc.contains("S2000 M3"), "{}", sink.nc);
    assert!(!sink.diags.iter().any(|d| d.code == Code::SpindleStopped), "{:?}", sink.diags);
    // Stopped before the change: stays stopped, and the new tool's first feed (line 9: onto its
    // point from the clearance) says so.
    let off = cl.replace("LOADTL/2\n", "SPINDL/OFF\nLOADTL/2\n");
    let (sink, _) = run(&m, off.as_bytes(), &defaults(&m));
    assert_eq!(sink.nc.matches("S1000").count(), 1, "{}", sink.nc);
    assert!(
        sink.diags
            .iter()
            .any(|d| d.code == Code::SpindleStopped && d.severity == Severity::Warning && d.line == Some(9)),
        "{:?}",
        sink.diags
    );
}

/// `spindle_speed` turns a CLSF's standing spindle (NX writes no SPINDL) into one that turns:
/// started clockwise after each tool change, before the tool's first move, with an info; feed per
/// revolution runs on it. The CL's own SPINDL wins, and a SPINDL/OFF is kept.
#[test]
fn a_default_spindle_speed_starts_what_the_cl_does_not() {
    let m = machine("vmc-3axis");
    let mut o = defaults(&m);
    o.spindle_speed = Some(8000.0);
    let cl = "UNITS/MM\nLOADTL/1\nGOTO/10,20,5\nFEDRAT/0.1,MMPR\nGOTO/10,20,0\nLOADTL/2\nGOTO/30,20,5\nGOTO/30,20,0\n";
    let (sink, _) = run(&m, cl.as_bytes(), &o);
    let lines: Vec<&str> = sink.nc.lines().collect();
    let at = |w: &str, from: usize| {
        from + lines[from..]
            .iter()
            .position(|l| *l == w)
            .unwrap_or_else(|| panic!("{w}:\n{}", sink.nc))
    };
    for t in 1..=2 {
        let change = at(&format!("T{t} M6"), 0);
        let (s, comp) = (at("S8000 M3", change), at(&format!("G43 H{t}"), change));
        assert_eq!(s + 1, comp, "{}", sink.nc);
    }
    assert!(sink.nc.contains("(SPINDLE S8000 WHERE THE CL STARTS NONE)"), "{}", sink.nc);
    // F 0.1 mm/rev at 8000 RPM: 800 mm/min, and no warning of a feed per revolution at S0.
    assert!(sink.nc.contains("F800."), "{}", sink.nc);
    let told: Vec<_> = sink
        .diags
        .iter()
        .filter(|d| d.code == Code::SpindleStopped)
        .map(|d| (d.severity, d.line))
        .collect();
    // The second tool's is the restart after its change (line 6), as for a CL's own speed.
    assert_eq!(told, [(Severity::Info, Some(3)), (Severity::Info, Some(6))]);
    assert!(!sink.diags.iter().any(|d| d.code == Code::FeedClamped), "{:?}", sink.diags);
    // The CL's speed wins; a SPINDL/OFF before the first move stays off (and its first feed, onto
    // the point from the clearance, is told).
    let own = cl.replace("LOADTL/1\n", "LOADTL/1\nSPINDL/1200,RPM,CCLW\n");
    let (sink, _) = run(&m, own.as_bytes(), &o);
    assert!(sink.nc.contains("S1200 M4") && !sink.nc.contains("S8000 M"), "{}", sink.nc);
    let off = cl.replace("LOADTL/2\n", "LOADTL/2\nSPINDL/OFF\n");
    let (sink, _) = run(&m, off.as_bytes(), &o);
    assert_eq!(sink.nc.matches("S8000 M3").count(), 1, "{}", sink.nc);
    assert_eq!(sink.first(Code::SpindleStopped).severity, Severity::Info);
    assert!(
        sink.diags
            .iter()
            .any(|d| d.code == Code::SpindleStopped && d.severity == Severity::Warning && d.line == Some(8)),
        "{:?}",
        sink.diags
    );
    // Validated where it is given.
    for bad in [0.0, -5.0, 2e6, f64::NAN] {
        let s = post::Settings {
            spindle_speed: Some(bad),
            ..Default::default()
        };
        assert!(s.options(&m).unwrap_err().message.contains("spindle_speed"), "{bad}");
    }
}

/// Coolant on through a tool change sprays into the open spindle and the changer (through-spindle
/// coolant above all): M9 before it. APT's COOLNT is modal, so where the CL does not say it again
/// the next tool's first move turns the same coolant on, with an info naming the change.
#[test]
fn a_tool_change_turns_the_coolant_off_and_on_again() {
    let m = machine("vmc-3axis");
    let cl = "UNITS/MM\nLOADTL/1\nSPINDL/1000\nCOOLNT/THRU\nFEDRAT/100,MMPM\nGOTO/10,20,5\nGOTO/10,20,0\n\
              LOADTL/2\nGOTO/30,20,5\nGOTO/30,20,0\n";
    let (sink, _) = run(&m, cl.as_bytes(), &defaults(&m));
    let lines: Vec<&str> = sink.nc.lines().collect();
    let at = |w: &str| {
        lines
            .iter()
            .position(|l| *l == w)
            .unwrap_or_else(|| panic!("{w}:\n{}", sink.nc))
    };
    let (off, change, on, comp) = (
        at("M9"),
        at("T2 M6"),
        lines.iter().rposition(|l| *l == "M88").unwrap(),
        at("G43 H2"),
    );
    assert!(off < change && change < on && on < comp, "{}", sink.nc);
    let info = sink.only(Code::CoolantRestored);
    assert_eq!((info.severity, info.line), (Severity::Info, Some(8)));
    // Said again by the CL: as it says; off before the change: stays off.
    let restated = cl.replace("LOADTL/2\n", "LOADTL/2\nCOOLNT/MIST\n");
    let (sink, _) = run(&m, restated.as_bytes(), &defaults(&m));
    assert_eq!(sink.nc.matches("M88").count(), 1, "{}", sink.nc);
    assert!(sink.nc.contains("T2 M6\nM7\n"), "{}", sink.nc);
    assert!(!sink.diags.iter().any(|d| d.code == Code::CoolantRestored));
    let off = cl.replace("LOADTL/2\n", "COOLNT/OFF\nLOADTL/2\n");
    let (sink, _) = run(&m, off.as_bytes(), &defaults(&m));
    assert_eq!(sink.nc.matches("M88").count(), 1, "{}", sink.nc);
    assert!(!sink.diags.iter().any(|d| d.code == Code::CoolantRestored));
}

/// NX writes a helical ramp as `CIRCLE/…,TIMES,n`: the helix passes the end's angle n times. Taken
/// once, the project file's 3° ramp (TIMES,7) came down at 21°. Written as half turns of G2/G3
/// (one block cannot say more than a turn), or as chords along the helix where no arc word fits.
#[test]
fn a_helix_of_several_turns_turns_them_all() {
    let m = machine("vmc-3axis");
    // Radius 10 about the origin, clockwise about (0,0,-1): counter-clockwise seen from +Z (G3);
    // from Z3 to Z0 at the same angle, three turns.
    let cl = "UNITS/MM\nLOADTL/1\nSPINDL/1000\nGOTO/10,0,3\nFEDRAT/MMPM,100\n\
              CIRCLE/0,0,0,0,0,-1,10,0.006,0.5,0.375,0,TIMES,3\nGOTO/10,0,0\nGOTO/0,0,0\n";
    let (sink, _) = run(&m, cl.as_bytes(), &fanuc(&m, Mode::Joint));
    let arcs: Vec<&str> = sink.nc.lines().filter(|l| l.contains(" I")).collect();
    assert_eq!(arcs.len(), 6, "{}", sink.nc);
    for (i, l) in arcs.iter().enumerate() {
        let (x, z) = (
            if i % 2 == 0 { "X-10.000" } else { "X10.000" },
            format!("Z{:.3}", 2.5 - 0.5 * i as f64),
        );
        assert!(l.contains(x) && l.contains(&z), "half turn {i}: {l}");
        assert!(
            l.contains(if i % 2 == 0 { "I-10.000 J0.000" } else { "I10.000 J0.000" }),
            "{l}"
        );
    }
    assert!(arcs[0].contains(" G3 ") && !arcs[1].starts_with("G"), "{}", sink.nc);
    // Timed along the helix (three turns of 2π·10 mm, 3 mm down, at 100 mm/min), not the chords.
    let t: f64 = sink
        .blocks
        .iter()
        .filter(|b| b.source_line == Some(7))
        .map(|b| b.time_s)
        .sum();
    let want = (60.0 * std::f64::consts::PI).hypot(3.0) / 100.0 * 60.0;
    assert!((t - want).abs() < 1e-6, "{t} s, not {want} s");
    assert!(!sink.diags.iter().any(|d| d.severity != Severity::Info), "{:?}", sink.diags);
    // No arc word on the TNC for a helix: chords, every end on the helix, down at its pitch.
    let mut o = defaults(&m);
    o.dialect = kinepost::nc::dialect("heidenhain").unwrap();
    let (sink, _) = run(&m, cl.as_bytes(), &o);
    let on_helix: Vec<_> = sink.blocks.iter().filter(|b| b.source_line == Some(7)).collect();
    let sweep: f64 = on_helix
        .windows(2)
        .map(|w| {
            let (a, b) = (w[0].tip, w[1].tip);
            (a[0] * b[1] - a[1] * b[0]).atan2(a[0] * b[0] + a[1] * b[1])
        })
        .sum();
    assert!(
        (sweep.to_degrees() - 1080.0).abs() < 30.0,
        "{} chords sweep {sweep}",
        on_helix.len()
    );
    for b in &on_helix {
        let [x, y, z] = b.tip;
        let turned = (y.atan2(x).rem_euclid(std::f64::consts::TAU)) / std::f64::consts::TAU;
        assert!(((x * x + y * y).sqrt() - 10.0).abs() < 0.011, "{:?}", b.tip);
        // One mm down a turn: the height follows the angle (within a chord's turn).
        let below = (3.0 - z) % 1.0;
        assert!((below - turned).abs() < 0.02 || (below - turned).abs() > 0.98, "{:?}", b.tip);
    }
    // A TIMES without a whole number of turns is a bad record, never a guess.
    for bad in ["TIMES,0", "TIMES,2.5", "TIMES"] {
        let cl = cl.replace("TIMES,3", bad);
        let (sink, _) = run(&m, cl.as_bytes(), &fanuc(&m, Mode::Joint));
        let d = sink.first(Code::BadRecord);
        assert_eq!((d.severity, d.line), (Severity::Error, Some(6)), "{bad}: {d}");
    }
}

/// CAMWorks' CLT indexes the part with `ROTABL` (radians) and writes the path in the turned
/// frame (plunges along its Z, arcs about its Z) with `TLAXIS` in the part frame: taken
/// literally, every plunge went sideways through the part. The same path written in the part
/// frame (6-value GOTOs) must give the same program; a 3+1 program on the A table is the turned
/// frame's X Y Z with A at -90.
#[test]
fn a_rotabl_index_takes_the_path_out_of_the_turned_frame() {
    let m = machine("vmc-4axis-a");
    let turned = "UNITS/ MM \nTLAXIS/ 0.000000,-1.000000,0.000000 \nROTABL/ 1.570796,AAXIS,TABLE,CCLW \n\
                  ROTABL/ -0.000000,BAXIS,TABLE,CCLW \nROTABL/ 0.000000,CAXIS,TABLE,CCLW \nRAPID/ \nGOTO/ 20.0,30.0,25.0 \n\
                  FEDRAT/ MMPM,500.0\nGOTO/ 20.0,30.0,-5.0 \nGOTO/ 40.0,30.0,-5.0 \n\
                  CIRCLE/ 40.0,40.0,-5.0,0.0,0.0,1.0,10.0,COUNTERCLOCKWISE \nGOTO/ 50.0,40.0,-5.0 \n\
                  ROTABL/ -0.000000,CAXIS,TABLE,CCLW \nROTABL/ 0.000000,BAXIS,TABLE,CCLW \nROTABL/ -1.570796,AAXIS,TABLE,CCLW \n";
    // The same in the part frame: (x, y, z) turned 90° about +X is (x, -z, y).
    let part = "UNITS/MM\nRAPID\nGOTO/20,-25,30,0,-1,0\nFEDRAT/MMPM,500\nGOTO/20,5,30,0,-1,0\nGOTO/40,5,30,0,-1,0\n\
                CIRCLE/40,5,40,0,-1,0,10\nGOTO/50,5,40,0,-1,0\n";
    // ICAM-style APT: degrees, the other sense named.
    let degrees = turned.replace("1.570796,AAXIS,TABLE,CCLW", "90,AAXIS,CLW");
    for mode in [Mode::Joint, Mode::Tcp] {
        let o = fanuc(&m, mode);
        let (want, _) = run(&m, part.as_bytes(), &o);
        for cl in [turned, degrees.as_str()] {
            let (got, _) = run(&m, cl.as_bytes(), &o);
            assert_eq!(got.blocks.len(), want.blocks.len(), "{}", got.nc);
            for (g, w) in got.blocks.iter().zip(&want.blocks) {
                let d = (Vec3::from(g.tip) - Vec3::from(w.tip)).norm() + (Vec3::from(g.axis) - Vec3::from(w.axis)).norm();
                // 1.570796 is π/2 to six places: 3e-7 rad, 1e-5 mm at 30 mm (a word is 1e-3).
                assert!(
                    d < 1e-4,
                    "{mode:?} block {}: {:?} against {:?}\n{}",
                    g.n,
                    g.tip,
                    w.tip,
                    got.nc
                );
            }
            let i = got.first(Code::TableIndex);
            assert_eq!((i.severity, i.line), (Severity::Info, Some(7)), "{i}");
            assert!(!got.diags.iter().any(|d| d.severity == Severity::Error), "{:?}", got.diags);
        }
    }
    let (got, _) = run(&m, turned.as_bytes(), &fanuc(&m, Mode::Joint));
    assert!(
        got.nc.contains(" X20.000 Y30.000 ") && got.nc.contains(" A-90.0000"),
        "{}",
        got.nc
    );
    assert!(got.nc.contains("\nG3 X50.000 Y40.000 Z-5.000 I0.000 J10.000"), "{}", got.nc);
    assert!(!got.nc.contains("G18") && !got.nc.contains("G19"), "{}", got.nc);
}

/// An index the CL does not confirm is an error naming its line, never a guess: about the
/// tool axis itself (which way?), about two axes (which order?), one that turns the CL's Z
/// elsewhere than the tool axis, one that names no axis or no angle, and a tool axis that
/// contradicts the index in force.
#[test]
fn a_rotabl_index_the_cl_does_not_confirm_is_an_error() {
    let m = machine("vmc-4axis-a");
    let head = "UNITS/MM\nFEDRAT/MMPM,500\n";
    let cases = [
        ("TLAXIS/0,0,1\nROTABL/45,CAXIS\nGOTO/10,10,5\n", Code::TableIndex, 5),
        (
            "TLAXIS/0,-1,0\nROTABL/90,AAXIS\nROTABL/30,BAXIS\nGOTO/10,10,5\n",
            Code::TableIndex,
            6,
        ),
        ("TLAXIS/0,-1,0\nROTABL/30,AAXIS\nGOTO/10,10,5\n", Code::TableIndex, 5),
        ("TLAXIS/0,-1,0\nROTABL/1.5,,TABLE\nGOTO/10,10,5\n", Code::TableIndex, 4),
        ("TLAXIS/0,-1,0\nROTABL/,AAXIS\nGOTO/10,10,5\n", Code::BadRecord, 4),
        (
            "TLAXIS/0,-1,0\nROTABL/90,AAXIS\nGOTO/10,10,5\nTLAXIS/0,0,1\nGOTO/10,10,0\n",
            Code::TableIndex,
            7,
        ),
    ];
    for (cl, code, line) in cases {
        let cl = format!("{head}{cl}");
        let (got, _) = run(&m, cl.as_bytes(), &fanuc(&m, Mode::Joint));
        let e = got
            .diags
            .iter()
            .find(|d| d.code == code && d.severity == Severity::Error)
            .unwrap_or_else(|| panic!("{cl}: no {} error: {:?}", code.as_str(), got.diags));
        assert_eq!(e.line, Some(line), "{cl}: {e}");
        let mut strict = fanuc(&m, Mode::Joint);
        strict.strict = true;
        assert!(
            post::post(cl.as_bytes(), &m, &strict, &mut Collect::default()).is_err(),
            "{cl}"
        );
    }
    // CATIA's `ROTABL/0,,TABLE`: no index, nothing to say.
    let (got, _) = run(
        &m,
        b"UNITS/MM\nROTABL/    0.000000,,TABLE,CLW\nGOTO/10,10,5\n",
        &fanuc(&m, Mode::Joint),
    );
    assert!(!got.diags.iter().any(|d| d.code == Code::TableIndex), "{:?}", got.diags);
}

/// NX's `LOAD/TOOL,n,ADJUST,m` names the length offset register: where m is not n, `G43 H n`
/// took another tool's length (a crash, or a cut in the air). The H word is m, in joint and TCP
/// mode; a register that is no whole number is an error and no tool change.
#[test]
fn the_length_offset_register_is_the_one_the_cl_names() {
    let m = machine("vmc-3axis");
    let cl = "UNITS/MM\nLOAD/TOOL,5,ADJUST,25\nSPINDL/1000\nFEDRAT/100,MMPM\nGOTO/10,20,5\nGOTO/10,20,0\n\
              LOAD/TOOL,6,ADJUST,6\nGOTO/30,20,5\nGOTO/30,20,0\n";
    for (mode, word) in [(Mode::Joint, "G43"), (Mode::Tcp, "G43.4")] {
        let (sink, _) = run(&m, cl.as_bytes(), &fanuc(&m, mode));
        assert!(sink.nc.contains("(TOOL 5 LENGTH OFFSET 25)\nT5 M6\n"), "{}", sink.nc);
        assert!(
            sink.nc.contains(&format!("\n{word} H25\n")) && sink.nc.contains(&format!("\n{word} H6\n")),
            "{}",
            sink.nc
        );
        assert!(!sink.nc.contains("H5\n"), "{}", sink.nc);
    }
    // The same tool loaded again with another register: compensation again, with it.
    let again = cl.replace("LOAD/TOOL,6,ADJUST,6", "LOAD/TOOL,5,ADJUST,35");
    let (sink, _) = run(&m, again.as_bytes(), &fanuc(&m, Mode::Joint));
    assert_eq!(sink.nc.matches(" M6").count(), 1, "{}", sink.nc);
    assert!(sink.nc.contains("\nG43 H35\n"), "{}", sink.nc);
    // A register that cannot be written is told, and the change written with the tool's own
    // (a dropped change left the last tool cutting at this one's length).
    for bad in ["ADJUST,2.5", "ADJUST,0", "OSETNO,X", "ADJUST"] {
        let (sink, _) = run(&m, cl.replace("ADJUST,25", bad).as_bytes(), &fanuc(&m, Mode::Joint));
        let d = sink.first(Code::BadRecord);
        let sev = if bad == "ADJUST,0" { Severity::Warning } else { Severity::Error };
        assert_eq!((d.severity, d.line), (sev, Some(2)), "{bad}: {d}");
        assert!(sink.nc.contains("T5 M6\n") && sink.nc.contains("\nG43 H5\n"), "{bad}: {}", sink.nc);
    }
}

/// CATIA writes `COOLNT/ON` before its first `LOADTL`: coolant on with no tool in the spindle,
/// then off for the change and on again (M8, M9, T1 M6, M8). It goes on once, at the first move.
#[test]
fn coolant_before_the_first_tool_goes_on_at_its_first_move() {
    let m = machine("vmc-3axis");
    let cl = "UNITS/MM\nCOOLNT/ON\nLOADTL/1\nSPINDL/1000\nFEDRAT/100,MMPM\nGOTO/10,20,5\nGOTO/10,20,0\n";
    let (sink, _) = run(&m, cl.as_bytes(), &defaults(&m));
    let body: Vec<&str> = sink
        .nc
        .lines()
        .skip_while(|l| !l.starts_with("G90"))
        .skip(1)
        .take(5)
        .collect();
    assert_eq!(body, ["(TOOL 1)", "T1 M6", "S1000 M3", "M8", "G43 H1"], "{}", sink.nc);
    assert_eq!(sink.nc.matches("M9").count(), 1, "at the end only: {}", sink.nc);
    assert!(
        !sink.diags.iter().any(|d| d.code == Code::CoolantRestored),
        "{:?}",
        sink.diags
    );
    // Turned off again before the first move: never on.
    let off = cl.replace("LOADTL/1\n", "COOLNT/OFF\nLOADTL/1\n");
    let (sink, _) = run(&m, off.as_bytes(), &defaults(&m));
    assert!(!sink.nc.contains("M8"), "{}", sink.nc);
    // Without a tool change (NX CLSF has none): on at the first move.
    let (sink, _) = run(&m, cl.replace("LOADTL/1\n", "").as_bytes(), &defaults(&m));
    let (on, first) = (sink.nc.find("\nM8\n").expect("coolant on"), sink.nc.find("\nG0 ").unwrap());
    assert!(on < first, "{}", sink.nc);
}

/// The self-verification tells every block that misses its pose, not only the first or the
/// worst: in TCP mode at a tolerance finer than the X Y Z words (0.0004 mm against their 0.0005),
/// each block whose rounded tip misses by more carries a `verify_deviation` error, the others
/// none, and the summary's largest miss is the largest of them all (recomputed here from each
/// block's pose and the words' rounding, independently of the engine's replay).
#[test]
fn the_fk_replay_tells_every_block_that_misses_its_pose() {
    let m = machine("spinner-u5-620");
    let mut cl = Vec::new();
    kinepost::testgen::write_path(&m, 400, 3, m.default_tool_length, &mut cl).unwrap();
    let mut o = fanuc(&m, Mode::Tcp);
    o.tolerance = 0.0004;
    let (sink, s) = run(&m, &cl, &o);
    let (mut over, mut worst) = (0, 0.0f64);
    for b in &sink.blocks {
        let miss = (0..3)
            .map(|i| (kinepost::nc::round_to(b.tip[i], 3) as f64 / 1000.0 - b.tip[i]).powi(2))
            .sum::<f64>()
            .sqrt();
        worst = worst.max(miss);
        let told = b.diagnostics.iter().any(|d| d.code == Code::VerifyDeviation);
        assert_eq!(
            told,
            miss > o.tolerance,
            "block {} misses by {miss}: {:?}",
            b.n,
            b.diagnostics
        );
        over += told as usize;
    }
    assert!(over > 50, "only {over} of {} blocks over the tolerance", sink.blocks.len());
    assert!(over < sink.blocks.len(), "every block over the tolerance");
    assert!(
        (s.max_tip_deviation - worst).abs() < 1e-12,
        "{} against {worst}",
        s.max_tip_deviation
    );
    assert_eq!(s.counts.get("verify_deviation").copied().unwrap_or(0), over as u64);
}

/// TCP on htm50200-horizontal (angle error on A): the control's TCP knows only the nominal
/// kinematics, so X Y Z are not the CL point but the point whose nominal TCP puts the real tip
/// there. Written as the CL point, the real tip landed up to 37 mm off at a 36° tilt.
#[test]
fn tcp_with_angle_error_puts_the_real_tip_on_the_cl_point() {
    let m = machine("htm50200-horizontal");
    let mut cl = Vec::new();
    kinepost::testgen::write_path(&m, 200, 3, m.default_tool_length, &mut cl).unwrap();
    let o = fanuc(&m, Mode::Tcp);
    let (sink, s) = run(&m, &cl, &o);
    assert!(s.max_tip_deviation <= o.tolerance, "FK replay {}", s.max_tip_deviation);
    let setup = Setup::new(m.default_tool_length, Vec3::zeros());
    replay_matches(
        &m,
        std::str::from_utf8(&cl).unwrap(),
        &sink.nc,
        Mode::Tcp,
        &setup,
        o.tolerance,
    );
    // The words differ from the tips they put there (else nothing was compensated).
    let widest = sink
        .blocks
        .iter()
        .filter_map(|b| {
            let w = [b.joints.0[0]?, b.joints.0[1]?, b.joints.0[2]?];
            Some((Vec3::from(w) - Vec3::from(b.tip)).norm())
        })
        .fold(0.0, f64::max);
    assert!(widest > 1.0, "X Y Z within {widest} mm of the CL points: no compensation");
    // And between blocks: the control interpolates the words, the real tip stays on the chord.
    let r = kinepost::post::verify::verify(cl.as_slice(), sink.nc.as_bytes(), &m, &verify_options(&m, &o)).unwrap();
    assert!(r.ok && r.max_nonlinear <= o.tolerance, "{r:?}");
}

/// A tolerance finer than the X Y Z words can hold made every block an FK-replay error: it is
/// refused, naming the smallest that works.
#[test]
fn a_tolerance_below_the_words_resolution_is_refused() {
    for (id, least) in [("spinner-u5-620", "0.002 mm"), ("haas-umc750", "0.0002 in")] {
        let m = machine(id);
        for t in [1e-300, 1e-6] {
            let s = post::Settings {
                tolerance: Some(t),
                ..Default::default()
            };
            let e = s.options(&m).unwrap_err().message;
            assert!(e.contains(&format!("smallest that works is {least}")), "{id} {t}: {e}");
        }
        let least: f64 = least.split(' ').next().unwrap().parse().unwrap();
        let s = post::Settings {
            tolerance: Some(least),
            ..Default::default()
        };
        let o = s.options(&m).unwrap();
        let mut cl = Vec::new();
        kinepost::testgen::write_path(&m, 200, 4, m.default_tool_length, &mut cl).unwrap();
        for mode in [Mode::Joint, Mode::Tcp] {
            let o = Options { mode, ..o.clone() };
            let (_, sum) = run(&m, &cl, &o);
            assert_eq!(sum.errors, 0, "{id} {mode:?} at the least tolerance: {sum:?}");
        }
    }
}

/// Hostile numbers in every record that becomes a word: each is written within the control's
/// range or is an error naming its line; none is written as 0 or wraps (FEDRAT/9e17 wrote F0.0,
/// SPINDL/1e19 S9223372036854775807).
#[test]
fn hostile_numbers_are_written_within_range_or_told() {
    let m = machine("spinner-u5-620");
    let o = fanuc(&m, Mode::Joint);
    let r = o.dialect.ranges;
    let values = ["0", "0.0000001", "1e9", "1e18", "1e300", "NaN"];
    // (record template with {v} at CL line 4, what it becomes)
    let cases = [
        ("FEDRAT/{v}", 'F'),
        ("SPINDL/{v}", 'S'),
        ("LOADTL/{v}", 'T'),
        ("LOADTL/2,ADJUST,{v}", 'H'),
        ("DELAY/{v}", 'P'),
    ];
    for (rec, word) in cases {
        for v in values {
            let cl = format!(
                "UNITS/MM\nLOADTL/1\nSPINDL/1000\n{}\nGOTO/10,20,30,0,0,1\nGOTO/12,20,30,0.1,0,0.995\nGOTO/14,25,30,0,0,1\nFINI\n",
                rec.replace("{v}", v)
            );
            let (sink, _) = run(&m, cl.as_bytes(), &o);
            let told = sink
                .diags
                .iter()
                .any(|d| d.severity >= Severity::Warning && d.line == Some(4));
            for l in sink.nc.lines().filter(|l| !l.starts_with('(')) {
                for w in l.split_whitespace().filter(|w| w.starts_with(word)) {
                    let Ok(x) = w[1..].parse::<f64>() else { continue };
                    let max = match (word, l.contains("G93")) {
                        ('F', true) => r.inverse_time,
                        ('F', false) => r.feed_mm,
                        ('S', _) => post::MAX_SPINDLE_SPEED,
                        ('T', _) => r.tool as f64,
                        ('H', _) => r.register as f64,
                        _ => r.dwell_s * 1000.0, // G4 P in ms
                    };
                    // T0 is a word every control takes (the empty spindle); H0 cancels the offset.
                    assert!(x > 0.0 || word == 'T' || told, "{rec} {v}: {w} written as zero in {l:?}");
                    assert!(x <= max || told, "{rec} {v}: {w} beyond {max} and not told: {l:?}");
                }
            }
            // Out of range is an error naming line 4, never a silently different word.
            let huge = ["1e9", "1e18", "1e300", "NaN"].contains(&v);
            if huge {
                let e = sink.diags.iter().find(|d| d.severity == Severity::Error && d.line == Some(4));
                assert!(e.is_some(), "{rec} {v}: no error on line 4: {:?}\n{}", sink.diags, sink.nc);
            }
        }
    }
}

/// The profile's spindle range bounds S: a speed above it is an error naming its line and the
/// machine's maximum is written; `spindle_speed` beyond it is refused where options are made.
#[test]
fn spindle_speeds_stay_within_the_profiles_range() {
    let lib = common::library();
    for p in lib.iter() {
        let (lo, hi) = p.spindle_range();
        assert!(p.doc.spindle.is_some() && hi < post::MAX_SPINDLE_SPEED, "{}: every shipped profile states its spindle", p.doc.id);
        let o = post::Settings::default().profile_options(p, None).unwrap();
        let cl = format!(
            "UNITS/MM\nLOADTL/1\nSPINDL/{}\nFEDRAT/100\nGOTO/10,20,30,0,0,1\nSPINDL/{}\nGOTO/12,20,30,0,0,1\nFINI\n",
            hi,
            hi * 1.5
        );
        let (sink, _) = run(&p.machine, cl.as_bytes(), &o);
        let errs: Vec<_> = sink.diags.iter().filter(|d| d.code == Code::WordRange).collect();
        assert!(errs.len() == 1 && errs[0].line == Some(6) && errs[0].severity == Severity::Error, "{}: {errs:?}", p.doc.id);
        assert!(errs[0].message.contains("spindle maximum"), "{}", errs[0].message);
        let s_words: Vec<f64> = sink
            .nc
            .split_whitespace()
            .filter_map(|w| w.strip_prefix('S').and_then(|v| v.parse().ok()))
            .collect();
        assert!(s_words.iter().all(|&s| (lo..=hi).contains(&s)), "{}: {s_words:?}", p.doc.id);
        let too_fast = post::Settings {
            spindle_speed: Some(hi + 1.0),
            ..Default::default()
        };
        let e = too_fast.profile_options(p, None).unwrap_err().message;
        assert!(e.contains("spindle_speed") && e.contains(&p.doc.id), "{e}");
    }
}

/// A 0.5° swirl of the tool axis about the pole on spinner-u5-620 turns C a full turn within a
/// millimetre of tip motion: at the programmed feed that was G93 F71942, C at 1.3 M°/min. Every
/// block is slowed to the axes' velocities (the profile's max_feed), told as feed_clamped naming
/// the axis, and no inverse-time F exceeds the dialect's.
#[test]
fn a_swirl_about_the_pole_is_slowed_to_the_rotaries_velocity() {
    let m = machine("spinner-u5-620");
    let o = fanuc(&m, Mode::Joint);
    let mut cl = String::from("UNITS/MM\nLOADTL/1\nSPINDL/8000\nFEDRAT/2000\n");
    let tilt = 0.5f64.to_radians();
    for k in 0..=72 {
        let az = (k as f64 * 5.0).to_radians();
        let (i, j, kk) = (tilt.sin() * az.cos(), tilt.sin() * az.sin(), tilt.cos());
        cl.push_str(&format!("GOTO/{:.4},20,30,{i:.7},{j:.7},{kk:.7}\n", 10.0 + k as f64 / 72.0));
    }
    cl.push_str("FINI\n");
    let (sink, _) = run(&m, cl.as_bytes(), &o);
    let d = sink.first(Code::FeedClamped);
    assert!(d.message.contains("C would exceed its velocity"), "{d:?}");
    let vmax = |name: char| m.rotaries[m.rotary_index(name).unwrap()].max_feed.unwrap().to_degrees();
    let (mut b, mut c, mut g93, mut checked) = (0.0, 0.0, false, 0);
    for l in sink.nc.lines() {
        let w = |a: char| {
            l.split_whitespace()
                .find(|t| t.starts_with(a))
                .and_then(|t| t[1..].parse::<f64>().ok())
        };
        g93 = (g93 || l.contains("G93")) && !l.contains("G94");
        let (nb, nc) = (w('B').unwrap_or(b), w('C').unwrap_or(c));
        if g93 && let Some(f) = w('F') {
            assert!(f <= o.dialect.ranges.inverse_time, "{l}");
            // F is 1/minutes: each axis's step times F is its speed in °/min (F rounded to 3 digits).
            for (step, name) in [((nb - b).abs(), 'B'), ((nc - c).abs(), 'C')] {
                assert!(step * f <= vmax(name) * 1.001 + 1e-6, "{name} at {} °/min in {l}", step * f);
            }
            checked += 1;
        }
        (b, c) = (nb, nc);
    }
    assert!(checked > 50, "{checked} inverse-time blocks checked:\n{}", sink.nc);
}

/// A GOTO with values after i,j,k (a contact normal for 3D compensation) had them dropped
/// unread: they are told, naming the line.
#[test]
fn goto_values_after_the_tool_axis_are_told() {
    let m = machine("spinner-u5-620");
    let cl = "UNITS/MM\nLOADTL/1\nSPINDL/1000\nGOTO/10,20,30,0,0,1,0,0.7071,0.7071\nGOTO/10,25,30,0,0,1\nFINI\n";
    let (sink, s) = run(&m, cl.as_bytes(), &fanuc(&m, Mode::Joint));
    let d = sink.first(Code::IgnoredRecord);
    assert!(
        d.line == Some(4) && d.severity == Severity::Warning && d.message.contains("3 values"),
        "{d:?}"
    );
    assert_eq!(s.cl_points, 2, "the point itself is still posted");
}

/// A negative tool length from the CL was used (every point then misplaced by twice it along the
/// tool axis): an error naming the line, and the length in force stays.
#[test]
fn a_negative_tool_length_from_the_cl_is_refused() {
    let m = machine("spinner-u5-620");
    let cl = "UNITS/MM\nLOADTL/1,LENGTH,-120\nSPINDL/1000\nGOTO/10,20,30,0,0,1\nGOTO/10,25,30,0,0,1\nFINI\n";
    let (sink, s) = run(&m, cl.as_bytes(), &fanuc(&m, Mode::Joint));
    let d = sink.first(Code::ToolLength);
    assert!(d.severity == Severity::Error && d.line == Some(2), "{d:?}");
    assert_eq!(s.tool_length, m.default_tool_length);
}

/// Records that change what the machine does, placed in the middle of a path: each either
/// changes the NC or is told with its line. (The vocabulary's coordinate records and the rest of
/// the list are still to come; this is the part written so far.) `CUTCOM` changes the NC.
#[test]
fn records_that_change_the_machine_change_the_nc_or_are_told() {
    let m = machine("spinner-u5-620");
    let cl = |mid: &str| {
        format!(
            "UNITS/MM\nLOADTL/1\nSPINDL/1000,CLW\nFEDRAT/100,MMPM\nGOTO/0,0,10,0,0,1\nGOTO/5,0,10,0,0,1\n{mid}\nGOTO/10,0,10,0,0,1\nEND\n"
        )
    };
    let (plain, _) = run(&m, cl("").as_bytes(), &defaults(&m));
    for rec in [
        "STOP",
        "OPSTOP",
        "CUTCOM/LEFT",
        "CUTCOM/RIGHT,1",
        "CUTCOM/ ON ",
        "OPSKIP/ON",
        "AUXFUN/77",
        "PREFUN/61",
        "SELCTL/2",
    ] {
        let (sink, _) = run(&m, cl(rec).as_bytes(), &defaults(&m));
        let told = sink.diags.iter().any(|d| d.line == Some(7) && d.severity >= Severity::Warning);
        assert!(told || sink.nc != plain.nc, "{rec}: neither written nor told: {:?}", sink.diags);
    }
    // Cutter compensation is written, on the move after it (`ON` with no side before it names
    // none: an error there).
    for (rec, word) in [("CUTCOM/LEFT", "G41 D1 X10.000"), ("CUTCOM/RIGHT,1", "G42 D1 X10.000"), ("CUTCOM/LEFT,XYPLAN,4", "G41 D4 X10.000")] {
        let (sink, _) = run(&m, cl(rec).as_bytes(), &defaults(&m));
        assert!(sink.nc.lines().any(|l| l.ends_with(word)), "{rec}:\n{}", sink.nc);
    }
    let (sink, _) = run(&m, cl("CUTCOM/ ON ").as_bytes(), &defaults(&m));
    assert!(sink.diags.iter().any(|d| d.line == Some(7) && d.severity == Severity::Error && d.code == Code::CutterComp));
}

/// Issue 57: CL files from CAM systems kinepost had not seen. A turning program (a lathe tool,
/// `MODE/TURN`) was posted as milling, exit 0: `T1 M6`, `S70 M4` and a 190 mm plunge with a
/// turning insert. It is refused before anything is written, saying kinepost posts milling; a
/// turning operation inside a milling program is an error at its record, its moves not written.
#[test]
fn a_turning_program_is_refused_never_milled() {
    let m = machine("vmc-3axis");
    let moves = "FEDRAT/0.1,MMPR\nSPINDL/500,SFM,CCLW\nGOTO/17,0,2\nGOTO/17,0,-190\n";
    for (head, line) in [
        // CATIA's tool change: TOOLNO over three lines, then LOADTL.
        (
            "$$*CATIA0\nCUTTER/0.8\nTOOLNO/1,TURN,1,0,3,0.4,$\n0,0,0.1,MMPR,500,SFM,$\nCCLW,ON,0,NOTE\nLOADTL/1,1,1\n",
            3,
        ),
        ("UNITS/MM\nCUTTER/0.8\nTURRET/1,OSETNO,1,SETOOL,0,0,0\n", 3),
        ("UNITS/MM\nMODE/TURN\nLOADTL/1\n", 2),
        ("UNITS/MM\nTLDATA/TURN,0.8,55,0\nLOADTL/1\n", 2),
    ] {
        let cl = format!("{head}{moves}");
        let mut sink = Collect::default();
        match post::post(cl.as_bytes(), &m, &defaults(&m), &mut sink) {
            Err(post::Error::NotCl(d)) => {
                assert_eq!((d.code, d.line), (Code::Turning, Some(line)), "{cl}\n{d}");
                assert!(d.message.contains("kinepost posts milling"), "{d}");
            }
            other => panic!("{cl}: {other:?}\n{}", sink.nc),
        }
        assert!(sink.nc.is_empty(), "nothing written:\n{}", sink.nc);
    }
    // A milling program with a turning operation in it: told at the lathe tool, its moves not
    // written, the milling tool after it cuts again.
    let cl = "UNITS/MM\nLOADTL/1\nFEDRAT/100,MMPM\nGOTO/0,0,5\nGOTO/10,0,5\nTOOLNO/2,TURN\nLOADTL/2\n\
              GOTO/20,0,5\nGOTO/30,0,5\nLOADTL/3\nGOTO/40,0,5\nGOTO/50,0,5\n";
    let (sink, s) = run(&m, cl.as_bytes(), &defaults(&m));
    let d = sink.only(Code::Turning);
    assert_eq!((d.severity, d.line), (Severity::Error, Some(6)), "{d}");
    assert!(d.message.contains("from line 8"), "{d}");
    assert!(s.errors >= 1);
    assert!(!sink.nc.contains("X20.") && !sink.nc.contains("X30."), "{}", sink.nc);
    assert!(sink.nc.contains("X40.") && sink.nc.contains("X50."), "{}", sink.nc);
}

/// A tool change is never dropped: NX's `LOAD/TOOL,3,ADJUST,0` was an error and no change at
/// all, T2 cutting on at T3's length. The register that cannot be written is told, and the
/// change written with the tool's own.
#[test]
fn a_tool_change_with_an_unwritable_register_is_written_with_the_tools_own() {
    let m = machine("vmc-3axis");
    for (adjust, sev) in [("0", Severity::Warning), ("X", Severity::Error), ("-4", Severity::Error)] {
        let cl = format!("UNITS/MM\nLOADTL/2\nFEDRAT/100,MMPM\nGOTO/0,0,5\nLOAD/TOOL,3,ADJUST,{adjust}\nGOTO/10,0,5\n");
        let (sink, _) = run(&m, cl.as_bytes(), &defaults(&m));
        assert!(sink.nc.contains("T3 M6\nG43 H3\n"), "{cl}\n{}", sink.nc);
        let d = sink.only(Code::BadRecord);
        assert_eq!((d.line, d.severity), (Some(5), sev), "{d}");
        assert!(d.message.contains("the tool's own length offset"), "{d}");
    }
}

/// A program with no feed at all (a bare GOTO list) cuts at rapid wherever it touches: an
/// error, not only the warning at its first unfed move. One rapid approach before the first
/// FEDRAT stays a warning.
#[test]
fn a_program_with_no_feed_at_all_is_an_error() {
    let m = machine("vmc-3axis");
    let (sink, s) = run(&m, b"UNITS/MM\nGOTO/0,0,5\nGOTO/0,0,-1\nGOTO/30,0,-1\n", &defaults(&m));
    let errors: Vec<_> = sink
        .diags
        .iter()
        .filter(|d| d.code == Code::NoFeed && d.severity == Severity::Error)
        .collect();
    assert!(errors.len() == 1 && errors[0].line == Some(3), "{:?}", sink.diags);
    assert_eq!(s.errors, 1);
    assert!(sink.nc.contains("ERROR NO_FEED"), "{}", sink.nc);
    let (sink, s) = run(
        &m,
        b"UNITS/MM\nGOTO/0,0,5\nGOTO/0,0,2\nFEDRAT/100,MMPM\nGOTO/30,0,-1\n",
        &defaults(&m),
    );
    assert_eq!((s.errors, sink.only(Code::NoFeed).severity), (0, Severity::Warning));
}

/// A turning program no record names as one (no lathe tool, no `MODE/TURN`): its cutting moves
/// fed per revolution (`MMPR`) in one plane through the spindle axis (Y/Z at X0, as CATIA's are)
/// are a lathe's, refused before anything is written. A milling program fed per revolution off
/// that plane, or per minute in it, is posted as before.
#[test]
fn a_turning_program_is_told_by_its_motion() {
    let m = machine("vmc-3axis");
    let head = "UNITS/MM\nLOADTL/1\nSPINDL/500,CCLW\nRAPID\nGOTO/0,40,5\n";
    let cut = "FEDRAT/0.2,MMPR\nGOTO/0,40,0\nGOTO/0,40,-30\nGOTO/0,45,-30\nGOTO/0,45,-60\nGOTO/0,50,-60\nRAPID\nGOTO/0,60,5\n";
    let cl = format!("{head}{cut}");
    let mut sink = Collect::default();
    match post::post(cl.as_bytes(), &m, &defaults(&m), &mut sink) {
        Err(post::Error::NotCl(d)) => {
            assert_eq!((d.code, d.line), (Code::Turning, Some(7)), "{d}");
            assert!(d.message.contains("kinepost posts milling") && d.message.contains("per revolution"), "{d}");
        }
        other => panic!("{other:?}\n{}", sink.nc),
    }
    assert!(sink.nc.is_empty(), "{}", sink.nc);
    for milling in [
        cut.replace("MMPR", "MMPM"),
        cut.replace("GOTO/0,45,-30", "GOTO/3,45,-30"),
        format!("CUTTER/10\nTLDATA/MILL,10,0,50\n{cut}"),
        // Taps fed per revolution, in a row through the spindle axis: holes, not a lathe's path.
        "FEDRAT/1.25,MMPR\nCYCLE/TAP,FEDTO,12,MMPR,1.25,RAPTO,3,RTRCTO,15\nGOTO/0,10,0\nGOTO/0,20,0\nGOTO/0,30,0\nCYCLE/OFF\n".into(),
    ] {
        let cl = format!("{head}{milling}");
        let (sink, s) = run(&m, cl.as_bytes(), &defaults(&m));
        assert!(sink.nc.contains("M30") && s.errors == 0, "{cl}\n{:?}", sink.diags);
    }
}

/// A `UNITS` record its own file's values contradict (a part 8 m wide under `UNITS/INCHES`: CAM
/// output in millimetres; a whole program inside 0.3 mm under `UNITS/MM`: metres) is told at the
/// record, with what was assumed; an ordinary part in either units is not.
#[test]
fn a_units_record_its_magnitudes_contradict_is_told() {
    let m = machine("vmc-3axis");
    let cl = |u: &str, k: f64| {
        let mut t = format!("{u}\nLOADTL/1\nFEDRAT/100\n");
        for i in 0..20 {
            t += &format!("GOTO/{},{},{}\n", f64::from(i) * 16.0 * k, f64::from(i % 4) * 10.0 * k, k);
        }
        t
    };
    for (u, k, looks) in [("UNITS/INCHES", 1.0, "millimetres"), ("UNITS/MM", 0.001, "metres")] {
        let (sink, _) = run(&m, cl(u, k).as_bytes(), &defaults(&m));
        let d = sink.only(Code::UnitsAssumed);
        assert_eq!((d.line, d.severity), (Some(1), Severity::Warning), "{d}");
        assert!(d.message.contains(looks) && d.message.contains("taken in"), "{d}");
    }
    for (u, k) in [("UNITS/INCHES", 0.05), ("UNITS/MM", 1.0)] {
        let (sink, _) = run(&m, cl(u, k).as_bytes(), &defaults(&m));
        assert!(!sink.diags.iter().any(|d| d.code == Code::UnitsAssumed), "{u} {k}: {:?}", sink.diags);
    }
}

/// A feed unit that contradicts the file's UNITS (Fusion: `UNITS/INCHES`, `FEDRAT/35.,MMPM`) is
/// told at its line once, and the slower of the two readings taken: 35 mm/min, not 35 in/min;
/// 10 mm/min under `UNITS/MM` with `IPM`, not 254.
#[test]
fn a_feed_unit_that_contradicts_units_is_told_and_the_slower_reading_taken() {
    let m = machine("vmc-3axis");
    for (cl, f) in [
        (
            "UNITS/INCHES\nFEDRAT/35.,MMPM\nGOTO/0,0,1\nGOTO/1,0,1\nFEDRAT/30,MMPM\nGOTO/2,0,1\n",
            "F35.0",
        ),
        (
            "UNITS/MM\nFEDRAT/10,IPM\nGOTO/0,0,1\nGOTO/1,0,1\nFEDRAT/30,MMPM\nGOTO/2,0,1\n",
            "F10.0",
        ),
    ] {
        let (sink, _) = run(&m, cl.as_bytes(), &defaults(&m));
        assert!(sink.nc.contains(f) && sink.nc.contains("F30.0"), "{cl}\n{}", sink.nc);
        let d = sink.only(Code::UnitsAssumed);
        assert_eq!((d.line, d.severity), (Some(2), Severity::Warning), "{d}");
        assert!(d.message.contains("slower"), "{d}");
    }
    // The unit a file's own UNITS agrees with, or the only one it gives: nothing to tell.
    let (sink, _) = run(
        &m,
        b"UNITS/INCHES\nFEDRAT/35.,IPM\nGOTO/0,0,1\nGOTO/1,0,1\n",
        &defaults(&m),
    );
    assert!(
        sink.nc.contains("F889.0") && !sink.diags.iter().any(|d| d.code == Code::UnitsAssumed),
        "{}",
        sink.nc
    );
}

/// The first move onto a cutting point approaches on a 3-axis machine as on the 5-axis ones:
/// over the point at the top of Z, at rapid to the clearance above it, then at feed. It went at
/// rapid straight onto the feed point (`G0 X10. Y20. Z5.`).
#[test]
fn the_first_move_onto_a_cutting_point_approaches_through_the_clearance_on_three_axes() {
    let m = machine("vmc-3axis");
    let (sink, _) = run(
        &m,
        b"LOADTL/1\nFEDRAT/300,MMPM\nGOTO/10,20,5\nGOTO/30,20,5\n",
        &fanuc(&m, Mode::Joint),
    );
    let after = sink.nc.split("G43 H1\n").nth(1).unwrap();
    let top = m.linears[2].as_ref().unwrap().max;
    let want = format!("G0 X10.000 Y20.000 Z{top:.3} (APPROACH)\nZ55.000\nG94 G1 Z5.000 F300.0\nX30.000\n");
    assert!(after.starts_with(&want), "{}", sink.nc);
}

/// An operator's instruction on a stop is kept as a comment before its M0 / M1 (CATIA's
/// `STOP/(INSTALL TEST STRIP …)` became a bare M0).
#[test]
fn a_stops_instruction_is_kept_before_its_m0() {
    let m = machine("vmc-3axis");
    let cl =
        "UNITS/MM\nFEDRAT/100,MMPM\nGOTO/0,0,1\nSTOP/(INSTALL TEST STRIP 3)\nGOTO/1,0,1\nOPSTOP/CHECK THE BORE\nGOTO/2,0,1\n";
    let (sink, _) = run(&m, cl.as_bytes(), &fanuc(&m, Mode::Joint));
    assert!(sink.nc.contains("(INSTALL TEST STRIP 3)\nM0\n"), "{}", sink.nc);
    assert!(sink.nc.contains("(CHECK THE BORE)\nM1\n"), "{}", sink.nc);
}

/// CATIA's circle statements (APT source geometry: `INDIRV`, then `TLON,GOFWD/(CIRCLE/…),ON,
/// (LINE/…)` over `$` lines) are the arcs they describe, from the current point the way the
/// tool goes to where the check surface stops it; each was an unknown record, the arc missing
/// and the program `ERRORS 0`. A form that cannot be resolved (a surface named, not written) is
/// an error at its line, and no straight move in its place.
#[test]
fn catia_circle_statements_are_arcs_and_an_unresolvable_form_an_error() {
    let m = machine("vmc-3axis");
    let cl = "UNITS/MM\nCUTTER/10\nLOADTL/1\nFEDRAT/500,MMPM\nGOTO/0,0,5\nGOTO/5,0,5\n\
              TLON,GOFWD/ (CIRCLE/ 5.00000, 5.00000, 0.00000,$\n 5.00000), ON, (LINE/ 0.00000, 5.00000, 0.00000,$\n\
              10.00000, 5.00000, 0.00000)\nGOTO/10,10,5\n\
              INDIRV/0,1,0\nTLON,GOFWD/(CIRCLE/15,10,0,5),ON,(LINE/20,0,0,20,20,0)\n\
              INDIRV/0,-1,0\nTLON,GOFWD/(CIRCLE/25,10,0,5),TO,(LINE/30,0,0,30,20,0)\n\
              TLON,GOFWD/(CIRCLE/25,10,0,5),ON,C1\nGOTO/40,0,5\n";
    let (sink, s) = run(&m, cl.as_bytes(), &fanuc(&m, Mode::Joint));
    // Counter-clockwise from (5,0) (the tool came along +X) to the line y = 5: a quarter.
    assert!(sink.nc.contains("X5.000\nG3 X10.000 Y5.000 Z5.000 I0.000 J5.000\nG1 Y10.000\n"), "{}", sink.nc);
    // INDIRV up from (10,10): clockwise over the top to x = 20.
    assert!(sink.nc.contains("G2 X20.000 Y10.000 Z5.000 I5.000 J0.000\n"), "{}", sink.nc);
    // Down from (20,10) counter-clockwise; TO the line x = 30 stops the Ø10 tool's centre at x = 25.
    assert!(sink.nc.contains("G3 X25.000 Y5.000 Z5.000 I5.000 J0.000\n"), "{}", sink.nc);
    let d = sink.only(Code::BadRecord);
    assert_eq!((d.line, d.severity), (Some(15), Severity::Error), "{d}");
    assert!(d.message.contains("C1") && d.message.contains("not written"), "{d}");
    assert_eq!(s.errors, 1);
    assert!(!sink.diags.iter().any(|d| d.code == Code::UnknownRecord), "{:?}", sink.diags);
    // The tool beside the circle by its radius (Ø2), the other ways round, the other stops.
    for (drive, arc) in [
        ("TLLFT,GOFWD/(CIRCLE/5,5,10,6),ON,(LINE/0,5,10,10,5,10)", "G3 X10.000 Y5.000 Z10.000 I0.000 J5.000"),
        ("TLRGT,GOFWD/(CIRCLE/5,5,10,4),PAST,(PLANE/0,1,0,4)", "G3 X10.000 Y5.000 Z10.000 I0.000 J5.000"),
        ("TLON,GOFWD/(CIRCLE/5,5,10,5),TANTO,(CIRCLE/5,15,10,5)", "G3 X5.000 Y10.000 Z10.000 I0.000 J5.000"),
        ("TLON,GOBACK/(CIRCLE/5,5,10,5),ON,(LINE/0,5,10,10,5,10)", "G2 X0.000 Y5.000 Z10.000 I0.000 J5.000"),
        ("TLON,GORGT/(CIRCLE/10,0,10,5),ON,(LINE/10,-10,10,10,10,10)", "G3 X10.000 Y-5.000 Z10.000 I5.000 J0.000"),
    ] {
        let cl = format!("UNITS/MM\nCUTTER/2\nLOADTL/1\nFEDRAT/100,MMPM\nGOTO/0,0,10\nGOTO/5,0,10\n{drive}\nGOTO/20,20,10\n");
        let (sink, s) = run(&m, cl.as_bytes(), &fanuc(&m, Mode::Joint));
        assert!(sink.nc.contains(&format!("{arc}\n")) && s.errors == 0, "{drive}\n{}", sink.nc);
    }
    // At rapid no arc is written: points on it, never the chord across.
    let cl = "UNITS/MM\nLOADTL/1\nGOTO/0,0,5\nGOTO/5,0,5\nRAPID\nTLON,GOFWD/(CIRCLE/5,5,0,5),ON,(LINE/0,5,0,10,5,0)\n\
              FEDRAT/100,MMPM\nGOTO/10,10,5\n";
    let (sink, _) = run(&m, cl.as_bytes(), &fanuc(&m, Mode::Joint));
    assert!(sink.nc.contains("X7.500 Y0.670\n") && sink.nc.contains("X10.000 Y5.000\n"), "{}", sink.nc);
}

/// Words other CAM systems write (Creo's `REMARK` and `PPWORD`, NX's NURBS data `KNOT` and
/// `CNTRL`, a display's `CAMERA`) are known for what they are: an unknown_record warning on each
/// line (72 to 1 559 in a file) drowned the diagnostics that matter.
#[test]
fn other_cam_systems_informational_words_are_known() {
    let m = machine("vmc-3axis");
    let plain = "UNITS/MM\nFEDRAT/100,MMPM\nGOTO/0,0,1\nGOTO/1,0,1\n";
    let (want, _) = run(&m, plain.as_bytes(), &defaults(&m));
    for w in ["REMARK/ROUGH THE POCKET", "PPWORD/SPINDL,1", "KNOT/0,0,1,1", "CNTRL/0,0,5,1", "CAMERA/1,0,0"] {
        let cl = plain.replace("GOTO/1,0,1", &format!("{w}\nGOTO/1,0,1"));
        let (sink, _) = run(&m, cl.as_bytes(), &defaults(&m));
        assert!(sink.diags.iter().all(|d| d.line != Some(4)), "{w}: {:?}", sink.diags);
        let body = |nc: &str| nc.lines().filter(|l| !l.contains("DATE")).map(str::to_string).collect::<Vec<_>>();
        assert_eq!(body(&sink.nc), body(&want.nc), "{w}");
    }
}

/// CATIA's positional `CYCLE/DRILL,depth,,feed,clearance` (the feed unit left out: a
/// continuation line that starts with `,`) is read by its own rule: depth 10, feed 100, R 3. The
/// CAMWorks rule took the feed for the clearance (R 100) and the hole went at the FEDRAT's 500.
#[test]
fn catias_positional_cycle_with_an_empty_field_is_read_by_position() {
    let m = machine("vmc-3axis");
    let cl = "UNITS/MM\nFEDRAT/500,MMPM\nGOTO/5,5,20\nCYCLE/DRILL,  10.000000,$\n,  100.000000,  3.0000\n\
              GOTO/5,5,0\nCYCLE/OFF\nGOTO/5,5,20\n";
    let (sink, _) = run(&m, cl.as_bytes(), &fanuc(&m, Mode::Joint));
    let want = "G0 Z3.000 (CYCLE)\nG1 Z0.000 F100.0 (CYCLE)\nZ-10.000 (CYCLE)\nG0 Z3.000 (CYCLE)\n";
    assert!(sink.nc.contains(want), "{}", sink.nc);
    assert!(!sink.diags.iter().any(|d| d.code == Code::BadRecord), "{:?}", sink.diags);
}

/// A word told again and again (an unknown record, a word kinepost does not act on: 72 to 1 559
/// lines of one in a file) is told by one record a program, naming its first line and its count:
/// one warning per line drowned the diagnostics that matter, and so did two records a word.
#[test]
fn a_repeated_word_is_told_once_with_its_count() {
    let m = machine("vmc-3axis");
    let mut cl = String::from("UNITS/MM\nFEDRAT/100,MMPM\nSPINDL/1000\nGOTO/0,0,1\n");
    for i in 0..50 {
        cl += &format!("FOOWORD/{i}\nSWITCH/{i}\nGOTO/{},0,1\n", i + 1);
    }
    let (sink, s) = run(&m, cl.as_bytes(), &defaults(&m));
    for (code, first) in [(Code::UnknownRecord, 5), (Code::IgnoredRecord, 6)] {
        let told: Vec<_> = sink.diags.iter().filter(|d| d.code == code && d.line.is_some()).collect();
        assert!(
            told.len() == 1
                && told[0].line == Some(first)
                && told[0].message.contains("(50 records in all, the first at line"),
            "{told:?}"
        );
    }
    assert_eq!(s.warnings, 2, "{:?}", sink.diags);
}

/// A post that stops before the end of its input (strict mode's first error, the budget) still
/// tells the words the reader held to tell at the end, each with its count so far, on one
/// thread and on two: held, they were never told.
#[test]
fn held_words_are_told_when_a_post_stops_early() {
    use kinepost::post::Budget;
    let m = machine("vmc-3axis");
    let mut cl = String::from("UNITS/MM\nFEDRAT/100,MMPM\nSPINDL/1000\nGOTO/0,0,1\n");
    for i in 0..40 {
        cl += &format!("FOOWORD/{i}\nSWITCH/{i}\nGOTO/{},{},1\n", i % 7, i % 5);
    }
    let strict = format!("{cl}GOTO/1,2\nGOTO/3,4,5\n");
    let mut long = cl.clone();
    for i in 0..3000 {
        long += &format!("GOTO/{},{},1\n", i % 7, i % 5);
    }
    let _one = common::TWO_THREAD_POSTS.lock().unwrap_or_else(|e| e.into_inner());
    for threads in [1, 2] {
        let mut o = defaults(&m);
        o.threads = threads;
        o.strict = true;
        let mut sink = Collect::default();
        let r = post::post(strict.as_bytes(), &m, &o, &mut sink);
        assert!(matches!(r, Err(post::Error::Strict(_))), "{r:?}");
        let mut o = defaults(&m);
        o.threads = threads;
        o.budget = Budget { floor_blocks: 500, blocks_per_byte: 0, seconds: f64::INFINITY };
        let mut over = Collect::default();
        let r = post::post(long.as_bytes(), &m, &o, &mut over);
        assert!(matches!(r, Err(post::Error::Stop(post::Stop::Budget(_)))), "{r:?}");
        for sink in [&sink, &over] {
            for (code, first) in [(Code::UnknownRecord, 5), (Code::IgnoredRecord, 6)] {
                let told: Vec<_> = sink.diags.iter().filter(|d| d.code == code && d.line.is_some()).collect();
                assert!(
                    told.len() == 1
                        && told[0].line == Some(first)
                        && told[0].message.contains("(40 records before the post stopped, the first at line"),
                    "threads {threads}: {:?}",
                    sink.diags
                );
            }
        }
    }
}

/// `GOHOME` is honoured, not an error and nothing: without a point, the tool up to the top of Z
/// travel and the next move positioning from there; with one, a rapid to it.
#[test]
fn gohome_goes_home() {
    let m = machine("vmc-3axis");
    let cl = "UNITS/MM\nLOADTL/1\nFEDRAT/100,MMPM\nGOTO/0,0,1\nGOTO/10,0,1\nGOHOME\nGOTO/20,0,1\nGOTO/30,0,1\n\
              GOHOME/50,50,100\nEND\n";
    let (sink, s) = run(&m, cl.as_bytes(), &fanuc(&m, Mode::Joint));
    let top = m.linears[2].as_ref().unwrap().max;
    let want = format!("X10.000\nG0 Z{top:.3} (RETRACT)\nX20.000\nZ51.000\nG1 Z1.000\nX30.000\nG0 X50.000 Y50.000 Z100.000\n");
    assert!(sink.nc.contains(&want), "{}", sink.nc);
    assert_eq!(s.errors, 0, "{:?}", sink.diags);
}

/// Text after the program's `END` that is no record (CATIA's demo ends in a stray line of
/// letters) is no part of the program: an info, not an unknown_record warning.
#[test]
fn text_after_the_end_is_no_unknown_record() {
    let m = machine("vmc-3axis");
    let cl = "UNITS/MM\nLOADTL/1\nSPINDL/1000\nFEDRAT/100,MMPM\nGOTO/0,0,1\nGOTO/1,0,1\nEND\nY43ewsdrjckhvl\n";
    let (sink, s) = run(&m, cl.as_bytes(), &defaults(&m));
    let d = sink.only(Code::IgnoredRecord);
    assert!(d.line == Some(8) && d.severity == Severity::Info && d.message.contains("after the program's END"), "{d}");
    assert!(!sink.diags.iter().any(|d| d.code == Code::UnknownRecord), "{:?}", sink.diags);
    assert_eq!(s.warnings, 0, "{:?}", sink.diags);
}

/// The NC lines of `sink` that are feed blocks, by index into its program's lines.
fn feed_lines(sink: &Collect) -> Vec<usize> {
    let (mut k, mut feeds) = (0, Vec::new());
    for (i, l) in sink.nc.lines().enumerate() {
        if k < sink.texts.len() && l == sink.texts[k] {
            if !sink.blocks[k].rapid {
                feeds.push(i);
            }
            k += 1;
        }
    }
    feeds
}

/// Clamps per operation: the NX variable-axis file on haas-umc750 (TCP and joint) was locked
/// after its approach (`M12`/`M10` before the first feed, the first blocks happening not to turn
/// a rotary) and unlocked three blocks into the cut, a stop with a dwell mid-surface. A rotary
/// that turns while an operation cuts is unlocked before its first move and stays so: no clamp
/// word between the first and the last feed move. A 3+2 operation (the SOLIDWORKS CAM boss
/// file, read in place: GPL) locks once per orientation.
#[test]
fn clamps_hold_for_a_whole_operation_never_between_feed_moves() {
    let lib = common::library();
    let p = lib.get("haas-umc750").unwrap();
    let clamp = |l: &str| ["M10", "M11", "M12", "M13"].iter().any(|w| l.starts_with(w));
    for mode in [Mode::Tcp, Mode::Joint] {
        let mut o = defaults(&p.machine);
        o.mode = mode;
        o.clamps = p.clamps();
        let (sink, _) = run(
            &p.machine,
            &std::fs::read(data("nx_clsf_mech491_variable_axis_inch_5ax.cls")).unwrap(),
            &o,
        );
        let feeds = feed_lines(&sink);
        let lines: Vec<&str> = sink.nc.lines().collect();
        let (first, last) = (feeds[0], *feeds.last().unwrap());
        let inside: Vec<&&str> = lines[first..=last].iter().filter(|l| clamp(l)).collect();
        assert!(
            inside.is_empty(),
            "{mode:?}: {inside:?} between feed lines {first} and {last}"
        );
        assert!(
            lines[..first].iter().any(|l| l.starts_with("M13")),
            "{mode:?}: B unlocked before"
        );
        assert!(
            lines[last..].iter().any(|l| l.starts_with("M12")),
            "{mode:?}: locked at the end"
        );
    }
    let boss = Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../shared/corpus/swcam_apt_boss_3plus2.apt"
    ));
    let Ok(cl) = std::fs::read(boss) else { return };
    let o = Options {
        clamps: p.clamps(),
        ..defaults(&p.machine)
    };
    let (sink, _) = run(&p.machine, &cl, &o);
    let words: Vec<&str> = sink.nc.lines().filter(|l| clamp(l)).collect();
    // One orientation change (to B90): B unlocked to turn, locked for the operation once.
    assert_eq!(words, ["M13 (B UNLOCK)", "M12 (B LOCK)"], "{words:?}");
}

/// A 30° cone that starts with the tool vertical (the singular pose: C free) on spinner-u5-620
/// was cut with B+ whatever was preferred: from the singular start the B− branch cost the free C
/// a half turn it never makes (the machine positions onto the start, C turned where the cut
/// needs it). A preference holds from a singular start as anywhere else.
#[test]
fn a_preference_holds_from_a_singular_start() {
    let m = machine("spinner-u5-620");
    let mut cl = String::from("UNITS/MM\nLOADTL/1\nSPINDL/RPM,3000,CLW\nRAPID\nGOTO/20,0,30,0,0,1\nFEDRAT/MMPM,500\n");
    // Tilting from vertical to 30° about Y, then around the cone.
    for k in 1..=6 {
        let t = (5.0 * k as f64).to_radians();
        cl += &format!("GOTO/20,0,30,{},0,{}\n", t.sin(), t.cos());
    }
    for k in 1..=24 {
        let a = (15.0 * k as f64).to_radians();
        let t = 30f64.to_radians();
        cl += &format!(
            "GOTO/{},{},30,{},{},{}\n",
            20.0 * a.cos(),
            20.0 * a.sin(),
            t.sin() * a.cos(),
            t.sin() * a.sin(),
            t.cos()
        );
    }
    cl += "END\n";
    for side in ["B-", "B+"] {
        let mut o = defaults(&m);
        o.prefer = Some(kinepost::post::Prefer::parse(side, &m).unwrap());
        let (sink, sum) = run(&m, cl.as_bytes(), &o);
        assert_eq!(sum.errors, 0, "{side}\n{}", sink.nc);
        let b: Vec<f64> = sink.blocks.iter().filter_map(|x| x.joints.0[4]).collect();
        let sign = if side == "B-" { -1.0 } else { 1.0 };
        assert!(b.iter().all(|v| v * sign >= -1e-6), "{side}: {b:?}\n{}", sink.nc);
        assert!(b.iter().any(|v| v.abs() > 29.0), "{side}: {b:?}");
    }
}

/// Tool preload: right after each tool change, the next tool the CL loads (`preselect` `next`,
/// the default, on a CL read twice): `T2` after `T1 M6` and before `T2 M6`. A streamed CL is
/// read once: readied where the CL says `SELCTL`, and said. `cl`: only `SELCTL`; `off`: none.
#[test]
fn the_next_tool_is_readied_right_after_each_tool_change() {
    let m = machine("vmc-3axis");
    let cl = "UNITS/MM\nLOADTL/1\nSPINDL/RPM,3000,CLW\nFEDRAT/MMPM,500\nRAPID\nGOTO/0,0,50,0,0,1\nGOTO/10,0,0\n\
              LOADTL/2\nRAPID\nGOTO/0,0,50\nGOTO/20,0,0\nSELCTL/9\nLOADTL/7\nGOTO/20,0,10\nEND\n";
    let seekable = |p: Option<&str>| {
        let mut o = defaults(&m);
        if let Some(p) = p {
            o.preselect = post::Preselect::parse(p).unwrap();
        }
        let mut sink = Collect::default();
        post::post_seekable(std::io::Cursor::new(cl.as_bytes()), &m, &o, &mut sink).unwrap();
        sink
    };
    let lines = |nc: &str| nc.lines().map(str::to_string).collect::<Vec<_>>();
    let at = |l: &[String], w: &str| l.iter().position(|x| x == w).unwrap_or_else(|| panic!("no {w}: {l:?}"));
    let l = lines(&seekable(None).nc);
    let (t1, t2, t7) = (at(&l, "T1 M6"), at(&l, "T2 M6"), at(&l, "T7 M6"));
    assert_eq!(at(&l, "T2"), t1 + 1, "{l:?}");
    assert_eq!(at(&l, "T7"), t2 + 1, "{l:?}");
    // The CL's own SELCTL/9 is still written where it stands (between T2 M6 and T7 M6).
    assert!((t2..t7).contains(&at(&l, "T9")), "{l:?}");
    // Read once: only the CL's SELCTL, and why.
    let (sink, _) = run(&m, cl.as_bytes(), &defaults(&m));
    let l = lines(&sink.nc);
    assert!(
        !l.iter().any(|x| x == "T2" || x == "T7") && l.iter().any(|x| x == "T9"),
        "{l:?}"
    );
    assert!(sink.diags.iter().any(|d| d.message.contains("read once")), "{:?}", sink.diags);
    let l = lines(&seekable(Some("cl")).nc);
    assert!(
        !l.iter().any(|x| x == "T2" || x == "T7") && l.iter().any(|x| x == "T9"),
        "{l:?}"
    );
    let l = lines(&seekable(Some("off")).nc);
    assert!(!l.iter().any(|x| x == "T2" || x == "T7" || x == "T9"), "{l:?}");
    assert!(post::Preselect::parse("later").is_err());
}

/// Fusion's APT post writes `LOADTL/t, 0, length, offset`: the length and register were read past
/// without a word, and the tool ran at the profile's length. Positions after the tool number mean
/// different things to different CAM systems, so they are told, on the record's line.
#[test]
fn positional_values_after_the_tool_number_are_told() {
    let m = machine("vmc-3axis");
    let cl = "UNITS/MM\nFEDRAT/500,MMPM\nLOADTL/3, 0, 75.000000, 3\nGOTO/10,20,5\nEND\n";
    let (sink, _) = run(&m, cl.as_bytes(), &fanuc(&m, Mode::Joint));
    let d = sink
        .diags
        .iter()
        .find(|d| d.line == Some(3) && d.severity == Severity::Warning && d.code == Code::IgnoredRecord)
        .unwrap_or_else(|| panic!("{:?}", sink.diags));
    assert!(d.message.contains("0, 75.000000, 3") && d.message.contains("not read"), "{d}");
    assert!(sink.nc.lines().any(|l| l.contains("T3 M6")), "{}", sink.nc);
    // The forms kinepost reads say nothing.
    let cl = "UNITS/MM\nFEDRAT/500,MMPM\nLOADTL/3,LENGTH,75,ADJUST,4\nGOTO/10,20,5\nEND\n";
    let (sink, _) = run(&m, cl.as_bytes(), &fanuc(&m, Mode::Joint));
    assert!(!sink.diags.iter().any(|d| d.line == Some(3)), "{:?}", sink.diags);
}
