//! APT motion statements that carry their source geometry, as CATIA V5 writes them:
//! `INDIRV/i,j,k` (or `INDIRP/x,y,z`), then
//! `TLON,GOFWD/(CIRCLE/x,y,z,r),ON,(LINE/x1,y1,z1,x2,y2,z2)` over several `$` lines. The
//! statement says which curve the tool follows (the drive), which way, and where it stops (the
//! check): the source resolves it into an arc from the current point. What names a surface
//! defined elsewhere, or a form not read here, is an error at its line: the motion is missing,
//! never a straight move in its place.

use super::{Stmt, num};
use crate::diag::{Code, Diagnostic, Severity};

/// Where the tool stands against the drive curve (`TLON`, `TLLFT`, `TLRGT`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ToolSide {
    On,
    Left,
    Right,
}

/// Which way the tool goes from the direction it came in (`GOFWD`, `GOBACK`, `GOLFT`, `GORGT`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Go {
    Fwd,
    Back,
    Left,
    Right,
}

/// Where on the check surface the motion stops (`ON`, `TO`, `PAST`, `TANTO`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stop {
    On,
    To,
    Past,
    Tanto,
}

/// Geometry written in the statement (CL units).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Geometry {
    /// `CIRCLE/x,y,z,r` (about z) or `CIRCLE/x,y,z,i,j,k,r`.
    Circle { center: [f64; 3], axis: [f64; 3], radius: f64 },
    /// `LINE/x1,y1,z1,x2,y2,z2` (or `x1,y1,x2,y2`): as APT reads it, the plane through the line
    /// along the tool axis.
    Line { a: [f64; 3], b: [f64; 3] },
    /// `PLANE/a,b,c,d`: a·x + b·y + c·z = d, the normal unit.
    Plane { normal: [f64; 3], d: f64 },
}

/// One drive statement.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Drive {
    /// The statement's motion word (for messages).
    pub word: &'static str,
    pub side: ToolSide,
    pub go: Go,
    pub drive: Geometry,
    pub stop: Stop,
    pub check: Geometry,
}

/// The motion words of a drive statement's major (`TLON,GOFWD`): the side and the direction,
/// `None` when it is no drive statement.
pub(in crate::cl) fn drive_major(major: &str) -> Option<(ToolSide, Go, &'static str)> {
    let (mut side, mut go) = (ToolSide::On, None);
    for w in major.split(',').map(str::trim) {
        match w {
            "TLON" => side = ToolSide::On,
            "TLLFT" => side = ToolSide::Left,
            "TLRGT" => side = ToolSide::Right,
            "GOFWD" => go = Some((Go::Fwd, "GOFWD")),
            "GOBACK" => go = Some((Go::Back, "GOBACK")),
            "GOLFT" => go = Some((Go::Left, "GOLFT")),
            "GORGT" => go = Some((Go::Right, "GORGT")),
            _ => return None,
        }
    }
    go.map(|(g, w)| (side, g, w))
}

/// `TLON,GOFWD/(CIRCLE/…),ON,(LINE/…)`: the drive, the stop and the check, each as written.
pub(in crate::cl) fn drive(
    st: &Stmt,
    side: ToolSide,
    go: Go,
    word: &'static str,
    diags: &mut Vec<Diagnostic>,
) -> Option<super::Record> {
    let bad = |diags: &mut Vec<Diagnostic>, why: String| {
        let msg = format!("{word}: {why}: the motion is not written");
        diags.push(Diagnostic::new(Code::BadRecord, Severity::Error, Some(st.line), msg).at(st.rest_col));
    };
    let parts = top_level(st.rest);
    let [d, m, c] = parts.as_slice() else {
        bad(
            diags,
            format!(
                "expected (drive curve), ON|TO|PAST|TANTO, (check surface), found {} parts",
                parts.len()
            ),
        );
        return None;
    };
    let stop = match m.to_ascii_uppercase().as_str() {
        "ON" => Stop::On,
        "TO" => Stop::To,
        "PAST" => Stop::Past,
        "TANTO" => Stop::Tanto,
        other => {
            bad(diags, format!("{other:?} is no stop kinepost reads (ON, TO, PAST, TANTO)"));
            return None;
        }
    };
    let drive = match geometry(d) {
        Ok(g @ (Geometry::Circle { .. } | Geometry::Line { .. })) => g,
        Ok(_) => {
            bad(diags, "the tool follows a CIRCLE or a LINE, not a PLANE".into());
            return None;
        }
        Err(why) => {
            bad(diags, why);
            return None;
        }
    };
    match geometry(c) {
        Ok(check) => Some(super::Record::Drive(Drive {
            word,
            side,
            go,
            drive,
            stop,
            check,
        })),
        Err(why) => {
            bad(diags, why);
            None
        }
    }
}

