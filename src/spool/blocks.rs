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
//! length]`, its joints, and with diagnostics their JSON's length and the JSON. What is implied
//! (the next number and CL line, the line to the newline) is not written.
//!
//! A joint is `zigzag(bits − predicted bits)`, the residual, written in as many bits as it has
//! (its top bit, always 1, left out), after that bit count coded against the axis's last one
//! ([`put_count`]: one bit where it is the same, three to seven where it moved by up to seven); a
//! block's joints are one bit string padded to a byte. Version 1 ([`MAGIC_V1`], still read)
//! wrote whole bytes of the residual after a nibble of their count: the padding and the nibbles
//! cost 3.4 bytes a block of five axes, 14 % of the store.

use crate::diag::Diagnostic;
use crate::output::Record;
use crate::post::{AxisWords, BlockInfo};
use std::io::{self, BufRead, Read, Write};
use super::varint::{get_varint, put_varint, unzigzag, zigzag};

/// The file's first bytes; a later format gets a new one.
pub const MAGIC: &[u8; 8] = b"KPBLKS2\n";
/// The first format: residuals in whole bytes after a nibble of their count.
pub const MAGIC_V1: &[u8; 8] = b"KPBLKS1\n";

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
/// Block flags: NC bytes skipped before its line given; (version 1) its residuals' lengths the
/// last block's (no nibbles); an extension byte follows.
const F_SKIP: u8 = 16;
const F_LENS: u8 = 32;
const F_EXT: u8 = 64;
/// The extension's flags: the number given (not the last one's next); the axis mask given; the
/// NC line's length given (else it ends at the next newline).
const X_N: u8 = 1;
const X_MASK: u8 = 2;
const X_LEN: u8 = 4;
/// (Version 2) the diagnostics are the last block's with diagnostics, theirs about its CL line
/// about this one's: no JSON follows. A path through a singular cone has the same note on
/// thousands of blocks in a row, 150 bytes each.
const X_REPEAT: u8 = 8;

/// A line or diagnostics' JSON longer than this is a damaged file, not a record.
const MAX_LINE: u64 = 64 << 20;

/// The last two values of one axis and the CL lines of their blocks, for the prediction.
#[derive(Clone, Copy, Default)]
struct History {
    seen: u8,
    p1: f64,
    p2: f64,
    t1: u32,
    t2: u32,
}

impl History {
    /// Linear extrapolation from the two values before (the previous one, or 0, before that),
    /// in CL lines where they step: a path whose points the post merged (two CL lines a block
    /// here and there) moves twice as far in such a block. Version 1 ([`MAGIC_V1`]) extrapolated
    /// by blocks (`t` 0 throughout): 3 bytes a block more on such a path.
    fn predict(&self, t: u32) -> f64 {
        match self.seen {
            0 => 0.0,
            1 => self.p1,
            _ if self.t1 != self.t2 && t != self.t1 => {
                let ratio = (t as f64 - self.t1 as f64) / (self.t1 as f64 - self.t2 as f64);
                self.p1 + (self.p1 - self.p2) * ratio
            }
            _ => 2.0 * self.p1 - self.p2,
        }
    }

    fn push(&mut self, v: f64, t: u32) {
        (self.p2, self.t2) = (self.p1, self.t1);
        (self.p1, self.t1) = (v, t);
        self.seen = (self.seen + 1).min(2);
    }
}

/// What writer and reader both track from block to block.
#[derive(Default)]
struct Carried {
    n: u64,
    source: u32,
    mask: u8,
    /// Version 1: the last block's residuals' lengths.
    lens: [u8; 6],
    /// Each axis's last residual's bit count.
    bits: [u8; 6],
    axes: [History; 6],
    /// The last block with diagnostics: them, and its CL line.
    diags: Vec<Diagnostic>,
    diags_line: Option<u32>,
}

impl Carried {
    /// The CL line a block's joints are predicted at (the last known where it has none; 0
    /// throughout in version 1).
    fn at(&self, source_line: Option<u32>) -> u32 {
        source_line.unwrap_or(self.source)
    }

