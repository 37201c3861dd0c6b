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

    /// musl's atan2 (via the `libm` crate): < 1 ulp like glibc's, but inlinable and without
    /// glibc's slow correctly-rounded paths; it was 40% of IK time.
    #[inline]
    pub fn angle(self) -> f64 {
        libm::atan2(self.s, self.c)
    }
}

/// The caller's free angle, turned into (cos, sin) only at a singular pose.
#[derive(Clone, Copy)]
pub(crate) struct FreeAngle(pub f64);

impl FreeAngle {
    #[inline]
    pub(crate) fn cs(self) -> Cs {
        Cs::of(self.0)
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
    /// cos ω of ω = ∠(s1, s2).
    cw: f64,
    /// Unit tangent at s1 toward s2, and the normal s1 × s2 / sin ω.
    e: Vec3,
    f: Vec3,
    /// cos θ2 − cos ω, without cancellation.
    k0: f64,
    /// α2 from c without projections: with z' = z − s2 (s2·z) and w = s2 × z', (cos α2, sin α2) =
    /// (z'·c, w·c) / |z'|², and c = ct1 s1 + st1 (cos A e + sin A f): six constant products.
    zs: [f64; 3],
    ws: [f64; 3],
    /// Angle about s2 of s1's projection: c− mirrors c+ across the plane (s1, s2), which holds
    /// s2, so α2− = 2 θm − α2+.
    theta_m: f64,
    inv_sw: f64,
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
    /// q's components across s1, along e and f (exact: no projection is subtracted).
    eq: f64,
    fq: f64,
    /// sin² A: negative where the cones miss each other (q unreachable), 0 on the fold.
    pub reach: f64,
    /// q lies along s1 (θ1 ≈ 0 or π): α1 is free and c = q.
    pub on_axis: bool,
}

impl Meet {
    /// sin θ1: 0 where `q` lies along s1.
    #[inline]
    pub fn st1(&self) -> f64 {
        self.st1
    }
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
        let (e, f) = ((s2 - s1 * cw) / sw, n / sw);
        let zp = Vec3::z() - s2 * s2.z;
        let z2 = zp.norm_squared();
        let w = s2.cross(&zp);
        let zs = [zp.dot(&s1) / z2, zp.dot(&e) / z2, zp.dot(&f) / z2];
        let ws = [w.dot(&s1) / z2, w.dot(&e) / z2, w.dot(&f) / z2];
        let theta_m = ws[0].atan2(zs[0]);
        Some(Pair {
            s1,
            s2,
            cw,
            e,
            f,
            k0,
            zs,
            ws,
            theta_m,
            inv_sw: 1.0 / sw,
            cos_t2,
            t2,
            band,
        })
    }

    #[inline]
    pub fn meet(&self, q: &Vec3) -> Meet {
        // (s1, e, f) is orthonormal: q's components across s1 are exact, and so is sin θ1.
        let (eq, fq) = (self.e.dot(q), self.f.dot(q));
        let st1 = (eq * eq + fq * fq).sqrt();
        let ct1 = self.s1.dot(q);
        if st1 < 1e-12 {
            // c = q: reachable iff q sits on the cone of s2 (checked by `reach`).
            let d = (self.s2.cross(q).norm().atan2(self.s2.dot(q)) - self.t2).abs();
            return Meet {
                ct1,
                st1,
                cos_a: 1.0,
                eq: 0.0,
                fq: 0.0,
                reach: if d < 1e-12 { 0.0 } else { -d },
                on_axis: true,
            };
        }
        // 1 − cos θ1 without cancellation.
        let inv = 1.0 / st1;
        let cos_a = self.lateral(ct1, st1 * st1) * inv * self.inv_sw;
        let reach = (1.0 - cos_a) * (1.0 + cos_a);
        Meet {
            ct1,
            st1,
            cos_a,
            eq: eq * inv,
            fq: fq * inv,
            reach,
            on_axis: false,
        }
    }

    /// The meet as polynomials in `q`, for the 3-rotary resultant: with `γ = sin θ1 sin A`
    /// (either sign), `(cos α1, sin α1) · st1²` and `(cos α2, sin α2)` are affine in `γ` and in
    /// `q`'s components, and `γ² = st1² − L²`; [`Pair::angles`] is [`Formal::angles`] at
    /// `γ = ±√D`.
    #[inline]
    pub fn formal(&self, q: &Vec3) -> Formal {
        let (eq, fq, ct1) = (self.e.dot(q), self.f.dot(q), self.s1.dot(q));
        let st2 = eq * eq + fq * fq;
        let st1 = st2.sqrt();
        let l = self.lateral(ct1, st2) * self.inv_sw;
        Formal {
            ct1,
            eq,
            fq,
            st2,
            l,
            d: (st1 - l) * (st1 + l),
            zs: self.zs,
            ws: self.ws,
        }
    }

