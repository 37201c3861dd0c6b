//! A dialect file (`dialects/<id>.toml`) → a validated [`Dialect`]. A file may `extends` another
//! dialect and say only what differs: its keys replace the parent's, tables (`ranges`, `format`,
//! `sequence`, `templates`) key by key. Every error names the dialect and what is wrong.

use super::templates::Templates;
use super::{Cycles, Planes, Ranges, Style};
use serde::Deserialize;
use std::collections::BTreeMap;

/// A program frame line (`%`, `O1000`, `BEGIN PGM …`) and whether it takes a block number.
#[derive(Clone, Debug, Deserialize, PartialEq, Eq)]
#[serde(deny_unknown_fields)]
pub struct Frame {
    pub text: String,
    #[serde(default)]
    pub numbered: bool,
}

/// How numbers are written, where a control wants other than kinepost's defaults.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq)]
#[serde(deny_unknown_fields)]
pub struct WordFormat {
    /// Decimals of the linear words (default 3 in mm, 4 in inch).
    pub linear_mm: Option<u32>,
    pub linear_inch: Option<u32>,
    /// Decimals of the rotary words (default 4).
    pub rotary: Option<u32>,
    /// Decimals of a programmed feed per minute (default 1 in mm, 2 in inch).
    pub feed_mm: Option<u32>,
    pub feed_inch: Option<u32>,
    /// Decimals of an inverse-time F (default 3).
    pub inverse_time: Option<u32>,
    /// `false`: `X1.5` for `X1.500`, `X1.` for `X1.000` (the decimal point stays: without it
    /// many controls read the number in their least increment).
    #[serde(default = "yes")]
    pub trailing_zeros: bool,
    /// `false`: `X.5` for `X0.5`.
    #[serde(default = "yes")]
    pub leading_zero: bool,
    /// `false`: every axis word on every block, not only those that changed.
    #[serde(default = "yes")]
    pub modal: bool,
}

fn yes() -> bool {
    true
}

impl Default for WordFormat {
    fn default() -> Self {
        WordFormat {
            linear_mm: None,
            linear_inch: None,
            rotary: None,
            feed_mm: None,
            feed_inch: None,
            inverse_time: None,
            trailing_zeros: true,
            leading_zero: true,
            modal: true,
        }
    }
}

/// Block numbers, where the job asks for them (always on a conversational control).
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq)]
#[serde(deny_unknown_fields)]
pub struct Sequence {
    pub start: u32,
    pub step: u32,
    /// Zero-padded to this many digits (0: as wide as the number).
    #[serde(default)]
    pub width: u32,
}

