//! Solution planning over a whole cut: which IK branch and which 360° winding of every bounded
//! rotary each point takes, so that blocks stay within limits, branches do not change mid-cut when
//! a continuous solution exists, rotary travel is least, and bounded axes unwind only when they
//! must.
//!
//! A Viterbi pass over the candidates of each point, with a bounded window: when the window holds
//! `WINDOW` points, all but the last `KEEP` are committed along the best path and those are
//! re-rooted on what was committed. Memory is O(WINDOW · candidates), whatever the file's length.

use super::source::{MotionPt, ProgEvent};
use crate::kinematics::{IkOptions, Machine, Setup, Solution, Solutions, Vec3, ik_into, tool_axis};
use arrayvec::ArrayVec;
use std::collections::VecDeque;

pub const WINDOW: usize = 1024;
/// Points left in the window after a commit: the least look-ahead any committed choice had. A
/// commit re-roots what is left (one relax per point kept), so committing most of the window at
/// once keeps that cost at a third of a relax per point.
const KEEP: usize = 256;
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
}

/// Largest deviation (radians) of the joint-space midpoint's tool axis from the CL great circle
/// for a move across the fold between two IK branches still to count as continuous.
pub const FOLD_TOLERANCE: f64 = 0.0175;

/// Whether the joint-space move between two branch-labelled solutions is continuous: the branches
/// of a two-rotary chain meet on a fold (B = 0 on a B/C table), and a path passing near it crosses
/// from one to the other with small rotary steps. A true branch jump swings the tool far off the
/// CL orientation halfway.
pub fn crosses_fold(m: &Machine, ja: &[f64; 3], jb: &[f64; 3], ua: &Vec3, ub: &Vec3) -> bool {
    let mut mid = [0.0; 3];
    for (i, r) in m.rotaries.iter().enumerate() {
        let d = jb[i] - ja[i];
        mid[i] = ja[i] + 0.5 * if r.limits.is_none() { wrap(d) } else { d };
    }
    let axis = tool_axis(m, &mid);
    let s = ua + ub;
    let want = if s.norm() < 1e-9 { *ua } else { s.normalize() };
    // angle ≤ tolerance, as a dot product (both unit): no libm call on the planner's hot path.
    axis.dot(&want) >= FOLD_TOLERANCE.cos() * axis.norm() * want.norm()
}

pub struct Column {
    pub pt: MotionPt,
    pub cands: ArrayVec<Cand, MAX_CANDS>,
    cost: [f64; MAX_CANDS],
    back: [u8; MAX_CANDS],
    /// Fold checks against the predecessor's candidates done (bit `a·MAX_CANDS + b`), and
    /// which of them found the move continuous.
    fold_known: u64,
    fold_crosses: u64,
    /// IK failed: the point is reported and skipped, and the chain restarts after it. (Boxed:
    /// rare, and every column and committed point is moved at least once.)
    pub error: Option<Box<crate::kinematics::Error>>,
}

/// A committed point: its column and the candidate chosen.
pub struct Committed {
    pub pt: MotionPt,
    pub cand: Option<Cand>,
    pub error: Option<Box<crate::kinematics::Error>>,
}

#[allow(clippy::large_enum_variant)]
pub enum Out {
    Event(ProgEvent),
    Point(Committed),
}

pub struct Planner<'m> {
    m: &'m Machine,
    pub setup: Setup,
    /// A ring of `WINDOW` columns, reused in place (point `g` in `cols[g % WINDOW]`): a column
    /// is over a kilobyte, and moving one per point cost more than planning it.
    cols: Vec<Column>,
    /// Points pushed so far, and how many of the last are not committed yet.
    pushed: usize,
    points: usize,
    /// Events behind uncommitted points, each with the number of points pushed before it.
    events: VecDeque<(usize, ProgEvent)>,
    /// The last committed candidate: the root the window's costs start from.
    root: Option<(Cand, Vec3)>,
    choice: Vec<Option<usize>>,
    buf: Solutions,
    opt: IkOptions,
}

