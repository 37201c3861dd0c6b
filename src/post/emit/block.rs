//! The block writer: a motion block's words, its diagnostics, its FK replay from the words as
//! written, the statistics, and the line handed to the sink.

use super::{ArcBlock, At, Emitter, feed, limit_error};
use crate::diag::{Code, Diagnostic, Severity};
use crate::kinematics::{self, Vec3, angle_between, fk};
use crate::nc::Motion;
use crate::post::{AxisStats, AxisWords, BlockInfo, Error, Mode, MotionPt, Sink, Summary};

/// Axis miss (degrees) of an FK replay that is an error.
const REPLAY_AXIS_DEG: f64 = 0.01;

/// What the program has come to so far: the blocks written (how many, the last one's CL line,
/// whether positioning brought the machine there), each axis's extents and travel, the FK
/// replay's largest misses, what has been told, and the summary all of it goes into.
pub(super) struct Written {
    sum: Summary,
    blocks: u64,
    /// Per axis letter (X Y Z A B C): extents and travel, moved into the summary at the end.
    stats: [Option<AxisStats>; 6],
    /// The CL line of the last block written (a retract at a tool change or the end has none).
    last_line: u32,
    /// The machine stands at a CL rapid point that positioning brought it to, in the air where
    /// the CAM put it: a rapid from there that turns rotaries need not climb the whole Z again.
    positioned: bool,
    /// The CL line of the last point outside travel: blocks inserted for it say nothing more.
    outside_line: Option<u32>,
    /// Retracts shortened to stay within travel, told on the next block.
    lift_notes: Vec<Diagnostic>,
    /// Squares of the tip miss and of the axis miss's tangent below which a block's replay is
    /// neither a new largest miss nor an error (kept by `replayed`).
    quiet_tip2: f64,
    quiet_tan2: f64,
    /// Strict mode: the first error, which stops the post.
    strict_error: Option<Diagnostic>,
    /// Why holes were written as moves, or 3+2 as positioning: each said once.
    said_once: Vec<&'static str>,
    /// The feed's warnings: which a run of blocks has had.
    feed: feed::Runs,
}

impl Written {
    /// `standing`: tip moves shorter than this are a standing tip (half the last digit of X Y Z).
    pub(super) fn new(sum: Summary, standing: f64) -> Written {
        Written {
            sum,
            blocks: 0,
            stats: Default::default(),
            last_line: 0,
            positioned: false,
            outside_line: None,
            lift_notes: Vec::new(),
            quiet_tip2: 0.0,
            quiet_tan2: 0.0,
            strict_error: None,
            said_once: Vec::new(),
            feed: feed::Runs::new(standing),
        }
    }

    /// The CL line of the last block written.
    pub(super) fn last_line(&self) -> u32 {
        self.last_line
    }

    /// Whether the machine stood at a CL rapid point positioning brought it to; from now on it
    /// does not (until `positioned` says so again).
    pub(super) fn take_positioned(&mut self) -> bool {
        std::mem::take(&mut self.positioned)
    }

    /// Positioning has brought the machine to its point: a CL rapid point (`rapid`), or not.
    pub(super) fn positioned(&mut self, rapid: bool) {
        self.positioned = rapid;
    }

    /// The point at CL `line` is outside travel (its error is on its block).
    pub(super) fn outside(&mut self, line: u32) {
        self.outside_line = Some(line);
    }

    /// A diagnostic for the next block (its line is the block's).
    pub(super) fn tell_next(&mut self, d: Diagnostic) {
        self.lift_notes.push(d);
    }

    /// A CL point read (`counted`: not one the source inserted).
    pub(super) fn cl_point(&mut self, counted: bool) {
        self.sum.cl_points += counted as u64;
    }

    pub(super) fn cl_points(&self) -> u64 {
        self.sum.cl_points
    }

