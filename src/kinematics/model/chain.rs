//! What inverse kinematics reads of a machine's chain, derived once when the machine is built.
//!
//! The tool axis seen from W is `Rot(s1, α1) · … · Rot(sn, αn) · z` over the "orientation
//! sequence": table rotaries from the workpiece inward (axis negated, since W sees the table turn
//! backwards), then head rotaries from the ram outward. Its first element is the outermost.

use super::{Linear, Mount, Rotary};
use crate::kinematics::Vec3;
use crate::kinematics::subproblem::Pair;
use crate::kinematics::three::Form;
use arrayvec::ArrayVec;

#[derive(Clone, Debug)]
pub(crate) struct Chain {
    /// Rotary index (chain order) of each element of the orientation sequence.
    pub(crate) seq: ArrayVec<usize, 3>,
    pub(crate) shape: Shape,
    /// The rotaries in chain order, compact: what placing the linears reads per solution.
    pub(crate) links: ArrayVec<Link, 3>,
    pub(crate) has_linear: [bool; 3],
}

#[derive(Clone, Copy, Debug)]
pub(crate) struct Link {
    pub(crate) axis: [f64; 3],
    pub(crate) pivot: [f64; 3],
    pub(crate) head: bool,
    /// Has angle-error compensation (words differ from actual angles).
    pub(crate) compensated: bool,
}

#[derive(Clone, Debug)]
pub(crate) enum Shape {
    /// No rotary: the tool stays along z.
    Fixed,
    /// One rotary about `s`.
    One { s: Vec3 },
    /// Two rotaries: subproblem 2.
    Two(Pair),
    /// Three rotaries, one linear missing: the outer angle is found by a 1-D root search on the
    /// missing linear's coordinate, the inner two by subproblem 2.
    Three { s0: Vec3, pair: Pair, missing: usize, form: Box<Form> },
}

impl Chain {
    /// The error says why the chain cannot orient or place the tool.
    pub(crate) fn new(linears: &[Option<Linear>; 3], rotaries: &[Rotary]) -> Result<Chain, String> {
        let mut seq: ArrayVec<usize, 3> = ArrayVec::new();
        for i in (0..rotaries.len()).rev() {
            if rotaries[i].mount == Mount::Table {
                seq.push(i);
            }
        }
        for (i, r) in rotaries.iter().enumerate() {
            if r.mount == Mount::Head {
                seq.push(i);
            }
        }
        let s = |k: usize| {
            let r = &rotaries[seq[k]];
            if r.mount == Mount::Table { -r.axis } else { r.axis }
        };
        let nlin = linears.iter().filter(|l| l.is_some()).count();
        let missing: Vec<usize> = (0..3).filter(|&i| linears[i].is_none()).collect();
        let pair = |a: usize, b: usize| {
            Pair::new(s(a), s(b)).ok_or_else(|| {
                format!(
                    "rotaries {} and {} are parallel: the pair cannot orient the tool",
                    rotaries[seq[a]].name, rotaries[seq[b]].name
                )
            })
        };
        let inner_ok = |k: usize| {
            if s(k).cross(&Vec3::z()).norm() < 1e-6 {
                Err(format!(
                    "rotary {} is the innermost of the orientation chain and lies along the tool (z): it cannot change the tool orientation",
                    rotaries[seq[k]].name
                ))
            } else {
                Ok(())
            }
        };
        let links = rotaries
            .iter()
            .map(|r| Link {
                axis: r.axis.into(),
                pivot: r.pivot.into(),
                head: r.mount == Mount::Head,
                compensated: r.angle_error.is_some(),
            })
            .collect::<ArrayVec<Link, 3>>();
        let shape = match (rotaries.len(), nlin) {
            (0, 3) => Shape::Fixed,
            (1, 3) => Shape::One { s: s(0) },
            (2, 3) => {
                inner_ok(1)?;
                Shape::Two(pair(0, 1)?)
            }
            (3, 2) => {
                inner_ok(2)?;
                Shape::Three {
                    s0: s(0),
                    pair: pair(1, 2)?,
                    missing: missing[0],
                    form: Box::new(Form::new(&links, &seq, missing[0])),
                }
            }
            (3, 3) => return Err("three rotaries with three linears are redundant: not supported".into()),
            (n, l) => {
                return Err(format!(
                    "{n} rotaries with {l} linears cannot place an arbitrary tool pose: supported chains are 3 linears with 0 to 2 rotaries, or 2 linears with 3 rotaries"
                ));
            }
        };
        Ok(Chain {
            seq,
            shape,
            links,
            has_linear: [linears[0].is_some(), linears[1].is_some(), linears[2].is_some()],
        })
    }
}
