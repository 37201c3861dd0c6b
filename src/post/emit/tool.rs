//! The tool in force: the change (retract, compensation and coolant off, the dialect's lines),
//! its length and where it came from, its length offset register, length compensation (or TCP)
//! on before its first move, the next tool readied, and the operation it cuts.

use super::Emitter;
use crate::diag::{Code, Diagnostic, Severity};
use crate::kinematics::Setup;
use crate::post::sink::ToolUse;
use crate::post::tools::LengthFrom;
use crate::post::{Error, Mode, Preselect, Sink, Summary};
use crate::post::Stop;

/// Lines of the summary's tool list: a program of thousands of tool changes repeats its tools.
const MAX_TOOL_LINES: usize = 1000;

/// The tool in the spindle and what the program has said of it.
#[derive(Debug)]
pub(super) struct Tool {
    /// The tool length in force (and the work offset): what FK and IK take.
    setup: Setup,
    number: Option<u32>,
    /// The tool's length offset register where the CL names one other than its number.
    adjust: Option<u32>,
    /// A tool change since the last block: the machine is not at the last block any more.
    changed: bool,
    /// Length compensation (or TCP) is on.
    comp_on: bool,
    /// The next compensation on is a tool's first move (the `first_move` template).
    first_move_due: bool,
    /// A tool or length changed: the summary's line for it is written at the next move.
    line_due: bool,
    /// Where the tool length in force came from.
    from: LengthFrom,
    /// The last tool length comment written (said again only when it changes).
    said: Option<String>,
    /// The cutter the CL last described (diameter, corner radius; profile units).
    cutter: Option<(f64, f64)>,
    /// The tool `SELCTL` readied: what templates see.
    next: Option<u32>,
    /// The tools the CL loads, in order (`preselect` `next` on a CL read twice), and how many
    /// tool changes have been written.
    load_order: Option<Vec<u32>>,
    changes: usize,
    /// No tool loaded before a move was told.
    warned_no_tool: bool,
    /// The CL's operation in progress.
    operation: Option<String>,
    /// The summary's tool lines: each tool's length and where it came from.
    used: Vec<ToolUse>,
}

impl Tool {
    /// `job_length`: the job fixed one length for every tool.
    pub(super) fn new(setup: Setup, job_length: bool, load_order: Option<Vec<u32>>) -> Tool {
        Tool {
            setup,
            number: None,
            adjust: None,
            changed: false,
            comp_on: false,
            first_move_due: true,
            line_due: true,
            from: if job_length { LengthFrom::Job } else { LengthFrom::Profile },
            said: None,
            cutter: None,
            next: None,
            load_order,
            changes: 0,
            warned_no_tool: false,
            operation: None,
            used: Vec::new(),
        }
    }

    #[inline]
    pub(super) fn setup(&self) -> &Setup {
        &self.setup
    }

    pub(super) fn number(&self) -> Option<u32> {
        self.number
    }

    /// A tool change (or a return home) since the last block: the machine is elsewhere.
    #[inline]
    pub(super) fn changed(&self) -> bool {
        self.changed
    }

    /// A block was written: the machine is where it says.
    #[inline]
    pub(super) fn moved(&mut self) {
        self.changed = false;
    }

    /// The machine went home (`at_block`: from a block written): positioned from there next.
    pub(super) fn homed(&mut self, at_block: bool) {
        self.changed |= at_block;
    }

    pub(super) fn comp_on(&self) -> bool {
        self.comp_on
    }

    /// Length compensation cancelled (around a plane change): on again before the next move.
    pub(super) fn comp_off(&mut self) {
        self.comp_on = false;
    }

    /// The summary's line for this tool and length is due at the next move.
    #[inline]
    pub(super) fn line_due(&self) -> bool {
        self.line_due
    }

    pub(super) fn cutter(&self) -> Option<(f64, f64)> {
        self.cutter
    }

    /// The cutter the CL describes (diameter, corner radius).
    pub(super) fn describe(&mut self, diameter: f64, corner_radius: f64) {
        self.cutter = Some((diameter, corner_radius));
    }

    pub(super) fn next(&self) -> Option<u32> {
        self.next
    }

    pub(super) fn operation(&self) -> Option<&str> {
        self.operation.as_deref()
    }

    pub(super) fn start_operation(&mut self, name: String) {
        self.operation = Some(name);
    }

    /// The tool length at the end, and each tool's line.
    pub(super) fn summary(&self, sum: &mut Summary) {
        sum.tool_length = self.setup.tool_length;
        sum.tools.clone_from(&self.used);
    }
}

