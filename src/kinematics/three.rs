//! The 3-rotary / 2-linear chain, where the outer angle is the one unknown. At each outer angle
//! the inner pair meets the orientation on two branches (`γ = ±√D`), and the missing linear's
//! coordinate f±(a) must vanish there. The product `st1⁴ f₊ f₋` is a trigonometric polynomial of
//! degree 8 in the outer angle (odd powers of γ cancel), so 17 samples give it exactly; its
//! roots are isolated with proven bounds, each settled on its own branch and polished in joint
//! space. Where the product is too small for its rounding to tell (a double root; the
//! orientation passing near the inner axis, where the factor `st1⁴` is tiny), the adaptive scan
//! of f± ([`scan`]) searches that stretch; it searches the whole turn where the orientation
//! passes through the inner axis or the product vanishes identically.

mod scan;

use super::fk::rotate;
use super::model::{Chain, Machine};
use super::solver::{IkOptions, Solution, Solutions, controlled_point_cs, push};
use super::subproblem::{Cs, FreeAngle, Meet, Pair};
use super::{Error, Pose, Setup, Vec3, wrap};
use arrayvec::ArrayVec;

/// Degree of the product in the outer angle, and its samples.
const DEGREE: usize = 8;
const NODES: usize = 2 * DEGREE + 1;
/// First sample angle: away from the angles a profile's axes favour (0, ±π/2, π).
const OFFSET: f64 = 0.123_456_789;
/// Intervals of the first pass over the circle.
const GRID: usize = 32;
/// Subdivisions below the grid: 2π/32 / 2³⁰ ≈ 2e-10 rad.
const MAX_DEPTH: u32 = 30;
/// sin² of the closest approach of the orientation to the inner axis below which the scan
/// searches the whole turn: within 3e-5 rad of it the inner angles turn through π within a few
/// µrad of outer angle, finer than a stretch's scan resolves.
const NEAR_INNER_AXIS: f64 = 1e-9;

/// The 1-D problem of one pose: the chain, the orientation and the point to place.
pub(super) struct Residual<'a> {
    m: &'a Machine,
    ch: &'a Chain,
    s0: &'a Vec3,
    pair: &'a Pair,
    missing: usize,
    u: &'a Vec3,
    p_w: Vec3,
    tool_length: f64,
    free: FreeAngle,
}

