//! Solution planning over a whole cut: which IK branch and which 360° winding of every bounded
//! rotary each point takes, so that blocks stay within limits, branches do not change mid-cut when
//! a continuous solution exists, rotary travel is least, and bounded axes unwind only when they
//! must.
//!
//! A Viterbi pass over the candidates of each point, with a bounded window: when the window holds
//! `WINDOW` points, all but the last `KEEP` are committed along the best path and those are
//! re-rooted on what was committed. Memory is O(WINDOW · candidates), whatever the file's length.

use super::Prefer;
use super::source::{MotionPt, ProgEvent};
pub use crate::kinematics::wrap;
use crate::kinematics::{IkOptions, Machine, Setup, Solution, Solutions, Vec3, WINDINGS, ik_into, tool_axis};
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
/// Cost of a point on the side `Options::prefer` does not want: a window of them (`WINDOW`)
/// still costs less than a branch change, so a preference picks the branch a run starts on and
/// never makes the planner leave one inside a cut.
const PREFER_PENALTY: f64 = BRANCH_PENALTY / (WINDOW as f64 + 128.0);

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
    let mid = fold_mid(m, ja, jb);
    fold_deviation_ok(&tool_axis(m, &mid), &fold_want(ua, ub))
}

/// The joint-space midpoint of a move (unbounded axes the short way round).
#[inline]
fn fold_mid(m: &Machine, ja: &[f64; 3], jb: &[f64; 3]) -> [f64; 3] {
    let mut mid = [0.0; 3];
    for (i, r) in m.rotaries.iter().enumerate() {
        let d = jb[i] - ja[i];
        mid[i] = ja[i] + 0.5 * if r.limits.is_none() { wrap(d) } else { d };
    }
    mid
}

/// The CL great circle's midpoint between two tool axes.
#[inline]
fn fold_want(ua: &Vec3, ub: &Vec3) -> Vec3 {
    let s = ua + ub;
    if s.norm() < 1e-9 { *ua } else { s.normalize() }
}

/// Angle between `axis` and `want` ≤ [`FOLD_TOLERANCE`], as a dot product (no libm call).
#[inline]
fn fold_deviation_ok(axis: &Vec3, want: &Vec3) -> bool {
    axis.dot(want) >= FOLD_TOLERANCE.cos() * axis.norm() * want.norm()
}

/// Fold checks remembered as lower bounds, so that most are answered without FK. A jump between
/// branches is checked at every point of a cut (the other branch's chain carries the root's
/// branch penalty, so the jump always looks cheaper than staying on it), and its deviation changes
/// little from one point to the next: with `θ` the deviation measured at midpoint `q` and want
/// `w`, the deviation at `q'`, `w'` is at least `θ − Σ|q'ᵢ − qᵢ| − ∠(w, w')`, since turning one
/// rotary by δ turns the tool axis by at most δ (unit axes, and no angle error, whose slope would
/// scale that). When that bound is beyond the tolerance, the check's answer (no) is known.
pub(crate) struct FoldMemo {
    enabled: bool,
    /// Per candidate pair (`a·MAX_CANDS + b`): the last measured midpoint, want and deviation.
    refs: Vec<FoldRef>,
}

#[derive(Clone, Copy)]
struct FoldRef {
    mid: [f64; 3],
    want: Vec3,
    theta: f64,
}

/// Slack (radians) for rounding in the bound and in `acos` near 0: the bound must never answer
/// a check whose exact answer it could get wrong.
const FOLD_BOUND_SLACK: f64 = 1e-7;

impl FoldMemo {
    pub(crate) fn new(m: &Machine) -> FoldMemo {
        FoldMemo {
            enabled: !m.has_angle_error(),
            refs: vec![
                FoldRef {
                    mid: [0.0; 3],
                    want: Vec3::zeros(),
                    theta: f64::NEG_INFINITY,
                };
                MAX_CANDS * MAX_CANDS
            ],
        }
    }

