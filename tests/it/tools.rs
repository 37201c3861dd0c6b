//! Tool tables: each tool's own length in joint mode on a head machine, in the program and in
//! `verify`; the precedence of the job's length, the table, the CL and the profile; bad tables.

use crate::common;

use common::collect::Collect;
use kinepost::diag::{Code, Severity};
use kinepost::kinematics::Machine;
use kinepost::machines::Profile;
use kinepost::post::verify::{VerifyOptions, verify};
use kinepost::post::{self, LengthFrom, Options, Settings, Summary};
use std::path::Path;
use std::sync::Arc;

/// A short 5-axis cut, the tool tilted up to 25° about two axes, on the fryer's table.
fn cut(n: usize, x0: f64) -> String {
    let mut s = String::new();
    for i in 0..n {
        let t = i as f64 / (n.max(2) - 1) as f64;
        let (a, c) = ((10.0 + 15.0 * t).to_radians(), (90.0 * t).to_radians());
        let axis = [a.sin() * c.cos(), a.sin() * c.sin(), a.cos()];
        s += &format!(
            "GOTO/{:.4},{:.4},{:.4},{:.6},{:.6},{:.6}\n",
            x0 + 2.0 * t,
            1.0 - t,
            -9.0,
            axis[0],
            axis[1],
            axis[2]
        );
    }
    s
}

/// Two tools, neither with a length in the CL: the table must give each its own.
fn two_tools() -> String {
    format!(
        "UNITS/INCHES\nLOADTL/1\nSPINDL/3000\nRAPID\n{}FEDRAT/20,IPM\n{}LOADTL/2\nSPINDL/3000\nRAPID\n{}FEDRAT/20,IPM\n{}FINI\n",
        cut(1, -3.0),
        cut(12, -3.0),
        cut(1, 1.0),
        cut(12, 1.0)
    )
}

const TABLE: &str = "units = \"inch\"
[[tool]]
number = 1
length = 3.5
diameter = 0.5
[[tool]]
number = 2
length = 6.25
diameter = 0.25
corner_radius = 0.125
holder = { diameter = 1.5, length = 2.5 }
";

fn post_with(p: &Profile, s: &Settings, cl: &str) -> (Collect, Summary, Options) {
    let mut o = s.profile_options(p, None).unwrap();
    o.dialect = kinepost::nc::dialect("fanuc").unwrap();
    let mut sink = Collect::default();
    let sum = post::post(cl.as_bytes(), &p.machine, &o, &mut sink).unwrap();
    (sink, sum, o)
}

fn verify_with(m: &Machine, o: &Options, cl: &str, nc: &str) -> post::verify::Report {
    let vo = VerifyOptions {
        mode: o.mode,
        setup: kinepost::kinematics::Setup::new(o.tool_length.unwrap_or(m.default_tool_length), o.work_offset),
        tolerance: o.tolerance,
        angle_tolerance_deg: 0.01,
        cl_units: None,
        cl_tool_length: o.tool_length.is_none(),
        tool_table: o.tool_table.clone(),
    };
    verify(cl.as_bytes(), nc.as_bytes(), m, &vo).unwrap()
}

/// X Y Z and tool axis of the last feed block of each CL line (the one on its point).
fn words_by_line(sink: &Collect) -> std::collections::BTreeMap<u32, ([f64; 3], [f64; 3])> {
    sink.blocks
        .iter()
        .filter(|b| !b.rapid)
        .filter_map(|b| {
            let w = b.joints.0;
            Some((b.source_line?, ([w[0]?, w[1]?, w[2]?], b.axis)))
        })
        .collect()
}