    /// The last block's diagnostics as they would be at CL line `line`: those about its own CL
    /// line about this one's.
    fn repeated(&self, line: Option<u32>) -> impl Iterator<Item = Diagnostic> + '_ {
        self.diags.iter().map(move |d| Diagnostic {
            line: if d.line == self.diags_line { line } else { d.line },
            ..d.clone()
        })
    }
}

/// Writes the store as the program's lines and records go by.
pub struct BlockWriter<W: Write> {
    out: W,
    state: Carried,
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
            state: Carried::default(),
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
        let repeat = with_diags && self.repeats(b);
        self.encode_block(b, skip, text, with_diags, repeat);
        if with_diags && !repeat {
            self.line.clear();
            serde_json::to_writer(&mut self.line, &b.diagnostics)?;
            put_varint(&mut self.buf, self.line.len() as u64);
            self.buf.extend_from_slice(&self.line);
        }
        if with_diags {
            self.state.diags.clone_from(&b.diagnostics);
            self.state.diags_line = b.source_line;
        }
        self.out.write_all(&self.buf)
    }

    /// The block's diagnostics are the last ones repeated ([`X_REPEAT`]), as written (a
    /// collision's bodies, which the NDJSON leaves out, aside).
    fn repeats(&self, b: &BlockInfo) -> bool {
        let same = |a: &Diagnostic, r: Diagnostic| {
            (a.code, a.severity, a.line, a.column, &a.message) == (r.code, r.severity, r.line, r.column, &r.message)
        };
        b.diagnostics.len() == self.state.diags.len()
            && b.diagnostics.iter().zip(self.state.repeated(b.source_line)).all(|(a, r)| same(a, r))
    }

    fn encode_block(&mut self, b: &BlockInfo, skip: u64, text: &str, with_diags: bool, repeat: bool) {
        let s = &mut self.state;
        let t = s.at(b.source_line);
        let mask = b.joints.0.iter().enumerate().fold(0u8, |m, (i, v)| m | ((v.is_some() as u8) << i));
        // The residuals, by axis.
        let mut residuals = [0u64; 6];
        for (i, v) in b.joints.0.iter().enumerate() {
            if let Some(v) = *v {
                let h = &mut s.axes[i];
                residuals[i] = zigzag((v.to_bits() as i64).wrapping_sub(h.predict(t).to_bits() as i64));
                h.push(v, t);
            }
        }
        let source = match b.source_line {
            None => SRC_NONE,
            Some(l) if l == s.source.wrapping_add(1) => SRC_NEXT,
            Some(l) if l == s.source => SRC_SAME,
            Some(_) => SRC_DELTA,
        };
        // A line with a newline inside (none is written so) gives its length.
        let ext = ((b.n != s.n + 1) as u8 * X_N)
            | ((mask != s.mask) as u8 * X_MASK)
            | (text.contains('\n') as u8 * X_LEN)
            | (repeat as u8 * X_REPEAT);
        let mut first = if with_diags { BLOCK_DIAGS } else { BLOCK } | source << 2;
        first |= if skip == 0 { 0 } else { F_SKIP };
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
        let mut bits = Bits::new(out);
        for i in (0..6).filter(|i| mask & (1 << i) != 0) {
            let r = residuals[i];
            let count = (64 - r.leading_zeros()) as u8;
            put_count(&mut bits, count, s.bits[i]);
            if count > 1 {
                bits.put(r, count as u32 - 1);
            }
            s.bits[i] = count;
        }
        bits.finish();
        s.n = b.n;
        s.source = b.source_line.unwrap_or(s.source);
        s.mask = mask;
    }

    /// A record that is no block (diagnostic, summary, error), as its NDJSON line.
    pub fn record(&mut self, r: &Record) -> io::Result<()> {
        self.out.write_all(&record_event(r)?)
    }

    pub fn into_inner(self) -> W {
        self.out
    }
}

/// Bits into bytes, least significant first, eight bytes at a time.
struct Bits<'a> {
    out: &'a mut Vec<u8>,
    acc: u64,
    /// Bits in `acc` (0–63).
    n: u32,
}

impl<'a> Bits<'a> {
    fn new(out: &'a mut Vec<u8>) -> Self {
        Bits { out, acc: 0, n: 0 }
    }

