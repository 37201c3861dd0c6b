//! `CYCLE/` records: a drilling cycle's values by keyword (`FEDTO`, `RAPTO`, …) or, as CAMWorks
//! writes them, by position around the keywords.

use super::{Arg, CycleKind, CycleParams, FeedUnit, Record, num};
use crate::diag::{Code, Diagnostic, Severity};
use crate::kinematics::Units;

/// `CYCLE/kind,…`: its values by keyword (`FEDTO`, `RAPTO`, …) or, as CAMWorks writes them,
/// by position around the keywords.
pub(in crate::cl) fn parse_cycle(args: &[Arg], line: u32, rest_col: u32, diags: &mut Vec<Diagnostic>) -> Option<Record> {
    let first = args.first().map(Arg::word).unwrap_or_default();
    let kind = match first.as_str() {
        "OFF" => return Some(Record::CycleOff),
        "INIT" | "ON" | "" => return Some(Record::Ignored("CYCLE".into())),
        "DRILL" | "FACE" | "CSINK" => CycleKind::Drill,
        "DEEP" | "DEEP2" | "PECK" => CycleKind::Deep,
        "BRKCHP" => CycleKind::BreakChip,
        "TAP" | "RGDTAP" => CycleKind::Tap {
            rigid: first == "RGDTAP",
            left: false,
        },
        "BORE" | "REAM" => CycleKind::Bore,
        _ => CycleKind::Other,
    };
    let mut p = CycleParams {
        kind,
        depth: f64::NAN,
        rapid_to: f64::NAN,
        retract_to: None,
        feed: None,
        peck: None,
        dwell: None,
        shift: None,
    };
    if !iso_positional(args, &mut p) {
        let positional = cycle_keywords(args, line, &mut p, diags);
        cycle_positional(&mut p, &positional);
    }
    let warn = |diags: &mut Vec<Diagnostic>, msg: String| {
        diags.push(Diagnostic::new(Code::BadRecord, Severity::Warning, Some(line), msg).at(rest_col));
    };
    if p.depth.is_nan() {
        warn(diags, format!("CYCLE/{first}: no depth given; holes are positioned only"));
        p.depth = 0.0;
    } else if p.depth < 0.0 {
        // A depth is measured down the tool axis from the hole's point: a negative one would
        // drill upward out of the hole, which no cycle means.
        warn(
            diags,
            format!("CYCLE/{first}: depth {} is negative; holes are positioned only", p.depth),
        );
        p.depth = 0.0;
    }
    Some(Record::Cycle(p))
}

/// A cycle's kind changed by a word after its first: `DRILL,DEEP`, `BORE,DRAG`, `TAP,LEFT`.
fn with_word(kind: CycleKind, word: &str) -> CycleKind {
    match (kind, word) {
        (CycleKind::Drill, "DEEP") => CycleKind::Deep,
        (CycleKind::Drill | CycleKind::Deep, "BRKCHP") => CycleKind::BreakChip,
        (CycleKind::Bore, "DRAG") => CycleKind::BoreStop,
        (CycleKind::Bore, "NODRAG" | "ORIENT") => CycleKind::BoreOrient,
        (CycleKind::Bore, "BACK") => CycleKind::BoreBack,
        (CycleKind::Tap { rigid, .. }, "LEFT" | "CCLW") => CycleKind::Tap { rigid, left: true },
        (CycleKind::Tap { left, .. }, "RIGID") => CycleKind::Tap { rigid: true, left },
        (k, _) => k,
    }
}

/// Sets the values a keyword names (the number after it) and returns the numbers no keyword
/// names, in order.
fn cycle_keywords(args: &[Arg], line: u32, p: &mut CycleParams, diags: &mut Vec<Diagnostic>) -> Vec<f64> {
    let mut positional = Vec::new();
    let mut i = 1;
    while i < args.len() {
        let k = args[i].word();
        // The keyword's value: the argument after it, taken.
        let mut next = || {
            i += 1;
            cycle_value(args, i, line, diags)
        };
        match k.as_str() {
            "FEDTO" | "DEPTH" => p.depth = next().unwrap_or(f64::NAN),
            "RAPTO" | "CLEAR" => p.rapid_to = next().unwrap_or(f64::NAN),
            "RTRCTO" => p.retract_to = next(),
            "1STPECK" | "STEP" => p.peck = next(),
            "DWELL" => p.dwell = next(),
            "SHIFT" => p.shift = next(),
            // The words that say which cycle (NX: `DRILL,DEEP`, `BORE,DRAG`, `TAP,LEFT` …).
            "DEEP" | "BRKCHP" | "DRAG" | "NODRAG" | "ORIENT" | "BACK" | "LEFT" | "CCLW" | "RIGID" => {
                p.kind = with_word(p.kind, &k);
            }
            "MMPM" | "IPM" | "MMPR" | "IPR" => {
                let unit = if k.ends_with("PR") {
                    FeedUnit::PerRev
                } else {
                    FeedUnit::PerMinute
                };
                let units = if k.starts_with("MM") { Units::Mm } else { Units::Inch };
                p.feed = next().map(|f| (f, unit, Some(units)));
            }
            _ => positional.extend(cycle_value(args, i, line, diags)),
        }
        i += 1;
    }
    positional
}

