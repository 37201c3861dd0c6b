//! The feed: F per minute or inverse time, the machine axes' path where the tip stands, axis
//! feed limits, and the time of each block for the cycle-time estimate.

use super::{ArcBlock, At, Emitter};
use crate::cl::FeedUnit;
use crate::diag::{Code, Diagnostic, Severity};
use crate::kinematics::{self, Units};
use crate::nc::{Dialect, FeedMode};
use crate::post::{Mode, MotionPt, RotaryFeed, Sink};

/// What the feed keeps from block to block (the block writer holds it): the tip moves taken
/// for a standing tip, and which of its warnings have been told, once a program or once a run.
#[derive(Debug)]
pub(super) struct Runs {
    /// Tip moves shorter than this (half the X Y Z words' last digit) are a standing tip.
    standing: f64,
    /// Feed per revolution with no spindle speed was told.
    per_rev_told: bool,
    /// In a run of blocks slowed to the F word's range, or to an axis's velocity (each run
    /// told at its first block).
    range_run: bool,
    clamp_run: bool,
}

impl Runs {
    pub(super) fn new(standing: f64) -> Runs {
        Runs {
            standing,
            per_rev_told: false,
            range_run: false,
            clamp_run: false,
        }
    }

    /// Whether this block (`slowed` or not to an axis's velocity) starts a run of slowed blocks.
    fn clamp_starts(&mut self, slowed: bool) -> bool {
        let first = slowed && !self.clamp_run;
        self.clamp_run = slowed;
        first
    }

    /// Whether this block (`beyond` the F word's range or not) starts a run of such blocks.
    fn range_starts(&mut self, beyond: bool) -> bool {
        let first = beyond && !self.range_run;
        self.range_run = beyond;
        first
    }
}

