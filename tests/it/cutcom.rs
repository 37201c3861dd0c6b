//! Cutter radius compensation (`CUTCOM`): G41/G42 … G40 where the CL says, on straight moves,
//! only where the control's compensation plane is across the tool; everything else an error
//! naming the line. The programs read back through `verify` as the path the CL gave.

use crate::common;

use common::machine;

use common::collect::Collect;
use kinepost::diag::{Code, Diagnostic, Severity};
use kinepost::kinematics::Machine;
use kinepost::post::verify::verify;
use kinepost::post::{self, Mode, Options};

impl Collect {
    /// The lines of the cutter-compensation diagnostics of `severity`.
    fn told(&self, severity: Severity) -> Vec<u32> {
        self.diags
            .iter()
            .filter(|d| d.code == Code::CutterComp && d.severity == severity)
            .filter_map(|d| d.line)
            .collect()
    }
}

fn post(m: &Machine, cl: &str, dialect: &str, mode: Mode, planes: bool) -> Collect {
    let mut o = Options::new(m);
    o.mode = mode;
    o.dialect = kinepost::nc::dialect(dialect).unwrap();
    o.tilted_planes = planes;
    let mut sink = Collect::default();
    post::post(cl.as_bytes(), m, &o, &mut sink).unwrap();
    sink
}

/// `kinepost verify` reads the compensated program back as the path the CL gave.
fn verifies(m: &Machine, cl: &str, nc: &str, mode: Mode) {
    let r = verify(cl.as_bytes(), nc.as_bytes(), m, &common::verify::options(m, mode)).unwrap();
    assert!(r.ok && r.matched == r.cl_points, "{r:?}\n{nc}");
}

/// A pocket wall: plunge, CUTCOM, a lead-in line, a side, an arc, a side, CUTCOM/OFF, lead-out.
const WALL: &str = "UNITS/MM\nLOADTL/3\nSPINDL/5000,CLW\nFEDRAT/500,MMPM\nGOTO/0,0,20,0,0,1\nGOTO/0,0,0\n\
    CUTCOM/LEFT,5\nGOTO/10,0,0\nGOTO/10,10,0\nCIRCLE/5,10,0,0,0,1,5\nGOTO/0,10,0\nCUTCOM/OFF\nGOTO/-5,10,0\nGOTO/-5,10,20\nEND\n";

#[test]
fn every_dialect_starts_and_ends_compensation_where_the_cl_says() {
    let m = machine("vmc-3axis");
    for (d, on, off) in [
        ("fanuc", "G41", "G40"),
        ("haas", "G41", "G40"),
        ("linuxcnc", "G41", "G40"),
        ("siemens", "G41", "G40"),
        ("heidenhain", "RL", "R0"),
    ] {
        let s = post(&m, WALL, d, Mode::Joint, false);
        assert_eq!(s.lines_with(on), [8], "{d}: on the lead-in after CUTCOM/LEFT:\n{}", s.nc);
        assert_eq!(s.lines_with(off), [13], "{d}: on the lead-out after CUTCOM/OFF:\n{}", s.nc);
        // The register: the CL's on the controls with D words, none on Siemens (D1 with the
        // tool) and Heidenhain (the tool table), told.
        let d_word = s.nc.contains(" D5 ");
        assert_eq!(d_word, !matches!(d, "siemens" | "heidenhain"), "{d}:\n{}", s.nc);
        let warned = s.diags.iter().any(|x| x.message.contains("offset 5 not written"));
        assert_eq!(warned, !d_word, "{d}: {:?}", s.diags);
        // The CL does not say what its path is: the tool centre, assumed and said where it starts.
        let assumed: Vec<_> = s
            .diags
            .iter()
            .filter(|x| x.message.contains("does not say"))
            .map(|x| (x.line, x.severity))
            .collect();
        assert_eq!(assumed, [(Some(7), Severity::Warning)], "{d}: {:?}", s.diags);
        assert!(
            s.nc.contains("TOOL CENTRE PATH") && s.nc.contains("= WEAR ONLY"),
            "{d}:\n{}",
            s.nc
        );
        assert!(!s.nc.contains("ERROR "), "{d}:\n{}", s.nc);
        verifies(&m, WALL, &s.nc, Mode::Joint);
    }
    // RIGHT, and the tool's own number where the CL names no register.
    let s = post(
        &m,
        &WALL.replace("CUTCOM/LEFT,5", "CUTCOM/RIGHT"),
        "fanuc",
        Mode::Joint,
        false,
    );
    assert!(s.nc.contains("G42 D3 X10.000"), "{}", s.nc);
}