/// CATIA's (ISO 4343's) positional form, `CYCLE/DRILL,depth,[unit],feed,clearance[,retract]`,
/// where an empty field (a continuation line that starts with `,`) is the feed unit left out:
/// read by position, not by the CAMWorks rule, which took the feed for the clearance. Only a
/// record of numbers, one empty field or unit word second, is this form.
fn iso_positional(args: &[Arg], p: &mut CycleParams) -> bool {
    let rest = args.get(1..).unwrap_or_default();
    let unit = rest.get(1).map(Arg::word);
    let is_unit = |w: &str| matches!(w, "" | "MMPM" | "IPM" | "MMPR" | "IPR");
    let v: Vec<Option<f64>> = rest.iter().map(|a| num(a.text)).collect();
    let empty_field = rest.iter().any(|a| a.text.trim().is_empty());
    if !empty_field || !(4..=5).contains(&rest.len()) || !unit.as_deref().is_some_and(is_unit) {
        return false;
    }
    let Some(numbers) = [v[0], v[2], v[3]].into_iter().collect::<Option<Vec<f64>>>() else {
        return false;
    };
    let retract = v.get(4).copied();
    if retract.is_some_and(|r| r.is_none()) {
        return false;
    }
    let (f_unit, units) = match unit.as_deref() {
        Some("MMPR") => (FeedUnit::PerRev, Some(Units::Mm)),
        Some("IPR") => (FeedUnit::PerRev, Some(Units::Inch)),
        Some("MMPM") => (FeedUnit::PerMinute, Some(Units::Mm)),
        Some("IPM") => (FeedUnit::PerMinute, Some(Units::Inch)),
        _ => (FeedUnit::PerMinute, None),
    };
    (p.depth, p.feed, p.rapid_to) = (numbers[0], Some((numbers[1], f_unit, units)), numbers[2]);
    p.retract_to = retract.flatten();
    true
}

/// CAMWorks: DRILL,G98,depth,PECKING,a,b,MMPM,feed,clear,retract — positional around keywords:
/// the first number is the depth, the last two the clearance and retract.
fn cycle_positional(p: &mut CycleParams, positional: &[f64]) {
    if p.depth.is_nan() && !positional.is_empty() {
        p.depth = positional[0];
    }
    if p.rapid_to.is_nan() {
        p.rapid_to = positional
            .get(positional.len().wrapping_sub(2))
            .copied()
            .filter(|_| positional.len() >= 3)
            .unwrap_or(0.0);
        if p.retract_to.is_none() && positional.len() >= 3 {
            p.retract_to = positional.last().copied();
        }
    }
}

/// The number of argument `i`. CAMWorks writes one value as "46.927686 46.927686": the first is
/// taken, with a warning.
fn cycle_value(args: &[Arg], i: usize, line: u32, diags: &mut Vec<Diagnostic>) -> Option<f64> {
    let a = args.get(i)?;
    let t = a.text.trim();
    if let Some(x) = num(t) {
        return Some(x);
    }
    let first = t.split_whitespace().next().and_then(num);
    if first.is_some() {
        let msg = format!("CYCLE: value {t:?} has extra text; used the first number");
        diags.push(Diagnostic::new(Code::BadRecord, Severity::Warning, Some(line), msg).at(a.col));
    }
    first
}

impl CycleKind {
    /// Only ever the control's cycle: never written as moves.
    pub fn canned_only(self) -> bool {
        matches!(
            self,
            CycleKind::Tap { .. } | CycleKind::BoreStop | CycleKind::BoreOrient | CycleKind::BoreBack
        )
    }

    /// What a person calls it, for messages.
    pub fn name(self) -> &'static str {
        match self {
            CycleKind::Drill | CycleKind::Other => "drilling",
            CycleKind::Deep => "deep drilling",
            CycleKind::BreakChip => "chip-breaking drilling",
            CycleKind::Tap { rigid: true, .. } => "rigid tapping",
            CycleKind::Tap { .. } => "tapping",
            CycleKind::Bore => "boring",
            CycleKind::BoreStop => "boring with a spindle stop",
            CycleKind::BoreOrient => "fine boring",
            CycleKind::BoreBack => "back boring",
        }
    }
}
