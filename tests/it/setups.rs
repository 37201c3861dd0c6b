//! Programs of several setups: each NX operation's points are in its own MCS (`MSYS`), and the
//! program's frame is the first operation's.

use crate::common;

use common::collect::Collect;
use common::machine;
use kinepost::diag::{Code, Severity};
use kinepost::kinematics::{Machine, Vec3};
use kinepost::post::verify::verify;
use kinepost::post::{self, Mode, Options};

fn data(name: &str) -> String {
    std::fs::read_to_string(common::data("generated").join(name)).unwrap()
}

fn post(m: &Machine, cl: &str, mode: Mode) -> Collect {
    let mut o = Options::new(m);
    o.mode = mode;
    o.dialect = kinepost::nc::dialect("fanuc").unwrap();
    let mut sink = Collect::default();
    post::post(cl.as_bytes(), m, &o, &mut sink).unwrap();
    sink
}

fn verified(m: &Machine, cl: &str, nc: &str, mode: Mode) -> kinepost::post::verify::Report {
    verify(cl.as_bytes(), nc.as_bytes(), m, &common::verify::options(m, mode)).unwrap()
}

/// The second operation's MCS is the first's moved 100 mm along its X and turned 90° about its
/// Z (and the first is itself turned 30° in NX's absolute frame): its points are cut where the
/// same path written in the first MCS is, which `verify` confirms against that file and
/// against the program's own, in both modes. Read as written, they were 100 mm and a quarter
/// turn away.
#[test]
fn a_second_operations_mcs_is_taken_into_the_first() {
    let m = machine("spinner-u5-620");
    let (two, one) = (data("nx_two_setups.cls"), data("nx_two_setups_first_mcs.cls"));
    for mode in [Mode::Joint, Mode::Tcp] {
        let s = post(&m, &two, mode);
        let errors: Vec<_> = s.diags.iter().filter(|d| d.severity == Severity::Error).collect();
        assert!(errors.is_empty(), "{mode:?}: {errors:?}");
        for cl in [&one, &two] {
            let r = verified(&m, cl, &s.nc, mode);
            assert!(r.ok && r.matched == 80, "{mode:?}: {r:?}");
        }
        let d = s.diags.iter().find(|d| d.code == Code::CoordinateSystem).expect("the MCS change is told");
        assert_eq!((d.line, d.severity), (Some(55), Severity::Info), "{d:?}");
        assert!(d.message.contains("100.0000, 0.0000, 0.0000 mm") && d.message.contains("turned 90.0000°"), "{d:?}");
        assert!(s.nc.contains("(MCS MOVED 100.0000, 0.0000, 0.0000 MM TURNED 90.000 DEG FROM THE FIRST"), "{}", s.nc);
        // The same machine motion as the path written in one MCS.
        let same = post(&m, &one, mode);
        assert_eq!(s.blocks.len(), same.blocks.len(), "{mode:?}");
        for (a, b) in s.blocks.iter().zip(&same.blocks) {
            for (x, y) in a.joints.0.iter().zip(b.joints.0.iter()) {
                let (x, y) = (x.unwrap_or(0.0), y.unwrap_or(0.0));
                assert!((x - y).abs() < 2e-3, "{mode:?} block {}: {:?} vs {:?}", a.n, a.joints, b.joints);
            }
        }
    }
}

/// 3-axis operations give no tool axis: the axis in force is the MCS's Z, so a second operation
/// whose MCS is turned onto the part's side is cut along that side's normal.
#[test]
fn a_turned_mcs_turns_the_modal_tool_axis() {
    let m = machine("dmg-dmc75v");
    let cl = "UNITS/MM\nMSYS/0,0,0,1,0,0,0,1,0\nLOADTL/1\nFEDRAT/500,MMPM\nGOTO/10,0,20\nGOTO/10,10,20\n\
              MSYS/0,0,0,1,0,0,0,0,1\nRAPID\nGOTO/10,0,20\nGOTO/10,10,20\nFINI\n";
    let s = post(&m, cl, Mode::Tcp);
    let last = s.blocks.iter().find(|b| b.source_line == Some(10)).unwrap();
    // Second MCS: X along X, Y along the first's Z, Z along the first's -Y.
    let (tip, axis) = (Vec3::from(last.tip), Vec3::from(last.axis));
    assert!((tip - Vec3::new(10.0, -20.0, 10.0)).norm() < 1e-6, "{tip:?}");
    assert!((axis - Vec3::new(0.0, -1.0, 0.0)).norm() < 1e-9, "{axis:?}");
    let errors: Vec<_> = s.diags.iter().filter(|d| d.severity == Severity::Error).collect();
    assert!(errors.is_empty(), "{errors:?}");
}

/// An MCS whose axes are not square is an error at its line, and the points stay as written
/// rather than in a frame the record does not define.
#[test]
fn an_mcs_that_is_no_frame_is_refused_at_its_line() {
    let m = machine("haas-umc750");
    let cl = "UNITS/MM\nMSYS/0,0,0,1,0,0,0,0,1\nLOADTL/1\nFEDRAT/500,MMPM\nGOTO/10,0,20\nMSYS/5,0,0,1,0,0,0.5,0.5,0\nGOTO/10,10,20\nFINI\n";
    let s = post(&m, cl, Mode::Tcp);
    let d = s.diags.iter().find(|d| d.line == Some(6) && d.severity == Severity::Error).expect("line 6 told");
    assert_eq!(d.code, Code::BadRecord, "{d:?}");
    assert!(d.message.contains("MSYS") && d.message.contains("not applied"), "{d:?}");
    assert!(s.nc.contains("ERROR"), "{}", s.nc);
}

