//! Program events: the program's start and end, comments, operations, dwells, stops, passed-through
//! M and G codes, block delete; what a tool's first move needs on before it (`ensure_comp`).

use super::Emitter;
use crate::cl::Dwell;
use crate::diag::{Code, Diagnostic, Severity};
use crate::kinematics::Vec3;
use crate::post::{Error, Mode, ProgEvent, Sink};
use crate::post::Stop;

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
                self.tool.setup().tool_length,
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

    pub(in crate::post) fn program_end(&mut self) -> Result<(), Error> {
        self.cancel_cycle()?;
        self.cutcom_end("the program's end")?;
        self.leave_plane(false)?;
        self.retract_up()?;
        self.clamps.operation_ahead(false);
        self.lock_all()?;
        self.smooth_off()?;
        // TCP: X Y Z are the tip, and the retract above went the clearance along the tool axis;
        // machine Z home takes the spindle clear of the part whatever comes next.
        let z_up = self.o.mode == Mode::Tcp && self.at.is_some();
        if self.tool.operation().is_some() {
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
            ProgEvent::Cutter { diameter, corner_radius } => self.tool.describe(diameter, corner_radius),
            ProgEvent::ToolLength { length: l, .. } => {
                // Only when the job fixed the length (else `tool_length`, before planning).
                let length = self.tool.setup().tool_length;
                if (l - length).abs() > self.f.fmt.half_linear() {
                    self.note(Diagnostic::new(
                        Code::ToolLength,
                        Severity::Info,
                        None,
                        format!(
                            "the CL sets tool length {l:.*}; the job's {:.*} is used",
                            self.f.fmt.linear as usize, self.f.fmt.linear as usize, length
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
                if self.tool.operation().is_some() {
                    self.template("operation_end", None)?;
                }
                let c = self.f.comment(&format!("OPERATION {name}")).to_string();
                self.out(&c)?;
                self.smooth_operation(&name);
                self.tool.start_operation(name);
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
                self.tool.homed(self.at.is_some());
            }
            ProgEvent::End => {}
        }
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
        self.spindle.stopped(line);
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

    /// DELAY: seconds, or revolutions at the speed in force.
    fn dwell(&mut self, dwell: Dwell, line: u32) -> Result<(), Error> {
        // Revolutions at the speed in force; with no speed to turn them into time the
        // dwell cannot be written as the CL meant it.
        let secs = match dwell {
            Dwell::Seconds(t) => Ok(t),
            Dwell::Revolutions(n) => self.spindle.turning().map(|rpm| n * 60.0 / rpm).ok_or(n),
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
                self.written.add_time(t);
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

    /// Length compensation (or TCP) on, before the first motion of a tool (at CL `line`); and the
    /// spindle and coolant again where a tool change or a stop halted them, or at
    /// `spindle_speed` where the CL started none.
    pub(super) fn ensure_comp(&mut self, line: u32) -> Result<(), Stop> {
        if self.spindle.halted() {
            self.restart_after_stop()?;
        }
        if self.tool.comp_on() {
            return Ok(());
        }
        self.restore_for_move(line)?;
        self.length_comp(line)
    }

    /// The closing comment: how the run went, the last thing a client streaming the NC reads
    /// before the program end (the HTTP status went out with the first line).
    fn outcome(&self) -> String {
        let (e, w) = self.written.errors_warnings();
        if e > 0 {
            format!("KINEPOST: ERRORS {e}, WARNINGS {w}: NOT FIT TO RUN AS IS, SEE THE DIAGNOSTICS")
        } else {
            format!("KINEPOST: ERRORS 0, WARNINGS {w}")
        }
    }
}
