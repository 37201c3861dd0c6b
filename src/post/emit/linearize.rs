//! Linearization: a feed segment subdivided where a rotary steps too far or the joint-space
//! motion strays from the CL chord, at midpoints on the CL segment.

use super::{At, Emitter};
use crate::diag::{Code, Diagnostic, Severity};
use crate::kinematics::{self, IkOptions, Joints, Pose, Solutions, Vec3, fk, ik_into};
use crate::post::plan::wrap;
use crate::post::{Error, Mode, MotionPt, Sink};

/// What the linearization of one CL segment may still spend: halvings left (see
/// [`MAX_SEGMENT_SPLITS`]), and whether running out was told.
struct Budget {
    splits: u32,
    told: bool,
}

impl<S: Sink + ?Sized> Emitter<'_, S> {
    /// A feed move from `a` to `b`, subdivided where the rotaries step too far in one block or
    /// (joint mode) the joint-space line strays from the CL segment.
    pub(super) fn segment(&mut self, a: At, b: At, pt: &MotionPt, diags: Vec<Diagnostic>) -> Result<u32, Error> {
        let mut budget = Budget {
            splits: MAX_SEGMENT_SPLITS,
            told: false,
        };
        self.split(a, b, pt, diags, 0, &mut budget)
    }

    /// What the linearization bound's lever adds to the tip's distance, less the tool length:
    /// the work offset and the rotaries' pivots.
    fn lever_base(&self) -> f64 {
        self.tool.setup().work_offset.norm() + self.m.rotaries.iter().map(|r| r.pivot.norm()).sum::<f64>()
    }

    /// [`Emitter::segment`] `depth` halvings in, from `budget`.
    fn split(&mut self, a: At, b: At, pt: &MotionPt, diags: Vec<Diagnostic>, depth: u32, budget: &mut Budget) -> Result<u32, Error> {
        let step = (0..self.m.rotaries.len())
            .map(|i| (b.joints.rotary[i] - a.joints.rotary[i]).abs())
            .fold(0.0, f64::max);
        let mut split = step > self.o.max_rotary_step;
        // TCP with angle error: the control interpolates the words, the real tip bends with Δ.
        let compensated = self.m.has_angle_error();
        let curved = self.o.mode == Mode::Joint || compensated;
        if !split && curved && step > 0.0 {
            // In W the tip follows R(θ(t))·x(t); |P''| ≤ Σ²·lever + 2·Σ·|Δxyz| (rotaries sweeping
            // and turning the moving linears), so the chord error is at most that over 8: below
            // the tolerance there is no need to sample.
            let sum: f64 = (0..self.m.rotaries.len())
                .map(|i| (b.joints.rotary[i] - a.joints.rotary[i]).abs())
                .sum();
            let dlin = (0..3)
                .map(|i| (b.joints.linear[i] - a.joints.linear[i]).powi(2))
                .sum::<f64>()
                .sqrt();
            // Longest distance from a rotary's line to what it moves (tip, pivots, tool).
            let lever =
                a.pose.tip.norm_squared().max(b.pose.tip.norm_squared()).sqrt() + self.lever_base() + self.tool.setup().tool_length.abs();
            // With angle-error compensation the actual angle is not linear in the interpolated
            // word: no bound, always sample.
            let bound = if compensated {
                f64::INFINITY
            } else {
                (sum * sum * lever + 2.0 * sum * dlin) / 8.0
            };
            split = bound > 0.5 * self.o.tolerance && self.nonlinear_over(&a, &b, 0.8 * self.o.tolerance);
        }
        // An end farther outside travel than the travel is long is a typo in the CL file (it is
        // a limit error already): following it to the tolerance cannot converge. `GOTO/1e8,…`
        // made 2¹⁴ leaves, each written as a reposition: 98 000 blocks for one bad point.
        if split && depth == 0 {
            let far = |j: &Joints| {
                self.m.linears.iter().zip(j.linear).any(|(l, v)| {
                    l.as_ref()
                        .is_some_and(|l| !(v >= l.min - (l.max - l.min) && v <= l.max + (l.max - l.min)))
                })
            };
            if far(&a.joints) || far(&b.joints) {
                split = false;
            }
        }
        if split
            && depth >= MAX_SPLIT_DEPTH
            && (step > self.o.max_rotary_step || curved && self.nonlinear_over(&a, &b, self.o.tolerance))
        {
            // Subdivision did not converge: the solution followed runs into a fold (or, any
            // mode, a rotary still steps too far: it was a feed block turning C 180°).
            self.reposition(a, b, false, pt)?;
            return Ok(3);
        }
        if split && depth < MAX_SPLIT_DEPTH && budget.splits == 0 {
            // Never seen in a real or generated path; bounds the output whatever comes. Told
            // once a segment (the budget is reset with the next one).
            if !budget.told {
                budget.told = true;
                let d = Diagnostic::new(
                    Code::Linearized,
                    Severity::Warning,
                    Some(pt.line),
                    format!(
                        "segment not linearized past {MAX_SEGMENT_SPLITS} blocks: the motion between them may leave the tolerance"
                    ),
                );
                self.note(d)?;
            }
            split = false;
        }
        if split && depth < MAX_SPLIT_DEPTH {
            budget.splits = budget.splits.saturating_sub(1);
            match self.midpoint(&a, &b) {
                Some(mid) => {
                    let n1 = self.split(a, mid, pt, Vec::new(), depth + 1, budget)?;
                    let n2 = self.split(mid, b, pt, diags, depth + 1, budget)?;
                    return Ok(n1 + n2);
                }
                None => {
                    // No solution continues between the two: the root followed ends on a fold
                    // (3-rotary chains). The machine cannot follow the segment: reposition.
                    self.reposition(a, b, false, pt)?;
                    return Ok(3);
                }
            }
        }
        let mut diags = diags;
        let is_last = (b.pose.tip - pt.pose.tip).norm_squared() < 1e-24 && (b.pose.axis - pt.pose.axis).norm_squared() < 1e-24;
        if is_last && depth > 0 {
            diags.push(Diagnostic::new(
                Code::Linearized,
                Severity::Info,
                Some(pt.line),
                "segment subdivided (see the blocks before this one)",
            ));
        }
        self.block(b, pt, false, diags, !is_last || pt.inserted, None)?;
        Ok(1)
    }

    /// Whether the joint-space line a→b strays from the CL chord by more than `limit`, sampled
    /// at ½, ¼, ¾ and, where those leave less than half of `limit` proven, at the other eighths
    /// ([`NONLINEAR_SAMPLES`]): every eighth on every block cost curved 5-axis files +47 %.
    pub(super) fn nonlinear_over(&self, a: &At, b: &At, limit: f64) -> bool {
        let tcp = self.o.mode == Mode::Tcp;
        let (pa, pb) = if tcp {
            (self.tcp_xyz(a), self.tcp_xyz(b))
        } else {
            (Vec3::zeros(), Vec3::zeros())
        };
        let mut worst: f64 = 0.0;
        for (k, t) in [0.5, 0.25, 0.75, 0.125, 0.375, 0.625, 0.875].into_iter().enumerate() {
            if k == 3 && worst < 0.5 * limit {
                break;
            }
            let mut j = a.joints;
            for i in 0..3 {
                j.linear[i] += t * (b.joints.linear[i] - a.joints.linear[i]);
                j.rotary[i] += t * (b.joints.rotary[i] - a.joints.rotary[i]);
            }
            let p = if tcp {
                kinematics::tcp_fk(self.m, &(pa + (pb - pa) * t), &j.rotary, self.tool.setup()).tip
            } else {
                fk(self.m, &j, self.tool.setup()).tip
            };
            worst = worst.max(seg_dist(&p, &a.pose.tip, &b.pose.tip));
            if worst > limit {
                return true;
            }
        }
        false
    }

    /// The pose halfway along the CL segment (tip on the chord, axis on the great circle) and
    /// its IK solution nearest the joint-space midpoint.
    pub(super) fn midpoint(&mut self, a: &At, b: &At) -> Option<At> {
        let tip = (a.pose.tip + b.pose.tip) * 0.5;
        let axis = slerp_half(&a.pose.axis, &b.pose.axis);
        let pose = Pose { tip, axis };
        let mut want = [0.0; 3];
        for i in 0..3 {
            want[i] = 0.5 * (a.actual[i] + b.actual[i]);
        }
        // At a singular midpoint the free rotary takes the interpolated angle, and the linears
        // follow from it (they were computed for the first rotary's angle: 35 mm off the pose).
        let opt = IkOptions {
            free_angle: kinematics::free_rotary(self.m).map_or(0.0, |f| want[f]),
            ..Default::default()
        };
        let mut buf = Solutions::new();
        ik_into(self.m, &pose, self.tool.setup(), &opt, &mut buf).ok()?;
        let mut best: Option<(f64, At)> = None;
        for s in buf.iter() {
            let mut actual = s.actual;
            let mut joints = s.joints;
            let mut d = 0.0;
            for (i, r) in self.m.rotaries.iter().enumerate() {
                if s.singular == Some(i) {
                    actual[i] = want[i];
                } else {
                    actual[i] = want[i] + wrap(s.actual[i] - want[i]);
                }
                joints.rotary[i] = r.word(actual[i]);
                d += (actual[i] - want[i]).abs();
            }
            if best.as_ref().is_none_or(|(bd, _)| d < *bd) {
                best = Some((
                    d,
                    At {
                        joints,
                        actual,
                        pose,
                        branch: s.branch,
                        free: s.singular.map(|f| f as u8),
                    },
                ));
            }
        }
        // A chain without one linear (3 rotaries) can only place the tip with an exact root.
        let missing_linear = self.m.linears.iter().any(|l| l.is_none());
        let limit = if missing_linear {
            std::f64::consts::FRAC_PI_2
        } else {
            NEAR_SINGULAR_SWING
        };
        match best {
            // Near the interpolation (the second-order difference of any short segment away
            // from a singular direction): the exact solution, nothing to weigh.
            Some((d, at)) if d <= 1e-4 => return Some(at),
            Some((d, at)) if missing_linear => return (d <= limit).then_some(at),
            None if missing_linear => return None,
            // Outside the singular cone nothing swings: the exact midpoint can still leave the
            // interpolation far (a 90° tilt on a nutating table: B 65.5° against 90°), and holding
            // the interpolated rotaries there put the tool axis 31° off the CL orientation.
            Some((d, at)) if d <= std::f64::consts::FRAC_PI_2 && !self.in_singular_cone(&axis) => return Some(at),
            _ => {}
        }
        // Near a singular direction the exact midpoint's free rotary follows the azimuth of a
        // nearly aligned axis and swings wildly. Keep the interpolated rotaries (the motion the
        // control makes between the two blocks anyway), put the tip exactly on the chord, and
        // account for the orientation this leaves (bounded by how near the path passes).
        // Microradians from it the exact rotary chases the azimuth of an all but vertical axis
        // (and the rounding of i, j, k) to and fro: where the interpolated rotaries miss the
        // orientation by less than a rotary word can say, they are the better midpoint even
        // within the swing limit (it never converged 14 halvings deep, C wandering by a degree
        // at a standing tip).
        let (held, dev) = self.held_midpoint(a, &want, &tip, &axis);
        if let Some((d, at)) = best
            && d <= limit
            && dev > self.f.fmt.half_rotary()
        {
            return Some(at);
        }
        self.singular.midpoint_held(dev);
        Some(held)
    }
}