/// `INDIRV/i,j,k` (a direction) or `INDIRP/x,y,z` (towards a point): which way the next drive
/// statement goes.
pub(in crate::cl) fn indir(st: &Stmt, diags: &mut Vec<Diagnostic>) -> Option<super::Record> {
    let v: Vec<f64> = st.args.iter().filter_map(|a| num(a.text)).filter(|x| x.is_finite()).collect();
    let point = st.major == "INDIRP";
    if v.len() != 3 || st.args.len() != 3 || !point && v.iter().all(|x| *x == 0.0) {
        let what = if point {
            "a point x,y,z"
        } else {
            "a direction i,j,k, not zero"
        };
        st.bad(diags, st.rest_col, format!("{}: expected {what}", st.major));
        return None;
    }
    Some(super::Record::InDir {
        v: [v[0], v[1], v[2]],
        point,
    })
}

/// The statement's parts at the top level: commas inside parentheses belong to their geometry.
fn top_level(rest: &str) -> Vec<&str> {
    let mut out = Vec::new();
    let (mut depth, mut start) = (0i32, 0);
    for (i, ch) in rest.char_indices() {
        match ch {
            '(' => depth += 1,
            ')' => depth -= 1,
            ',' if depth == 0 => {
                out.push(rest[start..i].trim());
                start = i + 1;
            }
            _ => {}
        }
    }
    out.push(rest[start..].trim());
    out
}

/// `(CIRCLE/…)`, `(LINE/…)` or `(PLANE/…)` as written; a name (a surface defined elsewhere)
/// cannot be resolved here.
fn geometry(text: &str) -> Result<Geometry, String> {
    let Some(inner) = text.strip_prefix('(').and_then(|t| t.strip_suffix(')')) else {
        return Err(format!(
            "{} names a surface defined elsewhere: kinepost reads geometry written in the statement, (CIRCLE/…), (LINE/…), (PLANE/…)",
            crate::text::quote(text)
        ));
    };
    let Some((kind, values)) = inner.split_once('/') else {
        return Err(format!("{} is no CIRCLE, LINE or PLANE", crate::text::quote(inner)));
    };
    let kind = kind.trim().to_ascii_uppercase();
    let v: Option<Vec<f64>> = values.split(',').map(|a| num(a).filter(|x| x.is_finite())).collect();
    let Some(v) = v else {
        return Err(format!("{kind}: expected numbers, found {}", crate::text::quote(values)));
    };
    let unit = |a: [f64; 3]| {
        let n = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
        (n > 1e-12).then(|| a.map(|x| x / n))
    };
    match (kind.as_str(), v.len()) {
        ("CIRCLE", 4 | 7) => {
            let (axis, radius) = if v.len() == 4 {
                (Some([0.0, 0.0, 1.0]), v[3])
            } else {
                (unit([v[3], v[4], v[5]]), v[6])
            };
            match axis {
                Some(axis) if radius > 0.0 => Ok(Geometry::Circle {
                    center: [v[0], v[1], v[2]],
                    axis,
                    radius,
                }),
                _ => Err("CIRCLE: its axis is zero or its radius not positive".into()),
            }
        }
        ("LINE", 4 | 6) => {
            let (a, b) = if v.len() == 4 {
                ([v[0], v[1], 0.0], [v[2], v[3], 0.0])
            } else {
                ([v[0], v[1], v[2]], [v[3], v[4], v[5]])
            };
            if a == b {
                return Err("LINE: its two points are one".into());
            }
            Ok(Geometry::Line { a, b })
        }
        ("PLANE", 4) => match unit([v[0], v[1], v[2]]) {
            Some(normal) => {
                let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
                Ok(Geometry::Plane { normal, d: v[3] / n })
            }
            None => Err("PLANE: its normal is zero".into()),
        },
        (k @ ("CIRCLE" | "LINE" | "PLANE"), n) => Err(format!("{k} with {n} values is a form kinepost does not read")),
        (k, _) => Err(format!("{k} is no curve or surface kinepost reads (CIRCLE, LINE, PLANE)")),
    }
}
