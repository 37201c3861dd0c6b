//! LinuxCNC's own interpreter reads what kinepost writes in its dialect: `rs274` (Debian's
//! `linuxcnc-uspace`) runs every program to its end, with no error, on every shipped profile,
//! joint and TCP, the corpus files copied here in every option that changes the words, and the
//! program-flow golden file. Skipped where `rs274` is not installed, unless
//! `KINEPOST_REQUIRE_RS274` is set (CI sets it).

use crate::common;

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
    interpret_with(rs274, dir, nc, None)
}

/// One interpreter at a time: two at once in this process crash now and then (killed by a
/// signal, nothing said).
static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// [`interpret`] with an INI file (`-i`): a configuration's remapped M codes.
fn interpret_with(rs274: &Path, dir: &Path, nc: &str, ini: Option<&Path>) -> Option<String> {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let table = dir.join("tools.tbl");
    if !table.exists() {
        let lines: String = (1..=20).map(|t| format!("T{t} P{t} D0.1 Z0 ;tool {t}\n")).collect();
        std::fs::write(&table, lines).unwrap();
    }
    let (prog, canon) = (dir.join("prog.ngc"), dir.join("canon.txt"));
    std::fs::write(&prog, nc).unwrap();
    let mut cmd = Command::new(rs274);
    if let Some(ini) = ini {
        cmd.arg("-i").arg(ini);
    }
    let out = cmd
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
    let lib = Library::load_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/machines").as_ref())
        .and_then(|l| l.with_dialects(concat!(env!("CARGO_MANIFEST_DIR"), "/dialects").as_ref()))
        .unwrap();
    let p = lib.get(machine).unwrap();
    let mut s = Settings { dialect: Some("linuxcnc".into()), ..Default::default() };
    extra(&mut s);
    let o = s.profile_options_with(&p, None, &|id| lib.dialects.get(id)).unwrap();
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
    let lib = common::library();
    for p in lib.iter() {
        let id = &p.machine.id;
        let mut cl = Vec::new();
        kinepost::testgen::write_path(&p.machine, 120, 3, p.machine.default_tool_length, &mut cl).unwrap();
        for mode in ["joint", "tcp"] {
            run(format!("{id} {mode}"), post_linuxcnc(&cl, id, |s| s.mode = Some(mode.into())));
        }
        run(format!("{id} feed mode dpm"), post_linuxcnc(&cl, id, |s| s.feed_mode = Some("dpm".into())));
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
            ("feed mode dpm", |s| s.feed_mode = Some("dpm".into())),
        ] {
            run(format!("{f} haas-umc750 {what}"), post_linuxcnc(&cl, "haas-umc750", extra));
        }
    }
    let golden = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/golden/flow-linuxcnc-vmc-4axis-a.nc");
    run("the program-flow golden".into(), std::fs::read_to_string(golden).unwrap());
    let _ = std::fs::remove_dir_all(&dir);
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// LinuxCNC 2.9's xyzbc-trt kinematics, from its module's geometry: a part point `p` (the tip in
/// TCP mode) stands at the joints `r + d + Ry(b)·(Rz(c)·(p − r) − d)`, `r` the rot point, `d` the
/// x- and z-offsets; its tables turn by +b about +y and +c about +z (the module's note: the other
/// way round from the conventional directions). The shipped profile is that machine: kinepost's
/// FK gives the same part point for the same joints, on random joints.
#[test]
fn the_xyzbc_trt_profile_is_linuxcncs_trt_kinematics() {
    use kinepost::kinematics::{self, Joints, Setup, Vec3};
    use nalgebra::Rotation3;
    let lib = common::library();
    let m = &lib.get("linuxcnc-xyzbc-trt").unwrap().machine;
    let (r, d) = (Vec3::zeros(), Vec3::new(-20.0, 0.0, -15.0));
    let mut seed = 7u64;
    let mut next = |lo: f64, hi: f64| {
        seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        lo + (hi - lo) * ((seed >> 11) as f64 / (1u64 << 53) as f64)
    };
    for _ in 0..500 {
        let p = Vec3::new(next(-80.0, 80.0), next(-60.0, 60.0), next(-40.0, 60.0));
        let (b, c) = (next(-100.0, 50.0), next(-720.0, 720.0));
        let (rb, rc) = (Rotation3::from_axis_angle(&Vec3::y_axis(), b.to_radians()), Rotation3::from_axis_angle(&Vec3::z_axis(), c.to_radians()));
        let joint = r + d + rb * (rc * (p - r) - d);
        let j = Joints { linear: joint.into(), rotary: [b.to_radians(), c.to_radians(), 0.0] };
        let pose = kinematics::fk(m, &j, &Setup { tool_length: 50.0, work_offset: Vec3::zeros() });
        assert!((pose.tip - p).norm() < 1e-9, "B{b} C{c}: kinepost {} LinuxCNC {p}", pose.tip);
        let axis = rc.inverse() * (rb.inverse() * Vec3::z());
        assert!((pose.axis - axis).norm() < 1e-12, "B{b} C{c}");
    }
}

