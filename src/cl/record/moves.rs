//! Records that shape a move without being one: Fusion's arc `MOVARC`, and the clearance plane
//! (`CLEARP`, `CLRSRF`) a `RETRCT` withdraws the tool to.

use super::{Arg, Record, Stmt, num};
use crate::diag::Diagnostic;

/// A plane `normal · p = offset` in the CL's frame and units (`normal` a unit vector).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Plane {
    pub normal: [f64; 3],
    pub offset: f64,
}

/// `MOVARC/xc,yc,zc,i,j,k,r,ANGLE,a`: the next GOTO ends an arc about this centre and axis,
/// sweeping `a` degrees. Autodesk's ISO 4343 post turns counter-clockwise about the axis (it
/// negates the axis of a clockwise arc); the sweep lets the source tell an older post's arc,
/// which did not, and say so.
pub(in crate::cl) fn movarc(st: &Stmt, diags: &mut Vec<Diagnostic>) -> Option<Record> {
    let mut v = Vec::with_capacity(7);
    let mut sweep = None;
    let mut args = st.args.iter();
    while let Some(a) = args.next() {
        match (num(a.text).filter(|x| x.is_finite()), a.word().as_str()) {
            (Some(x), _) if v.len() < 7 => v.push(x),
            (None, "ANGLE") => sweep = args.next().and_then(|b| num(b.text)).filter(|x| x.is_finite() && *x > 0.0),
            _ => {
                st.bad(diags, a.col, format!("MOVARC: expected a number or ANGLE, found {:?}: taken as a straight move", a.text.trim()));
                return None;
            }
        }
    }
    if v.len() < 7 || sweep.is_none() {
        let msg = "MOVARC: expected centre, axis, radius, ANGLE and the sweep in degrees: taken as a straight move";
        st.bad(diags, st.rest_col, msg.into());
        return None;
    }
    Some(Record::Circle {
        center: [v[0], v[1], v[2]],
        axis: [v[3], v[4], v[5]],
        radius: Some(v[6]),
        clockwise: false,
        turns: 1,
        sweep_deg: sweep,
    })
}

/// `CLEARP` / `CLRSRF`: `d` or `XYPLAN,d` (the plane z = d), `YZPLAN,d`, `ZXPLAN,d`, `a,b,c,d`
/// (the plane ax + by + cz = d), or `OFF` / `NOMORE` (none).
pub(in crate::cl) fn clearance(st: &Stmt, diags: &mut Vec<Diagnostic>) -> Option<Record> {
    let first = st.args.first().map(Arg::word).unwrap_or_default();
    if matches!(first.as_str(), "OFF" | "NOMORE") {
        return Some(Record::Clearance(None));
    }
    let along = match first.as_str() {
        "XYPLAN" => Some([0.0, 0.0, 1.0]),
        "YZPLAN" => Some([1.0, 0.0, 0.0]),
        "ZXPLAN" => Some([0.0, 1.0, 0.0]),
        _ => None,
    };
    let nums: Option<Vec<f64>> = st.args[usize::from(along.is_some())..]
        .iter()
        .map(|a| num(a.text).filter(|x| x.is_finite()))
        .collect();
    let plane = match (along, nums.as_deref()) {
        (_, Some([d])) => Some(Plane {
            normal: along.unwrap_or([0.0, 0.0, 1.0]),
            offset: *d,
        }),
        (None, Some([a, b, c, d])) => unit_plane([*a, *b, *c], *d),
        _ => None,
    };
    match plane {
        Some(p) => Some(Record::Clearance(Some(p))),
        None => {
            let msg = format!(
                "{}: expected d, XYPLAN|YZPLAN|ZXPLAN,d, a,b,c,d or OFF: the clearance in force stays",
                st.major
            );
            st.bad(diags, st.rest_col, msg);
            None
        }
    }
}

/// `ax + by + cz = d` with (a, b, c) made a unit normal; none if it is zero.
fn unit_plane(n: [f64; 3], d: f64) -> Option<Plane> {
    let len = n.iter().map(|c| c * c).sum::<f64>().sqrt();
    (len > 1e-9).then(|| Plane {
        normal: n.map(|c| c / len),
        offset: d / len,
    })
}

/// `RETRCT` (or `RETRCT/ON`): withdraw along the tool axis to the clearance plane; `RETRCT/OFF`
/// asks for nothing.
pub(in crate::cl) fn retract(st: &Stmt, diags: &mut Vec<Diagnostic>) -> Option<Record> {
    match st.args.first().map(Arg::word).as_deref() {
        None | Some("ON") => Some(Record::Retract),
        Some("OFF") => Some(Record::Ignored(st.major.clone())),
        Some(other) => {
            st.bad(diags, st.args[0].col, format!("RETRCT: expected ON or OFF, found {other:?}: no retract"));
            None
        }
    }
}
