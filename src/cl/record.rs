//! One CL statement → one [`Record`]. The syntax variety of NX, Creo, SOLIDWORKS CAM / CAMWorks and
//! CATIA: spaces around `/` and `,`, `6.` and `.9625`, units before or after values, free-text
//! records without a slash.
pub(super) mod cycle;
pub mod drive;
pub(super) mod fast;
pub(super) mod flow;
pub(super) mod frames;
pub(super) mod moves;
pub(super) mod tool;

use super::vocabulary::Treatment;
use fast::fast_goto;
use crate::diag::{Code, Diagnostic, Severity};
use crate::kinematics::Units;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FeedUnit {
    /// Length units per minute (MMPM, IPM, or none given).
    PerMinute,
    /// Length units per spindle revolution (MMPR, IPR).
    PerRev,
}

/// APT's `DELAY`: a dwell in seconds, or in spindle revolutions (`DELAY/REV,n`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Dwell {
    Seconds(f64),
    Revolutions(f64),
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SpindleCmd {
    Rpm {
        speed: f64,
        clockwise: bool,
    },
    /// Surface speed; the RPM depends on the tool diameter.
    Surface {
        speed: f64,
        clockwise: bool,
        /// SMM (metres a minute), else SFM (feet a minute).
        metric: bool,
    },
    Off,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CoolantCmd {
    Flood,
    Mist,
    Through,
    Off,
}

/// What a hole cycle does, as a control runs it. A tap and a bore that stops or orients the
/// spindle cannot be written as moves (a rapid out of a tap snaps it, a turning bar drawn out of
/// a bore marks the wall): they are only ever the control's own cycles.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CycleKind {
    /// `DRILL`, `FACE`, `CSINK` (a spot drill with a `DWELL`).
    Drill,
    /// `DEEP`, `DEEP2`, `PECK`: pecks with a full retract.
    Deep,
    /// `BRKCHP`: pecks with a short retract that breaks the chip.
    BreakChip,
    /// `TAP` (a floating holder) and `RGDTAP` (`rigid`, the spindle synchronised with Z);
    /// `left`: a left-hand thread (`LEFT`/`CCLW` in the record, or the spindle turning CCW).
    Tap {
        rigid: bool,
        left: bool,
    },
    /// `BORE`, `REAM`: feed in, feed out (a `DWELL` at the bottom where given).
    Bore,
    /// `BORE,DRAG`: feed in, the spindle stopped at the bottom, rapid out.
    BoreStop,
    /// `BORE,NODRAG` / `ORIENT`: fine bore, the spindle oriented at the bottom and the bar
    /// shifted off the wall (`SHIFT`) before it rapids out.
    BoreOrient,
    /// `BORE,BACK`: back boring, from below the part upward.
    BoreBack,
    Other,
}

/// A drilling cycle: every GOTO while it is on is a hole at that point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CycleParams {
    pub kind: CycleKind,
    /// Depth below the point along the tool axis (FEDTO).
    pub depth: f64,
    /// Rapid to this height above the point (RAPTO).
    pub rapid_to: f64,
    /// Retract to this height above the point (RTRCTO), else `rapid_to`.
    pub retract_to: Option<f64>,
    pub feed: Option<(f64, FeedUnit, Option<Units>)>,
    pub peck: Option<f64>,
    pub dwell: Option<f64>,
    /// A fine bore's shift off the wall at the bottom (`SHIFT`).
    pub shift: Option<f64>,
}

