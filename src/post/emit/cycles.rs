//! Canned drilling cycles (ISO G81–G83, Siemens MCALL, Heidenhain CYCL DEF 200) where a hole
//! runs along the machine's Z, with the hole's bottom replayed through FK.

use super::{At, Emitter};
use crate::cl::{CycleKind, FeedUnit};
use crate::diag::{Code, Diagnostic};
use crate::kinematics::{self, Joints, Vec3, angle_between, fk};
use crate::nc::{Canned, CannedKind};
use crate::post::plan::Committed;
use crate::post::{AxisWords, BlockInfo, Error, Hole, Mode, MotionPt, Sink};

impl<S: Sink + ?Sized> Emitter<'_, S> {
    pub(super) fn cancel_cycle(&mut self) -> std::io::Result<()> {
        if self.cycle_on.take().is_some()
            && let Some(l) = self.f.canned_off()
        {
            self.out(&l)?;
        }
        Ok(())
    }

    pub(super) fn expanded(&mut self, pt: &MotionPt, why: &'static str) -> std::io::Result<()> {
        self.say_once(why, Code::CycleExpanded, Some(pt.line), "drilling cycle written as moves")
    }

    /// The hole starting at this point as a canned cycle, with the tool where the point puts it,
    /// or why it cannot be one. Z levels are filled in from the start level once known.
    pub(super) fn canned_check(&mut self, c: &Committed, h: &Hole) -> Result<(Canned, At), &'static str> {
        let m = self.m;
        if self.o.mode != Mode::Joint {
            return Err("canned cycles are written in joint mode only (TCP controls refuse most)");
        }
        if h.depth <= 0.0 {
            return Err("the cycle has no depth");
        }
        if m.linears[2].is_none() {
            return Err("the machine has no Z axis");
        }
        let kind = match (h.kind, h.peck, h.dwell) {
            (CycleKind::Deep, Some(q), _) if q > 0.0 => CannedKind::Peck,
            (CycleKind::Drill | CycleKind::Deep, _, Some(t)) if t > 0.0 => CannedKind::Spot,
            (CycleKind::Drill | CycleKind::Deep, _, _) => CannedKind::Drill,
            _ => return Err("only drilling and peck drilling cycles are written canned"),
        };
        let feed = match h.feed {
            Some((f, FeedUnit::PerMinute)) => f,
            Some((f, FeedUnit::PerRev)) => f * self.rpm.ok_or("a feed per revolution with no spindle speed")?,
            None => 0.0,
        };
        if feed.is_nan() || feed <= 0.0 {
            return Err("the cycle has no feed");
        }
        let cand = c
            .cand
            .as_ref()
            .filter(|k| k.feasible)
            .ok_or("the hole's start is not reachable within travel")?;
        let (joints, actual, branch, free) = self.resolve(&c.pt.pose, cand, true).ok_or("no solution")?;
        let start = joints.linear[2];
        let (bottom, r) = (start - h.start - h.depth, start - h.start + h.clear);
        let in_plane = self.o.tilted_planes && self.plane_refused().is_none();
        if !in_plane && !self.along_z(&joints, &actual, &c.pt.pose.axis) {
            return Err("the hole does not run along the machine's Z (a tilted head needs a tilted work plane)");
        }
        if m.linears[2]
            .as_ref()
            .is_some_and(|l| bottom < l.min - 1e-6 || bottom > l.max + 1e-6)
        {
            return Err("the hole's bottom is beyond Z travel");
        }
        let cb = Canned {
            kind,
            x: m.linears[0].is_some().then_some(joints.linear[0]),
            y: m.linears[1].is_some().then_some(joints.linear[1]),
            z_top: start - h.start,
            z_r: r,
            z_bottom: bottom,
            z_start: start,
            feed,
            peck: h.peck.unwrap_or(0.0),
            dwell: h.dwell.unwrap_or(0.0),
        };
        let at = At {
            joints,
            actual,
            pose: c.pt.pose,
            branch,
            free,
        };
        Ok((cb, at))
    }

    /// Whether one unit of machine Z moves the tip one unit back along the tool axis here: then
    /// a canned cycle's Z words drill the hole.
    pub(super) fn along_z(&self, joints: &Joints, actual: &[f64; 3], axis: &Vec3) -> bool {
        let mut up = joints.linear;
        up[2] += 1.0;
        let d = kinematics::fk_actual(self.m, &up, actual, &self.setup).tip
            - kinematics::fk_actual(self.m, &joints.linear, actual, &self.setup).tip;
        (d - axis.normalize()).norm() < 1e-9
    }

    /// One hole as a canned cycle: the approach as any rapid (cancelling the previous cycle
    /// unless this hole continues it), then the cycle block.
    pub(super) fn canned_hole(&mut self, c: Committed, h: Hole, mut cb: Canned, start: At) -> Result<(), Error> {
        let pt = c.pt.clone();
        let before = self.at;
        self.cycle_in_plane(&mut cb, &start);
        let modal = match (self.cycle_on, self.at) {
            (Some(on), Some(at)) => {
                let same_rot = (0..self.m.rotaries.len()).all(|i| (start.joints.rotary[i] - at.joints.rotary[i]).abs() < 1e-9);
                same_rot && on.same_cycle(&cb, &self.f.fmt)
            }
            _ => false,
        };
        let at = if modal {
            start
        } else {
            self.cancel_cycle()?;
            self.point(Committed {
                pt: MotionPt {
                    hole: None,
                    ..pt.clone()
                },
                ..c
            })?;
            // The approach as written: the cycle starts from there.
            match self.at {
                // In a tilted plane its Z is the tool axis: the cycle in plane coordinates.
                Some(at) if (at.pose.tip - pt.pose.tip).norm() < 1e-9 && self.cycle_in_plane(&mut cb, &at) => at,
                Some(at) if (at.pose.tip - pt.pose.tip).norm() < 1e-9 && self.along_z(&at.joints, &at.actual, &at.pose.axis) => {
                    let [x, y, z] = at.joints.linear;
                    cb.start_at(cb.x.map(|_| x), cb.y.map(|_| y), z);
                    at
                }
                _ => return Ok(()), // the rest of the hole follows as moves
            }
        };
        self.at = Some(at);
        self.positioned = false;
        self.canned_block(&pt, &h, cb, at, before.filter(|_| modal))
    }

    /// A cycle's words moved into the tilted plane in force, when the tool stands on its
    /// rotaries at `at` (the cycle's start); false when no plane holds there.
    pub(super) fn cycle_in_plane(&self, cb: &mut Canned, at: &At) -> bool {
        let Some(t) = self.plane_at(&at.joints.rotary) else {
            return false;
        };
        let q = self.plane_coords(&t, &at.pose.tip);
        cb.start_at(Some(q.x), Some(q.y), q.z);
        true
    }

    /// The cycle's block; `from`: the hole before, where this one goes on with its cycle.
    pub(super) fn canned_block(&mut self, pt: &MotionPt, h: &Hole, cb: Canned, at: At, from: Option<At>) -> Result<(), Error> {
        let (m, modal) = (self.m, from.is_some());
        let lines = self.f.canned(&cb, modal);
        let Some((call, def)) = lines.split_last() else {
            return Ok(());
        };
        for l in def {
            self.out(l)?;
        }
        // Self-verification: the bottom of the hole, replayed from the words as written.
        let u = at.pose.axis.normalize();
        let want = at.pose.tip - u * (h.start + h.depth);
        let mut j = at.joints;
        j.linear[2] = cb.z_bottom;
        let tilt = self.tilt;
        if tilt.is_some() {
            // The machine's linears at the bottom (block info); the words are plane coordinates.
            let cp = kinematics::controlled_point(m, &at.actual, &want, &self.setup);
            j.linear = [cp.x, cp.y, cp.z];
        }
        let mut axes: [Option<f64>; 6] = [None; 6];
        for i in 0..3 {
            if m.linears[i].is_some() {
                axes[i] = Some(j.linear[i]);
                j.linear[i] = self.f.written(j.linear[i], i);
            }
        }
        for (i, r) in m.rotaries.iter().enumerate() {
            axes[r.slot()] = Some(at.joints.rotary[i].to_degrees());
        }
        j.rotary = self.written_rotaries(&at.joints.rotary);
        let replay = fk(m, &j, &self.setup);
        let tip_dev = match &tilt {
            Some(t) => (self.plane_tip(t, [cb.x.unwrap_or(0.0), cb.y.unwrap_or(0.0), cb.z_bottom]) - want).norm(),
            None => (replay.tip - want).norm(),
        };
        let ax_dev = angle_between(&replay.axis, &u).to_degrees();
        let mut diags: Vec<Diagnostic> = self
            .replayed(pt.line, tip_dev, ax_dev, "the cycle's bottom misses the hole")
            .into_iter()
            .chain(self.spindle_standing(pt.line))
            .collect();
        self.hole_collisions(from.as_ref(), &at, &cb, pt.line, &mut diags);
        for d in &diags {
            self.count(d);
            self.flag(d)?;
        }
        // Rapid down to R, feed to the bottom, rapid back to the start level.
        let time = self.z_rapid_time(cb.z_start - cb.z_r)
            + (cb.z_r - cb.z_bottom) / cb.feed
            + self.z_rapid_time(cb.z_start - cb.z_bottom);
        self.sum.cycle_time_s += time * 60.0;
        if let Some(st) = self.stats[2].as_mut() {
            st.min = st.min.min(axes[2].unwrap_or(cb.z_bottom));
        }
        self.blocks += 1;
        self.sum.blocks += 1;
        self.sum.canned_holes += 1;
        let info = BlockInfo {
            n: self.blocks,
            source_line: Some(pt.line),
            joints: AxisWords(axes),
            diagnostics: diags,
            rapid: false,
            tip: want.into(),
            axis: u.into(),
            time_s: time * 60.0,
        };
        self.line(call, Some(&info))?;
        self.cycle_on = Some(cb);
        self.in_hole = true;
        Ok(())
    }
}