/// A controller's words for the same things. Only data: adding a dialect is a file.
/// Word templates: `{n}` program number, `{n4}`/`{n5}` zero-padded, `{UNITS}` MM|INCH, `{t}` tool,
/// `{s}` spindle speed; the program's events take [`Templates`] (MiniJinja).
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Dialect {
    #[serde(rename = "id")]
    pub name: String,
    pub title: String,
    #[serde(default)]
    pub notes: String,
    pub style: Style,
    /// Comment delimiters: `(` `)` or `;` and nothing.
    pub comment: (String, String),
    /// Program start and end lines.
    pub begin: Vec<Frame>,
    pub end: Vec<Frame>,
    pub units_mm: String,
    pub units_inch: String,
    pub safe_start: String,
    /// The work coordinate systems a program can select (the first is the default, written on
    /// the safe-start line); none where the control takes its datum otherwise (a TNC's preset).
    pub work_coordinates: Vec<String>,
    pub rapid: String,
    pub feed: String,
    pub feed_per_min: String,
    /// Inverse-time feed word (G93); none (or empty): the control has none, and a move with
    /// rotaries gets the combined machine-axis feed (units and degrees per minute) that gives
    /// the same time.
    #[serde(default, deserialize_with = "empty_is_none")]
    pub inverse_time: Option<String>,
    /// The numbers its words take.
    pub ranges: Ranges,
    pub tool_change: Vec<String>,
    /// The next tool readied in the magazine while this one cuts (CL `SELCTL`).
    pub tool_preselect: String,
    pub length_comp: String,
    pub tcp_on: String,
    pub tcp_off: String,
    /// Spindle to the machine's Z home in machine coordinates, compensation off (`G53 G0 Z0`,
    /// where machine Z0 is the top of travel, as on every Haas): what a TCP program leaves the
    /// part with before a tool change and at the end, where its X Y Z (tip coordinates) cannot
    /// name the top of Z. Empty where the control's machine zero is not known to be the top.
    pub machine_z_up: String,
    pub spindle: String,
    pub spindle_cw: String,
    pub spindle_ccw: String,
    pub spindle_off: String,
    pub coolant_flood: String,
    pub coolant_mist: String,
    pub coolant_through: String,
    pub coolant_off: String,
    /// Program stop and optional stop (CL `STOP`, `OPSTOP`).
    pub stop: String,
    pub optional_stop: String,
    /// Cutter radius compensation (CL `CUTCOM`) left, right and off, in the working plane (G17);
    /// `{t}` is the offset register. Started and ended on a straight move.
    pub cutcom: [String; 3],
    /// The same for simultaneous 5-axis motion in TCP mode (3D tool-side compensation), where
    /// the control has it (an empty list: it has not).
    #[serde(default, deserialize_with = "three_or_none")]
    pub cutcom_3d: Option<[String; 3]>,
    /// Where the control takes the compensation radius from: what the header tells the operator
    /// to set to the wear (tool centre path) or the full radius (contour).
    pub cutcom_radius: String,
    /// G codes a CL's `PREFUN` may pass through: they set only how the control moves (exact
    /// stop, continuous path, look-ahead); any other could change coordinates, units, plane,
    /// compensation or motion under the program's own words.
    pub harmless_g: Vec<String>,
    /// The M codes the control knows, as ranges; none: any (a machine builder adds its own, as
    /// on Fanuc and Haas controls). A code outside them stops the program where it is read.
    #[serde(default)]
    pub m_codes: Option<Vec<(u32, u32)>>,
    /// N numbers are optional (a job option) on word-address controls.
    pub block_numbers: bool,
    /// How the control writes canned drilling cycles.
    pub cycles: Cycles,
    /// How the control tilts the working plane (3+2).
    pub planes: Planes,
    /// Number formats beyond the defaults.
    #[serde(default)]
    pub format: WordFormat,
    /// Block numbers: where they start and their step (default N5, N10 … on word-address
    /// controls; 0, 1, 2 … on conversational ones).
    #[serde(default)]
    pub sequence: Option<Sequence>,
    /// The clamp words of a rotary by name, lock then unlock (`B = ["M10", "M11"]`): they replace
    /// the profile's `clamp` for programs in this dialect.
    #[serde(default)]
    pub clamps: BTreeMap<String, [String; 2]>,
    /// The block-delete character (`/`).
    #[serde(default = "slash")]
    pub block_delete: String,
    /// The longest line the control reads (0: no limit): a longer one is an error at its line.
    #[serde(default)]
    pub line_length: usize,
    /// The path-blending word written after the safe start (`G64 P{tol}` on LinuxCNC,
    /// `CYCLE832({tol}, _SEMIFIN, 1)` on a Sinumerik); `{tol}` is the job's tolerance. Empty:
    /// none.
    #[serde(default)]
    pub blend: String,
    /// The smoothing words of an operation by level, `{tol}` its tolerance (`[smoothing]`):
    /// written before an operation's first feed move (`smoothing`), `off` before a tool change
    /// and at the end where one is in force. No words: none.
    #[serde(default)]
    pub smoothing: Smoothing,
    /// Templates for the program's events (`[templates]`).
    #[serde(skip)]
    pub templates: Templates,
    /// The merged TOML this dialect was made from: what a dialect that extends it starts from.
    #[serde(skip)]
    pub table: toml::Table,
}

/// A dialect's `[smoothing]` lines: one list per level, and the cancel.
#[derive(Clone, Debug, Default, Deserialize, PartialEq, Eq)]
#[serde(deny_unknown_fields)]
pub struct Smoothing {
    /// The job's `smoothing` where neither it nor the profile says (`auto`, `off`, `rough`,
    /// `finish`; checked by `post::Smoothing`).
    #[serde(default)]
    pub default: Option<String>,
    #[serde(default)]
    pub rough: Vec<String>,
    #[serde(default)]
    pub semifinish: Vec<String>,
    #[serde(default)]
    pub finish: Vec<String>,
    #[serde(default)]
    pub off: Vec<String>,
}

/// The most lines a `[smoothing]` level may write (Heidenhain's cycle 32 takes three).
const MAX_SMOOTHING_LINES: usize = 4;

fn slash() -> String {
    "/".into()
}

fn empty_is_none<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Option<String>, D::Error> {
    Ok(Option::<String>::deserialize(d)?.filter(|s| !s.is_empty()))
}

