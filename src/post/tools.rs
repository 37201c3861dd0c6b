//! Which tool length is in force, tool by tool. In joint mode on a head machine every X Y Z
//! depends on it, so `post` and `verify` both ask this one place: the job's single length, else
//! the tool table's entry for the tool loaded, else the length the CL gives, else the profile's.

use crate::diag::{Code, Diagnostic, Severity};
use crate::kinematics::Units;
use crate::machines::tools::ToolTable;
use serde::Serialize;

/// Where a tool length came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum LengthFrom {
    /// The job's `tool_length`: one length for every tool.
    Job,
    /// The tool table (the job's own, or the machine's).
    Table,
    /// The CL (`TLDATA`, `LOADTL/n,LENGTH,l`, `CUTTER` with a length).
    Cl,
    /// The profile's `[tool] default_length`.
    Profile,
}

impl LengthFrom {
    /// The words of the NC comment and the summary.
    pub fn as_str(self) -> &'static str {
        match self {
            LengthFrom::Job => "the job",
            LengthFrom::Table => "the tool table",
            LengthFrom::Cl => "the CL",
            LengthFrom::Profile => "the profile",
        }
    }
}

/// What a CL record changes: a new length in force (now), and a diagnostic to tell.
#[derive(Debug, Default)]
pub struct Step {
    pub set: Option<(f64, LengthFrom)>,
    pub diag: Option<Diagnostic>,
}

/// The per-tool length resolution, fed the CL's tool records in order.
pub struct Lengths<'a> {
    units: Units,
    fixed: Option<f64>,
    table: Option<&'a ToolTable>,
    default: f64,
    /// The tool in the spindle, and the distinct tools loaded so far (for the one warning).
    tool: Option<u32>,
    distinct: u32,
    warned_fixed: bool,
    /// The CL's last length, and the one it gave since the last tool change (with its line).
    cl: Option<f64>,
    cl_since: Option<(f64, u32)>,
    /// With a table, a CL length given before any tool is loaded: the tool change it precedes
    /// weighs it, or else the first move takes it.
    waiting: Option<f64>,
    /// The length in force now and where it came from.
    pub length: f64,
    pub from: LengthFrom,
}

impl<'a> Lengths<'a> {
    /// `fixed`: the job's one length; `table` in its own units, read in the profile's `units`.
    pub fn new(units: Units, fixed: Option<f64>, table: Option<&'a ToolTable>, default: f64) -> Self {
        Lengths {
            units,
            fixed,
            table,
            default,
            tool: None,
            distinct: 0,
            warned_fixed: false,
            cl: None,
            cl_since: None,
            waiting: None,
            length: fixed.unwrap_or(default),
            from: if fixed.is_some() {
                LengthFrom::Job
            } else {
                LengthFrom::Profile
            },
        }
    }

    /// The CL gives a length (profile units): in force now unless the job's length or the
    /// table's entry for the tool in the spindle governs. NX gives the next tool's `TLDATA`
    /// before its `LOAD/TOOL`, so with a table it waits for the tool change to be weighed.
    pub fn cl_length(&mut self, l: f64, line: u32) -> Step {
        self.cl = Some(l);
        self.cl_since = Some((l, line));
        let table_tool = self.tool.is_some_and(|n| self.table.is_some_and(|t| t.get(n).is_some()));
        if self.fixed.is_some() || table_tool {
            return Step::default();
        }
        if self.table.is_some() && self.tool.is_none() {
            self.waiting = Some(l);
            return Step::default();
        }
        self.set(l, LengthFrom::Cl)
    }

    /// Whether the next move must ask [`Lengths::motion`] first (rarely: a CL length with a
    /// table and no tool loaded).
    pub fn waiting(&self) -> bool {
        self.waiting.is_some()
    }

    /// A move before any tool change: the CL's length given before it is in force.
    pub fn motion(&mut self) -> Step {
        match self.waiting.take() {
            Some(l) => self.set(l, LengthFrom::Cl),
            None => Step::default(),
        }
    }

    /// A tool change to `number` at CL `line`.
    pub fn tool(&mut self, number: u32, line: u32) -> Step {
        if self.tool == Some(number) {
            return Step::default(); // loaded again: no change
        }
        self.tool = Some(number);
        self.distinct += 1;
        self.waiting = None;
        let since = self.cl_since.take();
        if let Some(l) = self.fixed {
            if self.distinct == 2 && !self.warned_fixed && (self.table.is_some() || self.cl.is_some()) {
                self.warned_fixed = true;
                let own = if self.table.is_some() {
                    "the tool table's"
                } else {
                    "the CL's"
                };
                return Step {
                    set: None,
                    diag: Some(Diagnostic::new(
                        Code::ToolLength,
                        Severity::Warning,
                        Some(line),
                        format!(
                            "the job's tool length {l} is one length for every tool: tool {number} is cut with it too, not with {own}; give a tool table instead for a program of several tools"
                        ),
                    )),
                };
            }
            return Step::default();
        }
        let Some(table) = self.table else {
            return Step::default(); // the CL's length in force stays, as it always has
        };
        match table.length(number, self.units) {
            Some(len) => {
                let mut s = self.set(len, LengthFrom::Table);
                if let Some((l, at)) = since.filter(|(l, _)| (l - len).abs() > 1e-9 * (1.0 + len)) {
                    s.diag = Some(Diagnostic::new(
                        Code::ToolLength,
                        Severity::Info,
                        Some(line),
                        format!("tool {number}: the tool table's length {len} is used, not the CL's {l} (line {at})"),
                    ));
                }
                s
            }
            None => {
                let (len, from) = match self.cl {
                    Some(l) => (l, LengthFrom::Cl),
                    None => (self.default, LengthFrom::Profile),
                };
                let mut s = self.set(len, from);
                s.diag = Some(Diagnostic::new(
                    Code::ToolLength,
                    Severity::Warning,
                    Some(line),
                    format!(
                        "tool {number} is not in the tool table: cut with {} length {len}",
                        from.as_str()
                    ),
                ));
                s
            }
        }
    }

