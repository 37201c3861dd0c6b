//! Inverse kinematics: every joint solution of a tool pose, in closed form where the chain allows
//! and by a bracketed 1-D root search where it does not (a missing linear axis). It reads what the
//! machine precomputed of its chain ([`Chain`]: the orientation sequence, the chain's shape).

use super::fk::rotate;
use super::model::{Chain, Machine, Shape};
use super::subproblem::{Cs, FreeAngle, Pair, sp1};
use super::{Error, Joints, Pose, Setup, Vec3, wrap};
use arrayvec::ArrayVec;

/// The tool-axis direction (in W) at which the outer rotary of a two-rotary chain turns freely:
/// near it, exact orientation makes that rotary swing. `None` for other chains.
pub fn singular_direction(m: &Machine) -> Option<Vec3> {
    match &m.chain.shape {
        Shape::Two(p) => Some(p.s1),
        _ => None,
    }
}

/// For a two-rotary chain: the solution with the outer rotary held at `outer` (actual, radians)
/// that comes closest to `pose`'s orientation, with the tip exact, and the angle (radians) by
/// which its tool axis misses the pose's. What smoothing near a singular direction trades: a
/// bounded orientation error for a still outer rotary. `None` for other chains.
pub fn hold_outer(m: &Machine, pose: &Pose, setup: &Setup, outer: f64, branch: i8) -> Option<(Solution, f64)> {
    let Shape::Two(pair) = &m.chain.shape else { return None };
    let u = pose.axis.normalize();
    let a1 = Cs::of(outer);
    let v = rotate(&pair.s1, a1.c, -a1.s, &u);
    let a2 = sp1(&pair.s2, &Vec3::z(), &v).unwrap_or(Cs::ZERO);
    let mut out = Solutions::new();
    let seq = &m.chain.seq;
    push(m, &mut out, pose, setup, seq, [a1, a2, Cs::ZERO], None, branch, 0, None);
    let mut s = out.pop()?;
    s.actual[seq[0]] = outer;
    s.joints.rotary[seq[0]] = m.rotaries[seq[0]].word(outer);
    // The orientation actually reached, through the forward chain.
    let reached = super::fk::fk_actual(m, &s.joints.linear, &s.actual, setup).axis;
    Some((s, super::angle_between(&reached, &u)))
}

/// The rotary (chain index) that [`IkOptions::free_angle`] sets at a singular pose, on any chain.
pub fn free_rotary(m: &Machine) -> Option<usize> {
    match &m.chain.shape {
        Shape::Fixed => None,
        Shape::One { .. } | Shape::Two(_) => Some(m.chain.seq[0]),
        Shape::Three { .. } => Some(m.chain.seq[1]),
    }
}

/// The rotary (chain index) that turns freely at the singular direction of a two-rotary chain.
pub fn outer_rotary(m: &Machine) -> Option<usize> {
    matches!(m.chain.shape, Shape::Two(_)).then(|| m.chain.seq[0])
}

/// One joint solution.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Solution {
    /// Commanded words: linears in profile units (0 for a missing one), rotaries in radians in
    /// (−π, π] before angle-error compensation, i.e. the NC words for that winding.
    pub joints: Joints,
    /// The actual rotary angles (radians, (−π, π] unless singular with a free angle outside).
    pub actual: [f64; 3],
    /// +1 or −1: the sign of γ in the subproblem-2 meet `c = c0 ± γ (s1 × s2)`; 0 on the fold
    /// where both coincide. A branch is continuous in the pose until γ passes 0, so the planner
    /// keeps it through a cut.
    pub branch: i8,
    /// For the 3-rotary chain: the index of this root of the 1-D equation, by increasing outer
    /// angle; 0 otherwise.
    pub root: u8,
    /// The rotary (chain index) whose angle is free at this pose: the value came from
    /// [`IkOptions::free_angle`] and any other value also reproduces the pose (with other linears).
    pub singular: Option<usize>,
}