    /// [`crosses_fold`], answered from the pair's last measurement where the bound allows.
    fn crosses(&mut self, m: &Machine, pair: usize, ja: &[f64; 3], jb: &[f64; 3], ua: &Vec3, ub: &Vec3) -> bool {
        let mid = fold_mid(m, ja, jb);
        let want = fold_want(ua, ub);
        // The bound holds between unit wants (not the degenerate reversal, where want is a CL
        // axis as given).
        let wn = want.norm();
        let unit = (wn - 1.0).abs() < 1e-12;
        let r = &mut self.refs[pair];
        if unit && r.theta > FOLD_TOLERANCE {
            let mut moved = 0.0;
            for i in 0..m.rotaries.len() {
                moved += wrap(mid[i] - r.mid[i]).abs();
            }
            // The angle between unit vectors is at most π/2 times their chord.
            let turned = std::f64::consts::FRAC_PI_2 * (want - r.want).norm();
            if r.theta - moved - turned > FOLD_TOLERANCE + FOLD_BOUND_SLACK {
                return false;
            }
        }
        let axis = tool_axis(m, &mid);
        let ok = fold_deviation_ok(&axis, &want);
        // Remembered only where the bound holds: unit axes (no angle error), a unit want.
        if self.enabled && unit {
            let c = axis.dot(&want) / (axis.norm() * wn);
            *r = FoldRef {
                mid,
                want,
                theta: c.clamp(-1.0, 1.0).acos(),
            };
        }
        ok
    }
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
#[derive(Clone)]
pub struct Committed {
    pub pt: MotionPt,
    pub cand: Option<Cand>,
    pub error: Option<Box<crate::kinematics::Error>>,
}

#[allow(clippy::large_enum_variant)]
#[derive(Clone)]
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
    fold: FoldMemo,
    axes: PlanAxes,
}

/// Rotary travel (degrees) between two candidates, and whether the move changes branch or
/// unwinds a bounded axis. Unbounded axes compare modulo a turn (the emitter picks the nearest
/// winding); the free axis of a singular candidate costs nothing into it (it keeps the previous
/// angle, which `relax` gives it) and its turn out of it is travel, no unwind (the emitter turns
/// it at the singular point, tip standing); `placed`: `a` was reached by positioning, where the
/// emitter turns that free rotary before the cut (see `rotary_travel`).
/// Returns the cost without the branch penalty, and whether that penalty may apply (it needs
/// the fold check, which callers skip when the move cannot win anyway).
#[inline(always)]
fn transition(ax: &PlanAxes, a: &Cand, b: &Cand, rapid: bool, placed: bool) -> (f64, bool) {
    let (ja, jb) = (&a.sol.joints.rotary, &b.sol.joints.rotary);
    // Plain indices (no rotary is 3): `Option` compares cost 60 instructions a point here.
    let (sa, sb) = (a.sol.singular.unwrap_or(3), b.sol.singular.unwrap_or(3));
    // Neither singular (nearly every pair): no axis to leave out.
    let (travel, unwind) = if sa & sb == 3 {
        rotary_travel::<false>(ax, ja, jb, sa, sb, placed)
    } else {
        rotary_travel::<true>(ax, ja, jb, sa, sb, placed)
    };
    let mut cost = travel.to_degrees();
    if !rapid && unwind {
        cost += UNWIND_PENALTY;
    }
    if !b.feasible {
        cost += INFEASIBLE;
    }
    (cost, !rapid && a.sol.branch * b.sol.branch < 0)
}