/// Its programs in the switchkins dialect (M428 on, M429 off) read by LinuxCNC's interpreter
/// with the sim configuration's remaps: every program to its end.
#[test]
fn xyzbc_trt_programs_run_with_switchkins() {
    let Some(rs274) = rs274() else { return };
    let dir = std::env::temp_dir().join(format!("kinepost-rs274-trt-{}", std::process::id()));
    std::fs::create_dir_all(dir.join("subs")).unwrap();
    for m in ["428", "429"] {
        std::fs::write(dir.join("subs").join(format!("{m}remap.ngc")), format!("o<{m}remap> sub\no<{m}remap> endsub\nM2\n")).unwrap();
    }
    let ini = dir.join("trt.ini");
    std::fs::write(
        &ini,
        format!(
            "[RS274NGC]\nSUBROUTINE_PATH = {}\nREMAP = M428  modalgroup=10  ngc=428remap\nREMAP = M429  modalgroup=10  ngc=429remap\n",
            dir.join("subs").display()
        ),
    )
    .unwrap();
    let lib = common::library();
    let m = &lib.get("linuxcnc-xyzbc-trt").unwrap().machine;
    let mut cl = Vec::new();
    kinepost::testgen::write_path(m, 200, 5, m.default_tool_length, &mut cl).unwrap();
    let mut failures = Vec::new();
    for mode in ["joint", "tcp"] {
        let nc = post_linuxcnc(&cl, "linuxcnc-xyzbc-trt", |s| {
            s.mode = Some(mode.into());
            s.dialect = Some("linuxcnc-switchkins".into());
        });
        assert_eq!(nc.contains("M428"), mode == "tcp", "{nc}");
        if let Some(e) = interpret_with(&rs274, &dir, &nc, Some(&ini)) {
            failures.push(format!("{mode}: {e}"));
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// Every hole cycle LinuxCNC has (G81 G82 G83 G73, G84 and G74 for a floating holder, G33.1
/// for a rigid tap, G85 G86 G89), canned and as moves, on a 3-axis and a 5-axis profile: rs274
/// reads each program to its end. (A fine bore is an error there: its G76 is threading.)
#[test]
fn linuxcnc_reads_every_hole_cycle_it_has() {
    let Some(rs274) = rs274() else { return };
    let dir = std::env::temp_dir().join(format!("kinepost-rs274-holes-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let kinds = [
        ("DRILL", "MMPM,120", ""),
        ("DRILL", "MMPM,120", ",DWELL,0.5"),
        ("DEEP", "MMPM,120", ",STEP,2"),
        ("BRKCHP", "MMPM,120", ",STEP,2"),
        ("TAP", "MMPR,1.25", ""),
        ("RGDTAP", "MMPR,1.25", ""),
        ("BORE", "MMPM,120", ""),
        ("BORE", "MMPM,120", ",DWELL,0.5"),
        ("REAM", "MMPM,120", ""),
        ("BORE,DRAG", "MMPM,120", ""),
    ];
    let mut cl = String::from("UNITS/MM\nLOADTL/1\nSPINDL/RPM,800,CLW\nRAPID\nGOTO/0,0,40,0,0,1\n");
    let mut x = 0;
    for (k, feed, extra) in kinds {
        x += 10;
        cl += &format!("CYCLE/{k},FEDTO,12,{feed},RAPTO,3,RTRCTO,15{extra}\nGOTO/{x},20,TOP\nCYCLE/OFF\n");
    }
    // Left-hand taps: the spindle turning CCW (G74, G33.1 follows the spindle).
    cl += "SPINDL/RPM,800,CCLW\n";
    for k in ["TAP", "RGDTAP"] {
        x += 10;
        cl += &format!("CYCLE/{k},FEDTO,12,MMPR,1.25,RAPTO,3\nGOTO/{x},20,TOP\nCYCLE/OFF\n");
    }
    cl += "END\nFINI\n";
    let mut failures = Vec::new();
    // The holes' tops where the table is not in the way.
    for (id, top) in [("vmc-3axis", "0"), ("spinner-u5-620", "60")] {
        let cl = cl.replace("TOP", top);
        for canned in [false, true] {
            let nc = post_linuxcnc(cl.as_bytes(), id, |s| {
                if canned {
                    s.cycles = Some("canned".into());
                }
            });
            assert!(nc.contains("ERRORS 0,"), "{id} canned {canned}:\n{nc}");
            let words: &[&str] = if canned {
                &[
                    "G81 ", "G82 ", "G83 ", "G73 ", "G84 ", "G74 ", "G33.1 ", "G85 ", "G86 ", "G89 ",
                ]
            } else {
                // Taps and the stopping bore are cycles even so.
                &["G84 ", "G74 ", "G33.1 ", "G86 "]
            };
            for w in words {
                assert!(nc.contains(w), "{id} canned {canned}: no {w}\n{nc}");
            }
            if let Some(e) = interpret(&rs274, &dir, &nc) {
                failures.push(format!("{id} canned {canned}: {e}\n{nc}"));
            }
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// The smoothing words (`G64 P<tol>` per operation, `G64` before a tool change and at the end)
/// as LinuxCNC's interpreter reads them: two operations at INTOL/OUTTOL 0.1 and 0.005, and the
/// NX 5-axis file with every operation at the finish level (the job's tolerance: the profile is
/// in inches).
#[test]
fn linuxcnc_reads_the_smoothing_words() {
    let Some(rs274) = rs274() else { return };
    let dir = std::env::temp_dir().join(format!("kinepost-rs274-smooth-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let op = |name: &str, t: &str, tool: u32, x: u32| {
        format!(
            "TOOL PATH/{name},TOOL,EM{tool}\nINTOL/{t}\nOUTTOL/{t}\nLOADTL/{tool}\nSPINDL/8000,CLW\nRAPID\nGOTO/0,0,50,0,0,1\nGOTO/0,0,5\nFEDRAT/1000\nGOTO/{x},0,5\nGOTO/{x},{x},5\nRAPID\nGOTO/{x},{x},50\n"
        )
    };
    let cl = format!("UNITS/MM\n{}{}FINI\n", op("POCKET_A", "0.1", 1, 10), op("WALLS_B", "0.005", 2, 20));
    let nc = post_linuxcnc(cl.as_bytes(), "vmc-3axis", |_| {});
    assert!(nc.contains("\nG64 P0.200\n") && nc.contains("\nG64 P0.010\n") && nc.contains("\nG64\n"), "{nc}");
    let mut failures: Vec<String> = interpret(&rs274, &dir, &nc).into_iter().collect();
    let data = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data");
    let cl = std::fs::read(Path::new(data).join("nx_clsf_mech491_variable_axis_inch_5ax.cls")).unwrap();
    for mode in ["joint", "tcp"] {
        let nc = post_linuxcnc(&cl, "haas-umc750", |s| {
            s.mode = Some(mode.into());
            s.smoothing = Some("finish".into());
        });
        assert!(nc.contains("\nG64 P0.0004\n"), "{mode}:\n{nc}");
        failures.extend(interpret(&rs274, &dir, &nc).map(|e| format!("{mode}: {e}")));
    }
    let _ = std::fs::remove_dir_all(&dir);
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