    /// The low `count` bits of `v` (at most 64).
    fn put(&mut self, v: u64, count: u32) {
        let v = if count == 64 { v } else { v & ((1u64 << count) - 1) };
        self.acc |= v << self.n;
        let total = self.n + count;
        if total >= 64 {
            self.out.extend_from_slice(&self.acc.to_le_bytes());
            // What did not fit (none where `acc` was empty).
            self.acc = if self.n == 0 { 0 } else { v >> (64 - self.n) };
            self.n = total - 64;
        } else {
            self.n = total;
        }
    }

    /// The last bits, padded to a byte.
    fn finish(self) {
        let bytes = self.n.div_ceil(8) as usize;
        self.out.extend_from_slice(&self.acc.to_le_bytes()[..bytes]);
    }
}

/// A residual's bit count (0–64) against the axis's last, as the zigzag of the change: `1` the
/// same; `01` then one bit, 1–2; `001` then two, 3–6; `0001` then three, 7–14; `0000` then the
/// count in seven bits. The counts of a smooth path's residuals wander by a few bits: 3.4 bits
/// an axis on a generated path, against 2.5 for the counts' entropy.
fn put_count(bits: &mut Bits, count: u8, last: u8) {
    match zigzag(count as i64 - last as i64) {
        0 => bits.put(1, 1),
        z @ 1..=2 => bits.put(0b10 | (z - 1) << 2, 3),
        z @ 3..=6 => bits.put(0b100 | (z - 3) << 3, 5),
        z @ 7..=14 => bits.put(0b1000 | (z - 7) << 4, 7),
        _ => bits.put((count as u64) << 4, 11),
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
    /// `len` long), and its diagnostics where it has any.
    Block {
        n: u64,
        source_line: Option<u32>,
        joints: AxisWords,
        skip: u64,
        len: Option<u64>,
        diagnostics: Option<Vec<Diagnostic>>,
    },
    /// A record's NDJSON line; `error`: the one that ends a failed run.
    Record { line: Vec<u8>, error: bool },
}

/// Reads events; `at` is where the last whole one ended.
pub(super) struct Decoder<R: BufRead> {
    r: R,
    state: Carried,
    /// The store's format (1 or 2).
    version: u8,
    pub at: u64,
    pos: u64,
    /// Bits read and not yet used, within a block's joints.
    acc: u64,
    n: u32,
}

impl<R: BufRead> Decoder<R> {
    /// Checks the magic.
    pub fn new(mut r: R) -> io::Result<Self> {
        let mut m = [0u8; 8];
        r.read_exact(&mut m)?;
        let version = match &m {
            MAGIC => 2,
            MAGIC_V1 => 1,
            _ => return Err(io::Error::new(io::ErrorKind::InvalidData, "not a job block store")),
        };
        Ok(Decoder {
            r,
            state: Carried::default(),
            version,
            at: MAGIC.len() as u64,
            pos: MAGIC.len() as u64,
            acc: 0,
            n: 0,
        })
    }

    fn byte(&mut self) -> io::Result<u8> {
        let mut b = [0u8; 1];
        self.r.read_exact(&mut b)?;
        self.pos += 1;
        Ok(b[0])
    }

    fn varint(&mut self) -> io::Result<u64> {
        get_varint(|| self.byte(), || io::Error::new(io::ErrorKind::InvalidData, "varint too long"))
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
        let joints = if self.version == 1 {
            self.joints_v1(first & F_LENS != 0)?
        } else {
            self.joints(self.state.at(source_line))?
        };
        let diagnostics = match (with_diags, ext & X_REPEAT != 0) {
            (false, _) => None,
            (true, true) => Some(self.state.repeated(source_line).collect()),
            (true, false) => Some(serde_json::from_slice::<Vec<Diagnostic>>(&self.bytes()?)?),
        };
        if let Some(d) = &diagnostics {
            self.state.diags.clone_from(d);
            self.state.diags_line = source_line;
        }
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

    /// A block's joints: from the reader's buffer where it holds the most they can take (a
    /// word at a time), else a byte at a time.
    fn joints(&mut self, t: u32) -> io::Result<AxisWords> {
        let mut state = std::mem::take(&mut self.state);
        let joints = match self.r.fill_buf() {
            Ok(buf) if buf.len() >= MOST_JOINT_BYTES => {
                let mut b = SliceBits { b: buf, pos: 0 };
                let joints = decode_joints(&mut b, &mut state, t);
                let used = b.pos.div_ceil(8);
                self.r.consume(used);
                self.pos += used as u64;
                joints
            }
            _ => {
                let joints = decode_joints(self, &mut state, t);
                // The padding to the byte.
                (self.acc, self.n) = (0, 0);
                joints
            }
        };
        self.state = state;
        joints
    }

    fn joints_v1(&mut self, same_lens: bool) -> io::Result<AxisWords> {
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
            let bits = (h.predict(0).to_bits() as i64).wrapping_add(unzigzag(u64::from_le_bytes(le)));
            let v = f64::from_bits(bits as u64);
            h.push(v, 0);
            joints.0[i] = Some(v);
        }
        Ok(joints)
    }
}

/// The most a block's joints take: six counts of 11 bits and residuals of 63.
const MOST_JOINT_BYTES: usize = (6 * (11 + 63usize)).div_ceil(8);

/// Where a block's joints' bits come from: the reader a byte at a time, or its buffer.
trait BitRead {
    /// The next `count` bits (at most 64).
    fn bits(&mut self, count: u32) -> io::Result<u64>;

    /// A residual's bit count ([`put_count`]).
    fn count(&mut self, last: u8) -> io::Result<u8> {
        let z = if self.bits(1)? == 1 {
            0
        } else if self.bits(1)? == 1 {
            1 + self.bits(1)?
        } else if self.bits(1)? == 1 {
            3 + self.bits(2)?
        } else if self.bits(1)? == 1 {
            7 + self.bits(3)?
        } else {
            let c = self.bits(7)?;
            if c > 64 {
                return Err(io::Error::new(io::ErrorKind::InvalidData, "a residual of more than 64 bits"));
            }
            return Ok(c as u8);
        };
        let c = last as i64 + unzigzag(z);
        if !(0..=64).contains(&c) {
            return Err(io::Error::new(io::ErrorKind::InvalidData, "a residual of more than 64 bits"));
        }
        Ok(c as u8)
    }
}

impl<R: BufRead> BitRead for Decoder<R> {
    fn bits(&mut self, count: u32) -> io::Result<u64> {
        if count > 32 {
            let low = self.bits(32)?;
            return Ok(low | self.bits(count - 32)? << 32);
        }
        while self.n < count {
            self.acc |= (self.byte()? as u64) << self.n;
            self.n += 8;
        }
        let v = self.acc & ((1u64 << count) - 1);
        self.acc >>= count;
        self.n -= count;
        Ok(v)
    }
}

/// The bits of a buffer that holds a whole block's joints ([`MOST_JOINT_BYTES`] or more).
struct SliceBits<'a> {
    b: &'a [u8],
    pos: usize,
}

