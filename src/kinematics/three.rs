//! The 3-rotary / 2-linear chain, where the outer angle is the one unknown. At each outer angle
//! the inner pair meets the orientation on two branches (`γ = ±√D`), and the missing linear's
//! coordinate f±(a) must vanish there. The product `st1⁴ f₊ f₋` is a trigonometric polynomial of
//! degree 8 in the outer angle (odd powers of γ cancel), so 17 samples give it exactly; its
//! roots are isolated with proven bounds, each settled on its own branch and polished in joint
//! space. Where the product is too small for its rounding to tell (a double root; the
//! orientation passing near the inner axis, where the factor `st1⁴` is tiny), the adaptive scan
//! of f± ([`scan`]) searches that stretch; it searches the whole turn where the orientation
//! passes through the inner axis or the product vanishes identically.

mod circle;
mod scan;

use super::fk::rotate;
use super::model::{Form, Machine, TERMS};
use super::solution::{Found, IkOptions, Solution, Solutions, push};
use super::subproblem::{Cs, FreeAngle, Meet, Pair};
use super::{Error, Pose, Setup, Vec3, wrap};
use arrayvec::ArrayVec;
use circle::{chord_mid, mul, turn, turn_small, unit};
use wide::f64x2;

/// Degree of the product in the outer angle, and its samples.
const DEGREE: usize = 8;
const NODES: usize = 2 * DEGREE + 1;
/// First sample angle: away from the angles a profile's axes favour (0, ±π/2, π).
const OFFSET: f64 = 0.123_456_789;
/// Intervals of the first pass over the circle (fewer take more subdivisions, more take more
/// intervals that hold nothing: 20 is the least work on the bench's poses).
const GRID: usize = 20;
/// Subdivisions below the grid: 2π/20 / 2³⁰ ≈ 3e-10 rad.
const MAX_DEPTH: u32 = 30;
/// sin² of the closest approach of the orientation to the inner axis below which the scan
/// searches the whole turn: within 3e-5 rad of it the inner angles turn through π within a few
/// µrad of outer angle, finer than a stretch's scan resolves.
const NEAR_INNER_AXIS: f64 = 1e-9;

