//! A job's diagnostics, stored compactly (`<id>.blocks`) and served as the NDJSON the CLI's
//! `--diagnostics` writes, rebuilt as it streams.
//!
//! The NDJSON repeats each block's NC text (already in the NC file) and prints its joints as
//! decimals: 170 bytes a block, seven times the program. The store keeps what the NC does not
//! have: per block its joints' exact bits (each against its value predicted from the two blocks
//! before, so a smooth path costs about four bytes an axis), its number and CL line where they
//! are not the obvious ones, and where its text lies in the NC. A block's diagnostics (a few
//! blocks in a hundred) are kept as their JSON, read back and written in its record; the rest —
//! a diagnostic of no block, the summary, the error that ends a failed run — as its NDJSON line,
//! written by [`Record`] when it happened and copied out verbatim.
//!
//! The file: [`MAGIC`] (its format version), then events. An event's first byte holds its kind
//! (low two bits) and, for a block, which fields follow; integers are LEB128, signed ones
//! zigzagged. A block: `[extension] [n] [axis mask] [NC bytes skipped] [CL line delta] [NC
//! length]`, a nibble per present axis (its bytes, 0–8) unless they are the last block's, those
//! bytes of `zigzag(bits − predicted bits)`; with diagnostics, their JSON's length and the JSON.
//! What is implied (the next number and CL line, the line to the newline) is not written.

use crate::diag::Diagnostic;
use crate::output::Record;
use crate::post::{AxisWords, BlockInfo};
use std::io::{self, BufRead, Read, Write};

/// The file's first bytes; a later format gets a new one.
pub const MAGIC: &[u8; 8] = b"KPBLKS1\n";

/// Event kinds.
const BLOCK: u8 = 0;
/// A block with diagnostics: its block fields, then their JSON array.
const BLOCK_DIAGS: u8 = 1;
/// Any other record: its NDJSON line.
const RECORD: u8 = 2;
/// The error record that ends a failed run.
const ERROR: u8 = 3;

/// A block's CL line (bits 2–3 of the first byte): the last one's next, the same, a delta given
/// (zigzag), none.
const SRC_NEXT: u8 = 0;
const SRC_SAME: u8 = 1;
const SRC_DELTA: u8 = 2;
const SRC_NONE: u8 = 3;
/// Block flags: NC bytes skipped before its line given; its residuals' lengths the last
/// block's (no nibbles); an extension byte follows.
const F_SKIP: u8 = 16;
const F_LENS: u8 = 32;
const F_EXT: u8 = 64;
/// The extension's flags: the number given (not the last one's next); the axis mask given; the
/// NC line's length given (else it ends at the next newline).
const X_N: u8 = 1;
const X_MASK: u8 = 2;
const X_LEN: u8 = 4;

/// A line or diagnostics' JSON longer than this is a damaged file, not a record.
const MAX_LINE: u64 = 64 << 20;

/// The last two values of one axis, for the prediction.
#[derive(Clone, Copy, Default)]
struct History {
    seen: u8,
    p1: f64,
    p2: f64,
}

impl History {
    /// Linear extrapolation from the two values before (the previous one, or 0, before that).
    fn predict(&self) -> f64 {
        match self.seen {
            0 => 0.0,
            1 => self.p1,
            _ => 2.0 * self.p1 - self.p2,
        }
    }

    fn push(&mut self, v: f64) {
        self.p2 = self.p1;
        self.p1 = v;
        self.seen = (self.seen + 1).min(2);
    }
}

/// What writer and reader both track from block to block.
#[derive(Default)]
struct State {
    n: u64,
    source: u32,
    mask: u8,
    /// The last block's residuals' lengths.
    lens: [u8; 6],
    axes: [History; 6],
}

fn zigzag(v: i64) -> u64 {
    ((v << 1) ^ (v >> 63)) as u64
}

fn unzigzag(v: u64) -> i64 {
    ((v >> 1) as i64) ^ -((v & 1) as i64)
}

