//! What inverse kinematics answers: a joint solution, the set of them for a pose, the options
//! asked with. Its own module so that each solver (the closed forms in `solver`, the 3-rotary
//! root search in `three`) builds its answers here without one importing the other's.

use super::model::{Machine, controlled_point_cs};
use super::subproblem::Cs;
use super::{Joints, Pose, Setup};
use arrayvec::ArrayVec;

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