/// The 1-D problem of one pose: the chain, the orientation and the point to place.
pub(super) struct Residual<'a> {
    m: &'a Machine,
    s0: &'a Vec3,
    pair: &'a Pair,
    missing: usize,
    u: &'a Vec3,
    /// The missing linear's coordinate at this pose's tip and tool length: [`Form`]'s terms.
    terms: [f64; TERMS],
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
        contract(&contract_outer(&self.terms, cs[0]), cs[1], cs[2])
    }

    /// The orientation the inner pair must reach with the outer rotation at `a0`, and its meet.
    #[inline(always)]
    fn meet_at(&self, a0: Cs) -> (Vec3, Meet) {
        let v = rotate(self.s0, a0.c, -a0.s, self.u);
        (v, self.pair.meet(&v))
    }

    /// f on branch `sg` at outer angle `a`, with the angles; `None` where the inner pair cannot
    /// reach the orientation, unless `clamp` (evaluated on the fold).
    fn eval(&self, a: f64, sg: i8, clamp: bool) -> Option<(f64, [Cs; 3], bool)> {
        let a0 = Cs::of(a);
        let (v, meet) = self.meet_at(a0);
        if meet.reach < 0.0 && !clamp {
            return None;
        }
        let (a1, a2, sing) = self.pair.angles(&v, &meet, sg as f64, self.free);
        let cs = [a0, a1, a2];
        Some((self.coordinate(cs), cs, sing))
    }

    /// f on both branches with the outer rotation at `a0` (clamped to the fold), sin² θ1 and the
    /// pair's reach there.
    fn branches(&self, a0: Cs) -> ([f64; 2], f64, f64) {
        let (v, meet) = self.meet_at(a0);
        let outer = contract_outer(&self.terms, a0);
        let on = |sg: f64| {
            let (a1, a2, _) = self.pair.angles(&v, &meet, sg, self.free);
            contract(&outer, a1, a2)
        };
        ([on(1.0), on(-1.0)], meet.st1() * meet.st1(), meet.reach)
    }

    /// f on branch `sg` with the outer rotation at `a0` (clamped to the fold), and the pair's
    /// reach there.
    fn clamped(&self, a0: Cs, sg: i8) -> (f64, f64) {
        let (v, meet) = self.meet_at(a0);
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
        let inner = contract_outer(&self.terms, a0);
        let at = |g: f64| {
            let (a1, a2) = fm.angles(g);
            contract(&inner, a1, a2)
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

    /// The longest lever arm of the chain: bounds how far the tip moves per radian of any angle.
    fn lever(&self, scale: f64) -> f64 {
        scale + self.m.rotaries.iter().map(|r| r.pivot.norm()).sum::<f64>()
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

/// The terms with the outer rotary at `a0`: a form in the inner two.
#[inline(always)]
fn contract_outer(t: &[f64; TERMS], a0: Cs) -> [f64; 9] {
    let mut out = [0.0; 9];
    for (i, o) in out.iter_mut().enumerate() {
        *o = t[i] + t[i + 9] * a0.c + t[i + 18] * a0.s;
    }
    out
}

/// The form in the inner two at `a1`, `a2`.
#[inline(always)]
fn contract(t: &[f64; 9], a1: Cs, a2: Cs) -> f64 {
    let row = |i: usize| t[i] + t[i + 1] * a2.c + t[i + 2] * a2.s;
    row(0) + row(3) * a1.c + row(6) * a1.s
}

/// A three-rotary chain's shape, as the chain holds it (`Shape::Three`).
pub(super) struct Three<'a> {
    pub(super) s0: &'a Vec3,
    pub(super) pair: &'a Pair,
    pub(super) missing: usize,
    pub(super) form: &'a Form,
}

/// Every solution of `pose` on a three-rotary chain: the outer angle at each root of the
/// missing linear's residual, the inner two by subproblem 2.
pub(super) fn three(m: &Machine, shape: &Three, u: &Vec3, pose: &Pose, setup: &Setup, opt: &IkOptions, out: &mut Solutions) -> Result<(), Error> {
    let Three { s0, pair, missing, form } = *shape;
    let (ch, free) = (&m.chain, FreeAngle(opt.free_angle));
    let p_w = pose.tip + setup.work_offset;
    let r = Residual {
        m,
        s0,
        pair,
        missing,
        u,
        terms: form.at(&p_w, setup.tool_length),
        free,
    };
    let scale = 1.0 + p_w.norm() + setup.tool_length.abs();
    let mut found = match resultant_roots(&r, scale) {
        Some(found) if !found.is_empty() => found,
        _ => scan::roots(&r, scale)?.into_iter().map(|(a, sg)| (a, Cs::of(a), sg)).collect(),
    };
    found.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut count = 0u8;
    let first = out.len();
    let lever = r.lever(scale);
    for (a, a0, sg) in found {
        let (v, meet) = r.meet_at(a0);
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
        let found = Found {
            branch,
            root: count,
            singular: sing,
            ..Found::of([a0, a1, a2])
        };
        push(m, out, pose, setup, &ch.seq, found);
        if built_miss(&r, [a0, a1, a2], lever) > 1e-13 * (1.0 + pose.tip.norm() + setup.tool_length.abs())
            && let Some(s) = out.last_mut()
        {
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

/// How far the rotations `cs` (sequence order) with the linears they give miss the pose, by the
/// arithmetic that built them, in tip units: the linears place the tip exactly for these
/// (cos, sin) but for the missing coordinate, so the miss is that coordinate plus the longest
/// lever `lever` times the angles the orientation is off by: the axis the rotations turn z to,
/// and how far a (cos, sin) is off the circle (the solution's angle is its direction). Where it
/// is at rounding the polish has nothing to correct, and its FK (three sincos and the chain) is
/// not run.
fn built_miss(r: &Residual, cs: [Cs; 3], lever: f64) -> f64 {
    let z = Vec3::z();
    let inner = rotate(&r.pair.s2, cs[2].c, cs[2].s, &z);
    let axis = rotate(r.s0, cs[0].c, cs[0].s, &rotate(&r.pair.s1, cs[1].c, cs[1].s, &inner));
    let off_circle: f64 = cs.iter().map(|z| (z.c * z.c + z.s * z.s - 1.0).abs()).sum();
    r.coordinate(cs).abs() + lever * ((axis - r.u).norm() + off_circle)
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
fn resultant_roots(r: &Residual, scale: f64) -> Option<ArrayVec<(f64, Cs, i8), 16>> {
    if r.nearest_inner_axis() < NEAR_INNER_AXIS {
        return None;
    }
    let poly = Trig::interpolate(|a0| r.product(a0))?;
    let iso = poly.isolate()?;
    let mut found: ArrayVec<(f64, Cs, i8), 16> = ArrayVec::new();
    let mut add = |a: f64, z: Cs, sg: i8| {
        let a = wrap(a);
        if !found.iter().any(|&(b, _, s)| s == sg && wrap(a - b).abs() < 1e-9) {
            found.try_push((a, z, sg)).ok()
        } else {
            Some(())
        }
    };
    // Where the product's rounding hides how many roots there are (a double root; the
    // orientation near the inner axis, where its factor st1⁴ is tiny), the scan of f± searches.
    let mut scans: ArrayVec<(f64, f64), 64> = iso.unsure.iter().copied().collect();
    for &(x, z, slope, lo, hi) in &iso.roots {
        let mut got = settled(r, x, z, slope, (lo, hi), scale);
        if got.is_empty() {
            // Next to a fold f± turns like √reach, so the polynomial's root (rounded to the
            // product's largest values) can sit where f is far from zero: bracket the product
            // itself, smooth across the fold and rounded to its own size.
            let g = |x: f64| r.product(Cs::of(x)).unwrap_or(0.0);
            let (gl, gh) = (g(lo), g(hi));
            if gl.signum() != gh.signum()
                && let Some(x) = brent(|x| Some(g(x)), lo, hi, gl, gh)
            {
                got = settled(r, x, Cs::of(x), f64::NAN, (lo, hi), scale);
            }
        }
        if got.is_empty() {
            scans.try_push((lo, hi)).ok()?;
        }
        for (a, z, sg) in got {
            add(a, z, sg)?;
        }
    }
    for &(lo, hi) in &scans {
        for sg in [1i8, -1] {
            for a in scan::local(r, sg, lo - 1e-9, hi + 1e-9, scale) {
                add(a, Cs::of(a), sg)?;
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

/// The roots of f± at a root `x` (`z` its cos, sin) of the product alone in (lo, hi): the branch
/// nearer zero (both on the fold), settled; `slope`: the product's g' at x, or NaN.
fn settled(r: &Residual, x: f64, z: Cs, slope: f64, (lo, hi): (f64, f64), scale: f64) -> ArrayVec<(f64, Cs, i8), 2> {
    // On the circle to rounding: the turns that carried z here each left an ulp or so, and a
    // (cos, sin) off the circle tilts the orientation the inner pair is asked to reach.
    let z = unit(z);
    let (f, st2, reach) = r.branches(z);
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
        let (a, za, fa, reach) = settle(|z| r.clamped(z, sg), (x, z), (f[k], reach), d, (lo, hi), scale);
        if fa.abs() <= 1e-9 * scale && reaches(reach) {
            out.push((a, za, sg));
        }
    }
    out
}

/// Newton's step on f from a root of the product, then secant steps, within the interval that
/// holds the root alone: the product's rounding (its coefficients carry that of every sample)
/// can leave its root a few ulps of the product away from f's. `slope`: f' at x, or NaN; `f`
/// gives f and something else of the point (`px` at x) from its (cos, sin), returned with the
/// point settled on. Each point's (cos, sin) is its neighbour's turned by the step.
fn settle<P: Copy>(f: impl Fn(Cs) -> (f64, P), (x, z): (f64, Cs), (fx, px): (f64, P), slope: f64, (lo, hi): (f64, f64), scale: f64) -> (f64, Cs, f64, P) {
    let (mut x, mut z, mut fx, mut px, mut d) = (x, z, fx, px, slope);
    for _ in 0..8 {
        if !(fx.abs() > 1e-14 * scale) {
            break;
        }
        if !(d.is_finite() && d != 0.0) {
            let h = 1e-8 * (1.0 + x.abs());
            d = (f(turn(z, h)).0 - fx) / h;
        }
        let xn = x - fx / d;
        if !(lo..=hi).contains(&xn) {
            break;
        }
        let zn = turn(z, xn - x);
        let (fn_, pn) = f(zn);
        if fn_.abs() >= fx.abs() {
            break;
        }
        d = (fn_ - fx) / (xn - x);
        (x, z, fx, px) = (xn, zn, fn_, pn);
    }
    (x, z, fx, px)
}

/// Whether the pair's reach is that of an orientation it reaches (on the fold to rounding).
fn reaches(reach: f64) -> bool {
    reach >= -1e-14
}

/// `g(x) = a₀ + Σ aₖ cos kx + bₖ sin kx`, k = 1..=8.
struct Trig {
    a0: f64,
    /// aₖ and bₖ at index k − 1.
    a: [f64; DEGREE],
    b: [f64; DEGREE],
    /// Σ k³(|aₖ| + |bₖ|): bounds |g‴|, so that |g''| near a point is bounded by its value
    /// there (the product's size varies by orders over the circle: a global bound on g'' would
    /// prove nothing where it is small).
    jerk: f64,
    /// Σ k⁴(|aₖ| + |bₖ|): bounds |g⁗|, so that |g‴| near a point is bounded by its value there
    /// (in the valley the factor st1⁴ digs, every derivative is small but `jerk` is not).
    snap: f64,
    /// Σ k⁵(|aₖ| + |bₖ|) plus the coefficients' rounding there (8⁵ `noise`): bounds the fifth
    /// derivative of the computed g, so that |g⁗| near a point is bounded by its value there, the
    /// same way.
    crackle: f64,
    /// The bound on how wrong a computed g is.
    noise: f64,
    /// ... and its n-th derivative: the coefficients' rounding (at most `noise` summed) reaches
    /// it 8ⁿ-fold.
    noise_at: [f64; 5],
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
        let (mut a0, mut a, mut b) = (0.0, [0.0; DEGREE], [0.0; DEGREE]);
        let mut sum = 0.0;
        for zk in NODE_POWERS.iter() {
            let gj = g(zk.first())?;
            if !gj.is_finite() {
                return None;
            }
            sum += gj.abs();
            a0 += gj;
            for k in 0..DEGREE {
                a[k] += gj * zk.c[k];
                b[k] += gj * zk.s[k];
            }
        }
        a0 /= NODES as f64;
        for k in 0..DEGREE {
            a[k] *= 2.0 / NODES as f64;
            b[k] *= 2.0 / NODES as f64;
        }
        let size: f64 = a0.abs() + (0..DEGREE).map(|k| a[k].abs() + b[k].abs()).sum::<f64>();
        // A product that is rounding only: f± vanishes identically (the scan's case).
        if !(size > 1e-12 * sum / NODES as f64) {
            return None;
        }
        let noise = 2e-14 * (size + sum);
        let weighed = |n: i32| (0..DEGREE).map(|k| ((k + 1) as f64).powi(n) * (a[k].abs() + b[k].abs())).sum::<f64>();
        Some(Trig {
            a0,
            a,
            b,
            jerk: weighed(3),
            snap: weighed(4),
            crackle: weighed(5) + 32768.0 * noise,
            noise,
            noise_at: std::array::from_fn(|n| 8f64.powi(n as i32) * noise),
        })
    }

    /// g and its derivatives at the point `z` = (cos x, sin x).
    #[inline]
    fn at(&self, x: f64, z: Cs) -> At {
        self.at_powers(x, &powers(z))
    }

    /// As [`Trig::at`], from the powers `z¹ … z⁸` (a grid point's are a table's).
    #[inline]
    fn at_powers(&self, x: f64, zk: &Powers) -> At {
        // Terms k and k + 1 side by side: g, g″ and g⁗ weigh the terms u, g′ and g‴ the terms v.
        let mut acc = [f64x2::ZERO; 5];
        for k in (0..DEGREE).step_by(2) {
            let (u, v) = self.terms(zk, k);
            acc[0] = acc[0] + u;
            acc[1] = acc[1] + lanes(&WEIGHT[1], k) * v;
            acc[2] = acc[2] + lanes(&WEIGHT[2], k) * u;
            acc[3] = acc[3] + lanes(&WEIGHT[3], k) * v;
            acc[4] = acc[4] + lanes(&WEIGHT[4], k) * u;
        }
        At {
            x,
            z: zk.first(),
            g: self.a0 + acc[0].reduce_add(),
            d: acc[1].reduce_add(),
            e: -acc[2].reduce_add(),
            j: -acc[3].reduce_add(),
            four: acc[4].reduce_add(),
        }
    }

    /// g and g′ alone at the point `z` = (cos x, sin x): what Newton's steps read.
    #[inline]
    fn slope_at(&self, z: Cs) -> (f64, f64) {
        let zk = powers(z);
        let mut acc = [f64x2::ZERO; 2];
        for k in (0..DEGREE).step_by(2) {
            let (u, v) = self.terms(&zk, k);
            acc[0] = acc[0] + u;
            acc[1] = acc[1] + lanes(&WEIGHT[1], k) * v;
        }
        (self.a0 + acc[0].reduce_add(), acc[1].reduce_add())
    }

    /// The terms `aₖ cos kx + bₖ sin kx` and `bₖ cos kx − aₖ sin kx` (g's and g′'s without
    /// their factors k) at index `k` and the next.
    #[inline(always)]
    fn terms(&self, zk: &Powers, k: usize) -> (f64x2, f64x2) {
        let (a, b) = (lanes(&self.a, k), lanes(&self.b, k));
        let (c, s) = (lanes(&zk.c, k), lanes(&zk.s, k));
        (a * c + b * s, b * c - a * s)
    }

    /// The one root between `p` and `q` (with its (cos, sin) and g' there), where g is proven
    /// monotone, with |g'| ≥ `slope` and |g''| ≤ `curve` there: Newton's steps from the root of
    /// the cubic through the ends' values and slopes, bisecting whenever a step would leave the
    /// bracket. A step whose landing is provably within rounding of the root (curve · δ² / 2|g'|,
    /// δ the distance to the root, which |g| over |g'| near the point bounds) is taken without
    /// evaluating g there. Each point's (cos, sin) is its neighbour's turned by the step
    /// ([`turn_small`]), or the bracket's chord midpoint: no sincos.
    fn newton(&self, p: &At, q: &At, slope: f64, curve: f64) -> (f64, Cs, f64) {
        let (mut lo, mut hi) = ((p.x, p.z, p.g), (q.x, q.z, q.g));
        let mut x = p.x + (q.x - p.x) * Cubic::hermite(p.g, p.d, q.g, q.d, q.x - p.x).root();
        let mut z = turn_small(p.z, x - p.x);
        let mut d = p.d;
        for _ in 0..32 {
            let g;
            (g, d) = self.slope_at(z);
            if g.abs() <= self.noise {
                return (x, z, d);
            }
            if g.signum() == lo.2.signum() {
                lo = (x, z, g);
            } else {
                hi = (x, z, g);
            }
            let (l, r) = (lo.0.min(hi.0), lo.0.max(hi.0));
            let mut next = x - g / d;
            let landed = if next > l && next < r {
                z = turn_small(z, next - x);
                // |g'| between x and the root: `slope` over the bracket, or near x, where g''
                // moves it little, |d| (less its rounding) less that move over twice |g / d|, if
                // that leaves half of it.
                let least = d.abs() - self.noise_at[1];
                let near = least - 2.0 * curve * (g / d).abs();
                let far = g / if near >= 0.5 * least { near.max(slope) } else { slope };
                curve * far * far <= 4.0 * f64::EPSILON * (1.0 + next.abs()) * d.abs()
            } else {
                next = 0.5 * (l + r);
                z = chord_mid(lo.1, hi.1);
                false
            };
            if landed || (next - x).abs() <= 4.0 * f64::EPSILON * (1.0 + x.abs()) {
                return (next, z, d);
            }
            x = next;
        }
        (x, z, d)
    }

    /// Every root on the circle, by subdivision: an interval is dropped where the bounds on g''
    /// or g'''' prove g keeps its sign, and bracketed where those on g'' or g⁽⁵⁾ prove g
    /// monotone (each bound turned into one on g or g' by the chord or the cubic through the
    /// ends, [`Cubic::min`]); where neither is proven once the bound is down to rounding, the
    /// interval is unsure (a double root, roots closer than rounding tells apart, or none).
    /// `None` past 32 of either.
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
            out.interval(&prev, &cur, 0)?;
            prev = cur;
        }
        Some(out)
    }
}

/// `z¹ … z⁸` as (cos kx, sin kx) at index k − 1, cosines and sines apart so that the terms
/// are computed two at a time.
#[derive(Clone, Copy)]
struct Powers {
    c: [f64; DEGREE],
    s: [f64; DEGREE],
}

impl Powers {
    fn first(&self) -> Cs {
        Cs { c: self.c[0], s: self.s[0] }
    }
}

/// kⁿ at index k − 1, n = 0..=4: the factors the derivatives put on the terms.
const WEIGHT: [[f64; DEGREE]; 5] = {
    let mut w = [[1.0; DEGREE]; 5];
    let mut n = 1;
    while n < 5 {
        let mut k = 0;
        while k < DEGREE {
            w[n][k] = w[n - 1][k] * (k + 1) as f64;
            k += 1;
        }
        n += 1;
    }
    w
};

/// Terms `k` and `k + 1` of `v` in the two lanes of a vector register.
#[inline(always)]
fn lanes(v: &[f64; DEGREE], k: usize) -> f64x2 {
    f64x2::new([v[k], v[k + 1]])
}

/// `z¹ … z⁸`, by products in a tree (four deep, not a chain of eight).
#[inline(always)]
fn powers(z: Cs) -> Powers {
    let z2 = mul(z, z);
    let (z3, z4) = (mul(z2, z), mul(z2, z2));
    let (z5, z6, z7, z8) = (mul(z4, z), mul(z4, z2), mul(z4, z3), mul(z4, z4));
    Powers {
        c: [z.c, z2.c, z3.c, z4.c, z5.c, z6.c, z7.c, z8.c],
        s: [z.s, z2.s, z3.s, z4.s, z5.s, z6.s, z7.s, z8.s],
    }
}

/// The powers at the sample angles and at the grid's points: the same for every pose.
static NODE_POWERS: std::sync::LazyLock<[Powers; NODES]> = std::sync::LazyLock::new(circle);
static GRID_POWERS: std::sync::LazyLock<[Powers; GRID]> = std::sync::LazyLock::new(circle);

/// The powers at `N` equally spaced angles from [`OFFSET`].
fn circle<const N: usize>() -> [Powers; N] {
    std::array::from_fn(|i| powers(Cs::of(OFFSET + std::f64::consts::TAU * i as f64 / N as f64)))
}

/// What the isolation found.
struct Isolated<'a> {
    t: &'a Trig,
    /// A root, its (cos, sin), g' there, and an interval that holds it and no other.
    roots: ArrayVec<(f64, Cs, f64, f64, f64), 32>,
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

    fn interval(&mut self, p: &At, q: &At, depth: u32) -> Option<()> {
        let (t, h) = (self.t, q.x - p.x);
        // |g''''| on the interval: g'''' leaves each end at most at the rate `crackle`, so it
        // stays within the tent of the two ends' values; or `snap`, where that is less.
        let snap = min(0.5 * (p.four + q.four).abs() + 0.5 * t.crackle * h, t.snap) + t.noise_at[4];
        // |g'''| on the interval: within the tent of the two ends' values, the same way.
        let jerk = min(0.5 * (p.j + q.j).abs() + 0.5 * snap * h, t.jerk) + t.noise_at[3];
        // |g''| on the interval: within the tent of the two ends' values, the same way.
        let c = 0.5 * (p.e + q.e).abs() + 0.5 * jerk * h + t.noise_at[2];
        // A computed zero proves nothing (the roots near it may be one or three): it counts by
        // its sign bit, and the interval ending there is unsure once subdivided to rounding.
        let s0 = sign(p.g);
        let bend = 0.125 * c * h * h;
        let h4 = (h * h) * (h * h);
        if s0 != sign(q.g) && q.g != 0.0 {
            // |g'| from below: its least end less what |g''| lets it dip, or where that proves
            // nothing, the cubic through g′'s and g″'s values at the ends less its error
            // (|g⁽⁵⁾| h⁴/384) and that of the curvatures.
            let sd = sign(p.d);
            if sd == sign(q.d) {
                let mut slope = min(p.d.abs(), q.d.abs()) - t.noise_at[1] - 0.5 * c * h;
                if !(slope > 0.0) {
                    slope = Cubic::hermite(sd * p.d, sd * p.e, sd * q.d, sd * q.e, h).min()
                        - t.crackle * h4 / 384.0
                        - t.noise_at[1]
                        - 0.25 * h * t.noise_at[2];
                }
                if slope > 0.0 {
                    let (r, z, d) = t.newton(p, q, slope, c);
                    return self.roots.try_push((r, z, d, p.x, q.x)).ok();
                }
            }
        } else {
            // |g| from below: the chord less the bend, or on each half the tangent at its end
            // less the bend (each half's bound is concave: least at the half's ends).
            let (g0, g1) = (s0 * p.g, s0 * q.g);
            let chord = min(g0, g1);
            let left = g0 + (s0 * p.d - t.noise_at[1]) * 0.5 * h - bend;
            let right = g1 - (s0 * q.d + t.noise_at[1]) * 0.5 * h - bend;
            // Or the cubic through the ends' values and slopes, less its error (|g''''| h⁴/384)
            // and that of the slopes.
            let hermite = || Cubic::hermite(g0, s0 * p.d, g1, s0 * q.d, h).min() - snap * h4 / 384.0 - 0.25 * h * t.noise_at[1];
            if chord - bend > t.noise || min(chord, min(left, right)) > t.noise || hermite() > t.noise {
                return Some(());
            }
        }
        if bend <= t.noise || depth >= MAX_DEPTH {
            return self.unsure(p.x, q.x);
        }
        let mid = t.at(0.5 * (p.x + q.x), chord_mid(p.z, q.z));
        self.interval(p, &mid, depth + 1)?;
        self.interval(&mid, q, depth + 1)
    }
}

/// The cubic on an interval of width `h` with values `v0`, `v1` and slopes `d0`, `d1` at its
/// ends (Hermite's), in powers of the fraction s ∈ [0, 1] of the interval.
struct Cubic {
    v0: f64,
    v1: f64,
    m0: f64,
    c2: f64,
    c3: f64,
    /// The size of its terms, which its rounding follows.
    size: f64,
}

impl Cubic {
    fn hermite(v0: f64, d0: f64, v1: f64, d1: f64, h: f64) -> Cubic {
        let (m0, m1) = (h * d0, h * d1);
        Cubic {
            v0,
            v1,
            m0,
            c2: 3.0 * (v1 - v0) - 2.0 * m0 - m1,
            c3: 2.0 * (v0 - v1) + m0 + m1,
            size: v0.abs() + v1.abs() + m0.abs() + m1.abs(),
        }
    }

    fn at(&self, s: f64) -> f64 {
        ((self.c3 * s + self.c2) * s + self.m0) * s + self.v0
    }

    /// Its least value (its rounding included): at an end or where its slope vanishes inside.
    fn min(&self) -> f64 {
        let (c2, c3, m0) = (self.c2, self.c3, self.m0);
        let mut lo = min(self.v0, self.v1);
        let disc = c2 * c2 - 3.0 * c3 * m0;
        if disc > 0.0 {
            let q = -(c2 + sign(c2) * disc.sqrt());
            for s in [q / (3.0 * c3), m0 / q] {
                if s > 0.0 && s < 1.0 {
                    lo = min(lo, self.at(s));
                }
            }
        }
        lo - 1e-14 * self.size
    }

    /// Where it crosses zero (`v0`, `v1` of opposite signs), as a fraction of the interval: a
    /// start for Newton's steps on the function it interpolates, which it misses by at most
    /// |g⁗| h⁴ / 384 there. Newton's steps on the cubic from the chord's root, kept inside.
    fn root(&self) -> f64 {
        let chord = self.v0 / (self.v0 - self.v1);
        let mut s = chord;
        for _ in 0..4 {
            let d = (3.0 * self.c3 * s + 2.0 * self.c2) * s + self.m0;
            s = (s - self.at(s) / d).clamp(0.0, 1.0);
        }
        if s.is_finite() { s } else { chord }
    }
}

/// ±1 by the sign bit: `signum` without its NaN test (the isolation's values are finite).
#[inline(always)]
fn sign(x: f64) -> f64 {
    1f64.copysign(x)
}

/// The lesser of two finite values: `f64::min` without its NaN handling.
#[inline(always)]
fn min(a: f64, b: f64) -> f64 {
    if a < b { a } else { b }
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
