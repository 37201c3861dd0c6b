//! NC output: controller dialects as data, plus small formatters. The engine hands over program
//! events (tool change, spindle, motion blocks …); a [`Formatter`] turns each into text lines in
//! its dialect, suppressing modal words, and keeps no more state than a controller would.

mod number;
pub mod read;

pub use number::{round_to, write_fixed};

use crate::kinematics::Units;

/// A controller's words for the same things. Only data: adding a word-address dialect is a value.
#[derive(Clone, Debug)]
pub struct Dialect {
    pub name: &'static str,
    pub comment: (&'static str, &'static str),
    pub program_start: &'static [&'static str],
    pub program_end: &'static [&'static str],
    pub units_mm: &'static str,
    pub units_inch: &'static str,
    pub safe_start: &'static str,
    pub rapid: &'static str,
    pub feed: &'static str,
    pub feed_per_min: &'static str,
    pub inverse_time: &'static str,
    /// `{t}` is the tool (and length offset) number.
    pub tool_change: &'static str,
    pub length_comp: &'static str,
    pub tcp_on: &'static str,
    pub tcp_off: &'static str,
    pub spindle_cw: &'static str,
    pub spindle_ccw: &'static str,
    pub spindle_off: &'static str,
    pub coolant_flood: &'static str,
    pub coolant_mist: &'static str,
    pub coolant_through: &'static str,
    pub coolant_off: &'static str,
    pub block_numbers: bool,
}

pub const FANUC: Dialect = Dialect {
    name: "fanuc",
    comment: ("(", ")"),
    program_start: &["%"],
    program_end: &["M30", "%"],
    units_mm: "G21",
    units_inch: "G20",
    safe_start: "G90 G17 G40 G49 G80",
    rapid: "G0",
    feed: "G1",
    feed_per_min: "G94",
    inverse_time: "G93",
    tool_change: "T{t} M6",
    length_comp: "G43 H{t}",
    tcp_on: "G43.4 H{t}",
    tcp_off: "G49",
    spindle_cw: "M3",
    spindle_ccw: "M4",
    spindle_off: "M5",
    coolant_flood: "M8",
    coolant_mist: "M7",
    coolant_through: "M88",
    coolant_off: "M9",
    block_numbers: true,
};

pub fn dialect(name: &str) -> Option<&'static Dialect> {
    match name {
        "fanuc" => Some(&FANUC),
        _ => None,
    }
}

pub const DIALECTS: &[&str] = &["fanuc"];

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
    sequence: Option<u32>,
    motion: Option<Motion>,
    feed_mode: Option<FeedMode>,
    feed: Option<i64>,
    /// Last written value of each axis word (X Y Z A B C), as rounded integers.
    axes: [Option<i64>; 6],
    buf: String,
}

pub const AXIS_LETTERS: [char; 6] = ['X', 'Y', 'Z', 'A', 'B', 'C'];

impl Formatter {
    pub fn new(d: &'static Dialect, fmt: Formats, sequence_numbers: bool) -> Formatter {
        Formatter {
            d,
            fmt,
            sequence: (sequence_numbers && d.block_numbers).then_some(0),
            motion: None,
            feed_mode: None,
            feed: None,
            axes: [None; 6],
            buf: String::with_capacity(128),
        }
    }

    fn start(&mut self) {
        self.buf.clear();
        if let Some(n) = self.sequence.as_mut() {
            *n += 5;
            self.buf.push('N');
            self.buf.push_str(itoa::Buffer::new().format(*n));
            self.buf.push(' ');
        }
    }

    /// A comment line; characters the dialect cannot hold in a comment are replaced.
    pub fn comment(&mut self, text: &str) -> &str {
        self.buf.clear();
        self.buf.push_str(self.d.comment.0);
        let close = self.d.comment.1.chars().next();
        for c in text.chars().take(120) {
            self.buf.push(if Some(c) == close || c == '(' || c.is_control() {
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

    pub fn words_t(&mut self, template: &str, tool: u32) -> &str {
        let w = template.replace("{t}", itoa::Buffer::new().format(tool));
        self.words(&w)
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
        self.start();
        let start_len = self.buf.len();
        if let Some((mode, _)) = feed
            && motion == Motion::Feed
            && self.feed_mode != Some(mode)
        {
            self.buf.push_str(match mode {
                FeedMode::PerMinute => self.d.feed_per_min,
                FeedMode::InverseTime => self.d.inverse_time,
            });
            self.buf.push(' ');
            self.feed_mode = Some(mode);
            self.feed = None;
        }
        let mut moved = false;
        let motion_pos = self.buf.len();
        for (i, v) in axes.iter().enumerate() {
            let Some(v) = v else { continue };
            let dec = if i < 3 { self.fmt.linear } else { self.fmt.rotary };
            let r = round_to(*v, dec);
            if self.axes[i] != Some(r) {
                self.axes[i] = Some(r);
                self.buf.push(AXIS_LETTERS[i]);
                write_fixed(&mut self.buf, r, dec);
                self.buf.push(' ');
                moved = true;
            }
        }
        if !moved {
            self.buf.truncate(start_len);
            if self.sequence.is_some() {
                // Undo the block number we took.
                if let Some(n) = self.sequence.as_mut() {
                    *n -= 5;
                }
            }
            return None;
        }
        if self.motion != Some(motion) {
            let w = match motion {
                Motion::Rapid => self.d.rapid,
                Motion::Feed => self.d.feed,
            };
            self.buf.insert_str(motion_pos, &format!("{w} "));
            self.motion = Some(motion);
        }
        if let Some((mode, f)) = feed
            && motion == Motion::Feed
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
