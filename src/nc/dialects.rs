//! The five dialects as values, and what a dialect lets a CL pass through to its control.

use super::{Cycles, Dialect, Planes, Ranges, Style};

pub const FANUC: Dialect = Dialect {
    name: "fanuc",
    title: "Fanuc (0i/30i)",
    style: Style::WordAddress,
    comment: ("(", ")"),
    begin: &[("%", false), ("O{n4}", false)],
    end: &[("M30", true), ("%", false)],
    units_mm: "G21",
    units_inch: "G20",
    safe_start: "G90 G17 G40 G49 G80",
    work_coordinates: &["G54", "G55", "G56", "G57", "G58", "G59"],
    rapid: "G0",
    feed: "G1",
    feed_per_min: "G94",
    inverse_time: Some("G93"),
    // Fanuc 30i, IS-B: F 0.001-999000 mm/min; T up to 8 digits; offsets H/D up to 999; G4 P up
    // to 99 999 999 ms.
    ranges: Ranges {
        feed_mm: 999_000.0,
        inverse_time: 99_999.999,
        tool: 99_999_999,
        register: 999,
        dwell_s: 99_999.999,
    },
    tool_change: &["T{t} M6"],
    tool_preselect: "T{t}",
    length_comp: "G43 H{t}",
    tcp_on: "G43.4 H{t}",
    tcp_off: "G49",
    machine_z_up: "G53 G0 Z0",
    spindle: "S{s}",
    spindle_cw: "M3",
    spindle_ccw: "M4",
    spindle_off: "M5",
    coolant_flood: "M8",
    coolant_mist: "M7",
    coolant_through: "M88",
    coolant_off: "M9",
    stop: "M0",
    optional_stop: "M1",
    cutcom: ["G41 D{t}", "G42 D{t}", "G40"],
    // 30i: 3-dimensional cutter compensation, tool side offset (an option of the control).
    cutcom_3d: Some(["G41.2 D{t}", "G42.2 D{t}", "G40"]),
    cutcom_radius: "D REGISTER",
    harmless_g: &["5.1", "8", "9", "61", "61.1", "62", "63", "64"],
    m_codes: None,
    block_numbers: true,
    cycles: Cycles::Iso { dwell_ms: true },
    planes: Planes::Fanuc,
    notes: "TCP with G43.4 (type 1); inverse time G93",
};

pub const HAAS: Dialect = Dialect {
    name: "haas",
    title: "Haas NGC",
    harmless_g: &["9", "61", "64", "187"],
    begin: &[("%", false), ("O{n5}", false)],
    tcp_on: "G234 H{t}",
    cycles: Cycles::Iso { dwell_ms: false },
    planes: Planes::Haas,
    // G141 (3D+ compensation) needs the surface normal on every block, which kinepost does not
    // write.
    cutcom_3d: None,
    notes: "TCP with G234 (TCPC); inverse time G93",
    ..FANUC
};

pub const LINUXCNC: Dialect = Dialect {
    name: "linuxcnc",
    title: "LinuxCNC",
    harmless_g: &["61", "61.1", "64"],
    // LinuxCNC's own M codes and the user's M100–M199 (scripts its configuration provides).
    m_codes: Some(&[(0, 9), (19, 19), (30, 30), (48, 53), (60, 68), (70, 73), (100, 199)]),
    begin: &[("%", false)],
    end: &[("M30", true), ("%", false)],
    tcp_on: "G43 H{t} (TCP: SWITCH THE KINEMATICS TO TOOL-TIP MODE IN THE MACHINE CONFIG)",
    tcp_off: "G49",
    // Homing sets machine Z0 where the configuration says: not always the top.
    machine_z_up: "",
    coolant_through: "M8",
    cycles: Cycles::Iso { dwell_ms: false },
    planes: Planes::None,
    cutcom_3d: None,
    cutcom_radius: "TOOL TABLE RADIUS OF TOOL D",
    notes: "no TCP G-code: the machine configuration switches kinematics; inverse time G93",
    ..FANUC
};

