//! Points of the unit circle as (cos, sin), turned and halved without sincos: the isolation's and
//! the settling's steps along the outer angle.

use super::GRID;
use crate::kinematics::subproblem::Cs;

/// The midpoint of the arc between two points of the unit circle (less than a half turn apart):
/// the normalised sum of its ends.
#[inline]
pub(super) fn chord_mid(p: Cs, q: Cs) -> Cs {
    unit(Cs { c: p.c + q.c, s: p.s + q.s })
}

/// `z` scaled onto the unit circle.
#[inline]
pub(super) fn unit(z: Cs) -> Cs {
    let n = 1.0 / (z.c * z.c + z.s * z.s).sqrt();
    Cs { c: z.c * n, s: z.s * n }
}

/// `z` turned by `h` (|h| ≤ 2π/20, within a grid interval): cos h and sin h by their Taylor
/// series to h¹⁴ and h¹³, whose next terms are below 3e-20 there.
#[inline]
pub(super) fn turn_small(z: Cs, h: f64) -> Cs {
    debug_assert!(h.abs() <= std::f64::consts::TAU / GRID as f64, "{h}");
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

/// `z` turned by `h`, on the circle: by [`turn_small`] within a grid interval, else by sincos.
pub(super) fn turn(z: Cs, h: f64) -> Cs {
    unit(if h.abs() <= std::f64::consts::TAU / GRID as f64 {
        turn_small(z, h)
    } else {
        mul(z, Cs::of(h))
    })
}

/// (cos, sin) of the sum of two angles.
#[inline(always)]
pub(super) fn mul(p: Cs, q: Cs) -> Cs {
    Cs {
        c: p.c * q.c - p.s * q.s,
        s: p.c * q.s + p.s * q.c,
    }
}
