//! NC output: controller dialects as data, plus small formatters. The engine hands over program
//! events (tool change, spindle, motion blocks …); a [`Formatter`] turns each into text lines in
//! its dialect, suppressing modal words, and keeps no more state than a controller would.

mod number;
pub mod read;

pub use number::{round_to, write_fixed};

use crate::kinematics::Units;

/// How a control's blocks are put together.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Style {
    /// ISO word address: `N10 G1 X1.000 Y2.000 F500.0 (comment)`.
    WordAddress,
    /// Heidenhain conversational: `12 L X+1.000 Y+2.000 F500 ; comment`, every line numbered from
    /// 0, signed numbers, FMAX for rapids.
    Conversational,
}

/// A controller's words for the same things. Only data: adding a dialect is a value.
/// Templates: `{n}` program number, `{n4}`/`{n5}` zero-padded, `{UNITS}` MM|INCH, `{t}` tool,
/// `{s}` spindle speed.
#[derive(Clone, Debug)]
pub struct Dialect {
    pub name: &'static str,
    pub title: &'static str,
    pub style: Style,
    /// Comment delimiters: `(` `)` or `;` and nothing.
    pub comment: (&'static str, &'static str),
    /// Program start and end lines, and whether each takes a block number.
    pub begin: &'static [(&'static str, bool)],
    pub end: &'static [(&'static str, bool)],
    pub units_mm: &'static str,
    pub units_inch: &'static str,
    pub safe_start: &'static str,
    pub rapid: &'static str,
    pub feed: &'static str,
    pub feed_per_min: &'static str,
    /// Inverse-time feed word (G93); `None`: the control has none, and a move with rotaries gets
    /// the combined machine-axis feed (units and degrees per minute) that gives the same time.
    pub inverse_time: Option<&'static str>,
    pub tool_change: &'static [&'static str],
    pub length_comp: &'static str,
    pub tcp_on: &'static str,
    pub tcp_off: &'static str,
    pub spindle: &'static str,
    pub spindle_cw: &'static str,
    pub spindle_ccw: &'static str,
    pub spindle_off: &'static str,
    pub coolant_flood: &'static str,
    pub coolant_mist: &'static str,
    pub coolant_through: &'static str,
    pub coolant_off: &'static str,
    /// N numbers are optional (a job option) on word-address controls.
    pub block_numbers: bool,
    pub notes: &'static str,
}

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
    rapid: "G0",
    feed: "G1",
    feed_per_min: "G94",
    inverse_time: Some("G93"),
    tool_change: &["T{t} M6"],
    length_comp: "G43 H{t}",
    tcp_on: "G43.4 H{t}",
    tcp_off: "G49",
    spindle: "S{s}",
    spindle_cw: "M3",
    spindle_ccw: "M4",
    spindle_off: "M5",
    coolant_flood: "M8",
    coolant_mist: "M7",
    coolant_through: "M88",
    coolant_off: "M9",
    block_numbers: true,
    notes: "TCP with G43.4 (type 1); inverse time G93",
};

pub const HAAS: Dialect = Dialect {
    name: "haas",
    title: "Haas NGC",
    begin: &[("%", false), ("O{n5}", false)],
    tcp_on: "G234 H{t}",
    notes: "TCP with G234 (TCPC); inverse time G93",
    ..FANUC
};

pub const LINUXCNC: Dialect = Dialect {
    name: "linuxcnc",
    title: "LinuxCNC",
    begin: &[("%", false)],
    end: &[("M30", true), ("%", false)],
    tcp_on: "G43 H{t} (TCP: SWITCH THE KINEMATICS TO TOOL-TIP MODE IN THE MACHINE CONFIG)",
    tcp_off: "G49",
    coolant_through: "M8",
    notes: "no TCP G-code: the machine configuration switches kinematics; inverse time G93",
    ..FANUC
};

pub const SIEMENS: Dialect = Dialect {
    name: "siemens",
    title: "Siemens Sinumerik 840D",
    style: Style::WordAddress,
    comment: ("; ", ""),
    begin: &[("; PROGRAM {n}", false)],
    end: &[("M30", true)],
    units_mm: "G71",
    units_inch: "G70",
    safe_start: "G90 G17 G40 G64",
    tool_change: &["T{t}", "M6", "D1"],
    length_comp: "",
    tcp_on: "TRAORI",
    tcp_off: "TRAFOOF",
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
    rapid: "FMAX",
    feed: "",
    feed_per_min: "",
    inverse_time: None,
    tool_change: &["TOOL CALL {t} Z"],
    length_comp: "",
    tcp_on: "FUNCTION TCPM F TCP AXIS POS PATHCTRL AXIS",
    tcp_off: "FUNCTION RESET TCPM",
    spindle: "TOOL CALL S{s}",
    spindle_cw: "M3",
    spindle_ccw: "M4",
    spindle_off: "M5",
    coolant_flood: "M8",
    coolant_mist: "M7",
    coolant_through: "M8",
    coolant_off: "M9",
    block_numbers: true,
    notes: "TCP with FUNCTION TCPM; no inverse time: rotary moves get the combined machine-axis feed",
};

