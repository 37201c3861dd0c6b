//! CL events → motion points (poses in the profile's units) and program events, in file order.
//!
//! Owns what CL makes modal: units, tool axis, RAPID for the next motion, feed, an arc announced
//! by CIRCLE, an active drilling cycle. Arcs and cycles become plain points here (linearized or
//! expanded) so the planner sees one kind of motion.

use crate::cl::{CoolantCmd, CutterComp, CycleKind, CycleParams, Dwell, Event, FeedUnit, Reader, Record, SpindleCmd};
use crate::diag::{Code, Diagnostic, Severity};
use crate::kinematics::{Pose, Units, Vec3};
use nalgebra::Matrix3;
use std::collections::VecDeque;
use std::io::BufRead;
use start::{Start, look_ahead};

mod drive;
mod frames;
mod start;
mod moves;
mod spindle;

/// Events read ahead before the first motion is planned: to find the units the CL starts in,
/// and to tell CL from what is not.
const UNITS_LOOKAHEAD: usize = 4096;

/// NC-looking statements before any CL record after which the input is refused as NC.
const NC_VERDICT: u32 = 16;

#[derive(Clone, Debug)]
pub struct MotionPt {
    pub line: u32,
    pub pose: Pose,
    pub rapid: bool,
    /// Programmed feed in profile units per minute (or per rev).
    pub feed: Option<(f64, FeedUnit)>,
    /// A point the source inserted (arc or cycle expansion), not a CL GOTO itself.
    pub inserted: bool,
    pub comment: Option<&'static str>,
    /// This point ends an arc from the previous one (CL CIRCLE): the engine writes G2/G3 where
    /// the control and the machine's pose allow, else it linearizes within the tolerance.
    pub arc: Option<Box<ArcSpec>>,
    /// This point is part of a drilling cycle's expansion: with canned-cycle output the engine
    /// may write the whole hole as one cycle block; `verify` finds a hole's top on the feed in.
    pub hole: Option<Box<HolePart>>,
}

/// The points of one hole, in order: `Start` (canned output, and every tap or stopping bore:
/// rapid, above the hole at the higher of the clearance and retract heights, carrying the
/// cycle), then the R plane (`Clear` where it starts a hole written as moves), `Top` (the CL
/// GOTO), the bottom and the retract, those three `Rest`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum HolePart {
    Start(Hole),
    Clear,
    Top,
    Rest,
}

/// A drilling cycle at one hole, heights along the tool axis from the hole's top (the CL point),
/// profile units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hole {
    pub kind: CycleKind,
    pub depth: f64,
    /// The R plane: where the feed starts.
    pub clear: f64,
    /// Where the tool waits between holes (and returns to): the higher of clearance and retract.
    pub start: f64,
    pub peck: Option<f64>,
    /// Seconds at the bottom.
    pub dwell: Option<f64>,
    /// A fine bore's shift off the wall, profile units.
    pub shift: Option<f64>,
    /// Feed in profile units per minute or per rev (None: no feed, the expansion rapids).
    pub feed: Option<(f64, FeedUnit)>,
}

/// An arc in the part frame, profile units: motion turns counter-clockwise about `normal`.
#[derive(Clone, Copy, Debug)]
pub struct ArcSpec {
    pub center: Vec3,
    pub normal: Vec3,
    pub radius: f64,
    /// Swept angle (radians, in (0, 2π], or beyond for a helix of several turns).
    pub sweep: f64,
}

#[derive(Clone, Debug)]
pub enum ProgEvent {
    /// A tool change; `adjust`: its length offset register where it is not `number`.
    Tool {
        number: u32,
        adjust: Option<u32>,
        line: u32,
    },
    /// The cutter the CL describes (`TLDATA`, `CUTTER`): diameter and corner radius, profile
    /// units; the collision check's tool where the tool table does not say.
    Cutter {
        diameter: f64,
        corner_radius: f64,
    },
    /// A tool length the CL gives (profile units), at `line`.
    ToolLength {
        length: f64,
        line: u32,
    },
    Dwell {
        dwell: Dwell,
        line: u32,
    },
    Spindle(SpindleCmd),
    Coolant(CoolantCmd),
    Comment(String),
    /// A program stop (`optional`: the operator's optional stop).
    Stop {
        optional: bool,
        line: u32,
    },
    /// An M or G code the CAM passes to the control.
    Function {
        letter: char,
        code: String,
        line: u32,
    },
    /// `INTOL` (`outer` false) or `OUTTOL`: the CAM's tolerance (profile units).
    Tolerance {
        outer: bool,
        value: f64,
    },
    /// The next tool readied (`SELCTL`).
    Preselect {
        tool: u32,
        line: u32,
    },
    /// The operation's MCS changed (NX `MSYS`): its origin from the first's (part frame,
    /// profile units), and whether it is turned against it. Its points come already taken into
    /// the first's frame.
    Setup {
        shift: Vec3,
        turned: bool,
        line: u32,
        /// What the program says of it where the points are taken into the first's frame.
        comment: String,
    },
    /// `OPSKIP/ON` or `OFF`.
    BlockSkip {
        on: bool,
        line: u32,
    },
    /// `CUTCOM`; `turns`: the line of the first record before its `OFF` that turns the tool
    /// axis (simultaneous motion under compensation), as far as the source reads ahead.
    CutterComp {
        comp: CutterComp,
        line: u32,
        turns: Option<u32>,
    },
    /// The CL's word on its path: the tool centre (`centre`) or the contour.
    PathMeaning {
        centre: bool,
        said: String,
        line: u32,
    },
    Operation(String),
    /// `GOHOME` without a point: up to the top of Z travel (the machine's home as far as a
    /// profile says one), the next move positioning from there.
    Home {
        line: u32,
    },
    Diag(Diagnostic),
    End,
}