impl<S: Sink + ?Sized> Emitter<'_, S> {
    /// A new tool length in force (the job fixed none): the NC from here on is cut for it, so
    /// the program says so where it takes effect, and where it came from (the header only knew
    /// the profile's).
    pub(in crate::post) fn tool_length(&mut self, l: f64, from: LengthFrom) -> Result<(), Stop> {
        let t = &mut self.tool;
        t.setup.tool_length = l;
        t.from = from;
        t.line_due = true;
        let w = self.f.fmt.linear as usize;
        let text = match t.number {
            // The table's length, or the fallback for a tool it lacks, is that tool's; the CL's
            // may be the next tool's (NX's TLDATA comes before its LOAD/TOOL): no number.
            Some(n) if from != LengthFrom::Cl => format!("TOOL {n} LENGTH {l:.w$} FROM {}", from.as_str().to_uppercase()),
            _ => format!("TOOL LENGTH {l:.w$} FROM {}", from.as_str().to_uppercase()),
        };
        // When it changes: NX repeats TLDATA with every operation (before its LOAD/TOOL).
        if t.said.as_deref() == Some(text.as_str()) {
            return Ok(());
        }
        let c = self.f.comment(&text).to_string();
        self.tool.said = Some(text);
        self.out(&c)
    }

    /// The summary's line for the tool in the spindle, at its first move with a new tool or
    /// length: the length it cut with, and where it came from (NX gives the next tool's TLDATA
    /// before its LOAD/TOOL: a line at the change would name the old tool).
    pub(super) fn record_tool(&mut self) {
        self.tool.line_due = false;
        let shape = self.tool_shape();
        self.sink.tool(self.written.next_block(), &shape);
        let t = &mut self.tool;
        let u = ToolUse {
            tool: t.number,
            length: t.setup.tool_length,
            from: t.from,
        };
        if !t.used.contains(&u) && t.used.len() < MAX_TOOL_LINES {
            t.used.push(u);
        }
    }

    /// A tool change: retract, compensation and coolant off, the dialect's change lines.
    pub(super) fn tool_change(&mut self, number: u32, adjust: Option<u32>, line: u32) -> Result<(), Error> {
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
        if self.tool.number == Some(number) {
            // With another length offset: in force from the next move.
            if adjust != self.tool.adjust {
                self.tool.adjust = adjust;
                self.tool.comp_on = false;
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
        if self.tool.comp_on {
            let templated = self.o.mode == Mode::Tcp && self.template("tcp_off", Some(line))?;
            if !templated && let Some(l) = self.f.line(&d.tcp_off, number, 0) {
                self.out(&l)?;
            }
            self.tool.comp_on = false;
            // TCP: the retract went the clearance along the tool axis (see `program_end`).
            if self.o.mode == Mode::Tcp
                && let Some(l) = self.f.line(&d.machine_z_up, number, 0)
            {
                self.out(&l)?;
            }
        }
        self.coolant_off_for_change(number, line)?;
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
        let t = &mut self.tool;
        t.number = Some(number);
        t.adjust = adjust;
        t.changed = true;
        t.first_move_due = true;
        t.line_due = true;
        t.changes += 1;
        self.preselect_next(line)?;
        self.spindle.tool_changed(line);
        Ok(())
    }

    /// `preselect` `next`: right after a tool change, the next tool the CL loads readied (the
    /// first pass's order); on a CL read once (a stream) the order is not known: said once at
    /// the second change, and `SELCTL` is written as the CL says.
    fn preselect_next(&mut self, line: u32) -> Result<(), Error> {
        if self.o.preselect != Preselect::Next || self.o.dialect.tool_preselect.is_empty() {
            return Ok(());
        }
        let Some(order) = &self.tool.load_order else {
            // Said at the second change: the tool it loads was not readied after the first.
            if self.tool.changes < 2 {
                return Ok(());
            }
            let why = "the CL is read once here (a stream), so the next tool is not known: readied where the CL says SELCTL";
            return self
                .say_once(why, Code::IgnoredRecord, Some(line), "preselect next")
                .map_err(Error::from);
        };
        match order.get(self.tool.changes).copied() {
            Some(next) if Some(next) != self.tool.next => self.preselect(next, line),
            _ => Ok(()),
        }
    }

    /// SELCTL: as the CL says (`preselect` `cl`, or `next` on a stream); with `next` the tool
    /// the first pass readied already is not written twice; with `off` none.
    pub(super) fn selctl(&mut self, tool: u32, line: u32) -> Result<(), Error> {
        match self.o.preselect {
            Preselect::Off => {
                let what = format!("SELCTL/{tool}: not written (preselect off)");
                self.note(Diagnostic::new(Code::IgnoredRecord, Severity::Info, Some(line), what))?;
                Ok(())
            }
            Preselect::Next if self.tool.load_order.is_some() && self.tool.next == Some(tool) => Ok(()),
            _ => self.preselect(tool, line),
        }
    }

    /// The next tool readied while this one cuts, within the tool word's range.
    fn preselect(&mut self, tool: u32, line: u32) -> Result<(), Error> {
        self.tool.next = Some(tool);
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

    /// Length compensation (or TCP) on with the tool's register, and the `first_move` template
    /// where this is a tool's first move (at CL `line`).
    pub(super) fn length_comp(&mut self, line: u32) -> Result<(), Stop> {
        let t = match self.tool.number {
            Some(t) => t,
            None => {
                if !self.tool.warned_no_tool {
                    self.tool.warned_no_tool = true;
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
        if !templated && let Some(l) = self.f.line(w, self.tool.adjust.unwrap_or(t), 0) {
            self.out(&l)?;
        }
        self.tool.comp_on = true;
        if std::mem::take(&mut self.tool.first_move_due) {
            self.template("first_move", Some(line))?;
        }
        Ok(())
    }
}