pub type Solutions = ArrayVec<Solution, 16>;

/// Options of [`ik`]; the defaults reproduce poses exactly.
#[derive(Clone, Copy, Debug)]
pub struct IkOptions {
    /// Actual angle (radians) given to a rotary that is free at a singular pose.
    pub free_angle: f64,
    /// How far (radians) an orientation may lie outside the reachable set and still be taken
    /// (projected onto it): covers the rounding of i, j, k in CL files on 4-axis machines.
    pub orientation_tolerance: f64,
}

impl Default for IkOptions {
    fn default() -> Self {
        IkOptions {
            free_angle: 0.0,
            orientation_tolerance: 1e-7,
        }
    }
}

/// Every joint solution of `pose` (in W, profile units), unfiltered by limits.
pub fn ik(m: &Machine, pose: &Pose, setup: &Setup, opt: &IkOptions) -> Result<Solutions, Error> {
    let mut out = Solutions::new();
    ik_into(m, pose, setup, opt, &mut out)?;
    Ok(out)
}

/// As [`ik`], into a caller's buffer (cleared first): the hot path of the planner, which reuses
/// one buffer rather than moving a solution set per pose.
pub fn ik_into(m: &Machine, pose: &Pose, setup: &Setup, opt: &IkOptions, out: &mut Solutions) -> Result<(), Error> {
    out.clear();
    let n2 = pose.axis.norm_squared();
    let inside = |v: &f64| super::coordinate_ok(*v);
    if !(n2.is_finite() && n2 > 1e-24 && pose.tip.iter().all(inside)) {
        return Err(Error::InvalidPose {
            problem: format!(
                "tip and axis must be finite, the tip within ±{:e}, the axis non-zero",
                super::MAX_COORD
            ),
        });
    }
    if !(inside(&setup.tool_length) && setup.work_offset.iter().all(inside)) {
        return Err(Error::InvalidPose {
            problem: format!(
                "tool length and work offset must be finite and within ±{:e}",
                super::MAX_COORD
            ),
        });
    }
    // CL readers hand over unit axes; normalise only what is not unit to rounding.
    let u = if (n2 - 1.0).abs() <= 4.0 * f64::EPSILON {
        pose.axis
    } else {
        pose.axis * (1.0 / n2.sqrt())
    };
    let free = FreeAngle(opt.free_angle);
    let ch = &m.chain;
    match &ch.shape {
        Shape::Fixed => {
            let miss = u.z.clamp(-1.0, 1.0).acos();
            if miss > opt.orientation_tolerance {
                return Err(Error::Unreachable { miss });
            }
            push(m, out, pose, setup, &[], [Cs::ZERO; 3], None, 0, 0, None);
        }
        Shape::One { s } => {
            let cone = s.z.clamp(-1.0, 1.0).acos();
            let miss = (s.dot(&u).clamp(-1.0, 1.0).acos() - cone).abs();
            if miss > opt.orientation_tolerance {
                return Err(Error::Unreachable { miss });
            }
            let (a, sing) = match sp1(s, &Vec3::z(), &u) {
                Some(a) if (u - s * s.dot(&u)).norm_squared() > 1e-18 && s.cross(&Vec3::z()).norm_squared() > 1e-18 => (a, None),
                _ => (free.cs(), Some((ch.seq[0], opt.free_angle))),
            };
            push(m, out, pose, setup, &ch.seq, [a, Cs::ZERO, Cs::ZERO], None, 0, 0, sing);
        }
        Shape::Two(pair) => {
            let meet = pair.meet(&u);
            if meet.reach < 0.0 {
                let miss = pair.miss(&u).max(if meet.on_axis { -meet.reach } else { 0.0 });
                if miss > opt.orientation_tolerance {
                    return Err(Error::Unreachable { miss });
                }
            }
            if meet.reach > 0.0 && !meet.on_axis {
                for ((a1, t1, a2, t2), sg) in pair.both(&meet).into_iter().zip([1i8, -1]) {
                    push(
                        m,
                        out,
                        pose,
                        setup,
                        &ch.seq,
                        [a1, a2, Cs::ZERO],
                        Some([t1, t2, 0.0]),
                        sg,
                        0,
                        None,
                    );
                }
            } else {
                let (a1, a2, sing) = pair.angles(&u, &meet, 0.0, free);
                let sing = sing.then_some((ch.seq[0], opt.free_angle));
                push(m, out, pose, setup, &ch.seq, [a1, a2, Cs::ZERO], None, 0, 0, sing);
            }
        }
        Shape::Three { s0, pair, missing } => three(m, ch, s0, pair, *missing, &u, pose, setup, opt, free, out)?,
    }
    Ok(())
}

