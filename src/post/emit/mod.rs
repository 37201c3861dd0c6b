//! The emitter: committed CL points and program events in, NC blocks out, one file per concept.
//!
//! | concept | file |
//! |---|---|
//! | a committed point: windings, the motion it needs | `point.rs` |
//! | program events: comments, dwells, stops, passed-through codes, start and end | `program.rs` |
//! | singular handling: free rotary turned, held, smoothed | `singular.rs` |
//! | linearization of a feed segment | `linearize.rs` |
//! | positioning: retract, approach, reposition | `position.rs` |
//! | rotary clamps: locked, unlocked around a move or an operation | `clamps.rs` |
//! | the tool in force: change, length, preselect, length compensation | `tool.rs` |
//! | spindle and coolant: started, stopped, restored | `spindle.rs` |
//! | work offsets of a program of several setups | `setups.rs` |
//! | arcs | `arcs.rs` |
//! | canned cycles | `cycles.rs` |
//! | cutter radius compensation | `cutcom.rs` |
//! | tilted working planes | `planes.rs` |
//! | the feed and the time of a block | `feed.rs` |
//! | the block writer and its FK replay | `block.rs` |
//! | the collision check of each block and the motion to it | `collide.rs` |
//! | smoothing per operation | `smooth.rs` |

mod arcs;
mod block;
mod clamps;
pub(super) mod collide;
mod cutcom;
mod cycles;
pub(super) mod feed;
pub(super) mod linearize;

pub(super) use feed::feed_max;
pub(super) use point::Ahead;
mod planes;
mod point;
mod position;
mod program;
mod setups;
mod singular;
pub(super) mod smooth;
mod spindle;
mod templates;
mod tool;

use super::{Error, Options, Sink, Source, Summary};
use crate::diag::{Code, Diagnostic, Severity};
use crate::kinematics::{self, Joints, Machine, Pose, Setup};
use crate::nc::{Formats, Formatter};
use crate::post::Stop;

/// The last block written: where the machine is.
#[derive(Clone, Copy, Debug)]
pub(super) struct At {
    joints: Joints,
    actual: [f64; 3],
    pose: Pose,
    branch: i8,
    /// The rotary whose angle is free here (the tool axis along the singular direction): any
    /// angle of it holds this pose, with other linears. A byte: `At` stays 128 bytes, copied
    /// inline (a word more made every block's copies `memcpy` calls, +3.7 % instructions).
    free: Option<u8>,
}

/// A block written as an arc (G2/G3, or Heidenhain's C after its CC): what `arcs` hands the
/// block writer.
pub(super) struct ArcBlock {
    /// G3 (Heidenhain DR+).
    pub(super) ccw: bool,
    /// The centre words (I J K, or DR±).
    pub(super) words: String,
    /// Its length along the helix: the time at F (a full circle's chord is none).
    pub(super) length: f64,
    /// The tip's path, for the collision check.
    pub(super) path: collide::ArcPath,
}

/// The emitter: what every concept shares (the machine, the options, the sink, the formatter,
/// the last block written), and one field per concept, each owning its state in its own file.
pub(super) struct Emitter<'a, S: Sink + ?Sized> {
    m: &'a Machine,
    o: &'a Options,
    pub(super) sink: &'a mut S,
    f: Formatter,
    at: Option<At>,
    /// The blocks written so far, what was told, and the summary they make.
    written: block::Written,
    /// The tool in force: its number, length (the setup FK takes), register, compensation.
    tool: tool::Tool,
    /// The spindle and the coolant as the NC leaves them.
    spindle: spindle::Spindle,
    /// The singular cone, and the outer rotary's travel the singular tolerance saved.
    singular: singular::Held,
    /// Which clamped rotaries are locked, and whether the operation ahead keeps them open.
    clamps: clamps::Clamps,
    /// The canned cycle the control has on, and the hole it drills.
    cycles: cycles::Cycles,
    /// The tilted working plane, the arc plane word and the work offset in force.
    frames: planes::Frames,
    /// Cutter radius compensation: asked, on, and what the CL says its path is.
    cutcom: cutcom::State,
    /// The operation's smoothing word: what it is made from, what is in force.
    smooth: smooth::Smooth,
    /// The machine's bodies, the tool and the stock, when the collision check is on.
    collide: collide::Check,
}