/// Rotary travel (radians) from `ja` to `jb` and whether a bounded axis unwinds. With `SINGULAR`:
/// `b`'s free axis (`sb`) costs nothing (it keeps the angle); `a`'s (`sa`) turns without an unwind,
/// or, without an inherited angle (`PlanAxes::inherit`) or where `a` was `placed` (reached by
/// positioning: the emitter turns its free rotary to where the cut after it needs it), costs
/// nothing either: else a singular start cost the branch a preference wants a half turn of C.
#[inline(always)]
fn rotary_travel<const SINGULAR: bool>(
    ax: &PlanAxes,
    ja: &[f64; 3],
    jb: &[f64; 3],
    sa: usize,
    sb: usize,
    placed: bool,
) -> (f64, bool) {
    let free_a = if ax.inherit && !placed { 3 } else { sa };
    let (mut travel, mut unwind) = (0.0, false);
    let mut axis = |i: usize| {
        if !SINGULAR || (sb != i && free_a != i) {
            let d = jb[i] - ja[i];
            let d = if ax.unbounded[i] { wrap(d) } else { d }.abs();
            unwind |= d > std::f64::consts::PI && (!SINGULAR || sa != i);
            travel += d;
        }
    };
    // Unrolled: a loop to a count known only at run time costs more than the work here.
    if ax.n > 0 {
        axis(0);
    }
    if ax.n > 1 {
        axis(1);
    }
    if ax.n > 2 {
        axis(2);
    }
    (travel, unwind)
}

/// What [`transition`] needs of the machine, as plain arrays (it runs for every pair of
/// candidates of every point).
struct PlanAxes {
    n: usize,
    unbounded: [bool; 3],
    /// A singular candidate takes its free angle from its predecessor: where the emitter's IK
    /// places the tip at any free angle (three linears). A chain missing one (three rotaries)
    /// has only some, and the candidate must stay the solution the planner's IK found.
    inherit: bool,
    prefer: Option<Prefer>,
}

impl PlanAxes {
    /// `PREFER_PENALTY` for a candidate on the side not preferred.
    fn off_side(&self, c: &Cand) -> f64 {
        match self.prefer {
            Some(p) if p.sign != 0.0 && c.sol.joints.rotary[p.rotary] * p.sign < -1e-9 => PREFER_PENALTY,
            _ => 0.0,
        }
    }

    fn new(m: &Machine, prefer: Option<Prefer>) -> PlanAxes {
        let mut unbounded = [false; 3];
        for (u, r) in unbounded.iter_mut().zip(&m.rotaries) {
            *u = r.limits.is_none();
        }
        PlanAxes {
            n: m.rotaries.len().min(3),
            unbounded,
            inherit: m.linears.iter().all(|l| l.is_some()),
            prefer,
        }
    }
}

/// The full transition cost, fold check included (from the committed root: once per commit).
#[cold]
fn transition_cost(m: &Machine, axes: &PlanAxes, a: &Cand, b: &Cand, rapid: bool, ua: &Vec3, ub: &Vec3) -> f64 {
    let (c, check) = transition(axes, a, b, rapid, false);
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

/// Costs of `col` from its predecessor column, or from the committed root.
fn relax(
    m: &Machine,
    axes: &PlanAxes,
    root: &Option<(Cand, Vec3)>,
    fold: &mut FoldMemo,
    prev: Option<&Column>,
    col: &mut Column,
) {
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
                let mut deferred = [0.0; MAX_CANDS];
                let mut check_mask = 0u32;
                for (a, ca) in p.cands.iter().enumerate() {
                    let (t, check) = transition(axes, ca, cb, rapid, p.pt.rapid);
                    let c = p.cost[a] + t;
                    if check {
                        deferred[a] = c;
                        check_mask |= 1 << a;
                    } else if c < best {
                        (best, arg) = (c, a as u8);
                    }
                }
                while check_mask != 0 {
                    let a = check_mask.trailing_zeros() as usize;
                    check_mask &= check_mask - 1;
                    let mut c = deferred[a];
                    if c >= best {
                        continue; // the branch penalty only adds: no need to look at the fold
                    }
                    // The predecessor of a column never changes: a re-root asks again.
                    let bit = 1u64 << (a * MAX_CANDS + b);
                    if *fold_known & bit == 0 {
                        *fold_known |= bit;
                        if fold.crosses(
                            m,
                            a * MAX_CANDS + b,
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
                    Some((r, ua)) => transition_cost(m, axes, r, cb, rapid, ua, &pt.pose.axis),
                    // First point of the program: angles near the preferred start (small ones
                    // where none is), within travel.
                    None => {
                        let start = axes.prefer.map_or([None; 3], |p| p.start);
                        let from = |i: usize, a: f64| (a - start[i].unwrap_or(0.0)).abs().to_degrees();
                        cb.sol.joints.rotary.iter().enumerate().map(|(i, a)| from(i, *a)).sum::<f64>() * 1e-3
                            + if cb.feasible { 0.0 } else { INFEASIBLE }
                    }
                };
            }
        }
        cost[b] = best + axes.off_side(cb);
        back[b] = arg;
    }
    // A singular candidate's free rotary stands where the move into it left it (the emitter
    // holds it there), so that the move out of it pays for turning it: free everywhere, it left
    // the winding of a bounded table to the order of the list (C −270° for +90°).
    if !axes.inherit {
        return;
    }
    for (cb, &arg) in cands.iter_mut().zip(back.iter()) {
        if let Some(f) = cb.sol.singular {
            let from = match prev {
                Some(p) => p.cands.get(arg as usize),
                None => root.as_ref().map(|(r, _)| r),
            };
            if let Some(a) = from {
                cb.sol.joints.rotary[f] = a.sol.joints.rotary[f];
                cb.sol.actual[f] = a.sol.actual[f];
            }
        }
    }
}

