//! Solution planning over a whole cut: which IK branch and which 360° winding of every bounded
//! rotary each point takes, so that blocks stay within limits, branches do not change mid-cut when
//! a continuous solution exists, rotary travel is least, and bounded axes unwind only when they
//! must.
//!
//! A Viterbi pass over the candidates of each point, with a bounded window: when the window holds
//! `WINDOW` points, the first half is committed along the best path and the rest is re-rooted on
//! what was committed. Memory is O(WINDOW · candidates), whatever the file's length.

use super::source::{MotionPt, ProgEvent};
use crate::kinematics::{IkOptions, Joints, Machine, Setup, Solution, Solutions, Vec3, angle_between, fk, ik_into};
use arrayvec::ArrayVec;
use std::collections::VecDeque;

pub const WINDOW: usize = 512;
pub const MAX_CANDS: usize = 8;
/// Cost (in degrees of rotary travel) of leaving a branch in the middle of a cut: it takes a
/// retract, a reposition and a re-approach.
const BRANCH_PENALTY: f64 = 3600.0;
/// Cost of unwinding a bounded rotary (same sequence as a branch change).
const UNWIND_PENALTY: f64 = 3600.0;
/// Cost of a candidate outside travel: taken only when nothing else exists.
const INFEASIBLE: f64 = 1e9;

#[derive(Clone, Copy, Debug)]
pub struct Cand {
    pub sol: Solution,
    pub feasible: bool,
    /// The CL tool axis of the point (for judging a move across the fold between branches).
    pub axis: Vec3,
}

/// Largest deviation (radians) of the joint-space midpoint's tool axis from the CL great circle
/// for a move across the fold between two IK branches still to count as continuous.
pub const FOLD_TOLERANCE: f64 = 0.0175;

/// Whether the joint-space move between two branch-labelled solutions is continuous: the branches
/// of a two-rotary chain meet on a fold (B = 0 on a B/C table), and a path passing near it crosses
/// from one to the other with small rotary steps. A true branch jump swings the tool far off the
/// CL orientation halfway.
pub fn crosses_fold(m: &Machine, ja: &[f64; 3], jb: &[f64; 3], ua: &Vec3, ub: &Vec3) -> bool {
    let mut mid = Joints::default();
    for (i, r) in m.rotaries.iter().enumerate() {
        let d = jb[i] - ja[i];
        mid.rotary[i] = ja[i] + 0.5 * if r.limits.is_none() { wrap(d) } else { d };
    }
    let axis = fk(m, &mid, &Setup::new(0.0, Vec3::zeros())).axis;
    let s = ua + ub;
    let want = if s.norm() < 1e-9 { *ua } else { s.normalize() };
    angle_between(&axis, &want) <= FOLD_TOLERANCE
}

pub struct Column {
    pub pt: MotionPt,
    pub cands: ArrayVec<Cand, MAX_CANDS>,
    cost: [f64; MAX_CANDS],
    back: [u8; MAX_CANDS],
    /// IK failed: the point is reported and skipped, and the chain restarts after it.
    pub error: Option<crate::kinematics::Error>,
}

// Points are the common case: boxing them would allocate once per CL point.
#[allow(clippy::large_enum_variant)]
pub enum Slot {
    Event(ProgEvent),
    Point(Column),
}

/// A committed point: its column and the candidate chosen.
pub struct Committed {
    pub pt: MotionPt,
    pub cand: Option<Cand>,
    pub error: Option<crate::kinematics::Error>,
}

#[allow(clippy::large_enum_variant)]
pub enum Out {
    Event(ProgEvent),
    Point(Committed),
}

pub struct Planner<'m> {
    m: &'m Machine,
    pub setup: Setup,
    window: VecDeque<Slot>,
    points: usize,
    /// The last committed candidate: the root the window's costs start from.
    root: Option<Cand>,
    buf: Solutions,
    opt: IkOptions,
}

