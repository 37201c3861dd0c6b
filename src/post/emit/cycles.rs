//! Canned hole cycles (ISO G73–G89, Siemens MCALL CYCLE81–89, Heidenhain CYCL DEF 200–207)
//! where a hole runs along the machine's Z, with the hole's bottom replayed through FK; the
//! cycle's values checked against what the control's words take.

use super::{Ahead, At, Emitter};
use crate::cl::{CycleKind, FeedUnit};
use crate::diag::{Code, Diagnostic, Severity};
use crate::kinematics::{self, Joints, Vec3, angle_between, fk};
use crate::nc::{Canned, CannedKind, CycleLines, FeedMode};
use crate::post::plan::Committed;
use crate::post::{AxisWords, BlockInfo, Error, Hole, HolePart, Mode, MotionPt, Sink, Summary};
use crate::post::Stop;

/// The canned cycle the control has on (until cancelled), and whether the points of the hole it
/// just drilled are still arriving (they were written as the cycle).
#[derive(Debug, Default)]
pub(super) struct Cycles {
    on: Option<Canned>,
    in_hole: bool,
    /// Holes written as canned cycles.
    holes: u64,
}

impl Cycles {
    pub(super) fn summary(&self, sum: &mut Summary) {
        sum.canned_holes = self.holes;
    }
}