pub const SIEMENS: Dialect = Dialect {
    name: "siemens",
    title: "Siemens Sinumerik 840D",
    harmless_g: &["9", "60", "64", "601", "602", "603", "641", "642", "644", "645"],
    m_codes: None,
    style: Style::WordAddress,
    comment: ("; ", ""),
    begin: &[("; PROGRAM {n}", false)],
    end: &[("M30", true)],
    units_mm: "G71",
    units_inch: "G70",
    safe_start: "G90 G17 G40 G64",
    // G58 and G59 are programmable (additive) offsets on a Sinumerik, not settable datums.
    work_coordinates: &["G54", "G55", "G56", "G57"],
    tool_change: &["T{t}", "M6", "D1"],
    tool_preselect: "T{t}",
    length_comp: "",
    tcp_on: "TRAORI",
    tcp_off: "TRAFOOF",
    machine_z_up: "",
    cycles: Cycles::Siemens,
    planes: Planes::Siemens,
    // The radius is the tool's cutting edge D1 (with its length): no register of its own.
    cutcom: ["G41", "G42", "G40"],
    // 3D tool radius compensation for circumferential milling with TRAORI.
    cutcom_3d: Some(["CUT3DC G41", "CUT3DC G42", "G40 CUT2D"]),
    cutcom_radius: "D1 RADIUS",
    notes: "TCP with TRAORI; tool offset with D1; inverse time G93; rotaries programmed as linear (not modulo) axes",
    ..FANUC
};

pub const HEIDENHAIN: Dialect = Dialect {
    name: "heidenhain",
    title: "Heidenhain TNC (conversational)",
    style: Style::Conversational,
    comment: ("; ", ""),
    begin: &[("BEGIN PGM {n} {UNITS}", true)],
    end: &[("M30", true), ("END PGM {n} {UNITS}", true)],
    units_mm: "",
    units_inch: "",
    safe_start: "",
    work_coordinates: &[],
    rapid: "FMAX",
    feed: "",
    feed_per_min: "",
    inverse_time: None,
    // TNC 640: tool numbers 0-32767 (the tool table's T); F up to 999 999 mm/min; dwell
    // (cycle 9) up to 3 600 s.
    ranges: Ranges {
        feed_mm: 999_999.0,
        inverse_time: 99_999.999,
        tool: 32_767,
        register: 32_767,
        dwell_s: 3_600.0,
    },
    tool_change: &["TOOL CALL {t} Z"],
    tool_preselect: "TOOL DEF {t}",
    length_comp: "",
    tcp_on: "FUNCTION TCPM F TCP AXIS POS PATHCTRL AXIS",
    tcp_off: "FUNCTION RESET TCPM",
    machine_z_up: "",
    spindle: "TOOL CALL S{s}",
    spindle_cw: "M3",
    spindle_ccw: "M4",
    spindle_off: "M5",
    coolant_flood: "M8",
    coolant_mist: "M7",
    coolant_through: "M8",
    coolant_off: "M9",
    stop: "M0",
    optional_stop: "M1",
    // The radius is the tool table's R + DR; with FUNCTION TCPM, RL/RR offset across the tool
    // axis and the path (3D radius compensation for peripheral milling).
    cutcom: ["RL", "RR", "R0"],
    cutcom_3d: Some(["RL", "RR", "R0"]),
    cutcom_radius: "TOOL TABLE R+DR",
    harmless_g: &[],
    m_codes: None,
    block_numbers: true,
    cycles: Cycles::Heidenhain,
    planes: Planes::Heidenhain,
    notes: "TCP with FUNCTION TCPM; no inverse time: rotary moves get the combined machine-axis feed",
};

impl Dialect {
    /// The program numbers the program frame can carry: an `O` word of four (five) digits
    /// takes 1 to 9999 (99999); `O0` and wider numbers are alarms on the control. Unbounded
    /// where the number is a name or a comment.
    pub fn program_numbers(&self) -> std::ops::RangeInclusive<u32> {
        let digits = |t: &str| t.contains("{n4}").then_some(9999).or(t.contains("{n5}").then_some(99999));
        match self.begin.iter().chain(self.end).find_map(|(t, _)| digits(t)) {
            Some(max) => 1..=max,
            None => 0..=u32::MAX,
        }
    }
}

pub const ALL: [&Dialect; 5] = [&FANUC, &HAAS, &SIEMENS, &HEIDENHAIN, &LINUXCNC];

pub fn dialect(name: &str) -> Option<&'static Dialect> {
    ALL.iter().copied().find(|d| d.name == name)
}

pub const DIALECTS: &[&str] = &["fanuc", "haas", "siemens", "heidenhain", "linuxcnc"];

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
        return match (d.style, d.harmless_g.contains(&code)) {
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