/// Rotary travel (degrees) between two candidates, and whether the move changes branch or
/// unwinds a bounded axis. Unbounded axes compare modulo a turn (the emitter picks the nearest
/// winding); the free axis of a singular candidate costs nothing (it keeps the previous angle).
/// Returns the cost without the branch penalty, and whether that penalty may apply (it needs
/// the fold check, which callers skip when the move cannot win anyway).
#[inline]
fn transition(m: &Machine, a: &Cand, b: &Cand, rapid: bool) -> (f64, bool) {
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
    if !rapid && unwind {
        cost += UNWIND_PENALTY;
    }
    if !b.feasible {
        cost += INFEASIBLE;
    }
    (cost, !rapid && a.sol.branch * b.sol.branch < 0)
}

/// The full transition cost, fold check included.
fn transition_cost(m: &Machine, a: &Cand, b: &Cand, rapid: bool, ua: &Vec3, ub: &Vec3) -> f64 {
    let (c, check) = transition(m, a, b, rapid);
    if check && !crosses_fold(m, &a.sol.joints.rotary, &b.sol.joints.rotary, ua, ub) {
        c + BRANCH_PENALTY
    } else {
        c
    }
}

/// Whether `new` is `old` less one constant over the first `n` costs (to 1e-12 of their size).
fn offset_only(old: &[f64; MAX_CANDS], new: &[f64; MAX_CANDS], n: usize) -> bool {
    if n == 0 {
        return false;
    }
    let d0 = old[0] - new[0];
    (0..n).all(|b| {
        let d = old[b] - new[b];
        d.is_finite() && (d - d0).abs() <= 1e-12 * old[b].abs().max(1.0)
    })
}

/// `a` in (−π, π].
#[inline]
pub fn wrap(a: f64) -> f64 {
    use std::f64::consts::{PI, TAU};
    if a > -PI && a <= PI {
        return a; // the common case, exactly, without fmod
    }
    let r = (a + PI).rem_euclid(TAU) - PI;
    if r == -PI { PI } else { r }
}

/// Costs of `col` from its predecessor column, or from the committed root.
fn relax(m: &Machine, root: &Option<(Cand, Vec3)>, prev: Option<&Column>, col: &mut Column) {
    let Column {
        pt,
        cands,
        cost,
        back,
        fold_known,
        fold_crosses,
        ..
    } = col;
    let rapid = pt.rapid;
    for (b, cb) in cands.iter().enumerate() {
        let (mut best, mut arg) = (f64::INFINITY, 0u8);
        match prev {
            Some(p) => {
                // Moves that need no fold check first, so that `best` is tight before any
                // (costlier) check runs: the check can only add the branch penalty.
                let mut deferred: ArrayVec<(usize, f64), MAX_CANDS> = ArrayVec::new();
                for (a, ca) in p.cands.iter().enumerate() {
                    let (t, check) = transition(m, ca, cb, rapid);
                    let c = p.cost[a] + t;
                    if check {
                        deferred.push((a, c));
                    } else if c < best {
                        (best, arg) = (c, a as u8);
                    }
                }
                for &(a, mut c) in &deferred {
                    if c >= best {
                        continue; // the branch penalty only adds: no need to look at the fold
                    }
                    // The predecessor of a column never changes: a re-root asks again.
                    let bit = 1u64 << (a * MAX_CANDS + b);
                    if *fold_known & bit == 0 {
                        *fold_known |= bit;
                        if crosses_fold(
                            m,
                            &p.cands[a].sol.joints.rotary,
                            &cb.sol.joints.rotary,
                            &p.pt.pose.axis,
                            &pt.pose.axis,
                        ) {
                            *fold_crosses |= bit;
                        }
                    }
                    if *fold_crosses & bit == 0 {
                        c += BRANCH_PENALTY;
                    }
                    if c < best {
                        (best, arg) = (c, a as u8);
                    }
                }
            }
            None => {
                best = match root {
                    Some((r, ua)) => transition_cost(m, r, cb, rapid, ua, &pt.pose.axis),
                    // First point of the program: prefer small angles, within travel.
                    None => {
                        cb.sol.joints.rotary.iter().map(|a| a.abs().to_degrees()).sum::<f64>() * 1e-3
                            + if cb.feasible { 0.0 } else { INFEASIBLE }
                    }
                };
            }
        }
        cost[b] = best;
        back[b] = arg;
    }
}

