//! CL (APT / CLSF) reading: a streaming statement reader that never fails the whole file.
//!
//! Bytes in, events out: each event is a record with its source line, or a diagnostic. Memory is
//! one statement (bounded by [`MAX_STATEMENT`]); a malformed record becomes an error diagnostic
//! naming line, column and what was expected, and reading goes on.

mod foreign;
mod record;
pub mod vocabulary;

pub use record::drive;
pub use record::flow::{CutterComp, Side};
pub use foreign::{NcKind, NcSeen, nc_kind};
pub use record::moves::Plane;

pub use record::{CoolantCmd, CycleKind, CycleParams, Dwell, FeedUnit, Record, SpindleCmd, parse_statement};

use crate::diag::{Code, Diagnostic, Severity};
use std::io::BufRead;

/// Distinct repeated diagnostics counted (`Reader::repeats`); past these, each is told as it comes.
const MAX_REPEATS: usize = 1024;

/// Longest statement (after joining `$` continuations) kept; longer ones are reported and skipped.
pub const MAX_STATEMENT: usize = 64 * 1024;

/// One parsed record and the line its statement starts on.
#[derive(Clone, Debug, PartialEq)]
pub struct Statement {
    pub line: u32,
    pub record: Record,
}

#[derive(Clone, Debug, PartialEq)]
pub enum Event {
    Statement(Statement),
    Diagnostic(Diagnostic),
}

#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error("reading CL input: {0}")]
    Io(#[from] std::io::Error),
}

/// Streaming reader over any `BufRead` (a file, stdin, an HTTP body).
pub struct Reader<R> {
    input: R,
    raw: Vec<u8>,
    line_no: u32,
    pending: String,
    pending_line: u32,
    pending_overflow: bool,
    in_comment: bool,
    queue: std::collections::VecDeque<Event>,
    done: bool,
    /// The byte order mark was looked for (once, before the first line).
    started: bool,
    /// Bytes of input consumed: what a post's output budget is counted against.
    consumed: u64,
    /// Unknown records that read as NC: what the input is when it is no CL.
    nc: NcSeen,
    /// Statements read (records, bad records, unknown ones).
    statements: u64,
    /// The line of the program's `END`/`FINI`: text after it that is no record is no part of
    /// the program (CATIA's demo ends in a stray line of letters).
    end: Option<u32>,
    /// A word told again and again (an unknown record, a word not acted on: 72 to 1 559 lines of
    /// one in a file) is told by one record a program, at the end, naming its first line and its
    /// count: by message, the first diagnostic held and the count.
    repeats: std::collections::HashMap<String, (Diagnostic, u64)>,
}

impl<R: BufRead> Reader<R> {
    pub fn new(input: R) -> Reader<R> {
        Reader {
            input,
            raw: Vec::with_capacity(256),
            line_no: 0,
            pending: String::with_capacity(256),
            pending_line: 0,
            pending_overflow: false,
            in_comment: false,
            queue: Default::default(),
            done: false,
            started: false,
            consumed: 0,
            nc: NcSeen::default(),
            statements: 0,
            end: None,
            repeats: Default::default(),
        }
    }

    pub fn line(&self) -> u32 {
        self.line_no
    }

    pub fn bytes_read(&self) -> u64 {
        self.consumed
    }

    /// Statements read so far.
    pub fn statements(&self) -> u64 {
        self.statements
    }

    /// The unknown records so far that read as NC.
    pub fn nc_seen(&self) -> &NcSeen {
        &self.nc
    }

    /// Reads one physical line into `raw` without letting a huge line grow memory: past
    /// `MAX_STATEMENT` bytes the rest of the line is consumed and dropped. Returns (got a line,
    /// overflowed).
    fn read_line(&mut self) -> Result<(bool, bool), Error> {
        self.raw.clear();
        let mut overflow = false;
        loop {
            let buf = fill(&mut self.input)?;
            if buf.is_empty() {
                return Ok((!self.raw.is_empty() || overflow, overflow));
            }
            let (take, end) = match memchr(b'\n', buf) {
                Some(i) => (i + 1, true),
                None => (buf.len(), false),
            };
            let room = MAX_STATEMENT.saturating_sub(self.raw.len());
            if take > room {
                overflow = true;
                self.raw.extend_from_slice(&buf[..room]);
            } else {
                self.raw.extend_from_slice(&buf[..take]);
            }
            self.input.consume(take);
            self.consumed += take as u64;
            if end {
                return Ok((true, overflow));
            }
        }
    }