/// Builds a solution from orientation angles (in sequence order) and places the linears.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn push(
    m: &Machine,
    out: &mut Solutions,
    pose: &Pose,
    setup: &Setup,
    seq: &[usize],
    cs: [Cs; 3],
    angles: Option<[f64; 3]>,
    branch: i8,
    root: u8,
    singular: Option<(usize, f64)>,
) {
    let mut rcs = [Cs::ZERO; 3];
    let mut actual = [0.0; 3];
    for (k, &ri) in seq.iter().enumerate() {
        rcs[ri] = cs[k];
        actual[ri] = match angles {
            Some(a) => a[k],
            None => cs[k].angle(),
        };
    }
    let singular = singular.map(|(ri, free)| {
        // The caller's free angle as given: it may carry windings the planner wants to keep.
        actual[ri] = free;
        ri
    });
    let cp = controlled_point_cs(m, &rcs, &(pose.tip + setup.work_offset), setup.tool_length);
    let mut joints = Joints::default();
    for i in 0..3 {
        joints.linear[i] = if m.chain.has_linear[i] { cp[i] } else { 0.0 };
    }
    for (i, l) in m.chain.links.iter().enumerate() {
        joints.rotary[i] = if l.compensated {
            m.rotaries[i].word(actual[i])
        } else {
            actual[i]
        };
    }
    if out.is_full() {
        return;
    }
    out.push(Solution {
        joints,
        actual,
        branch,
        root,
        singular,
    });
}

/// `T(φ)(p) − head offset(θ)` from (cos, sin) pairs: the same composition as `fk`, in plain
/// scalars (the hot path of every solution; nalgebra's generic ops cost 3× the instructions here).
/// Always inlined: called, it read back a `tip + offset` just stored as halves with one wide load
/// (a store-forwarding stall: 17% of this function's samples, itself 8% of a joint-mode run).
#[inline(always)]
fn controlled_point_cs(m: &Machine, cs: &[Cs; 3], p_w: &Vec3, tool_length: f64) -> Vec3 {
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
    let links = &m.chain.links;
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

/// Samples of the outer angle for the root search of the 3-rotary chain; intervals where the
/// inner angles swing fast (near the inner pair's singularity) are subdivided further.
const SAMPLES: usize = 360;
const MAX_DEPTH: u32 = 10;
const SWING: f64 = 0.1; // rad of inner-angle change that asks for a finer look

/// One evaluation of the 3-rotary residual: outer angle, missing-linear coordinate, angles.
#[derive(Clone, Copy)]
struct Sample {
    a: f64,
    v: Option<(f64, [Cs; 3])>,
}

/// Adaptive scan of one branch: leaf samples in increasing angle, refined where the inner angles
/// swing fast and up to the fold where the inner pair's reach ends.
struct Scan<'a, F: Fn(f64, bool) -> Option<(f64, [Cs; 3], bool)>, G: Fn(f64) -> f64> {
    eval: &'a F,
    reach: &'a G,
    leaves: Vec<Sample>,
    /// Longest lever arm of the chain: bounds how far f moves per radian of any angle.
    lever: f64,
}