#[derive(Clone, Debug)]
pub enum Item {
    Motion(MotionPt),
    Event(ProgEvent),
}

pub struct Source<R> {
    reader: Reader<R>,
    ahead: VecDeque<Event>,
    out: VecDeque<Item>,
    /// CL units → profile units.
    pub scale: f64,
    pub cl_units: Units,
    pub units_source: &'static str,
    profile_units: Units,
    tip: Option<Vec3>,
    axis: Vec3,
    rapid_next: bool,
    /// A move with no feed was reported (once a program: the rest follow the same rule).
    warned_no_feed: bool,
    feed: Option<(f64, FeedUnit)>,
    /// The last CUTTER/TLDATA diameter, in mm: turns a surface speed into RPM (not for a lathe
    /// tool, whose surface speed is about the part's diameter).
    diameter_mm: Option<f64>,
    turning: bool,
    /// The record that made the moves a lathe's (line, what it is), while it holds: kinepost
    /// posts milling, so those moves are told and not written.
    lathe: Option<(u32, &'static str)>,
    /// `lathe` was set since the last motion or tool change: the tool change it describes is
    /// still to come.
    lathe_fresh: bool,
    /// The first move under `lathe` was told.
    lathe_told: bool,
    /// A feed was programmed somewhere: without one, every move was a rapid (`no_feed`).
    fed: bool,
    /// The first move written at rapid for want of a feed.
    first_unfed: Option<u32>,
    /// A `UNITS` record is in force: a feed unit that contradicts it is told (once).
    units_declared: bool,
    feed_unit_told: bool,
    circle: Option<([f64; 3], [f64; 3], Option<f64>)>,
    circle_cw: bool,
    circle_turns: u32,
    /// The direction of the last move (CL frame), and the one `INDIRV` gives the next drive
    /// statement: which way it goes.
    last_dir: Option<Vec3>,
    indir: Option<Vec3>,
    /// `MOVARC`'s sweep (radians): which way round the arc goes.
    circle_sweep: Option<f64>,
    /// The clearance plane (`CLEARP`) in the part frame, profile units: unit normal, offset.
    clearance: Option<(Vec3, f64)>,
    cycle: Option<CycleParams>,
    /// `ROTABL` angles (A, B, C) as the CL states them, and the line of the last one.
    table: [f64; 3],
    table_line: u32,
    /// The indexing frame: CL positions (and tool axes a GOTO gives) after a `ROTABL` are in
    /// the part turned by it, `frame` takes them into the part frame. Resolved at the first
    /// motion after the index changes (`frame_pending`).
    frame: Option<Matrix3<f64>>,
    frame_pending: bool,
    /// NX `MSYS`: the first operation's MCS (rotation, origin in mm), and the current one
    /// relative to it (rotation, translation in mm) while they differ.
    mcs0: Option<(Matrix3<f64>, Vec3)>,
    mcs: Option<(Matrix3<f64>, Vec3)>,
    /// Mark drilling holes for canned-cycle output (and approach them at the start level).
    pub canned_cycles: bool,
    /// The largest feed per minute the control's F word takes, profile units.
    pub feed_max: f64,
    /// The machine's spindle speeds, RPM (`Options::spindle_range`).
    pub spindle_range: (f64, f64),
    ended: bool,
    /// The line of an `END`/`FINI` not yet followed by motion.
    end_line: Option<u32>,
    /// For the `CUTCOM` being handled: where its compensated stretch turns the tool axis.
    comp_turns: Option<u32>,
    pub strict_error: Option<Diagnostic>,
    strict: bool,
}

#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error(transparent)]
    Read(#[from] crate::cl::Error),
    /// The input is no CL data: NC, or nothing a CL reader recognises.
    #[error("{}", .0.message)]
    NotCl(Diagnostic),
}

impl<R: BufRead> Source<R> {
    /// `cl_units`: the caller's statement of the CL units where the file makes none before its
    /// first motion.
    pub fn new(input: R, profile_units: Units, cl_units: Option<Units>, strict: bool) -> Result<Self, Error> {
        let mut reader = Reader::new(input);
        let Start { ahead, units, source, told } = look_ahead(&mut reader, profile_units, cl_units)?;
        let mut out: VecDeque<Item> = told.map(|d| Item::Event(ProgEvent::Diag(d))).into_iter().collect();
        if source.starts_with("assumed") {
            out.push_back(Item::Event(ProgEvent::Diag(Diagnostic::new(
                Code::UnitsAssumed,
                Severity::Warning,
                None,
                format!(
                    "no UNITS record before the first motion and no unit-bearing FEDRAT: CL taken as {} until a UNITS record says otherwise",
                    profile_units.as_str()
                ),
            ))));
        }
        Ok(Source {
            reader,
            ahead,
            out,
            scale: units.factor_to(profile_units),
            cl_units: units,
            units_source: source,
            profile_units,
            tip: None,
            axis: Vec3::z(),
            rapid_next: false,
            warned_no_feed: false,
            feed: None,
            diameter_mm: None,
            turning: false,
            lathe: None,
            lathe_fresh: false,
            lathe_told: false,
            fed: false,
            first_unfed: None,
            units_declared: source == "UNITS record",
            feed_unit_told: false,
            circle: None,
            circle_cw: false,
            circle_turns: 1,
            circle_sweep: None,
            last_dir: None,
            indir: None,
            clearance: None,
            cycle: None,
            table: [0.0; 3],
            table_line: 0,
            frame: None,
            frame_pending: false,
            mcs0: None,
            mcs: None,
            canned_cycles: false,
            feed_max: f64::INFINITY,
            spindle_range: (1.0, super::MAX_SPINDLE_SPEED),
            ended: false,
            end_line: None,
            comp_turns: None,
            strict_error: None,
            strict,
        })
    }

