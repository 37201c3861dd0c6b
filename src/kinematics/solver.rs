//! Inverse kinematics: every joint solution of a tool pose, in closed form where the chain allows
//! and by a 1-D root search where it does not (a missing linear axis: `three`). It reads what the
//! machine precomputed of its chain ([`super::model::Chain`]: the orientation sequence, the chain's shape).

use super::fk::rotate;
use super::model::{Machine, Shape};
use super::solution::{Found, IkOptions, Solution, Solutions, push};
use super::subproblem::{Cs, FreeAngle, sp1};
use super::{Error, Pose, Setup, Vec3};

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
    push(m, &mut out, pose, setup, seq, Found { branch, ..Found::of([a1, a2, Cs::ZERO]) });
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
            push(m, out, pose, setup, &[], Found::of([Cs::ZERO; 3]));
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
            push(m, out, pose, setup, &ch.seq, Found { singular: sing, ..Found::of([a, Cs::ZERO, Cs::ZERO]) });
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
                    let found = Found {
                        angles: Some([t1, t2, 0.0]),
                        branch: sg,
                        ..Found::of([a1, a2, Cs::ZERO])
                    };
                    push(m, out, pose, setup, &ch.seq, found);
                }
            } else {
                let (a1, a2, sing) = pair.angles(&u, &meet, 0.0, free);
                let sing = sing.then_some((ch.seq[0], opt.free_angle));
                push(m, out, pose, setup, &ch.seq, Found { singular: sing, ..Found::of([a1, a2, Cs::ZERO]) });
            }
        }
        Shape::Three { s0, pair, missing, form } => {
            let shape = super::three::Three { s0, pair, missing: *missing, form };
            super::three::three(m, &shape, &u, pose, setup, opt, out)?
        }
    }
    Ok(())
}
