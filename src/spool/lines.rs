//! A job's line map, stored compactly (`<id>.lines`) and served as the fixed-size entries of
//! `spool::linemap`, rebuilt as they stream.
//!
//! The fixed-size map costs 16 bytes a line, two thirds of the NC itself, though nearly every
//! line says only "this long, the next CL line, no flags". Stored, a line is one byte: its kind
//! of CL line (low two bits: the last one's next, the same, a delta given, none), whether flags
//! follow (bit 2), and its length in bytes as `zigzag(length − the last line's length)` in the
//! top five bits (31: the length follows); then the CL line's zigzag delta and the flags as
//! LEB128 where given. Every [`EVERY`] lines a checkpoint (where its line starts in the store
//! and in the NC, the last CL line and length) lets a Range request start anywhere after
//! decoding a few thousand lines.
//!
//! The file: [`MAGIC`], the lines, the checkpoints (24 bytes each), and a trailer: lines (u64),
//! where the checkpoints start (u64), [`EVERY`] (u32) and [`TAIL`], all little-endian. A job run
//! before this format left the fixed-size entries themselves, whose first 8 bytes (line 1's
//! offset) are zeros: no magic, served as they are.

use super::linemap::{ENTRY, Entries, Entry};
use crate::post::BlockInfo;
use std::io::{self, BufRead, Read, Seek, SeekFrom, Write};
use std::path::Path;
use super::varint::{get_varint, put_varint, unzigzag, zigzag};

/// The file's first bytes; a later format gets a new one.
pub const MAGIC: &[u8; 8] = b"KPLINES2";
/// The trailer's last bytes: a file without them was cut short.
const TAIL: &[u8; 4] = b"LEND";
const TRAILER: u64 = 24;
const CHECKPOINT: u64 = 24;
/// Lines between checkpoints: a Range decodes at most this many lines before its first.
pub const EVERY: u64 = 4096;

/// The CL line's kind (low two bits).
const CL_NEXT: u8 = 0;
const CL_SAME: u8 = 1;
const CL_DELTA: u8 = 2;
const CL_NONE: u8 = 3;
const FLAGS: u8 = 4;
/// The length code that says the length follows.
const LEN_GIVEN: u64 = 31;

/// What writer and reader track from line to line (a checkpoint holds it).
#[derive(Clone, Copy, Default)]
struct Cursor {
    offset: u64,
    cl: u32,
    len: u32,
}

/// Writes the store as the program's lines go by; [`Writer::finish`] adds the checkpoints.
pub struct Writer<W: Write> {
    out: W,
    entries: Entries,
    state: Cursor,
    lines: u64,
    /// Bytes written so far.
    at: u64,
    checkpoints: Vec<u8>,
    buf: Vec<u8>,
}

impl<W: Write> Writer<W> {
    pub fn new(mut out: W) -> io::Result<Self> {
        out.write_all(MAGIC)?;
        Ok(Writer {
            out,
            entries: Entries::default(),
            state: Cursor::default(),
            lines: 0,
            at: MAGIC.len() as u64,
            checkpoints: Vec::new(),
            buf: Vec::with_capacity(16),
        })
    }

    /// One NC line as the NC file has it (`text` and its newline).
    pub fn line(&mut self, text: &str, b: Option<&BlockInfo>) -> io::Result<()> {
        let e = self.entries.next(text, b);
        if self.lines % EVERY == 0 {
            checkpoint(&mut self.checkpoints, self.at, self.state);
        }
        self.buf.clear();
        let len = text.len() as u64 + 1;
        encode(&mut self.buf, &mut self.state, e, len);
        self.lines += 1;
        self.at += self.buf.len() as u64;
        self.out.write_all(&self.buf)
    }

