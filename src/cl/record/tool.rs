//! The tool records: `LOADTL`/`LOAD/TOOL` (the change, its length and register) and what a tool
//! is (`TLDATA`, `CUTTER`, CATIA's `TOOLNO` and `TURRET`), milling or turning.

use super::{Arg, Record, Stmt, num};
use crate::diag::{Code, Diagnostic, Severity};

/// `LOADTL/n[,LENGTH,l]` and `LOAD/TOOL,n[,ADJUST,m]`.
pub(in crate::cl) fn load_tool(st: &Stmt, diags: &mut Vec<Diagnostic>) -> Option<Record> {
    let args = &st.args;
    let (mut number, mut length, mut adjust) = (None, None, None);
    let mut unread: Vec<&Arg> = Vec::new();
    let mut i = 0;
    while i < args.len() {
        let w = args[i].word();
        match w.as_str() {
            "TOOL" => {}
            "LENGTH" => {
                length = args.get(i + 1).and_then(|a| num(a.text));
                i += 1;
            }
            "ADJUST" | "OSETNO" => {
                adjust = length_offset(st, i, &w, diags);
                i += 1;
            }
            _ => match num(args[i].text) {
                Some(x) if number.is_none() => number = Some(tool_number(st, &args[i], x, diags)?),
                Some(_) => unread.push(&args[i]),
                None if w.is_empty() || matches!(w.as_str(), "MILL" | "LATHE") => {}
                None => st.unused(diags, &args[i], &w),
            },
        }
        i += 1;
    }
    if let Some(first) = unread.first() {
        // Fusion's APT post writes `LOADTL/t, 0, length, offset` and CATIA `LOADTL/t,1`: the
        // positions mean different things in each, so they are told rather than guessed.
        let values: Vec<&str> = unread.iter().map(|a| a.text.trim()).collect();
        let msg = format!(
            "{}: {} after the tool number not read (kinepost reads LENGTH,l and ADJUST,n): the tool's length and register come from a tool table, the profile or the tool's own number",
            st.major,
            values.join(", ")
        );
        diags.push(Diagnostic::new(Code::IgnoredRecord, Severity::Warning, Some(st.line), msg).at(first.col));
    }
    let Some(number) = number else {
        st.bad(
            diags,
            st.rest_col,
            format!("{}: no tool number: no tool change written", st.major),
        );
        return None;
    };
    Some(Record::LoadTool {
        number,
        length,
        adjust: adjust.filter(|&a| a != number),
    })
}

/// The length offset register after `ADJUST` or `OSETNO` (the word at `i`), the one the CAM
/// system named. One that cannot be written is told and `None`: the change is still written,
/// with the tool's own register, since a dropped change leaves the last tool cutting at the
/// new one's length (NX's `LOAD/TOOL,3,ADJUST,0`: T2 ran on, 25.4 mm too deep). `ADJUST,0`
/// names no register (NX writes it for "none"): a warning; anything else unreadable an error.
fn length_offset(st: &Stmt, i: usize, w: &str, diags: &mut Vec<Diagnostic>) -> Option<u32> {
    let (text, col) = st.args.get(i + 1).map_or(("", st.args[i].col), |a| (a.text.trim(), a.col));
    match num(text) {
        Some(x) if (1.0..1e6).contains(&x) && x.fract() == 0.0 => Some(x as u32),
        x => {
            let (sev, why) = if x == Some(0.0) {
                (Severity::Warning, "names no register")
            } else {
                (Severity::Error, "is not a length offset number from 1 to 999999")
            };
            let msg = format!(
                "{}: {w} {text:?} {why}: the tool change is written with the tool's own length offset",
                st.major
            );
            diags.push(Diagnostic::new(Code::BadRecord, sev, Some(st.line), msg).at(col));
            None
        }
    }
}

/// A tool number as given: another tool than the one the CAM system meant is a crash.
fn tool_number(st: &Stmt, a: &Arg, x: f64, diags: &mut Vec<Diagnostic>) -> Option<u32> {
    if x >= 0.0 && x.fract() == 0.0 && x < 1e9 {
        return Some(x as u32);
    }
    let msg = format!(
        "{}: tool number {:?} is not a whole number from 0 to 999999999: no tool change written",
        st.major,
        a.text.trim()
    );
    st.bad(diags, a.col, msg);
    None
}

/// What a tool is, by the record that describes it.
pub(in crate::cl) fn tool_data(st: &Stmt) -> Record {
    let args = &st.args;
    match st.major.as_str() {
        // TLDATA/MILL,diameter,corner radius,length,…
        "TLDATA" => {
            let nums: Vec<f64> = args.iter().filter_map(|a| num(a.text)).collect();
            let turning = tool_kind(args);
            Record::ToolData {
                diameter: nums.first().copied().filter(|_| turning != Some(true)),
                corner_radius: nums.get(1).copied().filter(|_| turning != Some(true)),
                length: nums.get(2).copied().filter(|l| *l > 0.0 && turning != Some(true)),
                turning,
            }
        }
        // TURRET/… selects a lathe's turret station (a mill's tool change is LOADTL): what
        // CATIA's lathe output says of its tools.
        "TURRET" => Record::ToolData {
            diameter: None,
            corner_radius: None,
            length: None,
            turning: Some(true),
        },
        // TOOLNO/number,TURN,… (CATIA): only what kind of tool it is.
        "TOOLNO" => Record::ToolData {
            diameter: None,
            corner_radius: None,
            length: None,
            turning: tool_kind(args),
        },
        _ => Record::ToolData {
            diameter: args.first().and_then(|a| num(a.text)),
            corner_radius: args.get(1).and_then(|a| num(a.text)),
            length: None,
            turning: None,
        },
    }
}

/// A lathe tool (`TURN`, `GROOVE`, `THREAD`) or a milling one (`MILL`, `DRILL`), where the record
/// names its kind.
fn tool_kind(args: &[Arg]) -> Option<bool> {
    args.iter().find_map(|a| {
        let w = a.text.trim();
        let is = |k: &str| w.eq_ignore_ascii_case(k);
        if is("TURN") || is("GROOVE") || is("THREAD") {
            Some(true)
        } else if is("MILL") || is("DRILL") {
            Some(false)
        } else {
            None
        }
    })
}