    /// What the CL said of its path (tool centre or contour) before the first motion, as far as
    /// the units look-ahead read: the header states it.
    pub fn stated_path(&self) -> Option<(bool, String, u32)> {
        self.ahead.iter().find_map(|e| match e {
            Event::Statement(s) => match &s.record {
                Record::PathMeaning { centre, said } => Some((*centre, said.clone(), s.line)),
                _ => None,
            },
            _ => None,
        })
    }

    /// Reads ahead (at most [`UNITS_LOOKAHEAD`] events held) over the stretch a `CUTCOM` turns
    /// compensation on for, to its `OFF` or a tool change: the line of the first record there
    /// that turns the tool axis. The control's compensation must be chosen at its start (2D in
    /// a plane, or 3D), before those moves are planned.
    fn stretch_turns(&mut self) -> Result<Option<u32>, Error> {
        let mut axis = self.frame.map_or(self.axis, |r| r.transpose() * self.axis);
        let mut k = 0;
        loop {
            if k == self.ahead.len() {
                if self.ahead.len() >= UNITS_LOOKAHEAD {
                    return Ok(None);
                }
                match self.reader.next_event()? {
                    Some(e) => self.ahead.push_back(e),
                    None => return Ok(None),
                }
            }
            let Event::Statement(s) = &self.ahead[k] else {
                k += 1;
                continue;
            };
            let given = match &s.record {
                Record::CutterComp(CutterComp::Off) | Record::LoadTool { .. } | Record::End => return Ok(None),
                Record::RotaryTable { .. } => return Ok(Some(s.line)),
                Record::Goto { axis: Some(a), .. }
                | Record::GoDelta { axis: Some(a), .. }
                | Record::From { axis: Some(a), .. } => Some(*a),
                Record::ToolAxis(a) => Some(*a),
                Record::Multax(false) => Some([0.0, 0.0, 1.0]),
                _ => None,
            };
            if let Some(a) = given.map(Vec3::from).filter(|a| a.norm() > 1e-9).map(|a| a.normalize()) {
                if (a - axis).norm() > 1e-6 {
                    return Ok(Some(s.line));
                }
                axis = a;
            }
            k += 1;
        }
    }

    /// The reader's held words not yet told ([`crate::cl::Reader::take_held`]).
    pub fn take_held(&mut self) -> Vec<Diagnostic> {
        self.reader.take_held()
    }