pub const ALL: [&Dialect; 5] = [&FANUC, &HAAS, &SIEMENS, &HEIDENHAIN, &LINUXCNC];

pub fn dialect(name: &str) -> Option<&'static Dialect> {
    ALL.iter().copied().find(|d| d.name == name)
}

pub const DIALECTS: &[&str] = &["fanuc", "haas", "siemens", "heidenhain", "linuxcnc"];

/// Number formats: linear words 3 decimals in mm, 4 in inch; rotary words 4 decimals; feed 1.
#[derive(Clone, Copy, Debug)]
pub struct Formats {
    pub linear: u32,
    pub rotary: u32,
    pub feed: u32,
}

impl Formats {
    pub fn for_units(u: Units) -> Formats {
        match u {
            Units::Mm => Formats {
                linear: 3,
                rotary: 4,
                feed: 1,
            },
            Units::Inch => Formats {
                linear: 4,
                rotary: 4,
                feed: 2,
            },
        }
    }
}

/// Motion kinds as the controller knows them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Motion {
    Rapid,
    Feed,
    /// Circular, counter-clockwise (G3) or clockwise (G2) in the active plane; its axis words
    /// are always written (a full circle ends where it starts).
    Arc {
        ccw: bool,
    },
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FeedMode {
    PerMinute,
    InverseTime,
}

/// Formats lines of one program; keeps the modal state to suppress repeated words.
pub struct Formatter {
    pub d: &'static Dialect,
    pub fmt: Formats,
    /// Next block number, when blocks are numbered: N5, N10 … (word address, optional) or
    /// 0, 1, 2 … on every line (conversational).
    sequence: Option<u32>,
    motion: Option<Motion>,
    feed_mode: Option<FeedMode>,
    feed: Option<i64>,
    /// Last written value of each axis word (X Y Z A B C), as rounded integers.
    axes: [Option<i64>; 6],
    buf: String,
    program_number: u32,
    units: &'static str,
}

pub const AXIS_LETTERS: [char; 6] = ['X', 'Y', 'Z', 'A', 'B', 'C'];

impl Formatter {
    pub fn new(d: &'static Dialect, fmt: Formats, sequence_numbers: bool) -> Formatter {
        let numbered = d.style == Style::Conversational || (sequence_numbers && d.block_numbers);
        Formatter {
            d,
            fmt,
            sequence: numbered.then_some(0),
            motion: None,
            feed_mode: None,
            feed: None,
            axes: [None; 6],
            buf: String::with_capacity(128),
            program_number: 1000,
            units: "MM",
        }
    }

    fn conversational(&self) -> bool {
        self.d.style == Style::Conversational
    }

    fn start(&mut self) {
        self.buf.clear();
        if let Some(n) = self.sequence.as_mut() {
            if self.d.style == Style::Conversational {
                self.buf.push_str(itoa::Buffer::new().format(*n));
                *n += 1;
            } else {
                *n += 5;
                self.buf.push('N');
                self.buf.push_str(itoa::Buffer::new().format(*n));
            }
            self.buf.push(' ');
        }
    }

    fn fill(&self, template: &str, t: u32, s: i64) -> String {
        let mut out = template.to_string();
        for (k, v) in [
            ("{n4}", format!("{:04}", self.program_number)),
            ("{n5}", format!("{:05}", self.program_number)),
            ("{n}", self.program_number.to_string()),
            ("{UNITS}", self.units.to_string()),
            ("{t}", t.to_string()),
            ("{s}", s.to_string()),
        ] {
            out = out.replace(k, &v);
        }
        out
    }

    /// A comment line; characters the dialect cannot hold in a comment are replaced. Numbered
    /// on a conversational control (every line is).
    pub fn comment(&mut self, text: &str) -> &str {
        if self.conversational() {
            self.start();
        } else {
            self.buf.clear();
        }
        self.buf.push_str(self.d.comment.0);
        let close = self.d.comment.1.chars().next();
        for c in text.chars().take(120) {
            // Nothing that could end the comment early or open another: parentheses and `;`.
            let _ = close;
            self.buf.push(if c == ')' || c == '(' || c == ';' || c.is_control() {
                ' '
            } else {
                c.to_ascii_uppercase()
            });
        }
        self.buf.push_str(self.d.comment.1);
        &self.buf
    }

    /// A line of plain words (e.g. `G90 G17`), with a block number if numbering is on.
    pub fn words(&mut self, words: &str) -> &str {
        self.start();
        self.buf.push_str(words);
        &self.buf
    }

    /// A templated line (`T{t} M6`); `None` for an empty template (the control needs no line).
    pub fn line(&mut self, template: &str, tool: u32, speed: i64) -> Option<String> {
        if template.is_empty() {
            return None;
        }
        let w = self.fill(template, tool, speed);
        Some(self.words(&w).to_string())
    }

