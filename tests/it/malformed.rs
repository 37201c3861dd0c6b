//! The table of malformed inputs: each is answered with a clear error naming the problem code,
//! the CL line and the column — by the CLI (`kinepost lint`) and by HTTP (strict mode: 422
//! problem+json) alike. Every input is `UNITS/MM`, the case on line 2, then a good GOTO.

use crate::common;

use serde_json::Value;
use std::process::Command;

/// (input on line 2, problem code, column; None where the problem has no single column)
const CASES: &[(&str, &str, Option<u32>)] = &[
    ("GOTO/1,2", "bad_record", Some(8)),
    ("GOTO/1,2,3,4", "bad_record", Some(12)),
    ("GOTO/1,2,3,4,5", "bad_record", Some(14)),
    ("GOTO/1,2,3,0.1,0.2", "bad_record", Some(16)),
    ("GOTO/a,2,3", "bad_record", Some(6)),
    ("GOTO/1,b,3", "bad_record", Some(8)),
    ("GOTO/1,2,c", "bad_record", Some(10)),
    ("GOTO/1,2,3,0,0,x", "bad_record", Some(16)),
    ("GOTO/1e999,2,3", "bad_record", Some(6)),
    ("GOTO/NaN,2,3", "bad_record", Some(6)),
    ("GOTO / 1, 2, zz", "bad_record", Some(14)),
    ("GOTO/1,,3", "bad_record", Some(8)),
    ("GOTO/,1,2", "bad_record", Some(6)),
    ("GOTO/1,2,3,,", "bad_record", Some(12)),
    ("GOTO/1.2.3,0,0", "bad_record", Some(6)),
    ("GOTO/--1,0,0", "bad_record", Some(6)),
    ("GOTO/1e,0,0", "bad_record", Some(6)),
    ("GOTO/0x10,0,0", "bad_record", Some(6)),
    ("GODLTA/1,2", "bad_record", Some(10)),
    ("FROM/x,0,0", "bad_record", Some(6)),
    ("FEDRAT/abc", "bad_record", Some(8)),
    ("FEDRAT/MMPM", "bad_record", Some(8)),
    ("FEDRAT/100,XYZ", "bad_record", Some(12)),
    ("FEDRAT/-5,MMPM", "bad_record", Some(8)),
    ("FEDRAT/100,MMPM,200", "bad_record", Some(17)),
    ("SPINDL/fast", "bad_record", Some(8)),
    ("SPINDL/RPM", "bad_record", Some(8)),
    ("SPINDL/1000,RPM,WRONG", "bad_record", Some(17)),
    ("SPINDL/RPM,-100", "bad_record", Some(12)),
    ("COOLNT/LAVA", "bad_record", Some(8)),
    ("UNITS/FURLONGS", "bad_record", Some(7)),
    ("UNIT/CM", "bad_record", Some(6)),
    ("UNITS/", "bad_record", Some(7)),
    ("TLAXIS/0,0", "bad_record", Some(8)),
    ("TLAXIS/a,b,c", "bad_record", Some(8)),
    ("CIRCLE/1,2,3", "bad_record", Some(8)),
    ("CIRCLE/a,2,3,0,0,1,5", "bad_record", Some(8)),
    ("CIRCLE/1,2,3,0,0,1,5.x", "bad_record", Some(20)),
    ("GOTO/1,$\n2,x", "bad_record", Some(10)),
    ("GOTO/1,2,3,0,0,0", "bad_record", Some(12)),
    ("FEDRAT/0,MMPM", "bad_record", Some(8)),
    ("LOADTL/2.5", "bad_record", Some(8)),
    ("LOADTL/-1", "bad_record", Some(8)),
    ("LOADTL/999999999999", "bad_record", Some(8)),
    ("LOAD/TOOL", "bad_record", Some(6)),
    ("LOAD/TOOL,5,ADJUST,2.5", "bad_record", Some(20)),
    ("ROTABL/,AAXIS", "bad_record", Some(8)),
    ("DELAY/-1", "bad_record", Some(7)),
    ("LONG", "line_too_long", None),
];