    /// CL bytes consumed so far.
    pub fn bytes_read(&self) -> u64 {
        self.reader.bytes_read()
    }

    pub fn next_item(&mut self) -> Result<Option<Item>, Error> {
        loop {
            if let Some(i) = self.out.pop_front() {
                return Ok(Some(i));
            }
            if self.ended || self.strict_error.is_some() {
                return Ok(None);
            }
            let ev = match self.ahead.pop_front() {
                Some(e) => e,
                None => match self.reader.next_event()? {
                    Some(e) => e,
                    None => {
                        self.ended = true;
                        self.at_end();
                        continue;
                    }
                },
            };
            match ev {
                Event::Diagnostic(d) => {
                    if self.strict && d.severity == Severity::Error {
                        self.strict_error = Some(d.clone());
                    }
                    self.out.push_back(Item::Event(ProgEvent::Diag(d)));
                }
                Event::Statement(s) => {
                    if matches!(s.record, Record::CutterComp(CutterComp::On { .. })) {
                        self.comp_turns = self.stretch_turns()?;
                    }
                    if let Some(pt) = self.statement(s.line, s.record) {
                        // The common case, nothing queued before it: handed over directly.
                        if self.out.is_empty() {
                            return Ok(Some(Item::Motion(pt)));
                        }
                        self.out.push_back(Item::Motion(pt));
                    }
                }
            }
        }
    }

    fn diag(&mut self, code: Code, sev: Severity, line: u32, msg: String) {
        let d = Diagnostic::new(code, sev, Some(line), msg);
        if self.strict && sev == Severity::Error {
            self.strict_error = Some(d.clone());
        }
        self.out.push_back(Item::Event(ProgEvent::Diag(d)));
    }


    fn set_axis(&mut self, a: [f64; 3], line: u32) -> bool {
        let v = Vec3::from(a);
        let n = v.norm();
        if !(n.is_finite() && n > 1e-9) {
            self.diag(
                Code::BadRecord,
                Severity::Error,
                line,
                "tool axis is zero or not finite: record skipped".into(),
            );
            return false;
        }
        if (n - 1.0).abs() > 1e-4 {
            self.diag(
                Code::AxisNormalized,
                Severity::Warning,
                line,
                format!("tool axis of length {n:.6} normalised"),
            );
        }
        self.axis = v / n;
        true
    }

    /// A tool length the CL gives: a negative one (the tip above the gauge line) is a typo or a
    /// sign convention kinepost does not share, an error, and the length in force stays.
    fn tool_length(&mut self, length: Option<f64>, line: u32) {
        match length {
            Some(l) if l < 0.0 => self.diag(
                Code::ToolLength,
                Severity::Error,
                line,
                format!("tool length {l} is negative: not used (the length in force stays)"),
            ),
            Some(l) => self.out.push_back(Item::Event(ProgEvent::ToolLength {
                length: l * self.scale,
                line,
            })),
            None => {}
        }
    }

    /// The end of the CL: what only the whole program shows.
    fn at_end(&mut self) {
        if let (false, Some(line)) = (self.fed, self.first_unfed) {
            // One rapid approach is a program's right; a program with no feed at all cuts at
            // rapid wherever it touches the part.
            self.diag(
                Code::NoFeed,
                Severity::Error,
                line,
                format!("no FEDRAT in the whole program: every move was written at rapid (the first that may cut at line {line}); a cut at rapid breaks the tool"),
            );
        }
    }

    /// `MODE/TURN`, a lathe tool (`turning`), or their milling counterparts: the moves after a
    /// lathe's are told once and not written, up to a milling tool or mode.
    fn lathe(&mut self, turning: bool, line: u32, what: &'static str) {
        if !turning {
            self.lathe = None;
            return;
        }
        if self.lathe.is_none() {
            self.lathe = Some((line, what));
            self.lathe_told = false;
        }
        self.lathe_fresh = true;
    }

    /// UNITS: from its line on. After motion a change is told: the points before it keep the
    /// units they were read in.
    fn units(&mut self, u: Units, line: u32) {
        if u != self.cl_units && self.tip.is_some() {
            let (was, now) = (self.cl_units.as_str(), u.as_str());
            self.diag(
                Code::UnitsChanged,
                Severity::Warning,
                line,
                format!("units change after motion, from {was} to {now}: the CL from line {line} on is read as {now}, the points before it as {was}"),
            );
        }
        self.cl_units = u;
        self.scale = u.factor_to(self.profile_units);
        self.units_declared = true;
    }