impl Residual<'_> {
    /// The orientation the inner pair must reach at outer angle `a`.
    fn inner(&self, a: f64) -> Vec3 {
        rotate(self.s0, a.cos(), -a.sin(), self.u)
    }

    /// The missing linear's coordinate with the rotaries at `cs` (sequence order).
    #[inline(always)]
    fn coordinate(&self, cs: [Cs; 3]) -> f64 {
        let mut rcs = [Cs::ZERO; 3];
        for (k, &ri) in self.ch.seq.iter().enumerate() {
            rcs[ri] = cs[k];
        }
        controlled_point_cs(self.m, &rcs, &self.p_w, self.tool_length)[self.missing]
    }

    /// The outer rotation at `a`, the orientation the inner pair must reach, and their meet.
    #[inline(always)]
    fn meet_at(&self, a: f64) -> (Cs, Vec3, Meet) {
        let a0 = Cs::of(a);
        let v = rotate(self.s0, a0.c, -a0.s, self.u);
        (a0, v, self.pair.meet(&v))
    }

    /// f on branch `sg` at outer angle `a`, with the angles; `None` where the inner pair cannot
    /// reach the orientation, unless `clamp` (evaluated on the fold).
    fn eval(&self, a: f64, sg: i8, clamp: bool) -> Option<(f64, [Cs; 3], bool)> {
        let (a0, v, meet) = self.meet_at(a);
        if meet.reach < 0.0 && !clamp {
            return None;
        }
        let (a1, a2, sing) = self.pair.angles(&v, &meet, sg as f64, self.free);
        let cs = [a0, a1, a2];
        Some((self.coordinate(cs), cs, sing))
    }

    /// f on both branches at outer angle `a` (clamped to the fold), sin² θ1 and the pair's reach
    /// there.
    fn branches(&self, a: f64) -> ([f64; 2], f64, f64) {
        let (a0, v, meet) = self.meet_at(a);
        let f = [1.0, -1.0].map(|sg| {
            let (a1, a2, _) = self.pair.angles(&v, &meet, sg, self.free);
            self.coordinate([a0, a1, a2])
        });
        (f, meet.st1() * meet.st1(), meet.reach)
    }

    /// f on branch `sg` at outer angle `a` (clamped to the fold), and the pair's reach there.
    fn clamped(&self, a: f64, sg: i8) -> (f64, f64) {
        let (a0, v, meet) = self.meet_at(a);
        let (a1, a2, _) = self.pair.angles(&v, &meet, sg as f64, self.free);
        (self.coordinate([a0, a1, a2]), meet.reach)
    }

    /// Whether the inner pair reaches the orientation at outer angle `a` (on the fold to
    /// rounding): a zero of f clamped to the fold inside a gap of reach is not a solution.
    fn reachable(&self, a: f64) -> bool {
        reaches(self.pair.meet(&self.inner(a)).reach)
    }

    /// `st1⁴ f₊ f₋` at outer angle `a0`, also where the branches are complex (D < 0), from f
    /// at γ = 0 and ±st1 (f is quadratic in γ); `None` where the orientation lies on the inner
    /// axis.
    fn product(&self, a0: Cs) -> Option<f64> {
        let v = rotate(self.s0, a0.c, -a0.s, self.u);
        let fm = self.pair.formal(&v);
        if !(fm.st2 > 1e-200) {
            return None;
        }
        let h = fm.st2.sqrt();
        let at = |g: f64| {
            let (a1, a2) = fm.angles(g);
            self.coordinate([a0, a1, a2])
        };
        let (f0, fp, fm_) = (at(0.0), at(h), at(-h));
        let (q1, q2) = (0.5 * (fp - fm_), 0.5 * (fp + fm_) - f0);
        let rho = fm.d / fm.st2; // sin² A
        let p = f0 + q2 * rho;
        let g = if rho >= 0.0 {
            let r = q1 * rho.sqrt();
            (p + r) * (p - r)
        } else {
            p * p - q1 * q1 * rho
        };
        Some(g * fm.st2 * fm.st2)
    }

    /// sin² of the orientation's closest approach to the inner axis (toward +s1 or −s1) over a
    /// turn of the outer rotary (`s1·v(a) = α + β cos a − γ sin a`).
    fn nearest_inner_axis(&self) -> f64 {
        let (s0, s1, u) = (self.s0, &self.pair.s1, self.u);
        let alpha = s1.dot(s0) * s0.dot(u);
        let (beta, gamma) = (s1.dot(u) - alpha, s1.dot(&s0.cross(u)));
        let m = (alpha.abs() + beta.hypot(gamma)).min(1.0);
        (1.0 - m) * (1.0 + m)
    }
}

#[allow(clippy::too_many_arguments)]
pub(super) fn three(
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
    let r = Residual {
        m,
        ch,
        s0,
        pair,
        missing,
        u,
        p_w: pose.tip + setup.work_offset,
        tool_length: setup.tool_length,
        free,
    };
    let scale = 1.0 + r.p_w.norm() + setup.tool_length.abs();
    let mut found = match resultant_roots(&r, scale) {
        Some(found) if !found.is_empty() => found,
        _ => scan::roots(&r, scale)?,
    };
    found.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut count = 0u8;
    let first = out.len();
    for (a, sg) in found {
        let (a0, v, meet) = r.meet_at(a);
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
        push(m, out, pose, setup, &ch.seq, [a0, a1, a2], None, branch, count, sing);
        if let Some(s) = out.last_mut() {
            polish(m, pose, setup, s);
        }
        // Next to the inner axis the rounding can split one root of f in two, a hair apart: one
        // solution, the one that reproduces the pose better.
        let n = out.len();
        if let Some(k) = (first..n.saturating_sub(1)).find(|&k| {
            (0..3).all(|i| wrap(out[k].actual[i] - out[n - 1].actual[i]).abs() < 1e-7)
        }) {
            if miss(m, pose, setup, &out[n - 1]) < miss(m, pose, setup, &out[k]) {
                out.swap(k, n - 1);
            }
            out.pop();
            continue;
        }
        count += 1;
    }
    Ok(())
}

/// How far a solution's pose is from the one wanted: tip distance plus axis angle (rad).
fn miss(m: &Machine, pose: &Pose, setup: &Setup, s: &Solution) -> f64 {
    let (dt, da) = pose_error(m, &s.joints.linear, &s.actual, pose, setup);
    dt.norm() + da.norm()
}