    /// The checkpoints and the trailer; the writer back.
    pub fn finish(mut self) -> io::Result<W> {
        let index_at = self.at;
        self.checkpoints.extend_from_slice(&self.lines.to_le_bytes());
        self.checkpoints.extend_from_slice(&index_at.to_le_bytes());
        self.checkpoints.extend_from_slice(&(EVERY as u32).to_le_bytes());
        self.checkpoints.extend_from_slice(TAIL);
        self.out.write_all(&self.checkpoints)?;
        Ok(self.out)
    }
}

fn checkpoint(out: &mut Vec<u8>, at: u64, s: Cursor) {
    out.extend_from_slice(&at.to_le_bytes());
    out.extend_from_slice(&s.offset.to_le_bytes());
    out.extend_from_slice(&s.cl.to_le_bytes());
    out.extend_from_slice(&s.len.to_le_bytes());
}

/// One line's bytes; `len` is its length with the newline (the next line's offset less its own).
fn encode(out: &mut Vec<u8>, s: &mut Cursor, e: Entry, len: u64) {
    let kind = match e.cl {
        0 => CL_NONE,
        cl if cl == s.cl.wrapping_add(1) => CL_NEXT,
        cl if cl == s.cl => CL_SAME,
        _ => CL_DELTA,
    };
    let code = zigzag(len as i64 - s.len as i64).min(LEN_GIVEN);
    out.push(kind | if e.flags != 0 { FLAGS } else { 0 } | (code as u8) << 3);
    if kind == CL_DELTA {
        put_varint(out, zigzag(e.cl as i64 - s.cl as i64));
    }
    if e.flags != 0 {
        put_varint(out, e.flags as u64);
    }
    if code == LEN_GIVEN {
        put_varint(out, len);
    }
    if e.cl != 0 {
        s.cl = e.cl;
    }
    // A line longer than 4 GiB (none is written so) is predicted as 4 GiB long: still exact.
    s.len = len.min(u32::MAX as u64) as u32;
    s.offset += len;
}

/// The next line's entry, from the store's bytes.
fn decode<R: BufRead>(r: &mut R, s: &mut Cursor) -> io::Result<Entry> {
    let head = byte(r)?;
    let cl = match head & 3 {
        CL_NEXT => s.cl.wrapping_add(1),
        CL_SAME => s.cl,
        CL_DELTA => (s.cl as i64 + unzigzag(varint(r)?)) as u32,
        _ => 0,
    };
    let flags = if head & FLAGS != 0 { varint(r)? as u32 } else { 0 };
    let code = (head >> 3) as u64;
    let len = if code == LEN_GIVEN {
        varint(r)?
    } else {
        (s.len as i64 + unzigzag(code)) as u64
    };
    let e = Entry {
        offset: s.offset,
        cl,
        flags,
    };
    if cl != 0 {
        s.cl = cl;
    }
    s.len = len.min(u32::MAX as u64) as u32;
    s.offset += len;
    Ok(e)
}

fn byte<R: BufRead>(r: &mut R) -> io::Result<u8> {
    let mut b = [0u8; 1];
    r.read_exact(&mut b)?;
    Ok(b[0])
}

fn varint<R: BufRead>(r: &mut R) -> io::Result<u64> {
    get_varint(|| byte(r), || damaged("varint too long"))
}

fn damaged(why: &str) -> io::Error {
    io::Error::new(io::ErrorKind::InvalidData, format!("job line map: {why}"))
}

/// A compact store opened: its checkpoints, read from its end.
pub struct LineIndex {
    path: std::path::PathBuf,
    lines: u64,
    index_at: u64,
    checkpoints: Vec<(u64, Cursor)>,
}