    /// FEDRAT: in profile units, within the F word's range.
    fn feedrate(&mut self, value: f64, unit: FeedUnit, units: Option<Units>, line: u32) {
        self.fed = true;
        let mut f = units.map_or(self.scale, |u| u.factor_to(self.profile_units));
        if let Some(u) = units.filter(|u| self.units_declared && *u != self.cl_units) {
            // Fusion writes `UNITS/INCHES` with `FEDRAT/35.,MMPM`: one of the two is wrong, and
            // the file does not say which. The slower reading is the one that breaks nothing.
            f = f.min(self.scale);
            if !std::mem::replace(&mut self.feed_unit_told, true) {
                let (said, declared) = (u.as_str(), self.cl_units.as_str());
                let taken = if f == self.scale { declared } else { said };
                let msg = format!(
                    "FEDRAT in {said} per {} where UNITS says {declared}: {value} taken in {taken}, the slower reading (and so every such feed of the program)",
                    if unit == FeedUnit::PerRev { "revolution" } else { "minute" }
                );
                self.diag(Code::UnitsAssumed, Severity::Warning, line, msg);
            }
        }
        let mut v = value * f;
        // Beyond the F word's range (a typo, a unit mix-up): an error where the CL says
        // it, and the control's largest F, the slower side (it overflowed to F0).
        if unit == FeedUnit::PerMinute && (v.is_nan() || v > self.feed_max) {
            self.diag(
                Code::WordRange,
                Severity::Error,
                line,
                format!(
                    "feed {v:e} is beyond what the control's F word takes: written F{}",
                    self.feed_max
                ),
            );
            v = self.feed_max;
        }
        self.feed = Some((v, unit));
    }