#[derive(Clone, Debug, PartialEq)]
pub enum Record {
    /// Tip point, and the tool axis when the record gives one (else modal).
    Goto {
        p: [f64; 3],
        axis: Option<[f64; 3]>,
    },
    GoDelta {
        d: [f64; 3],
        axis: Option<[f64; 3]>,
    },
    From {
        p: [f64; 3],
        axis: Option<[f64; 3]>,
    },
    /// The next motion only is a rapid.
    Rapid,
    /// `units` is what the record itself says (MMPM → mm, IPM → inch), if anything.
    Feedrate {
        value: f64,
        unit: FeedUnit,
        units: Option<Units>,
    },
    Spindle(SpindleCmd),
    Coolant(CoolantCmd),
    LoadTool {
        number: u32,
        length: Option<f64>,
        /// The length offset register (`ADJUST,m` or `OSETNO,m`) where it is not the tool's
        /// number: the H word.
        adjust: Option<u32>,
    },
    ToolData {
        diameter: Option<f64>,
        /// The cutter's corner radius (`TLDATA/MILL,d,r,…`, `CUTTER/d,r`).
        corner_radius: Option<f64>,
        length: Option<f64>,
        /// `TURN` (a lathe tool: its diameter is no cutting diameter) or `MILL`/`DRILL` in
        /// `TLDATA`/`TOOLNO`; `None` where the record does not say (CUTTER).
        turning: Option<bool>,
    },
    Units(Units),
    Multax(bool),
    ToolAxis([f64; 3]),
    Delay(Dwell),
    /// `ROTABL/a,AAXIS|BAXIS|CAXIS[,INCR][,TABLE][,CLW|CCLW]`: a rotary indexed to `a` (or by
    /// it, `incr`), in the record's own number: CAMWorks writes radians, ICAM-style APT degrees.
    /// `axis` 0..3 for A..C; `None` where the record names none (CATIA's `ROTABL/0,,TABLE`).
    RotaryTable {
        axis: Option<usize>,
        angle: f64,
        incr: bool,
    },
    /// The next GOTO ends an arc about this centre and axis. `clockwise`: the motion turns
    /// clockwise about the axis (right-hand rule) — NX CLSF's 11-value form; APT from Creo,
    /// SOLIDWORKS CAM and CAMWorks turns counter-clockwise about it. `turns`: NX's `TIMES,n`, a
    /// helix that passes the end's angle n times (n − 1 whole turns before the arc to it).
    Circle {
        center: [f64; 3],
        axis: [f64; 3],
        radius: Option<f64>,
        clockwise: bool,
        turns: u32,
        /// `MOVARC`'s sweep in degrees: the arc that sweeps it is the one meant.
        sweep_deg: Option<f64>,
    },
    /// `CLEARP`/`CLRSRF`: the plane a `RETRCT` withdraws to (none: `OFF`).
    Clearance(Option<moves::Plane>),
    /// `RETRCT`: along the tool axis to the clearance plane.
    Retract,
    Cycle(CycleParams),
    CycleOff,
    /// Operation start (`TOOL PATH/…`) with its name.
    OperationStart(String),
    OperationEnd,
    PartNo(String),
    /// Text to pass through as an NC comment (PPRINT, INSERT).
    Comment(String),
    /// `STOP` (a program stop) or `OPSTOP` (`optional`: the operator's optional stop), with
    /// the operator's instruction where the record gives one (`STOP/(INSTALL TEST STRIP)`).
    Stop { optional: bool, text: String },
    /// `MODE/TURN` or `MODE/LATHE` (`turning`), `MODE/MILL`: what the program's moves are.
    Mode { turning: bool },
    /// `AUXFUN/n` (`M`) or `PREFUN/n` (`G`): a machine function the CAM passes to the control.
    Function { letter: char, code: String },
    /// `OPSKIP/ON|OFF`: the blocks between are skipped with the operator's block delete.
    BlockSkip(bool),
    /// `SELCTL/n`: tool `n` readied for the next change.
    Preselect(u32),
    /// `INTOL/t` (`outer` false) or `OUTTOL/t`: the chordal tolerance the CAM cut the path
    /// to, inside or outside; with `smoothing` `auto` it sets the control's smoothing word.
    Tolerance { outer: bool, value: f64 },
    /// NX's `MSYS`: the operation's machine coordinate system (origin, X and Y axes, all in
    /// NX's absolute frame; unit and square); the points and axes after it are in it.
    Mcs { origin: [f64; 3], x: [f64; 3], y: [f64; 3] },
    /// `CUTCOM`: cutter radius compensation on (a side, a register) or off.
    CutterComp(flow::CutterComp),
    /// The CL says whether its path is the tool centre (`centre`) or the contour: `said`, its
    /// words (Creo's `CUTCOM_GEOMETRY_TYPE` comment).
    PathMeaning { centre: bool, said: String },
    End,
    /// A motion statement with its geometry (`TLON,GOFWD/(CIRCLE/…),ON,(LINE/…)`).
    Drive(drive::Drive),
    /// `GOHOME[/x,y,z[,i,j,k]]`: at rapid to the point, or (none given) to the machine's home.
    GoHome { p: Option<[f64; 3]>, axis: Option<[f64; 3]> },
    /// `INDIRV/i,j,k` (`point`: `INDIRP/x,y,z`, towards it): the next drive's direction.
    InDir { v: [f64; 3], point: bool },
    /// Recognised and not acted on: informational, or told where it stands
    /// ([`super::vocabulary`]).
    Ignored(String),
}


pub(super) struct Arg<'a> {
    pub(super) text: &'a str,
    pub(super) col: u32,
}

impl Arg<'_> {
    /// The argument as a keyword: trimmed, upper-case.
    pub(super) fn word(&self) -> String {
        self.text.trim().to_ascii_uppercase()
    }
}

