//! Program events: the program's start and end, tool changes, the tool length, spindle, coolant,
//! comments, dwells; length compensation (or TCP) on before a tool's first move.

use super::Emitter;
use crate::cl::{CoolantCmd, Dwell, SpindleCmd};
use crate::diag::{Code, Diagnostic, Severity};
use crate::kinematics::Vec3;
use crate::post::sink::ToolUse;
use crate::post::Stop;
use crate::post::tools::LengthFrom;
use crate::post::{Error, Mode, Preselect, ProgEvent, Sink};

/// Lines of the summary's tool list: a program of thousands of tool changes repeats its tools.
const MAX_TOOL_LINES: usize = 1000;

impl<S: Sink + ?Sized> Emitter<'_, S> {
    pub(in crate::post) fn program_start(&mut self) -> Result<(), Stop> {
        let mut lines = vec![
            format!("KINEPOST {} FOR {} ({})", env!("CARGO_PKG_VERSION"), self.m.id, self.m.name),
            format!(
                "MODE {} UNITS {} TOOL LENGTH {}{} TOLERANCE {}",
                match self.o.mode {
                    Mode::Joint => "JOINT",
                    Mode::Tcp => "TCP",
                },
                self.m.units.as_str(),
                self.setup.tool_length,
                // The header is out before the CL is read: say which length the NC is cut for.
                match (self.o.tool_length, &self.o.tool_table) {
                    (Some(_), _) => "",
                    (None, None) => " UNTIL THE CL SETS ONE",
                    (None, Some(_)) => " UNTIL A TOOL IS LOADED",
                },
                self.o.tolerance
            ),
        ];
        if let (None, Some(t)) = (self.o.tool_length, &self.o.tool_table) {
            let label = &self.o.tool_table_label;
            lines.push(format!(
                "TOOL LENGTHS FROM {label}, {} TOOLS, ELSE THE CL'S, ELSE THE PROFILE'S",
                t.len()
            ));
        }
        let wo = self.o.work_offset;
        if wo != Vec3::zeros() {
            lines.push(format!("WORK OFFSET {},{},{}", wo.x, wo.y, wo.z));
        }
        if let Some(s) = self.o.spindle_speed {
            lines.push(format!("SPINDLE S{} WHERE THE CL STARTS NONE", s.round()));
        }
        lines.extend(self.path_header());
        lines.extend(self.o.header.iter().cloned());
        for l in self.f.header(self.o.program_number, self.m.units, &lines, self.o.wcs_word()) {
            self.out(&l)?;
        }
        self.template("program_start", None)?;
        self.unknown_clamps()
    }

    /// A new tool length in force (the job fixed none): the NC from here on is cut for it, so
    /// the program says so where it takes effect, and where it came from (the header only knew
    /// the profile's).
    pub(in crate::post) fn tool_length(&mut self, l: f64, from: LengthFrom) -> Result<(), Stop> {
        self.setup.tool_length = l;
        self.sum.tool_length = l;
        self.length_from = from;
        self.tool_line_due = true;
        let w = self.f.fmt.linear as usize;
        let text = match self.tool {
            // The table's length, or the fallback for a tool it lacks, is that tool's; the CL's
            // may be the next tool's (NX's TLDATA comes before its LOAD/TOOL): no number.
            Some(n) if from != LengthFrom::Cl => format!("TOOL {n} LENGTH {l:.w$} FROM {}", from.as_str().to_uppercase()),
            _ => format!("TOOL LENGTH {l:.w$} FROM {}", from.as_str().to_uppercase()),
        };
        // When it changes: NX repeats TLDATA with every operation (before its LOAD/TOOL).
        if self.length_said.as_deref() == Some(text.as_str()) {
            return Ok(());
        }
        let c = self.f.comment(&text).to_string();
        self.length_said = Some(text);
        self.out(&c)
    }

    /// The summary's line for the tool in the spindle, at its first move with a new tool or
    /// length: the length it cut with, and where it came from (NX gives the next tool's TLDATA
    /// before its LOAD/TOOL: a line at the change would name the old tool).
    pub(super) fn record_tool(&mut self) {
        self.tool_line_due = false;
        let shape = self.tool_shape();
        self.sink.tool(self.blocks + 1, &shape);
        let u = ToolUse {
            tool: self.tool,
            length: self.setup.tool_length,
            from: self.length_from,
        };
        let tools = &mut self.sum.tools;
        if !tools.contains(&u) && tools.len() < MAX_TOOL_LINES {
            tools.push(u);
        }
    }

    pub(in crate::post) fn program_end(&mut self) -> Result<(), Error> {
        self.cancel_cycle()?;
        self.cutcom_end("the program's end")?;
        self.leave_plane(false)?;
        self.retract_up()?;
        self.cut_turns = false;
        self.lock_all()?;
        self.smooth_off()?;
        // TCP: X Y Z are the tip, and the retract above went the clearance along the tool axis;
        // machine Z home takes the spindle clear of the part whatever comes next.
        let z_up = self.o.mode == Mode::Tcp && self.at.is_some();
        if self.operation.is_some() {
            self.template("operation_end", None)?;
        }
        self.template("program_end", None)?;
        // The template's TCP off in place of the dialect's word, in the footer's order.
        let tcp_off = match self.o.mode == Mode::Tcp && self.o.dialect.templates.has("tcp_off") {
            true => Some(self.rendered("tcp_off")?),
            false => None,
        };
        let c = self.f.comment(&self.outcome()).to_string();
        self.out(&c)?;
        for l in self.f.footer(z_up, tcp_off) {
            self.out(&l)?;
        }
        Ok(())
    }

    pub(in crate::post) fn event(&mut self, ev: ProgEvent) -> Result<(), Error> {
        if !matches!(
            ev,
            ProgEvent::Comment(_)
                | ProgEvent::Operation(_)
                | ProgEvent::Diag(_)
                | ProgEvent::End
                | ProgEvent::PathMeaning { .. }
                | ProgEvent::Cutter { .. }
                | ProgEvent::Tolerance { .. }
        ) {
            self.cancel_cycle()?;
        }
        match ev {
            ProgEvent::Tool { number, adjust, line } => self.tool_change(number, adjust, line)?,
            ProgEvent::Cutter { diameter, corner_radius } => self.cl_cutter = Some((diameter, corner_radius)),
            ProgEvent::ToolLength { length: l, .. } => {
                // Only when the job fixed the length (else `tool_length`, before planning).
                if (l - self.setup.tool_length).abs() > self.f.fmt.half_linear() {
                    self.note(Diagnostic::new(
                        Code::ToolLength,
                        Severity::Info,
                        None,
                        format!(
                            "the CL sets tool length {l:.*}; the job's {:.*} is used",
                            self.f.fmt.linear as usize, self.f.fmt.linear as usize, self.setup.tool_length
                        ),
                    ))?;
                }
            }
            ProgEvent::Spindle(c) => self.spindle(c)?,
            ProgEvent::Coolant(c) => self.coolant(c)?,
            ProgEvent::Comment(t) => {
                let c = self.f.comment(&t).to_string();
                self.out(&c)?;
            }
            ProgEvent::Operation(name) => {
                if self.operation.is_some() {
                    self.template("operation_end", None)?;
                }
                let c = self.f.comment(&format!("OPERATION {name}")).to_string();
                self.out(&c)?;
                self.smooth_operation(&name);
                self.operation = Some(name);
                self.template("operation_start", None)?;
            }
            ProgEvent::Dwell { dwell, line } => self.dwell(dwell, line)?,
            ProgEvent::Stop { optional, line } => self.program_stop(optional, line)?,
            ProgEvent::Function { letter, code, line } => self.function(letter, &code, line)?,
            ProgEvent::BlockSkip { on, line } => self.block_skip(on, line)?,
            ProgEvent::Preselect { tool, line } => self.selctl(tool, line)?,
            ProgEvent::Tolerance { outer, value } => self.cl_tolerance(outer, value),
            ProgEvent::Setup { shift, turned, line, comment } => self.setup_change(shift, turned, line, &comment)?,
            ProgEvent::CutterComp { comp, line, turns } => self.cutter_comp(comp, line, turns),
            ProgEvent::PathMeaning { centre, said, line } => self.path_meaning(centre, said, line),
            ProgEvent::Diag(dg) => self.note(dg)?,
            ProgEvent::Home { .. } => {
                // Where a tool change leaves the machine: the next move positions from there.
                self.retract_up()?;
                self.tool_changed |= self.at.is_some();
            }
            ProgEvent::End => {}
        }
        Ok(())
    }

    /// A tool change: retract, compensation and coolant off, the dialect's change lines.
    fn tool_change(&mut self, number: u32, adjust: Option<u32>, line: u32) -> Result<(), Error> {
        let d = self.o.dialect.clone();
        // No safe side for a tool number: written as the CL says, and an error.
        let (tmax, hmax) = (d.ranges.tool, d.ranges.register);
        if adjust == Some(0) {
            self.note(Diagnostic::new(
                Code::WordRange,
                Severity::Error,
                Some(line),
                "length offset register 0 cancels the length offset: the tool would cut uncompensated",
            ))?;
        }
        for (what, v, max) in [
            ("tool number", number, tmax),
            ("offset register", adjust.unwrap_or(number), hmax),
        ] {
            if v > max {
                self.note(Diagnostic::new(
                    Code::WordRange,
                    Severity::Error,
                    Some(line),
                    format!("{what} {v} is beyond what {} takes (at most {max})", d.name),
                ))?;
            }
        }
        // The tool in the spindle loaded again (CATIA writes `LOADTL/1` then `LOADTL/1,1`):
        // a second change would only stop the spindle and retract.
        if self.tool == Some(number) {
            // With another length offset: in force from the next move.
            if adjust != self.adjust {
                self.adjust = adjust;
                self.comp_on = false;
            }
            self.note(Diagnostic::new(
                Code::IgnoredRecord,
                Severity::Info,
                Some(line),
                format!("tool {number} is in the spindle already: no tool change written"),
            ))?;
            return Ok(());
        }
        self.cutcom_end("a tool change")?;
        self.leave_plane(false)?;
        self.retract_up()?;
        // Fanuc's AI contour control must be off for M6; on every control the next tool's
        // operation says its own.
        self.smooth_off()?;
        if self.comp_on {
            let templated = self.o.mode == Mode::Tcp && self.template("tcp_off", Some(line))?;
            if !templated && let Some(l) = self.f.line(&d.tcp_off, number, 0) {
                self.out(&l)?;
            }
            self.comp_on = false;
            // TCP: the retract went the clearance along the tool axis (see `program_end`).
            if self.o.mode == Mode::Tcp
                && let Some(l) = self.f.line(&d.machine_z_up, number, 0)
            {
                self.out(&l)?;
            }
        }
        if self.coolant.is_some()
            && self.coolant_restore.is_none()
            && !self.coolant_deferred
            && let Some(l) = self.f.line(&d.coolant_off, number, 0)
        {
            self.out(&l)?;
            self.coolant_restore = Some(line);
        }
        let c = match adjust {
            Some(a) => format!("TOOL {number} LENGTH OFFSET {a}"),
            None => format!("TOOL {number}"),
        };
        let c = self.f.comment(&c).to_string();
        self.out(&c)?;
        if !self.template_with("tool_change", Some(line), |v| {
            v.set("tool", number);
        })? {
            for t in &d.tool_change {
                if let Some(l) = self.f.line(t, number, 0) {
                    self.out(&l)?;
                }
            }
        }
        self.f.reset_modal();
        self.tool = Some(number);
        self.adjust = adjust;
        self.tool_changed = true;
        self.first_move_due = true;
        self.tool_line_due = true;
        self.changes += 1;
        self.preselect_next(line)?;
        if std::mem::take(&mut self.spindle_on) {
            self.spindle_restore = Some(line);
        }
        // The tool change restarts what it stopped (`ensure_comp`).
        (self.stopped_spindle, self.stopped_coolant) = (None, None);
        self.spindle_said_off = false;
        Ok(())
    }

    /// SPINDL: a speed and direction, or off.
    fn spindle(&mut self, c: SpindleCmd) -> Result<(), Error> {
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
        self.rpm = speed;
        self.spindle_restore = None;
        self.stopped_spindle = None;
        self.spindle_said_off = speed.is_none();
        match speed {
            Some(v) => self.spindle_start(v, cw)?,
            None => {
                if let Some(l) = self.f.line(&d.spindle_off, self.tool.unwrap_or(1), 0) {
                    self.out(&l)?;
                }
                self.spindle_on = false;
            }
        }
        Ok(())
    }

    /// COOLNT: its word, deferred before the first tool and move.
    fn coolant(&mut self, c: CoolantCmd) -> Result<(), Error> {
        let d = self.o.dialect.clone();
        let w = match c {
            CoolantCmd::Flood => d.coolant_flood.clone(),
            CoolantCmd::Mist => d.coolant_mist.clone(),
            CoolantCmd::Through => d.coolant_through.clone(),
            CoolantCmd::Off => d.coolant_off.clone(),
        };
        let on = c != CoolantCmd::Off;
        // Nothing to cool before the first tool and move, and M6 would only stop it.
        let early = self.tool.is_none() && self.at.is_none();
        if !(early && (on || self.coolant_deferred))
            && let Some(l) = self.f.line(&w, 0, 0)
        {
            self.out(&l)?;
        }
        self.coolant = on.then_some(w);
        self.coolant_restore = None;
        self.stopped_coolant = None;
        self.coolant_deferred = early && on;
        Ok(())
    }

    /// STOP / OPSTOP: the control's program stop or optional stop. Most controls stop the
    /// spindle and coolant at either and do not start them on cycle start: unless the CL says
    /// otherwise first, the next move starts again what ran before.
    fn program_stop(&mut self, optional: bool, line: u32) -> Result<(), Error> {
        let d = self.o.dialect.clone();
        if let Some(l) = self.f.line(if optional { &d.optional_stop } else { &d.stop }, 0, 0) {
            self.out(&l)?;
        }
        self.stopped_spindle = (self.spindle_on && self.spindle_restore.is_none()).then_some(line);
        self.stopped_coolant = (self.coolant.is_some() && !self.coolant_deferred).then_some(line);
        Ok(())
    }

    /// AUXFUN / PREFUN: the code as the CAM gave it, on its own line, told; one that would
    /// contradict what kinepost writes (a program end, a tool change, a coordinate or motion
    /// mode) is an error and not written.
    fn function(&mut self, letter: char, code: &str, line: u32) -> Result<(), Error> {
        let word = format!("{letter}{code}");
        let (severity, what) = match crate::nc::function_risk(&self.o.dialect, letter, code) {
            crate::nc::Risk::Refused(why) => (Severity::Error, format!("{word} not written: {why}")),
            crate::nc::Risk::Untracked(why) => (Severity::Warning, format!("{word} written as the CL asks: {why}")),
            crate::nc::Risk::None => (Severity::Info, format!("{word} written as the CL asks")),
        };
        if severity != Severity::Error {
            let l = self.f.words(&word).to_string();
            self.out(&l)?;
        }
        self.note(Diagnostic::new(Code::IgnoredRecord, severity, Some(line), what))?;
        Ok(())
    }

    /// `preselect` `next`: right after a tool change, the next tool the CL loads readied (the
    /// first pass's order); on a CL read once (a stream) the order is not known: said once at
    /// the second change, and `SELCTL` is written as the CL says.
    fn preselect_next(&mut self, line: u32) -> Result<(), Error> {
        if self.o.preselect != Preselect::Next || self.o.dialect.tool_preselect.is_empty() {
            return Ok(());
        }
        let Some(order) = &self.load_order else {
            // Said at the second change: the tool it loads was not readied after the first.
            if self.changes < 2 {
                return Ok(());
            }
            let why = "the CL is read once here (a stream), so the next tool is not known: readied where the CL says SELCTL";
            return self
                .say_once(why, Code::IgnoredRecord, Some(line), "preselect next")
                .map_err(Error::from);
        };
        match order.get(self.changes).copied() {
            Some(next) if Some(next) != self.next_tool => self.preselect(next, line),
            _ => Ok(()),
        }
    }

    /// SELCTL: as the CL says (`preselect` `cl`, or `next` on a stream); with `next` the tool
    /// the first pass readied already is not written twice; with `off` none.
    fn selctl(&mut self, tool: u32, line: u32) -> Result<(), Error> {
        match self.o.preselect {
            Preselect::Off => {
                let what = format!("SELCTL/{tool}: not written (preselect off)");
                self.note(Diagnostic::new(Code::IgnoredRecord, Severity::Info, Some(line), what))?;
                Ok(())
            }
            Preselect::Next if self.load_order.is_some() && self.next_tool == Some(tool) => Ok(()),
            _ => self.preselect(tool, line),
        }
    }

    /// The next tool readied while this one cuts, within the tool word's range.
    fn preselect(&mut self, tool: u32, line: u32) -> Result<(), Error> {
        self.next_tool = Some(tool);
        let max = self.o.dialect.ranges.tool;
        if tool > max {
            return self.note(Diagnostic::new(
                Code::WordRange,
                Severity::Error,
                Some(line),
                format!("SELCTL/{tool}: beyond the tool numbers {} takes (up to {max}): not written", self.o.dialect.name),
            ))
            .map_err(Error::from);
        }
        if let Some(l) = self.f.line(&self.o.dialect.tool_preselect, tool, 0) {
            self.out(&l)?;
        }
        Ok(())
    }

    /// OPSKIP: the blocks until `OPSKIP/OFF` start with `/`, the operator's block delete. Not on
    /// a conversational control, whose skip syntax kinepost does not write: told instead.
    fn block_skip(&mut self, on: bool, line: u32) -> Result<(), Error> {
        if self.o.dialect.style != crate::nc::Style::Conversational {
            self.f.block_skip = on;
        } else if on {
            self.note(Diagnostic::new(
                Code::IgnoredRecord,
                Severity::Warning,
                Some(line),
                format!(
                    "OPSKIP/ON: block delete is not written on {}: the blocks after it run whatever the switch",
                    self.o.dialect.name
                ),
            ))?;
        }
        Ok(())
    }

    /// Before the first move after a stop: the spindle and coolant that ran before it.
    #[cold]
    fn restart_after_stop(&mut self) -> Result<(), Stop> {
        if let Some(line) = self.stopped_spindle.take() {
            self.restart_spindle(line, "the stop halts the spindle")?;
        }
        if let Some(line) = self.stopped_coolant.take() {
            self.restart_coolant(line, "the stop halts the coolant")?;
        }
        Ok(())
    }

    /// The spindle again at the CL's last speed and direction, told at `line`: `why` it stood.
    fn restart_spindle(&mut self, line: u32, why: &str) -> Result<(), Stop> {
        let Some(v) = self.rpm else { return Ok(()) };
        let msg = format!("{why} and the CL did not start it again: S{} restarted", v.round());
        self.note(Diagnostic::new(Code::SpindleStopped, Severity::Info, Some(line), msg))?;
        self.spindle_start(v, self.spindle_cw)
    }

    /// The coolant in force again, told at `line`: `why` it was off.
    fn restart_coolant(&mut self, line: u32, why: &str) -> Result<(), Stop> {
        let Some(l) = self.coolant.clone().and_then(|w| self.f.line(&w, 0, 0)) else {
            return Ok(());
        };
        let msg = format!("{why} and the CL did not turn it on again: {l} restarted");
        self.note(Diagnostic::new(Code::CoolantRestored, Severity::Info, Some(line), msg))?;
        self.out(&l)
    }

    /// DELAY: seconds, or revolutions at the speed in force.
    fn dwell(&mut self, dwell: Dwell, line: u32) -> Result<(), Error> {
        // Revolutions at the speed in force; with no speed to turn them into time the
        // dwell cannot be written as the CL meant it.
        let secs = match dwell {
            Dwell::Seconds(t) => Ok(t),
            Dwell::Revolutions(n) => self.rpm.filter(|_| self.spindle_on).map(|rpm| n * 60.0 / rpm).ok_or(n),
        };
        let max = self.o.dialect.ranges.dwell_s;
        if let Ok(t) = secs
            && (t.is_nan() || t > max)
        {
            self.note(Diagnostic::new(
                Code::WordRange,
                Severity::Error,
                Some(line),
                format!(
                    "a dwell of {t:e} s is beyond what {} takes ({max} s): written {max} s",
                    self.o.dialect.name
                ),
            ))?;
        }
        match secs.map(|t| if t <= max { t } else { max }) {
            // Shorter than a millisecond, the word says G4 P0: nothing to wait for.
            Ok(t) if t < 0.0005 => self.note(Diagnostic::new(
                Code::IgnoredRecord,
                Severity::Info,
                Some(line),
                format!("a dwell of {t:e} s rounds to nothing: none written"),
            ))?,
            Ok(t) => {
                for l in self.f.dwell(t) {
                    self.out(&l)?;
                }
                self.sum.cycle_time_s += t;
            }
            Err(n) => self.note(Diagnostic::new(
                Code::BadRecord,
                Severity::Warning,
                Some(line),
                format!("DELAY of {n} revolutions with no spindle turning: no dwell written"),
            ))?,
        }
        Ok(())
    }

    /// S and M3/M4 (TNC: a speed-only TOOL CALL, then the direction alone).
    pub(super) fn spindle_start(&mut self, speed: f64, cw: bool) -> Result<(), Stop> {
        let d = self.o.dialect.clone();
        let (t, s) = (self.tool.unwrap_or(1), speed.round() as i64);
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
        (self.spindle_on, self.spindle_cw, self.warned_spindle) = (true, cw, false);
        Ok(())
    }

    /// A cut with the spindle standing (a tool fed into the part without turning breaks): told
    /// once until the spindle starts. A warning, not an error: a probe or a scribe cuts nothing.
    pub(super) fn spindle_standing(&mut self, line: u32) -> Option<Diagnostic> {
        if self.spindle_on || self.warned_spindle {
            return None;
        }
        self.warned_spindle = true;
        Some(Diagnostic::new(
            Code::SpindleStopped,
            Severity::Warning,
            Some(line),
            "feed move with the spindle standing: the CL starts none before it (no SPINDL with a speed, or SPINDL/OFF since; spindle_speed gives one)",
        ))
    }

    /// Length compensation (or TCP) on, before the first motion of a tool (at CL `line`); and the
    /// spindle again where the tool change stopped it, or at `spindle_speed` where the CL started
    /// none.
    pub(super) fn ensure_comp(&mut self, line: u32) -> Result<(), Stop> {
        if self.stopped_spindle.is_some() || self.stopped_coolant.is_some() {
            self.restart_after_stop()?;
        }
        if self.comp_on {
            return Ok(());
        }
        if let Some(line) = self.spindle_restore.take() {
            self.restart_spindle(line, "the tool change stopped the spindle")?;
        }
        if let Some(v) = self.o.spindle_speed
            && !self.spindle_on
            && !self.spindle_said_off
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
            self.rpm = Some(v);
            self.spindle_start(v, true)?;
        }
        if std::mem::take(&mut self.coolant_deferred)
            && let Some(w) = self.coolant.clone()
            && let Some(l) = self.f.line(&w, 0, 0)
        {
            self.out(&l)?;
        }
        if let Some(line) = self.coolant_restore.take() {
            self.restart_coolant(line, "coolant off for the tool change")?;
        }
        let t = match self.tool {
            Some(t) => t,
            None => {
                if !self.warned_no_tool {
                    self.warned_no_tool = true;
                    self.note(Diagnostic::new(
                        Code::IgnoredRecord,
                        Severity::Info,
                        None,
                        "no tool loaded in the CL: length offset H1 used",
                    ))?;
                }
                1
            }
        };
        let d = self.o.dialect.clone();
        let w = match self.o.mode {
            Mode::Joint => &d.length_comp,
            Mode::Tcp => &d.tcp_on,
        };
        // The H word: the register the CL named, else the tool's own.
        let templated = self.o.mode == Mode::Tcp && self.template("tcp_on", Some(line))?;
        if !templated && let Some(l) = self.f.line(w, self.adjust.unwrap_or(t), 0) {
            self.out(&l)?;
        }
        self.comp_on = true;
        if std::mem::take(&mut self.first_move_due) {
            self.template("first_move", Some(line))?;
        }
        Ok(())
    }

    /// The closing comment: how the run went, the last thing a client streaming the NC reads
    /// before the program end (the HTTP status went out with the first line).
    fn outcome(&self) -> String {
        let (e, w) = (self.sum.errors, self.sum.warnings);
        if e > 0 {
            format!("KINEPOST: ERRORS {e}, WARNINGS {w}: NOT FIT TO RUN AS IS, SEE THE DIAGNOSTICS")
        } else {
            format!("KINEPOST: ERRORS 0, WARNINGS {w}")
        }
    }
}