impl<S: Sink + ?Sized> Emitter<'_, S> {
    /// The F word (per minute or inverse time) and the time (minutes) of a block to `to` from
    /// `prev` (an `arc`, or a line): the tip's path at F, the machine axes' path where the tip
    /// stands while the tool turns, slowed to every axis's feed limit; a rapid at the rapid rate.
    #[inline]
    pub(super) fn feed(
        &mut self,
        to: &At,
        prev: Option<&At>,
        pt: &MotionPt,
        arc: Option<&ArcBlock>,
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
                match self.spindle.rpm().filter(|&r| r > 0.0) {
                    Some(r) => f *= r,
                    None if !self.written.feed_runs().per_rev_told => {
                        self.written.feed_runs().per_rev_told = true;
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
            let len = match arc {
                Some(a) => a.length,
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
                && len < self.written.feed_runs().standing
                && f > 0.0
                && let Some(p) = prev
            {
                t = t.max(machine_len(p) / f);
            }
            // No axis faster than its velocity: the slowest axis sets the time.
            let limited_axis = match prev.and_then(|p| self.slowest_axis(p, to)) {
                Some((need, a)) if need > t * (1.0 + 1e-9) => {
                    t = need;
                    Some(a)
                }
                _ => None,
            };
            if rot_moves && !tcp {
                if t <= 0.0 {
                    t = 1e-6;
                }
                let g93 = self.o.dialect.inverse_time.is_some();
                feed = Some(match (self.o.rotary_feed, prev) {
                    (RotaryFeed::InverseTime, _) if g93 => (FeedMode::InverseTime, 1.0 / t),
                    (_, None) => (FeedMode::InverseTime, 1.0 / t),
                    (RotaryFeed::DegreesPerMinute, Some(p)) => (FeedMode::PerMinute, self.dpm_len(p, to) / t),
                    // No inverse time on this control, or the combined feed asked for: the feed
                    // along the machine axes (units and degrees) that takes the same time.
                    (_, Some(p)) => (FeedMode::PerMinute, machine_len(p) / t),
                });
            } else {
                let fz = if limited_axis.is_some() && t > 0.0 { len / t } else { f };
                feed = Some((FeedMode::PerMinute, fz.max(0.0)));
            }
            // Told at the first block of each run of slowed blocks: a dense path slowed
            // throughout is one warning, not one a block.
            if self.written.feed_runs().clamp_starts(limited_axis.is_some())
                && let Some(a) = limited_axis
            {
                diags.push(Diagnostic::new(
                    Code::FeedClamped,
                    Severity::Warning,
                    Some(pt.line),
                    format!("feed reduced from here on while {a} would exceed its velocity (the profile's max_feed) at the programmed feed"),
                ));
            }
            if let Some(fw) = &mut feed {
                self.within_word(fw, &mut t, pt.line, diags);
            }
            time = t;
        } else if let Some(p) = prev {
            time = self.rapid_time(p, to);
        }
        (feed, time)
    }

    /// The path F is read along in `dpm` (NIST RS274, LinuxCNC, Haas): the linear axes' when
    /// their words change, else the rotaries' degrees.
    fn dpm_len(&self, p: &At, to: &At) -> f64 {
        let lin = (0..3).map(|i| (to.joints.linear[i] - p.joints.linear[i]).powi(2)).sum::<f64>().sqrt();
        if lin >= self.f.fmt.half_linear() {
            return lin;
        }
        (0..self.m.rotaries.len())
            .map(|i| (to.joints.rotary[i] - p.joints.rotary[i]).to_degrees().powi(2))
            .sum::<f64>()
            .sqrt()
    }

    /// F within what the word carries: one that rounds to zero is the smallest (an alarm on every
    /// control), one beyond the word's range the largest; `t` (minutes) follows the F written.
    fn within_word(&mut self, (mode, v): &mut (FeedMode, f64), t: &mut f64, line: u32, diags: &mut Vec<Diagnostic>) {
        // A feed the F word rounds to zero is an alarm on every control (a move of days in
        // inverse time, or a feed per minute below the word's last digit): the smallest F.
        let step = self.f.fmt.feed_step(*mode);
        if *v < 0.5 * step {
            diags.push(Diagnostic::new(
                Code::FeedClamped,
                Severity::Warning,
                Some(line),
                format!("F{v:.2e} rounds to zero: the smallest F the word carries written (a faster move)"),
            ));
            if *v > 0.0 {
                *t *= *v / step;
            }
            *v = step;
        }
        // Beyond the word's range: the control's largest F, the slower side (it overflowed
        // to F0). A FEDRAT beyond it was an error where the CL said it; a short move at a
        // fast feed in inverse time is only slowed (told once a run of such blocks).
        let max = feed_max(&self.o.dialect, self.m.units, *mode);
        let beyond = v.is_nan() || *v > max;
        let first = self.written.feed_runs().range_starts(beyond);
        if beyond {
            if first {
                diags.push(Diagnostic::new(
                    Code::FeedClamped,
                    Severity::Warning,
                    Some(line),
                    format!(
                        "F{v:.6e} is beyond what the {} F word takes ({max}): written F{max} from here on while it is, a slower move",
                        self.o.dialect.name
                    ),
                ));
            }
            if v.is_finite() {
                *t *= *v / max;
            }
            *v = max;
        }
    }

    /// A rapid's time (minutes): each axis at its velocity and acceleration from rest to rest,
    /// the slowest setting it; a linear the profile gives no velocity at a typical rapid.
    pub(super) fn rapid_time(&self, p: &At, to: &At) -> f64 {
        let m = self.m;
        let mut t: f64 = 0.0;
        for (i, l) in m.linears.iter().enumerate() {
            if let Some(l) = l {
                let d = (to.joints.linear[i] - p.joints.linear[i]).abs();
                t = t.max(travel_time(d, l.max_feed.unwrap_or(self.typical_rapid()), l.max_accel));
            }
        }
        for (i, r) in m.rotaries.iter().enumerate() {
            if let Some(v) = r.max_feed {
                t = t.max(travel_time((to.joints.rotary[i] - p.joints.rotary[i]).abs(), v, r.max_accel));
            }
        }
        t
    }

    /// Z's rapid time (minutes) over `d`: a canned cycle's moves to R and back.
    pub(super) fn z_rapid_time(&self, d: f64) -> f64 {
        match &self.m.linears[2] {
            Some(l) => travel_time(d.abs(), l.max_feed.unwrap_or(self.typical_rapid()), l.max_accel),
            None => d.abs() / self.typical_rapid(),
        }
    }

    /// A rapid traverse for a linear the profile gives no velocity.
    fn typical_rapid(&self) -> f64 {
        if self.m.units == Units::Mm { 10000.0 } else { 400.0 }
    }

    /// The time (minutes) the slowest axis needs from `p` to `to` at its velocity, and its name.
    fn slowest_axis(&self, p: &At, to: &At) -> Option<(f64, char)> {
        let m = self.m;
        let mut worst: Option<(f64, char)> = None;
        let mut take = |need: f64, name: char| {
            if worst.is_none_or(|(w, _)| need > w) {
                worst = Some((need, name));
            }
        };
        for (i, l) in m.linears.iter().enumerate() {
            if let Some(mf) = l.as_ref().and_then(|l| l.max_feed) {
                take(
                    (to.joints.linear[i] - p.joints.linear[i]).abs() / mf,
                    kinematics::LINEAR_NAMES[i],
                );
            }
        }
        for (i, r) in m.rotaries.iter().enumerate() {
            if let Some(mf) = r.max_feed {
                take((to.joints.rotary[i] - p.joints.rotary[i]).abs() / mf, r.name);
            }
        }
        worst
    }
}

/// The largest F `d` takes in `mode`, in `units` per minute (inverse time: 1/min).
pub(in crate::post) fn feed_max(d: &Dialect, units: Units, mode: FeedMode) -> f64 {
    let r = d.ranges;
    match (mode, units) {
        (FeedMode::InverseTime, _) => r.inverse_time,
        (FeedMode::PerMinute, Units::Mm) => r.feed_mm,
        (FeedMode::PerMinute, Units::Inch) => (r.feed_mm / 25.4).floor(),
    }
}

/// Minutes to travel `d` at velocity `v` (per minute) with acceleration `a` (per second²) from
/// rest to rest: a trapezoid, or a triangle where the move is too short to reach `v`.
fn travel_time(d: f64, v: f64, a: Option<f64>) -> f64 {
    let Some(a) = a.map(|a| a * 3600.0) else {
        return d / v;
    };
    if d >= v * v / a { d / v + v / a } else { 2.0 * (d / a).sqrt() }
}