impl<F: Fn(f64, bool) -> Option<(f64, [Cs; 3], bool)>, G: Fn(f64) -> f64> Scan<'_, F, G> {
    fn sample(&self, a: f64, clamp: bool) -> Sample {
        Sample {
            a,
            v: (self.eval)(a, clamp).map(|(f, cs, _)| (f, cs)),
        }
    }

    /// Adds the samples of (lo, hi] (lo is already in `leaves`).
    fn refine(&mut self, lo: Sample, hi: Sample, depth: u32) {
        match (lo.v, hi.v) {
            (Some((flo, clo)), Some((fhi, chi)))
                if depth < MAX_DEPTH && {
                    // Split where the inner angles swing fast, and wherever a root cannot be ruled
                    // out: f moves at most lever × (angle changes) across the interval, so ends
                    // farther from 0 than that bound hold no root (swings measured at the ends).
                    let (s1, s2) = (swing(&clo[1], &chi[1]), swing(&clo[2], &chi[2]));
                    let bound = self.lever * ((hi.a - lo.a).abs() + s1 + s2);
                    s1 > SWING || s2 > SWING || flo.abs().min(fhi.abs()) <= bound
                } =>
            {
                let mid = self.sample(0.5 * (lo.a + hi.a), false);
                let mid = if mid.v.is_none() { self.sample(mid.a, true) } else { mid };
                self.refine(lo, mid, depth + 1);
                self.refine(mid, hi, depth + 1);
                return;
            }
            (Some(_), None) if depth < MAX_DEPTH => {
                let e = self.sample(fold(self.reach, lo.a, hi.a), true);
                self.refine(lo, e, depth + 1);
            }
            (None, Some(_)) if depth < MAX_DEPTH => {
                let e = self.sample(fold(self.reach, hi.a, lo.a), true);
                self.leaves.push(Sample { a: e.a, v: None }); // continuity breaks before the fold
                self.leaves.push(e);
            }
            _ => {}
        }
        self.leaves.push(hi);
    }

    /// Roots: sign changes (Brent), and dips of |f| that touch zero (double roots, golden section).
    fn roots(&self, tol: f64) -> ArrayVec<f64, 16> {
        let mut out: ArrayVec<f64, 16> = ArrayVec::new();
        let mut add = |r: f64| {
            let r = wrap(r);
            if !out.iter().any(|&x| wrap(x - r).abs() < 1e-9) && !out.is_full() {
                out.push(r);
            }
        };
        let f = |x: f64| (self.eval)(x, true).map(|v| v.0);
        for w in self.leaves.windows(2) {
            if let (Some((f0, _)), Some((f1, _))) = (w[0].v, w[1].v) {
                if f0 == 0.0 {
                    add(w[0].a);
                } else if f0.signum() != f1.signum()
                    && let Some(r) = brent(f, w[0].a, w[1].a, f0, f1)
                {
                    add(r);
                }
            }
        }
        for w in self.leaves.windows(3) {
            if let (Some((f0, _)), Some((f1, _)), Some((f2, _))) = (w[0].v, w[1].v, w[2].v)
                && f0.signum() == f1.signum()
                && f1.signum() == f2.signum()
                && f1.abs() < f0.abs()
                && f1.abs() <= f2.abs()
            {
                // Minimise f toward zero over the dip: crossing zero means two close simple
                // roots (bracket each); touching it means a double root.
                let sg = f1.signum();
                let (x, fx) = golden_min(|x| f(x).map(|v| sg * v), w[0].a, w[2].a);
                if fx < 0.0 {
                    let fxs = sg * fx; // f itself at x
                    for (a, b, fa, fb) in [(w[0].a, x, f0, fxs), (x, w[2].a, fxs, f2)] {
                        if let Some(r) = brent(f, a, b, fa, fb) {
                            add(r);
                        }
                    }
                } else if fx <= tol {
                    add(x);
                }
            }
        }
        out
    }
}

