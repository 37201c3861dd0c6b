//! The command line as a user runs it: real process, real output.

use serde_json::Value;
use std::process::Command;

fn kinepost(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_kinepost"))
        .args(args)
        .env("KINEPOST_MACHINES", concat!(env!("CARGO_MANIFEST_DIR"), "/machines"))
        .output()
        .unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8(out.stdout).unwrap(),
        String::from_utf8(out.stderr).unwrap(),
    )
}

fn json(s: &str) -> Value {
    serde_json::from_str(s).unwrap_or_else(|e| panic!("{e}: {s}"))
}

#[test]
fn machines_lists_every_profile_with_its_facts() {
    let (code, out, _) = kinepost(&["machines", "--json"]);
    assert_eq!(code, 0);
    let rows: Vec<Value> = out.lines().map(json).collect();
    assert_eq!(rows.len(), 11);
    let haas = rows.iter().find(|r| r["id"] == "haas-umc750").unwrap();
    assert_eq!(haas["kinematics"], "table-table");
    assert_eq!(haas["controller"], "haas");
    assert_eq!(haas["units"], "inch");
    let (code, table, _) = kinepost(&["machines"]);
    assert_eq!(code, 0);
    assert!(table.contains("propeller-3r2l") && table.contains("3-rotary/2-linear"));
}

#[test]
fn fk_then_ik_round_trips_through_the_cli_with_negative_options() {
    let (code, out, err) = kinepost(&[
        "fk",
        "--machine",
        "htm50200-horizontal",
        "--tool-length",
        "120",
        "--work-offset",
        "-1500,-1600,-400",
        "X=-900",
        "Y=-1000",
        "Z=-500",
        "A=230",
        "B=5",
    ]);
    assert_eq!(code, 0, "{err}");
    let pose = json(&out);
    let nums: Vec<String> = pose["tip"]
        .as_array()
        .unwrap()
        .iter()
        .chain(pose["axis"].as_array().unwrap())
        .map(|v| v.to_string())
        .collect();
    let mut args = vec![
        "ik",
        "--machine",
        "htm50200-horizontal",
        "--tool-length",
        "120",
        "--work-offset",
        "-1500,-1600,-400",
        "--",
    ];
    args.extend(nums.iter().map(|s| s.as_str()));
    let (code, out, err) = kinepost(&args);
    assert_eq!(code, 0, "{err}");
    let sols = json(&out)["solutions"].as_array().unwrap().clone();
    assert_eq!(sols.len(), 2);
    // Every solution printed, in limits or not, must reproduce the pose through `fk`: the words
    // are never wrapped (angle error is not periodic: the out-of-limits branch needs B > 180°).
    for s in &sols {
        let words: Vec<String> = ["X", "Y", "Z", "A", "B"].iter().map(|k| format!("{k}={}", s[k])).collect();
        let mut a = vec![
            "fk",
            "--machine",
            "htm50200-horizontal",
            "--tool-length",
            "120",
            "--work-offset",
            "-1500,-1600,-400",
        ];
        a.extend(words.iter().map(|s| s.as_str()));
        let (code, back, err) = kinepost(&a);
        assert_eq!(code, 0, "{err}");
        let back = json(&back);
        for k in 0..3 {
            let d = back["tip"][k].as_f64().unwrap() - pose["tip"][k].as_f64().unwrap();
            assert!(d.abs() < 1e-8, "{s}: tip {k} off by {d}");
        }
    }
    let inside = sols.iter().find(|s| s["within_limits"] == true).unwrap();
    assert!(
        (inside["A"].as_f64().unwrap() - -130.0).abs() < 1e-9,
        "A 230° is -130° in (-180, 180]: {inside}"
    );
    assert!((inside["B"].as_f64().unwrap() - 5.0).abs() < 1e-9);
}

