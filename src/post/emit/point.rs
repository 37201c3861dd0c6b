//! One committed CL point: the planner's candidate resolved against where the machine is, its
//! pose's diagnostics, and the motion that reaches it (positioning, arc, segment, reposition).

use super::singular::nearest_singular;
use super::{At, Emitter, limit_error};
use crate::diag::{Code, Diagnostic, Severity};
use crate::kinematics::{self, IkOptions, Joints, Pose, Solutions, angle_between, ik_into};
use crate::post::PLANE_AXIS_EPS;
use crate::post::plan::{self, Cand, Committed, wrap};
use crate::post::{Error, MotionPt, Sink};

/// What the look-ahead found after a committed point, handed to [`Emitter::point`] with it.
#[derive(Clone, Copy, Debug, Default)]
pub(in crate::post) struct Ahead {
    /// The point is a rapid whose fixed tool axis holds until the next rapid with another axis
    /// (or a tool change, or the end): a tilted plane may start there.
    pub(in crate::post) plane: bool,
    /// For a singular point: the free rotary's word (the planner's winding) where the cut after
    /// it fixes it.
    pub(in crate::post) free: Option<f64>,
}

impl<S: Sink + ?Sized> Emitter<'_, S> {
    /// The machine reaches `pt` by positioning, not by cutting: the first move, the first after
    /// a tool change, a rapid.
    pub(in crate::post) fn positioning(&self, pt: &MotionPt) -> bool {
        self.at.is_none() || self.tool.changed() || pt.rapid
    }

    /// The chosen candidate with its unbounded windings and singular free angle resolved against
    /// where the machine is; `hint`: the free angle the cut after a singular point needs.
    pub(super) fn resolve(
        &mut self,
        pose: &Pose,
        cand: &Cand,
        positioning: bool,
        hint: Option<f64>,
    ) -> Option<(Joints, [f64; 3], i8, Option<u8>)> {
        let mut sol = cand.sol;
        // Before the first move, an unbounded rotary starts nearest the angle the shop prefers.
        let start = self.o.prefer.map_or([None; 3], |p| p.start);
        if let Some(free) = sol.singular {
            let prev = self.at.map(|a| a.actual[free]).or(start[free]).unwrap_or(0.0);
            // Positioning onto a singular point (the first move, after a tool change or a rapid)
            // turns the free rotary to where the cut after it needs it: held at the old angle,
            // it turned during that cut, the tool axis off the CL orientation by up to 11° (a
            // cut from vertical to a 30° tilt on spinner-u5-620).
            let r = &self.m.rotaries[free];
            let prev = match hint.map(|w| r.actual(w)) {
                Some(h) if positioning => {
                    if r.limits.is_some() {
                        h
                    } else {
                        prev + wrap(h - prev)
                    }
                }
                _ => prev,
            };
            let opt = IkOptions {
                free_angle: prev,
                ..Default::default()
            };
            // The planned root: a chain missing a linear has several singular ones (C a half
            // turn apart), and the first of them, with the planner's A and B windings copied in,
            // put the tool 180° off the pose (propeller-3r2l).
            let mut buf = Solutions::new();
            if ik_into(self.m, pose, self.tool.setup(), &opt, &mut buf).is_ok()
                && let Some(s) = nearest_singular(&buf, free, &cand.sol.actual)
            {
                sol = s;
            }
            // The bounded windings the planner chose stay as chosen.
            for (i, r) in self.m.rotaries.iter().enumerate() {
                if i != free && r.limits.is_some() {
                    sol.joints.rotary[i] = cand.sol.joints.rotary[i];
                }
            }
        }
        let mut joints = sol.joints;
        let mut actual = sol.actual;
        for (i, r) in self.m.rotaries.iter().enumerate() {
            let base = self.at.map(|a| a.actual[i]).or(start[i]);
            if let Some(b) = base
                && r.limits.is_none()
                && sol.singular != Some(i)
            {
                actual[i] = b + wrap(sol.actual[i] - b);
                joints.rotary[i] = r.word(actual[i]);
            }
        }
        for (i, r) in self.m.rotaries.iter().enumerate() {
            if r.limits.is_some() {
                actual[i] = r.actual(joints.rotary[i]);
            }
        }
        Some((joints, actual, sol.branch, sol.singular.map(|f| f as u8)))
    }

    /// One committed CL point, with what the look-ahead found after it; a rapid that starts a
    /// fixed-axis run tilts the working plane once the machine stands there.
    pub(in crate::post) fn point(&mut self, c: Committed, ahead: Ahead) -> Result<(), Error> {
        let (rapid, tip) = (c.pt.rapid, c.pt.pose.tip);
        if self.tool.line_due() {
            self.record_tool();
        }
        self.point_at(c, ahead)?;
        if rapid && ahead.plane && self.frames.tilt().is_none() {
            self.enter_plane(&tip)?;
        }
        Ok(())
    }

    pub(super) fn point_at(&mut self, c: Committed, ahead: Ahead) -> Result<(), Error> {
        let Some(c) = self.hole_point(c, ahead)? else {
            return Ok(());
        };
        self.written.cl_point(!c.pt.inserted);
        let pt = c.pt;
        let Some(cand) = c.cand else {
            let what = match &c.error {
                Some(e) => e.to_string(),
                None => "no solution".into(),
            };
            self.note_at(
                Diagnostic::new(
                    Code::Unreachable,
                    Severity::Error,
                    Some(pt.line),
                    format!("pose unreachable on {}: {what}; block skipped", self.m.id),
                ),
                &pt.pose,
            )?;
            return Ok(());
        };
        let Some((mut joints, mut actual, branch, mut free)) = self.resolve(&pt.pose, &cand, self.positioning(&pt), ahead.free)
        else {
            return Ok(());
        };
        self.ensure_comp(pt.line)?;
        let mut diags: Vec<Diagnostic> = Vec::new();
        let mut pose = pt.pose;
        let outer = kinematics::outer_rotary(self.m);
        let exact_outer = outer.map(|oi| actual[oi]);
        if let Some(sm) = self.smooth(&pt.pose, &joints, &actual, branch) {
            diags.push(Diagnostic::new(
                Code::Singular,
                Severity::Info,
                Some(pt.line),
                format!(
                    "free rotary held: tool axis {:.4}° off the CL orientation ({:.3}° less turn in this block)",
                    sm.3, sm.4
                ),
            ));
            (joints, actual, pose.axis, free) = (sm.0, sm.1, sm.2, None);
        }
        if let (Some(oi), Some(exact)) = (outer, exact_outer) {
            self.singular.outer_at(exact, actual[oi]);
        }
        // The planner judged travel at the IK's free angle; a singular point stands at the one
        // held (mikron-ucp710: C held at 666° put Y at -277 of ±275, told as "near" its limit).
        let outside = if !cand.feasible || free.is_some() {
            kinematics::limit_violation(self.m, &joints, 1e-6)
        } else {
            None
        };
        if let Some(v) = &outside {
            self.written.outside(pt.line);
            diags.push(limit_error(v, pt.line, ""));
        } else if let Some(v) = self.near_limit(&joints) {
            diags.push(Diagnostic::new(Code::NearLimit, Severity::Info, Some(pt.line), v));
        }
        let target = At {
            joints,
            actual,
            pose,
            branch,
            free,
        };
        // After a tool change the machine stands where the change left it, not at the last
        // block: the next move, feed or not, positions as a rapid that turns rotaries does.
        let chained = self.written.take_positioned() && !self.tool.changed();
        if let Some(prev) = &self.at
            && (self.tool.changed()
                || pt.rapid
                    && (0..self.m.rotaries.len()).any(|i| (joints.rotary[i] - prev.joints.rotary[i]).abs() > 1f64.to_radians()))
        {
            self.safe_rapid(*prev, target, &pt, diags, chained)?;
            self.written.positioned(pt.rapid);
            return Ok(());
        }
        match self.at {
            Some(prev) if !pt.rapid => {
                let prev = if prev.free.is_some() {
                    self.turn_free(prev, &target, &pt)?
                } else {
                    prev
                };
                let unwind =
                    self.m.rotaries.iter().enumerate().any(|(i, r)| {
                        r.limits.is_some() && (joints.rotary[i] - prev.joints.rotary[i]).abs() > std::f64::consts::PI
                    });
                let branch_change = prev.branch * branch < 0
                    && !plan::crosses_fold(self.m, &prev.joints.rotary, &joints.rotary, &prev.pose.axis, &pt.pose.axis);
                if let (Some(arc), false, false) = (pt.arc.as_deref().copied(), unwind, branch_change) {
                    self.arc_move(prev, target, &arc, &pt, diags)?;
                    return Ok(());
                }
                // A feed that turns the axis of the plane in force: a cut longer than the look-ahead.
                if self
                    .frames
                    .tilt()
                    .is_some_and(|t| angle_between(&t.axis, &pt.pose.axis) > PLANE_AXIS_EPS)
                {
                    self.reposition(prev, target, false, &pt)?;
                } else if unwind || branch_change {
                    self.reposition(prev, target, unwind, &pt)?;
                } else {
                    self.segment(prev, target, &pt, diags)?;
                    return Ok(());
                }
            }
            _ => {}
        }
        if self.at.is_none() {
            self.approach(target, &pt, diags)?;
            self.written.positioned(pt.rapid);
            return Ok(());
        }
        self.block(target, &pt, pt.rapid || self.at.is_none(), diags, pt.inserted, None)?;
        Ok(())
    }
}