    /// The next event, `None` at the end of input.
    pub fn next_event(&mut self) -> Result<Option<Event>, Error> {
        loop {
            if let Some(e) = self.queue.pop_front() {
                return Ok(Some(e));
            }
            if self.done {
                return Ok(None);
            }
            if !self.started {
                self.started = true;
                self.byte_order_mark()?;
                continue;
            }
            if !self.in_comment
                && self.pending.is_empty()
                && let Some(s) = self.whole_goto()?
            {
                return Ok(Some(Event::Statement(s)));
            }
            let (got, overflow) = self.read_line()?;
            if !got {
                self.done = true;
                if !self.pending.is_empty() {
                    self.flush();
                }
                self.tally();
                continue;
            }
            self.line_no += 1;
            let line_no = self.line_no;
            if overflow {
                self.queue.push_back(Event::Diagnostic(Diagnostic::new(
                    Code::LineTooLong,
                    Severity::Error,
                    Some(line_no),
                    format!("line longer than {MAX_STATEMENT} bytes: skipped"),
                )));
                self.in_comment = false;
                continue;
            }
            let raw = std::mem::take(&mut self.raw);
            match std::str::from_utf8(&raw) {
                Ok(t) => self.take_line(t.trim_end_matches(['\n', '\r']), line_no),
                Err(e) => {
                    self.queue.push_back(Event::Diagnostic(
                        Diagnostic::new(
                            Code::InvalidUtf8,
                            Severity::Warning,
                            Some(line_no),
                            "bytes that are not UTF-8 replaced",
                        )
                        .at(e.valid_up_to() as u32 + 1),
                    ));
                    let t = String::from_utf8_lossy(&raw);
                    self.take_line(t.trim_end_matches(['\n', '\r']), line_no);
                }
            }
            self.raw = raw;
        }
    }

    /// A UTF-8 byte order mark (Windows editors write one) is dropped: left in, it would hide
    /// the first record, and a lost `UNITS/INCHES` scales the whole part by 25.4. A UTF-16 file
    /// is no CL text at all: one error says how to save it, and nothing is read.
    fn byte_order_mark(&mut self) -> Result<(), Error> {
        const BOM: [u8; 3] = [0xEF, 0xBB, 0xBF];
        let mut matched = 0;
        // Matched and consumed piecewise, wherever the input's buffers split it.
        loop {
            let buf = fill(&mut self.input)?;
            if buf.is_empty() {
                break;
            }
            if matched == 0 && buf.len() >= 2 && (buf[..2] == [0xFF, 0xFE] || buf[..2] == [0xFE, 0xFF]) {
                self.queue.push_back(Event::Diagnostic(
                    Diagnostic::new(
                        Code::InvalidUtf8,
                        Severity::Error,
                        Some(1),
                        "the file is UTF-16 text: CL files are ASCII; save it as ASCII or UTF-8",
                    )
                    .at(1),
                ));
                self.done = true;
                return Ok(());
            }
            let k = buf.len().min(3 - matched);
            if buf[..k] != BOM[matched..matched + k] {
                break;
            }
            self.input.consume(k);
            self.consumed += k as u64;
            matched += k;
            if matched == 3 {
                return Ok(());
            }
        }
        if matched > 0 {
            // Part of a mark, then something else: bytes that were no UTF-8 anyway, now gone.
            self.queue.push_back(Event::Diagnostic(
                Diagnostic::new(
                    Code::InvalidUtf8,
                    Severity::Warning,
                    Some(1),
                    "bytes that are not UTF-8 dropped",
                )
                .at(1),
            ));
        }
        Ok(())
    }

    /// Most lines of a 5-axis file are one whole `GOTO/x,y,z,i,j,k`: read in place in the input
    /// buffer, without the copy, UTF-8 check, comment scan and statement assembly every other line
    /// goes through. Only a line the general path would read the same way is taken (ASCII, no
    /// `$`, complete within the buffer, six or three short decimals); anything else is left for it.
    fn whole_goto(&mut self) -> Result<Option<Statement>, Error> {
        // A failed read is the input's error, not a decline: the reader behind may answer the
        // next read with its end (a broken upload), which the general path would take for EOF.
        let buf = fill(&mut self.input)?;
        let Some(end) = memchr(b'\n', buf) else {
            return Ok(None);
        };
        // A `$` anywhere (continuation, comment) is outside fast_goto's grammar: it declines.
        let Some(record) = record::fast::fast_goto(buf[..end].trim_ascii()) else {
            return Ok(None);
        };
        self.input.consume(end + 1);
        self.consumed += (end + 1) as u64;
        self.line_no += 1;
        self.statements += 1;
        Ok(Some(Statement {
            line: self.line_no,
            record,
        }))
    }

