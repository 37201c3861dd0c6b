//! The emitter: committed CL points and program events in, NC blocks out, one file per concept.
//!
//! | concept | file |
//! |---|---|
//! | a committed point: windings, the motion it needs | `point.rs` |
//! | program events: tools, spindle, coolant, dwells, start and end | `program.rs` |
//! | singular handling: free rotary turned, held, smoothed | `singular.rs` |
//! | linearization of a feed segment | `linearize.rs` |
//! | positioning: retract, approach, reposition, clamps | `position.rs` |
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
pub(super) mod collide;
mod cutcom;
mod cycles;
pub(super) mod feed;
pub(super) mod linearize;

pub(super) use feed::feed_max;
mod planes;
mod point;
mod position;
mod program;
mod setups;
mod singular;
pub(super) mod smooth;
mod templates;

use super::{AxisStats, Error, Options, Sink, Source, Summary};
use super::Stop;
use crate::diag::{Code, Diagnostic, Severity};
use crate::kinematics::{self, Joints, Machine, Pose, Setup, Solutions, Vec3};
use crate::nc::{Canned, Formats, Formatter};
use planes::Tilt;

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

/// A block written as an arc (G2/G3, or Heidenhain's C after its CC).
pub(super) struct ArcBlock {
    /// G3 (Heidenhain DR+).
    pub(super) ccw: bool,
    /// The centre words (I J K, or DR±).
    pub(super) words: String,
    /// Its length along the helix: the time at F (a full circle's chord is none).
    pub(super) length: f64,
    /// The tip's path, for the collision check: the whole arc's start and end tips, the arc,
    /// and the stretch of it (fractions) this block takes.
    pub(super) path: (Vec3, Vec3, crate::post::ArcSpec, [f64; 2]),
}