#[test]
fn ik_reports_singular_and_unreachable_poses() {
    let (code, out, _) = kinepost(&["ik", "--machine", "spinner-u5-620", "10", "20", "30", "0", "0", "1"]);
    assert_eq!(code, 0);
    let s = &json(&out)["solutions"][0];
    assert_eq!(s["singular"], true);
    assert_eq!(s["free_axis"], "C");
    let (code, _, err) = kinepost(&["ik", "--machine", "vmc-3axis", "0", "0", "0", "0", "0.5", "0.866"]);
    assert_ne!(code, 0);
    assert!(err.contains("unreachable") && err.contains("30.0"), "{err}");
}

#[test]
fn ik_converts_explicit_units() {
    // 25.4 mm on an inch machine is 1 inch.
    let (_, a, _) = kinepost(&[
        "ik",
        "--machine",
        "haas-umc750",
        "--units",
        "mm",
        "25.4",
        "0",
        "0",
        "0",
        "0",
        "1",
    ]);
    let (_, b, _) = kinepost(&["ik", "--machine", "haas-umc750", "1", "0", "0", "0", "0", "1"]);
    let (a, b) = (json(&a), json(&b));
    let (sa, sb) = (&a["solutions"][0], &b["solutions"][0]);
    for k in ["X", "Y", "Z", "B", "C"] {
        // 25.4 × (1 / 25.4) is 1 less an ulp.
        assert!((sa[k].as_f64().unwrap() - sb[k].as_f64().unwrap()).abs() < 1e-12, "{k}: {sa} {sb}");
    }
    for k in ["branch", "within_limits", "singular", "free_axis"] {
        assert_eq!(sa[k], sb[k], "{k}");
    }
    assert_eq!(a["solutions"].as_array().unwrap().len(), b["solutions"].as_array().unwrap().len());
}

#[test]
fn bad_arguments_are_clear_errors() {
    for (args, want) in [
        (vec!["fk", "--machine", "nope", "X=1"], "no machine profile"),
        (vec!["fk", "--machine", "propeller-3r2l", "X=1"], "no X axis"),
        (vec!["fk", "--machine", "spinner-u5-620", "Q=1"], "no axis"),
        (vec!["fk", "--machine", "spinner-u5-620", "B=abc"], "not a number"),
        (
            vec!["fk", "--machine", "spinner-u5-620", "--work-offset", "1,2", "B=1"],
            "three numbers x,y,z within",
        ),
        (
            vec!["ik", "--machine", "spinner-u5-620", "1", "2", "3", "0", "0", "0"],
            "axis non-zero",
        ),
        (
            vec!["post", "--machine", "spinner-u5-620", "--work-coordinates", "G60", "-"],
            "work_coordinates \"G60\": fanuc takes G54, G55, G56, G57, G58, G59 or none",
        ),
        (
            vec!["post", "--machine", "spinner-u5-620", "--spindle-speed", "-100", "-"],
            "spindle_speed must be from 1 to 200000 RPM",
        ),
    ] {
        let (code, _, err) = kinepost(&args);
        assert_ne!(code, 0, "{args:?}");
        assert!(err.contains(want), "{args:?}: {err}");
    }
}