/// The tip's and the axis's errors of the joints' pose against the one wanted.
fn pose_error(m: &Machine, linear: &[f64; 3], actual: &[f64; 3], pose: &Pose, setup: &Setup) -> (Vec3, Vec3) {
    let p = super::fk::fk_actual(m, linear, actual, setup);
    (p.tip - pose.tip, p.axis - pose.axis.normalize())
}

/// The roots of f± (outer angle, branch) through the product's roots; `None` where the scan must
/// search instead.
fn resultant_roots(r: &Residual, scale: f64) -> Option<ArrayVec<(f64, i8), 16>> {
    if r.nearest_inner_axis() < NEAR_INNER_AXIS {
        return None;
    }
    let poly = Trig::interpolate(|a0| r.product(a0))?;
    let iso = poly.isolate()?;
    let mut found: ArrayVec<(f64, i8), 16> = ArrayVec::new();
    let mut add = |a: f64, sg: i8| {
        let a = wrap(a);
        if !found.iter().any(|&(b, s)| s == sg && wrap(a - b).abs() < 1e-9) {
            found.try_push((a, sg)).ok()
        } else {
            Some(())
        }
    };
    // Where the product's rounding hides how many roots there are (a double root; the
    // orientation near the inner axis, where its factor st1⁴ is tiny), the scan of f± searches.
    let mut scans: ArrayVec<(f64, f64), 64> = iso.unsure.iter().copied().collect();
    for &(x, slope, lo, hi) in &iso.roots {
        let mut got = settled(r, x, slope, (lo, hi), scale);
        if got.is_empty() {
            // Next to a fold f± turns like √reach, so the polynomial's root (rounded to the
            // product's largest values) can sit where f is far from zero: bracket the product
            // itself, smooth across the fold and rounded to its own size.
            let g = |x: f64| r.product(Cs::of(x)).unwrap_or(0.0);
            let (gl, gh) = (g(lo), g(hi));
            if gl.signum() != gh.signum()
                && let Some(x) = brent(|x| Some(g(x)), lo, hi, gl, gh)
            {
                got = settled(r, x, f64::NAN, (lo, hi), scale);
            }
        }
        if got.is_empty() {
            scans.try_push((lo, hi)).ok()?;
        }
        for (a, sg) in got {
            add(a, sg)?;
        }
    }
    for &(lo, hi) in &scans {
        for sg in [1i8, -1] {
            for a in scan::local(r, sg, lo - 1e-9, hi + 1e-9, scale) {
                add(a, sg)?;
            }
        }
    }
    Some(found)
}

/// Whether branch `k` of f = [f₊, f₋] is the one a root of the product belongs to: the one
/// nearer zero, or both on the fold.
fn vanishes(f: &[f64; 2], k: usize, scale: f64) -> bool {
    f[k].abs() <= f[1 - k].abs() || f[k].abs() <= 1e-6 * scale
}

/// The roots of f± at a root `x` of the product alone in (lo, hi): the branch nearer zero (both
/// on the fold), settled; `slope`: the product's g' at x, or NaN.
fn settled(r: &Residual, x: f64, slope: f64, (lo, hi): (f64, f64), scale: f64) -> ArrayVec<(f64, i8), 2> {
    let (f, st2, reach) = r.branches(x);
    let mut out = ArrayVec::new();
    for (k, sg) in [1i8, -1].into_iter().enumerate() {
        if !vanishes(&f, k, scale) {
            continue;
        }
        // f's slope there, from the product's: g' = st1⁴ f' f_other where f = 0.
        let other = f[1 - k];
        let d = if other.abs() > 1e-6 * scale {
            slope / (st2 * st2 * other)
        } else {
            f64::NAN
        };
        let (a, fa, reach) = settle(|a| r.clamped(a, sg), x, (f[k], reach), d, (lo, hi), scale);
        if fa.abs() <= 1e-9 * scale && reaches(reach) {
            out.push((a, sg));
        }
    }
    out
}