impl<S: Sink + ?Sized> Emitter<'_, S> {
    /// A committed point that is part of a hole: a hole's start written as a canned cycle (or
    /// refused), the rest of a hole so written passed over. `Some`: the point is written as a
    /// move.
    #[inline]
    pub(super) fn hole_point(&mut self, c: Committed, ahead: Ahead) -> Result<Option<Committed>, Error> {
        match c.pt.hole.as_deref().copied() {
            Some(HolePart::Start(h)) if self.o.canned_cycles || h.kind.canned_only() => {
                self.cycles.in_hole = false;
                match self.canned_check(&c, &h, ahead) {
                    Ok((cb, start)) => return self.canned_hole(c, h, cb, start, ahead).map(|_| None),
                    Err(why) if h.kind.canned_only() => return self.hole_refused(c, &h, why, ahead).map(|_| None),
                    Err(why) => self.expanded(&c.pt, why)?,
                }
            }
            // A hole written as moves begins.
            Some(HolePart::Clear) => self.cycles.in_hole = false,
            // The rest of a hole written as a cycle (or refused).
            Some(HolePart::Top) if self.cycles.in_hole => {
                self.written.cl_point(true);
                return Ok(None);
            }
            Some(_) if self.cycles.in_hole => return Ok(None),
            _ => self.cycles.in_hole = false,
        }
        Ok(Some(c))
    }

    pub(super) fn cancel_cycle(&mut self) -> Result<(), Stop> {
        if self.cycles.on.take().is_some()
            && let Some(l) = self.f.canned_off()
        {
            self.out(&l)?;
        }
        Ok(())
    }

    pub(super) fn expanded(&mut self, pt: &MotionPt, why: &'static str) -> Result<(), Stop> {
        self.say_once(why, Code::CycleExpanded, Some(pt.line), "drilling cycle written as moves")
    }

    /// The hole starting at this point as a canned cycle, with the tool where the point puts it,
    /// or why it cannot be one. Z levels are filled in from the start level once known.
    fn canned_check(&mut self, c: &Committed, h: &Hole, ahead: Ahead) -> Result<(Canned, At), &'static str> {
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
        let kind = self.canned_kind(h)?;
        if let Some(why) = self.f.cannot(kind) {
            return Err(why);
        }
        let feed = match h.feed {
            Some((f, FeedUnit::PerMinute)) => f,
            Some((f, FeedUnit::PerRev)) => f * self.spindle.rpm().ok_or("a feed per revolution with no spindle speed")?,
            None => 0.0,
        };
        if feed.is_nan() || feed <= 0.0 {
            return Err("the cycle has no feed");
        }
        // A tap's feed is its pitch times the speed: both must be known, and the speed turning.
        let rpm = self.spindle.turning().filter(|s| *s > 0.0);
        let pitch = match (kind, rpm) {
            (CannedKind::Tap { .. }, None) => {
                return Err("a tap with no spindle speed turning (its feed is the pitch times the speed)");
            }
            (CannedKind::Tap { .. }, Some(s)) => feed / s,
            _ => 0.0,
        };
        let feed = match (h.feed, rpm) {
            (Some((f, FeedUnit::PerRev)), Some(s)) if matches!(kind, CannedKind::Tap { .. }) => f * s,
            _ => feed,
        };
        let cand = c
            .cand
            .as_ref()
            .filter(|k| k.feasible)
            .ok_or("the hole's start is not reachable within travel")?;
        let (joints, actual, branch, free) = self.resolve(&c.pt.pose, cand, true, ahead.free).ok_or("no solution")?;
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
            pitch,
            rpm: rpm.unwrap_or(0.0),
            shift: h.shift.unwrap_or(0.0),
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

    /// A tap or a stopping bore that cannot be the control's cycle here: an error naming its CL
    /// line, the tool taken to the hole's start level above it, and the hole left undrilled
    /// (moves would snap the tap or mark the wall).
    fn hole_refused(&mut self, c: Committed, h: &Hole, why: &str, ahead: Ahead) -> Result<(), Error> {
        let line = c.pt.line;
        let d = Diagnostic::new(
            Code::CycleRefused,
            Severity::Error,
            Some(line),
            format!("{} not written: {why}; the hole is not machined", h.kind.name()),
        );
        self.note(d)?;
        let pt = MotionPt { hole: None, ..c.pt };
        self.point_at(Committed { pt, ..c }, ahead)?;
        self.cycles.in_hole = true;
        Ok(())
    }

    /// The control's cycle for a CL cycle: the hand of a tap from the record or else the
    /// spindle's direction (a left-hand record with the spindle turning CW is refused: the
    /// control would cut a right-hand thread or stop).
    fn canned_kind(&self, h: &Hole) -> Result<CannedKind, &'static str> {
        let pecks = h.peck.is_some_and(|q| q > 0.0);
        let dwells = h.dwell.is_some_and(|t| t > 0.0);
        Ok(match h.kind {
            CycleKind::Deep if pecks => CannedKind::Peck,
            CycleKind::BreakChip if pecks => CannedKind::ChipBreak,
            CycleKind::Drill | CycleKind::Deep | CycleKind::BreakChip if dwells => CannedKind::Spot,
            CycleKind::Drill | CycleKind::Deep | CycleKind::BreakChip => CannedKind::Drill,
            CycleKind::Tap { left: true, .. } if self.spindle.ccw() == Some(false) => {
                return Err("a left-hand tap with the spindle turning clockwise");
            }
            CycleKind::Tap { rigid, left } => CannedKind::Tap {
                rigid,
                left: left || self.spindle.ccw() == Some(true),
            },
            CycleKind::Bore => CannedKind::Bore,
            CycleKind::BoreStop => CannedKind::BoreStop,
            CycleKind::BoreOrient => CannedKind::FineBore,
            CycleKind::BoreBack => return Err("kinepost writes no back boring cycle yet"),
            CycleKind::Other => return Err("the CL's cycle is not one kinepost knows as a canned cycle"),
        })
    }

    /// The cycle's values within what the control's words take, else an error naming the CL
    /// line and the value written at the safe side: a feed at the control's largest (slower),
    /// a dwell at its longest (shorter), a peck deeper than the hole as the hole's depth (the
    /// same one plunge), one that rounds to nothing as the word's smallest step (more pecks).
    fn cycle_values(&self, cb: &mut Canned, line: u32) -> Vec<Diagnostic> {
        let (d, fmt) = (&self.o.dialect, self.f.fmt);
        let mut told = Vec::new();
        let mut err = |msg: String| told.push(Diagnostic::new(Code::WordRange, Severity::Error, Some(line), msg));
        let max = super::feed::feed_max(d, self.m.units, FeedMode::PerMinute);
        if cb.feed.is_nan() || cb.feed > max {
            err(format!(
                "the cycle's feed {:e} is beyond what {} takes ({max}): written {max}",
                cb.feed, d.name
            ));
            cb.feed = max;
        }
        let step = fmt.feed_step(FeedMode::PerMinute);
        if cb.feed < 0.5 * step {
            err(format!("the cycle's feed {:e} rounds to F0: written {step}", cb.feed));
            cb.feed = step;
        }
        if cb.dwell.is_nan() || cb.dwell > d.ranges.dwell_s {
            let max = d.ranges.dwell_s;
            err(format!(
                "the cycle's dwell of {:e} s is beyond what {} takes ({max} s): written {max} s",
                cb.dwell, d.name
            ));
            cb.dwell = max;
        }
        if matches!(cb.kind, CannedKind::Peck | CannedKind::ChipBreak) {
            let (depth, lstep) = (cb.z_top - cb.z_bottom, 2.0 * fmt.half_linear());
            if cb.peck.is_nan() || cb.peck < 0.5 * lstep {
                err(format!("the cycle's peck of {:e} rounds to Q0: written {lstep}", cb.peck));
                cb.peck = lstep;
            } else if cb.peck > depth {
                cb.peck = depth.max(lstep);
            }
        }
        told
    }

    /// Whether one unit of machine Z moves the tip one unit back along the tool axis here: then
    /// a canned cycle's Z words drill the hole.
    pub(super) fn along_z(&self, joints: &Joints, actual: &[f64; 3], axis: &Vec3) -> bool {
        let mut up = joints.linear;
        up[2] += 1.0;
        let d = kinematics::fk_actual(self.m, &up, actual, self.tool.setup()).tip
            - kinematics::fk_actual(self.m, &joints.linear, actual, self.tool.setup()).tip;
        (d - axis.normalize()).norm() < 1e-9
    }

    /// One hole as a canned cycle: the approach as any rapid (cancelling the previous cycle
    /// unless this hole continues it), then the cycle block.
    fn canned_hole(&mut self, c: Committed, h: Hole, mut cb: Canned, start: At, ahead: Ahead) -> Result<(), Error> {
        let pt = c.pt.clone();
        let before = self.at;
        self.cycle_in_plane(&mut cb, &start);
        let told = self.cycle_values(&mut cb, pt.line);
        let modal = match (self.cycles.on, self.at) {
            (Some(on), Some(at)) => {
                let same_rot = (0..self.m.rotaries.len()).all(|i| (start.joints.rotary[i] - at.joints.rotary[i]).abs() < 1e-9);
                same_rot && on.same_cycle(&cb, &self.f.fmt) && self.f.modal_cycle(cb.kind)
            }
            _ => false,
        };
        let at = if modal {
            start
        } else {
            self.cancel_cycle()?;
            self.point(
                Committed {
                    pt: MotionPt {
                        hole: None,
                        ..pt.clone()
                    },
                    ..c
                },
                ahead,
            )?;
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
        self.written.positioned(false);
        self.canned_block(&pt, &h, cb, at, before.filter(|_| modal), told)
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
    pub(super) fn canned_block(
        &mut self,
        pt: &MotionPt,
        h: &Hole,
        cb: Canned,
        at: At,
        from: Option<At>,
        told: Vec<Diagnostic>,
    ) -> Result<(), Error> {
        let (m, modal) = (self.m, from.is_some());
        let CycleLines { lines, call } = self.f.canned(&cb, modal);
        for l in &lines[..call] {
            self.out(l)?;
        }
        // Self-verification: the bottom of the hole, replayed from the words as written.
        let u = at.pose.axis.normalize();
        let want = at.pose.tip - u * (h.start + h.depth);
        let mut j = at.joints;
        j.linear[2] = cb.z_bottom;
        let tilt = self.frames.tilt();
        if tilt.is_some() {
            // The machine's linears at the bottom (block info); the words are plane coordinates.
            let cp = kinematics::controlled_point(m, &at.actual, &want, self.tool.setup());
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
        let replay = fk(m, &j, self.tool.setup());
        let tip_dev = match &tilt {
            Some(t) => (self.plane_tip(t, [cb.x.unwrap_or(0.0), cb.y.unwrap_or(0.0), cb.z_bottom]) - want).norm(),
            None => (replay.tip - want).norm(),
        };
        let ax_dev = angle_between(&replay.axis, &u).to_degrees();
        let mut diags: Vec<Diagnostic> = told
            .into_iter()
            .chain(self.replayed(pt.line, tip_dev, ax_dev, "the cycle's bottom misses the hole"))
            .chain(self.spindle.standing(pt.line))
            .collect();
        self.hole_collisions(from.as_ref(), &at, &cb, pt.line, &mut diags);
        for d in &diags {
            self.count(d);
            self.flag(d)?;
        }
        // Rapid down to R, feed to the bottom, the dwell, back to the start level: at rapid, or
        // at the feed to R for a tap or a bore that comes out as it went in.
        let (down, out) = (cb.z_r - cb.z_bottom, cb.z_start - cb.z_bottom);
        let back = match cb.kind.feeds_out() {
            true => down / cb.feed + self.z_rapid_time(cb.z_start - cb.z_r),
            false => self.z_rapid_time(out),
        };
        let time = self.z_rapid_time(cb.z_start - cb.z_r) + down / cb.feed + back + cb.dwell / 60.0;
        let n = self.written.hole(time, axes[2], cb.z_bottom);
        self.cycles.holes += 1;
        let info = BlockInfo {
            n,
            source_line: Some(pt.line),
            joints: AxisWords(axes),
            diagnostics: diags,
            rapid: false,
            tip: want.into(),
            axis: u.into(),
            time_s: time * 60.0,
        };
        self.line(&lines[call], Some(&info))?;
        for l in &lines[call + 1..] {
            self.out(l)?;
        }
        self.cycles.on = self.f.modal_cycle(cb.kind).then_some(cb);
        self.cycles.in_hole = true;
        Ok(())
    }
}
