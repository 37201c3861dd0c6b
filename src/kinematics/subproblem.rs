//! Paden–Kahan rotation subproblems, on unit vectors, returning (cos, sin) pairs so that callers
//! can rotate without evaluating trigonometric functions again.

use super::Vec3;

/// Angle pair of a rotation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cs {
    pub c: f64,
    pub s: f64,
}

impl Cs {
    pub const ZERO: Cs = Cs { c: 1.0, s: 0.0 };

    #[inline]
    pub fn of(angle: f64) -> Cs {
        let (s, c) = angle.sin_cos();
        Cs { c, s }
    }

    #[inline]
    pub fn angle(self) -> f64 {
        self.s.atan2(self.c)
    }
}

/// Subproblem 1: the rotation about unit `k` that takes `p` to `q` (both assumed at the same
/// height along `k`). `None` when `p` or `q` lies on the axis, where every angle works.
#[inline]
pub fn sp1(k: &Vec3, p: &Vec3, q: &Vec3) -> Option<Cs> {
    let pp = p - k * k.dot(p);
    let qp = q - k * k.dot(q);
    let y = k.dot(&pp.cross(&qp));
    let x = pp.dot(&qp);
    let n = (x * x + y * y).sqrt();
    if n < 1e-18 {
        return None;
    }
    Some(Cs { c: x / n, s: y / n })
}

/// Subproblem 2 prepared for one pair of axes: find `α1, α2` with
/// `Rot(s1, α1) · Rot(s2, α2) · z = q`. The rotations meet at `c = Rot(s2, α2) z`, which lies on
/// both cones: at angle θ1 = ∠(s1, q) from `s1` and θ2 = ∠(s2, z) from `s2`.
///
/// Solved as a spherical triangle (s1, s2, c) rather than with the textbook
/// `c = α s1 + β s2 ± γ (s1 × s2)`: that form computes γ² as `1 − α² − …`, which cancels
/// catastrophically near a vertical tool on a table-table machine (1e-9 rad of tilt error there);
/// here sin θ1 comes from a cross product and nothing small is a difference of large numbers.
#[derive(Clone, Debug)]
pub struct Pair {
    pub s1: Vec3,
    pub s2: Vec3,
    /// cos ω, sin ω of ω = ∠(s1, s2).
    cw: f64,
    sw: f64,
    /// Unit tangent at s1 toward s2, and the normal s1 × s2 / sin ω.
    e: Vec3,
    f: Vec3,
    /// cos θ2 − cos ω, without cancellation.
    k0: f64,
    cos_t2: f64,
    t2: f64,
    /// Half-width of the band of `s1·c` over the cone of `s2` (for the miss of an unreachable q).
    band: f64,
}

/// Where the two cones meet for one target `q`: `c± = cos θ1 s1 + sin θ1 (cos A e ± sin A f)`.
#[derive(Clone, Copy, Debug)]
pub struct Meet {
    ct1: f64,
    st1: f64,
    cos_a: f64,
    /// sin² A: negative where the cones miss each other (q unreachable), 0 on the fold.
    pub reach: f64,
    /// q lies along s1 (θ1 ≈ 0 or π): α1 is free and c = q.
    pub on_axis: bool,
}

impl Pair {
    /// `None` when the axes are parallel (they would leave one orientation freedom unused).
    pub fn new(s1: Vec3, s2: Vec3) -> Option<Pair> {
        let n = s1.cross(&s2);
        let sw = n.norm();
        if sw < 1e-6 {
            return None;
        }
        let cw = s1.dot(&s2);
        let w = sw.atan2(cw);
        let t2 = s2.cross(&Vec3::z()).norm().atan2(s2.z);
        let cos_t2 = t2.cos();
        let k0 = -2.0 * ((t2 + w) / 2.0).sin() * ((t2 - w) / 2.0).sin();
        let band = t2.sin() * sw;
        Some(Pair {
            s1,
            s2,
            cw,
            sw,
            e: (s2 - s1 * cw) / sw,
            f: n / sw,
            k0,
            cos_t2,
            t2,
            band,
        })
    }

    #[inline]
    pub fn meet(&self, q: &Vec3) -> Meet {
        let st1 = self.s1.cross(q).norm();
        let ct1 = self.s1.dot(q);
        if st1 < 1e-12 {
            // c = q: reachable iff q sits on the cone of s2 (checked by `reach`).
            let d = (self.s2.cross(q).norm().atan2(self.s2.dot(q)) - self.t2).abs();
            return Meet {
                ct1,
                st1,
                cos_a: 1.0,
                reach: if d < 1e-12 { 0.0 } else { -d },
                on_axis: true,
            };
        }
        // 1 − cos θ1 without cancellation.
        let one_minus = if ct1 > 0.0 { st1 * st1 / (1.0 + ct1) } else { 1.0 - ct1 };
        let cos_a = (self.k0 + self.cw * one_minus) / (st1 * self.sw);
        let reach = (1.0 - cos_a) * (1.0 + cos_a);
        Meet {
            ct1,
            st1,
            cos_a,
            reach,
            on_axis: false,
        }
    }

    /// The angle by which `q` misses the reachable set (0 when reachable).
    pub fn miss(&self, q: &Vec3) -> f64 {
        let centre = self.cw * self.cos_t2;
        let lo = (centre + self.band).clamp(-1.0, 1.0).acos();
        let hi = (centre - self.band).clamp(-1.0, 1.0).acos();
        let t = self.s1.cross(q).norm().atan2(self.s1.dot(q));
        (lo - t).max(t - hi).max(0.0)
    }

    /// Both angles for one branch (`sign` +1 or −1; the fold takes either). Returns (α1, α2) as
    /// Cs pairs and whether α1 is free (`q` along `s1`), in which case `free` is used for it.
    #[inline]
    pub fn angles(&self, q: &Vec3, m: &Meet, sign: f64, free: Cs) -> (Cs, Cs, bool) {
        if m.on_axis {
            let a2 = sp1(&self.s2, &Vec3::z(), q).unwrap_or(Cs::ZERO);
            return (free, a2, true);
        }
        let sin_a = m.reach.max(0.0).sqrt() * sign;
        let c = self.s1 * m.ct1 + (self.e * m.cos_a.clamp(-1.0, 1.0) + self.f * sin_a) * m.st1;
        let a2 = sp1(&self.s2, &Vec3::z(), &c).unwrap_or(Cs::ZERO);
        let a1 = sp1(&self.s1, &c, q).unwrap_or(Cs::ZERO);
        (a1, a2, false)
    }
}
