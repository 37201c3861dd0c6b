//! Program-flow records: what the operator's switches and the control's own codes do between
//! the moves (`OPSKIP`, `AUXFUN`, `PREFUN`, `SELCTL`, `INTOL`/`OUTTOL`, `STOP`, `MODE`), and
//! cutter compensation (`CUTCOM`, with what the CL says its path is: Creo's
//! `$$-> CUTCOM_GEOMETRY_TYPE` comment).

use super::{Arg, Record, Stmt, num};
use crate::diag::Diagnostic;

/// Which side of the path the tool is offset to, looking along the motion with the tool axis
/// pointing at the viewer (APT's and the controls' G41/G42 sense).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    Left,
    Right,
}

/// `CUTCOM`: cutter radius compensation from the next move on, or off.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CutterComp {
    /// `LEFT`/`RIGHT` (`side`), or `ON` alone (no side: CAMWorks writes `ON` then `LEFT`; alone
    /// it repeats the last side); `register`: the offset number the CL names (`CUTCOM/LEFT,5`).
    On {
        side: Option<Side>,
        register: Option<u32>,
    },
    Off,
}

/// `CUTCOM/LEFT|RIGHT|ON|OFF[,XYPLAN][,n]` (NX `CUTCOM/LEFT,XYPLAN`, APT `CUTCOM/RIGHT,XYPLAN,5`,
/// `ADJUST,n`, `NOMORE` for off). A plane other than XY, or a word not known, is an error and
/// no compensation: a guess could put the tool on the wrong side of the contour.
pub(in crate::cl) fn cutcom(st: &Stmt, diags: &mut Vec<Diagnostic>) -> Option<Record> {
    let (mut on, mut off, mut side, mut register) = (false, false, None, None);
    for a in &st.args {
        match a.word().as_str() {
            "LEFT" => side = Some(Side::Left),
            "RIGHT" => side = Some(Side::Right),
            "ON" => on = true,
            "OFF" | "NOMORE" => off = true,
            "XYPLAN" | "ADJUST" | "" => {}
            w @ ("YZPLAN" | "ZXPLAN") => {
                st.bad(
                    diags,
                    a.col,
                    format!("CUTCOM: compensation in the {w} is not written (XYPLAN only): no compensation"),
                );
                return None;
            }
            w => match num(a.text) {
                Some(x) if (1.0..1e6).contains(&x) && x.fract() == 0.0 && register.is_none() => register = Some(x as u32),
                _ => {
                    let msg = format!(
                        "CUTCOM: {w:?} is no side (LEFT, RIGHT), ON, OFF, XYPLAN or offset number from 1: no compensation"
                    );
                    st.bad(diags, a.col, msg);
                    return None;
                }
            },
        }
    }
    match (off, on || side.is_some()) {
        (true, false) => Some(Record::CutterComp(CutterComp::Off)),
        (false, true) => Some(Record::CutterComp(CutterComp::On { side, register })),
        _ => {
            st.bad(
                diags,
                st.rest_col,
                "CUTCOM: expected LEFT, RIGHT, ON or OFF: no compensation".into(),
            );
            None
        }
    }
}

/// A `$$` comment that states something the post needs: Creo's `$$-> CUTCOM_GEOMETRY_TYPE /
/// OUTPUT_ON_CENTER` (the path is the tool centre) or `OUTPUT_ON_PROFILE` (the contour).
pub(in crate::cl) fn comment_record(comment: &str) -> Option<Record> {
    let rest = comment.trim_start().strip_prefix("->")?.trim_start();
    let (key, value) = rest.split_once('/')?;
    if !key.trim().eq_ignore_ascii_case("CUTCOM_GEOMETRY_TYPE") {
        return None;
    }
    let value = value.trim().to_ascii_uppercase();
    let centre = match value.as_str() {
        "OUTPUT_ON_CENTER" => true,
        "OUTPUT_ON_PROFILE" => false,
        _ => return None,
    };
    Some(Record::PathMeaning {
        centre,
        said: format!("CUTCOM_GEOMETRY_TYPE / {value}"),
    })
}

