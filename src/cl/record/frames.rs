//! Coordinate-system records: the frame the CL's following points and tool axes are written in.

use super::{Record, Stmt, num};
use crate::diag::Diagnostic;

/// How far from unit length and from square an MCS's axes may be (NX writes seven decimals).
const SQUARE: f64 = 1e-4;

/// NX's `MSYS/x,y,z,xi,xj,xk,yi,yj,yk`: the operation's machine coordinate system, its origin
/// and X and Y axes in NX's absolute frame. The GOTOs after it are in this MCS.
pub(in crate::cl) fn msys(st: &Stmt, diags: &mut Vec<Diagnostic>) -> Option<Record> {
    let mut v = Vec::with_capacity(9);
    for a in &st.args {
        match num(a.text).filter(|x| x.is_finite()) {
            Some(x) => v.push(x),
            None => {
                st.bad(diags, a.col, format!("MSYS: expected a number, found {:?}: not applied", a.text.trim()));
                return None;
            }
        }
    }
    if v.len() != 9 {
        let msg = format!("MSYS: expected origin, X axis and Y axis (9 values), found {}: not applied", v.len());
        st.bad(diags, st.rest_col, msg);
        return None;
    }
    // An origin of 1e300 put every point of the operation beyond any bound the engine holds.
    if !v[..3].iter().all(|c| crate::kinematics::coordinate_ok(*c)) {
        let msg = format!("MSYS: its origin must be within ±{:e}: not applied", crate::kinematics::MAX_COORD);
        st.bad(diags, st.args[0].col, msg);
        return None;
    }
    let (x, y) = ([v[3], v[4], v[5]], [v[6], v[7], v[8]]);
    let norm = |a: [f64; 3]| a.iter().map(|c| c * c).sum::<f64>().sqrt();
    let dot: f64 = x.iter().zip(&y).map(|(a, b)| a * b).sum();
    if (norm(x) - 1.0).abs() > SQUARE || (norm(y) - 1.0).abs() > SQUARE || dot.abs() > SQUARE {
        let msg = "MSYS: its X and Y axes are not unit vectors at right angles: not applied".into();
        st.bad(diags, st.args[3].col, msg);
        return None;
    }
    Some(Record::Mcs {
        origin: [v[0], v[1], v[2]],
        x,
        y,
    })
}