fn three_or_none<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Option<[String; 3]>, D::Error> {
    let v = Vec::<String>::deserialize(d)?;
    match <[String; 3]>::try_from(v) {
        Ok(a) => Ok(Some(a)),
        Err(v) if v.is_empty() => Ok(None),
        Err(_) => Err(serde::de::Error::custom("expected three words (left, right, off) or an empty list")),
    }
}

/// Keys whose values are tables merged key by key when a dialect extends another.
const MERGED_TABLES: [&str; 6] = ["ranges", "format", "sequence", "templates", "clamps", "smoothing"];

/// The largest dialect file read.
pub const MAX_DIALECT_BYTES: usize = 64 * 1024;

/// Reads a dialect from `text` (named `file` in errors). `parent` finds the dialect an
/// `extends` names. `id`: the id the file must have (its file stem, or the API's path).
pub fn parse_dialect(
    text: &str,
    file: &str,
    id: Option<&str>,
    parent: &dyn Fn(&str) -> Option<std::sync::Arc<Dialect>>,
) -> Result<Dialect, String> {
    if text.len() > MAX_DIALECT_BYTES {
        return Err(format!("{file}: larger than {MAX_DIALECT_BYTES} bytes"));
    }
    let own: toml::Table = toml::from_str(text).map_err(|e| format!("{file}: {}", toml_error(text, &e)))?;
    let mut table = match own.get("extends") {
        None => toml::Table::new(),
        Some(toml::Value::String(p)) => {
            let base = parent(p).ok_or_else(|| format!("{file}: extends: no dialect {p:?}"))?;
            base.table.clone()
        }
        Some(_) => return Err(format!("{file}: extends: expected a dialect's id")),
    };
    for (k, v) in own {
        match (table.get_mut(&k), v) {
            (Some(toml::Value::Table(base)), toml::Value::Table(over)) if MERGED_TABLES.contains(&k.as_str()) => {
                base.extend(over);
            }
            (_, v) => {
                table.insert(k, v);
            }
        }
    }
    table.remove("extends");
    let templates: BTreeMap<String, String> = match table.remove("templates") {
        None => BTreeMap::new(),
        Some(t) => t.try_into().map_err(|e| format!("{file}: templates: {e}"))?,
    };
    let mut d: Dialect = toml::Value::Table(table.clone())
        .try_into()
        .map_err(|e: toml::de::Error| format!("{file}: {}", e.message()))?;
    if !templates.is_empty() {
        table.insert("templates".into(), toml::Value::try_from(&templates).map_err(|e| e.to_string())?);
    }
    d.templates = Templates::compile(&templates).map_err(|e| format!("{file}: {e}"))?;
    d.table = table;
    validate(&d, file, id)?;
    Ok(d)
}

fn toml_error(text: &str, e: &toml::de::Error) -> String {
    match e.span() {
        Some(s) => format!("line {}: {}", text[..s.start.min(text.len())].matches('\n').count() + 1, e.message()),
        None => e.message().to_string(),
    }
}

fn validate(d: &Dialect, file: &str, id: Option<&str>) -> Result<(), String> {
    let bad = |key: &str, problem: String| Err(format!("{file}: {key}: {problem}"));
    if let Some(id) = id
        && d.name != id
    {
        return bad("id", format!("{:?} must equal {id:?}", d.name));
    }
    if d.name.is_empty() || d.name.len() > 64 || !d.name.bytes().all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || b == b'-') {
        return bad("id", "[a-z0-9-]+, at most 64 characters".into());
    }
    if let Some(s) = d.sequence
        && s.step == 0
    {
        return bad("sequence.step", "must be at least 1".into());
    }
    // A width of 3e8 once padded every block number to 300 MB.
    if let Some(s) = d.sequence
        && s.width > MAX_SEQUENCE_WIDTH
    {
        return bad("sequence.width", format!("at most {MAX_SEQUENCE_WIDTH} digits"));
    }
    words(d).map_err(|(key, problem)| format!("{file}: {key}: {problem}"))?;
    let f = d.format;
    for (k, v) in [
        ("format.linear_mm", f.linear_mm),
        ("format.linear_inch", f.linear_inch),
        ("format.rotary", f.rotary),
        ("format.feed_mm", f.feed_mm),
        ("format.feed_inch", f.feed_inch),
        ("format.inverse_time", f.inverse_time),
    ] {
        if v.is_some_and(|v| v > 6) {
            return bad(k, "at most 6 decimals".into());
        }
    }
    let r = d.ranges;
    if !(r.feed_mm > 0.0 && r.feed_mm.is_finite() && r.inverse_time > 0.0 && r.inverse_time.is_finite() && r.dwell_s >= 0.0 && r.dwell_s.is_finite()) {
        return bad("ranges", "feeds must be positive and finite, the dwell finite".into());
    }
    if let Some(k) = d.clamps.keys().find(|k| !matches!(k.as_str(), "A" | "B" | "C")) {
        return bad("clamps", format!("{k:?}: a rotary is A, B or C"));
    }
    let lines = d.begin.iter().chain(&d.end).map(|f| f.text.as_str());
    if let Some(l) = lines.chain(d.tool_change.iter().map(String::as_str)).find(|l| l.chars().any(char::is_control)) {
        return bad("begin/end/tool_change", format!("{}: one line each", crate::text::quote(l)));
    }
    Ok(())
}