#[test]
fn the_cl_statement_of_its_path_goes_in_the_header() {
    let m = machine("vmc-3axis");
    let creo = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/data/creo8_ncl_profilfraesen_profile_mm.ncl"
    ))
    .unwrap();
    let s = post(&m, &creo, "fanuc", Mode::Joint, false);
    let header: Vec<&str> = s.nc.lines().take_while(|l| !l.starts_with("G21")).collect();
    assert!(
        header.iter().any(|l| l.contains("TOOL CENTRE PATH: D REGISTER = WEAR ONLY")
            && l.contains("CL LINE 6: CUTCOM_GEOMETRY_TYPE / OUTPUT_ON_CENTER")),
        "{header:?}"
    );
    // A contour path, stated: the full radius, and no assumption told.
    let cl = format!("$$-> CUTCOM_GEOMETRY_TYPE / OUTPUT_ON_PROFILE\n{WALL}");
    let s = post(&m, &cl, "fanuc", Mode::Joint, false);
    assert!(
        s.nc.lines()
            .take(8)
            .any(|l| l.contains("CONTOUR PATH: D REGISTER = FULL TOOL RADIUS")),
        "{}",
        s.nc
    );
    assert!(
        s.told(Severity::Warning).is_empty() && s.nc.contains("G41 D5"),
        "{:?}",
        s.diags
    );
}

#[test]
fn an_arc_neither_starts_nor_ends_compensation() {
    let m = machine("vmc-3axis");
    let cl = "UNITS/MM\nLOADTL/1\nSPINDL/5000,CLW\nFEDRAT/500,MMPM\nGOTO/0,0,20,0,0,1\nGOTO/0,0,0\n\
              CUTCOM/LEFT\nCIRCLE/5,0,0,0,0,1,5\nGOTO/10,0,0\nGOTO/10,10,0\nCUTCOM/OFF\nCIRCLE/5,10,0,0,0,1,5\nGOTO/0,10,0\nGOTO/0,10,20\nEND\n";
    let s = post(&m, cl, "fanuc", Mode::Joint, false);
    let errors: Vec<u32> = s.told(Severity::Error);
    assert_eq!(errors, [9, 13], "the arcs' lines: {:?}", s.diags);
    assert_eq!(s.lines_with("G41"), [10], "{}", s.nc);
    assert_eq!(s.lines_with("G40"), [14], "{}", s.nc);
}

#[test]
fn compensation_in_joint_mode_needs_the_tool_along_the_machines_z() {
    // A B head tilted 30°: the machine's X-Y plane is not across the tool.
    let m = machine("dmg-dmc75v");
    let (s30, c30) = (0.5, 0.866_025_403_784_438_6);
    let cl = format!(
        "UNITS/MM\nLOADTL/1\nSPINDL/5000,CLW\nFEDRAT/500,MMPM\nRAPID\nGOTO/0,0,20,{s30},0,{c30}\nGOTO/0,0,0\n\
         CUTCOM/LEFT\nGOTO/10,0,0\nGOTO/10,10,0\nCUTCOM/OFF\nGOTO/0,10,0\nGOTO/0,10,20\nEND\n"
    );
    let s = post(&m, &cl, "fanuc", Mode::Joint, false);
    assert_eq!(s.told(Severity::Error), [8], "{:?}", s.diags);
    assert!(
        s.lines_with("G41").is_empty() && s.nc.contains("ERROR CUTTER_COMP"),
        "{}",
        s.nc
    );
    // In a tilted plane its own G17 applies: compensation there.
    let s = post(&m, &cl, "fanuc", Mode::Joint, true);
    assert!(s.nc.contains("G68.2"), "{}", s.nc);
    assert_eq!(
        (s.lines_with("G41"), s.lines_with("G40")),
        (vec![9], vec![12]),
        "{}\n{:?}",
        s.nc,
        s.diags
    );
    assert!(s.told(Severity::Error).is_empty(), "{:?}", s.diags);
    // In TCP mode the part's X-Y plane is not across it either: 3D compensation where the control
    // has it (Fanuc's G41.2), an error where not (Haas).
    let s = post(&m, &cl, "fanuc", Mode::Tcp, false);
    assert_eq!(s.lines_with("G41.2"), [9], "{}", s.nc);
    let s = post(&m, &cl, "haas", Mode::Tcp, false);
    assert_eq!(s.told(Severity::Error), [8], "{:?}", s.diags);
}

/// A table machine in 3+2 (the tool along the machine's Z whatever the table does): plain G41.
#[test]
fn compensation_on_a_turned_table_is_in_the_machines_plane() {
    let m = machine("spinner-u5-620");
    let cl = "UNITS/MM\nLOADTL/1\nSPINDL/5000,CLW\nFEDRAT/500,MMPM\nRAPID\nGOTO/0,0,20,0,-0.5,0.8660254037844386\nGOTO/0,0,0\n\
              CUTCOM/RIGHT\nGOTO/10,0,0\nGOTO/10,10,0\nCUTCOM/OFF\nGOTO/0,10,0\nGOTO/0,10,20\nEND\n";
    let s = post(&m, cl, "fanuc", Mode::Joint, false);
    assert_eq!(
        (s.lines_with("G42"), s.lines_with("G40")),
        (vec![9], vec![12]),
        "{}\n{:?}",
        s.nc,
        s.diags
    );
    assert!(s.told(Severity::Error).is_empty(), "{:?}", s.diags);
    verifies(&m, cl, &s.nc, Mode::Joint);
}

