//! The block writer: a motion block's words, its diagnostics, its FK replay from the words as
//! written, the statistics, and the line handed to the sink.

use super::{At, Emitter, limit_error};
use crate::diag::{Code, Diagnostic, Severity};
use crate::kinematics::{self, Vec3, angle_between, fk};
use crate::nc::Motion;
use crate::post::{AxisStats, AxisWords, BlockInfo, Error, Mode, MotionPt, Sink};

/// Axis miss (degrees) of an FK replay that is an error.
const REPLAY_AXIS_DEG: f64 = 0.01;

impl<S: Sink + ?Sized> Emitter<'_, S> {
    /// Writes one motion block and accounts for it.
    pub(super) fn block(
        &mut self,
        to: At,
        pt: &MotionPt,
        rapid: bool,
        mut diags: Vec<Diagnostic>,
        inserted: bool,
        comment: Option<&str>,
    ) -> Result<(), Error> {
        self.positioned = false;
        self.cancel_cycle()?;
        if self.tilt.is_some() && self.plane_at(&to.joints.rotary).is_none() {
            self.leave_plane(true)?;
        }
        // The machine's axis values (summary, block info), and the words written (in a tilted
        // plane: plane coordinates, no rotaries).
        let axes = self.axis_values(&to);
        let tilt = self.tilt;
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
        let (feed, time) = self.feed(&to, prev.as_ref(), pt, rapid, &mut diags);
        self.pose_diagnostics(&to, pt, rapid, inserted, &mut diags);
        if self.world.is_some() {
            self.collisions(prev.as_ref(), &to, rapid, pt.line, &mut diags);
        }
        let comp = match self.cutcom.idle() {
            true => None,
            false => self.cutcom_words(&to, pt.line, !rapid && self.arc.is_some(), &mut diags)?,
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
        if self.smooth.due && !rapid {
            self.smooth_now()?;
        }
        let arc = self.arc.take();
        let motion = match (&arc, rapid) {
            (_, true) => Motion::Rapid,
            (Some(a), false) => Motion::Arc { ccw: a.ccw },
            (None, false) => Motion::Feed,
        };
        let extra = arc.as_ref().map_or("", |a| a.words.as_str());
        self.at = Some(to);
        self.tool_changed = false;
        self.last_line = pt.line;
        let comp_words = comp.as_ref().map_or("", |c| c.0.as_str());
        let plain = self.f.plain();
        match self.f.motion(motion, &rounded, feed, extra, comp_words, comment) {
            Some(text) => {
                if let Some((_, now)) = comp {
                    self.cutcom.on = now;
                }
                self.blocks += 1;
                self.sum.blocks += 1;
                self.sum.inserted_blocks += inserted as u64;
                let info = BlockInfo {
                    n: self.blocks,
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
        if !rapid && let Some(d) = self.spindle_standing(pt.line) {
            diags.push(d);
        }
        for mut d in self.lift_notes.drain(..) {
            d.line = Some(pt.line);
            diags.push(d);
        }
        // A CL point's travel was checked where it was planned; a block inserted between two
        // points within travel (linearization, a retract along the tool axis) can still leave
        // it: the machine would stop on overtravel mid-cut.
        if inserted
            && self.outside_line != Some(pt.line)
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
        let tilt = self.tilt;
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
        let replay = fk(m, &written, &self.setup);
        let tip_miss = if let Some(t) = &tilt {
            self.plane_tip(t, [words[0], words[1], words[2]].map(|w| w.unwrap_or(0.0))) - to.pose.tip
        } else if tcp && self.compensated {
            kinematics::tcp_fk(m, &Vec3::from(written.linear), &written.rotary, &self.setup).tip - to.pose.tip
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
        if !(d2 <= self.quiet_tip2 && c > 0.0 && s2 <= self.quiet_tan2 * c * c) {
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
            let st = self.stats[k].get_or_insert(AxisStats {
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
                let Some(st) = self.stats[r.slot()].as_mut() else {
                    continue;
                };
                *st.travel.get_or_insert(0.0) += d;
                if stepped && d > st.largest_step.unwrap_or(0.0) {
                    st.largest_step = Some(d);
                    st.largest_step_line = Some(line);
                }
            }
        }
        self.sum.cycle_time_s += time * 60.0;
    }

    /// Books an FK replay's deviation (tip, degrees) in the summary; beyond the tolerance (or
    /// 0.01°) it is an error on the block.
    pub(super) fn replayed(&mut self, line: u32, tip_dev: f64, ax_dev: f64, what: &str) -> Option<Diagnostic> {
        self.sum.max_tip_deviation = self.sum.max_tip_deviation.max(tip_dev);
        self.sum.max_axis_deviation_deg = self.sum.max_axis_deviation_deg.max(ax_dev);
        // What a block may miss by and need no look (see `block`): within both the largest
        // misses so far and the error thresholds, a little inside them for rounding.
        let tip = self.sum.max_tip_deviation.min(self.o.tolerance) * (1.0 - 1e-9);
        let tan = self.sum.max_axis_deviation_deg.min(REPLAY_AXIS_DEG).to_radians().tan() * (1.0 - 1e-9);
        (self.quiet_tip2, self.quiet_tan2) = (tip * tip, tan * tan);
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
        if self.compensated {
            kinematics::tcp_point(self.m, &at.joints, &self.setup)
        } else {
            at.pose.tip
        }
    }
}
