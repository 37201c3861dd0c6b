#![allow(clippy::needless_range_loop)] // X Y Z loops index several parallel arrays
//! The postprocessing engine: CL records → poses → planned joint moves → NC blocks with
//! diagnostics, pushed into a [`Sink`] (a file, an HTTP stream, a golden test are all sinks).
//!
//! Every block written is replayed through FK from the words as written (rounded) and compared
//! with the pose it was meant to reach: the summary carries the largest deviation, and a block
//! over tolerance is an error diagnostic.

mod plan;
pub mod preview;
mod source;
pub mod verify;

pub use source::{ArcSpec, Hole, HolePart, Item, MotionPt, ProgEvent, Source};

use crate::cl::{CoolantCmd, CycleKind, Dwell, FeedUnit, SpindleCmd};
use crate::diag::{Code, Diagnostic, Severity};
use crate::kinematics::{self, IkOptions, Joints, Machine, Pose, Setup, Solutions, Units, Vec3, angle_between, fk, ik_into};
use crate::nc::{Canned, CannedKind, Dialect, FeedMode, Formats, Formatter, Motion};
use plan::{Cand, Committed, Out, Planner, wrap};
use serde::Serialize;
use std::collections::{BTreeMap, VecDeque};
use std::io::BufRead;

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// No TCP on the controller: X Y Z are the machine's linear joints.
    Joint,
    /// The controller's tool-centre-point control: X Y Z are the tip in the part frame.
    Tcp,
}

#[derive(Clone, Debug)]
pub struct Options {
    pub mode: Mode,
    pub dialect: &'static Dialect,
    /// Profile units; overrides the CL file's and the profile's default.
    pub tool_length: Option<f64>,
    pub work_offset: Vec3,
    /// Chord tolerance (profile units): linearization, arcs, and the self-verification bound.
    pub tolerance: f64,
    pub sequence_numbers: bool,
    pub program_number: u32,
    pub strict: bool,
    pub cl_units: Option<Units>,
    /// Largest rotary change in one feed block before it is subdivided (radians).
    pub max_rotary_step: f64,
    /// Retract distance along the tool axis for unwinds and repositions (profile units).
    pub clearance: f64,
    /// Cone (radians) around a singular direction within which blocks are marked `singular`.
    pub singular_cone: f64,
    /// Orientation tolerance (radians) the free rotary may use near a singular direction: 0 is
    /// exact (the default); e.g. 0.5° for a ball-end tool holds the rotary still where the tool
    /// axis passes within that angle of the singular direction.
    pub singular_tolerance: f64,
    /// Per rotary (chain order): the words that lock and unlock it, if the machine clamps it.
    pub clamps: [Option<(String, String)>; 3],
    /// Header comment lines (source file name, date …) the caller wants in the program.
    pub header: Vec<String>,
    /// Drilling cycles (CL `CYCLE/`) as the control's canned cycles where the hole runs along
    /// the machine's Z (joint mode); else, and by default, expanded into moves.
    pub canned_cycles: bool,
    /// Fixed-axis (3+2) runs in a tilted working plane (G68.2, G254, CYCLE800, PLANE SPATIAL)
    /// with their motion in plane coordinates (joint mode); else, and by default, 5-axis
    /// positioning.
    pub tilted_planes: bool,
    /// The work coordinate system the program selects (`G54`…): its origin must be where the
    /// X Y Z words are measured from (joint mode: the profile's origin; TCP: the part's).
    /// `None`: the dialect's first (none on a control without one); `Some("none")`: the program
    /// selects none and runs in whatever the control has active.
    pub work_coordinates: Option<String>,
    /// Spindle speed (RPM, clockwise) for a tool whose CL starts none before its first move (NX's
    /// CLSF listings carry no SPINDL: its post takes the speed from the operation). `None`: the
    /// CL's own, and a cut with none is a `spindle_stopped` warning.
    pub spindle_speed: Option<f64>,
}

impl Options {
    pub fn new(m: &Machine) -> Options {
        let mm = m.units == Units::Mm;
        Options {
            mode: Mode::Joint,
            dialect: crate::nc::dialect(&m.controller).unwrap_or(&crate::nc::FANUC),
            tool_length: None,
            work_offset: Vec3::zeros(),
            tolerance: if mm { 0.01 } else { 0.0004 },
            sequence_numbers: false,
            program_number: 1000,
            strict: false,
            cl_units: None,
            max_rotary_step: 10f64.to_radians(),
            clearance: if mm { 50.0 } else { 2.0 },
            singular_cone: 2f64.to_radians(),
            singular_tolerance: 0.0,
            clamps: Default::default(),
            header: Vec::new(),
            canned_cycles: false,
            tilted_planes: false,
            work_coordinates: None,
            spindle_speed: None,
        }
    }

    /// The work coordinate word the program writes, if any.
    pub fn wcs_word(&self) -> Option<&str> {
        match self.work_coordinates.as_deref() {
            None => self.dialect.work_coordinates.first().copied(),
            Some("none") => None,
            Some(w) => Some(w),
        }
    }
}

/// Post settings as users give them (CLI flags, HTTP query or form fields): plain values,
/// validated once, here, into [`Options`].
#[derive(Clone, Debug, Default, Serialize, serde::Deserialize)]
pub struct Settings {
    /// Machine profile id (required over HTTP; the CLI has its own flag).
    pub machine: Option<String>,
    /// NC dialect; default: the profile's controller.
    pub dialect: Option<String>,
    /// `joint` (default) or `tcp`.
    pub mode: Option<String>,
    /// Tool length (gauge line to tip), profile units; default: the CL file's, else the profile's.
    pub tool_length: Option<f64>,
    /// Work offset `x,y,z` in profile units.
    pub work_offset: Option<String>,
    /// Chord tolerance in profile units (default 0.01 mm / 0.0004 in, at most 1 mm / 0.04 in):
    /// also the bound of the FK replay's tip check.
    pub tolerance: Option<f64>,
    pub sequence_numbers: Option<bool>,
    /// Program number (default 1000): 1 to 9999 on fanuc (`O` and four digits), 1 to 99999 on
    /// haas; any on the others, which name the program.
    pub program_number: Option<u32>,
    /// Stop at the first error instead of reporting it and going on.
    pub strict: Option<bool>,
    /// Degrees of orientation the free rotary may use near a singular direction (0: exact).
    pub singular_tolerance: Option<f64>,
    /// Units of the CL when the file does not say: `mm` or `inch`.
    pub cl_units: Option<String>,
    /// Drilling cycles: `expand` (default: moves) or `canned` (G81/G82/G83, CYCLE81–83, CYCL DEF
    /// 200 where the hole runs along the machine's Z).
    #[serde(default)]
    pub cycles: Option<String>,
    /// 3+2 work: `positioning` (default: 5-axis positioning, machine coordinates) or `tilted`
    /// (a tilted working plane per fixed-axis run, motion in plane coordinates; joint mode).
    #[serde(default)]
    pub planes: Option<String>,
    /// Work coordinate system the program selects: `G54` (default) to `G59` (Sinumerik: `G57`),
    /// or `none` (the control's active one). Its origin must be where the X Y Z words are measured
    /// from (joint mode: the profile's origin; TCP: the part's). A Heidenhain program selects none
    /// (the TNC's preset is chosen on the control).
    #[serde(default)]
    pub work_coordinates: Option<String>,
    /// Spindle speed (RPM, clockwise) for a tool the CL starts no spindle for before its first
    /// move (NX's CLSF listings carry no SPINDL); the CL's own SPINDL, and SPINDL/OFF, win.
    #[serde(default)]
    pub spindle_speed: Option<f64>,
}

impl Settings {
    /// Options for a loaded profile: [`Settings::options`] plus what the profile adds beyond
    /// its kinematics (rotary clamp words).
    pub fn profile_options(&self, p: &crate::machines::Profile) -> Result<Options, String> {
        let mut o = self.options(&p.machine)?;
        o.clamps = p.clamps();
        Ok(o)
    }

    /// Validated options for machine `m`; the error names the setting.
    pub fn options(&self, m: &Machine) -> Result<Options, String> {
        let mut o = Options::new(m);
        if let Some(d) = &self.dialect {
            o.dialect =
                crate::nc::dialect(d).ok_or_else(|| format!("dialect {d:?}: known dialects are {:?}", crate::nc::DIALECTS))?;
        }
        o.mode = match self.mode.as_deref() {
            None | Some("joint") => Mode::Joint,
            Some("tcp") => Mode::Tcp,
            Some(x) => return Err(format!("mode {x:?}: expected joint or tcp")),
        };
        if let Some(l) = self.tool_length {
            if !(l >= 0.0 && crate::kinematics::coordinate_ok(l)) {
                return Err(format!(
                    "tool_length must be a length from 0 to {:e}",
                    crate::kinematics::MAX_COORD
                ));
            }
            o.tool_length = Some(l);
        }
        if let Some(w) = &self.work_offset {
            o.work_offset = crate::cli::parse_triple(w).map_err(|e| format!("work_offset: {e}"))?;
        }
        if let Some(t) = self.tolerance {
            // It is also the FK replay's bound: a huge one would switch the self-verification off.
            let (max, unit) = if m.units == Units::Mm { (1.0, "mm") } else { (0.04, "in") };
            if !(t.is_finite() && t > 0.0 && t <= max) {
                return Err(format!("tolerance must be a positive number up to {max} {unit}"));
            }
            o.tolerance = t;
        }
        o.sequence_numbers = self.sequence_numbers.unwrap_or(false);
        o.program_number = self.program_number.unwrap_or(1000);
        let numbers = o.dialect.program_numbers();
        if !numbers.contains(&o.program_number) {
            return Err(format!(
                "program_number {}: {} takes {} to {}",
                o.program_number,
                o.dialect.name,
                numbers.start(),
                numbers.end()
            ));
        }
        o.strict = self.strict.unwrap_or(false);
        if let Some(t) = self.singular_tolerance {
            if !(t.is_finite() && (0.0..=10.0).contains(&t)) {
                return Err("singular_tolerance must be between 0 and 10 degrees".into());
            }
            o.singular_tolerance = t.to_radians();
        }
        o.cl_units = match self.cl_units.as_deref() {
            None => None,
            Some("mm") => Some(Units::Mm),
            Some("inch") => Some(Units::Inch),
            Some(u) => return Err(format!("cl_units {u:?}: expected mm or inch")),
        };
        o.canned_cycles = match self.cycles.as_deref() {
            None | Some("expand") => false,
            Some("canned") => true,
            Some(x) => return Err(format!("cycles {x:?}: expected expand or canned")),
        };
        o.tilted_planes = match self.planes.as_deref() {
            None | Some("positioning") => false,
            Some("tilted") => true,
            Some(x) => return Err(format!("planes {x:?}: expected positioning or tilted")),
        };
        if let Some(w) = self.work_coordinates.as_deref().map(str::trim).filter(|w| !w.is_empty()) {
            let known = o.dialect.work_coordinates;
            let w = w.to_ascii_uppercase();
            if w == "NONE" {
                o.work_coordinates = Some("none".into());
            } else if known.contains(&w.as_str()) {
                o.work_coordinates = Some(w);
            } else if known.is_empty() {
                return Err(format!(
                    "work_coordinates {w:?}: {} selects none (its datum is the control's preset); expected none",
                    o.dialect.name
                ));
            } else {
                return Err(format!(
                    "work_coordinates {w:?}: {} takes {} or none",
                    o.dialect.name,
                    known.join(", ")
                ));
            }
        }
        if let Some(s) = self.spindle_speed {
            if !(s.is_finite() && (1.0..=MAX_SPINDLE_SPEED).contains(&s)) {
                return Err(format!("spindle_speed must be from 1 to {MAX_SPINDLE_SPEED} RPM"));
            }
            o.spindle_speed = Some(s);
        }
        Ok(o)
    }
}

/// The largest `spindle_speed` taken: above any machining spindle (a typo's extra digit fails).
pub const MAX_SPINDLE_SPEED: f64 = 200_000.0;

/// What a sink is told about a motion block, beside its text.
#[derive(Clone, Debug, Serialize)]
pub struct BlockInfo {
    /// 1-based index of the motion block in the program.
    pub n: u64,
    pub source_line: Option<u32>,
    /// Axis words as written (X Y Z A B C; profile units, degrees), as a JSON map of the present.
    pub joints: AxisWords,
    pub diagnostics: Vec<Diagnostic>,
    pub rapid: bool,
    /// The pose this block reaches, in the part frame (profile units): what a preview draws.
    pub tip: [f64; 3],
    pub axis: [f64; 3],
    /// Estimated duration of this block, seconds (the cycle-time estimate's share).
    pub time_s: f64,
}

/// X Y Z A B C values of a block, `None` where the block has no such word. A fixed array: one
/// is built per block, so no allocation.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct AxisWords(pub [Option<f64>; 6]);

impl Serialize for AxisWords {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeMap;
        let mut m = s.serialize_map(Some(self.0.iter().flatten().count()))?;
        for (k, v) in self.0.iter().enumerate() {
            if let Some(v) = v {
                m.serialize_entry(&crate::nc::AXIS_LETTERS[k], v)?;
            }
        }
        m.end()
    }
}

/// Where the program goes. The NC file, the NDJSON stream and a golden test are all sinks.
pub trait Sink {
    fn line(&mut self, text: &str, block: Option<&BlockInfo>) -> std::io::Result<()>;
    /// A diagnostic not attached to a block (reader problems, program-level notes).
    fn diagnostic(&mut self, _d: &Diagnostic) -> std::io::Result<()> {
        Ok(())
    }
    /// A diagnostic about a CL pose (part frame, profile units) that got no block.
    fn diagnostic_at(&mut self, d: &Diagnostic, _pose: &Pose) -> std::io::Result<()> {
        self.diagnostic(d)
    }
    fn summary(&mut self, _s: &Summary) -> std::io::Result<()> {
        Ok(())
    }
}