fn put_varint(out: &mut Vec<u8>, mut v: u64) {
    while v >= 0x80 {
        out.push(v as u8 | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

/// Writes the store as the program's lines and records go by.
pub struct BlockWriter<W: Write> {
    out: W,
    state: State,
    /// NC bytes written so far, and where the last block's line ended.
    nc_at: u64,
    after_block: u64,
    buf: Vec<u8>,
    line: Vec<u8>,
}

impl<W: Write> BlockWriter<W> {
    pub fn new(mut out: W) -> io::Result<Self> {
        out.write_all(MAGIC)?;
        Ok(BlockWriter {
            out,
            state: State::default(),
            nc_at: 0,
            after_block: 0,
            buf: Vec::with_capacity(128),
            line: Vec::new(),
        })
    }

    /// One NC line as the NC file has it (`text` and its newline); a motion block is stored.
    pub fn line(&mut self, text: &str, b: Option<&BlockInfo>) -> io::Result<()> {
        let start = self.nc_at;
        self.nc_at += text.len() as u64 + 1;
        let Some(b) = b else { return Ok(()) };
        let skip = start - self.after_block;
        self.after_block = self.nc_at;
        self.buf.clear();
        let with_diags = !b.diagnostics.is_empty();
        self.encode_block(b, skip, text, with_diags);
        if with_diags {
            self.line.clear();
            serde_json::to_writer(&mut self.line, &b.diagnostics)?;
            put_varint(&mut self.buf, self.line.len() as u64);
            self.buf.extend_from_slice(&self.line);
        }
        self.out.write_all(&self.buf)
    }

    fn encode_block(&mut self, b: &BlockInfo, skip: u64, text: &str, with_diags: bool) {
        let s = &mut self.state;
        let mask = b.joints.0.iter().enumerate().fold(0u8, |m, (i, v)| m | ((v.is_some() as u8) << i));
        // The residuals and their lengths in bytes.
        let (mut residuals, mut lens, mut k) = ([0u64; 6], [0u8; 6], 0);
        for (i, v) in b.joints.0.iter().enumerate() {
            if let Some(v) = *v {
                let h = &mut s.axes[i];
                residuals[k] = zigzag((v.to_bits() as i64).wrapping_sub(h.predict().to_bits() as i64));
                lens[k] = (64 - residuals[k].leading_zeros()).div_ceil(8) as u8;
                h.push(v);
                k += 1;
            }
        }
        let source = match b.source_line {
            None => SRC_NONE,
            Some(l) if l == s.source.wrapping_add(1) => SRC_NEXT,
            Some(l) if l == s.source => SRC_SAME,
            Some(_) => SRC_DELTA,
        };
        // A line with a newline inside (none is written so) gives its length.
        let ext = (b.n != s.n + 1) as u8 * X_N | (mask != s.mask) as u8 * X_MASK | text.contains('\n') as u8 * X_LEN;
        let same_lens = mask == s.mask && lens == s.lens;
        let mut first = if with_diags { BLOCK_DIAGS } else { BLOCK } | source << 2;
        first |= if skip == 0 { 0 } else { F_SKIP };
        first |= if same_lens { F_LENS } else { 0 };
        first |= if ext == 0 { 0 } else { F_EXT };
        let out = &mut self.buf;
        out.push(first);
        if ext != 0 {
            out.push(ext);
        }
        if ext & X_N != 0 {
            put_varint(out, b.n);
        }
        if ext & X_MASK != 0 {
            out.push(mask);
        }
        if skip != 0 {
            put_varint(out, skip);
        }
        if let (SRC_DELTA, Some(l)) = (source, b.source_line) {
            put_varint(out, zigzag(l as i64 - s.source as i64));
        }
        if ext & X_LEN != 0 {
            put_varint(out, text.len() as u64);
        }
        if !same_lens {
            for pair in lens[..k].chunks(2) {
                out.push(pair[0] | pair.get(1).map_or(0, |&l| l << 4));
            }
        }
        for (r, l) in residuals[..k].iter().zip(lens) {
            out.extend_from_slice(&r.to_le_bytes()[..l as usize]);
        }
        s.n = b.n;
        s.source = b.source_line.unwrap_or(s.source);
        s.mask = mask;
        s.lens = lens;
    }

    /// A record that is no block (diagnostic, summary, error), as its NDJSON line.
    pub fn record(&mut self, r: &Record) -> io::Result<()> {
        self.out.write_all(&record_event(r)?)
    }

    pub fn into_inner(self) -> W {
        self.out
    }
}

/// The event of a record that is no block: its kind, length and NDJSON line.
pub(super) fn record_event(r: &Record) -> io::Result<Vec<u8>> {
    let mut line = Vec::new();
    r.write_to(&mut line)?;
    let mut ev = vec![if matches!(r, Record::Error { .. }) { ERROR } else { RECORD }];
    put_varint(&mut ev, line.len() as u64);
    ev.extend_from_slice(&line);
    Ok(ev)
}

/// The NDJSON of a job's store and NC (either may be missing: see [`Ndjson::new`]).
pub fn rebuild(
    store: &std::path::Path,
    nc: &std::path::Path,
    end: Option<Vec<u8>>,
) -> io::Result<Ndjson<io::BufReader<std::fs::File>, io::BufReader<std::fs::File>>> {
    let open = |p: &std::path::Path, cap: usize| match std::fs::File::open(p) {
        Ok(f) => Ok(Some(io::BufReader::with_capacity(cap, f))),
        Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(None),
        Err(e) => Err(e),
    };
    let store = open(store, 64 << 10)?;
    if store.is_none() && end.is_none() {
        return Err(io::Error::new(io::ErrorKind::NotFound, "the job's block store is gone"));
    }
    Ndjson::new(store, open(nc, 64 << 10)?, end)
}

/// One event read back.
pub(super) enum Event {
    /// A block: its fields, where its text lies in the NC (after `skip` bytes, to the newline or
    /// `len` long), and its diagnostics' JSON where it has any.
    Block {
        n: u64,
        source_line: Option<u32>,
        joints: AxisWords,
        skip: u64,
        len: Option<u64>,
        diagnostics: Option<Vec<u8>>,
    },
    /// A record's NDJSON line; `error`: the one that ends a failed run.
    Record { line: Vec<u8>, error: bool },
}

/// Reads events; `at` is where the last whole one ended.
pub(super) struct Decoder<R: BufRead> {
    r: R,
    state: State,
    pub at: u64,
    pos: u64,
}

impl<R: BufRead> Decoder<R> {
    /// Checks the magic.
    pub fn new(mut r: R) -> io::Result<Self> {
        let mut m = [0u8; 8];
        r.read_exact(&mut m)?;
        if &m != MAGIC {
            return Err(io::Error::new(io::ErrorKind::InvalidData, "not a job block store"));
        }
        Ok(Decoder {
            r,
            state: State::default(),
            at: MAGIC.len() as u64,
            pos: MAGIC.len() as u64,
        })
    }

    fn byte(&mut self) -> io::Result<u8> {
        let mut b = [0u8; 1];
        self.r.read_exact(&mut b)?;
        self.pos += 1;
        Ok(b[0])
    }

    fn varint(&mut self) -> io::Result<u64> {
        let mut v = 0u64;
        for shift in (0..64).step_by(7) {
            let b = self.byte()?;
            v |= ((b & 0x7f) as u64) << shift;
            if b & 0x80 == 0 {
                return Ok(v);
            }
        }
        Err(io::Error::new(io::ErrorKind::InvalidData, "varint too long"))
    }

    fn bytes(&mut self) -> io::Result<Vec<u8>> {
        let len = self.varint()?;
        if len > MAX_LINE {
            return Err(io::Error::new(io::ErrorKind::InvalidData, "record too long"));
        }
        let mut v = vec![0u8; len as usize];
        self.r.read_exact(&mut v)?;
        self.pos += len;
        Ok(v)
    }

    /// The next whole event; `None` at the end of the file (an event cut short is an error).
    pub fn next(&mut self) -> io::Result<Option<Event>> {
        let first = match self.byte() {
            Ok(b) => b,
            Err(e) if e.kind() == io::ErrorKind::UnexpectedEof => return Ok(None),
            Err(e) => return Err(e),
        };
        let ev = match first & 3 {
            RECORD | ERROR => Event::Record {
                line: self.bytes()?,
                error: first & 3 == ERROR,
            },
            kind => self.block(first, kind == BLOCK_DIAGS)?,
        };
        self.at = self.pos;
        Ok(Some(ev))
    }

    fn block(&mut self, first: u8, with_diags: bool) -> io::Result<Event> {
        let ext = if first & F_EXT != 0 { self.byte()? } else { 0 };
        let n = if ext & X_N != 0 { self.varint()? } else { self.state.n + 1 };
        if ext & X_MASK != 0 {
            self.state.mask = self.byte()?;
        }
        let skip = if first & F_SKIP != 0 { self.varint()? } else { 0 };
        let last = self.state.source;
        let source_line = match (first >> 2) & 3 {
            SRC_NEXT => Some(last.wrapping_add(1)),
            SRC_SAME => Some(last),
            SRC_DELTA => Some((last as i64 + unzigzag(self.varint()?)) as u32),
            _ => None,
        };
        let len = if ext & X_LEN != 0 { Some(self.varint()?) } else { None };
        let joints = self.joints(first & F_LENS != 0)?;
        let diagnostics = if with_diags { Some(self.bytes()?) } else { None };
        self.state.n = n;
        self.state.source = source_line.unwrap_or(last);
        Ok(Event::Block {
            n,
            source_line,
            joints,
            skip,
            len,
            diagnostics,
        })
    }

    fn joints(&mut self, same_lens: bool) -> io::Result<AxisWords> {
        let mask = self.state.mask;
        let k = mask.count_ones() as usize;
        if !same_lens {
            self.state.lens = [0; 6];
            for i in (0..k).step_by(2) {
                let b = self.byte()?;
                self.state.lens[i] = b & 15;
                if i + 1 < k {
                    self.state.lens[i + 1] = b >> 4;
                }
            }
        }
        let mut joints = AxisWords::default();
        for (j, i) in (0..6).filter(|i| mask & (1 << i) != 0).enumerate() {
            let mut le = [0u8; 8];
            let n = (self.state.lens[j] as usize).min(8);
            self.r.read_exact(&mut le[..n])?;
            self.pos += n as u64;
            let h = &mut self.state.axes[i];
            let bits = (h.predict().to_bits() as i64).wrapping_add(unzigzag(u64::from_le_bytes(le)));
            let v = f64::from_bits(bits as u64);
            h.push(v);
            joints.0[i] = Some(v);
        }
        Ok(joints)
    }
}

/// The NDJSON rebuilt from a store and the NC it points into, read like a file: bounded memory
/// (a block's record at a time). With `end` (a failed job's error record), a store or NC cut
/// short ends the stream with that record, unless the last record read was an error; without
/// it, with an error.
pub struct Ndjson<R: BufRead, N: BufRead> {
    dec: Option<Decoder<R>>,
    nc: Option<N>,
    end: Option<Vec<u8>>,
    closed: bool,
    /// The last event was a record that is no error: how a whole run's store ends (the summary).
    summed: bool,
    done: bool,
    /// An error met after some output: returned once that output is read.
    failed: Option<io::Error>,
    out: Vec<u8>,
    at: usize,
    text: Vec<u8>,
}

impl<R: BufRead, N: BufRead> Ndjson<R, N> {
    /// `store` `None`: there is none (the run never began), only `end` is served.
    pub fn new(store: Option<R>, nc: Option<N>, end: Option<Vec<u8>>) -> io::Result<Self> {
        let dec = match store.map(Decoder::new).transpose() {
            Ok(d) => d,
            Err(_) if end.is_some() => None,
            Err(e) => return Err(e),
        };
        Ok(Ndjson {
            dec,
            nc,
            end,
            closed: false,
            summed: false,
            done: false,
            failed: None,
            out: Vec::with_capacity(64 << 10),
            at: 0,
            text: Vec::new(),
        })
    }

    /// Decodes until at least 32 KiB are ready, or the end.
    fn fill(&mut self) {
        self.out.clear();
        self.at = 0;
        while !self.done && self.out.len() < 32 << 10 {
            let next = match self.dec.as_mut() {
                Some(d) => d.next(),
                None => Ok(None),
            };
            let r = match next {
                Ok(Some(ev)) => self.emit(ev),
                Ok(None) if self.end.is_none() && !self.summed => Err(io::Error::new(
                    io::ErrorKind::UnexpectedEof,
                    "the job's block store ends before its summary",
                )),
                Ok(None) => {
                    self.finish();
                    Ok(())
                }
                Err(e) => Err(e),
            };
            if let Err(e) = r {
                if self.end.is_some() {
                    self.finish();
                } else {
                    self.done = true;
                    self.failed = Some(e);
                }
            }
        }
    }

    /// The end of the stream: a failed job's error record unless one was the last.
    fn finish(&mut self) {
        if let Some(end) = self.end.take()
            && !self.closed
        {
            self.out.extend_from_slice(&end);
        }
        self.done = true;
    }

    fn emit(&mut self, ev: Event) -> io::Result<()> {
        match ev {
            Event::Record { line, error } => {
                self.out.extend_from_slice(&line);
                self.closed = error;
                self.summed = !error;
            }
            Event::Block {
                n,
                source_line,
                joints,
                skip,
                len,
                diagnostics,
            } => {
                let nc = self
                    .nc
                    .as_mut()
                    .ok_or_else(|| io::Error::new(io::ErrorKind::NotFound, "the job's NC is gone"))?;
                io::copy(&mut nc.take(skip), &mut io::sink())?;
                self.text.clear();
                match len {
                    Some(len) => {
                        self.text.resize(len as usize + 1, 0);
                        nc.read_exact(&mut self.text)?;
                    }
                    None => {
                        nc.read_until(b'\n', &mut self.text)?;
                    }
                }
                if self.text.pop() != Some(b'\n') {
                    return Err(io::Error::new(io::ErrorKind::UnexpectedEof, "the job's NC ends mid-line"));
                }
                self.closed = false;
                self.summed = false;
                let diagnostics: Vec<Diagnostic> = match diagnostics {
                    Some(json) => serde_json::from_slice(&json)?,
                    None => Vec::new(),
                };
                let nc = std::str::from_utf8(&self.text).map_err(|e| io::Error::new(io::ErrorKind::InvalidData, e))?;
                Record::Block {
                    n,
                    nc,
                    source_line,
                    joints: &joints,
                    diagnostics: &diagnostics,
                }
                .write_to(&mut self.out)?;
            }
        }
        Ok(())
    }
}

impl<R: BufRead, N: BufRead> Read for Ndjson<R, N> {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        if self.at == self.out.len() {
            if let Some(e) = self.failed.take() {
                return Err(e);
            }
            if self.done {
                return Ok(0);
            }
            self.fill();
            if self.out.is_empty()
                && let Some(e) = self.failed.take()
            {
                return Err(e);
            }
        }
        let n = buf.len().min(self.out.len() - self.at);
        buf[..n].copy_from_slice(&self.out[self.at..self.at + n]);
        self.at += n;
        Ok(n)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diag::{Code, Severity};
    use crate::output::FileSink;
    use crate::post::{Sink, Summary};
    use proptest::prelude::*;

    fn block(n: u64, source_line: Option<u32>, joints: [Option<f64>; 6], diagnostics: Vec<Diagnostic>) -> BlockInfo {
        BlockInfo {
            n,
            source_line,
            joints: AxisWords(joints),
            diagnostics,
            rapid: false,
            tip: [0.0; 3],
            axis: [0.0, 0.0, 1.0],
            time_s: 0.0,
        }
    }

    /// One program into the CLI's files (NC, NDJSON) and into NC and a block store, the store's
    /// NDJSON rebuilt: `(cli ndjson, rebuilt)`.
    fn both(lines: &[(String, Option<BlockInfo>)], notes: &[(usize, Diagnostic)]) -> (Vec<u8>, Vec<u8>) {
        let mut cli = FileSink::new(Vec::new(), Some(Vec::new()));
        let mut store = BlockWriter::new(Vec::new()).unwrap();
        let mut nc = Vec::new();
        for (i, (text, b)) in lines.iter().enumerate() {
            for (_, d) in notes.iter().filter(|(at, _)| *at == i) {
                cli.diagnostic(d).unwrap();
                store.record(&Record::Diagnostic { diagnostic: d }).unwrap();
            }
            cli.line(text, b.as_ref()).unwrap();
            store.line(text, b.as_ref()).unwrap();
            nc.extend_from_slice(text.as_bytes());
            nc.push(b'\n');
        }
        let s = Summary {
            blocks: lines.len() as u64,
            ..Summary::default()
        };
        cli.summary(&s).unwrap();
        store.record(&Record::Summary { summary: &s }).unwrap();
        let (_, nd) = cli.into_inner().unwrap();
        let store = store.into_inner();
        let mut out = Vec::new();
        Ndjson::new(Some(&store[..]), Some(&nc[..]), None)
            .unwrap()
            .read_to_end(&mut out)
            .unwrap();
        (nd.unwrap(), out)
    }

    fn value() -> impl Strategy<Value = f64> {
        prop_oneof![
            4 => -1000.0..1000.0f64,
            1 => Just(0.0),
            1 => Just(-0.0),
            1 => prop::num::f64::ANY,
            1 => (-100i64..100).prop_map(|k| k as f64 * 0.001),
        ]
    }

    proptest! {
        /// Any blocks, joints (any bits), numbering, CL lines, other lines and diagnostics: the
        /// same bytes as the CLI's NDJSON.
        #[test]
        fn the_rebuilt_ndjson_is_the_clis(
            rows in prop::collection::vec((
                prop::array::uniform6(prop::option::weighted(0.9, value())),
                0u8..16,
                0u32..5000,
            ), 1..300),
        ) {
            let mut lines = Vec::new();
            let mut n = 0;
            let mut notes = Vec::new();
            let mut last = 0u32;
            for (i, (joints, pick, line)) in rows.iter().enumerate() {
                let text = format!("G1 X{i} \"quoted\" é");
                match pick {
                    0 => lines.push((format!("(COMMENT {i})"), None)),
                    1 => {
                        n += 3;
                        lines.push((text, Some(block(n, None, *joints, vec![]))));
                    }
                    2 => {
                        n += 1;
                        let d = Diagnostic::new(Code::Unwind, Severity::Warning, Some(*line), "turned");
                        lines.push((text, Some(block(n, Some(*line), *joints, vec![d]))));
                    }
                    3 => notes.push((lines.len(), Diagnostic::new(Code::Unwind, Severity::Info, None, format!("note {i}")))),
                    4 => {
                        n += 1;
                        lines.push((format!("G1 X{i}\nY1"), Some(block(n, Some(*line), *joints, vec![]))));
                    }
                    5..=9 => {
                        // The CL line after the last block's, or the same.
                        n += 1;
                        last = last.wrapping_add((pick & 1) as u32);
                        lines.push((text, Some(block(n, Some(last), *joints, vec![]))));
                    }
                    _ => {
                        n += 1;
                        last = *line;
                        lines.push((text, Some(block(n, Some(*line), *joints, vec![]))));
                    }
                }
            }
            let (cli, rebuilt) = both(&lines, &notes);
            prop_assert_eq!(String::from_utf8(cli).unwrap(), String::from_utf8(rebuilt).unwrap());
        }
    }

    #[test]
    fn a_smooth_path_costs_a_few_bytes_an_axis() {
        let lines: Vec<_> = (0..10_000u32)
            .map(|i| {
                let t = i as f64 * 0.001;
                let j = [
                    Some(100.0 * t.sin()),
                    Some(50.0 * t.cos()),
                    Some(-20.0 + t),
                    None,
                    Some(30.0 * t.sin()),
                    Some(7.0 * t),
                ];
                (format!("X{t:.3}"), Some(block(i as u64 + 1, Some(i + 10), j, vec![])))
            })
            .collect();
        let mut store = BlockWriter::new(Vec::new()).unwrap();
        for (t, b) in &lines {
            store.line(t, b.as_ref()).unwrap();
        }
        let per_block = store.into_inner().len() as f64 / 10_000.0;
        assert!(per_block < 24.0, "{per_block} bytes a block");
        let (cli, rebuilt) = both(&lines, &[]);
        assert_eq!(cli, rebuilt);
    }

    /// Cut anywhere, a failed job's stream ends with its error after the last whole record; a
    /// succeeded job's ends in an error, never silently short.
    #[test]
    fn a_store_cut_short_ends_with_the_error_or_fails() {
        let lines: Vec<_> = (0..50u32)
            .map(|i| {
                (
                    format!("X{i}"),
                    Some(block(
                        i as u64 + 1,
                        Some(i + 1),
                        [Some(i as f64 / 3.0), None, None, None, None, None],
                        vec![],
                    )),
                )
            })
            .collect();
        let (cli, _) = both(&lines, &[]);
        let mut store = BlockWriter::new(Vec::new()).unwrap();
        let mut nc = Vec::new();
        for (t, b) in &lines {
            store.line(t, b.as_ref()).unwrap();
            nc.extend_from_slice(format!("{t}\n").as_bytes());
        }
        let store = store.into_inner();
        let end = b"{\"type\":\"error\"}\n".to_vec();
        for cut in [MAGIC.len() + 1, store.len() / 2, store.len() - 1] {
            let mut out = Vec::new();
            Ndjson::new(Some(&store[..cut]), Some(&nc[..]), Some(end.clone()))
                .unwrap()
                .read_to_end(&mut out)
                .unwrap();
            let text = String::from_utf8(out).unwrap();
            assert!(
                text.ends_with("\n{\"type\":\"error\"}\n") || text == "{\"type\":\"error\"}\n",
                "{text}"
            );
            assert!(String::from_utf8_lossy(&cli).starts_with(text.trim_end_matches("{\"type\":\"error\"}\n")));
            let mut out = Vec::new();
            let r = Ndjson::new(Some(&store[..cut]), Some(&nc[..]), None)
                .unwrap()
                .read_to_end(&mut out);
            assert!(r.is_err());
        }
        // The NC gone short: the same.
        let mut out = Vec::new();
        Ndjson::new(Some(&store[..]), Some(&nc[..nc.len() / 2]), Some(end.clone()))
            .unwrap()
            .read_to_end(&mut out)
            .unwrap();
        assert!(out.ends_with(&end));
    }
}
