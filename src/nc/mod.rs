//! NC output: controller dialects as data, plus small formatters. The engine hands over program
//! events (tool change, spindle, motion blocks …); a [`Formatter`] turns each into text lines in
//! its dialect, suppressing modal words, and keeps no more state than a controller would.

mod cycles;
mod dialect;
mod dialects;
pub mod templates;
mod number;
pub mod plane;
pub mod read;

pub use cycles::{Canned, CannedKind, CycleLines, Cycles, IsoTaps};
pub use dialect::{Dialect, Frame, MAX_DIALECT_BYTES, Sequence, Smoothing, WordFormat, parse_dialect};
pub use dialects::{BUILTIN_FILES, DIALECTS, Risk, builtins, dialect, function_risk};
pub use number::{restyle, round_to, write_fixed};
pub use plane::Planes;

use crate::kinematics::Units;
use std::sync::Arc;

/// How a control's blocks are put together.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Style {
    /// ISO word address: `N10 G1 X1.000 Y2.000 F500.0 (comment)`.
    WordAddress,
    /// Heidenhain conversational: `12 L X+1.000 Y+2.000 F500 ; comment`, every line numbered from
    /// 0, signed numbers, FMAX for rapids.
    Conversational,
}

/// What a control's words take. Beyond it a word is an error naming its CL line (and written at
/// the bound where that is the safe side: a slower feed, a shorter dwell), never a number that
/// rounds to zero or wraps.
#[derive(Clone, Copy, Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Ranges {
    /// Largest programmed feed per minute, mm/min (an inch program's: this over 25.4).
    pub feed_mm: f64,
    /// Largest inverse-time F, 1/min (a block of 0.6 ms at 99 999.999).
    pub inverse_time: f64,
    /// Largest tool number (T) and offset register (H, D).
    pub tool: u32,
    pub register: u32,
    /// Longest dwell, seconds.
    pub dwell_s: f64,
}

/// Number formats: linear words 3 decimals in mm, 4 in inch; rotary words 4 decimals; feed 1
/// (mm) or 2 (inch); inverse time 3, as NX's Haas post writes it: a 1/min value is small where
/// a move is long, and one decimal of F2.4 is a 2 % error in the move's time.
#[derive(Clone, Copy, Debug)]
pub struct Formats {
    pub linear: u32,
    pub rotary: u32,
    pub feed: u32,
    pub inverse_feed: u32,
}

impl Formats {
    pub fn feed_decimals(&self, mode: FeedMode) -> u32 {
        match mode {
            FeedMode::InverseTime => self.inverse_feed,
            FeedMode::PerMinute => self.feed,
        }
    }

    /// The smallest F the word can carry: below half of it the word says F0, an alarm.
    pub fn feed_step(&self, mode: FeedMode) -> f64 {
        10f64.powi(-(self.feed_decimals(mode) as i32))
    }

    /// Half the last digit of a linear word: lengths closer than this write the same word.
    pub fn half_linear(&self) -> f64 {
        0.5 * 10f64.powi(-(self.linear as i32))
    }

    /// Half the last digit of a rotary word, in degrees.
    pub fn half_rotary(&self) -> f64 {
        0.5 * 10f64.powi(-(self.rotary as i32))
    }

    /// The formats of `d` in units `u`: the defaults below, where the dialect says nothing.
    pub fn for_dialect(d: &Dialect, u: Units) -> Formats {
        let mut f = Formats::for_units(u);
        let w = d.format;
        let (linear, feed) = match u {
            Units::Mm => (w.linear_mm, w.feed_mm),
            Units::Inch => (w.linear_inch, w.feed_inch),
        };
        f.linear = linear.unwrap_or(f.linear);
        f.feed = feed.unwrap_or(f.feed);
        f.rotary = w.rotary.unwrap_or(f.rotary);
        f.inverse_feed = w.inverse_time.unwrap_or(f.inverse_feed);
        f
    }