fn post_offsets(m: &Machine, cl: &str, mode: Mode) -> Collect {
    let s = post::Settings {
        mode: Some(if mode == Mode::Tcp { "tcp" } else { "joint" }.into()),
        dialect: Some("fanuc".into()),
        setups: Some("work-offsets".into()),
        ..Default::default()
    };
    let o = s.options(m).unwrap();
    let mut sink = Collect::default();
    post::post(cl.as_bytes(), m, &o, &mut sink).unwrap();
    sink
}

/// `setups=work-offsets`: the second operation, its MCS moved 100 mm, runs in G55 with its words
/// measured from G55's origin, and the program says where to set G55; `verify` measures each
/// block from its offset and finds every point. The machine moves as in the default.
#[test]
fn with_work_offsets_a_moved_mcs_runs_in_the_next_offset() {
    let m = machine("spinner-u5-620");
    let moved = data("nx_two_setups_moved.cls");
    for mode in [Mode::Joint, Mode::Tcp] {
        let s = post_offsets(&m, &moved, mode);
        let errors: Vec<_> = s.diags.iter().filter(|d| d.severity == Severity::Error).collect();
        assert!(errors.is_empty(), "{mode:?}: {errors:?}");
        let lines: Vec<&str> = s.nc.lines().collect();
        let g55 = lines.iter().position(|l| *l == "G55").expect("G55 selected");
        assert_eq!(lines[g55 + 1], "(WORK OFFSET G55 = G54 + X100.000 Y0.000 Z0.000)", "{mode:?}");
        assert_eq!(lines.iter().filter(|l| l.starts_with("(WORK OFFSET G55 = G54 + X100.000")).count(), 2, "{mode:?}: at the change and before the end");
        let r = verified(&m, &moved, &s.nc, mode);
        assert!(r.ok && r.matched == 80, "{mode:?}: {r:?}");
        // The same machine motion as with the points taken into the first MCS.
        let plain = post(&m, &moved, mode);
        assert_eq!(s.blocks.len(), plain.blocks.len(), "{mode:?}");
        for (a, b) in s.blocks.iter().zip(&plain.blocks) {
            assert_eq!(a.joints.0, b.joints.0, "{mode:?} block {}", a.n);
        }
        // Block by block after the change, an X both write is 100 less in G55.
        let motion = |nc: &str| -> Vec<Option<f64>> {
            let after = nc.lines().skip_while(|l| !l.starts_with("(MCS MOVED") && !l.starts_with("(WORK OFFSET")).skip(1);
            after
                .filter(|l| l.starts_with(['G', 'X', 'Y', 'Z', 'A', 'B', 'C']) && *l != "G55")
                .map(|l| l.split(' ').find_map(|w| w.strip_prefix('X')?.parse().ok()))
                .collect()
        };
        let (wo, tr) = (motion(&s.nc), motion(&plain.nc));
        assert_eq!(wo.len(), tr.len(), "{mode:?}");
        let both: Vec<(f64, f64)> = wo.iter().zip(&tr).filter_map(|(a, b)| Some(((*a)?, (*b)?))).collect();
        assert!(both.len() > 10 && both.iter().all(|(a, b)| (b - a - 100.0).abs() < 2e-3), "{mode:?}: {both:?}");
    }
}

/// A turned MCS cannot be a work offset on these controls: an error at its line, and its points
/// taken into the first MCS, so the cut is still right.
#[test]
fn with_work_offsets_a_turned_mcs_is_an_error_and_still_cut_right() {
    let m = machine("spinner-u5-620");
    let two = data("nx_two_setups.cls");
    let s = post_offsets(&m, &two, Mode::Joint);
    let e = s.diags.iter().find(|d| d.severity == Severity::Error).expect("an error");
    assert_eq!((e.code, e.line), (Code::CoordinateSystem, Some(55)), "{e:?}");
    assert!(!s.nc.contains("G55"), "{}", s.nc);
    assert!(verified(&m, &data("nx_two_setups_first_mcs.cls"), &s.nc, Mode::Joint).ok);
}

#[test]
fn work_offsets_are_refused_where_the_program_selects_none_or_uses_planes() {
    let m = machine("spinner-u5-620");
    for (dialect, wcs, planes) in [("heidenhain", None, None), ("fanuc", Some("none"), None), ("fanuc", None, Some("tilted"))] {
        let s = post::Settings {
            dialect: Some(dialect.into()),
            work_coordinates: wcs.map(Into::into),
            planes: planes.map(Into::into),
            setups: Some("work-offsets".into()),
            ..Default::default()
        };
        let e = s.options(&m).unwrap_err().message;
        assert!(e.starts_with("setups work-offsets"), "{dialect} {wcs:?} {planes:?}: {e}");
    }
    let bad = post::Settings { setups: Some("offsets".into()), ..Default::default() };
    assert!(bad.options(&m).unwrap_err().message.contains("expected transform or work-offsets"));
}

/// A file can be read twice: the CLI's header lists the offsets before the program starts,
/// where the operator reads first.
#[test]
fn the_cli_header_lists_the_work_offsets_of_a_file() {
    let path = format!("{}/tests/data/generated/nx_two_setups_moved.cls", env!("CARGO_MANIFEST_DIR"));
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_kinepost"))
        .args(["post", "--machine", "spinner-u5-620", "--setups", "work-offsets", &path])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let nc = String::from_utf8(out.stdout).unwrap();
    let at = |s: &str| nc.find(s).unwrap_or_else(|| panic!("{s} missing:\n{nc}"));
    assert!(at("(WORK OFFSET G55 = G54 + X100.000 Y0.000 Z0.000)") < at("G90 G17"), "{nc}");
}
