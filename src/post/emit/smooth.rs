//! Smoothing per operation: the control's smoothing word (`G187`, `CYCLE832`, `G05.1`, cycle
//! 32, `G64 P`) before each operation's first feed move, at the operation's tolerance and a
//! level for roughing or finishing; cancelled before a tool change and at the end.

use super::Emitter;
use crate::kinematics::Units;
use crate::post::{Sink, Smoothing};
use crate::post::Stop;

/// Total tolerances (`INTOL` + `OUTTOL`, mm) from which an operation is roughing, and up to
/// which it is finishing; between: semi-finishing. A roughing pass leaves stock at a coarse
/// chord (0.05-0.2 mm), a finish pass cuts the surface to a few microns.
const ROUGH_FROM_MM: f64 = 0.05;
const FINISH_TO_MM: f64 = 0.012;

/// A dialect's smoothing levels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Level {
    Rough,
    Semifinish,
    Finish,
}

/// What the smoothing word of the operation ahead is made from, and what is in force.
#[derive(Debug, Default)]
pub(in crate::post) struct Smooth {
    /// The CL's `INTOL` and `OUTTOL` in force (profile units; modal, as APT has them).
    inner: Option<f64>,
    outer: Option<f64>,
    /// The level the operation's name says (NX's `TOOL PATH/ROUGH_…`), if it says one.
    named: Option<Level>,
    /// The next feed move writes the word (a new operation or tolerance).
    due: bool,
    /// The lines of the word in force: the same word is not written twice.
    on: Option<Vec<String>>,
}

impl Smooth {
    /// `rough` and `finish` write their word before the first feed move, operation or none.
    pub(super) fn new(mode: Smoothing) -> Smooth {
        let due = matches!(mode, Smoothing::Rough | Smoothing::Finish);
        Smooth { due, ..Default::default() }
    }

    /// The next feed move writes the operation's word.
    #[inline]
    pub(super) fn due(&self) -> bool {
        self.due
    }
}

/// The level an operation's name says: NX names its operations after their type
/// (`CAVITY_MILL`, `ZLEVEL_PROFILE`, `FINISH_WALLS`), other CAMs after what the user typed.
fn named(name: &str) -> Option<Level> {
    let n = name.to_ascii_uppercase();
    let has = |words: &[&str]| words.iter().any(|w| n.contains(w));
    if has(&["SEMI"]) {
        Some(Level::Semifinish)
    } else if has(&["ROUGH", "CAVITY", "ADAPTIVE", "PLUNGE"]) {
        Some(Level::Rough)
    } else if has(&["FINISH", "ZLEVEL", "FLOWCUT", "CONTOUR_AREA", "STREAMLINE"]) {
        Some(Level::Finish)
    } else {
        None
    }
}

impl<S: Sink + ?Sized> Emitter<'_, S> {
    /// `INTOL` or `OUTTOL`: the next operation's (and this one's next feed move's) tolerance.
    pub(super) fn cl_tolerance(&mut self, outer: bool, value: f64) {
        match outer {
            true => self.smooth.outer = Some(value),
            false => self.smooth.inner = Some(value),
        }
        self.smooth.due = self.o.smoothing != Smoothing::Off;
    }

    /// A new operation: its word before its first feed move.
    pub(super) fn smooth_operation(&mut self, name: &str) {
        self.smooth.named = named(name);
        self.smooth.due = self.o.smoothing != Smoothing::Off;
    }

    /// The operation's smoothing word, before its first feed move, where it differs from the
    /// one in force. `auto` writes none until the CL says a tolerance: a CL without one is
    /// posted as it was before smoothing existed.
    pub(super) fn smooth_now(&mut self) -> Result<(), Stop> {
        self.smooth.due = false;
        let s = &self.smooth;
        let said = s.inner.is_some() || s.outer.is_some();
        if self.o.smoothing == Smoothing::Off || (self.o.smoothing == Smoothing::Auto && !said) {
            return Ok(());
        }
        // The band the CAM cut to, inside plus outside; none said (or none wide): the job's.
        let band = s.inner.unwrap_or(0.0) + s.outer.unwrap_or(0.0);
        let tol = if band > 0.0 { band } else { self.o.tolerance };
        let mm = match self.m.units {
            Units::Mm => tol,
            Units::Inch => tol * 25.4,
        };
        let by_tolerance = match mm {
            t if t >= ROUGH_FROM_MM => Level::Rough,
            t if t <= FINISH_TO_MM => Level::Finish,
            _ => Level::Semifinish,
        };
        let level = match self.o.smoothing {
            Smoothing::Rough => Level::Rough,
            Smoothing::Finish => Level::Finish,
            _ => s.named.unwrap_or(by_tolerance),
        };
        let words = &self.o.dialect.smoothing;
        let template = match level {
            Level::Rough => &words.rough,
            Level::Semifinish => &words.semifinish,
            Level::Finish => &words.finish,
        };
        if template.is_empty() {
            return Ok(());
        }
        let lines = self.f.smoothing(template, tol);
        if self.smooth.on.as_ref() == Some(&lines) {
            return Ok(());
        }
        for l in &lines {
            self.out(l)?;
        }
        self.smooth.on = Some(lines);
        Ok(())
    }

    /// The smoothing word in force cancelled (before a tool change, at the end): the next
    /// operation writes its own.
    pub(super) fn smooth_off(&mut self) -> Result<(), Stop> {
        if self.smooth.on.take().is_none() {
            return Ok(());
        }
        self.smooth.due = self.o.smoothing != Smoothing::Off;
        let off = self.o.dialect.smoothing.off.clone();
        for l in self.f.smoothing(&off, self.o.tolerance) {
            self.out(&l)?;
        }
        Ok(())
    }
}