/// Minimises f on [a, b] by golden section; (argmin, f there).
fn golden_min(f: impl Fn(f64) -> Option<f64>, a: f64, b: f64) -> (f64, f64) {
    let g = 0.5 * (5f64.sqrt() - 1.0);
    let h = |x: f64| f(x).unwrap_or(f64::INFINITY);
    let (mut a, mut b) = (a, b);
    let (mut c, mut d) = (b - g * (b - a), a + g * (b - a));
    let (mut fc, mut fd) = (h(c), h(d));
    for _ in 0..200 {
        if (b - a).abs() <= 4.0 * f64::EPSILON * (1.0 + a.abs()) {
            break;
        }
        if fc < fd {
            b = d;
            d = c;
            fd = fc;
            c = b - g * (b - a);
            fc = h(c);
        } else {
            a = c;
            c = d;
            fc = fd;
            d = a + g * (b - a);
            fd = h(d);
        }
    }
    if fc < fd { (c, fc) } else { (d, fd) }
}

/// |Δ angle| between two rotations given as (cos, sin).
#[inline]
fn swing(a: &Cs, b: &Cs) -> f64 {
    (a.s * b.c - a.c * b.s).atan2(a.c * b.c + a.s * b.s).abs()
}

#[allow(clippy::too_many_arguments)]
fn three(
    m: &Machine,
    ch: &Chain,
    s0: &Vec3,
    pair: &Pair,
    missing: usize,
    u: &Vec3,
    pose: &Pose,
    setup: &Setup,
    opt: &IkOptions,
    free: FreeAngle,
    out: &mut Solutions,
) -> Result<(), Error> {
    let p_w = pose.tip + setup.work_offset;
    let inner = |a: f64| rotate(s0, a.cos(), -a.sin(), u);
    let reach = |a: f64| pair.meet(&inner(a)).reach;
    let step = std::f64::consts::TAU / SAMPLES as f64;
    let scale = 1.0 + p_w.norm() + setup.tool_length.abs();
    let lever = scale + m.rotaries.iter().map(|r| r.pivot.norm()).sum::<f64>();
    let mut found: ArrayVec<(f64, i8), 16> = ArrayVec::new();
    let mut any_valid = false;
    let mut best_miss = f64::INFINITY;
    let mut closest = f64::INFINITY;
    for sg in [1i8, -1] {
        // The missing linear's coordinate for outer angle `a` on this branch; None where the
        // inner pair cannot reach the orientation, unless `clamp` (evaluate on the fold).
        let eval = |a: f64, clamp: bool| -> Option<(f64, [Cs; 3], bool)> {
            let a0 = Cs::of(a);
            let v = rotate(s0, a0.c, -a0.s, u);
            let meet = pair.meet(&v);
            if meet.reach < 0.0 && !clamp {
                return None;
            }
            let (a1, a2, sing) = pair.angles(&v, &meet, sg as f64, free);
            let cs = [a0, a1, a2];
            let mut rcs = [Cs::ZERO; 3];
            for (k, &ri) in ch.seq.iter().enumerate() {
                rcs[ri] = cs[k];
            }
            Some((controlled_point_cs(m, &rcs, &p_w, setup.tool_length)[missing], cs, sing))
        };
        let mut scan = Scan {
            eval: &eval,
            reach: &reach,
            leaves: Vec::with_capacity(SAMPLES + 64),
            lever,
        };
        let mut prev = scan.sample(-std::f64::consts::PI, false);
        scan.leaves.push(prev);
        for k in 1..=SAMPLES {
            let cur = scan.sample(-std::f64::consts::PI + step * k as f64, false);
            match cur.v {
                Some((f, _)) => {
                    any_valid = true;
                    closest = closest.min(f.abs());
                }
                None => best_miss = best_miss.min(pair.miss(&inner(cur.a))),
            }
            scan.refine(prev, cur, 0);
            prev = cur;
        }
        for r in scan.roots(1e-9 * scale) {
            // Keep only true roots: a sign change across a branch discontinuity is not one.
            if let Some((f, _, _)) = eval(r, true)
                && f.abs() <= 1e-9 * scale
                && !found.is_full()
            {
                found.push((r, sg));
            }
        }
    }
    if !any_valid {
        return Err(Error::Unreachable { miss: best_miss });
    }
    found.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut count = 0u8;
    for (a, sg) in found {
        let v = inner(a);
        let meet = pair.meet(&v);
        let (a1, a2, sing) = pair.angles(&v, &meet, sg as f64, free);
        let branch = if meet.reach <= 1e-14 || meet.on_axis { 0 } else { sg };
        // The same pose reached on the fold by both branches is one solution.
        if branch == 0
            && out
                .iter()
                .any(|s| s.branch == 0 && wrap(s.actual[ch.seq[0]] - a).abs() < 1e-9)
        {
            continue;
        }
        let sing = sing.then_some((ch.seq[1], opt.free_angle));
        push(m, out, pose, setup, &ch.seq, [Cs::of(a), a1, a2], None, branch, count, sing);
        if let Some(s) = out.last_mut() {
            polish(m, pose, setup, s);
        }
        count += 1;
    }
    if out.is_empty() {
        return Err(Error::NoSolution {
            reason: format!(
                "no outer angle keeps the missing {} axis at 0 (closest: {:.6} units away)",
                ['X', 'Y', 'Z'][missing],
                closest
            ),
        });
    }
    Ok(())
}

