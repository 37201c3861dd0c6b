//! A failed job's diagnostics end with its `error` record, so that a reader never takes a file
//! cut short for a whole one. The engine writes the record when it stops; where the run failed
//! otherwise (the spool's disk full, the input gone), the store closes the file when it records
//! the failure; where even that write failed, the file is served with the record after its last
//! complete line.

use super::{Error, Job, Output, Store};
use crate::output::{ErrorBody, Record};
use std::fs::File;
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::Path;

/// How a failed job's diagnostics are to be served.
pub enum Diagnostics {
    /// The file as it is: it ends with the error record.
    Whole,
    /// The file's first `keep` bytes (its complete lines), then `tail` (the error record, or
    /// nothing where the last complete line is one).
    Mended { keep: u64, tail: Vec<u8> },
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

/// Makes the file (created if missing) end with an error record: a partial last line is cut
/// off, the record appended unless the last complete line is one, and the file fsynced.
pub(super) fn close(path: &Path, message: &str) -> std::io::Result<()> {
    let mut f = File::options()
        .read(true)
        .write(true)
        .create(true)
        .truncate(false)
        .open(path)?;
    let (complete, closed) = ending(&mut f)?;
    if closed && complete == f.metadata()?.len() {
        return Ok(());
    }
    f.set_len(complete)?;
    if !closed {
        f.seek(SeekFrom::Start(complete))?;
        f.write_all(&error_line(message))?;
    }
    f.sync_all()
}

impl Store {
    /// How a failed job's diagnostics are served: whole when they end with the error record,
    /// else mended (the record written at failure did not fit, or the run never wrote one).
    pub async fn diagnostics(&self, job: &Job) -> Result<Diagnostics, Error> {
        let path = self.output_path(&job.id, Output::Diagnostics);
        let message = job.error.clone().unwrap_or_else(|| "the job failed".into());
        let read = tokio::task::spawn_blocking(move || -> std::io::Result<Diagnostics> {
            let mut f = match File::open(&path) {
                Ok(f) => f,
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                    return Ok(Diagnostics::Mended {
                        keep: 0,
                        tail: error_line(&message),
                    });
                }
                Err(e) => return Err(e),
            };
            let (complete, closed) = ending(&mut f)?;
            Ok(match (closed, complete == f.metadata()?.len()) {
                (true, true) => Diagnostics::Whole,
                (true, false) => Diagnostics::Mended {
                    keep: complete,
                    tail: Vec::new(),
                },
                (false, _) => Diagnostics::Mended {
                    keep: complete,
                    tail: error_line(&message),
                },
            })
        });
        Ok(read.await.map_err(std::io::Error::other)??)
    }
}

#[cfg(test)]
mod tests {
    use super::{close, ending};

    fn lines(path: &std::path::Path) -> Vec<serde_json::Value> {
        std::fs::read_to_string(path)
            .unwrap()
            .lines()
            .map(|l| serde_json::from_str(l).unwrap())
            .collect()
    }

    #[test]
    fn a_file_cut_short_is_closed_with_the_error_after_its_last_whole_line() {
        let dir = std::env::temp_dir().join(format!("kinepost-diag-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("d.ndjson");
        let block = r#"{"type":"block","n":1,"nc":"G1 X1"}"#;
        // Cut mid-record: the partial line goes, the record follows the whole one.
        std::fs::write(&p, format!("{block}\n{}", &block[..20])).unwrap();
        close(&p, "job spool: No space left on device").unwrap();
        let l = lines(&p);
        assert_eq!(l.len(), 2);
        assert_eq!(l[1]["type"], "error");
        assert_eq!(l[1]["error"]["detail"], "job spool: No space left on device");
        // Closed once: closing again changes nothing (the engine's own record is kept too).
        let before = std::fs::read(&p).unwrap();
        close(&p, "another message").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), before);
        assert!(ending(&mut std::fs::File::open(&p).unwrap()).unwrap().1);
        // No file at all (the run never began): the record alone.
        let q = dir.join("none.ndjson");
        close(&q, "machine gone").unwrap();
        assert_eq!(lines(&q)[0]["error"]["detail"], "machine gone");
        // Lines longer than a read chunk.
        let long = format!(r#"{{"type":"block","nc":"{}"}}"#, "x".repeat(200_000));
        std::fs::write(&p, format!("{long}\n{long}\n")).unwrap();
        close(&p, "stopped").unwrap();
        assert_eq!(lines(&p).len(), 3);
        let _ = std::fs::remove_dir_all(&dir);
    }
}