/// Simultaneous 5-axis under compensation: 3D compensation in TCP mode where the dialect has it
/// (G41.2, CUT3DC, TCPM with RL), else an error naming the CUTCOM's line and the line that turns
/// the tool; in joint mode always an error.
#[test]
fn simultaneous_five_axis_compensation_is_3d_or_an_error() {
    let m = machine("spinner-u5-620");
    let cl = "UNITS/MM\nLOADTL/1\nSPINDL/5000,CLW\nFEDRAT/500,MMPM\nGOTO/0,0,20,0,0,1\nGOTO/0,0,0\n\
              CUTCOM/LEFT\nGOTO/10,0,0,0,0,1\nGOTO/20,0,0,0,-0.5,0.8660254037844386\nGOTO/30,0,0,0,-0.7071067811865476,0.7071067811865476\n\
              CUTCOM/OFF\nGOTO/40,0,0\nGOTO/40,0,20\nEND\n";
    for (d, on) in [
        ("fanuc", Some("G41.2")),
        ("siemens", Some("G41")),
        ("heidenhain", Some("RL")),
        ("haas", None),
        ("linuxcnc", None),
    ] {
        let s = post(&m, cl, d, Mode::Tcp, false);
        match on {
            Some(w) => {
                assert_eq!(s.lines_with(w), [8], "{d}:\n{}", s.nc);
                assert!(s.told(Severity::Error).is_empty(), "{d}: {:?}", s.diags);
                if d == "siemens" {
                    assert!(s.nc.contains("CUT3DC G41") && s.nc.contains("G40 CUT2D"), "{}", s.nc);
                }
                verifies(&m, cl, &s.nc, Mode::Tcp);
            }
            None => {
                let e: Vec<&Diagnostic> = s
                    .diags
                    .iter()
                    .filter(|x| x.code == Code::CutterComp && x.severity == Severity::Error)
                    .collect();
                assert!(
                    e.len() == 1 && e[0].line == Some(7) && e[0].message.contains("line 9"),
                    "{d}: {e:?}"
                );
                assert!(!s.nc.contains("G41") && s.nc.contains("ERROR CUTTER_COMP"), "{d}:\n{}", s.nc);
            }
        }
    }
    let s = post(&m, cl, "fanuc", Mode::Joint, false);
    assert_eq!(s.told(Severity::Error), [7], "{:?}", s.diags);
    assert!(!s.nc.contains("G41"), "{}", s.nc);
}

/// CAMWorks writes `CUTCOM/ ON` then `CUTCOM/ LEFT`; `ON` alone repeats the last side, and with
/// none before it is an error. Compensation left on at a tool change ends there, told.
#[test]
fn on_repeats_the_last_side_and_a_tool_change_ends_compensation() {
    let m = machine("vmc-3axis");
    let cl = "UNITS/MM\nLOADTL/1\nSPINDL/5000,CLW\nFEDRAT/500,MMPM\nGOTO/0,0,20\nCUTCOM/ ON \nGOTO/0,0,0\n\
              CUTCOM/ ON \nCUTCOM/ LEFT \nGOTO/10,0,0\nCUTCOM/ OFF \nGOTO/10,10,0\nCUTCOM/ON\nGOTO/20,10,0\n\
              LOADTL/2\nGOTO/20,10,20\nEND\n";
    let s = post(&m, cl, "fanuc", Mode::Joint, false);
    assert_eq!(s.lines_with("G41"), [10, 14], "{}", s.nc);
    assert_eq!(s.lines_with("G40"), [12], "{}", s.nc);
    assert_eq!(s.told(Severity::Error), [6], "ON with no side yet: {:?}", s.diags);
    let lines: Vec<&str> = s.nc.lines().collect();
    let g40 = lines.iter().position(|l| *l == "G40").expect("G40 before the tool change");
    let m6 = lines.iter().position(|l| l.contains("M6") && l.contains("T2")).unwrap();
    assert!(g40 < m6, "{}", s.nc);
    assert!(s.told(Severity::Warning).contains(&13), "{:?}", s.diags);
    // A register beyond the D word's range: an error, no compensation.
    let s = post(&m, &WALL.replace("LEFT,5", "LEFT,5000"), "fanuc", Mode::Joint, false);
    assert!(
        s.diags.iter().any(|d| d.code == Code::WordRange && d.line == Some(7)),
        "{:?}",
        s.diags
    );
    assert!(!s.nc.contains("G41"), "{}", s.nc);
}
