//! The adaptive scan of the outer angle: f± sampled at 360 angles per branch, refined where the
//! inner angles swing fast or a root cannot be ruled out, roots bracketed (Brent) or found at
//! dips (golden section). Slow (about 200 µs a pose) but needs no polynomial: the solver's answer
//! near the inner pair's singularity, and where the resultant vanishes identically.

use super::{Residual, brent};
use crate::kinematics::subproblem::Cs;
use crate::kinematics::{Error, wrap};
use arrayvec::ArrayVec;

/// Samples of the outer angle for the root search of the 3-rotary chain; intervals where the
/// inner angles swing fast (near the inner pair's singularity) are subdivided further.
const SAMPLES: usize = 360;
const MAX_DEPTH: u32 = 10;
const SWING: f64 = 0.1; // rad of inner-angle change that asks for a finer look
/// A stretch's scan starts this deep: the stretches the product leaves to it are narrow.
const LOCAL_DEPTH: u32 = 6;

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

/// The roots of f± (outer angle, branch), or why there are none.
pub(super) fn roots(r: &Residual, scale: f64) -> Result<ArrayVec<(f64, i8), 16>, Error> {
    let step = std::f64::consts::TAU / SAMPLES as f64;
    let mut found: ArrayVec<(f64, i8), 16> = ArrayVec::new();
    let mut any_valid = false;
    let mut best_miss = f64::INFINITY;
    let mut closest = f64::INFINITY;
    for sg in [1i8, -1] {
        let at = |k: usize| -std::f64::consts::PI + step * k as f64;
        let seen = |s: &Sample| match s.v {
            Some((f, _)) => {
                any_valid = true;
                closest = closest.min(f.abs());
            }
            None => best_miss = best_miss.min(r.pair.miss(&r.inner(s.a))),
        };
        for a in branch(r, sg, SAMPLES, at, scale, 0, seen) {
            let _ = found.try_push((a, sg));
        }
    }
    if !any_valid {
        return Err(Error::Unreachable { miss: best_miss });
    }
    if found.is_empty() {
        return Err(Error::NoSolution {
            reason: format!(
                "no outer angle keeps the missing {} axis at 0 (closest: {:.6} units away)",
                ['X', 'Y', 'Z'][r.missing],
                closest
            ),
        });
    }
    Ok(found)
}

/// The roots of f on branch `sg` over the stretch [a, b] (where the product's rounding cannot
/// tell its roots).
pub(super) fn local(r: &Residual, sg: i8, a: f64, b: f64, scale: f64) -> ArrayVec<f64, 16> {
    const N: usize = 4;
    branch(r, sg, N, |k| a + (b - a) * k as f64 / N as f64, scale, LOCAL_DEPTH, |_| {})
}

/// One branch scanned from the samples at `at(0..=n)` (increasing), refined between them, each
/// after the first shown to `seen`: its roots that are zeros of f where the pair reaches.
fn branch(r: &Residual, sg: i8, n: usize, at: impl Fn(usize) -> f64, scale: f64, depth0: u32, mut seen: impl FnMut(&Sample)) -> ArrayVec<f64, 16> {
    let reach = |a: f64| r.pair.meet(&r.inner(a)).reach;
    let eval = |a: f64, clamp: bool| r.eval(a, sg, clamp);
    let lever = r.lever(scale);
    let mut scan = Scan {
        eval: &eval,
        reach: &reach,
        leaves: Vec::with_capacity(n + 64),
        lever,
    };
    let mut prev = scan.sample(at(0), false);
    scan.leaves.push(prev);
    for k in 1..=n {
        let cur = scan.sample(at(k), false);
        seen(&cur);
        scan.refine(prev, cur, depth0);
        prev = cur;
    }
    // Keep only true roots: a sign change across a branch discontinuity is not one, nor is a
    // zero of f clamped to the fold inside a gap where the pair cannot reach.
    let tol = 1e-9 * scale;
    scan.roots(tol)
        .into_iter()
        .filter(|&x| eval(x, true).is_some_and(|(f, _, _)| f.abs() <= tol) && r.reachable(x))
        .collect()
}