/// Gauss–Newton on all joints at once. Next to the inner pair's singularity the 1-D
/// parametrisation is ill-conditioned (the inner angle moves ~1e5× faster than the outer one), so
/// the best double for the outer angle can leave 1e-8 of tip error; in full joint space the same
/// problem is well-conditioned and two steps bring it to rounding level.
/// Enough for any 6×5 the polish sees; a matrix that needs more is not worth polishing with.
const SVD_MAX_ITER: usize = 200;

fn polish(m: &Machine, pose: &Pose, setup: &Setup, sol: &mut Solution) {
    use nalgebra::{SMatrix, SVector};
    let lin: ArrayVec<usize, 3> = (0..3).filter(|&i| m.linears[i].is_some()).collect();
    let nr = m.rotaries.len();
    if lin.len() + nr != 5 {
        return;
    }
    let residual = |x: &SVector<f64, 5>| -> SVector<f64, 6> {
        let mut l = [0.0; 3];
        for (k, &i) in lin.iter().enumerate() {
            l[i] = x[k];
        }
        let mut a = [0.0; 3];
        a[..nr].copy_from_slice(&x.as_slice()[lin.len()..lin.len() + nr]);
        let p = super::fk::fk_actual(m, &l, &a, setup);
        let (dt, da) = (p.tip - pose.tip, p.axis - pose.axis.normalize());
        SVector::<f64, 6>::new(dt.x, dt.y, dt.z, da.x, da.y, da.z)
    };
    let mut x = SVector::<f64, 5>::zeros();
    for (k, &i) in lin.iter().enumerate() {
        x[k] = sol.joints.linear[i];
    }
    for k in 0..nr {
        x[lin.len() + k] = sol.actual[k];
    }
    let mut r = residual(&x);
    if !r.iter().all(|v| v.is_finite()) {
        return;
    }
    let scale = 1.0 + pose.tip.norm() + setup.tool_length.abs();
    for _ in 0..3 {
        if r.norm() <= 1e-12 * scale {
            break;
        }
        let mut jac = SMatrix::<f64, 6, 5>::zeros();
        for c in 0..5 {
            let h = 1e-6 * (1.0 + x[c].abs());
            let (mut xp, mut xm) = (x, x);
            xp[c] += h;
            xm[c] -= h;
            jac.set_column(c, &((residual(&xp) - residual(&xm)) / (2.0 * h)));
        }
        // Minimum-norm least squares: directions the pose barely sees (near a singularity) get
        // no step, so the polish cannot slide along them to another, equally exact solution.
        // Bounded: nalgebra's plain `svd` never returns on a matrix holding inf or NaN.
        let Some(svd) = jac.try_svd(true, true, f64::EPSILON, SVD_MAX_ITER) else {
            return;
        };
        let cutoff = 1e-8 * svd.singular_values.max();
        let Ok(step) = svd.solve(&(-r), cutoff) else { return };
        if step.norm() > 1e-6 * (1.0 + x.norm()) {
            break; // a polish corrects rounding, it does not move to another solution
        }
        let xn = x + step;
        let rn = residual(&xn);
        if rn.norm() >= r.norm() {
            break;
        }
        x = xn;
        r = rn;
    }
    for (k, &i) in lin.iter().enumerate() {
        sol.joints.linear[i] = x[k];
    }
    for k in 0..nr {
        sol.actual[k] = x[lin.len() + k];
        sol.joints.rotary[k] = m.rotaries[k].word(sol.actual[k]);
    }
}

