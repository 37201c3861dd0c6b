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
mod settings;
pub mod setups;
mod sink;
mod source;
pub mod verify;

pub use emit::linearize::{NONLINEAR_SAMPLES, seg_dist};
pub use settings::{Budget, MAX_SPINDLE_SPEED, Mode, Options, Settings, parse_triple};
pub use sink::{AxisStats, AxisWords, BlockInfo, Sink, Summary, TextSink};
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
    src.feed_max = emit::feed_max(o.dialect, m.units, crate::nc::FeedMode::PerMinute);
    let setup = Setup::new(o.tool_length.unwrap_or(m.default_tool_length), o.work_offset);
    let mut e = Emitter::new(m, o, sink, setup, &src);
    e.program_start()?;
    let mut planner = Planner::new(m, setup);
    let mut pending: VecDeque<Out> = VecDeque::new();
    let mut failed: Option<Error> = None;
    loop {
        let item = src.next_item()?;
        e.sink.read = src.bytes_read();
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
    e.finish()
}