/// Candidates of one pose, into `out`: every IK solution, and for bounded rotaries every winding
/// within travel, or on a long-travel table those nearest `near`, the words the best path so far
/// stands at (unbounded ones stay in (−π, π]: the emitter winds them).
fn candidates(
    m: &Machine,
    setup: &Setup,
    opt: &IkOptions,
    buf: &mut Solutions,
    pt: &MotionPt,
    mut near: impl FnMut() -> [Option<f64>; 3],
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
        // Bounded rotaries: the words within travel for this solution's angle. Most have at most
        // one, known without a list (tilting axes); the others (a table over a turn of travel)
        // multiply the candidates.
        let mut v = *s;
        let mut rot_ok = true;
        let mut ws: [ArrayVec<f64, WINDINGS>; 3] = Default::default();
        let mut listed = [false; 3];
        let mut combos = 1usize;
        for (i, r) in m.rotaries.iter().enumerate() {
            if r.limits.is_none() || s.singular == Some(i) {
                continue;
            }
            match r.one_winding(s.actual[i]) {
                Some(Some(w)) => v.joints.rotary[i] = w,
                Some(None) => rot_ok = false, // out of travel: kept, marked infeasible
                None => {
                    ws[i] = r.windings(s.actual[i], near()[i].unwrap_or(s.actual[i]));
                    combos *= ws[i].len().max(1);
                    listed[i] = true;
                }
            }
        }
        // Full (at most MAX_CANDS): the rest are dropped.
        let mut add = |sol, ok: bool| {
            out.try_push(Cand {
                sol,
                feasible: lin_ok && ok,
            })
            .is_ok()
        };
        if listed == [false; 3] {
            if !add(v, rot_ok) {
                return Ok(());
            }
            continue;
        }
        for k in 0..combos {
            let mut c = v;
            let mut ok = rot_ok;
            let mut rest = k;
            for i in (0..3).filter(|&i| listed[i]) {
                match ws[i].len() {
                    0 => ok = false,
                    n => {
                        c.joints.rotary[i] = ws[i][rest % n];
                        rest /= n;
                    }
                }
            }
            if !add(c, ok) {
                return Ok(());
            }
        }
    }
    Ok(())
}