impl<'a, S: Sink + ?Sized> Emitter<'a, S> {
    /// `load_order`: the tools the CL loads, in order, where it is read twice (`preselect`
    /// `next`).
    pub(in crate::post) fn new<R: std::io::BufRead>(
        m: &'a Machine,
        o: &'a Options,
        sink: &'a mut S,
        setup: Setup,
        src: &Source<R>,
        load_order: Option<Vec<u32>>,
    ) -> Self {
        let formats = Formats::for_dialect(&o.dialect, m.units);
        let mut f = Formatter::new(o.dialect.clone(), formats, o.sequence_numbers);
        f.tolerance = o.tolerance;
        let sum = Summary {
            machine: m.id.clone(),
            mode: Some(o.mode),
            units: m.units.as_str().into(),
            cl_units: src.cl_units.as_str().into(),
            cl_units_source: src.units_source.into(),
            tool_length: setup.tool_length,
            ..Default::default()
        };
        let offsets = o
            .setup_offsets
            .then(|| crate::post::setups::WorkOffsets::new(&o.dialect.work_coordinates, o.wcs_word().unwrap_or("")));
        Emitter {
            m,
            o,
            sink,
            f,
            at: None,
            written: block::Written::new(sum, formats.half_linear()),
            tool: tool::Tool::new(setup, o.tool_length.is_some(), load_order),
            spindle: spindle::Spindle::default(),
            singular: singular::Held::new(m, o.singular_cone),
            clamps: clamps::Clamps::default(),
            cycles: cycles::Cycles::default(),
            frames: planes::Frames::new(offsets),
            cutcom: cutcom::State::new(src.stated_path()),
            smooth: smooth::Smooth::new(o.smoothing),
            collide: collide::Check::new(m, o, src.scale),
        }
    }

    /// The program's end and its summary, handed to the sink and returned.
    pub(in crate::post) fn finish(&mut self) -> Result<Summary, Error> {
        if self.written.cl_points() == 0 {
            // An empty program that ends well is easily taken for a posted part (a wrong file
            // uploaded, a CL dialect not read): say it.
            self.note(Diagnostic::new(
                Code::NoMotion,
                Severity::Warning,
                None,
                "no motion in the CL input (no GOTO, GODLTA or FROM was read): the program moves nothing",
            ))?;
        }
        self.list_work_offsets()?;
        self.program_end()?;
        let tolerance = self.o.singular_tolerance;
        let sum = self.written.summary(|sum| {
            self.tool.summary(sum);
            self.singular.summary(sum, tolerance);
            self.cycles.summary(sum);
            self.frames.summary(sum);
        });
        self.sink.summary(&sum)?;
        Ok(sum)
    }

    /// Strict mode's stop: the first error, taken.
    pub(in crate::post) fn take_strict_error(&mut self) -> Option<Diagnostic> {
        self.written.take_strict_error()
    }

    pub(super) fn out(&mut self, text: &str) -> Result<(), Stop> {
        self.line(text, None)
    }

    /// Every line goes out here: in the dialect's number format, and told when it is longer
    /// than the control reads.
    pub(super) fn line(&mut self, text: &str, info: Option<&crate::post::BlockInfo>) -> Result<(), Stop> {
        let (text, long) = self.f.finish(text);
        // The error's own comment line is cut to fit: never told again.
        if long && info.is_some() {
            let n = self.o.dialect.line_length;
            self.note(Diagnostic::new(
                Code::LineTooLong,
                Severity::Error,
                info.and_then(|i| i.source_line),
                format!("a line of {} characters, longer than the {n} {} reads: {:.60}", text.len(), self.o.dialect.name, text),
            ))?;
        }
        self.sink.line(&text, info)
    }

    pub(in crate::post) fn note(&mut self, d: Diagnostic) -> Result<(), Stop> {
        self.count(&d);
        self.flag(&d)?;
        self.sink.diagnostic(&d)
    }

    /// A diagnostic about a CL pose that got no block (unreachable): where it is, for a preview.
    pub(super) fn note_at(&mut self, d: Diagnostic, pose: &Pose) -> Result<(), Stop> {
        self.count(&d);
        self.flag(&d)?;
        self.sink.diagnostic_at(&d, pose)
    }

    /// An error with no block of its own (a point skipped, a record refused) is a comment line
    /// where it happened: the machinist runs the NC, not the diagnostics.
    pub(super) fn flag(&mut self, d: &Diagnostic) -> Result<(), Stop> {
        if d.severity != Severity::Error {
            return Ok(());
        }
        let at = d.line.map_or(String::new(), |l| format!(" CL LINE {l}"));
        let c = self
            .f
            .comment(&format!("ERROR {}{at}: {}", d.code.as_str(), d.message))
            .to_string();
        self.out(&c)
    }

    pub(super) fn count(&mut self, d: &Diagnostic) {
        self.written.count(d, self.o.strict);
    }

    /// An info `{what}: {why}` the first time `why` comes up in a program.
    pub(super) fn say_once(&mut self, why: &'static str, code: Code, line: Option<u32>, what: &str) -> Result<(), Stop> {
        if !self.written.first_time(why) {
            return Ok(());
        }
        self.note(Diagnostic::new(
            code,
            Severity::Info,
            line,
            format!("{what}: {why} (said once)"),
        ))
    }
}

/// The error a block outside travel carries: axis, value and travel, and what the block is.
fn limit_error(v: &kinematics::LimitViolation, line: u32, what: &str) -> Diagnostic {
    Diagnostic::new(
        Code::LimitViolation,
        Severity::Error,
        Some(line),
        format!("{} = {:.4} outside its travel [{}, {}]{what}", v.axis, v.value, v.min, v.max),
    )
}