/// NC text to any writer, one line each.
pub struct TextSink<W: std::io::Write>(pub W);

impl<W: std::io::Write> Sink for TextSink<W> {
    fn line(&mut self, text: &str, _b: Option<&BlockInfo>) -> std::io::Result<()> {
        self.0.write_all(text.as_bytes())?;
        self.0.write_all(b"\n")
    }
}

/// NC text into one writer and, optionally, one NDJSON line per block, diagnostic and summary
/// into another: the CLI's `--output`/`--diagnostics` and a job's spool files are this sink.
pub struct FileSink<W: std::io::Write, D: std::io::Write> {
    pub nc: std::io::BufWriter<W>,
    pub nd: Option<std::io::BufWriter<D>>,
    /// Print warnings and errors to stderr as they come (the CLI does; a job does not).
    pub echo_warnings: bool,
}

impl<W: std::io::Write, D: std::io::Write> FileSink<W, D> {
    pub fn new(nc: W, nd: Option<D>) -> Self {
        FileSink {
            nc: std::io::BufWriter::with_capacity(1 << 16, nc),
            nd: nd.map(|d| std::io::BufWriter::with_capacity(1 << 16, d)),
            echo_warnings: false,
        }
    }

    pub fn flush(&mut self) -> std::io::Result<()> {
        use std::io::Write;
        self.nc.flush()?;
        if let Some(nd) = self.nd.as_mut() {
            nd.flush()?;
        }
        Ok(())
    }

    /// Unwraps the writers, flushed (so the caller can fsync them).
    pub fn into_inner(self) -> std::io::Result<(W, Option<D>)> {
        let nc = self.nc.into_inner().map_err(|e| e.into_error())?;
        let nd = self.nd.map(|w| w.into_inner().map_err(|e| e.into_error())).transpose()?;
        Ok((nc, nd))
    }

    /// One line of the NDJSON (nothing without it).
    pub fn json(&mut self, v: &serde_json::Value) -> std::io::Result<()> {
        use std::io::Write;
        if let Some(nd) = self.nd.as_mut() {
            serde_json::to_writer(&mut *nd, v)?;
            nd.write_all(b"\n")?;
        }
        Ok(())
    }
}

impl<W: std::io::Write, D: std::io::Write> Sink for FileSink<W, D> {
    fn line(&mut self, text: &str, b: Option<&BlockInfo>) -> std::io::Result<()> {
        use std::io::Write;
        self.nc.write_all(text.as_bytes())?;
        self.nc.write_all(b"\n")?;
        if let (true, Some(b)) = (self.nd.is_some(), b) {
            self.json(
                &serde_json::json!({"type": "block", "n": b.n, "nc": text, "source_line": b.source_line,
                "joints": b.joints, "diagnostics": b.diagnostics}),
            )?;
        }
        Ok(())
    }
    fn diagnostic(&mut self, d: &Diagnostic) -> std::io::Result<()> {
        self.json(&serde_json::json!({"type": "diagnostic", "diagnostic": d}))?;
        if self.echo_warnings && d.severity >= crate::diag::Severity::Warning {
            eprintln!("kinepost: {d}");
        }
        Ok(())
    }
    fn summary(&mut self, s: &Summary) -> std::io::Result<()> {
        self.json(&serde_json::json!({"type": "summary", "summary": s}))
    }
}

/// Per-axis figures of the summary.
#[derive(Clone, Debug, Default, Serialize)]
pub struct AxisStats {
    pub min: f64,
    pub max: f64,
    /// Rotary axes: total travel in degrees.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub travel: Option<f64>,
    /// Rotary axes: largest change in one feed block, and the CL line of that block.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub largest_step: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub largest_step_line: Option<u32>,
}

#[derive(Clone, Debug, Default, Serialize)]
pub struct Summary {
    pub machine: String,
    pub mode: Option<Mode>,
    pub units: String,
    pub cl_units: String,
    pub cl_units_source: String,
    pub tool_length: f64,
    pub cl_points: u64,
    pub blocks: u64,
    pub inserted_blocks: u64,
    pub counts: BTreeMap<String, u64>,
    pub axes: BTreeMap<char, AxisStats>,
    pub cycle_time_s: f64,
    /// FK replay of every written block against the pose it was meant to reach.
    pub max_tip_deviation: f64,
    pub max_axis_deviation_deg: f64,
    /// Largest angle between an inserted block's tool axis and the CL orientation, where a
    /// segment passing near a singular direction is followed in joint space (as the control
    /// would between the CL points) instead of swinging the free rotary.
    pub max_singular_deviation_deg: f64,
    /// With a singular tolerance: blocks whose free rotary was held, the rotary travel that saved,
    /// and the largest orientation deviation it used.
    pub smoothed_blocks: u64,
    pub smoothing_travel_saved_deg: f64,
    pub smoothing_max_deviation_deg: f64,
    /// Holes written as canned cycles (with `cycles=canned`).
    pub canned_holes: u64,
    /// Tilted working planes written (with `planes=tilted`).
    pub tilted_planes: u64,
    pub errors: u64,
    pub warnings: u64,
}

#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error(transparent)]
    Read(#[from] source::Error),
    #[error("writing output: {0}")]
    Io(#[from] std::io::Error),
    /// Strict mode: the first error diagnostic ends the run.
    #[error("{0}")]
    Strict(Diagnostic),
}

/// The last block written: where the machine is.
#[derive(Clone, Copy, Debug)]
struct At {
    joints: Joints,
    actual: [f64; 3],
    pose: Pose,
    branch: i8,
    /// The rotary whose angle is free here (the tool axis along the singular direction): any
    /// angle of it holds this pose, with other linears. A byte: `At` stays 128 bytes, copied
    /// inline (a word more made every block's copies `memcpy` calls, +3.7 % instructions).
    free: Option<u8>,
}

struct Emitter<'a, S: Sink + ?Sized> {
    m: &'a Machine,
    o: &'a Options,
    sink: &'a mut S,
    f: Formatter,
    setup: Setup,
    at: Option<At>,
    /// A tool change since the last block: the machine is not at `at` any more.
    tool_changed: bool,
    /// Halvings left to the CL segment being linearized (see [`MAX_SEGMENT_SPLITS`]).
    split_budget: u32,
    /// The CL line of the last point outside travel: blocks inserted for it say nothing more.
    outside_line: Option<u32>,
    /// Retracts [`Emitter::lifted`] shortened to stay within travel, told on the next block.
    lift_notes: Vec<Diagnostic>,
    split_told: bool,
    /// Tip moves shorter than this (half the X Y Z words' last digit) are a standing tip.
    standing: f64,
    /// The CL line of the last block written (a retract at a tool change or the end has none).
    last_line: u32,
    /// The tool length the program last said it is cut for (a comment).
    length_said: Option<f64>,
    tool: Option<u32>,
    /// The tool's length offset register where the CL names one other than its number.
    adjust: Option<u32>,
    comp_on: bool,
    rpm: Option<f64>,
    blocks: u64,
    sum: Summary,
    buf: Solutions,
    strict_error: Option<Diagnostic>,
    warned_no_tool: bool,
    warned_per_rev: bool,
    /// The spindle as the NC leaves it: turning (and which way), to be restarted before the next
    /// motion (a tool change stopped it and the CL did not say SPINDL again: APT's spindle is
    /// modal, M6 stops it on every control), and whether a cut with it standing was told.
    spindle_on: bool,
    spindle_cw: bool,
    spindle_restore: Option<u32>,
    warned_spindle: bool,
    /// The CL said SPINDL/OFF since the last tool change: `Options::spindle_speed` starts nothing.
    spindle_said_off: bool,
    /// The coolant word the CL has on (APT's COOLNT is modal too), and the tool change that
    /// turned it off (M9 before M6: coolant, through-spindle above all, sprays into an open
    /// spindle and the changer) until the next tool's first move turns it on again.
    coolant: Option<&'static str>,
    coolant_restore: Option<u32>,
    /// Coolant the CL turned on before its first tool and first move (CATIA writes COOLNT/ON
    /// before LOADTL): written at the first move, not before a tool change that turns it off.
    coolant_deferred: bool,
    /// Which clamped rotaries are locked now (a clamped axis is taken as locked at the start).
    locked: [bool; 3],
    /// Set for the next block: an arc (G3 when true) with its centre words, and its length
    /// (the time at F: a full circle's chord is none).
    arc_words: Option<(bool, String, f64)>,
    /// The active circular-interpolation plane word (G17/G18/G19).
    plane: &'static str,
    /// Outer-rotary travel of the exact solutions and of what was written, at CL points: what
    /// the singular tolerance saved, honestly (a held block's saving is partly paid back later).
    exact_prev: Option<f64>,
    exact_travel: f64,
    held_prev: Option<f64>,
    held_travel: f64,
    /// The canned cycle the control has on (until cancelled), and whether the points of the
    /// hole it just drilled are still arriving (they were written as the cycle).
    cycle_on: Option<Canned>,
    in_hole: bool,
    /// Why holes were written as moves, or 3+2 as positioning: each said once.
    said_once: Vec<&'static str>,
    /// The tilted working plane in force, if any.
    tilt: Option<Tilt>,
    /// The point being written is a rapid whose fixed tool axis holds, in the look-ahead, until
    /// the next rapid with another axis (or a tool change, or the end): a plane may start there.
    plane_ahead: bool,
    /// For a singular point: the free rotary's word (the planner's winding) where the cut after it
    /// fixes it.
    free_hint: Option<f64>,
    /// Per axis letter (X Y Z A B C): extents and travel, moved into the summary at the end.
    stats: [Option<AxisStats>; 6],
    /// cos of the singular cone and the singular direction, once (they are checked per block).
    singular: Option<(Vec3, f64)>,
    /// What the linearization bound's lever adds to the tip's distance, less the tool length
    /// (work offset and pivots), and whether angle-error compensation rules the bound out: both
    /// fixed for the run, and the bound is taken for every block.
    lever_base: f64,
    compensated: bool,
    /// Squares of the tip miss and of the axis miss's tangent below which a block's replay is
    /// neither a new largest miss nor an error (kept by `replayed`).
    quiet_tip2: f64,
    quiet_tan2: f64,
}

/// Axis miss (degrees) of an FK replay that is an error.
const REPLAY_AXIS_DEG: f64 = 0.01;

/// A tilted working plane in force: the rotary words it stands on (radians), its frame as the
/// control builds it from the words written, and the CL tool axis of its run.
#[derive(Clone, Copy, Debug)]
struct Tilt {
    rotary: [f64; 3],
    frame: nalgebra::Matrix3<f64>,
    axis: Vec3,
}

/// The free rotary's angle at the first point ahead of a singular one that fixes it, within the
/// cut (up to a rapid, a tool change or the end, and [`LOOK_AHEAD`] items): what a machine that
/// positions onto the singular point turns to, instead of turning it during the cut that follows.
fn free_angle_ahead(free: usize, ahead: &VecDeque<Out>) -> Option<f64> {
    ahead.iter().take(LOOK_AHEAD).find_map(|o| free_angle_at(o, free)).flatten()
}

/// What `o` says of the free angle (rotary `free`) of a singular point before it: `Some(Some(a))`
/// a point that fixes it at `a`, `Some(None)` the cut ends first (a rapid, a tool change, the
/// end), `None` nothing yet.
fn free_angle_at(o: &Out, free: usize) -> Option<Option<f64>> {
    match o {
        Out::Event(ev) => matches!(ev, ProgEvent::Tool { .. } | ProgEvent::End).then_some(None),
        Out::Point(c) if c.pt.rapid => Some(None),
        // The planner's word: a bounded table's winding is there, not in the IK's angle.
        Out::Point(c) => match &c.cand {
            Some(k) if k.sol.singular.is_none() => Some(Some(k.sol.joints.rotary[free])),
            _ => None,
        },
    }
}

/// Items held back for the tilted-plane look-ahead (about one planner commit).
const LOOK_AHEAD: usize = 256;
/// Tool axes closer than this (radians) are the same fixed axis.
const PLANE_AXIS_EPS: f64 = 1e-9;

/// Whether the run of points after a rapid keeps `axis` until a rapid with another axis, a tool
/// change or the end, as far as the next [`LOOK_AHEAD`] items show (beyond them, the run is taken
/// as fixed: a later cut that turns the axis is repositioned out of the plane). Exactly that far,
/// however much the planner happened to commit at once, so that the output does not depend on it.
fn fixed_run_ahead(axis: &Vec3, ahead: &VecDeque<Out>) -> bool {
    for o in ahead.iter().take(LOOK_AHEAD) {
        match o {
            Out::Event(ProgEvent::Tool { .. } | ProgEvent::End) => return true,
            Out::Event(_) => {}
            Out::Point(c) => {
                if angle_between(axis, &c.pt.pose.axis) > PLANE_AXIS_EPS {
                    return c.pt.rapid;
                }
            }
        }
    }
    true
}

/// Hands what the planner committed to the emitter: at once, or with tilted planes through the
/// look-ahead queue (see [`Emitter::drain`]). The first error stops the rest.
fn deliver<S: Sink + ?Sized>(e: &mut Emitter<'_, S>, pending: &mut VecDeque<Out>, failed: &mut Option<Error>, x: Out) {
    if failed.is_some() {
        return;
    }
    if e.o.tilted_planes {
        pending.push_back(x);
        return;
    }
    // A singular point the machine positions onto waits for the point that fixes its free
    // rotary (see `free_angle_ahead`); everything else goes straight through.
    if pending.is_empty() && !e.positions_onto_singular(&x) {
        if let Err(err) = e.take(x, pending) {
            *failed = Some(err);
        }
        return;
    }
    // Whatever the free rotary's index, the same items settle it.
    let resolves = free_angle_at(&x, 0).is_some();
    pending.push_back(x);
    if resolves || pending.len() > LOOK_AHEAD {
        while let Some(o) = pending.pop_front() {
            if let Err(err) = e.take(o, pending) {
                *failed = Some(err);
                return;
            }
        }
    }
}