impl LineIndex {
    /// `None`: the file is a fixed-size map from before this format (served as it is).
    pub fn open(path: &Path) -> io::Result<Option<LineIndex>> {
        let mut f = std::fs::File::open(path)?;
        let mut magic = [0u8; 8];
        match f.read_exact(&mut magic) {
            Ok(()) if &magic == MAGIC => {}
            Ok(()) => return Ok(None),
            // Shorter than a magic: a map of no lines, in the old format.
            Err(e) if e.kind() == io::ErrorKind::UnexpectedEof => return Ok(None),
            Err(e) => return Err(e),
        }
        let size = f.metadata()?.len();
        if size < MAGIC.len() as u64 + TRAILER {
            return Err(damaged("cut short"));
        }
        let mut t = [0u8; TRAILER as usize];
        f.seek(SeekFrom::Start(size - TRAILER))?;
        f.read_exact(&mut t)?;
        let u64_at = |i: usize| u64::from_le_bytes(t[i..i + 8].try_into().expect("8 bytes"));
        let (lines, index_at) = (u64_at(0), u64_at(8));
        let every = u32::from_le_bytes(t[16..20].try_into().expect("4 bytes")) as u64;
        let count = lines.div_ceil(EVERY);
        if &t[20..] != TAIL || every != EVERY || index_at.checked_add(count * CHECKPOINT + TRAILER) != Some(size) {
            return Err(damaged("its trailer does not match its length"));
        }
        let mut raw = vec![0u8; (count * CHECKPOINT) as usize];
        f.seek(SeekFrom::Start(index_at))?;
        f.read_exact(&mut raw)?;
        let checkpoints = raw
            .chunks(CHECKPOINT as usize)
            .map(|c| {
                let at = u64::from_le_bytes(c[0..8].try_into().expect("8 bytes"));
                let offset = u64::from_le_bytes(c[8..16].try_into().expect("8 bytes"));
                let cl = u32::from_le_bytes(c[16..20].try_into().expect("4 bytes"));
                let len = u32::from_le_bytes(c[20..24].try_into().expect("4 bytes"));
                (at, Cursor { offset, cl, len })
            })
            .collect();
        Ok(Some(LineIndex {
            path: path.to_path_buf(),
            lines,
            index_at,
            checkpoints,
        }))
    }

    /// The fixed-size map's length in bytes (what is served).
    pub fn len(&self) -> u64 {
        self.lines * ENTRY as u64
    }

    pub fn is_empty(&self) -> bool {
        self.lines == 0
    }

    /// The fixed-size map's bytes `start..end` (`end` ≤ [`LineIndex::len`]), read as they are made.
    pub fn range(&self, start: u64, end: u64) -> io::Result<Entries16> {
        let end = end.min(self.len());
        let start = start.min(end);
        let line = start / ENTRY as u64;
        let (at, state) = self
            .checkpoints
            .get((line / EVERY) as usize)
            .copied()
            .unwrap_or((self.index_at, Cursor::default()));
        let mut f = std::fs::File::open(&self.path)?;
        f.seek(SeekFrom::Start(at))?;
        let mut r = Entries16 {
            r: io::BufReader::with_capacity(64 << 10, f.take(self.index_at.saturating_sub(at))),
            state,
            line: line - line % EVERY,
            pos: start,
            end,
            entry: [0; ENTRY],
        };
        // Up to the line the range starts in.
        while r.line < line {
            decode(&mut r.r, &mut r.state)?;
            r.line += 1;
        }
        Ok(r)
    }
}

/// A range of the fixed-size map, made from the store as it is read.
pub struct Entries16 {
    r: io::BufReader<io::Take<std::fs::File>>,
    state: Cursor,
    /// The next line to decode, and the map's byte to serve next (within its entry or at it).
    line: u64,
    pos: u64,
    end: u64,
    entry: [u8; ENTRY],
}

impl Read for Entries16 {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        let mut n = 0;
        while n < buf.len() && self.pos < self.end {
            let within = (self.pos % ENTRY as u64) as usize;
            // A line's entry is decoded when its first byte served is.
            if self.pos / ENTRY as u64 == self.line {
                self.entry = decode(&mut self.r, &mut self.state).map_err(short)?.to_bytes();
                self.line += 1;
            }
            let k = (ENTRY - within).min(buf.len() - n).min((self.end - self.pos) as usize);
            buf[n..n + k].copy_from_slice(&self.entry[within..within + k]);
            n += k;
            self.pos += k as u64;
        }
        Ok(n)
    }
}