    /// The tool in the spindle, if one was loaded.
    pub fn tool_number(&self) -> Option<u32> {
        self.tool
    }

    fn set(&mut self, l: f64, from: LengthFrom) -> Step {
        self.length = l;
        self.from = from;
        Step {
            set: Some((l, from)),
            diag: None,
        }
    }
}

/// Most tool loads a first pass keeps (`load_order`): beyond them no tool is readied.
const MAX_LOADS: usize = 100_000;

/// The tools the CL loads, in order (the tool in the spindle loaded again left out, as the
/// emitter writes no change for it): a first pass over a CL that can be read twice, so that
/// `preselect` `next` readies each next tool right after a change.
pub(super) fn load_order<R: std::io::BufRead>(input: R) -> Result<Vec<u32>, crate::cl::Error> {
    let mut reader = crate::cl::Reader::new(input);
    let mut order = Vec::new();
    while let Some(ev) = reader.next_event()? {
        if let crate::cl::Event::Statement(s) = ev
            && let crate::cl::Record::LoadTool { number, .. } = s.record
            && order.last() != Some(&number)
            && order.len() < MAX_LOADS
        {
            order.push(number);
        }
    }
    Ok(order)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::machines::tools::parse_tool_table;

    fn table() -> ToolTable {
        parse_tool_table(
            "units = \"mm\"\n[[tool]]\nnumber = 1\nlength = 80\n[[tool]]\nnumber = 2\nlength = 120\n",
            "t",
        )
        .unwrap()
    }

    /// The precedence, tool by tool: job > table > CL > profile.
    #[test]
    fn precedence() {
        let t = table();
        // The job's length wins over everything, and a second tool with its own length is told.
        let mut l = Lengths::new(Units::Mm, Some(50.0), Some(&t), 100.0);
        assert!(l.cl_length(70.0, 1).set.is_none());
        assert!(l.tool(1, 2).set.is_none());
        let s = l.tool(2, 9);
        assert!(
            s.set.is_none()
                && s.diag
                    .as_ref()
                    .is_some_and(|d| d.severity == Severity::Warning && d.line == Some(9))
        );
        assert_eq!((l.length, l.from), (50.0, LengthFrom::Job));
        // The table's entry over the CL's, told as info; a tool not in it: the CL's, with a warning.
        let mut l = Lengths::new(Units::Mm, None, Some(&t), 100.0);
        assert_eq!(l.tool(7, 1).set, Some((100.0, LengthFrom::Profile)));
        assert_eq!(l.cl_length(70.0, 1).set, Some((70.0, LengthFrom::Cl)));
        let s = l.tool(2, 2);
        assert_eq!(s.set, Some((120.0, LengthFrom::Table)));
        assert!(s.diag.is_some_and(|d| d.severity == Severity::Info));
        assert!(l.cl_length(75.0, 3).set.is_none(), "tool 2 is the table's");
        let s = l.tool(7, 4);
        assert_eq!(s.set, Some((75.0, LengthFrom::Cl)));
        assert!(
            s.diag
                .is_some_and(|d| d.severity == Severity::Warning && d.line == Some(4) && d.message.contains("tool 7"))
        );
        // No CL length and no entry: the profile's.
        let mut l = Lengths::new(Units::Mm, None, Some(&t), 100.0);
        assert_eq!(l.tool(9, 1).set, Some((100.0, LengthFrom::Profile)));
        assert_eq!(l.tool(1, 2).set, Some((80.0, LengthFrom::Table)));
        assert!(l.tool(1, 3).set.is_none(), "the same tool again");
        // A CL length before any tool waits for the tool change, else for the first move.
        let mut l = Lengths::new(Units::Mm, None, Some(&t), 100.0);
        assert!(l.cl_length(70.0, 1).set.is_none() && l.waiting());
        assert_eq!(l.motion().set, Some((70.0, LengthFrom::Cl)));
        let mut l = Lengths::new(Units::Mm, None, Some(&t), 100.0);
        assert!(l.cl_length(70.0, 1).set.is_none());
        assert_eq!(l.tool(1, 2).set, Some((80.0, LengthFrom::Table)));
        assert!(!l.waiting());
        // No table: the CL's length in force, as before.
        let mut l = Lengths::new(Units::Mm, None, None, 100.0);
        assert_eq!(l.cl_length(70.0, 1).set, Some((70.0, LengthFrom::Cl)));
        assert!(l.tool(2, 2).set.is_none());
        assert_eq!(l.length, 70.0);
    }

    #[test]
    fn a_table_in_inches_is_read_in_the_profile_units() {
        let t = parse_tool_table("units = \"inch\"\n[[tool]]\nnumber = 4\nlength = 4\n", "t").unwrap();
        let mut l = Lengths::new(Units::Mm, None, Some(&t), 100.0);
        let (len, _) = l.tool(4, 1).set.unwrap();
        assert!((len - 101.6).abs() < 1e-9);
    }
}
