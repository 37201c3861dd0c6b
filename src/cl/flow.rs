//! Program-flow records: what the operator's switches and the control's own codes do between
//! the moves (`OPSKIP`, `AUXFUN`, `PREFUN`, `SELCTL`), and `CUTCOM`, told until it is written.

use super::record::{Arg, Record, Stmt};
use crate::diag::{Code, Diagnostic, Severity};

/// `CUTCOM`, not written yet: told where it stands, with what the program does instead
/// (turning it off needs no word).
pub(super) fn cutcom(st: &Stmt, diags: &mut Vec<Diagnostic>) -> Option<Record> {
    let first = st.args.first().map(|a| a.word()).unwrap_or_default();
    if first == "OFF" {
        return Some(Record::Ignored(st.major.clone()));
    }
    let msg = format!(
        "CUTCOM/{first}: cutter compensation is not written (no G41/G42 or RL/RR): the path is cut as the CL gives it"
    );
    diags.push(Diagnostic::new(Code::IgnoredRecord, Severity::Warning, Some(st.line), msg).at(st.lead + 1));
    Some(Record::Ignored(st.major.clone()))
}

/// `OPSKIP/ON|OFF` (a bare `OPSKIP` turns it on).
pub(super) fn block_skip(st: &Stmt, diags: &mut Vec<Diagnostic>) -> Option<Record> {
    match st.args.first().map(Arg::word).as_deref() {
        Some("ON") | None => Some(Record::BlockSkip(true)),
        Some("OFF") => Some(Record::BlockSkip(false)),
        Some(other) => {
            st.bad(diags, st.args[0].col, format!("OPSKIP: expected ON or OFF, found {other:?}"));
            None
        }
    }
}

/// `SELCTL/n`: the next tool's number.
pub(super) fn preselect(st: &Stmt, diags: &mut Vec<Diagnostic>) -> Option<Record> {
    let Some(a) = st.args.first() else {
        st.bad(diags, st.rest_col, "SELCTL: expected a tool number".into());
        return None;
    };
    match a.text.trim().trim_end_matches('.').parse::<u32>() {
        Ok(n) => Some(Record::Preselect(n)),
        Err(_) => {
            st.bad(diags, a.col, format!("SELCTL: expected a tool number, found {:?}", a.text.trim()));
            None
        }
    }
}

/// `AUXFUN/n` and `PREFUN/n`: a code number (`5.1` for G) the control is to get as it is.
pub(super) fn function(st: &Stmt, diags: &mut Vec<Diagnostic>) -> Option<Record> {
    let letter = if st.major == "AUXFUN" { 'M' } else { 'G' };
    let Some(a) = st.args.first() else {
        st.bad(diags, st.rest_col, format!("{}: expected a code number", st.major));
        return None;
    };
    let code = a.text.trim().trim_end_matches('.');
    let (whole, frac) = code.split_once('.').unwrap_or((code, ""));
    let digits = |s: &str, most: usize| s.len() <= most && s.bytes().all(|b| b.is_ascii_digit());
    if whole.is_empty() || !digits(whole, 3) || !digits(frac, 1) {
        st.bad(diags, a.col, format!("{}: expected a code number (up to 3 digits), found {code:?}", st.major));
        return None;
    }
    let whole = whole.trim_start_matches('0');
    let code = match (whole.is_empty(), frac.is_empty()) {
        (true, true) => "0".to_string(),
        (_, true) => whole.to_string(),
        (true, false) => format!("0.{frac}"),
        (false, false) => format!("{whole}.{frac}"),
    };
    Some(Record::Function { letter, code })
}

/// `SELECT/TOOL,n` (NX, SOLIDWORKS CAM): `SELCTL/n` in other words.
pub(super) fn select(st: &Stmt, diags: &mut Vec<Diagnostic>) -> Option<Record> {
    match (st.args.first().map(Arg::word).as_deref(), st.args.get(1)) {
        (Some("TOOL"), Some(a)) => match a.text.trim().trim_end_matches('.').parse::<u32>() {
            Ok(n) => Some(Record::Preselect(n)),
            Err(_) => {
                st.bad(diags, a.col, format!("SELECT: expected a tool number, found {:?}", a.text.trim()));
                None
            }
        },
        _ => {
            st.bad(diags, st.rest_col, "SELECT: expected TOOL and a tool number".into());
            None
        }
    }
}