#[test]
fn post_verify_lint_and_generate_as_a_user_runs_them() {
    let dir = std::env::temp_dir().join(format!("kinepost-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let cl = dir.join("p.cls");
    let (code, out, err) = kinepost(&["generate", "--machine", "htm50200-horizontal", "--points", "60"]);
    assert_eq!(code, 0, "{err}");
    std::fs::write(&cl, out).unwrap();
    let (nc, nd) = (dir.join("p.nc"), dir.join("p.ndjson"));
    let (code, _, err) = kinepost(&[
        "post",
        "--machine",
        "htm50200-horizontal",
        "--work-offset",
        "-1500,-1600,-400",
        "--sequence-numbers",
        "--work-coordinates",
        "g55",
        "--diagnostics",
        nd.to_str().unwrap(),
        "-o",
        nc.to_str().unwrap(),
        cl.to_str().unwrap(),
    ]);
    // The path was generated for no work offset: shifted, parts of it leave the travel, and a
    // program written with errors exits 1.
    assert_eq!(code, 1, "{err}");
    assert!(err.contains("60 CL points") && err.contains("not fit to run"), "{err}");
    let text = std::fs::read_to_string(&nc).unwrap();
    assert!(
        text.starts_with("%\nO1000\n") && text.trim_end().ends_with("M30\n%"),
        "{text}"
    );
    assert!(text.contains(" G80 G55\n"), "the work coordinates asked for: {text}");
    assert!(
        text.contains("N5 ") && text.contains("G93"),
        "joint mode with rotary motion writes inverse time"
    );
    let lines: Vec<Value> = std::fs::read_to_string(&nd).unwrap().lines().map(json).collect();
    assert!(lines.iter().any(|l| l["type"] == "block" && l["source_line"].is_number()));
    assert_eq!(lines.last().unwrap()["type"], "summary");
    let (code, out, err) = kinepost(&[
        "verify",
        "--machine",
        "htm50200-horizontal",
        "--work-offset",
        "-1500,-1600,-400",
        "--cl",
        cl.to_str().unwrap(),
        "--nc",
        nc.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(json(&out)["matched"], 60);
    // Without the work offset the same program does not reproduce the CL.
    let (code, _, err) = kinepost(&[
        "verify",
        "--machine",
        "htm50200-horizontal",
        "--cl",
        cl.to_str().unwrap(),
        "--nc",
        nc.to_str().unwrap(),
    ]);
    assert_ne!(code, 0);
    assert!(err.contains("CL points matched"), "{err}");
    // lint exits non-zero on a bad record and names it.
    let bad = dir.join("bad.cls");
    std::fs::write(&bad, "GOTO/1,2,3\nGOTO/1,x,3\n").unwrap();
    let (code, _, err) = kinepost(&["lint", bad.to_str().unwrap()]);
    assert_ne!(code, 0);
    assert!(err.contains("line 2, column 8"), "{err}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn machines_validate_add_and_fit_offline() {
    let dir = std::env::temp_dir().join(format!("kinepost-machines-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let shipped = concat!(env!("CARGO_MANIFEST_DIR"), "/machines/vmc-3axis.toml");
    let (code, out, _) = kinepost(&["machines", "validate", shipped]);
    assert_eq!(code, 0);
    assert!(out.starts_with("ok "));
    let bad = dir.join("bad.toml");
    std::fs::write(&bad, "id = \"bad\"\nunits = \"cm\"\n").unwrap();
    let (code, out, _) = kinepost(&["machines", "validate", bad.to_str().unwrap()]);
    assert_ne!(code, 0);
    assert!(out.contains("units"), "{out}");
    // The paper's polynomial from a CSV of angle,error.
    let paper = [0.1808, -2.95e-2, 2.3e-3, -7e-5, -8e-7];
    let mut csv = String::from("angle,error\n");
    for t in 0..=40 {
        csv.push_str(&format!("{t},{}\n", paper.iter().rev().fold(0.0, |a, k| a * t as f64 + k)));
    }
    let input = dir.join("b.csv");
    std::fs::write(&input, csv).unwrap();
    let (code, toml_out, err) = kinepost(&[
        "machines",
        "fit-angle-error",
        "--machine",
        "htm50200-horizontal",
        "--axis",
        "B",
        "--input",
        input.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("proposed: degree 4"), "{err}");
    // Apply it explicitly into a library of our own.
    let lib = dir.join("lib");
    std::fs::create_dir_all(&lib).unwrap();
    let proposal = dir.join("htm50200-horizontal.toml");
    std::fs::write(&proposal, toml_out).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_kinepost"))
        .args([
            "--machines",
            lib.to_str().unwrap(),
            "machines",
            "add",
            proposal.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(lib.join("htm50200-horizontal.toml").exists());
    std::fs::remove_dir_all(&dir).ok();
}

/// `post`'s exit status says what the program is: 0 clean, 1 written with error diagnostics (the
/// NC is there, and says so), 2 refused (strict mode, unreadable input): nothing for a script to
/// mistake for a good program.
#[test]
fn post_exits_0_clean_1_with_errors_2_refused() {
    let dir = std::env::temp_dir().join(format!("kinepost-cli-exit-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let write = |name: &str, text: &str| {
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p.to_str().unwrap().to_string()
    };
    let good = write(
        "good.cl",
        "FEDRAT/500,MMPM\nLOADTL/1\nSPINDL/1000\nGOTO/10,20,30,0,0,1\nGOTO/10,25,30,0,0,1\nFINI\n",
    );
    let bad = write(
        "bad.cl",
        "FEDRAT/500,MMPM\nLOADTL/1\nSPINDL/1000\nGOTO/10,20,30,0,0,1\nGOTO/9000,20,30,0,0,1\nFINI\n",
    );
    let nc = dir.join("out.nc");
    let post = |cl: &str, extra: &[&str]| {
        let mut a = vec!["post", "--machine", "spinner-u5-620", cl, "-o", nc.to_str().unwrap()];
        a.extend_from_slice(extra);
        kinepost(&a)
    };
    let (code, _, err) = post(&good, &[]);
    assert_eq!(code, 0, "{err}");
    let (code, _, err) = post(&bad, &[]);
    assert_eq!(code, 1, "{err}");
    assert!(err.contains("not fit to run"), "{err}");
    let text = std::fs::read_to_string(&nc).unwrap();
    assert!(
        text.contains("ERROR LIMIT_VIOLATION") && text.contains("KINEPOST: ERRORS 1,"),
        "{text}"
    );
    let (code, _, err) = post(&bad, &["--strict"]);
    assert_eq!(code, 2, "{err}");
    let text = std::fs::read_to_string(&nc).unwrap();
    let last = text.lines().last().unwrap();
    assert!(last.starts_with("(KINEPOST: NOT FIT TO RUN, CUT SHORT: ERROR[LIMIT_VIOLATION] LINE 5"), "{text}");
    // Over its time bound: refused, and the file cut short says so.
    let (code, _, err) = post(&good, &["--max-post-seconds", "0.000001"]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("time bound"), "{err}");
    let text = std::fs::read_to_string(&nc).unwrap();
    assert!(text.contains("(KINEPOST: NOT FIT TO RUN, CUT SHORT: TIME BOUND"), "{text}");
    let (code, _, err) = post(&good, &["--max-post-seconds", "-1"]);
    assert_eq!(code, 2, "{err}");
    let (code, _, err) = post(dir.join("missing.cl").to_str().unwrap(), &[]);
    assert_eq!(code, 2, "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// An NC program given where CL is meant is refused (exit 2), naming what it looks like, and
/// nothing is written for the machinist to take for a program.
#[test]
fn post_refuses_g_code_given_as_cl() {
    let dir = std::env::temp_dir().join(format!("kinepost-cli-notcl-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let nc = dir.join("part.nc");
    std::fs::write(&nc, "%\nO1000\nG21 G90 G54\nG0 X10 Y20 Z30\nG1 Z5 F500\nM30\n%\n").unwrap();
    let out = dir.join("out.nc");
    let (code, stdout, err) = kinepost(&[
        "post",
        "--machine",
        "vmc-3axis",
        nc.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("this looks like G-code (\"O1000\" at line 2), not CL data"),
        "{err}"
    );
    assert!(stdout.is_empty() && std::fs::read_to_string(&out).unwrap().is_empty());
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A whitespace-only admin token would be a token anyone can guess: the service refuses to start.
#[test]
fn a_blank_admin_token_is_refused_at_start() {
    let out = Command::new(env!("CARGO_BIN_EXE_kinepost"))
        .args(["serve", "--bind", "127.0.0.1:0"])
        .env("KINEPOST_ADMIN_TOKEN", "   ")
        .env("KINEPOST_MACHINES", concat!(env!("CARGO_MANIFEST_DIR"), "/machines"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("only whitespace"));
}

/// A profile file is read only so far: `machines validate /dev/zero` grew to 9.6 GB.
#[test]
fn machines_validate_reads_a_bounded_file() {
    let (code, out, err) = kinepost(&["machines", "validate", "/dev/zero"]);
    assert_eq!(code, 2, "{out}{err}");
    assert!(out.contains("larger than 1048576 bytes"), "{out}{err}");
}

/// A reader that goes away (`kinepost machines validate … | head`) ends the output; it panicked
/// (exit 101) on the closed pipe.
#[test]
fn a_closed_pipe_ends_the_output_without_a_panic() {
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/machines");
    let files: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path().display().to_string())
        .collect();
    let mut args = vec!["machines".to_string(), "validate".to_string()];
    // Enough lines that they outlast the pipe's buffer once the reader is gone.
    for _ in 0..2000 {
        args.extend(files.iter().cloned());
    }
    let mut child = Command::new(env!("CARGO_BIN_EXE_kinepost"))
        .args(&args)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
}

/// `--log-format json` writes nothing but JSON lines (a plain "listening on" line broke every
/// log shipper), and a log that is no terminal carries no colour codes.
#[test]
fn the_service_log_is_one_format_and_plain_in_a_file() {
    use std::io::{BufRead, BufReader};
    for format in ["json", "text"] {
        let data = std::env::temp_dir().join(format!("kinepost-log-{format}-{}", std::process::id()));
        let mut child = Command::new(env!("CARGO_BIN_EXE_kinepost"))
            .args(["serve", "--bind", "127.0.0.1:0", "--log-format", format, "--data-dir", data.to_str().unwrap()])
            .env("KINEPOST_MACHINES", concat!(env!("CARGO_MANIFEST_DIR"), "/machines"))
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let mut err = BufReader::new(child.stderr.take().unwrap());
        let mut first = String::new();
        err.read_line(&mut first).unwrap();
        Command::new("kill").args(["-TERM", &child.id().to_string()]).status().unwrap();
        child.wait().unwrap();
        let mut lines = vec![first];
        lines.extend(err.lines().map(Result::unwrap));
        assert!(lines[0].contains("listening on http://127.0.0.1:"), "{format}: {lines:?}");
        for l in lines.iter().filter(|l| !l.trim().is_empty()) {
            assert!(!l.contains('\u{1b}'), "{format}: colour codes in a file: {l:?}");
            if format == "json" {
                assert!(serde_json::from_str::<Value>(l).is_ok(), "not JSON: {l:?}");
            }
        }
        let _ = std::fs::remove_dir_all(&data);
    }
}

/// The image's HEALTHCHECK asks the port `KINEPOST_BIND` names (it asked 8080 whatever the
/// service listened on): the Dockerfile's own command, run by bash against a real server.
#[test]
fn the_images_health_check_follows_the_bind_address() {
    use std::io::{BufRead, BufReader};
    let dockerfile = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/Dockerfile")).unwrap();
    let cmd = dockerfile.split("HEALTHCHECK").nth(1).unwrap().lines().find(|l| l.trim_start().starts_with("CMD [")).unwrap();
    let args: Vec<String> = serde_json::from_str(&cmd[cmd.find('[').unwrap()..]).unwrap();
    assert_eq!(args[..2], ["bash", "-c"]);
    let data = std::env::temp_dir().join(format!("kinepost-health-{}", std::process::id()));
    let mut child = Command::new(env!("CARGO_BIN_EXE_kinepost"))
        .args(["serve", "--bind", "127.0.0.1:0", "--data-dir", data.to_str().unwrap()])
        .env("KINEPOST_MACHINES", concat!(env!("CARGO_MANIFEST_DIR"), "/machines"))
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut line = String::new();
    BufReader::new(child.stderr.take().unwrap()).read_line(&mut line).unwrap();
    let port = line.split("listening on http://127.0.0.1:").nth(1).unwrap().split(|c: char| !c.is_ascii_digit()).next().unwrap().to_string();
    let health = |bind: &str| Command::new("bash").args(["-c", &args[2]]).env("KINEPOST_BIND", bind).status().unwrap().success();
    let (wild, lo) = (health(&format!("0.0.0.0:{port}")), health(&format!("127.0.0.1:{port}")));
    let elsewhere = health("0.0.0.0:1");
    child.kill().unwrap();
    child.wait().unwrap();
    let _ = std::fs::remove_dir_all(&data);
    assert!(wild && lo, "healthy on its own port: {wild} {lo}");
    assert!(!elsewhere, "and not where nothing listens");
}
