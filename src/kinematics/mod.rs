//! Machine model, forward and inverse kinematics of `docs/machine-model.md`.
//!
//! Pure: no IO, no async, no serde, no HTTP. Radians and profile units inside; degrees appear only
//! at the edges (profile loading, NC words, CLI and JSON output). Free functions take the machine,
//! the pose and the setup explicitly, so nothing here holds state between calls.

mod angle_error;
mod fk;
mod model;
mod solution;
mod solver;
mod subproblem;
mod three;

pub use angle_error::AngleError;
pub use fk::{controlled_point, fk, fk_actual, machine_frame, tcp_fk, tcp_point, tool_axis};
pub use model::{LINEAR_NAMES, Linear, Machine, MachineSpec, Mount, Rotary, Units, WINDINGS};
pub use solution::{IkOptions, Solution, Solutions};
pub use solver::{free_rotary, hold_outer, ik, ik_into, outer_rotary, singular_direction};

pub type Vec3 = nalgebra::Vector3<f64>;

/// Joint values: the NC words. Linears X, Y, Z in profile units (0 where the machine lacks one);
/// rotaries in chain order, radians, before angle-error compensation (what the NC word says).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Joints {
    pub linear: [f64; 3],
    pub rotary: [f64; 3],
}

/// A tool pose in the workpiece frame W: tip point and unit tool axis (tip toward spindle).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose {
    pub tip: Vec3,
    pub axis: Vec3,
}

/// Largest coordinate (mm or inch) kinematics takes: a million-metre pose is a typing error, and
/// far beyond it arithmetic overflows into inf, which no solver can use.
pub const MAX_COORD: f64 = 1e9;

/// Whether a coordinate is one kinematics takes: finite and within ±[`MAX_COORD`].
pub fn coordinate_ok(v: f64) -> bool {
    v.abs() <= MAX_COORD // false for NaN
}

/// What a job adds to a profile: tool length (gauge line to tip) and work offset (origin of W in
/// M at home), both in profile units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Setup {
    pub tool_length: f64,
    pub work_offset: Vec3,
}

impl Setup {
    pub fn new(tool_length: f64, work_offset: Vec3) -> Setup {
        Setup {
            tool_length,
            work_offset,
        }
    }

    /// The one rule every edge checks a setup by: finite and within ±[`MAX_COORD`]. The tool
    /// length defaults to the profile's.
    pub fn checked(m: &Machine, tool_length: Option<f64>, work_offset: Vec3) -> Result<Setup, String> {
        let l = tool_length.unwrap_or(m.default_tool_length);
        if !coordinate_ok(l) || !work_offset.iter().all(|v| coordinate_ok(*v)) {
            return Err(format!(
                "tool_length and work_offset must be finite and within ±{MAX_COORD:e}"
            ));
        }
        Ok(Setup::new(l, work_offset))
    }
}

#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum Error {
    /// A profile value is wrong; `key` names it (`rotary[1] (C).axis`).
    #[error("{key}: {problem}")]
    Profile { key: String, problem: String },
    #[error("invalid pose: {problem}")]
    InvalidPose { problem: String },
    /// The tool orientation lies outside what the machine's rotaries can reach.
    #[error("orientation unreachable: misses the reachable set by {:.6}°", .miss.to_degrees())]
    Unreachable { miss: f64 },
    /// The orientation is reachable but no rotary position also places the tip.
    #[error("no solution: {reason}")]
    NoSolution { reason: String },
}

/// One axis outside its travel.
#[derive(Clone, Debug, PartialEq)]
pub struct LimitViolation {
    pub axis: char,
    /// Profile units, or degrees for rotaries (this is an edge type: it names what an operator reads).
    pub value: f64,
    pub min: f64,
    pub max: f64,
}