#[test]
fn two_tools_on_a_head_head_machine_in_joint_mode_verify_per_tool() {
    let lib = common::library();
    let p = lib.get("fryer-5x-45").unwrap();
    assert_eq!(p.machine.kinematics_kind(), "head-head");
    let cl = two_tools();
    let s = Settings {
        tool_table: Some(TABLE.into()),
        ..Default::default()
    };
    let (sink, sum, o) = post_with(&p, &s, &cl);
    assert_eq!((sum.errors, sum.warnings), (0, 0), "{:?}\n{}", sink.diags, sink.nc);
    assert!(sink.nc.contains("(TOOL 1 LENGTH 3.5000 FROM THE TOOL TABLE)"), "{}", sink.nc);
    assert!(sink.nc.contains("(TOOL 2 LENGTH 6.2500 FROM THE TOOL TABLE)"), "{}", sink.nc);
    assert!(
        sink.nc.contains("TOOL LENGTHS FROM THE JOB'S TOOL TABLE, 2 TOOLS"),
        "{}",
        sink.nc
    );
    let tools: Vec<_> = sum.tools.iter().map(|t| (t.tool, t.length, t.from)).collect();
    assert_eq!(tools, [(Some(1), 3.5, LengthFrom::Table), (Some(2), 6.25, LengthFrom::Table)]);
    // The shared verifier's replay, with the table: every CL point of both tools reproduced.
    let rep = verify_with(&p.machine, &o, &cl, &sink.nc);
    assert!(rep.ok && rep.matched == 26, "{rep:?}");
    // Without it (the profile's length for both) the second tool's blocks miss their points, and
    // the first tool's too: the table is what the program was cut for.
    let plain = Settings::default().profile_options(&p, None).unwrap();
    let rep = verify_with(&p.machine, &plain, &cl, &sink.nc);
    assert!(!rep.ok && rep.matched == 0, "{rep:?}");
    // The same CL points under each length: the same rotary words, and X Y Z apart by the
    // length difference times |axis - Z| (joint mode measures the tip at home, rotaries at 0).
    let (single, _, _) = post_with(&p, &Settings::default(), &cl);
    let (ours, theirs) = (words_by_line(&sink), words_by_line(&single));
    let feed_lines: Vec<u32> = (7..=18).chain(24..=35).collect();
    let both: Vec<u32> = feed_lines
        .into_iter()
        .filter(|l| ours.contains_key(l) && theirs.contains_key(l))
        .collect();
    assert!(both.len() >= 20, "{both:?}");
    for line in &both {
        let ((w, axis), (v, _)) = (ours[line], theirs[line]);
        let d = (0..3).map(|i| (w[i] - v[i]).powi(2)).sum::<f64>().sqrt();
        let tilt = (axis[0].powi(2) + axis[1].powi(2) + (axis[2] - 1.0).powi(2)).sqrt();
        let dl = if *line < 19 { 3.5 - 3.0 } else { 6.25 - 3.0 };
        assert!(
            d > 0.05 && (d - dl * tilt).abs() < 2e-4,
            "CL line {line}: moved {d}, expected {}",
            dl * tilt
        );
    }
}

#[test]
fn precedence_job_length_then_table_then_cl_then_profile() {
    let lib = common::library();
    let p = lib.get("fryer-5x-45").unwrap();
    // Tool 1 has a length in the CL and in the table; tool 2 only in the CL; tool 3 nowhere.
    let cl = format!(
        "UNITS/INCHES\nLOADTL/1,LENGTH,4.0\nSPINDL/3000\n{}LOADTL/2,LENGTH,4.5\nSPINDL/3000\n{}LOADTL/3\nSPINDL/3000\n{}FINI\n",
        cut(4, -3.0),
        cut(4, 0.0),
        cut(4, 2.0)
    );
    let table = "units = \"inch\"\n[[tool]]\nnumber = 1\nlength = 3.5\n[[tool]]\nnumber = 9\nlength = 1\n";
    let s = Settings {
        tool_table: Some(table.into()),
        ..Default::default()
    };
    let (sink, sum, o) = post_with(&p, &s, &cl);
    let tools: Vec<_> = sum.tools.iter().map(|t| (t.tool, t.length, t.from)).collect();
    assert_eq!(
        tools,
        [
            (Some(1), 3.5, LengthFrom::Table),
            (Some(2), 4.5, LengthFrom::Cl),
            (Some(3), 4.5, LengthFrom::Cl)
        ],
        "{:?}",
        sink.diags
    );
    // The CL's length the table overrides is told; tools 2 and 3 are missing from the table,
    // each a warning naming its LOADTL line.
    let told: Vec<_> = sink.diags.iter().filter(|d| d.code == Code::ToolLength).collect();
    assert!(
        told.iter()
            .any(|d| d.severity == Severity::Info && d.line == Some(2) && d.message.contains("4")),
        "{told:?}"
    );
    for (n, line) in [(2, 8), (3, 14)] {
        assert!(
            told.iter().any(|d| d.severity == Severity::Warning
                && d.line == Some(line)
                && d.message.contains(&format!("tool {n} is not in the tool table"))),
            "tool {n}: {told:?}"
        );
    }
    assert!(verify_with(&p.machine, &o, &cl, &sink.nc).ok);
    // Nothing in the CL for a tool missing from the table: the profile's default.
    let cl3 = format!("UNITS/INCHES\nLOADTL/3\nSPINDL/3000\n{}FINI\n", cut(4, 0.0));
    let (sink, sum, _) = post_with(&p, &s, &cl3);
    assert_eq!(
        (sum.tools[0].length, sum.tools[0].from),
        (3.0, LengthFrom::Profile),
        "{:?}",
        sink.diags
    );
    // The job's one length beats all, and a program of several tools is warned once.
    let s = Settings {
        tool_table: Some(table.into()),
        tool_length: Some(5.0),
        ..Default::default()
    };
    let (sink, sum, o) = post_with(&p, &s, &cl);
    assert!(
        sum.tools.iter().all(|t| (t.length, t.from) == (5.0, LengthFrom::Job)),
        "{:?}",
        sum.tools
    );
    let w: Vec<_> = sink
        .diags
        .iter()
        .filter(|d| d.code == Code::ToolLength && d.severity == Severity::Warning)
        .collect();
    assert!(
        w.len() == 1 && w[0].line == Some(8) && w[0].message.contains("every tool"),
        "{w:?}"
    );
    assert!(verify_with(&p.machine, &o, &cl, &sink.nc).ok);
}