/// The store ending before its trailer says is damage, not the end.
fn short(e: io::Error) -> io::Error {
    if e.kind() == io::ErrorKind::UnexpectedEof {
        damaged("its lines end before their count")
    } else {
        e
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::spool::linemap::LineMap;

    /// Lines of every kind: blocks with CL lines that step, repeat, jump back and are absent,
    /// flags, error comments, tool changes, long and empty lines.
    fn program(n: usize) -> Vec<(String, Option<BlockInfo>)> {
        (0..n)
            .map(|i| {
                let text = match i % 97 {
                    0 => "T2 M6".to_string(),
                    1 => format!("(ERROR UNREACHABLE CL LINE {i}: POSE UNREACHABLE)"),
                    2 => "x".repeat(300 + i % 7),
                    3 => String::new(),
                    _ => format!("X{}.{} Y{}", i * 7 % 1000, i % 13, i % 3),
                };
                let b = (i % 97 > 3).then(|| BlockInfo {
                    n: i as u64,
                    source_line: match i % 11 {
                        0 => None,
                        1 => Some((i / 3) as u32),
                        2 => Some(u32::MAX - i as u32),
                        _ => Some(i as u32 + 1),
                    },
                    joints: Default::default(),
                    diagnostics: if i % 31 == 0 {
                        vec![crate::diag::Diagnostic::new(
                            crate::diag::Code::Unwind,
                            crate::diag::Severity::Warning,
                            None,
                            "turned",
                        )]
                    } else {
                        vec![]
                    },
                    rapid: false,
                    tip: [0.0; 3],
                    axis: [0.0, 0.0, 1.0],
                    time_s: 0.0,
                });
                (text, b)
            })
            .collect()
    }

    /// The old writer's bytes and the store's file.
    fn both(lines: &[(String, Option<BlockInfo>)]) -> (Vec<u8>, tempfile::Spooled) {
        let mut old = LineMap::new(Vec::new());
        let mut new = Writer::new(Vec::new()).unwrap();
        for (t, b) in lines {
            old.line(t, b.as_ref()).unwrap();
            new.line(t, b.as_ref()).unwrap();
        }
        (old.into_inner(), tempfile::Spooled::new(&new.finish().unwrap()))
    }

    fn read(s: &LineIndex, a: u64, b: u64) -> Vec<u8> {
        let mut out = Vec::new();
        s.range(a, b).unwrap().read_to_end(&mut out).unwrap();
        out
    }

    #[test]
    fn whole_and_every_kind_of_range_are_the_old_bytes() {
        for n in [0, 1, 4095, 4096, 4097, 20_000] {
            let (old, file) = both(&program(n));
            let s = LineIndex::open(file.path()).unwrap().expect("compact");
            assert_eq!(s.len(), old.len() as u64);
            assert_eq!(read(&s, 0, s.len()), old, "{n} lines");
            let len = old.len() as u64;
            let mut x = 12345u64;
            for _ in 0..200 {
                x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                let a = (x >> 33) % (len + 1);
                let b = a + (x >> 13) % (len + 1 - a).min(70_000);
                assert_eq!(read(&s, a, b), old[a as usize..b as usize], "{n} lines, {a}..{b}");
            }
        }
    }

    #[test]
    fn a_line_costs_a_few_bytes_at_most() {
        let (old, file) = both(&program(100_000));
        let size = std::fs::metadata(file.path()).unwrap().len();
        // Lines of every kind, lengths jumping by hundreds, CL lines jumping: still under 3 bytes.
        assert!(size * 6 < old.len() as u64, "{size} bytes for {} lines", old.len() / ENTRY);
    }

    #[test]
    fn the_old_format_is_told_apart_and_damage_is_an_error() {
        let (old, file) = both(&program(5000));
        let legacy = tempfile::Spooled::new(&old);
        assert!(LineIndex::open(legacy.path()).unwrap().is_none());
        assert!(LineIndex::open(tempfile::Spooled::new(b"").path()).unwrap().is_none());
        // A job's map as the version before wrote it (`tests/data/job_v1`).
        let v1 = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/job_v1/job.lines");
        assert!(LineIndex::open(&v1).unwrap().is_none());
        let bytes = std::fs::read(file.path()).unwrap();
        for cut in [9, bytes.len() / 2, bytes.len() - 1] {
            assert!(
                LineIndex::open(tempfile::Spooled::new(&bytes[..cut]).path()).is_err(),
                "cut at {cut}"
            );
        }
    }

    /// Both writers, fed by the engine.
    struct Both(LineMap<Vec<u8>>, Writer<Vec<u8>>);

    impl crate::post::Sink for Both {
        fn line(&mut self, text: &str, b: Option<&BlockInfo>) -> Result<(), crate::post::Stop> {
            self.0.line(text, b)?;
            Ok(self.1.line(text, b)?)
        }
    }

    /// Corpus files (warnings, errors, tool changes, TCP) and a generated path, posted: every
    /// range of the store is the old writer's bytes.
    #[test]
    fn posted_programs_round_trip() {
        let lib = crate::machines::Library::load_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/machines").as_ref()).unwrap();
        let data = |f: &str| std::fs::read(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data").join(f)).unwrap();
        let spinner = lib.get("spinner-u5-620").unwrap();
        let mut generated = Vec::new();
        crate::testgen::write_path(&spinner.machine, 30_000, 7, 100.0, &mut generated).unwrap();
        let cases = [
            ("haas-umc750", data("nx_clsf_mech491_variable_axis_inch_5ax.cls"), "joint"),
            ("haas-umc750", data("nx_clsf_mech491_project2_inch_5ax.cls"), "joint"),
            ("spinner-u5-620", data("generated/near_singular_jitter.cls"), "tcp"),
            ("dmg-dmc75v", data("generated/htm_shuffled.cls"), "joint"),
            ("spinner-u5-620", generated, "joint"),
        ];
        for (machine, cl, mode) in cases {
            let p = lib.get(machine).unwrap();
            let settings = crate::post::Settings {
                mode: Some(mode.into()),
                ..Default::default()
            };
            let opts = settings.profile_options(&p, None).unwrap();
            let mut both = Both(LineMap::new(Vec::new()), Writer::new(Vec::new()).unwrap());
            crate::post::post(&cl[..], &p.machine, &opts, &mut both).unwrap();
            let (old, file) = (both.0.into_inner(), tempfile::Spooled::new(&both.1.finish().unwrap()));
            let s = LineIndex::open(file.path()).unwrap().unwrap();
            assert_eq!(read(&s, 0, s.len()), old, "{machine} {mode}");
            let len = old.len() as u64;
            for k in 0..100u64 {
                let a = k * 7919 * 16 % len + k % 16;
                let b = (a + k * k * 13 + 1).min(len);
                assert_eq!(read(&s, a, b), old[a as usize..b as usize], "{machine} {mode} {a}..{b}");
            }
            let size = std::fs::metadata(file.path()).unwrap().len();
            eprintln!("{machine} {mode}: {} lines, {size} bytes stored", len / ENTRY as u64);
        }
    }

    /// Files for the tests, removed when dropped.
    mod tempfile {
        pub struct Spooled(std::path::PathBuf);
        impl Spooled {
            pub fn new(bytes: &[u8]) -> Spooled {
                static N: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
                let n = N.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                let p = std::env::temp_dir().join(format!("kinepost-lines-{}-{n}", std::process::id()));
                std::fs::write(&p, bytes).unwrap();
                Spooled(p)
            }
            pub fn path(&self) -> &std::path::Path {
                &self.0
            }
        }
        impl Drop for Spooled {
            fn drop(&mut self) {
                let _ = std::fs::remove_file(&self.0);
            }
        }
    }
}
