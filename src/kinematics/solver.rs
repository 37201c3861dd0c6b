//! Inverse kinematics: every joint solution of a tool pose, in closed form where the chain allows
//! and by a 1-D root search where it does not (a missing linear axis: `three`). It reads what the
//! machine precomputed of its chain ([`super::model::Chain`]: the orientation sequence, the chain's shape).

use super::fk::rotate;
use super::model::{Link, Machine, Shape};
use super::subproblem::{Cs, FreeAngle, sp1};
use super::{Error, Joints, Pose, Setup, Vec3};
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

/// A solution as a solver finds it, before its linears are placed: the rotations in sequence
/// order.
#[derive(Clone, Copy)]
pub(super) struct Found {
    /// Each rotation as (cos, sin).
    pub(super) cs: [Cs; 3],
    /// The angles themselves where the solver has them (else read from `cs`).
    pub(super) angles: Option<[f64; 3]>,
    pub(super) branch: i8,
    pub(super) root: u8,
    /// The rotary (chain index) free at a singular pose, and the angle it is set to.
    pub(super) singular: Option<(usize, f64)>,
}

impl Found {
    /// The rotations `cs`, branch and root 0, nothing singular.
    pub(super) fn of(cs: [Cs; 3]) -> Found {
        Found {
            cs,
            angles: None,
            branch: 0,
            root: 0,
            singular: None,
        }
    }
}

/// Builds a solution from orientation angles (in sequence order) and places the linears.
#[inline(always)]
pub(super) fn push(m: &Machine, out: &mut Solutions, pose: &Pose, setup: &Setup, seq: &[usize], found: Found) {
    let Found {
        cs,
        angles,
        branch,
        root,
        singular,
    } = found;
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
    let cp = controlled_point_cs(&m.chain.links, &rcs, &(pose.tip + setup.work_offset), setup.tool_length);
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
pub(super) fn controlled_point_cs(links: &[Link], cs: &[Cs; 3], p_w: &Vec3, tool_length: f64) -> Vec3 {
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
