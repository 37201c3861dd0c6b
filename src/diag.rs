//! Diagnostics: data, not errors. Every stage (reader, planner, writer) reports what it noticed
//! as a `Diagnostic` with a stable code, and carries on.

use serde::{Deserialize, Serialize};

// Deserialize: a job's block store keeps a block's diagnostics as their JSON and reads them back.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Severity {
    Info,
    Warning,
    Error,
}

/// Stable codes: tools and tests match on these, so never rename one.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Code {
    BadRecord,
    UnknownRecord,
    IgnoredRecord,
    UnitsAssumed,
    AxisNormalized,
    LineTooLong,
    InvalidUtf8,
    Unreachable,
    LimitViolation,
    NearLimit,
    Singular,
    BranchChange,
    Unwind,
    Linearized,
    FeedClamped,
    NoFeed,
    NoMotion,
    AngleCompOutOfRange,
    VerifyDeviation,
    ArcLinearized,
    CycleExpanded,
    /// A hole that is only ever the control's cycle (a tap, a bore that stops or orients the
    /// spindle) and cannot be one here: not machined, an error at its line.
    CycleRefused,
    SurfaceSpeed,
    SpindleSpeed,
    SpindleStopped,
    CoolantRestored,
    ToolLength,
    TableIndex,
    /// A number beyond what the control's word takes (F, S, T, H, dwell).
    WordRange,
    /// A UNITS record after motion changes the units in force.
    UnitsChanged,
    /// The input is no CL data (NC, or nothing recognisable): refused.
    NotCl,
    /// A coordinate-system record (`MSYS`, …): what the points after it are taken in.
    CoordinateSystem,
    /// A word the dialect's control does not know (a profile's clamp M code on LinuxCNC).
    UnknownWord,
    /// Cutter radius compensation (`CUTCOM`): what it is taken to mean, or why it is not written.
    CutterComp,
    /// A dialect's template for a program event failed to render (out of fuel, a filter on the
    /// wrong kind of value): nothing written for the event.
    Template,
    /// Two of the machine's bodies (the tool, the stock) overlap at a block or between blocks.
    Collision,
    /// Two bodies come closer than the collision clearance.
    NearCollision,
    /// The motion to a block needed more samples than the collision check takes for one block:
    /// between two a body moves farther than the clearance or half the smallest body's size.
    CollisionCoarse,
    /// A turning (lathe) program or operation: kinepost posts milling.
    Turning,
}

impl Code {
    pub fn as_str(self) -> &'static str {
        match self {
            Code::BadRecord => "bad_record",
            Code::UnknownRecord => "unknown_record",
            Code::IgnoredRecord => "ignored_record",
            Code::UnitsAssumed => "units_assumed",
            Code::AxisNormalized => "axis_normalized",
            Code::LineTooLong => "line_too_long",
            Code::InvalidUtf8 => "invalid_utf8",
            Code::Unreachable => "unreachable",
            Code::LimitViolation => "limit_violation",
            Code::NearLimit => "near_limit",
            Code::Singular => "singular",
            Code::Collision => "collision",
            Code::NearCollision => "near_collision",
            Code::BranchChange => "branch_change",
            Code::Unwind => "unwind",
            Code::Linearized => "linearized",
            Code::FeedClamped => "feed_clamped",
            Code::NoFeed => "no_feed",
            Code::NoMotion => "no_motion",
            Code::AngleCompOutOfRange => "angle_comp_out_of_range",
            Code::VerifyDeviation => "verify_deviation",
            Code::ArcLinearized => "arc_linearized",
            Code::CycleExpanded => "cycle_expanded",
            Code::CycleRefused => "cycle_refused",
            Code::SurfaceSpeed => "surface_speed",
            Code::SpindleSpeed => "spindle_speed",
            Code::WordRange => "word_range",
            Code::SpindleStopped => "spindle_stopped",
            Code::CoolantRestored => "coolant_restored",
            Code::ToolLength => "tool_length",
            Code::TableIndex => "table_index",
            Code::UnitsChanged => "units_changed",
            Code::NotCl => "not_cl",
            Code::CoordinateSystem => "coordinate_system",
            Code::UnknownWord => "unknown_word",
            Code::CutterComp => "cutter_comp",
            Code::Template => "template",
            Code::CollisionCoarse => "collision_coarse",
            Code::Turning => "turning",
        }
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Diagnostic {
    pub code: Code,
    pub severity: Severity,
    /// 1-based line of the CL source, where the diagnostic has one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub line: Option<u32>,
    /// 1-based column in that line.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub column: Option<u32>,
    pub message: String,
    /// What a `collision` or `near_collision` message says, for a reader that draws it (the
    /// preview); NDJSON carries the message only.
    #[serde(skip)]
    pub bodies: Option<Box<Bodies>>,
}

/// The two bodies a collision names and their distance (negative: the overlap's depth), profile
/// units.
#[derive(Clone, Debug, PartialEq)]
pub struct Bodies {
    pub a: String,
    pub b: String,
    pub distance: f64,
}

impl Diagnostic {
    pub fn new(code: Code, severity: Severity, line: Option<u32>, message: impl Into<String>) -> Diagnostic {
        Diagnostic {
            code,
            severity,
            line,
            column: None,
            message: message.into(),
            bodies: None,
        }
    }

    pub fn at(mut self, column: u32) -> Diagnostic {
        self.column = Some(column);
        self
    }
}

impl std::fmt::Display for Diagnostic {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let sev = match self.severity {
            Severity::Info => "info",
            Severity::Warning => "warning",
            Severity::Error => "error",
        };
        match (self.line, self.column) {
            (Some(l), Some(c)) => write!(f, "{sev}[{}] line {l}, column {c}: {}", self.code.as_str(), self.message),
            (Some(l), None) => write!(f, "{sev}[{}] line {l}: {}", self.code.as_str(), self.message),
            _ => write!(f, "{sev}[{}]: {}", self.code.as_str(), self.message),
        }
    }
}