    pub fn for_units(u: Units) -> Formats {
        match u {
            Units::Mm => Formats {
                linear: 3,
                rotary: 4,
                feed: 1,
                inverse_feed: 3,
            },
            Units::Inch => Formats {
                linear: 4,
                rotary: 4,
                feed: 2,
                inverse_feed: 3,
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
    pub d: Arc<Dialect>,
    pub fmt: Formats,
    /// Next block number, when blocks are numbered: N5, N10 … (word address, optional) or
    /// 0, 1, 2 … on every line (conversational), unless the dialect says otherwise.
    sequence: Option<u32>,
    step: u32,
    /// The dialect writes numbers otherwise than the defaults (no trailing or leading zeros).
    restyle: bool,
    motion: Option<Motion>,
    feed_mode: Option<FeedMode>,
    feed: Option<i64>,
    /// Last written value of each axis word (X Y Z A B C), as rounded integers.
    axes: [Option<i64>; 6],
    buf: String,
    program_number: u32,
    units: &'static str,
    /// The job's tolerance, for the dialect's blending word.
    pub tolerance: f64,
    /// Blocks start with `/`: the operator's block delete skips them (CL `OPSKIP/ON`).
    pub block_skip: bool,
    /// The origin of the work offset in force relative to the program's first (profile units):
    /// X Y Z words are measured from it (`setups=work-offsets`); 0 for the rotary words, so the
    /// words' hot loop subtracts without a branch.
    shift: [f64; 6],
}

/// The axis words' addresses as bytes, for the formatter's hot loop.
pub const AXIS_ADDRESSES: [u8; 6] = *b"XYZABC";

/// The same letters as `char`s, for summaries and previews.
pub const AXIS_LETTERS: [char; 6] = {
    let mut letters = ['\0'; 6];
    let mut i = 0;
    while i < 6 {
        letters[i] = AXIS_ADDRESSES[i] as char;
        i += 1;
    }
    letters
};

/// `text` as one comment in `d`'s syntax, appended to `buf`: nothing in it can end the comment
/// early or open another (parentheses, `;`, control characters), at most 120 characters.
fn push_comment(buf: &mut String, d: &Dialect, text: &str) {
    let room = match d.line_length {
        0 => 120,
        n => n.saturating_sub(buf.len() + d.comment.0.len() + d.comment.1.len()).min(120),
    };
    buf.push_str(&d.comment.0);
    for c in text.chars().take(room) {
        buf.push(if closes_comment(c) { ' ' } else { c.to_ascii_uppercase() });
    }
    buf.push_str(&d.comment.1);
}

/// A character no text from outside may bring into a block: a comment's delimiters (every
/// dialect's: `(`, `)`, `;`) and control characters (a line break would start a block).
fn closes_comment(c: char) -> bool {
    c == ')' || c == '(' || c == ';' || c.is_control()
}

/// Text from the CL (an operation's name) as a template may write it: what would end a comment
/// or a block made a space, as in every comment, its case kept, at most 120 characters.
pub fn comment_safe(text: &str) -> String {
    text.chars().take(120).map(|c| if closes_comment(c) { ' ' } else { c }).collect()
}

impl Dialect {
    /// Whether the control knows `word` (a whole word such as `M13`); words other than M codes
    /// are not judged here.
    pub fn knows(&self, word: &str) -> bool {
        let Some(ranges) = &self.m_codes else { return true };
        match word.strip_prefix('M').map(str::parse::<u32>) {
            Some(Ok(n)) => ranges.iter().any(|(lo, hi)| (*lo..=*hi).contains(&n)),
            Some(Err(_)) => false,
            None => true,
        }
    }

    /// The word that puts the control in feed mode `mode` (empty: none needed or none there).
    pub fn feed_mode_word(&self, mode: FeedMode) -> &str {
        match mode {
            FeedMode::PerMinute => &self.feed_per_min,
            FeedMode::InverseTime => self.inverse_time.as_deref().unwrap_or(&self.feed_per_min),
        }
    }

    /// A comment line outside any program's numbering: the last line of a program cut short.
    pub fn comment_line(&self, text: &str) -> String {
        let mut s = String::new();
        push_comment(&mut s, self, text);
        s
    }
}

impl Formatter {
    pub fn new(d: Arc<Dialect>, fmt: Formats, sequence_numbers: bool) -> Formatter {
        let numbered = d.style == Style::Conversational || (sequence_numbers && d.block_numbers);
        let seq = d.sequence.unwrap_or(match d.style {
            Style::Conversational => Sequence { start: 0, step: 1, width: 0 },
            Style::WordAddress => Sequence { start: 5, step: 5, width: 0 },
        });
        let restyle = !d.format.trailing_zeros || !d.format.leading_zero;
        Formatter {
            d,
            fmt,
            sequence: numbered.then_some(seq.start),
            step: seq.step,
            restyle,
            tolerance: 0.0,
            motion: None,
            feed_mode: None,
            feed: None,
            axes: [None; 6],
            buf: String::with_capacity(128),
            program_number: 1000,
            units: "MM",
            block_skip: false,
            shift: [0.0; 6],
        }
    }

    fn conversational(&self) -> bool {
        self.d.style == Style::Conversational
    }

    fn start(&mut self) {
        self.buf.clear();
        if self.block_skip {
            self.buf.push_str(&self.d.block_delete);
        }
        if let Some(n) = self.sequence.as_mut() {
            if self.d.style == Style::WordAddress {
                self.buf.push('N');
            }
            let digits = itoa::Buffer::new().format(*n).to_string();
            let width = self.d.sequence.map_or(0, |s| s.width as usize);
            for _ in digits.len()..width {
                self.buf.push('0');
            }
            self.buf.push_str(&digits);
            *n = n.saturating_add(self.step);
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
            ("{tol}", format!("{:.*}", self.fmt.linear as usize, self.tolerance)),
        ] {
            out = out.replace(k, &v);
        }
        out
    }

    /// Lines go out as written: no number restyled, no length to check (every built-in).
    pub fn plain(&self) -> bool {
        !self.restyle && self.d.line_length == 0
    }

    /// A line as the dialect's number format wants it, and whether it is longer than the
    /// control reads.
    pub fn finish<'a>(&self, line: &'a str) -> (std::borrow::Cow<'a, str>, bool) {
        let text: std::borrow::Cow<'a, str> = if self.restyle {
            let f = self.d.format;
            restyle(line, &self.d.comment.0, f.trailing_zeros, f.leading_zero).into()
        } else {
            line.into()
        };
        let long = self.d.line_length > 0 && text.len() > self.d.line_length;
        (text, long)
    }

    /// A comment line; characters the dialect cannot hold in a comment are replaced. Numbered
    /// on a conversational control (every line is).
    pub fn comment(&mut self, text: &str) -> &str {
        if self.conversational() {
            self.start();
        } else {
            self.buf.clear();
        }
        push_comment(&mut self.buf, &self.d, text);
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

    /// Program start: the dialect's opening lines, the header comments, units, safe start (with
    /// `wcs`, a work coordinate word, last on it).
    pub fn header(&mut self, program_number: u32, units: Units, comments: &[String], wcs: Option<&str>) -> Vec<String> {
        self.program_number = program_number;
        self.units = match units {
            Units::Mm => "MM",
            Units::Inch => "INCH",
        };
        let mut out = Vec::new();
        let d = self.d.clone();
        for f in &d.begin {
            let text = self.fill(&f.text, 0, 0);
            out.push(if f.numbered { self.words(&text).to_string() } else { text });
        }
        for c in comments {
            out.push(self.comment(c).to_string());
        }
        let u = match units {
            Units::Mm => &d.units_mm,
            Units::Inch => &d.units_inch,
        };
        let start = match wcs {
            Some(w) if d.safe_start.is_empty() => w.to_string(),
            Some(w) => format!("{} {w}", d.safe_start),
            None => d.safe_start.to_string(),
        };
        let blend = self.fill(&d.blend, 0, 0);
        for w in [u, &start, &blend] {
            if !w.is_empty() {
                out.push(self.words(w).to_string());
            }
        }
        out
    }

    /// A dialect's `[smoothing]` lines as written, `{tol}` the operation's tolerance `tol`.
    pub fn smoothing(&mut self, lines: &[String], tol: f64) -> Vec<String> {
        let tol = format!("{:.*}", self.fmt.linear as usize, tol);
        lines.iter().map(|l| {
            let text = self.fill(&l.replace("{tol}", &tol), 0, 0);
            self.words(&text).to_string()
        }).collect()
    }

    /// Program end: spindle and coolant off, compensation off (then, `z_up`, the spindle to
    /// machine Z home), the dialect's closing lines.
    /// `tcp_off`: lines in place of the dialect's TCP-off word (its template's).
    pub fn footer(&mut self, z_up: bool, tcp_off: Option<Vec<String>>) -> Vec<String> {
        // The program's end runs whatever the block delete switch says.
        self.block_skip = false;
        let mut out = Vec::new();
        let d = self.d.clone();
        let up = if z_up { d.machine_z_up.as_str() } else { "" };
        let off = tcp_off.unwrap_or_else(|| vec![d.tcp_off.clone()]);
        let words = [d.spindle_off.as_str(), &d.coolant_off].into_iter().chain(off.iter().map(String::as_str)).chain([up]);
        for w in words {
            if !w.is_empty() {
                out.push(self.words(w).to_string());
            }
        }
        out.extend(self.closing());
        out
    }

    /// The dialect's closing lines (`M30`, `%`).
    pub fn closing(&mut self) -> Vec<String> {
        let d = self.d.clone();
        let mut out = Vec::new();
        for f in &d.end {
            let text = self.fill(&f.text, 0, 0);
            out.push(if f.numbered { self.words(&text).to_string() } else { text });
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

    /// One motion block. `words`: X Y Z A B C as written, rounded by [`Formatter::round_words`]
    /// (None = not on this machine): the emitter rounds each once, for the line and for its FK
    /// replay. Returns the line, or None when nothing changed (no block needed).
    pub fn motion(
        &mut self,
        motion: Motion,
        words: &[Option<i64>; 6],
        feed: Option<(FeedMode, f64)>,
        extra: &str,
        comp: &str,
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
            && let Some(d) = self.switch_feed_mode(mode)
        {
            self.buf.push_str(d.feed_mode_word(mode));
            self.buf.push(' ');
        }
        let mut moved = false;
        let motion_pos = self.buf.len();
        let force = matches!(motion, Motion::Arc { .. });
        // Read once: the dialect is behind a pointer the word writer could alias.
        let every_word = !self.d.format.modal;
        for (i, r) in words.iter().enumerate() {
            let Some(r) = *r else { continue };
            let dec = self.decimals(i);
            // An ISO arc names its end point whole; a Heidenhain `C` only the plane's (a Z
            // there would ask for a helix).
            let changed = (force && i < if conv { 2 } else { 3 }) || self.axes[i] != Some(r);
            if changed || every_word {
                self.axes[i] = Some(r);
                number::write_word(&mut self.buf, AXIS_ADDRESSES[i], conv, r, dec);
                moved |= changed;
            }
        }
        if !moved {
            self.buf.truncate(start_len);
            self.sequence = seq_before;
            return None;
        }
        // Compensation words: ISO before the axes (`G1 G41 D5 X…`), conversational after them
        // (`L X+… RL F…`).
        if !comp.is_empty() {
            if conv {
                self.buf.push_str(comp);
                self.buf.push(' ');
            } else {
                self.buf.insert_str(motion_pos, &format!("{comp} "));
            }
        }
        if conv {
            if motion == Motion::Rapid {
                self.buf.push_str(&self.d.rapid);
                self.buf.push(' ');
            }
        } else if self.motion != Some(motion) {
            let w = match motion {
                Motion::Rapid => self.d.rapid.as_str(),
                Motion::Feed => self.d.feed.as_str(),
                Motion::Arc { ccw: true } => "G3",
                Motion::Arc { ccw: false } => "G2",
            };
            self.buf.insert_str(motion_pos, &format!("{w} "));
        }
        self.motion = Some(motion);
        if let Some((mode, f)) = feed
            && motion != Motion::Rapid
        {
            let dec = self.fmt.feed_decimals(mode);
            let r = round_to(f, dec);
            // Inverse time needs F on every block; per-minute feed is modal.
            if mode == FeedMode::InverseTime || self.feed != Some(r) {
                self.buf.push('F');
                write_fixed(&mut self.buf, r, dec);
                if mode == FeedMode::InverseTime {
                    // Its decimals are for small values: F3200.0, not F3200.000.
                    while self.buf.ends_with('0') && !self.buf[..self.buf.len() - 1].ends_with('.') {
                        self.buf.pop();
                    }
                }
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
            self.buf.push_str(&self.d.comment.0);
            self.buf.push_str(c);
            self.buf.push_str(&self.d.comment.1);
        }
        Some(&self.buf)
    }

    /// The word that switches the feed mode to `mode`, when it is not on already (the modal F is
    /// forgotten then: it means another thing now). `None` also where the control has no word.
    fn switch_feed_mode(&mut self, mode: FeedMode) -> Option<Arc<Dialect>> {
        if self.feed_mode == Some(mode) {
            return None;
        }
        self.feed_mode = Some(mode);
        self.feed = None;
        (!self.d.feed_mode_word(mode).is_empty()).then(|| self.d.clone())
    }

    fn number(&mut self, v: f64, dec: u32, signed: bool) {
        let r = round_to(v, dec);
        if signed && r >= 0 {
            self.buf.push('+');
        }
        write_fixed(&mut self.buf, r, dec);
    }

    /// A dwell of `seconds` (APT's `DELAY`): `G4 P` in milliseconds on Fanuc, in seconds with a
    /// decimal point on Haas and LinuxCNC (a Haas `P` without one is milliseconds), `G4 F`
    /// seconds on a Sinumerik (`G4 S` would be revolutions), cycle 9 on a TNC.
    pub fn dwell(&mut self, seconds: f64) -> Vec<String> {
        let mut out = Vec::new();
        let (word, ms) = match self.d.cycles {
            Cycles::Iso { dwell_ms, .. } => ("G4 P", dwell_ms),
            Cycles::Siemens => ("G4 F", false),
            Cycles::Heidenhain => {
                out.push(self.words("CYCL DEF 9.0 DWELL TIME").to_string());
                ("CYCL DEF 9.1 DWELL ", false)
            }
        };
        self.start();
        self.buf.push_str(word);
        self.seconds(seconds, ms);
        out.push(self.buf.clone());
        out
    }

    /// A time word's value: whole milliseconds, or seconds to 3 decimals (the point says so).
    fn seconds(&mut self, s: f64, ms: bool) {
        if ms {
            self.buf.push_str(itoa::Buffer::new().format((s * 1000.0).round() as i64));
        } else {
            self.number(s, 3, false);
        }
    }

    /// The value a word of this axis index carries once written (for replaying what was output).
    /// The lines that tilt the working plane to `frame` (after the rotaries stand there), and
    /// the frame as the control builds it from the words as written (rounded angles).
    /// `positive`: the sign of the tilting rotary, for the controls that choose a solution.
    pub fn plane_on(&mut self, frame: &nalgebra::Matrix3<f64>, positive: bool) -> (Vec<String>, nalgebra::Matrix3<f64>) {
        let p = self.d.planes;
        let a = plane::angles(p, frame);
        let rd = self.fmt.rotary;
        let deg = a.map(|r| number::rounded(r.to_degrees(), rd));
        let written = match p {
            Planes::Haas | Planes::None => *frame,
            _ => plane::frame(p, deg.map(f64::to_radians)),
        };
        let conv = self.conversational();
        self.start();
        let named = |head, names, tail| Some((head, names, tail));
        let words: Option<(&str, [&str; 3], &str)> = match p {
            Planes::Fanuc => named("G68.2 X0 Y0 Z0", ["I", "J", "K"], ""),
            Planes::Heidenhain => named(
                "PLANE SPATIAL",
                ["SPA", "SPB", "SPC"],
                if positive { " TURN FMAX SEQ+" } else { " TURN FMAX SEQ-" },
            ),
            _ => None,
        };
        match (p, words) {
            (_, Some((head, names, tail))) => {
                self.buf.push_str(head);
                for (l, v) in names.into_iter().zip(deg) {
                    self.buf.push(' ');
                    self.buf.push_str(l);
                    self.number(v, rd, conv);
                }
                self.buf.push_str(tail);
            }
            (Planes::Haas, _) => self.buf.push_str("G254"),
            (Planes::Siemens, _) => {
                self.buf.push_str("CYCLE800(0,\"TC1\",0,57,0,0,0");
                for v in deg {
                    self.buf.push(',');
                    self.number(v, rd, false);
                }
                self.buf.push_str(if positive { ",0,0,0,1,0)" } else { ",0,0,0,-1,0)" });
            }
            _ => return (Vec::new(), written),
        }
        let mut out = vec![self.buf.clone()];
        if p == Planes::Fanuc {
            out.push(self.words("G53.1").to_string());
        }
        // Coordinates change meaning: every word is written again.
        self.reset_modal();
        (out, written)
    }

    /// The line that returns to the untilted program coordinates.
    pub fn plane_off(&mut self) -> Option<String> {
        let w = match self.d.planes {
            Planes::Fanuc => "G69",
            Planes::Haas => "G255",
            Planes::Siemens => "CYCLE800()",
            Planes::Heidenhain => "PLANE RESET STAY",
            Planes::None => return None,
        };
        let l = self.words(w).to_string();
        self.reset_modal();
        Some(l)
    }

    pub fn written(&self, value: f64, axis_index: usize) -> f64 {
        let s = self.shift_of(axis_index);
        number::rounded(value - s, self.decimals(axis_index)) + s
    }

    /// From here X Y Z words are measured from `shift` (another work offset's origin); every
    /// word is written again.
    pub fn set_shift(&mut self, shift: [f64; 3]) {
        self.shift[..3].copy_from_slice(&shift);
        self.reset_modal();
    }

    #[inline]
    fn shift_of(&self, axis_index: usize) -> f64 {
        self.shift[axis_index]
    }

    /// Decimals of the word for axis slot `axis_index` (X Y Z A B C).
    #[inline]
    pub fn decimals(&self, axis_index: usize) -> u32 {
        if axis_index < 3 { self.fmt.linear } else { self.fmt.rotary }
    }

    /// The words of `axes` as written: integers of 10^-decimals (see [`Formatter::motion`]).
    #[inline]
    pub fn round_words(&self, axes: &[Option<f64>; 6]) -> [Option<i64>; 6] {
        let mut r = [None; 6];
        for (k, v) in axes.iter().enumerate() {
            r[k] = v.map(|v| round_to(v - self.shift_of(k), self.decimals(k)));
        }
        r
    }

    /// The value a rounded word stands for: [`Formatter::written`] of what it was rounded from.
    #[inline]
    pub fn word_value(&self, rounded: i64, axis_index: usize) -> f64 {
        number::value(rounded, self.decimals(axis_index)) + self.shift_of(axis_index)
    }
}
