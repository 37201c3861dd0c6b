//! Positioning: retracts (as `Options::retract` says: the top of Z, along the tool axis, or up
//! to a plane, within travel), approaches, rapids that turn rotaries, repositions and unwinds
//! (the rotary clamps around them: `clamps.rs`).

use super::singular::rotary_offset;
use super::{At, Emitter};
use crate::diag::{Code, Diagnostic, Severity};
use crate::kinematics::{self, IkOptions, Joints, Pose, Solutions, Vec3, fk, ik_into};
use crate::post::plan::wrap;
use crate::post::{Error, Mode, MotionPt, Retract, Sink};

impl<S: Sink + ?Sized> Emitter<'_, S> {
    /// `a` out of the way, as the retract policy says: at the top of Z travel (same X Y and
    /// rotaries), else along the tool axis (`clear_of`).
    pub(super) fn above(&mut self, a: At) -> At {
        match self.z_top() {
            Some(zmax) => {
                let mut joints = a.joints;
                joints.linear[2] = zmax;
                At {
                    joints,
                    pose: fk(self.m, &joints, self.tool.setup()),
                    ..a
                }
            }
            None => self.clear_of(a),
        }
    }

    /// The top of Z travel, where positioning turns the rotaries under `retract=machine-z`
    /// (none in TCP mode, where X Y Z are the tip, or on a machine without Z).
    pub(super) fn z_top(&self) -> Option<f64> {
        let zmax = self.m.linears[2].as_ref().map(|l| l.max);
        zmax.filter(|_| self.o.mode == Mode::Joint && self.o.retract == Retract::MachineZ)
    }

    /// `a` lifted along its tool axis: by the policy's distance, up to its plane (not down: a
    /// point above the plane stays), or by the clearance where the policy is the top of Z. A
    /// tool axis within 6° of horizontal never reaches a plane: the clearance then.
    pub(super) fn clear_of(&mut self, a: At) -> At {
        let d = match self.o.retract {
            Retract::Axis(d) => d,
            Retract::Plane(z) if a.pose.axis.z > 0.1 => ((z - a.pose.tip.z) / a.pose.axis.z).max(0.0),
            _ => self.o.clearance,
        };
        self.lifted(a, d)
    }

    /// Up and away from the part before a tool change and at the program's end, whatever the
    /// change macro or the operator does next: joint mode to the top of Z travel where the tool
    /// stands, TCP (or no Z axis) the clearance along the tool axis. Nothing before the first
    /// block.
    #[cold]
    pub(super) fn retract_up(&mut self) -> Result<(), Error> {
        let Some(prev) = self.at else { return Ok(()) };
        let up = self.above(prev);
        if up.joints.linear == prev.joints.linear {
            return Ok(()); // at the top already
        }
        let pt = MotionPt {
            line: self.written.last_line(),
            pose: up.pose,
            rapid: true,
            feed: None,
            inserted: true,
            comment: None,
            arc: None,
            hole: None,
        };
        self.block(up, &pt, true, Vec::new(), true, Some("RETRACT"))
    }

    /// The program's first move, from home (the tool up, rotaries at 0): over the point at the
    /// top of Z travel with the rotaries turned, then straight down (TCP, or no Z axis: from
    /// the clearance along the tool axis), so that the table or head never turns while the tool
    /// comes down to the part. The real NX post also turns the rotaries first.
    #[cold]
    pub(super) fn approach(&mut self, to: At, pt: &MotionPt, diags: Vec<Diagnostic>) -> Result<(), Error> {
        let over = self.above(to);
        self.block(over, pt, true, diags, true, Some("APPROACH"))?;
        self.lock_all()?;
        self.descend(to, pt)
    }

    /// The end of positioning, from over the point (joint mode: the top of Z; else the clearance
    /// along the tool axis) onto it: at rapid onto a rapid point; onto a feed point at rapid to
    /// the clearance along the tool axis, then at feed, as a reposition re-approaches. A feed
    /// point may lie on the part: after a tool change it was reached at rapid.
    pub(super) fn descend(&mut self, to: At, pt: &MotionPt) -> Result<(), Error> {
        if pt.rapid || pt.feed.is_none() {
            return self.block(to, pt, true, Vec::new(), pt.inserted, None);
        }
        if self.z_top().is_some() {
            let near = self.lifted(to, self.o.clearance);
            if kinematics::limit_violation(self.m, &near.joints, 1e-6).is_none() {
                self.block(near, pt, true, Vec::new(), true, None)?;
            }
        }
        self.block(to, pt, false, Vec::new(), pt.inserted, None)
    }

    /// An axis within 1 % of its travel (1° for rotaries) of an end: worth knowing before the
    /// machine stops on a limit with the next setup's offsets.
    pub(super) fn near_limit(&self, j: &Joints) -> Option<String> {
        for (i, l) in self.m.linears.iter().enumerate() {
            if let Some(l) = l {
                let margin = 0.01 * (l.max - l.min);
                let v = j.linear[i];
                if v < l.min + margin || v > l.max - margin {
                    return Some(format!(
                        "{} = {:.4} within 1% of its travel [{}, {}]",
                        kinematics::LINEAR_NAMES[i],
                        v,
                        l.min,
                        l.max
                    ));
                }
            }
        }
        for (i, r) in self.m.rotaries.iter().enumerate() {
            if let Some((lo, hi)) = r.limits {
                let v = j.rotary[i];
                let margin = 1f64.to_radians();
                if v < lo + margin || v > hi - margin {
                    return Some(format!(
                        "{} = {:.4}° within 1° of its travel [{}, {}]",
                        r.name,
                        v.to_degrees(),
                        lo.to_degrees(),
                        hi.to_degrees()
                    ));
                }
            }
        }
        None
    }

    /// A rapid that turns the rotaries: never together with the linears near the part. At the
    /// top of Z (`retract=machine-z`): machine Z up, rotaries alone, then X Y, then down. Else,
    /// or `chained` to a positioning that climbed already (the machine stands at a CL rapid
    /// point in the air): lift along the tool axis (`clear_of`), turn there, approach.
    pub(super) fn safe_rapid(
        &mut self,
        prev: At,
        to: At,
        pt: &MotionPt,
        mut diags: Vec<Diagnostic>,
        chained: bool,
    ) -> Result<(), Error> {
        // The rotaries turn: out of a tilted plane first, so the retract reads as one.
        self.leave_plane(true)?;
        if self.z_top().is_none() || chained {
            let (up, over) = (self.clear_of(prev), self.clear_of(to));
            if up.joints != prev.joints {
                self.block(up, pt, true, std::mem::take(&mut diags), true, Some("RETRACT"))?;
            }
            self.block(over, pt, true, diags, true, Some("ROTARY REPOSITION"))?;
            if chained {
                self.lock_all()?; // as after the climb it stands for
            }
            return self.descend(to, pt);
        }
        let (up, over) = (self.above(prev), self.above(to));
        // Turned at the top, still over the old X Y; then over the new one, then down.
        let mut joints = up.joints;
        joints.rotary = to.joints.rotary;
        let turned = At {
            joints,
            pose: fk(self.m, &joints, self.tool.setup()),
            ..to
        };
        self.block(up, pt, true, diags, true, Some("RETRACT Z"))?;
        self.block(turned, pt, true, Vec::new(), true, Some("ROTARY REPOSITION"))?;
        self.block(over, pt, true, Vec::new(), true, None)?;
        self.lock_all()?;
        self.descend(to, pt)
    }

    /// Retract along the tool axis, turn at clearance, re-approach: for an unwind of a bounded
    /// rotary or a change of IK branch inside a cut.
    pub(super) fn reposition(&mut self, prev: At, to: At, unwind: bool, pt: &MotionPt) -> Result<(), Error> {
        let word = if unwind { "UNWIND" } else { "REPOSITION" };
        let code = if unwind { Code::Unwind } else { Code::BranchChange };
        let why = if self.frames.tilt().is_some() {
            " (the tilted plane's fixed tool axis turns inside a cut)"
        } else {
            ""
        };
        let r1 = self.clear_of(prev);
        let r2 = self.clear_of(to);
        // The shop's policy may allow unwinds only where the CL repositions anyway.
        let refused = unwind && self.o.unwind == crate::post::Unwind::AtRapids;
        let d = Diagnostic::new(
            code,
            if refused { Severity::Error } else { Severity::Warning },
            Some(pt.line),
            format!(
                "{word}: retract {:.3} along the tool axis, turn, re-approach{why}{}",
                (r1.pose.tip - prev.pose.tip).norm(),
                if refused { " (unwind=rapids allows none inside a cut: written so the part is safe, check the toolpath)" } else { "" }
            ),
        );
        let mut diags = vec![d];
        if r1.joints != prev.joints {
            self.block(r1, pt, true, std::mem::take(&mut diags), true, Some(&format!("RETRACT {word}")))?;
        }
        self.block(r2, pt, true, diags, true, Some(word))?;
        self.block(to, pt, false, Vec::new(), pt.inserted, None)?;
        Ok(())
    }

    /// The same orientation `clear` further along the tool axis, or less where the travel ends
    /// first (a `near_limit` warning on the next block says how much): a retract, approach or
    /// re-approach point past the travel stopped the machine on overtravel (fryer-5x-45 in TCP
    /// mode: every approach 1 in over Z's end). With three linears only the linears move; a
    /// chain missing one needs the exact solution nearest the current one.
    pub(super) fn lifted(&mut self, a: At, clear: f64) -> At {
        let at = |e: &mut Self, t: f64| -> At {
            let tip = a.pose.tip + a.pose.axis * t;
            if e.m.linears.iter().all(|l| l.is_some()) {
                return e.at_tip(&a, tip);
            }
            let pose = Pose { tip, axis: a.pose.axis };
            e.exact_near(pose, &a).unwrap_or(a)
        };
        let full = at(self, clear);
        let Some(v) = kinematics::limit_violation(self.m, &full.joints, 1e-6) else {
            return full;
        };
        // From a point within travel only (one outside is its own error): the longest retract
        // that stays within, by bisection (the linears are affine in it with three linears, not
        // with two; 40 halvings leave nanometres).
        if kinematics::limit_violation(self.m, &a.joints, 1e-6).is_some() {
            return full;
        }
        // One word's unit inside the travel: the written, rounded words land within it too (at
        // the bisection's exact end, TCP's rounded tip put dmg-dmc75v's X 0.0005 mm past -375).
        let margin = -2.0 * self.f.fmt.half_linear();
        let (mut lo, mut hi) = (0.0, clear);
        for _ in 0..40 {
            let mid = 0.5 * (lo + hi);
            if kinematics::limit_violation(self.m, &at(self, mid).joints, margin).is_some() {
                hi = mid;
            } else {
                lo = mid;
            }
        }
        self.written.tell_next(Diagnostic::new(
            Code::NearLimit,
            Severity::Warning,
            None,
            format!(
                "retract along the tool axis shortened to {lo:.4} of {clear} by {}'s travel [{}, {}]",
                v.axis, v.min, v.max
            ),
        ));
        at(self, lo)
    }

    /// `a`'s rotaries and orientation with the tip at `tip`: only the linears move. For a machine
    /// with all three linears (on one missing a linear the rotaries place the tip too).
    pub(super) fn at_tip(&self, a: &At, tip: Vec3) -> At {
        let cp = kinematics::controlled_point(self.m, &a.actual, &tip, self.tool.setup());
        let mut joints = a.joints;
        joints.linear = [cp.x, cp.y, cp.z];
        At {
            joints,
            pose: Pose { tip, axis: a.pose.axis },
            ..*a
        }
    }

    /// The exact solution of `pose` nearest `a` in the rotaries, wound next to `a`'s angles. On a
    /// chain missing a linear the rotaries place the tip too: a pose of `a`'s orientation
    /// elsewhere needs other angles. A singular pose keeps its free rotary where `a` has it.
    pub(super) fn exact_near(&mut self, pose: Pose, a: &At) -> Option<At> {
        let opt = IkOptions {
            free_angle: kinematics::free_rotary(self.m).map_or(0.0, |f| a.actual[f]),
            ..Default::default()
        };
        let mut buf = Solutions::new();
        ik_into(self.m, &pose, self.tool.setup(), &opt, &mut buf).ok()?;
        let s = buf
            .iter()
            .min_by(|x, y| rotary_offset(x, &a.actual, None).total_cmp(&rotary_offset(y, &a.actual, None)))?;
        let mut actual = s.actual;
        let mut joints = s.joints;
        for (i, r) in self.m.rotaries.iter().enumerate() {
            actual[i] = a.actual[i] + wrap(s.actual[i] - a.actual[i]);
            joints.rotary[i] = r.word(actual[i]);
        }
        Some(At {
            joints,
            actual,
            pose,
            branch: s.branch,
            free: s.singular.map(|f| f as u8),
        })
    }
}
