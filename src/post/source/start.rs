//! The start of a CL: the look-ahead that finds the units it starts in, and refuses what is no
//! CL (NC, nothing recognisable) or a lathe's program, before anything is written.

use super::{Error, NC_VERDICT, UNITS_LOOKAHEAD};
use crate::cl::{Event, FeedUnit, Reader, Record};
use crate::diag::{Code, Diagnostic, Severity};
use crate::kinematics::Units;
use std::collections::VecDeque;
use std::io::BufRead;

/// What the look-ahead found: the units the CL starts in, and whether it is CL at all.
pub(super) struct Start {
    pub(super) ahead: VecDeque<Event>,
    pub(super) units: Units,
    pub(super) source: &'static str,
    /// A `UNITS` record its own values contradict (`units_assumed`), told before anything.
    pub(super) told: Option<Diagnostic>,
}

/// Inch values wider than this (3 m) are read as millimetres written under `UNITS/INCHES`: no
/// mill kinepost posts for moves a part that wide, and 120 mm is an ordinary part.
const INCH_SPAN_MAX: f64 = 120.0;
/// Millimetre values that all fit in this (with at least [`SPAN_POINTS`] moves) are read as
/// metres written under `UNITS/MM`: a whole program's motion inside half a millimetre.
const MM_SPAN_MIN: f64 = 0.5;
const SPAN_POINTS: u32 = 10;
/// How far off the plane through the spindle axis a turning point may be (CL units).
const PLANE_TOL: f64 = 1e-4;

/// What the look-ahead sees of the motion itself: the extent of the points (a `UNITS` their
/// magnitudes contradict) and whether the cutting moves are a lathe's (fed per revolution, in
/// one plane through the spindle axis, with no milling tool).
#[derive(Default)]
struct Shape {
    lo: [f64; 3],
    hi: [f64; 3],
    points: u32,
    rapid_next: bool,
    per_rev: bool,
    /// A hole cycle is on: its points are holes, not a path (taps fed per revolution, holes in
    /// a row through the origin are no lathe's).
    cycle: bool,
    /// A cutting move that is no lathe's was seen (fed per minute, off the plane, a milling
    /// tool): the program is milling, whatever follows.
    milling: bool,
    /// The plane's direction in XY, from the first point off the axis.
    radial: Option<[f64; 2]>,
    /// Cutting moves in the plane, those of them that change the radius (a drill's plunges on
    /// the axis do not), and the first one's line.
    cuts: u32,
    turned: u32,
    first_cut: u32,
    last: Option<[f64; 3]>,
}

impl Shape {
    fn see(&mut self, r: &Record, line: u32) {
        match r {
            Record::Rapid => self.rapid_next = true,
            Record::Cycle(_) => self.cycle = true,
            Record::CycleOff => self.cycle = false,
            Record::Goto { .. } if self.cycle => {}
            Record::Feedrate { unit, .. } => self.per_rev = *unit == FeedUnit::PerRev,
            Record::ToolData { turning: Some(false), .. } => self.milling = true,
            Record::Goto { p, .. } => self.point(*p, line),
            _ => {}
        }
    }

    fn point(&mut self, p: [f64; 3], line: u32) {
        let rapid = std::mem::take(&mut self.rapid_next);
        if p.iter().any(|v| !v.is_finite()) {
            return;
        }
        for k in 0..3 {
            (self.lo[k], self.hi[k]) = match self.points {
                0 => (p[k], p[k]),
                _ => (self.lo[k].min(p[k]), self.hi[k].max(p[k])),
            };
        }
        self.points += 1;
        let last = self.last.replace(p);
        let r = p[0].hypot(p[1]);
        if self.radial.is_none() && r > PLANE_TOL {
            self.radial = Some([p[0] / r, p[1] / r]);
        }
        let off = self.radial.is_some_and(|[u, v]| (p[0] * v - p[1] * u).abs() > PLANE_TOL);
        if rapid || self.milling {
            self.milling |= off;
            return;
        }
        if !self.per_rev || off {
            self.milling = true;
            return;
        }
        self.cuts += 1;
        if self.cuts == 1 {
            self.first_cut = line;
        }
        if last.is_some_and(|q| (q[0].hypot(q[1]) - r).abs() > PLANE_TOL) {
            self.turned += 1;
        }
    }

