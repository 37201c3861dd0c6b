//! Singular handling: a free rotary turned where the tool axis is along it, held within a
//! singular tolerance, or held at a midpoint near the singular direction.

use super::{At, Emitter};
use crate::diag::{Code, Diagnostic, Severity};
use crate::kinematics::{self, IkOptions, Joints, Machine, Pose, Solutions, Vec3, angle_between, fk, ik_into};
use crate::post::plan::wrap;
use crate::post::{Error, MotionPt, Sink, Summary};

/// What singular handling keeps: the singular cone, and the outer rotary's travel, exact and as
/// written, with what the singular tolerance's holding did (for the summary).
#[derive(Debug)]
pub(super) struct Held {
    /// The singular direction and cos of the singular cone, once (they are checked per block).
    cone: Option<(Vec3, f64)>,
    /// Outer-rotary travel of the exact solutions and of what was written, at CL points: what
    /// the singular tolerance saved, honestly (a held block's saving is partly paid back later).
    exact_prev: Option<f64>,
    exact_travel: f64,
    held_prev: Option<f64>,
    held_travel: f64,
    /// Blocks whose free rotary was held, and the largest deviation (degrees) that used.
    smoothed_blocks: u64,
    smoothed_max_deg: f64,
    /// The largest deviation (degrees) of a midpoint held near the singular direction.
    midpoint_max_deg: f64,
}

impl Held {
    /// `cone`: the singular cone's half angle (radians).
    pub(super) fn new(m: &Machine, cone: f64) -> Held {
        Held {
            cone: kinematics::singular_direction(m).map(|d| (d.normalize(), cone.cos())),
            exact_prev: None,
            exact_travel: 0.0,
            held_prev: None,
            held_travel: 0.0,
            smoothed_blocks: 0,
            smoothed_max_deg: 0.0,
            midpoint_max_deg: 0.0,
        }
    }

    /// Whether `axis` lies within the singular cone of the singular direction, either way.
    #[inline]
    pub(super) fn in_cone(&self, axis: &Vec3) -> bool {
        self.cone
            .is_some_and(|(dir, cone_cos)| axis.dot(&dir).abs() > cone_cos * axis.norm())
    }

    /// The outer rotary at a CL point: `exact` where the IK put it, `written` where the block
    /// takes it (the same unless held).
    pub(super) fn outer_at(&mut self, exact: f64, written: f64) {
        self.exact_travel += wrap(exact - self.exact_prev.unwrap_or(exact)).abs();
        self.exact_prev = Some(exact);
        self.held_travel += (written - self.held_prev.unwrap_or(written)).abs();
        self.held_prev = Some(written);
    }

    /// A block with its free rotary held, `dev` degrees off the CL orientation.
    fn smoothed(&mut self, dev: f64) {
        self.smoothed_blocks += 1;
        self.smoothed_max_deg = self.smoothed_max_deg.max(dev);
    }

    /// A midpoint held near the singular direction, `dev` degrees off the CL orientation.
    pub(super) fn midpoint_held(&mut self, dev: f64) {
        self.midpoint_max_deg = self.midpoint_max_deg.max(dev);
    }

    /// `tolerance`: the singular tolerance (the travel saved is told where there is one).
    pub(super) fn summary(&self, sum: &mut Summary, tolerance: f64) {
        sum.max_singular_deviation_deg = self.midpoint_max_deg;
        sum.smoothed_blocks = self.smoothed_blocks;
        sum.smoothing_max_deviation_deg = self.smoothed_max_deg;
        if tolerance > 0.0 && self.exact_prev.is_some() {
            sum.smoothing_travel_saved_deg = (self.exact_travel - self.held_travel).to_degrees();
        }
    }
}