/// Candidates of one pose, into `out`: every IK solution, and for bounded rotaries every winding
/// within travel (unbounded ones stay in (−π, π]: the emitter winds them).
fn candidates(
    m: &Machine,
    setup: &Setup,
    opt: &IkOptions,
    buf: &mut Solutions,
    pt: &MotionPt,
    out: &mut ArrayVec<Cand, MAX_CANDS>,
) -> Result<(), crate::kinematics::Error> {
    ik_into(m, &pt.pose, setup, opt, buf)?;
    for s in buf.iter() {
        // The linears only (the rotaries' windings are judged below): a rotary word of 0 is not
        // within every machine's travel.
        let lin_ok = m
            .linears
            .iter()
            .zip(&s.joints.linear)
            .all(|(l, &v)| l.as_ref().is_none_or(|l| v >= l.min - 1e-6 && v <= l.max + 1e-6));
        // Bounded rotaries: the words within travel for this solution's angle (most have one).
        let mut ws: [ArrayVec<f64, 8>; 3] = Default::default();
        let mut combos = 1usize;
        for (i, r) in m.rotaries.iter().enumerate() {
            if r.limits.is_some() && s.singular != Some(i) {
                ws[i] = r.windings(s.actual[i], s.actual[i]);
                combos *= ws[i].len().max(1);
            }
        }
        for k in 0..combos {
            let mut v = *s;
            let mut rest = k;
            let mut rot_ok = true;
            for (i, r) in m.rotaries.iter().enumerate() {
                if r.limits.is_none() || s.singular == Some(i) {
                    continue;
                }
                match ws[i].len() {
                    0 => rot_ok = false, // out of travel: kept, marked infeasible
                    n => {
                        v.joints.rotary[i] = ws[i][rest % n];
                        rest /= n;
                    }
                }
            }
            if out
                .try_push(Cand {
                    sol: v,
                    feasible: lin_ok && rot_ok,
                })
                .is_err()
            {
                return Ok(());
            }
        }
    }
    Ok(())
}

/// Column `k` (if any) to read and column `i` (another) to write.
fn two(v: &mut [Column], k: Option<usize>, i: usize) -> (Option<&Column>, &mut Column) {
    match k {
        None => (None, &mut v[i]),
        Some(k) if k < i => {
            let (x, y) = v.split_at_mut(i);
            (Some(&x[k]), &mut y[0])
        }
        Some(k) => {
            let (x, y) = v.split_at_mut(k);
            (Some(&y[0]), &mut x[i])
        }
    }
}

