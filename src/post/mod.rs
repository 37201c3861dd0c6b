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
mod plan;
mod policy;
mod settings;
pub mod setups;
mod sink;
mod source;
pub mod tools;
pub mod verify;

pub use emit::linearize::{NONLINEAR_SAMPLES, seg_dist};
pub use policy::{Prefer, Retract, RotaryFeed, Unwind};
pub use settings::{Budget, MAX_SPINDLE_SPEED, Mode, Options, Settings, parse_triple};
pub use sink::{AxisStats, AxisWords, BlockInfo, Sink, Summary, TextSink, ToolUse};
pub use tools::LengthFrom;
pub use source::{ArcSpec, Hole, HolePart, Item, MotionPt, ProgEvent, Source};

use crate::diag::Diagnostic;
use crate::kinematics::{Machine, Setup};
use emit::Emitter;
use lookahead::deliver;
use plan::{Out, Planner};
use std::collections::VecDeque;
use std::io::BufRead;

#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error(transparent)]
    Read(source::Error),
    /// The input is no CL data (NC, or nothing recognisable): refused before anything is written.
    #[error("{}", .0.message)]
    NotCl(Diagnostic),
    #[error("writing output: {0}")]
    Io(#[from] std::io::Error),
    /// Strict mode: the first error diagnostic ends the run.
    #[error("{0}")]
    Strict(Diagnostic),
    /// The run went over its [`Budget`]: what it wrote before is all it writes.
    #[error("{0}")]
    Budget(String),
}

impl From<source::Error> for Error {
    fn from(e: source::Error) -> Self {
        match e {
            source::Error::NotCl(d) => Error::NotCl(d),
            e => Error::Read(e),
        }
    }
}

/// Post-processes CL from `input` for machine `m` into `sink`.
pub fn post<R: BufRead, S: Sink + ?Sized>(input: R, m: &Machine, o: &Options, sink: &mut S) -> Result<Summary, Error> {
    let mut sink = budget::Metered::new(sink, o.budget);
    let r = run(input, m, o, &mut sink);
    match (r, sink.tripped) {
        (Err(_), Some(why)) => Err(Error::Budget(why)),
        (r, _) => r,
    }
}

fn run<R: BufRead, S: Sink + ?Sized>(
    input: R,
    m: &Machine,
    o: &Options,
    sink: &mut budget::Metered<'_, S>,
) -> Result<Summary, Error> {
    let mut src = Source::new(input, m.units, o.cl_units, o.strict)?;
    src.canned_cycles = o.canned_cycles;
    src.feed_max = emit::feed_max(&o.dialect, m.units, crate::nc::FeedMode::PerMinute);
    src.spindle_range = o.spindle_range;
    let mut lengths = tools::Lengths::new(m.units, o.tool_length, o.tool_table.as_deref(), m.default_tool_length);
    let setup = Setup::new(lengths.length, o.work_offset);
    let mut e = Emitter::new(m, o, sink, setup, &src);
    e.program_start()?;
    let mut planner = Planner::new(m, setup, o.prefer);
    let mut pending: VecDeque<Out> = VecDeque::new();
    let mut failed: Option<Error> = None;
    loop {
        let item = src.next_item()?;
        e.sink.read = src.bytes_read();
        let Some(item) = item else { break };
        // The tool length governs IK: a change cannot wait in the window. It takes effect after
        // the tool change it belongs to is written (the retract is the old tool's).
        let step = match &item {
            Item::Event(ProgEvent::ToolLength { length, line }) if o.tool_length.is_none() => {
                lengths.cl_length(*length, *line)
            }
            Item::Event(ProgEvent::Tool { number, line, .. }) => lengths.tool(*number, *line),
            Item::Motion(_) if lengths.waiting() => lengths.motion(),
            _ => tools::Step::default(),
        };
        let length_change = step.set.is_some() || step.diag.is_some();
        if length_change {
            planner.finish(&mut |x| deliver(&mut e, &mut pending, &mut failed, x));
            let tool = match &item {
                Item::Event(ev @ ProgEvent::Tool { .. }) => Some(ev.clone()),
                _ => None,
            };
            for ev in tool.into_iter().chain(step.diag.map(ProgEvent::Diag)) {
                planner.push_event(ev, &mut |x| deliver(&mut e, &mut pending, &mut failed, x));
            }
            e.drain(&mut pending, true)?;
            if let Some((l, from)) = step.set {
                planner.setup.tool_length = l;
                e.tool_length(l, from)?;
            }
        }
        match item {
            Item::Motion(pt) => planner.push_point(pt, &mut |x| deliver(&mut e, &mut pending, &mut failed, x)),
            // Weighed above (with the job's length fixed, the emitter tells a CL length it overrides).
            Item::Event(ProgEvent::ToolLength { .. }) if o.tool_length.is_none() => {}
            Item::Event(ProgEvent::Tool { .. }) if length_change => {} // written above
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
    e.finish()
}
