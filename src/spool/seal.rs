//! Where a job's diagnostics come from, and that a failed job's end with its `error` record, so
//! that a reader never takes a stream cut short for a whole one: sealed. The engine writes the
//! record when it stops; where the run failed otherwise (the spool's disk full, the input gone),
//! the queue seals the block store ([`close`]) when it records the failure; where even that
//! write failed, the stream is rebuilt up to its last whole record and the error record follows.
//!
//! Jobs run by a version before the block store (`blocks.rs`) left an NDJSON file
//! (`<id>.ndjson`): served as it is, or mended the same way after its last complete line.

use super::Paths;
use super::blocks::{self, Decoder, Event};
use crate::output::{ErrorBody, Record};
use std::fs::File;
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

/// How a job's diagnostics are to be served.
pub enum Diagnostics {
    /// Rebuilt from the block store ([`blocks::rebuild`]); `len`, the store's length, never
    /// changes once the job has finished (a validator). `end`: a failed job's error record.
    Rebuilt {
        store: PathBuf,
        nc: PathBuf,
        end: Option<Vec<u8>>,
        len: u64,
    },
    /// An NDJSON file from before the block store, as it is (it ends with the error record
    /// where the job failed).
    Whole(PathBuf),
    /// Such a file's first `keep` bytes (its complete lines), then `tail` (the error record, or
    /// nothing where the last complete line is one).
    Mended { path: PathBuf, keep: u64, tail: Vec<u8> },
}

/// The error record's line.
fn error_line(message: &str) -> Vec<u8> {
    let mut out = Vec::new();
    let _ = Record::Error {
        error: ErrorBody::new(message),
    }
    .write_to(&mut out);
    out
}

/// Where the line holding byte `before - 1` starts: after the last `\n` before `before`, or 0.
fn line_start(f: &mut File, before: u64) -> std::io::Result<u64> {
    let mut end = before;
    let mut buf = vec![0u8; 64 << 10];
    while end > 0 {
        let start = end.saturating_sub(buf.len() as u64);
        let chunk = &mut buf[..(end - start) as usize];
        f.seek(SeekFrom::Start(start))?;
        f.read_exact(chunk)?;
        if let Some(i) = chunk.iter().rposition(|&b| b == b'\n') {
            return Ok(start + i as u64 + 1);
        }
        end = start;
    }
    Ok(0)
}

/// Where the file's complete lines end, and whether the last of them is an error record.
fn ending(f: &mut File) -> std::io::Result<(u64, bool)> {
    let len = f.metadata()?.len();
    let complete = line_start(f, len)?;
    if complete == 0 {
        return Ok((0, false));
    }
    let start = line_start(f, complete - 1)?;
    // An error record is short; a long last line is something else.
    if complete - start > 1 << 20 {
        return Ok((complete, false));
    }
    let mut line = vec![0u8; (complete - 1 - start) as usize];
    f.seek(SeekFrom::Start(start))?;
    f.read_exact(&mut line)?;
    let is_error = serde_json::from_slice::<serde_json::Value>(&line).is_ok_and(|v| v["type"] == "error");
    Ok((complete, is_error))
}

/// Makes a block store (created if missing) end with an error record: an event cut short is
/// cut off, the record appended unless the last whole event is one, and the file fsynced.
pub fn close(path: &Path, message: &str) -> std::io::Result<()> {
    let mut f = File::options()
        .read(true)
        .write(true)
        .create(true)
        .truncate(false)
        .open(path)?;
    let (whole, closed) = match Decoder::new(std::io::BufReader::with_capacity(64 << 10, &f)) {
        Ok(mut d) => {
            let mut closed = false;
            while let Ok(Some(ev)) = d.next() {
                closed = matches!(ev, Event::Record { error: true, .. });
            }
            (d.at, closed)
        }
        // Empty, or not even the magic whole: begun afresh.
        Err(_) => (0, false),
    };
    if closed && whole == f.metadata()?.len() {
        return Ok(());
    }
    f.set_len(whole)?;
    f.seek(SeekFrom::Start(whole))?;
    if whole == 0 {
        f.write_all(blocks::MAGIC)?;
    }
    if !closed {
        let record = Record::Error {
            error: ErrorBody::new(message),
        };
        f.write_all(&blocks::record_event(&record)?)?;
    }
    f.sync_all()
}

/// How an NDJSON file from before the block store is served: whole, or (a failed job's not
/// ending with its error record) mended.
fn legacy(path: PathBuf, failed: Option<&str>) -> std::io::Result<Diagnostics> {
    let Some(message) = failed else {
        return Ok(Diagnostics::Whole(path));
    };
    let mut f = File::open(&path)?;
    let (complete, closed) = ending(&mut f)?;
    Ok(match (closed, complete == f.metadata()?.len()) {
        (true, true) => Diagnostics::Whole(path),
        (true, false) => Diagnostics::Mended {
            path,
            keep: complete,
            tail: Vec::new(),
        },
        (false, _) => Diagnostics::Mended {
            path,
            keep: complete,
            tail: error_line(message),
        },
    })
}

