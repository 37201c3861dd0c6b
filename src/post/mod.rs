#![allow(clippy::needless_range_loop)] // X Y Z loops index several parallel arrays
//! The postprocessing engine: CL records → poses → planned joint moves → NC blocks with
//! diagnostics, pushed into a [`Sink`] (a file, an HTTP stream, a golden test are all sinks).
//!
//! This file is the pipeline loop only: [`Source`] reads the CL, the planner chooses among the IK
//! candidates, [`lookahead`] holds back what must see ahead, and the emitter (`emit/`, one file
//! per concept) writes blocks through the dialect's formatter. Every block written is replayed
//! through FK from the words as written (rounded) and compared with the pose it was meant to
//! reach: the summary carries the largest deviation, and a block over tolerance is an error.

mod budget;
mod emit;
mod lookahead;
mod pipe;
mod plan;
mod settings;
pub mod setups;
mod sink;
mod source;
pub mod tools;
pub mod verify;

pub use emit::linearize::{NONLINEAR_SAMPLES, seg_dist};
pub use crate::machines::policy::{Prefer, Preselect, Retract, RotaryFeed, Smoothing, Unwind};
pub use settings::{Budget, MAX_SPINDLE_SPEED, Mode, Options, SettingError, Settings, parse_triple, threads};
pub use sink::{AxisStats, AxisWords, BlockInfo, Sink, Stop, Summary, TextSink, ToolUse};
pub use tools::LengthFrom;
pub use source::{ArcSpec, Hole, HolePart, Item, MotionPt, ProgEvent, Source};

use crate::diag::Diagnostic;
use crate::kinematics::{Machine, Setup};
use emit::Emitter;
use lookahead::deliver;
use plan::{Out, Planner};
use std::collections::VecDeque;
use std::io::BufRead;

/// Tool axes closer than this (radians) are the same fixed axis: for the look-ahead that finds
/// a tilted plane's run and for the emitter that leaves the plane, alike.
const PLANE_AXIS_EPS: f64 = 1e-9;