    /// Adds one physical line to the statement being assembled.
    fn take_line(&mut self, text: &str, line_no: u32) {
        if self.in_comment {
            // A `$$` comment that ended in `$` continues onto this line.
            self.in_comment = text.trim_end().ends_with('$');
            return;
        }
        let (code, comment) = match find_comment(text) {
            Some(i) => (&text[..i], Some(&text[i + 2..])),
            None => (text, None),
        };
        let code = code.trim();
        if code.is_empty() {
            if let Some(c) = comment {
                self.in_comment = c.trim_end().ends_with('$');
                if let Some(record) = record::flow::comment_record(c) {
                    self.queue.push_back(Event::Statement(Statement { line: line_no, record }));
                }
            }
            return;
        }
        if self.pending.is_empty() {
            self.pending_line = line_no;
            self.pending_overflow = false;
        }
        let (part, continued) = match code.strip_suffix('$') {
            Some(p) => (p.trim_end(), true),
            None => (code, false),
        };
        if self.pending.len() + part.len() > MAX_STATEMENT {
            self.pending_overflow = true;
        } else {
            self.pending.push_str(part);
        }
        if continued {
            return;
        }
        // NX writes a GOTO whose values run on after a trailing comma.
        if self.pending.ends_with(',') && starts_with_ci(&self.pending, "GO") {
            return;
        }
        self.flush();
    }

    fn flush(&mut self) {
        let line = self.pending_line;
        if self.pending_overflow {
            self.queue.push_back(Event::Diagnostic(Diagnostic::new(
                Code::LineTooLong,
                Severity::Error,
                Some(line),
                format!("statement longer than {MAX_STATEMENT} bytes after joining continuations: skipped"),
            )));
        } else {
            let mut diags = Vec::new();
            self.statements += 1;
            let rec = parse_statement(&self.pending, line, &mut diags);
            if rec.is_none() && diags.iter().any(|d| d.code == Code::UnknownRecord) {
                self.nc.note(&self.pending, line);
            }
            if matches!(rec, Some(Record::End)) {
                self.end.get_or_insert(line);
            }
            for mut d in diags {
                if let (Some(end), Code::UnknownRecord) = (self.end, d.code) {
                    d.code = Code::IgnoredRecord;
                    d.severity = Severity::Info;
                    d.message = format!("{} (after the program's END at line {end}: no part of the program)", d.message);
                }
                if self.repeated(&d) {
                    continue;
                }
                self.queue.push_back(Event::Diagnostic(d));
            }
            if let Some(record) = rec {
                self.queue.push_back(Event::Statement(Statement { line, record }));
            }
        }
        self.pending.clear();
    }
}

impl<R: BufRead> Reader<R> {
    /// Whether `d` is a warning or info about a word, held to be told once at the end (the
    /// first one is held, the rest counted): one record a word a program, with its count, so
    /// that 1 559 lines of `REMARK` do not drown what matters. Errors are each told at once:
    /// each one is something missing from the program, at its place.
    fn repeated(&mut self, d: &Diagnostic) -> bool {
        if !matches!(d.code, Code::UnknownRecord | Code::IgnoredRecord) || d.severity == Severity::Error {
            return false;
        }
        if let Some(r) = self.repeats.get_mut(&d.message) {
            r.1 += 1;
            return true;
        }
        if self.repeats.len() < MAX_REPEATS {
            self.repeats.insert(d.message.clone(), (d.clone(), 1));
            return true;
        }
        false
    }

    /// The first word held to be told at the end (the look-ahead's witness where the input
    /// holds no CL: an unknown word is held, not yet an event).
    pub fn first_held(&self) -> Option<&Diagnostic> {
        self.repeats.values().map(|(d, _)| d).min_by_key(|d| d.line)
    }

    /// At the end: each word held, told once at its first line, with its count where it came
    /// more than once.
    fn tally(&mut self) {
        for d in self.held("in all") {
            self.queue.push_back(Event::Diagnostic(d));
        }
    }

    /// The words held and not yet told, each at its first line with its count (`whence` says
    /// over what the count runs), in line order; none are held after. A post that stops before
    /// the end of its input (an error, its budget, a reader gone) takes them so: held, they
    /// would never be told, and "nothing silent" would break where it matters most.
    pub fn take_held(&mut self) -> Vec<Diagnostic> {
        self.held("before the post stopped")
    }

    fn held(&mut self, whence: &str) -> Vec<Diagnostic> {
        let mut told: Vec<_> = self.repeats.drain().map(|(_, r)| r).collect();
        told.sort_by_key(|(d, _)| d.line);
        told.into_iter()
            .map(|(mut d, n)| {
                if n > 1 {
                    let first = d.line.unwrap_or(0);
                    d.message = format!("{} ({n} records {whence}, the first at line {first})", d.message);
                }
                d
            })
            .collect()
    }
}

impl<R: BufRead> Iterator for Reader<R> {
    type Item = Result<Event, Error>;
    fn next(&mut self) -> Option<Self::Item> {
        self.next_event().transpose()
    }
}

fn starts_with_ci(s: &str, prefix: &str) -> bool {
    s.len() >= prefix.len() && s.as_bytes()[..prefix.len()].eq_ignore_ascii_case(prefix.as_bytes())
}