/// How a finished job's diagnostics are served (a blocking look at its files): rebuilt from
/// its block store, or its NDJSON file where a version before the store ran it; `failed`, a
/// failed job's error, ends them.
pub fn locate(p: Paths, failed: Option<String>) -> std::io::Result<Diagnostics> {
    let found = |p: &Path| match std::fs::metadata(p) {
        Ok(m) => Ok(Some(m.len())),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
        Err(e) => Err(e),
    };
    if let Some(len) = found(&p.blocks)? {
        return Ok(Diagnostics::Rebuilt {
            nc: if failed.is_some() { p.nc_partial } else { p.nc },
            store: p.blocks,
            end: failed.as_deref().map(error_line),
            len,
        });
    }
    match (found(&p.diag)?, failed) {
        (Some(_), failed) => legacy(p.diag, failed.as_deref()),
        // Nothing at all (the run never began, or its files were lost): the record alone.
        (None, Some(message)) => Ok(Diagnostics::Mended {
            path: p.diag,
            keep: 0,
            tail: error_line(&message),
        }),
        (None, None) => Err(std::io::Error::new(
            std::io::ErrorKind::NotFound,
            "the job's diagnostics are gone",
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::{Diagnostics, close, ending, legacy};
    use crate::spool::blocks::{BlockWriter, MAGIC, rebuild};
    use crate::output::Record;
    use crate::post::{AxisWords, BlockInfo, Summary};
    use std::io::Read;

    fn lines(bytes: &[u8]) -> Vec<serde_json::Value> {
        String::from_utf8_lossy(bytes)
            .lines()
            .map(|l| serde_json::from_str(l).unwrap())
            .collect()
    }

    fn served(store: &std::path::Path, nc: &std::path::Path, end: Option<&str>) -> Vec<serde_json::Value> {
        let mut out = Vec::new();
        rebuild(store, nc, end.map(super::error_line))
            .unwrap()
            .read_to_end(&mut out)
            .unwrap();
        lines(&out)
    }

    /// A store of `n` blocks and its NC; `summary`: a whole run's.
    fn store(dir: &std::path::Path, n: u32, summary: bool) -> (std::path::PathBuf, std::path::PathBuf) {
        let (p, q) = (dir.join("d.blocks"), dir.join("d.nc"));
        let mut w = BlockWriter::new(Vec::new()).unwrap();
        let mut nc = String::new();
        for i in 1..=n {
            let b = BlockInfo {
                n: i as u64,
                source_line: Some(i),
                joints: AxisWords([Some(i as f64 * 0.7), None, None, None, None, None]),
                diagnostics: vec![],
                rapid: false,
                tip: [0.0; 3],
                axis: [0.0, 0.0, 1.0],
                time_s: 0.0,
            };
            let text = format!("G1 X{}", "9".repeat(i as usize % 50));
            w.line(&text, Some(&b)).unwrap();
            nc.push_str(&text);
            nc.push('\n');
        }
        if summary {
            w.record(&Record::Summary {
                summary: &Summary::default(),
            })
            .unwrap();
        }
        std::fs::write(&p, w.into_inner()).unwrap();
        std::fs::write(&q, nc).unwrap();
        (p, q)
    }

    #[test]
    fn a_store_cut_short_is_closed_with_the_error_after_its_last_whole_event() {
        let dir = std::env::temp_dir().join(format!("kinepost-diag-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let (p, nc) = store(&dir, 3000, false);
        // Cut mid-event: the partial event goes, the record follows the whole ones.
        let len = std::fs::metadata(&p).unwrap().len();
        std::fs::File::options()
            .write(true)
            .open(&p)
            .unwrap()
            .set_len(len - 1)
            .unwrap();
        close(&p, "job spool: No space left on device").unwrap();
        let l = served(&p, &nc, Some("another message"));
        assert_eq!(l.len(), 3000);
        assert_eq!(l[2999]["type"], "error");
        assert_eq!(l[2999]["error"]["detail"], "job spool: No space left on device");
        // Closed once: closing again changes nothing (the engine's own record is kept too).
        let before = std::fs::read(&p).unwrap();
        close(&p, "another message").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), before);
        // No file at all (the run never began): the record alone.
        let q = dir.join("none.blocks");
        close(&q, "machine gone").unwrap();
        assert!(std::fs::read(&q).unwrap().starts_with(MAGIC));
        assert_eq!(served(&q, &nc, Some("machine gone"))[0]["error"]["detail"], "machine gone");
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// A job run before the block store left NDJSON: served as it is, or mended after its last
    /// whole line where a failed job's does not end with its error record.
    #[test]
    fn an_ndjson_file_from_before_the_store_is_served_or_mended() {
        let dir = std::env::temp_dir().join(format!("kinepost-diag-v1-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("d.ndjson");
        let block = r#"{"type":"block","n":1,"nc":"G1 X1"}"#;
        std::fs::write(&p, format!("{block}\n")).unwrap();
        assert!(matches!(legacy(p.clone(), None).unwrap(), Diagnostics::Whole(_)));
        std::fs::write(&p, format!("{block}\n{}", &block[..20])).unwrap();
        match legacy(p.clone(), Some("stopped")).unwrap() {
            Diagnostics::Mended { keep, tail, .. } => {
                assert_eq!(keep as usize, block.len() + 1);
                assert_eq!(lines(&tail)[0]["error"]["detail"], "stopped");
            }
            _ => panic!("not mended"),
        }
        let closed = format!("{block}\n{}", String::from_utf8(super::error_line("x")).unwrap());
        std::fs::write(&p, &closed).unwrap();
        assert!(matches!(legacy(p.clone(), Some("y")).unwrap(), Diagnostics::Whole(_)));
        // Lines longer than a read chunk.
        let long = format!(r#"{{"type":"block","nc":"{}"}}"#, "x".repeat(200_000));
        std::fs::write(&p, format!("{long}\n{long}\n")).unwrap();
        assert_eq!(
            ending(&mut std::fs::File::open(&p).unwrap()).unwrap(),
            (2 * (long.len() as u64 + 1), false)
        );
        let _ = std::fs::remove_dir_all(&dir);
    }
}