    /// Seconds of the cycle-time estimate that no motion block accounts for (a dwell).
    pub(super) fn add_time(&mut self, s: f64) {
        self.sum.cycle_time_s += s;
    }

    /// A diagnostic counted by its code and severity; under `strict` the first error is kept.
    pub(super) fn count(&mut self, d: &Diagnostic, strict: bool) {
        *self.sum.counts.entry(d.code.as_str().to_string()).or_default() += 1;
        match d.severity {
            Severity::Error => {
                self.sum.errors += 1;
                if strict && self.strict_error.is_none() {
                    self.strict_error = Some(d.clone());
                }
            }
            Severity::Warning => self.sum.warnings += 1,
            Severity::Info => {}
        }
    }

    /// The errors and warnings counted so far.
    pub(super) fn errors_warnings(&self) -> (u64, u64) {
        (self.sum.errors, self.sum.warnings)
    }

    /// The first error under strict mode, taken.
    pub(super) fn take_strict_error(&mut self) -> Option<Diagnostic> {
        self.strict_error.take()
    }

    /// Whether `why` comes up for the first time (it is remembered).
    pub(super) fn first_time(&mut self, why: &'static str) -> bool {
        if self.said_once.contains(&why) {
            return false;
        }
        self.said_once.push(why);
        true
    }

    /// The feed's warnings told in this run of blocks.
    pub(super) fn feed_runs(&mut self) -> &mut feed::Runs {
        &mut self.feed
    }

    /// A canned cycle's block: its time (minutes) and its bottom's Z; its number.
    pub(super) fn hole(&mut self, time: f64, z: Option<f64>, bottom: f64) -> u64 {
        self.sum.cycle_time_s += time * 60.0;
        if let Some(st) = self.stats[2].as_mut() {
            st.min = st.min.min(z.unwrap_or(bottom));
        }
        self.blocks += 1;
        self.sum.blocks += 1;
        self.blocks
    }

    /// The number the next block will have.
    pub(super) fn next_block(&self) -> u64 {
        self.blocks + 1
    }

    /// The summary so far, with each axis's statistics; `fill` adds what the concepts kept.
    pub(super) fn summary(&mut self, fill: impl FnOnce(&mut Summary)) -> Summary {
        for (k, st) in self.stats.iter().enumerate() {
            if let Some(st) = st {
                self.sum.axes.insert(crate::nc::AXIS_LETTERS[k], st.clone());
            }
        }
        fill(&mut self.sum);
        self.sum.clone()
    }
}

/// How a block moves: at rapid, at feed in a line, or as an arc.
pub(super) enum Move {
    Rapid,
    Feed,
    Arc(ArcBlock),
}