#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error(transparent)]
    Read(source::Error),
    /// The input is no CL data (NC, or nothing recognisable): refused before anything is written.
    #[error("{}", .0.message)]
    NotCl(Diagnostic),
    /// Strict mode: the first error diagnostic ends the run.
    #[error("{0}")]
    Strict(Diagnostic),
    /// The sink stopped the run (its budget, a cancel, a reader gone, a failed write): what it
    /// wrote before is all it writes.
    #[error(transparent)]
    Stop(#[from] Stop),
    /// The engine's own fault: one of its two threads ended without its end.
    #[error("writing output: {0}")]
    Engine(&'static str),
}

/// Reading a file twice (the CL's seek) fails as a write does.
impl From<std::io::Error> for Error {
    fn from(e: std::io::Error) -> Self {
        Error::Stop(Stop::Io(e))
    }
}

impl Error {
    /// The I/O error that ended the run, reading the CL or writing the output, where one did: a
    /// caller tells a failing file from a fault of the input by it.
    pub fn io(&self) -> Option<&std::io::Error> {
        match self {
            Error::Stop(Stop::Io(e)) | Error::Read(source::Error::Read(crate::cl::Error::Io(e))) => Some(e),
            _ => None,
        }
    }
}

impl From<source::Error> for Error {
    fn from(e: source::Error) -> Self {
        match e {
            source::Error::NotCl(d) => Error::NotCl(d),
            e => Error::Read(e),
        }
    }
}

/// Post-processes CL from `input` for machine `m` into `sink`. With `o.threads` 2 the CL is read
/// and planned on a second thread (`pipe`); the output is the same byte for byte.
pub fn post<R: BufRead + Send, S: Sink + ?Sized>(input: R, m: &Machine, o: &Options, sink: &mut S) -> Result<Summary, Error> {
    post_with(input, m, o, sink, None)
}

/// [`post`] from a CL that can be read twice (a file): with `preselect` `next`, a first pass
/// finds the order the CL loads its tools in, so that each tool change can ready the next one.
pub fn post_seekable<R: BufRead + std::io::Seek + Send, S: Sink + ?Sized>(
    mut input: R,
    m: &Machine,
    o: &Options,
    sink: &mut S,
) -> Result<Summary, Error> {
    let order = match o.preselect == Preselect::Next && !o.dialect.tool_preselect.is_empty() {
        true => {
            let order = tools::load_order(&mut input).map_err(source::Error::from)?;
            input.seek(std::io::SeekFrom::Start(0))?;
            Some(order)
        }
        false => None,
    };
    post_with(input, m, o, sink, order)
}

fn post_with<R: BufRead + Send, S: Sink + ?Sized>(
    input: R,
    m: &Machine,
    o: &Options,
    sink: &mut S,
    order: Option<Vec<u32>>,
) -> Result<Summary, Error> {
    let mut sink = budget::Metered::new(sink, o.budget);
    let held = std::sync::Mutex::new(Vec::new());
    let r = run(input, m, o, &mut sink, order, &held);
    if r.is_err() {
        // The words the reader held to tell at the end of the input, which the run did not
        // reach: told now, before the caller's error record, past the budget (at most one a
        // word) and whether or not the reader is still there to read them.
        for d in held.into_inner().unwrap_or_default() {
            let _ = sink.inner.diagnostic(&d);
        }
    }
    r
}

fn run<R: BufRead + Send, S: Sink + ?Sized>(
    input: R,
    m: &Machine,
    o: &Options,
    sink: &mut budget::Metered<'_, S>,
    order: Option<Vec<u32>>,
    held: &std::sync::Mutex<Vec<Diagnostic>>,
) -> Result<Summary, Error> {
    let mut src = Source::new(input, m.units, o.cl_units, o.strict)?;
    src.canned_cycles = o.canned_cycles;
    src.feed_max = emit::feed_max(&o.dialect, m.units, crate::nc::FeedMode::PerMinute);
    src.spindle_range = o.spindle_range;
    let lengths = tools::Lengths::new(m.units, o.tool_length, o.tool_table.as_deref(), m.default_tool_length);
    let setup = Setup::new(lengths.length, o.work_offset);
    let mut e = Emitter::new(m, o, sink, setup, &src, order);
    e.program_start()?;
    let plan = Plan {
        src,
        planner: Planner::new(m, setup, o.prefer),
        lengths,
        o,
        held,
    };
    let apply = Apply {
        e,
        pending: VecDeque::new(),
        failed: None,
    };
    if o.threads > 1 {
        return pipe::run(plan, apply);
    }
    let mut direct = Direct { apply, summary: None };
    plan.produce(&mut direct)?;
    direct.summary.ok_or(Error::Engine("the post ended without its end"))
}

/// What the reading and planning half asks of the emitting half, in the order a single thread
/// does it: both halves on one thread ([`Direct`]) or on two (`pipe`) run the same calls, so
/// the output cannot differ.
#[allow(clippy::large_enum_variant)]
enum Op {
    /// CL bytes read so far: the budget's measure for what is written next.
    Read(u64),
    Out(Out),
    /// Write everything held back (before a tool length takes effect).
    DrainAll,
    ToolLength(f64, tools::LengthFrom),
    /// One CL item done: the emitter's first error, what it may write now, strict mode's stop
    /// (with the source's own strict error, if this item raised one).
    ItemEnd(Option<Diagnostic>),
    /// Strict mode: the source's error after its last item.
    Strict(Diagnostic),
    /// The source failed (a read error).
    Fail(Error),
    /// The end of the CL: everything written, the summary.
    End,
}

/// The emitting half: the emitter and what waits for its look-ahead.
struct Apply<'a, 'b, S: Sink + ?Sized> {
    e: Emitter<'a, budget::Metered<'b, S>>,
    pending: VecDeque<Out>,
    failed: Option<Error>,
}

impl<S: Sink + ?Sized> Apply<'_, '_, S> {
    /// One op; the summary at [`Op::End`]. An error ends the post.
    fn op(&mut self, op: Op) -> Result<Option<Summary>, Error> {
        let e = &mut self.e;
        match op {
            Op::Read(n) => e.sink.read = n,
            Op::Out(x) => deliver(e, &mut self.pending, &mut self.failed, x),
            Op::DrainAll => e.drain(&mut self.pending, true)?,
            Op::ToolLength(l, from) => e.tool_length(l, from)?,
            Op::ItemEnd(src_strict) => {
                if let Some(err) = self.failed.take() {
                    return Err(err);
                }
                if let Some(stop) = e.sink.halted() {
                    return Err(stop.into());
                }
                e.drain(&mut self.pending, false)?;
                if let Some(d) = e.take_strict_error().or(src_strict) {
                    return Err(Error::Strict(d));
                }
            }
            Op::Strict(d) => return Err(Error::Strict(d)),
            Op::Fail(err) => return Err(err),
            Op::End => {
                if let Some(err) = self.failed.take() {
                    return Err(err);
                }
                e.drain(&mut self.pending, true)?;
                if let Some(d) = e.take_strict_error() {
                    return Err(Error::Strict(d));
                }
                return e.finish().map(Some);
            }
        }
        Ok(None)
    }
}

/// Where the reading half's ops go. An error stops it (the post failed, or the emitting half
/// is gone).
trait Down {
    fn op(&mut self, op: Op) -> Result<(), Error>;
}

/// One thread: each op applied as it comes.
struct Direct<'a, 'b, S: Sink + ?Sized> {
    apply: Apply<'a, 'b, S>,
    summary: Option<Summary>,
}

impl<S: Sink + ?Sized> Down for Direct<'_, '_, S> {
    fn op(&mut self, op: Op) -> Result<(), Error> {
        if let Some(s) = self.apply.op(op)? {
            self.summary = Some(s);
        }
        Ok(())
    }
}

/// The reading half: the source, the tool lengths (they govern IK) and the planner.
struct Plan<'m, R> {
    src: Source<R>,
    planner: Planner<'m>,
    lengths: tools::Lengths<'m>,
    o: &'m Options,
    /// Where the reader's held words go when the reading ends before the input does.
    held: &'m std::sync::Mutex<Vec<Diagnostic>>,
}