    /// `sin θ1 cos A · sin ω` from cos θ1 and sin² θ1: `cos θ2 − cos ω + cos ω (1 − cos θ1)`,
    /// with 1 − cos θ1 taken without cancellation (1 − c = s²/(1 + c) where c > 0).
    #[inline]
    fn lateral(&self, ct1: f64, st2: f64) -> f64 {
        let one_minus = if ct1 > 0.0 { st2 / (1.0 + ct1) } else { 1.0 - ct1 };
        self.k0 + self.cw * one_minus
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
    /// Cs pairs and whether α1 is free (`q` along `s1`), in which case `free` is used for it (its sine and cosine are taken only then).
    #[inline]
    pub fn angles(&self, q: &Vec3, m: &Meet, sign: f64, free: FreeAngle) -> (Cs, Cs, bool) {
        if m.on_axis {
            let a2 = sp1(&self.s2, &Vec3::z(), q).unwrap_or(Cs::ZERO);
            return (free.cs(), a2, true);
        }
        let sin_a = m.reach.max(0.0).sqrt() * sign;
        let cos_a = m.cos_a.clamp(-1.0, 1.0);
        // α1 turns ĉ = cos A e + sin A f (c across s1, unit) onto q̂ (q across s1, unit); since
        // s1 × ĉ = cos A f − sin A e: cos α1 = ĉ·q̂, sin α1 = (s1 × ĉ)·q̂.
        let a1 = Cs {
            c: cos_a * m.eq + sin_a * m.fq,
            s: cos_a * m.fq - sin_a * m.eq,
        };
        let (ce, cf) = (m.st1 * cos_a, m.st1 * sin_a);
        let a2 = Cs {
            c: self.zs[0] * m.ct1 + self.zs[1] * ce + self.zs[2] * cf,
            s: self.ws[0] * m.ct1 + self.ws[1] * ce + self.ws[2] * cf,
        };
        (a1, a2, false)
    }

    /// Both branches (+ then −) with their angles, for a reachable `q` off the axis: three atan2
    /// for the four angles, by α1± = φq ∓ A and the mirror identity for α2−.
    #[inline]
    pub fn both(&self, m: &Meet) -> [(Cs, f64, Cs, f64); 2] {
        let sin_a = m.reach.max(0.0).sqrt();
        let cos_a = m.cos_a.clamp(-1.0, 1.0);
        let phi_q = libm::atan2(m.fq, m.eq);
        let big_a = libm::atan2(sin_a, cos_a);
        let (ce, cf) = (m.st1 * cos_a, m.st1 * sin_a);
        let a2p = Cs {
            c: self.zs[0] * m.ct1 + self.zs[1] * ce + self.zs[2] * cf,
            s: self.ws[0] * m.ct1 + self.ws[1] * ce + self.ws[2] * cf,
        };
        let a2m = Cs {
            c: self.zs[0] * m.ct1 + self.zs[1] * ce - self.zs[2] * cf,
            s: self.ws[0] * m.ct1 + self.ws[1] * ce - self.ws[2] * cf,
        };
        let t2p = a2p.angle();
        [
            (
                Cs {
                    c: cos_a * m.eq + sin_a * m.fq,
                    s: cos_a * m.fq - sin_a * m.eq,
                },
                wrap(phi_q - big_a),
                a2p,
                t2p,
            ),
            (
                Cs {
                    c: cos_a * m.eq - sin_a * m.fq,
                    s: cos_a * m.fq + sin_a * m.eq,
                },
                wrap(phi_q + big_a),
                a2m,
                wrap(2.0 * self.theta_m - t2p),
            ),
        ]
    }
}

/// [`Pair::formal`]'s pieces for one target.
#[derive(Clone, Copy, Debug)]
pub struct Formal {
    ct1: f64,
    eq: f64,
    fq: f64,
    /// sin² θ1: 0 where `q` lies along s1.
    pub st2: f64,
    l: f64,
    /// γ²: negative where the cones miss each other.
    pub d: f64,
    zs: [f64; 3],
    ws: [f64; 3],
}

impl Formal {
    /// `(cos α1, sin α1)` and `(cos α2, sin α2)` at any real `γ` (`st2` > 0): rotations only
    /// at `γ = ±√D`, but the controlled point is affine in each pair, so three values of `γ`
    /// give its residual as a quadratic in `γ`.
    #[inline]
    pub fn angles(&self, gamma: f64) -> (Cs, Cs) {
        let inv = 1.0 / self.st2;
        let a1 = Cs {
            c: (self.l * self.eq + gamma * self.fq) * inv,
            s: (self.l * self.fq - gamma * self.eq) * inv,
        };
        let a2 = Cs {
            c: self.zs[0] * self.ct1 + self.zs[1] * self.l + self.zs[2] * gamma,
            s: self.ws[0] * self.ct1 + self.ws[1] * self.l + self.ws[2] * gamma,
        };
        (a1, a2)
    }
}

/// Into (−π, π].
#[inline]
pub fn wrap(a: f64) -> f64 {
    use std::f64::consts::{PI, TAU};
    if a > PI {
        a - TAU
    } else if a <= -PI {
        a + TAU
    } else {
        a
    }
}
