//! What inverse kinematics reads of a machine's chain, derived once when the machine is built.
//!
//! The tool axis seen from W is `Rot(s1, α1) · … · Rot(sn, αn) · z` over the "orientation
//! sequence": table rotaries from the workpiece inward (axis negated, since W sees the table turn
//! backwards), then head rotaries from the ram outward. Its first element is the outermost.

use super::{Linear, Mount, Rotary};
use crate::kinematics::Vec3;
use crate::kinematics::subproblem::{Cs, Pair};
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

/// Terms of the multilinear form: (1, cos, sin) of each rotary, in sequence order.
pub(crate) const TERMS: usize = 27;

/// The missing linear's coordinate as a form in the rotaries' (1, cos, sin), the outer first:
/// the chain turns the tip and the tool's pivots once per rotary, affinely in its (cos, sin), so
/// the coordinate is multilinear in the three pairs, and its terms are linear in the tip and the
/// tool length. Built with the chain; a pose's terms are five products each, and evaluating them
/// costs a few dozen products where turning the chain costs three rotations.
#[derive(Clone, Debug)]
pub(crate) struct Form {
    /// The terms' parts proportional to the tip's x, y, z and to the tool length, and the rest.
    parts: [[f64; TERMS]; 5],
}

impl Form {
    pub(crate) fn new(links: &[Link], seq: &[usize], missing: usize) -> Form {
        // The tip's and the tool length's parts come from the chain turned about its axes through
        // the origin (their rotations alone), the rest from the chain as built: no part is the
        // difference of large values.
        let bare: ArrayVec<Link, 3> = links.iter().map(|l| Link { pivot: [0.0; 3], ..*l }).collect();
        let mut parts = [[0.0; TERMS]; 5];
        for (input, part) in parts.iter_mut().enumerate() {
            let mut p = Vec3::zeros();
            if input < 3 {
                p[input] = 1.0;
            }
            let (chain, tool_length) = match input {
                0..=2 => (&bare[..], 0.0),
                3 => (&bare[..], 1.0),
                _ => (links, 0.0),
            };
            // Values at (cos, sin) = (0, 0), (1, 0), (0, 1) of each rotary ...
            const AT: [Cs; 3] = [Cs { c: 0.0, s: 0.0 }, Cs { c: 1.0, s: 0.0 }, Cs { c: 0.0, s: 1.0 }];
            for (t, value) in part.iter_mut().enumerate() {
                let mut cs = [Cs::ZERO; 3];
                for (k, &ri) in seq.iter().enumerate() {
                    cs[ri] = AT[t / 3usize.pow(2 - k as u32) % 3];
                }
                *value = controlled_point_cs(chain, &cs, &p, tool_length)[missing];
            }
            // ... to the coefficients of (1, cos, sin): less the value at (0, 0), factor by factor.
            for k in 0..3 {
                let stride = 3usize.pow(2 - k as u32);
                for t in (0..TERMS).filter(|t| t / stride % 3 == 0) {
                    part[t + stride] -= part[t];
                    part[t + 2 * stride] -= part[t];
                }
            }
        }
        Form { parts }
    }

    /// The terms at the tip `p_w` (work offset added) and the tool length.
    pub(crate) fn at(&self, p_w: &Vec3, tool_length: f64) -> [f64; TERMS] {
        let [x, y, z, l, one] = &self.parts;
        std::array::from_fn(|t| x[t] * p_w.x + y[t] * p_w.y + z[t] * p_w.z + l[t] * tool_length + one[t])
    }
}

/// `T(φ)(p) − head offset(θ)` from (cos, sin) pairs: the same composition as `fk`, in plain
/// scalars (the hot path of every solution; nalgebra's generic ops cost 3× the instructions here).
/// Always inlined: called, it read back a `tip + offset` just stored as halves with one wide load
/// (a store-forwarding stall: 17% of this function's samples, itself 8% of a joint-mode run).
#[inline(always)]
pub(crate) fn controlled_point_cs(links: &[Link], cs: &[Cs; 3], p_w: &Vec3, tool_length: f64) -> Vec3 {
    #[inline(always)]
    fn turn(k: &[f64; 3], o: &[f64; 3], c: f64, s: f64, p: [f64; 3]) -> [f64; 3] {
        let v = [p[0] - o[0], p[1] - o[1], p[2] - o[2]];
        let d = (k[0] * v[0] + k[1] * v[1] + k[2] * v[2]) * (1.0 - c);
        [
            o[0] + v[0] * c + (k[1] * v[2] - k[2] * v[1]) * s + k[0] * d,
            o[1] + v[1] * c + (k[2] * v[0] - k[0] * v[2]) * s + k[1] * d,
            o[2] + v[2] * c + (k[0] * v[1] - k[1] * v[0]) * s + k[2] * d,
        ]
    }
    let mut v = [0.0; 3];
    let mut p = [p_w.x, p_w.y, p_w.z];
    for i in (0..links.len()).rev() {
        let (l, a) = (&links[i], cs[i]);
        if l.head {
            let q = [l.pivot[0], l.pivot[1], l.pivot[2] + tool_length];
            v = turn(&l.axis, &q, a.c, a.s, v);
        } else {
            p = turn(&l.axis, &l.pivot, a.c, a.s, p);
        }
    }
    Vec3::new(p[0] - v[0], p[1] - v[1], p[2] - v[2])
}