    /// Whether more motion could still change a verdict.
    fn open(&self, units: Option<Units>) -> bool {
        let span = self.span();
        !self.milling || units == Some(Units::Inch) && span <= INCH_SPAN_MAX || units == Some(Units::Mm) && span < MM_SPAN_MIN
    }

    fn span(&self) -> f64 {
        (0..3).map(|k| self.hi[k] - self.lo[k]).fold(0.0, f64::max)
    }

    /// A lathe's cutting moves: fed per revolution in one plane through the spindle axis,
    /// changing the radius, with no milling move or tool among them.
    fn turning(&self) -> Option<u32> {
        (!self.milling && self.cuts >= 3 && self.turned >= 1).then_some(self.first_cut)
    }

    /// A `UNITS` record at `line` that the values read under it contradict.
    fn contradicts(&self, u: Units, line: u32) -> Option<Diagnostic> {
        let span = self.span();
        let (looks, taken) = match u {
            Units::Inch if span > INCH_SPAN_MAX => ("millimetres", format!("{:.1} m", span * 0.0254)),
            Units::Mm if self.points >= SPAN_POINTS && span < MM_SPAN_MIN => ("metres", format!("{span} mm")),
            _ => return None,
        };
        let msg = format!(
            "UNITS/{} here, yet its first {} moves already span {taken}: values that look like {looks}; taken in {} as the record says (check the CAM system's output units)",
            if u == Units::Inch { "INCHES" } else { "MM" },
            self.points,
            u.as_str()
        );
        Some(Diagnostic::new(Code::UnitsAssumed, Severity::Warning, Some(line), msg))
    }
}

/// Reads ahead to the units the CL starts in: a UNITS record before the first motion decides
/// them; one after motion applies from its line only (the same program wherever it sits), so
/// the start is the caller's `cl_units`, else the first unit-bearing FEDRAT before it, else the
/// profile's, assumed. Input with no CL record in the look-ahead is refused here, before
/// anything is written. While the motion could still show a lathe's program or a `UNITS` its
/// values contradict ([`Shape`]), it reads on, within the same bound: a milling program in
/// millimetres is decided at its first cut, an inch one at the bound or its end.
pub(super) fn look_ahead<R: BufRead>(
    reader: &mut Reader<R>,
    profile_units: Units,
    cl_units: Option<Units>,
) -> Result<Start, Error> {
    let mut ahead = VecDeque::new();
    let (mut units_rec, mut units_seen, mut moved, mut cl) = (None, false, false, false);
    let mut units_line = 0;
    let mut shape = Shape::default();
    let mut feed_hint: Option<Units> = None;
    let mut first_diag: Option<Diagnostic> = None;
    // A lathe's record before the first move, where it stands: a turning program.
    let mut lathe: Option<(u32, &str)> = None;
    // Statements bound it too: a word told once is not an event each time it comes.
    while ahead.len() < UNITS_LOOKAHEAD && reader.statements() < UNITS_LOOKAHEAD as u64 {
        let decided = units_seen || moved && (cl_units.is_some() || feed_hint.is_some());
        if cl && decided && moved && !shape.open(units_rec) || !cl && reader.nc_seen().blocks >= NC_VERDICT {
            break;
        }
        let Some(ev) = reader.next_event()? else { break };
        match &ev {
            Event::Statement(s) => {
                shape.see(&s.record, s.line);
                // `END` alone is no evidence: Heidenhain's `END PGM` reads as one.
                cl |= !matches!(s.record, Record::End);
                match &s.record {
                    Record::Units(u) if !units_seen => {
                        units_seen = true;
                        units_rec = (!moved).then_some(*u);
                        units_line = s.line;
                    }
                    Record::Feedrate { units: Some(u), .. } if !units_seen && feed_hint.is_none() => feed_hint = Some(*u),
                    Record::Goto { .. } | Record::GoDelta { .. } | Record::From { .. } if !moved => {
                        moved = true;
                        if let Some((at, what)) = lathe {
                            return Err(Error::NotCl(turning(at, what, s.line)));
                        }
                    }
                    Record::ToolData { turning: Some(t), .. } | Record::Mode { turning: t } if !moved => {
                        lathe = t.then(|| {
                            (
                                s.line,
                                if matches!(s.record, Record::Mode { .. }) {
                                    "MODE/TURN"
                                } else {
                                    "a lathe tool"
                                },
                            )
                        });
                    }
                    _ => {}
                }
            }
            // A record the reader knew but could not read is CL all the same.
            Event::Diagnostic(d) => {
                cl |= d.code == Code::BadRecord;
                first_diag.get_or_insert_with(|| d.clone());
            }
        }
        ahead.push_back(ev);
    }
    if !cl {
        return Err(Error::NotCl(not_cl(reader, first_diag, ahead.len())));
    }
    if let Some(at) = shape.turning() {
        let d = turning_motion(at);
        return Err(Error::NotCl(d));
    }
    let told = units_rec.and_then(|u| shape.contradicts(u, units_line));
    let (units, source) = units_rec
        .map(|u| (u, "UNITS record"))
        .or(cl_units.map(|u| (u, "option")))
        .or(feed_hint.map(|u| (u, "FEDRAT unit")))
        .unwrap_or((profile_units, "assumed: the profile's"));
    Ok(Start { ahead, units, source, told })
}