/// Parses one statement (continuations joined). `None` when the statement yields no record; then
/// `diags` says why.
pub fn parse_statement(stmt: &str, line: u32, diags: &mut Vec<Diagnostic>) -> Option<Record> {
    if let Some(r) = fast_goto(stmt.as_bytes()) {
        return Some(r);
    }
    parse_general(stmt, line, diags)
}

/// The most turns a `CIRCLE/…,TIMES,n` may ask for: a helix of more is a typo, and each turn
/// is blocks.
pub const MAX_CIRCLE_TURNS: u32 = 1000;

/// The lines NX's information listing puts around a CLSF: a header (`Information listing created
/// by`, `Date`, `Current work part`, `Node name`, each a tab and a value) and the trailer `Tool
/// Path Listing has 388 lines.`
fn is_nx_listing(s: &str) -> bool {
    let w: Vec<&str> = s.split_whitespace().collect();
    let starts = |head: &[&str]| w.len() > head.len() && w.iter().zip(head).all(|(a, b)| a == b);
    starts(&["Information", "listing", "created", "by"])
        || starts(&["Date"]) && s.contains('\t')
        || starts(&["Current", "work", "part"])
        || starts(&["Node", "name"])
        || matches!(w.as_slice(), [t, p, l, h, n, e]
            if [*t, *p, *l, *h].iter().zip(["TOOL", "PATH", "LISTING", "HAS"]).all(|(a, b)| a.eq_ignore_ascii_case(b))
                && n.bytes().all(|b| b.is_ascii_digit())
                && e.trim_end_matches('.').eq_ignore_ascii_case("lines"))
}

/// Every statement the long way (the fast path's reference in tests): routed by its major word
/// to the parser of its record family.
fn parse_general(stmt: &str, line: u32, diags: &mut Vec<Diagnostic>) -> Option<Record> {
    let st = Stmt::new(stmt, line);
    match st.major.as_str() {
        "GOTO" | "GODLTA" | "FROM" => motion(&st, diags),
        "GOHOME" if st.args.is_empty() => Some(Record::GoHome { p: None, axis: None }),
        "GOHOME" => match motion(&st, diags)? {
            Record::From { p, axis } => Some(Record::GoHome { p: Some(p), axis }),
            _ => None,
        },
        "TLAXIS" => tool_axis(&st, diags),
        "ROTABL" => rotary_table(&st, diags),
        "RAPID" => Some(Record::Rapid),
        "FEDRAT" => feedrate(&st, diags),
        "SPINDL" => spindle(&st, diags),
        "COOLNT" => coolant(&st, diags),
        "LOADTL" | "LOAD" => tool::load_tool(&st, diags),
        "TLDATA" | "TURRET" | "TOOLNO" | "CUTTER" => Some(tool::tool_data(&st)),
        "CIRCLE" => circle(&st, diags),
        "MOVARC" => moves::movarc(&st, diags),
        "CLEARP" | "CLRSRF" => moves::clearance(&st, diags),
        "RETRCT" => moves::retract(&st, diags),
        "CYCLE" => cycle::parse_cycle(&st.args, line, st.rest_col, diags),
        "UNITS" | "UNIT" => units(&st, diags),
        "MULTAX" => Some(Record::Multax(!matches!(
            st.args.first().map(Arg::word).as_deref(),
            Some("OFF")
        ))),
        "DELAY" | "DWELL" => delay(&st, diags),
        "INDIRV" | "INDIRP" => drive::indir(&st, diags),
        m => match drive::drive_major(m) {
            Some((side, go, word)) => drive::drive(&st, side, go, word, diags),
            None => informational(&st, diags),
        },
    }
}

/// One statement cut at its major word, as every family parser reads it.
pub(super) struct Stmt<'a> {
    /// The statement without its leading blanks, `lead` bytes of them.
    s: &'a str,
    pub(super) lead: u32,
    /// The major word upper-cased, inner runs of blanks made one (`TOOL PATH`).
    pub(super) major: String,
    pub(super) rest: &'a str,
    /// Column (1-based) where `rest` begins: where a record with no usable argument is blamed.
    pub(super) rest_col: u32,
    pub(super) args: Vec<Arg<'a>>,
    pub(super) line: u32,
}