fn smoothing_lines(s: &Smoothing) -> impl Iterator<Item = &String> {
    s.rough.iter().chain(&s.semifinish).chain(&s.finish).chain(&s.off)
}

/// The most digits a block number is padded to.
const MAX_SEQUENCE_WIDTH: u32 = 9;
/// The longest a dialect's word key may be.
const MAX_WORD: usize = 200;

/// The dialect's words held as a profile's are: each key one line of at most [`MAX_WORD`]
/// characters without control characters (a multi-line `safe_start` wrote `G0 Z-500` as a block
/// of its own), a clamp one word (`"M10 M30"` wrote an `M30`). The error: the key, the problem.
fn words(d: &Dialect) -> Result<(), (String, String)> {
    let one_line = [
        ("units_mm", &d.units_mm),
        ("units_inch", &d.units_inch),
        ("safe_start", &d.safe_start),
        ("rapid", &d.rapid),
        ("feed", &d.feed),
        ("feed_per_min", &d.feed_per_min),
        ("tool_preselect", &d.tool_preselect),
        ("length_comp", &d.length_comp),
        ("tcp_on", &d.tcp_on),
        ("tcp_off", &d.tcp_off),
        ("machine_z_up", &d.machine_z_up),
        ("spindle", &d.spindle),
        ("spindle_cw", &d.spindle_cw),
        ("spindle_ccw", &d.spindle_ccw),
        ("spindle_off", &d.spindle_off),
        ("coolant_flood", &d.coolant_flood),
        ("coolant_mist", &d.coolant_mist),
        ("coolant_through", &d.coolant_through),
        ("coolant_off", &d.coolant_off),
        ("stop", &d.stop),
        ("optional_stop", &d.optional_stop),
        ("cutcom_radius", &d.cutcom_radius),
        ("block_delete", &d.block_delete),
        ("blend", &d.blend),
        ("comment", &d.comment.0),
        ("comment", &d.comment.1),
    ];
    let lists = d
        .work_coordinates
        .iter()
        .map(|w| ("work_coordinates", w))
        .chain(d.inverse_time.iter().map(|w| ("inverse_time", w)))
        .chain(d.cutcom.iter().chain(d.cutcom_3d.iter().flatten()).map(|w| ("cutcom", w)))
        .chain(d.harmless_g.iter().map(|w| ("harmless_g", w)))
        .chain(smoothing_lines(&d.smoothing).map(|w| ("smoothing", w)));
    let s = &d.smoothing;
    if let Some(m) = s.default.as_deref().filter(|m| !matches!(*m, "auto" | "off" | "rough" | "finish")) {
        return Err(("smoothing.default".into(), format!("{}: expected auto, off, rough or finish", crate::text::quote(m))));
    }
    if [&s.rough, &s.semifinish, &s.finish, &s.off].iter().any(|l| l.len() > MAX_SMOOTHING_LINES) {
        return Err(("smoothing".into(), format!("at most {MAX_SMOOTHING_LINES} lines a level")));
    }
    for (key, w) in one_line.into_iter().chain(lists) {
        if w.chars().count() > MAX_WORD || w.chars().any(char::is_control) {
            return Err((key.into(), format!("{}: one line of at most {MAX_WORD} characters", crate::text::quote(w))));
        }
    }
    for (axis, pair) in &d.clamps {
        for w in pair {
            if w.is_empty() || w.len() > 16 || !w.chars().all(|c| c.is_ascii_alphanumeric() || c == '.' || c == '-') {
                return Err((
                    format!("clamps.{axis}"),
                    format!("{}: one NC word each, lock then unlock, e.g. [\"M10\", \"M11\"]", crate::text::quote(w)),
                ));
            }
        }
    }
    Ok(())
}
