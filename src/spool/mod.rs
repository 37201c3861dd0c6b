//! The spool's file formats: everything a job leaves on disk, and how each is read back. The
//! queue (`jobs`) decides when a file is written, published or removed; this module knows what
//! is in it. Below the edges (`jobs`, `http`) and beside `output`: it imports neither edge.
//!
//! - [`Paths`]: a job's files by name (input, outputs, one run's temporaries) and the
//!   [`Output`]s a finished job publishes;
//! - [`blocks`]: the diagnostics' block store, and the NDJSON rebuilt from it as it streams;
//! - [`linemap`]: the line map's fixed-size entries, as a viewer reads them;
//! - [`lines`]: the line map stored compactly, and its entries rebuilt by range;
//! - [`seal`]: where a job's diagnostics are read from, and a failed job's sealed with its
//!   error record;
//! - `varint`: the LEB128 integers and zigzag signs the two compact formats are written in.

pub mod blocks;
pub mod linemap;
pub mod lines;
pub mod seal;
mod varint;

use std::path::{Path, PathBuf};

/// What a finished job publishes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Output {
    /// The NC program (succeeded jobs).
    Nc,
    /// The NDJSON of blocks, diagnostics and the summary or the error (finished jobs).
    Diagnostics,
    /// The decimated path, joints and marks (`output::preview`) for display (finished jobs).
    Preview,
    /// Each NC line's offset, CL line and flags ([`linemap`]; succeeded jobs).
    Lines,
    /// The CL data as it was uploaded (every job, until it is removed).
    Input,
}

/// A job's files in the spool.
pub struct Paths {
    pub input: PathBuf,
    pub nc: PathBuf,
    /// The NDJSON of a job run before the block store (served as it is; written no more).
    pub diag: PathBuf,
    /// The diagnostics' block store ([`blocks`]), which points into the NC.
    pub blocks: PathBuf,
    /// A failed job's partial NC: its diagnostics' text, never served as a program.
    pub nc_partial: PathBuf,
    pub preview: PathBuf,
    pub lines: PathBuf,
    /// Where one run writes, before it publishes: a run cut off and its successor (perhaps on
    /// another replica) never write the same file.
    pub nc_tmp: PathBuf,
    pub blocks_tmp: PathBuf,
    pub preview_tmp: PathBuf,
    pub lines_tmp: PathBuf,
}

impl Paths {
    pub fn new(spool: &Path, id: &str, attempt: i64) -> Paths {
        Paths {
            input: spool.join(format!("{id}.cl")),
            nc: spool.join(format!("{id}.nc")),
            diag: spool.join(format!("{id}.ndjson")),
            blocks: spool.join(format!("{id}.blocks")),
            nc_partial: spool.join(format!("{id}.nc.partial")),
            preview: spool.join(format!("{id}.preview.json")),
            lines: spool.join(format!("{id}.lines")),
            nc_tmp: spool.join(format!("{id}.nc.{attempt}.tmp")),
            blocks_tmp: spool.join(format!("{id}.blocks.{attempt}.tmp")),
            preview_tmp: spool.join(format!("{id}.preview.json.{attempt}.tmp")),
            lines_tmp: spool.join(format!("{id}.lines.{attempt}.tmp")),
        }
    }

    /// Where a finished job's output lives.
    pub fn output(self, o: Output) -> PathBuf {
        match o {
            Output::Nc => self.nc,
            Output::Diagnostics => self.diag,
            Output::Preview => self.preview,
            Output::Lines => self.lines,
            Output::Input => self.input,
        }
    }
}

/// Makes a rename or a new file durable: the directory entry itself is fsynced.
pub fn sync_dir(dir: &Path) -> std::io::Result<()> {
    #[cfg(unix)]
    std::fs::File::open(dir)?.sync_all()?;
    let _ = dir;
    Ok(())
}