impl<'a> Stmt<'a> {
    /// The major word ends at the `/`, or (free-text records such as `PPRINT text`) at the first
    /// blank.
    fn new(stmt: &'a str, line: u32) -> Stmt<'a> {
        let s = stmt.trim_start();
        let lead = (stmt.len() - s.len()) as u32;
        let (major, rest, rest_col) = match s.find('/') {
            Some(i) => (s[..i].trim(), &s[i + 1..], lead + i as u32 + 2),
            None => {
                let word_end = s.find(char::is_whitespace).unwrap_or(s.len());
                (&s[..word_end], s[word_end..].trim(), lead + word_end as u32 + 2)
            }
        };
        Stmt {
            s,
            lead,
            major: major.split_whitespace().collect::<Vec<_>>().join(" ").to_ascii_uppercase(),
            rest,
            rest_col,
            args: split_args(rest, rest_col),
            line,
        }
    }

    pub(super) fn bad(&self, diags: &mut Vec<Diagnostic>, col: u32, msg: String) {
        diags.push(Diagnostic::new(Code::BadRecord, Severity::Error, Some(self.line), msg).at(col));
    }

    /// A word of the record that kinepost reads past: said, not an error.
    pub(super) fn unused(&self, diags: &mut Vec<Diagnostic>, a: &Arg, w: &str) {
        let msg = format!("{}: {w} not used", self.major);
        diags.push(Diagnostic::new(Code::IgnoredRecord, Severity::Info, Some(self.line), msg).at(a.col));
    }
}

/// `GOTO`, `GODLTA`, `FROM`: a point, and the tool axis where six values give one. Bit for bit
/// what [`fast_goto`] reads, which the tests hold it to.
fn motion(st: &Stmt, diags: &mut Vec<Diagnostic>) -> Option<Record> {
    let major = &st.major;
    let n = st.args.len();
    if !(n == 3 || n >= 6) {
        let col = st.args.last().map_or(st.rest_col, |a| a.col);
        st.bad(
            diags,
            col,
            format!("{major}: expected 3 values (x,y,z) or 6 (x,y,z,i,j,k), found {n}"),
        );
        return None;
    }
    let mut v = [0.0; 6];
    for (k, a) in st.args.iter().take(6).enumerate() {
        let Some(x) = num(a.text).filter(|x| x.is_finite()) else {
            let msg = format!(
                "{major}: expected a finite number as value {}, found {:?}",
                k + 1,
                a.text.trim()
            );
            st.bad(diags, a.col, msg);
            return None;
        };
        v[k] = x;
    }
    if n > 6 {
        // A contact normal or cutter data after i,j,k (3D compensation's input): read past, said.
        let msg = format!(
            "{major}: {} values after x,y,z,i,j,k are not used (no 3D cutter compensation written)",
            n - 6
        );
        diags.push(Diagnostic::new(Code::IgnoredRecord, Severity::Warning, Some(st.line), msg).at(st.args[6].col));
    }
    let p = [v[0], v[1], v[2]];
    let axis = (n >= 6).then_some([v[3], v[4], v[5]]);
    if let Some(a) = axis
        && a.iter().map(|x| x * x).sum::<f64>() < 1e-24
    {
        st.bad(diags, st.args[3].col, format!("{major}: the tool axis (i,j,k) is zero"));
        return None;
    }
    Some(match major.as_str() {
        "GOTO" => Record::Goto { p, axis },
        "GODLTA" => Record::GoDelta { d: p, axis },
        _ => Record::From { p, axis },
    })
}

fn tool_axis(st: &Stmt, diags: &mut Vec<Diagnostic>) -> Option<Record> {
    let v: Vec<f64> = st.args.iter().filter_map(|a| num(a.text)).collect();
    if v.len() >= 3 {
        Some(Record::ToolAxis([v[0], v[1], v[2]]))
    } else {
        st.bad(diags, st.rest_col, "TLAXIS: expected i,j,k".into());
        None
    }
}

fn rotary_table(st: &Stmt, diags: &mut Vec<Diagnostic>) -> Option<Record> {
    let mut angle = None;
    let mut axis = None;
    let mut incr = false;
    for a in &st.args {
        match a.word().as_str() {
            "AAXIS" => axis = Some(0),
            "BAXIS" => axis = Some(1),
            "CAXIS" => axis = Some(2),
            "INCR" => incr = true,
            _ if angle.is_none() => angle = num(a.text),
            _ => {}
        }
    }
    let Some(angle) = angle else {
        // An index that cannot be read leaves the frame of what follows unknown.
        st.bad(diags, st.rest_col, "ROTABL: expected an angle".into());
        return None;
    };
    Some(Record::RotaryTable { axis, angle, incr })
}

fn feedrate(st: &Stmt, diags: &mut Vec<Diagnostic>) -> Option<Record> {
    let mut value = None;
    let mut unit = FeedUnit::PerMinute;
    let mut units = None;
    for a in &st.args {
        match a.word().as_str() {
            "MMPM" => units = Some(Units::Mm),
            "IPM" => units = Some(Units::Inch),
            "MMPR" => (unit, units) = (FeedUnit::PerRev, Some(Units::Mm)),
            "IPR" => (unit, units) = (FeedUnit::PerRev, Some(Units::Inch)),
            "" => {}
            _ => value = Some(feed_value(st, a, value.is_some(), diags)?),
        }
    }
    let Some(value) = value else {
        st.bad(diags, st.rest_col, "FEDRAT: no feed value".into());
        return None;
    };
    Some(Record::Feedrate { value, unit, units })
}

/// The one feed value of a `FEDRAT`; a second value, or anything else, skips the record.
fn feed_value(st: &Stmt, a: &Arg, have_one: bool, diags: &mut Vec<Diagnostic>) -> Option<f64> {
    match num(a.text) {
        Some(x) if x.is_finite() && x > 0.0 && !have_one => Some(x),
        // A zero feed is an alarm on every control, not a move.
        Some(x) if x == 0.0 && !have_one => {
            st.bad(
                diags,
                a.col,
                "FEDRAT: a feed of 0 cannot move the machine: record skipped".into(),
            );
            None
        }
        _ => {
            let msg = format!(
                "FEDRAT: expected a feed value and MMPM, IPM, MMPR or IPR, found {:?}",
                a.text.trim()
            );
            st.bad(diags, a.col, msg);
            None
        }
    }
}

fn spindle(st: &Stmt, diags: &mut Vec<Diagnostic>) -> Option<Record> {
    let mut speed = None;
    let (mut cw, mut surface, mut metric, mut off) = (true, false, false, false);
    for a in &st.args {
        match a.word().as_str() {
            "RPM" => {}
            "SFM" => surface = true,
            "SMM" => (surface, metric) = (true, true),
            "CLW" => cw = true,
            "CCLW" => cw = false,
            "OFF" => off = true,
            "ON" | "" | "RANGE" | "MAXRPM" => {}
            _ => speed = speed.or(Some(spindle_speed(st, a, diags)?)),
        }
    }
    Some(Record::Spindle(match (off, speed, surface) {
        (true, _, _) => SpindleCmd::Off,
        (false, Some(speed), false) => SpindleCmd::Rpm { speed, clockwise: cw },
        (false, Some(speed), true) => SpindleCmd::Surface {
            speed,
            clockwise: cw,
            metric,
        },
        (false, None, _) => {
            st.bad(diags, st.rest_col, "SPINDL: expected a speed or OFF".into());
            return None;
        }
    }))
}

/// A number in a `SPINDL`, which must be a speed: anything else skips the record.
fn spindle_speed(st: &Stmt, a: &Arg, diags: &mut Vec<Diagnostic>) -> Option<f64> {
    let x = num(a.text).filter(|x| x.is_finite() && *x >= 0.0);
    if x.is_none() {
        let msg = format!(
            "SPINDL: expected a speed, RPM, SFM, CLW, CCLW or OFF, found {:?}",
            a.text.trim()
        );
        st.bad(diags, a.col, msg);
    }
    x
}

fn coolant(st: &Stmt, diags: &mut Vec<Diagnostic>) -> Option<Record> {
    let w = st.args.first().map(Arg::word).unwrap_or_default();
    Some(Record::Coolant(match w.as_str() {
        "ON" | "FLOOD" | "" => CoolantCmd::Flood,
        "MIST" => CoolantCmd::Mist,
        "THRU" | "THROUGH" | "TAP" => CoolantCmd::Through,
        "OFF" => CoolantCmd::Off,
        other => {
            let msg = format!("COOLNT: expected ON, FLOOD, MIST, THRU or OFF, found {other:?}");
            st.bad(diags, st.args[0].col, msg);
            return None;
        }
    }))
}

/// Centre, axis[, radius[, tolerances…]], then optional words: SOLIDWORKS CAM leaves the radius
/// out (the next point implies it), NX appends TIMES,n, CAMWorks a direction word that the axis
/// already states (motion is counter-clockwise about it).
fn circle(st: &Stmt, diags: &mut Vec<Diagnostic>) -> Option<Record> {
    let mut v = Vec::with_capacity(11);
    let mut words = Vec::new();
    let mut turns = 1;
    for a in &st.args {
        match num(a.text) {
            Some(x) if x.is_finite() && words.is_empty() => v.push(x),
            Some(x) if words.last().is_some_and(|w| w == "TIMES") => {
                turns = circle_turns(st, a, x, diags)?;
                words.push("TIMES n".into());
            }
            Some(_) if !words.is_empty() => {}
            _ if v.len() >= 6 && a.text.trim().chars().all(|c| c.is_ascii_alphabetic()) => words.push(a.word()),
            _ => {
                st.bad(diags, a.col, format!("CIRCLE: expected a number, found {:?}", a.text.trim()));
                return None;
            }
        }
    }
    if v.len() < 6 {
        let msg = format!(
            "CIRCLE: expected centre and axis (6 values) and a radius, found {} values",
            v.len()
        );
        st.bad(diags, st.rest_col, msg);
        return None;
    }
    if words.last().is_some_and(|w| w == "TIMES") {
        st.bad(diags, st.rest_col, "CIRCLE: TIMES without its number of turns".into());
        return None;
    }
    // NX writes CIRCLE/x,y,z,i,j,k,r,tol,d,a,b and turns clockwise about (i,j,k): its own
    // post writes G03 for an axis of (0,0,-1), and 98 of 98 of its arcs in the corpus are
    // tangent to the next move only that way; the other systems' arcs are tangent the
    // other way (Creo 81/81, SOLIDWORKS CAM 1155/1182).
    let clockwise = v.len() >= 10;
    Some(Record::Circle {
        center: [v[0], v[1], v[2]],
        axis: [v[3], v[4], v[5]],
        radius: v.get(6).copied(),
        clockwise,
        turns,
        sweep_deg: None,
    })
}

/// A helical ramp's turns after `TIMES`: taken once it plunged 7× as steep (NX's 3° ramp of
/// TIMES,7 at 21°).
fn circle_turns(st: &Stmt, a: &Arg, x: f64, diags: &mut Vec<Diagnostic>) -> Option<u32> {
    if x >= 1.0 && x.fract() == 0.0 && x <= MAX_CIRCLE_TURNS as f64 {
        return Some(x as u32);
    }
    let msg = format!(
        "CIRCLE: TIMES expects a whole number of turns from 1 to {MAX_CIRCLE_TURNS}, found {:?}",
        a.text.trim()
    );
    st.bad(diags, a.col, msg);
    None
}

fn units(st: &Stmt, diags: &mut Vec<Diagnostic>) -> Option<Record> {
    let w = st.args.first().map(Arg::word).unwrap_or_default();
    match w.as_str() {
        "MM" | "MILLIMETERS" | "METRIC" => Some(Record::Units(Units::Mm)),
        "INCHES" | "INCH" | "IN" => Some(Record::Units(Units::Inch)),
        other => {
            let col = st.args.first().map_or(st.rest_col, |a| a.col);
            st.bad(diags, col, format!("{}: expected MM or INCHES, found {other:?}", st.major));
            None
        }
    }
}

fn delay(st: &Stmt, diags: &mut Vec<Diagnostic>) -> Option<Record> {
    let revs = st.args.first().is_some_and(|a| a.word() == "REV");
    let v = st.args.get(usize::from(revs));
    match v.and_then(|a| num(a.text)) {
        Some(t) if (0.0..=3600.0).contains(&t) => {
            Some(Record::Delay(if revs { Dwell::Revolutions(t) } else { Dwell::Seconds(t) }))
        }
        _ => {
            let col = v.map_or(st.rest_col, |a| a.col);
            let what = if revs { "revolutions" } else { "seconds" };
            st.bad(
                diags,
                col,
                format!("DELAY: expected a dwell of 0 to 3600 {what}: no dwell written"),
            );
            None
        }
    }
}

/// Operation bounds, the part name, comments, the end, and the records recognised only to be
/// ignored; anything else is unknown (a warning, no record).
fn informational(st: &Stmt, diags: &mut Vec<Diagnostic>) -> Option<Record> {
    match st.major.as_str() {
        "TOOL PATH" => Some(Record::OperationStart(
            st.args.first().map(|a| a.text.trim().to_string()).unwrap_or_default(),
        )),
        "END-OF-PATH" => Some(Record::OperationEnd),
        // NX's information listing around the CLSF: who, when, which part; a count of lines.
        "INFORMATION" | "DATE" | "CURRENT" | "NODE" | "TOOL" if is_nx_listing(st.s) => Some(Record::Ignored("NX LISTING".into())),
        "PARTNO" => Some(Record::PartNo(st.rest.trim().to_string())),
        "PPRINT" | "INSERT" => Some(Record::Comment(st.rest.trim().to_string())),
        "STOP" | "OPSTOP" => Some(Record::Stop {
            optional: st.major == "OPSTOP",
            text: flow::stop_text(st.rest),
        }),
        "MODE" => flow::mode(st),
        "FINI" | "END" => Some(Record::End),
        "CUTCOM" => flow::cutcom(st, diags),
        "OPSKIP" => flow::block_skip(st, diags),
        "AUXFUN" | "PREFUN" => flow::function(st, diags),
        "SELCTL" => flow::preselect(st, diags),
        "INTOL" | "OUTTOL" => flow::tolerance(st, diags),
        "SELECT" => flow::select(st, diags),
        "MSYS" => frames::msys(st, diags),
        // SOLIDWORKS CAM's vendor records: tool and path parameters for its own posts.
        m if m.starts_with("CSI_") => Some(Record::Ignored(m.to_string())),
        m if let Some(w) = super::vocabulary::word(m) && w.treatment != Treatment::Honoured => {
            if let Treatment::Told(sev, why) = w.treatment {
                let msg = format!("{m}: {why}");
                diags.push(Diagnostic::new(Code::IgnoredRecord, sev, Some(st.line), msg).at(st.lead + 1));
            }
            Some(Record::Ignored(m.to_string()))
        }
        m => {
            let shown: String = st.s.chars().take(60).collect();
            let msg = format!("unknown record {:?}: ignored", if m.is_empty() { &shown } else { m });
            diags.push(Diagnostic::new(Code::UnknownRecord, Severity::Warning, Some(st.line), msg).at(st.lead + 1));
            None
        }
    }
}

fn split_args(rest: &str, start_col: u32) -> Vec<Arg<'_>> {
    if rest.trim().is_empty() {
        return Vec::new();
    }
    let mut out = Vec::new();
    let mut col = start_col;
    for part in rest.split(',') {
        let lead = (part.len() - part.trim_start().len()) as u32;
        out.push(Arg {
            text: part,
            col: col + lead,
        });
        col += part.len() as u32 + 1;
    }
    // A trailing comma (CAMWorks' CUTTER/…,) adds no argument.
    if out.last().is_some_and(|a| a.text.trim().is_empty()) {
        out.pop();
    }
    out
}

