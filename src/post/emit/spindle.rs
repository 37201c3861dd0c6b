//! The spindle and the coolant: SPINDL and COOLNT as the CL says them, stopped by a tool change
//! or a program stop and started again before the next move, and the spindle's standing told
//! where a cut would need it turning.

use super::Emitter;
use crate::cl::{CoolantCmd, SpindleCmd};
use crate::diag::{Code, Diagnostic, Severity};
use crate::post::{Error, Sink};
use crate::post::Stop;

/// The spindle and the coolant as the NC leaves them. APT's spindle and coolant are modal: what
/// a tool change or a stop halts the next move starts again, unless the CL said otherwise.
#[derive(Debug)]
pub(super) struct Spindle {
    /// The speed the CL last gave (none after `SPINDL/OFF`).
    rpm: Option<f64>,
    /// Turning, and which way.
    on: bool,
    cw: bool,
    /// The tool change (its CL line) that stopped it, the CL not saying SPINDL again since: M6
    /// stops it on every control.
    restore: Option<u32>,
    /// A cut with it standing was told (until it starts).
    warned: bool,
    /// The CL said SPINDL/OFF since the last tool change: `Options::spindle_speed` starts nothing.
    said_off: bool,
    /// The coolant word the CL has on, and the tool change that turned it off (M9 before M6:
    /// coolant, through-spindle above all, sprays into an open spindle and the changer) until
    /// the next tool's first move turns it on again.
    coolant: Option<String>,
    coolant_restore: Option<u32>,
    /// The CL line of a program stop that halted the spindle, or the coolant, not yet restarted.
    stopped_spindle: Option<u32>,
    stopped_coolant: Option<u32>,
    /// Coolant the CL turned on before its first tool and first move (CATIA writes COOLNT/ON
    /// before LOADTL): written at the first move, not before a tool change that turns it off.
    coolant_deferred: bool,
}

impl Default for Spindle {
    fn default() -> Spindle {
        Spindle {
            rpm: None,
            on: false,
            cw: true,
            restore: None,
            warned: false,
            said_off: false,
            coolant: None,
            coolant_restore: None,
            stopped_spindle: None,
            stopped_coolant: None,
            coolant_deferred: false,
        }
    }
}

impl Spindle {
    /// The speed the CL last gave.
    pub(super) fn rpm(&self) -> Option<f64> {
        self.rpm
    }

    /// The speed, where the spindle is turning.
    pub(super) fn turning(&self) -> Option<f64> {
        self.rpm.filter(|_| self.on)
    }

    /// Turning counter-clockwise (M4), or clockwise (M3); `None`: standing.
    pub(super) fn ccw(&self) -> Option<bool> {
        self.on.then_some(!self.cw)
    }

    /// A cut with the spindle standing (a tool fed into the part without turning breaks): told
    /// once until the spindle starts. A warning, not an error: a probe or a scribe cuts nothing.
    #[inline]
    pub(super) fn standing(&mut self, line: u32) -> Option<Diagnostic> {
        if self.on || self.warned {
            return None;
        }
        self.warned = true;
        Some(Diagnostic::new(
            Code::SpindleStopped,
            Severity::Warning,
            Some(line),
            "feed move with the spindle standing: the CL starts none before it (no SPINDL with a speed, or SPINDL/OFF since; spindle_speed gives one)",
        ))
    }

    /// A program stop at CL `line`: what ran stops with it, to start again at the next move.
    pub(super) fn stopped(&mut self, line: u32) {
        self.stopped_spindle = (self.on && self.restore.is_none()).then_some(line);
        self.stopped_coolant = (self.coolant.is_some() && !self.coolant_deferred).then_some(line);
    }

    /// A program stop halted the spindle or the coolant, not yet started again.
    #[inline]
    pub(super) fn halted(&self) -> bool {
        self.stopped_spindle.is_some() || self.stopped_coolant.is_some()
    }

    /// A tool change at CL `line` stopped the spindle: started again at the next tool's first
    /// move; and restarted what a stop halted.
    pub(super) fn tool_changed(&mut self, line: u32) {
        if std::mem::take(&mut self.on) {
            self.restore = Some(line);
        }
        (self.stopped_spindle, self.stopped_coolant) = (None, None);
        self.said_off = false;
    }
}

