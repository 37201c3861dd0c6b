//! The feed: F per minute or inverse time, the machine axes' path where the tip stands, axis
//! feed limits, and the time of each block for the cycle-time estimate.

use super::{At, Emitter};
use crate::cl::FeedUnit;
use crate::diag::{Code, Diagnostic, Severity};
use crate::kinematics::Units;
use crate::nc::FeedMode;
use crate::post::{Mode, MotionPt, Sink};

impl<S: Sink + ?Sized> Emitter<'_, S> {
    /// The F word (per minute or inverse time) and the time (minutes) of a block to `to` from
    /// `prev`: the tip's path at F, the machine axes' path where the tip stands while the tool
    /// turns, slowed to every axis's feed limit; a rapid at the rapid rate.
    #[inline]
    pub(super) fn feed(
        &mut self,
        to: &At,
        prev: Option<&At>,
        pt: &MotionPt,
        rapid: bool,
        diags: &mut Vec<Diagnostic>,
    ) -> (Option<(FeedMode, f64)>, f64) {
        let m = self.m;
        let tcp = self.o.mode == Mode::Tcp;
        let mut feed = None;
        let mut time = 0.0;
        if !rapid && let Some((fv, unit)) = pt.feed {
            let mut f = fv;
            if unit == FeedUnit::PerRev {
                // A stopped spindle (S0) gives no feed per minute either: F0 is an alarm.
                match self.rpm.filter(|&r| r > 0.0) {
                    Some(r) => f *= r,
                    None if !self.warned_per_rev => {
                        self.warned_per_rev = true;
                        diags.push(Diagnostic::new(
                            Code::FeedClamped,
                            Severity::Warning,
                            Some(pt.line),
                            "feed per revolution with no spindle speed: taken per minute",
                        ));
                    }
                    None => {}
                }
            }
            let len = match &self.arc_words {
                Some((_, _, l)) => *l,
                None => prev.map_or(0.0, |p| (to.pose.tip - p.pose.tip).norm()),
            };
            let rot_moves =
                prev.is_some_and(|p| (0..m.rotaries.len()).any(|i| (to.joints.rotary[i] - p.joints.rotary[i]).abs() > 1e-12));
            // The path of the machine's axes, units and degrees combined: what a control without
            // inverse time reads F along.
            let machine_len = |p: &At| {
                let mut sq = 0.0;
                for i in 0..3 {
                    sq += (to.joints.linear[i] - p.joints.linear[i]).powi(2);
                }
                for i in 0..m.rotaries.len() {
                    sq += (to.joints.rotary[i] - p.joints.rotary[i]).to_degrees().powi(2);
                }
                sq.sqrt()
            };
            let mut t = if f > 0.0 { len / f } else { 0.0 };
            // The tool turning about a tip that stands (it moves less than the X Y Z words can
            // say): the tip's path gives the move no time (it was G93 F1000000, the control's
            // fastest cutting feed for a swing of the table); the machine axes' path at F does.
            // Only there: a tip that moves, however little, is what F is about.
            if rot_moves
                && !tcp
                && len < self.standing
                && f > 0.0
                && let Some(p) = prev
            {
                t = t.max(machine_len(p) / f);
            }
            // Axis feed limits.
            let mut limited = false;
            if let Some(p) = prev {
                for (i, l) in m.linears.iter().enumerate() {
                    if let Some(l) = l
                        && let Some(mf) = l.max_feed
                    {
                        let need = (to.joints.linear[i] - p.joints.linear[i]).abs() / mf;
                        if need > t * (1.0 + 1e-9) {
                            (t, limited) = (need, true);
                        }
                    }
                }
                for (i, r) in m.rotaries.iter().enumerate() {
                    if let Some(mf) = r.max_feed {
                        let need = (to.joints.rotary[i] - p.joints.rotary[i]).abs() / mf;
                        if need > t * (1.0 + 1e-9) {
                            (t, limited) = (need, true);
                        }
                    }
                }
            }
            if rot_moves && !tcp {
                if t <= 0.0 {
                    t = 1e-6;
                }
                feed = Some(match (self.o.dialect.inverse_time, prev) {
                    (Some(_), _) | (None, None) => (FeedMode::InverseTime, 1.0 / t),
                    // No inverse time on this control: the feed along the combined machine axes
                    // (units and degrees) that takes the same time.
                    (None, Some(p)) => (FeedMode::PerMinute, machine_len(p) / t),
                });
            } else {
                let fz = if limited && t > 0.0 { len / t } else { f };
                feed = Some((FeedMode::PerMinute, fz.max(0.0)));
            }
            if limited {
                diags.push(Diagnostic::new(
                    Code::FeedClamped,
                    Severity::Warning,
                    Some(pt.line),
                    "feed reduced to respect an axis feed limit",
                ));
            }
            // A feed the F word rounds to zero is an alarm on every control (a move of days in
            // inverse time, or a feed per minute below the word's last digit): the smallest F.
            if let Some((mode, v)) = &mut feed {
                let step = self.f.fmt.feed_step(*mode);
                if *v < 0.5 * step {
                    diags.push(Diagnostic::new(
                        Code::FeedClamped,
                        Severity::Warning,
                        Some(pt.line),
                        format!("F{v:.2e} rounds to zero: the smallest F the word carries written (a faster move)"),
                    ));
                    if *v > 0.0 {
                        t *= *v / step;
                    }
                    *v = step;
                }
            }
            time = t;
        } else if let Some(p) = prev {
            let len = (to
                .joints
                .linear
                .iter()
                .zip(p.joints.linear.iter())
                .map(|(a, b)| (a - b) * (a - b))
                .sum::<f64>())
            .sqrt();
            time = len / self.rapid_rate();
        }
        (feed, time)
    }

    /// Writes one motion block and accounts for it.
    /// Rapid traverse for the time estimate: the slowest linear's feed limit, else a typical one.
    pub(super) fn rapid_rate(&self) -> f64 {
        let r = self
            .m
            .linears
            .iter()
            .flatten()
            .filter_map(|l| l.max_feed)
            .fold(f64::INFINITY, f64::min);
        if r.is_finite() {
            r
        } else if self.m.units == Units::Mm {
            10000.0
        } else {
            400.0
        }
    }
}