/// Newton's step on f from a root of the product, then secant steps, within the interval that
/// holds the root alone: the product's rounding (its coefficients carry that of every sample)
/// can leave its root a few ulps of the product away from f's. `slope`: f' at x, or NaN; `f`
/// gives f and something else of the point (`px` at x), returned with the point settled on.
fn settle<P: Copy>(f: impl Fn(f64) -> (f64, P), x: f64, (fx, px): (f64, P), slope: f64, (lo, hi): (f64, f64), scale: f64) -> (f64, f64, P) {
    let (mut x, mut fx, mut px, mut d) = (x, fx, px, slope);
    for _ in 0..4 {
        if !(fx.abs() > 1e-14 * scale) {
            break;
        }
        if !(d.is_finite() && d != 0.0) {
            let h = 1e-8 * (1.0 + x.abs());
            d = (f(x + h).0 - fx) / h;
        }
        let xn = x - fx / d;
        if !(lo..=hi).contains(&xn) {
            break;
        }
        let (fn_, pn) = f(xn);
        if fn_.abs() >= fx.abs() {
            break;
        }
        d = (fn_ - fx) / (xn - x);
        (x, fx, px) = (xn, fn_, pn);
    }
    (x, fx, px)
}

/// Whether the pair's reach is that of an orientation it reaches (on the fold to rounding).
fn reaches(reach: f64) -> bool {
    reach >= -1e-14
}

/// `g(x) = a₀ + Σ aₖ cos kx + bₖ sin kx`, k = 1..=8.
struct Trig {
    a: [f64; DEGREE + 1],
    b: [f64; DEGREE + 1],
    /// Σ k³(|aₖ| + |bₖ|): bounds |g‴|, so that |g''| near a point is bounded by its value
    /// there (the product's size varies by orders over the circle: a global bound on g'' would
    /// prove nothing where it is small).
    jerk: f64,
    /// Σ k⁴(|aₖ| + |bₖ|): bounds |g⁗|, so that |g‴| near a point is bounded by its value there
    /// (in the valley the factor st1⁴ digs, every derivative is small but `jerk` is not).
    snap: f64,
    /// Σ k⁵(|aₖ| + |bₖ|): bounds the fifth derivative, so that |g⁗| near a point is bounded by
    /// its value there, the same way.
    crackle: f64,
    /// The bound on how wrong a computed g is.
    noise: f64,
}

/// A point of the circle with g and its first four derivatives there.
#[derive(Clone, Copy)]
struct At {
    x: f64,
    z: Cs,
    g: f64,
    d: f64,
    e: f64,
    j: f64,
    four: f64,
}

impl Trig {
    /// The polynomial through `NODES` equally spaced samples (exact for degree ≤ 8).
    fn interpolate(g: impl Fn(Cs) -> Option<f64>) -> Option<Trig> {
        let (mut a, mut b) = ([0.0; DEGREE + 1], [0.0; DEGREE + 1]);
        let mut sum = 0.0;
        for zk in NODE_POWERS.iter() {
            let gj = g(zk[1])?;
            if !gj.is_finite() {
                return None;
            }
            sum += gj.abs();
            for k in 0..=DEGREE {
                a[k] += gj * zk[k].c;
                b[k] += gj * zk[k].s;
            }
        }
        a[0] /= NODES as f64;
        b[0] = 0.0;
        for k in 1..=DEGREE {
            a[k] *= 2.0 / NODES as f64;
            b[k] *= 2.0 / NODES as f64;
        }
        let size: f64 = (0..=DEGREE).map(|k| a[k].abs() + b[k].abs()).sum();
        // A product that is rounding only: f± vanishes identically (the scan's case).
        if !(size > 1e-12 * sum / NODES as f64) {
            return None;
        }
        Some(Trig {
            a,
            b,
            jerk: (1..=DEGREE).map(|k| (k * k * k) as f64 * (a[k].abs() + b[k].abs())).sum(),
            snap: (1..=DEGREE).map(|k| (k * k * k * k) as f64 * (a[k].abs() + b[k].abs())).sum(),
            crackle: (1..=DEGREE).map(|k| (k * k * k * k * k) as f64 * (a[k].abs() + b[k].abs())).sum(),
            noise: 2e-14 * (size + sum),
        })
    }

    /// g and its derivatives at the point `z` = (cos x, sin x).
    #[inline]
    fn at(&self, x: f64, z: Cs) -> At {
        self.at_powers(x, &powers(z))
    }

    /// As [`Trig::at`], from the powers `z¹ … z⁸` (a grid point's are a table's).
    #[inline]
    fn at_powers(&self, x: f64, zk: &[Cs; DEGREE + 1]) -> At {
        let (mut g, mut d, mut e, mut j, mut four) = (self.a[0], 0.0, 0.0, 0.0, 0.0);
        for k in 1..=DEGREE {
            let (c, s) = (self.a[k] * zk[k].c + self.b[k] * zk[k].s, self.b[k] * zk[k].c - self.a[k] * zk[k].s);
            let k = k as f64;
            g += c;
            d += k * s;
            e -= k * k * c;
            j -= k * k * k * s;
            four += k * k * k * k * c;
        }
        At { x, z: zk[1], g, d, e, j, four }
    }