/// The first axis of `joints` outside its travel (rotaries compared as given, no windings).
pub fn limit_violation(m: &Machine, joints: &Joints, eps: f64) -> Option<LimitViolation> {
    for (i, l) in m.linears.iter().enumerate() {
        if let Some(l) = l {
            let v = joints.linear[i];
            if !(v >= l.min - eps && v <= l.max + eps) {
                return Some(LimitViolation {
                    axis: LINEAR_NAMES[i],
                    value: v,
                    min: l.min,
                    max: l.max,
                });
            }
        }
    }
    for (i, r) in m.rotaries.iter().enumerate() {
        if let Some((lo, hi)) = r.limits {
            let v = joints.rotary[i];
            if !r.within(v, 1e-9) {
                return Some(LimitViolation {
                    axis: r.name,
                    value: v.to_degrees(),
                    min: lo.to_degrees(),
                    max: hi.to_degrees(),
                });
            }
        }
    }
    None
}

/// Whether some winding of every rotary, with these linears, lies within travel.
pub fn reachable_within_limits(m: &Machine, sol: &Solution) -> bool {
    let lin_ok = m.linears.iter().enumerate().all(|(i, l)| match l {
        Some(l) => sol.joints.linear[i] >= l.min - 1e-9 && sol.joints.linear[i] <= l.max + 1e-9,
        None => true,
    });
    lin_ok
        && m.rotaries
            .iter()
            .enumerate()
            .all(|(i, r)| !r.windings(sol.actual[i], sol.actual[i]).is_empty())
}

/// `a` in (−π, π].
#[inline]
pub fn wrap(a: f64) -> f64 {
    use std::f64::consts::{PI, TAU};
    if a > -PI && a <= PI {
        return a; // the common case, exactly, without fmod
    }
    let x = a + PI;
    // `x.rem_euclid(TAU)` without fmod within a turn either side (a move between the branches of
    // a table's C axis differs by up to two turns' worth of half turns): there fmod is `x − TAU`
    // (exact, by Sterbenz) or `x`, and rem_euclid adds TAU to a negative remainder; the same
    // operations, so the same bits.
    let r = if (TAU..2.0 * TAU).contains(&x) {
        x - TAU
    } else if x < 0.0 && x > -TAU {
        x + TAU
    } else {
        x.rem_euclid(TAU)
    } - PI;
    if r == -PI { PI } else { r }
}

/// Angle in radians between two vectors (robust near 0 and π).
#[inline]
pub fn angle_between(a: &Vec3, b: &Vec3) -> f64 {
    let (s, c) = (a.cross(b).norm(), a.dot(b));
    // The common case on a toolpath (a few µrad, every block's replay): atan's series, exact to
    // the last bit for t < 1e-3 (the next term is t⁵/5 < 2e-16·t), without a libm call.
    if c > 0.0 && s < 1e-3 * c {
        let t = s / c;
        return t - t * t * t / 3.0;
    }
    s.atan2(c)
}

#[cfg(test)]
mod tests {
    use super::wrap;
    use std::f64::consts::{PI, TAU};

    fn reference(a: f64) -> f64 {
        if a > -PI && a <= PI {
            return a;
        }
        let r = (a + PI).rem_euclid(TAU) - PI;
        if r == -PI { PI } else { r }
    }

    proptest::proptest! {
        #[test]
        fn wrap_is_rem_euclid_bit_for_bit(a in -40.0f64..40.0, k in -8i32..8, ulps in -4i64..4) {
            // Around every multiple of π too, where the branches of the fast path meet.
            for x in [a, k as f64 * PI, f64::from_bits((k as f64 * PI).to_bits().wrapping_add_signed(ulps))] {
                proptest::prop_assert_eq!(wrap(x).to_bits(), reference(x).to_bits(), "{}", x);
            }
        }
    }

    #[test]
    fn wrap_keeps_odd_values() {
        for x in [
            f64::NAN,
            f64::INFINITY,
            -0.0,
            0.0,
            1e300,
            -1e300,
            -PI,
            PI,
            TAU,
            -TAU,
            3.0 * PI,
            -3.0 * PI,
        ] {
            assert_eq!(wrap(x).to_bits(), reference(x).to_bits(), "{x}");
        }
    }
}