impl<S: Sink + ?Sized> Emitter<'_, S> {
    /// Leaving a singular point by feed toward a pose that fixes its free rotary elsewhere: the
    /// rotary turns at the point, tip standing, where every angle of it holds the CL orientation,
    /// and the cut after it starts where it needs it. Turned during that cut instead, it tilted
    /// the tool axis off the CL orientation (0.8° for a 2° step on spinner-u5-620, 11° for 30°),
    /// and a bounded one far off retracted to unwind. Returns where the machine stands.
    #[cold]
    pub(super) fn turn_free(&mut self, prev: At, to: &At, pt: &MotionPt) -> Result<At, Error> {
        let Some(f) = prev.free.map(usize::from) else {
            return Ok(prev);
        };
        if to.free.is_some() || self.frames.tilt().is_some() {
            return Ok(prev);
        }
        // Spread over the cut, the turn leaves the axis within twice the cut's angle from the
        // singular direction (both the machine's axis and the CL's stay within that angle of
        // it): below half a rotary word, or the singular tolerance, nothing to stop for.
        let half_word = self.f.fmt.half_rotary().to_radians();
        let arc = angle_between(&prev.pose.axis, &to.pose.axis);
        if 2.0 * arc <= half_word.max(self.o.singular_tolerance) {
            return Ok(prev);
        }
        // The angle the cut leaves the point with: the exact solution on `to`'s branch a hair
        // along the CL arc. On an orthogonal table it is `to`'s; a nutating one twists the
        // azimuth as it tilts (C −90° just off vertical, −180° at the end of a 90° tilt).
        let t = (1e-7 / arc).min(0.5);
        let near = Pose {
            tip: prev.pose.tip + (to.pose.tip - prev.pose.tip) * t,
            axis: (prev.pose.axis * (1.0 - t) + to.pose.axis * t).normalize(),
        };
        let mut want = to.actual[f];
        let mut buf = Solutions::new();
        if ik_into(self.m, &near, self.tool.setup(), &IkOptions::default(), &mut buf).is_ok()
            && let Some(s) = buf.iter().find(|s| s.singular.is_none() && s.branch == to.branch)
        {
            want += wrap(s.actual[f] - want);
        }
        if (want - prev.actual[f]).abs() <= half_word {
            return Ok(prev);
        }
        let opt = IkOptions {
            free_angle: want,
            ..Default::default()
        };
        let Some(s) = ik_into(self.m, &prev.pose, self.tool.setup(), &opt, &mut buf)
            .ok()
            .and_then(|_| nearest_singular(&buf, f, &prev.actual))
        else {
            return Ok(prev);
        };
        let mut turned = At {
            joints: s.joints,
            actual: s.actual,
            ..prev
        };
        for (i, r) in self.m.rotaries.iter().enumerate() {
            if i != f {
                turned.actual[i] = prev.actual[i] + wrap(s.actual[i] - prev.actual[i]);
            }
            turned.joints.rotary[i] = r.word(turned.actual[i]);
        }
        let r = &self.m.rotaries[f];
        let d = Diagnostic::new(
            Code::Singular,
            Severity::Info,
            Some(pt.line),
            format!(
                "{} turned by {:.4}° to {:.4}°, tip standing, where the tool axis is along it (line {}): the cut after it needs it there",
                r.name,
                (want - prev.actual[f]).to_degrees(),
                turned.joints.rotary[f].to_degrees(),
                self.written.last_line()
            ),
        );
        self.segment(prev, turned, pt, vec![d])?;
        Ok(turned)
    }

    /// With a singular tolerance: the outer (free) rotary moved only as far from where it stands
    /// as keeps the tool axis within the tolerance of the CL orientation (the tip stays exact).
    /// Returns joints, actual angles, the axis reached, its deviation and the travel saved (°).
    pub(super) fn smooth(
        &mut self,
        pose: &Pose,
        joints: &Joints,
        actual: &[f64; 3],
        branch: i8,
    ) -> Option<(Joints, [f64; 3], Vec3, f64, f64)> {
        let tol = self.o.singular_tolerance;
        let prev = self.at?;
        let oi = kinematics::outer_rotary(self.m)?;
        if tol <= 0.0 {
            return None;
        }
        let (from, target) = (prev.actual[oi], actual[oi]);
        if (target - from).abs() < 1e-9 {
            return None;
        }
        let dev = |a: f64| kinematics::hold_outer(self.m, pose, self.tool.setup(), a, branch).map_or(f64::INFINITY, |(_, d)| d);
        // The smallest step toward the planner's exact choice that stays within the tolerance.
        let t = if dev(from) <= tol {
            0.0
        } else {
            let (mut lo, mut hi) = (0.0, 1.0);
            for _ in 0..40 {
                let mid = 0.5 * (lo + hi);
                if dev(from + mid * (target - from)) <= tol {
                    hi = mid
                } else {
                    lo = mid
                }
            }
            hi
        };
        if t >= 1.0 - 1e-9 {
            return None;
        }
        let a = from + t * (target - from);
        let (s, d) = kinematics::hold_outer(self.m, pose, self.tool.setup(), a, branch)?;
        let mut j = s.joints;
        let mut act = s.actual;
        for (i, r) in self.m.rotaries.iter().enumerate() {
            act[i] = if i == oi {
                a
            } else {
                prev.actual[i] + wrap(s.actual[i] - prev.actual[i])
            };
            j.rotary[i] = r.word(act[i]);
        }
        if kinematics::limit_violation(self.m, &j, 1e-6).is_some() && kinematics::limit_violation(self.m, joints, 1e-6).is_none()
        {
            return None; // holding would leave travel: stay exact
        }
        let reached = fk(self.m, &j, self.tool.setup()).axis;
        let saved = ((target - from).abs() - (a - from).abs()).to_degrees();
        self.singular.smoothed(d.to_degrees());
        Some((j, act, reached, d.to_degrees(), saved))
    }

    /// Whether `axis` lies within the singular cone (`Options::singular_cone`) of the singular
    /// direction, either way: where the free rotary is held.
    pub(super) fn in_singular_cone(&self, axis: &Vec3) -> bool {
        self.singular.in_cone(axis)
    }

    /// The midpoint with the rotaries at `want` (actual angles), the tip exactly at `tip`, and
    /// the angle (degrees) by which its tool axis misses `axis`.
    pub(super) fn held_midpoint(&self, a: &At, want: &[f64; 3], tip: &Vec3, axis: &Vec3) -> (At, f64) {
        let mut joints = a.joints;
        for (i, r) in self.m.rotaries.iter().enumerate() {
            joints.rotary[i] = r.word(want[i]);
        }
        let axis_fk = fk(self.m, &joints, self.tool.setup()).axis;
        let cp = kinematics::controlled_point(self.m, want, tip, self.tool.setup());
        for i in 0..3 {
            joints.linear[i] = if self.m.linears[i].is_some() { cp[i] } else { 0.0 };
        }
        let at = At {
            joints,
            actual: *want,
            pose: Pose {
                tip: *tip,
                axis: axis_fk,
            },
            branch: a.branch,
            free: None,
        };
        (at, angle_between(&axis_fk, axis).to_degrees())
    }
}

/// The solution with `free` free whose other rotaries lie nearest `actual`: the same root. A chain
/// missing a linear has several (the outer rotary a half turn apart).
pub(super) fn nearest_singular(sols: &kinematics::Solutions, free: usize, actual: &[f64; 3]) -> Option<kinematics::Solution> {
    sols.iter()
        .filter(|s| s.singular == Some(free))
        .min_by(|x, y| rotary_offset(x, actual, Some(free)).total_cmp(&rotary_offset(y, actual, Some(free))))
        .copied()
}

/// How far a solution's rotaries lie from `actual`, each the short way round (`skip`: a free one
/// left out).
pub(super) fn rotary_offset(s: &kinematics::Solution, actual: &[f64; 3], skip: Option<usize>) -> f64 {
    (0..3)
        .filter(|&i| Some(i) != skip)
        .map(|i| wrap(s.actual[i] - actual[i]).abs())
        .sum()
}