    /// The one root between `p` and `q`, where g is proven monotone: Newton's steps, bisecting
    /// whenever a step would leave the bracket. Each point's (cos, sin) is its neighbour's turned
    /// by the step ([`turn_small`]), or the bracket's chord midpoint: no sincos.
    fn newton(&self, p: At, q: At) -> (f64, f64) {
        let (mut lo, mut hi) = (p, q);
        let mut x = p.x - p.g * (q.x - p.x) / (q.g - p.g);
        let mut z = turn_small(p.z, x - p.x);
        let mut d = p.d;
        for _ in 0..32 {
            let a = self.at(x, z);
            d = a.d;
            if a.g.abs() <= self.noise {
                return (x, d);
            }
            if a.g.signum() == lo.g.signum() {
                lo = a;
            } else {
                hi = a;
            }
            let (l, r) = (lo.x.min(hi.x), lo.x.max(hi.x));
            let mut next = x - a.g / a.d;
            if next > l && next < r {
                z = turn_small(a.z, next - x);
            } else {
                next = 0.5 * (l + r);
                z = chord_mid(lo.z, hi.z);
            }
            if (next - x).abs() <= 4.0 * f64::EPSILON * (1.0 + x.abs()) {
                return (next, d);
            }
            x = next;
        }
        (x, d)
    }

    /// Every root on the circle, by subdivision: an interval is dropped where the bound on g''
    /// proves g keeps its sign, and bracketed where it proves g monotone; where neither is
    /// proven once the bound is down to rounding, the interval is unsure (a double root, roots
    /// closer than rounding tells apart, or none). `None` past 32 of either.
    fn isolate(&self) -> Option<Isolated<'_>> {
        let mut out = Isolated {
            t: self,
            roots: ArrayVec::new(),
            unsure: ArrayVec::new(),
        };
        let step = std::f64::consts::TAU / GRID as f64;
        let first = self.at_powers(OFFSET, &GRID_POWERS[0]);
        let mut prev = first;
        for i in 1..=GRID {
            // The circle closes on the first point.
            let cur = if i == GRID {
                At {
                    x: OFFSET + std::f64::consts::TAU,
                    ..first
                }
            } else {
                self.at_powers(OFFSET + step * i as f64, &GRID_POWERS[i])
            };
            out.interval(prev, cur, 0)?;
            prev = cur;
        }
        Some(out)
    }
}

/// `z⁰ … z⁸`, by products in a tree (four deep, not a chain of eight).
#[inline(always)]
fn powers(z: Cs) -> [Cs; DEGREE + 1] {
    let z2 = mul(z, z);
    let (z3, z4) = (mul(z2, z), mul(z2, z2));
    [Cs::ZERO, z, z2, z3, z4, mul(z4, z), mul(z4, z2), mul(z4, z3), mul(z4, z4)]
}

/// The powers at the sample angles and at the grid's points: the same for every pose.
static NODE_POWERS: std::sync::LazyLock<[[Cs; DEGREE + 1]; NODES]> = std::sync::LazyLock::new(circle);
static GRID_POWERS: std::sync::LazyLock<[[Cs; DEGREE + 1]; GRID]> = std::sync::LazyLock::new(circle);

/// The powers at `N` equally spaced angles from [`OFFSET`].
fn circle<const N: usize>() -> [[Cs; DEGREE + 1]; N] {
    std::array::from_fn(|i| powers(Cs::of(OFFSET + std::f64::consts::TAU * i as f64 / N as f64)))
}

/// The midpoint of the arc between two points of the unit circle (less than a half turn apart):
/// the normalised sum of its ends.
#[inline]
fn chord_mid(p: Cs, q: Cs) -> Cs {
    let (c, s) = (p.c + q.c, p.s + q.s);
    let n = 1.0 / (c * c + s * s).sqrt();
    Cs { c: c * n, s: s * n }
}