/// A number as CL files write them: `6.`, `.9625`, `-0.5`, `1e-3`, spaces around.
#[inline]
pub(crate) fn num(s: impl AsRef<[u8]>) -> Option<f64> {
    // ASCII whitespace only: anything else is not part of a CL number anyway.
    let b = s.as_ref().trim_ascii();
    match b.first() {
        Some(c) if c.is_ascii_digit() || matches!(c, b'-' | b'+' | b'.') => fast_float2::parse(b).ok(),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use fast::{digits_value, leading_digits};
    use super::*;
    use proptest::prelude::*;

    fn goto(args: &str) -> Option<[f64; 6]> {
        match fast_goto(format!("GOTO/{args}").as_bytes()) {
            Some(Record::Goto { p, axis: Some(a) }) => Some([p[0], p[1], p[2], a[0], a[1], a[2]]),
            Some(Record::Goto { p, axis: None }) => Some([p[0], p[1], p[2], 0.0, 0.0, 0.0]),
            _ => None,
        }
    }

    fn digits_naive(b: &[u8; 8]) -> (usize, u64) {
        let k = b.iter().take_while(|c| c.is_ascii_digit()).count();
        (k, b[..k].iter().fold(0, |v, c| v * 10 + (c - b'0') as u64))
    }

    #[test]
    fn digit_runs_at_once() {
        for (b, k, v) in [
            (*b"12345678", 8, 12_345_678),
            (*b"00000009", 8, 9),
            (*b"99999999", 8, 99_999_999),
            (*b"224382,-", 6, 224_382),
            (*b"1234:678", 4, 1234),
            (*b"12 45678", 2, 12),
            (*b"7\xfa\xff\xff\xff\xff\xff\xff", 1, 7),
            (*b"/2345678", 0, 0),
            (*b"\x001234567", 0, 0),
        ] {
            let w = u64::from_le_bytes(b);
            assert_eq!(leading_digits(w), k, "{b:?}");
            if k > 0 {
                assert_eq!(digits_value(w, k), v, "{b:?}");
            }
        }
    }

    proptest::proptest! {
        #[test]
        fn digit_runs_agree_with_a_byte_loop(
            b in proptest::array::uniform8(proptest::prop_oneof![
                8 => b'0'..=b'9',
                1 => proptest::num::u8::ANY,
                1 => proptest::sample::select(vec![b',', b'.', b' ', b'/', b':', b'\xfa', b'\xff']),
            ])
        ) {
            let (k, v) = digits_naive(&b);
            let w = u64::from_le_bytes(b);
            proptest::prop_assert_eq!(leading_digits(w), k);
            if k > 0 {
                proptest::prop_assert_eq!(digits_value(w, k), v);
            }
        }
    }

    #[test]
    fn the_goto_fast_path_reads_short_decimals_and_leaves_the_rest() {
        let bits = |v: [f64; 6]| v.map(f64::to_bits);
        assert_eq!(
            goto(" 6. , .9625,-0.5 ,+.5,-0,1").map(bits),
            Some(bits([6.0, 0.9625, -0.5, 0.5, -0.0, 1.0]))
        );
        assert_eq!(goto("1,2,3").map(bits), Some(bits([1.0, 2.0, 3.0, 0.0, 0.0, 0.0])));
        // To the general parser: exponents, long mantissas, empty and junk arguments, a trailing
        // comma, a zero axis, too many values, any `$`.
        let long = format!("{},0,0", "9".repeat(400));
        assert_eq!(goto(&long), None);
        for a in [
            "1.5e3,0,0",
            "1234567890123456,0,0",
            "1,,2",
            "1,2,3,",
            "1,2,x",
            "1,2,3,0,0,0",
            "1,2,3,4,5,6,7",
            ".,1,2",
            "-,1,2",
            // Continuations and comments: the reader relies on the fast path declining them.
            "1,2,3 $$ a comment",
            "1,2,$",
            "1,2,3$",
            "1,2$,3",
        ] {
            assert_eq!(goto(a), None, "{a}");
        }
    }

    /// A number as CAM systems and people write it: sign, leading zeros, a point anywhere or
    /// none, an exponent now and then.
    fn cl_number() -> impl Strategy<Value = String> {
        (
            prop::sample::select(vec!["", "-", "+"]),
            "[0-9]{0,9}",
            prop::option::weighted(0.8, "[0-9]{0,9}"),
            prop::option::weighted(0.02, -3i32..3),
        )
            .prop_map(|(sign, int, frac, exp)| {
                let mut s = format!("{sign}{int}");
                if let Some(f) = frac {
                    s += &format!(".{f}");
                }
                if let Some(e) = exp {
                    s += &format!("e{e}");
                }
                s
            })
    }

    /// Whatever the fast path takes, the general parser reads to the same record, bit for bit;
    /// and it takes most well-formed GOTOs.
    #[test]
    fn the_fast_path_is_the_general_parser() {
        use proptest::test_runner::{Config, TestRunner};
        let lines = (
            prop::sample::select(vec![3usize, 6, 6, 6, 4, 7]).prop_flat_map(|n| prop::collection::vec(cl_number(), n)),
            prop::collection::vec(prop::sample::select(vec!["", " ", "  ", "\t"]), 16),
            any::<bool>(),
        );
        let taken = std::cell::Cell::new(0);
        let mut runner = TestRunner::new(Config {
            cases: 2000,
            ..Config::default()
        });
        runner
            .run(&lines, |(nums, pad, lower)| {
                let mut s = format!("{}{}{}/", pad[0], if lower { "goto" } else { "GOTO" }, pad[1]);
                for (k, n) in nums.iter().enumerate() {
                    if k > 0 {
                        s.push(',');
                    }
                    s += &format!("{}{n}{}", pad[2 + k % 7], pad[9 + k % 7]);
                }
                if let Some(fast) = fast_goto(s.trim_ascii().as_bytes()) {
                    taken.set(taken.get() + 1);
                    let mut diags = Vec::new();
                    let general = parse_general(&s, 1, &mut diags);
                    let text = |r: &Record| format!("{r:?}");
                    prop_assert_eq!(Some(text(&fast)), general.as_ref().map(text), "{}", s);
                    prop_assert!(diags.is_empty(), "{}: {:?}", s, diags);
                }
                Ok(())
            })
            .unwrap();
        assert!(taken.get() > 400, "the fast path took only {} of 2000 lines", taken.get());
    }

    proptest! {
        #[test]
        fn short_decimals_are_the_general_parsers_doubles(
            int in 0u64..10_000_000_000_000,
            dec in 0usize..16,
            neg: bool,
        ) {
            let digits = int.to_string();
            let s = if dec == 0 {
                digits.clone()
            } else if dec >= digits.len() {
                format!(".{}{digits}", "0".repeat(dec - digits.len()))
            } else {
                format!("{}.{}", &digits[..digits.len() - dec], &digits[digits.len() - dec..])
            };
            let s = if neg { format!("-{s}") } else { s };
            let want: f64 = s.parse().unwrap();
            let got = goto(&format!("{s},0,0,0,0,1"));
            prop_assert_eq!(got.map(|v| v[0].to_bits()), Some(want.to_bits()), "{}", s);
        }
    }
}