/// Post-processes CL from `input` for machine `m` into `sink`.
pub fn post<R: BufRead, S: Sink + ?Sized>(input: R, m: &Machine, o: &Options, sink: &mut S) -> Result<Summary, Error> {
    let mut src = Source::new(input, m.units, o.cl_units, o.strict)?;
    src.canned_cycles = o.canned_cycles;
    let setup = Setup::new(o.tool_length.unwrap_or(m.default_tool_length), o.work_offset);
    let formats = Formats::for_units(m.units);
    let mut e = Emitter {
        m,
        o,
        sink,
        f: Formatter::new(o.dialect, formats, o.sequence_numbers),
        setup,
        at: None,
        tool_changed: false,
        split_budget: 0,
        outside_line: None,
        lift_notes: Vec::new(),
        split_told: false,
        last_line: 0,
        standing: formats.half_linear(),
        tool: None,
        adjust: None,
        comp_on: false,
        rpm: None,
        blocks: 0,
        sum: Summary {
            machine: m.id.clone(),
            mode: Some(o.mode),
            units: m.units.as_str().into(),
            cl_units: src.cl_units.as_str().into(),
            cl_units_source: src.units_source.into(),
            tool_length: setup.tool_length,
            ..Default::default()
        },
        buf: Solutions::new(),
        strict_error: None,
        warned_no_tool: false,
        warned_per_rev: false,
        spindle_on: false,
        spindle_cw: true,
        spindle_restore: None,
        warned_spindle: false,
        spindle_said_off: false,
        coolant: None,
        coolant_restore: None,
        coolant_deferred: false,
        arc_words: None,
        locked: [true; 3],
        plane: "G17",
        exact_prev: None,
        exact_travel: 0.0,
        held_prev: None,
        held_travel: 0.0,
        cycle_on: None,
        in_hole: false,
        said_once: Vec::new(),
        tilt: None,
        plane_ahead: false,
        free_hint: None,
        length_said: None,
        stats: Default::default(),
        singular: kinematics::singular_direction(m).map(|d| (d.normalize(), o.singular_cone.cos())),
        lever_base: setup.work_offset.norm() + m.rotaries.iter().map(|r| r.pivot.norm()).sum::<f64>(),
        compensated: m.has_angle_error(),
        quiet_tip2: 0.0,
        quiet_tan2: 0.0,
    };
    e.program_start()?;
    let mut planner = Planner::new(m, setup);
    let mut pending: VecDeque<Out> = VecDeque::new();
    let mut failed: Option<Error> = None;
    loop {
        let item = src.next_item()?;
        let Some(item) = item else { break };
        match item {
            Item::Motion(pt) => planner.push_point(pt, &mut |x| deliver(&mut e, &mut pending, &mut failed, x)),
            Item::Event(ProgEvent::ToolLength(l)) if o.tool_length.is_none() => {
                // The tool length governs IK: it cannot wait in the window.
                planner.finish(&mut |x| deliver(&mut e, &mut pending, &mut failed, x));
                e.drain(&mut pending, true)?;
                planner.setup.tool_length = l;
                e.cl_tool_length(l)?;
            }
            Item::Event(ev) => planner.push_event(ev, &mut |x| deliver(&mut e, &mut pending, &mut failed, x)),
        }
        if let Some(err) = failed.take() {
            return Err(err);
        }
        e.drain(&mut pending, false)?;
        if let Some(d) = e.strict_error.take().or_else(|| src.strict_error.take()) {
            return Err(Error::Strict(d));
        }
    }
    if let Some(d) = src.strict_error.take() {
        return Err(Error::Strict(d));
    }
    planner.finish(&mut |x| deliver(&mut e, &mut pending, &mut failed, x));
    if let Some(err) = failed.take() {
        return Err(err);
    }
    e.drain(&mut pending, true)?;
    if let Some(d) = e.strict_error.take() {
        return Err(Error::Strict(d));
    }
    if e.sum.cl_points == 0 {
        // An empty program that ends well is easily taken for a posted part (a wrong file
        // uploaded, a CL dialect not read): say it.
        e.note(Diagnostic::new(
            Code::NoMotion,
            Severity::Warning,
            None,
            "no motion in the CL input (no GOTO, GODLTA or FROM was read): the program moves nothing",
        ))?;
    }
    e.program_end()?;
    for (k, st) in e.stats.iter().enumerate() {
        if let Some(st) = st {
            e.sum.axes.insert(crate::nc::AXIS_LETTERS[k], st.clone());
        }
    }
    let sum = e.sum.clone();
    e.sink.summary(&sum)?;
    Ok(sum)
}