fn body(case: &str) -> String {
    let line = if case == "LONG" {
        "G".repeat(70 * 1024)
    } else {
        case.to_string()
    };
    format!("UNITS/MM\n{line}\nGOTO/1,2,3\n")
}

#[test]
fn the_table_has_forty_five_cases() {
    assert!(CASES.len() >= 45);
}

#[test]
fn every_case_by_the_cli() {
    let dir = std::env::temp_dir().join(format!("kinepost-malformed-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    for (i, (case, code, col)) in CASES.iter().enumerate() {
        let f = dir.join(format!("{i}.cls"));
        std::fs::write(&f, body(case)).unwrap();
        let out = Command::new(env!("CARGO_BIN_EXE_kinepost"))
            .args(["lint", f.to_str().unwrap()])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{case:?} accepted");
        let want = match col {
            Some(c) => format!("error[{code}] line 2, column {c}:"),
            None => format!("error[{code}] line 2"),
        };
        assert!(err.contains(&want), "{case:?}: want {want:?} in {err}");
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[tokio::test]
async fn every_case_by_http() {
    let base = common::server(common::cfg()).await;
    let c = reqwest::Client::new();
    for (case, code, col) in CASES {
        let r = c
            .post(format!("{base}/v1/post?machine=spinner-u5-620&strict=true"))
            .header("content-type", "text/plain")
            .body(body(case))
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 422, "{case:?}");
        assert_eq!(r.headers()["content-type"], "application/problem+json");
        let p: Value = r.json().await.unwrap();
        assert_eq!(p["type"], "https://kinepost.dev/problems/bad-record", "{case:?}");
        assert_eq!(p["code"], *code, "{case:?}: {p}");
        assert_eq!(p["line"], 2, "{case:?}: {p}");
        assert_eq!(p["column"].as_u64(), col.map(u64::from), "{case:?}: {p}");
    }
}

/// Poses and limits: the block's CL line and the axis named, by HTTP (strict) and CLI.
#[tokio::test]
async fn unreachable_poses_and_limits_name_line_and_axis() {
    let base = common::server(common::cfg()).await;
    let c = reqwest::Client::new();
    for (cl, code, needle) in [
        (
            "FEDRAT/500,MMPM\nGOTO/0,0,10,0,0,1\nGOTO/0,0,10,0,0.5,0.8660254\n",
            "unreachable",
            "30.0",
        ),
        (
            "FEDRAT/500,MMPM\nGOTO/0,0,10,0,0,1\nGOTO/900,0,10,0,0,1\n",
            "limit_violation",
            "X = 900",
        ),
    ] {
        let r = c
            .post(format!("{base}/v1/post?machine=vmc-3axis&strict=true"))
            .header("content-type", "text/plain")
            .body(cl)
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 422);
        let p: Value = r.json().await.unwrap();
        assert_eq!((p["code"].as_str(), p["line"].as_u64()), (Some(code), Some(3)), "{p}");
        assert!(p["detail"].as_str().unwrap().contains(needle), "{p}");
    }
}

/// Non-ASCII where the NC reader looked at the first bytes of a word (`CYCLE800(`, `MCALL`,
/// `BEGIN PGM`, an axis letter) is an error or nothing, never a panic on a char boundary.
#[test]
fn the_nc_reader_takes_non_ascii_words_without_panicking() {
    use kinepost::nc::read::NcReader;
    let programs = [
        "%\nO1000\nABCDEFGHé X1\nMCALé\nCYCLE80é(1)\nG1 Xé Y1\n%\n",
        "BEGIN PGM 1 MM\nL é\nL Xé Y+1\nL Ié\nBEGIN PGé\nEND PGM 1 MM\n",
        "é\nééééééééé\n",
    ];
    for nc in programs {
        let mut r = NcReader::new(nc.as_bytes(), kinepost::kinematics::Units::Mm);
        for _ in 0..64 {
            match r.next_block() {
                Ok(Some(_)) | Err(_) => {}
                Ok(None) => break,
            }
        }
    }
}
