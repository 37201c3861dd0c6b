//! The five built-in dialects (the files of `dialects/`, compiled in), and what a dialect lets a
//! CL pass through to its control.

use super::dialect::{Dialect, parse_dialect};
use super::Style;
use std::sync::{Arc, LazyLock};

/// The built-in dialects' files, parents first (the others extend `fanuc`).
pub const BUILTIN_FILES: [(&str, &str); 5] = [
    ("fanuc", include_str!("../../dialects/fanuc.toml")),
    ("haas", include_str!("../../dialects/haas.toml")),
    ("siemens", include_str!("../../dialects/siemens.toml")),
    ("heidenhain", include_str!("../../dialects/heidenhain.toml")),
    ("linuxcnc", include_str!("../../dialects/linuxcnc.toml")),
];

pub const DIALECTS: &[&str] = &["fanuc", "haas", "siemens", "heidenhain", "linuxcnc"];

static BUILTINS: LazyLock<Vec<Arc<Dialect>>> = LazyLock::new(|| {
    let mut out: Vec<Arc<Dialect>> = Vec::new();
    for (id, text) in BUILTIN_FILES {
        let parent = |p: &str| out.iter().find(|d| d.name == p).cloned();
        // The files are the crate's own: a test reads each, so this cannot fail in a release.
        let d = parse_dialect(text, &format!("dialects/{id}.toml"), Some(id), &parent)
            .unwrap_or_else(|e| panic!("built-in dialect: {e}"));
        out.push(Arc::new(d));
    }
    out
});

/// The built-in dialects, in the order of [`DIALECTS`].
pub fn builtins() -> &'static [Arc<Dialect>] {
    &BUILTINS
}

/// A built-in dialect by id: what `extends` names, and a profile's `controller`.
pub fn dialect(name: &str) -> Option<Arc<Dialect>> {
    BUILTINS.iter().find(|d| d.name == name).cloned()
}

impl Dialect {
    /// The program numbers the program frame can carry: an `O` word of four (five) digits
    /// takes 1 to 9999 (99999); `O0` and wider numbers are alarms on the control. Unbounded
    /// where the number is a name or a comment.
    pub fn program_numbers(&self) -> std::ops::RangeInclusive<u32> {
        let digits = |t: &str| t.contains("{n4}").then_some(9999).or(t.contains("{n5}").then_some(99999));
        match self.begin.iter().chain(&self.end).find_map(|f| digits(&f.text)) {
            Some(max) => 1..=max,
            None => 0..=u32::MAX,
        }
    }
}
/// What passing an M or G code from the CL (`AUXFUN`, `PREFUN`) to a control risks.
pub enum Risk {
    None,
    /// Written, but it changes what kinepost keeps track of (the spindle, the coolant).
    Untracked(&'static str),
    /// Not written: it contradicts what the program's own words do.
    Refused(&'static str),
}

/// Whether `letter``code` may pass to `d`'s program as the CL asks.
pub fn function_risk(d: &Dialect, letter: char, code: &str) -> Risk {
    if letter == 'G' {
        return match (d.style, d.harmless_g.iter().any(|g| g == code)) {
            (Style::Conversational, _) => Risk::Refused("the control takes no G codes"),
            (_, true) => Risk::None,
            _ => Risk::Refused("a G code that may change coordinates, units, plane, compensation or motion under the program's own words"),
        };
    }
    match code {
        "0" | "1" => Risk::Refused("a stop is STOP or OPSTOP in the CL"),
        "2" | "30" => Risk::Refused("a program end in the middle of the program"),
        "6" => Risk::Refused("a tool change is LOADTL in the CL"),
        "98" | "99" => Risk::Refused("a subprogram call or return"),
        "3" | "4" | "5" => Risk::Untracked("the spindle is SPINDL in the CL; kinepost does not know of this one"),
        "7" | "8" | "9" => Risk::Untracked("the coolant is COOLNT in the CL; kinepost does not know of this one"),
        _ if !d.knows(&format!("M{code}")) => {
            Risk::Refused("an M code the control does not know: it stops the program where it is read")
        }
        _ => Risk::None,
    }
}