pub(super) struct Emitter<'a, S: Sink + ?Sized> {
    pub(super) m: &'a Machine,
    pub(super) o: &'a Options,
    pub(super) sink: &'a mut S,
    pub(super) f: Formatter,
    pub(super) setup: Setup,
    pub(super) at: Option<At>,
    /// A tool change since the last block: the machine is not at `at` any more.
    pub(super) tool_changed: bool,
    /// The machine stands at a CL rapid point that positioning brought it to, in the air where
    /// the CAM put it: a rapid from there that turns rotaries need not climb the whole Z again.
    pub(super) positioned: bool,
    /// Halvings left to the CL segment being linearized (see [`MAX_SEGMENT_SPLITS`]).
    pub(super) split_budget: u32,
    /// The CL line of the last point outside travel: blocks inserted for it say nothing more.
    pub(super) outside_line: Option<u32>,
    /// Retracts [`Emitter::lifted`] shortened to stay within travel, told on the next block.
    pub(super) lift_notes: Vec<Diagnostic>,
    pub(super) split_told: bool,
    /// Tip moves shorter than this (half the X Y Z words' last digit) are a standing tip.
    pub(super) standing: f64,
    /// The CL line of the last block written (a retract at a tool change or the end has none).
    pub(super) last_line: u32,
    /// The tool length the program last said it is cut for (a comment).
    /// The last tool length comment written (said again only when it changes).
    pub(super) length_said: Option<String>,
    /// A tool or length changed: the summary's line for it is written at the next move.
    pub(super) tool_line_due: bool,
    /// Where the tool length in force came from.
    pub(super) length_from: crate::post::tools::LengthFrom,
    pub(super) tool: Option<u32>,
    /// The cutter the CL last described (diameter, corner radius; profile units).
    pub(super) cl_cutter: Option<(f64, f64)>,
    /// The tool `SELCTL` readied, and the CL's operation in progress: what templates see.
    pub(super) next_tool: Option<u32>,
    /// The tools the CL loads, in order (`preselect` `next` on a CL read twice), and how many
    /// tool changes have been written.
    pub(in crate::post) load_order: Option<Vec<u32>>,
    pub(super) changes: usize,
    pub(super) operation: Option<String>,
    /// The operation's smoothing word: what it is made from, what is in force.
    pub(super) smooth: smooth::Smooth,
    /// The next compensation on is a tool's first move (the `first_move` template).
    pub(super) first_move_due: bool,
    /// The tool's length offset register where the CL names one other than its number.
    pub(super) adjust: Option<u32>,
    pub(super) comp_on: bool,
    pub(super) rpm: Option<f64>,
    pub(super) blocks: u64,
    pub(super) sum: Summary,
    pub(super) buf: Solutions,
    pub(super) strict_error: Option<Diagnostic>,
    pub(super) warned_no_tool: bool,
    pub(super) warned_per_rev: bool,
    /// The spindle as the NC leaves it: turning (and which way), to be restarted before the next
    /// motion (a tool change stopped it and the CL did not say SPINDL again: APT's spindle is
    /// modal, M6 stops it on every control), and whether a cut with it standing was told.
    pub(super) spindle_on: bool,
    pub(super) spindle_cw: bool,
    pub(super) spindle_restore: Option<u32>,
    pub(super) warned_spindle: bool,
    /// The CL said SPINDL/OFF since the last tool change: `Options::spindle_speed` starts nothing.
    pub(super) spindle_said_off: bool,
    /// The coolant word the CL has on (APT's COOLNT is modal too), and the tool change that
    /// turned it off (M9 before M6: coolant, through-spindle above all, sprays into an open
    /// spindle and the changer) until the next tool's first move turns it on again.
    pub(super) coolant: Option<String>,
    pub(super) coolant_restore: Option<u32>,
    /// The CL line of a program stop that halted the spindle, or the coolant, not yet restarted.
    pub(super) stopped_spindle: Option<u32>,
    pub(super) stopped_coolant: Option<u32>,
    /// Coolant the CL turned on before its first tool and first move (CATIA writes COOLNT/ON
    /// before LOADTL): written at the first move, not before a tool change that turns it off.
    pub(super) coolant_deferred: bool,
    /// Which clamped rotaries are locked now (a clamped axis is taken as locked at the start).
    pub(super) locked: [bool; 3],
    /// The operation ahead turns a rotary while cutting: no clamp is locked until it ends.
    pub(super) cut_turns: bool,
    /// Set for the next block: it is an arc.
    pub(super) arc: Option<ArcBlock>,
    /// The active circular-interpolation plane word (G17/G18/G19).
    pub(super) plane: &'static str,
    /// Outer-rotary travel of the exact solutions and of what was written, at CL points: what
    /// the singular tolerance saved, honestly (a held block's saving is partly paid back later).
    pub(super) exact_prev: Option<f64>,
    pub(super) exact_travel: f64,
    pub(super) held_prev: Option<f64>,
    pub(super) held_travel: f64,
    /// The canned cycle the control has on (until cancelled), and whether the points of the
    /// hole it just drilled are still arriving (they were written as the cycle).
    pub(super) cycle_on: Option<Canned>,
    pub(super) in_hole: bool,
    /// Why holes were written as moves, or 3+2 as positioning: each said once.
    pub(super) said_once: Vec<&'static str>,
    /// The tilted working plane in force, if any.
    pub(super) tilt: Option<Tilt>,
    /// The point being written is a rapid whose fixed tool axis holds, in the look-ahead, until
    /// the next rapid with another axis (or a tool change, or the end): a plane may start there.
    pub(super) plane_ahead: bool,
    /// For a singular point: the free rotary's word (the planner's winding) where the cut after it
    /// fixes it.
    pub(super) free_hint: Option<f64>,
    /// Per axis letter (X Y Z A B C): extents and travel, moved into the summary at the end.
    pub(super) stats: [Option<AxisStats>; 6],
    /// cos of the singular cone and the singular direction, once (they are checked per block).
    pub(super) singular: Option<(Vec3, f64)>,
    /// What the linearization bound's lever adds to the tip's distance, less the tool length
    /// (work offset and pivots), and whether angle-error compensation rules the bound out: both
    /// fixed for the run, and the bound is taken for every block.
    pub(super) lever_base: f64,
    pub(super) compensated: bool,
    /// Squares of the tip miss and of the axis miss's tangent below which a block's replay is
    /// neither a new largest miss nor an error (kept by `replayed`).
    pub(super) quiet_tip2: f64,
    pub(super) quiet_tan2: f64,
    /// In a run of blocks slowed to the F word's range, or to an axis's velocity (each run
    /// told at its first block).
    pub(super) range_run: bool,
    pub(super) clamp_run: bool,
    /// `setups=work-offsets`: the offsets used, and the one in force.
    pub(super) offsets: Option<crate::post::setups::WorkOffsets>,
    pub(super) offset_at: usize,
    /// Per rotary: its clamp words are no codes of the dialect's control, and not written.
    pub(super) clamp_unknown: [bool; 3],
    /// Cutter radius compensation: asked, on, and what the CL says its path is.
    pub(super) cutcom: cutcom::State,
    /// The machine's bodies, the tool and the stock, when the collision check is on.
    pub(super) world: Option<crate::collide::World>,
}