impl<'m> Planner<'m> {
    pub fn new(m: &'m Machine, setup: Setup) -> Planner<'m> {
        Planner {
            m,
            setup,
            cols: Vec::with_capacity(WINDOW),
            pushed: 0,
            points: 0,
            events: VecDeque::new(),
            root: None,
            choice: Vec::with_capacity(WINDOW),
            buf: Solutions::new(),
            opt: IkOptions::default(),
        }
    }

    pub fn push_event(&mut self, e: ProgEvent, out: &mut impl FnMut(Out)) {
        if self.points == 0 {
            out(Out::Event(e));
        } else {
            self.events.push_back((self.pushed, e));
        }
    }

    /// The last uncommitted point without an IK error, as a global index.
    fn last_ok(&self) -> Option<usize> {
        (self.pushed - self.points..self.pushed)
            .rev()
            .find(|&g| self.cols[g % WINDOW].error.is_none())
    }

    pub fn push_point(&mut self, pt: MotionPt, out: &mut impl FnMut(Out)) {
        let prev = self.last_ok().map(|g| g % WINDOW);
        let i = self.pushed % WINDOW;
        if i == self.cols.len() {
            self.cols.push(Column {
                pt,
                cands: ArrayVec::new(),
                cost: [f64::INFINITY; MAX_CANDS],
                back: [0; MAX_CANDS],
                fold_known: 0,
                fold_crosses: 0,
                error: None,
            });
        } else {
            let c = &mut self.cols[i];
            c.pt = pt;
            c.cands.clear();
            (c.fold_known, c.fold_crosses, c.error) = (0, 0, None);
        }
        self.pushed += 1;
        self.points += 1;
        let (prev, col) = two(&mut self.cols, prev, i);
        match candidates(self.m, &self.setup, &self.opt, &mut self.buf, &col.pt, &mut col.cands) {
            Ok(()) if col.cands.is_empty() => {
                col.error = Some(Box::new(crate::kinematics::Error::NoSolution {
                    reason: "no solution".into(),
                }))
            }
            Ok(()) => {}
            Err(e) => col.error = Some(Box::new(e)),
        }
        if col.error.is_none() {
            relax(self.m, &self.root, prev, col);
        }
        if self.points >= WINDOW {
            self.commit(WINDOW - KEEP, out);
        }
    }

    /// Commits the first `n` points (and the events before them) along the best path.
    fn commit(&mut self, n: usize, out: &mut impl FnMut(Out)) {
        let first = self.pushed - self.points;
        // Trace the best path back through the window.
        self.choice.clear();
        self.choice.resize(self.points, None);
        let mut next: Option<usize> = None;
        for g in (first..self.pushed).rev() {
            let c = &self.cols[g % WINDOW];
            if c.error.is_some() || c.cands.is_empty() {
                continue;
            }
            let pick = match next {
                Some(b) => b,
                None => (0..c.cands.len())
                    .min_by(|&x, &y| c.cost[x].total_cmp(&c.cost[y]))
                    .unwrap_or(0),
            };
            self.choice[g - first] = Some(pick);
            next = Some(c.back[pick] as usize);
        }
        for g in first..first + n {
            while self.events.front().is_some_and(|(k, _)| *k <= g) {
                if let Some((_, e)) = self.events.pop_front() {
                    out(Out::Event(e));
                }
            }
            // Read in place: the column's slot is reused by a later point.
            let c = &mut self.cols[g % WINDOW];
            let cand = self.choice[g - first].map(|k| c.cands[k]);
            if let Some(cd) = cand {
                self.root = Some((cd, c.pt.pose.axis));
            }
            out(Out::Point(Committed {
                pt: c.pt.clone(),
                cand,
                error: c.error.take(),
            }));
        }
        self.points -= n;
        // Re-root the rest on what was committed. Once a column's costs come out as its old ones
        // less one constant (every best path there ran through the committed choice), every later
        // column would too, with the same back pointers: a constant offset changes no choice, so
        // the rest is left as it is.
        let mut prev: Option<usize> = None;
        for g in self.pushed - self.points..self.pushed {
            let i = g % WINDOW;
            if self.cols[i].error.is_some() {
                continue;
            }
            let (p, col) = two(&mut self.cols, prev, i);
            let old = col.cost;
            relax(self.m, &self.root, p, col);
            if offset_only(&old, &col.cost, col.cands.len()) {
                break;
            }
            prev = Some(i);
        }
    }

    /// Commits everything (end of program).
    pub fn finish(&mut self, out: &mut impl FnMut(Out)) {
        self.commit(self.points, out);
        while let Some((_, e)) = self.events.pop_front() {
            out(Out::Event(e));
        }
    }
}