impl BitRead for SliceBits<'_> {
    fn bits(&mut self, count: u32) -> io::Result<u64> {
        if count > 32 {
            let low = self.bits(32)?;
            return Ok(low | self.bits(count - 32)? << 32);
        }
        let (byte, shift) = (self.pos / 8, self.pos % 8);
        let mut w = [0u8; 8];
        let end = (byte + 8).min(self.b.len());
        w[..end - byte].copy_from_slice(&self.b[byte..end]);
        self.pos += count as usize;
        Ok((u64::from_le_bytes(w) >> shift) & ((1u64 << count) - 1))
    }
}

/// A block's joints (version 2): per present axis its residual's bit count, then the residual.
fn decode_joints(b: &mut impl BitRead, state: &mut Carried, t: u32) -> io::Result<AxisWords> {
    let mut joints = AxisWords::default();
    for i in (0..6).filter(|i| state.mask & (1 << i) != 0) {
        let count = b.count(state.bits[i])?;
        state.bits[i] = count;
        let r = match count {
            0 => 0,
            c => 1u64 << (c - 1) | b.bits(c as u32 - 1)?,
        };
        let h = &mut state.axes[i];
        let v = f64::from_bits((h.predict(t).to_bits() as i64).wrapping_add(unzigzag(r)) as u64);
        h.push(v, t);
        joints.0[i] = Some(v);
    }
    Ok(joints)
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
                let diagnostics = diagnostics.unwrap_or_default();
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
mod tests;