impl<'a, S: Sink + ?Sized> Emitter<'a, S> {
    pub(in crate::post) fn new<R: std::io::BufRead>(
        m: &'a Machine,
        o: &'a Options,
        sink: &'a mut S,
        setup: Setup,
        src: &Source<R>,
    ) -> Self {
        let formats = Formats::for_dialect(&o.dialect, m.units);
        let mut f = Formatter::new(o.dialect.clone(), formats, o.sequence_numbers);
        f.tolerance = o.tolerance;
        Emitter {
            m,
            o,
            sink,
            f,
            setup,
            at: None,
            tool_changed: false,
            positioned: false,
            split_budget: 0,
            outside_line: None,
            lift_notes: Vec::new(),
            split_told: false,
            last_line: 0,
            standing: formats.half_linear(),
            next_tool: None,
            load_order: None,
            changes: 0,
            first_move_due: true,
            operation: None,
            smooth: smooth::Smooth::new(o.smoothing),
            tool: None,
            cl_cutter: None,
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
            stopped_spindle: None,
            stopped_coolant: None,
            coolant_deferred: false,
            arc: None,
            cut_turns: false,
            locked: [true; 3],
            plane: "G17",
            offsets: o
                .setup_offsets
                .then(|| crate::post::setups::WorkOffsets::new(&o.dialect.work_coordinates, o.wcs_word().unwrap_or(""))),
            offset_at: 0,
            clamp_unknown: [false; 3],
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
            tool_line_due: true,
            length_from: if o.tool_length.is_some() {
                crate::post::tools::LengthFrom::Job
            } else {
                crate::post::tools::LengthFrom::Profile
            },
            stats: Default::default(),
            singular: kinematics::singular_direction(m).map(|d| (d.normalize(), o.singular_cone.cos())),
            lever_base: setup.work_offset.norm() + m.rotaries.iter().map(|r| r.pivot.norm()).sum::<f64>(),
            compensated: m.has_angle_error(),
            quiet_tip2: 0.0,
            quiet_tan2: 0.0,
            range_run: false,
            clamp_run: false,
            cutcom: cutcom::State::new(src.stated_path()),
            world: o.geometry.as_ref().map(|g| {
                // The job gives stock and fixtures in the CL's units, known once the reader has
                // looked ahead.
                let k = |v: &[crate::collide::Solid]| v.iter().map(|s| s.scaled(src.scale)).collect::<Vec<_>>();
                crate::collide::World::new(m, g, &k(&o.stock), &k(&o.fixtures), o.collision_clearance, o.tolerance.max(1e-3))
            }),
        }
    }

    /// The program's end and its summary, handed to the sink and returned.
    pub(in crate::post) fn finish(&mut self) -> Result<Summary, Error> {
        if self.sum.cl_points == 0 {
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
        for (k, st) in self.stats.iter().enumerate() {
            if let Some(st) = st {
                self.sum.axes.insert(crate::nc::AXIS_LETTERS[k], st.clone());
            }
        }
        let sum = self.sum.clone();
        self.sink.summary(&sum)?;
        Ok(sum)
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

    /// An info `{what}: {why}` the first time `why` comes up in a program.
    pub(super) fn say_once(&mut self, why: &'static str, code: Code, line: Option<u32>, what: &str) -> Result<(), Stop> {
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