/// The rotary words of the cheapest candidate of `prev`, or of the committed root.
fn best_words(prev: Option<&Column>, root: Option<&Cand>) -> [Option<f64>; 3] {
    let best = match prev {
        Some(p) => p
            .cands
            .iter()
            .zip(&p.cost)
            .min_by(|a, b| a.1.total_cmp(b.1))
            .map(|(c, _)| c),
        None => root,
    };
    best.map_or([None; 3], |c| c.sol.joints.rotary.map(Some))
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
    pub fn new(m: &'m Machine, setup: Setup, prefer: Option<Prefer>) -> Planner<'m> {
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
            fold: FoldMemo::new(m),
            axes: PlanAxes::new(m, prefer),
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
        let mut known = None;
        let root = self.root.as_ref().map(|(c, _)| c);
        let near = || *known.get_or_insert_with(|| best_words(prev, root));
        match candidates(self.m, &self.setup, &self.opt, &mut self.buf, &col.pt, near, &mut col.cands) {
            Ok(()) if col.cands.is_empty() => {
                col.error = Some(Box::new(crate::kinematics::Error::NoSolution {
                    reason: "no solution".into(),
                }))
            }
            Ok(()) => {}
            Err(e) => col.error = Some(Box::new(e)),
        }
        if col.error.is_none() {
            relax(self.m, &self.axes, &self.root, &mut self.fold, prev, col);
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
            relax(self.m, &self.axes, &self.root, &mut self.fold, p, col);
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

#[cfg(test)]
mod tests {
    use super::*;

    fn library() -> crate::machines::Library {
        crate::machines::Library::load_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/machines").as_ref()).unwrap()
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(48))]
        /// The memo answers exactly what the check answers, on slow walks of both candidates'
        /// joints (the planner's case: consecutive points of a cut) that pass over the fold and
        /// away from it again, on every shipped machine.
        #[test]
        fn the_fold_memo_answers_as_the_check_does(
            seed in proptest::num::u64::ANY,
            step in 1e-5f64..2e-2,
            spread in 0.0f64..3.5,
        ) {
            let lib = library();
            let mut rng = seed | 1;
            let mut next = move || {
                // xorshift: enough to wander.
                rng ^= rng << 13;
                rng ^= rng >> 7;
                rng ^= rng << 17;
                (rng >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
            };
            for p in lib.iter() {
                let m = &p.machine;
                if m.rotaries.len() < 2 {
                    continue;
                }
                let mut memo = FoldMemo::new(m);
                let n = m.rotaries.len();
                let mut ja = [0.0; 3];
                let mut off = [0.0; 3];
                for i in 0..n {
                    ja[i] = next() * 2.0;
                    off[i] = next() * spread;
                }
                let mut ua = tool_axis(m, &ja);
                for _ in 0..400 {
                    let mut ja2 = ja;
                    let mut jb = [0.0; 3];
                    for i in 0..n {
                        ja2[i] += next() * step;
                        // The other candidate drifts through the first one and away.
                        off[i] += next() * step * 3.0;
                        jb[i] = ja2[i] + off[i];
                    }
                    let ub = tool_axis(m, &jb);
                    let exact = crosses_fold(m, &ja, &jb, &ua, &ub);
                    let got = memo.crosses(m, 3, &ja, &jb, &ua, &ub);
                    proptest::prop_assert_eq!(got, exact, "{} at {:?} {:?}", p.machine.id, ja, jb);
                    ja = ja2;
                    ua = tool_axis(m, &ja);
                }
            }
        }
    }

    /// On a plain cut far from the fold, the memo answers nearly every check without FK.
    #[test]
    fn the_fold_memo_skips_most_checks_of_a_cut() {
        let lib = library();
        let m = &lib.get("spinner-u5-620").unwrap().machine;
        let mut memo = FoldMemo::new(m);
        let (mut exact_runs, mut crossed) = (0, 0);
        for k in 0..1000 {
            let t = k as f64 * 1e-3;
            // B about 40°, C turning; the other candidate far away on the other side of the fold
            // (not C + 180° exactly, whose midpoint rounds to either side from point to point).
            let ja = [0.7 + 0.1 * t.sin(), t, 0.0];
            let jb = [-0.6 * ja[0], wrap(ja[1] + 3.0), 0.0];
            let (ua, ub) = (tool_axis(m, &ja), tool_axis(m, &ja));
            let before = memo.refs[1].theta;
            crossed += memo.crosses(m, 1, &ja, &jb, &ua, &ub) as usize;
            exact_runs += (memo.refs[1].theta != before) as usize;
        }
        assert_eq!(crossed, 0, "a jump to a candidate 70° away is no fold crossing");
        assert!(exact_runs < 20, "{exact_runs} of 1000 checks ran FK");
    }
}
