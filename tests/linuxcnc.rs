//! LinuxCNC's own interpreter reads what kinepost writes in its dialect: `rs274` (Debian's
//! `linuxcnc-uspace`) runs every program to its end, with no error, on every shipped profile,
//! joint and TCP, the corpus files copied here in every option that changes the words, and the
//! program-flow golden file. Skipped where `rs274` is not installed, unless
//! `KINEPOST_REQUIRE_RS274` is set (CI sets it).

mod common;

use common::collect::Collect;
use kinepost::machines::Library;
use kinepost::post::{self, Settings};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

fn rs274() -> Option<PathBuf> {
    let found = std::env::var_os("PATH")
        .iter()
        .flat_map(std::env::split_paths)
        .map(|d| d.join("rs274"))
        .find(|p| p.is_file());
    if found.is_none() {
        assert!(std::env::var_os("KINEPOST_REQUIRE_RS274").is_none(), "rs274 is required here (apt-get install linuxcnc-uspace)");
        eprintln!("rs274 not installed: LinuxCNC's interpreter not run");
    }
    found
}

/// `nc` through the interpreter in batch mode: `None` if it ran to the end with no message,
/// else what it said. Tools 1–20 exist (a G41's register needs one), 2.54 mm across.
fn interpret(rs274: &Path, dir: &Path, nc: &str) -> Option<String> {
    let table = dir.join("tools.tbl");
    if !table.exists() {
        let lines: String = (1..=20).map(|t| format!("T{t} P{t} D0.1 Z0 ;tool {t}\n")).collect();
        std::fs::write(&table, lines).unwrap();
    }
    let (prog, canon) = (dir.join("prog.ngc"), dir.join("canon.txt"));
    std::fs::write(&prog, nc).unwrap();
    let out = Command::new(rs274)
        .arg("-t")
        .arg(&table)
        .arg("-g")
        .arg(&prog)
        .arg(&canon)
        .stdin(Stdio::null())
        .current_dir(dir)
        .output()
        .unwrap();
    let said: String = [&out.stdout[..], &out.stderr[..]]
        .iter()
        .map(|b| String::from_utf8_lossy(b).to_string())
        .collect::<Vec<_>>()
        .join("")
        .lines()
        .filter(|l| l.trim() != "executing")
        .collect::<Vec<_>>()
        .join(" | ");
    (!out.status.success() || !said.is_empty()).then(|| format!("exit {:?}: {said}", out.status.code()))
}

fn post_linuxcnc(cl: &[u8], machine: &str, extra: impl Fn(&mut Settings)) -> String {
    let lib = Library::load_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/machines").as_ref()).unwrap();
    let p = lib.get(machine).unwrap();
    let mut s = Settings { dialect: Some("linuxcnc".into()), ..Default::default() };
    extra(&mut s);
    let o = s.profile_options(&p, None).unwrap();
    let mut sink = Collect::default();
    post::post(cl, &p.machine, &o, &mut sink).unwrap();
    sink.nc
}

#[test]
fn linuxcnc_reads_every_program_to_its_end() {
    let Some(rs274) = rs274() else { return };
    let dir = std::env::temp_dir().join(format!("kinepost-rs274-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mut failures = Vec::new();
    let mut run = |what: String, nc: String| {
        if let Some(e) = interpret(&rs274, &dir, &nc) {
            failures.push(format!("{what}: {e}"));
        }
    };
    let lib = Library::load_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/machines").as_ref()).unwrap();
    for p in lib.iter() {
        let id = &p.machine.id;
        let mut cl = Vec::new();
        kinepost::testgen::write_path(&p.machine, 120, 3, p.machine.default_tool_length, &mut cl).unwrap();
        for mode in ["joint", "tcp"] {
            run(format!("{id} {mode}"), post_linuxcnc(&cl, id, |s| s.mode = Some(mode.into())));
        }
    }
    let data = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data");
    let files = ["nx_clsf_mech491_simple_mill_plane_mm.cls", "nx_clsf_mech491_variable_axis_inch_5ax.cls",
        "creo8_ncl_bohren_drill_mm.ncl", "creo8_ncl_profilfraesen_profile_mm.ncl", "generated/nx_two_setups_moved.cls"];
    for f in files {
        let cl = std::fs::read(Path::new(data).join(f)).unwrap();
        for (what, extra) in [
            ("joint", (|_: &mut Settings| {}) as fn(&mut Settings)),
            ("tcp", |s| s.mode = Some("tcp".into())),
            ("canned cycles", |s| s.cycles = Some("canned".into())),
            ("work offsets", |s| s.setups = Some("work-offsets".into())),
        ] {
            run(format!("{f} haas-umc750 {what}"), post_linuxcnc(&cl, "haas-umc750", extra));
        }
    }
    let golden = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/golden/flow-linuxcnc-vmc-4axis-a.nc");
    run("the program-flow golden".into(), std::fs::read_to_string(golden).unwrap());
    let _ = std::fs::remove_dir_all(&dir);
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