    /// One record: a plain move comes back (to go after whatever the record queued), everything
    /// else is queued here.
    fn statement(&mut self, line: u32, rec: Record) -> Option<MotionPt> {
        let from = matches!(rec, Record::From { .. });
        match rec {
            Record::Goto { p, axis } | Record::From { p, axis } => {
                if !self.motion_axis(axis, line) {
                    return None;
                }
                // FROM says where the tool stands, it programs no cut: the machine gets there at
                // rapid, whatever feed is in force.
                self.rapid_next |= from;
                return self.motion(line, Vec3::from(p));
            }
            // A point: a rapid there, as any rapid is written (rotaries turned at the top of
            // Z). None: the machine's home.
            Record::GoHome { p: Some(p), axis } => {
                if !self.motion_axis(axis, line) {
                    return None;
                }
                self.rapid_next = true;
                return self.motion(line, Vec3::from(p));
            }
            Record::GoHome { p: None, .. } => self.out.push_back(Item::Event(ProgEvent::Home { line })),
            Record::GoDelta { d, axis } => {
                if !self.motion_axis(axis, line) {
                    return None;
                }
                let base = self.tip.unwrap_or_else(Vec3::zeros);
                return self.motion(line, base + Vec3::from(d));
            }
            Record::Rapid => self.rapid_next = true,
            Record::Feedrate { value, unit, units } => self.feedrate(value, unit, units, line),
            Record::Units(u) => self.units(u, line),
            Record::Spindle(c) => self.spindle(c, line),
            Record::Coolant(c) => self.out.push_back(Item::Event(ProgEvent::Coolant(c))),
            Record::LoadTool { number, length, adjust } => {
                // A tool change after a turning operation's moves is a new tool: a lathe's only
                // if its own records say so (they come before the LOADTL, as CATIA writes them).
                if !std::mem::take(&mut self.lathe_fresh) {
                    self.lathe = None;
                }
                self.tool_length(length, line);
                self.out.push_back(Item::Event(ProgEvent::Tool { number, adjust, line }));
            }
            Record::ToolData {
                diameter,
                corner_radius,
                length,
                turning,
            } => self.tool_data(diameter, corner_radius, length, turning, line),
            Record::Multax(on) => {
                if !on {
                    self.axis = self.to_program(Vec3::z());
                }
            }
            Record::ToolAxis(a) => {
                // Under an index, a new tool axis must agree with it again.
                let a = self.to_program(Vec3::from(a)).into();
                self.frame_pending |= self.set_axis(a, line) && self.table != [0.0; 3];
            }
            Record::Delay(dwell) => self.out.push_back(Item::Event(ProgEvent::Dwell { dwell, line })),
            Record::Stop { optional, text } => {
                // The operator's instruction is the point of the stop: kept, as PPRINT is.
                if !text.is_empty() {
                    self.out.push_back(Item::Event(ProgEvent::Comment(text)));
                }
                self.out.push_back(Item::Event(ProgEvent::Stop { optional, line }))
            }
            Record::Mode { turning } => self.lathe(turning, line, "MODE/TURN"),
            Record::Function { letter, code } => {
                self.out.push_back(Item::Event(ProgEvent::Function { letter, code, line }))
            }
            Record::Preselect(tool) => self.out.push_back(Item::Event(ProgEvent::Preselect { tool, line })),
            Record::Tolerance { outer, value } => {
                let value = value * self.scale;
                self.out.push_back(Item::Event(ProgEvent::Tolerance { outer, value }))
            }
            Record::BlockSkip(on) => self.out.push_back(Item::Event(ProgEvent::BlockSkip { on, line })),
            Record::Mcs { origin, x, y } => self.mcs(origin, x, y, line),
            Record::CutterComp(comp) => {
                let turns = self.comp_turns.take();
                self.out.push_back(Item::Event(ProgEvent::CutterComp { comp, line, turns }));
            }
            Record::PathMeaning { centre, said } => {
                self.out.push_back(Item::Event(ProgEvent::PathMeaning { centre, said, line }))
            }
            Record::RotaryTable { axis, angle, incr } => match axis {
                Some(i) => {
                    self.table[i] = if incr { self.table[i] + angle } else { angle };
                    self.table_line = line;
                    self.frame_pending = true;
                }
                None if angle == 0.0 => {}
                None => self.diag(
                    Code::TableIndex,
                    Severity::Error,
                    line,
                    format!(
                        "ROTABL {angle} names no axis (AAXIS, BAXIS, CAXIS): the frame of what follows is not known; not applied"
                    ),
                ),
            },
            Record::Circle {
                center,
                axis,
                radius,
                clockwise,
                turns,
                sweep_deg,
            } => {
                self.circle = Some((center, axis, radius));
                self.circle_cw = clockwise;
                self.circle_turns = turns;
                self.circle_sweep = sweep_deg.map(f64::to_radians);
            }
            Record::Clearance(plane) => self.clearance(plane),
            Record::Retract => self.retract(line),
            Record::Cycle(c) => {
                // A cycle's own feed is a feed: its holes are not cut at rapid.
                self.fed |= c.feed.is_some();
                self.cycle = Some(self.r_at_or_above_top(c, line));
                // Canned output says per hole what it could not write as a cycle.
                if self.canned_cycles || c.kind.canned_only() {
                    return None;
                }
                self.diag(
                    Code::CycleExpanded,
                    Severity::Info,
                    line,
                    "drilling cycle expanded into moves".into(),
                );
            }
            Record::CycleOff => self.cycle = None,
            Record::OperationStart(name) => self.out.push_back(Item::Event(ProgEvent::Operation(name))),
            Record::OperationEnd => {}
            Record::PartNo(t) => self.out.push_back(Item::Event(ProgEvent::Comment(format!("PART {t}")))),
            Record::Comment(t) => self.out.push_back(Item::Event(ProgEvent::Comment(t))),
            Record::End => {
                self.end_line.get_or_insert(line);
                self.out.push_back(Item::Event(ProgEvent::End));
            }
            Record::Drive(d) => return self.drive(line, d),
            Record::InDir { v, point } => self.indir(v, point, line),
            Record::Ignored(_) => {}
        }
        None
    }

    /// `TLDATA`, `CUTTER`, `TOOLNO`, `TURRET`: the cutter (its diameter turns a surface speed
    /// into RPM and shapes the collision check), its length, and whether it is a lathe's.
    fn tool_data(&mut self, diameter: Option<f64>, corner_radius: Option<f64>, length: Option<f64>, turning: Option<bool>, line: u32) {
        if let Some(t) = turning {
            self.turning = t;
            self.lathe(t, line, "a lathe tool");
        }
        if let Some(d) = diameter.filter(|d| d.is_finite() && *d > 0.0) {
            self.diameter_mm = Some(d * self.cl_units.factor_to(Units::Mm));
            let r = corner_radius.filter(|r| r.is_finite() && *r >= 0.0 && *r <= d / 2.0).unwrap_or(0.0);
            self.out.push_back(Item::Event(ProgEvent::Cutter {
                diameter: d * self.scale,
                corner_radius: r * self.scale,
            }));
        }
        self.tool_length(length, line);
    }

    /// What a motion record does before its point: the index frame resolved if it changed, and
    /// the tool axis it gives (CL frame) taken into the part frame. False: the axis is bad and
    /// the record skipped.
    fn motion_axis(&mut self, axis: Option<[f64; 3]>, line: u32) -> bool {
        if let Some(end) = self.end_line.take() {
            let msg = format!("the CL ends here, yet moves on (line {line}): what follows is posted as the CL goes on");
            self.diag(Code::IgnoredRecord, Severity::Warning, end, msg);
        }
        if self.frame_pending {
            self.resolve_frame(line);
        }
        axis.is_none_or(|a| self.set_axis(self.to_part(Vec3::from(a)).into(), line))
    }