/// The angle between `valid` (reach ≥ 0) and `invalid` (reach < 0) where reach crosses 0.
fn fold(reach: &impl Fn(f64) -> f64, valid: f64, invalid: f64) -> f64 {
    let (mut a, mut b) = (valid, invalid);
    for _ in 0..64 {
        let mid = 0.5 * (a + b);
        if reach(mid) >= 0.0 {
            a = mid;
        } else {
            b = mid;
        }
    }
    a
}

/// Brent's method on a bracket with `fa`, `fb` of opposite signs; to machine precision.
fn brent(f: impl Fn(f64) -> Option<f64>, a: f64, b: f64, fa: f64, fb: f64) -> Option<f64> {
    let (mut a, mut b, mut fa, mut fb) = (a, b, fa, fb);
    if fa.abs() < fb.abs() {
        std::mem::swap(&mut a, &mut b);
        std::mem::swap(&mut fa, &mut fb);
    }
    let (mut c, mut fc) = (a, fa);
    let mut d = b - a;
    let mut bisected = true;
    for _ in 0..200 {
        if fb == 0.0 || (b - a).abs() < 4.0 * f64::EPSILON * (1.0 + b.abs()) {
            return Some(b);
        }
        let mut s = if fa != fc && fb != fc {
            a * fb * fc / ((fa - fb) * (fa - fc)) + b * fa * fc / ((fb - fa) * (fb - fc)) + c * fa * fb / ((fc - fa) * (fc - fb))
        } else {
            b - fb * (b - a) / (fb - fa)
        };
        let lo = (3.0 * a + b) / 4.0;
        let between = if lo < b { s > lo && s < b } else { s > b && s < lo };
        let tol = 2.0 * f64::EPSILON * (1.0 + b.abs());
        if !between
            || (bisected && (s - b).abs() >= (b - c).abs() / 2.0)
            || (!bisected && (s - b).abs() >= (c - d).abs() / 2.0)
            || (bisected && (b - c).abs() < tol)
            || (!bisected && (c - d).abs() < tol)
        {
            s = 0.5 * (a + b);
            bisected = true;
        } else {
            bisected = false;
        }
        let fs = f(s)?;
        d = c;
        c = b;
        fc = fb;
        if fa.signum() != fs.signum() {
            b = s;
            fb = fs;
        } else {
            a = s;
            fa = fs;
        }
        if fa.abs() < fb.abs() {
            std::mem::swap(&mut a, &mut b);
            std::mem::swap(&mut fa, &mut fb);
        }
    }
    Some(b)
}
