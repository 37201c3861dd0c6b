//! The start of a CL: the look-ahead that finds the units it starts in, and refuses what is no
//! CL (NC, nothing recognisable) or a lathe's program, before anything is written.

use super::{Error, NC_VERDICT, UNITS_LOOKAHEAD};
use crate::cl::{Event, Reader, Record};
use crate::diag::{Code, Diagnostic, Severity};
use crate::kinematics::Units;
use std::collections::VecDeque;
use std::io::BufRead;

/// What the look-ahead found: the units the CL starts in, and whether it is CL at all.
pub(super) struct Start {
    pub(super) ahead: VecDeque<Event>,
    pub(super) units: Units,
    pub(super) source: &'static str,
}

/// Reads ahead to the units the CL starts in: a UNITS record before the first motion decides
/// them; one after motion applies from its line only (the same program wherever it sits), so
/// the start is the caller's `cl_units`, else the first unit-bearing FEDRAT before it, else the
/// profile's, assumed. Input with no CL record in the look-ahead is refused here, before
/// anything is written.
pub(super) fn look_ahead<R: BufRead>(
    reader: &mut Reader<R>,
    profile_units: Units,
    cl_units: Option<Units>,
) -> Result<Start, Error> {
    let mut ahead = VecDeque::new();
    let (mut units_rec, mut units_seen, mut moved, mut cl) = (None, false, false, false);
    let mut feed_hint: Option<Units> = None;
    let mut first_diag: Option<Diagnostic> = None;
    // A lathe's record before the first move, where it stands: a turning program.
    let mut lathe: Option<(u32, &str)> = None;
    // Statements bound it too: a word told once is not an event each time it comes.
    while ahead.len() < UNITS_LOOKAHEAD && reader.statements() < UNITS_LOOKAHEAD as u64 {
        let decided = units_seen || moved && (cl_units.is_some() || feed_hint.is_some());
        if cl && decided && moved || !cl && reader.nc_seen().blocks >= NC_VERDICT {
            break;
        }
        let Some(ev) = reader.next_event()? else { break };
        match &ev {
            Event::Statement(s) => {
                // `END` alone is no evidence: Heidenhain's `END PGM` reads as one.
                cl |= !matches!(s.record, Record::End);
                match &s.record {
                    Record::Units(u) if !units_seen => {
                        units_seen = true;
                        units_rec = (!moved).then_some(*u);
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
    let (units, source) = units_rec
        .map(|u| (u, "UNITS record"))
        .or(cl_units.map(|u| (u, "option")))
        .or(feed_hint.map(|u| (u, "FEDRAT unit")))
        .unwrap_or((profile_units, "assumed: the profile's"));
    Ok(Start { ahead, units, source })
}

/// Why a turning program is refused: kinepost posts milling.
fn turning(at: u32, what: &str, first_move: u32) -> Diagnostic {
    let msg = format!(
        "a turning program ({what} at line {at}, its first move at line {first_move}): kinepost posts milling, and a lathe's moves on a mill are a crash; nothing written"
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