/// `OPSKIP/ON|OFF` (a bare `OPSKIP` turns it on).
pub(in crate::cl) fn block_skip(st: &Stmt, diags: &mut Vec<Diagnostic>) -> Option<Record> {
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
pub(in crate::cl) fn preselect(st: &Stmt, diags: &mut Vec<Diagnostic>) -> Option<Record> {
    let Some(a) = st.args.first() else {
        st.bad(diags, st.rest_col, "SELCTL: expected a tool number".into());
        return None;
    };
    preselected(st, a, diags)
}

/// The most an `INTOL`/`OUTTOL` may say (CL units): a band wider than this is no tolerance.
const MAX_TOLERANCE: f64 = 10.0;

/// `INTOL/t` or `OUTTOL/t`: a tolerance of 0 up to [`MAX_TOLERANCE`].
pub(in crate::cl) fn tolerance(st: &Stmt, diags: &mut Vec<Diagnostic>) -> Option<Record> {
    let Some(a) = st.args.first() else {
        st.bad(diags, st.rest_col, format!("{}: expected a tolerance", st.major));
        return None;
    };
    match a.text.trim().parse::<f64>() {
        Ok(v) if (0.0..=MAX_TOLERANCE).contains(&v) => Some(Record::Tolerance { outer: st.major == "OUTTOL", value: v }),
        _ => {
            let msg = format!("{}: expected a tolerance of 0 to {MAX_TOLERANCE}, found {:?}", st.major, a.text.trim());
            st.bad(diags, a.col, msg);
            None
        }
    }
}

/// The tool `SELCTL` or `SELECT/TOOL` readies, from its argument.
fn preselected(st: &Stmt, a: &Arg, diags: &mut Vec<Diagnostic>) -> Option<Record> {
    match a.text.trim().trim_end_matches('.').parse::<u32>() {
        Ok(n) => Some(Record::Preselect(n)),
        Err(_) => {
            let msg = format!("{}: expected a tool number, found {:?}", st.major, a.text.trim());
            st.bad(diags, a.col, msg);
            None
        }
    }
}

/// `AUXFUN/n` and `PREFUN/n`: a code number (`5.1` for G) the control is to get as it is.
pub(in crate::cl) fn function(st: &Stmt, diags: &mut Vec<Diagnostic>) -> Option<Record> {
    let letter = if st.major == "AUXFUN" { 'M' } else { 'G' };
    let Some(a) = st.args.first() else {
        st.bad(diags, st.rest_col, format!("{}: expected a code number", st.major));
        return None;
    };
    let code = a.text.trim().trim_end_matches('.');
    let (whole, frac) = code.split_once('.').unwrap_or((code, ""));
    let digits = |s: &str, most: usize| s.len() <= most && s.bytes().all(|b| b.is_ascii_digit());
    if whole.is_empty() || !digits(whole, 3) || !digits(frac, 1) {
        st.bad(
            diags,
            a.col,
            format!("{}: expected a code number (up to 3 digits), found {code:?}", st.major),
        );
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
pub(in crate::cl) fn select(st: &Stmt, diags: &mut Vec<Diagnostic>) -> Option<Record> {
    match (st.args.first().map(Arg::word).as_deref(), st.args.get(1)) {
        (Some("TOOL"), Some(a)) => preselected(st, a, diags),
        _ => {
            st.bad(diags, st.rest_col, "SELECT: expected TOOL and a tool number".into());
            None
        }
    }
}

/// An operator's instruction on a stop: CATIA writes it in parentheses, which an NC comment
/// cannot hold.
pub(in crate::cl) fn stop_text(rest: &str) -> String {
    let t = rest.trim();
    let t = t.strip_prefix('(').and_then(|t| t.strip_suffix(')')).unwrap_or(t);
    t.trim().to_string()
}

/// `MODE/TURN|LATHE` says the moves are a lathe's, `MODE/MILL` a mill's; other modes (a
/// listing's) are informational.
pub(in crate::cl) fn mode(st: &Stmt) -> Option<Record> {
    match st.args.first().map(Arg::word).as_deref() {
        Some("TURN" | "LATHE") => Some(Record::Mode { turning: true }),
        Some("MILL") => Some(Record::Mode { turning: false }),
        _ => Some(Record::Ignored("MODE".into())),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cl::parse_statement;

    fn comp(s: &str) -> Result<CutterComp, Vec<Diagnostic>> {
        let mut d = Vec::new();
        match parse_statement(s, 1, &mut d) {
            Some(Record::CutterComp(c)) if d.is_empty() => Ok(c),
            _ => Err(d),
        }
    }

    #[test]
    fn cutcom_in_the_forms_cam_systems_write() {
        let on = |side, register| Ok(CutterComp::On { side, register });
        let (l, r) = (Some(Side::Left), Some(Side::Right));
        for (s, want) in [
            ("CUTCOM/LEFT", on(l, None)),
            ("CUTCOM/ LEFT ", on(l, None)),
            ("CUTCOM/RIGHT", on(r, None)),
            ("CUTCOM/LEFT,XYPLAN", on(l, None)),
            ("CUTCOM/RIGHT,XYPLAN,5", on(r, Some(5))),
            ("CUTCOM/LEFT,12", on(l, Some(12))),
            ("CUTCOM/ADJUST,3,LEFT", on(l, Some(3))),
            ("CUTCOM/ ON ", on(None, None)),
            ("CUTCOM/OFF", Ok(CutterComp::Off)),
            ("CUTCOM/ OFF ", Ok(CutterComp::Off)),
            ("CUTCOM/NOMORE", Ok(CutterComp::Off)),
        ] {
            assert_eq!(comp(s), want, "{s}");
        }
        // What cannot be read is an error, never a guessed side or register.
        for s in [
            "CUTCOM/YZPLAN,LEFT",
            "CUTCOM/SIDE",
            "CUTCOM/",
            "CUTCOM/LEFT,0",
            "CUTCOM/LEFT,2.5",
            "CUTCOM/LEFT,OFF",
            "CUTCOM/LEFT,1,2",
        ] {
            let e = comp(s).expect_err(s);
            assert!(e.iter().any(|d| d.code == crate::diag::Code::BadRecord), "{s}: {e:?}");
        }
    }

    #[test]
    fn creo_says_what_its_path_is_in_a_comment() {
        let rec = |c: &str| comment_record(c);
        assert_eq!(
            rec("-> CUTCOM_GEOMETRY_TYPE / OUTPUT_ON_CENTER"),
            Some(Record::PathMeaning {
                centre: true,
                said: "CUTCOM_GEOMETRY_TYPE / OUTPUT_ON_CENTER".into()
            })
        );
        assert!(matches!(
            rec("->cutcom_geometry_type/output_on_profile"),
            Some(Record::PathMeaning { centre: false, .. })
        ));
        for c in [
            "-> CUTTER / 3.000000",
            " CUTCOM_GEOMETRY_TYPE / OUTPUT_ON_CENTER",
            "-> CUTCOM_GEOMETRY_TYPE / SOMETHING",
        ] {
            assert_eq!(rec(c), None, "{c}");
        }
    }

    /// `INTOL`/`OUTTOL` read (`outer` for OUTTOL); a tolerance that is no number, negative or
    /// wider than any is an error at its line, never a guessed band.
    #[test]
    fn intol_and_outtol_or_an_error() {
        let read = |s: &str| {
            let mut d = Vec::new();
            (parse_statement(s, 4, &mut d), d)
        };
        assert_eq!(read("INTOL/0.005").0, Some(Record::Tolerance { outer: false, value: 0.005 }));
        assert_eq!(read("OUTTOL/ 0.1 ").0, Some(Record::Tolerance { outer: true, value: 0.1 }));
        for s in ["INTOL/", "INTOL/FINE", "OUTTOL/-0.01", "OUTTOL/1e9", "INTOL/NaN"] {
            let (r, d) = read(s);
            assert!(r.is_none() && d.len() == 1 && d[0].line == Some(4), "{s}: {r:?} {d:?}");
        }
    }
}