    fn push(&mut self, line: u32, p_cl: Vec3, rapid: bool, inserted: bool, comment: Option<&'static str>) {
        let pt = self.motion_pt(line, p_cl, rapid, inserted, comment);
        self.out.push_back(Item::Motion(pt));
    }

    fn motion_pt(&self, line: u32, p_cl: Vec3, rapid: bool, inserted: bool, comment: Option<&'static str>) -> MotionPt {
        MotionPt {
            line,
            pose: Pose {
                tip: self.to_part_point(p_cl),
                axis: self.axis,
            },
            rapid,
            feed: self.feed,
            inserted,
            comment,
            arc: None,
            hole: None,
        }
    }

    fn mark(&mut self, part: HolePart) {
        if let Some(Item::Motion(m)) = self.out.back_mut() {
            m.hole = Some(Box::new(part));
        }
    }

    /// A move to `p` (CL units): a drilling cycle's moves are queued here; a plain move (with the
    /// arc it ends, if any) comes back.
    fn motion(&mut self, line: u32, p: Vec3) -> Option<MotionPt> {
        self.lathe_fresh = false;
        if let Some((at, what)) = self.lathe {
            self.rapid_next = false;
            self.circle = None;
            if std::mem::replace(&mut self.lathe_told, true) {
                return None;
            }
            let msg = format!(
                "a turning operation ({what} at line {at}): kinepost posts milling, and a lathe's moves on a mill are a crash; its moves (from line {line}) are not written"
            );
            self.diag(Code::Turning, Severity::Error, at, msg);
            return None;
        }
        let asked = std::mem::take(&mut self.rapid_next);
        // The first move positions at rapid anyway; a later one with no feed yet is most
        // likely an approach, but if the CAM system meant a cut, G0 through stock is a crash.
        if !asked && self.feed.is_none() && self.cycle.is_none() && self.tip.is_some() && !self.warned_no_feed {
            self.warned_no_feed = true;
            self.diag(
                Code::NoFeed,
                Severity::Warning,
                line,
                "move with no FEDRAT programmed yet: written at rapid, as is every move until one comes".into(),
            );
        }
        let rapid = asked || self.feed.is_none();
        if !asked && self.feed.is_none() && self.cycle.is_none() && self.tip.is_some() {
            self.first_unfed.get_or_insert(line);
        }
        if let Some(c) = self.cycle {
            self.hole(line, p, c);
            self.tip = Some(p);
            return None;
        }
        let arc = match (self.circle.take(), self.tip) {
            (Some((center, axis, radius)), Some(start)) if !rapid => {
                self.arc(line, start, p, Vec3::from(center), Vec3::from(axis), radius)
            }
            _ => None,
        };
        let mut pt = self.motion_pt(line, p, rapid, false, None);
        pt.arc = arc.map(Box::new);
        if let Some(d) = self.tip.and_then(|t| (p - t).try_normalize(1e-12)) {
            self.last_dir = Some(d);
        }
        self.tip = Some(p);
        Some(pt)
    }

    /// The arc from `start` to `end` about `axis` through `center` (CL units in, profile units
    /// out), in the sense the CAM system meant (see `Record::Circle`).
    fn arc(&mut self, line: u32, start: Vec3, end: Vec3, center: Vec3, axis: Vec3, radius: Option<f64>) -> Option<ArcSpec> {
        let n = axis.norm();
        if n.is_nan() || n <= 1e-12 {
            return None;
        }
        // Turning clockwise about k is turning counter-clockwise about -k.
        let k = if self.circle_cw { -axis / n } else { axis / n };
        let (a, b) = (start - center, end - center);
        let (a_p, b_p) = (a - k * k.dot(&a), b - k * k.dot(&b));
        let r = radius.unwrap_or_else(|| a_p.norm());
        if r.is_nan() || r <= 1e-9 || a_p.norm() < 1e-9 {
            return None;
        }
        if (a_p.norm() - b_p.norm()).abs() > 1e-3 * r.max(1.0) {
            self.diag(
                Code::BadRecord,
                Severity::Warning,
                line,
                "CIRCLE: start and end are not on one circle about the centre: taken as a straight move".into(),
            );
            return None;
        }
        let mut sweep = k.dot(&a_p.cross(&b_p)).atan2(a_p.dot(&b_p));
        if sweep <= 1e-12 {
            sweep += std::f64::consts::TAU;
        }
        // A helix (NX's TIMES,n) passes the end's angle n times: n − 1 whole turns first.
        sweep += f64::from(self.circle_turns.saturating_sub(1)) * std::f64::consts::TAU;
        let (k, sweep) = match self.circle_sweep.take() {
            Some(want) => self.movarc_sense(line, k, sweep, want)?,
            None => (k, sweep),
        };
        // The plane's centre: where the start point projects onto the axis line.
        let c_plane = center + k * k.dot(&a);
        Some(ArcSpec {
            center: self.to_part_point(c_plane),
            normal: self.to_part(k),
            radius: a_p.norm() * self.scale,
            sweep,
        })
    }