/// Where the joint-space motion between two blocks is measured against the CL chord: every
/// eighth. At ¼, ½, ¾ only, a block near htm50200's singular direction passed at 0.0091 mm
/// while its error peaked off the samples at 0.0107 (tolerance 0.01; the shared verifier samples
/// ninths). `verify` takes them all; the engine the outer four only where ½, ¼, ¾ come near.
pub const NONLINEAR_SAMPLES: [f64; 7] = [0.125, 0.25, 0.375, 0.5, 0.625, 0.75, 0.875];

/// Rotary distance (radians, summed) from the joint-space midpoint beyond which an exact midpoint
/// is not taken: the segment passes near a singular direction.
const NEAR_SINGULAR_SWING: f64 = 0.0873;

/// Distance of `p` from the segment [a, b].
pub fn seg_dist(p: &Vec3, a: &Vec3, b: &Vec3) -> f64 {
    let ab = b - a;
    let l2 = ab.norm_squared();
    let t = if l2 == 0.0 {
        0.0
    } else {
        ((p - a).dot(&ab) / l2).clamp(0.0, 1.0)
    };
    (p - (a + ab * t)).norm()
}

/// The unit vector halfway along the great circle from `a` to `b`.
fn slerp_half(a: &Vec3, b: &Vec3) -> Vec3 {
    let s = a + b;
    let n = s.norm();
    if n < 1e-9 { *a } else { s / n }
}

/// Halvings of one CL segment before linearization gives up: a path passing within microradians
/// of a singular direction swings the free rotary over a millionth of its segment (14 left
/// leaves at 0.98 of the tolerance, over it once rounded).
const MAX_SPLIT_DEPTH: u32 = 20;

/// Blocks one CL segment may be linearized into: a bound on the output whatever the input.
const MAX_SEGMENT_SPLITS: u32 = 1 << 14;