/// Byte offset of `$$`, scanning bytes (most lines have no `$` at all).
#[inline]
fn find_comment(text: &str) -> Option<usize> {
    let b = text.as_bytes();
    let mut i = memchr(b'$', b)?;
    while i + 1 < b.len() {
        if b[i + 1] == b'$' {
            return Some(i);
        }
        i += 1 + memchr(b'$', &b[i + 1..])?;
    }
    None
}

#[inline]
/// The input's buffer, read again after an interrupted read (a signal is no end of input).
fn fill<R: BufRead>(input: &mut R) -> Result<&[u8], Error> {
    loop {
        match input.fill_buf() {
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(e.into()),
            Ok(_) => break,
        }
    }
    // Asked again to hand the borrow out (returning it from inside the loop is beyond today's
    // borrow checker): the buffer is filled, so this only returns it.
    Ok(input.fill_buf()?)
}

fn memchr(b: u8, s: &[u8]) -> Option<usize> {
    memchr::memchr(b, s)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn events(text: &[u8], capacity: usize) -> Vec<Event> {
        let input = std::io::BufReader::with_capacity(capacity, text);
        Reader::new(input).map(|e| e.expect("in-memory input")).collect()
    }

    proptest! {
        /// The in-place GOTO path (a whole line in the buffer) and the general path (a line cut
        /// by the buffer's end) read any mix of lines to the same events.
        #[test]
        fn events_do_not_depend_on_where_the_buffer_ends(
            lines in prop::collection::vec(prop::sample::select(vec![
                "GOTO/1.5,-2.25,3.0,0,0,1",
                "  goto / 1.5 , -2.25 , 3.0  ",
                "GOTO/1,2,3",
                "GOTO/1.5,-2.25,3.0,0,0,1\r",
                "GOTO/1.5,-2.25,$",
                "3.0,0,0,1",
                "GOTO/1,2,3 $$ a comment",
                "$$ a comment that goes on $",
                "GOTO/1e2,2,3",
                "GOTO/1,2,",
                "GOTO/12345678901234567,2,3",
                "GOTO/0,0,0,0,0,0",
                "GOTO/x,2,3",
                "FEDRAT/500,MMPM",
                "",
            ]), 0..40),
            small in 1usize..40,
            last_newline: bool,
        ) {
            let mut text = lines.join("\n");
            if last_newline {
                text.push('\n');
            }
            prop_assert_eq!(events(text.as_bytes(), small), events(text.as_bytes(), 1 << 16));
        }
    }

    /// A UTF-8 byte order mark is dropped however the buffer splits it, so the first record
    /// (here the units) is read; UTF-16 is one error and nothing else; a broken mark is told.
    #[test]
    fn byte_order_marks() {
        let plain = events(b"UNITS/INCHES\nGOTO/1,2,3\n", 1 << 16);
        for capacity in [1, 2, 3, 4, 1 << 16] {
            assert_eq!(
                events(b"\xEF\xBB\xBFUNITS/INCHES\nGOTO/1,2,3\n", capacity),
                plain,
                "{capacity}"
            );
        }
        let utf16: Vec<u8> = [0xFF, 0xFE]
            .into_iter()
            .chain("GOTO/1,2,3\n".bytes().flat_map(|b| [b, 0]))
            .collect();
        match &events(&utf16, 1 << 16)[..] {
            [Event::Diagnostic(d)] => {
                assert_eq!((d.code, d.severity, d.line), (Code::InvalidUtf8, Severity::Error, Some(1)));
                assert!(d.message.contains("UTF-16"), "{d}");
            }
            other => panic!("{other:?}"),
        }
        let broken = events(b"\xEF\xBBGOTO/1,2,3\n", 1);
        assert!(matches!(&broken[0], Event::Diagnostic(d) if d.code == Code::InvalidUtf8 && d.severity == Severity::Warning));
        assert_eq!(broken[1..], events(b"GOTO/1,2,3\n", 1)[..]);
    }

    /// A read that fails is an error wherever it happens, the in-place GOTO path included: the
    /// reader behind may then say it has ended (a broken upload does), and that is no end of
    /// input. Here it fails after the first GOTO, where the in-place path reads next.
    #[test]
    fn a_failed_read_is_an_error_not_the_end() {
        struct FailsThenEnds(u8);
        impl std::io::Read for FailsThenEnds {
            fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
                self.0 += 1;
                match self.0 {
                    1 => (&b"UNITS/MM\nGOTO/1,2,3\n"[..]).read(buf),
                    2 => Err(std::io::Error::other("connection reset")),
                    _ => Ok(0),
                }
            }
        }
        let got: Vec<_> = Reader::new(std::io::BufReader::new(FailsThenEnds(0))).collect();
        assert!(got.iter().any(|e| e.is_err()), "{got:?}");
    }
}
