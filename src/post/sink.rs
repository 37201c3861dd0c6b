//! Where the program goes: the [`Sink`] a run pushes into, what it is told per block, why it
//! may stop the run ([`Stop`]), and the run's [`Summary`].

use crate::diag::Diagnostic;
use crate::kinematics::Pose;
use serde::Serialize;
use std::collections::BTreeMap;

use super::Mode;

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

/// Why a sink stops a run before its end. Each edge tells the reasons apart by the variant
/// (HTTP's status, a job's end), never by a message's words; the text is what a user reads.
#[derive(Debug, thiserror::Error)]
pub enum Stop {
    /// The run went over its [`Budget`](super::Budget): output per CL byte, or time. The
    /// message names the bound.
    #[error("{0}")]
    Budget(String),
    /// The job it writes for was cancelled.
    #[error("cancelled")]
    Cancelled,
    /// Whoever reads the output has gone (a client that left): nobody is told.
    #[error("the output's reader has gone")]
    Gone,
    /// Writing the output failed (a full disk, a closed pipe).
    #[error("writing output: {0}")]
    Io(#[from] std::io::Error),
}

/// Where the program goes. The NC file, the NDJSON stream and a golden test are all sinks.
/// Every method but [`Sink::tool`] may stop the run, saying why.
pub trait Sink {
    fn line(&mut self, text: &str, block: Option<&BlockInfo>) -> Result<(), Stop>;
    /// A diagnostic not attached to a block (reader problems, program-level notes).
    fn diagnostic(&mut self, _d: &Diagnostic) -> Result<(), Stop> {
        Ok(())
    }
    /// A diagnostic about a CL pose (part frame, profile units) that got no block.
    fn diagnostic_at(&mut self, d: &Diagnostic, _pose: &Pose) -> Result<(), Stop> {
        self.diagnostic(d)
    }
    fn summary(&mut self, _s: &Summary) -> Result<(), Stop> {
        Ok(())
    }
    /// The tool in the spindle from motion block `first_block` on (its length in force, its
    /// cutter and holder as the collision check sees them): what a preview draws.
    fn tool(&mut self, _first_block: u64, _t: &crate::collide::ToolShape) {}
    /// Whether the run should stop now, though nothing is being written, and why: whoever
    /// reads the output has gone (a client that left), the job was cancelled. The engine looks
    /// between CL items and between the samples of a collision check, so a run stops within a
    /// second of it rather than at its next write, which a long check can hold back for minutes.
    fn halted(&mut self) -> Option<Stop> {
        None
    }
}

/// NC text to any writer, one line each.
pub struct TextSink<W: std::io::Write>(pub W);

impl<W: std::io::Write> Sink for TextSink<W> {
    fn line(&mut self, text: &str, _b: Option<&BlockInfo>) -> Result<(), Stop> {
        self.0.write_all(text.as_bytes())?;
        Ok(self.0.write_all(b"\n")?)
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

/// One tool's length in a program, and where it came from.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ToolUse {
    /// `None`: before any tool change.
    pub tool: Option<u32>,
    pub length: f64,
    pub from: crate::post::tools::LengthFrom,
}

#[derive(Clone, Debug, Default, Serialize)]
pub struct Summary {
    pub machine: String,
    pub mode: Option<Mode>,
    pub units: String,
    pub cl_units: String,
    pub cl_units_source: String,
    /// The tool length in force at the end.
    pub tool_length: f64,
    /// Each tool's length and where it came from, in the order the tools were loaded (a tool
    /// whose length changed has a line per length).
    pub tools: Vec<ToolUse>,
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
