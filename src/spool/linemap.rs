//! The line map a job writes beside its NC: one fixed-size entry per NC line, so that a viewer
//! can show any line of a program of millions by byte range, link it to the CL line it came
//! from, and jump to the next error, warning or unwind without reading the NDJSON.
//!
//! Each entry is [`ENTRY`] bytes, four little-endian `u32`: the line's byte offset in the NC
//! (low 32 bits, then high), its CL line (0: none), and its flags ([`ERROR`], [`WARNING`],
//! [`UNWIND`], [`BRANCH_CHANGE`], [`TOOL_CHANGE`]).

use crate::diag::{Code, Severity};
use crate::post::BlockInfo;
use std::io::Write;

/// Bytes per NC line.
pub const ENTRY: usize = 16;
/// A block with an error, or an `ERROR` comment the program carries where a pose was skipped.
pub const ERROR: u32 = 1;
pub const WARNING: u32 = 2;
pub const UNWIND: u32 = 4;
pub const BRANCH_CHANGE: u32 = 8;
/// A line that changes the tool (`M6`, `TOOL CALL n`).
pub const TOOL_CHANGE: u32 = 16;

/// One NC line's entry.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Entry {
    pub offset: u64,
    pub cl: u32,
    pub flags: u32,
}

impl Entry {
    /// The entry as the line map serves it.
    pub fn to_bytes(self) -> [u8; ENTRY] {
        let mut e = [0u8; ENTRY];
        e[0..4].copy_from_slice(&(self.offset as u32).to_le_bytes());
        e[4..8].copy_from_slice(&((self.offset >> 32) as u32).to_le_bytes());
        e[8..12].copy_from_slice(&self.cl.to_le_bytes());
        e[12..16].copy_from_slice(&self.flags.to_le_bytes());
        e
    }
}

/// Makes the entries as the program's lines go by (the writers' one definition of them).
#[derive(Default)]
pub struct Entries {
    offset: u64,
}

impl Entries {
    /// The entry of one NC line as the NC file has it (`text` and its newline).
    pub fn next(&mut self, text: &str, b: Option<&BlockInfo>) -> Entry {
        let (cl, flags) = match b {
            Some(b) => (b.source_line.unwrap_or(0), block_flags(b)),
            None => other_line(text),
        };
        let offset = self.offset;
        self.offset += text.len() as u64 + 1;
        Entry {
            offset,
            cl,
            flags: flags | tool_change(text),
        }
    }
}

/// Writes the fixed-size entries as the program's lines go by (what the line map serves; a job
/// stores them compactly, `spool::lines`).
pub struct LineMap<W: Write> {
    out: W,
    entries: Entries,
}

impl<W: Write> LineMap<W> {
    pub fn new(out: W) -> Self {
        LineMap {
            out,
            entries: Entries::default(),
        }
    }

    /// One NC line as the NC file has it (`text` and its newline).
    pub fn line(&mut self, text: &str, b: Option<&BlockInfo>) -> std::io::Result<()> {
        self.out.write_all(&self.entries.next(text, b).to_bytes())
    }

    pub fn into_inner(self) -> W {
        self.out
    }
}

fn block_flags(b: &BlockInfo) -> u32 {
    b.diagnostics.iter().fold(0, |f, d| {
        let severity = match d.severity {
            Severity::Error => ERROR,
            Severity::Warning => WARNING,
            Severity::Info => 0,
        };
        let event = match d.code {
            Code::Unwind => UNWIND,
            Code::BranchChange => BRANCH_CHANGE,
            _ => 0,
        };
        f | severity | event
    })
}

/// A line that is no motion block: an `ERROR` comment names the CL line it is about.
fn other_line(text: &str) -> (u32, u32) {
    let Some(at) = text.find("ERROR ") else {
        return (0, 0);
    };
    let cl = text[at..]
        .split_once("CL LINE ")
        .and_then(|(_, rest)| {
            let digits = rest.bytes().take_while(u8::is_ascii_digit).count();
            rest[..digits].parse().ok()
        })
        .unwrap_or(0);
    (cl, ERROR)
}

/// `M6`/`M06` as a word outside a comment, or a TNC `TOOL CALL` that names a tool (a speed-only
/// `TOOL CALL S…` changes nothing).
fn tool_change(text: &str) -> u32 {
    // Neither `M` nor `T`: no tool change (a motion block, millions of them; this is the cheap test).
    if memchr::memchr2(b'M', b'T', text.as_bytes()).is_none() {
        return 0;
    }
    let code = text.split([';', '(']).next().unwrap_or("");
    let m6 = code.split_ascii_whitespace().any(|w| matches!(w, "M6" | "M06"));
    let call = code
        .split_once("TOOL CALL ")
        .is_some_and(|(_, r)| r.starts_with(|c: char| c.is_ascii_digit()));
    if m6 || call { TOOL_CHANGE } else { 0 }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn entries(buf: &[u8]) -> Vec<[u32; 4]> {
        buf.chunks(ENTRY)
            .map(|c| std::array::from_fn(|i| u32::from_le_bytes(c[i * 4..i * 4 + 4].try_into().unwrap())))
            .collect()
    }

    #[test]
    fn offsets_cl_lines_and_flags() {
        let mut m = LineMap::new(Vec::new());
        m.line("%", None).unwrap();
        m.line("T1 M6 (FACE MILL M6)", None).unwrap();
        m.line("(ERROR UNREACHABLE CL LINE 10: POSE UNREACHABLE)", None).unwrap();
        m.line("TOOL CALL S6000", None).unwrap();
        m.line("7 TOOL CALL 3 Z", None).unwrap();
        let e = entries(&m.into_inner());
        assert_eq!(e[0], [0, 0, 0, 0]);
        assert_eq!(e[1], [2, 0, 0, TOOL_CHANGE]);
        assert_eq!(e[2], [23, 0, 10, ERROR]);
        assert_eq!(e[3][3], 0);
        assert_eq!(e[4][3], TOOL_CHANGE);
    }
}
