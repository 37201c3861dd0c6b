//! What `SPINDL` asks of the spindle: a speed it can turn at, in RPM where the cutter says how.

use super::{Item, ProgEvent, Source, fmt_len};
use crate::cl::SpindleCmd;
use crate::diag::{Code, Severity};
use std::io::BufRead;

impl<R: BufRead> Source<R> {
    /// SPINDL: a speed that turns (not S0) and that a spindle can (not S9223372036854775807).
    pub(super) fn spindle(&mut self, c: SpindleCmd, line: u32) {
        let mut c = self.spindle_rpm(c, line);
        let range = match c {
            SpindleCmd::Rpm { .. } => self.spindle_range,
            _ => (1.0, crate::post::MAX_SPINDLE_SPEED), // a surface speed: the control turns it to RPM
        };
        if let SpindleCmd::Rpm { speed, .. } | SpindleCmd::Surface { speed, .. } = &mut c {
            if speed.is_nan() || speed.round() < 1.0 {
                // S0 starts a spindle that does not turn, and the next feed drives a standing tool
                // into the part (CATIA's tap demo: `SPINDL/0.3980,RPM`): an error, and the
                // spindle stops (a cut after it is told as one with the spindle standing).
                self.diag(
                    Code::SpindleSpeed,
                    Severity::Error,
                    line,
                    format!("spindle speed {speed} rounds to S0: the spindle would not turn (it is stopped, no S0 written)"),
                );
                c = SpindleCmd::Off;
            } else if let Some((bound, why)) = beyond_spindle(*speed, range) {
                // Bounded where it is told: the S written and any feed per revolution take it.
                self.diag(
                    Code::WordRange,
                    Severity::Error,
                    line,
                    format!("spindle speed {speed:e} is {why}: written S{bound}"),
                );
                *speed = bound;
            }
        }
        self.out.push_back(Item::Event(ProgEvent::Spindle(c)));
    }

    /// A surface speed at the cutter's diameter, as RPM (a mill's spindle word is RPM; NX's
    /// posts convert the same way). Without a diameter it stays a surface speed, which the
    /// engine writes as S with a warning.
    fn spindle_rpm(&mut self, c: SpindleCmd, line: u32) -> SpindleCmd {
        let SpindleCmd::Surface {
            speed,
            clockwise,
            metric,
        } = c
        else {
            return c;
        };
        let Some(d) = self.diameter_mm.filter(|_| !self.turning) else {
            return c;
        };
        // Metres or feet a minute, in mm, over the circumference.
        let per_min_mm = speed * if metric { 1000.0 } else { 304.8 };
        let rpm = per_min_mm / (std::f64::consts::PI * d);
        self.diag(
            Code::SurfaceSpeed,
            Severity::Info,
            line,
            format!(
                "surface speed {speed} {} at the cutter's diameter {}: {rpm:.0} RPM",
                if metric { "m/min" } else { "ft/min" },
                fmt_len(d, self.cl_units)
            ),
        );
        SpindleCmd::Rpm { speed: rpm, clockwise }
    }
}

/// The speed the spindle turns at instead of `rpm`, and why, when `rpm` is outside `range`
/// (the machine's, or any spindle's where the profile states none).
fn beyond_spindle(rpm: f64, (lo, hi): (f64, f64)) -> Option<(f64, String)> {
    if rpm > hi {
        let why = if hi == crate::post::MAX_SPINDLE_SPEED {
            "beyond any spindle".to_string()
        } else {
            format!("above the machine's spindle maximum {hi} RPM")
        };
        return Some((hi, why));
    }
    (rpm < lo).then(|| (lo, format!("below the machine's spindle minimum {lo} RPM")))
}