impl<R: BufRead> Plan<'_, R> {
    /// Reads and plans the whole CL, handing every emitter call to `down` in order. Stops at
    /// the first op `down` refuses, or at the source's strict error; then the words the reader
    /// still holds go to `held`, for the caller to tell.
    fn produce(mut self, down: &mut impl Down) -> Result<(), Error> {
        let r = self.items(down);
        let left = self.src.take_held();
        if !left.is_empty()
            && let Ok(mut h) = self.held.lock()
        {
            *h = left;
        }
        r
    }

    fn items(&mut self, down: &mut impl Down) -> Result<(), Error> {
        let o = self.o;
        loop {
            let item = match self.src.next_item() {
                Ok(i) => i,
                Err(err) => return down.op(Op::Fail(err.into())),
            };
            down.op(Op::Read(self.src.bytes_read()))?;
            let Some(item) = item else { break };
            // The tool length governs IK: a change cannot wait in the window. It takes effect
            // after the tool change it belongs to is written (the retract is the old tool's).
            let lengths = &mut self.lengths;
            let step = match &item {
                Item::Event(ProgEvent::ToolLength { length, line }) if o.tool_length.is_none() => lengths.cl_length(*length, *line),
                Item::Event(ProgEvent::Tool { number, line, .. }) => lengths.tool(*number, *line),
                Item::Motion(_) if lengths.waiting() => lengths.motion(),
                _ => tools::Step::default(),
            };
            let mut out = |x| {
                // A refusal shows at the next op outside the planner.
                let _ = down.op(Op::Out(x));
            };
            let length_change = step.set.is_some() || step.diag.is_some();
            if length_change {
                self.planner.finish(&mut out);
                let tool = match &item {
                    Item::Event(ev @ ProgEvent::Tool { .. }) => Some(ev.clone()),
                    _ => None,
                };
                for ev in tool.into_iter().chain(step.diag.map(ProgEvent::Diag)) {
                    self.planner.push_event(ev, &mut out);
                }
                down.op(Op::DrainAll)?;
                if let Some((l, from)) = step.set {
                    self.planner.setup.tool_length = l;
                    down.op(Op::ToolLength(l, from))?;
                }
            }
            let mut out = |x| {
                let _ = down.op(Op::Out(x));
            };
            match item {
                Item::Motion(pt) => self.planner.push_point(pt, &mut out),
                // Weighed above (with the job's length fixed, the emitter tells a CL length it overrides).
                Item::Event(ProgEvent::ToolLength { .. }) if o.tool_length.is_none() => {}
                Item::Event(ProgEvent::Tool { .. }) if length_change => {} // written above
                Item::Event(ev) => self.planner.push_event(ev, &mut out),
            }
            let strict = self.src.strict_error.take();
            let stop = strict.is_some();
            down.op(Op::ItemEnd(strict))?;
            if stop {
                return Ok(()); // the emitting half stops there
            }
        }
        if let Some(d) = self.src.strict_error.take() {
            return down.op(Op::Strict(d));
        }
        self.planner.finish(&mut |x| {
            let _ = down.op(Op::Out(x));
        });
        down.op(Op::End)
    }
}