impl<S: Sink + ?Sized> Emitter<'_, S> {
    /// Writes one motion block (a rapid or a straight feed) and accounts for it.
    pub(super) fn block(
        &mut self,
        to: At,
        pt: &MotionPt,
        rapid: bool,
        diags: Vec<Diagnostic>,
        inserted: bool,
        comment: Option<&str>,
    ) -> Result<(), Error> {
        let how = if rapid { Move::Rapid } else { Move::Feed };
        self.write(to, pt, how, diags, inserted, comment)
    }

    /// Writes one motion block of any kind and accounts for it.
    pub(super) fn write(
        &mut self,
        to: At,
        pt: &MotionPt,
        how: Move,
        mut diags: Vec<Diagnostic>,
        inserted: bool,
        comment: Option<&str>,
    ) -> Result<(), Error> {
        let (rapid, arc) = match how {
            Move::Rapid => (true, None),
            Move::Feed => (false, None),
            Move::Arc(a) => (false, Some(a)),
        };
        self.written.positioned = false;
        self.cancel_cycle()?;
        if self.frames.tilt().is_some() && self.plane_at(&to.joints.rotary).is_none() {
            self.leave_plane(true)?;
        }
        // The machine's axis values (summary, block info), and the words written (in a tilted
        // plane: plane coordinates, no rotaries).
        let axes = self.axis_values(&to);
        let tilt = self.frames.tilt();
        // Borrowed, not copied, in the common case (the copy stalled on the stores just made).
        let plane_words;
        let words = match &tilt {
            Some(t) => {
                let q = self.plane_coords(t, &to.pose.tip);
                plane_words = [Some(q.x), Some(q.y), Some(q.z), None, None, None];
                &plane_words
            }
            None => &axes,
        };
        let prev = self.at;
        let (feed, time) = self.feed(&to, prev.as_ref(), pt, arc.as_ref(), rapid, &mut diags);
        self.pose_diagnostics(&to, pt, rapid, inserted, &mut diags);
        if self.collide.on() {
            self.collisions(prev.as_ref(), &to, rapid, arc.as_ref().map(|a| a.path), pt.line, &mut diags);
        }
        let comp = match self.cutcom.idle() {
            true => None,
            false => self.cutcom_words(&to, pt.line, !rapid && arc.is_some(), &mut diags)?,
        };
        // Each word is rounded once, for the line and for the replay.
        let rounded = self.f.round_words(words);
        self.replay(&to, &axes, &rounded, words, pt.line, &mut diags);
        self.account(&to, prev.as_ref(), &axes, !rapid && comment.is_none(), pt.line, time);
        for d in &diags {
            self.count(d);
        }
        let comment = comment.or(pt.comment);
        // A block with an error says so where the machinist reads the program.
        let flagged;
        let comment = match diags.iter().find(|d| d.severity == Severity::Error) {
            Some(e) => {
                flagged = format!(
                    "{}ERROR {}",
                    comment.map_or(String::new(), |c| format!("{c} ")),
                    e.code.as_str()
                )
                .to_ascii_uppercase();
                Some(flagged.as_str())
            }
            None => comment,
        };
        self.unlock_moving(&to.joints)?;
        if !rapid && self.smooth.due() {
            self.smooth_now()?;
        }
        let motion = match (&arc, rapid) {
            (_, true) => Motion::Rapid,
            (Some(a), false) => Motion::Arc { ccw: a.ccw },
            (None, false) => Motion::Feed,
        };
        let extra = arc.as_ref().map_or("", |a| a.words.as_str());
        self.at = Some(to);
        self.tool.moved();
        self.written.last_line = pt.line;
        let comp_words = comp.as_ref().map_or("", |c| c.0.as_str());
        let plain = self.f.plain();
        match self.f.motion(motion, &rounded, feed, extra, comp_words, comment) {
            Some(text) => {
                if let Some((_, now)) = comp {
                    self.cutcom.written(now);
                }
                let w = &mut self.written;
                w.blocks += 1;
                w.sum.blocks += 1;
                w.sum.inserted_blocks += inserted as u64;
                let info = BlockInfo {
                    n: w.blocks,
                    source_line: Some(pt.line),
                    joints: AxisWords(axes),
                    diagnostics: diags,
                    rapid,
                    tip: to.pose.tip.into(),
                    axis: to.pose.axis.into(),
                    time_s: time * 60.0,
                };
                if plain {
                    self.sink.line(text, Some(&info))?;
                } else {
                    let text = text.to_string();
                    self.line(&text, Some(&info))?;
                }
            }
            None => {
                for d in diags {
                    self.flag(&d)?;
                    self.sink.diagnostic(&d)?;
                }
            }
        }
        Ok(())
    }

    /// X Y Z A B C as the machine stands at `to` (TCP: X Y Z are the tip's words).
    #[inline]
    fn axis_values(&self, to: &At) -> [Option<f64>; 6] {
        let m = self.m;
        let tcp = self.o.mode == Mode::Tcp;
        let mut axes: [Option<f64>; 6] = [None; 6];
        let xyz = if tcp { self.tcp_xyz(to) } else { to.pose.tip };
        for i in 0..3 {
            if m.linears[i].is_some() || tcp {
                axes[i] = Some(if tcp { xyz[i] } else { to.joints.linear[i] });
            }
        }
        for (i, r) in m.rotaries.iter().enumerate() {
            axes[r.slot()] = Some(to.joints.rotary[i].to_degrees());
        }
        axes
    }

    /// Diagnostics of the pose itself: the spindle, shortened retracts, travel of an inserted
    /// block, the angle-error range, the singular cone.
    #[inline]
    fn pose_diagnostics(&mut self, to: &At, pt: &MotionPt, rapid: bool, inserted: bool, diags: &mut Vec<Diagnostic>) {
        let m = self.m;
        if !rapid && let Some(d) = self.spindle.standing(pt.line) {
            diags.push(d);
        }
        for mut d in self.written.lift_notes.drain(..) {
            d.line = Some(pt.line);
            diags.push(d);
        }
        // A CL point's travel was checked where it was planned; a block inserted between two
        // points within travel (linearization, a retract along the tool axis) can still leave
        // it: the machine would stop on overtravel mid-cut.
        if inserted
            && self.written.outside_line != Some(pt.line)
            && let Some(v) = kinematics::limit_violation(m, &to.joints, 1e-6)
        {
            diags.push(limit_error(
                &v,
                pt.line,
                " (a block kinepost inserted: linearization, retract or approach)",
            ));
        }
        for (i, r) in m.rotaries.iter().enumerate() {
            if let Some(e) = &r.angle_error
                && !e.in_range(to.joints.rotary[i])
            {
                diags.push(Diagnostic::new(
                    Code::AngleCompOutOfRange,
                    Severity::Warning,
                    Some(pt.line),
                    format!(
                        "{} = {:.4}° outside the angle-error fitted range [{}, {}]",
                        r.name,
                        to.joints.rotary[i].to_degrees(),
                        e.range_deg.0,
                        e.range_deg.1
                    ),
                ));
            }
        }
        if self.in_singular_cone(&to.pose.axis) {
            diags.push(Diagnostic::new(
                Code::Singular,
                Severity::Info,
                Some(pt.line),
                "tool axis within the singular cone: the free rotary is held",
            ));
        }
    }

    /// Self-verification: FK of the machine's axes as written (`rounded`: the words of the
    /// line; in a tilted plane the axes are rounded apart) against the pose `to` was meant for.
    #[inline]
    fn replay(
        &mut self,
        to: &At,
        axes: &[Option<f64>; 6],
        rounded: &[Option<i64>; 6],
        words: &[Option<f64>; 6],
        line: u32,
        diags: &mut Vec<Diagnostic>,
    ) {
        let m = self.m;
        let tcp = self.o.mode == Mode::Tcp;
        let tilt = self.frames.tilt();
        let tilted_axes;
        let axes_written = match tilt {
            None => rounded,
            Some(_) => {
                tilted_axes = self.f.round_words(axes);
                &tilted_axes
            }
        };
        let mut written = to.joints;
        for i in 0..3 {
            if let Some(r) = axes_written[i] {
                written.linear[i] = self.f.word_value(r, i);
            }
        }
        for (i, r) in m.rotaries.iter().enumerate() {
            if let Some(w) = axes_written[r.slot()] {
                written.rotary[i] = self.f.word_value(w, r.slot()).to_radians();
            }
        }
        let setup = self.tool.setup();
        let replay = fk(m, &written, setup);
        let tip_miss = if let Some(t) = &tilt {
            self.plane_tip(t, [words[0], words[1], words[2]].map(|w| w.unwrap_or(0.0))) - to.pose.tip
        } else if tcp && m.has_angle_error() {
            kinematics::tcp_fk(m, &Vec3::from(written.linear), &written.rotary, setup).tip - to.pose.tip
        } else if tcp {
            // X Y Z are the tip: its deviation is their rounding, already read back above.
            Vec3::from(written.linear) - to.pose.tip
        } else {
            replay.tip - to.pose.tip
        };
        // Nearly every block misses by less than the largest miss so far and the tolerance: that
        // is told from squares and the tangent's square (no square root, division or arctangent:
        // their latency was an eighth of this function's time). Only a block beyond either is
        // measured and recorded.
        let (d2, s2, c) = (
            tip_miss.norm_squared(),
            replay.axis.cross(&to.pose.axis).norm_squared(),
            replay.axis.dot(&to.pose.axis),
        );
        if !(d2 <= self.written.quiet_tip2 && c > 0.0 && s2 <= self.written.quiet_tan2 * c * c) {
            let (tip_dev, ax_dev) = (d2.sqrt(), angle_between(&replay.axis, &to.pose.axis).to_degrees());
            diags.extend(self.replayed(line, tip_dev, ax_dev, "the written block misses the pose"));
        }
    }

    /// Statistics per axis letter (the summary's map at the end) and the cycle time. `stepped`:
    /// a cutting block, whose rotary steps count toward the largest.
    #[inline]
    fn account(&mut self, to: &At, prev: Option<&At>, axes: &[Option<f64>; 6], stepped: bool, line: u32, time: f64) {
        for (k, v) in axes.iter().enumerate() {
            let Some(v) = v else { continue };
            let st = self.written.stats[k].get_or_insert(AxisStats {
                min: *v,
                max: *v,
                ..Default::default()
            });
            st.min = st.min.min(*v);
            st.max = st.max.max(*v);
        }
        if let Some(p) = prev {
            for (i, r) in self.m.rotaries.iter().enumerate() {
                let d = (to.joints.rotary[i] - p.joints.rotary[i]).to_degrees().abs();
                let Some(st) = self.written.stats[r.slot()].as_mut() else {
                    continue;
                };
                *st.travel.get_or_insert(0.0) += d;
                if stepped && d > st.largest_step.unwrap_or(0.0) {
                    st.largest_step = Some(d);
                    st.largest_step_line = Some(line);
                }
            }
        }
        self.written.sum.cycle_time_s += time * 60.0;
    }

    /// Books an FK replay's deviation (tip, degrees) in the summary; beyond the tolerance (or
    /// 0.01°) it is an error on the block.
    pub(super) fn replayed(&mut self, line: u32, tip_dev: f64, ax_dev: f64, what: &str) -> Option<Diagnostic> {
        let w = &mut self.written;
        w.sum.max_tip_deviation = w.sum.max_tip_deviation.max(tip_dev);
        w.sum.max_axis_deviation_deg = w.sum.max_axis_deviation_deg.max(ax_dev);
        // What a block may miss by and need no look (see `block`): within both the largest
        // misses so far and the error thresholds, a little inside them for rounding.
        let tip = w.sum.max_tip_deviation.min(self.o.tolerance) * (1.0 - 1e-9);
        let tan = w.sum.max_axis_deviation_deg.min(REPLAY_AXIS_DEG).to_radians().tan() * (1.0 - 1e-9);
        (w.quiet_tip2, w.quiet_tan2) = (tip * tip, tan * tan);
        (tip_dev > self.o.tolerance || ax_dev > REPLAY_AXIS_DEG).then(|| {
            Diagnostic::new(
                Code::VerifyDeviation,
                Severity::Error,
                Some(line),
                format!("FK replay of {what} by {tip_dev:.6} / {ax_dev:.6}°"),
            )
        })
    }

    /// A TCP block's X Y Z at `at`: the tip itself, or on a profile with angle error the point
    /// whose nominal TCP puts the real tip there ([`kinematics::tcp_point`]).
    pub(super) fn tcp_xyz(&self, at: &At) -> Vec3 {
        if self.m.has_angle_error() {
            kinematics::tcp_point(self.m, &at.joints, self.tool.setup())
        } else {
            at.pose.tip
        }
    }
}