    /// Program start: the dialect's opening lines, the header comments, units, safe start.
    pub fn header(&mut self, program_number: u32, units: Units, comments: &[String]) -> Vec<String> {
        self.program_number = program_number;
        self.units = match units {
            Units::Mm => "MM",
            Units::Inch => "INCH",
        };
        let mut out = Vec::new();
        for (t, numbered) in self.d.begin {
            let text = self.fill(t, 0, 0);
            out.push(if *numbered { self.words(&text).to_string() } else { text });
        }
        for c in comments {
            out.push(self.comment(c).to_string());
        }
        let u = match units {
            Units::Mm => self.d.units_mm,
            Units::Inch => self.d.units_inch,
        };
        for w in [u, self.d.safe_start] {
            if !w.is_empty() {
                out.push(self.words(w).to_string());
            }
        }
        out
    }

    /// Program end: spindle and coolant off, compensation off, the dialect's closing lines.
    pub fn footer(&mut self) -> Vec<String> {
        let mut out = Vec::new();
        for w in [self.d.spindle_off, self.d.coolant_off, self.d.tcp_off] {
            if !w.is_empty() {
                out.push(self.words(w).to_string());
            }
        }
        for (t, numbered) in self.d.end {
            let text = self.fill(t, 0, 0);
            out.push(if *numbered { self.words(&text).to_string() } else { text });
        }
        out
    }

    /// Forget the modal state (after a tool change or anything that moves axes unseen).
    pub fn reset_modal(&mut self) {
        self.motion = None;
        self.axes = [None; 6];
        self.feed = None;
        self.feed_mode = None;
    }

    /// One motion block. `axes`: values for X Y Z A B C (None = not on this machine). Returns the
    /// line, or None when nothing changed (no block needed).
    pub fn motion(
        &mut self,
        motion: Motion,
        axes: &[Option<f64>; 6],
        feed: Option<(FeedMode, f64)>,
        extra: &str,
        comment: Option<&str>,
    ) -> Option<&str> {
        let seq_before = self.sequence;
        self.start();
        let start_len = self.buf.len();
        let conv = self.conversational();
        if conv {
            self.buf
                .push_str(if matches!(motion, Motion::Arc { .. }) { "C " } else { "L " });
        } else if let Some((mode, _)) = feed
            && motion != Motion::Rapid
            && self.feed_mode != Some(mode)
        {
            let w = match mode {
                FeedMode::PerMinute => self.d.feed_per_min,
                FeedMode::InverseTime => self.d.inverse_time.unwrap_or(self.d.feed_per_min),
            };
            if !w.is_empty() {
                self.buf.push_str(w);
                self.buf.push(' ');
            }
            self.feed_mode = Some(mode);
            self.feed = None;
        }
        let mut moved = false;
        let motion_pos = self.buf.len();
        let force = matches!(motion, Motion::Arc { .. });
        for (i, v) in axes.iter().enumerate() {
            let Some(v) = v else { continue };
            let dec = if i < 3 { self.fmt.linear } else { self.fmt.rotary };
            let r = round_to(*v, dec);
            // An ISO arc names its end point whole; a Heidenhain `C` only the plane's (a Z
            // there would ask for a helix).
            if (force && i < if conv { 2 } else { 3 }) || self.axes[i] != Some(r) {
                self.axes[i] = Some(r);
                self.buf.push(AXIS_LETTERS[i]);
                if conv && r >= 0 {
                    self.buf.push('+');
                }
                write_fixed(&mut self.buf, r, dec);
                self.buf.push(' ');
                moved = true;
            }
        }
        if !moved {
            self.buf.truncate(start_len);
            self.sequence = seq_before;
            return None;
        }
        if conv {
            if motion == Motion::Rapid {
                self.buf.push_str(self.d.rapid);
                self.buf.push(' ');
            }
        } else if self.motion != Some(motion) {
            let w = match motion {
                Motion::Rapid => self.d.rapid,
                Motion::Feed => self.d.feed,
                Motion::Arc { ccw: true } => "G3",
                Motion::Arc { ccw: false } => "G2",
            };
            self.buf.insert_str(motion_pos, &format!("{w} "));
        }
        self.motion = Some(motion);
        if let Some((mode, f)) = feed
            && motion != Motion::Rapid
        {
            let r = round_to(f, self.fmt.feed);
            // Inverse time needs F on every block; per-minute feed is modal.
            if mode == FeedMode::InverseTime || self.feed != Some(r) {
                self.buf.push('F');
                write_fixed(&mut self.buf, r, self.fmt.feed);
                self.buf.push(' ');
                self.feed = Some(r);
            }
        }
        if !extra.is_empty() {
            self.buf.push_str(extra);
            self.buf.push(' ');
        }
        while self.buf.ends_with(' ') {
            self.buf.pop();
        }
        if let Some(c) = comment {
            self.buf.push(' ');
            self.buf.push_str(self.d.comment.0);
            self.buf.push_str(c);
            self.buf.push_str(self.d.comment.1);
        }
        Some(&self.buf)
    }

    /// The value a word of this axis index carries once written (for replaying what was output).
    pub fn written(&self, value: f64, axis_index: usize) -> f64 {
        let dec = if axis_index < 3 { self.fmt.linear } else { self.fmt.rotary };
        round_to(value, dec) as f64 / 10f64.powi(dec as i32)
    }
}