/// Rotary travel (degrees) between two candidates, and whether the move changes branch or
/// unwinds a bounded axis. Unbounded axes compare modulo a turn (the emitter picks the nearest
/// winding); the free axis of a singular candidate costs nothing (it keeps the previous angle).
fn transition(m: &Machine, a: &Cand, b: &Cand, rapid: bool) -> f64 {
    let mut travel = 0.0;
    let mut unwind = false;
    for (i, r) in m.rotaries.iter().enumerate() {
        if a.sol.singular == Some(i) || b.sol.singular == Some(i) {
            continue;
        }
        let d = b.sol.joints.rotary[i] - a.sol.joints.rotary[i];
        let d = if r.limits.is_none() { wrap(d) } else { d };
        if d.abs() > std::f64::consts::PI {
            unwind = true;
        }
        travel += d.abs();
    }
    let mut cost = travel.to_degrees();
    if !rapid {
        if a.sol.branch * b.sol.branch < 0 && !crosses_fold(m, &a.sol.joints.rotary, &b.sol.joints.rotary, &a.axis, &b.axis) {
            cost += BRANCH_PENALTY;
        }
        if unwind {
            cost += UNWIND_PENALTY;
        }
    }
    if !b.feasible {
        cost += INFEASIBLE;
    }
    cost
}

#[inline]
pub fn wrap(a: f64) -> f64 {
    use std::f64::consts::{PI, TAU};
    let r = (a + PI).rem_euclid(TAU) - PI;
    if r == -PI { PI } else { r }
}

/// Costs of `col` from its predecessor column, or from the committed root.
fn relax(m: &Machine, root: &Option<Cand>, prev: Option<&Column>, col: &mut Column) {
    let rapid = col.pt.rapid;
    for (b, cb) in col.cands.iter().enumerate() {
        let (mut best, mut arg) = (f64::INFINITY, 0u8);
        match prev {
            Some(p) => {
                for (a, ca) in p.cands.iter().enumerate() {
                    let c = p.cost[a] + transition(m, ca, cb, rapid);
                    if c < best {
                        (best, arg) = (c, a as u8);
                    }
                }
            }
            None => {
                best = match root {
                    Some(r) => transition(m, r, cb, rapid),
                    // First point of the program: prefer small angles, within travel.
                    None => {
                        cb.sol.joints.rotary.iter().map(|a| a.abs().to_degrees()).sum::<f64>() * 1e-3
                            + if cb.feasible { 0.0 } else { INFEASIBLE }
                    }
                };
            }
        }
        col.cost[b] = best;
        col.back[b] = arg;
    }
}