impl<S: Sink + ?Sized> Emitter<'_, S> {
    /// SPINDL: a speed and direction, or off.
    pub(super) fn spindle(&mut self, c: SpindleCmd) -> Result<(), Error> {
        let d = self.o.dialect.clone();
        let (speed, cw) = match c {
            SpindleCmd::Rpm { speed, clockwise } => (Some(speed), clockwise),
            SpindleCmd::Surface { speed, clockwise, .. } => {
                self.note(Diagnostic::new(
                    Code::SurfaceSpeed,
                    Severity::Warning,
                    None,
                    "surface speed not converted (no milling cutter's diameter before it): written as S",
                ))?;
                (Some(speed), clockwise)
            }
            SpindleCmd::Off => (None, true),
        };
        let s = &mut self.spindle;
        s.rpm = speed;
        s.restore = None;
        s.stopped_spindle = None;
        s.said_off = speed.is_none();
        match speed {
            Some(v) => self.spindle_start(v, cw)?,
            None => {
                if let Some(l) = self.f.line(&d.spindle_off, self.tool.number().unwrap_or(1), 0) {
                    self.out(&l)?;
                }
                self.spindle.on = false;
            }
        }
        Ok(())
    }

    /// COOLNT: its word, deferred before the first tool and move.
    pub(super) fn coolant(&mut self, c: CoolantCmd) -> Result<(), Error> {
        let d = self.o.dialect.clone();
        let w = match c {
            CoolantCmd::Flood => d.coolant_flood.clone(),
            CoolantCmd::Mist => d.coolant_mist.clone(),
            CoolantCmd::Through => d.coolant_through.clone(),
            CoolantCmd::Off => d.coolant_off.clone(),
        };
        let on = c != CoolantCmd::Off;
        // Nothing to cool before the first tool and move, and M6 would only stop it.
        let early = self.tool.number().is_none() && self.at.is_none();
        if !(early && (on || self.spindle.coolant_deferred))
            && let Some(l) = self.f.line(&w, 0, 0)
        {
            self.out(&l)?;
        }
        let s = &mut self.spindle;
        s.coolant = on.then_some(w);
        s.coolant_restore = None;
        s.stopped_coolant = None;
        s.coolant_deferred = early && on;
        Ok(())
    }

    /// Before a tool change (tool `number`, at CL `line`): the coolant off (M9 before M6), to
    /// be turned on again at the next tool's first move.
    pub(super) fn coolant_off_for_change(&mut self, number: u32, line: u32) -> Result<(), Stop> {
        let s = &self.spindle;
        if s.coolant.is_some()
            && s.coolant_restore.is_none()
            && !s.coolant_deferred
            && let Some(l) = self.f.line(&self.o.dialect.coolant_off, number, 0)
        {
            self.out(&l)?;
            self.spindle.coolant_restore = Some(line);
        }
        Ok(())
    }

    /// Before the first move after a stop: the spindle and coolant that ran before it.
    #[cold]
    pub(super) fn restart_after_stop(&mut self) -> Result<(), Stop> {
        if let Some(line) = self.spindle.stopped_spindle.take() {
            self.restart_spindle(line, "the stop halts the spindle")?;
        }
        if let Some(line) = self.spindle.stopped_coolant.take() {
            self.restart_coolant(line, "the stop halts the coolant")?;
        }
        Ok(())
    }

    /// Before a tool's first move (at CL `line`): the spindle again where the tool change
    /// stopped it, or at `spindle_speed` where the CL started none; the coolant deferred or
    /// turned off for the change.
    pub(super) fn restore_for_move(&mut self, line: u32) -> Result<(), Stop> {
        if let Some(line) = self.spindle.restore.take() {
            self.restart_spindle(line, "the tool change stopped the spindle")?;
        }
        if let Some(v) = self.o.spindle_speed
            && !self.spindle.on
            && !self.spindle.said_off
        {
            self.note(Diagnostic::new(
                Code::SpindleStopped,
                Severity::Info,
                Some(line),
                format!(
                    "the CL starts no spindle before this tool's first move: S{} (spindle_speed) started",
                    v.round()
                ),
            ))?;
            self.spindle.rpm = Some(v);
            self.spindle_start(v, true)?;
        }
        if std::mem::take(&mut self.spindle.coolant_deferred)
            && let Some(w) = self.spindle.coolant.clone()
            && let Some(l) = self.f.line(&w, 0, 0)
        {
            self.out(&l)?;
        }
        if let Some(line) = self.spindle.coolant_restore.take() {
            self.restart_coolant(line, "coolant off for the tool change")?;
        }
        Ok(())
    }

    /// The spindle again at the CL's last speed and direction, told at `line`: `why` it stood.
    fn restart_spindle(&mut self, line: u32, why: &str) -> Result<(), Stop> {
        let Some(v) = self.spindle.rpm else { return Ok(()) };
        let msg = format!("{why} and the CL did not start it again: S{} restarted", v.round());
        self.note(Diagnostic::new(Code::SpindleStopped, Severity::Info, Some(line), msg))?;
        self.spindle_start(v, self.spindle.cw)
    }

    /// The coolant in force again, told at `line`: `why` it was off.
    fn restart_coolant(&mut self, line: u32, why: &str) -> Result<(), Stop> {
        let Some(l) = self.spindle.coolant.clone().and_then(|w| self.f.line(&w, 0, 0)) else {
            return Ok(());
        };
        let msg = format!("{why} and the CL did not turn it on again: {l} restarted");
        self.note(Diagnostic::new(Code::CoolantRestored, Severity::Info, Some(line), msg))?;
        self.out(&l)
    }

    /// S and M3/M4 (TNC: a speed-only TOOL CALL, then the direction alone).
    fn spindle_start(&mut self, speed: f64, cw: bool) -> Result<(), Stop> {
        let d = self.o.dialect.clone();
        let (t, s) = (self.tool.number().unwrap_or(1), speed.round() as i64);
        let dir = if cw { &d.spindle_cw } else { &d.spindle_ccw };
        if d.style == crate::nc::Style::Conversational {
            for w in [&d.spindle, dir] {
                if let Some(l) = self.f.line(w, t, s) {
                    self.out(&l)?;
                }
            }
        } else if let Some(l) = self.f.line(&format!("{} {dir}", d.spindle), t, s) {
            self.out(&l)?;
        }
        let sp = &mut self.spindle;
        (sp.on, sp.cw, sp.warned) = (true, cw, false);
        Ok(())
    }
}