    /// A cycle's R plane below the hole's top would rapid into the part: the safe side is the
    /// top itself, the feed starting there; an error at the CYCLE record.
    fn r_at_or_above_top(&mut self, mut c: CycleParams, line: u32) -> CycleParams {
        if c.rapid_to < 0.0 {
            self.diag(
                Code::BadRecord,
                Severity::Error,
                line,
                format!(
                    "CYCLE: RAPTO {} is below the hole's top: the tool would rapid into the part; written from the top",
                    c.rapid_to
                ),
            );
            c.rapid_to = 0.0;
            c.retract_to = c.retract_to.map(|r| r.max(0.0));
        }
        c
    }

    fn hole(&mut self, line: u32, p: Vec3, c: CycleParams) {
        // Along the tool axis, in the CL's frame (the points go into the part frame as pushed).
        let u = self.to_cl(self.axis);
        let clear = p + u * c.rapid_to;
        let saved = self.feed;
        if let Some((f, unit, units)) = c.feed {
            let s = units.map_or(self.scale, |x| x.factor_to(self.profile_units));
            self.feed = Some((f * s, unit));
        }
        if self.feed.is_none() {
            // A drill, let alone a tap, driven at rapid into the part breaks: not a program to
            // run. Written (G0 to depth) so that it can be read, and an error.
            self.diag(
                Code::NoFeed,
                Severity::Error,
                line,
                format!(
                    "{} cycle without a feed (no FEDRAT and none in the CYCLE record): its holes are {}",
                    c.kind.name(),
                    match c.kind.canned_only() {
                        true => "not machined",
                        false => "written at rapid to depth",
                    }
                ),
            );
        }
        // Rapid to the R plane, feed through the hole's point (the CL GOTO) to depth, rapid out.
        let rapid = self.feed.is_none();
        let retract = c.retract_to.unwrap_or(c.rapid_to);
        // A tap, or a bore that stops or orients the spindle, is only ever the control's cycle.
        if self.canned_cycles || c.kind.canned_only() {
            // Canned output: the cycle waits above the hole at the higher of R and the retract
            // height (G98's initial level), so the approach goes there first.
            let start = retract.max(c.rapid_to);
            let hole = Hole {
                kind: c.kind,
                depth: c.depth * self.scale,
                clear: c.rapid_to * self.scale,
                start: start * self.scale,
                peck: c.peck.map(|x| x * self.scale),
                dwell: c.dwell,
                shift: c.shift.map(|x| x * self.scale),
                feed: self.feed,
            };
            self.push(line, p + u * start, true, true, Some("CYCLE"));
            self.mark(HolePart::Start(hole));
            if start > c.rapid_to {
                self.push(line, clear, true, true, Some("CYCLE"));
                self.mark(HolePart::Rest);
            }
        } else {
            self.push(line, clear, true, true, Some("CYCLE"));
            self.mark(HolePart::Clear);
        }
        self.push(line, p, rapid, false, Some("CYCLE"));
        self.mark(HolePart::Top);
        if c.depth > 0.0 {
            self.push(line, p - u * c.depth, rapid, true, Some("CYCLE"));
            self.mark(HolePart::Rest);
        }
        // Expanded, the dwell at the bottom is a dwell (a canned hole's cycle has its own).
        if let Some(t) = c.dwell.filter(|t| *t > 0.0 && !self.canned_cycles && !c.kind.canned_only()) {
            let dwell = Dwell::Seconds(t);
            self.out.push_back(Item::Event(ProgEvent::Dwell { dwell, line }));
        }
        // A bore or ream comes out as it went in, at the feed: a rapid would mark the wall.
        let out_rapid = rapid || !matches!(c.kind, CycleKind::Bore);
        self.push(line, p + u * retract, out_rapid, true, Some("CYCLE"));
        self.mark(HolePart::Rest);
        self.feed = saved;
    }
}

/// A length in mm as the CL file states it (its own units).
fn fmt_len(mm: f64, u: Units) -> String {
    match u {
        Units::Mm => format!("{mm} mm"),
        Units::Inch => format!("{} in", mm / 25.4),
    }
}