impl<'m> Planner<'m> {
    pub fn new(m: &'m Machine, setup: Setup) -> Planner<'m> {
        Planner {
            m,
            setup,
            window: VecDeque::new(),
            points: 0,
            root: None,
            buf: Solutions::new(),
            opt: IkOptions::default(),
        }
    }

    /// Candidates of one pose: every IK solution, and for bounded rotaries every winding within
    /// travel (unbounded ones stay in (−π, π]: the emitter winds them).
    fn candidates(&mut self, pt: &MotionPt) -> Result<ArrayVec<Cand, MAX_CANDS>, crate::kinematics::Error> {
        ik_into(self.m, &pt.pose, &self.setup, &self.opt, &mut self.buf)?;
        let mut out = ArrayVec::new();
        for s in self.buf.iter() {
            let lin_ok = crate::kinematics::limit_violation(
                self.m,
                &crate::kinematics::Joints {
                    rotary: [0.0; 3],
                    ..s.joints
                },
                1e-6,
            )
            .is_none();
            // Windings of bounded rotaries within travel.
            let mut variants: ArrayVec<Solution, MAX_CANDS> = ArrayVec::new();
            variants.push(*s);
            for (i, r) in self.m.rotaries.iter().enumerate() {
                if r.limits.is_none() || s.singular == Some(i) {
                    continue;
                }
                let mut next: ArrayVec<Solution, MAX_CANDS> = ArrayVec::new();
                for v in &variants {
                    let ws = r.windings(s.actual[i], s.actual[i]);
                    if ws.is_empty() {
                        let _ = next.try_push(*v); // out of travel: kept, marked infeasible below
                    }
                    for w in ws {
                        let mut v2 = *v;
                        v2.joints.rotary[i] = w;
                        let _ = next.try_push(v2);
                    }
                }
                variants = next;
            }
            for v in variants {
                let rot_ok = self
                    .m
                    .rotaries
                    .iter()
                    .enumerate()
                    .all(|(i, r)| s.singular == Some(i) || r.within(v.joints.rotary[i], 1e-9));
                if out
                    .try_push(Cand {
                        sol: v,
                        feasible: lin_ok && rot_ok,
                        axis: pt.pose.axis,
                    })
                    .is_err()
                {
                    break;
                }
            }
        }
        Ok(out)
    }

    pub fn push_event(&mut self, e: ProgEvent, out: &mut impl FnMut(Out)) {
        if self.window.is_empty() {
            out(Out::Event(e));
        } else {
            self.window.push_back(Slot::Event(e));
        }
    }

    pub fn push_point(&mut self, pt: MotionPt, out: &mut impl FnMut(Out)) {
        let (cands, error) = match self.candidates(&pt) {
            Ok(c) if !c.is_empty() => (c, None),
            Ok(_) => (
                ArrayVec::new(),
                Some(crate::kinematics::Error::NoSolution {
                    reason: "no solution".into(),
                }),
            ),
            Err(e) => (ArrayVec::new(), Some(e)),
        };
        let mut col = Column {
            pt,
            cands,
            cost: [f64::INFINITY; MAX_CANDS],
            back: [0; MAX_CANDS],
            error,
        };
        let prev = self.window.iter().rev().find_map(|s| match s {
            Slot::Point(c) if c.error.is_none() => Some(c),
            _ => None,
        });
        relax(self.m, &self.root, prev, &mut col);
        self.window.push_back(Slot::Point(col));
        self.points += 1;
        if self.points >= WINDOW {
            self.commit(WINDOW / 2, out);
        }
    }

    /// Commits the first `n` points (and the events among them) along the best path.
    fn commit(&mut self, n: usize, out: &mut impl FnMut(Out)) {
        // Trace the best path back through the window.
        let mut choice: Vec<Option<usize>> = vec![None; self.window.len()];
        let mut next: Option<usize> = None;
        for (i, slot) in self.window.iter().enumerate().rev() {
            if let Slot::Point(c) = slot {
                if c.error.is_some() || c.cands.is_empty() {
                    continue;
                }
                let pick = match next {
                    Some(b) => b,
                    None => (0..c.cands.len())
                        .min_by(|&x, &y| c.cost[x].total_cmp(&c.cost[y]))
                        .unwrap_or(0),
                };
                choice[i] = Some(pick);
                next = Some(c.back[pick] as usize);
            }
        }
        let mut committed = 0;
        let mut idx = 0;
        while committed < n {
            let Some(slot) = self.window.pop_front() else { break };
            match slot {
                Slot::Event(e) => out(Out::Event(e)),
                Slot::Point(c) => {
                    let cand = choice[idx].map(|k| c.cands[k]);
                    if cand.is_some() {
                        self.root = cand;
                    }
                    out(Out::Point(Committed {
                        pt: c.pt,
                        cand,
                        error: c.error,
                    }));
                    committed += 1;
                    self.points -= 1;
                }
            }
            idx += 1;
        }
        // Re-root the rest on what was committed.
        let slots = self.window.make_contiguous();
        let mut prev: Option<usize> = None;
        for i in 0..slots.len() {
            if !matches!(&slots[i], Slot::Point(c) if c.error.is_none()) {
                continue;
            }
            let (before, after) = slots.split_at_mut(i);
            let p = prev.and_then(|k| match &before[k] {
                Slot::Point(c) => Some(c),
                Slot::Event(_) => None,
            });
            if let Slot::Point(col) = &mut after[0] {
                relax(self.m, &self.root, p, col);
            }
            prev = Some(i);
        }
    }

    /// Commits everything (end of program).
    pub fn finish(&mut self, out: &mut impl FnMut(Out)) {
        let n = self.points;
        self.commit(n, out);
        while let Some(slot) = self.window.pop_front() {
            if let Slot::Event(e) = slot {
                out(Out::Event(e));
            }
        }
    }
}