/// Why a turning program is refused: kinepost posts milling.
fn turning(at: u32, what: &str, first_move: u32) -> Diagnostic {
    let msg = format!(
        "a turning program ({what} at line {at}, its first move at line {first_move}): kinepost posts milling, and a lathe's moves on a mill are a crash; nothing written"
    );
    Diagnostic::new(Code::Turning, Severity::Error, Some(at), msg)
}

/// Why a program whose cutting moves are a lathe's, though no record names a lathe tool, is
/// refused: as milling, its moves would be a crash all the same.
fn turning_motion(at: u32) -> Diagnostic {
    let msg = format!(
        "a turning program (its cutting moves from line {at} fed per revolution in one plane through the spindle axis, no milling tool): kinepost posts milling, and a lathe's moves on a mill are a crash; nothing written"
    );
    Diagnostic::new(Code::Turning, Severity::Error, Some(at), msg)
}

/// Why input with no CL record is refused: what it looks like, where.
fn not_cl<R: BufRead>(reader: &Reader<R>, first: Option<Diagnostic>, read: usize) -> Diagnostic {
    let what = "not CL data (APT/CLSF): post the CL file the CAM system wrote, not an NC program";
    let first = first.or_else(|| reader.first_held().cloned());
    let (line, message) = match (&reader.nc_seen().first, first) {
        (Some((kind, line, text)), _) => (
            Some(*line),
            format!(
                "this looks like {} ({} at line {line}), {what}",
                kind.name(),
                crate::text::quote(text)
            ),
        ),
        (None, Some(d)) => {
            let within = if read >= UNITS_LOOKAHEAD {
                format!(" in its first {read} statements")
            } else {
                String::new()
            };
            let at = d.line.map(|l| format!("line {l}: ")).unwrap_or_default();
            (d.line, format!("nothing in the input is CL data{within} ({at}{})", d.message))
        }
        (None, None) => (None, "the input holds no CL data: it is empty (or comments only)".into()),
    };
    Diagnostic::new(Code::NotCl, Severity::Error, line, message)
}