/// `z` turned by `h` (|h| ≤ 0.2, within a grid interval): cos h and sin h by their Taylor series
/// to h¹⁴ and h¹³, whose next terms are below 1e-22 there.
#[inline]
fn turn_small(z: Cs, h: f64) -> Cs {
    debug_assert!(h.abs() <= 0.2, "{h}");
    const S: [f64; 7] = [1.0, -1.0 / 6.0, 1.0 / 120.0, -1.0 / 5040.0, 1.0 / 362_880.0, -1.0 / 39_916_800.0, 1.0 / 6_227_020_800.0];
    const C: [f64; 8] = [
        1.0,
        -1.0 / 2.0,
        1.0 / 24.0,
        -1.0 / 720.0,
        1.0 / 40_320.0,
        -1.0 / 3_628_800.0,
        1.0 / 479_001_600.0,
        -1.0 / 87_178_291_200.0,
    ];
    let h2 = h * h;
    let s = h * S.iter().rev().fold(0.0, |acc, k| acc * h2 + k);
    let c = C.iter().rev().fold(0.0, |acc, k| acc * h2 + k);
    mul(z, Cs { c, s })
}

/// (cos, sin) of the sum of two angles.
#[inline(always)]
fn mul(p: Cs, q: Cs) -> Cs {
    Cs {
        c: p.c * q.c - p.s * q.s,
        s: p.c * q.s + p.s * q.c,
    }
}

/// What the isolation found.
struct Isolated<'a> {
    t: &'a Trig,
    /// A root, g' there, and an interval that holds it and no other.
    roots: ArrayVec<(f64, f64, f64, f64), 32>,
    /// Intervals where rounding hides how many roots there are (adjacent ones merged).
    unsure: ArrayVec<(f64, f64), 32>,
}

impl Isolated<'_> {
    fn unsure(&mut self, lo: f64, hi: f64) -> Option<()> {
        match self.unsure.last_mut() {
            Some(last) if lo <= last.1 + 1e-12 => last.1 = hi,
            _ => self.unsure.try_push((lo, hi)).ok()?,
        }
        Some(())
    }

    fn interval(&mut self, p: At, q: At, depth: u32) -> Option<()> {
        let h = q.x - p.x;
        let noise = self.t.noise;
        // The coefficients' rounding (at most `noise` summed) reaches the n-th derivative 8ⁿ-fold.
        let (slope_noise, curve_noise) = (8.0 * noise, 64.0 * noise);
        // |g''''| on the interval: g'''' leaves each end at most at the rate `crackle`, so it
        // stays within the tent of the two ends' values; or `snap`, where that is less.
        let crackle = self.t.crackle + 32768.0 * noise;
        let snap = (0.5 * (p.four + q.four).abs() + 0.5 * crackle * h).min(self.t.snap) + 4096.0 * noise;
        // |g'''| on the interval: within the tent of the two ends' values, the same way.
        let jerk = (0.5 * (p.j + q.j).abs() + 0.5 * snap * h).min(self.t.jerk) + 512.0 * noise;
        // |g''| on the interval: within the tent of the two ends' values, the same way.
        let c = 0.5 * (p.e + q.e).abs() + 0.5 * jerk * h + curve_noise;
        // A zero at the left end is a root whose interval is its neighbourhood.
        let s0 = if p.g == 0.0 {
            self.roots.try_push((p.x, p.d, p.x - h, q.x)).ok()?;
            p.d.signum()
        } else {
            p.g.signum()
        };
        let change = s0 != q.g.signum() && q.g != 0.0;
        let bend = 0.125 * c * h * h;
        if change {
            if p.d.signum() == q.d.signum() && p.d.abs().min(q.d.abs()) - slope_noise > 0.5 * c * h {
                let (r, d) = self.t.newton(p, q);
                return self.roots.try_push((r, d, p.x, q.x)).ok();
            }
        } else {
            // |g| from below: the chord less the bend, or on each half the tangent at its end
            // less the bend (each half's bound is concave: least at the half's ends).
            let (g0, g1) = (s0 * p.g, s0 * q.g);
            let tangents = g0
                .min(g1)
                .min(g0 + (s0 * p.d - slope_noise) * 0.5 * h - bend)
                .min(g1 - (s0 * q.d + slope_noise) * 0.5 * h - bend);
            if tangents.max(g0.min(g1) - bend) > noise {
                return Some(());
            }
        }
        if bend <= noise || depth >= MAX_DEPTH {
            return self.unsure(p.x, q.x);
        }
        let mid = self.t.at(0.5 * (p.x + q.x), chord_mid(p.z, q.z));
        self.interval(p, mid, depth + 1)?;
        self.interval(mid, q, depth + 1)
    }
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
        let (dt, da) = pose_error(m, &l, &a, pose, setup);
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

#[cfg(test)]
mod tests;