#[test]
fn a_table_in_other_units_is_converted() {
    let lib = common::library();
    let p = lib.get("fryer-5x-45").unwrap();
    let mm = "units = \"mm\"\n[[tool]]\nnumber = 1\nlength = 88.9\n[[tool]]\nnumber = 2\nlength = 158.75\n";
    let s = Settings {
        tool_table: Some(mm.into()),
        ..Default::default()
    };
    let (_, sum, _) = post_with(&p, &s, &two_tools());
    let l: Vec<f64> = sum.tools.iter().map(|t| t.length).collect();
    assert!((l[0] - 3.5).abs() < 1e-9 && (l[1] - 6.25).abs() < 1e-9, "{l:?}");
}

#[test]
fn bad_tables_are_refused_naming_the_entry() {
    let lib = common::library();
    let p = lib.get("fryer-5x-45").unwrap();
    for (table, names) in [
        ("units = \"inch\"\n[[tool]]\nnumber = 1\nlength = -2\n", "tool[0] (T1).length"),
        (
            "units = \"inch\"\n[[tool]]\nnumber = 1\nlength = 2\n[[tool]]\nnumber = 1\nlength = 3\n",
            "tool 1 is in the table twice",
        ),
        ("units = \"feet\"\n", "units"),
        ("units = \"inch\"\n[[tool]]\nnumber = 1\nlenght = 2\n", "unknown field"),
        (
            "units = \"inch\"\n[[tool]]\nnumber = 100000000\nlength = 2\n",
            "tool[0].number",
        ),
    ] {
        let s = Settings {
            tool_table: Some(table.into()),
            ..Default::default()
        };
        let e = s.profile_options(&p, None).unwrap_err().message;
        assert!(e.starts_with("tool_table") && e.contains(names), "{e}");
    }
}

/// The machine's standing table is used unless the job brings its own.
#[test]
fn the_job_table_replaces_the_machine_table() {
    let lib = common::library();
    let p = lib.get("fryer-5x-45").unwrap();
    let standing = kinepost::machines::tools::parse_tool_table(TABLE, "t").unwrap();
    let o = Settings::default()
        .profile_options(&p, Some((Arc::new(standing.clone()), "THE MACHINE'S TOOL TABLE".into())))
        .unwrap();
    assert_eq!(o.tool_table.as_deref(), Some(&standing));
    let s = Settings {
        tool_table: Some("units = \"inch\"\n".into()),
        ..Default::default()
    };
    let o = s
        .profile_options(&p, Some((Arc::new(standing), "THE MACHINE'S TOOL TABLE".into())))
        .unwrap();
    assert!(o.tool_table.unwrap().is_empty());
}

fn bin() -> std::process::Command {
    std::process::Command::new(env!("CARGO_BIN_EXE_kinepost"))
}