impl<S: Sink + ?Sized> Emitter<'_, S> {
    fn out(&mut self, text: &str) -> std::io::Result<()> {
        self.sink.line(text, None)
    }

    fn note(&mut self, d: Diagnostic) -> std::io::Result<()> {
        self.count(&d);
        self.sink.diagnostic(&d)
    }

    /// A diagnostic about a CL pose that got no block (unreachable): where it is, for a preview.
    fn note_at(&mut self, d: Diagnostic, pose: &Pose) -> std::io::Result<()> {
        self.count(&d);
        self.sink.diagnostic_at(&d, pose)
    }

    fn count(&mut self, d: &Diagnostic) {
        *self.sum.counts.entry(d.code.as_str().to_string()).or_default() += 1;
        match d.severity {
            Severity::Error => {
                self.sum.errors += 1;
                if self.o.strict && self.strict_error.is_none() {
                    self.strict_error = Some(d.clone());
                }
            }
            Severity::Warning => self.sum.warnings += 1,
            Severity::Info => {}
        }
    }

    fn program_start(&mut self) -> std::io::Result<()> {
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
                if self.o.tool_length.is_some() {
                    ""
                } else {
                    " UNTIL THE CL SETS ONE"
                },
                self.o.tolerance
            ),
        ];
        let wo = self.o.work_offset;
        if wo != Vec3::zeros() {
            lines.push(format!("WORK OFFSET {},{},{}", wo.x, wo.y, wo.z));
        }
        if let Some(s) = self.o.spindle_speed {
            lines.push(format!("SPINDLE S{} WHERE THE CL STARTS NONE", s.round()));
        }
        lines.extend(self.o.header.iter().cloned());
        for l in self.f.header(self.o.program_number, self.m.units, &lines, self.o.wcs_word()) {
            self.out(&l)?;
        }
        Ok(())
    }

    /// The CL sets the tool length (the job fixed none): the NC from here on is cut for it, so
    /// the program says so where it takes effect (the header only knew the profile's).
    fn cl_tool_length(&mut self, l: f64) -> std::io::Result<()> {
        self.setup.tool_length = l;
        self.sum.tool_length = l;
        // When it changes: NX repeats TLDATA with every operation (before its LOAD/TOOL).
        if self.length_said == Some(l) {
            return Ok(());
        }
        self.length_said = Some(l);
        let c = self
            .f
            .comment(&format!("TOOL LENGTH {l:.*} FROM THE CL", self.f.fmt.linear as usize))
            .to_string();
        self.out(&c)
    }

    fn program_end(&mut self) -> Result<(), Error> {
        self.cancel_cycle()?;
        self.leave_plane(false)?;
        self.retract_up()?;
        self.lock_all()?;
        // TCP: X Y Z are the tip, and the retract above went the clearance along the tool axis;
        // machine Z home takes the spindle clear of the part whatever comes next.
        let z_up = self.o.mode == Mode::Tcp && self.at.is_some();
        for l in self.f.footer(z_up) {
            self.out(&l)?;
        }
        Ok(())
    }

    /// Writes what the planner committed, keeping [`LOOK_AHEAD`] items back (until `all`) when
    /// tilted planes are on: whether a fixed-axis run ends at a rapid is decided from them.
    fn drain(&mut self, pending: &mut VecDeque<Out>, all: bool) -> Result<(), Error> {
        // Without tilted planes only a held singular point waits here (`deliver` releases it).
        if !all && !self.o.tilted_planes {
            return Ok(());
        }
        let keep = if all || !self.o.tilted_planes { 0 } else { LOOK_AHEAD };
        while pending.len() > keep {
            let Some(o) = pending.pop_front() else { break };
            self.take(o, pending)?;
        }
        Ok(())
    }

    /// A committed singular point that the machine reaches by positioning (the first move, after
    /// a tool change, a rapid): its free rotary is best taken from the cut that follows.
    fn positions_onto_singular(&self, x: &Out) -> bool {
        match x {
            Out::Point(c) => c.cand.as_ref().is_some_and(|k| k.sol.singular.is_some()) && self.positioning(&c.pt),
            Out::Event(_) => false,
        }
    }

    /// The machine reaches `pt` by positioning, not by cutting: the first move, the first after
    /// a tool change, a rapid.
    fn positioning(&self, pt: &MotionPt) -> bool {
        self.at.is_none() || self.tool_changed || pt.rapid
    }

    /// One committed item, with what is known to follow it (the tilted-plane look-ahead).
    fn take(&mut self, o: Out, ahead: &VecDeque<Out>) -> Result<(), Error> {
        match o {
            Out::Event(ev) => self.event(ev),
            Out::Point(c) => {
                self.plane_ahead = c.pt.rapid && self.o.tilted_planes && fixed_run_ahead(&c.pt.pose.axis, ahead);
                self.free_hint = c
                    .cand
                    .as_ref()
                    .and_then(|k| k.sol.singular)
                    .and_then(|free| free_angle_ahead(free, ahead));
                self.point(c)
            }
        }
    }

    fn event(&mut self, ev: ProgEvent) -> Result<(), Error> {
        let d = self.o.dialect;
        if !matches!(
            ev,
            ProgEvent::Comment(_) | ProgEvent::Operation(_) | ProgEvent::Diag(_) | ProgEvent::End
        ) {
            self.cancel_cycle()?;
        }
        match ev {
            ProgEvent::Tool { number, adjust, line } => {
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
                self.leave_plane(false)?;
                self.retract_up()?;
                if self.comp_on {
                    if let Some(l) = self.f.line(d.tcp_off, number, 0) {
                        self.out(&l)?;
                    }
                    self.comp_on = false;
                    // TCP: the retract went the clearance along the tool axis (see `program_end`).
                    if self.o.mode == Mode::Tcp
                        && let Some(l) = self.f.line(d.machine_z_up, number, 0)
                    {
                        self.out(&l)?;
                    }
                }
                if self.coolant.is_some()
                    && self.coolant_restore.is_none()
                    && !self.coolant_deferred
                    && let Some(l) = self.f.line(d.coolant_off, number, 0)
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
                for t in d.tool_change {
                    if let Some(l) = self.f.line(t, number, 0) {
                        self.out(&l)?;
                    }
                }
                self.f.reset_modal();
                self.tool = Some(number);
                self.adjust = adjust;
                self.tool_changed = true;
                if std::mem::take(&mut self.spindle_on) {
                    self.spindle_restore = Some(line);
                }
                self.spindle_said_off = false;
            }
            ProgEvent::ToolLength(l) => {
                // Only when the job fixed the length (else `cl_tool_length`, before planning).
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
            ProgEvent::Spindle(c) => {
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
                self.spindle_said_off = speed.is_none();
                match speed {
                    Some(v) => self.spindle_start(v, cw)?,
                    None => {
                        if let Some(l) = self.f.line(d.spindle_off, self.tool.unwrap_or(1), 0) {
                            self.out(&l)?;
                        }
                        self.spindle_on = false;
                    }
                }
            }
            ProgEvent::Coolant(c) => {
                let w = match c {
                    CoolantCmd::Flood => d.coolant_flood,
                    CoolantCmd::Mist => d.coolant_mist,
                    CoolantCmd::Through => d.coolant_through,
                    CoolantCmd::Off => d.coolant_off,
                };
                let on = c != CoolantCmd::Off;
                // Nothing to cool before the first tool and move, and M6 would only stop it.
                let early = self.tool.is_none() && self.at.is_none();
                if !(early && (on || self.coolant_deferred))
                    && let Some(l) = self.f.line(w, 0, 0)
                {
                    self.out(&l)?;
                }
                self.coolant = on.then_some(w);
                self.coolant_restore = None;
                self.coolant_deferred = early && on;
            }
            ProgEvent::Comment(t) => {
                let c = self.f.comment(&t).to_string();
                self.out(&c)?;
            }
            ProgEvent::Operation(name) => {
                let c = self.f.comment(&format!("OPERATION {name}")).to_string();
                self.out(&c)?;
            }
            ProgEvent::Dwell { dwell, line } => {
                // Revolutions at the speed in force; with no speed to turn them into time the
                // dwell cannot be written as the CL meant it.
                let secs = match dwell {
                    Dwell::Seconds(t) => Ok(t),
                    Dwell::Revolutions(n) => self.rpm.filter(|_| self.spindle_on).map(|rpm| n * 60.0 / rpm).ok_or(n),
                };
                match secs {
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
            }
            ProgEvent::Diag(dg) => self.note(dg)?,
            ProgEvent::End => {}
        }
        Ok(())
    }

    /// S and M3/M4 (TNC: a speed-only TOOL CALL, then the direction alone).
    fn spindle_start(&mut self, speed: f64, cw: bool) -> std::io::Result<()> {
        let d = self.o.dialect;
        let (t, s) = (self.tool.unwrap_or(1), speed.round() as i64);
        let dir = if cw { d.spindle_cw } else { d.spindle_ccw };
        if d.style == crate::nc::Style::Conversational {
            for w in [d.spindle, dir] {
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
    fn spindle_standing(&mut self, line: u32) -> Option<Diagnostic> {
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
    fn ensure_comp(&mut self, line: u32) -> std::io::Result<()> {
        if self.comp_on {
            return Ok(());
        }
        if let Some(line) = self.spindle_restore.take()
            && let Some(v) = self.rpm
        {
            self.note(Diagnostic::new(
                Code::SpindleStopped,
                Severity::Info,
                Some(line),
                format!(
                    "the tool change stopped the spindle and the CL did not start it again: S{} restarted",
                    v.round()
                ),
            ))?;
            self.spindle_start(v, self.spindle_cw)?;
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
            && let Some(w) = self.coolant
            && let Some(l) = self.f.line(w, 0, 0)
        {
            self.out(&l)?;
        }
        if let Some(line) = self.coolant_restore.take()
            && let Some(w) = self.coolant
            && let Some(l) = self.f.line(w, 0, 0)
        {
            self.note(Diagnostic::new(
                Code::CoolantRestored,
                Severity::Info,
                Some(line),
                format!("coolant off for the tool change and the CL did not turn it on again: {l} restarted"),
            ))?;
            self.out(&l)?;
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
        let d = self.o.dialect;
        let w = match self.o.mode {
            Mode::Joint => d.length_comp,
            Mode::Tcp => d.tcp_on,
        };
        // The H word: the register the CL named, else the tool's own.
        if let Some(l) = self.f.line(w, self.adjust.unwrap_or(t), 0) {
            self.out(&l)?;
        }
        self.comp_on = true;
        Ok(())
    }

    /// The chosen candidate with its unbounded windings and singular free angle resolved against
    /// where the machine is.
    fn resolve(&mut self, pose: &Pose, cand: &Cand, positioning: bool) -> Option<(Joints, [f64; 3], i8, Option<u8>)> {
        let mut sol = cand.sol;
        if let Some(free) = sol.singular {
            let prev = self.at.map_or(0.0, |a| a.actual[free]);
            // Positioning onto a singular point (the first move, after a tool change or a rapid)
            // turns the free rotary to where the cut after it needs it: held at the old angle,
            // it turned during that cut, the tool axis off the CL orientation by up to 11° (a
            // cut from vertical to a 30° tilt on spinner-u5-620).
            let r = &self.m.rotaries[free];
            let prev = match self.free_hint.map(|w| r.actual(w)) {
                Some(h) if positioning => {
                    if r.limits.is_some() {
                        h
                    } else {
                        prev + wrap(h - prev)
                    }
                }
                _ => prev,
            };
            let opt = IkOptions {
                free_angle: prev,
                ..Default::default()
            };
            // The planned root: a chain missing a linear has several singular ones (C a half
            // turn apart), and the first of them, with the planner's A and B windings copied in,
            // put the tool 180° off the pose (propeller-3r2l).
            if ik_into(self.m, pose, &self.setup, &opt, &mut self.buf).is_ok()
                && let Some(s) = nearest_singular(&self.buf, free, &cand.sol.actual)
            {
                sol = s;
            }
            // The bounded windings the planner chose stay as chosen.
            for (i, r) in self.m.rotaries.iter().enumerate() {
                if i != free && r.limits.is_some() {
                    sol.joints.rotary[i] = cand.sol.joints.rotary[i];
                }
            }
        }
        let mut joints = sol.joints;
        let mut actual = sol.actual;
        if let Some(at) = self.at {
            for (i, r) in self.m.rotaries.iter().enumerate() {
                if r.limits.is_none() && sol.singular != Some(i) {
                    actual[i] = at.actual[i] + wrap(sol.actual[i] - at.actual[i]);
                    joints.rotary[i] = r.word(actual[i]);
                }
            }
        }
        for (i, r) in self.m.rotaries.iter().enumerate() {
            if r.limits.is_some() {
                actual[i] = r.actual(joints.rotary[i]);
            }
        }
        Some((joints, actual, sol.branch, sol.singular.map(|f| f as u8)))
    }

    /// One committed CL point; a rapid that starts a fixed-axis run (seen ahead) tilts the
    /// working plane once the machine stands there.
    fn point(&mut self, c: Committed) -> Result<(), Error> {
        let (rapid, tip, ahead) = (c.pt.rapid, c.pt.pose.tip, self.plane_ahead);
        self.point_at(c)?;
        if rapid && ahead && self.tilt.is_none() {
            self.enter_plane(&tip)?;
        }
        Ok(())
    }

    fn point_at(&mut self, c: Committed) -> Result<(), Error> {
        if self.o.canned_cycles {
            match c.pt.hole.as_deref().copied() {
                Some(HolePart::Start(h)) => {
                    self.in_hole = false;
                    match self.canned_check(&c, &h) {
                        Ok((cb, start)) => return self.canned_hole(c, h, cb, start),
                        Err(why) => self.expanded(&c.pt, why)?,
                    }
                }
                // The rest of a hole written as a cycle.
                Some(HolePart::Top) if self.in_hole => {
                    self.sum.cl_points += 1;
                    return Ok(());
                }
                Some(_) if self.in_hole => return Ok(()),
                _ => self.in_hole = false,
            }
        }
        self.sum.cl_points += !c.pt.inserted as u64;
        let pt = c.pt;
        let Some(cand) = c.cand else {
            let what = match &c.error {
                Some(e) => e.to_string(),
                None => "no solution".into(),
            };
            self.note_at(
                Diagnostic::new(
                    Code::Unreachable,
                    Severity::Error,
                    Some(pt.line),
                    format!("pose unreachable on {}: {what}; block skipped", self.m.id),
                ),
                &pt.pose,
            )?;
            return Ok(());
        };
        let Some((mut joints, mut actual, branch, mut free)) = self.resolve(&pt.pose, &cand, self.positioning(&pt)) else {
            return Ok(());
        };
        self.ensure_comp(pt.line)?;
        let mut diags: Vec<Diagnostic> = Vec::new();
        let mut pose = pt.pose;
        let outer = kinematics::outer_rotary(self.m);
        if let Some(sm) = self.smooth(&pt.pose, &joints, &actual, branch) {
            diags.push(Diagnostic::new(
                Code::Singular,
                Severity::Info,
                Some(pt.line),
                format!(
                    "free rotary held: tool axis {:.4}° off the CL orientation ({:.3}° less turn in this block)",
                    sm.3, sm.4
                ),
            ));
            if let Some(oi) = outer {
                let d = wrap(actual[oi] - self.exact_prev.unwrap_or(actual[oi])).abs();
                self.exact_travel += d;
                self.exact_prev = Some(actual[oi]);
            }
            (joints, actual, pose.axis, free) = (sm.0, sm.1, sm.2, None);
        } else if let Some(oi) = outer {
            self.exact_travel += wrap(actual[oi] - self.exact_prev.unwrap_or(actual[oi])).abs();
            self.exact_prev = Some(actual[oi]);
        }
        if let Some(oi) = outer {
            self.held_travel += (actual[oi] - self.held_prev.unwrap_or(actual[oi])).abs();
            self.held_prev = Some(actual[oi]);
            if self.o.singular_tolerance > 0.0 {
                self.sum.smoothing_travel_saved_deg = (self.exact_travel - self.held_travel).to_degrees();
            }
        }
        // The planner judged travel at the IK's free angle; a singular point stands at the one
        // held (mikron-ucp710: C held at 666° put Y at -277 of ±275, told as "near" its limit).
        let outside = if !cand.feasible || free.is_some() {
            kinematics::limit_violation(self.m, &joints, 1e-6)
        } else {
            None
        };
        if let Some(v) = &outside {
            self.outside_line = Some(pt.line);
            diags.push(limit_error(v, pt.line, ""));
        } else if let Some(v) = self.near_limit(&joints) {
            diags.push(Diagnostic::new(Code::NearLimit, Severity::Info, Some(pt.line), v));
        }
        let target = At {
            joints,
            actual,
            pose,
            branch,
            free,
        };
        // After a tool change the machine stands where the change left it, not at the last
        // block: the next move, feed or not, positions as a rapid that turns rotaries does.
        if let Some(prev) = &self.at
            && (self.tool_changed
                || pt.rapid
                    && (0..self.m.rotaries.len()).any(|i| (joints.rotary[i] - prev.joints.rotary[i]).abs() > 1f64.to_radians()))
        {
            self.safe_rapid(*prev, target, &pt, diags)?;
            return Ok(());
        }
        match self.at {
            Some(prev) if !pt.rapid => {
                let prev = if prev.free.is_some() {
                    self.turn_free(prev, &target, &pt)?
                } else {
                    prev
                };
                let unwind =
                    self.m.rotaries.iter().enumerate().any(|(i, r)| {
                        r.limits.is_some() && (joints.rotary[i] - prev.joints.rotary[i]).abs() > std::f64::consts::PI
                    });
                let branch_change = prev.branch * branch < 0
                    && !plan::crosses_fold(self.m, &prev.joints.rotary, &joints.rotary, &prev.pose.axis, &pt.pose.axis);
                if let (Some(arc), false, false) = (pt.arc.as_deref().copied(), unwind, branch_change) {
                    self.arc_move(prev, target, &arc, &pt, diags)?;
                    return Ok(());
                }
                // A feed that turns the axis of the plane in force: a cut longer than the look-ahead.
                if self
                    .tilt
                    .is_some_and(|t| angle_between(&t.axis, &pt.pose.axis) > PLANE_AXIS_EPS)
                {
                    self.reposition(prev, target, false, &pt)?;
                } else if unwind || branch_change {
                    self.reposition(prev, target, unwind, &pt)?;
                } else {
                    self.segment(prev, target, &pt, diags, 0)?;
                    return Ok(());
                }
            }
            _ => {}
        }
        if self.at.is_none() && !self.m.rotaries.is_empty() {
            return self.approach(target, &pt, diags);
        }
        self.block(target, &pt, pt.rapid || self.at.is_none(), diags, pt.inserted, None)?;
        Ok(())
    }

    /// Leaving a singular point by feed toward a pose that fixes its free rotary elsewhere: the
    /// rotary turns at the point, tip standing, where every angle of it holds the CL orientation,
    /// and the cut after it starts where it needs it. Turned during that cut instead, it tilted
    /// the tool axis off the CL orientation (0.8° for a 2° step on spinner-u5-620, 11° for 30°),
    /// and a bounded one far off retracted to unwind. Returns where the machine stands.
    #[cold]
    fn turn_free(&mut self, prev: At, to: &At, pt: &MotionPt) -> Result<At, Error> {
        let Some(f) = prev.free.map(usize::from) else {
            return Ok(prev);
        };
        if to.free.is_some() || self.tilt.is_some() {
            return Ok(prev);
        }
        // Spread over the cut, the turn leaves the axis within twice the cut's angle from the
        // singular direction (both the machine's axis and the CL's stay within that angle of
        // it): below half a rotary word, or the singular tolerance, nothing to stop for.
        let half_word = self.f.fmt.half_rotary().to_radians();
        let arc = angle_between(&prev.pose.axis, &to.pose.axis);
        if 2.0 * arc <= half_word.max(self.o.singular_tolerance) {
            return Ok(prev);
        }
        // The angle the cut leaves the point with: the exact solution on `to`'s branch a hair
        // along the CL arc. On an orthogonal table it is `to`'s; a nutating one twists the
        // azimuth as it tilts (C −90° just off vertical, −180° at the end of a 90° tilt).
        let t = (1e-7 / arc).min(0.5);
        let near = Pose {
            tip: prev.pose.tip + (to.pose.tip - prev.pose.tip) * t,
            axis: (prev.pose.axis * (1.0 - t) + to.pose.axis * t).normalize(),
        };
        let mut want = to.actual[f];
        if ik_into(self.m, &near, &self.setup, &IkOptions::default(), &mut self.buf).is_ok()
            && let Some(s) = self.buf.iter().find(|s| s.singular.is_none() && s.branch == to.branch)
        {
            want += wrap(s.actual[f] - want);
        }
        if (want - prev.actual[f]).abs() <= half_word {
            return Ok(prev);
        }
        let opt = IkOptions {
            free_angle: want,
            ..Default::default()
        };
        let Some(s) = ik_into(self.m, &prev.pose, &self.setup, &opt, &mut self.buf)
            .ok()
            .and_then(|_| nearest_singular(&self.buf, f, &prev.actual))
        else {
            return Ok(prev);
        };
        let mut turned = At {
            joints: s.joints,
            actual: s.actual,
            ..prev
        };
        for (i, r) in self.m.rotaries.iter().enumerate() {
            if i != f {
                turned.actual[i] = prev.actual[i] + wrap(s.actual[i] - prev.actual[i]);
            }
            turned.joints.rotary[i] = r.word(turned.actual[i]);
        }
        let r = &self.m.rotaries[f];
        let d = Diagnostic::new(
            Code::Singular,
            Severity::Info,
            Some(pt.line),
            format!(
                "{} turned by {:.4}° to {:.4}°, tip standing, where the tool axis is along it (line {}): the cut after it needs it there",
                r.name,
                (want - prev.actual[f]).to_degrees(),
                turned.joints.rotary[f].to_degrees(),
                self.last_line
            ),
        );
        self.segment(prev, turned, pt, vec![d], 0)?;
        Ok(turned)
    }

    /// `a` out of the way: joint mode at the top of Z travel (same X Y and rotaries), TCP or a
    /// machine without Z the clearance along the tool axis.
    fn above(&mut self, a: At) -> At {
        match self.z_top() {
            Some(zmax) => {
                let mut joints = a.joints;
                joints.linear[2] = zmax;
                At {
                    joints,
                    pose: fk(self.m, &joints, &self.setup),
                    ..a
                }
            }
            None => self.lifted(a, self.o.clearance),
        }
    }

    /// The top of Z travel, where joint-mode positioning turns the rotaries (none in TCP mode,
    /// where X Y Z are the tip, or on a machine without Z).
    fn z_top(&self) -> Option<f64> {
        let zmax = self.m.linears[2].as_ref().map(|l| l.max);
        zmax.filter(|_| self.o.mode == Mode::Joint)
    }

    /// Up and away from the part before a tool change and at the program's end, whatever the
    /// change macro or the operator does next: joint mode to the top of Z travel where the tool
    /// stands, TCP (or no Z axis) the clearance along the tool axis. Nothing before the first
    /// block.
    #[cold]
    fn retract_up(&mut self) -> Result<(), Error> {
        let Some(prev) = self.at else { return Ok(()) };
        let up = self.above(prev);
        if up.joints.linear == prev.joints.linear {
            return Ok(()); // at the top already
        }
        let pt = MotionPt {
            line: self.last_line,
            pose: up.pose,
            rapid: true,
            feed: None,
            inserted: true,
            comment: None,
            arc: None,
            hole: None,
        };
        self.block(up, &pt, true, Vec::new(), true, Some("RETRACT"))
    }

    /// The program's first move, from home (the tool up, rotaries at 0): over the point at the
    /// top of Z travel with the rotaries turned, then straight down (TCP, or no Z axis: from
    /// the clearance along the tool axis), so that the table or head never turns while the tool
    /// comes down to the part. The real NX post also turns the rotaries first.
    #[cold]
    fn approach(&mut self, to: At, pt: &MotionPt, diags: Vec<Diagnostic>) -> Result<(), Error> {
        let over = self.above(to);
        self.block(over, pt, true, diags, true, Some("APPROACH"))?;
        self.lock_all()?;
        self.descend(to, pt)
    }

    /// The end of positioning, from over the point (joint mode: the top of Z; else the clearance
    /// along the tool axis) onto it: at rapid onto a rapid point; onto a feed point at rapid to
    /// the clearance along the tool axis, then at feed, as a reposition re-approaches. A feed
    /// point may lie on the part: after a tool change it was reached at rapid.
    fn descend(&mut self, to: At, pt: &MotionPt) -> Result<(), Error> {
        if pt.rapid || pt.feed.is_none() {
            return self.block(to, pt, true, Vec::new(), pt.inserted, None);
        }
        if self.z_top().is_some() {
            let near = self.lifted(to, self.o.clearance);
            if kinematics::limit_violation(self.m, &near.joints, 1e-6).is_none() {
                self.block(near, pt, true, Vec::new(), true, None)?;
            }
        }
        self.block(to, pt, false, Vec::new(), pt.inserted, None)
    }

    /// An axis within 1 % of its travel (1° for rotaries) of an end: worth knowing before the
    /// machine stops on a limit with the next setup's offsets.
    fn near_limit(&self, j: &Joints) -> Option<String> {
        for (i, l) in self.m.linears.iter().enumerate() {
            if let Some(l) = l {
                let margin = 0.01 * (l.max - l.min);
                let v = j.linear[i];
                if v < l.min + margin || v > l.max - margin {
                    return Some(format!(
                        "{} = {:.4} within 1% of its travel [{}, {}]",
                        kinematics::LINEAR_NAMES[i],
                        v,
                        l.min,
                        l.max
                    ));
                }
            }
        }
        for (i, r) in self.m.rotaries.iter().enumerate() {
            if let Some((lo, hi)) = r.limits {
                let v = j.rotary[i];
                let margin = 1f64.to_radians();
                if v < lo + margin || v > hi - margin {
                    return Some(format!(
                        "{} = {:.4}° within 1° of its travel [{}, {}]",
                        r.name,
                        v.to_degrees(),
                        lo.to_degrees(),
                        hi.to_degrees()
                    ));
                }
            }
        }
        None
    }

    /// With a singular tolerance: the outer (free) rotary moved only as far from where it stands
    /// as keeps the tool axis within the tolerance of the CL orientation (the tip stays exact).
    /// Returns joints, actual angles, the axis reached, its deviation and the travel saved (°).
    fn smooth(
        &mut self,
        pose: &Pose,
        joints: &Joints,
        actual: &[f64; 3],
        branch: i8,
    ) -> Option<(Joints, [f64; 3], Vec3, f64, f64)> {
        let tol = self.o.singular_tolerance;
        let prev = self.at?;
        let oi = kinematics::outer_rotary(self.m)?;
        if tol <= 0.0 {
            return None;
        }
        let (from, target) = (prev.actual[oi], actual[oi]);
        if (target - from).abs() < 1e-9 {
            return None;
        }
        let dev = |a: f64| kinematics::hold_outer(self.m, pose, &self.setup, a, branch).map_or(f64::INFINITY, |(_, d)| d);
        // The smallest step toward the planner's exact choice that stays within the tolerance.
        let t = if dev(from) <= tol {
            0.0
        } else {
            let (mut lo, mut hi) = (0.0, 1.0);
            for _ in 0..40 {
                let mid = 0.5 * (lo + hi);
                if dev(from + mid * (target - from)) <= tol {
                    hi = mid
                } else {
                    lo = mid
                }
            }
            hi
        };
        if t >= 1.0 - 1e-9 {
            return None;
        }
        let a = from + t * (target - from);
        let (s, d) = kinematics::hold_outer(self.m, pose, &self.setup, a, branch)?;
        let mut j = s.joints;
        let mut act = s.actual;
        for (i, r) in self.m.rotaries.iter().enumerate() {
            act[i] = if i == oi {
                a
            } else {
                prev.actual[i] + wrap(s.actual[i] - prev.actual[i])
            };
            j.rotary[i] = r.word(act[i]);
        }
        if kinematics::limit_violation(self.m, &j, 1e-6).is_some() && kinematics::limit_violation(self.m, joints, 1e-6).is_none()
        {
            return None; // holding would leave travel: stay exact
        }
        let reached = fk(self.m, &j, &self.setup).axis;
        let saved = ((target - from).abs() - (a - from).abs()).to_degrees();
        self.sum.smoothed_blocks += 1;
        self.sum.smoothing_max_deviation_deg = self.sum.smoothing_max_deviation_deg.max(d.to_degrees());
        Some((j, act, reached, d.to_degrees(), saved))
    }

    /// An arc from `a` to `b`: G2/G3 (Heidenhain: CC + C) where the tool axis stays put and the
    /// arc's plane is a principal plane of the output coordinates (the machine's in joint mode,
    /// the part's in TCP mode), else chords within the tolerance (with the rotaries still, chords are straight in
    /// the machine too, so no further check is needed).
    fn arc_move(&mut self, a: At, b: At, arc: &ArcSpec, pt: &MotionPt, diags: Vec<Diagnostic>) -> Result<(), Error> {
        let m = self.m;
        let still = (0..m.rotaries.len()).all(|i| (a.joints.rotary[i] - b.joints.rotary[i]).abs() < 1e-9);
        let tcp = self.o.mode == Mode::Tcp;
        let full_linears = m.linears.iter().all(|l| l.is_some());
        let conversational = self.o.dialect.style == crate::nc::Style::Conversational;
        // In a tilted plane (the arc's end stands on the plane's rotaries): plane coordinates.
        let tilt = self.plane_at(&b.joints.rotary);
        let (center, normal, start) = if let Some(t) = &tilt {
            (
                self.plane_coords(t, &arc.center),
                t.frame.transpose() * arc.normal,
                self.plane_coords(t, &a.pose.tip),
            )
        } else if tcp && !self.compensated {
            (arc.center, arc.normal, a.pose.tip)
        } else if tcp {
            // The words' frame is the nominal one: the CL's frame moved rigidly at still rotaries.
            let c = self.tcp_xyz(&self.at_tip(&b, arc.center));
            let n = self.tcp_xyz(&self.at_tip(&b, arc.center + arc.normal)) - c;
            (c, n, self.tcp_xyz(&a))
        } else {
            let c = kinematics::controlled_point(m, &b.actual, &arc.center, &self.setup);
            let n = kinematics::controlled_point(m, &b.actual, &(arc.center + arc.normal), &self.setup) - c;
            (c, n, Vec3::from(a.joints.linear))
        };
        // Along the helix (a flat arc: no rise): what the tool travels at F.
        let length = (arc.radius * arc.sweep).hypot(arc.normal.dot(&(b.pose.tip - a.pose.tip)));
        // G17: normal ±Z (I J), G18: ±Y (I K), G19: ±X (J K).
        let plane = [(2usize, "G17", [0usize, 1]), (1, "G18", [0, 2]), (0, "G19", [1, 2])]
            .into_iter()
            .find(|(k, _, _)| normal[*k].abs() > 1.0 - 1e-9);
        if let (true, true, false, Some((k, word, ij))) = (still, tcp || full_linears, conversational, plane) {
            let ccw = normal[k] > 0.0;
            if self.plane != word {
                let l = self.f.words(word).to_string();
                self.out(&l)?;
                self.plane = word;
            }
            // A helix of several turns (NX's TIMES): one block can say at most one, and an end on
            // its start reads as a full circle on some controls only. Half turns say it anywhere.
            let pieces = if arc.sweep > std::f64::consts::TAU + 1e-9 {
                (arc.sweep / std::f64::consts::PI).ceil() as usize
            } else {
                1
            };
            let mut from = start;
            for i in 1..=pieces {
                let to = if i == pieces {
                    b
                } else {
                    self.at_tip(&b, helix_tip(a.pose.tip, b.pose.tip, arc, i as f64 / pieces as f64))
                };
                let d = center - from;
                let dec = self.f.fmt.linear;
                let mut words = String::new();
                for idx in ij {
                    words.push(['I', 'J', 'K'][idx]);
                    crate::nc::write_fixed(&mut words, crate::nc::round_to(d[idx], dec), dec);
                    words.push(' ');
                }
                self.arc_words = Some((ccw, words.trim_end().to_string(), length / pieces as f64));
                if i == pieces {
                    return self.block(b, pt, false, diags, pt.inserted, None);
                }
                from = match &tilt {
                    Some(t) => self.plane_coords(t, &to.pose.tip),
                    None if tcp => self.tcp_xyz(&to),
                    None => Vec3::from(to.joints.linear),
                };
                self.block(to, pt, false, Vec::new(), true, None)?;
            }
        }
        // Heidenhain: `CC` (the centre, absolute) then `C` to the end point with `DR+`/`DR-`, for a
        // flat arc in the working plane (XY: the tool along Z); anything else as chords.
        let end = match &tilt {
            Some(t) => self.plane_coords(t, &b.pose.tip),
            None if tcp => self.tcp_xyz(&b),
            None => Vec3::from(b.joints.linear),
        };
        if let (true, true, true, Some((2, _, _))) = (still, tcp || full_linears, conversational, plane)
            && (end[2] - start[2]).abs() < 1e-9
        {
            let ccw = normal[2] > 0.0;
            let dec = self.f.fmt.linear;
            let mut cc = String::from("CC");
            for (idx, name) in [(0usize, 'X'), (1, 'Y')] {
                let r = crate::nc::round_to(center[idx], dec);
                cc.push(' ');
                cc.push(name);
                if r >= 0 {
                    cc.push('+');
                }
                crate::nc::write_fixed(&mut cc, r, dec);
            }
            let l = self.f.words(&cc).to_string();
            self.out(&l)?;
            self.arc_words = Some((ccw, if ccw { "DR+" } else { "DR-" }.to_string(), length));
            return self.block(b, pt, false, diags, pt.inserted, None);
        }
        // Chords: the arc swept in the part frame, tool axis fixed, linears from the rotaries.
        let step = 2.0 * (1.0 - (self.o.tolerance / arc.radius).min(1.0)).acos();
        let segs = ((arc.sweep / step.max(1e-6)).ceil() as usize).clamp(1, 100_000);
        let mut diags = diags;
        if segs > 1 {
            diags.push(Diagnostic::new(
                Code::ArcLinearized,
                Severity::Info,
                Some(pt.line),
                format!("arc of {:.1}° written as {segs} chords", arc.sweep.to_degrees()),
            ));
        }
        let chord_tip = |i: usize| helix_tip(a.pose.tip, b.pose.tip, arc, i as f64 / segs as f64);
        if !full_linears {
            // Without a linear the rotaries place the tip too: every chord end is an exact
            // solution (the one nearest the last), and every chord a feed segment, linearized
            // (it held the end's rotaries: 9.6 mm off on propeller-3r2l).
            let mut prev = a;
            let mut skipped = Vec::new();
            for i in 1..segs {
                let pose = Pose {
                    tip: chord_tip(i),
                    axis: b.pose.axis,
                };
                let Some(at) = self.exact_near(pose, &prev) else {
                    // The next chord spans this end too; its own checks judge the result.
                    skipped.push(Diagnostic::new(
                        Code::Unreachable,
                        Severity::Warning,
                        Some(pt.line),
                        format!("chord end {i} of the arc's {segs} has no solution: the next chord spans two"),
                    ));
                    continue;
                };
                self.segment(prev, at, pt, std::mem::take(&mut skipped), 0)?;
                prev = at;
            }
            diags.append(&mut skipped);
            self.segment(prev, b, pt, diags, 0)?;
            return Ok(());
        }
        for i in 1..segs {
            let at = self.at_tip(&b, chord_tip(i));
            self.block(at, pt, false, Vec::new(), true, None)?;
        }
        self.block(b, pt, false, diags, pt.inserted, None)
    }

    /// A rapid that turns the rotaries: never together with the linears near the part. Joint
    /// mode: machine Z to the top of its travel, rotaries alone, then X Y, then down. TCP mode
    /// (or no Z axis): lift along the tool axis, turn at clearance, approach.
    fn safe_rapid(&mut self, prev: At, to: At, pt: &MotionPt, diags: Vec<Diagnostic>) -> Result<(), Error> {
        // The rotaries turn: out of a tilted plane first, so the retract reads as one.
        self.leave_plane(true)?;
        let up = self.above(prev);
        let over = self.above(to);
        if self.z_top().is_none() {
            self.block(up, pt, true, diags, true, Some("RETRACT"))?;
            self.block(over, pt, true, Vec::new(), true, Some("ROTARY REPOSITION"))?;
            return self.descend(to, pt);
        }
        // Turned at the top, still over the old X Y; then over the new one, then down.
        let mut joints = up.joints;
        joints.rotary = to.joints.rotary;
        let turned = At {
            joints,
            pose: fk(self.m, &joints, &self.setup),
            ..to
        };
        self.block(up, pt, true, diags, true, Some("RETRACT Z"))?;
        self.block(turned, pt, true, Vec::new(), true, Some("ROTARY REPOSITION"))?;
        self.block(over, pt, true, Vec::new(), true, None)?;
        self.lock_all()?;
        self.descend(to, pt)
    }

    /// Retract along the tool axis, turn at clearance, re-approach: for an unwind of a bounded
    /// rotary or a change of IK branch inside a cut.
    fn reposition(&mut self, prev: At, to: At, unwind: bool, pt: &MotionPt) -> Result<(), Error> {
        let word = if unwind { "UNWIND" } else { "REPOSITION" };
        let code = if unwind { Code::Unwind } else { Code::BranchChange };
        let why = if self.tilt.is_some() {
            " (the tilted plane's fixed tool axis turns inside a cut)"
        } else {
            ""
        };
        let d = Diagnostic::new(
            code,
            Severity::Warning,
            Some(pt.line),
            format!(
                "{word}: retract {} along the tool axis, turn, re-approach{why}",
                self.o.clearance
            ),
        );
        let r1 = self.lifted(prev, self.o.clearance);
        let r2 = self.lifted(to, self.o.clearance);
        self.block(r1, pt, true, vec![d], true, Some(&format!("RETRACT {word}")))?;
        self.block(r2, pt, true, Vec::new(), true, Some(word))?;
        self.block(to, pt, false, Vec::new(), pt.inserted, None)?;
        Ok(())
    }

    /// The same orientation `clear` further along the tool axis, or less where the travel ends
    /// first (a `near_limit` warning on the next block says how much): a retract, approach or
    /// re-approach point past the travel stopped the machine on overtravel (fryer-5x-45 in TCP
    /// mode: every approach 1 in over Z's end). With three linears only the linears move; a
    /// chain missing one needs the exact solution nearest the current one.
    fn lifted(&mut self, a: At, clear: f64) -> At {
        let at = |e: &mut Self, t: f64| -> At {
            let tip = a.pose.tip + a.pose.axis * t;
            if e.m.linears.iter().all(|l| l.is_some()) {
                return e.at_tip(&a, tip);
            }
            let pose = Pose { tip, axis: a.pose.axis };
            e.exact_near(pose, &a).unwrap_or(a)
        };
        let full = at(self, clear);
        let Some(v) = kinematics::limit_violation(self.m, &full.joints, 1e-6) else {
            return full;
        };
        // From a point within travel only (one outside is its own error): the longest retract
        // that stays within, by bisection (the linears are affine in it with three linears, not
        // with two; 40 halvings leave nanometres).
        if kinematics::limit_violation(self.m, &a.joints, 1e-6).is_some() {
            return full;
        }
        // One word's unit inside the travel: the written, rounded words land within it too (at
        // the bisection's exact end, TCP's rounded tip put dmg-dmc75v's X 0.0005 mm past -375).
        let margin = -2.0 * self.f.fmt.half_linear();
        let (mut lo, mut hi) = (0.0, clear);
        for _ in 0..40 {
            let mid = 0.5 * (lo + hi);
            if kinematics::limit_violation(self.m, &at(self, mid).joints, margin).is_some() {
                hi = mid;
            } else {
                lo = mid;
            }
        }
        self.lift_notes.push(Diagnostic::new(
            Code::NearLimit,
            Severity::Warning,
            None,
            format!(
                "retract along the tool axis shortened to {lo:.4} of {clear} by {}'s travel [{}, {}]",
                v.axis, v.min, v.max
            ),
        ));
        at(self, lo)
    }

    /// A TCP block's X Y Z at `at`: the tip itself, or on a profile with angle error the point
    /// whose nominal TCP puts the real tip there ([`kinematics::tcp_point`]).
    fn tcp_xyz(&self, at: &At) -> Vec3 {
        if self.compensated {
            kinematics::tcp_point(self.m, &at.joints, &self.setup)
        } else {
            at.pose.tip
        }
    }

    /// `a`'s rotaries and orientation with the tip at `tip`: only the linears move. For a machine
    /// with all three linears (on one missing a linear the rotaries place the tip too).
    fn at_tip(&self, a: &At, tip: Vec3) -> At {
        let cp = kinematics::controlled_point(self.m, &a.actual, &tip, &self.setup);
        let mut joints = a.joints;
        joints.linear = [cp.x, cp.y, cp.z];
        At {
            joints,
            pose: Pose { tip, axis: a.pose.axis },
            ..*a
        }
    }

    /// The exact solution of `pose` nearest `a` in the rotaries, wound next to `a`'s angles. On a
    /// chain missing a linear the rotaries place the tip too: a pose of `a`'s orientation
    /// elsewhere needs other angles. A singular pose keeps its free rotary where `a` has it.
    fn exact_near(&mut self, pose: Pose, a: &At) -> Option<At> {
        let opt = IkOptions {
            free_angle: kinematics::free_rotary(self.m).map_or(0.0, |f| a.actual[f]),
            ..Default::default()
        };
        ik_into(self.m, &pose, &self.setup, &opt, &mut self.buf).ok()?;
        let s = self
            .buf
            .iter()
            .min_by(|x, y| rotary_offset(x, &a.actual, None).total_cmp(&rotary_offset(y, &a.actual, None)))?;
        let mut actual = s.actual;
        let mut joints = s.joints;
        for (i, r) in self.m.rotaries.iter().enumerate() {
            actual[i] = a.actual[i] + wrap(s.actual[i] - a.actual[i]);
            joints.rotary[i] = r.word(actual[i]);
        }
        Some(At {
            joints,
            actual,
            pose,
            branch: s.branch,
            free: s.singular.map(|f| f as u8),
        })
    }

    /// A feed move from `a` to `b`, subdivided where the rotaries step too far in one block or
    /// (joint mode) the joint-space line strays from the CL segment.
    fn segment(&mut self, a: At, b: At, pt: &MotionPt, diags: Vec<Diagnostic>, depth: u32) -> Result<u32, Error> {
        let step = (0..self.m.rotaries.len())
            .map(|i| (b.joints.rotary[i] - a.joints.rotary[i]).abs())
            .fold(0.0, f64::max);
        let mut split = step > self.o.max_rotary_step;
        // TCP with angle error: the control interpolates the words, the real tip bends with Δ.
        let curved = self.o.mode == Mode::Joint || self.compensated;
        if !split && curved && step > 0.0 {
            // In W the tip follows R(θ(t))·x(t); |P''| ≤ Σ²·lever + 2·Σ·|Δxyz| (rotaries sweeping
            // and turning the moving linears), so the chord error is at most that over 8: below
            // the tolerance there is no need to sample.
            let sum: f64 = (0..self.m.rotaries.len())
                .map(|i| (b.joints.rotary[i] - a.joints.rotary[i]).abs())
                .sum();
            let dlin = (0..3)
                .map(|i| (b.joints.linear[i] - a.joints.linear[i]).powi(2))
                .sum::<f64>()
                .sqrt();
            // Longest distance from a rotary's line to what it moves (tip, pivots, tool).
            let lever =
                a.pose.tip.norm_squared().max(b.pose.tip.norm_squared()).sqrt() + self.lever_base + self.setup.tool_length.abs();
            // With angle-error compensation the actual angle is not linear in the interpolated
            // word: no bound, always sample.
            let bound = if self.compensated {
                f64::INFINITY
            } else {
                (sum * sum * lever + 2.0 * sum * dlin) / 8.0
            };
            split = bound > 0.5 * self.o.tolerance && self.nonlinear_over(&a, &b, 0.8 * self.o.tolerance);
        }
        // An end farther outside travel than the travel is long is a typo in the CL file (it is
        // a limit error already): following it to the tolerance cannot converge. `GOTO/1e8,…`
        // made 2¹⁴ leaves, each written as a reposition: 98 000 blocks for one bad point.
        if depth == 0 {
            (self.split_budget, self.split_told) = (MAX_SEGMENT_SPLITS, false);
        }
        if split && depth == 0 {
            let far = |j: &Joints| {
                self.m.linears.iter().zip(j.linear).any(|(l, v)| {
                    l.as_ref()
                        .is_some_and(|l| !(v >= l.min - (l.max - l.min) && v <= l.max + (l.max - l.min)))
                })
            };
            if far(&a.joints) || far(&b.joints) {
                split = false;
            }
        }
        if split
            && depth >= MAX_SPLIT_DEPTH
            && (step > self.o.max_rotary_step || curved && self.nonlinear_over(&a, &b, self.o.tolerance))
        {
            // Subdivision did not converge: the solution followed runs into a fold (or, any
            // mode, a rotary still steps too far: it was a feed block turning C 180°).
            self.reposition(a, b, false, pt)?;
            return Ok(3);
        }
        if split && depth < MAX_SPLIT_DEPTH && self.split_budget == 0 {
            // Never seen in a real or generated path; bounds the output whatever comes. Told
            // once a segment (the budget is reset with the next one).
            if !self.split_told {
                self.split_told = true;
                let d = Diagnostic::new(
                    Code::Linearized,
                    Severity::Warning,
                    Some(pt.line),
                    format!(
                        "segment not linearized past {MAX_SEGMENT_SPLITS} blocks: the motion between them may leave the tolerance"
                    ),
                );
                self.note(d)?;
            }
            split = false;
        }
        if split && depth < MAX_SPLIT_DEPTH {
            self.split_budget = self.split_budget.saturating_sub(1);
            match self.midpoint(&a, &b) {
                Some(mid) => {
                    let n1 = self.segment(a, mid, pt, Vec::new(), depth + 1)?;
                    let n2 = self.segment(mid, b, pt, diags, depth + 1)?;
                    return Ok(n1 + n2);
                }
                None => {
                    // No solution continues between the two: the root followed ends on a fold
                    // (3-rotary chains). The machine cannot follow the segment: reposition.
                    self.reposition(a, b, false, pt)?;
                    return Ok(3);
                }
            }
        }
        let mut diags = diags;
        let is_last = (b.pose.tip - pt.pose.tip).norm_squared() < 1e-24 && (b.pose.axis - pt.pose.axis).norm_squared() < 1e-24;
        if is_last && depth > 0 {
            diags.push(Diagnostic::new(
                Code::Linearized,
                Severity::Info,
                Some(pt.line),
                "segment subdivided (see the blocks before this one)",
            ));
        }
        self.block(b, pt, false, diags, !is_last || pt.inserted, None)?;
        Ok(1)
    }

    /// Whether the joint-space line a→b strays from the CL chord by more than `limit`, sampled
    /// at ½, ¼, ¾ and, where those leave less than half of `limit` proven, at the other eighths
    /// ([`NONLINEAR_SAMPLES`]): every eighth on every block cost curved 5-axis files +47 %.
    fn nonlinear_over(&self, a: &At, b: &At, limit: f64) -> bool {
        let tcp = self.o.mode == Mode::Tcp;
        let (pa, pb) = if tcp {
            (self.tcp_xyz(a), self.tcp_xyz(b))
        } else {
            (Vec3::zeros(), Vec3::zeros())
        };
        let mut worst: f64 = 0.0;
        for (k, t) in [0.5, 0.25, 0.75, 0.125, 0.375, 0.625, 0.875].into_iter().enumerate() {
            if k == 3 && worst < 0.5 * limit {
                break;
            }
            let mut j = a.joints;
            for i in 0..3 {
                j.linear[i] += t * (b.joints.linear[i] - a.joints.linear[i]);
                j.rotary[i] += t * (b.joints.rotary[i] - a.joints.rotary[i]);
            }
            let p = if tcp {
                kinematics::tcp_fk(self.m, &(pa + (pb - pa) * t), &j.rotary, &self.setup).tip
            } else {
                fk(self.m, &j, &self.setup).tip
            };
            worst = worst.max(seg_dist(&p, &a.pose.tip, &b.pose.tip));
            if worst > limit {
                return true;
            }
        }
        false
    }

    /// The pose halfway along the CL segment (tip on the chord, axis on the great circle) and
    /// its IK solution nearest the joint-space midpoint.
    fn midpoint(&mut self, a: &At, b: &At) -> Option<At> {
        let tip = (a.pose.tip + b.pose.tip) * 0.5;
        let axis = slerp_half(&a.pose.axis, &b.pose.axis);
        let pose = Pose { tip, axis };
        let mut want = [0.0; 3];
        for i in 0..3 {
            want[i] = 0.5 * (a.actual[i] + b.actual[i]);
        }
        // At a singular midpoint the free rotary takes the interpolated angle, and the linears
        // follow from it (they were computed for the first rotary's angle: 35 mm off the pose).
        let opt = IkOptions {
            free_angle: kinematics::free_rotary(self.m).map_or(0.0, |f| want[f]),
            ..Default::default()
        };
        ik_into(self.m, &pose, &self.setup, &opt, &mut self.buf).ok()?;
        let mut best: Option<(f64, At)> = None;
        for s in self.buf.iter() {
            let mut actual = s.actual;
            let mut joints = s.joints;
            let mut d = 0.0;
            for (i, r) in self.m.rotaries.iter().enumerate() {
                if s.singular == Some(i) {
                    actual[i] = want[i];
                } else {
                    actual[i] = want[i] + wrap(s.actual[i] - want[i]);
                }
                joints.rotary[i] = r.word(actual[i]);
                d += (actual[i] - want[i]).abs();
            }
            if best.as_ref().is_none_or(|(bd, _)| d < *bd) {
                best = Some((
                    d,
                    At {
                        joints,
                        actual,
                        pose,
                        branch: s.branch,
                        free: s.singular.map(|f| f as u8),
                    },
                ));
            }
        }
        // A chain without one linear (3 rotaries) can only place the tip with an exact root.
        let missing_linear = self.m.linears.iter().any(|l| l.is_none());
        let limit = if missing_linear {
            std::f64::consts::FRAC_PI_2
        } else {
            NEAR_SINGULAR_SWING
        };
        match best {
            // Near the interpolation (the second-order difference of any short segment away
            // from a singular direction): the exact solution, nothing to weigh.
            Some((d, at)) if d <= 1e-4 => return Some(at),
            Some((d, at)) if missing_linear => return (d <= limit).then_some(at),
            None if missing_linear => return None,
            // Outside the singular cone nothing swings: the exact midpoint can still leave the
            // interpolation far (a 90° tilt on a nutating table: B 65.5° against 90°), and holding
            // the interpolated rotaries there put the tool axis 31° off the CL orientation.
            Some((d, at)) if d <= std::f64::consts::FRAC_PI_2 && !self.in_singular_cone(&axis) => return Some(at),
            _ => {}
        }
        // Near a singular direction the exact midpoint's free rotary follows the azimuth of a
        // nearly aligned axis and swings wildly. Keep the interpolated rotaries (the motion the
        // control makes between the two blocks anyway), put the tip exactly on the chord, and
        // account for the orientation this leaves (bounded by how near the path passes).
        // Microradians from it the exact rotary chases the azimuth of an all but vertical axis
        // (and the rounding of i, j, k) to and fro: where the interpolated rotaries miss the
        // orientation by less than a rotary word can say, they are the better midpoint even
        // within the swing limit (it never converged 14 halvings deep, C wandering by a degree
        // at a standing tip).
        let (held, dev) = self.held_midpoint(a, &want, &tip, &axis);
        if let Some((d, at)) = best
            && d <= limit
            && dev > self.f.fmt.half_rotary()
        {
            return Some(at);
        }
        self.sum.max_singular_deviation_deg = self.sum.max_singular_deviation_deg.max(dev);
        Some(held)
    }

    /// Whether `axis` lies within the singular cone (`Options::singular_cone`) of the singular
    /// direction, either way: where the free rotary is held.
    fn in_singular_cone(&self, axis: &Vec3) -> bool {
        self.singular
            .is_some_and(|(dir, cone_cos)| axis.dot(&dir).abs() > cone_cos * axis.norm())
    }

    /// The midpoint with the rotaries at `want` (actual angles), the tip exactly at `tip`, and
    /// the angle (degrees) by which its tool axis misses `axis`.
    fn held_midpoint(&self, a: &At, want: &[f64; 3], tip: &Vec3, axis: &Vec3) -> (At, f64) {
        let mut joints = a.joints;
        for (i, r) in self.m.rotaries.iter().enumerate() {
            joints.rotary[i] = r.word(want[i]);
        }
        let axis_fk = fk(self.m, &joints, &self.setup).axis;
        let cp = kinematics::controlled_point(self.m, want, tip, &self.setup);
        for i in 0..3 {
            joints.linear[i] = if self.m.linears[i].is_some() { cp[i] } else { 0.0 };
        }
        let at = At {
            joints,
            actual: *want,
            pose: Pose {
                tip: *tip,
                axis: axis_fk,
            },
            branch: a.branch,
            free: None,
        };
        (at, angle_between(&axis_fk, axis).to_degrees())
    }

    /// Lock every clamped rotary that is unlocked (after positioning, at the end).
    fn lock_all(&mut self) -> std::io::Result<()> {
        for i in 0..3 {
            if let Some((lock, _)) = &self.o.clamps[i]
                && !self.locked[i]
            {
                let (open, close) = self.o.dialect.comment;
                let l = format!(
                    "{} {open}{} LOCK{close}",
                    self.f.words(&lock.clone()),
                    self.m.rotaries[i].name
                );
                self.out(&l)?;
                self.locked[i] = true;
            }
        }
        Ok(())
    }

    /// Unlock the clamped rotaries this move turns.
    fn unlock_moving(&mut self, to: &Joints) -> std::io::Result<()> {
        // Before the first block the machine stands at home: rotaries at 0.
        let from = self.at.map_or([0.0; 3], |p| p.joints.rotary);
        for i in 0..self.m.rotaries.len() {
            if let Some((_, unlock)) = &self.o.clamps[i]
                && self.locked[i]
                && (to.rotary[i] - from[i]).abs() > 1e-12
            {
                let (open, close) = self.o.dialect.comment;
                let l = format!(
                    "{} {open}{} UNLOCK{close}",
                    self.f.words(&unlock.clone()),
                    self.m.rotaries[i].name
                );
                self.out(&l)?;
                self.locked[i] = false;
            }
        }
        Ok(())
    }

    /// Writes one motion block and accounts for it.
    /// Rapid traverse for the time estimate: the slowest linear's feed limit, else a typical one.
    fn rapid_rate(&self) -> f64 {
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

    /// Books an FK replay's deviation (tip, degrees) in the summary; beyond the tolerance (or
    /// 0.01°) it is an error on the block.
    fn replayed(&mut self, line: u32, tip_dev: f64, ax_dev: f64, what: &str) -> Option<Diagnostic> {
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

    /// Why a fixed-axis run is not written in a tilted plane, if it cannot be.
    fn plane_refused(&self) -> Option<&'static str> {
        let m = self.m;
        if self.o.mode != Mode::Joint {
            return Some("tilted planes are written in joint mode only (TCP moves the tool in part coordinates already)");
        }
        if self.o.dialect.planes == crate::nc::Planes::None {
            return Some("this dialect has no tilted-plane command");
        }
        if m.linears.iter().any(|l| l.is_none()) || m.rotaries.len() != 2 {
            return Some("tilted planes need three linear and two rotary axes");
        }
        if self.o.dialect.planes == crate::nc::Planes::Haas && m.rotaries.iter().any(|r| r.mount != kinematics::Mount::Table) {
            return Some("G254 (dynamic work offset) needs a table-table machine");
        }
        None
    }

    /// Tilts the working plane where the machine stands (the rapid to `tip` just written), if
    /// the tool axis there is tilted and the machine and dialect allow it.
    fn enter_plane(&mut self, tip: &Vec3) -> std::io::Result<()> {
        let Some(at) = self.at else { return Ok(()) };
        if (at.pose.tip - tip).norm() > 1e-9 || angle_between(&at.pose.axis, &Vec3::z()) < 1e-6 {
            return Ok(());
        }
        if let Some(why) = self.plane_refused() {
            return self.say_once(why, Code::IgnoredRecord, None, "3+2 written as 5-axis positioning");
        }
        self.cancel_cycle()?;
        let m = self.m;
        let frame = kinematics::machine_frame(m, &self.written_rotaries(&at.joints.rotary));
        // The tilting rotary is the one that is not free about the singular direction.
        let free = kinematics::outer_rotary(m);
        let master = (0..m.rotaries.len()).find(|&i| Some(i) != free).unwrap_or(0);
        let positive = at.joints.rotary[master] >= 0.0;
        let c = self.f.comment("TILTED WORK PLANE").to_string();
        self.out(&c)?;
        self.comp_cancel()?;
        let (lines, written) = self.f.plane_on(&frame, positive);
        for l in &lines {
            self.out(l)?;
        }
        self.tilt = Some(Tilt {
            rotary: at.joints.rotary,
            frame: written,
            axis: at.pose.axis,
        });
        self.sum.tilted_planes += 1;
        self.ensure_comp(self.last_line)
    }

    /// Back to untilted coordinates; `recomp`: length compensation on again for the blocks that
    /// follow (not before a tool change, which sets its own).
    fn leave_plane(&mut self, recomp: bool) -> std::io::Result<()> {
        if self.tilt.take().is_none() {
            return Ok(());
        }
        self.cancel_cycle()?;
        self.comp_cancel()?;
        if let Some(l) = self.f.plane_off() {
            self.out(&l)?;
        }
        if recomp { self.ensure_comp(self.last_line) } else { Ok(()) }
    }

    /// Length compensation off (word-address controls with a G43-style word) around a plane
    /// change, which redefines the direction it applies in.
    fn comp_cancel(&mut self) -> std::io::Result<()> {
        let d = self.o.dialect;
        if self.comp_on && !d.length_comp.is_empty() && d.style == crate::nc::Style::WordAddress {
            if let Some(l) = self.f.line(d.tcp_off, self.tool.unwrap_or(1), 0) {
                self.out(&l)?;
            }
            self.comp_on = false;
        }
        Ok(())
    }

    /// The tip in the plane's coordinates (its origin is the joint-mode program zero).
    fn plane_coords(&self, t: &Tilt, tip_w: &Vec3) -> Vec3 {
        t.frame.transpose() * (tip_w + self.setup.work_offset)
    }

    /// The inverse, from the words as written (rounded): where the control puts the tip.
    fn plane_tip(&self, t: &Tilt, words: [f64; 3]) -> Vec3 {
        let q = Vec3::new(
            self.f.written(words[0], 0),
            self.f.written(words[1], 1),
            self.f.written(words[2], 2),
        );
        t.frame * q - self.setup.work_offset
    }

    /// The plane in force, if the rotary words `rotary` stand on it.
    fn plane_at(&self, rotary: &[f64; 3]) -> Option<Tilt> {
        self.tilt
            .filter(|t| (0..self.m.rotaries.len()).all(|i| (rotary[i] - t.rotary[i]).abs() <= 1e-9))
    }

    /// Rotary words (radians) as the control reads them back from the written degrees.
    fn written_rotaries(&self, rotary: &[f64; 3]) -> [f64; 3] {
        let mut w = [0.0; 3];
        for (i, r) in self.m.rotaries.iter().enumerate() {
            w[i] = self.f.written(rotary[i].to_degrees(), r.slot()).to_radians();
        }
        w
    }

    fn cancel_cycle(&mut self) -> std::io::Result<()> {
        if self.cycle_on.take().is_some()
            && let Some(l) = self.f.canned_off()
        {
            self.out(&l)?;
        }
        Ok(())
    }

    fn expanded(&mut self, pt: &MotionPt, why: &'static str) -> std::io::Result<()> {
        self.say_once(why, Code::CycleExpanded, Some(pt.line), "drilling cycle written as moves")
    }

    /// An info `{what}: {why}` the first time `why` comes up in a program.
    fn say_once(&mut self, why: &'static str, code: Code, line: Option<u32>, what: &str) -> std::io::Result<()> {
        if self.said_once.contains(&why) {
            return Ok(());
        }
        self.said_once.push(why);
        self.note(Diagnostic::new(
            code,
            Severity::Info,
            line,
            format!("{what}: {why} (said once)"),
        ))
    }

    /// The hole starting at this point as a canned cycle, with the tool where the point puts it,
    /// or why it cannot be one. Z levels are filled in from the start level once known.
    fn canned_check(&mut self, c: &Committed, h: &Hole) -> Result<(Canned, At), &'static str> {
        let m = self.m;
        if self.o.mode != Mode::Joint {
            return Err("canned cycles are written in joint mode only (TCP controls refuse most)");
        }
        if h.depth <= 0.0 {
            return Err("the cycle has no depth");
        }
        if m.linears[2].is_none() {
            return Err("the machine has no Z axis");
        }
        let kind = match (h.kind, h.peck, h.dwell) {
            (CycleKind::Deep, Some(q), _) if q > 0.0 => CannedKind::Peck,
            (CycleKind::Drill | CycleKind::Deep, _, Some(t)) if t > 0.0 => CannedKind::Spot,
            (CycleKind::Drill | CycleKind::Deep, _, _) => CannedKind::Drill,
            _ => return Err("only drilling and peck drilling cycles are written canned"),
        };
        let feed = match h.feed {
            Some((f, FeedUnit::PerMinute)) => f,
            Some((f, FeedUnit::PerRev)) => f * self.rpm.ok_or("a feed per revolution with no spindle speed")?,
            None => 0.0,
        };
        if feed.is_nan() || feed <= 0.0 {
            return Err("the cycle has no feed");
        }
        let cand = c
            .cand
            .as_ref()
            .filter(|k| k.feasible)
            .ok_or("the hole's start is not reachable within travel")?;
        let (joints, actual, branch, free) = self.resolve(&c.pt.pose, cand, true).ok_or("no solution")?;
        let start = joints.linear[2];
        let (bottom, r) = (start - h.start - h.depth, start - h.start + h.clear);
        let in_plane = self.o.tilted_planes && self.plane_refused().is_none();
        if !in_plane && !self.along_z(&joints, &actual, &c.pt.pose.axis) {
            return Err("the hole does not run along the machine's Z (a tilted head needs a tilted work plane)");
        }
        if m.linears[2]
            .as_ref()
            .is_some_and(|l| bottom < l.min - 1e-6 || bottom > l.max + 1e-6)
        {
            return Err("the hole's bottom is beyond Z travel");
        }
        let cb = Canned {
            kind,
            x: m.linears[0].is_some().then_some(joints.linear[0]),
            y: m.linears[1].is_some().then_some(joints.linear[1]),
            z_top: start - h.start,
            z_r: r,
            z_bottom: bottom,
            z_start: start,
            feed,
            peck: h.peck.unwrap_or(0.0),
            dwell: h.dwell.unwrap_or(0.0),
        };
        let at = At {
            joints,
            actual,
            pose: c.pt.pose,
            branch,
            free,
        };
        Ok((cb, at))
    }

    /// Whether one unit of machine Z moves the tip one unit back along the tool axis here: then
    /// a canned cycle's Z words drill the hole.
    fn along_z(&self, joints: &Joints, actual: &[f64; 3], axis: &Vec3) -> bool {
        let mut up = joints.linear;
        up[2] += 1.0;
        let d = kinematics::fk_actual(self.m, &up, actual, &self.setup).tip
            - kinematics::fk_actual(self.m, &joints.linear, actual, &self.setup).tip;
        (d - axis.normalize()).norm() < 1e-9
    }

    /// One hole as a canned cycle: the approach as any rapid (cancelling the previous cycle
    /// unless this hole continues it), then the cycle block.
    fn canned_hole(&mut self, c: Committed, h: Hole, mut cb: Canned, start: At) -> Result<(), Error> {
        let pt = c.pt.clone();
        self.cycle_in_plane(&mut cb, &start);
        let modal = match (self.cycle_on, self.at) {
            (Some(on), Some(at)) => {
                let same_rot = (0..self.m.rotaries.len()).all(|i| (start.joints.rotary[i] - at.joints.rotary[i]).abs() < 1e-9);
                same_rot && on.same_cycle(&cb, &self.f.fmt)
            }
            _ => false,
        };
        let at = if modal {
            start
        } else {
            self.cancel_cycle()?;
            self.point(Committed {
                pt: MotionPt {
                    hole: None,
                    ..pt.clone()
                },
                ..c
            })?;
            // The approach as written: the cycle starts from there.
            match self.at {
                // In a tilted plane its Z is the tool axis: the cycle in plane coordinates.
                Some(at) if (at.pose.tip - pt.pose.tip).norm() < 1e-9 && self.cycle_in_plane(&mut cb, &at) => at,
                Some(at) if (at.pose.tip - pt.pose.tip).norm() < 1e-9 && self.along_z(&at.joints, &at.actual, &at.pose.axis) => {
                    let [x, y, z] = at.joints.linear;
                    cb.start_at(cb.x.map(|_| x), cb.y.map(|_| y), z);
                    at
                }
                _ => return Ok(()), // the rest of the hole follows as moves
            }
        };
        self.at = Some(at);
        self.canned_block(&pt, &h, cb, at, modal)
    }

    /// A cycle's words moved into the tilted plane in force, when the tool stands on its
    /// rotaries at `at` (the cycle's start); false when no plane holds there.
    fn cycle_in_plane(&self, cb: &mut Canned, at: &At) -> bool {
        let Some(t) = self.plane_at(&at.joints.rotary) else {
            return false;
        };
        let q = self.plane_coords(&t, &at.pose.tip);
        cb.start_at(Some(q.x), Some(q.y), q.z);
        true
    }

    fn canned_block(&mut self, pt: &MotionPt, h: &Hole, cb: Canned, at: At, modal: bool) -> Result<(), Error> {
        let m = self.m;
        let lines = self.f.canned(&cb, modal);
        let Some((call, def)) = lines.split_last() else {
            return Ok(());
        };
        for l in def {
            self.out(l)?;
        }
        // Self-verification: the bottom of the hole, replayed from the words as written.
        let u = at.pose.axis.normalize();
        let want = at.pose.tip - u * (h.start + h.depth);
        let mut j = at.joints;
        j.linear[2] = cb.z_bottom;
        let tilt = self.tilt;
        if tilt.is_some() {
            // The machine's linears at the bottom (block info); the words are plane coordinates.
            let cp = kinematics::controlled_point(m, &at.actual, &want, &self.setup);
            j.linear = [cp.x, cp.y, cp.z];
        }
        let mut axes: [Option<f64>; 6] = [None; 6];
        for i in 0..3 {
            if m.linears[i].is_some() {
                axes[i] = Some(j.linear[i]);
                j.linear[i] = self.f.written(j.linear[i], i);
            }
        }
        for (i, r) in m.rotaries.iter().enumerate() {
            axes[r.slot()] = Some(at.joints.rotary[i].to_degrees());
        }
        j.rotary = self.written_rotaries(&at.joints.rotary);
        let replay = fk(m, &j, &self.setup);
        let tip_dev = match &tilt {
            Some(t) => (self.plane_tip(t, [cb.x.unwrap_or(0.0), cb.y.unwrap_or(0.0), cb.z_bottom]) - want).norm(),
            None => (replay.tip - want).norm(),
        };
        let ax_dev = angle_between(&replay.axis, &u).to_degrees();
        let diags: Vec<Diagnostic> = self
            .replayed(pt.line, tip_dev, ax_dev, "the cycle's bottom misses the hole")
            .into_iter()
            .chain(self.spindle_standing(pt.line))
            .collect();
        for d in &diags {
            self.count(d);
        }
        // Rapid down to R, feed to the bottom, rapid back to the start level.
        let rate = self.rapid_rate();
        let time = (cb.z_start - cb.z_r) / rate + (cb.z_r - cb.z_bottom) / cb.feed + (cb.z_start - cb.z_bottom) / rate;
        self.sum.cycle_time_s += time * 60.0;
        if let Some(st) = self.stats[2].as_mut() {
            st.min = st.min.min(axes[2].unwrap_or(cb.z_bottom));
        }
        self.blocks += 1;
        self.sum.blocks += 1;
        self.sum.canned_holes += 1;
        let info = BlockInfo {
            n: self.blocks,
            source_line: Some(pt.line),
            joints: AxisWords(axes),
            diagnostics: diags,
            rapid: false,
            tip: want.into(),
            axis: u.into(),
            time_s: time * 60.0,
        };
        self.sink.line(call, Some(&info))?;
        self.cycle_on = Some(cb);
        self.in_hole = true;
        Ok(())
    }

    fn block(
        &mut self,
        to: At,
        pt: &MotionPt,
        rapid: bool,
        mut diags: Vec<Diagnostic>,
        inserted: bool,
        comment: Option<&str>,
    ) -> Result<(), Error> {
        self.cancel_cycle()?;
        let m = self.m;
        if self.tilt.is_some() && self.plane_at(&to.joints.rotary).is_none() {
            self.leave_plane(true)?;
        }
        let tcp = self.o.mode == Mode::Tcp;
        // The machine's axis values (summary, block info), and the words written (in a tilted
        // plane: plane coordinates, no rotaries).
        let mut axes: [Option<f64>; 6] = [None; 6];
        let xyz = if tcp { self.tcp_xyz(&to) } else { to.pose.tip };
        for i in 0..3 {
            if m.linears[i].is_some() || tcp {
                axes[i] = Some(if tcp { xyz[i] } else { to.joints.linear[i] });
            }
        }
        for (i, r) in m.rotaries.iter().enumerate() {
            let k = r.slot();
            axes[k] = Some(to.joints.rotary[i].to_degrees());
        }
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
        // Feed.
        let prev = self.at;
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
                && let Some(p) = &prev
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
                    (None, Some(p)) => (FeedMode::PerMinute, machine_len(&p) / t),
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
        if !rapid && let Some(d) = self.spindle_standing(pt.line) {
            diags.push(d);
        }
        for mut d in self.lift_notes.drain(..) {
            d.line = Some(pt.line);
            diags.push(d);
        }
        // Diagnostics of the pose itself. A CL point's travel was checked where it was planned;
        // a block inserted between two points within travel (linearization, a retract along the
        // tool axis) can still leave it: the machine would stop on overtravel mid-cut.
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
        // Self-verification: FK of the machine's axes as written. Each word is rounded once, for
        // the line too; outside a tilted plane the words are the axes.
        let rounded = self.f.round_words(words);
        let tilted_axes;
        let axes_written = match tilt {
            None => &rounded,
            Some(_) => {
                tilted_axes = self.f.round_words(&axes);
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
            diags.extend(self.replayed(pt.line, tip_dev, ax_dev, "the written block misses the pose"));
        }
        // Statistics (per block: an array by axis letter, the summary's map at the end).
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
            for (i, r) in m.rotaries.iter().enumerate() {
                let d = (to.joints.rotary[i] - p.joints.rotary[i]).to_degrees().abs();
                let Some(st) = self.stats[r.slot()].as_mut() else {
                    continue;
                };
                *st.travel.get_or_insert(0.0) += d;
                if !rapid && comment.is_none() && d > st.largest_step.unwrap_or(0.0) {
                    st.largest_step = Some(d);
                    st.largest_step_line = Some(pt.line);
                }
            }
        }
        self.sum.cycle_time_s += time * 60.0;
        for d in &diags {
            self.count(d);
        }
        let comment = comment.or(pt.comment);
        self.unlock_moving(&to.joints)?;
        let arc = self.arc_words.take();
        let motion = match (&arc, rapid) {
            (_, true) => Motion::Rapid,
            (Some((ccw, _, _)), false) => Motion::Arc { ccw: *ccw },
            (None, false) => Motion::Feed,
        };
        let extra = arc.as_ref().map_or("", |(_, w, _)| w.as_str());
        self.at = Some(to);
        self.tool_changed = false;
        self.last_line = pt.line;
        match self.f.motion(motion, &rounded, feed, extra, comment) {
            Some(text) => {
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
                self.sink.line(text, Some(&info))?;
            }
            None => {
                for d in diags {
                    self.sink.diagnostic(&d)?;
                }
            }
        }
        Ok(())
    }
}

/// The solution with `free` free whose other rotaries lie nearest `actual`: the same root. A chain
/// missing a linear has several (the outer rotary a half turn apart).
fn nearest_singular(sols: &kinematics::Solutions, free: usize, actual: &[f64; 3]) -> Option<kinematics::Solution> {
    sols.iter()
        .filter(|s| s.singular == Some(free))
        .min_by(|x, y| rotary_offset(x, actual, Some(free)).total_cmp(&rotary_offset(y, actual, Some(free))))
        .copied()
}

/// How far a solution's rotaries lie from `actual`, each the short way round (`skip`: a free one
/// left out).
fn rotary_offset(s: &kinematics::Solution, actual: &[f64; 3], skip: Option<usize>) -> f64 {
    (0..3)
        .filter(|&i| Some(i) != skip)
        .map(|i| wrap(s.actual[i] - actual[i]).abs())
        .sum()
}

/// Where the joint-space motion between two blocks is measured against the CL chord: every
/// eighth. At ¼, ½, ¾ only, a block near htm50200's singular direction passed at 0.0091 mm
/// while its error peaked off the samples at 0.0107 (tolerance 0.01; the shared verifier samples
/// ninths). `verify` takes them all; the engine the outer four only where ½, ¼, ¾ come near.
pub const NONLINEAR_SAMPLES: [f64; 7] = [0.125, 0.25, 0.375, 0.5, 0.625, 0.75, 0.875];

/// Rotary distance (radians, summed) from the joint-space midpoint beyond which an exact midpoint
/// is not taken: the segment passes near a singular direction.
const NEAR_SINGULAR_SWING: f64 = 0.0873;

/// The error a block outside travel carries: axis, value and travel, and what the block is.
fn limit_error(v: &kinematics::LimitViolation, line: u32, what: &str) -> Diagnostic {
    Diagnostic::new(
        Code::LimitViolation,
        Severity::Error,
        Some(line),
        format!("{} = {:.4} outside its travel [{}, {}]{what}", v.axis, v.value, v.min, v.max),
    )
}

/// Distance of `p` from the segment [a, b].
pub fn seg_dist(p: &Vec3, a: &Vec3, b: &Vec3) -> f64 {
    let ab = b - a;
    let l2 = ab.norm_squared();
    let t = if l2 == 0.0 {
        0.0
    } else {
        ((p - a).dot(&ab) / l2).clamp(0.0, 1.0)
    };
    (p - (a + ab * t)).norm()
}

/// The tip a fraction `t` along `arc` (a helix: the height along its normal in proportion to the
/// angle) from `from` to `to`.
fn helix_tip(from: Vec3, to: Vec3, arc: &ArcSpec, t: f64) -> Vec3 {
    let k = arc.normal;
    let (ra, rb) = (from - arc.center, to - arc.center);
    let (h0, h1) = (k.dot(&ra), k.dot(&rb));
    let ap = ra - k * h0;
    let (s, c) = (arc.sweep * t).sin_cos();
    arc.center + ap * c + k.cross(&ap) * s + k * (h0 + (h1 - h0) * t)
}

/// The unit vector halfway along the great circle from `a` to `b`.
fn slerp_half(a: &Vec3, b: &Vec3) -> Vec3 {
    let s = a + b;
    let n = s.norm();
    if n < 1e-9 { *a } else { s / n }
}

/// Halvings of one CL segment before linearization gives up: a path passing within microradians
/// of a singular direction swings the free rotary over a millionth of its segment (14 left
/// leaves at 0.98 of the tolerance, over it once rounded).
const MAX_SPLIT_DEPTH: u32 = 20;

/// Blocks one CL segment may be linearized into: a bound on the output whatever the input.
const MAX_SEGMENT_SPLITS: u32 = 1 << 14;