/// `--tool-table` on `post` and `verify`, and the machine's own table beside its profile.
#[test]
fn the_cli_takes_a_tool_table_and_a_machine_table_beside_the_profile() {
    let dir = std::env::temp_dir().join(format!("kinepost-tools-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let (cl, table, nc) = (dir.join("two.cls"), dir.join("tools.toml"), dir.join("two.nc"));
    std::fs::write(&cl, two_tools()).unwrap();
    std::fs::write(&table, TABLE).unwrap();
    let run = |args: &[&str], machines: Option<&Path>| {
        let mut c = bin();
        if let Some(m) = machines {
            c.env("KINEPOST_MACHINES", m);
        }
        c.args(args).output().unwrap()
    };
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let (cl_s, table_s, nc_s) = (s(&cl), s(&table), s(&nc));
    let post_args = [
        "post",
        "--machine",
        "fryer-5x-45",
        "--dialect",
        "fanuc",
        "--tool-table",
        &table_s,
        &cl_s,
        "-o",
        &nc_s,
    ];
    let out = run(&post_args, None);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = std::fs::read_to_string(&nc).unwrap();
    assert!(text.contains("(TOOL 2 LENGTH 6.2500 FROM THE TOOL TABLE)"), "{text}");
    let verify_args = ["verify", "--machine", "fryer-5x-45", "--cl", &cl_s, "--nc", &nc_s];
    let with: Vec<&str> = verify_args.iter().copied().chain(["--tool-table", &table_s]).collect();
    let out = run(&with, None);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stdout));
    assert_eq!(
        run(&verify_args, None).status.code(),
        Some(1),
        "without the table the blocks miss"
    );
    // A bad table names the file and the entry; nothing is written.
    std::fs::write(&table, "units = \"inch\"\n[[tool]]\nnumber = 2\nlength = nan\n").unwrap();
    let out = run(&post_args, None);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("tools.toml") && err.contains("tool[0] (T2).length"), "{err}");
    // The machine's standing table: `<id>.tools.toml` beside its profile.
    let machines = dir.join("machines");
    std::fs::create_dir_all(&machines).unwrap();
    std::fs::copy(
        concat!(env!("CARGO_MANIFEST_DIR"), "/machines/fryer-5x-45.toml"),
        machines.join("fryer-5x-45.toml"),
    )
    .unwrap();
    std::fs::write(machines.join("fryer-5x-45.tools.toml"), TABLE).unwrap();
    let out = run(
        &post_args[..5]
            .iter()
            .copied()
            .chain([cl_s.as_str(), "-o", &nc_s])
            .collect::<Vec<_>>(),
        Some(&machines),
    );
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = std::fs::read_to_string(&nc).unwrap();
    assert!(text.contains("THE MACHINE'S TOOL TABLE, 2 TOOLS"), "{text}");
    assert!(
        run(&verify_args, Some(&machines)).status.success(),
        "verify takes the machine's table too"
    );
    // A table for no profile is a load error naming it.
    std::fs::write(machines.join("fryer-5x-54.tools.toml"), TABLE).unwrap();
    let out = run(&["machines"], Some(&machines));
    assert!(!out.status.success() && String::from_utf8_lossy(&out.stderr).contains("fryer-5x-54.tools.toml"));
    let _ = std::fs::remove_dir_all(&dir);
}

/// NX gives the next tool's `TLDATA` before its `LOAD/TOOL`: each length is that tool's, in the
/// summary and in the replay, with a table or without.
#[test]
fn nx_lengths_before_the_tool_change_belong_to_the_next_tool() {
    let lib = common::library();
    let p = lib.get("fryer-5x-45").unwrap();
    let cl = format!(
        "UNITS/INCHES\nTLDATA/MILL,0.5000,0.0000,4.0000,0.0000,0.0000\nLOAD/TOOL,1\nSPINDL/3000\n{}TLDATA/MILL,0.2500,0.0000,5.0000,0.0000,0.0000\nLOAD/TOOL,2\nSPINDL/3000\n{}FINI\n",
        cut(6, -3.0),
        cut(6, 0.5)
    );
    let only_two = "units = \"inch\"\n[[tool]]\nnumber = 2\nlength = 5.5\n";
    for (table, want) in [
        (None, [(Some(1), 4.0, LengthFrom::Cl), (Some(2), 5.0, LengthFrom::Cl)]),
        (
            Some(only_two),
            [(Some(1), 4.0, LengthFrom::Cl), (Some(2), 5.5, LengthFrom::Table)],
        ),
    ] {
        let s = Settings {
            tool_table: table.map(str::to_string),
            ..Default::default()
        };
        let (sink, sum, o) = post_with(&p, &s, &cl);
        let tools: Vec<_> = sum.tools.iter().map(|t| (t.tool, t.length, t.from)).collect();
        assert_eq!(tools, want, "{table:?}: {:?}", sink.diags);
        let rep = verify_with(&p.machine, &o, &cl, &sink.nc);
        assert!(rep.ok && rep.matched == 12, "{table:?}: {rep:?}");
    }
}
